/* weights.c: the weight of the denoised image and the blends (SPEC "blend": Weight,
 * Blend, Easy blending, Ideal blending; Denisova & Bocchi 2024 Eqs. 2, 4, 8, 14).
 *
 * r = (I n + W d) / (I + W), computed in double. W is a sample count: 0 keeps the
 * noisy value, inf takes the denoised one. All-black values (no curve: v = 0) get
 * W = 0 unless the denoiser keeps zeros (paper Section 2.4). */
#include "blend.h"
#include "internal.h"

#include <math.h>
#include <string.h>

static double
mix(double spp, double n, double d, double w)
{
    if (isinf(w)) return d;
    if (!(w > 0)) return n; /* also NaN */
    return (spp * n + w * d) / (spp + w);
}

int
mcp_blend_weights(const mcp_image *curves, const mcp_image *sure,
                  const mcp_blend_options *opt, mcp_image **out)
{
    *out = NULL;
    mcp_blend_options defaults = mcp_blend_defaults();
    const mcp_blend_options *o = opt ? opt : &defaults;
    mcp__rgb s;
    int ab[6];
    static const char *const ab_names[6] = {"a.R", "a.G", "a.B", "b.R", "b.G", "b.B"};
    if (mcp_blend_options_check(o) || mcp__blend_rgb(sure, "SURE", &s) ||
        mcp_image_channels(curves, ab_names, 6, ab) ||
        mcp__blend_same_size(curves, sure, (const mcp_image *)NULL))
        return -1;
    int w = sure->width, h = sure->height;
    if (mcp__blend_rgb_new(w, h, "blend weights", out)) return -1;
    double cap = mcp__max_weight(o);
    double black = o->denoiser_keeps_zeros ? cap : 0.0;
    long n_negative = 0;
#pragma omp parallel for schedule(static) reduction(+ : n_negative)
    for (int y = 0; y < h; y++) {
        float *dst = mcp_image_px(*out, 0, y);
        for (int x = 0; x < w; x++) {
            const float *c = mcp_image_px(curves, x, y);
            for (int k = 0; k < 3; k++) {
                double sv = mcp__rgb_at(&s, x, y, k);
                if (sv < 0) n_negative++;
                double wt = mcp_curve_weight(o->curve, o->powerlaw_offset, c[ab[k]],
                                             c[ab[3 + k]], sv, cap);
                dst[3 * x + k] = (float)(isnan(wt) ? black : wt);
            }
        }
    }
    if (n_negative) {
        mcp_image_free(*out);
        *out = NULL;
        return mcp_error("blend: weights: SURE has %ld negative values (fix them first: "
                         "mcp_blend_fix_sure_inplace)",
                         n_negative);
    }
    return 0;
}

int
mcp_blend_mix(const mcp_image *noisy, double spp, const mcp_image *denoised,
              const mcp_image *weights, mcp_image **out)
{
    *out = NULL;
    mcp__rgb n, d, wt;
    if (!(spp > 0) || !isfinite(spp))
        return mcp_error("blend: spp must be finite and > 0 (got %g)", spp);
    if (mcp__blend_rgb(noisy, "noisy", &n) || mcp__blend_rgb(denoised, "denoised", &d) ||
        mcp__blend_rgb(weights, "weights", &wt) ||
        mcp__blend_same_size(noisy, denoised, weights, (const mcp_image *)NULL) ||
        mcp__blend_rgb_new(noisy->width, noisy->height, "blend", out))
        return -1;
    int w = noisy->width, h = noisy->height;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        float *dst = mcp_image_px(*out, 0, y);
        for (int x = 0; x < w; x++)
            for (int k = 0; k < 3; k++)
                dst[3 * x + k] =
                    (float)mix(spp, mcp__rgb_at(&n, x, y, k), mcp__rgb_at(&d, x, y, k),
                               mcp__rgb_at(&wt, x, y, k));
    }
    return 0;
}

int
mcp_blend_easy(const mcp_image *noisy, const mcp_image *denoised,
               const mcp_image *var_of_mean, const mcp_image *sure, mcp_image **out)
{
    *out = NULL;
    mcp__rgb n, d, v, s;
    if (mcp__blend_rgb(noisy, "noisy", &n) || mcp__blend_rgb(denoised, "denoised", &d) ||
        mcp__blend_rgb(var_of_mean, "variance", &v) || mcp__blend_rgb(sure, "SURE", &s) ||
        mcp__blend_same_size(noisy, denoised, var_of_mean, sure,
                             (const mcp_image *)NULL) ||
        mcp__blend_rgb_new(noisy->width, noisy->height, "easy blend", out))
        return -1;
    int w = noisy->width, h = noisy->height;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        float *dst = mcp_image_px(*out, 0, y);
        for (int x = 0; x < w; x++)
            for (int k = 0; k < 3; k++) {
                /* Eq. 8 with the estimates: RMSE_d ~ sqrt(SURE), RMSE_n ~ sqrt(v) */
                int noisy_better = mcp__rgb_at(&s, x, y, k) > mcp__rgb_at(&v, x, y, k);
                dst[3 * x + k] =
                    noisy_better ? mcp__rgb_at(&n, x, y, k) : mcp__rgb_at(&d, x, y, k);
            }
    }
    return 0;
}

int
mcp_blend_ideal(const mcp_image *noisy, double spp, const mcp_image *denoised,
                const mcp_image *reference, mcp_image **out, mcp_image **weights)
{
    *out = NULL;
    if (weights) *weights = NULL;
    mcp__rgb n, d, r;
    mcp_image *wmap = NULL;
    if (!(spp > 0) || !isfinite(spp))
        return mcp_error("blend: spp must be finite and > 0 (got %g)", spp);
    if (mcp__blend_rgb(noisy, "noisy", &n) || mcp__blend_rgb(denoised, "denoised", &d) ||
        mcp__blend_rgb(reference, "reference", &r) ||
        mcp__blend_same_size(noisy, denoised, reference, (const mcp_image *)NULL) ||
        mcp__blend_rgb_new(noisy->width, noisy->height, "ideal blend", out) ||
        mcp__blend_rgb_new(noisy->width, noisy->height, "ideal weights", &wmap)) {
        mcp_image_free(*out);
        *out = NULL;
        return -1;
    }
    int w = noisy->width, h = noisy->height;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        float *dst = mcp_image_px(*out, 0, y), *wd = mcp_image_px(wmap, 0, y);
        for (int x = 0; x < w; x++)
            for (int k = 0; k < 3; k++) {
                double nv = mcp__rgb_at(&n, x, y, k), dv = mcp__rgb_at(&d, x, y, k);
                double rv = mcp__rgb_at(&r, x, y, k);
                /* Eq. 4, W = I (R - n) / (d - R). SPEC clamps it at 0 where the paper
                 * does not: where R is not between n and d we keep n, even where R lies
                 * beyond d and W = inf (d) would be closer. d = R needs W = inf. */
                double wt = dv == rv ? INFINITY : fmax(0.0, spp * (rv - nv) / (dv - rv));
                wd[3 * x + k] = (float)wt;
                dst[3 * x + k] = (float)mix(spp, nv, dv, wt);
            }
    }
    if (weights)
        *weights = wmap;
    else
        mcp_image_free(wmap);
    return 0;
}

/* ---- one iteration ---- */

void
mcp_blend_result_free(mcp_blend_result *r)
{
    if (!r) return;
    mcp_image_free(r->blend);
    mcp_image_free(r->weights);
    r->blend = r->weights = NULL;
    mcp_blend_estimates_free(&r->est);
}

/* One row of the default on-the-fly blend, in float (the images are float):
 * W = K sqrt(v / SURE) capped, and r = n + rho (d - n) with rho = W / (K + W)
 * = 1 / (1 + K / W), which also gives d at W = inf and n at W = 0. */
static void
sqrt_form_row(const mcp__otf *otf, double black, const float *vr, float *sr,
              int magnitude, const mcp_image *noisy, const int *nc, const mcp_image *den,
              const int *dc, int y, float *wd, float *rd)
{
    const float spp = (float)otf->spp, cap = (float)otf->cap, zero_w = (float)black;
    for (int x = 0; x < noisy->width; x++) {
        const float *np = mcp_image_px(noisy, x, y), *dp = mcp_image_px(den, x, y);
        for (int k = 0; k < 3; k++) {
            float v = vr[3 * x + k], s = sr[3 * x + k];
            if (s < 0) /* the negative-SURE rule, fused here to save a pass */
                sr[3 * x + k] = s = magnitude ? -s : 0.0f;
            float wt = s > 0 ? spp * sqrtf(v / s) : INFINITY;
            wt = wt < cap ? wt : cap;
            if (!(v > 0) || !(v < INFINITY))
                wt = zero_w; /* no curve: an all-black value */
            float rho = 1.0f / (1.0f + spp / wt), nv = np[nc[k]], dv = dp[dc[k]];
            wd[3 * x + k] = wt;
            rd[3 * x + k] = rho == 1.0f ? dv : nv + rho * (dv - nv);
        }
    }
}

int
mcp__blend_on_the_fly(const mcp_blend_input *in, const mcp_blend_options *o,
                      mcp_blend_estimates *e, mcp_image **weights, mcp_image **blend)
{
    mcp__rgb n, d, v, s;
    mcp__otf otf;
    if (!(in->spp > 0) || !isfinite(in->spp))
        return mcp_error("blend: spp must be finite and > 0 (got %g)", in->spp);
    if (mcp__blend_rgb(in->noisy, "noisy", &n) ||
        mcp__blend_rgb(in->denoised, "denoised", &d) ||
        mcp__blend_rgb(e->var_of_mean, "variance", &v) ||
        mcp__blend_rgb(e->sure, "SURE", &s) ||
        mcp__blend_same_size(in->noisy, in->denoised, e->var_of_mean,
                             (const mcp_image *)NULL) ||
        mcp__otf_init(&otf, o, in->spp, mcp__max_weight(o)) ||
        mcp__blend_rgb_new(in->noisy->width, in->noisy->height, "blend weights",
                           weights) ||
        mcp__blend_rgb_new(in->noisy->width, in->noisy->height, "blend", blend))
        return -1;
    for (int k = 0; k < 3; k++)
        if (v.c[k] != k || s.c[k] != k || !mcp_image_is_packed(e->var_of_mean) ||
            !mcp_image_is_packed(e->sure) || e->var_of_mean->channels != 3 ||
            e->sure->channels != 3) {
            mcp_image_free(*weights);
            mcp_image_free(*blend);
            *weights = *blend = NULL;
            return mcp_error(
                "blend: the prepared estimates must be packed R, G, B images");
        }
    int w = in->noisy->width, h = in->noisy->height;
    double black = o->denoiser_keeps_zeros ? otf.cap : 0.0, spp = in->spp;
    /* the estimates are packed R, G, B (mcp_blend_prepare made them); the inputs are
     * read through their channel indices */
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        float *wd = mcp_image_px(*weights, 0, y), *rd = mcp_image_px(*blend, 0, y);
        const float *vr = mcp_image_px(e->var_of_mean, 0, y);
        float *sr = mcp_image_px(e->sure, 0, y);
        if (otf.sqrt_form)
            sqrt_form_row(&otf, black, vr, sr, e->magnitude, in->noisy, n.c, in->denoised,
                          d.c, y, wd, rd);
        else
            for (int x = 0; x < w; x++) {
                const float *np = mcp_image_px(in->noisy, x, y);
                const float *dp = mcp_image_px(in->denoised, x, y);
                for (int k = 0; k < 3; k++) {
                    float sv = sr[3 * x + k];
                    if (sv < 0) sr[3 * x + k] = sv = e->magnitude ? -sv : 0.0f;
                    double wt = mcp__otf_weight_general(&otf, vr[3 * x + k], sv);
                    if (isnan(wt)) wt = black;
                    wd[3 * x + k] = (float)wt;
                    rd[3 * x + k] = (float)mix(spp, np[n.c[k]], dp[d.c[k]], wt);
                }
            }
    }
    return 0;
}

int
mcp_blend_step(const mcp_blend_input *in, const mcp_blend_options *opt,
               const mcp_denoiser *den, mcp_blend_state *state, mcp_blend_result *out)
{
    memset(out, 0, sizeof *out);
    mcp_blend_options o = opt ? *opt : mcp_blend_defaults();
    if (!in->noisy || !in->var_of_mean || !in->denoised || !in->sure)
        return mcp_error("blend: noisy, variance, denoised and SURE images are required");
    /* on the fly, the fused pass applies the negative-SURE rule */
    if (mcp__blend_prepare(in->var_of_mean, in->sure, &o, den, state, in->curves != NULL,
                           &out->est))
        return -1;
    int rc;
    if (in->curves) {
        rc = mcp_blend_weights(in->curves, out->est.sure, &o, &out->weights) ||
             mcp_blend_mix(in->noisy, in->spp, in->denoised, out->weights, &out->blend);
    } else {
        /* one point: the on-the-fly curve is the only one possible */
        o.fit = MCP_CURVE_FIT_ON_THE_FLY;
        rc = mcp__blend_on_the_fly(in, &o, &out->est, &out->weights, &out->blend);
    }
    if (rc) {
        mcp_blend_result_free(out);
        return -1;
    }
    return 0;
}
