/* Where a function-space object's posterior lives: its GpisObject's posterior_* fields
 * point into the scene's posterior tables (compile/posterior.py fills them): n FsObs rows,
 * and alpha (n) followed by the packed lower factor L (n(n+1)/2) among the doubles. */

inline FsPost fs_posterior_of(__global const GpisObject* g, __global const FsObs* obs,
                              __global const double* doubles)
{
    FsPost P;
    P.obs = 0;
    P.alpha = P.L = 0;
    P.n = g->posterior_count;
    if (P.n == 0) return P;
    P.obs = obs + g->posterior_first;
    P.alpha = doubles + g->posterior_doubles;
    P.L = P.alpha + P.n;
    return P;
}
