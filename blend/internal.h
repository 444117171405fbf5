/* internal.h: helpers shared inside blend/ (not installed; no other module includes
 * it). */
#ifndef MCP_BLEND_INTERNAL_H
#define MCP_BLEND_INTERNAL_H

#include "blend.h"

#include <math.h>

/* An RGB input: the image and the indices of its R, G, B channels. */
typedef struct mcp__rgb {
    const mcp_image *img;
    int c[3];
} mcp__rgb;

/* Finds the R, G, B channels of img (mcp_rgb_channels), prefixing the message with
 * "blend: <what>: " on failure. img must not be NULL. */
int mcp__blend_rgb(const mcp_image *img, const char *what, mcp__rgb *out);

/* Checks that every image of a NULL-terminated list has the size of the first. */
int mcp__blend_same_size(const mcp_image *first, ...);

/* A new zero-filled packed image with channels R, G, B labelled source. */
int mcp__blend_rgb_new(int width, int height, const char *source, mcp_image **out);

/* The mean over pixels and the three channels, summed in double per row and the rows
 * added in order (independent of the thread count). */
int mcp__blend_mean(const mcp__rgb *in, double *mean);

/* mcp_blend_prepare, with the negative-SURE rule left to the caller when fix_sure is 0
 * (out->magnitude still says which rule applies). */
int mcp__blend_prepare(const mcp_image *var_of_mean, const mcp_image *sure,
                       const mcp_blend_options *opt, const mcp_denoiser *den,
                       mcp_blend_state *state, int fix_sure, mcp_blend_estimates *out);

/* On the fly, weights and blend in one pass (weights.c): W from the closed form of the
 * two-point curve (mcp__otf_weight), no curve image; e->sure's negative values are
 * fixed on the way (e->magnitude). *weights and *blend are new images. */
int mcp__blend_on_the_fly(const mcp_blend_input *in, const mcp_blend_options *o,
                          mcp_blend_estimates *e, mcp_image **weights, mcp_image **blend);

/* The safeguard of one blend (safeguard.c): the James-Stein rho of (noisy, denoised,
 * var_of_mean) over window with the self-influence kappa (may be NULL), then
 * mcp_blend_safeguard on weights and blend in place. */
int mcp__blend_safeguard_step(const mcp_image *noisy, double spp,
                              const mcp_image *denoised, const mcp_image *var_of_mean,
                              int window, const double *kappa, mcp_image *weights,
                              mcp_image *blend, double *pulled);

/* The share of d in r = (I n + W d) / (I + W), rho = W / (I + W), and back: W = inf is
 * rho = 1, W <= 0 is rho = 0, and the other way round. */
static inline double
mcp__rho_of_weight(double spp, double w)
{
    return isinf(w) ? 1.0 : w > 0 ? w / (spp + w) : 0.0;
}

static inline double
mcp__weight_of_rho(double spp, double rho)
{
    return rho >= 1 ? INFINITY : rho > 0 ? spp * rho / (1 - rho) : 0.0;
}

/* W (mcp__weight_of_rho) of a packed R, G, B share of d, as a new image. */
int mcp__blend_weights_from_rho(const mcp_image *rho, double spp, mcp_image **out);

/* The value of channel k (0..2) of pixel (x, y). */
static inline float
mcp__rgb_at(const mcp__rgb *in, int x, int y, int k)
{
    return mcp_image_px(in->img, x, y)[in->c[k]];
}

/* ---- on-the-fly curves (curves.c) ----
 * The line through (K, v) and the Eq. 11 point depends on v only through its
 * intercept, so the per-image constants are computed once. */
typedef struct mcp__otf {
    mcp_curve_model model;
    double c;         /* powerlaw offset */
    double spp;       /* K */
    double log_spp;   /* ln K */
    double slope;     /* log: a (= -2 up to rounding) */
    double log_ratio; /* ln(N/K - 1) = ln((N - K)/K) */
    double dx;        /* ln(N - K) - ln K, the same up to rounding */
    double cap;       /* the weight cap (INFINITY for none) */
    int sqrt_form;    /* log with a = -2: W = K sqrt(v / SURE) */
} mcp__otf;

/* The constants for spp K, far point N and the options' curve; -1 with a message
 * unless 0 < K < N. cap: the weight cap. */
int mcp__otf_init(mcp__otf *t, const mcp_blend_options *o, double spp, double cap);

/* The curve (a, b) of one value with variance v; 0 when there is none (v <= 0). */
int mcp__otf_curve(const mcp__otf *t, double v, double *a, double *b);

/* W of one value (NaN when there is no curve): mcp_curve_weight on mcp__otf_curve. */
double mcp__otf_weight_general(const mcp__otf *t, double v, double sure);

/* The same, without logarithms where the closed form allows: with a = -2 and
 * b = ln v + 2 ln K, exp((ln SURE - b) / a) = K sqrt(v / SURE). Inline: it runs once
 * per value. */
static inline double
mcp__otf_weight(const mcp__otf *t, double v, double sure)
{
    if (!t->sqrt_form) return mcp__otf_weight_general(t, v, sure);
    if (!(v > 0) || !(v < INFINITY)) return NAN; /* no curve: an all-black value */
    double w = sure > 0 ? t->spp * sqrt(v / sure) : INFINITY;
    return w < t->cap ? w : t->cap;
}

/* The weight cap that o selects: o->max_weight, else none (log) or 65536 (powerlaw). */
double mcp__max_weight(const mcp_blend_options *o);

/* What to do about a dump without variance: the recipe for a Cycles render, else
 * `otherwise` (common/dump/dump.c, common/dump/internal.h). */
const char *mcp__no_variance_hint(const mcp_dump *d, const char *otherwise);

/* ---- not exported by libmcpost.so (docs/library.md, "Exported symbols") ---- */

int mcp_curve_model_from_name(const char *name, mcp_curve_model *out);
int mcp_blend_filter_from_name(const char *name, mcp_blend_filter *out);
int mcp_neg_sure_from_name(const char *name, mcp_neg_sure *out);
/* "james_stein" (also "james-stein"), "curves" */
int mcp_blend_weighting_from_name(const char *name, mcp_blend_weighting *out);

/* Negative values of sure: zeroed (magnitude 0) or replaced by |value|. In place. */
int mcp_blend_fix_sure_inplace(mcp_image *sure, int magnitude);

#endif
