/* Scene preparation on the device (host: render/device_bakes.py): a procedural mean baked
 * to a grid; numpy twin gp/knob.py knob_grid. */
#pragma OPENCL FP_CONTRACT OFF

/* values[(i ny + j) nz + k] = function(ax[i], ay[j], az[k]) rounded to float32. */
__kernel void bake_procedural(BAKE_PROCEDURAL_PARAMS)
{
    int id = get_global_id(0);
    if (id >= nx * ny * nz) return;
    int k = id % nz, j = (id / nz) % ny, i = id / (nz * ny);
    values[id] = (float)knob_function(which, (double3)(ax[i], ay[j], az[k]));
}
