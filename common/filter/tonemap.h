/* tonemap.h: tone maps, luminance, and the perceptual kernel g of docs/mathematics.md §4.
 *
 * Tone maps T act per channel on linear values (Reinhard on luminance, as FLIP does):
 *   none      T(x) = x
 *   clamp     T(x) = min(max(x, 0), 1)                     (§4.2 default)
 *   aces      Narkowicz's fit x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14), clamped
 *             to [0, 1] (§2.6 "ACES (Narkowicz's fit)"; no pre-exposure)
 *   hable     Uncharted 2 with white point 11.2 and exposure bias 2, clamped, in
 *             the rational form FLIP uses (docs/flip.md §2)
 *   reinhard  x / (1 + x) per channel, clamped
 * Negative inputs are clamped to 0 before every map except none.
 *
 * HDR-FLIP uses its own coefficient table (mcp_tonemap_flip_coefficients), in which
 * ACES carries FLIP's 0.6 pre-exposure; see flip.h.
 *
 * The perceptual kernel g (Chizhov et al. 2022) is separable: the 3-tap binomial
 * approximation [1/pi, 1 - 2/pi, 1/pi] (variance 2/pi) by default, or a Gaussian whose
 * sigma comes from the viewing distance and screen resolution (Eq. 11). */
#ifndef MCP_TONEMAP_H
#define MCP_TONEMAP_H

#include <mcpost/image.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    MCP_TONEMAP_NONE,
    MCP_TONEMAP_CLAMP,
    MCP_TONEMAP_ACES,
    MCP_TONEMAP_HABLE,
    MCP_TONEMAP_REINHARD
} mcp_tonemap;

/* "none", "clamp", "aces", "hable", "reinhard" (case-insensitive). Fails with
 * "unknown tone map 'X' (known: ...)". */
MCP_API extern const mcp_wordlist mcp_tonemap_words;
MCP_API int mcp_tonemap_from_name(const char *name, mcp_tonemap *out);
MCP_API const char *mcp_tonemap_name(mcp_tonemap tm);

/* T(x) for one channel value (Reinhard per channel here). NaN maps to 0 except for
 * none. */
MCP_API float mcp_tonemap_value(mcp_tonemap tm, float x);

/* dT/dx at x (0 where T clamps), for tone-mapped error estimates (J_T v = T'(F) J v). */
MCP_API float mcp_tonemap_slope(mcp_tonemap tm, float x);

/* Applies T to every channel of img (any strides); *out is packed with img's names. */
MCP_API int mcp_tonemap_apply(const mcp_image *img, mcp_tonemap tm, mcp_image **out);

/* FLIP's rational tone-curve coefficients (k0 x^2 + k1 x + k2) / (k3 x^2 + k4 x + k5)
 * for aces, hable and reinhard (FLIP.h ToneMappingCoefficients, in float). Fails for
 * the other maps with "tone mapper must be aces, hable or reinhard (got 'X')". */
MCP_API int mcp_tonemap_flip_coefficients(mcp_tonemap tm, float k[6]);

/* Rec. 709 relative luminance 0.2126 R + 0.7152 G + 0.0722 B (in float, as FLIP). */
static inline float
mcp_luminance(float r, float g, float b)
{
    return 0.2126f * r + 0.7152f * g + 0.0722f * b;
}

/* Finds the R, G, B channels of img: by name (mcp_image_rgb_by_name: "R", "G", "B",
 * then any case, else Blender's "<layer>.Combined.R/G/B" when one layer has them), else
 * channels 0, 1, 2
 * of a 3-channel image, else channel 0 three times for a 1-channel (grey) image.
 * Fails with "<source>: no channel 'R'" (or 'G', 'B'). */
MCP_API int mcp_rgb_channels(const mcp_image *img, int rgb[3]);

/* ---- the perceptual kernel g ---- */

typedef enum {
    MCP_PKERNEL_TAP3,    /* [1/pi, 1 - 2/pi, 1/pi] */
    MCP_PKERNEL_GAUSSIAN /* sigma from dpi and distance (Eq. 11), radius ceil(3 sigma) */
} mcp_pkernel_kind;

typedef struct mcp_pkernel {
    mcp_pkernel_kind kind; /* [tap3] */
    double dpi;            /* screen resolution in dots per inch [300] */
    double distance_in;    /* viewing distance in inches [16] */
} mcp_pkernel;

MCP_API mcp_pkernel mcp_pkernel_defaults(void);

/* "tap3" or "gaussian". */
MCP_API extern const mcp_wordlist mcp_pkernel_kind_words;
MCP_API int mcp_pkernel_kind_from_name(const char *name, mcp_pkernel_kind *out);
MCP_API const char *mcp_pkernel_kind_name(mcp_pkernel_kind kind);

/* Chizhov Eq. 11: sigma = 0.00954 / tau pixels, tau = (180/pi) 2 atan(1/(2 R D))
 * degrees between neighbouring pixels. */
MCP_API double mcp_pkernel_sigma_px(double dpi, double distance_in);

/* The 1D taps of g (2r+1 values summing to 1, symmetric). *taps is malloc'd; fails
 * naming the bad field ("pkernel: dpi must be > 0 (got 0)"). The 2D kernel is the
 * outer product taps x taps. */
MCP_API int mcp_pkernel_taps(const mcp_pkernel *k, double **taps, int *radius);

/* Correlates every channel of img with taps along x, then along y, with replicate
 * borders, accumulating in double; *out is packed with img's names. */
MCP_API int mcp_pkernel_filter(const mcp_image *img, const double *taps, int radius,
                               mcp_image **out);

#ifdef __cplusplus
}
#endif
#endif
