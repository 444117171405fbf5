/* internal.h: helpers shared inside estimate/ (not installed; no other module includes
 * it). One section per concern; add new sections at the end. */
#ifndef MCP_ESTIMATE_INTERNAL_H
#define MCP_ESTIMATE_INTERNAL_H

#include <mcpost/denoiser.h>

#include "../ops/internal.h"

#include <stddef.h>

/* ---- denoisers (denoisers.c, denoise_*.c; docs/mathematics.md §2.1) ---- */

/* A data file of share/mcpost/ (common/core/paths.c): 0 and its path in buf, or -1. */
int mcp__find_data_file(const char *name, char *buf, size_t cap);
/* A command under /bin/sh with mcpost's programs on the end of its PATH, and its
 * status checked into one error line (common/core/shell.c, common/core/internal.h). */
int mcp__shell(const char *command);
int mcp__shell_check(int status, const char *what, const char *command);
/* A scratch folder PARENT/PREFIXxxxxxx, removed by end or, if the process is stopped
 * by SIGINT, SIGTERM or SIGHUP first, by the signal handler (common/io/outdir.c,
 * common/io/internal.h). */
int mcp__scratch_dir_begin(const char *parent, const char *prefix, char *dir, size_t cap);
void mcp__scratch_dir_end(const char *dir);
int mcp__shell_fill(const char *tmpl, int n, const char *const *names,
                    const char *const *values, unsigned quoted, char **out);

/* The built-in kinds; denoisers.c lists them in its table. */
extern const mcp_denoiser_kind mcp__denoiser_gauss;
/* The settings' tables of the kinds that have one, and the keys taken from them
 * (filled in by denoisers.c before a kind is handed out). */
#define MCP__DENOISER_KEYS_MAX 32
extern const mcp_operation mcp__op_gauss, mcp__op_nlm, mcp__op_bilateral, mcp__op_unet,
    mcp__op_external;
extern const char *mcp__gauss_keys[MCP__DENOISER_KEYS_MAX];
extern const char *mcp__nlm_keys[MCP__DENOISER_KEYS_MAX];
extern const char *mcp__unet_keys[MCP__DENOISER_KEYS_MAX];
extern const char *mcp__external_keys[MCP__DENOISER_KEYS_MAX];
extern const mcp_denoiser_kind mcp__denoiser_nlm;
/* The James-Stein post-correction around another kind; it lives with the combiner in
 * blend/ (blend/denoise_james_stein.c). */
extern const mcp_denoiser_kind mcp__denoiser_james_stein;
/* The denoiser used when none is named (denoise_default.c). */
extern const mcp_denoiser_kind mcp__denoiser_default;

/* Checks an input for denoiser `who`: colour present with 3 channels; albedo, normal
 * and variance, when given, 3 channels and the colour's size. */
int mcp__denoise_check_input(const char *who, const mcp_denoise_input *in);

/* Checks n >= 0 tangents against the input `at`: each colour part present, 3 channels,
 * same size; feature parts optional, checked the same way when given. */
int mcp__denoise_check_tangents(const char *who, const mcp_denoise_input *at,
                                const mcp_denoise_tangent *t, int n);

/* The `unet` inside a `default` denoiser (denoise_default.c): what it runs on inputs
 * with albedo and normal; NULL for any other denoiser, or when no weights were found. */
const mcp_denoiser *mcp__default_unet(const mcp_denoiser *d);

/* A new zero-filled packed image with channels R, G, B labelled `source`. */
int mcp__rgb_new(int width, int height, const char *source, mcp_image **out);

/* A new denoiser with the common fields set, a zeroed state block of state_size bytes
 * (freed with it) and a destroy that frees both; NULL with an error on failure. */
mcp_denoiser *mcp__denoiser_new(const char *name, size_t state_size);

/* ---- error estimation (probes.c, sure.c, variance.c, sampling_map.c, blockavg.c,
 *      stopping.c, estimate.c; docs/mathematics.md §2.2-§2.8) ---- */

#include <stdint.h>
#include <mcpost/estimate.h>

#include "../common/core/rng_internal.h"

/* A counter-based random stream (splitmix64, common/core/rng_internal.h) keyed by (seed,
 * stream kind, probe, pixel index): the same numbers whatever the thread count
 * (probes.c). */
typedef struct mcp__rng {
    uint64_t state;
    double spare; /* the second Box-Muller normal */
    int has_spare;
} mcp__rng;

void mcp__rng_init(mcp__rng *r, uint64_t seed, uint64_t stream, uint64_t k,
                   uint64_t index);
uint64_t mcp__rng_u64(mcp__rng *r);
double mcp__rng_normal(mcp__rng *r);
/* Box-Muller's own ln u for u in (0, 1] and sin, cos of 2 pi u for u in [0, 1)
 * (probes.c), exposed for their test. */
float mcp__log_unit(float u);
void mcp__sincos_turn(float u, float *s, float *c);

/* The rows of probe k from row0 on, of an image as wide as the dump: `dump` holds the
 * image's rows row0 .. row0 + its height (a band of a dump read in bands), and the
 * probe is those rows of the whole image's probe, bit for bit (the stream is keyed by
 * the pixel's index in the image). mcp_probe_gaussian and mcp_probe_rademacher are
 * row0 = 0 (probes.c). */
int mcp__probe_gaussian_rows(const mcp_dump *dump, int row0,
                             const mcp_feature_covariance *features, uint64_t seed, int k,
                             mcp_probe *out);
int mcp__probe_rademacher_rows(const mcp_dump *dump, int row0, uint64_t seed, int k,
                               mcp_image **out);

/* The variance the probes are drawn from, each value raised to the median of its
 * (2 radius + 1)² window where below it, and the colour covariance (if cov and the dump
 * has one) scaled to keep its correlations; radius 0 copies them (probe_floor.c). */
#define MCP__PROBE_FLOOR_MAX 16
int mcp__probe_variance_floor(const mcp_dump *d, int radius, mcp_image **var,
                              mcp_image **cov);

/* The parts of a dump that neither the denoiser nor joint SURE (sure_features) reads,
 * as MCP__DUMP_NO_* flags (common/dump/internal.h): the estimate, the series estimate
 * and the blend load their dumps without them (estimate.c). */
unsigned mcp__dump_parts_unread(const mcp_denoiser *den, int sure_features);

/* λ of each block's values, a value per pixel (3 channels, "lambda.R" ...), and with
 * with_s2 the distribution's s² beside it: mcp_error_dist_image's 6 channels
 * (stopping.c). distribution.exr holds λ alone (jobs/estimate_output.c). */
int mcp__error_dist_image(const mcp_error_dist *d, int with_s2, mcp_image **out);

/* Each block's mean of values (R, G, B: blocks->count x 3, malloc'd; NULL when out
 * of memory), summed in double over its rows in order: the values of
 * mcp_blocks_mean_image (blockavg.c). */
float *mcp__blocks_means(const mcp_blocks *blocks, const mcp_image *values);

/* mcp_block_average, except that a quiet block, one where Σ̂^r and the model's s² (s2:
 * the distribution's Var^r) are 0 in every pixel and channel, is not cut. Every value in
 * it has s = 0, so F_i = 1 whatever its block's λ: F(τ) and the percentiles are those of
 * Alg. 1, whose every cut there passes wherever SURE is above 0 (its Σ̂ are 0) and ends
 * in a block per pixel: a dump without variance (1 spp), or a region without any (a
 * noiseless textured background), at 8K 33 million blocks and 18 GB (blockavg.c). */
int mcp__block_average_quiet(const mcp_image *sure_rel, const mcp_image *sigma_rel,
                             const mcp_image *s2, const mcp_block_options *opt,
                             mcp_blocks **out);

/* Fails naming `who` when the dump lacks colour or the variance of the mean. */
int mcp__check_dump(const char *who, const mcp_dump *dump);
/* What to do about a dump without variance: the recipe for a Cycles render, else
 * `otherwise` (common/dump/dump.c, common/dump/internal.h). */
const char *mcp__no_variance_hint(const mcp_dump *d, const char *otherwise);

/* The values of given ranks among n floats without sorting them
 * (common/core/select.c). */
int mcp__select_ranks(const float *v, size_t n, const size_t *ranks, int k, float *out);
int mcp__select_percentiles(const float *v, size_t n, const double *p, int k,
                            double *out);

/* A new zero-filled packed image of n channels (names NULL: R, G, B), labelled source
 * (sure.c). */
int mcp__image_new(int width, int height, int n, const char *const *names,
                   const char *source, mcp_image **out);

/* A view of rows [y0, y1) of img, or NULL (and 0) for no image (sure.c). */
int mcp__rows_view(const mcp_image *img, int y0, int y1, mcp_image **out);

/* J t_k by the denoiser's jvp, or by finite differences (step delta) when fd is set or
 * the denoiser has no jvp (sure.c). */
int mcp__jvp(const mcp_denoiser *den, const mcp_denoise_input *at,
             const mcp_denoise_tangent *t, int n, int fd, double delta,
             mcp_image **primal, mcp_image **out);

/* The error maps made band by band (estimate_bands.c): begin allocates every map of
 * a w x h image (but the denoised image) for metric se or relse; rows writes rows
 * [y0, y0 + rows' height) of them from that band's dump rows, F, probes and JVPs (all
 * of the band's height), the values the whole image's maps have there (sure.c). */
int mcp__error_maps_begin(int w, int h, mcp_error_metric metric, mcp_error_maps *m);
int mcp__error_maps_rows(const mcp_dump *rows, const mcp_image *f,
                         const mcp_image *const *eps, const mcp_image *const *jeps, int k,
                         int y0, mcp_error_maps *m);

/* The rows of a band for the estimate's evaluation in bands of a w x h image, or 0 to
 * evaluate it whole: bands where the whole evaluation's probes and JVPs would pass
 * 1 GB and the bands are exact (a denoiser with a band_halo, the metric se or relse,
 * Gaussian probes of the dump's own variance); MCPOST_ESTIMATE_BAND_ROWS=N forces N,
 * =whole none (for tests); streamed, the rows of mcp__error_maps_streamed's bands,
 * which hold the band's maps too. The maps (and their F(X)) made so, the same values as
 * mcp__error_maps_from_own_probes after a whole evaluation; progress(ctx, fraction)
 * after each band (estimate_bands.c). */
int mcp__estimate_band_rows(int w, int h, const mcp_denoiser *den,
                            const mcp_estimate_options *o, int streamed);
int mcp__error_maps_in_bands(const mcp_dump *dump, const mcp_denoiser *den,
                             const mcp_estimate_options *o, int band_rows,
                             void (*progress)(void *ctx, double done), void *ctx,
                             mcp_error_maps *out);

/* The rows of an estimate's images that a streamed estimate hands out as its bands are
 * evaluated, instead of holding them whole: rows [y0, y1) of the width x height image
 * of F(X), SURE and Var[F] pooled as the estimate pools it (each a view of those rows
 * alone; the estimate's maps keep them NULL). */
typedef struct mcp__estimate_rows {
    int y0, y1, width, height;
    const mcp_image *denoised, *sure, *var;
    const mcp_attrs *denoised_attrs; /* F(X)'s header attributes (views carry none) */
} mcp__estimate_rows;
typedef struct mcp__estimate_sink {
    int (*rows)(void *ctx, const mcp__estimate_rows *rows);
    void *ctx;
} mcp__estimate_sink;

struct mcp__dump_held; /* common/dump/internal.h */
/* The streamed estimate's evaluation (estimate_bands.c): the dump read from held's
 * file a band at a time, the maps made band by band as mcp__error_maps_in_bands makes
 * them, of which only SURE^r, Var^r (unpooled) and Σ̂^r are kept whole in out; F(X),
 * SURE and Var[F] pooled by pool go to sink, and the sampling map's unblurred weights
 * (mcp__sampling_weights_rows) to *weights, made here. *any_variance: 1 when some
 * pixel has a variance above 0. band_rows must be a multiple of the EXR chunks'
 * height. */
int mcp__error_maps_streamed(struct mcp__dump_held *held, const mcp_denoiser *den,
                             const mcp_estimate_options *o, int band_rows, int pool,
                             const mcp__estimate_sink *sink,
                             void (*progress)(void *ctx, double done), void *ctx,
                             mcp_error_maps *out, mcp_image **weights, int *any_variance);

/* 1 when some pixel of a variance image (R, G, B) is above 0 (estimate.c). */
int mcp__any_variance(const mcp_image *var);

/* The sampling map in parts, for an estimate made band by band (sampling_map.c):
 * check says what is wrong with the options; weights_begin makes the w x h image of
 * unblurred weights, weights_rows fills the rows of s (the rows of dump, denoised and
 * numerator alike), finish blurs and normalises s into the map (it may replace *s). */
int mcp__sampling_check(const mcp_sampling_options *o);
int mcp__sampling_weights_begin(int w, int h, mcp_image **out);
void mcp__sampling_weights_rows(const mcp_dump *dump, const mcp_image *denoised,
                                const mcp_image *numerator, const mcp_sampling_options *o,
                                mcp_image *s);
int mcp__sampling_map_finish(mcp_image **s, const mcp_sampling_options *o);

/* An estimate of a dump read a band at a time from its file (estimate.c), for a large
 * EXR dump whose estimate goes in bands (mcp__estimate_band_rows): the dump is never
 * held whole, nor F(X), SURE and Var[F] (they go to sink as their bands are made, and
 * stay NULL in the estimate's maps, as Σ̂^r does, freed once the blocks are cut); the
 * estimate is otherwise mcp_estimate_compute's on the dump read whole with `without`.
 * *done 0 (and 0 returned) where it does not apply: the caller reads the dump whole. */
int mcp__estimate_streamed(const mcp_dump_spec *spec, unsigned without,
                           const mcp_denoiser *den, const mcp_estimate_options *opt,
                           const mcp__estimate_sink *sink, mcp_estimate **out, int *done);

/* mcp_error_maps_from_probes for a caller that is done with its evaluation: takes
 * *denoised for the maps' denoised image and may take probes[j] and jvps[j] (k of
 * each; their slots are then NULL) for five of the maps, instead of copying and
 * allocating; the caller frees what is left. The same values (sure.c). probe_var
 * (NULL: the dump's variance) is the variance the probes were drawn from where it is
 * not the dump's (the estimate's probe floor): SURE then weights each value's probe
 * terms by the dump's variance over it, so that it stays unbiased for the dump's
 * variance, while the variance maps, (Jε)², keep the probes' (relse and se only). */
#define MCP_SURE_MAX_OWN 16 /* more probes than this: copied, as the public call does */
int mcp__error_maps_from_own_probes(const mcp_dump *dump, mcp_image **denoised,
                                    mcp_image **probes, mcp_image **jvps, int k,
                                    const mcp_sure_options *opt,
                                    const mcp_image *probe_var, mcp_error_maps *out);

/* SURE's terms of series member i measured on its own samples by the delete-a-group
 * jackknife over at most `groups` (<= MCP__GROUPS_MAX) groups of its checkpoints, at
 * one denoiser apply per group (group_jackknife.c): cov = Cov(n, d) and var = Var[n]
 * per value (3 channels each). Both stay NULL (and 0 is returned) where the series
 * gives no groups: fewer than MCP__GROUPS_MIN checkpoints (the first two members), a
 * member without a scalar sample count or a
 * variance, checkpoints out of order, or members whose differences are noisier than
 * their variances say (not checkpoints of one render). */
#define MCP__GROUPS_MAX 8
#define MCP__GROUPS_MIN 3 /* fewer found than this (and than asked for): no groups */
/* The fewest groups a member's terms are taken from when `groups` are asked for. */
static inline int
mcp__groups_min(int groups)
{
    return groups < MCP__GROUPS_MIN ? groups : MCP__GROUPS_MIN;
}
/* Whether a member can give groups at all: a scalar sample count and a variance. */
static inline int
mcp__member_can_group(const mcp_dump *member)
{
    return member->var_of_mean && !member->spp_map && member->spp > 0;
}
typedef struct mcp__group_terms {
    mcp_image *cov, *var;
    int groups;      /* the groups found */
    double v_over_v; /* Σ Σ̂ / Σ V: the member's own variance over the groups' */
} mcp__group_terms;
int mcp__series_group_terms(const mcp_series *s, int i, const mcp_dump *member,
                            const mcp_denoiser *den, int groups, mcp__group_terms *out);
void mcp__group_terms_clear(mcp__group_terms *g);
/* The probes' variance over a series member whose per-sample variance overstates its
 * noise (a stratified sampler): the groups' V in its place, and the member's colour
 * covariance, if any, scaled to it so that the channels' correlations stay (a new
 * image in *cov, or NULL without one). */
int mcp__group_probe_variance(const mcp_dump *d, const mcp__group_terms *g,
                              mcp_image **cov);
/* mcp_estimate_compute with a series member's group terms (estimate.c; the series
 * estimate's step, for the tests). */
int mcp__estimate_compute_groups(const mcp_dump *dump, const mcp_denoiser *den,
                                 const mcp_estimate_options *opt,
                                 const mcp__group_terms *groups, mcp_estimate **out);

/* Per-value variance maps from n jvp images: mean_k (J v_k)² (through the CSF operator
 * for relse-perceptual), and divided by the denominator (1 channel) (variance.c). */
int mcp__variance_from_jvps(const mcp_image *const *jv, int n, mcp_error_metric metric,
                            double ppd, const mcp_image *denominator, mcp_image **var,
                            mcp_image **var_rel);

/* Wall-clock milliseconds (for the timings the pipeline reports). */
double mcp__now_ms(void);

/* ---- denoisers, continued (denoise_nlm.c) ---- */

extern const mcp_denoiser_kind mcp__denoiser_bilateral;

/* ---- denoisers, continued (denoise_external.c, denoise_unet.c) ---- */

extern const mcp_denoiser_kind mcp__denoiser_external;
extern const mcp_denoiser_kind mcp__denoiser_unet;

/* ---- the adaptive loops (adaptive.c, renderer_rule.c) ---- */

/* 0 when the pass's dump has exactly the counts it was asked to render; otherwise an
 * error naming the pixel (a renderer that ignores the counts would make every figure
 * after it wrong without a sign). */
int mcp__adaptive_check_pass(const mcp_dump *part, const mcp_image *counts, int pass);
/* Merges part into *acc, pooled (taking it when *acc is empty); takes ownership of
 * part. */
int mcp__adaptive_accumulate(mcp_dump **acc, mcp_dump *part);

/* Room for a path built from settings (a folder and a file name). */
#define PATH_CAP 4096

/* ---- not exported by libmcpost.so (docs/library.md, "Exported symbols") ---- */

int mcp_sampling_kind_from_name(const char *name, mcp_sampling_kind *out);
int mcp_adaptive_map_from_name(const char *name, mcp_adaptive_map *out);

#endif
