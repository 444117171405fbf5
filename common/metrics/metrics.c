/* metrics.c: MSE, RMSE, relMSE, PSNR, pMSE, RelSE percentiles and both FLIPs of a
 * test image against a reference (docs/mathematics.md §5, §4.3,
 * §2.9; definitions in metrics.h). */
#define _POSIX_C_SOURCE 200809L /* mkdir */
#include <mcpost/metrics.h>

#include "fastpow.h"
#include "internal.h"
#include "../core/internal.h"
#include "../report/internal.h" /* maps of one value */
#include <mcpost/filter.h>
#include <mcpost/imageio.h>
#include <mcpost/report.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define PARALLEL_MIN_PIXELS 16384

static const char *
src_name(const mcp_image *img)
{
    return img->source ? img->source : "image";
}

/* ---- options ---- */

mcp_pmse_options
mcp_pmse_defaults(void)
{
    return (mcp_pmse_options){.kernel = mcp_pkernel_defaults(),
                              .filter_reference = 0,
                              .tone_map = MCP_TONEMAP_CLAMP};
}

mcp_metrics_options
mcp_metrics_defaults(void)
{
    mcp_metrics_options o;
    memset(&o, 0, sizeof o);
    o.eps_rel = MCP_EPS_REL;
    o.n_percentiles = 3;
    o.percentiles[0] = 0.5;
    o.percentiles[1] = 0.9;
    o.percentiles[2] = 0.99;
    o.pmse = mcp_pmse_defaults();
    o.flip = mcp_flip_defaults();
    o.flip_ldr = 1;
    o.flip_hdr = 1;
    o.spectra = 1;
    o.spectra_opt = mcp_spectra_defaults();
    return o;
}

int
mcp_metrics_set_percentiles(mcp_metrics_options *opt, const double *p, int n_p)
{
    if (n_p < 1 || n_p > MCP_METRICS_MAX_PERCENTILES)
        return mcp_error("percentiles: give 1 to %d values (got %d)",
                         MCP_METRICS_MAX_PERCENTILES, n_p);
    for (int i = 0; i < n_p; i++)
        if (!(p[i] >= 0.0 && p[i] <= 1.0))
            return mcp_error("percentiles: each p must be in [0, 1] (got %g)", p[i]);
    opt->n_percentiles = n_p;
    memcpy(opt->percentiles, p, (size_t)n_p * sizeof *p);
    return 0;
}

const char *
mcp_above_map_name(mcp_above_map m)
{
    return m == MCP_ABOVE_FLIP_LDR   ? "flip_ldr"
           : m == MCP_ABOVE_FLIP_HDR ? "flip_hdr"
                                     : "relse";
}

int
mcp_above_map_from_name(const char *name, mcp_above_map *out)
{
    for (int m = MCP_ABOVE_FLIP_LDR; m <= MCP_ABOVE_RELSE; m++)
        if (!strcmp(name, mcp_above_map_name((mcp_above_map)m))) {
            *out = (mcp_above_map)m;
            return 0;
        }
    return mcp_error("unknown per-pixel map '%s' (use flip_ldr, flip_hdr or relse)",
                     name);
}

int
mcp_metrics_add_above(mcp_metrics_options *opt, mcp_above_map map, double threshold)
{
    if (!isfinite(threshold))
        return mcp_error("%s: the threshold must be finite", mcp_above_map_name(map));
    for (int k = 0; k < opt->n_above; k++)
        if (opt->above[k].map == map && opt->above[k].threshold == threshold) return 0;
    if (opt->n_above >= MCP_METRICS_MAX_ABOVE)
        return mcp_error("at most %d per-pixel thresholds", MCP_METRICS_MAX_ABOVE);
    opt->above[opt->n_above++] = (mcp_metrics_above){map, threshold};
    return 0;
}

/* The percentage of pixels of a map above t: FLIP maps have one channel; RelSE has
 * three and a pixel counts when any of them is above (idiff's per-pixel rule). */
static double
percent_above(const mcp_image *img, double t)
{
    size_t n = (size_t)img->width * img->height, above = 0;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++) {
            const float *px = mcp_image_px(img, x, y);
            int hit = 0;
            for (int c = 0; c < img->channels; c++)
                hit |= px[c] > t;
            above += (size_t)hit;
        }
    return 100.0 * (double)above / (double)n;
}

int
mcp_image_percent_above(const mcp_image *img, double t, double *percent)
{
    if (!img || img->width < 1 || img->height < 1)
        return mcp_error("percent above: no pixels");
    *percent = percent_above(img, t);
    return 0;
}

/* ---- checks ---- */

int
mcp_metrics_check_pair(const mcp_image *test, const mcp_image *ref, int rgb_test[3],
                       int rgb_ref[3])
{
    if (!test || !ref) return mcp_error("metrics: missing image");
    if (mcp_rgb_channels(test, rgb_test) || mcp_rgb_channels(ref, rgb_ref)) return -1;
    if (!mcp_image_same_size(test, ref)) return -1;
    if (test->width < 1 || test->height < 1)
        return mcp_error("%s: empty image", src_name(test));
    const mcp_image *imgs[2] = {test, ref};
    const int *idx[2] = {rgb_test, rgb_ref};
    for (int i = 0; i < 2; i++)
        for (int y = 0; y < imgs[i]->height; y++)
            for (int x = 0; x < imgs[i]->width; x++) {
                const float *p = mcp_image_px(imgs[i], x, y);
                for (int c = 0; c < 3; c++)
                    if (!isfinite(p[idx[i][c]]))
                        return mcp_error("%s: non-finite value %g at pixel (%d, %d) "
                                         "channel %s",
                                         src_name(imgs[i]), (double)p[idx[i][c]], x, y,
                                         imgs[i]->names[idx[i][c]]);
            }
    return 0;
}

/* ---- sums over pixels x channels ---- */

typedef enum { SUM_SQ, SUM_REL, SUM_SRGB } sum_kind;

/* The display encoding of the display MSE: clamped to [0, 1], then sRGB's curve, its
 * power by fastpow.h (libm's powf was a fifth of a 1080p metrics run; the two are a few
 * float roundings apart, far below the 1/255 steps of what a display shows). */
static inline MCP_ALWAYS_INLINE float
display(float v)
{
    v = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f;
    return v <= 0.0031308f ? 12.92f * v : 1.055f * mcp__powf_pos(v, 1.0f / 2.4f) - 0.055f;
}

/* The display values of row y of the channels idx[0..2] of img, channel after channel
 * (out[c w + x]): a loop that vectorises (metrics.c is built with -fno-trapping-math,
 * CMakeLists.txt), where a call per value did not. On x86-64 GCC also builds an AVX2
 * copy, picked at load time; without contraction (-std=c11) both give the same bits. */
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
__attribute__((target_clones("avx2", "default")))
#endif
static void
display_row(const mcp_image *img, const int *idx, int y, float *out)
{
    const int w = img->width;
    const ptrdiff_t stride = img->pixel_stride;
    for (int c = 0; c < 3; c++) {
        const float *p = mcp_image_px(img, 0, y) + idx[c];
        float *o = out + (size_t)c * w;
#pragma omp simd
        for (int x = 0; x < w; x++)
            o[x] = display(p[x * stride]);
    }
}

/* Mean over pixels x 3 of a per-value error; rows summed in double, then in order. */
static double
mean_error(const mcp_image *t, const int *it, const mcp_image *r, const int *ir,
           sum_kind kind, double eps)
{
    int w = t->width, h = t->height, out_of_memory = 0;
    double *rows = mcp_malloc((size_t)h * sizeof *rows), total = 0.0;
    if (!rows) return NAN;
#pragma omp parallel if ((size_t)w * h >= PARALLEL_MIN_PIXELS)
    {
        /* the row's display values, test then reference */
        float *disp = kind == SUM_SRGB ? mcp_malloc((size_t)w * 6 * sizeof *disp) : NULL;
        if (kind == SUM_SRGB && !disp) {
#pragma omp atomic write
            out_of_memory = 1;
        }
#pragma omp for
        for (int y = 0; y < h; y++) {
            double s = 0.0;
            if (disp) {
                display_row(t, it, y, disp);
                display_row(r, ir, y, disp + (size_t)w * 3);
            }
            for (int x = 0; x < w; x++) {
                const float *pt = mcp_image_px(t, x, y), *pr = mcp_image_px(r, x, y);
                for (int c = 0; c < 3; c++) {
                    double a = pt[it[c]], b = pr[ir[c]], d;
                    if (kind == SUM_SRGB) {
                        if (!disp) continue;
                        d = (double)disp[(size_t)c * w + x] -
                            disp[(size_t)(3 + c) * w + x];
                        s += d * d;
                    } else {
                        d = a - b;
                        s += kind == SUM_REL ? d * d / (b * b + eps) : d * d;
                    }
                }
            }
            rows[y] = s;
        }
        free(disp);
    }
    for (int y = 0; y < h; y++)
        total += rows[y];
    free(rows);
    return out_of_memory ? NAN : total / ((double)w * h * 3.0);
}

static int
mean_checked(const mcp_image *test, const mcp_image *ref, sum_kind kind, double eps,
             double *out)
{
    int it[3], ir[3];
    if (mcp_metrics_check_pair(test, ref, it, ir)) return -1;
    double m = mean_error(test, it, ref, ir, kind, eps);
    if (isnan(m))
        return mcp_error("metrics: out of memory (%dx%d)", test->width, test->height);
    *out = m;
    return 0;
}

int
mcp_mse(const mcp_image *test, const mcp_image *ref, double *mse)
{
    return mean_checked(test, ref, SUM_SQ, 0.0, mse);
}

int
mcp_relmse(const mcp_image *test, const mcp_image *ref, double eps_rel, double *relmse)
{
    if (!(eps_rel > 0.0) || !isfinite(eps_rel))
        return mcp_error("metrics: eps_rel must be > 0 (got %g)", eps_rel);
    return mean_checked(test, ref, SUM_REL, eps_rel, relmse);
}

static double
psnr_of(double mse_display)
{
    return mse_display > 0.0 ? 10.0 * log10(1.0 / mse_display) : INFINITY;
}

int
mcp_psnr(const mcp_image *test, const mcp_image *ref, double *psnr)
{
    /* set: GCC -O3 cannot see that mean_checked() fills m whenever it returns 0 */
    double m = 0.0;
    if (mean_checked(test, ref, SUM_SRGB, 0.0, &m)) return -1;
    *psnr = psnr_of(m);
    return 0;
}

/* ---- pMSE ---- */

/* T applied to the RGB channels, as a packed 3-channel image. */
static int
tone_rgb(const mcp_image *img, const int *idx, mcp_tonemap tm, mcp_image **out)
{
    mcp_image *o = NULL;
    if (mcp_image_new(img->width, img->height, 3, (const char *const[]){"R", "G", "B"},
                      &o))
        return -1;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++) {
            const float *p = mcp_image_px(img, x, y);
            float *q = mcp_image_px(o, x, y);
            for (int c = 0; c < 3; c++)
                q[c] = mcp_tonemap_value(tm, p[idx[c]]);
        }
    *out = o;
    return 0;
}

static int
pmse_checked(const mcp_image *test, const int *it, const mcp_image *ref, const int *ir,
             const mcp_pmse_options *opt, double *out)
{
    mcp_pmse_options d = mcp_pmse_defaults();
    if (!opt) opt = &d;
    if ((unsigned)opt->tone_map > MCP_TONEMAP_REINHARD)
        return mcp_error("pmse: unknown tone map %d", (int)opt->tone_map);
    double *taps = NULL;
    int radius, rc = -1;
    mcp_image *tt = NULL, *tr = NULL, *gt = NULL, *hr = NULL;
    if (mcp_pkernel_taps(&opt->kernel, &taps, &radius)) return -1;
    /* E = sum_c |g * T(O_c) - h * T(I_c)|^2 with replicate borders (docs/mathematics.md
     * §4.3; the borders are our choice, stated there). */
    if (tone_rgb(test, it, opt->tone_map, &tt) || tone_rgb(ref, ir, opt->tone_map, &tr) ||
        mcp_pkernel_filter(tt, taps, radius, &gt))
        goto done;
    if (opt->filter_reference && mcp_pkernel_filter(tr, taps, radius, &hr)) goto done;
    const mcp_image *h_ref = opt->filter_reference ? hr : tr;
    int w = test->width, h = test->height;
    double *rows = mcp_malloc((size_t)h * sizeof *rows), e = 0.0;
    if (!rows) goto done;
#pragma omp parallel for if ((size_t)w * h >= PARALLEL_MIN_PIXELS)
    for (int y = 0; y < h; y++) {
        double s = 0.0;
        const float *a = gt->data + (size_t)y * w * 3,
                    *b = h_ref->data + (size_t)y * w * 3;
        for (int i = 0; i < 3 * w; i++) {
            double dv = (double)a[i] - b[i];
            s += dv * dv;
        }
        rows[y] = s;
    }
    for (int y = 0; y < h; y++)
        e += rows[y];
    free(rows);
    *out = e / ((double)w * h * 3.0);
    rc = 0;
done:
    free(taps);
    mcp_image_free(hr);
    mcp_image_free(gt);
    mcp_image_free(tr);
    mcp_image_free(tt);
    return rc;
}

int
mcp_pmse(const mcp_image *test, const mcp_image *ref, const mcp_pmse_options *opt,
         double *pmse)
{
    int it[3], ir[3];
    if (mcp_metrics_check_pair(test, ref, it, ir)) return -1;
    return pmse_checked(test, it, ref, ir, opt, pmse);
}

/* ---- RelSE ---- */

static int
relse_checked(const mcp_image *test, const int *it, const mcp_image *ref, const int *ir,
              double eps, mcp_image **out)
{
    mcp_image *o = NULL;
    if (mcp_image_new(test->width, test->height, 3, (const char *const[]){"R", "G", "B"},
                      &o))
        return -1;
#pragma omp parallel for if ((size_t)test->width * test->height >= PARALLEL_MIN_PIXELS)
    for (int y = 0; y < test->height; y++)
        for (int x = 0; x < test->width; x++) {
            const float *pt = mcp_image_px(test, x, y), *pr = mcp_image_px(ref, x, y);
            double m = pt[it[0]];
            m = pt[it[1]] > m ? pt[it[1]] : m;
            m = pt[it[2]] > m ? pt[it[2]] : m;
            float *q = mcp_image_px(o, x, y);
            for (int c = 0; c < 3; c++) {
                double d = (double)pt[it[c]] - pr[ir[c]];
                q[c] = (float)(d * d / (m * m + eps));
            }
        }
    if (mcp_image_set_source(o, "RelSE")) {
        mcp_image_free(o);
        return -1;
    }
    *out = o;
    return 0;
}

int
mcp_relse_map(const mcp_image *test, const mcp_image *ref, double eps_rel,
              mcp_image **out)
{
    *out = NULL;
    int it[3], ir[3];
    if (!(eps_rel > 0.0) || !isfinite(eps_rel))
        return mcp_error("metrics: eps_rel must be > 0 (got %g)", eps_rel);
    if (mcp_metrics_check_pair(test, ref, it, ir)) return -1;
    return relse_checked(test, it, ref, ir, eps_rel, out);
}

int
mcp_image_percentiles(const mcp_image *img, const double *p, int n_p, double *out)
{
    size_t n;
    if (mcp_size_mul3((size_t)img->width, (size_t)img->height, (size_t)img->channels,
                      &n) ||
        n == 0)
        return mcp_error("%s: no values for percentiles", src_name(img));
    for (int k = 0; k < n_p; k++)
        if (!(p[k] >= 0.0 && p[k] <= 1.0))
            return mcp_error("percentiles: each p must be in [0, 1] (got %g)", p[k]);
    /* a packed image is selected from in place; a view is copied first */
    int packed = mcp_image_is_packed(img);
    float *copy = NULL;
    const float *v = img->data;
    if (!packed) {
        if (!(copy = mcp_malloc(n * sizeof *copy))) return -1;
        size_t i = 0;
        for (int y = 0; y < img->height; y++)
            for (int x = 0; x < img->width; x++) {
                const float *q = mcp_image_px(img, x, y);
                for (int c = 0; c < img->channels; c++)
                    copy[i++] = q[c];
            }
        v = copy;
    }
    long nan = 0;
#pragma omp parallel for reduction(+ : nan) schedule(static)
    for (size_t i = 0; i < n; i++)
        nan += isnan(v[i]);
    if (nan) {
        free(copy);
        return mcp_error("%s: NaN value among the percentiles' values", src_name(img));
    }
    int rc = mcp__select_percentiles(v, n, p, n_p, out);
    free(copy);
    return rc;
}

/* ---- everything ---- */

/* One pass over the pair for mcp_metrics_compute: the means of SUM_SQ, SUM_REL and
 * SUM_SRGB (each row summed in double, rows in order: the same bits as mean_error gives
 * each alone) and, where given, the RelSE and squared-error maps (relse_checked's and
 * sq_error_map's values). -1 when out of memory. */
static int
fused_pass(const mcp_image *t, const int *it, const mcp_image *r, const int *ir,
           double eps, double mean[3], mcp_image *relse, mcp_image *sq)
{
    int w = t->width, h = t->height, out_of_memory = 0;
    double *rows = mcp_malloc((size_t)h * 3 * sizeof *rows);
    if (!rows) return -1;
#pragma omp parallel if ((size_t)w * h >= PARALLEL_MIN_PIXELS)
    {
        /* the row's display values, test then reference */
        float *disp = mcp_malloc((size_t)w * 6 * sizeof *disp);
        if (!disp) {
#pragma omp atomic write
            out_of_memory = 1;
        }
#pragma omp for
        for (int y = 0; y < h; y++) {
            if (!disp) continue;
            double s_sq = 0.0, s_rel = 0.0, s_disp = 0.0;
            display_row(t, it, y, disp);
            display_row(r, ir, y, disp + (size_t)w * 3);
            for (int x = 0; x < w; x++) {
                const float *pt = mcp_image_px(t, x, y), *pr = mcp_image_px(r, x, y);
                double m = pt[it[0]];
                m = pt[it[1]] > m ? pt[it[1]] : m;
                m = pt[it[2]] > m ? pt[it[2]] : m;
                for (int c = 0; c < 3; c++) {
                    double a = pt[it[c]], b = pr[ir[c]], d = a - b;
                    double dd =
                        (double)disp[(size_t)c * w + x] - disp[(size_t)(3 + c) * w + x];
                    s_sq += d * d;
                    s_rel += d * d / (b * b + eps);
                    s_disp += dd * dd;
                    if (relse)
                        mcp_image_px(relse, x, y)[c] = (float)(d * d / (m * m + eps));
                    if (sq) mcp_image_px(sq, x, y)[c] = (float)(d * d);
                }
            }
            rows[3 * y] = s_sq;
            rows[3 * y + 1] = s_rel;
            rows[3 * y + 2] = s_disp;
        }
        free(disp);
    }
    if (out_of_memory) {
        free(rows);
        return -1;
    }
    for (int k = 0; k < 3; k++) {
        double total = 0.0;
        for (int y = 0; y < h; y++)
            total += rows[3 * y + k];
        mean[k] = total / ((double)w * h * 3.0);
    }
    free(rows);
    return 0;
}

void
mcp_metrics_maps_free(mcp_metrics_maps *maps)
{
    if (!maps) return;
    mcp_image_free(maps->sq_error);
    mcp_image_free(maps->relse);
    mcp_image_free(maps->flip_ldr);
    mcp_image_free(maps->flip_hdr);
    mcp_image_free(maps->flip_hdr_exposure);
    mcp_image_free(maps->spectra);
    memset(maps, 0, sizeof *maps);
}

/* The progress of one comparison, on a terminal, for an image of a megapixel or more
 * (a 4K pair takes 5 to 10 s): a step per figure, weighted by what it costs there
 * (HDR-FLIP: several exposures of LDR-FLIP's work). */
enum { STEP_FUSED = 1, STEP_PMSE = 1, STEP_LDR = 3, STEP_HDR = 8, STEP_SPECTRA = 1 };
typedef struct figures_bar {
    mcp_progress bar;
    int shown;
    long done;
} figures_bar;

static void
figures_bar_begin(figures_bar *b, const mcp_image *test, const mcp_metrics_options *opt)
{
    memset(b, 0, sizeof *b);
    b->shown = (double)test->width * test->height >= 1048576.0 && !mcp_progress_quiet();
    if (!b->shown) return;
    const char *name = src_name(test), *slash = strrchr(name, '/');
    char label[96];
    snprintf(label, sizeof label, "metrics %s", slash ? slash + 1 : name);
    long total = STEP_FUSED + STEP_PMSE + (opt->flip_ldr ? STEP_LDR : 0) +
                 (opt->flip_hdr ? STEP_HDR : 0) + (opt->spectra ? STEP_SPECTRA : 0);
    mcp_progress_begin(&b->bar, label, total);
}

static void
figures_bar_step(figures_bar *b, long weight)
{
    if (b->shown) mcp_progress_update(&b->bar, b->done += weight);
}

static void
figures_bar_end(figures_bar *b, int failed)
{
    if (!b->shown) return;
    if (failed)
        mcp__progress_stop(&b->bar);
    else
        mcp_progress_end(&b->bar);
}

int
mcp_metrics_compute(const mcp_image *test, const mcp_image *ref,
                    const mcp_metrics_options *opt, mcp_metrics *out,
                    mcp_metrics_maps *maps)
{
    mcp_metrics_options d = mcp_metrics_defaults();
    if (!opt) opt = &d;
    if (maps) memset(maps, 0, sizeof *maps);
    memset(out, 0, sizeof *out);
    if (!(opt->eps_rel > 0.0) || !isfinite(opt->eps_rel))
        return mcp_error("metrics: eps_rel must be > 0 (got %g)", opt->eps_rel);
    if (opt->n_percentiles < 0 || opt->n_percentiles > MCP_METRICS_MAX_PERCENTILES)
        return mcp_error("metrics: n_percentiles must be in [0, %d] (got %d)",
                         MCP_METRICS_MAX_PERCENTILES, opt->n_percentiles);
    for (int k = 0; k < opt->n_percentiles; k++)
        if (!(opt->percentiles[k] >= 0.0 && opt->percentiles[k] <= 1.0))
            return mcp_error("percentiles: each p must be in [0, 1] (got %g)",
                             opt->percentiles[k]);
    int it[3], ir[3];
    if (mcp_metrics_check_pair(test, ref, it, ir)) return -1;
    mcp_image *relse = NULL, *sq = NULL;
    const char *const rgb[] = {"R", "G", "B"};
    int rc = -1, w = test->width, h = test->height;
    out->n_values = (long)w * h * 3;
    /* MSE, relMSE, the display MSE and the maps in one pass */
    int want_relse = maps || opt->n_percentiles, above_ldr = 0, above_hdr = 0;
    for (int k = 0; k < opt->n_above; k++) {
        mcp_above_map am = opt->above[k].map;
        want_relse |= am == MCP_ABOVE_RELSE;
        above_ldr |= am == MCP_ABOVE_FLIP_LDR;
        above_hdr |= am == MCP_ABOVE_FLIP_HDR;
        if ((am == MCP_ABOVE_FLIP_LDR && !opt->flip_ldr) ||
            (am == MCP_ABOVE_FLIP_HDR && !opt->flip_hdr))
            return mcp_error("metrics: pixels above %g in %s asked for, but %s is not "
                             "computed",
                             opt->above[k].threshold, mcp_above_map_name(am),
                             am == MCP_ABOVE_FLIP_LDR ? "LDR-FLIP" : "HDR-FLIP");
    }
    if (opt->n_above < 0 || opt->n_above > MCP_METRICS_MAX_ABOVE)
        return mcp_error("metrics: n_above must be in [0, %d] (got %d)",
                         MCP_METRICS_MAX_ABOVE, opt->n_above);
    /* FLIP maps kept here when the caller wants no maps but a share above a threshold */
    mcp_image *own_ldr = NULL, *own_hdr = NULL;
    figures_bar bar;
    figures_bar_begin(&bar, test, opt);
    if ((want_relse && mcp_image_new(w, h, 3, rgb, &relse)) ||
        (maps && mcp_image_new(w, h, 3, rgb, &sq)))
        goto done;
    double mean[3];
    if (fused_pass(test, it, ref, ir, opt->eps_rel, mean, relse, sq)) {
        mcp_error("metrics: out of memory (%dx%d)", w, h);
        goto done;
    }
    if ((relse && mcp_image_set_source(relse, "RelSE")) ||
        (sq && mcp_image_set_source(sq, "squared error")))
        goto done;
    out->mse = mean[0];
    out->relmse = mean[1];
    out->rmse = sqrt(out->mse);
    out->psnr = psnr_of(mean[2]);
    figures_bar_step(&bar, STEP_FUSED);
    if (pmse_checked(test, it, ref, ir, &opt->pmse, &out->pmse)) goto done;
    figures_bar_step(&bar, STEP_PMSE);
    out->n_percentiles = opt->n_percentiles;
    memcpy(out->percentiles, opt->percentiles, sizeof opt->percentiles);
    if (opt->n_percentiles &&
        mcp_image_percentiles(relse, opt->percentiles, opt->n_percentiles, out->relse))
        goto done;
    if (opt->flip_ldr) {
        if (mcp_flip_ldr(test, ref, &opt->flip, &out->flip_ldr,
                         maps        ? &maps->flip_ldr
                         : above_ldr ? &own_ldr
                                     : NULL))
            goto done;
        out->has_flip_ldr = 1;
        figures_bar_step(&bar, STEP_LDR);
    }
    if (opt->flip_hdr) {
        if (mcp_flip_hdr(test, ref, &opt->flip, &out->flip_hdr,
                         maps        ? &maps->flip_hdr
                         : above_hdr ? &own_hdr
                                     : NULL,
                         maps ? &maps->flip_hdr_exposure : NULL))
            goto done;
        out->has_flip_hdr = 1;
        figures_bar_step(&bar, STEP_HDR);
    }
    out->n_above = opt->n_above;
    for (int k = 0; k < opt->n_above; k++) {
        const mcp_metrics_above *a = &opt->above[k];
        const mcp_image *img = a->map == MCP_ABOVE_RELSE ? relse
                               : a->map == MCP_ABOVE_FLIP_LDR
                                   ? (maps ? maps->flip_ldr : own_ldr)
                                   : (maps ? maps->flip_hdr : own_hdr);
        out->above[k] = *a;
        out->above_percent[k] = percent_above(img, a->threshold);
    }
    if (opt->spectra && test->width >= opt->spectra_opt.tile_size &&
        test->height >= opt->spectra_opt.tile_size) {
        if (mcp_spectra_blue_noise(test, ref, &opt->spectra_opt, &out->spectra,
                                   maps ? &maps->spectra : NULL))
            goto done;
        out->has_spectra = 1;
    }
    if (maps) {
        maps->sq_error = sq;
        maps->relse = relse;
        sq = relse = NULL;
    }
    rc = 0;
done:
    figures_bar_end(&bar, rc != 0);
    mcp_image_free(own_ldr);
    mcp_image_free(own_hdr);
    mcp_image_free(sq);
    mcp_image_free(relse);
    if (rc && maps) mcp_metrics_maps_free(maps);
    return rc;
}

/* ---- output ---- */

static int
add_number(cJSON *obj, const char *key, double v)
{
    cJSON *item = isnan(v)   ? cJSON_CreateNull()
                  : isinf(v) ? cJSON_CreateString(v > 0 ? "inf" : "-inf")
                             : cJSON_CreateNumber(v);
    if (!item) return mcp_error("out of memory for the report");
    cJSON_AddItemToObject(obj, key, item);
    return 0;
}

/* FLIP's statistics beside its mean (flip.h; named as the tool prints them). */
static void
add_flip_stats(cJSON *f, const mcp_flip_stats *s)
{
    cJSON_AddNumberToObject(f, "weighted_median", s->weighted_median);
    cJSON_AddNumberToObject(f, "weighted_q1", s->weighted_q1);
    cJSON_AddNumberToObject(f, "weighted_q3", s->weighted_q3);
    cJSON_AddNumberToObject(f, "min", s->min);
    cJSON_AddNumberToObject(f, "max", s->max);
}

static int
add_counts(cJSON *h, const char *key, const mcp_flip_stats *s)
{
    cJSON *a = cJSON_AddArrayToObject(h, key);
    if (!a) return mcp_error("out of memory for the report");
    for (int i = 0; i < MCP_FLIP_HISTOGRAM_BUCKETS; i++)
        cJSON_AddItemToArray(a, cJSON_CreateNumber((double)s->histogram[i]));
    return 0;
}

int
mcp_metrics_json(const mcp_metrics *m, const mcp_metrics_options *opt, cJSON *obj)
{
    mcp_metrics_options d = mcp_metrics_defaults();
    if (!opt) opt = &d;
    if (add_number(obj, "mse", m->mse) || add_number(obj, "rmse", m->rmse) ||
        add_number(obj, "relmse", m->relmse) || add_number(obj, "psnr", m->psnr) ||
        add_number(obj, "pmse", m->pmse))
        return -1;
    cJSON *pm = cJSON_AddObjectToObject(obj, "pmse_settings");
    if (!pm) return mcp_error("out of memory for the report");
    cJSON_AddStringToObject(pm, "kernel", mcp_pkernel_kind_name(opt->pmse.kernel.kind));
    if (opt->pmse.kernel.kind == MCP_PKERNEL_GAUSSIAN) {
        cJSON_AddNumberToObject(pm, "dpi", opt->pmse.kernel.dpi);
        cJSON_AddNumberToObject(pm, "distance_in", opt->pmse.kernel.distance_in);
        cJSON_AddNumberToObject(
            pm, "sigma_px",
            mcp_pkernel_sigma_px(opt->pmse.kernel.dpi, opt->pmse.kernel.distance_in));
    }
    cJSON_AddStringToObject(pm, "reference_filter",
                            opt->pmse.filter_reference ? "g" : "delta");
    cJSON_AddStringToObject(pm, "tone_map", mcp_tonemap_name(opt->pmse.tone_map));
    if (m->n_percentiles) {
        cJSON *rp = cJSON_AddObjectToObject(obj, "relse_percentiles");
        cJSON *ps = rp ? cJSON_AddArrayToObject(rp, "p") : NULL;
        cJSON *vs = rp ? cJSON_AddArrayToObject(rp, "value") : NULL;
        if (!vs) return mcp_error("out of memory for the report");
        for (int k = 0; k < m->n_percentiles; k++) {
            cJSON_AddItemToArray(ps, cJSON_CreateNumber(m->percentiles[k]));
            cJSON_AddItemToArray(vs, cJSON_CreateNumber(m->relse[k]));
        }
    }
    if (m->has_flip_ldr) {
        cJSON *f = cJSON_AddObjectToObject(obj, "flip_ldr");
        if (!f) return mcp_error("out of memory for the report");
        cJSON_AddNumberToObject(f, "mean", m->flip_ldr.mean);
        add_flip_stats(f, &m->flip_ldr.stats);
        cJSON_AddNumberToObject(f, "ppd", m->flip_ldr.ppd);
    }
    if (m->has_flip_hdr) {
        cJSON *f = cJSON_AddObjectToObject(obj, "flip_hdr");
        if (!f) return mcp_error("out of memory for the report");
        cJSON_AddNumberToObject(f, "mean", m->flip_hdr.mean);
        add_flip_stats(f, &m->flip_hdr.stats);
        cJSON_AddNumberToObject(f, "ppd", m->flip_hdr.ppd);
        cJSON_AddStringToObject(f, "tone_mapper",
                                mcp_tonemap_name(opt->flip.tone_mapper));
        cJSON_AddNumberToObject(f, "start_exposure", m->flip_hdr.start_exposure);
        cJSON_AddNumberToObject(f, "stop_exposure", m->flip_hdr.stop_exposure);
        cJSON_AddNumberToObject(f, "num_exposures", m->flip_hdr.num_exposures);
    }
    if (m->has_spectra) {
        cJSON *b = cJSON_AddObjectToObject(obj, "blue_noise");
        if (!b) return mcp_error("out of memory for the report");
        cJSON_AddNumberToObject(b, "low_fraction", m->spectra.low_fraction);
        cJSON_AddNumberToObject(b, "white_fraction", m->spectra.white_fraction);
        cJSON_AddNumberToObject(b, "energy", m->spectra.energy);
        cJSON_AddNumberToObject(b, "tile_size", m->spectra.tile_size);
        cJSON_AddNumberToObject(b, "cutoff", opt->spectra_opt.cutoff);
        cJSON_AddStringToObject(b, "tone_map",
                                mcp_tonemap_name(opt->spectra_opt.tone_map));
    }
    if (m->has_flip_ldr || m->has_flip_hdr) {
        /* apart from the figures: a report's page draws it rather than listing it */
        cJSON *h = cJSON_AddObjectToObject(obj, "flip_histogram");
        if (!h) return mcp_error("out of memory for the report");
        cJSON_AddNumberToObject(h, "bucket_width", 1.0 / MCP_FLIP_HISTOGRAM_BUCKETS);
        if ((m->has_flip_ldr && add_counts(h, "flip_ldr", &m->flip_ldr.stats)) ||
            (m->has_flip_hdr && add_counts(h, "flip_hdr", &m->flip_hdr.stats)))
            return -1;
    }
    if (m->n_above) {
        cJSON *list = cJSON_AddArrayToObject(obj, "pixels_above");
        if (!list) return mcp_error("out of memory for the report");
        for (int k = 0; k < m->n_above; k++) {
            cJSON *a = cJSON_CreateObject();
            if (!a) return mcp_error("out of memory for the report");
            cJSON_AddItemToArray(list, a);
            cJSON_AddStringToObject(a, "map", mcp_above_map_name(m->above[k].map));
            cJSON_AddNumberToObject(a, "threshold", m->above[k].threshold);
            cJSON_AddNumberToObject(a, "percent", m->above_percent[k]);
        }
    }
    return 0;
}

/* One channel of img through a colour map into an 8-bit PNG. */
static int
write_png(const mcp_image *img, int channel, double lo, double hi, mcp_colormap map,
          const char *path)
{
    size_t n;
    if (mcp_size_mul3((size_t)img->width, (size_t)img->height, 3, &n))
        return mcp_error("%s: image too large", path);
    unsigned char *rgb = mcp_malloc(n);
    if (!rgb) return -1;
    int rc = mcp_colormap_apply(img, channel, lo, hi, map, rgb) ||
             mcp_write_rgb8(rgb, img->width, img->height, path);
    free(rgb);
    return rc ? -1 : 0;
}

typedef struct {
    const char *dir, *prefix;
    cJSON *section;
    /* "writing maps" on a terminal for a megapixel or more: a step per file */
    mcp_progress bar;
    int bar_shown;
    long written;
} map_out;

static int
out_path(const map_out *o, const char *name, const char *ext, char *path, size_t cap,
         char *rel, size_t rel_cap)
{
    int a = snprintf(rel, rel_cap, "%s%s.%s", o->prefix, name, ext);
    int b = snprintf(path, cap, "%s/%s", o->dir, rel);
    if (a < 0 || b < 0 || (size_t)a >= rel_cap || (size_t)b >= cap)
        return mcp_error("output path too long: %s/%s%s.%s", o->dir, o->prefix, name,
                         ext);
    return 0;
}

/* Writes img as EXR (exr) and channel png_channel as a false-colour PNG for the
 * report: lo..hi over the colour map, with log_values when the channel holds log10 of
 * what unit names (the colour bar then shows 10^lo..10^hi on a log axis). */
static int
emit(map_out *o, const mcp_image *img, const char *name, int exr, int png_channel,
     double lo, double hi, mcp_colormap map, int log_values, const char *caption,
     const char *unit)
{
    char path[4096], rel[2048];
    if (exr && (out_path(o, name, "exr", path, sizeof path, rel, sizeof rel) ||
                mcp_image_write(img, path, NULL)))
        return -1;
    if (o->bar_shown && exr) mcp_progress_update(&o->bar, ++o->written);
    if (png_channel < 0) return 0;
    if (out_path(o, name, "png", path, sizeof path, rel, sizeof rel) ||
        write_png(img, png_channel, lo, hi, map, path))
        return -1;
    if (o->bar_shown) mcp_progress_update(&o->bar, ++o->written);
    if (!o->section) return 0;
    cJSON *m =
        mcp_report_add_map(o->section, rel, caption, map, log_values ? pow(10.0, lo) : lo,
                           log_values ? pow(10.0, hi) : hi,
                           log_values ? MCP_AXIS_LOG : MCP_AXIS_LINEAR, unit);
    return m && !mcp__report_map_one_value(m, img, png_channel, log_values, 1.0) ? 0 : -1;
}

static int write_all(const mcp_metrics_maps *maps, map_out *o);

int
mcp_metrics_write_maps(const mcp_metrics_maps *maps, const char *dir, const char *prefix,
                       cJSON *section)
{
    map_out o = {.dir = dir, .prefix = prefix ? prefix : "", .section = section};
    const mcp_image *any = maps->flip_ldr   ? maps->flip_ldr
                           : maps->flip_hdr ? maps->flip_hdr
                           : maps->relse    ? maps->relse
                                            : maps->sq_error;
    o.bar_shown =
        any && (double)any->width * any->height >= 1048576.0 && !mcp_progress_quiet();
    if (o.bar_shown) {
        /* the files emit writes: an EXR and a PNG of each FLIP map, the EXRs of the
           squared and relative errors, the PNG of the latter, the spectra's PNG */
        long files =
            2 * (!!maps->flip_ldr + !!maps->flip_hdr + !!maps->flip_hdr_exposure) +
            !!maps->sq_error + 2 * !!maps->relse + !!maps->spectra;
        mcp_progress_begin(&o.bar, "writing maps", files);
    }
    int rc = write_all(maps, &o);
    if (o.bar_shown) {
        if (rc)
            mcp__progress_stop(&o.bar);
        else
            mcp_progress_end(&o.bar);
    }
    return rc;
}

static int
write_all(const mcp_metrics_maps *maps, map_out *o)
{
    char sub[4096];
    /* The prefix may name a sub-folder ("maps/"): create it with the folder. */
    const char *slash = strrchr(o->prefix, '/');
    int n = snprintf(sub, sizeof sub, "%s/%.*s", o->dir,
                     slash ? (int)(slash - o->prefix) : 0, o->prefix);
    if (n < 0 || (size_t)n >= sizeof sub)
        return mcp_error("output path too long: %s/%s", o->dir, o->prefix);
    if (mcp_make_dirs(sub)) return -1;
    static const char flip_unit[] = "FLIP error: 0 identical, 1 most different";
    if (maps->flip_ldr && emit(o, maps->flip_ldr, "flip_ldr", 1, 0, 0.0, 1.0,
                               MCP_COLORMAP_MAGMA, 0, "LDR-FLIP per pixel", flip_unit))
        return -1;
    if (maps->flip_hdr && emit(o, maps->flip_hdr, "flip_hdr", 1, 0, 0.0, 1.0,
                               MCP_COLORMAP_MAGMA, 0, "HDR-FLIP per pixel", flip_unit))
        return -1;
    if (maps->flip_hdr_exposure &&
        emit(o, maps->flip_hdr_exposure, "flip_hdr_exposure", 1, 0, 0.0, 1.0,
             MCP_COLORMAP_VIRIDIS, 0,
             "HDR-FLIP: the exposure where each pixel's error is largest",
             "0: the start exposure, 1: the stop exposure (flip_hdr in the figures)"))
        return -1;
    if (maps->sq_error &&
        emit(o, maps->sq_error, "sq_error", 1, -1, 0, 0, 0, 0, NULL, NULL))
        return -1;
    if (maps->relse) {
        if (emit(o, maps->relse, "relse", 1, -1, 0, 0, 0, 0, NULL, NULL)) return -1;
        mcp_image *lg = NULL;
        if (mcp_image_new(maps->relse->width, maps->relse->height, 1,
                          (const char *const[]){"log10_relse"}, &lg))
            return -1;
        for (int y = 0; y < lg->height; y++)
            for (int x = 0; x < lg->width; x++) {
                const float *p = mcp_image_px(maps->relse, x, y);
                double mean = 0.0;
                for (int c = 0; c < maps->relse->channels; c++)
                    mean += p[c];
                mean /= maps->relse->channels;
                mcp_image_px(lg, x, y)[0] = (float)(mean > 1e-30 ? log10(mean) : -30.0);
            }
        int rc = mcp_image_set_source(lg, "RelSE") ||
                 emit(o, lg, "relse", 0, 0, -5.0, 0.0, MCP_COLORMAP_INFERNO, 1,
                      "relative squared error per pixel, mean of the channels",
                      "(test - ref)^2 / (largest channel of test^2 + 0.01), log scale");
        mcp_image_free(lg);
        if (rc) return -1;
    }
    if (maps->spectra &&
        emit(o, maps->spectra, "spectra", 0, 0, 0.0, 1.0, MCP_COLORMAP_GRAY, 0,
             "error power spectrum per tile, zero frequency at each tile's centre",
             "c ln(1 + power), scaled to 0..1 per picture: blue noise is dark at the "
             "centre of each tile"))
        return -1;
    return 0;
}
