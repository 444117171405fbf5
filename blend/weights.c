/* weights.c: the weight of the denoised image and the blends (docs/mathematics.md
 * §3.4-§3.6: Weight, Blend, Easy blending, Ideal blending; Denisova & Bocchi 2024 Eqs. 2,
 * 4, 8, 14).
 *
 * r = (I n + W d) / (I + W), computed in double. W is a sample count: 0 keeps the
 * noisy value, inf takes the denoised one. All-black values (no curve: v = 0) get
 * W = 0 unless the denoiser keeps zeros (paper Section 2.4). */
#include "blend.h"
#include "internal.h"

#include <math.h>
#include <string.h>
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
#include <emmintrin.h>
#endif

/* The channels of a curve image (blend.h "curves"). */
static const char *const curve_channels[6] = {"a.R", "a.G", "a.B", "b.R", "b.G", "b.B"};

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
    if (mcp_blend_options_check(o) || mcp__blend_rgb(sure, "SURE", &s) ||
        mcp_image_channels(curves, curve_channels, 6, ab) ||
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
                /* Eq. 4, W = I (R - n) / (d - R). We clamp it at 0 (§3.6) where the paper
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

/* One value of the default on-the-fly blend, in float (the images are float):
 * W = K sqrt(v / SURE) capped, and r = n + rho (d - n) with rho = W / (K + W)
 * = 1 / (1 + K / W), which also gives d at W = inf and n at W = 0. *s gets the
 * negative-SURE rule (fused here to save a pass). */
static inline void
sqrt_form_value(float spp, float cap, float zero_w, int magnitude, float v, float *s,
                float nv, float dv, float *wd, float *rd)
{
    float sv = *s;
    if (sv < 0) *s = sv = magnitude ? -sv : 0.0f;
    float wt = sv > 0 ? spp * sqrtf(v / sv) : INFINITY;
    wt = wt < cap ? wt : cap;
    if (!(v > 0) || !(v < INFINITY)) wt = zero_w; /* no curve: an all-black value */
    float rho = 1.0f / (1.0f + spp / wt);
    *wd = wt;
    *rd = rho == 1.0f ? dv : nv + rho * (dv - nv);
}

/* A row of sqrt_form_value. Where the noisy and denoised rows are packed R, G, B (as
 * the estimates are), four values at a time in SSE with the same float operations
 * (sqrtps and divps round as sqrtf and / do; minps and the masks keep the scalar
 * code's NaN cases), so the figures do not depend on the path. */
static void
sqrt_form_row(const mcp__otf *otf, double black, const float *vr, float *sr,
              int magnitude, const mcp_image *noisy, const int *nc, const mcp_image *den,
              const int *dc, int y, float *wd, float *rd)
{
    const float spp = (float)otf->spp, cap = (float)otf->cap, zero_w = (float)black;
    int w = noisy->width, i = 0, n3 = 3 * w;
    int packed = noisy->pixel_stride == 3 && den->pixel_stride == 3 && nc[0] == 0 &&
                 nc[1] == 1 && nc[2] == 2 && dc[0] == 0 && dc[1] == 1 && dc[2] == 2;
    if (packed) {
        const float *np = mcp_image_px(noisy, 0, y), *dp = mcp_image_px(den, 0, y);
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
        const __m128 k = _mm_set1_ps(spp), kcap = _mm_set1_ps(cap),
                     kzero = _mm_set1_ps(zero_w), one = _mm_set1_ps(1.0f),
                     inf = _mm_set1_ps(INFINITY), zero = _mm_setzero_ps();
        for (; i + 4 <= n3; i += 4) {
            __m128 v = _mm_loadu_ps(vr + i), sv = _mm_loadu_ps(sr + i);
            __m128 neg = _mm_cmplt_ps(sv, zero);
            if (_mm_movemask_ps(neg)) {
                __m128 fixed = magnitude ? _mm_sub_ps(zero, sv) : zero;
                sv = _mm_or_ps(_mm_and_ps(neg, fixed), _mm_andnot_ps(neg, sv));
                _mm_storeu_ps(sr + i, sv);
            }
            __m128 pos = _mm_cmpgt_ps(sv, zero);
            __m128 wt = _mm_mul_ps(k, _mm_sqrt_ps(_mm_div_ps(v, sv)));
            wt = _mm_or_ps(_mm_and_ps(pos, wt), _mm_andnot_ps(pos, inf));
            wt = _mm_min_ps(wt, kcap); /* wt < cap ? wt : cap, NaN -> cap */
            __m128 curve = _mm_and_ps(_mm_cmpgt_ps(v, zero), _mm_cmplt_ps(v, inf));
            wt = _mm_or_ps(_mm_and_ps(curve, wt), _mm_andnot_ps(curve, kzero));
            __m128 rho = _mm_div_ps(one, _mm_add_ps(one, _mm_div_ps(k, wt)));
            __m128 nv = _mm_loadu_ps(np + i), dv = _mm_loadu_ps(dp + i);
            __m128 mixed = _mm_add_ps(nv, _mm_mul_ps(rho, _mm_sub_ps(dv, nv)));
            __m128 all_d = _mm_cmpeq_ps(rho, one);
            _mm_storeu_ps(wd + i, wt);
            _mm_storeu_ps(rd + i,
                          _mm_or_ps(_mm_and_ps(all_d, dv), _mm_andnot_ps(all_d, mixed)));
        }
#endif
        for (; i < n3; i++)
            sqrt_form_value(spp, cap, zero_w, magnitude, vr[i], sr + i, np[i], dp[i],
                            wd + i, rd + i);
        return;
    }
    for (int x = 0; x < w; x++) {
        const float *np = mcp_image_px(noisy, x, y), *dp = mcp_image_px(den, x, y);
        for (int k = 0; k < 3; k++)
            sqrt_form_value(spp, cap, zero_w, magnitude, vr[3 * x + k], sr + 3 * x + k,
                            np[nc[k]], dp[dc[k]], wd + 3 * x + k, rd + 3 * x + k);
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
    /* what every weighting needs of the inputs, checked before any work (the
       James-Stein weights use no curve, but a curve image given must be one) */
    int ab[6];
    if (!(in->spp > 0) || !isfinite(in->spp))
        return mcp_error("blend: spp must be finite and > 0 (got %g)", in->spp);
    if (in->curves && mcp_image_channels(in->curves, curve_channels, 6, ab)) return -1;
    /* on the fly, the fused pass applies the negative-SURE rule; the James-Stein
       weights need no curve, so it is applied here for them */
    int james_stein = o.weights == MCP_BLEND_WEIGHTS_JAMES_STEIN;
    if (mcp__blend_prepare(in->var_of_mean, in->sure, &o, den, state,
                           in->curves != NULL || james_stein, &out->est))
        return -1;
    int rc;
    if (james_stein) {
        /* the combiner's blend and its W (docs/blend.md "Which weights") */
        mcp_image *rho = NULL;
        rc = mcp_blend_james_stein(in->noisy, in->denoised, in->var_of_mean, o.js_window,
                                   in->kappa, &out->blend, &rho) ||
             mcp__blend_weights_from_rho(rho, in->spp, &out->weights);
        mcp_image_free(rho);
    } else if (in->curves) {
        rc = mcp_blend_weights(in->curves, out->est.sure, &o, &out->weights) ||
             mcp_blend_mix(in->noisy, in->spp, in->denoised, out->weights, &out->blend);
    } else {
        /* one point: the on-the-fly curve is the only one possible */
        o.fit = MCP_CURVE_FIT_ON_THE_FLY;
        rc = mcp__blend_on_the_fly(in, &o, &out->est, &out->weights, &out->blend);
    }
    if (!rc && !james_stein && o.safeguard) {
        rc = mcp__blend_safeguard_step(in->noisy, in->spp, in->denoised, in->var_of_mean,
                                       o.js_window, in->kappa, out->weights, out->blend,
                                       &out->safeguard_pulled);
    }
    if (rc) {
        mcp_blend_result_free(out);
        return -1;
    }
    return 0;
}
