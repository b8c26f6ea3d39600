/* Function-space free flight for Matern 3/2 and 5/2 by the exact state-space (Markov)
 * form of the process along the ray: O(1) work per sample, no Cholesky of ray rows, no
 * window. Needs fs_sampling.h and fs_march.h (fs_return_rate, fs_downcrossing_slope,
 * FsMoments, the step-rule constants). fs_markov_free_flight returns what fs_free_flight
 * returns; fs_objects.h dispatches to it where fs_markov_applies: stationary Matern
 * priors without fields, posteriors or global memory (those condition on rows off the ray
 * or make the process non-stationary, and keep fs_march.h's sampler).
 * Derivation, costs and rejected options: docs/design/markov-sampler.md.
 *
 * Contract:
 *  - Exact. The kernel restricted to the ray is the 1-D Matern with lambda = sqrt(2 nu)
 *    sqrt(dn'A dn) / l; its state (Y, Y', .., Y^(p)) is Markov with transition
 *    N(A(h) x, Q(h)), A(h) = e^(Fh) in closed form and Q(h) summed as a series without
 *    cancellation (fs_mk_transition), in double: Q's entries span h^(2p+1)..h and bridges
 *    at 1e-2 l_d invert them. The prior mean and its slope are added back at every node.
 *  - Start: the same law as fs_begin, from its draws.
 *  - Step rule: fs_march.h's bound with the moments in closed form; each try is aimed at
 *    ratio 2^FS_MK_TARGET by fs_mk_predict (laws unchanged: every accepted step has
 *    ratio <= 1).
 *  - Hit: bisection by exact bridge sampling down to FS_ROOT_WIDTH l_d (and `refine`
 *    times), the slope from its down-crossing law, tangential components exact in the
 *    metric-orthonormal frame (uncorrelated with everything on the ray).
 *  - Random numbers: fs_march.h's segments; slots 0..p the state noise of a step, the
 *    bisection, normal, slope and start slots of the slot plan (FS_SLOT_*). */
#define FS_MK_ELL32 1.3576766739458992   /* (1 + x) e^-x = e^-1/2 */
#define FS_MK_ELL52 1.9262524514893138   /* (1 + x + x^2 / 3) e^-x = e^-1/2 */
#define FS_MK_ROOT_CLAMP 1e-9            /* the root's fraction of the bracket, see fs_mk_hit */
/* The step predictor (fs_mk_predict): the ratio 2^FS_MK_TARGET it aims the next try at,
 * and the factors it may change h by, growing after an accepted step and shrinking
 * after a rejected try */
#define FS_MK_TARGET -3.0f
#define FS_MK_GROW_MIN 0.5f
#define FS_MK_GROW_MAX 2.0f
#define FS_MK_SHRINK_MIN 0.0625f
#define FS_MK_SHRINK_MAX 0.75f

typedef struct {
    int n;          /* state size p + 1 */
    double lam;     /* per world length along the ray */
    double s2;      /* sigma^2 */
} FsMarkov;

inline int fs_markov_applies(GpKernel p, FsParams prm, FsScratch S)
{
    return GP_KERNEL_MARKOV_ORDER(p.kind) > 0
        && !gp_kernel_nonstationary(p) && !S.post.n && !(prm.step_corr > 0.0)
        && fs_memory_markov_ok(prm);
}

inline FsMarkov fs_markov_of(GpKernel p, double3 dn)
{
    FsMarkov m;
    int five = GP_KERNEL_MARKOV_ORDER(p.kind) == 2;
    m.n = five ? 3 : 2;
    m.lam = (five ? 2.23606797749979 : 1.7320508075688772) / (double)p.length_scale
          * sqrt(dot(gp_aniso(p) * dn, dn));
    m.s2 = (double)p.sigma2;
    return m;
}

/* the series' coefficients k! / (k + i)!, i = 0..19, for k = 3 and 5 */
__constant double fs_mk_tail3[20] = {
    1.0, 0.25, 0.05, 0.008333333333333333, 0.0011904761904761906, 0.00014880952380952382,
    1.6534391534391536e-05, 1.6534391534391535e-06, 1.5031265031265032e-07,
    1.252605419272086e-08, 9.635426302092969e-10, 6.882447358637835e-11,
    4.58829823909189e-12, 2.867686399432431e-13, 1.6868743526073125e-14,
    9.371524181151737e-16, 4.932381147974598e-17, 2.466190573987299e-18,
    1.1743764638034756e-19, 5.338074835470344e-21};
__constant double fs_mk_tail5[20] = {
    1.0, 0.16666666666666666, 0.023809523809523808, 0.002976190476190476,
    0.00033068783068783067, 3.306878306878307e-05, 3.006253006253006e-06,
    2.505210838544172e-07, 1.9270852604185938e-08, 1.376489471727567e-09,
    9.17659647818378e-11, 5.735372798864862e-12, 3.373748705214625e-13,
    1.8743048362303472e-14, 9.864762295949196e-16, 4.932381147974598e-17,
    2.348752927606951e-18, 1.0676149670940688e-19, 4.641804204756821e-21,
    1.934085085315342e-22};

/* P(k, x) = e^-x sum_{j >= k} x^j / j! (regularised lower incomplete gamma) for k = 2p + 1
 * = 3 or 5, ex = e^-x: below x = 1 the series' tail e^-x x^k / k! sum_i c_i x^i (positive
 * terms, no cancellation as x -> 0; 20 terms: the next < 1e-20), by Estrin's scheme
 * (quads in x^4: a chain of 6 multiply-adds instead of Horner's 20, which was most of a
 * transition); above it 1 - the head (P(5, 1) = 0.0037: <= 2.5 digits lost, ~1e-13
 * relative). */
inline double fs_mk_gamma_tail(int k, double x, double ex)
{
    if (x >= 1.0) {   /* the head sum_{j < k} x^j / j! */
        double head = 1.0 + x * (1.0 + x * 0.5);
        if (k == 5) head += x * x * x * (1.0 / 6.0 + x * (1.0 / 24.0));
        return 1.0 - ex * head;
    }
    __constant const double* c = k == 3 ? fs_mk_tail3 : fs_mk_tail5;
    double x2 = x * x, x4 = x2 * x2, s = 0.0;
    for (int j = 16; j >= 0; j -= 4)
        s = s * x4 + ((c[j] + c[j + 1] * x) + (c[j + 2] + c[j + 3] * x) * x2);
    double xk = k == 3 ? x2 * x * (1.0 / 6.0) : x4 * x * (1.0 / 120.0);
    return ex * xk * s;
}

/* A(h) and Q(h) of a step of h world lengths (header comment): closed forms in u = lambda
 * h with e = e^-u, E = e^-2u and one incomplete gamma P = P(2p + 1, 2u); every other
 * P(k + 1, 2u) in Q_ij = q sum_k c_ijk k! / (2 lambda)^(k+1) P(k + 1, 2u) differs from P by
 * closed-form terms E (2u)^j / j!, which collect into the polynomials below (derived
 * symbolically from the header's G_i; tests/test_fs_markov.py checks them to 1e-10 against
 * the kernel's joint law). Their leading orders in u keep Q's graded entries exact to
 * rounding: no difference of O(1) terms. */
inline void fs_mk_transition(FsMarkov m, double h, double A[3][3], double Q[3][3])
{
    double l = m.lam, u = l * h, e = exp(-u), E = e * e, s2 = m.s2;
    if (m.n == 2) {
        A[0][0] = e * (1.0 + u);  A[0][1] = e * h;
        A[1][0] = -e * l * u;     A[1][1] = e * (1.0 - u);
        double P = fs_mk_gamma_tail(3, 2.0 * u, E);
        Q[0][0] = s2 * P;
        Q[1][0] = Q[0][1] = s2 * 2.0 * l * u * u * E;
        Q[1][1] = s2 * l * l * (P + 4.0 * u * E);
        return;
    }
    double u2 = u * u, l2 = l * l;
    A[0][0] = e * (1.0 + u + 0.5 * u2);  A[0][1] = e * h * (1.0 + u);  A[0][2] = e * 0.5 * h * h;
    A[1][0] = -e * 0.5 * l * u2;         A[1][1] = e * (1.0 + u - u2);  A[1][2] = e * 0.5 * h * (2.0 - u);
    A[2][0] = e * 0.5 * l2 * u * (u - 2.0);  A[2][1] = e * l * u * (u - 3.0);
    A[2][2] = e * 0.5 * (u2 - 4.0 * u + 2.0);
    double P = fs_mk_gamma_tail(5, 2.0 * u, E), su3E = s2 * u2 * u * E;
    Q[0][0] = s2 * P;
    Q[1][0] = Q[0][1] = s2 * (2.0 / 3.0) * l * u2 * u2 * E;
    Q[1][1] = s2 * l2 / 3.0 * P + (4.0 / 9.0) * l2 * su3E * (4.0 - u);
    Q[2][0] = Q[0][2] = -s2 * l2 / 3.0 * P + (8.0 / 9.0) * l2 * su3E * (1.0 - u);
    Q[2][1] = Q[1][2] = s2 * (2.0 / 3.0) * l2 * l * u2 * (u - 2.0) * (u - 2.0) * E;
    Q[2][2] = s2 * l2 * l2 * (P + 16.0 / 3.0 * u * (u2 - u + 1.0) * E);
}

/* Lower Cholesky factor of the n x n matrix a (n <= 3) in L and the reciprocals of its
 * diagonal in d (the solves below multiply by them: double divisions were a good part
 * of a bridge draw); a non-positive pivot (rounding of a degenerate Q) gives a zero
 * column and d = 0. */
inline void fs_mk_chol(int n, double a[3][3], double L[3][3], double* d)
{
    for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) L[j][i] = 0.0;
    for (int j = 0; j < n; ++j) {
        double p = a[j][j];
        for (int k = 0; k < j; ++k) p -= L[j][k] * L[j][k];
        L[j][j] = p > 0.0 ? sqrt(p) : 0.0;
        d[j] = p > 0.0 ? 1.0 / L[j][j] : 0.0;
        for (int i = j + 1; i < n; ++i) {
            double s = a[i][j];
            for (int k = 0; k < j; ++k) s -= L[i][k] * L[j][k];
            L[i][j] = s * d[j];
        }
    }
}

/* x := L^-1 x (forward) or L^-T x (backward) on the first n entries (d: fs_mk_chol's) */
inline void fs_mk_forward(int n, double L[3][3], const double* d, double* x)
{
    for (int i = 0; i < n; ++i) {
        double s = x[i];
        for (int k = 0; k < i; ++k) s -= L[i][k] * x[k];
        x[i] = s * d[i];
    }
}

inline void fs_mk_backward(int n, double L[3][3], const double* d, double* x)
{
    for (int i = n - 1; i >= 0; --i) {
        double s = x[i];
        for (int k = i + 1; k < n; ++k) s -= L[k][i] * x[k];
        x[i] = s * d[i];
    }
}

/* The inverse of a positive definite n x n matrix through its Cholesky factor: W = L^-1
 * (lower triangular), a^-1 = W'W. */
inline void fs_mk_inverse(int n, double a[3][3], double out[3][3])
{
    double L[3][3], W[3][3], d[3];
    fs_mk_chol(n, a, L, d);
    for (int j = 0; j < n; ++j) {
        W[j][j] = d[j];
        for (int i = j + 1; i < n; ++i) {
            double s = 0.0;
            for (int k = j; k < i; ++k) s += L[i][k] * W[k][j];
            W[i][j] = -d[i] * s;
        }
    }
    for (int i = 0; i < n; ++i)
        for (int j = 0; j <= i; ++j) {
            double s = 0.0;
            for (int k = i; k < n; ++k) s += W[k][i] * W[k][j];
            out[i][j] = out[j][i] = s;
        }
}

/* fs_normal at slots slot .. slot + n - 1 (n <= 3, slot even), one Philox block and one
 * Box-Muller pair per two slots: the same numbers, a third of the cost for 5/2. */
inline void fs_mk_normals(FsRng rng, uint seg, uint slot, int n, double* z)
{
    for (int j = 0; j < n; j += 2) {
        double2 u = fs_uniform2(rng, seg, (slot + (uint)j) >> 1);
        double rad = sqrt(-2.0 * log(1.0 - u.x)), c, sn = sincos(2.0 * M_PI * u.y, &c);
        z[j] = rad * c;
        if (j + 1 < n) z[j + 1] = rad * sn;
    }
}

inline void fs_mk_copy(int n, double src[3][3], double dst[3][3])
{
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) dst[i][j] = src[i][j];
}

/* The state h world lengths on: x := A(h) x + chol(Q(h)) z, z from slots slot.. */
inline void fs_mk_advance(FsMarkov m, double A[3][3], double Q[3][3], double* x,
                          FsRng rng, uint seg, uint slot)
{
    double L[3][3], d[3], z[3], y[3];
    fs_mk_chol(m.n, Q, L, d);
    fs_mk_normals(rng, seg, slot, m.n, z);
    for (int i = 0; i < m.n; ++i) {
        double s = 0.0;
        for (int k = 0; k < m.n; ++k) s += A[i][k] * x[k];
        for (int k = 0; k <= i; ++k) s += L[i][k] * z[k];
        y[i] = s;
    }
    for (int i = 0; i < m.n; ++i) x[i] = y[i];
}

/* The law of the state at a point h1 after xa and h2 before xb, in information form:
 * precision Lam = Q1^-1 + A2' Q2^-1 A2 and eta = Q1^-1 A1 xa + A2' Q2^-1 xb (the mean
 * is Lam^-1 eta). */
inline void fs_mk_bridge(FsMarkov m, double h1, double h2, const double* xa,
                         const double* xb, double Lam[3][3], double* eta)
{
    int n = m.n;
    double A1[3][3], Q1[3][3], A2[3][3], Q2[3][3], P1[3][3], P2[3][3], a[3], w[3];
    fs_mk_transition(m, h1, A1, Q1);
    fs_mk_inverse(n, Q1, P1);
    if (h2 == h1) {               /* a bisection's midpoint: both halves alike */
        fs_mk_copy(n, A1, A2);
        fs_mk_copy(n, P1, P2);
    } else {
        fs_mk_transition(m, h2, A2, Q2);
        fs_mk_inverse(n, Q2, P2);
    }
    for (int i = 0; i < n; ++i) {
        double s = 0.0;
        for (int k = 0; k < n; ++k) s += A1[i][k] * xa[k];
        a[i] = s;
    }
    for (int i = 0; i < n; ++i) {     /* w = P2 xb */
        double s = 0.0;
        for (int k = 0; k < n; ++k) s += P2[i][k] * xb[k];
        w[i] = s;
    }
    double PA[3][3];                  /* P2 A2, then Lam = P1 + A2' (P2 A2) */
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            double s = 0.0;
            for (int k = 0; k < n; ++k) s += P2[i][k] * A2[k][j];
            PA[i][j] = s;
        }
    for (int i = 0; i < n; ++i) {
        double s = 0.0;
        for (int k = 0; k < n; ++k) s += P1[i][k] * a[k] + A2[k][i] * w[k];
        eta[i] = s;
        for (int j = 0; j <= i; ++j) {
            double t = P1[i][j];
            for (int k = 0; k < n; ++k) t += A2[k][i] * PA[k][j];
            Lam[i][j] = Lam[j][i] = t;
        }
    }
}

/* A bridge draw: x = Lam^-1 eta + L^-T z, Lam = L L' (covariance Lam^-1) */
inline void fs_mk_bridge_sample(FsMarkov m, double h1, double h2, const double* xa,
                                const double* xb, FsRng rng, uint seg, uint slot, double* x)
{
    double Lam[3][3], L[3][3], d[3], eta[3];
    fs_mk_bridge(m, h1, h2, xa, xb, Lam, eta);
    fs_mk_chol(m.n, Lam, L, d);
    fs_mk_forward(m.n, L, d, eta);
    double z[3];
    fs_mk_normals(rng, seg, slot, m.n, z);
    for (int j = 0; j < m.n; ++j) eta[j] += z[j];
    fs_mk_backward(m.n, L, d, eta);
    for (int j = 0; j < m.n; ++j) x[j] = eta[j];
}

/* The residual slope's mean and standard deviation at the bridge point given both ends
 * and Y = y0 there: the conditional of (Y', ..) has precision Lam[1:, 1:] and
 * information eta[1:] - Lam[1:, 0] y0. */
inline double fs_mk_bridge_slope(FsMarkov m, double h1, double h2, const double* xa,
                                 const double* xb, double y0, double* sd)
{
    double Lam[3][3], eta[3], R[3][3], C[3][3];
    fs_mk_bridge(m, h1, h2, xa, xb, Lam, eta);
    int k = m.n - 1;
    double b[3];
    for (int i = 0; i < k; ++i) {
        b[i] = eta[i + 1] - Lam[i + 1][0] * y0;
        for (int j = 0; j < k; ++j) R[i][j] = Lam[i + 1][j + 1];
    }
    fs_mk_inverse(k, R, C);
    double mean = 0.0;
    for (int j = 0; j < k; ++j) mean += C[0][j] * b[j];
    *sd = sqrt(fmax(C[0][0], 0.0));
    return mean;
}

/* Conditional moments of (f, f') with means (m, m1) and covariance Q's leading 2 x 2
 * block (Q(h) of the state h on: v = Q_00, c = Q_01, w = Q_11) as fs_march.h's rule
 * takes them. */
inline FsMoments fs_mk_moments(double m, double m1, double Q[3][3])
{
    FsMoments M;
    M.m = m;
    M.m1 = m1;
    M.s = sqrt(fmax(Q[0][0], 0.0));
    M.r = M.s > 0.0 ? Q[0][1] / M.s : 0.0;
    M.g = sqrt(fmax(Q[1][1] - M.r * M.r, 0.0));
    return M;
}

/* The step rule's ratio r = scale * fs_return_rate(fs_mk_moments(m, m1, Q), outside), or
 * any value on the same side of each of the rule's thresholds (accept r <= 1; grow by 2,
 * 1.5, 1.1 below 0.05, 0.3, 1): the same decisions, without erfc where the bracket below
 * settles them (docs/design/markov-sampler.md, 'Cost'). rate = phi(z) e(a) g / s with
 * e(a) = phi(a) + a Phi(a); Birnbaum's and Sampford's bounds on the normal tail,
 * 2 / (t + sqrt(t^2 + 4)) < Q(t) / phi(t) < 4 / (3t + sqrt(t^2 + 8)) (t >= 0), bracket
 * e(a) within 15% (both exact at a = 0, both ~phi(a) / a^2 as a -> -inf), written without
 * cancellation. z^2 = m^2 / v, a = (m1 - c m / v) / g and g / s from one division (the
 * chain sqrt, divide, sqrt, divide of the moments was most of an evaluation's latency);
 * phi needs z^2 only. The bracket is widened by 1e-4 for the float rounding of z^2
 * (<= 2e-5 relative in r at z^2 ~ 170, where phi(z) underflows in float) and of a.
 * Degenerate moments take fs_return_rate itself. */
inline double fs_mk_rule_ratio(double m, double m1, double Q[3][3], int outside,
                               double scale, float hn, float* X, float* gam)
{
    double v = Q[0][0], c = Q[0][1];
    *X = 0.0f;
    *gam = 0.0f;
    if (!(v > 0.0)) return 0.0;
    double iv = 1.0 / v, g2 = Q[1][1] - c * c * iv;
    double ms = outside ? m : -m, m1s = outside ? m1 : -m1;
    float a = (float)(m1s - c * iv * ms) * rsqrt((float)g2);
    *X = (float)(ms * ms * iv) + (a < 0.0f ? a * a : 0.0f);
    *gam = 2.0f * (float)(c * iv) * hn;
    if (!(g2 > 0.0) || !(a == a))
        return scale * fs_return_rate(fs_mk_moments(m, m1, Q), outside);
    float pa = fs_phif(a), lo, hi, t = fabs(a);
    float s4 = sqrt(t * t + 4.0f), s8 = sqrt(t * t + 8.0f);
    if (a >= 0.0f) {   /* e = phi(a) + a (1 - Q(a)) */
        lo = pa + a * (1.0f - pa * 4.0f / (3.0f * a + s8));
        hi = pa + a * (1.0f - pa * 2.0f / (a + s4));
    } else {           /* e = phi(t) - t Q(t), t = -a */
        lo = pa * 8.0f / ((s8 + t) * (3.0f * t + s8));
        hi = pa * 4.0f / ((t + s4) * (t + s4));
        /* below a = -8 fs_return_rate takes the asymptotic phi(a) / a^2 (1 - 3 / a^2),
         * up to 0.35% under e(a) (less than 0.05% under lo there): the bracket must hold it */
        if (a < -8.0f) lo *= 0.995f;
    }
    float pz = 0.39894228f * exp(-0.5f * (float)(ms * ms * iv));
    double k = (double)pz * sqrt(g2 * iv) * scale;
    double rlo = k * lo * (1.0 - 1e-4), rhi = k * hi * (1.0 + 1e-4);
    /* a threshold strictly inside (rlo, rhi] could go either way: decide it exactly */
    if (rlo <= 1.0 && rhi > 1.0)
        return scale * fs_return_rate(fs_mk_moments(m, m1, Q), outside);
    return rhi;
}

/* log2 x and 2^y within 0.09 in log2 (Mitchell: the float's bits read as a piecewise
 * linear log2): the predictor's accuracy, at a few operations instead of a log and an exp
 * on its latency chain */
inline float fs_mk_log2(float x)
{
    return (float)as_int(fmax(x, 1e-30f)) * (1.0f / 8388608.0f) - 127.0f;
}

inline float fs_mk_exp2(float y)
{
    return as_float((int)((clamp(y, -126.0f, 126.0f) + 127.0f) * 8388608.0f));
}

/* log2 of X_t, the X at which the ratio would be 2^FS_MK_TARGET, from a try that saw X and
 * ratio 2^lr: the ratio is mostly e^(-X / 2) (X below), so X_t = X + 2 ln 2 (lr - target);
 * an underflowed ratio (r = 0 reads as lr ~ -100) says only that X is large. */
inline float fs_mk_target_x(float X, float lr)
{
    return fs_mk_log2(fmax(lr > -99.0f ? X + 1.3862944f * (lr - FS_MK_TARGET) : 0.25f * X,
                           1.0f));
}

/* The step predictor: the factor rho on h at which the rule's ratio would be about
 * 2^FS_MK_TARGET. The ratio is phi(z) e(a) g / s (fs_mk_rule_ratio) with e(a) ~ phi(a) /
 * a^2 for a < 0, so log r ~ -X / 2 + slowly varying terms, X = z^2 + a^2 [a < 0]. At small
 * h, z and a both scale like the node's mean m over s ~ rho^(gam / 2) (v ~ h^gam, gam = 2
 * c hn / v from dv/dh = 2c; a = (m1 - c m / v) / g with c / v ~ gam / 2h, g^2 ~ h^(gam -
 * 2)), so X(rho) = X (m(rho) / mn)^2 rho^-gam, mn the node mean X was seen at and m(rho) =
 * a0 + b0 rho linear (a0 the value at the step's start, b0 its slope times the node's
 * distance; a rejected try: the chord to the node's mean). One Newton step in log2 rho
 * from 0 on log2 X(rho) = log2 X_t (lx = log2 X - log2 X_t); clamped to [lo, hi].
 * Only the step sequence depends on it: a step is still accepted only at ratio <= 1. */
inline float fs_mk_predict(float lx, float a0, float b0, float mn, float gam, float lo,
                           float hi)
{
    float m = a0 + b0;
    if (!(m > 0.0f) || !(mn > 0.0f)) return clamp(0.5f, lo, hi);   /* the level within reach */
    float G = lx + 2.0f * (fs_mk_log2(m) - fs_mk_log2(mn)), dG = 2.0f * b0 / m - gam;
    float L = dG < -0.1f ? -G / dG : (G > 0.0f ? 1.0f : -1.0f);
    return clamp(fs_mk_exp2(clamp(L, -4.0f, 2.0f)), lo, hi);
}

/* The prior mean at ray parameter t and its slope along dn (per world length) */
inline double fs_mk_mean(__global const MeanNode* mean, int mc, FsRay ray, double3 dn,
                         double t, double* slope)
{
    float3 g;
    float v = gp_mean_eval(mean, mc, convert_float3(ray.o + t * ray.d), &g);
    *slope = dot(convert_double3(g), dn);
    return (double)v;
}

/* fs_mk_mean, or (flat: the mean's Lipschitz bound on the ray is 0, so it is constant
 * there) its value mu0 at the start and slope 0 without evaluating the mean program: the
 * same numbers (a constant mean's gradient is exactly 0), and the evaluation it skips is
 * a share of a flight (docs/design/markov-sampler.md, 'Cost'). */
inline double fs_mk_mean_on(int flat, double mu0, __global const MeanNode* mean, int mc,
                            FsRay ray, double3 dn, double t, double* slope)
{
    if (flat) { *slope = 0.0; return mu0; }
    return fs_mk_mean(mean, mc, ray, dn, t, slope);
}

/* The start state's free components given those set (Y, and Y' if `slope_set`):
 * stationary conditionals, Y' ~ N(0, P_inf,11), Y'' ~ N(-lambda^2 Y / 3, 8 s2 lambda^4 / 9). */
inline void fs_mk_start(FsMarkov m, double* x, int slope_set, FsRng rng)
{
    double l2 = m.lam * m.lam, var1 = m.n == 2 ? m.s2 * l2 : m.s2 * l2 / 3.0;
    if (!slope_set) x[1] = sqrt(var1) * fs_normal(rng, 0, FS_MK_SLOT_START);
    if (m.n == 3)
        x[2] = -l2 / 3.0 * x[0]
             + sqrt(8.0 / 9.0 * m.s2) * l2 * fs_normal(rng, 0, FS_MK_SLOT_START + 1);
}

inline FsResult fs_markov_free_flight(GpKernel p, __global const MeanNode* mean, int mc,
                                      FsParams prm, FsRay ray, FsVertex v, FsRng rng,
                                      FsScratch S)
{
    FsResult res = {0, 0, ray.t1, (double3)(0.0), 0, 0, 0, 0};
    double dlen = length(ray.d);
    double3 dn = ray.d / dlen;
    FsMarkov m = fs_markov_of(p, dn);
    /* l_d in t: the lag of correlation e^-1/2 (fs_march.h's length scale) */
    double ell = (m.n == 2 ? FS_MK_ELL32 : FS_MK_ELL52) / (m.lam * dlen);
    if (!(ell > 0.0) || !isfinite(ell)) { res.status = FS_STATUS_NAN; return res; }
    double fa, x[3], xb[3], mu1;
    int outside, n_old;
    fs_begin(p, mean, mc, prm, ray, v, 0, rng, S, &fa, &outside, &n_old);
    int with_slope = v.valid && GPIS_MEMORY_IS_RENEWS(prm.memory);
    double mu = fs_mk_mean(mean, mc, ray, dn, ray.t0, &mu1);
    x[0] = fa - mu;
    if (with_slope) x[1] = S.rows[1].value - mu1;
    fs_mk_start(m, x, with_slope, rng);

    double ta = ray.t0, tb = 0.0, fb = 0.0, mua = mu;
    double h = 0.5 * ell, tol = (double)prm.miss_tol, grow = 1.0, sd = sqrt(m.s2);
    double lip = (double)gp_mean_lipschitz_on(mean, mc, convert_float3(ray.o + ray.t0 * ray.d),
                                              convert_float3(ray.o + ray.t1 * ray.d)) * dlen;
    int flat = !(lip > 0.0);
    double Ae[3][3], Qe[3][3], Am[3][3], Qm[3][3], mue = 0.0, mu1e = 0.0;
    /* the accepted try's numbers for the next step's prediction (fs_mk_predict) */
    float p_lx = 0.0f, p_mn = 0.0f, p_gam = 0.0f, p_hn = 0.0f;
    int p_ok = 0, step = 0;
    for (;; ++step) {
        if (ta >= ray.t1) return res;
        if (step >= FS_MAX_STEPS) { res.status = FS_STATUS_STEPS; return res; }
        /* fs_march.h's rule; fs_mean_step with the prior sd sigma */
        double hmean = lip > 0.0
            ? fmax(FS_MEAN_KAPPA * sd, fabs(mua) - FS_MEAN_Z * sd) / lip : INFINITY;
        h = fmin(fmin(grow * h, FS_H_MAX * ell), hmean);
        for (;;) {
            /* fs_march.h's Gauss-Radau rule (nu(ta) = 0): the node nearer the end first,
             * whose numbers feed the predictor; the second node decides against what the
             * first left of the ratio (its returned ratio bounds the true one from above,
             * so an accepted try's sum is <= 1) */
            int clipped = ta + h >= ray.t1;
            double hs = clipped ? ray.t1 - ta : h, r = 0.0;
            float X = 0.0f, gam = 0.0f, hn = (float)(FS_RULE_NODE0 * hs * dlen), mn = 0.0f;
            float sg = outside ? 1.0f : -1.0f;
            for (int q = 0; q < 2 && r <= 1.0; ++q) {
                double u = q ? FS_RULE_NODE1 : FS_RULE_NODE0, mu1m;
                double mum = fs_mk_mean_on(flat, mu, mean, mc, ray, dn, ta + u * hs, &mu1m);
                fs_mk_transition(m, u * hs * dlen, Am, Qm);
                double y0 = 0.0, y1 = 0.0;   /* the node's conditional means: A x */
                for (int k = 0; k < m.n; ++k) { y0 += Am[0][k] * x[k]; y1 += Am[1][k] * x[k]; }
                double left = 1.0 - r;      /* > 0: the loop stops once r > 1 */
                float Xq, gq;
                double rq = fs_mk_rule_ratio(mum + y0, mu1m + y1, Qm, outside,
                                             (q ? FS_RULE_WEIGHT1 : FS_RULE_WEIGHT0) * dlen
                                             * ell / tol / fmax(left, 1e-300),
                                             (float)(u * hs * dlen), &Xq, &gq);
                r += rq * left;
                if (rq > 1.0) r = fmax(r, 1.0 + 1e-12);   /* rounding must not accept it */
                res.evals++;
                if (!q) {
                    X = Xq;
                    gam = gq;
                    mn = sg * (float)(mum + y0);   /* the node's mean on the safe side */
                }
            }
            /* the predictor's numbers: the first node's X, mean and gam, the try's ratio */
            float lx = fs_mk_log2(X) - fs_mk_target_x(X, fs_mk_log2((float)fmin(r, 1e30)));
            gam = gam > 0.5f && gam < 5.0f ? gam : 3.0f;
            if (r <= 1.0 || h <= FS_H_MIN * ell) {
                tb = clipped ? ray.t1 : ta + hs;
                p_ok = r <= 1.0 && X > 0.0f && mn > 0.0f;   /* else (the floor's forced step) 2 */
                p_lx = lx;
                p_mn = mn;
                p_gam = gam;
                p_hn = hn;
                mue = fs_mk_mean_on(flat, mu, mean, mc, ray, dn, ta + hs, &mu1e);
                fs_mk_transition(m, hs * dlen, Ae, Qe);
                break;
            }
            /* the same state: from the step's start value along the chord to the node */
            float a0 = sg * (float)fa;
            h = fmax(hs * (X > 0.0f ? fs_mk_predict(lx, a0, mn - a0, mn, gam, FS_MK_SHRINK_MIN,
                                                    FS_MK_SHRINK_MAX) : 0.5f),
                     FS_H_MIN * ell);
        }
        for (int j = 0; j < m.n; ++j) xb[j] = x[j];
        fs_mk_advance(m, Ae, Qe, xb, rng, (uint)step, 0u);
        fb = mue + xb[0];
        res.samples++;
        if (isnan(fb)) { res.status = FS_STATUS_NAN; return res; }
        if (outside && fb < 0.0) break;
        outside = fb >= 0.0;
        /* the next step's first try: the new value and slope, the accepted node's X */
        float sg = outside ? 1.0f : -1.0f;
        grow = p_ok ? fs_mk_predict(p_lx, sg * (float)fb, sg * (float)(mu1e + xb[1]) * p_hn,
                                    p_mn, p_gam, FS_MK_GROW_MIN, FS_MK_GROW_MAX)
                    : 2.0;
        ta = tb;
        fa = fb;
        mua = mue;
        for (int j = 0; j < m.n; ++j) x[j] = xb[j];
    }

    /* the root search (fs_march.h's fs_root_point: points chosen from values already
     * drawn) by bridge draws in (ta, tb]: x is the state at ta, xb at tb */
    /* an even number of slots per point (fs_mk_normals pairs them): 2 or 4 */
    int stride = (m.n + 1) & ~1, kmax = FS_SLOT_REFINE_COUNT / stride;
    double width = FS_ROOT_WIDTH * ell;
    int budget = fs_root_budget(tb - ta, width);
    for (int k = 0; (k < prm.refine || tb - ta > width) && k < kmax; ++k) {
        double tm = fs_root_point(ta, tb, fa, fb, width, k, budget), xm[3], mu1m;
        fs_mk_bridge_sample(m, (tm - ta) * dlen, (tb - tm) * dlen, x, xb, rng, (uint)step,
                            FS_SLOT_REFINE + (uint)(stride * k), xm);
        double f = fs_mk_mean_on(flat, mu, mean, mc, ray, dn, tm, &mu1m) + xm[0];
        res.samples++;
        res.roots++;
        if (isnan(f)) { res.status = FS_STATUS_NAN; return res; }
        if (f >= 0.0) { ta = tm; fa = f; for (int j = 0; j < m.n; ++j) x[j] = xm[j]; }
        else { tb = tm; fb = f; for (int j = 0; j < m.n; ++j) xb[j] = xm[j]; }
    }
    /* the linear root, kept FS_MK_ROOT_CLAMP of the bracket off its ends (a bridge to
     * an end point is degenerate: Q(0) = 0); moves x_h by < 1e-11 l_d */
    double w = clamp(fa / (fa - fb), FS_MK_ROOT_CLAMP, 1.0 - FS_MK_ROOT_CLAMP);
    res.hit = 1;
    res.t = ta + (tb - ta) * w;
    double3 xh = ray.o + res.t * ray.d;
    double muh1, muh = fs_mk_mean_on(flat, mu, mean, mc, ray, dn, res.t, &muh1), gsd;
    double b = muh1 + fs_mk_bridge_slope(m, (res.t - ta) * dlen, (tb - res.t) * dlen, x, xb,
                                         -muh, &gsd);
    double s = fs_downcrossing_slope(b, gsd, fs_uniform2(rng, step, FS_U_SLOPE));
    /* tangential derivatives in a frame orthonormal in the metric A (header comment) */
    double3 ra = sqrt(gp_aniso(p)), Tq, Bq;
    fs_frame(normalize(ra * dn), &Tq, &Bq);
    double3 T = Tq / ra, B = Bq / ra;
    double z1 = fs_normal(rng, step, FS_SLOT_NORMAL), z2 = fs_normal(rng, step, FS_SLOT_NORMAL + 1);
    double m1 = fs_prior_mean(mean, mc, xh, T, FS_OBS_DERIV), sd1 = sqrt(gp_cov(p, xh, T, 1, xh, T, 1));
    double m2 = fs_prior_mean(mean, mc, xh, B, FS_OBS_DERIV), sd2 = sqrt(gp_cov(p, xh, B, 1, xh, B, 1));
    double q1 = m1 + sd1 * z1, q2 = m2 + sd2 * z2;
    /* the gradient with g.dn = s, g.T = q1, g.B = q2: the dual basis of (dn, T, B) */
    double3 cTB = cross(T, B);
    double det = dot(dn, cTB);
    double3 tang = (q1 * cross(B, dn) + q2 * cross(dn, T)) / det;
    /* fs_march.h: |s| at least 1e-5 of the tangential part, so the normal faces the ray */
    res.law_s = fmin(s, -1e-5 * length(tang));
    res.grad = cTB / det * res.law_s + tang;
    /* the law the normal was drawn from, for next-event estimation (fs_normal_pdf.h):
     * given s, g_t = g - s dn = s (u0 - dn) + q1 u1 + q2 u2 with the dual basis u0 =
     * (T x B) / det, u1 = (B x dn) / det, u2 = (dn x T) / det (u1, u2 in the plane normal
     * to dn) and independent q1, q2; law_a, law_b are the plane's dual vectors of u1, u2
     * scaled by 1 / sd, so (law_a . r, law_b . r) = (z1, z2) for r = g_t - law_m.
     * Isotropic: u0 = dn, u1 = T, u2 = B, fs_march.h's law. */
    double3 u1 = cross(B, dn) / det, u2 = cross(dn, T) / det;
    double D = dot(cross(u1, u2), dn);
    res.law_m = res.law_s * (cTB / det - dn) + m1 * u1 + m2 * u2;
    res.law_a = cross(u2, dn) / (D * sd1);
    res.law_b = cross(dn, u1) / (D * sd2);
    return res;
}
