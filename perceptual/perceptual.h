/* perceptual.h: perceptual error optimisation of Monte Carlo renders
 * (docs/mathematics.md §4; Chizhov et al. 2022).
 *
 * The error model (Eq. 15 with Eq. 16/21):
 *
 *     E_C(O) = sum_p (1 - C_p) |g|_1^2 |T(O_p) - T(Q_init,p)|^2
 *            + sum_q C_q sum_c ((g * T(O_c))_q - (h * T(I'_c))_q)^2
 *
 * g the perceptual kernel (3-tap separable [default], a Gaussian from viewing distance
 * and dpi, or any user kernel), h = delta [or g], T a tone map (clamp [default], ACES,
 * none), I' the surrogate, C the confidence in it (a scalar [1] or a per-pixel map),
 * Q_init the candidates' mean. Convolutions use replicate borders. With C = 1 and the
 * ground truth as I', E / (N C) is the pMSE of metrics.h.
 *
 * Vertical methods choose, per pixel, one of M candidate values (M images of few
 * samples each): iterative minimisation (direct binary search), the same over the
 * power set of the candidates, error diffusion and dithering with a blue-noise mask.
 * Horizontal methods permute one image's pixels (and hence its seeds) within small
 * windows and output the permutation so that a renderer can re-render with it. The
 * baselines of Heitz & Belcour 2019 (histogram, permutation) are here for comparison.
 *
 * Every image is RGB (channels found with mcp_rgb_channels); results are new packed
 * images owned by the caller. */
#ifndef MCP_PERCEPTUAL_H
#define MCP_PERCEPTUAL_H

#include <stdint.h>
#include <mcpost/tonemap.h>
#include <mcpost/denoiser.h>
#include <cjson/cJSON.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- the error model ---- */

typedef struct mcp_perc_model {
    mcp_pkernel kernel;              /* g when no user kernel: tap3 [default] or gaussian
                                        (dpi [300], distance_in [16]) */
    const double *user_kernel;       /* any 2D kernel, row-major, used as given (not
                                        normalised); borrowed [NULL] */
    int user_kernel_width;           /* odd [0] */
    int user_kernel_height;          /* odd [0] */
    int filter_surrogate;            /* h = g instead of h = delta [0] */
    mcp_tonemap tone_map;            /* T [clamp] */
    double confidence;               /* C in [0, 1] [1] */
    const mcp_image *confidence_map; /* per-pixel C (channel 0, values in [0, 1]),
                                        overrides confidence; borrowed [NULL] */
} mcp_perc_model;

MCP_API mcp_perc_model mcp_perc_model_defaults(void);

/* E_C(img) by direct summation in double (no incremental state). qinit may be NULL
 * when C = 1 everywhere. model may be NULL (defaults). */
MCP_API int mcp_perc_energy(const mcp_image *img, const mcp_image *surrogate,
                            const mcp_image *qinit, const mcp_perc_model *model,
                            double *energy);

/* ---- the blue-noise mask (void and cluster, Ulichney 1993) ---- */

typedef struct mcp_blue_noise_options {
    int size;              /* side of the square, toroidal mask [128] */
    double sigma;          /* Gaussian energy filter in pixels [1.5] */
    uint64_t seed;         /* initial random pattern [1] */
    int use_cache;         /* read/write the cache folder [1] */
    const char *cache_dir; /* [NULL: $XDG_CACHE_HOME/mcpost, else ~/.cache/mcpost] */
} mcp_blue_noise_options;

MCP_API mcp_blue_noise_options mcp_blue_noise_defaults(void);

/* The void-and-cluster ranks: rank[y * size + x] is a permutation of 0..size^2 - 1,
 * deterministic for (size, sigma, seed). */
MCP_API int mcp_void_and_cluster(int size, double sigma, uint64_t seed, int *rank);

/* The mask as thresholds B = (rank + 0.5) / size^2 in (0, 1), one channel "B",
 * generated or read from the cache (a cache that cannot be read or written is
 * skipped: the mask is then generated). opt may be NULL. */
MCP_API int mcp_blue_noise_mask(const mcp_blue_noise_options *opt, mcp_image **out);

/* ---- methods ---- */

typedef enum {
    MCP_PERC_VERTICAL_ITERATIVE, /* "vertical-iterative" */
    MCP_PERC_POWER_SET,          /* "power-set" */
    MCP_PERC_ERROR_DIFFUSION,    /* "error-diffusion" */
    MCP_PERC_DITHER,             /* "dither" */
    MCP_PERC_HORIZONTAL,         /* "horizontal" */
    MCP_PERC_HISTOGRAM,          /* "histogram" (Heitz & Belcour 2019) */
    MCP_PERC_PERMUTATION,        /* "permutation" (Heitz & Belcour 2019) */
    MCP_PERC_N_METHODS
} mcp_perc_method;

MCP_API extern const mcp_wordlist mcp_perc_method_words;
MCP_API const char *mcp_perc_method_name(mcp_perc_method method);

typedef enum {
    MCP_PERC_INIT_RANDOM, /* a random candidate per pixel, from (seed, pixel) */
    MCP_PERC_INIT_MEAN    /* the candidates' mean (not itself a candidate) */
} mcp_perc_init;

MCP_API extern const mcp_wordlist mcp_perc_init_words;

typedef struct mcp_perc_options {
    mcp_perc_method method; /* [vertical-iterative] */
    mcp_perc_model model;
    int passes;                  /* T; 0: the method's own default, 100 for the vertical
                                    iterative methods, 10 for horizontal [0] */
    mcp_perc_init init;          /* start of the vertical iterative methods [random] */
    uint64_t seed;               /* random start [1] */
    int max_subsets;             /* power set: at most this many subset means [64] */
    int radius;                  /* horizontal: swap window (2R+1)^2 [1] */
    int travel;                  /* horizontal: how far (max norm) a pixel may travel
                                    from its origin [1] */
    int tile;                    /* permutation baseline: tile side [8] */
    mcp_blue_noise_options mask; /* dithering and the baselines */
    const mcp_image *mask_image; /* a threshold mask of your own (channel 0, values in
                                    [0, 1), tiled) instead of the generated one;
                                    borrowed [NULL] */
} mcp_perc_options;

MCP_API mcp_perc_options mcp_perc_defaults(void);

/* Checks every field; fails naming it ("perceptual: travel must be >= radius ..."). */
MCP_API int mcp_perc_check(const mcp_perc_options *opt);

typedef struct mcp_perc_result {
    mcp_image *image;       /* R, G, B: the optimised image; for horizontal methods the
                               prediction pi(Q) */
    mcp_image *index;       /* vertical methods: channel "index", the candidate (or
                               subset) each pixel took; else NULL */
    mcp_image *permutation; /* horizontal methods: channels X, Y, the source pixel
                               whose seed each pixel uses; else NULL */
    int passes;             /* passes run (iterative methods; 1 for one-pass methods) */
    long changes;           /* accepted changes (or swaps) over all passes */
    double energy_initial;  /* E_C at the start (iterative methods; else NaN) */
    double energy_final;    /* E_C of the result (iterative methods; else NaN:
                               mcp_perc_energy or mcp_perc_score compute it) */
    double seconds;         /* wall time of the optimisation itself */
} mcp_perc_result;

MCP_API void mcp_perc_result_free(mcp_perc_result *r);

/* Runs opt->method on the m candidates against the surrogate. Horizontal methods use
 * the candidates' mean as their one estimate per pixel. opt may be NULL. *out is
 * zeroed first and left zeroed on failure. */
MCP_API int mcp_perc_optimize(const mcp_image *const *cands, int m,
                              const mcp_image *surrogate, const mcp_perc_options *opt,
                              mcp_perc_result *out);

/* The power set's search space: the means of the non-empty subsets of the m
 * candidates, at most max_subsets of them, in this order: the m single candidates,
 * the mean of all m, then pairs, triples, ... (each size in lexicographic order).
 * masks[k] (bit i: candidate i) may be NULL; otherwise it receives *count masks
 * (the caller gives room for min(max_subsets, 2^m - 1)). */
MCP_API int mcp_perc_subset_masks(int m, int max_subsets, uint64_t *masks, int *count);

/* ---- surrogates ---- */

/* The per-pixel mean of the candidates (R, G, B). */
MCP_API int mcp_perc_mean(const mcp_image *const *cands, int m, mcp_image **out);

/* The denoiser applied to the candidates' mean, with optional albedo and normal
 * features (NULL: none). */
MCP_API int mcp_perc_surrogate_denoise(const mcp_image *const *cands, int m,
                                       const mcp_image *albedo, const mcp_image *normal,
                                       const mcp_denoiser *den, mcp_image **out);

/* ---- measuring ---- */

typedef struct mcp_perc_scores {
    double energy;            /* E_C against the surrogate, / (N C) */
    double pmse;              /* against the reference (metrics.h; the model's kernel,
                                 h and tone map, C = 1); NaN without one */
    double mse;               /* against the reference; NaN without one */
    double low_freq_fraction; /* spectra.h's blue-noise figure of T(img) - T(ref); NaN
                                 without a reference or below one tile */
    double white_fraction;    /* what white noise would give there */
} mcp_perc_scores;

/* Scores img: against the surrogate (with qinit, the candidates' mean, when the model's
 * confidence is below 1; else it may be NULL) and, when reference is not NULL, against
 * it. spectrum (may be NULL) receives the tiled spectrum picture ("spectrum") when it
 * is computed. */
MCP_API int mcp_perc_score(const mcp_image *img, const mcp_image *surrogate,
                           const mcp_image *qinit, const mcp_image *reference,
                           const mcp_perc_model *model, int spectra_tile,
                           mcp_perc_scores *out, mcp_image **spectrum);

/* ---- comparison ---- */

/* Re-renders with a permutation map for the comparison (e.g. by running the
 * procedural renderer); *out receives the new estimate (R, G, B). */
typedef int (*mcp_perc_rerender_fn)(void *ctx, mcp_perc_method method,
                                    const mcp_image *permutation, mcp_image **out);

/* Sees every method's result during the comparison (to write its images, say);
 * rerendered is NULL unless a rerender function made one. Returns 0 or -1. */
typedef int (*mcp_perc_result_fn)(void *ctx, mcp_perc_method method,
                                  const mcp_perc_result *result,
                                  const mcp_image *rerendered);

typedef struct mcp_perc_compare_options {
    mcp_perc_options base;         /* settings shared by every method */
    const mcp_image *reference;    /* ground truth for pMSE/MSE/spectra [NULL] */
    int spectra_tile;              /* blue-noise analysis tiles (spectra.h) [32] */
    mcp_perc_rerender_fn rerender; /* [NULL: horizontal rows show the prediction] */
    void *rerender_ctx;
    mcp_perc_result_fn on_result; /* [NULL] */
    void *on_result_ctx;
} mcp_perc_compare_options;

MCP_API mcp_perc_compare_options mcp_perc_compare_defaults(void);

/* The comparison of every method on one input (Chizhov et al. 2022, Table 1): a JSON
 * array of rows {"method", "energy" (E_C against the surrogate / (N C)), and with a
 * reference "pmse", "mse", "low_freq_fraction"; "seconds", "passes"}, the first row
 * being the candidates' mean ("mean") and, with a reference, the surrogate. Horizontal
 * rows measure the re-rendered image when a rerender function is given ("rerendered":
 * true), else the prediction. */
MCP_API int mcp_perc_compare(const mcp_image *const *cands, int m,
                             const mcp_image *surrogate,
                             const mcp_perc_compare_options *opt, cJSON **table);

#ifdef __cplusplus
}
#endif
#endif
