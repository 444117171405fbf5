/* procedural.h: a procedural Monte Carlo renderer whose exact answer is known.
 *
 * A small analytic scene (a perspective ground plane with a rotated checkerboard, a
 * floating sheet with a smooth colour gradient, a soft shadow from a rectangular area
 * light, a glossy highlight and rare very bright "firefly" paths). Each pixel value is a
 * Monte Carlo integral over the pixel's box footprint and the light, lobe and firefly
 * dimensions; its samples come from a counter-based random stream seeded by
 * (seed, source pixel), so any pixel, any realization and any seed permutation can be
 * re-rendered bit-identically, whatever the thread count. The expectation of every
 * pixel (and the per-sample variance) is computed by deterministic quadrature to about
 * 1e-12. README.md beside this file describes the scene. Tests and the perceptual
 * evaluation draw realizations from it (SPEC perceptual, "horizontal search space"). */
#ifndef MCP_PROCEDURAL_H
#define MCP_PROCEDURAL_H

#include <stdint.h>
#include <mcpost/dump.h>

#ifdef __cplusplus
extern "C" {
#endif

/* What to render. Start from mcp_proc_scene_defaults(); [defaults] in brackets. */
typedef struct mcp_proc_scene {
    int width, height;          /* image size in pixels [64 x 64] */
    double firefly_probability; /* chance per ground sample of a very bright path [1e-3];
                                   0 turns fireflies off */
    double firefly_value;       /* brightness of such a path (green channel) [100] */
    int truth_order;            /* Gauss-Legendre points per triangle side in
                                   mcp_proc_truth, 1..32 [8] */
} mcp_proc_scene;

MCP_API mcp_proc_scene mcp_proc_scene_defaults(void);

/* Checks the fields; sets "procedural: <field> must be ... (got ...)" and returns -1. */
MCP_API int mcp_proc_scene_check(const mcp_proc_scene *scene);

/* The seed of realization r of a render seeded with seed: r = 0 gives seed itself, so
 * a plain render and realization 0 are the same; others are hashed from (seed, r). */
MCP_API uint64_t mcp_proc_realization_seed(uint64_t seed, int realization);

/* Renders spp samples per pixel (sample indices 0..spp-1 of each stream). The samples
 * of pixel p come from the stream of pixel p, or of permutation(p) when permutation is
 * given: an image of the scene's size with channels "X" and "Y" holding integer
 * source-pixel coordinates. Only the random stream is borrowed; the integrand stays
 * that of p. *out: colour mean, var_of_mean (unbiased per-sample variance / spp; 0 at
 * spp 1), albedo (mean of the sampled diffuse albedo), normal (world space), spp. */
MCP_API int mcp_proc_render(const mcp_proc_scene *scene, int spp, uint64_t seed,
                            const mcp_image *permutation, mcp_dump **out);

/* count images (R, G, B) of spp samples each, image k using sample indices
 * [k*spp, (k+1)*spp) of the streams of mcp_proc_render with the same seed and
 * permutation: independent estimates for the perceptual methods. The mean of count
 * one-sample images equals mcp_proc_render(scene, count, seed, ...) up to float
 * rounding. out[0..count-1] receive the images; all stay NULL on failure. */
MCP_API int mcp_proc_render_samples(const mcp_proc_scene *scene, int count, int spp,
                                    uint64_t seed, const mcp_image *permutation,
                                    mcp_image **out);

/* One pixel, in double: the estimate of pixel (x, y) with spp samples starting at
 * sample index first_sample of the stream of pixel (src_x, src_y). */
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
 * (see README.md). Accurate to about 1e-12 at the default truth_order. */
MCP_API int mcp_proc_truth(const mcp_proc_scene *scene, mcp_image **mean,
                           mcp_image **var);

/* The same for one pixel, in double (the images above are float). */
MCP_API int mcp_proc_truth_pixel(const mcp_proc_scene *scene, int x, int y,
                                 double mean[3], double var[3]);

#ifdef __cplusplus
}
#endif
#endif
