/* The function-space GPIS objects of a scene as seen by one ray: shared by the hit stage
 * and the shadow stage so both sample with the same rules. */

inline uint fs_object_seed(uint seed, int k)
{
    return seed ^ ((uint)k * 0x9e3779b9u);   /* objects draw independent streams */
}

/* Free flight through object k along [o.w, t1] clipped to its proxy and occupancy bounds
 * (the start only for a fresh ray: a valid v conditions the ray at o.w), conditioned on
 * vertex record v, with random stream `stream` (0: continuation, 1: shadow). res.hit = 0
 * when k is not a function-space object or the ray misses its proxy; a failed solve is
 * counted in COUNT_GPIS_FAILED (reported by the host) and also returns no hit. *ray and
 * *prm receive what fs_vertex_at_hit needs. */
inline FsResult fs_object_flight(__constant RenderParams* params,
                                 __global const GpisObject* gpis, int k,
                                 __global const GpKernel* kernels,
                                 __global const MeanNode* means, GpisTables T, float4 o,
                                 float4 d, float t1,
                                 int pixel, int sample, uint stream, FsVertex v,
                                 __global const FsObs* ring, FsScratch S,
                                 __global int* counters, FsRay* ray, FsParams* prm)
{
    FsResult none = {0};
    __global const GpisObject* g = &gpis[k];
    float t0 = o.w;
#ifdef FS_PROFILE
    int occ_evals = 0;
#endif
    int in_proxy = g->sampler == GPIS_SAMPLER_FUNCTION_SPACE
        && gpis_proxy_clip(g, T.planes, o.xyz, d.xyz, &t0, &t1);
    int occupied = in_proxy && gpis_occupancy_clip(g, means, gpis_occ_mask(T, k), o.xyz, d.xyz,
                                                   &t0, &t1, !v.valid OCC_PROF_ARG(&occ_evals));
#ifdef FS_PROFILE
    /* the occupancy clip's work (gpis_proxy.h): proxy entries, those that march, and the
     * marches' mean evaluations */
    atomic_add(&counters[COUNT_FS_STEPS + FS_PROF_OCC_ENTRIES], in_proxy);
    atomic_add(&counters[COUNT_FS_STEPS + FS_PROF_OCC_MARCHES], occ_evals > 0);
    atomic_add(&counters[COUNT_FS_STEPS + FS_PROF_OCC_EVALS], occ_evals);
#endif
    if (!occupied) return none;
    FsParams pr = {g->window, g->memory, g->memory_cap, g->refine, (double)g->step_corr,
                   (double)g->miss_tolerance};
    FsRay r = {convert_double3(o.xyz), convert_double3(d.xyz), (double)t0, (double)t1};
    S.post = fs_posterior_of(g, T.obs, T.doubles);   /* none: the prior */
    FsRng rng = {fs_object_seed(params->seed, k), (uint)pixel, (uint)sample,
                 (uint)params->bounce, stream};
    /* Matern 3/2 and 5/2 along a ray without off-ray conditioning: the exact Markov
     * sampler (fs_markov.h); g->general keeps the general one (tests, benchmarks) */
    FsResult res = GPIS_MEMORY_IS_EXPONENTIAL(g->memory)
        ? fs_classical_flight(kernels[k], means + g->mean_first, g->mean_count, r, rng)
        : !g->general && fs_markov_applies(kernels[k], pr, S)
        ? fs_markov_free_flight(kernels[k], means + g->mean_first, g->mean_count, pr, r, v,
                                rng, S)
        : fs_free_flight(kernels[k], means + g->mean_first, g->mean_count, pr, r, v,
                         ring, rng, S);
    atomic_inc(&counters[COUNT_FS_FLIGHTS]);
    atomic_add(&counters[COUNT_FS_SAMPLES], res.samples);
    atomic_add(&counters[COUNT_FS_EVALS], res.evals);
#ifdef FS_PROFILE
    for (int q = 0; q < FS_PROF_COUNT; ++q) atomic_add(&counters[COUNT_FS_STEPS + q], res.prof[q]);
#endif
    if (res.status) {
        atomic_inc(&counters[COUNT_GPIS_FAILED]);
        return none;
    }
    *ray = r;
    *prm = pr;
    return res;
}
