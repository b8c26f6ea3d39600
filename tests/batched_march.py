"""The numpy twin of fs_march.h's step rule over many dense realizations at once, for
tests/test_fs_adaptive.py test07/test07b: each realization runs the twin's own march
(function_space.march_steps), and each rule evaluation's conditional moments are solved
in one stacked numpy call for every realization waiting on one (grouped by how many rows
it conditions on, so each matrix is the one the twin factors). The twin spends ~0.3 ms of
numpy call overhead per evaluation on 4-10 row matrices; stacked, 750 realizations take
~1 s instead of ~15 s. test07c checks that the stacked moments give march_realization's
steps, misses and evaluations."""
import numpy as np

from gpiscl.testing.reference import function_space as FS


def stacked_moments(kernel, mean, X, Y, x, d):
    """(m, m1, s, r, g) per realization b of f and its slope along d at x[b] given the
    values Y[b] at the points X[b] (b, n, 3): the twin's moments for a stack of n-row
    conditionings (covariance_matrix's formulas over a leading axis)."""
    n = Y.shape[1]
    pts = np.concatenate([X, x[:, None], x[:, None]], axis=1)
    K, mu = FS.stacked_observation_matrix(kernel, mean, pts, np.arange(n + 2) == n + 1, d)
    L = np.linalg.cholesky(K)
    e = np.linalg.solve(L[:, :n, :n], (Y - mu[:, :n])[..., None])[..., 0]
    return (mu[:, n] + np.einsum("bi,bi->b", L[:, n, :n], e),
            mu[:, n + 1] + np.einsum("bi,bi->b", L[:, n + 1, :n], e),
            L[:, n, n], L[:, n + 1, n], L[:, n + 1, n + 1])


def march_many(kernel, mean, o, d, ts, Z, tol):
    """march_realization(kernel, mean, o, d, ts, F, tol) for every row F of Z: a list of
    (sampled indices, missed, evaluations)."""
    d = np.asarray(d, float)
    results = [None] * len(Z)
    waiting = {}

    def advance(b, gen, sent):
        try:
            waiting[b] = (gen, gen.send(sent))
        except StopIteration as done:
            results[b] = done.value

    for b, F in enumerate(Z):
        advance(b, FS.march_steps(kernel, o, d, ts, F, tol), None)
    while waiting:
        groups = {}
        for b, (_, (xr, _, _)) in waiting.items():
            groups.setdefault(len(xr), []).append(b)
        for bs in groups.values():
            asks = [waiting.pop(b) for b in bs]
            X, Y, x = (np.stack([a[1][k] for a in asks]) for k in range(3))
            moments = np.stack(stacked_moments(kernel, mean, X, Y, x, d), axis=1)
            for b, (gen, _), m in zip(bs, asks, moments):
                advance(b, gen, tuple(float(v) for v in m))
    return results
