/* unet_internal.h: OIDN's RT U-Net in plain C -- the .tza weight archive (tza.c) and
 * the network's forward pass with OIDN's HDR pre-/post-processing (unet.c).
 * Not installed; see docs/oidn-network.md for the format, the layer list and the transfer
 * function. The denoiser kind `unet` over them is denoise_unet.c. */
#ifndef MCP_ESTIMATE_UNET_INTERNAL_H
#define MCP_ESTIMATE_UNET_INTERNAL_H

#include <mcpost/denoiser.h>
#include <mcpost/image.h>
#include <mcpost/progress.h>

#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* ---- .tza archive (tza.c; docs/oidn-network.md §2) ---- */

typedef struct mcp__tza_tensor {
    char *name;
    int ndims; /* 1..4 */
    int dims[4];
    char layout[5]; /* "oihw" or "x" */
    char dtype;     /* 'f' (float32) or 'h' (float16) as stored */
    size_t count;   /* number of values */
    float *data;    /* converted to float32, owned */
} mcp__tza_tensor;

typedef struct mcp__tza {
    int count;
    mcp__tza_tensor *tensors;
} mcp__tza;

/* Parses a whole archive held in memory; source names it in messages. */
int mcp__tza_parse(const unsigned char *bytes, size_t size, const char *source,
                   mcp__tza **out);
/* Reads and parses a file. */
int mcp__tza_read(const char *path, mcp__tza **out);
/* The tensor called name, or NULL (no error set). */
const mcp__tza_tensor *mcp__tza_find(const mcp__tza *tza, const char *name);
void mcp__tza_free(mcp__tza *tza);

/* float16 bits to float (exact; subnormals, infinities and NaN included). */
float mcp__half_to_float(unsigned short h);

/* ---- the U-Net (unet.c; docs/oidn-network.md §1, §3) ---- */

#define MCP__UNET_NCONV 16

typedef struct mcp__unet_conv {
    int cin, cout;
    float *weight; /* [cout][cin][3][3], owned */
    float *bias;   /* [cout], owned */
} mcp__unet_conv;

typedef struct mcp__unet {
    int ic;             /* input channels: 3 colour, 6 + albedo, 9 + albedo + normal */
    int v2;             /* 1 for float16 (OIDN 2.x) files: autoexposure bins by ceil */
    int fixed_bits;     /* 1: the direct loops (a setting, not read from the file) */
    int exact_tangents; /* 1: tangents on F(2x2, 3x3) in float, not F(4x4, 3x3) */
    int max_memory_mb;  /* the network's working memory at most (0: the default) */
    mcp__unet_conv conv[MCP__UNET_NCONV]; /* enc_conv0 ... dec_conv0 in order */
} mcp__unet;

/* Loads the base (or small) RT U-Net from a .tza file; channel counts are read from
 * the tensors and checked for consistency. `_large` weights are refused. */
int mcp__unet_load(const char *path, mcp__unet **out);
/* The same from a parsed archive. */
int mcp__unet_from_tza(const mcp__tza *tza, const char *source, mcp__unet **out);
void mcp__unet_free(mcp__unet *net);

/* OIDN's autoexposure scale of an RGB image (docs/oidn-network.md §3.3; v2: 2.x bins). */
double mcp__unet_autoexposure(const mcp_image *color, int v2);
/* The same over a W x H image fed in bands of rows, top to bottom (a streamed denoise's
 * pre-pass, unet_bands.c): the same sums in the same order, so the same value as
 * mcp__unet_autoexposure on the whole image, whatever the bands. rows: the next
 * rows->height rows, columns 0 .. W - 1, colour in channels 0..2. end frees. */
typedef struct mcp__unet_exposure {
    int W, H, hk, wk;
    int row, bin_row; /* the next row fed; the first row of bins not yet closed */
    double *sums;     /* the open row of bins' sums */
    double log_sum;
    int kept;
} mcp__unet_exposure;
int mcp__unet_exposure_begin(mcp__unet_exposure *e, int W, int H, int v2);
void mcp__unet_exposure_rows(mcp__unet_exposure *e, const mcp_image *rows);
double mcp__unet_exposure_end(mcp__unet_exposure *e);

/* HDR denoise of colour (3 channels) with albedo and normal as the net needs them
 * (NULL when the net does not read them). input_scale <= 0: autoexposure. The whole
 * image is one tile, padded at the bottom/right to a multiple of 16. *out is a new
 * RGB image. */
int mcp__unet_forward(const mcp__unet *net, const mcp_image *color,
                      const mcp_image *albedo, const mcp_image *normal,
                      double input_scale, mcp_image **out);

/* The same, and for k < n the exact Jacobian-vector product jt[k] = J t[k] in the
 * same pass (forward mode: t[k].color is required, its albedo and normal parts may be
 * NULL, meaning zero; they count only where the net reads those inputs). The input
 * scale is held constant for the JVP. out may be NULL. */
int mcp__unet_run(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
                  const mcp_image *normal, double input_scale,
                  const mcp_denoise_tangent *t, int n, mcp_image **out, mcp_image **jt);

/* The network's working memory at most, by default: beyond it the image runs in tiles
 * (MCPOST_UNET_MAX_MEMORY_MB or the denoiser's max_memory_mb set another). */
#define MCP__UNET_MAX_MEMORY_MB 2048

/* mcp__unet_run in tiles of tile x tile pixels (a multiple of 16), each run on a crop
 * about 192 pixels larger on every side, starting on a multiple of 32 (unet.c's
 * TILE_OVERLAP), which gives the same bits as the whole image; tile
 * 0 runs the whole image when it fits in the memory available, else the largest tiles
 * that fit (mcp__unet_run does that). */
int mcp__unet_run_tiled(const mcp__unet *net, const mcp_image *color,
                        const mcp_image *albedo, const mcp_image *normal,
                        double input_scale, const mcp_denoise_tangent *t, int n, int tile,
                        mcp_image **out, mcp_image **jt);

/* ---- what a streamed denoise by bands needs of the run (unet.c; unet_bands.c) ---- */

/* The network's working memory at most, in bytes (max_memory_mb, else
 * MCPOST_UNET_MAX_MEMORY_MB, else MCP__UNET_MAX_MEMORY_MB); what the system can give
 * without swapping (MemAvailable, or MCPOST_MEMORY_AVAILABLE_MB; 0: unknown); the bytes
 * the network takes at its peak for n_images of w x h (padded to 16). */
double mcp__unet_memory_bound(const mcp__unet *net);
double mcp__unet_memory_available(void);
double mcp__unet_batch_bytes(int w, int h, int n_images);
/* The overlap and alignment of tiles that give the whole image's bits (352 and 64 on
 * Winograd F(4x4, 3x3), 192 and 32 for the direct loops). */
void mcp__unet_tile_margins(const mcp__unet *net, int *overlap, int *align);
/* The input rows (or columns) [*c0, *c1) that outputs [a0, a1) of an image n long read
 * with those margins: the crop of a tile, or of a band. */
void mcp__unet_crop_of(int a0, int a1, int n, int overlap, int align, int *c0, int *c1);
/* The bytes the whole-image run's network may take, given what is available (0:
 * unknown): the bound, or half of what is available where that is less (the results
 * and the inputs take the rest). */
double mcp__unet_tile_limit(const mcp__unet *net, double have);
/* The side of the square tiles mcp__unet_run_tiled picks for a W x H image whose
 * network would not fit within limit bytes (0: none fits); W x H when it fits. */
int mcp__unet_auto_tile(const mcp__unet *net, int W, int H, double limit);
/* The primal alone on a crop, in tiles tile_w wide and as tall as the crop, at the
 * input scale scale_in (> 0): a band's run. Its pixels see what they see in the image
 * the crop was cut from where the crop extends them by the tiles' overlap and starts
 * on the tiles' alignment (unet_bands.c). *out is a new RGB image of the crop's size. */
int mcp__unet_run_crop(const mcp__unet *net, const mcp_image *color,
                       const mcp_image *albedo, const mcp_image *normal, double scale_in,
                       int tile_w, mcp_image **out);
/* A progress bar of steps (a convolution of a tile a step) that the runs of this thread
 * step, begun where it shows: an image of a megapixel or more, on a terminal, not
 * quiet, no bar already running; 1 when it was. finish ends it (stops it where it got,
 * after a failure) when it was shown. */
int mcp__unet_progress_begin(mcp_progress *bar, const char *label, long steps, int W,
                             int H);
void mcp__unet_progress_finish(mcp_progress *bar, int shown, int failed);

/* ---- the U-Net over an image read and written in bands of rows (unet_bands.c) ---- */

/* The network of a `unet` denoiser (denoise_unet.c), its input_scale (<= 0: auto) and
 * tile settings; NULL for any other denoiser. */
const mcp__unet *mcp__unet_of(const mcp_denoiser *d, double *input_scale, int *tile);

/* band_rows output rows a band (a multiple of 64; 0: the whole image at once, as
 * mcp__unet_run_tiled runs it), in tiles tile_w wide; bytes: the peak the plan counts
 * (images, network and the process), within budget (the memory bound, or what is
 * available when less). */
typedef struct mcp__unet_bands {
    int band_rows, tile_w;
    double bytes, budget;
} mcp__unet_bands;
/* Where a band's rows come from and go: read gives new images of rows [y0, y1) of the
 * colour and, where the input has them, albedo and normal (NULL otherwise), each
 * checked as a whole read would check it; every row is read once, top to bottom,
 * before any is read again (the pre-pass), and a reader may report what that pass
 * found at its last row. write takes rows [y0, y0 + rows->height) of the result, in
 * increasing y. Both return 0, or -1 with the error set. */
typedef struct mcp__unet_band_io {
    void *ctx;
    int (*read)(void *ctx, int y0, int y1, mcp_image **color, mcp_image **albedo,
                mcp_image **normal);
    int (*write)(void *ctx, const mcp_image *rows, int y0);
} mcp__unet_band_io;
/* The plan for a W x H image whose inputs and output take whole_bytes when held whole:
 * band_rows 0 when they fit beside the network, else the bands and tiles that compute
 * the fewest pixels within the budget (tile > 0: tiles that wide). MCPOST_UNET_BAND_ROWS
 * forces bands of that many rows (rounded up to 64), or with "whole" the whole image
 * (the tests' ways to compare the two). -1 when not even bands of 64 rows fit. */
int mcp__unet_bands_plan(const mcp__unet *net, int W, int H, double whole_bytes, int tile,
                         mcp__unet_bands *plan);
/* Runs a plan with band_rows > 0: the pre-pass (every row read once: the checks, and the
 * autoexposure when input_scale <= 0), then each band read, run and written. */
int mcp__unet_bands_run(const mcp__unet *net, double input_scale, int W, int H,
                        const mcp__unet_bands *plan, const mcp__unet_band_io *io);

/* One 3x3 convolution (padding 1) of n images as Winograd F(2x2, 3x3)
 * (unet_winograd.c): the input of image k is channels 0 .. ca - 1 at a + (k * ca + i)
 * * h * w (with a_up: planes of h/2 x w/2 read upsampled, nearest 2x; h and w even) and
 * channels ca .. cin - 1 at b + (k * (cin - ca) + i - ca) * h * w (the skip; NULL when
 * ca == cin); out (n * cout planes of h x w) receives conv + bias for image 0 and conv
 * alone for the tangents, with relu image 0's ReLU and its mask on the others. weight
 * is [cout][cin][3][3]. */
int mcp__unet_conv_winograd(const float *weight, const float *bias, int cin, int cout,
                            const float *a, int ca, int a_up, const float *b, int n,
                            int h, int w, int relu, const unsigned char *mask_bits,
                            unsigned char *record_bits, float *out);
/* mask_bits (with relu 0): every output is zeroed where the recorded bit of its value
 * (value i of the out batch's image: bit i % 8 of byte i / 8; unet.c's trace of the
 * primal's ReLU) is 0, as it is written. Replaying a tangent's mask this way costs a
 * few operations per value in the cache instead of a pass over the whole batch. The
 * bits are read 8 bytes at a time: their block has 8 bytes to spare. */
void mcp__unet_mask_row(float *row, int n, const unsigned char *bits, size_t at);
/* The converse, for the primal's trace: bits [at, at + n) (zeros before) set where row
 * > 0, as the rows are written, instead of a pass over the finished activation. Bytes
 * that the row covers only in part are or-ed atomically: two tasks' rows may meet
 * inside a byte. */
void mcp__unet_record_row(unsigned char *bits, size_t at, const float *row, int n);
/* A transform's row of outputs into its activation: non-temporal stores where the CPU
 * has AVX-512 (the activation is far larger than the caches, and a plain store reads
 * each line before it fills it), else memcpy; the convolution fences them before its
 * barrier. */
void mcp__unet_store_row(float *dst, const float *src, int n);
/* bfloat16, the upper half of a float's bits: a tangents' pass with bf16 products
 * stores its activations so (unet.c), which halves the bytes the transforms move. From
 * float rounded to nearest, ties to even, in integer operations, so that every CPU
 * path gives the same bits (the values are finite). */
static inline uint16_t
mcp__unet_to_bf16(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (uint16_t)((u + 0x7fffu + (u >> 16 & 1u)) >> 16);
}
/* mcp__unet_store_row for a row of bfloat16 values, rounded as above. */
void mcp__unet_store_row16(uint16_t *dst, const float *src, int n);
/* A Winograd convolution F(m x m, 3x3): its tile, its transforms (unet_winograd.c
 * and unet_winograd4.c), and the driver that runs them over an image in tasks of
 * about chunk tiles with the matrix products of unet_gemm.c (unet_winograd.c). */
typedef struct mcp__unet_winograd {
    int m;          /* outputs per tile side: 2 or 4 */
    int elems;      /* transformed elements per tile: (m + 2)^2 */
    int chunk;      /* tiles per task, about */
    int row_floats; /* the transforms' row scratch: row_floats x (tiles + 1) floats */
    void (*transform_weights)(const float *weight, int cin, int cout, float *u);
    /* src: floats, or with src16 bfloat16 values (F(4x4, 3x3) only) */
    void (*transform_input)(const void *src, int src16, int up, int h, int w, int ty,
                            int tx0, int nt, float *rows, float *v, size_t ld);
    /* dst: floats, or with dst16 bfloat16 values rounded to nearest even (F(4x4,
     * 3x3) only) */
    /* record (the primal with relu): the ReLU mask's bits are set there as the rows
     * are written (mcp__unet_record_row) */
    void (*transform_output)(const float *m, size_t ld, int ty, int tx0, int nt, int h,
                             int w, float bias, int relu, int primal, const float *p0,
                             const unsigned char *bits, unsigned char *record,
                             size_t bit0, void *dst, int dst16, float *row);
} mcp__unet_winograd;

/* Which of a convolution's activations hold bfloat16 values instead of floats (a
 * tangents' pass with bf16 products: unet.c): its inputs a and b, its output. */
enum { MCP__UNET_HALF_A = 1, MCP__UNET_HALF_B = 2, MCP__UNET_HALF_OUT = 4 };

int mcp__unet_winograd_conv(const mcp__unet_winograd *k, const float *weight,
                            const float *bias, int cin, int cout, const void *a, int ca,
                            int a_up, const void *b, int n, int h, int w, int relu,
                            const unsigned char *mask_bits, unsigned char *record_bits,
                            int bf16, unsigned half, void *out);

/* The same as F(4x4, 3x3) (unet_winograd4.c): 1.78 times fewer multiply-adds, a
 * relative error ~1e-4 instead of ~1e-6; for the tangents' passes. */
int mcp__unet_conv_winograd4(const float *weight, const float *bias, int cin, int cout,
                             const void *a, int ca, int a_up, const void *b, int n, int h,
                             int w, int relu, const unsigned char *mask_bits,
                             unsigned char *record_bits, int bf16, unsigned half,
                             void *out);
/* Prefetches the input rows that tiles [t0, t0 + nt) of m x m outputs read from one
 * channel of elem-byte values (unet_winograd.c). */
void mcp__unet_prefetch_rows(const void *src, size_t elem, int up, int h, int w,
                             size_t t0, int nt, int tw, int m);
/* 1 when the convolutions run as Winograd products (the default), 0 for the direct
 * loops whose bits are the same on every x86-64 (net->fixed_bits, the denoiser's
 * fixed_bits setting, or MCPOST_UNET_FIXED set to anything but 0). */
int mcp__unet_fast(const mcp__unet *net);

/* ---- the activations' memory (unet_memory.c) ----
 * malloc for activations and scratch: large blocks on huge pages where the system
 * allows; free() releases. NULL (with the error set) when out of memory. */
void *mcp__unet_alloc(size_t bytes);
/* A block of at least bytes for a batch (*cap: what it holds), and its return: from
 * the pass's plan where it has one, else from the calling thread's cache of freed
 * blocks. In a dry pass the address is a placeholder that must not be touched. */
void *mcp__unet_block_take(size_t bytes, size_t *cap);
void mcp__unet_block_give(void *p, size_t cap);
/* keep 1: the cache keeps what it is given (tangents follow); drain empties it. */
void mcp__unet_blocks_keep(int keep);
void mcp__unet_blocks_drain(void);
/* The plan: record starts a dry pass (the layers allocate but compute nothing while
 * mcp__unet_plan_dry() is 1); finish places what it recorded in one arena; pass starts
 * each real pass (the primal's and each tangent's), which must repeat the dry one;
 * release frees the arena. mcp__unet_plan_arena: the arena and its size (NULL and 0
 * without a plan). */
void mcp__unet_plan_record(void);
int mcp__unet_plan_dry(void);
int mcp__unet_plan_finish(void);
void mcp__unet_plan_pass(void);
void mcp__unet_plan_release(void);
const void *mcp__unet_plan_arena(size_t *bytes);

/* The Winograd products' kernel (unet_gemm.c): C = A B in blocks of mr rows x nr
 * columns, picked for the CPU (or by MCPOST_UNET_KERNEL). */
typedef struct mcp__unet_gemm {
    const char *name; /* avx512, avx2 (with FMA), sse2 or generic */
    int mr, nr;
    void (*kernel)(void);
} mcp__unet_gemm;

void mcp__unet_gemm_choose(mcp__unet_gemm *g);
/* 1 when the CPU can run the kernel of that name. */
int mcp__unet_gemm_has(const char *name);
/* A (m x kn, row-major) packed as g's kernel reads it: ceil(m / mr) blocks of kn x mr,
 * zero rows past m. */
void mcp__unet_gemm_pack(const mcp__unet_gemm *g, const float *a, int m, int kn,
                         float *packed);
/* C = A B for packed A; B is kn x n (row stride ldb), C ceil(m / mr) * mr x n (row
 * stride ldc); n must be a multiple of g->nr, and ldb, ldc at least n. */
void mcp__unet_gemm_run(const mcp__unet_gemm *g, const float *packed, int m, int kn,
                        const float *b, size_t ldb, int n, float *c, size_t ldc);

/* OIDN's PU transfer function (normalised: x = PU(y)/PU(65504)) and its inverse. */
/* The tangents' products in bfloat16 (unet_gemm.c): whether the CPU has AVX512-BF16
 * and they were not turned off (MCPOST_UNET_BF16=0); B as pairs of rows rounded to bf16
 * (out[p][j] = row 2p | row 2p + 1 << 16, a zero row past kn); A packed in blocks of
 * MCP__UNET_BF16_MR rows; C = A B for n a multiple of MCP__UNET_BF16_NR columns. */
#define MCP__UNET_BF16_MR 8
#define MCP__UNET_BF16_NR 48
int mcp__unet_gemm_bf16_has(void);
void mcp__unet_bf16_pairs(const float *v, size_t ldv, int kn, int ncols, uint32_t *out,
                          size_t ldo);
void mcp__unet_gemm_bf16_pack(const float *a, int m, int kn, uint32_t *packed);
void mcp__unet_gemm_bf16_run(const uint32_t *packed, int m, int kn, const uint32_t *b,
                             size_t ldb, int n, float *c, size_t ldc);

float mcp__pu_forward(float y);
float mcp__pu_inverse(float x);

#endif
