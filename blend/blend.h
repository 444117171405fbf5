/* blend.h: converging blends of a noisy render with its denoised image
 * (docs/mathematics.md §3; Denisova & Bocchi 2024, "Converging Algorithm-Agnostic
 * Denoising for Monte Carlo Rendering").
 *
 * Per pixel and channel, the noisy mean n(I) at I samples per pixel and a denoised
 * image d(I') (I' <= I: denoising may have stopped earlier) are mixed as
 *
 *     r = (I n + W d) / (I + W),
 *
 * where W, the "effective sample count" of d, comes from a convergence curve of the
 * variance of the mean, log v = a log I + b, evaluated at d's estimated error:
 * log W = (log SURE - b) / a. As I grows, v falls below SURE, W / I -> 0 and r
 * converges to the unbiased n whatever the denoiser.
 *
 * The steps, each usable on its own on images (3 channels R, G, B, found by
 * mcp_rgb_channels; any strides):
 *   curves.c          convergence curves: on the fly (newest point and the Eq. 11 point)
 *                     or retrospective (least squares), log-log or the authors' power law
 *   filtering.c       Gaussian blur (or the denoiser) of v and SURE, the stopping rule
 *                     and the negative-SURE rule
 *   weights.c         W from the curves, r, easy blending and ideal blending
 *   post_correction.c James-Stein combiner (its variance: estimate.h)
 *   series.c          a whole progressive render: denoising, SURE, every method and
 *                     their errors against a reference (mcp_blend_series)
 * mcp_blend_step() runs curves, filtering, weights and the blend for one iteration.
 *
 * Images here hold the variance OF THE MEAN (as mcp_dump does), never per-sample
 * variance. Weights are sample counts (spp), like I. */
#ifndef MCP_BLEND_H
#define MCP_BLEND_H

#include <mcpost/denoiser.h>
#include <mcpost/dump.h>
#include <mcpost/estimate.h>
#include <mcpost/flip.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- options ---- */

/* How curves are fitted. */
typedef enum {
    MCP_CURVE_FIT_ON_THE_FLY = 0, /* newest point + Eq. 11 point (§3.1 default) */
    MCP_CURVE_FIT_RETROSPECTIVE,  /* least squares over every stored point */
    /* The paper's on-the-fly curve (Section 2.5; the authors' code): the last two
     * points that the retrospective selection keeps, and the Eq. 11 point only where
     * one point survives. */
    MCP_CURVE_FIT_LAST_TWO
} mcp_curve_fit;

/* Which curve. */
typedef enum {
    /* log v = a log I + b; log W = (log SURE - b) / a (paper Eqs. 7, 14;
     * docs/mathematics.md §3.4) */
    MCP_CURVE_LOG = 0,
    /* The authors' code (MCPTBlender, curvepredictor.cpp): ln v + c = a I^b with
     * c = 100, W = ((ln SURE + c) / a)^(1/b), W capped at 65536. */
    MCP_CURVE_POWERLAW
} mcp_curve_model;

/* How v and SURE are filtered before the curves and weights. */
typedef enum {
    MCP_BLEND_FILTER_GAUSS = 0, /* Gaussian blur, sigma = min(sqrt(mean v), 1) x 100 */
    MCP_BLEND_FILTER_DENOISER,  /* the configured denoiser applied to v and SURE */
    MCP_BLEND_FILTER_NONE
} mcp_blend_filter;

/* What to do with negative SURE values. */
typedef enum {
    /* zero them while mean(v) >= mean(SURE), their magnitude after that (§3.3) */
    MCP_NEG_SURE_SWITCH = 0,
    MCP_NEG_SURE_ZERO,
    MCP_NEG_SURE_MAGNITUDE
} mcp_neg_sure;

/* Which weights make "the blend" (docs/blend.md "Which weights"). */
typedef enum {
    /* the James-Stein weight of d over js_window, min(1, (p - 2) mean(v) / sum (n -
     * d)^2): needs no estimate of d's error, and meets every convergence target on the
     * stratified fixtures (the default) */
    MCP_BLEND_WEIGHTS_JAMES_STEIN = 0,
    /* Denisova & Bocchi's convergence curves from SURE and v (with the safeguard) */
    MCP_BLEND_WEIGHTS_CURVES
} mcp_blend_weighting;

typedef struct mcp_blend_options {
    mcp_curve_fit fit;         /* [on_the_fly] */
    mcp_curve_model curve;     /* [log] */
    double far_spp;            /* N of Eq. 11, > every I [1e6] */
    mcp_blend_filter filter;   /* [gauss] */
    int filter_window;         /* Gaussian window, odd [11] */
    double filter_sigma_scale; /* sigma = min(sqrt(mean v), 1) x this [100] */
    /* Filter only while mean(v) >= mean(SURE); once it fails, never again [1]. */
    int stop_filtering;
    mcp_neg_sure negative_sure; /* [switch] */
    /* The denoiser keeps all-black pixels black, so W there may be anything: 1 gives
     * them W = inf (r = d); 0 gives W = 0 (r = n), docs/mathematics.md §3.4 [0]. */
    int denoiser_keeps_zeros;
    /* Cap on W (spp); 0 means the curve's own: none for log, 65536 for powerlaw [0]. */
    double max_weight;
    double powerlaw_offset; /* c of the power law [100] */
    /* James-Stein window side, odd [15]; also the safeguard's. Its leak where d is
     * right is the chi-square spread of the window: 2.3% of v per value at 7 x 7, 0.47%
     * at 15 x 15 (docs/blend.md "The window") */
    int js_window;
    /* Caps the weight of d at the James-Stein combiner's over js_window, so that the
     * blend converges to n whatever SURE says (mcp_blend_safeguard) [1] */
    int safeguard;
    mcp_blend_weighting weights; /* [james_stein] */
} mcp_blend_options;

MCP_API mcp_blend_options mcp_blend_defaults(void);

/* Checks the fields; the message names the field and the value. */
MCP_API int mcp_blend_options_check(const mcp_blend_options *o);

/* Names for the CLI and job files: "on_the_fly" (also "on-the-fly"),
 * "retrospective", "last_two"; "log", "powerlaw"; "gauss", "denoiser", "none";
 * "switch", "zero", "magnitude". Each enum's words are a wordlist, which its from_name
 * and name functions read and write (and the operation table's enum options). */
MCP_API extern const mcp_wordlist mcp_curve_fit_words;
MCP_API extern const mcp_wordlist mcp_curve_model_words;
MCP_API extern const mcp_wordlist mcp_blend_filter_words;
MCP_API extern const mcp_wordlist mcp_neg_sure_words;
MCP_API extern const mcp_wordlist mcp_blend_weighting_words;
MCP_API int mcp_curve_fit_from_name(const char *name, mcp_curve_fit *out);
MCP_API const char *mcp_blend_weighting_name(mcp_blend_weighting w);
MCP_API const char *mcp_curve_fit_name(mcp_curve_fit f);
MCP_API const char *mcp_curve_model_name(mcp_curve_model m);
MCP_API const char *mcp_blend_filter_name(mcp_blend_filter f);
MCP_API const char *mcp_neg_sure_name(mcp_neg_sure n);

/* ---- curves (curves.c) ----
 * A curve image has 6 channels: "a.R", "a.G", "a.B" (slope; for powerlaw the factor
 * a) and "b.R", "b.G", "b.B" (intercept; for powerlaw the exponent b). A value with no
 * curve (fewer than two usable points: an all-black pixel) holds NaN in both. */

/* Eq. 11: the second point of an on-the-fly curve, (N - K, v_K / (N/K - 1)^2).
 * Pure; returns 0, or -1 (no message) unless 0 < spp < far_spp. */
MCP_API int mcp_curve_far_point(double spp, double var_of_mean, double far_spp,
                                double *far_spp_out, double *far_var_out);

/* Fits a curve by least squares through n points (spp[i], var_of_mean[i]) taken as
 * they are (no selection). Log: in (ln I, ln v); powerlaw: in (ln I, ln(ln v + c)).
 * Points with v <= 0 (or ln v + c <= 0) are skipped. Returns the number of points
 * used when it fitted (>= 2, with at least two distinct I), else 0; pure. */
MCP_API int mcp_curve_fit_points(mcp_curve_model model, double powerlaw_offset,
                                 const double *spp, const double *var_of_mean, int n,
                                 double *a, double *b);

/* The retrospective selection (docs/mathematics.md §3.1): walking back from the newest of
 * n points (ordered by increasing I), keep a point when its v is positive and larger than
 * the last point kept; zeros and the rest are dropped. keep[i] receives 0 or 1; returns
 * the number kept. */
MCP_API int mcp_curve_select_points(const double *var_of_mean, int n,
                                    unsigned char *keep);

/* W for an estimated squared error `sure` (>= 0) on a curve (a, b): log:
 * exp((ln sure - b) / a), +inf at sure = 0; powerlaw: ((ln sure + c) / a)^(1/b), the
 * cap where sure is 0 or ln sure + c <= 0. The result is capped at max_weight (> 0;
 * INFINITY for none). NaN a or b (no curve) gives NaN. Pure. */
MCP_API double mcp_curve_weight(mcp_curve_model model, double powerlaw_offset, double a,
                                double b, double sure, double max_weight);

/* Curves of every value from n variance images (filtered as the caller wishes) at
 * sample counts spp[0] < spp[1] < ... . On the fly: the newest image only, with its
 * Eq. 11 point. Retrospective: mcp_curve_select_points over all n, then least squares.
 * Last two: the two newest points that selection keeps (one: with its Eq. 11 point).
 * *out: a curve image (above). */
MCP_API int mcp_blend_curves(const mcp_image *const *var_of_mean, const double *spp,
                             int n, const mcp_blend_options *opt, mcp_image **out);

/* ---- filtering of the estimates (filtering.c) ---- */

/* What the rules decided for one iteration; carried between iterations so that
 * "once" means once. Zero-initialise it before the first iteration. */
typedef struct mcp_blend_state {
    int filtering_stopped; /* mean(v) < mean(SURE) happened: no more filtering */
    int magnitude;         /* ditto: negative SURE by magnitude from now on */
} mcp_blend_state;

/* The filter of docs/mathematics.md §3.2 (or opt->filter): Gaussian blur of img (window,
 * sigma from mean_var) or the denoiser applied to img as a colour image (den required
 * then), or a copy for none. */
MCP_API int mcp_blend_filter_image(const mcp_image *img, double mean_var,
                                   const mcp_blend_options *opt, const mcp_denoiser *den,
                                   mcp_image **out);

/* Prepared estimates of one iteration: v and SURE filtered (or not, per the stopping
 * rule) and SURE made non-negative (per the negative rule). state may be NULL (the
 * rules then look at this iteration only). The sigma of both blurs comes from the
 * mean of var_of_mean. */
typedef struct mcp_blend_estimates {
    mcp_image *var_of_mean;     /* filtered v */
    mcp_image *sure;            /* filtered, non-negative SURE */
    double mean_var, mean_sure; /* of the raw inputs */
    int filtered;               /* 1 when filtered */
    int magnitude;              /* 1 when negative SURE became |SURE|, 0 when zeroed */
} mcp_blend_estimates;

MCP_API int mcp_blend_prepare(const mcp_image *var_of_mean, const mcp_image *sure,
                              const mcp_blend_options *opt, const mcp_denoiser *den,
                              mcp_blend_state *state, mcp_blend_estimates *out);
MCP_API void mcp_blend_estimates_free(mcp_blend_estimates *e);

/* ---- weights and blends (weights.c) ---- */

/* W per value from curves and a non-negative SURE (NaN curve: an all-black value,
 * W = 0, or inf with opt->denoiser_keeps_zeros). *out: channels R, G, B. */
MCP_API int mcp_blend_weights(const mcp_image *curves, const mcp_image *sure,
                              const mcp_blend_options *opt, mcp_image **out);

/* r = (I n + W d) / (I + W) per value; W = inf gives d, W = 0 gives n. */
MCP_API int mcp_blend_mix(const mcp_image *noisy, double spp, const mcp_image *denoised,
                          const mcp_image *weights, mcp_image **out);

/* Easy blending (Eq. 8): r = n where SURE > v, else d. */
MCP_API int mcp_blend_easy(const mcp_image *noisy, const mcp_image *denoised,
                           const mcp_image *var_of_mean, const mcp_image *sure,
                           mcp_image **out);

/* Ideal blending (Eq. 4, evaluation only): W = max(0, I (R - n) / (d - R)), inf where
 * d = R; *out = the blend, *weights (may be NULL) = W. */
MCP_API int mcp_blend_ideal(const mcp_image *noisy, double spp, const mcp_image *denoised,
                            const mcp_image *reference, mcp_image **out,
                            mcp_image **weights);

/* ---- post-correction (post_correction.c) ---- */

/* James-Stein combiner over a window x window neighbourhood per channel (clipped at
 * the borders; p = the values inside): r = d + s (n - d),
 * s = max(0, 1 - a_k (p - 2) mean(v) / sum (n - d)^2), a_k = min(1, 1.5 (1 - kappa[k]))
 * with kappa the denoiser's self-influence (mcp_blend_self_influence; NULL: 0, the
 * plain combiner; docs/blend.md "Self-influence"). rho (may be NULL) receives 1 - s,
 * the weight of d, for mcp_blend_james_stein_variance. */
MCP_API int mcp_blend_james_stein(const mcp_image *noisy, const mcp_image *denoised,
                                  const mcp_image *var_of_mean, int window,
                                  const double *kappa, mcp_image **out, mcp_image **rho);

/* The denoiser's variance-weighted self-influence per channel,
 * kappa[k] = sum v dd/dn / sum v = sum Cov(n, d) / sum v, read back from d's raw SURE
 * (absolute units, as mcp_error_maps_compute makes it with metric se):
 * v dd/dn = (SURE - (d - n)^2 + v) / 2, summed over the image; clamped to [0, 1]
 * (self_influence.c). */
MCP_API int mcp_blend_self_influence(const mcp_image *noisy, const mcp_image *denoised,
                                     const mcp_image *var_of_mean, const mcp_image *sure,
                                     double kappa[3]);

/* The variance of the combiner's output, for a sampling map: estimate's
 * mcp_postcorrection_variance (Firmino 2023 Eq. 4) with one denoised input (alpha = 1):
 * rho^2 Var[d] + (1 - rho)^2 v. var_denoised: Var[d] (e.g. from mcp_variance). */
MCP_API int mcp_blend_james_stein_variance(const mcp_image *rho,
                                           const mcp_image *var_denoised,
                                           const mcp_image *var_of_mean, mcp_image **out);

/* ---- the safeguard (safeguard.c; docs/blend.md "The safeguard") ---- */

/* Caps the share of d in a blend, rho = W / (I + W), at rho_max (an R, G, B image, the
 * rho of mcp_blend_james_stein: min(1, (p - 2) mean(v) / sum (n - d)^2) over its
 * window), in place: where the curve weight exceeds the cap, the weight becomes
 * I rho_max / (1 - rho_max) and the blend n + rho_max (d - n). weights and blend are
 * packed R, G, B (as mcp_blend_weights and mcp_blend_mix make them). *pulled (may be
 * NULL) receives the share of values that were pulled back. */
MCP_API int mcp_blend_safeguard(const mcp_image *noisy, double spp,
                                const mcp_image *denoised, const mcp_image *rho_max,
                                mcp_image *weights, mcp_image *blend, double *pulled);

/* ---- one iteration (weights.c) ---- */

typedef struct mcp_blend_input {
    const mcp_image *noisy;       /* n(I) */
    const mcp_image *var_of_mean; /* v(I), raw */
    double spp;                   /* I */
    const mcp_image *denoised;    /* d(I'), I' <= I */
    const mcp_image *sure;        /* SURE(I'), raw (may be negative) */
    /* Precomputed curves (e.g. retrospective ones); NULL: on the fly from the
     * filtered v. */
    const mcp_image *curves;
    /* The denoiser's self-influence per channel for the James-Stein weights and the
     * safeguard (mcp_blend_self_influence of d(I') with n(I'), v(I'), SURE(I'));
     * NULL: 0. */
    const double *kappa;
} mcp_blend_input;

typedef struct mcp_blend_result {
    mcp_image *blend;   /* r */
    mcp_image *weights; /* W */
    mcp_blend_estimates est;
    double safeguard_pulled; /* share of values the safeguard pulled back (0 when off) */
} mcp_blend_result;

/* Filtering, curves (unless given), weights, the blend and the safeguard (unless
 * opt->safeguard is 0); with opt->weights = james_stein the blend and W are then the
 * James-Stein combiner's (the estimates are still prepared). den is needed only for
 * opt->filter = denoiser. state may be NULL. */
MCP_API int mcp_blend_step(const mcp_blend_input *in, const mcp_blend_options *opt,
                           const mcp_denoiser *den, mcp_blend_state *state,
                           mcp_blend_result *out);
MCP_API void mcp_blend_result_free(mcp_blend_result *r);

/* ---- a progressive render (series.c) ---- */

/* The images the series driver compares (the paper's Fig. 4). */
typedef enum {
    MCP_BLEND_NOISY = 0,   /* n(I) */
    MCP_BLEND_DENOISED,    /* d(I') */
    MCP_BLEND_EASY,        /* Eq. 8 with the estimates */
    MCP_BLEND_CURVES,      /* r, the method */
    MCP_BLEND_IDEAL,       /* Eq. 4 with the reference (evaluation only) */
    MCP_BLEND_JAMES_STEIN, /* the post-correction combiner */
    MCP_BLEND_N_METHODS
} mcp_blend_method;

/* "noisy", "denoised", "easy", "curves", "ideal", "james_stein". */
MCP_API const char *mcp_blend_method_name(mcp_blend_method m);

typedef struct mcp_blend_series_options {
    mcp_blend_options blend;
    /* I': the last spp at which the denoiser runs; later members reuse d(I') and
     * SURE(I'). 0: denoise every member [0]. */
    double stop_denoising_at;
    mcp_sure_options sure; /* metric is always se (plain SURE) [1 probe, seed 0] */
    int flip;              /* HDR-FLIP against the reference [1] */
    mcp_flip_options flip_opt;
} mcp_blend_series_options;

MCP_API mcp_blend_series_options mcp_blend_series_defaults(void);

/* Errors of one image against the reference. */
typedef struct mcp_blend_errors {
    double mse, relmse, flip_hdr; /* flip_hdr NaN when not computed */
} mcp_blend_errors;

/* One member of the series. */
typedef struct mcp_blend_row {
    double spp;                 /* I */
    double denoised_spp;        /* I' */
    double mean_var, mean_sure; /* raw image means (the rules compare them) */
    int filtered;               /* estimates filtered at this member */
    int magnitude;              /* negative SURE by magnitude (else zeroed) */
    double mean_rho;            /* mean of W / (I + W): the share of d in the blend */
    double safeguard_pulled;    /* share of values the safeguard pulled back (0: off) */
    double self_influence;      /* the denoiser's at I', mean of R, G, B (the kappa of
                                   mcp_blend_self_influence that weighs the James-Stein
                                   weights) */
    mcp_blend_errors err[MCP_BLEND_N_METHODS]; /* with a reference; ideal too */
} mcp_blend_row;

typedef struct mcp_blend_series_result {
    int count;
    int has_reference;
    int has_flip;
    mcp_variance_source variance_source; /* what the members' variance rests on */
    mcp_blend_method method; /* the blend: MCP_BLEND_JAMES_STEIN or MCP_BLEND_CURVES */
    mcp_blend_row *rows;
} mcp_blend_series_result;

MCP_API void mcp_blend_series_result_free(mcp_blend_series_result *r);

/* What the driver hands the caller after each member; everything is borrowed and
 * valid only during the call. */
typedef struct mcp_blend_point {
    int index, count;
    const char *source; /* the member's file */
    const mcp_blend_row *row;
    /* the images of every method (ideal NULL without a reference) */
    const mcp_image *images[MCP_BLEND_N_METHODS];
    mcp_blend_method method;        /* which image is the blend (opt->weights) */
    const mcp_image *weights;       /* W of the blend (R, G, B) */
    const mcp_image *ideal_weights; /* W of ideal blending, or NULL */
    const mcp_blend_estimates *est; /* filtered v, SURE */
} mcp_blend_point;

typedef int (*mcp_blend_point_fn)(const mcp_blend_point *p, void *ctx);

/* Blends every member of a series (in increasing spp; each needs its variance of the
 * mean and a scalar sample count): denoising and SURE with den (up to
 * stop_denoising_at), filtering, curves (on the fly, or retrospective over every
 * member's filtered v, which takes a first pass), weights, easy, curve and
 * James-Stein blends, and with a reference (may be NULL) ideal blending and the
 * errors of every method. on_point (may be NULL) is called after each member; a
 * non-zero return stops the run with that error. opt may be NULL. */
MCP_API int mcp_blend_series(const mcp_series *series, const mcp_denoiser *den,
                             const mcp_image *reference,
                             const mcp_blend_series_options *opt,
                             mcp_blend_point_fn on_point, void *ctx,
                             mcp_blend_series_result **out);

#ifdef __cplusplus
}
#endif
#endif
