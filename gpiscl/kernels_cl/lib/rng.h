/* Counter-based random numbers: every draw is a pure function of
 * (seed, pixel, sample, bounce, dimension), so images do not depend on queue order,
 * batch size or device. One call yields four uniforms in [0, 1). */
#include <pyopencl-random123/philox.cl>

/* Dimension slots: each stage draws from its own slot within a bounce (DIM_*, generated
 * from gpiscl/host/layout/random_slots.py STAGE_DIMS). */

inline float4 rng4(uint seed, int pixel, int sample, int bounce, uint dim)
{
    philox4x32_ctr_t c = {{(uint)pixel, (uint)sample, (uint)bounce, dim}};
    philox4x32_key_t k = {{seed, 0x6a09e667u}};
    philox4x32_ctr_t r = philox4x32(c, k);
    /* 24 high bits give floats exactly representable and strictly below 1. */
    const float scale = 1.0f / 16777216.0f;
    return (float4)((float)(r.v[0] >> 8), (float)(r.v[1] >> 8),
                    (float)(r.v[2] >> 8), (float)(r.v[3] >> 8)) * scale;
}
