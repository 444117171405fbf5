/* spectra.h: blue-noise analysis of an error image (docs/mathematics.md §4.11, blue-noise
 * analysis; Chizhov et al. 2022).
 *
 * The error eps = T(test) - T(reference) (per RGB channel, T the tone map) is cut into
 * tiles (32x32 by default; tiles that do not fit at the right and bottom are dropped)
 * and each tile's power spectrum |DFT|^2 is summed over the channels. Two results:
 *  - a picture: per tile, c ln(1 + |eps^|) with the zero frequency in the tile centre
 *    and c chosen so that the tile's largest value is 1 (the DC term, i.e. the tile's
 *    mean error, is set to 0: it is bias, not the distribution being looked at);
 *  - a number: the fraction of the non-DC spectral energy at radial frequencies below
 *    cutoff x Nyquist (cutoff 1/4 by default). White noise gives about the share of
 *    frequency bins below the cutoff (reported as white_fraction, 0.043 for 32x32
 *    tiles); blue noise gives less, low-frequency (blotchy) error more. */
#ifndef MCP_SPECTRA_H
#define MCP_SPECTRA_H

#include <mcpost/image.h>
#include <mcpost/tonemap.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_spectra_options {
    int tile_size;        /* >= 4 [32] */
    mcp_tonemap tone_map; /* T [clamp] */
    double cutoff;        /* radial frequency as a fraction of Nyquist, (0, 1] [0.25] */
} mcp_spectra_options;

MCP_API mcp_spectra_options mcp_spectra_defaults(void);

typedef struct mcp_spectra_result {
    double low_fraction;   /* non-DC energy below the cutoff / all non-DC energy (0 when
                              there is none) */
    double white_fraction; /* what white noise would give: the share of non-DC bins below
                              the cutoff */
    double energy;         /* non-DC energy per pixel: sum |DFT|^2 / (tiles x area^2), by
                              Parseval the error's variance within tiles (summed over
                              channels) */
    int tiles_x, tiles_y, tile_size;
} mcp_spectra_result;

/* Analyses an error image already formed: every channel's spectrum is summed.
 * picture (may be NULL) receives one channel "spectrum" in [0, 1] of size
 * tiles_x * tile_size by tiles_y * tile_size. */
MCP_API int mcp_spectra_analyse(const mcp_image *error, const mcp_spectra_options *opt,
                                mcp_spectra_result *res, mcp_image **picture);

/* Forms eps = T(test) - T(ref) over R, G, B and analyses it. Same checks as the
 * metrics (size, channels, finite values). */
MCP_API int mcp_spectra_blue_noise(const mcp_image *test, const mcp_image *ref,
                                   const mcp_spectra_options *opt,
                                   mcp_spectra_result *res, mcp_image **picture);

#ifdef __cplusplus
}
#endif
#endif
