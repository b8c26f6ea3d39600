/* Scene preparation on the device (host: render/device_bakes.py): a trilinear grid's
 * slope bounds per brick; numpy twin compile/sdf_bake.py over gp/means.py. */
#pragma OPENCL FP_CONTRACT OFF

/* Per brick of brick^3 cells of a trilinear grid (nx, ny, nz samples, C order): the
 * largest squared |gradient| (voxel units) over its cells, each cell's being the largest
 * at its 8 corners (means._corner_gradients2: one-sided differences along the edges from
 * the corner; summed x, y, z in double as numpy does). The host takes sqrt(.) / h, which
 * commutes with the maximum (both are monotone and correctly rounded), so the brick bounds
 * and the grid's largest equal numpy's bit for bit. */
__kernel void bake_grid_slopes(BAKE_GRID_SLOPES_PARAMS)
{
    int cx = nx - 1, cy = ny - 1, cz = nz - 1;
    int bx = (cx + brick - 1) / brick, by = (cy + brick - 1) / brick,
        bz = (cz + brick - 1) / brick;
    int id = get_global_id(0);
    if (id >= bx * by * bz) return;
    int b2 = id % bz, b1 = (id / bz) % by, b0 = id / (bz * by);
    double best = 0.0;
    for (int i = b0 * brick; i < min(cx, (b0 + 1) * brick); ++i)
        for (int j = b1 * brick; j < min(cy, (b1 + 1) * brick); ++j)
            for (int k = b2 * brick; k < min(cz, (b2 + 1) * brick); ++k)
                for (int c = 0; c < 8; ++c) {
                    int a = c >> 2, b = (c >> 1) & 1, e = c & 1;
                    /* the edges along x, y, z that start at corner (i + a, j + b, k + e) */
                    size_t x0 = ((size_t)i * ny + (j + b)) * nz + (k + e);
                    size_t y0 = ((size_t)(i + a) * ny + j) * nz + (k + e);
                    size_t z0 = ((size_t)(i + a) * ny + (j + b)) * nz + k;
                    double dx = v[x0 + (size_t)ny * nz] - v[x0];
                    double dy = v[y0 + nz] - v[y0];
                    double dz = v[z0 + 1] - v[z0];
                    double total = dx * dx + dy * dy + dz * dz;
                    best = fmax(best, total);
                }
    brick_c2[id] = best;
}
