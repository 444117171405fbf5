/* self_influence.c: how much of the noisy image's own noise a denoiser keeps, read back
 * from SURE, for the James-Stein weight (docs/blend.md "Self-influence").
 *
 * The combiner r = n + rho (d - n) over a window of p values has, for a constant rho,
 * E|r - mu|^2 = S - 2 rho (S - C) + rho^2 E|d - n|^2 with S = sum v and
 * C = sum Cov(n_i, d_i), so the best rho is (S - C) / E|d - n|^2. The plain James-Stein
 * weight takes C = 0. For Gaussian noise Cov(n_i, d_i) = v_i E[dd_i/dn_i] (Stein's
 * lemma), the same divergence that SURE estimates with its probes:
 *
 *     SURE_i = (d_i - n_i)^2 - v_i + 2 v_i dd_i/dn_i,
 *
 * so v_i dd_i/dn_i = (SURE_i - (d_i - n_i)^2 + v_i) / 2. One probe makes that noisy per
 * value (the per-value version made blends worse), but summed over the image it is
 * precise: kappa = sum_i v_i dd_i/dn_i / sum_i v_i per channel, the denoiser's
 * variance-weighted self-influence. Sums are per row in double and the rows added in
 * order, so kappa does not depend on the thread count. */
#include "internal.h"

#include <math.h>
#include <stdlib.h>

int
mcp_blend_self_influence(const mcp_image *noisy, const mcp_image *denoised,
                         const mcp_image *var_of_mean, const mcp_image *sure,
                         double kappa[3])
{
    for (int k = 0; k < 3; k++)
        kappa[k] = 0.0;
    mcp__rgb n, d, v, s;
    if (mcp__blend_rgb(noisy, "noisy", &n) || mcp__blend_rgb(denoised, "denoised", &d) ||
        mcp__blend_rgb(var_of_mean, "variance", &v) || mcp__blend_rgb(sure, "SURE", &s) ||
        mcp__blend_same_size(noisy, denoised, var_of_mean, sure, (const mcp_image *)NULL))
        return -1;
    int w = noisy->width, h = noisy->height;
    double *rows = mcp_malloc((size_t)h * 6 * sizeof *rows);
    if (!rows) return -1;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        double *num = rows + 6 * (size_t)y, *den = num + 3;
        for (int k = 0; k < 3; k++)
            num[k] = den[k] = 0.0;
        for (int x = 0; x < w; x++)
            for (int k = 0; k < 3; k++) {
                double e = (double)mcp__rgb_at(&d, x, y, k) - mcp__rgb_at(&n, x, y, k);
                double vk = mcp__rgb_at(&v, x, y, k);
                double vj = ((double)mcp__rgb_at(&s, x, y, k) - e * e + vk) / 2;
                /* a value without a finite SURE (a bad pixel) says nothing */
                if (!isfinite(vj) || !isfinite(vk)) continue;
                num[k] += vj;
                den[k] += vk;
            }
    }
    double num[3] = {0, 0, 0}, den[3] = {0, 0, 0};
    for (int y = 0; y < h; y++)
        for (int k = 0; k < 3; k++) {
            num[k] += rows[6 * (size_t)y + k];
            den[k] += rows[6 * (size_t)y + 3 + k];
        }
    free(rows);
    for (int k = 0; k < 3; k++) {
        /* kappa outside [0, 1] is the estimate's noise (or no variance at all): a
           denoiser that amplifies its input's noise is not one to blend */
        double q = den[k] > 0 ? num[k] / den[k] : 0.0;
        kappa[k] = q < 0 ? 0.0 : q > 1 ? 1.0 : q;
    }
    return 0;
}
