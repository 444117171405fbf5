/* flip.c: LDR-FLIP and HDR-FLIP (docs/flip.md §1-3, §6), matching
 * NVlabs/flip v1.6 src/cpp/FLIP.h operation for operation in float32.
 *
 * Layout: each image is held as planes (Y, Cx, Cz, normalised Y) so that every filter
 * pass is a loop over x with the taps outside it. That vectorises across pixels while
 * each pixel still sums its taps sequentially from -r to r, in FLIP's order, so the
 * per-pixel values equal the reference's scalar loops. OpenMP splits rows only.
 *
 * This file needs -ffp-contract=off (the default in ISO C mode, which mcpost builds
 * in): a fused multiply-add would change the float rounding FLIP's numbers depend on. */
#include <mcpost/flip.h>
#include "fastpow.h"
#include "internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define PI_F 3.14159265358979f

/* D65 reference white and its inverse (FLIP.h DEFAULT_ILLUMINANT). */
static const float WHITE[3] = {0.950428545f, 1.000000000f, 1.088900371f};
static const float INV_WHITE[3] = {1.052156925f, 1.000000000f, 0.918357670f};

/* FLIP.h xGaussianConstants: channels Y, Cx, Cz. */
static const float CSF_A1[3] = {1.0f, 1.0f, 34.1f};
static const float CSF_B1[3] = {0.0047f, 0.0053f, 0.04f};
static const float CSF_A2[3] = {0.0f, 0.0f, 13.5f};
static const float CSF_B2[3] = {1.0e-5f, 1.0e-5f, 0.025f};

/* Pixels per register block in the filter loops (see filter_x1). */
#define VB 16

/* Images with fewer pixels than this are not worth an OpenMP team. */
#define PARALLEL_MIN_PIXELS 16384

/* ---- colour transforms (FLIP.h color3), float, same operation order ---- */

static inline MCP_ALWAYS_INLINE void
rgb_to_xyz(float r, float g, float b, float *xyz)
{
    const float a11 = 10135552.0f / 24577794.0f, a12 = 8788810.0f / 24577794.0f,
                a13 = 4435075.0f / 24577794.0f;
    const float a21 = 2613072.0f / 12288897.0f, a22 = 8788810.0f / 12288897.0f,
                a23 = 887015.0f / 12288897.0f;
    const float a31 = 1425312.0f / 73733382.0f, a32 = 8788810.0f / 73733382.0f,
                a33 = 70074185.0f / 73733382.0f;
    xyz[0] = a11 * r + a12 * g + a13 * b;
    xyz[1] = a21 * r + a22 * g + a23 * b;
    xyz[2] = a31 * r + a32 * g + a33 * b;
}

static inline MCP_ALWAYS_INLINE void
xyz_to_rgb(const float *xyz, float *rgb)
{
    rgb[0] = 3.241003275f * xyz[0] + -1.537398934f * xyz[1] + -0.498615861f * xyz[2];
    rgb[1] = -0.969224334f * xyz[0] + 1.875930071f * xyz[1] + 0.041554224f * xyz[2];
    rgb[2] = 0.055639423f * xyz[0] + -0.204011202f * xyz[1] + 1.057148933f * xyz[2];
}

static inline MCP_ALWAYS_INLINE void
xyz_to_ycxcz(const float *xyz, float *out)
{
    float x = xyz[0] * INV_WHITE[0], y = xyz[1] * INV_WHITE[1], z = xyz[2] * INV_WHITE[2];
    out[0] = 116.0f * y - 16.0f;
    out[1] = 500.0f * (x - y);
    out[2] = 200.0f * (y - z);
}

static inline MCP_ALWAYS_INLINE void
ycxcz_to_xyz(float Y, float Cx, float Cz, float *xyz)
{
    const float y = (Y + 16.0f) / 116.0f, cx = Cx / 500.0f, cz = Cz / 200.0f;
    xyz[0] = (y + cx) * WHITE[0];
    xyz[1] = y * WHITE[1];
    xyz[2] = (y - cz) * WHITE[2];
}

/* fast: the cube root by mcp__powf_pos (fastpow.h), which vectorises, instead of
 * libm's powf (a few float roundings apart; tests/common/test_flip.c compares the maps
 * with a double-precision FLIP per pixel). */
static inline MCP_ALWAYS_INLINE float
lab_f(float t, int fast)
{
    const float delta = 6.0f / 29.0f;
    const float delta_square = delta * delta;
    const float delta_cube = delta * delta_square;
    const float factor = 1.0f / (3.0f * delta_square);
    const float term = 4.0f / 29.0f;
    float cube_root = fast ? mcp__powf_pos(t, 1.0f / 3.0f) : powf(t, 1.0f / 3.0f);
    return t > delta_cube ? cube_root : factor * t + term;
}

/* XYZ -> CIELAB with the Hunt adjustment (a, b scaled by 0.01 L). */
static inline MCP_ALWAYS_INLINE void
xyz_to_lab_hunt(const float *xyz, float *lab, int fast)
{
    float fx = lab_f(xyz[0] * INV_WHITE[0], fast),
          fy = lab_f(xyz[1] * INV_WHITE[1], fast),
          fz = lab_f(xyz[2] * INV_WHITE[2], fast);
    float L = 116.0f * fy - 16.0f, a = 500.0f * (fx - fy), b = 200.0f * (fy - fz);
    lab[0] = L;
    lab[1] = 0.01f * L * a;
    lab[2] = 0.01f * L * b;
}

static inline MCP_ALWAYS_INLINE float
hyab(const float *r, const float *t)
{
    float dl = fabsf(r[0] - t[0]);
    return dl + sqrtf((r[1] - t[1]) * (r[1] - t[1]) + (r[2] - t[2]) * (r[2] - t[2]));
}

static inline MCP_ALWAYS_INLINE float
clamp01(float v)
{
    return (v > 0.0f ? v : 0.0f) > 1.0f ? 1.0f : (v > 0.0f ? v : 0.0f);
}

float
mcp_flip_cmax(void)
{
    float xyz[3], green[3], blue[3];
    rgb_to_xyz(0.0f, 1.0f, 0.0f, xyz);
    xyz_to_lab_hunt(xyz, green, 0);
    rgb_to_xyz(0.0f, 0.0f, 1.0f, xyz);
    xyz_to_lab_hunt(xyz, blue, 0);
    return powf(hyab(green, blue), MCP_FLIP_QC);
}

/* ---- filters (FLIP.h setSpatialFilters, setFeatureFilter) ---- */

static inline float
gaussian_ab(float x2, float a, float b)
{
    const float pi = PI_F, pi_sq = PI_F * PI_F;
    return a * sqrtf(pi / b) * expf(-pi_sq * x2 / b);
}

static inline float
gaussian_sqrt_ab(float x2, float a, float b)
{
    const float pi = PI_F, pi_sq = PI_F * PI_F;
    return sqrtf(a * sqrtf(pi / b)) * expf(-pi_sq * x2 / b);
}

static int
spatial_radius(float ppd)
{
    const float pi_sq = PI_F * PI_F;
    float max_b = 0.0f;
    for (int c = 0; c < 3; c++) {
        max_b = CSF_B1[c] > max_b ? CSF_B1[c] : max_b;
        max_b = CSF_B2[c] > max_b ? CSF_B2[c] : max_b;
    }
    return (int)ceilf(3.0f * sqrtf(max_b / (2.0f * pi_sq)) * ppd);
}

void
mcp_flip_filters_free(mcp_flip_filters *f)
{
    if (!f) return;
    free(f->y);
    free(f->g);
    free(f);
}

int
mcp_flip_filters_new(float ppd, mcp_flip_filters **out)
{
    *out = NULL;
    if (!(ppd > 0.0f) || !(ppd <= 10000.0f))
        return mcp_error("flip: ppd must be in (0, 10000] (got %g)", (double)ppd);
    mcp_flip_filters *f = mcp_calloc(1, sizeof *f);
    if (!f) return -1;
    f->ppd = ppd;
    int rs = f->spatial_radius = spatial_radius(ppd), ws = 2 * rs + 1;
    const float std_dev = 0.5f * MCP_FLIP_W * ppd;
    int rf = f->feature_radius = (int)ceilf(3.0f * std_dev), wf = 2 * rf + 1;
    if (!(f->y = mcp_malloc(4 * (size_t)ws * sizeof(float))) ||
        !(f->g = mcp_malloc(3 * (size_t)wf * sizeof(float)))) {
        mcp_flip_filters_free(f);
        return -1;
    }
    f->cx = f->y + ws;
    f->cz1 = f->cx + ws;
    f->cz2 = f->cz1 + ws;
    f->dg = f->g + wf;
    f->ddg = f->dg + wf;

    /* Spatial: taps at x in degrees, 1/ppd apart; Y and Cx normalised to sum 1, the
     * two Cz square-root Gaussians by 1/sqrt(S1^2 + S2^2). */
    const float delta_x = 1.0f / ppd;
    float sum_y = 0.0f, sum_cx = 0.0f, sum_cz1 = 0.0f, sum_cz2 = 0.0f;
    for (int x = 0; x < ws; x++) {
        float ix = (float)(x - rs) * delta_x, ix2 = ix * ix;
        f->y[x] = gaussian_ab(ix2, CSF_A1[0], CSF_B1[0]);
        f->cx[x] = gaussian_ab(ix2, CSF_A1[1], CSF_B1[1]);
        f->cz1[x] = gaussian_sqrt_ab(ix2, CSF_A1[2], CSF_B1[2]);
        f->cz2[x] = gaussian_sqrt_ab(ix2, CSF_A2[2], CSF_B2[2]);
        sum_y += f->y[x];
        sum_cx += f->cx[x];
        sum_cz1 += f->cz1[x];
        sum_cz2 += f->cz2[x];
    }
    const float norm_y = 1.0f / sum_y, norm_cx = 1.0f / sum_cx;
    const float norm_cz = 1.0f / sqrtf(sum_cz1 * sum_cz1 + sum_cz2 * sum_cz2);
    for (int x = 0; x < ws; x++) {
        f->y[x] *= norm_y;
        f->cx[x] *= norm_cx;
        f->cz1[x] *= norm_cz;
        f->cz2[x] *= norm_cz;
    }

    /* Feature: Gaussian (sum 1) and its derivatives (positive taps sum 1, negative -1),
     * sigma = 0.5 w ppd pixels. */
    float g_sum = 0.0f, dg_pos = 0.0f, dg_neg = 0.0f, ddg_pos = 0.0f, ddg_neg = 0.0f;
    for (int x = 0; x < wf; x++) {
        int xx = x - rf;
        float g = expf(-((float)xx * (float)xx) / (2.0f * std_dev * std_dev));
        g_sum += g;
        float dg = -(float)xx * g;
        if (dg > 0.0f)
            dg_pos += dg;
        else
            dg_neg -= dg;
        float ddg = ((float)xx * (float)xx / (std_dev * std_dev) - 1.0f) * g;
        if (ddg > 0.0f)
            ddg_pos += ddg;
        else
            ddg_neg -= ddg;
        f->g[x] = g;
        f->dg[x] = dg;
        f->ddg[x] = ddg;
    }
    for (int x = 0; x < wf; x++) {
        f->g[x] = f->g[x] / g_sum;
        f->dg[x] = f->dg[x] / (f->dg[x] > 0.0f ? dg_pos : dg_neg);
        f->ddg[x] = f->ddg[x] / (f->ddg[x] > 0.0f ? ddg_pos : ddg_neg);
    }
    *out = f;
    return 0;
}

/* ---- options ---- */

mcp_flip_options
mcp_flip_defaults(void)
{
    return (mcp_flip_options){.ppd = 0.0,
                              .distance_m = 0.7,
                              .display_width_m = 0.7,
                              .display_width_px = 3840.0,
                              .tone_mapper = MCP_TONEMAP_ACES,
                              .start_exposure = NAN,
                              .stop_exposure = NAN,
                              .num_exposures = 0};
}

static int
positive(double v)
{
    return v > 0.0 && isfinite(v);
}

int
mcp_flip_ppd(const mcp_flip_options *opt, float *ppd)
{
    mcp_flip_options d = mcp_flip_defaults();
    if (!opt) opt = &d;
    if (opt->ppd != 0.0) {
        if (!positive(opt->ppd) || opt->ppd > 10000.0)
            return mcp_error("flip: ppd must be in (0, 10000] (got %g)", opt->ppd);
        *ppd = (float)opt->ppd;
        return 0;
    }
    if (!positive(opt->distance_m))
        return mcp_error("flip: distance_m must be > 0 (got %g)", opt->distance_m);
    if (!positive(opt->display_width_m))
        return mcp_error("flip: display_width_m must be > 0 (got %g)",
                         opt->display_width_m);
    if (!positive(opt->display_width_px))
        return mcp_error("flip: display_width_px must be > 0 (got %g)",
                         opt->display_width_px);
    /* FLIP.h calculatePPD, in float. */
    float p = (float)opt->distance_m *
              ((float)opt->display_width_px / (float)opt->display_width_m) *
              (PI_F / 180.0f);
    if (!(p > 0.0f) || !(p <= 10000.0f))
        return mcp_error("flip: the viewing condition gives ppd %g, outside (0, 10000]",
                         (double)p);
    *ppd = p;
    return 0;
}

/* ---- input checks ---- */

static const char *
src_name(const mcp_image *img)
{
    return img->source ? img->source : "image";
}

/* Same size, RGB present, every value finite. */
static int
check_pair(const mcp_image *test, const mcp_image *ref, int rgb_t[3], int rgb_r[3])
{
    if (!test || !ref) return mcp_error("flip: missing image");
    if (mcp_rgb_channels(test, rgb_t) || mcp_rgb_channels(ref, rgb_r)) return -1;
    if (!mcp_image_same_size(test, ref)) return -1;
    if (test->width < 1 || test->height < 1)
        return mcp_error("%s: empty image", src_name(test));
    const mcp_image *imgs[2] = {test, ref};
    const int *idx[2] = {rgb_t, rgb_r};
    for (int i = 0; i < 2; i++) {
        long bad = -1;
        int w = imgs[i]->width, h = imgs[i]->height;
        for (int y = 0; y < h && bad < 0; y++)
            for (int x = 0; x < w; x++) {
                const float *p = mcp_image_px(imgs[i], x, y);
                if (!isfinite(p[idx[i][0]]) || !isfinite(p[idx[i][1]]) ||
                    !isfinite(p[idx[i][2]])) {
                    bad = (long)y * w + x;
                    break;
                }
            }
        if (bad >= 0)
            return mcp_error("%s: non-finite value at pixel (%ld, %ld)",
                             src_name(imgs[i]), bad % w, bad / w);
    }
    return 0;
}

/* ---- the LDR-FLIP core on planes ---- */

enum { REF = 0, TEST = 1 };

/* Scratch planes for one image pair, each w*h floats. The colour x pass writes
 * xy/xcx/xcz1/xcz2; the feature x pass reuses xy/xcx/xcz1 as dx/ddx/gauss. */
typedef struct {
    int w, h;
    float *block;
    float *Y[2], *Cx[2], *Cz[2], *Yn[2];
    float *xy[2], *xcx[2], *xcz1[2], *xcz2[2];
} flip_work;

static void
work_free(flip_work *k)
{
    free(k->block);
    k->block = NULL;
}

static int
work_new(flip_work *k, int w, int h)
{
    size_t n;
    memset(k, 0, sizeof *k);
    if (mcp_size_mul3((size_t)w, (size_t)h, 16, &n))
        return mcp_error("flip: image too large (%dx%d)", w, h);
    /* VB floats of slack after the last plane for whole-block reads. */
    if (!(k->block = mcp_calloc(n + VB, sizeof(float)))) return -1;
    k->w = w;
    k->h = h;
    size_t plane = (size_t)w * h;
    float **all[16] = {&k->Y[0],    &k->Y[1],    &k->Cx[0],   &k->Cx[1],
                       &k->Cz[0],   &k->Cz[1],   &k->Yn[0],   &k->Yn[1],
                       &k->xy[0],   &k->xy[1],   &k->xcx[0],  &k->xcx[1],
                       &k->xcz1[0], &k->xcz1[1], &k->xcz2[0], &k->xcz2[1]};
    for (int i = 0; i < 16; i++)
        *all[i] = k->block + i * plane;
    return 0;
}

/* One pixel of linear RGB (already in [0, 1]) into the YCxCz and normalised-Y planes. */
static inline void
put_ycxcz(flip_work *k, int which, size_t i, float r, float g, float b)
{
    const float one_over_116 = 1.0f / 116.0f, sixteen_over_116 = 16.0f / 116.0f;
    float xyz[3], ycc[3];
    rgb_to_xyz(r, g, b, xyz);
    xyz_to_ycxcz(xyz, ycc);
    k->Y[which][i] = ycc[0];
    k->Cx[which][i] = ycc[1];
    k->Cz[which][i] = ycc[2];
    k->Yn[which][i] = ycc[0] * one_over_116 + sixteen_over_116;
}

/* pad[0 .. n + 2r) = src[clamp(i - r)]: the row with its edges replicated, so that
 * reading pad[x + t] gives exactly the values (and order) of FLIP's clamped loop. */
static inline void
pad_row(const float *src, int n, int r, float *pad)
{
    for (int i = 0; i < r; i++) {
        pad[i] = src[0];
        pad[n + r + i] = src[n - 1];
    }
    memcpy(pad + r, src, (size_t)n * sizeof(float));
}

/* The filter loops keep the sums of a block of VB pixels in vector registers and add
 * each pixel's taps in order t = -r..r (FLIP's sequential float sum): the vector lanes
 * run over pixels, so no pixel's additions are reordered (GCC/Clang vector extensions
 * compute lane by lane in IEEE float). Filters that read the same input share its
 * loads. Blocks may read up to VB - 1 floats past the last pixel (pad rows and planes
 * have that slack) but store only real pixels. */
typedef float vf4 __attribute__((vector_size(16)));

static inline vf4
load4(const float *p)
{
    vf4 v;
    memcpy(&v, p, sizeof v);
    return v;
}

/* A block of VB = 16 sums in four vector registers. */
typedef struct {
    vf4 a, b, c, d;
} block16;

/* s += w * p[0..16) */
static inline void
block_madd(block16 *s, float w, const float *p)
{
    s->a += w * load4(p);
    s->b += w * load4(p + 4);
    s->c += w * load4(p + 8);
    s->d += w * load4(p + 12);
}

/* Stores the first n (<= VB) sums of a block. */
static inline void
block_store(float *dst, const block16 *s, int n)
{
    if (n == VB) {
        memcpy(dst, &s->a, 16);
        memcpy(dst + 4, &s->b, 16);
        memcpy(dst + 8, &s->c, 16);
        memcpy(dst + 12, &s->d, 16);
        return;
    }
    float tmp[VB];
    memcpy(tmp, &s->a, 16);
    memcpy(tmp + 4, &s->b, 16);
    memcpy(tmp + 8, &s->c, 16);
    memcpy(tmp + 12, &s->d, 16);
    memcpy(dst, tmp, (size_t)n * sizeof(float));
}

/* dst[x] = sum_t w[t] pad[x + t], for one row of n pixels. */
static inline void
filter_x1(const float *pad, int n, int r, const float *w, float *dst)
{
    for (int x0 = 0; x0 < n; x0 += VB) {
        block16 s = {{0}, {0}, {0}, {0}};
        for (int t = 0; t <= 2 * r; t++)
            block_madd(&s, w[t], pad + x0 + t);
        block_store(dst + x0, &s, n - x0 < VB ? n - x0 : VB);
    }
}

static inline void
filter_x2(const float *pad, int n, int r, const float *w0, const float *w1, float *d0,
          float *d1)
{
    for (int x0 = 0; x0 < n; x0 += VB) {
        block16 s0 = {{0}, {0}, {0}, {0}}, s1 = s0;
        for (int t = 0; t <= 2 * r; t++) {
            block_madd(&s0, w0[t], pad + x0 + t);
            block_madd(&s1, w1[t], pad + x0 + t);
        }
        int nb = n - x0 < VB ? n - x0 : VB;
        block_store(d0 + x0, &s0, nb);
        block_store(d1 + x0, &s1, nb);
    }
}

static inline void
filter_x3(const float *pad, int n, int r, const float *w0, const float *w1,
          const float *w2, float *d0, float *d1, float *d2)
{
    for (int x0 = 0; x0 < n; x0 += VB) {
        block16 s0 = {{0}, {0}, {0}, {0}}, s1 = s0, s2 = s0;
        for (int t = 0; t <= 2 * r; t++) {
            block_madd(&s0, w0[t], pad + x0 + t);
            block_madd(&s1, w1[t], pad + x0 + t);
            block_madd(&s2, w2[t], pad + x0 + t);
        }
        int nb = n - x0 < VB ? n - x0 : VB;
        block_store(d0 + x0, &s0, nb);
        block_store(d1 + x0, &s1, nb);
        block_store(d2 + x0, &s2, nb);
    }
}

/* off[t] = clamp(y + t - r) * w: the row offsets that output row y reads. */
static inline void
row_offsets(int y, int w, int h, int r, size_t *off)
{
    for (int t = -r; t <= r; t++) {
        int yy = y + t < 0 ? 0 : y + t > h - 1 ? h - 1 : y + t;
        off[t + r] = (size_t)yy * w;
    }
}

/* acc[i] = sum_t w[t] plane[off[t] + x0 + i], i < n (acc holds whole blocks). */
static inline void
filter_y1(const float *plane, const size_t *off, int x0, int n, int r, const float *w,
          float *acc)
{
    for (int i0 = 0; i0 < n; i0 += VB) {
        block16 s = {{0}, {0}, {0}, {0}};
        for (int t = 0; t <= 2 * r; t++)
            block_madd(&s, w[t], plane + off[t] + x0 + i0);
        block_store(acc + i0, &s, VB);
    }
}

static inline void
filter_y2(const float *plane, const size_t *off, int x0, int n, int r, const float *w0,
          const float *w1, float *a0, float *a1)
{
    for (int i0 = 0; i0 < n; i0 += VB) {
        block16 s0 = {{0}, {0}, {0}, {0}}, s1 = s0;
        for (int t = 0; t <= 2 * r; t++) {
            block_madd(&s0, w0[t], plane + off[t] + x0 + i0);
            block_madd(&s1, w1[t], plane + off[t] + x0 + i0);
        }
        block_store(a0 + i0, &s0, VB);
        block_store(a1 + i0, &s1, VB);
    }
}

/* The same filters 8 lanes wide for CPUs with AVX2, chosen at run time. Each lane
 * still computes sum += w * v with one rounding per multiply and per add (no FMA:
 * target "avx2" does not enable it, and ISO C mode does not contract), so both
 * versions give the same bits. */
#if defined(__GNUC__) && defined(__x86_64__)
#define FLIP_AVX2 1
#include <immintrin.h>

#define AVX2 __attribute__((target("avx2")))

typedef struct {
    __m256 a, b;
} block16x;

static inline AVX2 void
bx_madd(block16x *s, float w, const float *p)
{
    __m256 wv = _mm256_set1_ps(w);
    s->a = _mm256_add_ps(s->a, _mm256_mul_ps(wv, _mm256_loadu_ps(p)));
    s->b = _mm256_add_ps(s->b, _mm256_mul_ps(wv, _mm256_loadu_ps(p + 8)));
}

static inline AVX2 void
bx_store(float *dst, const block16x *s, int n)
{
    float tmp[VB];
    _mm256_storeu_ps(n == VB ? dst : tmp, s->a);
    _mm256_storeu_ps(n == VB ? dst + 8 : tmp + 8, s->b);
    if (n != VB) memcpy(dst, tmp, (size_t)n * sizeof(float));
}

static AVX2 void
filter_x1_avx2(const float *pad, int n, int r, const float *w, float *dst)
{
    for (int x0 = 0; x0 < n; x0 += VB) {
        block16x s = {_mm256_setzero_ps(), _mm256_setzero_ps()};
        for (int t = 0; t <= 2 * r; t++)
            bx_madd(&s, w[t], pad + x0 + t);
        bx_store(dst + x0, &s, n - x0 < VB ? n - x0 : VB);
    }
}

static AVX2 void
filter_x2_avx2(const float *pad, int n, int r, const float *w0, const float *w1,
               float *d0, float *d1)
{
    for (int x0 = 0; x0 < n; x0 += VB) {
        block16x s0 = {_mm256_setzero_ps(), _mm256_setzero_ps()}, s1 = s0;
        for (int t = 0; t <= 2 * r; t++) {
            bx_madd(&s0, w0[t], pad + x0 + t);
            bx_madd(&s1, w1[t], pad + x0 + t);
        }
        int nb = n - x0 < VB ? n - x0 : VB;
        bx_store(d0 + x0, &s0, nb);
        bx_store(d1 + x0, &s1, nb);
    }
}

static AVX2 void
filter_x3_avx2(const float *pad, int n, int r, const float *w0, const float *w1,
               const float *w2, float *d0, float *d1, float *d2)
{
    for (int x0 = 0; x0 < n; x0 += VB) {
        block16x s0 = {_mm256_setzero_ps(), _mm256_setzero_ps()}, s1 = s0, s2 = s0;
        for (int t = 0; t <= 2 * r; t++) {
            bx_madd(&s0, w0[t], pad + x0 + t);
            bx_madd(&s1, w1[t], pad + x0 + t);
            bx_madd(&s2, w2[t], pad + x0 + t);
        }
        int nb = n - x0 < VB ? n - x0 : VB;
        bx_store(d0 + x0, &s0, nb);
        bx_store(d1 + x0, &s1, nb);
        bx_store(d2 + x0, &s2, nb);
    }
}

static AVX2 void
filter_y1_avx2(const float *plane, const size_t *off, int x0, int n, int r,
               const float *w, float *acc)
{
    for (int i0 = 0; i0 < n; i0 += VB) {
        block16x s = {_mm256_setzero_ps(), _mm256_setzero_ps()};
        for (int t = 0; t <= 2 * r; t++)
            bx_madd(&s, w[t], plane + off[t] + x0 + i0);
        bx_store(acc + i0, &s, VB);
    }
}

static AVX2 void
filter_y2_avx2(const float *plane, const size_t *off, int x0, int n, int r,
               const float *w0, const float *w1, float *a0, float *a1)
{
    for (int i0 = 0; i0 < n; i0 += VB) {
        block16x s0 = {_mm256_setzero_ps(), _mm256_setzero_ps()}, s1 = s0;
        for (int t = 0; t <= 2 * r; t++) {
            bx_madd(&s0, w0[t], plane + off[t] + x0 + i0);
            bx_madd(&s1, w1[t], plane + off[t] + x0 + i0);
        }
        bx_store(a0 + i0, &s0, VB);
        bx_store(a1 + i0, &s1, VB);
    }
}
#endif

/* The colour difference of one pixel from filtered YCxCz (FLIP.h
 * computeColorDifference, after the y pass). Branch-free arithmetic, so that the row
 * loops below vectorise. */
static inline MCP_ALWAYS_INLINE float
color_difference(float yr, float cxr, float czr, float yt, float cxt, float czt,
                 float cmax, float pccmax)
{
    float xyz[3], rgb[3], lab_r[3], lab_t[3];
    ycxcz_to_xyz(yr, cxr, czr, xyz);
    xyz_to_rgb(xyz, rgb);
    rgb_to_xyz(clamp01(rgb[0]), clamp01(rgb[1]), clamp01(rgb[2]), xyz);
    xyz_to_lab_hunt(xyz, lab_r, 1);
    ycxcz_to_xyz(yt, cxt, czt, xyz);
    xyz_to_rgb(xyz, rgb);
    rgb_to_xyz(clamp01(rgb[0]), clamp01(rgb[1]), clamp01(rgb[2]), xyz);
    xyz_to_lab_hunt(xyz, lab_t, 1);
    float e = mcp__powf_pos(hyab(lab_r, lab_t), MCP_FLIP_QC);
    if (e < pccmax)
        e *= MCP_FLIP_PT / pccmax;
    else
        e = MCP_FLIP_PT + ((e - pccmax) / (cmax - pccmax)) * (1.0f - MCP_FLIP_PT);
    return e;
}

/* The per-pixel ends of the two y passes, over one tile row of nx pixels, from the
 * eight filtered planes in a (reference then test). Their loops vectorise (no calls:
 * fastpow.h instead of powf; sqrtf one instruction and compares masks because this
 * file is built with -fno-math-errno and -fno-trapping-math, CMakeLists.txt); the
 * same C is compiled for SSE2 and for AVX2, without FMA, so both give the same bits. */
static inline MCP_ALWAYS_INLINE void
color_row_body(float *const *a, int nx, float cmax, float pccmax, float *m)
{
#pragma omp simd
    for (int i = 0; i < nx; i++) {
        float yr = a[0][i], cxr = a[1][i], czr = a[2][i] + a[3][i];
        float yt = a[4][i], cxt = a[5][i], czt = a[6][i] + a[7][i];
        /* Equal filtered colours (black or saturated areas) give HyAB 0 and so an
         * error of exactly 0 (mcp__powf_pos(0, qc) is 0: no special case needed). */
        m[i] = color_difference(yr, cxr, czr, yt, cxt, czt, cmax, pccmax);
    }
}

static inline MCP_ALWAYS_INLINE void
feature_row_body(float *const *a, int nx, float *m)
{
    const float norm = 1.0f / sqrtf(2.0f);
#pragma omp simd
    for (int i = 0; i < nx; i++) {
        float dxr = a[0][i], ddxr = a[1][i], dyr = a[2][i], ddyr = a[3][i];
        float dxt = a[4][i], ddxt = a[5][i], dyt = a[6][i], ddyt = a[7][i];
        float edge_r = sqrtf(dxr * dxr + dyr * dyr);
        float edge_t = sqrtf(dxt * dxt + dyt * dyt);
        float point_r = sqrtf(ddxr * ddxr + ddyr * ddyr);
        float point_t = sqrtf(ddxt * ddxt + ddyt * ddyt);
        float edge_diff = fabsf(edge_r - edge_t);
        float point_diff = fabsf(point_r - point_t);
        /* FLIP raises to qf = 0.5 with powf; sqrtf is the same function, exactly
         * rounded. */
        float fd = sqrtf(norm * (edge_diff > point_diff ? edge_diff : point_diff));
        /* 0^(1 - fd) is 0, 1 or +Inf as with powf */
        m[i] = mcp__powf_pos(m[i], 1.0f - fd);
    }
}

static void
color_row(float *const *a, int nx, float cmax, float pccmax, float *m)
{
    color_row_body(a, nx, cmax, pccmax, m);
}

static void
feature_row(float *const *a, int nx, float *m)
{
    feature_row_body(a, nx, m);
}

#ifdef FLIP_AVX2
static AVX2 void
color_row_avx2(float *const *a, int nx, float cmax, float pccmax, float *m)
{
    color_row_body(a, nx, cmax, pccmax, m);
}

static AVX2 void
feature_row_avx2(float *const *a, int nx, float *m)
{
    feature_row_body(a, nx, m);
}
#endif

/* The filter set in use (the AVX2 one where the CPU has it, unless MCPOST_NO_AVX2 is
 * set in the environment, which the tests use to compare the two). */
typedef struct {
    void (*x1)(const float *, int, int, const float *, float *);
    void (*x2)(const float *, int, int, const float *, const float *, float *, float *);
    void (*x3)(const float *, int, int, const float *, const float *, const float *,
               float *, float *, float *);
    void (*y1)(const float *, const size_t *, int, int, int, const float *, float *);
    void (*y2)(const float *, const size_t *, int, int, int, const float *, const float *,
               float *, float *);
    void (*color_row)(float *const *, int, float, float, float *);
    void (*feature_row)(float *const *, int, float *);
} filter_set;

static const filter_set filters_sse = {filter_x1, filter_x2, filter_x3,  filter_y1,
                                       filter_y2, color_row, feature_row};
#ifdef FLIP_AVX2
static const filter_set filters_avx2 = {filter_x1_avx2,  filter_x2_avx2, filter_x3_avx2,
                                        filter_y1_avx2,  filter_y2_avx2, color_row_avx2,
                                        feature_row_avx2};
#endif

static const filter_set *
choose_filters(void)
{
#ifdef FLIP_AVX2
    const char *off = getenv("MCPOST_NO_AVX2");
    if (!(off && *off && strcmp(off, "0")) && __builtin_cpu_supports("avx2"))
        return &filters_avx2;
#endif
    return &filters_sse;
}

/* The y passes run over tiles TILE_W pixels wide and TILE_H rows high: the 2r + 1
 * rows of the 8 planes that one output row needs then stay in the L2 cache for the
 * next row. The tiling changes no arithmetic. */
#define TILE_W 256
#define TILE_H 32

/* Colour y pass over one tile, and the colour difference into map. */
static void
color_tile(const flip_work *k, const mcp_flip_filters *f, const filter_set *fs, int x0,
           int nx, int y0, int y1, float *acc, size_t *off, float *map)
{
    const int w = k->w, h = k->h, rs = f->spatial_radius;
    const float cmax = mcp_flip_cmax(), pccmax = MCP_FLIP_PC * cmax;
    float *a[8];
    for (int i = 0; i < 8; i++)
        a[i] = acc + (size_t)i * TILE_W;
    for (int y = y0; y < y1; y++) {
        row_offsets(y, w, h, rs, off);
        for (int s = 0; s < 2; s++) {
            fs->y1(k->xy[s], off, x0, nx, rs, f->y, a[4 * s + 0]);
            fs->y1(k->xcx[s], off, x0, nx, rs, f->cx, a[4 * s + 1]);
            fs->y1(k->xcz1[s], off, x0, nx, rs, f->cz1, a[4 * s + 2]);
            fs->y1(k->xcz2[s], off, x0, nx, rs, f->cz2, a[4 * s + 3]);
        }
        fs->color_row(a, nx, cmax, pccmax, map + (size_t)y * w + x0);
    }
}

/* Feature y pass over one tile, the feature difference, and the final error in map. */
static void
feature_tile(const flip_work *k, const mcp_flip_filters *f, const filter_set *fs, int x0,
             int nx, int y0, int y1, float *acc, size_t *off, float *map)
{
    const int w = k->w, h = k->h, rf = f->feature_radius;
    float *a[8];
    for (int i = 0; i < 8; i++)
        a[i] = acc + (size_t)i * TILE_W;
    for (int y = y0; y < y1; y++) {
        row_offsets(y, w, h, rf, off);
        for (int s = 0; s < 2; s++) {
            fs->y1(k->xy[s], off, x0, nx, rf, f->g, a[4 * s + 0]);  /* dx */
            fs->y1(k->xcx[s], off, x0, nx, rf, f->g, a[4 * s + 1]); /* ddx */
            fs->y2(k->xcz1[s], off, x0, nx, rf, f->dg, f->ddg, a[4 * s + 2],
                   a[4 * s + 3]); /* dy, ddy */
        }
        fs->feature_row(a, nx, map + (size_t)y * w + x0);
    }
}

/* LDR-FLIP of the planes in k into map (w*h). Returns -1 (no message) when a
 * worker could not allocate; the caller reports. */
static int
flip_planes(flip_work *k, const mcp_flip_filters *f, float *map)
{
    const int w = k->w, h = k->h, rs = f->spatial_radius, rf = f->feature_radius;
    const int rmax = rs > rf ? rs : rf;
    const int tiles_x = (w + TILE_W - 1) / TILE_W, tiles_y = (h + TILE_H - 1) / TILE_H;
    const int n_tiles = tiles_x * tiles_y;
    int failed = 0;
    const int par = (size_t)w * h >= PARALLEL_MIN_PIXELS;
    const filter_set *fs = choose_filters();

#pragma omp parallel if (par)
    {
        float *pad = mcp_malloc(((size_t)w + 2 * (size_t)rmax + VB) * sizeof(float));
        float *acc = mcp_malloc(8 * TILE_W * sizeof(float));
        size_t *off = mcp_malloc((2 * (size_t)rmax + 1) * sizeof(size_t));
        if (!pad || !acc || !off) {
#pragma omp atomic
            failed++;
        }
        const int ok = pad && acc && off;

        /* Colour, x pass: Y and Cx with their own taps; Cz with both halves. */
#pragma omp for schedule(static)
        for (int y = 0; y < h; y++) {
            if (!ok) continue;
            size_t o = (size_t)y * w;
            for (int s = 0; s < 2; s++) {
                pad_row(k->Y[s] + o, w, rs, pad);
                fs->x1(pad, w, rs, f->y, k->xy[s] + o);
                pad_row(k->Cx[s] + o, w, rs, pad);
                fs->x1(pad, w, rs, f->cx, k->xcx[s] + o);
                pad_row(k->Cz[s] + o, w, rs, pad);
                fs->x2(pad, w, rs, f->cz1, f->cz2, k->xcz1[s] + o, k->xcz2[s] + o);
            }
        }
        /* Colour, y pass and difference. */
#pragma omp for schedule(dynamic)
        for (int t = 0; t < n_tiles; t++) {
            int x0 = (t % tiles_x) * TILE_W, y0 = (t / tiles_x) * TILE_H;
            if (ok)
                color_tile(k, f, fs, x0, w - x0 < TILE_W ? w - x0 : TILE_W, y0,
                           h - y0 < TILE_H ? h : y0 + TILE_H, acc, off, map);
        }
        /* Features, x pass on the unfiltered normalised Y: dx, ddx and Gaussian,
         * into xy, xcx and xcz1 (the colour intermediates are no longer needed). */
#pragma omp for schedule(static)
        for (int y = 0; y < h; y++) {
            if (!ok) continue;
            size_t o = (size_t)y * w;
            for (int s = 0; s < 2; s++) {
                pad_row(k->Yn[s] + o, w, rf, pad);
                fs->x3(pad, w, rf, f->dg, f->ddg, f->g, k->xy[s] + o, k->xcx[s] + o,
                       k->xcz1[s] + o);
            }
        }
        /* Features, y pass, feature difference and the final error. */
#pragma omp for schedule(dynamic)
        for (int t = 0; t < n_tiles; t++) {
            int x0 = (t % tiles_x) * TILE_W, y0 = (t / tiles_x) * TILE_H;
            if (ok)
                feature_tile(k, f, fs, x0, w - x0 < TILE_W ? w - x0 : TILE_W, y0,
                             h - y0 < TILE_H ? h : y0 + TILE_H, acc, off, map);
        }
        free(off);
        free(acc);
        free(pad);
    }
    return failed ? -1 : 0;
}

/* FLIP's pooled mean: a float running sum in row-major order, divided by the count
 * converted to float (FLIP pooling.h getMean). */
static double
float_mean(const float *map, size_t n)
{
    float sum = 0.0f;
    for (size_t i = 0; i < n; i++)
        sum += map[i];
    return (double)(sum / (float)n);
}

static int
new_map(int w, int h, const char *name, mcp_image **out)
{
    return mcp_image_new(w, h, 1, (const char *const[]){name}, out);
}

/* ---- LDR-FLIP ---- */

int
mcp_flip_ldr(const mcp_image *test, const mcp_image *ref, const mcp_flip_options *opt,
             mcp_flip_result *res, mcp_image **map)
{
    if (map) *map = NULL;
    int rgb_t[3], rgb_r[3], rc = -1;
    float ppd;
    mcp_flip_filters *f = NULL;
    flip_work k = {0};
    mcp_image *m = NULL;
    float *out = NULL;
    if (mcp_flip_ppd(opt, &ppd) || check_pair(test, ref, rgb_t, rgb_r) ||
        mcp_flip_filters_new(ppd, &f))
        return -1;
    int w = ref->width, h = ref->height;
    if (work_new(&k, w, h) || new_map(w, h, "FLIP", &m)) goto done;
    out = m->data;
    /* FLIP::evaluate, LDR branch: clamp both to [0, 1] in linear RGB. */
#pragma omp parallel for if ((size_t)w * h >= PARALLEL_MIN_PIXELS)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *pr = mcp_image_px(ref, x, y), *pt = mcp_image_px(test, x, y);
            size_t i = (size_t)y * w + x;
            put_ycxcz(&k, REF, i, clamp01(pr[rgb_r[0]]), clamp01(pr[rgb_r[1]]),
                      clamp01(pr[rgb_r[2]]));
            put_ycxcz(&k, TEST, i, clamp01(pt[rgb_t[0]]), clamp01(pt[rgb_t[1]]),
                      clamp01(pt[rgb_t[2]]));
        }
    if (flip_planes(&k, f, out)) {
        mcp_error("flip: out of memory for row buffers (%dx%d)", w, h);
        goto done;
    }
    if (res) {
        memset(res, 0, sizeof *res);
        res->mean = float_mean(out, (size_t)w * h);
        res->ppd = ppd;
        if (mcp_flip_statistics(out, (size_t)w * h, &res->stats)) goto done;
    }
    if (map) {
        *map = m;
        m = NULL;
    }
    rc = 0;
done:
    mcp_image_free(m);
    work_free(&k);
    mcp_flip_filters_free(f);
    return rc;
}

/* ---- HDR-FLIP ---- */

int
mcp_flip_exposure_xmax(mcp_tonemap tm, float *xmax)
{
    float k[6];
    if (mcp_tonemap_flip_coefficients(tm, k)) return -1;
    /* FLIP.h computeExposures and solveSecondDegree: the larger root of
     * (k0 - t k3) x^2 + (k1 - t k4) x + (k2 - t k5) = 0. */
    const float t = MCP_FLIP_EXPOSURE_T;
    float a = k[0] - t * k[3], b = k[1] - t * k[4], c = k[2] - t * k[5];
    if (a == 0.0f) {
        *xmax = -c / b;
        return 0;
    }
    float d1 = -0.5f * (b / a);
    float d2 = sqrtf((d1 * d1) - (c / a));
    *xmax = d1 + d2;
    return 0;
}

/* The k-th smallest of v[0..n) (the value std::nth_element leaves at k), by
 * quickselect with a three-way partition (reference images are often mostly black,
 * so many values are equal). v is reordered; it holds no NaN. */
static float
select_kth(float *v, size_t n, size_t k)
{
    size_t lo = 0, hi = n;
    while (hi - lo > 1) {
        float a = v[lo], b = v[lo + (hi - lo) / 2], c = v[hi - 1];
        float pivot =
            a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        size_t lt = lo, i = lo, gt = hi;
        while (i < gt) {
            float t = v[i];
            if (t < pivot) {
                v[i++] = v[lt];
                v[lt++] = t;
            } else if (t > pivot) {
                v[i] = v[--gt];
                v[gt] = t;
            } else {
                i++;
            }
        }
        if (k < lt)
            hi = lt;
        else if (k >= gt)
            lo = gt;
        else
            return pivot;
    }
    return v[k];
}

/* The luminance statistics of max(ref, 0) (the negative clamp is our departure). */
static int
auto_exposures(const mcp_image *ref, const int rgb[3], mcp_tonemap tm, float *start,
               float *stop)
{
    float xmax;
    if (mcp_flip_exposure_xmax(tm, &xmax)) return -1;
    size_t n = (size_t)ref->width * ref->height;
    float *lum = mcp_malloc(n * sizeof *lum), ymax = -1e30f;
    if (!lum) return -1;
    for (int y = 0; y < ref->height; y++)
        for (int x = 0; x < ref->width; x++) {
            const float *p = mcp_image_px(ref, x, y);
            float r = fmaxf(p[rgb[0]], 0.0f), g = fmaxf(p[rgb[1]], 0.0f),
                  b = fmaxf(p[rgb[2]], 0.0f);
            float l = mcp_luminance(r, g, b);
            lum[(size_t)y * ref->width + x] = l;
            ymax = l > ymax ? l : ymax;
        }
    float ymedian = select_kth(lum, n, n / 2);
    free(lum);
    /* Departure from v1.6 (docs/flip.md §5): a zero median would make stop infinite and
     * the result silently 0; clamp it (and a zero maximum) to FLT_EPSILON, as v1.7. */
    ymedian = ymedian > FLT_EPSILON ? ymedian : FLT_EPSILON;
    ymax = ymax > FLT_EPSILON ? ymax : FLT_EPSILON;
    *start = log2f(xmax / ymax);
    *stop = log2f(xmax / ymedian);
    return 0;
}

int
mcp_flip_auto_exposures(const mcp_image *ref, mcp_tonemap tm, float *start, float *stop)
{
    int rgb[3];
    if (mcp_rgb_channels(ref, rgb)) return -1;
    if (ref->width < 1 || ref->height < 1)
        return mcp_error("%s: empty image", src_name(ref));
    return auto_exposures(ref, rgb, tm, start, stop);
}

/* Exposes, tone-maps and clamps n pixels given as planes of max(value, 0) (FLIP.h
 * expose, toneMap, clamp; the clamp of negatives to 0 is our departure, done when
 * the planes were filled), then converts them to YCxCz like put_ycxcz. A plain loop
 * over pixels, so that it vectorises. */
typedef int vi4 __attribute__((vector_size(16)));

/* clamp01 on four lanes, with the same results (NaN and -0 give 0). */
static inline vf4
vclamp01(vf4 v)
{
    const vf4 zero = {0, 0, 0, 0}, one = {1, 1, 1, 1};
    vi4 pos = v > zero;
    v = (vf4)((vi4)v & pos);
    vi4 low = v < one;
    return (vf4)(((vi4)v & low) | ((vi4)one & ~low));
}

static inline vf4
vtone_rational(vf4 c, const float *k)
{
    return vclamp01((c * c * k[0] + c * k[1] + k[2]) / (c * c * k[3] + c * k[4] + k[5]));
}

/* Tone-mapped linear RGB (4 lanes) to the YCxCz and normalised-Y planes at i, with
 * rgb_to_xyz and xyz_to_ycxcz's operations in their order. */
static inline void
vput_ycxcz(vf4 r, vf4 g, vf4 b, float *Y, float *Cx, float *Cz, float *Yn, size_t i)
{
    const float a11 = 10135552.0f / 24577794.0f, a12 = 8788810.0f / 24577794.0f,
                a13 = 4435075.0f / 24577794.0f;
    const float a21 = 2613072.0f / 12288897.0f, a22 = 8788810.0f / 12288897.0f,
                a23 = 887015.0f / 12288897.0f;
    const float a31 = 1425312.0f / 73733382.0f, a32 = 8788810.0f / 73733382.0f,
                a33 = 70074185.0f / 73733382.0f;
    const float one_over_116 = 1.0f / 116.0f, sixteen_over_116 = 16.0f / 116.0f;
    vf4 x = (a11 * r + a12 * g + a13 * b) * INV_WHITE[0];
    vf4 y = (a21 * r + a22 * g + a23 * b) * INV_WHITE[1];
    vf4 z = (a31 * r + a32 * g + a33 * b) * INV_WHITE[2];
    vf4 yc = 116.0f * y - 16.0f, cx = 500.0f * (x - y), cz = 200.0f * (y - z);
    vf4 yn = yc * one_over_116 + sixteen_over_116;
    memcpy(Y + i, &yc, sizeof yc);
    memcpy(Cx + i, &cx, sizeof cx);
    memcpy(Cz + i, &cz, sizeof cz);
    memcpy(Yn + i, &yn, sizeof yn);
}

static void
tone_row(const float *r, const float *g, const float *b, size_t n, float m, int reinhard,
         const float *k, float *Y, float *Cx, float *Cz, float *Yn)
{
    const float one_over_116 = 1.0f / 116.0f, sixteen_over_116 = 16.0f / 116.0f;
    size_t i = 0;
    for (; i + 4 <= n; i += 4) {
        vf4 cr = load4(r + i) * m, cg = load4(g + i) * m, cb = load4(b + i) * m;
        if (reinhard) {
            vf4 l = 0.2126f * cr + 0.7152f * cg + 0.0722f * cb;
            vf4 factor = 1.0f / (1.0f + l);
            vput_ycxcz(vclamp01(cr * factor), vclamp01(cg * factor),
                       vclamp01(cb * factor), Y, Cx, Cz, Yn, i);
        } else {
            vput_ycxcz(vtone_rational(cr, k), vtone_rational(cg, k),
                       vtone_rational(cb, k), Y, Cx, Cz, Yn, i);
        }
    }
    for (; i < n; i++) { /* the last pixels of the row, one by one, same arithmetic */
        float c[3] = {r[i] * m, g[i] * m, b[i] * m}, o[3], xyz[3], ycc[3];
        float factor = 1.0f / (1.0f + mcp_luminance(c[0], c[1], c[2]));
        for (int j = 0; j < 3; j++)
            o[j] = reinhard ? clamp01(c[j] * factor)
                            : clamp01((c[j] * c[j] * k[0] + c[j] * k[1] + k[2]) /
                                      (c[j] * c[j] * k[3] + c[j] * k[4] + k[5]));
        rgb_to_xyz(o[0], o[1], o[2], xyz);
        xyz_to_ycxcz(xyz, ycc);
        Y[i] = ycc[0];
        Cx[i] = ycc[1];
        Cz[i] = ycc[2];
        Yn[i] = ycc[0] * one_over_116 + sixteen_over_116;
    }
}

int
mcp_flip_hdr(const mcp_image *test, const mcp_image *ref, const mcp_flip_options *opt,
             mcp_flip_result *res, mcp_image **map, mcp_image **exposure_map)
{
    if (map) *map = NULL;
    if (exposure_map) *exposure_map = NULL;
    mcp_flip_options d = mcp_flip_defaults();
    if (!opt) opt = &d;
    int rgb_t[3], rgb_r[3], rc = -1;
    float ppd, k[6];
    if (mcp_flip_ppd(opt, &ppd) || mcp_tonemap_flip_coefficients(opt->tone_mapper, k))
        return -1;
    if (opt->num_exposures != 0 && opt->num_exposures < 2)
        return mcp_error("flip: num_exposures must be >= 2 (got %d)", opt->num_exposures);
    if (opt->num_exposures > 1000)
        return mcp_error("flip: num_exposures must be <= 1000 (got %d)",
                         opt->num_exposures);
    if (!isnan(opt->start_exposure) && !isfinite(opt->start_exposure))
        return mcp_error("flip: start_exposure must be finite (got %g)",
                         opt->start_exposure);
    if (!isnan(opt->stop_exposure) && !isfinite(opt->stop_exposure))
        return mcp_error("flip: stop_exposure must be finite (got %g)",
                         opt->stop_exposure);
    if (check_pair(test, ref, rgb_t, rgb_r)) return -1;

    float start = (float)opt->start_exposure, stop = (float)opt->stop_exposure;
    if (isnan(start) || isnan(stop)) {
        float s0, s1;
        if (auto_exposures(ref, rgb_r, opt->tone_mapper, &s0, &s1)) return -1;
        start = isnan(start) ? s0 : start;
        stop = isnan(stop) ? s1 : stop;
    }
    if (start > stop)
        return mcp_error("flip: start_exposure %g is above stop_exposure %g",
                         (double)start, (double)stop);
    int n_exp = opt->num_exposures;
    if (n_exp == 0) {
        float span = ceilf(stop - start);
        if (span > 1000.0f)
            return mcp_error(
                "flip: exposures %g to %g would need %g steps (more than 1000)",
                (double)start, (double)stop, (double)span);
        n_exp = (int)(2.0f > span ? 2.0f : span);
    }

    int w = ref->width, h = ref->height;
    mcp_flip_filters *f = NULL;
    flip_work wk = {0};
    mcp_image *m = NULL, *e = NULL;
    float *tmp = NULL, *rgbp = NULL;
    size_t n = (size_t)w * h;
    if (mcp_flip_filters_new(ppd, &f) || work_new(&wk, w, h) ||
        new_map(w, h, "FLIP", &m) || new_map(w, h, "exposure", &e) ||
        !(tmp = mcp_malloc(n * sizeof *tmp)) ||
        !(rgbp = mcp_malloc(6 * n * sizeof *rgbp)))
        goto done;
    const int reinhard = opt->tone_mapper == MCP_TONEMAP_REINHARD;
    const int par = n >= PARALLEL_MIN_PIXELS;
    const float step = (stop - start) / (float)(n_exp - 1);
    /* max(input, 0) as planes (R, G, B of the reference, then of the test), packed
     * once for all exposures. */
    const mcp_image *src[2] = {ref, test};
    const int *idx[2] = {rgb_r, rgb_t};
#pragma omp parallel for if (par)
    for (int y = 0; y < h; y++)
        for (int s = 0; s < 2; s++)
            for (int x = 0; x < w; x++) {
                const float *p = mcp_image_px(src[s], x, y);
                for (int c = 0; c < 3; c++) {
                    float v = p[idx[s][c]];
                    rgbp[(size_t)(3 * s + c) * n + (size_t)y * w + x] =
                        v > 0.0f ? v : 0.0f;
                }
            }
    for (int i = 0; i < n_exp; i++) {
        const float exposure = start + (float)i * step;
        const float mult = powf(2.0f, exposure);
#pragma omp parallel for if (par)
        for (int y = 0; y < h; y++)
            for (int s = 0; s < 2; s++) {
                size_t o = (size_t)y * w;
                const float *pr = rgbp + (size_t)(3 * s) * n + o;
                tone_row(pr, pr + n, pr + 2 * n, (size_t)w, mult, reinhard, k,
                         wk.Y[s] + o, wk.Cx[s] + o, wk.Cz[s] + o, wk.Yn[s] + o);
            }
        if (flip_planes(&wk, f, tmp)) {
            mcp_error("flip: out of memory for row buffers (%dx%d)", w, h);
            goto done;
        }
        /* FLIP.h setMaxExposure: keep strictly greater values. */
        const float level = (float)i / (float)(n_exp - 1);
#pragma omp parallel for if (par)
        for (size_t j = 0; j < n; j++)
            if (tmp[j] > m->data[j]) {
                m->data[j] = tmp[j];
                e->data[j] = level;
            }
    }
    if (res) {
        memset(res, 0, sizeof *res);
        res->mean = float_mean(m->data, n);
        res->ppd = ppd;
        res->start_exposure = start;
        res->stop_exposure = stop;
        res->num_exposures = n_exp;
        if (mcp_flip_statistics(m->data, n, &res->stats)) goto done;
    }
    if (map) {
        *map = m;
        m = NULL;
    }
    if (exposure_map) {
        *exposure_map = e;
        e = NULL;
    }
    rc = 0;
done:
    free(rgbp);
    free(tmp);
    mcp_image_free(e);
    mcp_image_free(m);
    work_free(&wk);
    mcp_flip_filters_free(f);
    return rc;
}
