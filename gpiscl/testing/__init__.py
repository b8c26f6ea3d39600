"""The test kit: statistics with thresholds corrected for the number of comparisons,
small OpenCL wrapper programs over the device headers, oracles (Rice's formula, dense
joint samples) and numpy reference twins of device code.

Only tests and tools import it; the renderer never does (tests/test_testing_kit.py checks
both directions), so a twin here can never become a production dependency."""
