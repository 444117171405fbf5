/* flip.h: LDR-FLIP and HDR-FLIP (Andersson et al. 2020, 2021), as NVIDIA's reference
 * implementation (NVlabs/flip v1.6, src/cpp/FLIP.h) computes them, and FLIP's spatial
 * contrast-sensitivity filter as a linear operator M for SURE_M.
 *
 * Everything runs in float32 with FLIP's order of operations: separable x-then-y
 * passes with clamp-to-edge borders, tap sums taken sequentially from -r to r, and the
 * mean as a float running sum in row-major order (docs/flip.md §3, §6). Where libm's
 * expf/powf agree with the reference build's, the numbers are the reference's own
 * (e.g. 0.169141844 for flat grey 128 vs 140, float artefacts included); docs/flip.md
 * §6 asks
 * for 1e-5 on means and 1e-4 per pixel. Per-pixel results depend neither on the thread
 * count nor on the SIMD width (AVX2 or not).
 *
 * Two deliberate departures from v1.6 (docs/flip.md §5):
 *  - HDR-FLIP clamps a zero median (and maximum) reference luminance to FLT_EPSILON
 *    before choosing exposures (v1.6 silently returns 0; v1.7 has the same fix);
 *  - HDR-FLIP clamps negative input values to 0 before anything else (v1.6 tone-maps
 *    large negative values to white).
 * Inputs must be finite: NaN or Inf fails, naming the file and pixel.
 *
 * Inputs are linear RGB images; channels are found by mcp_rgb_channels() (R, G, B by
 * name, else a 3-channel image in order, else a grey 1-channel image). The first image
 * is the test image and the second the reference, as everywhere in mcpost. */
#ifndef MCP_FLIP_H
#define MCP_FLIP_H

#include <mcpost/image.h>
#include <mcpost/tonemap.h>

#ifdef __cplusplus
extern "C" {
#endif

/* FLIP's constants (FLIP.h FLIPConstants) and defaults. */
#define MCP_FLIP_QC 0.7f
#define MCP_FLIP_QF 0.5f
#define MCP_FLIP_PC 0.4f
#define MCP_FLIP_PT 0.95f
#define MCP_FLIP_W 0.082f         /* feature-detector width in degrees */
#define MCP_FLIP_EXPOSURE_T 0.85f /* tone-mapped value that picks exposures */

typedef struct mcp_flip_options {
    /* Pixels per degree of visual angle; 0 computes it from the viewing condition
     * below as distance_m * (display_width_px / display_width_m) * pi / 180 [0]. */
    double ppd;
    double distance_m;       /* observer to screen [0.7] */
    double display_width_m;  /* [0.7] */
    double display_width_px; /* [3840]; the defaults give ppd 67.0206451 */
    /* HDR-FLIP only. */
    mcp_tonemap tone_mapper; /* aces, hable or reinhard [aces] */
    double start_exposure;   /* stops; NAN: automatic from the reference [NAN] */
    double stop_exposure;    /* stops; NAN: automatic [NAN] */
    int num_exposures;       /* >= 2; 0: max(2, ceil(stop - start)) [0] */
} mcp_flip_options;

MCP_API mcp_flip_options mcp_flip_defaults(void);

/* FLIP's statistics of a per-pixel error map, as NVIDIA's tool (v1.6, tool/pooling.h)
 * defines and prints them (docs/metrics.md, "FLIP's statistics"):
 *  - the weighted percentile at p (median p = 0.5, quartiles 0.25 and 0.75) weighs
 *    each pixel by its own error: with the errors sorted ascending, it is the first
 *    one at which the running sum exceeds p times the total, both float sums (the
 *    total in row-major order) as the tool takes them; 0 when none does (all zero);
 *  - min and max of the map (the tool starts max at FLT_MIN, so an all-zero map
 *    prints 1.2e-38 there; here it is 0);
 *  - the histogram: MCP_FLIP_HISTOGRAM_BUCKETS buckets over [0, 1] of width 0.01f,
 *    pixel v in bucket floor(double(v) / double(0.01f)), 1.0 in the last; the
 *    weighted histogram (what the tool plots) multiplies bucket i's count by its
 *    centre (i + 0.5) / 100 and divides by the megapixels, n / 2^20. */
#define MCP_FLIP_HISTOGRAM_BUCKETS 100

typedef struct mcp_flip_stats {
    double weighted_median, weighted_q1, weighted_q3;
    double min, max;
    long long pixels;                                /* n */
    long long histogram[MCP_FLIP_HISTOGRAM_BUCKETS]; /* pixel counts */
} mcp_flip_stats;

/* The statistics of n per-pixel FLIP values (row-major). Values must be finite;
 * those outside [0, 1] count in no bucket, as in the tool. n >= 1. */
MCP_API int mcp_flip_statistics(const float *values, size_t n, mcp_flip_stats *out);

/* Bucket i of the weighted histogram: count_i (i + 0.5) / 100 / (n / 2^20), the
 * weighted FLIP sum per megapixel that the tool plots. */
MCP_API double mcp_flip_weighted_bucket(const mcp_flip_stats *s, int i);

typedef struct mcp_flip_result {
    double mean; /* the FLIP value: arithmetic mean of the per-pixel map */
    float ppd;   /* pixels per degree used */
    /* HDR-FLIP only (0 for LDR-FLIP): the exposures used, in stops. */
    float start_exposure, stop_exposure;
    int num_exposures;
    mcp_flip_stats stats; /* the map's statistics (above) */
} mcp_flip_result;

/* LDR-FLIP of test against ref. Both are clamped to [0, 1] first, as the reference
 * does. map (may be NULL) receives one channel "FLIP" in [0, 1]. opt may be NULL. */
MCP_API int mcp_flip_ldr(const mcp_image *test, const mcp_image *ref,
                         const mcp_flip_options *opt, mcp_flip_result *res,
                         mcp_image **map);

/* HDR-FLIP: LDR-FLIP of the tone-mapped, clamped pair at each exposure
 * start + i (stop - start)/(N - 1), keeping the per-pixel maximum. map (may be NULL)
 * receives "FLIP"; exposure_map (may be NULL) receives "exposure", i/(N - 1) of the
 * exposure that gave the maximum (0 where every exposure gave 0). */
MCP_API int mcp_flip_hdr(const mcp_image *test, const mcp_image *ref,
                         const mcp_flip_options *opt, mcp_flip_result *res,
                         mcp_image **map, mcp_image **exposure_map);

/* ---- the CSF operator M of SURE_M (docs/mathematics.md §2.3, docs/flip.md §4) ----
 *
 * M = T^-1 blkdiag(K_Y, K_Cx, K_Cz) T: linear RGB -> YCxCz (without FLIP's -16 offset,
 * which the unit-DC filters pass through, so M is exactly linear) -> FLIP's CSF filter
 * per opponent channel with replicate borders -> linear RGB, without FLIP's clamp.
 * M preserves constants. With replicate borders M is not symmetric; the transpose
 * scatter-adds the taps that the borders fold. ppd <= 0 means FLIP's default 67.02.
 * Input channels as for FLIP; output channels R, G, B. */
MCP_API int mcp_flip_csf_apply(const mcp_image *rgb, double ppd, mcp_image **out);
MCP_API int mcp_flip_csf_apply_transpose(const mcp_image *rgb, double ppd,
                                         mcp_image **out);

#ifdef __cplusplus
}
#endif
#endif
