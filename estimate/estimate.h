/* estimate.h: how wrong a denoised render still is, where to put the next samples, and
 * when to stop rendering (docs/mathematics.md §2; Firmino et al. 2023 and 2024, Li 2017).
 *
 * The pieces, in the order the pipeline (mcp_estimate_compute) runs them:
 *   probes        ε ~ N(0, Σ̂) per pixel (3x3 colour covariance, or the joint
 *                 colour-feature covariance for joint SURE), Rademacher v = L r
 *   error maps    F(X), SURE, Var[F] = (Jε)² and Σ̂, each also divided by the metric's
 *                 denominator (maxc² + EPS_REL; FLIP's CSF operator M for SURE_M)
 *   sampling map  Firmino 2023 Eq. 3 (and its tone-mapped and MC-SURE variants), and
 *                 integer sample counts that sum exactly to a budget
 *   blocks        Firmino 2024 Alg. 1 over summed-area tables
 *   distribution  λ_i and s_i² (Eq. 14), the image error CDF F(τ), the stopping
 *                 predicate F(τ) >= p and percentiles by bisection in log τ
 *
 * Every random stream is seeded from (seed, pixel index) and every image-wide sum runs
 * in double per row with the rows added in order, so results do not depend on the
 * number of threads. Functions return 0, or -1 with mcp_error_message() set; results
 * come back through out-pointers that stay NULL on failure. */
#ifndef MCP_ESTIMATE_H
#define MCP_ESTIMATE_H

#include <stdint.h>
#include <mcpost/denoiser.h>
#include <mcpost/dump.h>
#include <mcpost/tonemap.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Relative quantities divide by maxc(p)² + EPS_REL (docs/mathematics.md §1). metrics.h
 * defines the same constant. */
#ifndef MCP_EPS_REL
#define MCP_EPS_REL 1e-2
#endif

#define MCP_ESTIMATE_MAX_PERCENTILES 32
#define MCP_ESTIMATE_MAX_TAUS 32

/* The error a run estimates and stops on. */
typedef enum {
    MCP_METRIC_RELSE = 0,        /* (F - μ)² / (maxc(F)² + EPS_REL)     "relse" */
    MCP_METRIC_RELSE_PERCEPTUAL, /* (M(F - μ))² / (maxc(MF)² + EPS_REL) "relse-perceptual"
                                  */
    MCP_METRIC_SE                /* (F - μ)²                            "se" */
} mcp_error_metric;

/* "relse", "relse-perceptual", "se"; fails with "unknown metric 'X' (known: ...)". */
/* "relse", "relse-perceptual", "se" (the words: mcp_error_metric_words) */
MCP_API extern const mcp_wordlist mcp_error_metric_words;
MCP_API int mcp_error_metric_from_name(const char *name, mcp_error_metric *out);
MCP_API const char *mcp_error_metric_name(mcp_error_metric metric);

/* ---- probes (estimate/probes.c) ---- */

/* Noisy features for joint SURE (Li 2017). Render dumps carry no colour-feature
 * covariance yet; a caller that has it passes it here. Every image has the dump's
 * size; NULL parts are zero (no correlation) or, for the feature variances, filled
 * with the smallest values that make the joint covariance positive semi-definite,
 * Σ_yx Σ_xx⁺ Σ_xy (only the cross-covariance enters SURE's expectation). A part is
 * used only when the dump has that feature and the denoiser reads it. */
typedef struct mcp_feature_covariance {
    /* Cov(colour_c, albedo_d) of the pixel means: 9 channels in the order
     * RR, RG, RB, GR, GG, GB, BR, BG, BB (colour channel first). */
    const mcp_image *color_albedo;
    /* Cov(colour_c, normal_d): 9 channels RX, RY, RZ, GX, ..., BZ. */
    const mcp_image *color_normal;
    const mcp_image *albedo_var; /* variance of the albedo mean, 3 channels, or NULL */
    const mcp_image *normal_var; /* variance of the normal mean, 3 channels, or NULL */
} mcp_feature_covariance;

/* One probe: a colour part and, for joint SURE, feature parts (NULL when absent).
 * All are 3-channel images of the dump's size. */
typedef struct mcp_probe {
    mcp_image *color;
    mcp_image *albedo;
    mcp_image *normal;
} mcp_probe;

MCP_API void mcp_probe_clear(mcp_probe *p); /* frees the parts, sets them to NULL */

/* Probe k of a Gaussian stream: ε ~ N(0, Σ̂_p) per pixel from the dump's variance of
 * the mean and, when present, its colour covariance (and from features when given,
 * drawing colour and features jointly). Negative eigenvalues of Σ̂_p are clamped to 0
 * (docs/mathematics.md §2.2). Deterministic in (seed, k, pixel). */
MCP_API int mcp_probe_gaussian(const mcp_dump *dump,
                               const mcp_feature_covariance *features, uint64_t seed,
                               int k, mcp_probe *out);

/* Probe k of a Rademacher stream: v_p = L_p r_p with L_p L_pᵀ = Σ̂_p (clamped) and
 * r_p a vector of independent ±1 (docs/mathematics.md §2.5, Firmino 2023 Eq. 2).
 * Colour only. */
MCP_API int mcp_probe_rademacher(const mcp_dump *dump, uint64_t seed, int k,
                                 mcp_image **out);

/* ---- SURE and variance (estimate/sure.c, estimate/variance.c) ---- */

typedef struct mcp_sure_options {
    mcp_error_metric metric; /* [relse] */
    int n_probes;            /* K >= 1: probes averaged in the Jε terms [1; in
                                mcp_estimate_defaults -1, the denoiser's choice,
                                mcp_estimate_auto_probes] */
    uint64_t seed;           /* [0] */
    double ppd;      /* relse-perceptual: pixels per degree, 0 = FLIP's 67.02 [0] */
    int mc_sure;     /* 1: Jε by finite differences (Ramani 2008), even when the
                        denoiser has an exact jvp [0] */
    double fd_delta; /* δ of the finite differences, unitless: the probe already
                        carries the noise scale (docs/mathematics.md §2.1) [0.1] */
    const mcp_feature_covariance *features; /* joint SURE; NULL: plain SURE [NULL] */
} mcp_sure_options;

MCP_API mcp_sure_options mcp_sure_defaults(void);

/* Everything one denoiser evaluation with probes gives, per value (3 channels R, G, B
 * unless said otherwise). "Scaled" maps are divided by the metric's denominator:
 * maxc(F)² + EPS_REL (relse), maxc(MF)² + EPS_REL (relse-perceptual) or 1 (se). */
typedef struct mcp_error_maps {
    mcp_error_metric metric;
    mcp_image *denoised; /* F(X) */
    mcp_image *sure;     /* SURE_i, or SURE_M,i for relse-perceptual */
    mcp_image *sure_rel; /* sure, scaled */
    mcp_image *var;     /* Var[F_i] ≈ mean_k (Jε_k)_i² (relse-perceptual: (MJε)²) */
    mcp_image *var_rel; /* var, scaled: s_i² of the error distribution */
    mcp_image *sigma_rel;   /* Σ̂_ii scaled (relse-perceptual: mean_k (Mε_k)_i² as the
                               estimate of (MΣ̂Mᵀ)_ii), for block splitting */
    mcp_image *denominator; /* 1 channel "denominator" (all 1 for se) */
} mcp_error_maps;

MCP_API void mcp_error_maps_free(mcp_error_maps *maps); /* frees the images, not maps */

/* Runs the denoiser once with opt->n_probes Gaussian probes (jvp, or finite
 * differences) and computes every map. opt may be NULL. */
MCP_API int mcp_error_maps_compute(const mcp_dump *dump, const mcp_denoiser *den,
                                   const mcp_sure_options *opt, mcp_error_maps *out);

/* The same from an evaluation the caller made (e.g. on a GPU): F(X), K probes ε_k
 * (colour parts) and J ε_k. Takes ownership of nothing; copies `denoised`. */
MCP_API int mcp_error_maps_from_probes(const mcp_dump *dump, const mcp_image *denoised,
                                       const mcp_image *const *probes,
                                       const mcp_image *const *jvps, int k,
                                       const mcp_sure_options *opt, mcp_error_maps *out);

/* Per-value SURE of den on dump, scaled as opt->metric says (se: plain SURE,
 * relse: SURE^r, relse-perceptual: SURE^r_M). One channel per colour, R, G, B. */
MCP_API int mcp_sure(const mcp_dump *dump, const mcp_denoiser *den,
                     const mcp_sure_options *opt, mcp_image **out);

typedef struct mcp_variance_options {
    int n_probes;    /* K >= 1 Rademacher probes [1] */
    uint64_t seed;   /* [0] */
    int relative;    /* divide by maxc(F)² + EPS_REL [0] */
    int mc;          /* finite differences instead of the jvp [0] */
    double fd_delta; /* [0.1] */
} mcp_variance_options;

MCP_API mcp_variance_options mcp_variance_defaults(void);

/* Var[F_i] ≈ mean_k (J v_k)_i² with Rademacher probes v (Firmino 2023 Eqs. 1-2).
 * denoised (may be NULL) receives F(X). */
MCP_API int mcp_variance(const mcp_dump *dump, const mcp_denoiser *den,
                         const mcp_variance_options *opt, mcp_image **var,
                         mcp_image **denoised);

/* J t_k for k < n by finite differences, (F(X + δ t) - F(X)) / δ, with the colour
 * and feature parts of t moved together; primal (may be NULL) receives F(X). The
 * black-box route of docs/mathematics.md §2.1, usable with any denoiser. */
MCP_API int mcp_jvp_finite_difference(const mcp_denoiser *den,
                                      const mcp_denoise_input *at,
                                      const mcp_denoise_tangent *t, int n, double delta,
                                      mcp_image **primal, mcp_image **out);

/* ---- sampling map (estimate/sampling_map.c) ---- */

typedef enum {
    MCP_SAMPLING_VARIANCE = 0, /* Var[F] / ((n+1)(F² + EPS_REL)), Eq. 3     "variance" */
    MCP_SAMPLING_TONEMAPPED, /* T'(F)² Var[F] / (n+1), T = ACES          "tonemapped" */
    MCP_SAMPLING_MC_SURE     /* SURE / ((n+1)(F² + EPS_REL)), wider blur  "mc-sure" */
} mcp_sampling_kind;

MCP_API extern const mcp_wordlist mcp_sampling_kind_words;
MCP_API const char *mcp_sampling_kind_name(mcp_sampling_kind kind);

typedef struct mcp_sampling_options {
    mcp_sampling_kind kind; /* [variance] */
    double blur_sigma_px;   /* 0: 0.5, or 4 for mc-sure [0] */
    int blur_window;        /* odd; 0: 5, or 17 for mc-sure [0] */
    mcp_tonemap tone_map;   /* tonemapped: T [aces] */
} mcp_sampling_options;

MCP_API mcp_sampling_options mcp_sampling_defaults(void);

/* The per-pixel sampling density for the next iteration: s_p = mean_c of the kind's
 * term, clipped at 0, blurred, normalised to sum 1 (uniform when every s_p is 0).
 * numerator: Var[F] (variance, tonemapped; absolute, not relative) or SURE (mc-sure),
 * 3 channels; denoised: F; dump: for n_p. *map has one channel "weight". */
MCP_API int mcp_sampling_map(const mcp_dump *dump, const mcp_image *denoised,
                             const mcp_image *numerator, const mcp_sampling_options *opt,
                             mcp_image **map);

/* Integer per-pixel sample counts for `budget` samples in all, proportional to a map
 * (any non-negative weights), by largest remainders: floor(budget w_p / Σw) each, and
 * one more to the pixels with the largest fractional parts (ties to the lower pixel
 * index), so they sum exactly to budget. *counts has one channel "SampleCount" (the
 * mcpost dump convention's per-pixel count); every count must fit a float exactly
 * (<= 2^24). */
MCP_API int mcp_sample_counts(const mcp_image *map, int64_t budget, mcp_image **counts);

/* The variance of the post-correction combiner (Firmino 2023 Eq. 4):
 * ρ²(α² Var[F(x0)] + (1 - α)² Var[F(x1)]) + (1 - ρ)² Var[x], per value. alpha and rho
 * have 1 channel or 3; the variances 3. The result can be the numerator of a
 * sampling map. */
MCP_API int mcp_postcorrection_variance(const mcp_image *var_f0, const mcp_image *var_f1,
                                        const mcp_image *var_x, const mcp_image *alpha,
                                        const mcp_image *rho, mcp_image **out);

/* ---- block averaging (estimate/blockavg.c) ---- */

typedef struct mcp_block {
    int x, y, w, h;
    double sure_sum[3]; /* Σ SURE^r over the block, per channel */
    double var_sum[3];  /* Σ Var^r, filled by mcp_error_distribution */
} mcp_block;

typedef struct mcp_blocks {
    int width, height;
    int count;
    mcp_block *items; /* disjoint, covering the image, in depth-first order */
} mcp_blocks;

MCP_API void mcp_blocks_free(mcp_blocks *blocks);

typedef struct mcp_block_options {
    int tile_size; /* pre-split into tiles of this side before Alg. 1; 0: none [0] */
} mcp_block_options;

MCP_API mcp_block_options mcp_block_defaults(void);

/* Firmino 2024 Alg. 1: starting from the image (or its tiles), cut a block with
 * longest side > 1 at the middle of its longest side (the width on ties) and keep the
 * cut when both halves pass, for every channel k,
 *     Σ sigma_rel / sqrt(|B_j ∩ C_k|) < Σ sure_rel.
 * Both inputs have 3 channels; sums run in double, from a summed-area table over
 * 4x4-pixel cells plus the pixels of the partial cells at a block's edges, so each
 * test costs O(perimeter) at most. opt may be NULL. */
MCP_API int mcp_block_average(const mcp_image *sure_rel, const mcp_image *sigma_rel,
                              const mcp_block_options *opt, mcp_blocks **out);

/* Each value replaced by its block ∩ channel mean (block-averaged SURE, Fig. 5). */
MCP_API int mcp_blocks_mean_image(const mcp_blocks *blocks, const mcp_image *values,
                                  mcp_image **out);

/* The block of every pixel: *label receives width * height indices, row-major
 * (malloc'd; free() it). */
MCP_API int mcp_blocks_label(const mcp_blocks *blocks, int32_t **label);

/* A false-colour picture of the blocks (turbo colours hashed from the block index,
 * so neighbours differ): rgb8 receives width * height * 3 bytes. */
MCP_API int mcp_blocks_picture(const mcp_blocks *blocks, unsigned char *rgb8);

/* ---- error distribution and stopping (estimate/stopping.c) ---- */

/* P((Z + sqrt(λ))² <= x), Z ~ N(0, 1): the CDF of the noncentral χ² with one degree of
 * freedom, Φ(√x - √λ) - Φ(-√x - √λ). x <= 0 gives 0. */
MCP_API double mcp_ncx2_cdf(double x, double lambda);

/* The per-value error model s_i² (Z + √λ_i)² (Eq. 14): s_i² = Var^r_i, λ_i constant
 * over block ∩ channel. It refers to the blocks and the variance it was made from
 * (like a view): both must outlive it. */
typedef struct mcp_error_dist mcp_error_dist;

MCP_API void mcp_error_dist_free(mcp_error_dist *dist);

/* λ_i = max(Σ_{B∩C} SURE^r / (Σ_{B∩C} Var^r + 1e-6), 1) - 1 and s_i² = Var^r_i.
 * Fills blocks->items[].var_sum. */
MCP_API int mcp_error_distribution(mcp_blocks *blocks, const mcp_image *var_rel,
                                   mcp_error_dist **out);

/* λ of block b, channel c. */
MCP_API double mcp_error_dist_lambda(const mcp_error_dist *dist, int block, int c);

/* mean_i s_i² (λ_i + 1): the mean scaled error the model expects. */
MCP_API double mcp_error_dist_mean(const mcp_error_dist *dist);

/* λ and s² as images (3 channels each: "lambda.R", ..., "s2.R", ...; 6 in all). */
MCP_API int mcp_error_dist_image(const mcp_error_dist *dist, mcp_image **out);

/* The image error CDF F(τ) = mean_i F_i(τ) (Eq. 15), in float with a vectorised
 * normal tail (Abramowitz & Stegun 26.2.17): each F_i is within 2e-7 of
 * mcp_ncx2_cdf, far below the 1 - p = 1e-3 that the stopping decision resolves.
 * Sums in double per block row, blocks added in order. NaN, with the error line set,
 * when memory runs out. */
MCP_API double mcp_error_cdf(const mcp_error_dist *dist, double tau);

/* The stopping predicate F(τ) >= p (Eq. 16): 1 to stop, 0 to go on, -1 (error line
 * set) when F(τ) is NaN (mcp_error_cdf). cdf (may be NULL) receives F(τ). */
MCP_API int mcp_error_should_stop(const mcp_error_dist *dist, double tau, double p,
                                  double *cdf);

/* The estimated error at percentile p[k] (in [0, 1), n at most
 * MCP_ESTIMATE_MAX_PERCENTILES): the τ with F(τ) = p, within a relative 1e-3 (searched
 * on the values' s² grouped in narrow bins, stopping.c; the same bits for any thread
 * count); 0 when F is already >= p for every τ > 0, +inf when no finite τ reaches p. */
MCP_API int mcp_error_percentiles(const mcp_error_dist *dist, const double *p, int n,
                                  double *tau);

/* ---- the pipeline (estimate/estimate.c) ---- */

typedef struct mcp_estimate_options {
    mcp_sure_options sure;
    int variance_rademacher; /* 1: Var from K separate Rademacher probes (Firmino 2023);
                                0: reuse the SURE probes, Var = (Jε)² (Firmino 2024) [0]
                              */
    mcp_block_options blocks;
    double tau;        /* the error threshold [0.01] */
    double p;          /* the fraction of values that must be below it [0.999] */
    int n_percentiles; /* the estimated percentile curve [5] */
    double
        percentiles[MCP_ESTIMATE_MAX_PERCENTILES]; /* [0.5, 0.9, 0.99, 0.999, 0.9999] */
    mcp_sampling_options sampling;
    int64_t budget; /* samples for the next iteration; 0: no counts [0] */
    /* s² = (Jε)² from K probes is Var[F] times a χ²_K / K draw; its spread fattens the
     * upper tail of the error distribution, so s² is pooled over a (2r + 1)² window
     * (docs "Variance sources"): -1 automatic (mcp_estimate_auto_s2_pool), 0 none
     * (the per-value s² of docs/mathematics.md §2.8), or r [-1] */
    int s2_pool;
    /* the probes' variance raised to its median over a (2r + 1)² window where below
     * it, so that it depends less on the noise of the pixels the denoiser sees
     * (docs/fidelity.md "The defaults"): -1 automatic (mcp_estimate_auto_probe_floor),
     * 0 none, or r [-1] */
    int probe_floor;
    /* Over a series: SURE's covariance term Cov(n, d), and the variance v beside it,
     * measured on the member's own samples by the delete-a-group jackknife over G
     * groups of its checkpoints (docs/mathematics.md §2.10), at G denoiser applies,
     * instead of the probes' divergence, which misreads a heavy-tailed noise: -1
     * automatic (MCP_ESTIMATE_SURE_GROUPS), 0 none, or G from 2 to 8 [-1]. A single
     * dump, the first two members (fewer than 3 groups unless G is 2), or members
     * that are not checkpoints of one render keep the probes' divergence. */
    int sure_groups;
} mcp_estimate_options;

#define MCP_ESTIMATE_SURE_GROUPS 4

/* The automatic probe count: that of the denoiser that runs on the dump (den, or the
 * one it picks for it: the `default` one's U-Net or nlm) from its estimate_probes (the
 * U-Net 3), else MCP_ESTIMATE_PROBES; docs/fidelity.md "The defaults" has the figures. */
#define MCP_ESTIMATE_PROBES 4
MCP_API int mcp_estimate_auto_probes(const mcp_dump *dump, const mcp_denoiser *den);

/* The automatic pooling radius: 1, except 0 for a denoiser with a sharp Var[F]
 * (den->sharp_variance) on a variance with many degrees of freedom (per-sample, of the
 * mean); docs/fidelity.md "The defaults" has the figures. */
MCP_API int mcp_estimate_auto_s2_pool(const mcp_dump *dump, const mcp_denoiser *den);

/* The automatic probe floor: the running denoiser's estimate_probe_floor (the U-Net 1,
 * the others 0), and 0 for relse-perceptual, whose maps take none; docs/fidelity.md
 * "The defaults" has the figures. */
MCP_API int mcp_estimate_auto_probe_floor(const mcp_dump *dump, const mcp_denoiser *den,
                                          mcp_error_metric metric);

MCP_API mcp_estimate_options mcp_estimate_defaults(void);

/* variance_rademacher's words: "sure" (0), "rademacher" (1). */
MCP_API extern const mcp_wordlist mcp_variance_probes_words;

/* Checks every field, naming it ("estimate: tau must be > 0 (got -1)"). */
MCP_API int mcp_estimate_check(const mcp_estimate_options *opt);

typedef struct mcp_estimate {
    mcp_error_maps maps;
    mcp_blocks *blocks;
    mcp_error_dist *dist;
    mcp_image *sampling_map;  /* "weight", sums to 1 */
    mcp_image *sample_counts; /* "SampleCount", sums to budget; NULL when budget is 0 */
    double tau, p;
    double cdf_at_tau; /* F(τ) */
    int stop;          /* F(τ) >= p, and the dump has variance somewhere */
    int no_variance;   /* the dump's variance is 0 everywhere (e.g. at 1 spp, where
                          a per-sample variance is undefined): every s_i is 0, so
                          the model would claim no error; stop is forced to 0 */
    int n_percentiles;
    double percentiles[MCP_ESTIMATE_MAX_PERCENTILES];    /* the p values */
    double percentile_tau[MCP_ESTIMATE_MAX_PERCENTILES]; /* estimated error at each */
    /* wall-clock times of the steps: F and its JVPs, the error maps, block averaging, the
     * distribution and the stop decision, the percentile curve, the sampling map */
    double ms_denoise, ms_error_terms, ms_blocks, ms_stopping, ms_percentiles,
        ms_sampling;
    mcp_variance_source variance_source; /* what the dump's variance rests on */
    double variance_dof;                 /* its degrees of freedom (0: many/unknown) */
    int s2_pool;                         /* the radius s² was pooled over */
    int probe_floor;                     /* the radius of the probes' variance floor */
    int probes;                          /* the probes it took */
    int sure_groups;        /* the groups SURE's covariance came from; 0: the probes' */
    int probes_from_groups; /* 1: the probes were drawn from the groups' variance (a
                               per-sample variance off from it: docs/estimate.md) */
} mcp_estimate;

MCP_API int mcp_estimate_compute(const mcp_dump *dump, const mcp_denoiser *den,
                                 const mcp_estimate_options *opt, mcp_estimate **out);
MCP_API void mcp_estimate_free(mcp_estimate *est);

/* The true per-value error of a denoised image against the reference μ in a metric
 * (docs/mathematics.md §2.9): (F - μ)², scaled by maxc(F)² + EPS_REL for
 * relse, or (M(F - μ))² / (maxc(MF)² + EPS_REL) for relse-perceptual. */
MCP_API int mcp_true_error(const mcp_image *denoised, const mcp_image *reference,
                           mcp_error_metric metric, double ppd, mcp_image **out);

/* Nearest-rank percentiles of every value of a 3-channel image: element
 * ceil(p n) - 1 of the ascending sort (p = 0: the smallest), as metrics.h. */
MCP_API int mcp_true_percentiles(const mcp_image *err, const double *p, int n,
                                 double *out);

/* ---- a progressive render: when is each τ reached? (Firmino 2024 Table 1) ---- */

typedef struct mcp_series_point {
    double spp;
    double cdf[MCP_ESTIMATE_MAX_TAUS];      /* estimated F(τ_j) */
    int stop[MCP_ESTIMATE_MAX_TAUS];        /* F(τ_j) >= p */
    double true_cdf[MCP_ESTIMATE_MAX_TAUS]; /* fraction of true errors <= τ_j */
    int true_stop[MCP_ESTIMATE_MAX_TAUS];   /* true percentile at p <= τ_j */
    double est_percentile[MCP_ESTIMATE_MAX_PERCENTILES];
    double true_percentile[MCP_ESTIMATE_MAX_PERCENTILES];
    double true_mean_error; /* mean true error (NAN without reference) */
    double est_mean_error;  /* mean s²(λ + 1) */
    int sure_groups;        /* the groups SURE's covariance came from; 0: the probes' */
    int probes_from_groups; /* 1: its probes were drawn from the groups' variance */
    int held; /* 1: F(τ_j) >= p for some τ_j, but a member before the third of one
                 render's checkpoints may not stop (its SURE has no groups yet;
                 docs/fidelity.md "Holding the first two checkpoints") */
} mcp_series_point;

typedef struct mcp_series_estimate {
    int count; /* members */
    mcp_series_point *points;
    int n_taus;
    double taus[MCP_ESTIMATE_MAX_TAUS];
    double p;
    int n_percentiles;
    double percentiles[MCP_ESTIMATE_MAX_PERCENTILES];
    int has_reference;
    /* first spp at which F(τ_j) >= p (estimated) and at which the true percentile
     * is <= τ_j; 0 when never within the series */
    double first_spp[MCP_ESTIMATE_MAX_TAUS];
    double true_first_spp[MCP_ESTIMATE_MAX_TAUS];
    int agree[MCP_ESTIMATE_MAX_TAUS];    /* mcp_stop_agrees (with a reference) */
    mcp_variance_source variance_source; /* the last member's */
    /* Σ(the last member's own Variance/n) / Σ(the spread of the increments before it):
     * how far the renderer's per-sample variance overstates (> 1) the variance of the
     * mean that the series itself shows; 0 when not measurable (no per-sample
     * variance, or fewer than two blocks) */
    double variance_ratio;
} mcp_series_estimate;

typedef struct mcp_series_estimate_options {
    mcp_estimate_options est;           /* est.tau is ignored: taus are used */
    int n_taus;                         /* [3] */
    double taus[MCP_ESTIMATE_MAX_TAUS]; /* [0.05, 0.02, 0.01] */
} mcp_series_estimate_options;

MCP_API mcp_series_estimate_options mcp_series_estimate_defaults(void);

/* Runs the estimate on every member of a series (loaded one at a time), and, with a
 * reference (may be NULL), the truth beside it. progress (may be NULL) is called
 * after each member. */
MCP_API int mcp_estimate_series(const mcp_series *series, const mcp_denoiser *den,
                                const mcp_series_estimate_options *opt,
                                const mcp_image *reference,
                                void (*progress)(int done, int total, void *ctx),
                                void *ctx, mcp_series_estimate **out);
/* As mcp_estimate_series, with a callback after each member that can end the series
 * (Python's Ctrl-C): a non-zero return fails the call with the message it set (else
 * "estimate: stopped after member N"). on_member may be NULL. */
MCP_API int mcp_estimate_series_each(const mcp_series *series, const mcp_denoiser *den,
                                     const mcp_series_estimate_options *opt,
                                     const mcp_image *reference,
                                     int (*on_member)(int done, int total, void *ctx),
                                     void *ctx, mcp_series_estimate **out);
MCP_API void mcp_series_estimate_free(mcp_series_estimate *s);

/* Agreement of a stopping spp with the true one (Firmino 2024 §5): equal, within one
 * step of the series (adjacent members), or within a third of the true count; both 0
 * (never reached) also agree. spps: the series' counts, ascending. */
MCP_API int mcp_stop_agrees(double est_spp, double true_spp, const double *spps, int n);

/* ---- the adaptive-sampling loop (estimate/adaptive.c; Firmino 2023 §4) ---- */

/* Where the next pass puts its samples: a sampling map of mcp_sampling_map (its three
 * kinds, the same names), or the same count in every pixel. */
typedef enum {
    MCP_ADAPTIVE_VARIANCE = 0, /* "variance"   */
    MCP_ADAPTIVE_TONEMAPPED,   /* "tonemapped" */
    MCP_ADAPTIVE_MC_SURE,      /* "mc-sure"    */
    MCP_ADAPTIVE_UNIFORM       /* "uniform"    */
} mcp_adaptive_map;

MCP_API extern const mcp_wordlist mcp_adaptive_map_words;
MCP_API const char *mcp_adaptive_map_name(mcp_adaptive_map map);

typedef struct mcp_adaptive_options {
    mcp_estimate_options est; /* the estimate of every iteration; its sampling.kind and
                                 budget are the loop's to set [defaults, no
                                 percentiles] */
    mcp_adaptive_map map;     /* [variance] */
    double spp_per_iteration; /* new samples per pixel per pass, on average [32] */
    double initial_spp;       /* the first, uniform pass; 0: spp_per_iteration [0] */
    double budget_spp;        /* stop once this many samples per pixel (on average) are
                                 rendered; the last pass is cut to land on it exactly;
                                 0: no budget [0] */
    int stop_on_estimate;     /* stop when the estimate says F(tau) >= p [0] */
    int max_iterations;       /* passes at most [1000] */
    int quantum;              /* every count is a multiple of this: k^2 for a renderer
                                 whose samples come in stratified passes of k^2 [1] */
    double uniform_mix;       /* share of every adaptive pass spread evenly over the
                                 pixels, the rest placed by the map: a floor under the
                                 counts for the rare paths (fireflies) that a pixel has
                                 not drawn yet, so the map cannot see [0] */
} mcp_adaptive_options;

MCP_API mcp_adaptive_options mcp_adaptive_defaults(void);
/* Checks every field, naming it; a budget or stop_on_estimate is required. */
MCP_API int mcp_adaptive_check(const mcp_adaptive_options *opt);

/* Renders pass `pass` with counts(p) new samples in pixel p (channel "SampleCount"),
 * from samples no earlier pass used, into *out: a dump whose per-pixel sample count is
 * counts (a spp_map equal to it, or a scalar spp where counts are all equal). */
typedef int (*mcp_adaptive_render_fn)(int pass, const mcp_image *counts, mcp_dump **out,
                                      void *ctx);

/* The figures of one pass. */
typedef struct mcp_adaptive_iteration {
    int pass;
    int64_t samples;       /* rendered in this pass: the sum of its counts */
    int64_t total_samples; /* in the accumulated dump */
    double mean_spp;       /* total_samples / pixels */
    double est_error;      /* the estimate's mean scaled error, mean s^2 (lambda + 1) */
    double cdf_at_tau;     /* F(tau) */
    int stop;              /* F(tau) >= p */
    double relmse;         /* of the denoised image against the reference (NAN: none) */
    double relmse_noisy;   /* of the accumulated mean (NAN: none) */
    /* wall-clock milliseconds: the render command, merging the pass in, the denoiser
     * with its JVPs (est ms_denoise), the rest of the estimate, the next counts */
    double ms_render, ms_merge, ms_denoise, ms_estimate, ms_counts;
} mcp_adaptive_iteration;

/* What an iteration's callback sees; everything is borrowed for the call. */
typedef struct mcp_adaptive_state {
    const mcp_adaptive_iteration *it;
    const mcp_image *counts;      /* what this pass rendered */
    const mcp_dump *accumulated;  /* every pass so far */
    const mcp_estimate *est;      /* on accumulated: denoised image, maps */
    const mcp_image *next_counts; /* for the next pass; NULL after the last */
} mcp_adaptive_state;

typedef enum {
    MCP_ADAPTIVE_STOP_BUDGET = 0, /* the budget is rendered */
    MCP_ADAPTIVE_STOP_ESTIMATE,   /* the estimate said F(tau) >= p */
    MCP_ADAPTIVE_STOP_ITERATIONS  /* max_iterations passes */
} mcp_adaptive_stop;

typedef struct mcp_adaptive_result {
    int count; /* passes */
    mcp_adaptive_iteration *iterations;
    mcp_dump *accumulated; /* every pass merged (pooled: exact per-pixel sums) */
    mcp_image *denoised;   /* the last estimate's F */
    mcp_adaptive_stop stopped_by;
} mcp_adaptive_result;

MCP_API void mcp_adaptive_result_free(mcp_adaptive_result *r);

/* The loop of Firmino 2023: pass 0 renders initial_spp uniformly; then every pass
 * is merged into the accumulated dump (mcp_dump_merge, pooled: per-pixel means and
 * variances as one render of all the samples), the accumulated dump is denoised and
 * estimated (mcp_estimate_compute), and the map's integer counts for the next pass
 * (mcp_sample_counts on the sampling map, in units of quantum) sum exactly to
 * min(spp_per_iteration, what is left of the budget) x pixels, until a stop rule
 * holds. reference (may be NULL) gives relmse. on_iteration (may be NULL) runs after
 * every pass; a non-zero return stops the loop with that error. opt may be NULL
 * (then a budget is missing: it fails). */
MCP_API int mcp_adaptive_run(int width, int height, const mcp_denoiser *den,
                             const mcp_adaptive_options *opt,
                             mcp_adaptive_render_fn render, void *render_ctx,
                             const mcp_image *reference,
                             int (*on_iteration)(const mcp_adaptive_state *, void *),
                             void *ctx, mcp_adaptive_result **out);

/* The uniform samples per pixel at which a uniform run's curve (mean_spp ascending,
 * error) reaches `error`, interpolated linearly in log spp and log error between the
 * two passes that bracket it; NAN when the curve never reaches it (or starts below
 * it: then below its first point). Equal-error speed-up = this / the method's spp. */
MCP_API double mcp_equal_error_spp(const double *spp, const double *error, int n,
                                   double target);

/* ---- the renderers' own adaptive stopping rule (estimate/renderer_rule.c) ----
 *
 * What Cycles (and Mitsuba 3's adaptive_sampling integrator) do, as a baseline for the
 * maps above (docs/adaptive.md, "The renderers' own rule"): every `step` samples,
 * once past min_samples, a pixel still sampling compares its mean I with the mean A of
 * its half buffer (the samples of class A, about every other one):
 *     error = (|I_r - A_r| + |I_g - A_g| + |I_b - A_b|) / (1e-4 + s(I)),
 *     s(I) = sqrt(I_r + I_g + I_b) below 1, I_r + I_g + I_b above,
 * and stops for good when error < 5 x threshold; then every pixel within `dilate`
 * pixels (a (2 dilate + 1)^2 square) of one that has not stopped samples on. */

typedef struct mcp_renderer_rule_options {
    double threshold; /* Cycles' noise threshold (its UI's number; the error is
                         compared with 5 x it, as Cycles does) [0.01] */
    int min_samples;  /* checks start once a pixel has more than min_samples + 1;
                         0: Cycles' automatic max(4, ceil(16 / threshold^0.3)) [0] */
    int step;         /* samples between two checks (Cycles: 16) [16] */
    int max_spp;      /* samples per pixel at most (Cycles' sample count) [1024] */
    int dilate;       /* radius of the square that an unstopped pixel keeps
                         sampling (Cycles: 1, 3x3); 0: none [1] */
    int record_every; /* denoise and record a point when the samples of an unstopped
                         pixel are a multiple of this, and at the end [step] */
} mcp_renderer_rule_options;

MCP_API mcp_renderer_rule_options mcp_renderer_rule_defaults(void);
/* Checks every field, naming it. */
MCP_API int mcp_renderer_rule_check(const mcp_renderer_rule_options *opt);
/* min_samples, or Cycles' automatic value for the threshold when it is 0. */
MCP_API int mcp_renderer_rule_min_samples(const mcp_renderer_rule_options *opt);

/* The error of one pixel (the formula above) from its mean and its half buffer's. */
MCP_API double mcp_renderer_rule_pixel_error(const float mean[3], const float half[3]);

/* One check: every pixel with converged[i] == 0 (row-major) gets 1 when its error is
 * below 5 x threshold; then every pixel within `dilate` of one still at 0 is set to
 * 0 (a stopped pixel next to an unstopped one samples again, as in Cycles). mean and
 * half: 3 channels R, G, B (more are ignored), the same size. Returns how many pixels
 * are still sampling (converged[i] == 0), or -1 with an error. */
MCP_API long mcp_renderer_rule_update(const mcp_image *mean, const mcp_image *half,
                                      double threshold, int dilate,
                                      unsigned char *converged);

/* Renders pass `pass` with counts(p) new samples in pixel p, as mcp_adaptive_render_fn,
 * and its half buffer *half: channels R, G, B the mean of the pass's class-A samples
 * and SampleCount their number (mcp_proc_render_counts_half). */
typedef int (*mcp_renderer_rule_render_fn)(int pass, const mcp_image *counts,
                                           mcp_dump **out, mcp_image **half, void *ctx);

/* The state at one recorded check: what a render with the same threshold and a
 * sample count (Cycles' max samples) of max_spp gives, the passes being in lockstep. */
typedef struct mcp_renderer_rule_point {
    int max_spp;         /* samples of a pixel that never stopped */
    double mean_spp;     /* samples rendered / pixels */
    long active;         /* pixels still sampling after this check */
    double relmse;       /* of the denoised image (NAN without a reference) */
    double relmse_noisy; /* of the accumulated mean */
} mcp_renderer_rule_point;

typedef struct mcp_renderer_rule_result {
    int count;
    mcp_renderer_rule_point *points;
    int min_samples;       /* the one used */
    mcp_dump *accumulated; /* every pass merged (pooled) */
    mcp_image *denoised;   /* F of the last point */
} mcp_renderer_rule_result;

MCP_API void mcp_renderer_rule_result_free(mcp_renderer_rule_result *r);

/* Runs the rule: pass k renders `step` samples (fewer at the end, to land on max_spp)
 * in every pixel still sampling and none in the others; the passes are merged as in
 * mcp_adaptive_run, the half buffers summed; the check runs after every pass once
 * past min_samples; it ends at max_spp or when every pixel has stopped. reference may
 * be NULL. */
MCP_API int mcp_renderer_rule_run(int width, int height, const mcp_denoiser *den,
                                  const mcp_renderer_rule_options *opt,
                                  mcp_renderer_rule_render_fn render, void *render_ctx,
                                  const mcp_image *reference,
                                  mcp_renderer_rule_result **out);

#ifdef __cplusplus
}
#endif
#endif
