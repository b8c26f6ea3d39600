"""Device layouts of the GP model and packing of host objects into them.

A kernel packs into one GpKernel. A mean tree packs into a postfix program of MeanNode
records that gp_mean.h runs with a fixed-size stack:
  * Transforms are folded into the leaves: each leaf carries its composite world-to-local
    affine map and distance scale, so the device has no transform nodes. A smooth CSG op
    under accumulated scale S gets blend width S k (smin is positively homogeneous), which
    keeps the result identical to the host's node-by-node semantics.
  * Primitive centres fold into the leaf's translation.
  * Children are emitted deeper-first (Sethi-Ullman), with a flag when that swaps the
    operands, so the stack never holds more than log2(leaves) + 1 entries.
"""
from __future__ import annotations

import numpy as np

from .struct import Struct
from ..gp import kernels as K
from ..gp import means as M
from ..kinds.colour_fields import COLOUR_FIELDS
from ..kinds.gp_kernels import GP_KERNELS
from ..kinds.means import MEAN_OPS, MEAN_PRIMITIVES, op_of, primitive_of

GP_KERNEL = Struct("GpKernel", (
    ("float4", "aniso"),            # xyz: diagonal of A
    ("int", "kind"),
    ("float", "sigma2"),
    ("float", "length_scale"),      # l; of the periodic factor for locally_periodic
    ("float", "alpha"),             # rational quadratic shape a
    ("float", "w"),                 # periodic frequency
    ("float", "se_length_scale"),   # locally periodic envelope
    ("float", "radius"),            # thin-plate R
    # Spatially varying multipliers sigma(x) = sigma m_s(x), l(x) = l m_l(x) (kernels.py):
    # kind GP_FIELD_*; linear p0 = (gradient, value), p1.xyz = origin; radial
    # p0 = (center, radius), p1 = (inner, outer, width, 0); grid: a grid record
    # (pack_grid_field) at sigma_grid / ls_grid records after the object's mean program
    # (function space only: fs_sampling.h reads it).
    ("int", "sigma_field"),
    ("int", "ls_field"),
    ("float", "ls_step"),           # smallest l(x) where rays sample: the step rule's l
    ("float", "sigma_top"),         # largest sigma(x) over the proxy (sigma fields; host):
                                    # fs_mean_step's far balls
    ("int", "sigma_grid"),
    ("int", "ls_grid"),
    ("float4", "sigma_p0"),
    ("float4", "sigma_p1"),
    ("float4", "ls_p0"),
    ("float4", "ls_p1"),
))

# Leaf parameters (local coordinates, centre folded into the map):
#   constant  p0.x = value
#   plane     p0.x = offset d, p0.y = scale, p0.z = min value; p1.xyz = unit normal;
#             value max(scale (n.y - d), min)
#   sphere    p0.x = radius          box        p1.xyz = half extents
#   rounded_box p0.x = radius, p1.xyz = half extents
#   torus     p0.x = major, p0.y = minor
#   capsule   p0.xyz = a, p0.w = radius, p1.xyz = b
#   grid      the map goes to index coordinates u (voxel units, sample (i,j,k) at u = i,j,k);
#             p1.xyz = sample counts (nx, ny, nz); p0.y = 1: cubic, the payload holds the
#             (nx + 2, ny + 2, nz + 2) B-spline coefficients (means.cubic_coefficients)
#             instead of the samples; p0.z = B: after the samples (C order), the slope
#             bound of each brick of B^3 cells (means.brick_slope_bounds / S, <= 1, bricks
#             in C order), which gp_mean_lipschitz_on reads for a segment's bound;
#             p0.w = 1 where that global bound is loose (loose_slope_bound);
#             p0.x = 1 / S, S = GridMean.lipschitz
#             (world units), the weight of the outside distance (in voxels); flags =
#             number of payload records that follow the leaf.
#             Samples are stored divided by S h, with scale multiplied by S h: the leaf's
#             primitive is then 1-Lipschitz in index units like every distance, so
#             ws_mean_lipschitz's |scale| ||M|| is the grid's bound with no special case.
# Grid payload: GRID_PAYLOAD_FLOATS floats per record in row0..p1, sample (i, j, k) at
# float index (i ny + j) nz + k; kind = payload, which every walker of the program skips
# as a non-leaf (gp_mean_eval jumps over it using the leaf's flags).
MEAN_NODE = Struct("MeanNode", (
    ("float4", "row0"),     # world -> local affine map, w = translation
    ("float4", "row1"),
    ("float4", "row2"),
    ("float4", "p0"),
    ("float4", "p1"),
    ("int", "kind"),
    ("int", "flags"),       # ops: MEAN_FLAG_SWAPPED if the right operand was emitted first;
                            # grid leaves: payload record count
    ("float", "scale"),     # leaves: distance scale of the composite transform
    ("float", "k"),         # ops: smooth blend width, 0 = sharp
))

FIELD_KINDS = {"none": 0, "linear": 1, "radial": 2, "grid": 3}
# payload: records of samples after a grid leaf or field, which every walker of a
# program skips as a non-leaf (ids from GP_MEAN_FIRST_OP up are not leaves)
MEAN_PAYLOAD = 31
MEAN_KINDS = {**{k: MEAN_PRIMITIVES.id(k) for k in MEAN_PRIMITIVES.names},
              **{k: MEAN_OPS.id(k) for k in MEAN_OPS.names}, "payload": MEAN_PAYLOAD}
MEAN_FLAG_SWAPPED = 1
MEAN_STACK_DEPTH = 8    # GP_MEAN_STACK_DEPTH in gp_mean.h
GRID_PAYLOAD_FLOATS = 20    # the float4 fields row0..p1; kind must stay a valid int
# Cells per brick edge of a grid leaf's slope-bound table: 4^3 cells share one bound, so a
# table costs 1/64 of the samples and a ray interval of a few cells reads a few bricks.
GRID_BRICK = 4
# A grid leaf whose global slope bound exceeds this many times the bound of nine bricks
# in ten is flagged (p0.w = 1) for the occupancy marches' brick scans: on the example
# grids (ratios 1.2-2.0) the scans cost more than the longer steps saved (paths per CPU s
# 1.09-1.15x without them, csg_baked 0.99x: docs/design/grid-means.md, "The marches'
# brick scans"); a grid whose bound is set by a few steep cells still needs them.
LOOSE_SLOPE_BOUND = 2.0
STRUCTS = (GP_KERNEL, MEAN_NODE)



def c_declarations() -> str:
    """#defines and struct declarations that gp_kernel.h and gp_mean.h assume."""
    lines = ["/* Generated from gpiscl/host/layout/gp_records.py: do not edit. */"]
    lines += GP_KERNELS.c_enum() + GP_KERNELS.c_traits()
    lines += [f"#define GP_FIELD_{k.upper()} {v}" for k, v in FIELD_KINDS.items()]
    lines += MEAN_PRIMITIVES.c_enum() + MEAN_OPS.c_enum(count=False)
    lines.append(f"#define GP_MEAN_PAYLOAD {MEAN_PAYLOAD}")
    lines.append(f"#define GP_MEAN_FIRST_OP {MEAN_OPS.first_id}")
    lines += COLOUR_FIELDS.c_enum()
    lines.append(f"#define GP_MEAN_FLAG_SWAPPED {MEAN_FLAG_SWAPPED}")
    lines.append(f"#define GP_MEAN_STACK_DEPTH {MEAN_STACK_DEPTH}")
    lines.append(f"#define GP_MEAN_GRID_PAYLOAD_FLOATS {GRID_PAYLOAD_FLOATS}")
    return "\n".join(lines) + "\n" + "\n".join(s.c_declaration() for s in STRUCTS)


def _pack_field(field):
    p0, p1 = np.zeros(4), np.zeros(4)
    if isinstance(field, K.LinearField):
        p0[:3], p0[3], p1[:3] = field.gradient, field.value, field.origin
    elif isinstance(field, K.RadialField):
        p0[:3], p0[3] = field.center, field.radius
        p1[:3] = field.inner, field.outer, field.width
    elif not isinstance(field, K.GridField):   # a grid's record offset: the scene compiler
        raise TypeError(f"no device form for field {type(field).__name__}")
    return FIELD_KINDS[field.kind], p0, p1


def sigma_top(kernel: K.NonStationary, field_max: float | None = None) -> np.float32:
    """GpKernel.sigma_top: the largest sigma(x), rounded up to float32 (the device's
    bound); field_max: the sigma field's largest value where rays sample (a linear field
    has one only over a proxy: compile/gpis.py passes it), else the field's own largest
    value (grid, radial; 0, no bound, for a linear field)."""
    f = kernel.sigma_field
    if field_max is None:
        field_max = (f.maximum() if isinstance(f, K.GridField)
                     else max(f.inner, f.outer) if isinstance(f, K.RadialField) else 0.0)
    top = float(np.sqrt(kernel.base.variance)) * field_max
    return np.nextafter(np.float32(top), np.float32(np.inf)) if top > 0.0 else np.float32(0.0)


def pack_kernel(kernel: K.Kernel) -> np.ndarray:
    if isinstance(kernel, K.NonStationary):
        out = pack_kernel(kernel.base)
        if kernel.sigma_field is not None:
            out["sigma_field"], out["sigma_p0"], out["sigma_p1"] = _pack_field(kernel.sigma_field)
            out["sigma_top"] = sigma_top(kernel)
        if kernel.length_scale_field is not None:
            out["ls_field"], out["ls_p0"], out["ls_p1"] = _pack_field(kernel.length_scale_field)
            step = kernel.step_length_scale
            if step is None:   # without a proxy only a bounded field gives a bound
                if isinstance(kernel.length_scale_field, K.LinearField):
                    raise ValueError("a linear length_scale field needs step_length_scale "
                                     "(its minimum over the sampled region)")
                step = kernel.length_scale * kernel.length_scale_field.minimum()
            out["ls_step"] = step
        return out
    out = GP_KERNEL.zeros(1)
    out["aniso"] = (*np.asarray(kernel.aniso, dtype=np.float64), 0.0)
    out["kind"] = GP_KERNELS.id(kernel.kind)
    out["sigma2"] = float(kernel.sigma) ** 2
    for name in GP_KERNELS[kernel.kind].host.params:
        out[name] = getattr(kernel, name)
    return out


# --- means -----------------------------------------------------------------------------



def _stack_need(node) -> int:
    if isinstance(node, M.Transform):
        return _stack_need(node.child)
    if op_of(node) is not None:
        a, b = _stack_need(node.left), _stack_need(node.right)
        return max(a, b) if a != b else a + 1
    return 1


def _compose(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """The map y -> inner(outer(y)) of two 3x4 affine maps."""
    return np.concatenate([inner[:, :3] @ outer[:, :3],
                           (inner[:, :3] @ outer[:, 3] + inner[:, 3])[:, None]], axis=1)


def _translate(m: np.ndarray, center) -> np.ndarray:
    return _compose(m, np.concatenate([np.eye(3), -np.asarray(center, float)[:, None]], 1))


def _leaf(node, m, scale):
    if isinstance(node, M.GridMean):
        return _grid_leaf(node, m, scale)
    kind = primitive_of(node)
    center, p0, p1 = kind.host.pack(node)
    if center is not None:
        m = _translate(m, center)
    rec = MEAN_NODE.zeros(1)
    rec["kind"] = MEAN_PRIMITIVES.id(kind.name)
    rec["row0"], rec["row1"], rec["row2"] = m
    rec["p0"], rec["p1"], rec["scale"] = p0, p1, scale
    return rec


def payload_records(count: int, lead: int = 0):
    """(records, floats): `lead` zeroed records (for the caller's header) then zeroed
    payload records for `count` floats, and the (payload records, GRID_PAYLOAD_FLOATS)
    float32 view of their row0..p1 that write_floats fills. Writing into the records
    directly spares the float64 and float32 copies of a whole grid that a
    concatenate-then-convert pass holds at once."""
    n_rec = -(-int(count) // GRID_PAYLOAD_FLOATS)
    records = MEAN_NODE.zeros(lead + n_rec)
    records["kind"][lead:] = MEAN_KINDS["payload"]
    assert [MEAN_NODE.dtype.fields[n][1] for n in _PAYLOAD_FIELDS] == [0, 16, 32, 48, 64]
    width = MEAN_NODE.dtype.itemsize // 4
    floats = records[lead:].view(np.float32).reshape(n_rec, width)[:, :GRID_PAYLOAD_FLOATS]
    return records, floats


def write_floats(floats: np.ndarray, start: int, values) -> int:
    """Write values (flattened in C order, rounded to float32) into the payload view
    `floats` from float index `start` on; returns the index after them."""
    values = np.asarray(values).ravel()
    width, n, i = floats.shape[1], values.size, 0
    row, col = divmod(int(start), width)
    if col and n:
        k = min(width - col, n)
        floats[row, col:col + k] = values[:k]
        i, row = k, row + 1
    full = (n - i) // width
    if full:
        floats[row:row + full] = values[i:i + full * width].reshape(full, width)
        i, row = i + full * width, row + full
    if i < n:
        floats[row, :n - i] = values[i:]
    return int(start) + n


_PAYLOAD_FIELDS = ("row0", "row1", "row2", "p0", "p1")


def pack_payload(floats) -> np.ndarray:
    """Payload records holding `floats` (float32, flattened) in row0..p1, as grid leaves,
    grid colour fields and grid kernel fields store their samples."""
    floats = np.asarray(floats)
    payload, view = payload_records(floats.size)
    write_floats(view, 0, floats)
    return payload


def _check_grid_size(values):
    if np.asarray(values).size >= 2**31:
        raise ValueError(f"grid of {np.shape(values)} samples is too large: the device "
                         f"indexes samples with 32-bit ints")


def pack_grid_field(field: K.GridField) -> np.ndarray:
    """A kernel grid field's record (row0..row2: world -> index coordinates, p1.xyz: sample
    counts, flags: payload count; fs_sampling.h fs_grid_field) and its samples."""
    values = np.asarray(field.values, np.float64)
    _check_grid_size(values)
    h = float(field.voxel_size)
    payload = pack_payload(values)         # C order: (i ny + j) nz + k
    rec = MEAN_NODE.zeros(1)
    rec["kind"] = MEAN_KINDS["payload"]    # never run as a mean leaf
    rec["flags"] = len(payload)
    rec["row0"], rec["row1"], rec["row2"] = np.concatenate(
        [np.eye(3) / h, -np.asarray(field.origin, float)[:, None] / h], 1)
    rec["p1"] = (*values.shape, 0.0)
    return np.concatenate([rec, payload])


def pack_kernel_grids(kernel: K.Kernel, record: np.ndarray, offset: int) -> list:
    """The records of kernel's grid fields, to be stored from `offset` records after the
    start of the object's mean program on; sets record's sigma_grid / ls_grid to match."""
    out = []
    for attr, slot in (("sigma_field", "sigma_grid"), ("length_scale_field", "ls_grid")):
        field = getattr(kernel, attr, None) if isinstance(kernel, K.NonStationary) else None
        if isinstance(field, K.GridField):
            record[slot] = offset
            out.append(pack_grid_field(field))
            offset += len(out[-1])
    return out


_PACK_LAYERS = 8   # x layers of a grid's samples per write_floats


def loose_slope_bound(bricks: np.ndarray) -> bool:
    """Whether a grid's global slope bound is loose: more than LOOSE_SLOPE_BOUND times the
    bound of nine bricks in ten. Only there do the occupancy marches pay for a brick scan
    a step (gp_mean_march_scans)."""
    return bool(np.percentile(bricks, 90) * LOOSE_SLOPE_BOUND < 1.0)


def _grid_leaf(node: M.GridMean, m, scale):
    """The grid leaf record followed by its payload records."""
    h = float(node.voxel_size)
    s_index = node.lipschitz * h            # slope bound per voxel
    to_index = np.concatenate([np.eye(3) / h, -np.asarray(node.origin, float)[:, None] / h], 1)
    cubic = node.interpolation == "cubic"
    samples = node.coefficients if cubic else node.values
    _check_grid_size(samples)
    # per-brick slope bounds in the samples' units (<= 1), after the samples
    bricks = M.brick_slope_bounds(node, GRID_BRICK) / node.lipschitz
    # samples / S h in double, rounded to float32, a few x layers at a time (the same
    # numbers as one whole-grid pass, without its temporaries)
    out, floats = payload_records(samples.size + bricks.size, lead=1)
    at = 0
    for i in range(0, samples.shape[0], _PACK_LAYERS):
        at = write_floats(floats, at, np.asarray(samples[i:i + _PACK_LAYERS], np.float64)
                          / s_index)
    write_floats(floats, at, bricks)
    rec = out[:1]                           # the leaf, then its payload
    rec["kind"] = MEAN_KINDS["grid"]
    rec["flags"] = len(out) - 1
    rec["row0"], rec["row1"], rec["row2"] = _compose(m, to_index)
    rec["p0"] = (h / s_index, 1.0 if cubic else 0.0, GRID_BRICK, float(loose_slope_bound(bricks)))
    rec["p1"] = (*np.shape(node.values), 0.0)
    rec["scale"] = scale * s_index
    return out


def _emit(node, m, scale, out):
    if isinstance(node, M.Transform):
        _emit(node.child, _compose(m, node.world_to_object), scale * node.distance_scale, out)
        return
    op = op_of(node)
    if op is not None:
        swapped = _stack_need(node.right) > _stack_need(node.left)
        first, second = (node.right, node.left) if swapped else (node.left, node.right)
        _emit(first, m, scale, out)
        _emit(second, m, scale, out)
        rec = MEAN_NODE.zeros(1)
        rec["kind"] = MEAN_OPS.id(op.name)
        rec["flags"] = MEAN_FLAG_SWAPPED if swapped else 0
        rec["k"] = max(node.k, 0.0) * scale
        out.append(rec)
        return
    out.append(_leaf(node, m, scale))


def pack_mean(mean: M.Mean) -> np.ndarray:
    """The postfix MeanNode program of a mean tree (raises if it needs too deep a stack)."""
    return np.concatenate(pack_mean_parts(mean))


def pack_mean_parts(mean: M.Mean) -> list:
    """pack_mean's program as the record arrays it concatenates, for a caller that joins
    several programs: one concatenation instead of two (a grid's records are large)."""
    need = _stack_need(mean)
    if need > MEAN_STACK_DEPTH:
        raise ValueError(f"mean CSG tree needs a stack of {need} entries; the device "
                         f"evaluator holds {MEAN_STACK_DEPTH} (about 2^{MEAN_STACK_DEPTH - 1}"
                         " leaves in a balanced tree): rebalance the unions")
    out = []
    _emit(mean, np.eye(3, 4), 1.0, out)
    return out
