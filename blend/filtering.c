/* filtering.c: the estimates before curves and weights (docs/mathematics.md §3.2, §3.3:
 * Negative SURE; Denisova & Bocchi 2024 Sections 2.5-2.6).
 *
 * v and SURE are blurred with a Gaussian (window 11, sigma = min(sqrt(mean v), 1) x
 * 100; Firmino 2022's rule) or passed through the configured denoiser, and filtering
 * stops once mean(v) < mean(SURE). Negative SURE is zeroed while mean(v) >= mean(SURE)
 * and replaced by its magnitude after that.
 *
 * Departures, on purpose:
 *  - Our rule (§3.2) stops filtering for the Gaussian blur too; the authors' code
 *    (MCPTBlender main.cpp step 9) stops it only for OIDN filtering.
 *  - Once the rule has fired in a series it stays fired ("once", §3.2), through
 *    mcp_blend_state; the authors' code tests each iteration afresh.
 *  - The authors' code floors sigma at 1e-3 x 100 rather than capping it at 100; we
 *    follow §3.2 (min) and skip the blur when sigma is 0 (v all zero).
 *  - Negative values are fixed after filtering, as in the authors' code (the blur sees
 *    the signed SURE, whose negative part carries information about the estimate's
 *    noise); the paper does not say which comes first. */
#include "blend.h"
#include "internal.h"

#include <mcpost/filter.h>
#include <mcpost/tonemap.h>

#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
#include <emmintrin.h>
#endif

static const char *const RGB_NAMES[3] = {"R", "G", "B"};

/* ---- helpers shared in blend/ ---- */

int
mcp__blend_rgb(const mcp_image *img, const char *what, mcp__rgb *out)
{
    out->img = img;
    if (mcp_rgb_channels(img, out->c)) return mcp_error_prefix("blend: %s: ", what);
    return 0;
}

int
mcp__blend_same_size(const mcp_image *first, ...)
{
    va_list ap;
    va_start(ap, first);
    const mcp_image *img;
    int ok = 1;
    while (ok && (img = va_arg(ap, const mcp_image *)) != NULL)
        ok = mcp_image_same_size(img, first);
    va_end(ap);
    return ok ? 0 : mcp_error_prefix("blend: ");
}

int
mcp__blend_rgb_new(int width, int height, const char *source, mcp_image **out)
{
    if (mcp_image_new(width, height, 3, RGB_NAMES, out)) return -1;
    if (mcp_image_set_source(*out, source)) {
        mcp_image_free(*out);
        *out = NULL;
        return -1;
    }
    return 0;
}

int
mcp__blend_mean(const mcp__rgb *in, double *mean)
{
    const mcp_image *img = in->img;
    int w = img->width, h = img->height;
    int flat = img->pixel_stride == 3 && in->c[0] == 0 && in->c[1] == 1 && in->c[2] == 2;
    double *rows = mcp_malloc((size_t)h * sizeof *rows);
    if (!rows) return -1;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        /* four partial sums break the dependency chain; their order is fixed */
        double s[4] = {0, 0, 0, 0};
        if (flat) {
            const float *p = mcp_image_px(img, 0, y);
            int n = 3 * w, i = 0;
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
            /* the same four sums, two per register */
            __m128d s01 = _mm_setzero_pd(), s23 = _mm_setzero_pd();
            for (; i + 4 <= n; i += 4) {
                __m128 v = _mm_loadu_ps(p + i);
                s01 = _mm_add_pd(s01, _mm_cvtps_pd(v));
                s23 = _mm_add_pd(s23, _mm_cvtps_pd(_mm_movehl_ps(v, v)));
            }
            _mm_storeu_pd(s, s01), _mm_storeu_pd(s + 2, s23);
#endif
            for (; i + 4 <= n; i += 4)
                for (int j = 0; j < 4; j++)
                    s[j] += p[i + j];
            for (; i < n; i++)
                s[0] += p[i];
        } else {
            for (int x = 0; x < w; x++)
                for (int k = 0; k < 3; k++)
                    s[k] += mcp__rgb_at(in, x, y, k);
        }
        rows[y] = (s[0] + s[1]) + (s[2] + s[3]);
    }
    double sum = 0;
    for (int y = 0; y < h; y++)
        sum += rows[y];
    free(rows);
    *mean = sum / ((double)w * h * 3);
    return 0;
}

/* A packed R, G, B copy of the channels that rgb names. */
static int
rgb_copy(const mcp__rgb *rgb, mcp_image **out)
{
    if (mcp_image_copy_channels(rgb->img, rgb->c, 3, out)) return -1;
    for (int k = 0; k < 3; k++)
        if (mcp_image_set_channel_name(*out, k, RGB_NAMES[k])) {
            mcp_image_free(*out);
            *out = NULL;
            return -1;
        }
    return 0;
}

/* ---- public ---- */

int
mcp_blend_filter_image(const mcp_image *img, double mean_var,
                       const mcp_blend_options *opt, const mcp_denoiser *den,
                       mcp_image **out)
{
    *out = NULL;
    mcp_blend_options defaults = mcp_blend_defaults();
    const mcp_blend_options *o = opt ? opt : &defaults;
    mcp__rgb rgb;
    if (mcp_blend_options_check(o) || mcp__blend_rgb(img, "filter", &rgb)) return -1;
    if (o->filter == MCP_BLEND_FILTER_DENOISER && !den)
        return mcp_error("blend: filter 'denoiser' needs a denoiser");
    double sigma = (mean_var > 0 ? fmin(sqrt(mean_var), 1.0) : 0) * o->filter_sigma_scale;
    if (!isfinite(sigma))
        return mcp_error("blend: filter: mean variance must be finite (got %g)",
                         mean_var);
    int identity = o->filter == MCP_BLEND_FILTER_NONE ||
                   (o->filter == MCP_BLEND_FILTER_GAUSS && sigma == 0);
    /* a packed R, G, B image is filtered as it is; anything else is gathered first */
    int direct = img->channels == 3 && mcp_image_is_packed(img) && rgb.c[0] == 0 &&
                 rgb.c[1] == 1 && rgb.c[2] == 2;
    mcp_image *packed = NULL;
    if ((identity || !direct) && rgb_copy(&rgb, &packed)) return -1;
    if (identity) {
        *out = packed; /* none, or a Gaussian of sigma 0: the identity */
        return 0;
    }
    const mcp_image *src = direct ? img : packed;
    int rc;
    if (o->filter == MCP_BLEND_FILTER_GAUSS) {
        rc = mcp_gaussian_blur(src, o->filter_window, sigma, out);
    } else {
        mcp_denoise_input in;
        memset(&in, 0, sizeof in);
        in.color = src;
        rc = den->apply(den, &in, out);
        if (rc) mcp_error_prefix("blend: filtering with denoiser '%s': ", den->name);
    }
    mcp_image_free(packed);
    return rc ? -1 : 0;
}

int
mcp_blend_fix_sure_inplace(mcp_image *sure, int magnitude)
{
    mcp__rgb rgb;
    if (mcp__blend_rgb(sure, "SURE", &rgb)) return -1;
    int w = sure->width, h = sure->height;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float *p = mcp_image_px(sure, x, y);
            for (int k = 0; k < 3; k++) {
                float s = p[rgb.c[k]];
                if (s < 0) p[rgb.c[k]] = magnitude ? -s : 0.0f;
            }
        }
    return 0;
}

void
mcp_blend_estimates_free(mcp_blend_estimates *e)
{
    if (!e) return;
    mcp_image_free(e->var_of_mean);
    mcp_image_free(e->sure);
    e->var_of_mean = e->sure = NULL;
}

int
mcp_blend_prepare(const mcp_image *var_of_mean, const mcp_image *sure,
                  const mcp_blend_options *opt, const mcp_denoiser *den,
                  mcp_blend_state *state, mcp_blend_estimates *out)
{
    return mcp__blend_prepare(var_of_mean, sure, opt, den, state, 1, out);
}

int
mcp__blend_prepare(const mcp_image *var_of_mean, const mcp_image *sure,
                   const mcp_blend_options *opt, const mcp_denoiser *den,
                   mcp_blend_state *state, int fix_sure, mcp_blend_estimates *out)
{
    memset(out, 0, sizeof *out);
    mcp_blend_options defaults = mcp_blend_defaults();
    const mcp_blend_options *o = opt ? opt : &defaults;
    mcp__rgb v_rgb, s_rgb;
    if (mcp_blend_options_check(o) || mcp__blend_rgb(var_of_mean, "variance", &v_rgb) ||
        mcp__blend_rgb(sure, "SURE", &s_rgb) ||
        mcp__blend_same_size(var_of_mean, sure, (const mcp_image *)NULL))
        return -1;
    if (mcp__blend_mean(&v_rgb, &out->mean_var) ||
        mcp__blend_mean(&s_rgb, &out->mean_sure))
        return -1;
    if (!isfinite(out->mean_var) || !isfinite(out->mean_sure))
        return mcp_error("blend: mean variance (%g) and mean SURE (%g) must be finite",
                         out->mean_var, out->mean_sure);
    /* The one rule behind both switches: the noisy image has become better than the
     * denoised one on average. An all-zero v (one sample per pixel: no variance
     * estimate yet) cannot tell, and must not end filtering for the whole series (our
     * addition, stated in docs/mathematics.md §3.2). */
    int crossed = out->mean_var > 0 && out->mean_var < out->mean_sure;
    if (state && crossed) {
        state->filtering_stopped = 1;
        state->magnitude = 1;
    }
    int stopped = state ? state->filtering_stopped : crossed;
    out->filtered = o->filter != MCP_BLEND_FILTER_NONE && !(o->stop_filtering && stopped);
    switch (o->negative_sure) {
    case MCP_NEG_SURE_ZERO:
        out->magnitude = 0;
        break;
    case MCP_NEG_SURE_MAGNITUDE:
        out->magnitude = 1;
        break;
    default:
        out->magnitude = state ? state->magnitude : crossed;
        break;
    }
    mcp_blend_options unfiltered = *o;
    if (!out->filtered) unfiltered.filter = MCP_BLEND_FILTER_NONE;
    if (mcp_blend_filter_image(var_of_mean, out->mean_var, &unfiltered, den,
                               &out->var_of_mean) ||
        mcp_blend_filter_image(sure, out->mean_var, &unfiltered, den, &out->sure) ||
        (fix_sure && mcp_blend_fix_sure_inplace(out->sure, out->magnitude))) {
        mcp_blend_estimates_free(out);
        return -1;
    }
    /* a filtered variance is still a variance: the denoiser may have made it negative */
    if (out->filtered && o->filter == MCP_BLEND_FILTER_DENOISER &&
        mcp_blend_fix_sure_inplace(out->var_of_mean, 0)) {
        mcp_blend_estimates_free(out);
        return -1;
    }
    return 0;
}
