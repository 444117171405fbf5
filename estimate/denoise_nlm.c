/* denoise_nlm.c: the `nlm` denoiser -- feature-guided non-local means with an exact
 * forward-mode Jacobian-vector product (docs/mathematics.md §2.1). Colour distance
 * of Rousselle, Knaus & Zwicker 2012 ("Adaptive rendering with non-local means
 * filtering", Eq. 5), feature weights as in a cross-bilateral filter.
 *
 * For every pixel p and every neighbour q = p + o in a (2R+1)^2 window:
 *
 *   out_p = sum_q w_pq x_q / W_p,   W_p = sum_q w_pq,
 *   w_pq  = exp(-soft_max0(dc_pq) - df_pq),
 *   dc_pq = 1/(3P) sum_{s in patch} sum_c D_c(p + s, q + s),   P = (2f+1)^2,
 *   D_c(a, b) = [(x_a - x_b)^2 - alpha (V_a + min(V_a, V_b))] / [eps + k^2 (V_a + V_b)]
 *               (channel c; V the variance of the mean, prefiltered),
 *   df_pq = |A_p - A_q|^2 / (2 sigma_albedo^2) + |N_p - N_q|^2 / (2 sigma_normal^2).
 *
 * soft_max0 is max(0, .) rounded off near 0 (see KINK). Pixels outside the image are
 * their nearest edge pixel, for neighbours and patches alike: the patch of q is
 * clamp(p + o + s), not clamp(p + o) + s. Product weights (not Rousselle 2013's min of
 * colour and feature weights) keep F smooth.
 *
 * The JVP differentiates the weights too. With g_pq = d log w_pq:
 *   d out_p = [sum_q w_pq t_q + sum_q w_pq g_pq (x_q - x_p) - (out_p - x_p) G_p] / W_p,
 *   G_p = sum_q w_pq g_pq,
 *   g_pq = -soft_max0'(dc_pq) d dc_pq - d df_pq, where d dc_pq is the same patch sum
 *   of 2 (x_a - x_b)(t_a - t_b) / [eps + k^2 (V_a + V_b)].
 * Centring on x_p keeps the weight-derivative sums small (less cancellation). The
 * variance is a constant of F, as SURE treats it; albedo and normal tangents, when
 * given, move df (joint SURE, Li 2017).
 *
 * Computation: per offset o and strip of rows, the distance D over the strip's rows
 * plus the patch margin, then sums over the patch along rows and columns (direct sums
 * of 2f+1 terms, no running sums, so no drift), then the weights; tangents reuse the
 * offset's coefficients and weights. Strips have STRIP_ROWS rows whatever the thread
 * count and each pixel sums its offsets in a fixed order, so results do not depend on
 * the number of threads. Inputs are first copied into padded planes, so the inner loops
 * run without clamping and vectorise. */
#include <mcpost/denoiser.h>

#include "../common/core/internal.h" /* mcp__progress_stop */
#include "internal.h"

#include <mcpost/filter.h>
#include <mcpost/progress.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Rows per work unit. 32 keeps the patch margin (2f rows) a small overhead and the
 * strip's buffers within a core's L2 cache at 1024 columns. */
#define STRIP_ROWS 32

/* Images this small (pixels) are not worth an OpenMP team. */
#define PARALLEL_MIN_PIXELS 4096

/* The strip kernel is compiled twice, for AVX2 and for the baseline, and picked at
 * load time (1.7x faster with 8-wide vectors). The C11 mode keeps FMA contraction off,
 * so both give the same bits. GCC needs flatten to pull the helpers into each clone;
 * clang refuses flatten beside target_clones: there the two big helpers are marked
 * always_inline (NLM_KERNEL_PART), and they inline theirs. */
#if defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define NLM_KERNEL __attribute__((target_clones("avx2", "default")))
#define NLM_KERNEL_PART __attribute__((always_inline))
#elif defined(__GNUC__) && defined(__x86_64__) && defined(__linux__)
#define NLM_KERNEL __attribute__((target_clones("avx2", "default"), flatten))
#define NLM_KERNEL_PART
#else
#define NLM_KERNEL
#define NLM_KERNEL_PART
#endif

/* Rousselle's max(0, dc) is rounded off over |dc| < KINK into a parabola (C1, like
 * Huber's loss), so that F is differentiable everywhere, not only almost everywhere:
 * similar patches sit near dc = 0, where finite differences would straddle a kink. It
 * lowers the weight of identical patches by at most KINK / 4 in log, which
 * normalisation mostly cancels. */
#define KINK 0.2f

#define RADIUS_MAX 64
#define PATCH_RADIUS_MAX 16

typedef struct {
    int radius;           /* search window radius, px */
    int patch_radius;     /* patch radius f, px */
    double k_color;       /* colour bandwidth, in noise standard deviations */
    double alpha;         /* how much of the expected noise to cancel */
    double epsilon;       /* added to the normaliser, squared colour units */
    double sigma_color;   /* noise std assumed where no variance is given */
    int use_variance;     /* read in->variance when given */
    double variance_blur; /* Gaussian prefilter of the variance, sigma in px; 0: none */
    double sigma_albedo;  /* albedo bandwidth; 0: ignore albedo */
    double sigma_normal;  /* normal bandwidth; 0: ignore normals */
    double sigma_spatial; /* Gaussian falloff over the window, px; 0: uniform window */
} nlm_params;

/* Padded planes of everything one call reads; pixel (x, y) of the image is at
 * (y + pad) * pw + x + pad, and pad = R + f covers every neighbour's patch. */
typedef struct {
    int w, h, pad, pw, ph;
    const float *x[3]; /* colour */
    const float *v[3]; /* effective variance (prefiltered, or sigma_color^2) */
    const float *a[3]; /* albedo, or NULL when not used */
    const float *n[3]; /* normal, or NULL when not used */
    float inv_2sa2, inv_2sn2, inv_2ss2;
    int nt;           /* tangents */
    const float **tx; /* nt * 3 colour tangent planes */
    const float **ta; /* nt * 3 albedo tangent planes (NULL: zero) */
    const float **tn; /* nt * 3 normal tangent planes (NULL: zero) */
    float **blocks;   /* what to free */
    int n_blocks, cap_blocks;
} nlm_work;

/* Where a strip writes: packed R,G,B outputs (NULL when not wanted). */
typedef struct {
    float *primal;
    float **tangent; /* nt outputs */
} nlm_out;

/* ---- settings: one table for nlm and bilateral, which differ in their defaults
 * (<mcpost/options.h>; docs/denoisers.md) ---- */

#define P(f) offsetof(nlm_params, f)
#define NLM_OPTIONS(RADIUS, PATCH, K_COLOR, SIGMA_SPATIAL)                               \
    {.name = "radius",                                                                   \
     .type = MCP_OPT_INT,                                                                \
     .offset = P(radius),                                                                \
     .def = RADIUS,                                                                      \
     .doc = "search window half width R, px",                                            \
     .lo = 0,                                                                            \
     .hi = RADIUS_MAX,                                                                   \
     .bounds = MCP_OPT_LO | MCP_OPT_HI},                                                 \
        {.name = "patch_radius",                                                         \
         .type = MCP_OPT_INT,                                                            \
         .offset = P(patch_radius),                                                      \
         .def = PATCH,                                                                   \
         .doc = "patch half width f, px; 0 compares single pixels",                      \
         .lo = 0,                                                                        \
         .hi = PATCH_RADIUS_MAX,                                                         \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "k_color",                                                              \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(k_color),                                                           \
         .def = K_COLOR,                                                                 \
         .doc = "colour bandwidth, in noise standard deviations",                        \
         .lo = 0,                                                                        \
         .hi = 1e6,                                                                      \
         .bounds = MCP_OPT_LO_OPEN | MCP_OPT_HI},                                        \
        {.name = "alpha",                                                                \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(alpha),                                                             \
         .def = "1",                                                                     \
         .doc =                                                                          \
             "how much of the expected noise to subtract from the squared difference",   \
         .lo = 0,                                                                        \
         .hi = 16,                                                                       \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "epsilon",                                                              \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(epsilon),                                                           \
         .def = "0.0001",                                                                \
         .doc = "added to the normaliser, squared colour units",                         \
         .lo = 0,                                                                        \
         .hi = 1e30,                                                                     \
         .bounds = MCP_OPT_LO_OPEN | MCP_OPT_HI},                                        \
        {.name = "sigma_color",                                                          \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(sigma_color),                                                       \
         .def = "0.05",                                                                  \
         .doc = "noise standard deviation assumed where no variance is given",           \
         .lo = 0,                                                                        \
         .hi = 1e15,                                                                     \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "use_variance",                                                         \
         .type = MCP_OPT_FLAG,                                                           \
         .offset = P(use_variance),                                                      \
         .def = "true",                                                                  \
         .doc = "use the input's variance; false: a constant sigma_color^2"},            \
        {.name = "variance_blur",                                                        \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(variance_blur),                                                     \
         .def = "1",                                                                     \
         .doc = "Gaussian prefilter of the variance, sigma in px (0: none)",             \
         .lo = 0,                                                                        \
         .hi = 100,                                                                      \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "sigma_albedo",                                                         \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(sigma_albedo),                                                      \
         .def = "0.2",                                                                   \
         .doc = "albedo bandwidth (0: ignore albedo)",                                   \
         .lo = 0,                                                                        \
         .hi = 1e15,                                                                     \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "sigma_normal",                                                         \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(sigma_normal),                                                      \
         .def = "0.3",                                                                   \
         .doc = "normal bandwidth (0: ignore normals)",                                  \
         .lo = 0,                                                                        \
         .hi = 1e15,                                                                     \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "sigma_spatial",                                                        \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = P(sigma_spatial),                                                     \
         .def = SIGMA_SPATIAL,                                                           \
         .doc = "Gaussian falloff over the window, px (0: a uniform window)",            \
         .lo = 0,                                                                        \
         .hi = 1e15,                                                                     \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
    {                                                                                    \
        0                                                                                \
    }

static const mcp_option nlm_options[] = {NLM_OPTIONS("7", "2", "0.6", "0")};
static const mcp_option bilateral_options[] = {NLM_OPTIONS("6", "0", "2", "2")};

/* The keys, from the table (denoisers.c fills them in before the kinds are handed
 * out); nlm and bilateral share them. */
const char *mcp__nlm_keys[MCP__DENOISER_KEYS_MAX];

static int
clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

/* exp(v) for -87 <= v <= 0 (the caller clamps), to about 2 float ulp (Cephes
 * expf's polynomial). Unlike libm's expf it vectorises; the JVP uses w' = w, which
 * this satisfies to the same relative accuracy. */
static inline float
exp_nonpositive(float v)
{
    /* n = round(v / ln 2), by truncation of a non-positive number shifted by -1/2 */
    int32_t n = (int32_t)(v * 1.44269504088896341f - 0.5f);
    float fn = (float)n;
    float r = v - fn * 0.693359375f - fn * -2.12194440e-4f;
    float q = 1.9875691500e-4f;
    q = q * r + 1.3981999507e-3f;
    q = q * r + 8.3334519073e-3f;
    q = q * r + 4.1665795894e-2f;
    q = q * r + 1.6666665459e-1f;
    q = q * r + 5.0000001201e-1f;
    float y = q * r * r + r + 1.0f;
    int32_t bits = (n + 127) * (1 << 23);
    float scale;
    memcpy(&scale, &bits, sizeof scale);
    return y * scale;
}

/* The colour distance of pixel a to pixel b in one channel (Rousselle 2012 Eq. 5),
 * and *inv, the factor of its derivative: d/dx_a = 2 diff inv = -d/dx_b. The
 * numerator cancels the noise expected in diff^2 as seen from a, min(V_a, V_b)
 * standing for V_b, so that a clean pixel does not take in noisier neighbours
 * (fireflies); min is written with fabsf so that the loops vectorise. */
static inline float
pair_distance(float diff, float va, float vb, float k2, float eps, float alpha,
              float *inv)
{
    float vmin = 0.5f * (va + vb - fabsf(va - vb));
    *inv = 1.0f / (eps + k2 * (va + vb));
    return (diff * diff - alpha * (va + vmin)) * *inv;
}

/* ---- padded planes ---- */

static float *
work_alloc(nlm_work *wk, size_t floats)
{
    if (wk->n_blocks == wk->cap_blocks) {
        int cap = wk->cap_blocks ? 2 * wk->cap_blocks : 16;
        float **b = mcp_realloc(wk->blocks, (size_t)cap * sizeof *b);
        if (!b) return NULL;
        wk->blocks = b;
        wk->cap_blocks = cap;
    }
    float *p = mcp_malloc(floats * sizeof *p);
    if (p) wk->blocks[wk->n_blocks++] = p;
    return p;
}

static void
work_free(nlm_work *wk)
{
    for (int i = 0; i < wk->n_blocks; i++)
        free(wk->blocks[i]);
    free(wk->blocks);
    free(wk->tx);
    free(wk->ta);
    free(wk->tn);
    memset(wk, 0, sizeof *wk);
}

/* Copies the 3 channels of img into padded planes, replicating the border; with
 * clamp_low, values that are not > 0 (negative or NaN variance) become 0. */
static int
pad_image(nlm_work *wk, const mcp_image *img, int clamp_low, const float *planes_out[3])
{
    size_t plane = (size_t)wk->pw * (size_t)wk->ph;
    float *block = work_alloc(wk, 3 * plane);
    if (!block) return -1;
    int w = wk->w, h = wk->h, pad = wk->pad, pw = wk->pw, ph = wk->ph;
#pragma omp parallel for schedule(static) if ((size_t)w * h >= PARALLEL_MIN_PIXELS)
    for (int py = 0; py < ph; py++) {
        int sy = clampi(py - pad, 0, h - 1);
        for (int px = 0; px < pw; px++) {
            const float *src = mcp_image_px(img, clampi(px - pad, 0, w - 1), sy);
            for (int c = 0; c < 3; c++) {
                float v = src[c];
                if (clamp_low && !(v > 0)) v = 0;
                block[c * plane + (size_t)py * pw + px] = v;
            }
        }
    }
    for (int c = 0; c < 3; c++)
        planes_out[c] = block + c * plane;
    return 0;
}

static int
fill_constant(nlm_work *wk, float value, const float *planes_out[3])
{
    size_t plane = (size_t)wk->pw * (size_t)wk->ph;
    float *block = work_alloc(wk, plane);
    if (!block) return -1;
    for (size_t i = 0; i < plane; i++)
        block[i] = value;
    for (int c = 0; c < 3; c++)
        planes_out[c] = block;
    return 0;
}

/* The effective variance planes: the prefiltered variance of the mean, or
 * sigma_color^2 everywhere. */
static int
pad_variance(const nlm_params *p, nlm_work *wk, const mcp_image *var)
{
    if (!var || !p->use_variance)
        return fill_constant(wk, (float)(p->sigma_color * p->sigma_color), wk->v);
    if (p->variance_blur <= 0) return pad_image(wk, var, 1, wk->v);
    mcp_image *blurred = NULL;
    int radius = (int)ceil(3 * p->variance_blur);
    if (mcp_gaussian_blur(var, 2 * radius + 1, p->variance_blur, &blurred)) return -1;
    int rc = pad_image(wk, blurred, 1, wk->v);
    mcp_image_free(blurred);
    return rc;
}

static int
work_init(const nlm_params *p, const mcp_denoise_input *in, const mcp_denoise_tangent *t,
          int nt, nlm_work *wk)
{
    memset(wk, 0, sizeof *wk);
    wk->w = in->color->width;
    wk->h = in->color->height;
    wk->pad = p->radius + p->patch_radius;
    wk->pw = wk->w + 2 * wk->pad;
    wk->ph = wk->h + 2 * wk->pad;
    wk->nt = nt;
    size_t plane;
    if (mcp_size_mul((size_t)wk->pw, (size_t)wk->ph, &plane) || plane > SIZE_MAX / 64)
        return mcp_error("image %dx%d too large", wk->w, wk->h);
    int use_a = in->albedo && p->sigma_albedo > 0;
    int use_n = in->normal && p->sigma_normal > 0;
    wk->inv_2sa2 = use_a ? (float)(1 / (2 * p->sigma_albedo * p->sigma_albedo)) : 0;
    wk->inv_2sn2 = use_n ? (float)(1 / (2 * p->sigma_normal * p->sigma_normal)) : 0;
    double ss = p->sigma_spatial;
    wk->inv_2ss2 = ss > 0 ? (float)(1 / (2 * ss * ss)) : 0;
    if (pad_image(wk, in->color, 0, wk->x) || pad_variance(p, wk, in->variance) ||
        (use_a && pad_image(wk, in->albedo, 0, wk->a)) ||
        (use_n && pad_image(wk, in->normal, 0, wk->n)))
        return -1;
    if (nt == 0) return 0;
    wk->tx = mcp_calloc((size_t)nt * 3, sizeof *wk->tx);
    wk->ta = mcp_calloc((size_t)nt * 3, sizeof *wk->ta);
    wk->tn = mcp_calloc((size_t)nt * 3, sizeof *wk->tn);
    if (!wk->tx || !wk->ta || !wk->tn) return -1;
    for (int k = 0; k < nt; k++) {
        if (pad_image(wk, t[k].color, 0, wk->tx + 3 * k) ||
            (use_a && t[k].albedo && pad_image(wk, t[k].albedo, 0, wk->ta + 3 * k)) ||
            (use_n && t[k].normal && pad_image(wk, t[k].normal, 0, wk->tn + 3 * k)))
            return -1;
    }
    return 0;
}

/* ---- one strip of rows ---- */

/* Scratch of one strip: S = STRIP_ROWS rows, E = S + 2f ext rows (the patch margin),
 * EW = w + 2f ext columns. */
typedef struct {
    float *d;  /* EW: per-pixel colour distance of one ext row (or its tangent) */
    float *hb; /* E x w: d summed along rows over the patch */
    float *
        coef; /* 3 x E x EW: 2 (x_a - x_b) / (eps + k^2 (V_a + V_b)); NULL: no tangents */
    float *wgt;   /* S x w: the offset's weights */
    float *slope; /* S x w: d(-log w) / d(sum of d over the patch); 0 where dc <= 0 */
    float *dc;    /* w: one row of patch distances or log-weights */
    float *acc;   /* (4 + 7 nt) x S x w: W, num[3], then per tangent A[3], B[3], G */
} nlm_scratch;

static size_t
scratch_floats(const nlm_work *wk, int f)
{
    size_t e = STRIP_ROWS + 2 * (size_t)f, ew = (size_t)wk->w + 2 * (size_t)f;
    size_t sw = STRIP_ROWS * (size_t)wk->w;
    return ew + e * wk->w + (wk->nt ? 3 * e * ew : 0) + 2 * sw + wk->w +
           (4 + 7 * (size_t)wk->nt) * sw;
}

static void
scratch_carve(const nlm_work *wk, int f, float *base, nlm_scratch *s)
{
    size_t e = STRIP_ROWS + 2 * (size_t)f, ew = (size_t)wk->w + 2 * (size_t)f;
    size_t sw = STRIP_ROWS * (size_t)wk->w;
    s->d = base;
    base += ew;
    s->hb = base;
    base += e * wk->w;
    s->coef = wk->nt ? base : NULL;
    base += wk->nt ? 3 * e * ew : 0;
    s->wgt = base;
    base += sw;
    s->slope = base;
    base += sw;
    s->dc = base;
    base += wk->w;
    s->acc = base;
}

/* hb[x] = sum_{j <= 2f} d[x + j]: one row of d summed over the patch width. The
 * rows are short enough to stay in L1, so one pass per term costs little and, unlike
 * an inner loop over j, vectorises. */
static void
box_row(const float *restrict d, float *restrict hb, int w, int f)
{
#pragma omp simd
    for (int x = 0; x < w; x++)
        hb[x] = d[x];
    for (int j = 1; j <= 2 * f; j++) {
        const float *restrict dj = d + j;
#pragma omp simd
        for (int x = 0; x < w; x++)
            hb[x] += dj[x];
    }
}

/* dc[x] = sum_{j <= 2f} hb[y + j][x]: the patch sum at strip row y. */
static void
box_column(const float *restrict hb, float *restrict dc, int y, int w, int f)
{
    const float *restrict src = hb + (size_t)y * w;
#pragma omp simd
    for (int x = 0; x < w; x++)
        dc[x] = src[x];
    for (int j = 1; j <= 2 * f; j++) {
        const float *restrict row = src + (size_t)j * w;
#pragma omp simd
        for (int x = 0; x < w; x++)
            dc[x] += row[x];
    }
}

/* lw[x] -= |F_p - F_q|^2 * inv for a 3-channel feature F (padded planes). */
static void
feature_term(const float *const planes[3], ptrdiff_t prow, ptrdiff_t off, float inv,
             float *restrict lw, int w)
{
    const float *restrict f0 = planes[0] + prow, *restrict f1 = planes[1] + prow;
    const float *restrict f2 = planes[2] + prow;
#pragma omp simd
    for (int x = 0; x < w; x++) {
        float d0 = f0[x] - f0[x + off], d1 = f1[x] - f1[x + off];
        float d2 = f2[x] - f2[x + off];
        lw[x] -= (d0 * d0 + d1 * d1 + d2 * d2) * inv;
    }
}

/* g[x] -= 2 inv (F_p - F_q) . (T_p - T_q): the tangent of feature_term. */
static void
feature_tangent(const float *const planes[3], const float *const tplanes[3],
                ptrdiff_t prow, ptrdiff_t off, float inv, float *restrict g, int w)
{
    const float *restrict f0 = planes[0] + prow, *restrict f1 = planes[1] + prow;
    const float *restrict f2 = planes[2] + prow, *restrict t0 = tplanes[0] + prow;
    const float *restrict t1 = tplanes[1] + prow, *restrict t2 = tplanes[2] + prow;
#pragma omp simd
    for (int x = 0; x < w; x++)
        g[x] -= 2 * inv *
                ((f0[x] - f0[x + off]) * (t0[x] - t0[x + off]) +
                 (f1[x] - f1[x + off]) * (t1[x] - t1[x + off]) +
                 (f2[x] - f2[x + off]) * (t2[x] - t2[x + off]));
}

/* The primal part of offset (ox, oy) for strip rows [y0, y0 + rows): distances,
 * coefficients for the tangents, weights, and the sums W and num. */
NLM_KERNEL_PART static void
strip_offset_primal(const nlm_params *p, const nlm_work *wk, nlm_scratch *s, int y0,
                    int rows, int ox, int oy)
{
    int f = p->patch_radius, w = wk->w, pw = wk->pw, pad = wk->pad;
    int e = rows + 2 * f, ew = w + 2 * f;
    ptrdiff_t off = (ptrdiff_t)oy * pw + ox;
    float k2 = (float)(p->k_color * p->k_color), eps = (float)p->epsilon;
    float alpha = (float)p->alpha;
    size_t eplane = (size_t)e * ew;
    for (int r = 0; r < e; r++) {
        ptrdiff_t base = (ptrdiff_t)(y0 - f + r + pad) * pw + (pad - f);
        float *restrict d = s->d;
        memset(d, 0, (size_t)ew * sizeof *d);
        for (int c = 0; c < 3; c++) {
            const float *restrict xa = wk->x[c] + base, *restrict va = wk->v[c] + base;
            float *restrict co = s->coef ? s->coef + c * eplane + (size_t)r * ew : NULL;
            /* the same arithmetic with and without coefficients, so that apply and jvp
             * agree bit for bit */
            if (co) {
#pragma omp simd
                for (int i = 0; i < ew; i++) {
                    float diff = xa[i] - xa[i + off], inv;
                    d[i] += pair_distance(diff, va[i], va[i + off], k2, eps, alpha, &inv);
                    co[i] = 2 * diff * inv;
                }
            } else {
#pragma omp simd
                for (int i = 0; i < ew; i++) {
                    float diff = xa[i] - xa[i + off], inv;
                    d[i] += pair_distance(diff, va[i], va[i + off], k2, eps, alpha, &inv);
                }
            }
        }
        box_row(d, s->hb + (size_t)r * w, w, f);
    }
    float norm = 1.0f / (3.0f * (float)((2 * f + 1) * (2 * f + 1)));
    size_t sw = (size_t)STRIP_ROWS * w;
    float *restrict lw = s->dc;
    for (int y = 0; y < rows; y++) {
        box_column(s->hb, lw, y, w, f);
        ptrdiff_t prow = (ptrdiff_t)(y0 + y + pad) * pw + pad;
        float *restrict wg = s->wgt + (size_t)y * w;
        float *restrict sl = s->slope + (size_t)y * w;
        /* log-weight -soft_max0(dc) and its slope d(-log w)/d(patch sum): with
         * m = clamp((dc + KINK) / (2 KINK), 0, 1), soft_max0 = KINK m^2 + max(0, dc -
         * KINK) and its derivative is m. Clamps and max are written with fabsf:
         * GCC does not vectorise selects that feed arithmetic (-ftrapping-math). */
        float inv_2h = 0.5f / KINK;
#pragma omp simd
        for (int x = 0; x < w; x++) {
            float dcx = lw[x] * norm, z = (dcx + KINK) * inv_2h;
            float m = 0.5f * (fabsf(z) - fabsf(z - 1.0f) + 1.0f), above = dcx - KINK;
            sl[x] = m * norm;
            lw[x] = -(KINK * m * m + 0.5f * (above + fabsf(above)));
        }
        if (wk->a[0]) feature_term(wk->a, prow, off, wk->inv_2sa2, lw, w);
        if (wk->n[0]) feature_term(wk->n, prow, off, wk->inv_2sn2, lw, w);
        /* the spatial falloff (a constant of the offset), and a floor: below -87 a
         * weight is about 1e-38, so clamping there changes F by less than float
         * rounding, and the JVP's w g stays as small. NaN (from NaN input) goes to the
         * floor too, so that exp_nonpositive never converts NaN to an integer. */
        float spatial = -(float)(ox * ox + oy * oy) * wk->inv_2ss2;
#pragma omp simd
        for (int x = 0; x < w; x++)
            lw[x] = lw[x] + spatial >= -87.0f ? lw[x] + spatial : -87.0f; /* NaN too */
        const float *restrict xq0 = wk->x[0] + prow + off;
        const float *restrict xq1 = wk->x[1] + prow + off;
        const float *restrict xq2 = wk->x[2] + prow + off;
        float *restrict wsum = s->acc + (size_t)y * w, *restrict n0 = wsum + sw;
        float *restrict n1 = n0 + sw, *restrict n2 = n1 + sw;
#pragma omp simd
        for (int x = 0; x < w; x++) {
            float wx = exp_nonpositive(lw[x]);
            wg[x] = wx;
            wsum[x] += wx;
            n0[x] += wx * xq0[x];
            n1[x] += wx * xq1[x];
            n2[x] += wx * xq2[x];
        }
    }
}

/* The part of tangent k for offset (ox, oy): A += w t_q, B += w g (x_q - x_p),
 * G += w g, with g = d log w. */
NLM_KERNEL_PART static void
strip_offset_tangent(const nlm_params *p, const nlm_work *wk, nlm_scratch *s, int y0,
                     int rows, int ox, int oy, int k)
{
    int f = p->patch_radius, w = wk->w, pw = wk->pw, pad = wk->pad;
    int e = rows + 2 * f, ew = w + 2 * f;
    ptrdiff_t off = (ptrdiff_t)oy * pw + ox;
    size_t eplane = (size_t)e * ew;
    const float *const *tx = wk->tx + 3 * k, *const *ta = wk->ta + 3 * k;
    const float *const *tn = wk->tn + 3 * k;
    for (int r = 0; r < e; r++) {
        ptrdiff_t base = (ptrdiff_t)(y0 - f + r + pad) * pw + (pad - f);
        const float *restrict t0 = tx[0] + base, *restrict t1 = tx[1] + base;
        const float *restrict t2 = tx[2] + base;
        const float *restrict c0 = s->coef + (size_t)r * ew, *restrict c1 = c0 + eplane;
        const float *restrict c2 = c1 + eplane;
        float *restrict d = s->d;
#pragma omp simd
        for (int i = 0; i < ew; i++)
            d[i] = c0[i] * (t0[i] - t0[i + off]) + c1[i] * (t1[i] - t1[i + off]) +
                   c2[i] * (t2[i] - t2[i + off]);
        box_row(d, s->hb + (size_t)r * w, w, f);
    }
    size_t sw = (size_t)STRIP_ROWS * w;
    float *acc = s->acc + (4 + 7 * (size_t)k) * sw;
    float *restrict g = s->dc;
    for (int y = 0; y < rows; y++) {
        box_column(s->hb, g, y, w, f);
        ptrdiff_t prow = (ptrdiff_t)(y0 + y + pad) * pw + pad;
        const float *restrict wg = s->wgt + (size_t)y * w;
        const float *restrict sl = s->slope + (size_t)y * w;
#pragma omp simd
        for (int x = 0; x < w; x++)
            g[x] = -sl[x] * g[x];
        if (wk->a[0] && ta[0]) feature_tangent(wk->a, ta, prow, off, wk->inv_2sa2, g, w);
        if (wk->n[0] && tn[0]) feature_tangent(wk->n, tn, prow, off, wk->inv_2sn2, g, w);
        const float *restrict xp0 = wk->x[0] + prow, *restrict xp1 = wk->x[1] + prow;
        const float *restrict xp2 = wk->x[2] + prow;
        const float *restrict tq0 = tx[0] + prow + off;
        const float *restrict tq1 = tx[1] + prow + off;
        const float *restrict tq2 = tx[2] + prow + off;
        size_t row = (size_t)y * w;
        float *restrict a0 = acc + row, *restrict a1 = a0 + sw, *restrict a2 = a1 + sw;
        float *restrict b0 = a2 + sw, *restrict b1 = b0 + sw, *restrict b2 = b1 + sw;
        float *restrict gs = b2 + sw;
#pragma omp simd
        for (int x = 0; x < w; x++) {
            float wx = wg[x], wgx = wx * g[x];
            gs[x] += wgx;
            a0[x] += wx * tq0[x];
            a1[x] += wx * tq1[x];
            a2[x] += wx * tq2[x];
            b0[x] += wgx * (xp0[x + off] - xp0[x]);
            b1[x] += wgx * (xp1[x + off] - xp1[x]);
            b2[x] += wgx * (xp2[x + off] - xp2[x]);
        }
    }
}

/* Rows [y0, y0 + rows): every offset in a fixed order, then the outputs. */
NLM_KERNEL static void
run_strip(const nlm_params *p, const nlm_work *wk, nlm_scratch *s, int y0, int rows,
          const nlm_out *out)
{
    int w = wk->w, r = p->radius, pad = wk->pad, pw = wk->pw;
    size_t sw = (size_t)STRIP_ROWS * w;
    memset(s->acc, 0, (4 + 7 * (size_t)wk->nt) * sw * sizeof *s->acc);
    for (int oy = -r; oy <= r; oy++)
        for (int ox = -r; ox <= r; ox++) {
            strip_offset_primal(p, wk, s, y0, rows, ox, oy);
            for (int k = 0; k < wk->nt; k++)
                strip_offset_tangent(p, wk, s, y0, rows, ox, oy, k);
        }
    for (int y = 0; y < rows; y++) {
        const float *wsum = s->acc + (size_t)y * w;
        ptrdiff_t prow = (ptrdiff_t)(y0 + y + pad) * pw + pad;
        for (int x = 0; x < w; x++) {
            float inv = 1.0f / wsum[x];
            size_t o = ((size_t)(y0 + y) * w + x) * 3;
            float den[3];
            for (int c = 0; c < 3; c++) {
                den[c] = s->acc[(1 + c) * sw + (size_t)y * w + x] * inv;
                if (out->primal) out->primal[o + c] = den[c];
            }
            for (int k = 0; k < wk->nt; k++) {
                const float *acc = s->acc + (4 + 7 * (size_t)k) * sw + (size_t)y * w + x;
                float g = acc[6 * sw];
                for (int c = 0; c < 3; c++) {
                    float xp = wk->x[c][prow + x];
                    out->tangent[k][o + c] =
                        (acc[c * sw] + acc[(3 + c) * sw] - (den[c] - xp) * g) * inv;
                }
            }
        }
    }
}

/* Progress of a run on a terminal, a step per strip: a megapixel takes seconds, an
 * estimate's tangents several times that. Shown as the U-Net's is (estimate/unet.c):
 * only on a terminal, for images of a megapixel or more, not with --quiet, and not
 * when called from inside a parallel region (several images at once would share one
 * line). The master thread draws it, as strips finish in any order. */
static int
show_progress(int w, int h)
{
    int nested = 0;
#ifdef _OPENMP
    nested = omp_in_parallel();
#endif
    return (double)w * h >= 1048576.0 && !mcp_progress_quiet() && isatty(STDERR_FILENO) &&
           !nested;
}

/* The bar's steps: a strip each, and the set-up before them (padding the colour, the
 * features and every tangent: about an eighth of an estimate's time at 4K, 7 of 60 s). */
static int
strips_of(int h)
{
    return (h + STRIP_ROWS - 1) / STRIP_ROWS;
}

static long
setup_steps(int h)
{
    return strips_of(h) / 8 + 1;
}

static int
thread_num(void)
{
#ifdef _OPENMP
    return omp_get_thread_num();
#else
    return 0;
#endif
}

/* Runs every strip; outputs must be allocated packed w x h x 3. bar: the progress
 * begun by the caller (NULL: none), at setup_steps. */
static int
run_all(const char *who, const nlm_params *p, const nlm_work *wk, const nlm_out *out,
        mcp_progress *bar)
{
    int n_strips = strips_of(wk->h), failed = 0, finished = 0;
    long before = setup_steps(wk->h);
    size_t floats = scratch_floats(wk, p->patch_radius);
    const int show = bar != NULL;
#pragma omp parallel if ((size_t)wk->w * wk->h >= PARALLEL_MIN_PIXELS && n_strips > 1)
    {
        float *buf = mcp_malloc(floats * sizeof *buf);
        nlm_scratch s = {0};
        if (!buf) {
#pragma omp atomic write
            failed = 1;
        } else {
            scratch_carve(wk, p->patch_radius, buf, &s);
        }
#pragma omp for schedule(dynamic, 1)
        for (int i = 0; i < n_strips; i++) {
            int y0 = i * STRIP_ROWS,
                rows = wk->h - y0 < STRIP_ROWS ? wk->h - y0 : STRIP_ROWS;
            if (buf) run_strip(p, wk, &s, y0, rows, out);
            if (show) {
                int n;
#pragma omp atomic capture
                n = ++finished;
                if (thread_num() == 0) mcp_progress_update(bar, before + n);
            }
        }
        free(buf);
    }
    if (failed)
        return mcp_error("%s: out of memory (%zu bytes of scratch per thread)", who,
                         floats * sizeof(float));
    return 0;
}

/* ---- the interface ---- */

static int
nlm_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
        const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const nlm_params *p = self->state;
    if (primal) *primal = NULL;
    for (int k = 0; k < n && out; k++)
        out[k] = NULL;
    if (mcp__denoise_check_input(self->name, at) ||
        mcp__denoise_check_tangents(self->name, at, t, n))
        return -1;
    if (n > 0 && !out)
        return mcp_error("%s: no room for %d tangent outputs", self->name, n);
    int w = at->color->width, h = at->color->height, rc = -1;
    nlm_work wk;
    mcp_image *prim = NULL;
    float **tout = n ? mcp_calloc((size_t)n, sizeof *tout) : NULL;
    if (n && !tout) return -1;
    mcp_progress bar;
    const int show = show_progress(w, h);
    if (show) {
        char label[96];
        snprintf(label, sizeof label, "%s%s", self->name, n ? " and its tangents" : "");
        mcp_progress_begin(&bar, label, setup_steps(h) + strips_of(h));
    }
    if (work_init(p, at, t, n, &wk)) goto done;
    if (show) mcp_progress_update(&bar, setup_steps(h));
    if (primal && mcp__rgb_new(w, h, self->name, &prim)) goto done;
    for (int k = 0; k < n; k++) {
        if (mcp__rgb_new(w, h, "jvp", &out[k])) goto done;
        tout[k] = out[k]->data;
    }
    nlm_out o = {prim ? prim->data : NULL, tout};
    if (run_all(self->name, p, &wk, &o, show ? &bar : NULL)) goto done;
    rc = 0;
done:
    if (show) {
        if (rc)
            mcp__progress_stop(&bar); /* no "100%" for a run that failed */
        else
            mcp_progress_end(&bar);
    }
    work_free(&wk);
    free(tout);
    if (rc) {
        mcp_image_free(prim);
        prim = NULL;
        for (int k = 0; k < n; k++) {
            mcp_image_free(out[k]);
            out[k] = NULL;
        }
    }
    if (primal) *primal = prim;
    return rc;
}

static int
nlm_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    *out = NULL;
    return nlm_jvp(self, in, NULL, 0, out, NULL);
}

/* Reads the settings through op's table (its defaults first) and makes a denoiser
 * called op's name. */
static int
create_with(const mcp_operation *op, const mcp_node *settings, mcp_denoiser **out)
{
    *out = NULL;
    const char *name = op->name;
    nlm_params p;
    if (mcp__options_from_node(op, settings, NULL, &p)) return -1;
    mcp_denoiser *d = mcp__denoiser_new(name, sizeof p);
    if (!d) return -1;
    memcpy(d->state, &p, sizeof p);
    d->uses_albedo = p.sigma_albedo > 0;
    d->uses_normal = p.sigma_normal > 0;
    d->sharp_variance = p.patch_radius == 0;
    /* a pixel reads patches around the pixels of its window, and the variance there
       prefiltered (pad_variance) */
    d->band_halo =
        p.radius + p.patch_radius +
        (p.use_variance && p.variance_blur > 0 ? (int)ceil(3 * p.variance_blur) : 0) + 1;
    d->apply = nlm_apply;
    d->jvp = nlm_jvp;
    *out = d;
    return 0;
}

/* Defaults tuned on the Cornell-box fixtures (1-1024 spp) and the procedural scene;
 * docs/denoisers.md and docs/benchmarks.md give the figures. */
static void
nlm_defaults(void *out)
{
    nlm_params p = {
        .radius = 7,
        .patch_radius = 2,
        .k_color = 0.6,
        .alpha = 1.0,
        .epsilon = 1e-4,
        .sigma_color = 0.05,
        .use_variance = 1,
        .variance_blur = 1.0,
        .sigma_albedo = 0.2,
        .sigma_normal = 0.3,
        .sigma_spatial = 0,
    };
    memcpy(out, &p, sizeof p);
}

/* The cross-bilateral filter is the same computation with one-pixel patches and a
 * spatial Gaussian; its single-pixel colour distances are noisier, hence a wider
 * colour bandwidth. */
static void
bilateral_defaults(void *out)
{
    nlm_defaults(out);
    nlm_params *p = out;
    p->radius = 6;
    p->patch_radius = 0;
    p->k_color = 2.0;
    p->sigma_spatial = 2.0;
}

const mcp_operation mcp__op_nlm = {
    .name = "nlm",
    .denoiser = 1,
    .summary = "feature-guided non-local means",
    .options = nlm_options,
    .size = sizeof(nlm_params),
    .defaults = nlm_defaults,
};

const mcp_operation mcp__op_bilateral = {
    .name = "bilateral",
    .denoiser = 1,
    .summary = "feature-guided cross-bilateral filter",
    .options = bilateral_options,
    .size = sizeof(nlm_params),
    .defaults = bilateral_defaults,
};

static int
nlm_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    (void)base_dir;
    return create_with(&mcp__op_nlm, settings, out);
}

static int
bilateral_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    (void)base_dir;
    return create_with(&mcp__op_bilateral, settings, out);
}

const mcp_denoiser_kind mcp__denoiser_nlm = {
    "nlm",
    "feature-guided non-local means: weights from colour patch distances (scaled by "
    "the variance), albedo and normal; exact JVP",
    mcp__nlm_keys,
    nlm_create,
    &mcp__op_nlm,
};

const mcp_denoiser_kind mcp__denoiser_bilateral = {
    "bilateral",
    "feature-guided cross-bilateral filter: nlm with one-pixel patches and a spatial "
    "Gaussian (sigma_spatial [2] px); exact JVP",
    mcp__nlm_keys,
    bilateral_create,
    &mcp__op_bilateral,
};
