/* post_correction.c: the James-Stein combiner of a noisy and a denoised image, without
 * a network (docs/mathematics.md §3.8; Gu et al. 2022). Its rho, the weight of the
 * denoised input, gives the output's variance through estimate's
 * mcp_postcorrection_variance (Firmino 2023 Eq. 4), for a sampling map:
 * Var[r] = rho^2 Var[d] + (1 - rho)^2 v.
 *
 * Per channel and pixel, over the window x window neighbourhood clipped to the image
 * (p values): r = d + s (n - d), s = max(0, 1 - a (p - 2) sigma^2 / |n - d|^2), sigma^2
 * the window mean of v, a = min(1, 1.5 (1 - kappa)) for a denoiser of self-influence
 * kappa (self_influence.c). Window sums come from summed-area tables in double, so each
 * pixel costs O(1) whatever the window. */
#include "blend.h"
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Summed-area tables of one channel: v and (n - d)^2, (w + 1) x (h + 1) each. */
typedef struct {
    int w, h;
    double *sum_v, *sum_sq;
} sat_pair;

static double
box(const double *t, int w, int x0, int y0, int x1, int y1)
{
    /* sum over [x0, x1) x [y0, y1) */
    size_t W = (size_t)w + 1;
    return t[(size_t)y1 * W + x1] - t[(size_t)y0 * W + x1] - t[(size_t)y1 * W + x0] +
           t[(size_t)y0 * W + x0];
}

static void
build_sats(sat_pair *s, const mcp__rgb *n, const mcp__rgb *d, const mcp__rgb *v, int k)
{
    int w = s->w, h = s->h;
    size_t W = (size_t)w + 1;
    memset(s->sum_v, 0, W * sizeof(double));
    memset(s->sum_sq, 0, W * sizeof(double));
    /* row prefix sums, then column prefix sums */
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        double *tv = s->sum_v + (size_t)(y + 1) * W,
               *ts = s->sum_sq + (size_t)(y + 1) * W;
        double av = 0, as = 0;
        tv[0] = ts[0] = 0;
        for (int x = 0; x < w; x++) {
            double e = (double)mcp__rgb_at(n, x, y, k) - mcp__rgb_at(d, x, y, k);
            av += mcp__rgb_at(v, x, y, k);
            as += e * e;
            tv[x + 1] = av;
            ts[x + 1] = as;
        }
    }
    /* down the columns a row at a time (each row adds the one above it: contiguous,
       the same additions in the same order as column by column); threads take strips
       of STRIP columns */
    enum { STRIP = 256 };
    int strips = (w + STRIP - 1) / STRIP;
#pragma omp parallel for schedule(static)
    for (int st = 0; st < strips; st++) {
        size_t x0 = 1 + (size_t)st * STRIP, x1 = x0 + STRIP > W ? W : x0 + STRIP;
        for (int y = 1; y <= h; y++) {
            double *rv = s->sum_v + (size_t)y * W, *rq = s->sum_sq + (size_t)y * W;
            for (size_t x = x0; x < x1; x++) {
                rv[x] += rv[x - W];
                rq[x] += rq[x - W];
            }
        }
    }
}

/* The share of the noise that the weight's numerator counts, for a denoiser of
 * self-influence kappa (docs/blend.md "Self-influence"). The best weight of d is
 * (S - C) / E|n - d|^2 with C = kappa S; the plain combiner counts all of S. A
 * numerator t times the best one keeps 2t - t^2 of the best blend's gain over n and
 * still beats n up to t = 2; t = 1.5 keeps 3/4 and tolerates kappa read too low by a
 * third of 1 - kappa. Where d is right the best weight is 1 and a numerator at the
 * expectation's edge lets half of the windows take noise back (measured with t = 1: the
 * nlm blend within 1.10x min at 75% of members), so the plain one stands while
 * 1.5 (1 - kappa) >= 1, i.e. for kappa <= 1/3. */
static double
numerator_share(const double *kappa, int k)
{
    return kappa ? fmin(1.0, 1.5 * (1.0 - kappa[k])) : 1.0;
}

int
mcp_blend_james_stein(const mcp_image *noisy, const mcp_image *denoised,
                      const mcp_image *var_of_mean, int window, const double *kappa,
                      mcp_image **out, mcp_image **rho)
{
    *out = NULL;
    if (rho) *rho = NULL;
    if (window < 3 || window % 2 == 0)
        return mcp_error("blend: james-stein: window must be odd and >= 3 (got %d)",
                         window);
    mcp__rgb n, d, v;
    mcp_image *r = NULL, *weight = NULL;
    sat_pair s = {0, 0, NULL, NULL};
    if (mcp__blend_rgb(noisy, "noisy", &n) || mcp__blend_rgb(denoised, "denoised", &d) ||
        mcp__blend_rgb(var_of_mean, "variance", &v) ||
        mcp__blend_same_size(noisy, denoised, var_of_mean, (const mcp_image *)NULL))
        return -1;
    int w = noisy->width, h = noisy->height, rad = window / 2;
    size_t cells;
    if (mcp_size_mul((size_t)w + 1, (size_t)h + 1, &cells))
        return mcp_error("blend: james-stein: image too large (%dx%d)", w, h);
    s.w = w;
    s.h = h;
    s.sum_v = mcp_malloc(cells * sizeof(double));
    s.sum_sq = s.sum_v ? mcp_malloc(cells * sizeof(double)) : NULL;
    if (!s.sum_sq || mcp__blend_rgb_new(w, h, "james-stein", &r) ||
        mcp__blend_rgb_new(w, h, "james-stein rho", &weight))
        goto fail;
    for (int k = 0; k < 3; k++) {
        double share = numerator_share(kappa, k);
        build_sats(&s, &n, &d, &v, k);
#pragma omp parallel for schedule(static)
        for (int y = 0; y < h; y++) {
            int y0 = y - rad < 0 ? 0 : y - rad, y1 = y + rad + 1 > h ? h : y + rad + 1;
            float *dst = mcp_image_px(r, 0, y), *wd = mcp_image_px(weight, 0, y);
            for (int x = 0; x < w; x++) {
                int x0 = x - rad < 0 ? 0 : x - rad,
                    x1 = x + rad + 1 > w ? w : x + rad + 1;
                double p = (double)(x1 - x0) * (y1 - y0);
                double sigma2 = share * box(s.sum_v, w, x0, y0, x1, y1) / p;
                double dist2 = box(s.sum_sq, w, x0, y0, x1, y1);
                /* dist2 = 0: n = d over the window, and any s gives d */
                double shrink =
                    dist2 > 0 ? fmax(0.0, 1.0 - (p - 2) * sigma2 / dist2) : 0.0;
                double nv = mcp__rgb_at(&n, x, y, k), dv = mcp__rgb_at(&d, x, y, k);
                dst[3 * x + k] = (float)(dv + shrink * (nv - dv));
                wd[3 * x + k] = (float)(1.0 - shrink);
            }
        }
    }
    free(s.sum_v);
    free(s.sum_sq);
    *out = r;
    if (rho)
        *rho = weight;
    else
        mcp_image_free(weight);
    return 0;
fail:
    free(s.sum_v);
    free(s.sum_sq);
    mcp_image_free(r);
    mcp_image_free(weight);
    return -1;
}

int
mcp_blend_james_stein_variance(const mcp_image *rho, const mcp_image *var_denoised,
                               const mcp_image *var_of_mean, mcp_image **out)
{
    *out = NULL;
    if (!rho || !var_denoised || !var_of_mean)
        return mcp_error("blend: james-stein variance needs rho, Var[d] and v");
    /* one denoised input: alpha = 1, and the second input's variance drops out */
    mcp_image *alpha = NULL;
    if (mcp_image_new(rho->width, rho->height, 1, NULL, &alpha)) return -1;
    size_t n = (size_t)rho->width * rho->height;
    for (size_t i = 0; i < n; i++)
        alpha->data[i] = 1.0f;
    int rc = mcp_postcorrection_variance(var_denoised, var_denoised, var_of_mean, alpha,
                                         rho, out);
    mcp_image_free(alpha);
    return rc ? mcp_error_prefix("blend: ") : 0;
}
