/* Dense per-work-item Cholesky (LL^T) for the function-space sampler.
 *
 * Storage. One symmetric system per work item, packed lower triangle, row-major:
 * L[i][j] (j <= i) at fs_tri(i) + j, in a __global scratch slice that the host sizes
 * (function_space_records.scratch_doubles). Row-major packing lets a system grow one row
 * at a time (a conditioned bisection point, a gradient at a hit) without moving anything,
 * and the factorisation below is row-oriented, so an appended row is factored by the
 * same code in O(n^2). Private arrays are not used: PoCL's CPU device segfaulted on
 * private double arrays of 512 entries at its automatic work-group size (256
 * and 384 worked; 8192 worked only with local size 1), far below the ~100 rows of a
 * global-memory ray (ring, window, bisection, hit rows).
 *
 * Precision: double. Along a ray the values are strongly correlated (steps of ~0.5-1
 * length scales, fs_march.h: neighbours at correlation 0.6-0.9): 32 SE values at
 * correlation 0.9 have lambda_min / lambda_max ~ 1e-10, and bisection points 1e-2 l apart
 * or a value and a slope at nearly the same point push it further. Cholesky loses ~log10(cond) digits, so
 * float (7 digits) fails outright on such systems, while double keeps >= 5 digits after
 * the jitter below bounds the condition number by ~1/jitter.
 *
 * Jitter: each pivot is computed from K_ii (1 + FS_JITTER), i.e. every observation gets
 * an independent nugget of variance FS_JITTER K_ii. Relative to its own variance, so
 * values (sigma^2) and derivatives (sigma^2 / l^2) are regularised alike, whatever the
 * units. 1e-10 is a noise of 1e-5 standard deviations on every value: invisible in any
 * crossing or normal statistic, while it keeps the factorisation of any positive
 * semidefinite K backward stable (rounding acts like a perturbation of ~n eps ||K|| ~
 * 1e-13 K_ii, a thousand times smaller), including exact duplicates (a value observed
 * twice). A non-positive or NaN pivot after jitter therefore means the kernel is not
 * PSD on these points (thin-plate beyond R, a bad parameter) or the input is NaN: it is
 * returned as a status that the caller counts, never patched over.
 */

inline int fs_tri(int i) { return i * (i + 1) / 2; }

/* Factor rows [from, n) in place; rows [0, from) must already hold their factor. On entry
 * row i holds K[i][0..i]. Returns FS_STATUS_OK, FS_STATUS_NOT_PD or FS_STATUS_NAN; on
 * failure *bad_row (if non-null) is the failing row. */
inline int fs_cholesky(__global double* L, int from, int n, int* bad_row)
{
    for (int i = from; i < n; ++i) {
        __global double* Li = L + fs_tri(i);
        for (int j = 0; j < i; ++j) {
            __global const double* Lj = L + fs_tri(j);
            double s = Li[j];
            for (int k = 0; k < j; ++k) s -= Li[k] * Lj[k];
            Li[j] = s / Lj[j];
        }
        double s = Li[i] * (1.0 + FS_JITTER);
        for (int k = 0; k < i; ++k) s -= Li[k] * Li[k];
        if (!(s > 0.0)) {
            if (bad_row) *bad_row = i;
            return isnan(s) ? FS_STATUS_NAN : FS_STATUS_NOT_PD;
        }
        Li[i] = sqrt(s);
    }
    return FS_STATUS_OK;
}

/* sum_{j < stop} L[i][j] x[j]: the part of row i explained by the first `stop` rows. */
inline double fs_row_dot(__global const double* L, int i, __global const double* x, int stop)
{
    __global const double* Li = L + fs_tri(i);
    double s = 0.0;
    for (int j = 0; j < stop; ++j) s += Li[j] * x[j];
    return s;
}

inline double fs_diag(__global const double* L, int i) { return L[fs_tri(i) + i]; }

/* Whitening and sampling share one forward pass over the rows of the joint system
 * [observed; targets] = mu + L e:
 *   observed row i:  e_i = (y_i - mu_i - sum_{j<i} L_ij e_j) / L_ii   (forward substitution)
 *   target row i:    e_i = z_i,  y_i = mu_i + sum_{j<i} L_ij e_j + L_ii z_i
 * The second line is m + L z with the conditional mean m = mu_X + L_XC e_C and the
 * conditional covariance's factor L_XX (the Schur complement's Cholesky factor is the
 * trailing block of the joint one), so a target conditioned on everything before it
 * costs one row. A sampled row is afterwards indistinguishable from an observed one. */
inline double fs_whiten_row(__global const double* L, __global double* e, int i,
                            double y, double mu)
{
    double r = (y - mu - fs_row_dot(L, i, e, i)) / fs_diag(L, i);
    e[i] = r;
    return r;
}

inline double fs_sample_row(__global const double* L, __global double* e, int i,
                            double mu, double z)
{
    e[i] = z;
    return mu + fs_row_dot(L, i, e, i) + fs_diag(L, i) * z;
}

/* Conditional law of target rows given the first m rows (whitened in e[0..m)):
 * mean_i = mu_i + sum_{j<m} L_ij e_j, cov_ij = sum_{m <= k <= min(i,j)} L_ik L_jk. */
inline double fs_conditional_mean(__global const double* L, __global const double* e,
                                  int m, int i, double mu)
{
    return mu + fs_row_dot(L, i, e, m);
}

inline double fs_conditional_cov(__global const double* L, int m, int i, int j)
{
    __global const double* Li = L + fs_tri(i);
    __global const double* Lj = L + fs_tri(j);
    int top = min(i, j);
    double s = 0.0;
    for (int k = m; k <= top; ++k) s += Li[k] * Lj[k];
    return s;
}

/* Triangular solves with the packed factor, in place on b[0..n). */
inline void fs_forward_solve(__global const double* L, int n, __global double* b)
{
    for (int i = 0; i < n; ++i) b[i] = (b[i] - fs_row_dot(L, i, b, i)) / fs_diag(L, i);
}

inline void fs_backward_solve(__global const double* L, int n, __global double* b)
{
    for (int i = n - 1; i >= 0; --i) {
        double s = b[i];
        for (int k = i + 1; k < n; ++k) s -= L[fs_tri(k) + i] * b[k];
        b[i] = s / fs_diag(L, i);
    }
}
