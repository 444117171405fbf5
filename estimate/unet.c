/* unet.c: OIDN's RT U-Net forward pass (docs/oidn-network.md §1.2, §3): HDR
 * pre-processing (input scale or autoexposure, PU transfer function, albedo/normal
 * clamps), the 16 3x3 convolutions with ReLU, 2x2 max pools, nearest 2x upsampling and
 * skip concats, then the inverse transfer function. Whole image as one tile, padded to
 * 16. Activations are planar (CHW) float32; each is freed as soon as it is consumed.
 * Convolutions are Winograd F(4x4, 3x3) products by default (unet_winograd4.c; the
 * exact tangents' F(2x2, 3x3): unet_winograd.c); the direct loops here,
 * register-blocked over output channels and columns, OpenMP over (image, row, column
 * chunk), are the fixed-bit mode (MCPOST_UNET_FIXED=1). */
#define _DEFAULT_SOURCE              /* isatty */
#include "../common/core/internal.h" /* mcp__progress_stop */
#include "unet_internal.h"
#include "internal.h"

#include <mcpost/progress.h>

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

static const char *const conv_names[MCP__UNET_NCONV] = {
    "enc_conv0",  "enc_conv1",  "enc_conv2",  "enc_conv3",  "enc_conv4",  "enc_conv5a",
    "enc_conv5b", "dec_conv4a", "dec_conv4b", "dec_conv3a", "dec_conv3b", "dec_conv2a",
    "dec_conv2b", "dec_conv1a", "dec_conv1b", "dec_conv0"};

enum { E0, E1, E2, E3, E4, E5A, E5B, D4A, D4B, D3A, D3B, D2A, D2B, D1A, D1B, D0 };

/* ---- transfer function (docs/oidn-network.md §3.2, §3.6) ---- */

#define PU_A 1.41283765e+03f
#define PU_B 1.64593172e+00f
#define PU_C 4.31384981e-01f
#define PU_D -2.94139609e-03f
#define PU_E 1.92653254e-01f
#define PU_F 6.26026094e-03f
#define PU_G 9.98620152e-01f
#define PU_Y0 1.57945760e-06f
#define PU_Y1 3.22087631e-02f
#define PU_X0 2.23151711e-03f
#define PU_X1 3.70974749e-01f

static float
pu_raw(float y)
{
    if (y <= PU_Y0) return PU_A * y;
    if (y <= PU_Y1) return PU_B * powf(y, PU_C) + PU_D;
    return PU_E * logf(y + PU_F) + PU_G;
}

static float
pu_raw_inverse(float x)
{
    if (x <= PU_X0) return x / PU_A;
    if (x <= PU_X1) return powf((x - PU_D) / PU_B, 1.0f / PU_C);
    return expf((x - PU_G) / PU_E) - PU_F;
}

/* dPU/dy: C1 at both breakpoints (docs/oidn-network.md §3.2) */
static float
pu_slope(float y)
{
    if (y <= PU_Y0) return PU_A;
    if (y <= PU_Y1) return PU_B * PU_C * powf(y, PU_C - 1.0f);
    return PU_E / (y + PU_F);
}

/* d PU^-1 / dx */
static float
pu_inverse_slope(float x)
{
    if (x <= PU_X0) return 1.0f / PU_A;
    if (x <= PU_X1) return powf((x - PU_D) / PU_B, 1.0f / PU_C - 1.0f) / (PU_B * PU_C);
    return expf((x - PU_G) / PU_E) / PU_E;
}

static float
norm_scale(void)
{
    return 1.0f / pu_raw(65504.0f);
}

float
mcp__pu_forward(float y)
{
    return pu_raw(y) * norm_scale();
}

float
mcp__pu_inverse(float x)
{
    return pu_raw_inverse(x / norm_scale());
}

/* ---- loading ---- */

void
mcp__unet_free(mcp__unet *net)
{
    if (!net) return;
    for (int k = 0; k < MCP__UNET_NCONV; k++) {
        free(net->conv[k].weight);
        free(net->conv[k].bias);
    }
    free(net);
}

/* The input channels each conv must have, given the outputs before it. */
static int
expected_cin(const mcp__unet *n, int k)
{
    const mcp__unet_conv *c = n->conv;
    switch (k) {
    case E0:
        return n->ic;
    case D4A:
        return c[E5B].cout + c[E3].cout; /* concat(up, pool3) */
    case D3A:
        return c[D4B].cout + c[E2].cout; /* concat(up, pool2) */
    case D2A:
        return c[D3B].cout + c[E1].cout; /* concat(up, pool1) */
    case D1A:
        return c[D2B].cout + n->ic; /* concat(up, input) */
    default:
        return c[k - 1].cout;
    }
}

int
mcp__unet_from_tza(const mcp__tza *tza, const char *source, mcp__unet **out)
{
    *out = NULL;
    const char *src = source ? source : "weights";
    if (mcp__tza_find(tza, "enc_conv1b.weight"))
        return mcp_error("%s: unet_large weights are not supported (only the base and "
                         "small RT U-Net)",
                         src);
    if (mcp__tza_find(tza, "dec_conv5a.weight"))
        return mcp_error("%s: OIDN 1.0-1.2 weights (5 pools) are not supported", src);
    mcp__unet *net = mcp_calloc(1, sizeof *net);
    if (!net) return -1;
    for (int k = 0; k < MCP__UNET_NCONV; k++) {
        char wn[64], bn[64];
        snprintf(wn, sizeof wn, "%s.weight", conv_names[k]);
        snprintf(bn, sizeof bn, "%s.bias", conv_names[k]);
        const mcp__tza_tensor *w = mcp__tza_find(tza, wn), *b = mcp__tza_find(tza, bn);
        if (!w || !b) {
            mcp_error("%s: missing tensor '%s' (not an OIDN RT U-Net)", src, w ? bn : wn);
            goto fail;
        }
        if (w->ndims != 4 || w->dims[2] != 3 || w->dims[3] != 3 || b->ndims != 1 ||
            b->dims[0] != w->dims[0]) {
            mcp_error("%s: tensor '%s' has shape not [O][I][3][3] with a bias of O", src,
                      wn);
            goto fail;
        }
        mcp__unet_conv *c = &net->conv[k];
        c->cout = w->dims[0];
        c->cin = w->dims[1];
        if (k == E0) {
            net->ic = c->cin;
            net->v2 = w->dtype == 'h';
            if (c->cin != 3 && c->cin != 6 && c->cin != 9) {
                mcp_error("%s: '%s' has %d input channels (expected 3, 6 or 9)", src, wn,
                          c->cin);
                goto fail;
            }
        }
        int want = expected_cin(net, k);
        if (c->cin != want || (k == D0 && c->cout != 3)) {
            mcp_error("%s: tensor '%s' is %dx%d, expected %d input channels%s", src, wn,
                      c->cout, c->cin, want, k == D0 ? " and 3 outputs" : "");
            goto fail;
        }
        if (!(c->weight = mcp_malloc(w->count * sizeof(float))) ||
            !(c->bias = mcp_malloc(b->count * sizeof(float))))
            goto fail;
        memcpy(c->weight, w->data, w->count * sizeof(float));
        memcpy(c->bias, b->data, b->count * sizeof(float));
    }
    *out = net;
    return 0;
fail:
    mcp__unet_free(net);
    return -1;
}

int
mcp__unet_load(const char *path, mcp__unet **out)
{
    *out = NULL;
    mcp__tza *tza = NULL;
    if (mcp__tza_read(path, &tza)) return -1;
    int rc = mcp__unet_from_tza(tza, path, out);
    mcp__tza_free(tza);
    return rc;
}

/* ---- layers on batches of planar tensors ----
 * A batch holds n images of c x h x w: image 0 is the primal, images 1 .. n-1 are
 * tangents at it. A layer passes tangents through its linearisation at the primal:
 * convolutions without the bias, the primal's ReLU mask, the primal's max-pool choice;
 * upsampling and concatenation copy (docs/oidn-network.md §3.7). */

typedef struct batch {
    int n, c, h, w;
    float *d;   /* image k, channel i: d + ((size_t)k * c + i) * h * w */
    size_t cap; /* bytes the block holds (it may be larger than n c h w values) */
    int half;   /* bfloat16 values (uint16_t) instead of floats: a tangents' pass with
                   bf16 products stores all but its input and output so */
} batch;

static size_t
plane_size(const batch *b)
{
    return (size_t)b->h * (size_t)b->w;
}

static float *
plane(const batch *b, int k, int i)
{
    return b->d + ((size_t)k * b->c + i) * plane_size(b);
}

static uint16_t *
plane16(const batch *b, int k, int i)
{
    return (uint16_t *)b->d + ((size_t)k * b->c + i) * plane_size(b);
}

/* A batch of floats, or (half) bfloat16 values, whose every value the caller writes
 * (no zeroing pass over fresh memory). */
static int
batch_new_as(batch *b, int n, int c, int h, int w, int half)
{
    *b = (batch){n, c, h, w, NULL, 0, half};
    const size_t bytes =
        (size_t)n * c * h * w * (half ? sizeof(uint16_t) : sizeof(float));
    b->d = mcp__unet_block_take(bytes, &b->cap);
    return b->d ? 0 : -1;
}

static int
batch_new_unset(batch *b, int n, int c, int h, int w)
{
    return batch_new_as(b, n, c, h, w, 0);
}

/* A batch of zeros. */
static int
batch_new(batch *b, int n, int c, int h, int w)
{
    if (batch_new_unset(b, n, c, h, w)) return -1;
    memset(b->d, 0, (size_t)n * c * h * w * sizeof(float));
    return 0;
}

static void
batch_free(batch *b)
{
    mcp__unet_block_give(b->d, b->cap);
    b->d = NULL;
}

/* Convolution blocking. Each output pixel's sum runs over input channel i, then row
 * ky, then column kx, in that order, starting at the bias for image 0 and at 0 for a
 * tangent, whatever the blocking and the thread count; taps outside the image add 0 *
 * weight, which leaves the sum as it is (up to the sign of a zero sum). The kernel holds
 * OB output channels x XB columns (two 4-float vectors each) in registers, so each input
 * vector loaded serves OB channels and each weight vector XB / 4 column vectors.
 * Weights are repacked per layer as [block][i][ky][kx][OB][WL], each repeated over WL
 * lanes so that it loads as a vector without a shuffle. A task is one row of up to XC
 * columns of one image, every output channel (all the primal's tasks before the
 * tangents'): its input rows are copied, zero-padded, into a per-thread buffer; the
 * sums run in passes of at most IC input channels (whose weights stay in the L1 cache
 * across the row), partial sums kept in the output between passes, and the last pass
 * stores with the ReLU mask. */
#define OB 4   /* output channels per register block */
#define XB 8   /* columns per register block */
#define WL 4   /* lanes of each repacked weight */
#define XC 256 /* columns per task */
#define IC 32  /* input channels per pass at most */

/* d[0 .. m) = acc as it is (relu 0 or 3), its ReLU (1), or where p0 > 0 and 0 elsewhere
 * (2). */
static inline void
store_block(float *restrict d, const float *restrict acc, const float *restrict p0, int m,
            int relu)
{
    if (relu == 0 || relu == 3)
        memcpy(d, acc, (size_t)m * sizeof(float));
    else if (relu == 1) {
#pragma omp simd
        for (int v = 0; v < m; v++) {
            const float t = acc[v];
            d[v] = t > 0.0f ? t : 0.0f;
        }
    } else {
#pragma omp simd
        for (int v = 0; v < m; v++) {
            const float t = acc[v];
            d[v] = p0[v] > 0.0f ? t : 0.0f;
        }
    }
}

/* Output channels o0 + o < o0 + on, columns [0, m) of a row, at dst + o * hw: acc[o][v]
 * = init[o] (or, init NULL, the partial sum stored at dst) + the sum over i0 <= i < i1,
 * ky0 <= ky < ky1, kx < 3 of weight(o, i, ky, kx) * input(i, ky, v + kx), with input
 * row (i, ky) at rows + (i * 3 + ky) * rs (its element 0 the column left of the block)
 * and wb the block's repacked weights; then stored as store_block does (relu < 3) or as
 * a partial sum (relu 3). p0, read with relu 2 only, is then another image's plane. */
static void
conv_block(const float *restrict rows, int rs, int i0, int i1, int ky0, int ky1,
           const float *restrict wb, const float *restrict init, float *restrict dst,
           const float *restrict p0, size_t hw, int on, int m, int relu)
{
    float acc[OB][XB];
    if (init)
        for (int o = 0; o < OB; o++)
            for (int v = 0; v < XB; v++)
                acc[o][v] = init[o];
    else if (on == OB && m == XB)
        for (int o = 0; o < OB; o++)
            memcpy(acc[o], dst + o * hw, XB * sizeof(float));
    else
        for (int o = 0; o < OB; o++)
            for (int v = 0; v < XB; v++)
                acc[o][v] = o < on && v < m ? dst[o * hw + v] : 0.0f;
    for (int i = i0; i < i1; i++)
        for (int ky = ky0; ky < ky1; ky++) {
            const float *restrict r = rows + ((size_t)i * 3 + ky) * rs;
            const float *restrict wk = wb + ((size_t)i * 9 + ky * 3) * OB * WL;
#pragma GCC unroll 3
            for (int kx = 0; kx < 3; kx++)
#pragma GCC unroll 8
                for (int o = 0; o < OB; o++) {
                    const float *restrict wq = wk + (kx * OB + o) * WL;
#pragma GCC unroll 4
                    for (int vv = 0; vv < XB; vv += WL)
#pragma omp simd
                        for (int v = 0; v < WL; v++)
                            acc[o][vv + v] += wq[v] * r[kx + vv + v];
                }
        }
    for (int o = 0; o < on; o++)
        if (m == XB)
            store_block(dst + o * hw, acc[o], p0 + o * hw, XB, relu);
        else
            store_block(dst + o * hw, acc[o], p0 + o * hw, m, relu);
}

/* The same block 16 columns wide in 8-float AVX2 vectors, for CPUs that have them
 * (picked per layer, unless MCPOST_NO_AVX2 is set: the tests compare the two). Each
 * lane still computes acc + w * r with one rounding for the multiply and one for the
 * add, in the same order (no FMA), so both kernels give the same bits. */
#if defined(__GNUC__) && defined(__x86_64__)
#define UNET_AVX2 1
#include <immintrin.h>

#define XB_AVX2 16

__attribute__((target("avx2"))) static void
conv_block_avx2(const float *restrict rows, int rs, int i0, int i1, int ky0, int ky1,
                const float *restrict wb, const float *restrict init, float *restrict dst,
                const float *restrict p0, size_t hw, int on, int m, int relu)
{
    float tmp[OB][XB_AVX2];
    for (int o = 0; o < OB; o++)
        for (int v = 0; v < XB_AVX2; v++)
            tmp[o][v] = init ? init[o] : o < on && v < m ? dst[o * hw + v] : 0.0f;
    /* eight accumulators by name, so that they stay in registers */
    __m256 a00 = _mm256_loadu_ps(tmp[0]), a01 = _mm256_loadu_ps(tmp[0] + 8);
    __m256 a10 = _mm256_loadu_ps(tmp[1]), a11 = _mm256_loadu_ps(tmp[1] + 8);
    __m256 a20 = _mm256_loadu_ps(tmp[2]), a21 = _mm256_loadu_ps(tmp[2] + 8);
    __m256 a30 = _mm256_loadu_ps(tmp[3]), a31 = _mm256_loadu_ps(tmp[3] + 8);
#define MADD(acc, w, r) acc = _mm256_add_ps(acc, _mm256_mul_ps(w, r))
    for (int i = i0; i < i1; i++)
        for (int ky = ky0; ky < ky1; ky++) {
            const float *restrict r = rows + ((size_t)i * 3 + ky) * rs;
            const float *restrict wk = wb + ((size_t)i * 9 + ky * 3) * OB * WL;
            for (int kx = 0; kx < 3; kx++, wk += OB * WL) {
                const __m256 r0 = _mm256_loadu_ps(r + kx),
                             r1 = _mm256_loadu_ps(r + kx + 8);
                __m256 w = _mm256_broadcast_ss(wk);
                MADD(a00, w, r0), MADD(a01, w, r1);
                w = _mm256_broadcast_ss(wk + WL);
                MADD(a10, w, r0), MADD(a11, w, r1);
                w = _mm256_broadcast_ss(wk + 2 * WL);
                MADD(a20, w, r0), MADD(a21, w, r1);
                w = _mm256_broadcast_ss(wk + 3 * WL);
                MADD(a30, w, r0), MADD(a31, w, r1);
            }
        }
#undef MADD
    _mm256_storeu_ps(tmp[0], a00), _mm256_storeu_ps(tmp[0] + 8, a01);
    _mm256_storeu_ps(tmp[1], a10), _mm256_storeu_ps(tmp[1] + 8, a11);
    _mm256_storeu_ps(tmp[2], a20), _mm256_storeu_ps(tmp[2] + 8, a21);
    _mm256_storeu_ps(tmp[3], a30), _mm256_storeu_ps(tmp[3] + 8, a31);
    for (int o = 0; o < on; o++)
        store_block(dst + o * hw, tmp[o], p0 + o * hw, m, relu);
}
#endif

typedef void (*conv_block_fn)(const float *restrict, int, int, int, int, int,
                              const float *restrict, const float *restrict,
                              float *restrict, const float *restrict, size_t, int, int,
                              int);

/* The block kernel and its width in columns: AVX2 where the CPU has it, unless
 * MCPOST_NO_AVX2 is set (to something other than 0). */
static conv_block_fn
choose_kernel(int *width)
{
#ifdef UNET_AVX2
    const char *off = getenv("MCPOST_NO_AVX2");
    if (!(off && *off && strcmp(off, "0")) && __builtin_cpu_supports("avx2")) {
        *width = XB_AVX2;
        return conv_block_avx2;
    }
#endif
    *width = XB;
    return conv_block;
}

/* A layer's convolution, as conv_into sets it up for conv_task. */
typedef struct conv_layer {
    const batch *a, *b; /* the input: concat(a, b), b may be NULL */
    batch *out;
    const float *wb,
        *bias; /* repacked weights (nob blocks of block_floats), bias or NULL */
    size_t block_floats;
    conv_block_fn kernel;
    int xb; /* the kernel's columns */
    int cin, cout, nob, nic, xc, rs, relu;
} conv_layer;

/* Image k, row y, columns [c * XC, c * XC + xc) of the output, every channel. With relu,
 * image 0 of the row must be done before the others (they take its mask). */
static void
conv_task(const conv_layer *l, int k, int y, int c, float *rows)
{
    const batch *a = l->a, *b = l->b;
    const int h = a->h, w = a->w, ca = a->c, cin = l->cin, cout = l->cout, rs = l->rs;
    const int xc = l->xc, nic = l->nic, x0 = c * XC, xn = w - x0 < xc ? w - x0 : xc;
    const int ky0 = y > 0 ? 0 : 1, ky1 = y < h - 1 ? 3 : 2;
    const int lo = x0 > 0 ? -1 : 0, hi = x0 + xc < w ? xc + 1 : w - x0;
    static const float zeros[OB];
    /* columns x0 - 1 .. x0 + xc of input rows y - 1 .. y + 1, 0 outside the image */
    for (int i = 0; i < cin; i++) {
        const float *src = i < ca ? plane(a, k, i) : plane(b, k, i - ca);
        for (int ky = ky0; ky < ky1; ky++) {
            float *d = rows + ((size_t)i * 3 + ky) * rs + 1;
            if (lo == 0) d[-1] = 0.0f;
            memcpy(d + lo, src + (size_t)(y + ky - 1) * w + x0 + lo,
                   (size_t)(hi - lo) * sizeof(float));
            for (int j = hi; j < rs - 1; j++)
                d[j] = 0.0f;
        }
    }
    const size_t hw = plane_size(l->out), at = (size_t)y * w + x0;
    for (int ob = 0; ob < l->nob; ob++) {
        const int o0 = ob * OB, on = cout - o0 < OB ? cout - o0 : OB;
        float *dst = plane(l->out, k, o0) + at;
        const float *p0 = plane(l->out, 0, o0) + at; /* the primal, ReLU'd */
        const float *wo = l->wb + (size_t)ob * l->block_floats;
        for (int j = 0; j < nic; j++) {
            const int i0 = cin * j / nic, i1 = cin * (j + 1) / nic;
            const int mode = i1 < cin ? 3 : l->relu ? k == 0 ? 1 : 2 : 0;
            const float *init = i0 > 0 ? NULL : k == 0 && l->bias ? l->bias + o0 : zeros;
            for (int xs = 0; xs < xn; xs += l->xb)
                l->kernel(rows + xs, rs, i0, i1, ky0, ky1, wo, init, dst + xs, p0 + xs,
                          hw, on, xn - xs < l->xb ? xn - xs : l->xb, mode);
        }
    }
}

/* Tangents on F(2x2, 3x3), not F(4x4, 3x3): net->exact_tangents, or
 * MCPOST_UNET_EXACT_TANGENTS set to anything but 0. */
static int
exact_tangents(const mcp__unet *net)
{
    const char *exact = getenv("MCPOST_UNET_EXACT_TANGENTS");
    return net->exact_tangents || (exact && *exact && strcmp(exact, "0"));
}

int
mcp__unet_fast(const mcp__unet *net)
{
    const char *fixed = getenv("MCPOST_UNET_FIXED");
    return !net->fixed_bits && !(fixed && *fixed && strcmp(fixed, "0"));
}

/* ---- the primal's trace: what the tangents' passes need of it ----
 * A tangent passes through each layer's linearisation at the primal, which needs only
 * the primal's ReLU masks and max-pool choices, not its activations. The primal runs
 * first and records them (a bit per activation, a byte per pooled value: about 30
 * bytes per pixel, against ~385 for the activations); each tangent then runs alone
 * through the network, replaying them. The peak memory of apply + K tangents is then
 * that of one apply, where a batch of 1 + K images held K + 1 times as much (4.85 GB
 * at 1080p with 4 tangents). Each tangent's operations are the same as in a batch, in
 * the same order: the bits do not change. */

#define N_POOLS 4

typedef struct primal_trace {
    int replay;                           /* 0: record the primal; 1: replay */
    unsigned char *relu[MCP__UNET_NCONV]; /* bit i of plane c: value > 0 */
    unsigned char *pick[N_POOLS];         /* per pooled value: 0 .. 3 */
    int pools;                            /* pools passed in this pass */
} primal_trace;

static void
trace_free(primal_trace *tr)
{
    for (int k = 0; k < MCP__UNET_NCONV; k++)
        free(tr->relu[k]);
    for (int k = 0; k < N_POOLS; k++)
        free(tr->pick[k]);
    *tr = (primal_trace){0};
}

/* One pass through the network: the convolutions' kind, and the trace (NULL for the
 * primal alone: a plain apply records nothing). */
typedef struct pass {
    const mcp__unet *net;
    int fast;   /* Winograd products */
    int coarse; /* F(4x4, 3x3): the primal's, and the tangents' unless exact_tangents */
    int bf16;   /* a tangents' pass on coarse: products in bfloat16 where the CPU can,
                   and its activations stored so (half_out) */
    primal_trace *trace;
} pass;

static int
layer_of(const pass *ps, const mcp__unet_conv *L)
{
    return (int)(L - ps->net->conv);
}

static int
is_replay(const pass *ps)
{
    return ps->trace && ps->trace->replay;
}

/* Zeroed bits for count values: 8 bytes to spare, as the Winograd replay reads 8 at a
 * time (unet_internal.h). */
static unsigned char *
relu_bits_new(size_t count)
{
    return mcp_calloc(count / 8 + 1 + 8, 1);
}

/* The Winograd convolution a pass runs: in a replay, with relu, the primal's recorded
 * mask is applied as the outputs are written (the bias and the ReLU are the
 * primal's). */
static int
winograd(const pass *ps, const mcp__unet_conv *L, const batch *a, int a_up,
         const batch *b, int n, int h, int w, int relu, batch *out)
{
    const int replay = is_replay(ps);
    const float *bias = replay ? NULL : L->bias;
    const unsigned char *bits = replay && relu ? ps->trace->relu[layer_of(ps, L)] : NULL;
    relu = relu && !replay;
    const unsigned half = (a->half ? MCP__UNET_HALF_A : 0u) |
                          (b && b->half ? MCP__UNET_HALF_B : 0u) |
                          (out->half ? MCP__UNET_HALF_OUT : 0u);
    /* the primal's pass with a trace records its ReLU mask as it writes the rows */
    unsigned char *record = NULL;
    if (ps->trace && !replay && relu) {
        const size_t count = (size_t)out->c * plane_size(out);
        if (!(record = relu_bits_new(count))) return -1;
        ps->trace->relu[layer_of(ps, L)] = record;
    }
    if (ps->coarse)
        return mcp__unet_conv_winograd4(L->weight, bias, L->cin, L->cout, a->d, a->c,
                                        a_up, b ? b->d : NULL, n, h, w, relu, bits,
                                        record, ps->bf16, half, out->d);
    if (half) return mcp_error("unet: bfloat16 activations need F(4x4, 3x3)");
    return mcp__unet_conv_winograd(L->weight, bias, L->cin, L->cout, a->d, a->c, a_up,
                                   b ? b->d : NULL, n, h, w, relu, bits, record, out->d);
}

/* Whether a layer's output is stored in bfloat16: in a tangents' pass with bf16
 * products, every layer's but the last (postprocess reads it as floats). The
 * products round their inputs to bf16 anyway, so this adds one rounding of each
 * activation (2^-9 relative), which the JVP's bound for bf16 covers
 * (tests/estimate/test_unet.c), and halves the bytes the transforms read and write. */
static int
half_out(const pass *ps, const mcp__unet_conv *L)
{
    return ps->bf16 && layer_of(ps, L) != MCP__UNET_NCONV - 1;
}

/* Records image 0's ReLU mask (out > 0) as bits, value i at bit i % 8 of byte i / 8. */
static int
record_relu(const batch *out, unsigned char **bits)
{
    const size_t count = (size_t)out->c * plane_size(out), whole = count / 8;
    if (!(*bits = relu_bits_new(count))) return -1;
    unsigned char *restrict m = *bits;
    const float *restrict v = out->d;
#pragma omp parallel for schedule(static)
    for (size_t j = 0; j < whole; j++) {
        unsigned byte = 0;
        for (int b = 0; b < 8; b++)
            byte |= (unsigned)(v[8 * j + b] > 0.0f) << b;
        m[j] = (unsigned char)byte;
    }
    for (size_t i = 8 * whole; i < count; i++) /* the last few, at the coarsest level */
        m[whole] |= (unsigned char)((v[i] > 0.0f) << (i % 8));
    return 0;
}

/* Zeroes every image of out where the recorded mask is 0 (the direct loops' replay;
 * the Winograd convolutions apply it as they write), with the Winograd's row masker
 * over pieces of 64k values. */
static void
replay_relu(batch *out, const unsigned char *bits)
{
    const size_t count = (size_t)out->c * plane_size(out), per = 65536;
    for (int k = 0; k < out->n; k++) {
        float *v = out->d + (size_t)k * count;
#pragma omp parallel for schedule(static)
        for (size_t j0 = 0; j0 < count; j0 += per)
            mcp__unet_mask_row(v + j0, (int)(count - j0 < per ? count - j0 : per), bits,
                               j0);
    }
}

/* out = conv3x3(concat(a, b)), with the bias on image 0 and with relu image 0's ReLU
 * and its mask on the others; in a replay (tangents alone), without the bias, and with
 * relu the recorded mask (Winograd: applied here; the direct loops: by trace_relu). */
static int
conv_plain(const pass *ps, const mcp__unet_conv *L, const batch *a, const batch *b,
           int relu, batch *out)
{
    const int replay = is_replay(ps), with_bias = !replay;
    const int n = a->n, h = a->h, w = a->w, cb = b ? b->c : 0;
    const int cin = a->c + cb, cout = L->cout, nob = (cout + OB - 1) / OB;
    if (cin != L->cin)
        return mcp_error("unet: layer of %d input channels given %d", L->cin, cin);
    if (ps->fast) {
        if (batch_new_as(out, n, cout, h, w, half_out(ps, L))) return -1;
        if (mcp__unet_plan_dry()) return 0;
        if (winograd(ps, L, a, 0, b, n, h, w, relu, out)) {
            batch_free(out);
            return -1;
        }
        return 0;
    }
    int xb;
    const conv_block_fn kernel = choose_kernel(&xb);
    /* tasks of xc columns (the last may have fewer), nxc of them per row */
    const int xc = w < XC ? (w + XB - 1) / XB * XB : XC, nxc = (w + XC - 1) / XC;
    /* a buffered row: columns -1 .. xc, and zeros up to the last block's full width */
    const int rs = (xc + xb + 2 + 3) / 4 * 4;
    const size_t block_floats = (size_t)cin * 9 * OB * WL;
    const size_t rows_floats = (size_t)cin * 3 * rs;
    int n_threads = 1;
#ifdef _OPENMP
    n_threads = omp_get_max_threads();
#endif
    float *wb = mcp_calloc((size_t)nob * block_floats + (size_t)nob * OB, sizeof(float));
    float *scratch =
        wb ? mcp_malloc((size_t)n_threads * rows_floats * sizeof(float)) : NULL;
    if (!scratch || batch_new(out, n, cout, h, w)) {
        free(wb), free(scratch);
        return -1;
    }
    float *bias = wb + (size_t)nob * block_floats; /* 0 past cout, as the weights */
    memcpy(bias, L->bias, (size_t)cout * sizeof(float));
#pragma omp parallel for schedule(static) num_threads(n_threads)
    for (int ob = 0; ob < nob; ob++)
        for (int i = 0; i < cin; i++)
            for (int t = 0; t < 9; t++)
                for (int o = ob * OB; o < ob * OB + OB && o < cout; o++) {
                    const float wt = L->weight[((size_t)o * cin + i) * 9 + t];
                    float *dst = wb + (size_t)ob * block_floats +
                                 (((size_t)i * 9 + t) * OB + o - ob * OB) * WL;
                    for (int lane = 0; lane < WL; lane++)
                        dst[lane] = wt;
                }
    const conv_layer l = {.a = a,
                          .b = b,
                          .out = out,
                          .wb = wb,
                          .bias = with_bias ? bias : NULL,
                          .block_floats = block_floats,
                          .kernel = kernel,
                          .xb = xb,
                          .cin = cin,
                          .cout = cout,
                          .nob = nob,
                          .nic = (cin + IC - 1) / IC,
                          .xc = xc,
                          .rs = rs,
                          .relu = relu && !replay};
#pragma omp parallel num_threads(n_threads)
    {
        int thread = 0;
#ifdef _OPENMP
        thread = omp_get_thread_num();
#endif
        float *rows = scratch + (size_t)thread * rows_floats;
        /* the primal, then (after the loop's barrier) the tangents */
#pragma omp for collapse(2) schedule(dynamic, 1)
        for (int y = 0; y < h; y++)
            for (int c = 0; c < nxc; c++)
                conv_task(&l, 0, y, c, rows);
#pragma omp for collapse(3) schedule(dynamic, 1)
        for (int k = 1; k < n; k++)
            for (int y = 0; y < h; y++)
                for (int c = 0; c < nxc; c++)
                    conv_task(&l, k, y, c, rows);
    }
    free(wb), free(scratch);
    return 0;
}

/* After a convolution with relu: the primal's pass records its mask, a replay of the
 * direct loops applies it (its convolution ran without bias and ReLU; the Winograd
 * convolutions record it and apply it as they write). out is freed on failure. */
static int
trace_relu(const pass *ps, const mcp__unet_conv *L, int relu, batch *out)
{
    primal_trace *tr = ps->trace;
    if (!tr || !relu) return 0;
    const int layer = layer_of(ps, L);
    if (ps->fast) return 0; /* the Winograd products applied it, or recorded it */
    if (tr->replay) {
        replay_relu(out, tr->relu[layer]);
        return 0;
    }
    if (record_relu(out, &tr->relu[layer])) {
        batch_free(out);
        return -1;
    }
    return 0;
}

/* out = conv3x3(concat(a, b)) (b may be NULL), the bias on image 0 only; then, with
 * relu, every image is zeroed where image 0's pre-activation is not > 0 (as it is
 * stored: the primal is done first, and its ReLU is > 0 where it was). Winograd
 * products by default (unet_winograd.c), else the direct loops below. With a trace,
 * the primal pass records its mask, and a replay (tangents alone: no bias) applies
 * it. */
/* Progress of a run on a terminal, a step per convolution of every pass and tile: a
 * 1080p apply takes seconds, an estimate's tangents tens of seconds. Shown only on a
 * terminal and for images of a megapixel or more (a log stays quiet, as with
 * --quiet); the calling thread's, as the block cache. */
static _Thread_local mcp_progress *run_progress;
static _Thread_local long run_steps;

static void
progress_step(void)
{
    if (run_progress) mcp_progress_update(run_progress, ++run_steps);
}

static int
conv_into(const pass *ps, const mcp__unet_conv *L, const batch *a, const batch *b,
          int relu, batch *out)
{
    if (conv_plain(ps, L, a, b, relu, out)) return -1;
    if (mcp__unet_plan_dry()) return 0;
    if (trace_relu(ps, L, relu, out)) return -1;
    progress_step();
    return 0;
}

/* *t = conv(concat(*t, skip)); the old *t and the skip (when given) are freed. */
static int
conv_replace(const pass *ps, const mcp__unet_conv *L, batch *t, batch *skip, int relu)
{
    batch out;
    if (conv_into(ps, L, t, skip, relu, &out)) return -1;
    batch_free(t);
    if (skip) batch_free(skip);
    *t = out;
    return 0;
}

#if defined(__GNUC__) && defined(__x86_64__)
#define POOL_KERNEL __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define POOL_KERNEL
#endif

/* One run of a pool's outputs (2 x 2 blocks from rows top and top + w): the primal's
 * choice and value. */
POOL_KERNEL static void
pool_pick(const float *restrict top, size_t w, int xn, unsigned char *restrict pick,
          float *restrict dst)
{
    const float *restrict bottom = top + w;
#pragma omp simd
    for (int x = 0; x < xn; x++) {
        const float a = top[2 * x], b = top[2 * x + 1], c = bottom[2 * x],
                    d = bottom[2 * x + 1];
        /* the first maximum: a later one wins only when strictly greater */
        float m = a;
        unsigned char k = 0;
        k = b > m ? 1 : k, m = b > m ? b : m;
        k = c > m ? 2 : k, m = c > m ? c : m;
        k = d > m ? 3 : k, m = d > m ? d : m;
        pick[x] = k;
        dst[x] = m;
    }
}

/* The same run for an image that takes the primal's choices: the four candidates
 * loaded and one selected (this vectorises; the gather of the chosen one did not, and
 * built for the baseline took 3% of an estimate). Floats (pool_take), or bfloat16
 * values (pool_take16). */
#define POOL_TAKE(name, type)                                                            \
    POOL_KERNEL static void name(const type *restrict top, size_t w,                     \
                                 const unsigned char *restrict pick, int xn,             \
                                 type *restrict dst)                                     \
    {                                                                                    \
        const type *restrict bottom = top + w;                                           \
        _Pragma("omp simd") for (int x = 0; x < xn; x++)                                 \
        {                                                                                \
            const int k = pick[x];                                                       \
            const type t = k & 1 ? top[2 * x + 1] : top[2 * x],                          \
                       u = k & 1 ? bottom[2 * x + 1] : bottom[2 * x];                    \
            dst[x] = k & 2 ? u : t;                                                      \
        }                                                                                \
    }
POOL_TAKE(pool_take, float)
POOL_TAKE(pool_take16, uint16_t)
#undef POOL_TAKE

/* 2x2 max pool of every image at image 0's arg-max (the first maximum in scan order,
 * as PyTorch picks it). Per output row, the primal's choice (0 .. 3: top left, top
 * right, bottom left, bottom right) is found first, in selects that vectorise; every
 * image then takes its value there. With a trace, the primal's pass records the
 * choices, and a replay (tangents alone) takes them from it. */
static int
maxpool_into(const pass *ps, const batch *in, batch *out)
{
    enum { RUN = 256 }; /* outputs per run of choices */
    const int h2 = in->h / 2, w2 = in->w / 2, w = in->w;
    primal_trace *tr = ps->trace;
    if (tr && tr->pools >= N_POOLS)
        return mcp_error("unet: more pools than the network has");
    unsigned char *picks = NULL;
    const int replay = tr && tr->replay;
    if (tr) {
        if (!replay && !(tr->pick[tr->pools] = mcp_malloc((size_t)in->c * h2 * w2)))
            return -1;
        picks = tr->pick[tr->pools++];
    }
    if (in->half && !replay) return mcp_error("unet: a primal in bfloat16");
    if (batch_new_as(out, in->n, in->c, h2, w2, in->half)) return -1;
    if (mcp__unet_plan_dry()) return 0;
#pragma omp parallel for collapse(2) schedule(static)
    for (int i = 0; i < in->c; i++)
        for (int y = 0; y < h2; y++)
            for (int x0 = 0; x0 < w2; x0 += RUN) {
                const int xn = w2 - x0 < RUN ? w2 - x0 : RUN;
                unsigned char buf[RUN];
                unsigned char *restrict pick =
                    picks ? picks + ((size_t)i * h2 + y) * w2 + x0 : buf;
                if (replay && in->half) { /* the same for bfloat16 values */
                    for (int t = 0; t < in->n; t++)
                        pool_take16(plane16(in, t, i) + (size_t)2 * y * w + 2 * x0,
                                    (size_t)w, pick, xn,
                                    plane16(out, t, i) + (size_t)y * w2 + x0);
                    continue;
                }
                /* a replay's images are all tangents; else image 0 is the primal */
                const int first = replay ? 0 : 1;
                if (!replay)
                    pool_pick(plane(in, 0, i) + (size_t)2 * y * w + 2 * x0, (size_t)w, xn,
                              pick, plane(out, 0, i) + (size_t)y * w2 + x0);
                for (int t = first; t < in->n; t++)
                    pool_take(plane(in, t, i) + (size_t)2 * y * w + 2 * x0, (size_t)w,
                              pick, xn, plane(out, t, i) + (size_t)y * w2 + x0);
            }
    return 0;
}

/* *skip = maxpool(*t), and *t is freed. */
static int
pool_to(const pass *ps, batch *t, batch *skip)
{
    if (maxpool_into(ps, t, skip)) return -1;
    batch_free(t);
    return 0;
}

static int
pool_replace(const pass *ps, batch *t)
{
    batch out;
    if (pool_to(ps, t, &out)) return -1;
    *t = out;
    return 0;
}

/* *t = nearest 2x upsampling of *t. */
static int
upsample_replace(batch *t)
{
    batch out;
    if (batch_new_unset(&out, t->n, t->c, 2 * t->h, 2 * t->w)) return -1;
    const int planes = t->n * t->c, h = t->h, w = t->w;
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < planes; k++)
        for (int y = 0; y < 2 * h; y++) {
            const float *src = t->d + ((size_t)k * h + y / 2) * w;
            float *dst = out.d + ((size_t)k * 2 * h + y) * 2 * w;
            for (int x = 0; x < 2 * w; x++)
                dst[x] = src[x / 2];
        }
    batch_free(t);
    *t = out;
    return 0;
}

/* *t = conv(concat(upsample(*t), skip)), the decoder's step; *t and the skip are
 * freed. The Winograd path reads *t upsampled as it transforms it, so the upsampled
 * batch (as large as the skip's level, and more channels) is never stored. */
static int
conv_up_replace(const pass *ps, const mcp__unet_conv *L, batch *t, batch *skip, int relu)
{
    if (!ps->fast) return upsample_replace(t) || conv_replace(ps, L, t, skip, relu);
    const int n = t->n, h = skip->h, w = skip->w, cin = t->c + skip->c;
    if (cin != L->cin || 2 * t->h != h || 2 * t->w != w)
        return mcp_error("unet: layer of %d input channels given %d", L->cin, cin);
    batch out;
    if (batch_new_as(&out, n, L->cout, h, w, half_out(ps, L))) return -1;
    if (!mcp__unet_plan_dry()) {
        if (winograd(ps, L, t, 1, skip, n, h, w, relu, &out)) {
            batch_free(&out);
            return -1;
        }
        if (trace_relu(ps, L, relu, &out)) return -1;
        progress_step();
    }
    batch_free(t);
    batch_free(skip);
    *t = out;
    return 0;
}

/* The network on a pre-processed input batch x (consumed); *t receives dec_conv0's
 * output, before the output clamp. With a trace, the primal's pass (tr->replay 0,
 * x of one image) records it, and a tangents' pass (tr->replay 1, x of tangents only)
 * replays it. */
static int
network(const mcp__unet *net, batch *x, batch *t, primal_trace *tr)
{
    const mcp__unet_conv *c = net->conv;
    batch p1 = {0}, p2 = {0}, p3 = {0};
    *t = (batch){0};
    if (tr) tr->pools = 0;
    const int fast = mcp__unet_fast(net);
    /* F(4x4, 3x3) for the primal, and for the tangents unless exact_tangents */
    const int replay = tr && tr->replay, exact = replay && exact_tangents(net);
    const int coarse = fast && !exact;
    const pass ps_ = {net, fast, coarse, coarse && replay && mcp__unet_gemm_bf16_has(),
                      tr},
               *ps = &ps_;
    int rc =
        conv_into(ps, &c[E0], x, NULL, 1, t) || conv_replace(ps, &c[E1], t, NULL, 1) ||
        pool_to(ps, t, &p1) || conv_into(ps, &c[E2], &p1, NULL, 1, t) ||
        pool_to(ps, t, &p2) || conv_into(ps, &c[E3], &p2, NULL, 1, t) ||
        pool_to(ps, t, &p3) || conv_into(ps, &c[E4], &p3, NULL, 1, t) ||
        pool_replace(ps, t) || conv_replace(ps, &c[E5A], t, NULL, 1) ||
        conv_replace(ps, &c[E5B], t, NULL, 1) ||
        /* decoder: concat(upsampled, skip) */
        conv_up_replace(ps, &c[D4A], t, &p3, 1) ||
        conv_replace(ps, &c[D4B], t, NULL, 1) ||
        conv_up_replace(ps, &c[D3A], t, &p2, 1) ||
        conv_replace(ps, &c[D3B], t, NULL, 1) ||
        conv_up_replace(ps, &c[D2A], t, &p1, 1) ||
        conv_replace(ps, &c[D2B], t, NULL, 1) || conv_up_replace(ps, &c[D1A], t, x, 1) ||
        conv_replace(ps, &c[D1B], t, NULL, 1) ||
        /* no ReLU on the last conv (1.4); the output clamp makes 2.x's ReLU moot */
        conv_replace(ps, &c[D0], t, NULL, 0);
    batch_free(&p1), batch_free(&p2), batch_free(&p3), batch_free(x);
    if (rc) batch_free(t);
    return rc ? -1 : 0;
}

/* ---- pre-/post-processing ---- */

static float
sanitize(float v, float lo, float hi)
{
    if (!(v == v)) return 0.0f;
    return v < lo ? lo : v > hi ? hi : v;
}

/* The luminance OIDN's autoexposure sums for one pixel (docs/oidn-network.md §3.3). */
static double
exposure_luminance(const float *p)
{
    return 0.212671 * sanitize(p[0], 0.0f, FLT_MAX) +
           0.715160 * sanitize(p[1], 0.0f, FLT_MAX) +
           0.072169 * sanitize(p[2], 0.0f, FLT_MAX);
}

/* The bins are rows [i H / hk, (i + 1) H / hk) x columns [j W / wk, (j + 1) W / wk);
 * each bin's sum takes its pixels row by row, left to right, so rows fed in order in
 * any bands give the same sums, and the bins' logarithms are added row of bins by row
 * of bins, left to right, as a whole image's are. */
static int
exposure_bin_y(const mcp__unet_exposure *e, int i)
{
    return (int)((int64_t)i * e->H / e->hk);
}

static int
exposure_bin_x(const mcp__unet_exposure *e, int j)
{
    return (int)((int64_t)j * e->W / e->wk);
}

int
mcp__unet_exposure_begin(mcp__unet_exposure *e, int W, int H, int v2)
{
    memset(e, 0, sizeof *e);
    e->W = W;
    e->H = H;
    e->hk = v2 ? (H + 15) / 16 : (H + 8) / 16;
    e->wk = v2 ? (W + 15) / 16 : (W + 8) / 16;
    e->hk = e->hk < 1 ? 1 : e->hk;
    e->wk = e->wk < 1 ? 1 : e->wk;
    e->sums = mcp_calloc((size_t)e->wk, sizeof *e->sums);
    return e->sums ? 0 : -1;
}

/* Closes the rows of bins that end at or before row e->row. */
static void
exposure_flush(mcp__unet_exposure *e)
{
    while (e->bin_row < e->hk && exposure_bin_y(e, e->bin_row + 1) <= e->row) {
        const int y0 = exposure_bin_y(e, e->bin_row),
                  y1 = exposure_bin_y(e, e->bin_row + 1);
        for (int j = 0; j < e->wk; j++) {
            const int n = (y1 - y0) * (exposure_bin_x(e, j + 1) - exposure_bin_x(e, j));
            const double L = n > 0 ? e->sums[j] / n : 0.0;
            if (L > 1e-8) {
                e->log_sum += log2(L);
                e->kept++;
            }
            e->sums[j] = 0.0;
        }
        e->bin_row++;
    }
}

void
mcp__unet_exposure_rows(mcp__unet_exposure *e, const mcp_image *rows)
{
    for (int y = 0; y < rows->height && e->row < e->H; y++) {
        for (int j = 0; j < e->wk; j++) {
            const int x0 = exposure_bin_x(e, j), x1 = exposure_bin_x(e, j + 1);
            double sum = e->sums[j];
            for (int x = x0; x < x1; x++)
                sum += exposure_luminance(mcp_image_px(rows, x, y));
            e->sums[j] = sum;
        }
        e->row++;
        exposure_flush(e);
    }
}

double
mcp__unet_exposure_end(mcp__unet_exposure *e)
{
    exposure_flush(e);
    free(e->sums);
    e->sums = NULL;
    return e->kept ? 0.18 / exp2(e->log_sum / e->kept) : 1.0;
}

double
mcp__unet_autoexposure(const mcp_image *color, int v2)
{
    mcp__unet_exposure e;
    if (mcp__unet_exposure_begin(&e, color->width, color->height, v2)) return -1.0;
    mcp__unet_exposure_rows(&e, color);
    return mcp__unet_exposure_end(&e);
}

/* The features the weights read must be given: they are not optional for them. */
static int
check_aux(const mcp__unet *net, const char *what, const mcp_image *color,
          const mcp_image *aux, int needed)
{
    if (!needed) return 0;
    if (!aux)
        return mcp_error("unet: these weights (%d input channels) need the %s", net->ic,
                         what);
    if (aux->channels < 3)
        return mcp_error("%s: unet %s needs 3 channels (got %d)", aux->source, what,
                         aux->channels);
    return mcp_image_same_size(color, aux) ? 0 : -1;
}

/* d/dy of the clamp to [lo, hi]: 1 inside, boundaries included (as autograd's clamp);
 * 0 outside and for NaN. */
static float
clamp_slope(float v, float lo, float hi)
{
    return v >= lo && v <= hi ? 1.0f : 0.0f;
}

/* The network's input for n images of W x H: the padding to 16 is the network's. */
static int
input_batch_new(const mcp__unet *net, int W, int H, int n, batch *x)
{
    return batch_new_unset(x, n, net->ic, (H + 15) / 16 * 16, (W + 15) / 16 * 16);
}

/* The input batch: with primal, image 0 the pre-processed colour | albedo | normal
 * (docs/oidn-network.md §3.2, §3.4) and image 1 + k its tangent along t[k]; without,
 * image k the tangent alone. Padding is 0 in every image. */
static int
preprocess(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
           const mcp_image *normal, float s_in, int primal, const mcp_denoise_tangent *t,
           int n, batch *x)
{
    const int H = color->height, W = color->width, ic = net->ic, o = primal ? 1 : 0;
    if (input_batch_new(net, W, H, o + n, x)) return -1;
    const float ns = norm_scale();
    const int wp = x->w, hp = x->h;
    /* zeros where nothing is written below: the padding, and a tangent's albedo and
     * normal planes when it has none (a whole pass over x cost 1% of an estimate) */
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < o + n; k++)
        for (int ch = 0; ch < ic; ch++) {
            float *p = plane(x, k, ch);
            const int absent = k >= o && ((ch >= 3 && ch < 6 && !t[k - o].albedo) ||
                                          (ch >= 6 && !t[k - o].normal));
            if (absent) {
                memset(p, 0, plane_size(x) * sizeof(float));
                continue;
            }
            if (wp > W)
                for (int y = 0; y < H; y++)
                    memset(p + (size_t)y * wp + W, 0, (size_t)(wp - W) * sizeof(float));
            memset(p + (size_t)H * wp, 0, (size_t)(hp - H) * wp * sizeof(float));
        }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; y++)
        for (int px = 0; px < W; px++) {
            const size_t at = (size_t)y * wp + px;
            const float *p = mcp_image_px(color, px, y);
            for (int ch = 0; ch < 3; ch++) {
                const float v = p[ch] * s_in, yv = sanitize(v, 0.0f, FLT_MAX);
                if (primal) plane(x, 0, ch)[at] = pu_raw(yv) * ns;
                const float slope =
                    clamp_slope(v, 0.0f, FLT_MAX) * s_in * ns * pu_slope(yv);
                for (int k = 0; k < n; k++)
                    plane(x, o + k, ch)[at] = slope * mcp_image_px(t[k].color, px, y)[ch];
            }
            if (ic >= 6) {
                const float *q = mcp_image_px(albedo, px, y);
                for (int ch = 0; ch < 3; ch++) {
                    if (primal) plane(x, 0, 3 + ch)[at] = sanitize(q[ch], 0.0f, 1.0f);
                    const float slope = clamp_slope(q[ch], 0.0f, 1.0f);
                    for (int k = 0; k < n; k++)
                        if (t[k].albedo)
                            plane(x, o + k, 3 + ch)[at] =
                                slope * mcp_image_px(t[k].albedo, px, y)[ch];
                }
            }
            if (ic >= 9) {
                const float *q = mcp_image_px(normal, px, y);
                for (int ch = 0; ch < 3; ch++) {
                    if (primal)
                        plane(x, 0, 6 + ch)[at] =
                            sanitize(q[ch], -1.0f, 1.0f) * 0.5f + 0.5f;
                    const float slope = 0.5f * clamp_slope(q[ch], -1.0f, 1.0f);
                    for (int k = 0; k < n; k++)
                        if (t[k].normal)
                            plane(x, o + k, 6 + ch)[at] =
                                slope * mcp_image_px(t[k].normal, px, y)[ch];
                }
            }
        }
    return 0;
}

/* Crops the network's output to H x W and maps it back (docs/oidn-network.md §3.6):
 * without t the primal (y0's image 0) through the clamp and PU^-1, else t's image k, a
 * tangent, through their derivatives at the primal. */
static int
postprocess(const batch *y0, const batch *t, int k, int W, int H, float s_out,
            mcp_image **out)
{
    if (mcp__rgb_new(W, H, "unet", out)) return -1;
    const float ns = norm_scale();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < H; y++)
        for (int px = 0; px < W; px++) {
            float *dst = mcp_image_px(*out, px, y);
            const size_t at = (size_t)y * y0->w + px;
            for (int ch = 0; ch < 3; ch++) {
                const float v = plane(y0, 0, ch)[at],
                            xs = sanitize(v, 0.0f, FLT_MAX) / ns;
                dst[ch] = !t ? pu_raw_inverse(xs) * s_out
                             : clamp_slope(v, 0.0f, FLT_MAX) * s_out *
                                   pu_inverse_slope(xs) / ns * plane(t, k, ch)[at];
            }
        }
    return 0;
}

/* Bytes per padded pixel and batch image at the network's peak, with a margin: the
 * memory plan's arena (a 64- and a 32-channel output at full resolution, ~385), the
 * outputs and the primal's trace (~440 in all), and the Winograd products' scratch.
 * Beyond what is available, the image is run in tiles. */
#define PEAK_BYTES_PER_PIXEL 480.0

/* The memory the system can give without swapping, in bytes (MemAvailable; the tests
 * set MCPOST_MEMORY_AVAILABLE_MB); 0 where it cannot tell. */
double
mcp__unet_memory_available(void)
{
    const char *forced = getenv("MCPOST_MEMORY_AVAILABLE_MB");
    if (forced && *forced) return atof(forced) * 1048576.0;
    FILE *f = fopen("/proc/meminfo", "r");
    if (!f) return 0;
    char line[256];
    double kb = 0;
    while (fgets(line, sizeof line, f))
        if (sscanf(line, "MemAvailable: %lf kB", &kb) == 1) break;
    fclose(f);
    return kb * 1024.0;
}

/* The network's working memory at most, in bytes: net->max_memory_mb, else
 * MCPOST_UNET_MAX_MEMORY_MB, else MCP__UNET_MAX_MEMORY_MB. */
double
mcp__unet_memory_bound(const mcp__unet *net)
{
    const char *env = getenv("MCPOST_UNET_MAX_MEMORY_MB");
    const double mb = net->max_memory_mb > 0         ? net->max_memory_mb
                      : env && *env && atof(env) > 0 ? atof(env)
                                                     : MCP__UNET_MAX_MEMORY_MB;
    return mb * 1048576.0;
}

/* The bytes a batch of n_images needs for a w x h image (padded to 16). */
double
mcp__unet_batch_bytes(int w, int h, int n_images)
{
    return PEAK_BYTES_PER_PIXEL * ((w + 15) / 16 * 16) * ((h + 15) / 16 * 16) * n_images;
}

/* The memory plan of one pass over a W x H image (unet_memory.c): the pass walked dry,
 * with the input batch of one image, as preprocess() makes it. Its output outlives the
 * pass (the primal's is read by every tangent's postprocess), so it stays out of the
 * plan, and its placeholder is dropped, not given back. */
static int
plan_pass(const mcp__unet *net, int W, int H)
{
    batch x, y;
    mcp__unet_plan_record();
    int rc = input_batch_new(net, W, H, 1, &x) || network(net, &x, &y, NULL);
    return mcp__unet_plan_finish() || rc ? -1 : 0;
}

/* The whole image in one pass: the inputs are checked and the scale is set. */
static int
run_whole(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
          const mcp_image *normal, double scale_in, const mcp_denoise_tangent *t, int n,
          mcp_image **out, mcp_image **jt)
{
    const float s_in = (float)scale_in, s_out = 1.0f / s_in;
    const int W = color->width, H = color->height;
    primal_trace trace = {0}, *tr = n ? &trace : NULL;
    mcp__unet_blocks_keep(n > 0);
    batch x, y0 = {0}, y;
    /* the memory plan of a pass, from a dry one (the direct loops are not planned);
     * then the primal, recording what the tangents need, and each tangent alone */
    int rc = mcp__unet_fast(net) && plan_pass(net, W, H);
    if (!rc) mcp__unet_plan_pass();
    rc = rc || preprocess(net, color, albedo, normal, s_in, 1, NULL, 0, &x) ||
         network(net, &x, &y0, tr);
    if (!rc && out) rc = postprocess(&y0, NULL, 0, W, H, s_out, out);
    if (tr) trace.replay = 1;
    for (int k = 0; k < n && !rc; k++) {
        mcp__unet_plan_pass();
        rc = preprocess(net, color, albedo, normal, s_in, 0, t + k, 1, &x) ||
             network(net, &x, &y, tr);
        if (!rc) {
            rc = postprocess(&y0, &y, 0, W, H, s_out, &jt[k]);
            batch_free(&y);
        }
    }
    batch_free(&y0);
    trace_free(&trace);
    mcp__unet_plan_release();
    mcp__unet_blocks_drain();
    return rc ? -1 : 0;
}

/* rows [y0, y0 + h) x columns [x0, x0 + w) of src (a tile's result, whose pixel (0, 0)
 * is dst's (ox, oy)) into dst */
static void
paste(const mcp_image *src, int ox, int oy, int x0, int y0, int w, int h, mcp_image *dst)
{
    for (int y = y0; y < y0 + h; y++)
        memcpy(mcp_image_px(dst, x0, y), mcp_image_px(src, x0 - ox, y - oy),
               (size_t)w * 3 * sizeof(float));
}

/* Tiles of tile x tile pixels, each run on a crop that extends it by about
 * TILE_OVERLAP on every side (within the image). The crops start on multiples of 32,
 * so that the pooling grid is the whole image's down to 1/16 and the Winograd tiles
 * (2 x 2 outputs) at 1/16 fall where they fall in the whole image; the overlap covers
 * what a pixel's value depends on, rounding included: the receptive field of the 3x3
 * convolutions and 2x2 pooling over five levels has a radius of ~110 pixels, and a
 * Winograd tile's outputs each depend on all 4 x 4 of its inputs (a radius of 2 per
 * convolution instead of 1), ~190 in all. The F(4x4, 3x3) tiles of the default
 * Winograd passes (4 x 4 outputs from 6 x 6 inputs: a radius of 4 per convolution)
 * need crops on multiples of 64 and ~330 pixels (16 convolutions' radii at their levels'
 * scales, 4 (5 + 3 x 2 + 3 x 4 + 3 x 8) + 4 x 2 x 16, and the pools'). A tile's pixels
 * then see what they see in the whole image, and the result is the same bits (the tests
 * compare). */
#define TILE_OVERLAP 192
#define TILE_ALIGN 32
#define TILE_OVERLAP_COARSE 352
#define TILE_ALIGN_COARSE 64

/* The overlap and alignment of a run's tiles: wider where the Winograd products run on
 * F(4x4, 3x3) (every pass but exact tangents'), narrower for the direct loops. */
void
mcp__unet_tile_margins(const mcp__unet *net, int *overlap, int *align)
{
    const int coarse = mcp__unet_fast(net);
    *overlap = coarse ? TILE_OVERLAP_COARSE : TILE_OVERLAP;
    *align = coarse ? TILE_ALIGN_COARSE : TILE_ALIGN;
}

void
mcp__unet_crop_of(int a0, int a1, int n, int overlap, int align, int *c0, int *c1)
{
    *c0 = a0 > overlap ? (a0 - overlap) / align * align : 0;
    *c1 = a1 + overlap < n ? a1 + overlap : n;
}

static int
run_tiled(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
          const mcp_image *normal, double scale_in, const mcp_denoise_tangent *t, int n,
          int tile_w, int tile_h, mcp_image **out, mcp_image **jt)
{
    const int W = color->width, H = color->height;
    int overlap, align;
    mcp__unet_tile_margins(net, &overlap, &align);
    int rc = 0;
    if (out) rc = mcp__rgb_new(W, H, "unet", out);
    for (int k = 0; k < n && !rc; k++)
        rc = mcp__rgb_new(W, H, "unet", &jt[k]);
    mcp_denoise_tangent *tt = n ? mcp_calloc((size_t)n, sizeof *tt) : NULL;
    mcp_image **views = mcp_calloc((size_t)3 * (n + 1), sizeof *views);
    mcp_image **res = mcp_calloc((size_t)n + 1, sizeof *res);
    if (!views || !res || (n && !tt)) rc = -1;
    for (int ty = 0; ty < H && !rc; ty += tile_h)
        for (int tx = 0; tx < W && !rc; tx += tile_w) {
            const int w = tx + tile_w < W ? tile_w : W - tx,
                      h = ty + tile_h < H ? tile_h : H - ty;
            int x0, x1, y0, y1;
            mcp__unet_crop_of(tx, tx + w, W, overlap, align, &x0, &x1);
            mcp__unet_crop_of(ty, ty + h, H, overlap, align, &y0, &y1);
            /* views of the crop: the inputs (k = 0), then each tangent's parts */
            for (int k = 0; k <= n && !rc; k++) {
                const mcp_image *src[3] = {k ? t[k - 1].color : color,
                                           k ? t[k - 1].albedo : albedo,
                                           k ? t[k - 1].normal : normal};
                for (int c = 0; c < 3 && !rc; c++)
                    if (src[c])
                        rc = mcp_image_crop_view(src[c], x0, y0, x1 - x0, y1 - y0,
                                                 &views[3 * k + c]);
            }
            for (int k = 0; k < n; k++)
                tt[k] = (mcp_denoise_tangent){views[3 * (k + 1)], views[3 * (k + 1) + 1],
                                              views[3 * (k + 1) + 2]};
            if (!rc)
                rc = run_whole(net, views[0], views[1], views[2], scale_in, tt, n,
                               out ? &res[0] : NULL, res + 1);
            if (!rc && out) paste(res[0], x0, y0, tx, ty, w, h, *out);
            for (int k = 0; k < n && !rc; k++)
                paste(res[1 + k], x0, y0, tx, ty, w, h, jt[k]);
            for (int i = 0; i < 3 * (n + 1); i++) {
                mcp_image_free(views[i]);
                views[i] = NULL;
            }
            for (int k = 0; k <= n; k++) {
                mcp_image_free(res[k]);
                res[k] = NULL;
            }
        }
    free(tt), free(views), free(res);
    return rc;
}

double
mcp__unet_tile_limit(const mcp__unet *net, double have)
{
    const double bound = mcp__unet_memory_bound(net);
    return have > 0 && have / 2 < bound ? have / 2 : bound;
}

int
mcp__unet_auto_tile(const mcp__unet *net, int W, int H, double limit)
{
    if (mcp__unet_batch_bytes(W, H, 1) <= limit) return W > H ? W : H;
    int overlap, align;
    mcp__unet_tile_margins(net, &overlap, &align);
    const int margin = 2 * overlap + align; /* a crop's largest extension */
    int tile;
    for (tile = (W > H ? W : H) / 16 * 16; tile >= 16; tile -= 16)
        if (mcp__unet_batch_bytes(tile + margin, tile + margin, 1) <= limit) break;
    return tile < 16 ? 0 : tile;
}

int
mcp__unet_run_crop(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
                   const mcp_image *normal, double scale_in, int tile_w, mcp_image **out)
{
    *out = NULL;
    if (!color || color->channels < 3) return mcp_error("unet: colour needs 3 channels");
    if (check_aux(net, "albedo", color, albedo, net->ic >= 6) ||
        check_aux(net, "normal", color, normal, net->ic >= 9))
        return -1;
    if (tile_w < 16 || tile_w % 16)
        return mcp_error("unet: a band's tiles must be a multiple of 16 wide (got %d)",
                         tile_w);
    if (!(scale_in > 0 && scale_in < 1e30))
        return mcp_error("unet: bad input scale %g", scale_in);
    const int H = color->height;
    int rc = run_tiled(net, color, albedo, normal, scale_in, NULL, 0, tile_w,
                       H > 16 ? (H + 15) / 16 * 16 : 16, out, NULL);
    if (rc) {
        mcp_image_free(*out);
        *out = NULL;
    }
    return rc;
}

int
mcp__unet_progress_begin(mcp_progress *bar, const char *label, long steps, int W, int H)
{
    if ((double)W * H < 1048576.0 || mcp_progress_quiet() || !isatty(STDERR_FILENO) ||
        run_progress)
        return 0;
    mcp_progress_begin(bar, label, steps);
    run_progress = bar;
    run_steps = 0;
    return 1;
}

void
mcp__unet_progress_finish(mcp_progress *bar, int shown, int failed)
{
    if (!shown) return;
    if (failed)
        mcp__progress_stop(bar); /* no "100%" for a run that failed */
    else
        mcp_progress_end(bar);
    run_progress = NULL;
}

int
mcp__unet_run_tiled(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
                    const mcp_image *normal, double input_scale,
                    const mcp_denoise_tangent *t, int n, int tile, mcp_image **out,
                    mcp_image **jt)
{
    if (out) *out = NULL;
    for (int k = 0; k < n; k++)
        jt[k] = NULL;
    if (!color || color->channels < 3) return mcp_error("unet: colour needs 3 channels");
    const mcp_denoise_input at = {color, albedo, normal, NULL};
    if (check_aux(net, "albedo", color, albedo, net->ic >= 6) ||
        check_aux(net, "normal", color, normal, net->ic >= 9) ||
        mcp__denoise_check_tangents("unet", &at, t, n))
        return -1;
    if (tile < 0 || tile % 16)
        return mcp_error("unet: tile must be 0 (as memory allows) or a multiple of 16 "
                         "(got %d)",
                         tile);
    const int W = color->width, H = color->height;
    /* The tangents run one at a time after the primal (its trace, above), so the
     * network holds one image's activations whatever n is. */
    const double bound = mcp__unet_memory_bound(net);
    const double have = tile == 0 ? mcp__unet_memory_available() : 0; /* when needed */
    const int short_of_memory = have > 0 && have < bound;
    if (tile == 0 && mcp__unet_batch_bytes(W, H, 1) > (short_of_memory ? have : bound)) {
        /* the largest tile whose crop fits in the bound, and in half of what is
         * available (the results and the inputs take the rest) */
        tile = mcp__unet_auto_tile(net, W, H, mcp__unet_tile_limit(net, have));
        if (tile < 16)
            return short_of_memory
                       ? mcp_error("unet: a %dx%d image with %d tangent(s) does not fit "
                                   "even in 16x16 tiles: %.0f MB are available",
                                   W, H, n, have / 1048576.0)
                       : mcp_error("unet: a %dx%d image does not fit even in 16x16 tiles "
                                   "within max_memory_mb %.0f",
                                   W, H, bound / 1048576.0);
    }
    if (tile >= W && tile >= H) tile = 0;
    /* The exposure is a constant of F, also for its JVP: it is computed once on the
     * primal colour, as a renderer fixes the exposure of a frame (docs/oidn-network.md
     * §3.7); the tiles share it. */
    const double scale_in =
        input_scale > 0 ? input_scale : mcp__unet_autoexposure(color, net->v2);
    if (!(scale_in > 0 && scale_in < 1e30))
        return mcp_error("unet: bad input scale %g", scale_in);
    mcp_progress bar;
    const int tiles = tile ? ((W + tile - 1) / tile) * ((H + tile - 1) / tile) : 1;
    const int shown =
        mcp__unet_progress_begin(&bar, n ? "U-Net and its tangents" : "U-Net",
                                 (long)MCP__UNET_NCONV * (1 + n) * tiles, W, H);
    int rc =
        tile ? run_tiled(net, color, albedo, normal, scale_in, t, n, tile, tile, out, jt)
             : run_whole(net, color, albedo, normal, scale_in, t, n, out, jt);
    mcp__unet_progress_finish(&bar, shown, rc);
    if (rc) {
        if (out) {
            mcp_image_free(*out);
            *out = NULL;
        }
        for (int k = 0; k < n; k++) {
            mcp_image_free(jt[k]);
            jt[k] = NULL;
        }
    }
    return rc;
}

int
mcp__unet_run(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
              const mcp_image *normal, double input_scale, const mcp_denoise_tangent *t,
              int n, mcp_image **out, mcp_image **jt)
{
    return mcp__unet_run_tiled(net, color, albedo, normal, input_scale, t, n, 0, out, jt);
}

int
mcp__unet_forward(const mcp__unet *net, const mcp_image *color, const mcp_image *albedo,
                  const mcp_image *normal, double input_scale, mcp_image **out)
{
    return mcp__unet_run(net, color, albedo, normal, input_scale, NULL, 0, out, NULL);
}
