/* metrics.h: how far a test image is from a reference (docs/mathematics.md §5).
 *
 * Over pixels x channels (R, G, B; see mcp_rgb_channels):
 *   MSE     mean (t - r)^2                RMSE sqrt(MSE)
 *   relMSE  mean (t - r)^2 / (r^2 + eps)  eps = EPS_REL = 1e-2
 *   PSNR    10 log10(1 / MSE) of the displayed images: clamped to [0, 1] and
 *           sRGB-encoded, so that for 8-bit files it is the usual PSNR of the file
 *           values (peak 1 = 255); +inf for identical images
 *   pMSE    E / (N C), E = sum_c |g * T(t_c) - h * T(r_c)|^2 (docs/mathematics.md §4:
 *           kernel g, h = delta or g, tone map T, replicate borders)
 *   RelSE percentiles  RelSE_i = (t_i - r_i)^2 / (maxc(t)^2 + eps), maxc(t) the
 *           largest of the test image's three channels at the pixel
 *           (docs/mathematics.md §2.9:
 *           maxc of the denoised image F, the image under test); the value at p is
 *           element ceil(p n) - 1 of the ascending sort (nearest rank)
 *   LDR-FLIP, HDR-FLIP (flip.h)
 *   blue noise  the low-frequency energy fraction of the error (spectra.h)
 * The first image is the test image, the second the reference. Sums run in double,
 * per row and then over rows in order, so results do not depend on the thread count.
 * Inputs must have the same size, R, G and B, and finite values; otherwise the call
 * fails with one line naming the file. */
#ifndef MCP_METRICS_H
#define MCP_METRICS_H

#include <cjson/cJSON.h>
#include <mcpost/flip.h>
#include <mcpost/spectra.h>
#include <mcpost/tonemap.h>

#ifdef __cplusplus
extern "C" {
#endif

#define MCP_EPS_REL 1e-2
#define MCP_METRICS_MAX_PERCENTILES 64

typedef struct mcp_pmse_options {
    mcp_pkernel kernel;   /* g [tap3] */
    int filter_reference; /* h = g instead of h = delta [0] */
    mcp_tonemap tone_map; /* T [clamp] */
} mcp_pmse_options;

MCP_API mcp_pmse_options mcp_pmse_defaults(void);

/* The share of pixels above a per-pixel threshold (idiff's -failpercent, with FLIP
 * or RelSE in place of the absolute difference; docs/metrics.md "Gates"): a pixel is
 * above when its FLIP value exceeds the threshold, or for RelSE when any of its three
 * channels' RelSE does (idiff counts a pixel when any channel fails). */
#define MCP_METRICS_MAX_ABOVE 16

typedef enum { MCP_ABOVE_FLIP_LDR, MCP_ABOVE_FLIP_HDR, MCP_ABOVE_RELSE } mcp_above_map;

typedef struct mcp_metrics_above {
    mcp_above_map map;
    double threshold;
} mcp_metrics_above;

/* "flip_ldr", "flip_hdr", "relse" (the names of the figures in the JSON). */
MCP_API const char *mcp_above_map_name(mcp_above_map m);
MCP_API int mcp_above_map_from_name(const char *name, mcp_above_map *out);

typedef struct mcp_metrics_options {
    double eps_rel;                                  /* [1e-2] */
    int n_percentiles;                               /* [3] */
    double percentiles[MCP_METRICS_MAX_PERCENTILES]; /* in [0, 1] [0.5, 0.9, 0.99] */
    mcp_pmse_options pmse;
    mcp_flip_options flip;
    int flip_ldr, flip_hdr; /* compute them [1, 1] */
    /* Blue-noise analysis [1]; skipped (has_spectra 0) when the image is smaller
     * than one tile. */
    int spectra;
    mcp_spectra_options spectra_opt;
    /* Shares of pixels above thresholds to measure [none]; mcp_metrics_add_above. */
    int n_above;
    mcp_metrics_above above[MCP_METRICS_MAX_ABOVE];
} mcp_metrics_options;

MCP_API mcp_metrics_options mcp_metrics_defaults(void);

typedef struct mcp_metrics {
    long n_values; /* pixels x 3 */
    double mse, rmse, relmse, psnr, pmse;
    int n_percentiles;
    double percentiles[MCP_METRICS_MAX_PERCENTILES]; /* the p values */
    double relse[MCP_METRICS_MAX_PERCENTILES];       /* RelSE at each p */
    int has_flip_ldr, has_flip_hdr;
    mcp_flip_result flip_ldr, flip_hdr;
    int has_spectra;
    mcp_spectra_result spectra;
    /* opt->above[k]'s share of the pixels, in percent */
    int n_above;
    mcp_metrics_above above[MCP_METRICS_MAX_ABOVE];
    double above_percent[MCP_METRICS_MAX_ABOVE];
} mcp_metrics;

/* Per-pixel maps that mcp_metrics_compute returns when given the struct (FLIP maps
 * stay NULL when that FLIP is not computed). */
typedef struct mcp_metrics_maps {
    mcp_image *sq_error;          /* R, G, B: (t - r)^2 */
    mcp_image *relse;             /* R, G, B: RelSE */
    mcp_image *flip_ldr;          /* FLIP */
    mcp_image *flip_hdr;          /* FLIP */
    mcp_image *flip_hdr_exposure; /* exposure */
    mcp_image *spectra;           /* spectrum (the blue-noise picture) */
} mcp_metrics_maps;

MCP_API void mcp_metrics_maps_free(mcp_metrics_maps *maps);

/* Every metric that opt selects (opt may be NULL). maps may be NULL. */
MCP_API int mcp_metrics_compute(const mcp_image *test, const mcp_image *ref,
                                const mcp_metrics_options *opt, mcp_metrics *out,
                                mcp_metrics_maps *maps);

/* The single metrics. */
MCP_API int mcp_mse(const mcp_image *test, const mcp_image *ref, double *mse);
MCP_API int mcp_relmse(const mcp_image *test, const mcp_image *ref, double eps_rel,
                       double *relmse);
MCP_API int mcp_psnr(const mcp_image *test, const mcp_image *ref, double *psnr);
MCP_API int mcp_pmse(const mcp_image *test, const mcp_image *ref,
                     const mcp_pmse_options *opt, double *pmse);

/* RelSE per value (R, G, B channels). */
MCP_API int mcp_relse_map(const mcp_image *test, const mcp_image *ref, double eps_rel,
                          mcp_image **out);

/* Percentiles of all the values of the given channels of img (all channels when
 * channels is NULL), by the nearest rank: out[k] = element ceil(p[k] n) - 1 of the
 * ascending sort (the smallest value at p = 0). NaN values fail. */
MCP_API int mcp_image_percentiles(const mcp_image *img, const double *p, int n_p,
                                  double *out);

/* The figures as members of obj (a JSON object): mse, rmse, relmse, psnr (the
 * string "inf" for identical displays), pmse (with its settings), relse_percentiles
 * {p: [...], value: [...]}, flip_ldr {mean, weighted_median, weighted_q1,
 * weighted_q3, min, max, ppd}, flip_hdr {the same, tone_mapper, start_exposure,
 * stop_exposure, num_exposures}, flip_histogram {bucket_width, flip_ldr: [counts],
 * flip_hdr: [counts]} (flip.h's histogram), blue_noise {low_fraction, white_fraction,
 * energy, tile_size, cutoff}, pixels_above [{map, threshold, percent}]. */
MCP_API int mcp_metrics_json(const mcp_metrics *m, const mcp_metrics_options *opt,
                             cJSON *obj);

/* Writes the maps that are present into dir (created if needed) as
 * <prefix>NAME.exr (float) and false-colour <prefix>NAME.png: flip_ldr, flip_hdr
 * (magma over [0, 1], as FLIP's tool shows them), flip_hdr_exposure (viridis over
 * [0, 1]), relse (EXR; PNG: inferno of log10 of the channel mean over [-5, 0]),
 * sq_error (EXR only) and spectra (PNG: grey). When section is not NULL each PNG is
 * added to its images as "<prefix>NAME.png". */
MCP_API int mcp_metrics_write_maps(const mcp_metrics_maps *maps, const char *dir,
                                   const char *prefix, cJSON *section);

/* The percentage of pixels of img above t: a pixel counts when any of its channels
 * is above (a FLIP map has one; RelSE three), as for pixels_above. */
MCP_API int mcp_image_percent_above(const mcp_image *img, double t, double *percent);

/* Asks for the share of pixels of map above threshold (once: a pair already asked
 * for is kept). Fails when the threshold is not finite or MCP_METRICS_MAX_ABOVE pairs
 * are asked for already; mcp_metrics_compute fails when the map is a FLIP that opt
 * does not compute. */
MCP_API int mcp_metrics_add_above(mcp_metrics_options *opt, mcp_above_map map,
                                  double threshold);

/* Sets opt->percentiles (1 to MCP_METRICS_MAX_PERCENTILES values, each in [0, 1]). */
MCP_API int mcp_metrics_set_percentiles(mcp_metrics_options *opt, const double *p,
                                        int n_p);

#ifdef __cplusplus
}
#endif
#endif
