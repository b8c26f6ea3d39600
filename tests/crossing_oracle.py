"""oracles.expected_crossings memoised for the tests that compare device crossing counts
with it (test_fs_adaptive, test_fs_markov): each call integrates a 6000 x 600 grid
(~0.25 s) and the same (kernel, level, length) recurs across their parametrisations
(55 calls, 29 distinct, in test_fs_adaptive alone)."""
import functools

from gpiscl.testing import oracles

expected_crossings = functools.lru_cache(maxsize=None)(oracles.expected_crossings)
