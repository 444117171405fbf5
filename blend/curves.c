/* curves.c: convergence curves of the variance of the mean, per pixel and channel, and
 * the weight they give a denoised value (docs/mathematics.md §3.1; Denisova & Bocchi 2024
 * Eqs. 7, 11, 14, Sections 2.4-2.5).
 *
 * On the fly, mcpost departs from the paper (docs/mathematics.md §3.1): it takes the
 * newest point and the Eq. 11 point; the paper (Section 2.5: "we accept only the last
 * variance value ... [then] we need to calculate the second point") and the authors' code
 * take the last two points that the retrospective selection keeps, and Eq. 11 only where
 * one survives. Ours is the default (MCP_CURVE_FIT_ON_THE_FLY), the paper's an option
 * (MCP_CURVE_FIT_LAST_TWO).
 *
 * Log curve: log v = a log I + b. On the fly the second point comes from Eq. 11,
 * (N - K, v_K / (N/K - 1)^2); since N/K - 1 = (N - K)/K, that line always has slope
 * a = -2 and b = ln v_K + 2 ln K, so W = K sqrt(v_K / SURE). We still fit the two
 * points rather than use the closed form, so both fits share one code path (the tests
 * check the closed form).
 *
 * Power law (the authors' code, MCPTBlender curvepredictor.cpp, offered as an
 * option): ln v + c = a I^b, c = 100, i.e. ln(ln v + c) = ln a + b ln I. Departures
 * from that code, on purpose: we fit ln(ln v + c) against ln I by ordinary least
 * squares, where the code regresses ln(ln v + c)/ln I on 1/ln I (the same line through
 * two points, but a weighted fit through more, and undefined at I = 1); W stays a real
 * number (the code truncates it to an int) and a zero SURE gets the cap (the code's
 * "minimum weight" from a second curve with N = 1e20 is not in the paper or
 * docs/mathematics.md). */
#include "blend.h"
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define N_CURVE_CHANNELS 6

static const char *const curve_channel_names[N_CURVE_CHANNELS] = {"a.R", "a.G", "a.B",
                                                                  "b.R", "b.G", "b.B"};

/* The y coordinate of a point: ln v (log) or ln(ln v + c) (powerlaw); NaN when the
 * point cannot be used. */
static double
curve_y(mcp_curve_model model, double c, double v)
{
    if (!(v > 0) || !isfinite(v)) return NAN;
    if (model == MCP_CURVE_LOG) return log(v);
    double t = log(v) + c;
    return t > 0 ? log(t) : NAN;
}

int
mcp_curve_far_point(double spp, double var_of_mean, double far_spp, double *far_spp_out,
                    double *far_var_out)
{
    if (!(spp > 0) || !(far_spp > spp) || !isfinite(far_spp)) return -1;
    double ratio = far_spp / spp - 1; /* (N - K) / K */
    *far_spp_out = far_spp - spp;
    *far_var_out = var_of_mean / (ratio * ratio);
    return 0;
}

int
mcp_curve_fit_points(mcp_curve_model model, double powerlaw_offset, const double *spp,
                     const double *var_of_mean, int n, double *a, double *b)
{
    /* Two passes (means, then centred sums) keep the fit accurate when ln I is large
     * next to its spread. */
    double sx = 0, sy = 0;
    int m = 0;
    for (int i = 0; i < n; i++) {
        double y = curve_y(model, powerlaw_offset, var_of_mean[i]);
        if (isnan(y) || !(spp[i] > 0)) continue;
        sx += log(spp[i]);
        sy += y;
        m++;
    }
    if (m < 2) return 0;
    double mx = sx / m, my = sy / m, sxx = 0, sxy = 0;
    for (int i = 0; i < n; i++) {
        double y = curve_y(model, powerlaw_offset, var_of_mean[i]);
        if (isnan(y) || !(spp[i] > 0)) continue;
        double dx = log(spp[i]) - mx;
        sxx += dx * dx;
        sxy += dx * (y - my);
    }
    if (!(sxx > 0)) return 0; /* every point at one I */
    double slope = sxy / sxx, intercept = my - slope * mx;
    if (model == MCP_CURVE_LOG) {
        *a = slope;
        *b = intercept;
    } else {
        *a = exp(intercept);
        *b = slope;
    }
    return m;
}

int
mcp_curve_select_points(const double *var_of_mean, int n, unsigned char *keep)
{
    /* docs/mathematics.md §3.1 (first written as "walking back from the newest point
     * keeping only points larger than the one after them"). We compare with the last
     * point kept (not the raw neighbour), so the kept points always fall strictly with I
     * and their fitted slope is negative; a point that is not larger is skipped and the
     * walk goes on (the authors' code stops at the first such point instead). */
    int kept = 0;
    double last = 0;
    for (int i = n - 1; i >= 0; i--) {
        double v = var_of_mean[i];
        keep[i] = 0;
        if (!(v > 0) || !isfinite(v)) continue;
        if (kept == 0 || v > last) {
            keep[i] = 1;
            last = v;
            kept++;
        }
    }
    return kept;
}

double
mcp_curve_weight(mcp_curve_model model, double powerlaw_offset, double a, double b,
                 double sure, double max_weight)
{
    if (isnan(a) || isnan(b)) return NAN;
    double w;
    if (model == MCP_CURVE_LOG) {
        if (!(a < 0)) return NAN; /* a curve that does not fall gives no weight */
        /* log W = (log SURE - b) / a (Eq. 14); SURE = 0: a perfect d, W = inf */
        w = sure > 0 ? exp((log(sure) - b) / a) : INFINITY;
    } else {
        if (!(a > 0) || !(b < 0)) return NAN;
        double t = sure > 0 ? log(sure) + powerlaw_offset : 0;
        w = t > 0 ? pow(t / a, 1.0 / b) : INFINITY;
    }
    return w < max_weight ? w : max_weight;
}

/* ---- on the fly, per image ---- */

double
mcp__max_weight(const mcp_blend_options *o)
{
    if (o->max_weight > 0) return o->max_weight;
    return o->curve == MCP_CURVE_POWERLAW ? 65536.0 : INFINITY;
}

int
mcp__otf_init(mcp__otf *t, const mcp_blend_options *o, double spp, double cap)
{
    double far_spp, far_var;
    if (mcp_curve_far_point(spp, 1, o->far_spp, &far_spp, &far_var))
        return mcp_error("blend: far_spp (%g) must be larger than the newest spp (%g)",
                         o->far_spp, spp);
    memset(t, 0, sizeof *t);
    t->model = o->curve;
    t->c = o->powerlaw_offset;
    t->spp = spp;
    t->log_spp = log(spp);
    t->log_ratio = log(o->far_spp / spp - 1);
    t->dx = log(far_spp) - t->log_spp;
    if (t->dx == 0)
        return mcp_error(
            "blend: far_spp (%g) is twice the spp (%g): the two points of an "
            "on-the-fly curve coincide",
            o->far_spp, spp);
    /* ln v2 - ln v = -2 ln(N/K - 1) over ln(N - K) - ln K = ln(N/K - 1): -2 */
    t->slope = -2 * t->log_ratio / t->dx;
    t->cap = cap;
    t->sqrt_form = t->model == MCP_CURVE_LOG && fabs(t->slope + 2) < 1e-9;
    return 0;
}

int
mcp__otf_curve(const mcp__otf *t, double v, double *a, double *b)
{
    if (!(v > 0) || !isfinite(v)) return 0;
    double lv = log(v);
    if (t->model == MCP_CURVE_LOG) {
        *a = t->slope;
        *b = lv - t->slope * t->log_spp;
        return 1;
    }
    /* the same two points in (ln I, ln(ln v + c)); each must have ln v + c > 0 */
    double u1 = lv + t->c, u2 = lv - 2 * t->log_ratio + t->c;
    if (!(u1 > 0) || !(u2 > 0)) return 0;
    double y1 = log(u1), slope = (log(u2) - y1) / t->dx;
    *a = exp(y1 - slope * t->log_spp);
    *b = slope;
    return 1;
}

double
mcp__otf_weight_general(const mcp__otf *t, double v, double sure)
{
    double a, b;
    if (!mcp__otf_curve(t, v, &a, &b)) return NAN;
    return mcp_curve_weight(t->model, t->c, a, b, sure, t->cap);
}

/* ---- images ---- */

static int
check_inputs(const mcp_image *const *var, const double *spp, int n, mcp__rgb *rgb)
{
    if (n < 1)
        return mcp_error("blend: curves need at least one variance image (got %d)", n);
    for (int i = 0; i < n; i++) {
        if (!var[i]) return mcp_error("blend: curves: variance image %d is missing", i);
        if (mcp__blend_rgb(var[i], "variance", &rgb[i])) return -1;
        if (i > 0 && !mcp_image_same_size(var[i], var[0]))
            return mcp_error_prefix("blend: curves: ");
        if (!(spp[i] > 0) || !isfinite(spp[i]))
            return mcp_error("blend: curves: spp %d must be finite and > 0 (got %g)", i,
                             spp[i]);
        if (i > 0 && !(spp[i] > spp[i - 1]))
            return mcp_error("blend: curves: spp must increase (%g after %g)", spp[i],
                             spp[i - 1]);
    }
    return 0;
}

int
mcp_blend_curves(const mcp_image *const *var_of_mean, const double *spp, int n,
                 const mcp_blend_options *opt, mcp_image **out)
{
    *out = NULL;
    mcp_blend_options defaults = mcp_blend_defaults();
    const mcp_blend_options *o = opt ? opt : &defaults;
    if (mcp_blend_options_check(o)) return -1;
    mcp__rgb *rgb = mcp_malloc((size_t)(n > 0 ? n : 1) * sizeof *rgb);
    if (!rgb) return -1;
    int on_the_fly = o->fit == MCP_CURVE_FIT_ON_THE_FLY;
    int last_two = o->fit == MCP_CURVE_FIT_LAST_TWO;
    mcp__otf otf;
    if (check_inputs(var_of_mean, spp, n, rgb) ||
        ((on_the_fly || last_two) &&
         mcp__otf_init(&otf, o, spp[n - 1], mcp__max_weight(o)))) {
        free(rgb);
        return -1;
    }
    const mcp_image *v0 = var_of_mean[0];
    int w = v0->width, h = v0->height;
    mcp_image *curves = NULL;
    if (mcp_image_new(w, h, N_CURVE_CHANNELS, curve_channel_names, &curves)) {
        free(rgb);
        return -1;
    }
    if (mcp_image_set_source(curves, "blend curves")) {
        free(rgb);
        mcp_image_free(curves);
        return -1;
    }
    /* points of one value: n at most, plus the far point on the fly */
    int cap = n + 1;
    long n_alloc_failed = 0;
#pragma omp parallel reduction(+ : n_alloc_failed)
    {
        double *xs = mcp_malloc(2 * (size_t)cap * sizeof *xs), *vs = xs ? xs + cap : NULL;
        unsigned char *keep = mcp_malloc((size_t)cap);
        if (!xs || !keep) n_alloc_failed++;
#pragma omp for schedule(static)
        for (int y = 0; y < h; y++) {
            if (!xs || !keep) continue;
            float *row = mcp_image_px(curves, 0, y);
            for (int x = 0; x < w; x++) {
                for (int k = 0; k < 3; k++) {
                    double a = NAN, b = NAN;
                    int m = 0;
                    if (on_the_fly) {
                        if (!mcp__otf_curve(&otf, mcp__rgb_at(&rgb[n - 1], x, y, k), &a,
                                            &b))
                            a = b = NAN;
                    } else {
                        for (int i = 0; i < n; i++)
                            vs[i] = mcp__rgb_at(&rgb[i], x, y, k);
                        int kept = mcp_curve_select_points(vs, n, keep);
                        /* last two: the older kept points are passed over */
                        int skip = last_two && kept > 2 ? kept - 2 : 0;
                        for (int i = 0; i < n; i++) {
                            if (!keep[i]) continue;
                            if (skip > 0) {
                                skip--;
                                continue;
                            }
                            xs[m] = spp[i];
                            vs[m] = vs[i];
                            m++;
                        }
                        /* one point left: the paper's fallback, its Eq. 11 point */
                        if (last_two && m == 1 &&
                            !mcp_curve_far_point(xs[0], vs[0], o->far_spp, &xs[1],
                                                 &vs[1]))
                            m = 2;
                        if (m < 2 || !mcp_curve_fit_points(o->curve, o->powerlaw_offset,
                                                           xs, vs, m, &a, &b))
                            a = b = NAN;
                    }
                    row[x * N_CURVE_CHANNELS + k] = (float)a;
                    row[x * N_CURVE_CHANNELS + 3 + k] = (float)b;
                }
            }
        }
        free(xs);
        free(keep);
    }
    free(rgb);
    if (n_alloc_failed) {
        mcp_image_free(curves);
        return mcp_error("blend: curves: out of memory (%d points per thread)", cap);
    }
    *out = curves;
    return 0;
}
