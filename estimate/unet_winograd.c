/* unet_winograd.c: the U-Net's 3x3 convolutions as Winograd F(2x2, 3x3) (Lavin &
 * Gray 2016): each 2x2 block of outputs from its 4x4 block of inputs with 16
 * multiplies per input channel instead of 36, so 2.25 times fewer multiply-adds than
 * the direct loops of unet.c. Per 2x2 tile and input channel the inputs are
 * transformed, V = B^T d B; per tile element e (of 16) the channels are mixed by one
 * matrix product, M_e = U_e V_e, with U_e the element of the transformed weights
 * G g G^T (computed per layer and call, in double, as the direct loops repack theirs);
 * the outputs are Y = A^T M A.
 *
 * The matrix products run in unet_gemm.c's kernels, picked for the CPU at run time
 * (AVX-512, AVX2 + FMA, SSE2). OpenMP runs independent tasks, each about CHUNK
 * consecutive tiles (in row-major order) of every image of the batch, the primal first,
 * and each output is one fixed sequence of operations whatever the thread count, the
 * chunk or where the image was cut. A task's transformed inputs and products live in a
 * per-thread scratch of 16 x (cin + cout) x CHUNK floats (under 2 MB), not in
 * image-sized buffers, so that peak memory stays below that of the direct loops. The
 * bits differ from the direct loops' (other order, FMA); unet.c keeps those as the
 * fixed-bit mode.
 *
 * Accuracy: the transforms have coefficients 0, +-1/2 and +-1, so they add a few float
 * roundings per value; tests/estimate/test_unet.c bounds the whole network's relative
 * L2 error against a double reference. */
#include "unet_internal.h"
#include "internal.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* The transforms are additions and scalings only, so wider vectors give the same
 * bits: AVX-512 or AVX2 where the CPU has it (picked at load time), provided no
 * multiply-add is contracted into an FMA (gcc's default in ISO C; clang's is to
 * contract, and AVX-512F has FMA). */
#ifdef __clang__
#pragma clang fp contract(off)
#endif
#if defined(__GNUC__) && defined(__x86_64__)
#define TRANSFORM_KERNEL __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define TRANSFORM_KERNEL
#endif

/* ---- a tangent's ReLU mask from the primal's recorded bits (unet_internal.h) ---- */

/* The 64 bits from bit b on (bits has 8 bytes to spare past its last value). */
static inline uint64_t
bits_at(const unsigned char *bits, size_t b)
{
    uint64_t word = 0;
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    memcpy(&word, bits + b / 8, sizeof word); /* one load */
#else
    for (int i = 0; i < 8; i++)
        word |= (uint64_t)bits[b / 8 + (size_t)i] << (8 * i);
#endif
    return word >> (b % 8);
}

static void
mask_row_generic(float *restrict row, int n, const unsigned char *restrict bits,
                 size_t at)
{
    for (int x = 0; x < n; x += 56) {
        const uint64_t word = bits_at(bits, at + (size_t)x);
        const int take = n - x < 56 ? n - x : 56;
        for (int i = 0; i < take; i++)
            row[x + i] = word >> i & 1u ? row[x + i] : 0.0f;
    }
}

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
/* 16 values per masked move. */
__attribute__((target("avx512f"))) static void
mask_row_avx512(float *restrict row, int n, const unsigned char *restrict bits, size_t at)
{
    int x = 0;
    for (; x + 16 <= n; x += 16) {
        const __mmask16 m = (__mmask16)bits_at(bits, at + (size_t)x);
        _mm512_storeu_ps(row + x, _mm512_maskz_mov_ps(m, _mm512_loadu_ps(row + x)));
    }
    if (x < n) mask_row_generic(row + x, n - x, bits, at + (size_t)x);
}

/* Stores n floats to dst with non-temporal stores where whole 64-byte lines are
 * written: an activation is far larger than the caches, and a plain store first reads
 * the line it fills. */
__attribute__((target("avx512f"))) static void
store_row_avx512(float *restrict dst, const float *restrict src, int n)
{
    int x = 0;
    for (; x < n && ((uintptr_t)(dst + x) & 63); x++)
        dst[x] = src[x];
    for (; x + 16 <= n; x += 16)
        _mm512_stream_ps(dst + x, _mm512_loadu_ps(src + x));
    for (; x < n; x++)
        dst[x] = src[x];
}

/* The same for bfloat16 values rounded to nearest even, 32 per 64-byte line. */
__attribute__((target("avx512f"))) static void
store_row16_avx512(uint16_t *restrict dst, const float *restrict src, int n)
{
    int x = 0;
    for (; x < n && ((uintptr_t)(dst + x) & 63); x++)
        dst[x] = mcp__unet_to_bf16(src[x]);
    const __m512i round = _mm512_set1_epi32(0x7fff), one = _mm512_set1_epi32(1);
    for (; x + 32 <= n; x += 32) {
        __m512i u0 = _mm512_castps_si512(_mm512_loadu_ps(src + x)),
                u1 = _mm512_castps_si512(_mm512_loadu_ps(src + x + 16));
        u0 = _mm512_srli_epi32(
            _mm512_add_epi32(_mm512_add_epi32(u0, round),
                             _mm512_and_si512(_mm512_srli_epi32(u0, 16), one)),
            16);
        u1 = _mm512_srli_epi32(
            _mm512_add_epi32(_mm512_add_epi32(u1, round),
                             _mm512_and_si512(_mm512_srli_epi32(u1, 16), one)),
            16);
        const __m512i both =
            _mm512_inserti64x4(_mm512_castsi256_si512(_mm512_cvtepi32_epi16(u0)),
                               _mm512_cvtepi32_epi16(u1), 1);
        _mm512_stream_si512((void *)(dst + x), both);
    }
    for (; x < n; x++)
        dst[x] = mcp__unet_to_bf16(src[x]);
}
#endif

void
mcp__unet_store_row16(uint16_t *dst, const float *src, int n)
{
#if defined(__GNUC__) && defined(__x86_64__)
    if (__builtin_cpu_supports("avx512f")) {
        store_row16_avx512(dst, src, n);
        return;
    }
#endif
    for (int x = 0; x < n; x++)
        dst[x] = mcp__unet_to_bf16(src[x]);
}

void
mcp__unet_store_row(float *dst, const float *src, int n)
{
#if defined(__GNUC__) && defined(__x86_64__)
    if (__builtin_cpu_supports("avx512f")) {
        store_row_avx512(dst, src, n);
        return;
    }
#endif
    memcpy(dst, src, (size_t)n * sizeof(float));
}

/* One byte's bits [b0, b0 + k) from row[0 .. k) (> 0), or-ed into it atomically. */
static void
record_part(unsigned char *byte, int b0, const float *row, int k)
{
    unsigned v = 0;
    for (int i = 0; i < k; i++)
        v |= (unsigned)(row[i] > 0.0f) << (b0 + i);
    if (v) __atomic_fetch_or(byte, (unsigned char)v, __ATOMIC_RELAXED);
}

#if defined(__GNUC__) && defined(__x86_64__)
/* Whole bytes of bits, 16 values at a time: a compare's mask is the two bytes as they
 * lie in memory (lane i is bit i % 8 of byte i / 8). Returns the values done. Built
 * for the baseline, the byte loop below took a quarter of the primal products' time. */
__attribute__((target("avx512f"))) static int
record_bytes_avx512(unsigned char *m, const float *row, int n)
{
    const __m512 zero = _mm512_setzero_ps();
    int x = 0;
    for (; x + 16 <= n; x += 16) {
        const uint16_t v =
            (uint16_t)_mm512_cmp_ps_mask(_mm512_loadu_ps(row + x), zero, _CMP_GT_OQ);
        memcpy(m + x / 8, &v, sizeof v);
    }
    return x;
}
#endif

void
mcp__unet_record_row(unsigned char *bits, size_t at, const float *row, int n)
{
    int x = 0;
    if (at % 8) { /* a byte shared with the row before it */
        const int k = 8 - (int)(at % 8) < n ? 8 - (int)(at % 8) : n;
        record_part(bits + at / 8, (int)(at % 8), row, k);
        x = k;
    }
    unsigned char *restrict m = bits + (at + (size_t)x) / 8;
#if defined(__GNUC__) && defined(__x86_64__)
    if (x < n && __builtin_cpu_supports("avx512f")) {
        const int done = record_bytes_avx512(m, row + x, n - x);
        x += done, m += done / 8;
    }
#endif
    for (; x + 8 <= n; x += 8, m++) { /* whole bytes: this row's alone */
        unsigned v = 0;
        for (int b = 0; b < 8; b++)
            v |= (unsigned)(row[x + b] > 0.0f) << b;
        *m = (unsigned char)v;
    }
    if (x < n) record_part(m, 0, row + x, n - x); /* one shared with the next */
}

void
mcp__unet_mask_row(float *row, int n, const unsigned char *bits, size_t at)
{
#if defined(__GNUC__) && defined(__x86_64__)
    if (__builtin_cpu_supports("avx512f")) {
        mask_row_avx512(row, n, bits, at);
        return;
    }
#endif
    mask_row_generic(row, n, bits, at);
}

/* Tiles per task: small enough that a task's transformed inputs and products (16 x
 * (cin + cout) x CHUNK floats) stay in the L2 cache, large enough for whole kernel
 * blocks (bench_unet measured 64 to 768). */
#ifndef CHUNK
#define CHUNK 128
#endif

/* U[e][o][i] = (G g_oi G^T)[e], G = [1 0 0; 1/2 1/2 1/2; 1/2 -1/2 1/2; 0 0 1]. */
static void
transform_weights(const float *weight, int cin, int cout, float *u)
{
    static const double G[4][3] = {
        {1, 0, 0}, {0.5, 0.5, 0.5}, {0.5, -0.5, 0.5}, {0, 0, 1}};
    const size_t plane = (size_t)cout * cin;
#pragma omp parallel for schedule(static)
    for (int o = 0; o < cout; o++)
        for (int i = 0; i < cin; i++) {
            const float *g = weight + ((size_t)o * cin + i) * 9;
            double t[4][3]; /* G g */
            for (int a = 0; a < 4; a++)
                for (int c = 0; c < 3; c++)
                    t[a][c] = G[a][0] * g[c] + G[a][1] * g[3 + c] + G[a][2] * g[6 + c];
            for (int a = 0; a < 4; a++)
                for (int b = 0; b < 4; b++) {
                    double s = G[b][0] * t[a][0] + G[b][1] * t[a][1] + G[b][2] * t[a][2];
                    u[(size_t)(a * 4 + b) * plane + (size_t)o * cin + i] = (float)s;
                }
        }
}

/* Input row y of one channel for tiles [tx0, tx0 + nt), split by column parity:
 * even[j] = column 2 (tx0 + j) - 1 and odd[j] = column 2 (tx0 + j), for j <= nt (zeros
 * outside the image, and for rows outside it), so that tile tx0 + j's four columns are
 * even[j], odd[j], even[j + 1], odd[j + 1]. */
static inline void
load_row(const float *src, int h, int w, int y, int tx0, int nt, float *restrict even,
         float *restrict odd)
{
    if (y < 0 || y >= h) {
        memset(even, 0, (size_t)(nt + 1) * sizeof(float));
        memset(odd, 0, (size_t)(nt + 1) * sizeof(float));
        return;
    }
    const float *r = src + (size_t)y * w + 2 * tx0; /* column 2 tx0 */
    const int x0 = 2 * tx0;
    /* j in [lo, hi): both columns inside the image */
    const int lo = x0 > 0 ? 0 : 1,
              hi = (w - x0 + 1) / 2 < nt + 1 ? (w - x0 + 1) / 2 : nt + 1;
#pragma omp simd
    for (int j = lo; j < hi; j++) {
        even[j] = r[2 * j - 1];
        odd[j] = r[2 * j];
    }
    if (lo) {
        even[0] = 0.0f;
        odd[0] = r[0];
    }
    for (int j = hi > lo ? hi : lo; j <= nt; j++) { /* at and past the right edge */
        even[j] = x0 + 2 * j - 1 < w ? r[2 * j - 1] : 0.0f;
        odd[j] = x0 + 2 * j < w ? r[2 * j] : 0.0f;
    }
}

/* The same for a source at half resolution that the convolution reads upsampled
 * (nearest, 2x: the decoder's upsampling, never stored): row y is the source's row y / 2
 * and columns 2 j - 1, 2 j its columns j - 1, j. */
static inline void
load_row_up(const float *src, int h, int w, int y, int tx0, int nt, float *restrict even,
            float *restrict odd)
{
    const int lw = w / 2; /* h and w are even (the network pads to 16) */
    if (y < 0 || y >= h) {
        memset(even, 0, (size_t)(nt + 1) * sizeof(float));
        memset(odd, 0, (size_t)(nt + 1) * sizeof(float));
        return;
    }
    const float *r = src + (size_t)(y / 2) * lw;
    /* j in [lo, hi): both source columns tx0 + j - 1 and tx0 + j inside */
    const int lo = tx0 > 0 ? 0 : 1, hi = lw - tx0 < nt + 1 ? lw - tx0 : nt + 1;
#pragma omp simd
    for (int j = lo; j < hi; j++) {
        even[j] = r[tx0 + j - 1];
        odd[j] = r[tx0 + j];
    }
    if (lo) {
        even[0] = 0.0f;
        odd[0] = r[0];
    }
    for (int j = hi > lo ? hi : lo; j <= nt; j++) { /* at and past the right edge */
        even[j] = tx0 + j - 1 < lw ? r[tx0 + j - 1] : 0.0f;
        odd[j] = 0.0f;
    }
}

/* Asks for the input rows that the tiles [t0, t0 + nt) (row-major, tw per row, m x m
 * outputs each) of one channel read, one cache line at a time: the rows of a task are
 * short runs in planes far apart, too short for the hardware prefetcher to find. */
void
mcp__unet_prefetch_rows(const void *src, size_t elem, int up, int h, int w, size_t t0,
                        int nt, int tw, int m)
{
    const int ty0 = (int)(t0 / tw), ty1 = (int)((t0 + nt - 1) / tw);
    int x0 = ty0 == ty1 ? m * (int)(t0 % tw) - 1 : 0;
    int x1 = ty0 == ty1 ? m * (int)((t0 + nt - 1) % tw) + m : w - 1;
    int y0 = m * ty0 - 1, y1 = m * ty1 + m;
    if (up) /* the source's own rows and columns */
        h /= 2, w /= 2, x0 /= 2, x1 /= 2, y0 /= 2, y1 /= 2;
    const int line = (int)(64 / elem); /* values per cache line */
    for (int y = y0 > 0 ? y0 : 0; y <= y1 && y < h; y++) {
        const char *r = (const char *)src + (size_t)y * w * elem;
        for (int x = x0 > 0 ? x0 : 0; x <= x1 && x < w; x += line)
            __builtin_prefetch(r + (size_t)x * elem);
    }
}

/* V for tiles [tx0, tx0 + nt) of tile row ty, one channel: v[e * ld + j], e = 4 a + b,
 * from the input rows 2 ty - 1 .. 2 ty + 2 (of the source upsampled, with up), V = B^T d
 * B with B^T = [1 0 -1 0; 0 1 1 0; 0 -1 1 0; 0 1 0 -1]: first B^T down the rows (whole
 * rows at a time), then B across each tile. rows holds 8 (nt + 1) floats. */
TRANSFORM_KERNEL static void
transform_input(const void *src_, int src16, int up, int h, int w, int ty, int tx0,
                int nt, float *rows, float *v, size_t ld)
{
    (void)src16; /* floats only: F(2x2, 3x3) runs no bf16 pass */
    const float *src = src_;
    const size_t n = (size_t)nt + 1;
    float *e[4], *o[4];
    for (int r = 0; r < 4; r++) {
        e[r] = rows + 2 * r * n;
        o[r] = e[r] + n;
        if (up)
            load_row_up(src, h, w, 2 * ty - 1 + r, tx0, nt, e[r], o[r]);
        else
            load_row(src, h, w, 2 * ty - 1 + r, tx0, nt, e[r], o[r]);
    }
    /* rows of B^T d, in place: q0 = d0 - d2, q1 = d1 + d2, q2 = d2 - d1, q3 = d1 - d3 */
    for (int p = 0; p < 2; p++) {
        float *restrict d0 = p ? o[0] : e[0], *restrict d1 = p ? o[1] : e[1];
        float *restrict d2 = p ? o[2] : e[2], *restrict d3 = p ? o[3] : e[3];
#pragma omp simd
        for (size_t j = 0; j < n; j++) {
            const float x0 = d0[j], x1 = d1[j], x2 = d2[j], x3 = d3[j];
            d0[j] = x0 - x2;
            d1[j] = x1 + x2;
            d2[j] = x2 - x1;
            d3[j] = x1 - x3;
        }
    }
    /* times B across each tile: columns c0 = e[j], c1 = o[j], c2 = e[j + 1],
     * c3 = o[j + 1] */
    for (int a = 0; a < 4; a++) {
        const float *restrict qe = e[a], *restrict qo = o[a];
        float *restrict v0 = v + (size_t)(4 * a) * ld, *restrict v1 = v0 + ld;
        float *restrict v2 = v1 + ld, *restrict v3 = v2 + ld;
#pragma omp simd
        for (int j = 0; j < nt; j++) {
            const float c0 = qe[j], c1 = qo[j], c2 = qe[j + 1], c3 = qo[j + 1];
            v0[j] = c0 - c2;
            v1[j] = c1 + c2;
            v2[j] = c2 - c1;
            v3[j] = c1 - c3;
        }
    }
}

/* Y = A^T m A for tiles [tx0, tx0 + nt) of tile row ty, channel o (m[e * ld + j]),
 * A^T = [1 1 1 0; 0 1 -1 -1]; then the bias (image 0), and the ReLU (image 0) or image
 * 0's mask (tangents), stored where inside the image. row holds 4 nt floats. */
TRANSFORM_KERNEL static void
transform_output(const float *m, size_t ld, int ty, int tx0, int nt, int h, int w,
                 float bias, int relu, int primal, const float *p0,
                 const unsigned char *bits, unsigned char *record, size_t bit0,
                 void *dst_, int dst16, float *row)
{
    (void)dst16; /* floats only, as the input */
    float *dst = dst_;
    float *restrict y0 = row, *restrict y1 = row + 2 * nt;
    const float *restrict m0 = m, *restrict m1 = m + 4 * ld, *restrict m2 = m + 8 * ld,
                          *restrict m3 = m + 12 * ld;
#pragma omp simd
    for (int j = 0; j < nt; j++) {
        /* A^T down the columns of the tile, then across */
        const float s00 = m0[j] + m1[j] + m2[j], s10 = m1[j] - m2[j] - m3[j];
        const float s01 = m0[ld + j] + m1[ld + j] + m2[ld + j];
        const float s11 = m1[ld + j] - m2[ld + j] - m3[ld + j];
        const float s02 = m0[2 * ld + j] + m1[2 * ld + j] + m2[2 * ld + j];
        const float s12 = m1[2 * ld + j] - m2[2 * ld + j] - m3[2 * ld + j];
        const float s03 = m0[3 * ld + j] + m1[3 * ld + j] + m2[3 * ld + j];
        const float s13 = m1[3 * ld + j] - m2[3 * ld + j] - m3[3 * ld + j];
        y0[2 * j] = s00 + s01 + s02 + bias;
        y0[2 * j + 1] = s01 - s02 - s03 + bias;
        y1[2 * j] = s10 + s11 + s12 + bias;
        y1[2 * j + 1] = s11 - s12 - s13 + bias;
    }
    const int x0 = 2 * tx0, xn = w - x0 < 2 * nt ? w - x0 : 2 * nt;
    for (int a = 0; a < 2 && 2 * ty + a < h; a++) {
        const size_t at = (size_t)(2 * ty + a) * w + x0;
        float *restrict y = a ? y1 : y0;
        const float *restrict mask = p0 + at;
        if (relu && primal) {
#pragma omp simd
            for (int x = 0; x < xn; x++) {
                const float t = y[x];
                y[x] = t > 0.0f ? t : 0.0f;
            }
        } else if (relu) {
#pragma omp simd
            for (int x = 0; x < xn; x++) {
                const float t = y[x];
                y[x] = mask[x] > 0.0f ? t : 0.0f;
            }
        } else if (bits)
            mcp__unet_mask_row(y, xn, bits, bit0 + at);
        if (record) mcp__unet_record_row(record, bit0 + at, y, xn);
        mcp__unet_store_row(dst + at, y, xn);
    }
}

/* The F(2x2, 3x3) convolution: 2x2 outputs per tile, 16 elements, rows of 8 (nt + 1)
 * floats for the transforms. */
static const mcp__unet_winograd f2x2 = {
    2, 16, CHUNK, 8, transform_weights, transform_input, transform_output};

int
mcp__unet_conv_winograd(const float *weight, const float *bias, int cin, int cout,
                        const float *a, int ca, int a_up, const float *b, int n, int h,
                        int w, int relu, const unsigned char *mask_bits,
                        unsigned char *record_bits, float *out)
{
    return mcp__unet_winograd_conv(&f2x2, weight, bias, cin, cout, a, ca, a_up, b, n, h,
                                   w, relu, mask_bits, record_bits, 0, 0, out);
}

/* The mask's bits of one plane (from bit plane0) for the tiles [t0, t0 + nt) of a
 * task: a line at each piece of pixel row. */
#define MASK_AHEAD 4
static void
prefetch_mask(const unsigned char *bits, size_t plane0, size_t t0, int nt, int tw,
              int tile_m, int w, int h)
{
    for (int j = 0; j < nt;) {
        const int ty = (int)((t0 + j) / tw), tx = (int)((t0 + j) % tw);
        const int len = tw - tx < nt - j ? tw - tx : nt - j;
        for (int a = 0; a < tile_m && tile_m * ty + a < h; a++) {
            const size_t b = plane0 + (size_t)(tile_m * ty + a) * w + (size_t)tile_m * tx;
            __builtin_prefetch(bits + b / 8);
            __builtin_prefetch(bits + (b + (size_t)tile_m * len) / 8);
        }
        j += len;
    }
}

/* A Winograd convolution of either size (unet_internal.h). */
int
mcp__unet_winograd_conv(const mcp__unet_winograd *k_, const float *weight,
                        const float *bias, int cin, int cout, const void *a_, int ca,
                        int a_up, const void *b_, int n, int h, int w, int relu,
                        const unsigned char *mask_bits, unsigned char *record_bits,
                        int bf16, unsigned half, void *out_)
{
    /* the activations as bytes: bfloat16 values (half) take 2, floats 4 */
    const int a16 = !!(half & MCP__UNET_HALF_A), b16 = !!(half & MCP__UNET_HALF_B),
              out16 = !!(half & MCP__UNET_HALF_OUT);
    const size_t ea = a16 ? 2 : 4, eb = b16 ? 2 : 4, eo = out16 ? 2 : 4;
    const char *a = a_, *b = b_;
    char *out = out_;
    const int tile_m = k_->m, elems = k_->elems;
    mcp__unet_gemm g;
    mcp__unet_gemm_choose(&g);
    const int cb = cin - ca, th = (h + tile_m - 1) / tile_m,
              tw = (w + tile_m - 1) / tile_m;
    /* tasks: the image's tiles in row-major order, chunk at a time (the last fewer),
     * chunk about k_->chunk in whole column blocks of the kernel (at least one) */
    const size_t n_tiles = (size_t)th * tw;
    const int rounded = (k_->chunk + g.nr / 2) / g.nr * g.nr,
              chunk = rounded > 0 ? rounded : g.nr;
    const int chunks = (int)((n_tiles + chunk - 1) / chunk);
    const int mp = (cout + g.mr - 1) / g.mr * g.mr; /* rows of the products */
    const size_t ld_max = (size_t)chunk;            /* whole blocks */
    const size_t hw = (size_t)h * w, plane = (size_t)cout * cin;
    const size_t a_hw = a_up ? hw / 4 : hw; /* a's planes */
    int n_threads = 1;
#ifdef _OPENMP
    n_threads = omp_get_max_threads();
#endif
    /* bf16 products run in the AVX-512 float kernel's blocks (every AVX512-BF16 CPU has
       that kernel), on the weights and V's channels as pairs of rows, kp of them */
    bf16 = bf16 && g.mr == MCP__UNET_BF16_MR && g.nr == MCP__UNET_BF16_NR;
    const int kp = (cin + 1) / 2;
    /* per thread: V (cin x elems x ld; with bf16, 2 channels' at a time), M (mp x elems
       x ld), rows for the transforms, and with bf16 V in pairs of channels (kp x elems x
       ld) */
    const size_t v_channels = bf16 ? 2 : (size_t)cin;
    const size_t per_thread = elems * ld_max * (v_channels + mp) +
                              (size_t)k_->row_floats * ((size_t)chunk + 1) +
                              (bf16 ? (size_t)kp * elems * ld_max : 0);
    float *u = mcp_malloc(elems * plane * sizeof(float)), *packed = NULL;
    uint32_t *packed_bf16 = NULL;
    if (u && bf16)
        packed_bf16 = mcp_malloc((size_t)elems * mp * kp * sizeof(uint32_t));
    else if (u)
        packed = mcp_malloc((size_t)elems * mp * cin * sizeof(float));
    float *scratch = packed || packed_bf16
                         ? mcp__unet_alloc((size_t)n_threads * per_thread * sizeof(float))
                         : NULL;
    if (!scratch) {
        free(u), free(packed), free(packed_bf16);
        return -1;
    }
    k_->transform_weights(weight, cin, cout, u);
    for (int e = 0; e < elems; e++)
        if (bf16)
            mcp__unet_gemm_bf16_pack(u + e * plane, cout, cin,
                                     packed_bf16 + (size_t)e * mp * kp);
        else
            mcp__unet_gemm_pack(&g, u + e * plane, cout, cin,
                                packed + (size_t)e * mp * cin);
#pragma omp parallel num_threads(n_threads)
    {
        int thread = 0;
#ifdef _OPENMP
        thread = omp_get_thread_num();
#endif
        float *v = scratch + (size_t)thread * per_thread;
        float *m = v + elems * ld_max * v_channels;
        float *rows = m + elems * ld_max * (size_t)mp;
        uint32_t *pairs =
            (uint32_t *)(rows + (size_t)k_->row_floats * ((size_t)chunk + 1));
        /* a task is one chunk of every image, the primal first: the tangents take its
         * ReLU mask while it is still in the cache */
#pragma omp for schedule(dynamic, 1)
        for (int c = 0; c < chunks; c++)
            for (int k = 0; k < n; k++) {
                const size_t t0 = (size_t)c * chunk;
                const int nt =
                    (int)(n_tiles - t0 < (size_t)chunk ? n_tiles - t0 : (size_t)chunk);
                const int ld = (nt + g.nr - 1) / g.nr * g.nr;
                /* V and M channel-major: channel i's elements are rows i elems + e
                 * of ld floats, so that a transform reads or writes one block of
                 * elems x ld floats per channel. Element-major, the elems rows of a
                 * channel lay cin (or mp) x ld floats apart, a multiple of 4 kB at
                 * most layer sizes: the output transform's 36 streams then shared a
                 * few L1 sets (perf: the output transforms -10 to -28%, the
                 * products +1 to +4% with their rows elems x ld apart). */
                const size_t se = (size_t)ld, sc = (size_t)elems * ld;
                for (int i = 0; i < cin; i++) {
                    /* with bf16 products, V holds a pair of channels at a time (in
                       the L1 cache), which the pairs take at once */
                    float *vi = v + (size_t)(bf16 ? i & 1 : i) * sc;
                    const int up = i < ca && a_up, src16 = i < ca ? a16 : b16;
                    const void *src = i < ca ? a + ((size_t)k * ca + i) * a_hw * ea
                                             : b + ((size_t)k * cb + (i - ca)) * hw * eb;
                    if (i + 1 < cin) /* the next channel's rows, while this one runs */
                        mcp__unet_prefetch_rows(
                            i + 1 < ca ? a + ((size_t)k * ca + i + 1) * a_hw * ea
                                       : b + ((size_t)k * cb + (i + 1 - ca)) * hw * eb,
                            i + 1 < ca ? ea : eb, i + 1 < ca && a_up, h, w, t0, nt, tw,
                            tile_m);
                    /* the chunk's pieces of tile rows */
                    for (int j = 0; j < nt;) {
                        const int ty = (int)((t0 + j) / tw), tx = (int)((t0 + j) % tw);
                        const int len = tw - tx < nt - j ? tw - tx : nt - j;
                        k_->transform_input(src, src16, up, h, w, ty, tx, len, rows,
                                            vi + j, se);
                        j += len;
                    }
                    /* the padding columns: zeros, so that the padded outputs are
                     * finite (they are not stored); none but in the last task */
                    for (int e = 0; e < elems && nt < ld; e++)
                        memset(vi + e * se + nt, 0, (size_t)(ld - nt) * sizeof(float));
                    /* bf16: a pair of channels' blocks into one block of pairs while
                     * they are in the cache, [p][e][j] as V's [i][e][j] */
                    if (bf16 && (i % 2 == 1 || i == cin - 1)) {
                        const int i0 = i & ~1;
                        mcp__unet_bf16_pairs(v, sc, i - i0 + 1, (int)sc,
                                             pairs + (size_t)(i0 / 2) * sc, sc);
                    }
                }
                for (int e = 0; e < elems; e++)
                    if (bf16)
                        mcp__unet_gemm_bf16_run(packed_bf16 + (size_t)e * mp * kp, cout,
                                                cin, pairs + e * se, sc, ld, m + e * se,
                                                sc);
                    else
                        mcp__unet_gemm_run(&g, packed + (size_t)e * mp * cin, cout, cin,
                                           v + e * se, sc, ld, m + e * se, sc);
                for (int o = 0; o < cout; o++) {
                    /* a replayed mask: its bits for a plane a few ahead, whose rows
                     * lie a plane apart (a cache miss each, which no hardware
                     * prefetcher foresees) */
                    if (mask_bits && o + MASK_AHEAD < cout)
                        prefetch_mask(mask_bits, (size_t)(o + MASK_AHEAD) * hw, t0, nt,
                                      tw, tile_m, w, h);
                    for (int j = 0; j < nt;) {
                        const int ty = (int)((t0 + j) / tw), tx = (int)((t0 + j) % tw);
                        const int len = tw - tx < nt - j ? tw - tx : nt - j;
                        k_->transform_output(
                            m + (size_t)o * sc + j, se, ty, tx, len, h, w,
                            k == 0 && bias ? bias[o] : 0.0f, relu, k == 0,
                            out16 ? NULL : (const float *)out + (size_t)o * hw, mask_bits,
                            k == 0 ? record_bits : NULL, (size_t)o * hw,
                            out + ((size_t)k * cout + o) * hw * eo, out16, rows);
                        j += len;
                    }
                }
            }
#if defined(__GNUC__) && defined(__x86_64__)
        _mm_sfence(); /* the non-temporal stores, before the barrier (store_row) */
#endif
    }
    free(u), free(packed), free(packed_bf16), free(scratch);
    return 0;
}
