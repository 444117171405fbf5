/* unet_gemm.c: the matrix products of the U-Net's Winograd convolutions
 * (unet_winograd.c), C = A B with A the packed transformed weights (cout x cin) and B
 * the transformed inputs (cin x tiles), in register-blocked kernels picked at run time
 * for the CPU: AVX-512F, AVX2 + FMA, or SSE2 (every x86-64; a portable loop
 * elsewhere). MCPOST_UNET_KERNEL=avx512|avx2|sse2|generic picks one the CPU has (the
 * tests compare them; a kernel the CPU lacks leaves the choice to the CPU).
 *
 * Every element of C is one sum over k in order, started at 0, one rounding per step
 * (an FMA, or a multiply and an add without FMA), whatever the element's place in the
 * block, the number of columns or the thread count: a tile's outputs do not depend on
 * where the image was cut (unet.c's tiles give the same bits as the whole image).
 * Blocks never have remainders: the caller pads A to a multiple of mr rows and B and C
 * to a multiple of nr columns.
 *
 * The tangents' passes may run in bfloat16 instead (mcp__unet_gemm_bf16_*): A and B
 * rounded to bf16 (8 significant bits, round to nearest even), pairs of k multiplied
 * and summed into float by AVX512-BF16's vdpbf16ps, twice the multiply-adds per
 * instruction of the float kernel. A product then carries a relative rounding of
 * about 2^-9 where the float kernel's is 2^-24; the tangents feed s^2 and SURE's
 * divergence, which need about 10% (docs/denoisers.md has the measured accuracy and
 * what it does to the stop). */
#include "unet_internal.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* C (mr x nr at c, row stride ldc) = sum over k < kn of a[k * mr + r] * b[k * ldb + j] */
typedef void (*gemm_kernel_fn)(const float *restrict a, const float *restrict b,
                               size_t ldb, int kn, float *restrict c, size_t ldc);

/* The portable kernel: 4 rows x 8 columns, a multiply and an add per step. */
#define GENERIC_MR 4
#define GENERIC_NR 8

static void
kernel_generic(const float *restrict a, const float *restrict b, size_t ldb, int kn,
               float *restrict c, size_t ldc)
{
    float acc[GENERIC_MR][GENERIC_NR] = {{0}};
    for (int k = 0; k < kn; k++) {
        const float *restrict bk = b + (size_t)k * ldb, *restrict ak =
                                                            a + (size_t)k * GENERIC_MR;
        for (int r = 0; r < GENERIC_MR; r++)
            for (int j = 0; j < GENERIC_NR; j++) {
                const float p = ak[r] * bk[j];
                acc[r][j] = acc[r][j] + p;
            }
    }
    for (int r = 0; r < GENERIC_MR; r++)
        memcpy(c + (size_t)r * ldc, acc[r], sizeof acc[r]);
}

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>

/* SSE2: 4 rows x 8 columns (two 4-float vectors), multiply then add. */
#define SSE2_MR 4
#define SSE2_NR 8

static void
kernel_sse2(const float *restrict a, const float *restrict b, size_t ldb, int kn,
            float *restrict c, size_t ldc)
{
    __m128 c00 = _mm_setzero_ps(), c01 = c00, c10 = c00, c11 = c00;
    __m128 c20 = c00, c21 = c00, c30 = c00, c31 = c00;
    for (int k = 0; k < kn; k++, a += SSE2_MR) {
        const float *bk = b + (size_t)k * ldb;
        const __m128 b0 = _mm_loadu_ps(bk), b1 = _mm_loadu_ps(bk + 4);
        __m128 x = _mm_set1_ps(a[0]);
        c00 = _mm_add_ps(c00, _mm_mul_ps(x, b0)),
        c01 = _mm_add_ps(c01, _mm_mul_ps(x, b1));
        x = _mm_set1_ps(a[1]);
        c10 = _mm_add_ps(c10, _mm_mul_ps(x, b0)),
        c11 = _mm_add_ps(c11, _mm_mul_ps(x, b1));
        x = _mm_set1_ps(a[2]);
        c20 = _mm_add_ps(c20, _mm_mul_ps(x, b0)),
        c21 = _mm_add_ps(c21, _mm_mul_ps(x, b1));
        x = _mm_set1_ps(a[3]);
        c30 = _mm_add_ps(c30, _mm_mul_ps(x, b0)),
        c31 = _mm_add_ps(c31, _mm_mul_ps(x, b1));
    }
    _mm_storeu_ps(c, c00), _mm_storeu_ps(c + 4, c01);
    _mm_storeu_ps(c + ldc, c10), _mm_storeu_ps(c + ldc + 4, c11);
    _mm_storeu_ps(c + 2 * ldc, c20), _mm_storeu_ps(c + 2 * ldc + 4, c21);
    _mm_storeu_ps(c + 3 * ldc, c30), _mm_storeu_ps(c + 3 * ldc + 4, c31);
}

/* AVX2 + FMA: 4 rows x 24 columns (three 8-float vectors): 12 accumulators, three
 * loads and four broadcasts per 12 FMAs, within the 16 registers. */
#define AVX2_MR 4
#define AVX2_NR 24

__attribute__((target("avx2,fma"))) static void
kernel_avx2(const float *restrict a, const float *restrict b, size_t ldb, int kn,
            float *restrict c, size_t ldc)
{
    __m256 c00 = _mm256_setzero_ps(), c01 = c00, c02 = c00, c10 = c00, c11 = c00,
           c12 = c00;
    __m256 c20 = c00, c21 = c00, c22 = c00, c30 = c00, c31 = c00, c32 = c00;
    for (int k = 0; k < kn; k++, a += AVX2_MR) {
        const float *bk = b + (size_t)k * ldb;
        const __m256 b0 = _mm256_loadu_ps(bk), b1 = _mm256_loadu_ps(bk + 8),
                     b2 = _mm256_loadu_ps(bk + 16);
        __m256 x = _mm256_broadcast_ss(a);
        c00 = _mm256_fmadd_ps(x, b0, c00), c01 = _mm256_fmadd_ps(x, b1, c01);
        c02 = _mm256_fmadd_ps(x, b2, c02);
        x = _mm256_broadcast_ss(a + 1);
        c10 = _mm256_fmadd_ps(x, b0, c10), c11 = _mm256_fmadd_ps(x, b1, c11);
        c12 = _mm256_fmadd_ps(x, b2, c12);
        x = _mm256_broadcast_ss(a + 2);
        c20 = _mm256_fmadd_ps(x, b0, c20), c21 = _mm256_fmadd_ps(x, b1, c21);
        c22 = _mm256_fmadd_ps(x, b2, c22);
        x = _mm256_broadcast_ss(a + 3);
        c30 = _mm256_fmadd_ps(x, b0, c30), c31 = _mm256_fmadd_ps(x, b1, c31);
        c32 = _mm256_fmadd_ps(x, b2, c32);
    }
    _mm256_storeu_ps(c, c00), _mm256_storeu_ps(c + 8, c01), _mm256_storeu_ps(c + 16, c02);
    c += ldc;
    _mm256_storeu_ps(c, c10), _mm256_storeu_ps(c + 8, c11), _mm256_storeu_ps(c + 16, c12);
    c += ldc;
    _mm256_storeu_ps(c, c20), _mm256_storeu_ps(c + 8, c21), _mm256_storeu_ps(c + 16, c22);
    c += ldc;
    _mm256_storeu_ps(c, c30), _mm256_storeu_ps(c + 8, c31), _mm256_storeu_ps(c + 16, c32);
}

/* AVX-512F: 8 rows x 48 columns (three 16-float vectors): 24 accumulators, three loads
 * and eight broadcasts per 24 FMAs. */
#define AVX512_MR 8
#define AVX512_NR 48

__attribute__((target("avx512f"))) static void
kernel_avx512(const float *restrict a, const float *restrict b, size_t ldb, int kn,
              float *restrict c, size_t ldc)
{
    __m512 acc[AVX512_MR][3];
    for (int r = 0; r < AVX512_MR; r++)
        acc[r][0] = acc[r][1] = acc[r][2] = _mm512_setzero_ps();
    for (int k = 0; k < kn; k++, a += AVX512_MR) {
        const float *bk = b + (size_t)k * ldb;
        const __m512 b0 = _mm512_loadu_ps(bk), b1 = _mm512_loadu_ps(bk + 16),
                     b2 = _mm512_loadu_ps(bk + 32);
#pragma GCC unroll 8
        for (int r = 0; r < AVX512_MR; r++) {
            const __m512 x = _mm512_set1_ps(a[r]);
            acc[r][0] = _mm512_fmadd_ps(x, b0, acc[r][0]);
            acc[r][1] = _mm512_fmadd_ps(x, b1, acc[r][1]);
            acc[r][2] = _mm512_fmadd_ps(x, b2, acc[r][2]);
        }
    }
    for (int r = 0; r < AVX512_MR; r++) {
        _mm512_storeu_ps(c + (size_t)r * ldc, acc[r][0]);
        _mm512_storeu_ps(c + (size_t)r * ldc + 16, acc[r][1]);
        _mm512_storeu_ps(c + (size_t)r * ldc + 32, acc[r][2]);
    }
}
#endif

typedef struct kernel_entry {
    const char *name;
    gemm_kernel_fn fn;
    int mr, nr;
} kernel_entry;

static const kernel_entry kernels[] = {
#if defined(__GNUC__) && defined(__x86_64__)
    {"avx512", kernel_avx512, AVX512_MR, AVX512_NR},
    {"avx2", kernel_avx2, AVX2_MR, AVX2_NR},
    {"sse2", kernel_sse2, SSE2_MR, SSE2_NR},
#endif
    {"generic", kernel_generic, GENERIC_MR, GENERIC_NR},
};
#define N_KERNELS ((int)(sizeof kernels / sizeof kernels[0]))

int
mcp__unet_gemm_has(const char *name)
{
#if defined(__GNUC__) && defined(__x86_64__)
    if (!strcmp(name, "avx512")) return __builtin_cpu_supports("avx512f");
    if (!strcmp(name, "avx2"))
        return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    if (!strcmp(name, "sse2")) return 1;
#endif
    return !strcmp(name, "generic");
}

/* MCPOST_UNET_KERNEL's kernel where the CPU has it, else the best the CPU has (the
 * list runs from the widest; generic is always there). */
static const kernel_entry *
choose(void)
{
    const char *want = getenv("MCPOST_UNET_KERNEL");
    for (int i = 0; want && *want && i < N_KERNELS; i++)
        if (!strcmp(want, kernels[i].name) && mcp__unet_gemm_has(kernels[i].name))
            return &kernels[i];
    for (int i = 0; i < N_KERNELS; i++)
        if (mcp__unet_gemm_has(kernels[i].name)) return &kernels[i];
    return &kernels[N_KERNELS - 1];
}

void
mcp__unet_gemm_choose(mcp__unet_gemm *g)
{
    const kernel_entry *k = choose();
    g->name = k->name;
    g->mr = k->mr;
    g->nr = k->nr;
    g->kernel = (void (*)(void))k->fn;
}

void
mcp__unet_gemm_pack(const mcp__unet_gemm *g, const float *a, int m, int kn, float *packed)
{
    const int mr = g->mr, blocks = (m + mr - 1) / mr;
    for (int ob = 0; ob < blocks; ob++)
        for (int k = 0; k < kn; k++)
            for (int r = 0; r < mr; r++) {
                const int o = ob * mr + r;
                packed[((size_t)ob * kn + k) * mr + r] =
                    o < m ? a[(size_t)o * kn + k] : 0.0f;
            }
}

void
mcp__unet_gemm_run(const mcp__unet_gemm *g, const float *packed, int m, int kn,
                   const float *b, size_t ldb, int n, float *c, size_t ldc)
{
    const gemm_kernel_fn kernel = (gemm_kernel_fn)g->kernel;
    const int mr = g->mr, nr = g->nr, blocks = (m + mr - 1) / mr;
    /* column blocks outside: a block of B (kn x nr) stays in the L1 cache across the
     * row blocks, and all of A in L2 */
    for (int j = 0; j < n; j += nr)
        for (int ob = 0; ob < blocks; ob++)
            kernel(packed + (size_t)ob * kn * mr, b + j, ldb, kn,
                   c + (size_t)ob * mr * ldc + j, ldc);
}

/* ---- bfloat16 products (the tangents' passes) ---- */

/* float to bf16 bits, rounded to nearest even (finite inputs: the network's values) */
static inline uint32_t
bf16_bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (u + 0x7FFFu + ((u >> 16) & 1u)) >> 16;
}

int
mcp__unet_gemm_bf16_has(void)
{
#if defined(__GNUC__) && defined(__x86_64__)
    /* the default where the CPU has them (MCPOST_UNET_BF16=0: float): the products
       run 1.76 times faster, the JVP's error grows from 2e-6 to 2.5-6.6e-2, within
       the ~10% that s^2 needs, and the stops are the same (docs/denoisers.md) */
    const char *env = getenv("MCPOST_UNET_BF16");
    if (env && !strcmp(env, "0")) return 0;
    return __builtin_cpu_supports("avx512bf16");
#else
    return 0;
#endif
}

#if defined(__GNUC__) && defined(__x86_64__)
/* The rows' bits as bf16_bits rounds them, 16 at a time, the low half cleared: the
 * pairs are then (r1 & 0xffff0000) | r0 >> 16. Only a CPU with AVX512-BF16 runs the
 * bf16 products, and every such CPU has AVX-512F; compiled for the baseline, the
 * generic loop below took 4-6% of an estimate's CPU. */
__attribute__((target("avx512f"))) static inline __m512i
bf16_rounded_avx512(const float *src, __mmask16 keep)
{
    const __m512i u = _mm512_castps_si512(_mm512_maskz_loadu_ps(keep, src));
    const __m512i odd = _mm512_and_si512(_mm512_srli_epi32(u, 16), _mm512_set1_epi32(1));
    return _mm512_add_epi32(_mm512_add_epi32(u, _mm512_set1_epi32(0x7FFF)), odd);
}

__attribute__((target("avx512f"))) static void
bf16_pairs_avx512(const float *r0, const float *r1, int ncols, uint32_t *o)
{
    const __m512i high = _mm512_set1_epi32((int)0xFFFF0000u);
    for (int j = 0; j < ncols; j += 16) {
        const __mmask16 keep =
            ncols - j >= 16 ? (__mmask16)0xFFFF : (__mmask16)((1u << (ncols - j)) - 1);
        __m512i pair = _mm512_srli_epi32(bf16_rounded_avx512(r0 + j, keep), 16);
        if (r1)
            pair = _mm512_or_si512(
                pair, _mm512_and_si512(bf16_rounded_avx512(r1 + j, keep), high));
        _mm512_mask_storeu_epi32(o + j, keep, pair);
    }
}
#endif

void
mcp__unet_bf16_pairs(const float *v, size_t ldv, int kn, int ncols, uint32_t *out,
                     size_t ldo)
{
#if defined(__GNUC__) && defined(__x86_64__)
    if (__builtin_cpu_supports("avx512f")) {
        for (int p = 0; p < (kn + 1) / 2; p++) {
            const float *r0 = v + (size_t)(2 * p) * ldv;
            bf16_pairs_avx512(r0, 2 * p + 1 < kn ? r0 + ldv : NULL, ncols,
                              out + (size_t)p * ldo);
        }
        return;
    }
#endif
    for (int p = 0; p < (kn + 1) / 2; p++) {
        const float *restrict r0 = v + (size_t)(2 * p) * ldv;
        const float *restrict r1 = 2 * p + 1 < kn ? r0 + ldv : NULL;
        uint32_t *restrict o = out + (size_t)p * ldo;
        if (r1) {
#pragma omp simd
            for (int j = 0; j < ncols; j++)
                o[j] = bf16_bits(r0[j]) | bf16_bits(r1[j]) << 16;
        } else {
#pragma omp simd
            for (int j = 0; j < ncols; j++)
                o[j] = bf16_bits(r0[j]);
        }
    }
}

void
mcp__unet_gemm_bf16_pack(const float *a, int m, int kn, uint32_t *packed)
{
    const int mr = MCP__UNET_BF16_MR, blocks = (m + mr - 1) / mr, kp = (kn + 1) / 2;
    for (int ob = 0; ob < blocks; ob++)
        for (int p = 0; p < kp; p++)
            for (int r = 0; r < mr; r++) {
                const int o = ob * mr + r;
                uint32_t lo = 0, hi = 0;
                if (o < m) {
                    lo = bf16_bits(a[(size_t)o * kn + 2 * p]);
                    hi = 2 * p + 1 < kn ? bf16_bits(a[(size_t)o * kn + 2 * p + 1]) : 0;
                }
                packed[((size_t)ob * kp + p) * mr + r] = lo | hi << 16;
            }
}

#if defined(__GNUC__) && defined(__x86_64__)
/* AVX512-BF16: 8 rows x 48 columns, as kernel_avx512, a pair of k per step. */
__attribute__((target("avx512f,avx512bf16"))) static void
kernel_bf16(const uint32_t *restrict a, const uint32_t *restrict b, size_t ldb, int kp,
            float *restrict c, size_t ldc)
{
    __m512 acc[MCP__UNET_BF16_MR][3];
    for (int r = 0; r < MCP__UNET_BF16_MR; r++)
        acc[r][0] = acc[r][1] = acc[r][2] = _mm512_setzero_ps();
    for (int p = 0; p < kp; p++, a += MCP__UNET_BF16_MR) {
        const uint32_t *bp = b + (size_t)p * ldb;
        const __m512bh b0 = (__m512bh)_mm512_loadu_si512(bp),
                       b1 = (__m512bh)_mm512_loadu_si512(bp + 16),
                       b2 = (__m512bh)_mm512_loadu_si512(bp + 32);
#pragma GCC unroll 8
        for (int r = 0; r < MCP__UNET_BF16_MR; r++) {
            const __m512bh x = (__m512bh)_mm512_set1_epi32((int)a[r]);
            acc[r][0] = _mm512_dpbf16_ps(acc[r][0], x, b0);
            acc[r][1] = _mm512_dpbf16_ps(acc[r][1], x, b1);
            acc[r][2] = _mm512_dpbf16_ps(acc[r][2], x, b2);
        }
    }
    for (int r = 0; r < MCP__UNET_BF16_MR; r++) {
        _mm512_storeu_ps(c + (size_t)r * ldc, acc[r][0]);
        _mm512_storeu_ps(c + (size_t)r * ldc + 16, acc[r][1]);
        _mm512_storeu_ps(c + (size_t)r * ldc + 32, acc[r][2]);
    }
}
#endif

void
mcp__unet_gemm_bf16_run(const uint32_t *packed, int m, int kn, const uint32_t *b,
                        size_t ldb, int n, float *c, size_t ldc)
{
#if defined(__GNUC__) && defined(__x86_64__)
    const int mr = MCP__UNET_BF16_MR, nr = MCP__UNET_BF16_NR, blocks = (m + mr - 1) / mr;
    const int kp = (kn + 1) / 2;
    for (int j = 0; j < n; j += nr)
        for (int ob = 0; ob < blocks; ob++)
            kernel_bf16(packed + (size_t)ob * kp * mr, b + j, ldb, kp,
                        c + (size_t)ob * mr * ldc + j, ldc);
#else
    (void)packed, (void)m, (void)kn, (void)b, (void)ldb, (void)n, (void)c, (void)ldc;
#endif
}
