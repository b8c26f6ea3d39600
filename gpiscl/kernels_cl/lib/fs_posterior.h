/* Where a function-space object's posterior lives: a block of MeanNode-sized records just
 * before its mean program (compile/posterior.py packs it), so neither GpisObject nor the
 * stage signatures change, and no walker of a mean program ever sees it:
 *   [raw doubles: n FsObs rows, alpha (n), packed lower factor L (n(n+1)/2)][header]
 * header: kind FS_POSTERIOR_KIND (no mean or field kind), flags = raw records before it,
 * p0.x = n. The record before a program without a posterior is the previous program's
 * last node (a mean kind), so the test below never misfires. */

inline FsPost fs_posterior_of(__global const MeanNode* means, int mean_first)
{
    FsPost P;
    P.obs = 0;
    P.alpha = P.L = 0;
    P.n = 0;
    if (mean_first <= 0) return P;
    __global const MeanNode* h = means + mean_first - 1;
    if (h->kind != FS_POSTERIOR_KIND) return P;
    __global const double* d = (__global const double*)(h - h->flags);
    P.n = (int)h->p0.x;
    P.obs = (__global const FsObs*)d;
    P.alpha = d + 8 * P.n;
    P.L = P.alpha + P.n;
    return P;
}
