"""Binned-SAH bounding volume hierarchy over primitive boxes, built breadth first.

All nodes of one tree level are split together with numpy, so the Python loop runs once
per level rather than once per node. Layout (kernels_cl/lib/bvh.h): node 0 is the root, the
two children of an inner node are adjacent, leaves index a contiguous run of `order`.
"""
from __future__ import annotations

import numpy as np

from ..layout.records import BVH_NODE

SAH_BINS = 16
# Cost of visiting a node relative to one primitive intersection.
TRAVERSAL_COST = 1.0
# From this depth on only median splits are made, so a tree over n primitives is at most
# MEDIAN_DEPTH + log2(n) deep and the device's fixed 64-entry stack cannot overflow.
MEDIAN_DEPTH = 32


def _half_area(lo, hi):
    d = np.maximum(hi - lo, 0.0)
    return d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0]


def _outward_f32(x, direction):
    """Round to float32 without shrinking a box (direction -inf for lo, +inf for hi)."""
    y = x.astype(np.float32)
    moved = (y < x) if direction > 0 else (y > x)
    y[moved] = np.nextafter(y[moved], np.float32(direction))
    return y


def _sah_splits(seg, k, cnt, bins, plo, phi, node_area):
    """Best binned-SAH split of each node: (cost, primitives going left).

    Primitives are grouped by node (seg) and sorted by bin inside each group, so every
    bin is a contiguous run and a split keeps a prefix of its node's run.
    """
    key = seg * SAH_BINS + bins
    counts = np.bincount(key, minlength=k * SAH_BINS).reshape(k, SAH_BINS).T
    runs = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    # (bin, node, xyz) so the scans over bins run on contiguous slices
    bin_lo = np.full((SAH_BINS, k, 3), np.inf)
    bin_hi = np.full((SAH_BINS, k, 3), -np.inf)
    bin_lo[bins[runs], seg[runs]] = np.minimum.reduceat(plo, runs)
    bin_hi[bins[runs], seg[runs]] = np.maximum.reduceat(phi, runs)
    # candidate s puts bins [0, s) left and [s, SAH_BINS) right, s = 1 .. SAH_BINS-1
    n_left = np.cumsum(counts, axis=0)[:-1]
    n_right = cnt - n_left
    a_left = _half_area(np.minimum.accumulate(bin_lo, axis=0)[:-1],
                        np.maximum.accumulate(bin_hi, axis=0)[:-1])
    a_right = _half_area(np.minimum.accumulate(bin_lo[::-1], axis=0)[::-1][1:],
                         np.maximum.accumulate(bin_hi[::-1], axis=0)[::-1][1:])
    with np.errstate(invalid="ignore"):
        cost = TRAVERSAL_COST + (a_left * n_left + a_right * n_right) / node_area
    cost = np.where((n_left > 0) & (n_right > 0), cost, np.inf)
    best = np.argmin(cost, axis=0)
    cols = np.arange(k)
    return cost[best, cols], n_left[best, cols]


def build_bvh(lo, hi, max_leaf: int = 4):
    """BVH over boxes lo, hi (n,3): (nodes with BVH_NODE.dtype, order (n,) int32).

    Leaves hold 1..max_leaf primitives order[left_or_first : left_or_first + count].
    n = 0 gives a single leaf with count 0, which the device reads as an empty scene.
    """
    if max_leaf < 1:
        raise ValueError("max_leaf must be at least 1")
    lo = np.asarray(lo, dtype=np.float64).reshape(-1, 3)
    hi = np.asarray(hi, dtype=np.float64).reshape(-1, 3)
    n = len(lo)
    nodes = BVH_NODE.zeros(max(2 * n - 1, 1))  # every leaf holds >= 1 primitive
    order = np.arange(n, dtype=np.int32)
    if n == 0:
        return nodes, order

    # Primitives of the current level's nodes, grouped by node; one row per primitive
    # (lo, hi, centroid) so each level needs one gather rather than one per array.
    prim = np.arange(n)
    data = np.concatenate([lo, hi, 0.5 * (lo + hi)], axis=1)
    nid, start, cnt = np.array([0]), np.array([0]), np.array([n])
    num_nodes, depth = 1, 0
    while len(nid):
        k, m = len(nid), len(prim)
        offsets = np.r_[0, np.cumsum(cnt)[:-1]]
        seg = np.repeat(np.arange(k), cnt)
        node_lo = np.minimum.reduceat(data[:, 0:3], offsets)
        node_hi = np.maximum.reduceat(data[:, 3:6], offsets)
        nodes["lo"][nid, :3] = _outward_f32(node_lo, -np.inf)
        nodes["hi"][nid, :3] = _outward_f32(node_hi, np.inf)

        cmin = np.minimum.reduceat(data[:, 6:9], offsets)
        cext = np.maximum.reduceat(data[:, 6:9], offsets) - cmin
        axis = np.argmax(cext, axis=1)
        nodes_k = np.arange(k)
        extent, cmin = cext[nodes_k, axis], cmin[nodes_k, axis]
        with np.errstate(divide="ignore"):
            scale = np.where(extent > 0, SAH_BINS / extent, 0.0)
        x = (data[np.arange(m), 6 + axis[seg]] - cmin[seg]) * scale[seg]
        bins = np.clip(np.floor(x), 0, SAH_BINS - 1).astype(np.int64)
        # sort by node, then bin, then centroid; the gap of 2 between (node, bin) keys
        # keeps them apart even where the fraction rounds up to 1
        sort = np.argsort(2.0 * (seg * SAH_BINS + bins) + np.clip(x - bins, 0.0, 1.0))
        data, prim, bins = data[sort], prim[sort], bins[sort]
        order[start[seg] + np.arange(m) - offsets[seg]] = prim

        # SAH only where a split can exist; single primitives are the bulk of deep levels
        try_sah = (cnt > 1) & (extent > 0) & (depth < MEDIAN_DEPTH)
        use_sah = np.zeros(k, bool)
        n_left = cnt // 2
        if try_sah.any():
            area = _half_area(node_lo[try_sah], node_hi[try_sah])
            on = try_sah[seg]
            sub_seg = (np.cumsum(try_sah) - 1)[seg[on]]
            cost, sah_left = _sah_splits(sub_seg, int(try_sah.sum()), cnt[try_sah], bins[on],
                                         data[on, 0:3], data[on, 3:6],
                                         np.where(area > 0, area, 1.0))
            use_sah[try_sah] = cost < cnt[try_sah]
            n_left[try_sah] = np.where(cost < cnt[try_sah], sah_left, n_left[try_sah])
        # too many primitives for a leaf and no useful SAH split: halve by centroid rank,
        # which also separates identical centroids
        split = use_sah | (cnt > max_leaf)

        leaf = ~split
        nodes["left_or_first"][nid[leaf]] = start[leaf]
        nodes["count"][nid[leaf]] = cnt[leaf]
        children = num_nodes + 2 * np.arange(int(split.sum()))
        nodes["left_or_first"][nid[split]] = children
        num_nodes += 2 * len(children)

        keep = split[seg]
        data, prim = data[keep], prim[keep]
        s, nl, ns = start[split], n_left[split], cnt[split]
        nid = np.stack([children, children + 1], 1).reshape(-1)
        start = np.stack([s, s + nl], 1).reshape(-1)
        cnt = np.stack([nl, ns - nl], 1).reshape(-1)
        depth += 1
    return nodes[:num_nodes].copy(), order
