/* Memory models: what a function-space path remembers of the realization between its rays
 * (scene key sampler.memory), as three hooks. The models and the traits asked here
 * (GPIS_MEMORY_IS_RING, _RENEWS, _FRESH_SLOPE) are declared in
 * gpiscl/host/kinds/memory_models.py, which says what each does:
 *   none          every ray starts afresh
 *   renewal       a ray from a hit starts from the hit's value and a fresh slope
 *   renewal_plus  ... and the slope the hit observed
 *   global        the path's ring holds every observation so far (capacity prm.cap)
 */

/* Rows [0, m) the memory gives a new ray from vertex v (v.valid == 0: fresh entry: none),
 * m = 0 when it gives none; d: the ray's unit direction, g: the vertex's gradient. Sets
 * the start value, whether the ray starts outside, and how many rows came from the ring. */
inline int fs_memory_start_rows(GpKernel p, __global const MeanNode* mean, int mc,
                                FsParams prm, FsVertex v, __global const FsObs* ring,
                                FsRng rng, FsScratch S, double3 d, double3 g, double* f0,
                                int* outside, int* n_old)
{
    if (v.valid && GPIS_MEMORY_IS_RING(prm.memory) && v.obs_count > 0 && ring) {
        int cnt = min(v.obs_count, prm.cap);
        for (int k = 0; k < cnt; ++k) S.rows[k] = ring[(v.obs_end - cnt + k) % prm.cap];
        /* a shadow ray of a normal other than the sampled one (fs_normal_pdf.h): the
         * ring's last two rows are the vertex's tangential derivatives (fs_march.h
         * appends f = 0, the slope, d_T f, d_B f), which take the implied gradient's
         * values; the slope row stays (the implied gradient keeps it, g . d = s) */
        for (int k = max(cnt - 2, 0); v.implied && k < cnt; ++k)
            S.rows[k].value = dot(g, fs_dir(S.rows + k));
        *n_old = cnt;
        *f0 = v.pos.w;
        *outside = dot(g, d) >= 0.0;
        return cnt;
    }
    if (v.valid && GPIS_MEMORY_IS_RENEWS(prm.memory)) {
        double3 x = convert_double3(v.pos.xyz);
        double s = dot(g, d);
        if (GPIS_MEMORY_IS_FRESH_SLOPE(prm.memory)) {   /* value and slope: independent at a point */
            double vs, ms = fs_mean_var(p, mean, mc, S, x, d, FS_OBS_DERIV, 1, &vs);
            /* ... of a stationary prior; observations correlate them, and so does a
             * sigma(x) field: cov(f(x), d_d f(x)) = m_s(x) (d . grad m_s(x)) k0(0) */
            if (S.post.n || gp_kernel_nonstationary(p)) {
                double vf, mf = fs_mean_var(p, mean, mc, S, x, d, FS_OBS_VALUE, 0, &vf);
                GpFieldsAt fx = fs_fields(p, mean, x);
                double c = gp_cov_at(p, x, d, 0, fx, x, d, 1, fx)
                         - fs_post_dot(fs_post_v(S, 0), fs_post_v(S, 1), S.post.n);
                if (vf > 0.0) {
                    ms += c / vf * (v.pos.w - mf);
                    vs = fmax(vs - c * c / vf, 0.0);
                }
            }
            s = fs_truncnorm_pos(ms, sqrt(vs), rng, 0, FS_U_START);
        }
        S.rows[0] = fs_obs(x, d, FS_OBS_VALUE, v.pos.w);
        S.rows[1] = fs_obs(x, d, FS_OBS_DERIV, s);
        *f0 = v.pos.w;
        *outside = s >= 0.0;
        return 2;
    }
    return 0;
}

/* What a continuation ray's hit records for later rays: a ring model appends this ray's
 * observations (values before the crossing, f(x_h) = 0, the three gradient components)
 * to the path's ring. */
inline void fs_memory_record(FsParams prm, FsResult r, __global FsObs* ring, FsScratch S,
                             FsVertex* v)
{
    if (GPIS_MEMORY_IS_RING(prm.memory) && ring && r.hit) {
        int k = r.new_end - r.new_first;   /* contiguous: values, bisection, gradient */
        for (int i = 0; i < k; ++i) {
            ring[v->obs_end % prm.cap] = S.rows[r.new_first + i];
            v->obs_end++;
        }
        v->obs_count = min(v->obs_count + k, prm.cap);
    }
}

/* Whether every row a ray conditions on lies on that ray (no ring of other rays' rows):
 * then the exact Markov sampler (fs_markov.h) may run, and a hit's tangential derivatives
 * are independent of the rows (fs_march.h). */
inline int fs_memory_markov_ok(FsParams prm) { return !GPIS_MEMORY_IS_RING(prm.memory); }

/* Conditioning rows [0, m) of a new ray from vertex v (v.valid == 0: fresh entry): the
 * memory's, else a fresh start value; sets the start value, whether the ray starts
 * outside, and how many rows came from the ring. */
inline int fs_begin(GpKernel p, __global const MeanNode* mean, int mc, FsParams prm,
                    FsRay ray, FsVertex v, __global const FsObs* ring, FsRng rng,
                    FsScratch S, double* f0, int* outside, int* n_old)
{
    double3 d = ray.d / length(ray.d), g = convert_double3(v.grad.xyz);
    *n_old = 0;
    *outside = 1;
    int m = fs_memory_start_rows(p, mean, mc, prm, v, ring, rng, S, d, g, f0, outside, n_old);
    if (m) return m;
    double3 x = ray.o + ray.t0 * ray.d;
    double var, m0 = fs_mean_var(p, mean, mc, S, x, d, FS_OBS_VALUE, 0, &var);
    *f0 = fs_truncnorm_pos(m0, sqrt(var), rng, 0, FS_U_START);
    S.rows[0] = fs_obs(x, d, FS_OBS_VALUE, *f0);
    return 1;
}

/* The vertex record of a continuation ray's hit, with what the memory records. Call only
 * for the continuation ray, after the previous vertex's shadow rays were traced (they read
 * the ring). */
inline FsVertex fs_vertex_at_hit(FsParams prm, FsRay ray, FsResult r, FsVertex prev,
                                 __global FsObs* ring, FsScratch S)
{
    FsVertex v;
    v.pos = (float4)(convert_float3(ray.o + r.t * ray.d), 0.0f);
    v.grad = (float4)(convert_float3(r.grad), 0.0f);
    v.valid = 1;
    v.obs_end = prev.valid ? prev.obs_end : 0;
    v.obs_count = prev.valid ? prev.obs_count : 0;
    v.implied = 0;
    fs_memory_record(prm, r, ring, S, &v);
    return v;
}
