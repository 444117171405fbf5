/* filter.h: separable and 2D filtering, Gaussian blur, tile DFTs and false colour,
 * over OpenCV (core + imgproc) behind a C++ shim.
 *
 * Border rule everywhere: replicate (clamp-to-edge), as FLIP and docs/mathematics.md ask.
 * Filters compute correlation, sum_i k[i] * img[x + i - r]; for the symmetric kernels
 * mcpost uses this equals convolution. Kernels have odd length 2r+1.
 * All functions filter every channel independently and accept views (any strides);
 * the output is a new packed image with the input's channel names. */
#ifndef MCP_FILTER_H
#define MCP_FILTER_H

#include <mcpost/image.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Correlates each channel with kx along rows and then ky along columns. */
MCP_API int mcp_filter_separable(const mcp_image *img, const float *kx, int kx_len,
                                 const float *ky, int ky_len, mcp_image **out);

/* Correlates each channel with a 2D kernel (row-major, kw x kh, both odd). */
MCP_API int mcp_filter_2d(const mcp_image *img, const float *kernel, int kw, int kh,
                          mcp_image **out);

/* Fills k[0..2r] with a normalised Gaussian of standard deviation sigma_px
 * (sum exactly 1 in double before rounding to float). */
MCP_API int mcp_gaussian_kernel(double sigma_px, int radius, float *k);

/* Gaussian blur with an explicit window (odd, >= 1) and sigma in pixels. */
MCP_API int mcp_gaussian_blur(const mcp_image *img, int window, double sigma_px,
                              mcp_image **out);

/* Power spectra of square tiles of one channel: for each tile_size x tile_size tile
 * (tiles that do not fit at the right/bottom edge are dropped), |DFT|^2 with the
 * zero frequency moved to the tile centre. out has the tiled size and one channel
 * "power". */
MCP_API int mcp_tile_power_spectra(const mcp_image *img, int channel, int tile_size,
                                   mcp_image **out);

typedef enum {
    MCP_COLORMAP_VIRIDIS,
    MCP_COLORMAP_MAGMA,
    MCP_COLORMAP_INFERNO,
    MCP_COLORMAP_TURBO,
    MCP_COLORMAP_GRAY
} mcp_colormap;

/* Maps channel `channel` of img, scaled so lo -> 0 and hi -> 1 (clamped), to 8-bit
 * false colour: rgb8 receives width*height*3 bytes, row-major. */
MCP_API int mcp_colormap_apply(const mcp_image *img, int channel, double lo, double hi,
                               mcp_colormap map, unsigned char *rgb8);

#ifdef __cplusplus
}
#endif
#endif
