/* cv_shim.h: the private C ABI over OpenCV (core + imgproc; docs/libraries.md §4).
 * cv_plugin.cpp, the only file in mcpost that talks to OpenCV, implements it in the
 * plug-in mcpost_cv.so; cv.c implements the functions below by loading that plug-in
 * on first use and calling through its table. Not installed.
 *
 * Buffers are the caller's: the shim wraps them as cv::Mat without copying and never
 * lets OpenCV reallocate an output (it checks and fails instead). Every function
 * catches every exception and returns 0, or -1 with a one-line message in err
 * (err_cap bytes, NUL-terminated). They set no mcp_error line themselves, so they may
 * be called from OpenMP workers; the caller reports after the parallel loop.
 *
 * Filters use BORDER_REPLICATE (clamp to edge) and compute correlation
 * sum_i k[i] * img[x + i - r] with the anchor at the kernel centre (filter.h). */
#ifndef MCP_CV_SHIM_H
#define MCP_CV_SHIM_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Up to this many interleaved channels are handed to OpenCV in one Mat; callers split
 * wider images into groups (OpenCV's own limit is CV_CN_MAX = 512). */
#define MCP__CV_MAX_CHANNELS 4

/* An interleaved float plane: height rows of width pixels of `channels` floats
 * (1..MCP__CV_MAX_CHANNELS), packed within a row, rows row_step floats apart
 * (row_step >= width * channels). */
typedef struct mcp__cv_plane {
    float *data;
    int width, height, channels;
    size_t row_step;
} mcp__cv_plane;

/* Filters rows [y0, y1) of src into the same rows of dst (same size and channels):
 * kx along rows, then ky along columns, odd lengths. Rows outside [y0, y1) are read
 * from src as real neighbours, so strips filtered separately are bit-identical to one
 * whole-image call. */
int mcp__cv_sep_filter_rows(const mcp__cv_plane *src, const mcp__cv_plane *dst, int y0,
                            int y1, const float *kx, int kx_len, const float *ky,
                            int ky_len, char *err, size_t err_cap);

/* The same with a row-major kw x kh kernel (both odd). Always direct correlation: a
 * whole image is split in two so that OpenCV never takes its DFT method, which would
 * spread one Inf or NaN pixel over the whole output. */
int mcp__cv_filter2d_rows(const mcp__cv_plane *src, const mcp__cv_plane *dst, int y0,
                          int y1, const float *kernel, int kw, int kh, char *err,
                          size_t err_cap);

/* power[v * n + u] = |DFT(tile)[v][u]|^2 for an n x n real tile (row-major, packed),
 * unshifted (zero frequency at [0]), computed in double. */
int mcp__cv_dft_power(const double *tile, int n, double *power, char *err,
                      size_t err_cap);

/* The 256-entry RGB table (rgb[3 * i + 0..2]) that cv::applyColorMap uses for grey
 * level i; cv_map is a cv::ColormapTypes value. OpenCV's BGR is turned into RGB. */
int mcp__cv_colormap_lut(int cv_map, unsigned char *rgb, char *err, size_t err_cap);

/* cv::ColormapTypes values the C side needs (checked against OpenCV at compile time
 * in cv_shim.cpp). */
/* The plug-in's table of the functions above (cv_plugin.cpp), from its one exported
 * function MCP__CV_TABLE; abi must be MCP__CV_ABI. */
typedef struct mcp__cv_table {
    int abi;
    int (*sep_filter_rows)(const mcp__cv_plane *, const mcp__cv_plane *, int, int,
                           const float *, int, const float *, int, char *, size_t);
    int (*filter2d_rows)(const mcp__cv_plane *, const mcp__cv_plane *, int, int,
                         const float *, int, int, char *, size_t);
    int (*dft_power)(const double *, int, double *, char *, size_t);
    int (*colormap_lut)(int, unsigned char *, char *, size_t);
} mcp__cv_table;
typedef const mcp__cv_table *(*mcp__cv_table_fn)(void);
#define MCP__CV_ABI 1
#define MCP__CV_TABLE "mcp_cv_plugin_table"

#define MCP__CV_COLORMAP_MAGMA 13
#define MCP__CV_COLORMAP_INFERNO 14
#define MCP__CV_COLORMAP_VIRIDIS 16
#define MCP__CV_COLORMAP_TURBO 20

#ifdef __cplusplus
}
#endif
#endif
