/* procedural.h: a procedural Monte Carlo renderer whose exact answer is known.
 *
 * A small analytic scene (a perspective ground plane with a rotated checkerboard, a
 * floating sheet with a smooth colour gradient, a soft shadow from a rectangular area
 * light, a glossy highlight and rare very bright "firefly" paths). Each pixel value is a
 * Monte Carlo integral over the pixel's box footprint and the light, lobe and firefly
 * dimensions; its samples come from a counter-based random stream seeded by
 * (seed, source pixel), so any pixel, any realization and any seed permutation can be
 * re-rendered bit-identically, whatever the thread count. The footprint point is
 * drawn independently or jittered (stratified in a k x k grid). The expectation of
 * every pixel, the per-sample variance and the variance of the pixel mean under either
 * sampler are computed by deterministic quadrature to about 1e-12. README.md beside
 * this file describes the scene. Tests and the perceptual
 * evaluation draw realizations from it (docs/mathematics.md §4.9). */
#ifndef MCP_PROCEDURAL_H
#define MCP_PROCEDURAL_H

#include <stdint.h>
#include <mcpost/dump.h>

#ifdef __cplusplus
extern "C" {
#endif

/* How the pixel-footprint point of each sample is drawn (README.md, "The stratified
 * sampler"). The light, lobe and firefly dimensions are independent either way. */
typedef enum {
    MCP_PROC_SAMPLER_INDEPENDENT = 0, /* uniform over the pixel, every sample alike */
    MCP_PROC_SAMPLER_JITTERED         /* passes of strata^2 consecutive samples; sample
                                         j of a pass lies in cell j (row-major) of a
                                         strata x strata grid of the pixel */
} mcp_proc_sampler;

/* The most cells per side: 4096 samples per pass is far more than a render needs. */
#define MCP_PROC_MAX_STRATA 64

/* What to render. Start from mcp_proc_scene_defaults(); [defaults] in brackets. */
typedef struct mcp_proc_scene {
    int width, height;          /* image size in pixels [64 x 64] */
    double firefly_probability; /* chance per ground sample of a very bright path [1e-3];
                                   0 turns fireflies off */
    double firefly_value;       /* brightness of such a path (green channel) [100] */
    int truth_order;            /* Gauss-Legendre points per triangle side in
                                   mcp_proc_truth, 1..32 [8] */
    mcp_proc_sampler sampler;   /* [MCP_PROC_SAMPLER_INDEPENDENT] */
    int strata;                 /* k of the jittered sampler, 1..64 [4]: a pass is k*k
                                   samples, and every spp (and first sample) must be
                                   a multiple of k*k; ignored by the independent
                                   sampler. k = 1 is the independent sampler. */
} mcp_proc_scene;

MCP_API mcp_proc_scene mcp_proc_scene_defaults(void);

/* Checks the fields; sets "procedural: <field> must be ... (got ...)" and returns -1. */
MCP_API int mcp_proc_scene_check(const mcp_proc_scene *scene);

/* The seed of realization r of a render seeded with seed: r = 0 gives seed itself, so
 * a plain render and realization 0 are the same; others are hashed from (seed, r). */
MCP_API uint64_t mcp_proc_realization_seed(uint64_t seed, int realization);

/* Renders spp samples per pixel (sample indices 0..spp-1 of each stream; with the
 * jittered sampler spp must be a whole number of passes, a multiple of strata^2). The
 * samples of pixel p come from the stream of pixel p, or of permutation(p) when
 * permutation is given: an image of the scene's size with channels "X" and "Y" holding
 * integer source-pixel coordinates. Only the random stream is borrowed; the integrand
 * stays that of p. *out: colour mean, var_of_mean (unbiased per-sample variance / spp; 0
 * at spp 1), albedo (mean of the sampled diffuse albedo), normal (world space), spp.
 * var_of_mean is what a real renderer reports, whatever the sampler: under the
 * jittered one it overstates the true variance of the mean (see
 * mcp_proc_truth_var_of_mean). A jittered dump carries the attribute
 * "mcpost.procedural.sampler" = "jittered KxK". */
MCP_API int mcp_proc_render(const mcp_proc_scene *scene, int spp, uint64_t seed,
                            const mcp_image *permutation, mcp_dump **out);

/* Where pass p of an adaptive render starts in every pixel's stream: sample index
 * p * 2^32. A pass never draws 2^32 samples in a pixel, so passes use disjoint samples
 * of the same streams (independent estimates) without knowing the earlier counts;
 * 2^32 is a multiple of every k^2 <= 64^2, so jittered passes stay whole passes. */
#define MCP_PROC_PASS_STRIDE ((uint64_t)1 << 32)

/* An adaptive pass: pixel p gets counts(p) samples (channel "SampleCount", or the
 * only channel; non-negative integers, multiples of strata^2 for the jittered sampler),
 * sample indices [pass * MCP_PROC_PASS_STRIDE, ... + counts(p)) of the stream of
 * mcp_proc_render with the same seed. *out is as mcp_proc_render's with a per-pixel
 * spp_map (a pixel given 0 samples has colour, variance and albedo 0), written in the
 * mcpost convention, and the attribute "mcpost.procedural.pass". */
MCP_API int mcp_proc_render_counts(const mcp_proc_scene *scene, const mcp_image *counts,
                                   int pass, uint64_t seed, mcp_dump **out);

/* The same pass, and its half buffer: what a renderer's own adaptive stopping rule
 * keeps beside the full mean (Cycles' adaptive auxiliary buffer, Mitsuba 3's odd
 * image; docs/adaptive.md). *half has channels R, G, B, the mean of the pass's samples
 * of class A, and SampleCount, how many those are (0 and mean 0 in a pixel without
 * one). Class A is every other sample of the independent sampler (even stream
 * indices); with the jittered one, in each pass of k^2 the cells (i, j) with
 * i + j + pass even, so that two passes hold exactly one class-A sample per cell.
 * Over a whole number of pairs of passes (any even count with the independent
 * sampler) class A is half the samples and its mean is unbiased. */
MCP_API int mcp_proc_render_counts_half(const mcp_proc_scene *scene,
                                        const mcp_image *counts, int pass, uint64_t seed,
                                        mcp_dump **out, mcp_image **half);

/* count images (R, G, B) of spp samples each, image k using sample indices
 * [k*spp, (k+1)*spp) of the streams of mcp_proc_render with the same seed and
 * permutation: independent estimates for the perceptual methods. The mean of count
 * one-sample images equals mcp_proc_render(scene, count, seed, ...) up to float
 * rounding. out[0..count-1] receive the images; all stay NULL on failure. */
MCP_API int mcp_proc_render_samples(const mcp_proc_scene *scene, int count, int spp,
                                    uint64_t seed, const mcp_image *permutation,
                                    mcp_image **out);

/* One pixel, in double: the estimate of pixel (x, y) with spp samples starting at
 * sample index first_sample of the stream of pixel (src_x, src_y). With the jittered
 * sampler spp and first_sample must be multiples of strata^2 (whole passes). */
typedef struct mcp_proc_pixel {
    double mean[3];
    double var_per_sample[3]; /* unbiased; 0 when spp is 1 */
    double albedo[3];
} mcp_proc_pixel;

MCP_API int mcp_proc_render_pixel(const mcp_proc_scene *scene, int x, int y, int src_x,
                                  int src_y, int spp, uint64_t seed,
                                  uint64_t first_sample, mcp_proc_pixel *out);

/* The exact expectation of every pixel (*mean, channels R, G, B) and, when var is not
 * NULL, the exact per-sample variance of the estimator (*var, channels R, G, B), by
 * Gauss-Legendre quadrature over pieces of the pixel on which the integrand is smooth
 * (see README.md). Accurate to about 1e-12 at the default truth_order. Both are the
 * same for either sampler: the variance is that of one sample with its footprint
 * point uniform over the whole pixel (under the independent sampler, the variance of
 * the mean is it / spp; see mcp_proc_truth_var_of_mean for both samplers). */
MCP_API int mcp_proc_truth(const mcp_proc_scene *scene, mcp_image **mean,
                           mcp_image **var);

/* The same for one pixel, in double (the images above are float). */
MCP_API int mcp_proc_truth_pixel(const mcp_proc_scene *scene, int x, int y,
                                 double mean[3], double var[3]);

/* The exact variance of the spp-sample pixel mean under the scene's sampler
 * (*var_of_mean, channels R, G, B). Independent: the per-sample variance / spp.
 * Jittered with k strata per side and P = spp / k^2 passes:
 *     (1 / P) (1 / k^4) sum over the k^2 cells of the within-cell variance,
 * each cell's moments integrated like mcp_proc_truth's (a cell of pixel (x, y) is
 * pixel (k x + i, k y + j) of the same scene k times finer), so k^2 times its cost.
 * spp must be >= 1, and a multiple of k^2 for the jittered sampler. */
MCP_API int mcp_proc_truth_var_of_mean(const mcp_proc_scene *scene, int spp,
                                       mcp_image **var_of_mean);

/* The same for one pixel, in double. */
MCP_API int mcp_proc_truth_pixel_var_of_mean(const mcp_proc_scene *scene, int x, int y,
                                             int spp, double var_of_mean[3]);

#ifdef __cplusplus
}
#endif
#endif
