import math

import numpy as np
import pytest

from gpiscl.host.compile.bvh import MEDIAN_DEPTH, build_bvh
from gpiscl.host.layout.records import BVH_NODE


def _random_triangles(n, rng, size=0.08):
    return rng.random((n, 1, 3)) + size * rng.standard_normal((n, 3, 3))


def _walk(nodes):
    """(node, depth) of every node reachable from the root, each checked to be new."""
    seen, stack, out = set(), [(0, 0)], []
    while stack:
        i, depth = stack.pop()
        assert i not in seen
        seen.add(i)
        out.append((i, depth))
        if nodes["count"][i] == 0:
            left = nodes["left_or_first"][i]
            assert i < left and left + 1 < len(nodes)
            stack += [(left, depth + 1), (left + 1, depth + 1)]
    assert len(seen) == len(nodes)
    return out


def _check_tree(lo, hi, nodes, order, max_leaf):
    n = len(lo)
    assert nodes.dtype == BVH_NODE.dtype and order.dtype == np.int32
    assert np.all(nodes["lo"][:, 3] == 0) and np.all(nodes["hi"][:, 3] == 0)
    covered = np.zeros(n, int)
    depths = []
    for i, depth in _walk(nodes):
        depths.append(depth)
        box_lo, box_hi = nodes["lo"][i, :3], nodes["hi"][i, :3]
        first, count = nodes["left_or_first"][i], nodes["count"][i]
        if count == 0:
            inside_lo = nodes["lo"][[first, first + 1], :3]
            inside_hi = nodes["hi"][[first, first + 1], :3]
        else:
            assert 1 <= count <= max_leaf
            covered[first:first + count] += 1
            prims = order[first:first + count]
            inside_lo, inside_hi = lo[prims], hi[prims]
        assert np.all(box_lo <= inside_lo) and np.all(inside_hi <= box_hi), f"node {i}"
    # leaves tile the order array, and order is a permutation
    assert np.all(covered == 1)
    np.testing.assert_array_equal(np.sort(order), np.arange(n))
    return max(depths)


@pytest.mark.parametrize("n,max_leaf", [(1, 4), (2, 1), (7, 4), (1000, 4), (1000, 1),
                                        (3000, 8)])
def test_tree_structure(n, max_leaf):
    tri = _random_triangles(n, np.random.default_rng(n))
    lo, hi = tri.min(1), tri.max(1)
    nodes, order = build_bvh(lo, hi, max_leaf=max_leaf)
    _check_tree(lo, hi, nodes, order, max_leaf)
    if n == 1:
        assert len(nodes) == 1 and nodes["count"][0] == 1 and nodes["left_or_first"][0] == 0


def test_empty_input_gives_empty_root_leaf():
    nodes, order = build_bvh(np.zeros((0, 3)), np.zeros((0, 3)))
    assert len(nodes) == 1 and len(order) == 0
    assert nodes["count"][0] == 0 and nodes["left_or_first"][0] == 0
    assert np.all(nodes["lo"] == 0) and np.all(nodes["hi"] == 0)


def test_identical_boxes_terminate():
    lo = np.tile([0.0, 1.0, 2.0], (101, 1))
    nodes, order = build_bvh(lo, lo + 1.0, max_leaf=4)
    depth = _check_tree(lo, lo + 1.0, nodes, order, 4)
    assert depth <= math.ceil(math.log2(101 / 4)) + 1


def test_depth_is_bounded_for_skewed_input():
    # every SAH split peels one primitive off the far end; the median fallback must cap
    # the depth below the device's 64-entry traversal stack
    c = 1.5 ** np.arange(200.0)
    lo = np.stack([c, np.zeros_like(c), np.zeros_like(c)], 1)
    nodes, order = build_bvh(lo, lo + 1e-3, max_leaf=1)
    depth = _check_tree(lo, lo + 1e-3, nodes, order, 1)
    assert MEDIAN_DEPTH < depth <= MEDIAN_DEPTH + math.ceil(math.log2(200)) < 63


def _intersect(o, d, tri, tmin=1e-9):
    """Moller-Trumbore distances, inf for a miss; o, d (..., 3) broadcast against tri (m,3,3)."""
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - v0
        u = np.sum(s * p, -1) * inv
        q = np.cross(s, e1)
        v = np.sum(d * q, -1) * inv
        t = np.sum(e2 * q, -1) * inv
    ok = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > tmin)
    return np.where(ok, t, np.inf)


def _traverse(nodes, order, prim_t, o, d):
    """Closest hit (primitive, t) by a stack traversal like kernels_cl/lib/bvh.h.

    prim_t: this ray's distance to every primitive (inf: miss), read only for primitives
    in the leaves the traversal reaches, so results depend on the tree's culling alone.
    """
    best_t, best = np.inf, -1
    inv_d = 1.0 / d
    # slab distances of every node at once; the walk below only reads them
    t0 = (nodes["lo"][:, :3] - o) * inv_d
    t1 = (nodes["hi"][:, :3] - o) * inv_d
    enter = np.maximum(np.minimum(t0, t1).max(1), 0.0).tolist()
    leave = np.maximum(t0, t1).min(1).tolist()
    firsts, counts = nodes["left_or_first"].tolist(), nodes["count"].tolist()
    stack = [0]
    while stack:
        i = stack.pop()
        # a hit exactly on a box face must not be lost to rounding in the slab test
        if enter[i] > min(leave[i], best_t) * (1 + 1e-9) + 1e-12:
            continue
        first, count = firsts[i], counts[i]
        if count == 0:
            stack += [first + 1, first]
            continue
        prims = order[first:first + count]
        t = prim_t[prims]
        j = np.argmin(t)
        if t[j] < best_t:
            best_t, best = t[j], prims[j]
    return best, best_t


def test_traversal_matches_brute_force():
    rng = np.random.default_rng(42)
    tri = _random_triangles(2000, rng)
    nodes, order = build_bvh(tri.min(1), tri.max(1))
    origins = rng.uniform(-0.3, 1.3, (1000, 3))
    dirs = rng.standard_normal((1000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    t_all = _intersect(origins[:, None], dirs[:, None], tri)
    brute = np.where(np.isfinite(t_all.min(1)), t_all.argmin(1), -1)
    assert 0.2 < np.mean(brute >= 0) < 0.95  # both hits and misses are exercised
    for k in range(len(origins)):
        hit, t = _traverse(nodes, order, t_all[k], origins[k], dirs[k])
        assert hit == brute[k], f"ray {k}"
        if hit >= 0:
            assert t == t_all[k, hit]
