/* unet_winograd4.c: the U-Net's 3x3 convolutions as Winograd F(4x4, 3x3) (Lavin &
 * Gray 2016), the default for every pass but exact tangents': each 4x4 block of outputs
 * from its 6x6 block of inputs with 36 multiplies per input channel instead of 144,
 * so 1.78 times fewer multiply-adds than F(2x2, 3x3) (unet_winograd.c) and 4 times fewer
 * than the direct loops, and 2.25 transformed values per output instead of 4, so that the
 * transforms move less memory too.
 *
 * Its transforms have coefficients up to 8 (interpolation at 0, +-1, +-2 and infinity),
 * so a value's rounding grows with them: the JVP through the whole network differs
 * from central differences of the double reference by 1.2e-6 (official weights) to
 * 2.1e-6 (a random network) in relative L2, against 0.5-0.8e-6 on F(2x2, 3x3)
 * (tests/estimate/test_unet.c, test_fast_kernels, measures both against 1e-5), and
 * the output by about 1e-6 from F(2x2, 3x3)'s (docs/denoisers.md): the primal runs on it
 * too since December 2026 (a 1080p apply 1.5x faster). The denoiser's exact_tangents
 * setting (or MCPOST_UNET_EXACT_TANGENTS=1) keeps the tangents on F(2x2, 3x3).
 *
 * Per 4x4 tile and input channel: V = B^T d B; per element e of 36: M_e = U_e V_e with
 * U = G g G^T (per layer and call, in double); Y = A^T M A, with
 *   B^T = [4 0 -5 0 1 0; 0 -4 -4 1 1 0; 0 4 -4 -1 1 0; 0 -2 -1 2 1 0; 0 2 -1 -2 1 0;
 *          0 4 0 -5 0 1],
 *   G = [1/4 0 0; -1/6 -1/6 -1/6; -1/6 1/6 -1/6; 1/24 1/12 1/6; 1/24 -1/12 1/6; 0 0 1],
 *   A^T = [1 1 1 1 1 0; 0 1 -1 2 -2 0; 0 1 1 4 4 0; 0 1 -1 8 -8 1].
 * The tasks, the matrix kernels and the determinism (each output one fixed sequence of
 * operations whatever the thread count or where the image was cut) are as in
 * unet_winograd.c. */
#include "unet_internal.h"
#include "internal.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#if defined(__x86_64__)
#include <emmintrin.h>
#include <xmmintrin.h>
#endif
#ifdef _OPENMP
#include <omp.h>
#endif

/* Each clone must give the same bits: no multiply-add contracted into an FMA (gcc's
 * default in ISO C; clang's is to contract, and AVX-512F has FMA) */
#ifdef __clang__
#pragma clang fp contract(off)
#endif
#if defined(__GNUC__) && defined(__x86_64__)
#define TRANSFORM_KERNEL __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define TRANSFORM_KERNEL
#endif

#define ALPHA 6   /* input tile side */
#define ELEMS 36  /* ALPHA x ALPHA transformed elements */
#define CHUNK4 64 /* tiles per task: 36 x (cin + cout) x CHUNK4 floats */

/* U[e][o][i] = (G g_oi G^T)[e]. */
static void
transform_weights(const float *weight, int cin, int cout, float *u)
{
    static const double G[ALPHA][3] = {{0.25, 0, 0},
                                       {-1.0 / 6, -1.0 / 6, -1.0 / 6},
                                       {-1.0 / 6, 1.0 / 6, -1.0 / 6},
                                       {1.0 / 24, 1.0 / 12, 1.0 / 6},
                                       {1.0 / 24, -1.0 / 12, 1.0 / 6},
                                       {0, 0, 1}};
    const size_t plane = (size_t)cout * cin;
#pragma omp parallel for schedule(static)
    for (int o = 0; o < cout; o++)
        for (int i = 0; i < cin; i++) {
            const float *g = weight + ((size_t)o * cin + i) * 9;
            double t[ALPHA][3]; /* G g */
            for (int a = 0; a < ALPHA; a++)
                for (int c = 0; c < 3; c++)
                    t[a][c] = G[a][0] * g[c] + G[a][1] * g[3 + c] + G[a][2] * g[6 + c];
            for (int a = 0; a < ALPHA; a++)
                for (int b = 0; b < ALPHA; b++) {
                    const double s =
                        G[b][0] * t[a][0] + G[b][1] * t[a][1] + G[b][2] * t[a][2];
                    u[(size_t)(a * ALPHA + b) * plane + (size_t)o * cin + i] = (float)s;
                }
        }
}

/* bfloat16, the upper half of a float's bits (unet_internal.h): to float exactly. */
static inline float
from_bf16(uint16_t b)
{
    const uint32_t u = (uint32_t)b << 16;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* Input row y of one channel for tiles [tx0, tx0 + nt), split by column phase:
 * ph[q][j] = column 4 (tx0 + j) - 1 + q for j <= nt, so that tile tx0 + j's six
 * columns are ph[0..3][j], ph[0][j + 1], ph[1][j + 1]; zeros outside the image. With
 * up, the source is at half resolution and read upsampled (nearest, 2x). src holds
 * floats, or with src16 bfloat16 values. */
static inline __attribute__((always_inline)) void
load_row4(const void *src, int src16, int up, int h, int w, int y, int tx0, int nt,
          float *ph[4])
{
    const int n = nt + 1;
    if (y < 0 || y >= h) {
        for (int q = 0; q < 4; q++)
            memset(ph[q], 0, (size_t)n * sizeof(float));
        return;
    }
    const int x0 = 4 * tx0 - 1;
    const size_t row = up ? (size_t)(y / 2) * (w / 2) : (size_t)y * w;
    const float *r = src16 ? NULL : (const float *)src + row;
    const uint16_t *r16 = src16 ? (const uint16_t *)src + row : NULL;
#define VALUE(x) (src16 ? from_bf16(r16[x]) : r[x])
    /* j in [lo, hi): all four columns inside the image */
    const int lo = x0 < 0 ? 1 : 0;
    int hi = w - 4 - x0 >= 0 ? (w - 4 - x0) / 4 + 1 : 0;
    hi = hi < n ? hi : n;
    int j = lo;
    if (!up) {
#if defined(__x86_64__)
        for (; j + 4 <= hi; j += 4) { /* 4 x 4 transposes */
            __m128 c0, c1, c2, c3;
            if (src16) { /* a bf16 value in a float's upper half is that float */
                const uint16_t *s = r16 + x0 + 4 * j;
                const __m128i zero = _mm_setzero_si128(),
                              lo8 = _mm_loadu_si128((const __m128i *)s),
                              hi8 = _mm_loadu_si128((const __m128i *)(s + 8));
                c0 = _mm_castsi128_ps(_mm_unpacklo_epi16(zero, lo8));
                c1 = _mm_castsi128_ps(_mm_unpackhi_epi16(zero, lo8));
                c2 = _mm_castsi128_ps(_mm_unpacklo_epi16(zero, hi8));
                c3 = _mm_castsi128_ps(_mm_unpackhi_epi16(zero, hi8));
            } else {
                const float *s = r + x0 + 4 * j;
                c0 = _mm_loadu_ps(s), c1 = _mm_loadu_ps(s + 4);
                c2 = _mm_loadu_ps(s + 8), c3 = _mm_loadu_ps(s + 12);
            }
            _MM_TRANSPOSE4_PS(c0, c1, c2, c3);
            _mm_storeu_ps(ph[0] + j, c0), _mm_storeu_ps(ph[1] + j, c1);
            _mm_storeu_ps(ph[2] + j, c2), _mm_storeu_ps(ph[3] + j, c3);
        }
#endif
        for (; j < hi; j++)
            for (int q = 0; q < 4; q++)
                ph[q][j] = VALUE(x0 + 4 * j + q);
    } else {
        /* columns 4 k - 1 .. 4 k + 2 (k = tx0 + j) read source columns 2 k - 1, 2 k,
         * 2 k, 2 k + 1 */
        float *restrict p0 = ph[0], *restrict p1 = ph[1], *restrict p2 = ph[2],
                        *restrict p3 = ph[3];
        if (src16) {
            const uint16_t *restrict rs = r16 + 2 * tx0;
#pragma omp simd
            for (int i = lo; i < hi; i++) {
                p0[i] = from_bf16(rs[2 * i - 1]);
                p1[i] = p2[i] = from_bf16(rs[2 * i]);
                p3[i] = from_bf16(rs[2 * i + 1]);
            }
        } else {
            const float *restrict rs = r + 2 * tx0;
#pragma omp simd
            for (int i = lo; i < hi; i++) {
                p0[i] = rs[2 * i - 1];
                p1[i] = rs[2 * i];
                p2[i] = rs[2 * i];
                p3[i] = rs[2 * i + 1];
            }
        }
        j = hi > lo ? hi : lo;
    }
    /* the edges: at most one value on the left (e < lo), a few on the right */
    const int edges[2][2] = {{0, lo}, {hi > lo ? hi : lo, n}};
    for (int side = 0; side < 2; side++)
        for (int e = edges[side][0]; e < edges[side][1]; e++)
            for (int q = 0; q < 4; q++) {
                const int x = x0 + 4 * e + q;
                ph[q][e] = x >= 0 && x < w ? VALUE(up ? x / 2 : x) : 0.0f;
            }
#undef VALUE
}

/* V for tiles [tx0, tx0 + nt) of tile row ty, one channel: v[e * ld + j], e = 6 a + b,
 * from input rows 4 ty - 1 .. 4 ty + 4: first B^T down the rows (whole phase arrays at
 * a time), then B across each tile. rows holds 24 (nt + 1) floats. */
TRANSFORM_KERNEL static void
transform_input4(const void *src, int src16, int up, int h, int w, int ty, int tx0,
                 int nt, float *rows, float *v, size_t ld)
{
    const size_t n = (size_t)nt + 1;
    float *ph[ALPHA][4];
    for (int r = 0; r < ALPHA; r++) {
        for (int q = 0; q < 4; q++)
            ph[r][q] = rows + (size_t)(4 * r + q) * n;
        load_row4(src, src16, up, h, w, 4 * ty - 1 + r, tx0, nt, ph[r]);
    }
    /* rows of B^T d, in place, phase by phase */
    for (int q = 0; q < 4; q++) {
        float *restrict d0 = ph[0][q], *restrict d1 = ph[1][q], *restrict d2 = ph[2][q];
        float *restrict d3 = ph[3][q], *restrict d4 = ph[4][q], *restrict d5 = ph[5][q];
#pragma omp simd
        for (size_t j = 0; j < n; j++) {
            const float x0 = d0[j], x1 = d1[j], x2 = d2[j], x3 = d3[j], x4 = d4[j],
                        x5 = d5[j];
            d0[j] = 4.0f * x0 - 5.0f * x2 + x4;
            d1[j] = x3 + x4 - 4.0f * (x1 + x2);
            d2[j] = 4.0f * (x1 - x2) + x4 - x3;
            d3[j] = 2.0f * (x3 - x1) + x4 - x2;
            d4[j] = 2.0f * (x1 - x3) + x4 - x2;
            d5[j] = 4.0f * x1 - 5.0f * x3 + x5;
        }
    }
    /* times B across each tile */
    for (int a = 0; a < ALPHA; a++) {
        const float *restrict p0 = ph[a][0], *restrict p1 = ph[a][1],
                              *restrict p2 = ph[a][2], *restrict p3 = ph[a][3];
        float *restrict v0 = v + (size_t)(ALPHA * a) * ld, *restrict v1 = v0 + ld,
                        *restrict v2 = v1 + ld, *restrict v3 = v2 + ld,
                        *restrict v4 = v3 + ld, *restrict v5 = v4 + ld;
#pragma omp simd
        for (int j = 0; j < nt; j++) {
            const float c0 = p0[j], c1 = p1[j], c2 = p2[j], c3 = p3[j], c4 = p0[j + 1],
                        c5 = p1[j + 1];
            v0[j] = 4.0f * c0 - 5.0f * c2 + c4;
            v1[j] = c3 + c4 - 4.0f * (c1 + c2);
            v2[j] = 4.0f * (c1 - c2) + c4 - c3;
            v3[j] = 2.0f * (c3 - c1) + c4 - c2;
            v4[j] = 2.0f * (c1 - c3) + c4 - c2;
            v5[j] = 4.0f * c1 - 5.0f * c3 + c5;
        }
    }
}

/* Y = A^T m A for tiles [tx0, tx0 + nt) of tile row ty, channel o (m[e * ld + j]);
 * the bias (image 0), and the ReLU (image 0) or image 0's mask (the others), stored
 * where inside the image. The 16 outputs of a tile are computed in 16 streams over the
 * tiles (o[4 a + q][j]: row a, column q), which vectorise, then interleaved into the
 * rows by 4 x 4 transposes. row holds 32 nt floats. */
TRANSFORM_KERNEL static void
transform_output4(const float *m, size_t ld, int ty, int tx0, int nt, int h, int w,
                  float bias, int relu, int primal, const float *p0,
                  const unsigned char *bits, unsigned char *record, size_t bit0,
                  void *dst, int dst16, float *row)
{
    float *restrict o = row;                      /* 16 streams of nt */
    float *restrict line = row + 16 * (size_t)nt; /* one output row, 4 nt */
#define M(e) m[(size_t)(e)*ld + j]
#pragma omp simd
    for (int j = 0; j < nt; j++) {
        /* A^T down the columns: s_a_b for column b */
        float s0[ALPHA], s1[ALPHA], s2[ALPHA], s3[ALPHA];
#pragma GCC unroll 6
        for (int b = 0; b < ALPHA; b++) {
            const float m0 = M(b), m1 = M(6 + b), m2 = M(12 + b), m3 = M(18 + b),
                        m4 = M(24 + b), m5 = M(30 + b);
            s0[b] = m0 + m1 + m2 + m3 + m4;
            s1[b] = m1 - m2 + 2.0f * (m3 - m4);
            s2[b] = m1 + m2 + 4.0f * (m3 + m4);
            s3[b] = m1 - m2 + 8.0f * (m3 - m4) + m5;
        }
#define ACROSS(a, t)                                                                     \
    o[(4 * (a) + 0) * (size_t)nt + j] = t[0] + t[1] + t[2] + t[3] + t[4] + bias;         \
    o[(4 * (a) + 1) * (size_t)nt + j] = t[1] - t[2] + 2.0f * (t[3] - t[4]) + bias;       \
    o[(4 * (a) + 2) * (size_t)nt + j] = t[1] + t[2] + 4.0f * (t[3] + t[4]) + bias;       \
    o[(4 * (a) + 3) * (size_t)nt + j] = t[1] - t[2] + 8.0f * (t[3] - t[4]) + t[5] + bias;
        ACROSS(0, s0)
        ACROSS(1, s1)
        ACROSS(2, s2)
        ACROSS(3, s3)
#undef ACROSS
    }
#undef M
    const int x0 = 4 * tx0, xn = w - x0 < 4 * nt ? w - x0 : 4 * nt;
    for (int a = 0; a < 4 && 4 * ty + a < h; a++) {
        const float *q0 = o + (size_t)(4 * a) * nt, *q1 = q0 + nt, *q2 = q1 + nt,
                    *q3 = q2 + nt;
        int j = 0;
#if defined(__x86_64__)
        for (; j + 4 <= nt; j += 4) {
            __m128 c0 = _mm_loadu_ps(q0 + j), c1 = _mm_loadu_ps(q1 + j),
                   c2 = _mm_loadu_ps(q2 + j), c3 = _mm_loadu_ps(q3 + j);
            _MM_TRANSPOSE4_PS(c0, c1, c2, c3);
            _mm_storeu_ps(line + 4 * j, c0), _mm_storeu_ps(line + 4 * j + 4, c1);
            _mm_storeu_ps(line + 4 * j + 8, c2), _mm_storeu_ps(line + 4 * j + 12, c3);
        }
#endif
        for (; j < nt; j++) {
            line[4 * j] = q0[j], line[4 * j + 1] = q1[j];
            line[4 * j + 2] = q2[j], line[4 * j + 3] = q3[j];
        }
        const size_t at = (size_t)(4 * ty + a) * w + x0;
        if (relu && primal) {
#pragma omp simd
            for (int x = 0; x < xn; x++)
                line[x] = line[x] > 0.0f ? line[x] : 0.0f;
        } else if (relu) {
            const float *restrict mask = p0 + at;
#pragma omp simd
            for (int x = 0; x < xn; x++)
                line[x] = mask[x] > 0.0f ? line[x] : 0.0f;
        } else if (bits)
            mcp__unet_mask_row(line, xn, bits, bit0 + at);
        if (record) mcp__unet_record_row(record, bit0 + at, line, xn);
        if (dst16) {
            mcp__unet_store_row16((uint16_t *)dst + at, line, xn);
        } else {
            mcp__unet_store_row((float *)dst + at, line, xn);
        }
    }
}

/* 4x4 outputs per tile, 36 elements; the transforms' rows: 24 (nt + 1) floats for the
 * input's phases, more than the output's 20 nt. */
static const mcp__unet_winograd f4x4 = {
    4, ELEMS, CHUNK4, 24, transform_weights, transform_input4, transform_output4};

int
mcp__unet_conv_winograd4(const float *weight, const float *bias, int cin, int cout,
                         const void *a, int ca, int a_up, const void *b, int n, int h,
                         int w, int relu, const unsigned char *mask_bits,
                         unsigned char *record_bits, int bf16, unsigned half, void *out)
{
    return mcp__unet_winograd_conv(&f4x4, weight, bias, cin, cout, a, ca, a_up, b, n, h,
                                   w, relu, mask_bits, record_bits, bf16, half, out);
}
