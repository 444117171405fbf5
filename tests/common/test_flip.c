/* test_flip.c: common/metrics/flip.c and common/metrics/flip_csf.c against independent
 * truths: the constants and filter taps measured from NVlabs/flip v1.6 (docs/flip.md),
 * the flat-grey value 0.169141844, and a straightforward double-precision implementation
 * with full 2D kernels written here from the formulas (notes §1; float and double
 * differ by at most ~3.4e-5 per pixel there, so 1e-4 per pixel and 5e-5 on means). */
#define _POSIX_C_SOURCE 200809L /* setenv */
#include "testing.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include <mcpost/flip.h>
#include <mcpost/imageio.h>
#include "../../common/metrics/internal.h"

#define PI_D 3.14159265358979323846

static const char *const RGB[] = {"R", "G", "B"};

/* ---- a double-precision, 2D-kernel LDR-FLIP (independent of flip.c) ---- */

static const double M_XYZ[9] = {
    10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0,
    2613072.0 / 12288897.0,  8788810.0 / 12288897.0, 887015.0 / 12288897.0,
    1425312.0 / 73733382.0,  8788810.0 / 73733382.0, 70074185.0 / 73733382.0};
static const double M_RGB[9] = {3.241003275,  -1.537398934, -0.498615861,
                                -0.969224334, 1.875930071,  0.041554224,
                                0.055639423,  -0.204011202, 1.057148933};
static const double WHITE_D[3] = {0.950428545, 1.0, 1.088900371};

static void
mul3(const double *m, const double *v, double *o)
{
    for (int i = 0; i < 3; i++)
        o[i] = m[3 * i] * v[0] + m[3 * i + 1] * v[1] + m[3 * i + 2] * v[2];
}

static double
clampd(double v)
{
    return v < 0 ? 0 : v > 1 ? 1 : v;
}

static void
rgb_to_ycxcz_d(const double *rgb, double *o)
{
    double xyz[3];
    mul3(M_XYZ, rgb, xyz);
    double x = xyz[0] / WHITE_D[0], y = xyz[1], z = xyz[2] / WHITE_D[2];
    o[0] = 116 * y - 16;
    o[1] = 500 * (x - y);
    o[2] = 200 * (y - z);
}

static double
lab_f_d(double t)
{
    double d = 6.0 / 29.0;
    return t > d * d * d ? cbrt(t) : t / (3 * d * d) + 4.0 / 29.0;
}

static void
rgb_to_lab_hunt_d(const double *rgb, double *lab)
{
    double xyz[3];
    mul3(M_XYZ, rgb, xyz);
    double fx = lab_f_d(xyz[0] / WHITE_D[0]), fy = lab_f_d(xyz[1]),
           fz = lab_f_d(xyz[2] / WHITE_D[2]);
    lab[0] = 116 * fy - 16;
    lab[1] = 0.01 * lab[0] * 500 * (fx - fy);
    lab[2] = 0.01 * lab[0] * 200 * (fy - fz);
}

static double
hyab_d(const double *a, const double *b)
{
    return fabs(a[0] - b[0]) + hypot(a[1] - b[1], a[2] - b[2]);
}

/* Correlates plane p (w x h) with a (2r+1)^2 kernel, replicate borders. */
static double
conv2(const double *p, int w, int h, int x, int y, const double *k, int r)
{
    double s = 0;
    for (int j = -r; j <= r; j++)
        for (int i = -r; i <= r; i++) {
            int xx = x + i < 0 ? 0 : x + i >= w ? w - 1 : x + i;
            int yy = y + j < 0 ? 0 : y + j >= h ? h - 1 : y + j;
            s += k[(j + r) * (2 * r + 1) + (i + r)] * p[yy * w + xx];
        }
    return s;
}

/* Normalises positive and negative weights to +1 and -1. */
static void
normalise_signed(double *k, int n)
{
    double pos = 0, neg = 0;
    for (int i = 0; i < n; i++)
        if (k[i] > 0)
            pos += k[i];
        else
            neg -= k[i];
    for (int i = 0; i < n; i++)
        k[i] /= k[i] > 0 ? pos : neg;
}

/* map[w*h] = LDR-FLIP(test, ref) from linear RGB in [0, 1] (interleaved doubles). */
static double
flip_ldr_reference(const double *test, const double *ref, int w, int h, double ppd,
                   double *map)
{
    const double a1[3] = {1, 1, 34.1}, b1[3] = {0.0047, 0.0053, 0.04},
                 a2[3] = {0, 0, 13.5}, b2[3] = {1e-5, 1e-5, 0.025};
    int n = w * h, r = (int)ceil(3 * sqrt(0.04 / (2 * PI_D * PI_D)) * ppd);
    int kw = 2 * r + 1;
    double *csf = calloc((size_t)3 * kw * kw, sizeof *csf);
    for (int c = 0; c < 3; c++) {
        double sum = 0, *k = csf + c * kw * kw;
        for (int j = -r; j <= r; j++)
            for (int i = -r; i <= r; i++) {
                double d2 = (i * i + j * j) / (ppd * ppd);
                double v = a1[c] * sqrt(PI_D / b1[c]) * exp(-PI_D * PI_D * d2 / b1[c]) +
                           a2[c] * sqrt(PI_D / b2[c]) * exp(-PI_D * PI_D * d2 / b2[c]);
                k[(j + r) * kw + i + r] = v;
                sum += v;
            }
        for (int i = 0; i < kw * kw; i++)
            k[i] /= sum;
    }
    double sigma = 0.5 * 0.082 * ppd;
    int rf = (int)ceil(3 * sigma), fw = 2 * rf + 1;
    double *g2 = calloc((size_t)fw * fw, sizeof *g2), *ek[2], *pk[2], gsum = 0;
    for (int i = 0; i < fw * fw; i++)
        gsum += g2[i] =
            exp(-((i % fw - rf) * (i % fw - rf) + (i / fw - rf) * (i / fw - rf)) /
                (2 * sigma * sigma));
    for (int d = 0; d < 2; d++) {
        ek[d] = calloc((size_t)fw * fw, sizeof(double));
        pk[d] = calloc((size_t)fw * fw, sizeof(double));
        for (int i = 0; i < fw * fw; i++) {
            double u = d == 0 ? i % fw - rf : i / fw - rf, g = g2[i] / gsum;
            ek[d][i] = -u * g;
            pk[d][i] = (u * u / (sigma * sigma) - 1) * g;
        }
        normalise_signed(ek[d], fw * fw);
        normalise_signed(pk[d], fw * fw);
    }
    double green[3] = {0, 1, 0}, blue[3] = {0, 0, 1}, lg[3], lb[3];
    rgb_to_lab_hunt_d(green, lg);
    rgb_to_lab_hunt_d(blue, lb);
    double cmax = pow(hyab_d(lg, lb), 0.7), pccmax = 0.4 * cmax;

    double *ycc[2], *yn[2];
    const double *img[2] = {ref, test};
    for (int s = 0; s < 2; s++) {
        ycc[s] = calloc((size_t)3 * n, sizeof(double));
        yn[s] = calloc((size_t)n, sizeof(double));
        for (int i = 0; i < n; i++) {
            double v[3] = {clampd(img[s][3 * i]), clampd(img[s][3 * i + 1]),
                           clampd(img[s][3 * i + 2])},
                   o[3];
            rgb_to_ycxcz_d(v, o);
            for (int c = 0; c < 3; c++)
                ycc[s][c * n + i] = o[c];
            yn[s][i] = (o[0] + 16) / 116;
        }
    }
    double sum = 0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double lab[2][3], edge[2], point[2];
            for (int s = 0; s < 2; s++) {
                double f[3], xyz[3], rgb[3];
                for (int c = 0; c < 3; c++)
                    f[c] = conv2(ycc[s] + c * n, w, h, x, y, csf + c * kw * kw, r);
                double yy = (f[0] + 16) / 116;
                xyz[0] = (yy + f[1] / 500) * WHITE_D[0];
                xyz[1] = yy;
                xyz[2] = (yy - f[2] / 200) * WHITE_D[2];
                mul3(M_RGB, xyz, rgb);
                for (int c = 0; c < 3; c++)
                    rgb[c] = clampd(rgb[c]);
                rgb_to_lab_hunt_d(rgb, lab[s]);
                edge[s] = hypot(conv2(yn[s], w, h, x, y, ek[0], rf),
                                conv2(yn[s], w, h, x, y, ek[1], rf));
                point[s] = hypot(conv2(yn[s], w, h, x, y, pk[0], rf),
                                 conv2(yn[s], w, h, x, y, pk[1], rf));
            }
            double e = pow(hyab_d(lab[0], lab[1]), 0.7);
            e = e < pccmax ? e * 0.95 / pccmax
                           : 0.95 + (e - pccmax) / (cmax - pccmax) * 0.05;
            double fd =
                pow(fmax(fabs(edge[0] - edge[1]), fabs(point[0] - point[1])) / sqrt(2.0),
                    0.5);
            map[y * w + x] = pow(e, 1 - fd);
            sum += map[y * w + x];
        }
    for (int s = 0; s < 2; s++) {
        free(ycc[s]);
        free(yn[s]);
    }
    for (int d = 0; d < 2; d++) {
        free(ek[d]);
        free(pk[d]);
    }
    free(g2);
    free(csf);
    return sum / n;
}

/* Smooth gradients, a hard-edged square and a thin line, plus noise in the test. */
static void
make_pair(int w, int h, double noise, uint64_t seed, float scale, mcp_image **test,
          mcp_image **ref)
{
    assert_int_equal(mcp_image_new(w, h, 3, RGB, ref), 0);
    assert_int_equal(mcp_image_new(w, h, 3, RGB, test), 0);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                double v =
                    0.2 + 0.5 * x / w * (c == 0) + 0.4 * y / h * (c == 1) + 0.1 * c;
                if (x > w / 4 && x < w / 2 && y > h / 3 && y < 2 * h / 3)
                    v = c == 2 ? 0.9 : 0.05;
                if (x == 3 * w / 4) v = 1.0;
                mcp_image_px(*ref, x, y)[c] = (float)(v * scale);
                double t = v + noise * (mcp_test_rand_uniform(&seed) - 0.5);
                mcp_image_px(*test, x, y)[c] = (float)(t * scale);
            }
}

static double *
to_doubles(const mcp_image *img, double scale)
{
    size_t n = (size_t)img->width * img->height * 3;
    double *d = malloc(n * sizeof *d);
    for (size_t i = 0; i < n; i++)
        d[i] = img->data[i] * scale;
    return d;
}

/* ---- constants and filters ---- */

static void
test_default_ppd_and_radii(void **state)
{
    (void)state;
    float ppd;
    assert_int_equal(mcp_flip_ppd(NULL, &ppd), 0);
    assert_close(ppd, 67.0206451, 1e-7, 0); /* notes §1.2, float */
    mcp_flip_filters *f = NULL;
    assert_int_equal(mcp_flip_filters_new(ppd, &f), 0);
    assert_int_equal(f->spatial_radius, 10);
    assert_int_equal(f->feature_radius, 9);
    mcp_flip_filters_free(f);
    const float ppds[2] = {30.0f, 100.0f};
    const int rs[2] = {5, 14}, rf[2] = {4, 13};
    for (int i = 0; i < 2; i++) {
        assert_int_equal(mcp_flip_filters_new(ppds[i], &f), 0);
        assert_int_equal(f->spatial_radius, rs[i]);
        assert_int_equal(f->feature_radius, rf[i]);
        mcp_flip_filters_free(f);
    }
    /* The -vc order (distance, width m, width px) of the defaults. */
    mcp_flip_options o = mcp_flip_defaults();
    o.distance_m = 0.5;
    o.display_width_m = 0.6;
    o.display_width_px = 2560;
    assert_int_equal(mcp_flip_ppd(&o, &ppd), 0);
    assert_close(ppd, 0.5 * 2560 / 0.6 * PI_D / 180, 1e-6, 0);
}

static void
test_filter_taps(void **state)
{
    (void)state;
    float ppd;
    mcp_flip_filters *f = NULL;
    assert_int_equal(mcp_flip_ppd(NULL, &ppd), 0);
    assert_int_equal(mcp_flip_filters_new(ppd, &f), 0);
    int r = f->spatial_radius;
    /* notes §1.2, measured with flip-dump --filters (printed to 9 digits). */
    const double y[] = {0.385760248, 0.241703719, 0.059453990, 0.005741300};
    const double cx[] = {0.363269061, 0.239982337, 0.069188185, 0.008705348};
    const double cz1[] = {0.115442053, 0.109271646, 0.092669748, 0.070413418,
                          0.047935791, 0.029238243, 0.015978266, 7.823e-3,
                          3.432e-3,    1.349e-3,    4.750e-4};
    const double cz2[] = {0.081692792, 0.074819252, 0.057478063, 0.037038215,
                          0.020019680, 9.077e-3,    3.452e-3,    1.101e-3,
                          2.946e-4,    6.61e-5,     1.24e-5};
    for (int i = 0; i < 4; i++) {
        assert_close(f->y[r + i], y[i], 2e-6, 1e-9);
        assert_close(f->y[r - i], y[i], 2e-6, 1e-9);
        assert_close(f->cx[r + i], cx[i], 2e-6, 1e-9);
    }
    /* The short-printed taps carry 3-4 significant digits. */
    for (int i = 0; i <= 10; i++) {
        assert_close(f->cz1[r + i], cz1[i], i < 7 ? 2e-6 : 1e-3, 1e-9);
        assert_close(f->cz2[r - i], cz2[i], i < 5 ? 2e-6 : 1e-2, 1e-9);
    }
    /* 2D centre taps and unit sums. */
    assert_close((double)f->y[r] * f->y[r], 0.148810969, 1e-6, 0);
    assert_close((double)f->cx[r] * f->cx[r], 0.131964411, 1e-6, 0);
    assert_close((double)f->cz1[r] * f->cz1[r] + (double)f->cz2[r] * f->cz2[r],
                 0.020000580, 1e-6, 0);
    double sy = 0, s1 = 0, s2 = 0;
    for (int i = 0; i <= 2 * r; i++) {
        sy += f->y[i];
        s1 += f->cz1[i];
        s2 += f->cz2[i];
    }
    assert_close(sy, 1.0, 1e-6, 0);
    assert_close(s1 * s1 + s2 * s2, 1.0, 1e-6, 0);
    /* Feature filters: g sums to 1; dg and ddg positive/negative halves to +-1. */
    int rf = f->feature_radius;
    double gs = 0, dp = 0, dn = 0, pp = 0, pn = 0;
    for (int i = 0; i <= 2 * rf; i++) {
        gs += f->g[i];
        *(f->dg[i] > 0 ? &dp : &dn) += f->dg[i];
        *(f->ddg[i] > 0 ? &pp : &pn) += f->ddg[i];
    }
    assert_close(gs, 1, 1e-6, 0);
    assert_close(dp, 1, 1e-6, 0);
    assert_close(dn, -1, 1e-6, 0);
    assert_close(pp, 1, 1e-6, 0);
    assert_close(pn, -1, 1e-6, 0);
    /* sigma = 2.7478466 px: g(1)/g(0) = exp(-1/(2 sigma^2)). */
    assert_close(f->g[rf + 1] / f->g[rf], exp(-1 / (2 * 2.7478466 * 2.7478466)), 1e-6, 0);
    assert_true(f->dg[rf + 1] < 0 && f->dg[rf - 1] > 0); /* dg = -x g */
    mcp_flip_filters_free(f);
}

static void
test_cmax_and_exposure_constants(void **state)
{
    (void)state;
    assert_close(mcp_flip_cmax(), 41.2760963, 1e-7, 0);
    assert_close(MCP_FLIP_PC * mcp_flip_cmax(), 16.5104389, 1e-7, 0);
    const mcp_tonemap tms[3] = {MCP_TONEMAP_ACES, MCP_TONEMAP_HABLE,
                                MCP_TONEMAP_REINHARD};
    const double xmax[3] = {2.1188723, 3.1277493, 5.6666667};
    for (int i = 0; i < 3; i++) {
        float x;
        assert_int_equal(mcp_flip_exposure_xmax(tms[i], &x), 0);
        /* The notes give the exact roots; FLIP solves in float, which cancels
         * digits (2.11887312, 3.12774992, 5.66666794). */
        assert_close(x, xmax[i], 1e-6, 0);
    }
    float x;
    assert_error_contains(mcp_flip_exposure_xmax(MCP_TONEMAP_CLAMP, &x),
                          "tone mapper must be aces, hable or reinhard (got 'clamp')");
}

/* ---- values ---- */

static void
test_flat_grey(void **state)
{
    (void)state;
    /* notes §3: flat sRGB 128 vs 140 gives 0.169141844 in float (0.169108196 in
     * double); the difference is the float residue of the derivative taps. */
    float a = mcp_srgb_to_linear(128.0f / 255.0f),
          b = mcp_srgb_to_linear(140.0f / 255.0f);
    mcp_image *ref = mcp_test_constant(24, 20, 3, a, RGB);
    mcp_image *test = mcp_test_constant(24, 20, 3, b, RGB);
    mcp_flip_result res;
    mcp_image *map = NULL;
    assert_int_equal(mcp_flip_ldr(test, ref, NULL, &res, &map), 0);
    assert_close(mcp_image_px(map, 7, 5)[0], 0.169141844, 0, 2e-7);
    /* The mean is FLIP's float running sum, which drifts by ~1e-6 over 480 equal
     * values; the same sum here reproduces it exactly. */
    float fsum = 0.0f;
    for (int i = 0; i < 480; i++)
        fsum += map->data[i];
    assert_true(res.mean == (double)(fsum / 480.0f));
    assert_close(res.mean, 0.169141844, 0, 2e-6);
    assert_close(res.ppd, 67.0206451, 1e-7, 0);
    /* The colour-only term (no feature difference) is 0.169108644: the double 2D
     * reference lands between, within the documented float-vs-double gap. */
    double *dt = to_doubles(test, 1), *dr = to_doubles(ref, 1), dmap[480];
    double dmean = flip_ldr_reference(dt, dr, 24, 20, 67.0206451, dmap);
    assert_close(dmean, 0.169108196, 0, 2e-6);
    free(dt);
    free(dr);
    mcp_image_free(map);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_identical_is_zero(void **state)
{
    (void)state;
    mcp_image *a = mcp_test_random(33, 17, 3, 0.0f, 2.0f, 5, RGB);
    mcp_flip_result res;
    mcp_image *map = NULL, *e = NULL;
    assert_int_equal(mcp_flip_ldr(a, a, NULL, &res, &map), 0);
    assert_close(res.mean, 0, 0, 0);
    assert_close(mcp_test_max_abs_diff(map, map), 0, 0, 0);
    mcp_image_free(map);
    assert_int_equal(mcp_flip_hdr(a, a, NULL, &res, &map, &e), 0);
    assert_close(res.mean, 0, 0, 0);
    for (int i = 0; i < 33 * 17; i++) {
        assert_true(map->data[i] == 0.0f);
        assert_true(e->data[i] == 0.0f);
    }
    mcp_image_free(e);
    mcp_image_free(map);
    mcp_image_free(a);
}

static void
test_ldr_against_double_2d(void **state)
{
    (void)state;
    const int w = 48, h = 40;
    const double ppds[2] = {67.0206451, 30.0};
    for (int k = 0; k < 2; k++) {
        mcp_image *test, *ref, *map = NULL;
        make_pair(w, h, 0.3, 11 + k, 1.0f, &test, &ref);
        mcp_flip_options o = mcp_flip_defaults();
        o.ppd = ppds[k];
        mcp_flip_result res;
        assert_int_equal(mcp_flip_ldr(test, ref, &o, &res, &map), 0);
        double *dt = to_doubles(test, 1), *dr = to_doubles(ref, 1);
        double *dmap = malloc(sizeof(double) * w * h);
        double dmean = flip_ldr_reference(dt, dr, w, h, ppds[k], dmap);
        double worst = 0;
        for (int i = 0; i < w * h; i++)
            worst = fmax(worst, fabs(map->data[i] - dmap[i]));
        assert_close(worst, 0, 0, 1e-4);
        assert_close(res.mean, dmean, 0, 5e-5);
        assert_true(res.mean > 0.05); /* the pair differs visibly */
        free(dmap);
        free(dt);
        free(dr);
        mcp_image_free(map);
        mcp_image_free(test);
        mcp_image_free(ref);
    }
}

static int
cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* HDR-FLIP with tone mapper tm (0 aces, 1 hable, 2 reinhard) against the double
 * 2D reference run at each exposure. */
static void
hdr_against_double(int tm)
{
    const int w = 40, h = 32, n = w * h;
    mcp_image *test, *ref, *map = NULL, *emap = NULL;
    make_pair(w, h, 0.4, 3 + tm, 6.0f, &test, &ref); /* values up to 6: HDR */
    mcp_flip_result res;
    mcp_flip_options o = mcp_flip_defaults();
    const mcp_tonemap tms[3] = {MCP_TONEMAP_ACES, MCP_TONEMAP_HABLE,
                                MCP_TONEMAP_REINHARD};
    const double xmaxs[3] = {2.1188723, 3.1277493, 5.6666667};
    o.tone_mapper = tms[tm];
    assert_int_equal(mcp_flip_hdr(test, ref, &o, &res, &map, &emap), 0);

    /* Exposures from the notes' rule, in double: start = log2(xmax/Ymax),
     * stop = log2(xmax/Ymedian), N = max(2, ceil(stop - start)). */
    double *lum = malloc(sizeof(double) * n), ymax = 0;
    for (int i = 0; i < n; i++) {
        const float *p = ref->data + 3 * i;
        lum[i] = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
        ymax = fmax(ymax, lum[i]);
    }
    qsort(lum, n, sizeof *lum, cmp_double);
    double start = log2(xmaxs[tm] / ymax), stop = log2(xmaxs[tm] / lum[n / 2]);
    int n_exp = (int)fmax(2, ceil(stop - start));
    /* FLIP solves for xmax in float (within 4e-7 relative, see above). */
    assert_close(res.start_exposure, start, 0, 2e-6);
    assert_close(res.stop_exposure, stop, 0, 2e-6);
    assert_int_equal(res.num_exposures, n_exp);
    assert_true(n_exp >= 2);

    double *dt = to_doubles(test, 1), *dr = to_doubles(ref, 1);
    double *tt = malloc(sizeof(double) * 3 * n), *tr = malloc(sizeof(double) * 3 * n);
    double *best = calloc(n, sizeof(double)), *lmap = malloc(sizeof(double) * n);
    int *which = calloc(n, sizeof(int));
    const double ks[2][6] = {
        {0.6 * 0.6 * 2.51, 0.6 * 0.03, 0, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14},
        {0.231683, 0.013791, 0, 0.18, 0.3, 0.018}};
    const double *k = ks[tm < 2 ? tm : 0];
    for (int i = 0; i < n_exp; i++) {
        double m = pow(2, start + i * (stop - start) / (n_exp - 1));
        for (int j = 0; j < 3 * n; j++) {
            /* negative values count as 0 (our departure; the noise makes some) */
            double a = fmax(dt[j], 0) * m, b = fmax(dr[j], 0) * m;
            if (tm == 2) { /* Reinhard: c / (1 + luminance) */
                int p0 = j - j % 3;
                double la = 0, lb = 0;
                for (int c = 0; c < 3; c++) {
                    const double wl[3] = {0.2126, 0.7152, 0.0722};
                    la += wl[c] * fmax(dt[p0 + c], 0) * m;
                    lb += wl[c] * fmax(dr[p0 + c], 0) * m;
                }
                tt[j] = clampd(a / (1 + la));
                tr[j] = clampd(b / (1 + lb));
                continue;
            }
            tt[j] = clampd((k[0] * a * a + k[1] * a) / (k[3] * a * a + k[4] * a + k[5]));
            tr[j] = clampd((k[0] * b * b + k[1] * b) / (k[3] * b * b + k[4] * b + k[5]));
        }
        flip_ldr_reference(tt, tr, w, h, res.ppd, lmap);
        for (int j = 0; j < n; j++)
            if (lmap[j] > best[j]) {
                best[j] = lmap[j];
                which[j] = i;
            }
    }
    double worst = 0, mean = 0;
    int exposure_agree = 0;
    for (int j = 0; j < n; j++) {
        worst = fmax(worst, fabs(map->data[j] - best[j]));
        mean += best[j] / n;
        exposure_agree += fabs(emap->data[j] - (double)which[j] / (n_exp - 1)) < 1e-6;
    }
    assert_close(worst, 0, 0, 1e-4);
    assert_close(res.mean, mean, 0, 5e-5);
    /* Where two exposures give nearly equal maxima, float and double may pick
     * different ones; nearly all pixels agree. */
    assert_true(exposure_agree > 0.95 * n);
    free(which);
    free(lmap);
    free(best);
    free(tt);
    free(tr);
    free(dt);
    free(dr);
    free(lum);
    mcp_image_free(emap);
    mcp_image_free(map);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_hdr_against_double_2d(void **state)
{
    (void)state;
    for (int tm = 0; tm < 3; tm++)
        hdr_against_double(tm);
}

static void
test_hdr_zero_median(void **state)
{
    (void)state;
    /* More than half of the reference black: v1.6 returns 0 (stop = inf); we clamp
     * the median to FLT_EPSILON (docs/flip.md §5) and get a finite schedule. */
    mcp_image *ref = mcp_test_constant(16, 16, 3, 0.0f, RGB);
    mcp_image *test = mcp_test_constant(16, 16, 3, 0.0f, RGB);
    for (int y = 0; y < 6; y++)
        for (int x = 0; x < 16; x++)
            for (int c = 0; c < 3; c++) {
                mcp_image_px(ref, x, y)[c] = 2.0f;
                mcp_image_px(test, x, y)[c] = 1.5f;
            }
    float start, stop;
    assert_int_equal(mcp_flip_auto_exposures(ref, MCP_TONEMAP_ACES, &start, &stop), 0);
    float xmax;
    mcp_flip_exposure_xmax(MCP_TONEMAP_ACES, &xmax);
    assert_close(start, log2(xmax / 2.0), 0, 1e-5); /* luminance of (2,2,2) is 2 */
    assert_close(stop, log2(xmax / FLT_EPSILON), 0, 1e-5);
    mcp_flip_result res;
    assert_int_equal(mcp_flip_hdr(test, ref, NULL, &res, NULL, NULL), 0);
    assert_int_equal(res.num_exposures, (int)ceilf(stop - start));
    assert_true(isfinite(res.mean) && res.mean > 0.0 && res.mean < 1.0);

    /* All black: the maximum is clamped too, so start == stop and N = 2. */
    mcp_image *black = mcp_test_constant(8, 8, 3, 0.0f, RGB);
    assert_int_equal(mcp_flip_hdr(black, black, NULL, &res, NULL, NULL), 0);
    assert_int_equal(res.num_exposures, 2);
    assert_close(res.mean, 0, 0, 0);
    mcp_image_free(black);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_hdr_negative_clamped(void **state)
{
    (void)state;
    /* Negative values act as 0 (docs/flip.md §5), not as ACES's near-white. */
    mcp_image *ref = mcp_test_random(20, 20, 3, 0.1f, 3.0f, 9, RGB);
    mcp_image *t0 = NULL, *t1 = NULL;
    assert_int_equal(mcp_image_copy(ref, &t0), 0);
    assert_int_equal(mcp_image_copy(ref, &t1), 0);
    for (int c = 0; c < 3; c++) {
        mcp_image_px(t0, 5, 5)[c] = 0.0f;
        mcp_image_px(t1, 5, 5)[c] = -50.0f;
    }
    mcp_flip_result r0, r1;
    assert_int_equal(mcp_flip_hdr(t0, ref, NULL, &r0, NULL, NULL), 0);
    assert_int_equal(mcp_flip_hdr(t1, ref, NULL, &r1, NULL, NULL), 0);
    assert_true(r0.mean > 0);
    assert_close(r1.mean, r0.mean, 0, 0);
    mcp_image_free(t1);
    mcp_image_free(t0);
    mcp_image_free(ref);
}

static void
test_hdr_user_exposures(void **state)
{
    (void)state;
    mcp_image *test, *ref;
    make_pair(24, 24, 0.2, 4, 3.0f, &test, &ref);
    mcp_flip_options o = mcp_flip_defaults();
    o.start_exposure = -1;
    o.stop_exposure = 2;
    o.num_exposures = 4;
    o.tone_mapper = MCP_TONEMAP_HABLE;
    mcp_flip_result res;
    mcp_image *e = NULL;
    assert_int_equal(mcp_flip_hdr(test, ref, &o, &res, NULL, &e), 0);
    assert_int_equal(res.num_exposures, 4);
    assert_close(res.start_exposure, -1, 0, 0);
    assert_close(res.stop_exposure, 2, 0, 0);
    for (int i = 0; i < 24 * 24; i++) {
        float v = e->data[i] * 3.0f; /* one of 0, 1/3, 2/3, 1 */
        assert_close(v, roundf(v), 0, 1e-6);
    }
    mcp_image_free(e);
    /* One bound given: only the other is automatic. */
    o.stop_exposure = NAN;
    o.num_exposures = 0;
    assert_int_equal(mcp_flip_hdr(test, ref, &o, &res, NULL, NULL), 0);
    float a, b;
    assert_int_equal(mcp_flip_auto_exposures(ref, MCP_TONEMAP_HABLE, &a, &b), 0);
    assert_close(res.start_exposure, -1, 0, 0);
    assert_close(res.stop_exposure, b, 0, 0);
    /* Reinhard runs (luminance form). */
    o.tone_mapper = MCP_TONEMAP_REINHARD;
    assert_int_equal(mcp_flip_hdr(test, ref, &o, &res, NULL, NULL), 0);
    assert_true(res.mean > 0 && res.mean < 1);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_threads_do_not_change_results(void **state)
{
    (void)state;
#ifdef _OPENMP
    mcp_image *test, *ref, *m1 = NULL, *m4 = NULL;
    make_pair(200, 120, 0.3, 21, 2.0f, &test, &ref); /* large enough for a team */
    int saved = omp_get_max_threads();
    mcp_flip_result r1, r4;
    omp_set_num_threads(1);
    assert_int_equal(mcp_flip_hdr(test, ref, NULL, &r1, &m1, NULL), 0);
    omp_set_num_threads(4);
    assert_int_equal(mcp_flip_hdr(test, ref, NULL, &r4, &m4, NULL), 0);
    omp_set_num_threads(saved);
    assert_true(memcmp(m1->data, m4->data, sizeof(float) * 200 * 120) == 0);
    assert_true(r1.mean == r4.mean);
    /* The AVX2 filters (where the CPU has them) and the 4-lane ones agree bit for bit. */
    mcp_image_free(m4);
    m4 = NULL;
    setenv("MCPOST_NO_AVX2", "1", 1);
    assert_int_equal(mcp_flip_hdr(test, ref, NULL, &r4, &m4, NULL), 0);
    unsetenv("MCPOST_NO_AVX2");
    assert_true(memcmp(m1->data, m4->data, sizeof(float) * 200 * 120) == 0);
    mcp_image_free(m1);
    mcp_image_free(m4);
    mcp_image_free(test);
    mcp_image_free(ref);
#else
    skip();
#endif
}

/* ---- errors ---- */

static void
test_errors(void **state)
{
    (void)state;
    mcp_image *a = mcp_test_constant(8, 8, 3, 0.5f, RGB);
    mcp_image *b = mcp_test_constant(9, 8, 3, 0.5f, RGB);
    mcp_image *two = mcp_test_constant(8, 8, 2, 0.5f, (const char *const[]){"X", "Y"});
    mcp_image *rg =
        mcp_test_constant(8, 8, 4, 0.5f, (const char *const[]){"R", "G", "A", "Z"});
    mcp_flip_result res;
    mcp_image_set_source(a, "a.exr");
    mcp_image_set_source(b, "b.exr");
    mcp_image_set_source(two, "two.exr");
    mcp_image_set_source(rg, "rg.exr");
    assert_error_contains(mcp_flip_ldr(a, b, NULL, &res, NULL),
                          "a.exr: size 8x8 does not match b.exr (9x8)");
    assert_error_contains(mcp_flip_hdr(a, b, NULL, &res, NULL, NULL), "does not match");
    assert_error_contains(mcp_flip_ldr(two, a, NULL, &res, NULL),
                          "two.exr: no channel 'R'");
    assert_error_contains(mcp_flip_ldr(a, rg, NULL, &res, NULL),
                          "rg.exr: no channel 'B'");
    mcp_image *nan = NULL;
    assert_int_equal(mcp_image_copy(a, &nan), 0);
    mcp_image_set_source(nan, "nan.exr");
    mcp_image_px(nan, 3, 2)[1] = NAN;
    assert_error_contains(mcp_flip_ldr(nan, a, NULL, &res, NULL),
                          "nan.exr: non-finite value at pixel (3, 2)");
    mcp_image_px(nan, 3, 2)[1] = INFINITY;
    assert_error_contains(mcp_flip_hdr(a, nan, NULL, &res, NULL, NULL),
                          "nan.exr: non-finite value at pixel (3, 2)");
    mcp_flip_options o = mcp_flip_defaults();
    o.ppd = -1;
    assert_error_contains(mcp_flip_ldr(a, a, &o, &res, NULL),
                          "flip: ppd must be in (0, 10000] (got -1)");
    o = mcp_flip_defaults();
    o.display_width_m = 0;
    assert_error_contains(mcp_flip_ldr(a, a, &o, &res, NULL),
                          "flip: display_width_m must be > 0 (got 0)");
    o = mcp_flip_defaults();
    o.num_exposures = 1;
    assert_error_contains(mcp_flip_hdr(a, a, &o, &res, NULL, NULL),
                          "flip: num_exposures must be >= 2 (got 1)");
    o = mcp_flip_defaults();
    o.start_exposure = 3;
    o.stop_exposure = 1;
    assert_error_contains(mcp_flip_hdr(a, a, &o, &res, NULL, NULL),
                          "flip: start_exposure 3 is above stop_exposure 1");
    o = mcp_flip_defaults();
    o.tone_mapper = MCP_TONEMAP_NONE;
    assert_error_contains(mcp_flip_hdr(a, a, &o, &res, NULL, NULL),
                          "tone mapper must be aces, hable or reinhard (got 'none')");
    /* A failed call leaves the outputs NULL. */
    mcp_image *map = (mcp_image *)&res, *e = (mcp_image *)&res;
    assert_int_equal(mcp_flip_hdr(a, b, NULL, &res, &map, &e), -1);
    assert_null(map);
    assert_null(e);
    mcp_image_free(nan);
    mcp_image_free(rg);
    mcp_image_free(two);
    mcp_image_free(b);
    mcp_image_free(a);
}

static void
test_grey_and_unnamed_channels(void **state)
{
    (void)state;
    /* A 1-channel image is grey (FLIP's tool replicates it); a 3-channel image
     * without R, G, B names is taken in order. */
    mcp_image *g1 = mcp_test_constant(10, 10, 1, 0.3f, NULL);
    mcp_image *g3 = mcp_test_constant(10, 10, 3, 0.3f, NULL);
    mcp_image *r3 = mcp_test_constant(10, 10, 3, 0.5f, RGB);
    mcp_flip_result a, b;
    assert_int_equal(mcp_flip_ldr(g1, r3, NULL, &a, NULL), 0);
    assert_int_equal(mcp_flip_ldr(g3, r3, NULL, &b, NULL), 0);
    assert_true(a.mean == b.mean && a.mean > 0);
    mcp_image_free(g1);
    mcp_image_free(g3);
    mcp_image_free(r3);
}

/* ---- the CSF operator M ---- */

static double
dot(const mcp_image *a, const mcp_image *b)
{
    double s = 0;
    for (size_t i = 0; i < (size_t)a->width * a->height * 3; i++)
        s += (double)a->data[i] * b->data[i];
    return s;
}

static void
test_csf_adjoint(void **state)
{
    (void)state;
    /* Sizes below, near and above the filter width 21, and a 1-pixel-high strip. */
    const int sizes[4][2] = {{37, 29}, {8, 5}, {21, 22}, {30, 1}};
    for (int k = 0; k < 4; k++) {
        int w = sizes[k][0], h = sizes[k][1];
        mcp_image *x = mcp_test_random(w, h, 3, -1, 1, 100 + k, RGB);
        mcp_image *y = mcp_test_random(w, h, 3, -1, 1, 200 + k, RGB);
        mcp_image *mx = NULL, *mty = NULL;
        assert_int_equal(mcp_flip_csf_apply(x, 0, &mx), 0);
        assert_int_equal(mcp_flip_csf_apply_transpose(y, 0, &mty), 0);
        double lhs = dot(mx, y), rhs = dot(x, mty);
        /* float filters: ~1e-7 per value, summed over a few thousand terms. */
        assert_close(lhs, rhs, 1e-5, 1e-6 * sqrt((double)w * h));
        mcp_image_free(mx);
        mcp_image_free(mty);
        mcp_image_free(x);
        mcp_image_free(y);
    }
    /* Other ppd: still adjoint. */
    mcp_image *x = mcp_test_random(25, 19, 3, -1, 1, 7, RGB);
    mcp_image *y = mcp_test_random(25, 19, 3, -1, 1, 8, RGB);
    mcp_image *mx = NULL, *mty = NULL;
    assert_int_equal(mcp_flip_csf_apply(x, 30.0, &mx), 0);
    assert_int_equal(mcp_flip_csf_apply_transpose(y, 30.0, &mty), 0);
    assert_close(dot(mx, y), dot(x, mty), 1e-5, 1e-5);
    mcp_image_free(mx);
    mcp_image_free(mty);
    mcp_image_free(x);
    mcp_image_free(y);
}

static void
test_csf_constants_and_trace(void **state)
{
    (void)state;
    mcp_image *one = mcp_test_constant(31, 23, 3, 1.0f, RGB), *m = NULL;
    assert_int_equal(mcp_flip_csf_apply(one, 0, &m), 0);
    for (int i = 0; i < 31 * 23 * 3; i++)
        assert_close(m->data[i], 1.0, 0, 2e-5);
    mcp_image_free(m);
    /* Not symmetric with replicate borders: M^T 1 is not 1 at the edges... */
    assert_int_equal(mcp_flip_csf_apply_transpose(one, 0, &m), 0);
    double sum = 0;
    for (int i = 0; i < 31 * 23 * 3; i++)
        sum += m->data[i];
    /* ...but it preserves the total (the columns of M sum to what the rows of M^T
     * spread): 1^T M^T 1 = 1^T M 1 = N. */
    assert_close(sum, 31 * 23 * 3, 1e-5, 0);
    assert_true(fabs(mcp_image_px(m, 0, 0)[0] - 1.0) > 0.01);
    mcp_image_free(m);
    mcp_image_free(one);

    /* Interior 3x3 diagonal block: trace 0.30077596, and its entries (notes §4). */
    const double block[3][3] = {{0.1236996, -0.0247732, 0.0498846},
                                {0.0045695, 0.1470815, -0.0028400},
                                {0.0286999, 0.0901162, 0.0299949}};
    double trace = 0;
    for (int c = 0; c < 3; c++) {
        mcp_image *e = mcp_test_constant(41, 41, 3, 0.0f, RGB);
        mcp_image_px(e, 20, 20)[c] = 1.0f;
        assert_int_equal(mcp_flip_csf_apply(e, 0, &m), 0);
        for (int r = 0; r < 3; r++)
            assert_close(mcp_image_px(m, 20, 20)[r], block[r][c], 0, 2e-6);
        trace += mcp_image_px(m, 20, 20)[c];
        mcp_image_free(m);
        mcp_image_free(e);
    }
    assert_close(trace, 0.30077596, 0, 1e-6);
    /* Corner pixel: the folded taps make the diagonal much larger. */
    mcp_image *e = mcp_test_constant(41, 41, 3, 0.0f, RGB);
    mcp_image_px(e, 0, 0)[0] = 1.0f;
    assert_int_equal(mcp_flip_csf_apply(e, 0, &m), 0);
    assert_true(mcp_image_px(m, 0, 0)[0] > 2 * block[0][0]);
    mcp_image_free(m);
    mcp_image_free(e);
}

static void
test_csf_errors(void **state)
{
    (void)state;
    mcp_image *two = mcp_test_constant(4, 4, 2, 0.0f, (const char *const[]){"U", "V"});
    mcp_image_set_source(two, "uv.exr");
    mcp_image *out = NULL;
    assert_error_contains(mcp_flip_csf_apply(two, 0, &out), "uv.exr: no channel 'R'");
    assert_null(out);
    mcp_image *ok = mcp_test_constant(4, 4, 3, 0.0f, RGB);
    assert_error_contains(mcp_flip_csf_apply_transpose(ok, 1e9, &out),
                          "flip: ppd must be in (0, 10000] (got 1e+09)");
    mcp_image_free(ok);
    mcp_image_free(two);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_default_ppd_and_radii),
        cmocka_unit_test(test_filter_taps),
        cmocka_unit_test(test_cmax_and_exposure_constants),
        cmocka_unit_test(test_flat_grey),
        cmocka_unit_test(test_identical_is_zero),
        cmocka_unit_test(test_ldr_against_double_2d),
        cmocka_unit_test(test_hdr_against_double_2d),
        cmocka_unit_test(test_hdr_zero_median),
        cmocka_unit_test(test_hdr_negative_clamped),
        cmocka_unit_test(test_hdr_user_exposures),
        cmocka_unit_test(test_threads_do_not_change_results),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_grey_and_unnamed_channels),
        cmocka_unit_test(test_csf_adjoint),
        cmocka_unit_test(test_csf_constants_and_trace),
        cmocka_unit_test(test_csf_errors),
    };
    return cmocka_run_group_tests_name("common/flip", tests, NULL, NULL);
}
