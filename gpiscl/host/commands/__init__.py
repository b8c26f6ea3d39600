"""What the CLI runs besides render: uq (realization statistics) and sample figures.
Imports render and below; nothing below imports it."""
