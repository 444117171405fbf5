/* safeguard.c: the blend's safeguard, which needs no estimate of the denoiser's error
 * (docs/blend.md "The safeguard").
 *
 * The curve weights rest on SURE and on the variance curve; where SURE misses the
 * denoiser's error (fine texture that a network blurs, a stratified sampler, few
 * replicates) they trust the denoised image too much and the blend no longer converges
 * to the noisy one. The safeguard tests the denoised image against the noisy one with
 * the noisy image's own variance: over a window x window neighbourhood (p values) the
 * weight of d is capped at
 *
 *     rho_max = min(1, (p - 2) mean(v) / sum (n - d)^2),
 *
 * the James-Stein combiner's weight (mcp_blend_james_stein). Where the difference
 * n - d is no larger than the noise explains, the cap is 1 and the curve weight
 * stands; where it is larger, the denoiser is biased there and the weight falls as
 * v / (n - d)^2, so that as v -> 0 the blend goes to n whatever SURE said. With
 * rho <= rho_max the blend's expected squared error in the window is at most the noisy
 * image's whenever the denoiser's variance-weighted self-influence
 * sum v_i dd_i/dn_i / sum v_i is at most 1/2 (docs/blend.md gives the derivation). */
#include "blend.h"
#include "internal.h"

#include <math.h>

int
mcp_blend_safeguard(const mcp_image *noisy, double spp, const mcp_image *denoised,
                    const mcp_image *rho_max, mcp_image *weights, mcp_image *blend,
                    double *pulled)
{
    if (pulled) *pulled = 0;
    mcp__rgb n, d, cap;
    if (!(spp > 0) || !isfinite(spp))
        return mcp_error("blend: safeguard: spp must be finite and > 0 (got %g)", spp);
    if (mcp__blend_rgb(noisy, "noisy", &n) || mcp__blend_rgb(denoised, "denoised", &d) ||
        mcp__blend_rgb(rho_max, "safeguard", &cap) ||
        mcp__blend_same_size(noisy, denoised, rho_max, weights, blend,
                             (const mcp_image *)NULL))
        return -1;
    if (!mcp_image_is_packed(weights) || weights->channels != 3 ||
        !mcp_image_is_packed(blend) || blend->channels != 3)
        return mcp_error("blend: safeguard: the weights and the blend must be packed "
                         "R, G, B images");
    int w = noisy->width, h = noisy->height;
    long count = 0;
#pragma omp parallel for schedule(static) reduction(+ : count)
    for (int y = 0; y < h; y++) {
        float *wd = mcp_image_px(weights, 0, y), *rd = mcp_image_px(blend, 0, y);
        for (int x = 0; x < w; x++)
            for (int k = 0; k < 3; k++) {
                double rho = mcp__rho_of_weight(spp, wd[3 * x + k]);
                double limit = mcp__rgb_at(&cap, x, y, k);
                if (!(rho > limit)) continue; /* also a NaN cap: nothing to test */
                double nv = mcp__rgb_at(&n, x, y, k), dv = mcp__rgb_at(&d, x, y, k);
                rd[3 * x + k] = (float)(nv + limit * (dv - nv));
                wd[3 * x + k] = (float)mcp__weight_of_rho(spp, limit);
                count++;
            }
    }
    if (pulled) *pulled = (double)count / (3.0 * w * h);
    return 0;
}

int
mcp__blend_safeguard_step(const mcp_image *noisy, double spp, const mcp_image *denoised,
                          const mcp_image *var_of_mean, int window, const double *kappa,
                          mcp_image *weights, mcp_image *blend, double *pulled)
{
    mcp_image *js = NULL, *rho = NULL;
    int rc =
        mcp_blend_james_stein(noisy, denoised, var_of_mean, window, kappa, &js, &rho) ||
        mcp_blend_safeguard(noisy, spp, denoised, rho, weights, blend, pulled);
    mcp_image_free(js);
    mcp_image_free(rho);
    return rc ? -1 : 0;
}

int
mcp__blend_weights_from_rho(const mcp_image *rho, double spp, mcp_image **out)
{
    *out = NULL;
    if (mcp__blend_rgb_new(rho->width, rho->height, "blend weights", out)) return -1;
    size_t n = (size_t)rho->width * rho->height * 3;
    for (size_t i = 0; i < n; i++)
        (*out)->data[i] = (float)mcp__weight_of_rho(spp, rho->data[i]);
    return 0;
}
