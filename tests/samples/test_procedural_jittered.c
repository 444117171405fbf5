/* test_procedural_jittered.c: the procedural renderer's jittered (stratified) sampler
 * (samples/procedural) -- over many seeds the variance of its pixel means is the exact
 * one from mcp_proc_truth_var_of_mean, well below the per-sample variance / n at
 * edges, while its means stay unbiased and its dumps report the ordinary sample
 * variance; the exact variance agrees with finer truths cut differently and with the
 * law of total variance; and the independent sampler is unchanged.
 *
 * The statistical tests use fixed seeds, so they are deterministic; each tolerance is
 * explained where it is used. */
#include "testing.h"

#include "procedural.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include <mcpost/dump.h>
#include <mcpost/imageio.h>

#define W 32
#define H 32
#define NV (W * H * 3) /* values (pixels x channels) of a W x H image */
#define R 400          /* realizations */
#define SPP 32         /* two passes of the default 4 x 4 strata */

static mcp_proc_scene
scene_of(int w, int h, mcp_proc_sampler sampler, int strata, double firefly_probability)
{
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = w;
    s.height = h;
    s.sampler = sampler;
    s.strata = strata;
    s.firefly_probability = firefly_probability;
    return s;
}

static mcp_dump *
render_or_fail(const mcp_proc_scene *s, int spp, uint64_t seed)
{
    mcp_dump *d = NULL;
    if (mcp_proc_render(s, spp, seed, NULL, &d))
        fail_msg("mcp_proc_render: %s", mcp_error_message());
    return d;
}

static void
truth_or_fail(const mcp_proc_scene *s, int spp, mcp_image **mean, mcp_image **var,
              mcp_image **var_of_mean)
{
    if (mcp_proc_truth(s, mean, var)) fail_msg("mcp_proc_truth: %s", mcp_error_message());
    if (mcp_proc_truth_var_of_mean(s, spp, var_of_mean))
        fail_msg("mcp_proc_truth_var_of_mean: %s", mcp_error_message());
}

/* The quantile of chi-square with nu degrees of freedom that matches the standard
 * normal quantile z (Wilson-Hilferty; relative error < 1e-3 for nu of hundreds). */
static double
chi2_quantile(double nu, double z)
{
    double a = 2.0 / (9.0 * nu), t = 1.0 - a + z * sqrt(a);
    return nu * t * t * t;
}

static int
compare_doubles(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* ---- many seeds: the variance of the mean and the mean ---- */

static void
test_jittered_variance_of_mean_over_seeds(void **state)
{
    (void)state;
    /* No fireflies here: they are not stratified (they do not depend on the
     * footprint) and would only add their Poisson noise to every variance. */
    mcp_proc_scene s = scene_of(W, H, MCP_PROC_SAMPLER_JITTERED, 4, 0.0);
    mcp_image *truth = NULL, *tvar = NULL, *tvm = NULL;
    truth_or_fail(&s, SPP, &truth, &tvar, &tvm);
    float *val = malloc((size_t)R * NV * sizeof *val);
    assert_non_null(val);
    static double avg[NV], dump_vm[NV];
    memset(avg, 0, sizeof avg);
    memset(dump_vm, 0, sizeof dump_vm);
    for (int r = 0; r < R; r++) {
        mcp_dump *d = render_or_fail(&s, SPP, mcp_proc_realization_seed(31, r));
        memcpy(val + (size_t)r * NV, d->color->data, NV * sizeof *val);
        for (int i = 0; i < NV; i++) {
            avg[i] += d->color->data[i] / (double)R;
            dump_vm[i] += d->var_of_mean->data[i] / (double)R;
        }
        mcp_dump_free(d);
    }

    /* Per pixel: the unbiased spread s2 of its R means against the exact variance of
     * the mean V, both summed over the channels (they move together: the same samples
     * make them). If the means were Gaussian, (R - 1) s2 / V would be chi-square with
     * R - 1 degrees of freedom, and a sum of s2 over pixels, over the sum of V, would
     * be (Satterthwaite) chi-square with nu = (R - 1) (sum V)^2 / sum V^2 degrees of
     * freedom, over nu (counting the three channels as one, which overstates its
     * spread). The tolerance is that distribution's two-sided 1e-6 range (4.9
     * standard deviations: +-2.8% for all pixels, +-2.2% for the edges); over 9 seeds
     * these ratios stayed within 1.5 of its standard deviations. */
    const double n = SPP;
    double all_s2 = 0, all_v = 0, all_v2 = 0, edge_s2 = 0, edge_v = 0, edge_v2 = 0;
    double edge_naive = 0, worst_bias = 0, image_bias[3] = {0}, image_var[3] = {0};
    double dump_sum = 0, dump_expected = 0, exact_sum = 0, naive_sum = 0;
    int edge = 0, outside = 0;
    const double lo = chi2_quantile(R - 1, -3.9) / (R - 1),
                 hi = chi2_quantile(R - 1, 3.9) / (R - 1);
    for (int p = 0; p < W * H; p++) {
        double s2 = 0, v = 0, naive = 0;
        for (int c = 0; c < 3; c++) {
            int i = 3 * p + c;
            double m2 = 0;
            for (int r = 0; r < R; r++) {
                double e = val[(size_t)r * NV + i] - avg[i];
                m2 += e * e;
            }
            s2 += m2 / (R - 1);
            v += tvm->data[i];
            naive += tvar->data[i] / n;
            assert_true(tvm->data[i] > 0.0);
            /* Unbiased: the average of R means within 5 exact standard errors,
             * plus two lit samples' worth for the umbra's border (test_procedural.c
             * explains it), plus float storage. */
            double err = avg[i] - truth->data[i];
            double tol = 5.0 * sqrt(tvm->data[i] / R) + 2.0 * 0.8 / (R * n) + 1e-6;
            worst_bias = fmax(worst_bias, fabs(err) / tol);
            if (!(fabs(err) <= tol))
                fail_msg("pixel (%d, %d), channel %d: average %.6f, truth %.6f, se %.2g",
                         p % W, p / W, c, avg[i], truth->data[i], sqrt(tvm->data[i] / R));
            image_bias[c] += err / (W * H);
            image_var[c] += tvm->data[i] / R / ((double)W * H * W * H);
            /* The dump's variance is the ordinary unbiased sample variance over all n
             * samples, over n. With the per-sample variance sigma2 its expectation is
             * (sigma2 - V) / (n - 1): sigma2 / n when V = sigma2 / n, and more than
             * V whenever the cells' means differ (samples/procedural/README.md). */
            dump_sum += dump_vm[i];
            dump_expected += (tvar->data[i] - tvm->data[i]) / (n - 1);
        }
        all_s2 += s2, all_v += v, all_v2 += v * v;
        exact_sum += v, naive_sum += naive;
        /* Edge pixels: stratification at least halves the variance of the mean (the
         * footprint's share dominates: edges of the checkers, the sheet, the shadow) */
        if (tvar->data[3 * p + 1] / n >= 2.0 * tvm->data[3 * p + 1]) {
            edge++;
            edge_s2 += s2, edge_v += v, edge_v2 += v * v, edge_naive += naive;
        }
        outside += !(s2 / v >= lo && s2 / v <= hi);
    }
    free(val);
    double nu_all = (R - 1) * all_v * all_v / all_v2;
    double nu_edge = (R - 1) * edge_v * edge_v / edge_v2;
    print_message("spread / exact var of mean: all pixels %.4f (nu %.0f, z %.2f), %d "
                  "edge pixels %.4f (nu %.0f, z %.2f); edges: spread / (per-sample "
                  "variance / n) %.3f; pixels outside the chi-square 1e-4 range: %d\n",
                  all_s2 / all_v, nu_all, (all_s2 / all_v - 1) / sqrt(2 / nu_all), edge,
                  edge_s2 / edge_v, nu_edge, (edge_s2 / edge_v - 1) / sqrt(2 / nu_edge),
                  edge_s2 / edge_naive, outside);
    print_message("largest error of the mean / tolerance %.2f; dump var_of_mean / its "
                  "expectation %.4f, / exact %.3f (per-sample / n: %.3f)\n",
                  worst_bias, dump_sum / dump_expected, dump_sum / exact_sum,
                  naive_sum / exact_sum);
    /* edges are a good part of the image (45%), so their sums are nearly normal */
    assert_true(edge > W * H / 5);
    assert_in_range((long)(1e6 * all_s2 / all_v),
                    (long)(1e6 * chi2_quantile(nu_all, -4.9) / nu_all),
                    (long)(1e6 * chi2_quantile(nu_all, 4.9) / nu_all));
    assert_in_range((long)(1e6 * edge_s2 / edge_v),
                    (long)(1e6 * chi2_quantile(nu_edge, -4.9) / nu_edge),
                    (long)(1e6 * chi2_quantile(nu_edge, 4.9) / nu_edge));
    /* and at edges the spread is far below the per-sample variance / n (~0.31) */
    assert_true(edge_s2 < 0.6 * edge_naive);
    /* Per pixel, the chi-square range at a two-sided 1e-4 would leave out ~0.1
     * pixels if the means were Gaussian; ~5.5% (53-60 over 9 seeds) are far from it,
     * where a rare event (a lit sample at the umbra's border, a far hit of the glossy
     * lobe) decides the spread. 9% still catches a wrong variance in a corner of the
     * image; the per-sample variance / n would put the edges (45%) out. */
    assert_true(outside < W * H * 9 / 100);
    for (int c = 0; c < 3; c++) {
        print_message("channel %d: image mean error %.3g, se %.2g\n", c, image_bias[c],
                      sqrt(image_var[c]));
        assert_close(image_bias[c], 0.0, 0.0, 5.0 * sqrt(image_var[c]));
    }
    /* The dumps average R * W * H per-sample variances of 32 samples each: their
     * image mean is its expectation within 0.5% (within 0.13% over 9 seeds); the
     * naive sigma2 / n would be 0.9% low, and the exact V is 29% lower. */
    assert_close(dump_sum / dump_expected, 1.0, 0.0, 0.005);
    assert_true(dump_sum > 1.2 * exact_sum);
    mcp_image_free(truth);
    mcp_image_free(tvar);
    mcp_image_free(tvm);
}

static void
test_jittered_image_mean_with_fireflies(void **state)
{
    (void)state;
    /* With fireflies (the default scene) the renders stay unbiased: per channel, the
     * image mean of R / 4 realizations against the truth's, within 5 exact standard
     * errors of that mean (pixels are independent, so their variances add; the
     * ~3300 fireflies drawn make it nearly normal). */
    enum { RF = R / 4 };
    mcp_proc_scene s = scene_of(W, H, MCP_PROC_SAMPLER_JITTERED, 4, 1e-3);
    mcp_image *truth = NULL, *tvar = NULL, *tvm = NULL;
    truth_or_fail(&s, SPP, &truth, &tvar, &tvm);
    double a[3] = {0}, t[3] = {0}, v[3] = {0};
    for (int r = 0; r < RF; r++) {
        mcp_dump *d = render_or_fail(&s, SPP, mcp_proc_realization_seed(32, r));
        for (int i = 0; i < NV; i++)
            a[i % 3] += d->color->data[i] / ((double)RF * W * H);
        mcp_dump_free(d);
    }
    for (int i = 0; i < NV; i++) {
        t[i % 3] += truth->data[i] / (W * H);
        v[i % 3] += tvm->data[i] / RF / ((double)W * H * W * H);
    }
    for (int c = 0; c < 3; c++) {
        print_message("channel %d: image mean %.6f, truth %.6f, se %.2g\n", c, a[c], t[c],
                      sqrt(v[c]));
        assert_close(a[c], t[c], 0.0, 5.0 * sqrt(v[c]));
    }
    mcp_image_free(truth);
    mcp_image_free(tvar);
    mcp_image_free(tvm);
}

/* ---- the exact variance of the mean ---- */

/* The moments of pixel (x, y) of s, in double: mean and E[Y^2]. */
static void
pixel_moments(const mcp_proc_scene *s, int x, int y, double mean[3], double m2[3])
{
    double var[3];
    if (mcp_proc_truth_pixel(s, x, y, mean, var))
        fail_msg("mcp_proc_truth_pixel: %s", mcp_error_message());
    for (int c = 0; c < 3; c++)
        m2[c] = var[c] + mean[c] * mean[c];
}

/* The checks of test_var_of_mean_against_finer_truths for one scene; returns the
 * largest ratio (sigma2 / n) / V of a pixel. */
static double
check_cells(double firefly_probability)
{
    /* A non-square image (the camera's aspect follows it), k = 4 and three passes.
     * Each cell of pixel (x, y) is computed twice more by hand:
     * (a) as pixel (4x + i, 4y + j) of the 4-times-finer scene, as the library does,
     *     which checks the cell bookkeeping and the formula
     *     V = (1 / P) (1 / k^4) sum over cells of var_cell;
     * (b) as the 2x2 pixels of the 8-times-finer scene, combined by the law of total
     *     variance: a different cut of every cell, so the cells are the sub-squares
     *     they claim to be.
     * And the cells must add up to the pixel: its mean is the mean of theirs, and its
     * per-sample variance is the mean of their variances plus the variance of their
     * means. Every value is an integral exact to ~1e-13 (test_procedural.c); the
     * tolerances are 1e-11 on moments of size ~10 (a firefly's 100^2 * 1e-3). */
    enum { SW = 20, SH = 12, KS = 4, P = 3 };
    const int spp = P * KS * KS;
    const double ff = firefly_probability;
    mcp_proc_scene s = scene_of(SW, SH, MCP_PROC_SAMPLER_JITTERED, KS, ff);
    mcp_proc_scene f4 = scene_of(KS * SW, KS * SH, MCP_PROC_SAMPLER_INDEPENDENT, 4, ff);
    mcp_proc_scene f8 =
        scene_of(2 * KS * SW, 2 * KS * SH, MCP_PROC_SAMPLER_INDEPENDENT, 4, ff);
    mcp_image *img = NULL;
    assert_int_equal(mcp_proc_truth_var_of_mean(&s, spp, &img), 0);
    double worst_a = 0, worst_b = 0, worst_mean = 0, worst_total = 0, gain_max = 0;
    for (int y = 0; y < SH; y++)
        for (int x = 0; x < SW; x++) {
            double v[3], pm[3], pm2[3];
            assert_int_equal(mcp_proc_truth_pixel_var_of_mean(&s, x, y, spp, v), 0);
            pixel_moments(&s, x, y, pm, pm2);
            double sum_a[3] = {0}, sum_b[3] = {0}, cell_mean[3] = {0}, between[3] = {0};
            for (int j = 0; j < KS; j++)
                for (int i = 0; i < KS; i++) {
                    double m[3], m2[3], mb[3] = {0}, m2b[3] = {0};
                    pixel_moments(&f4, KS * x + i, KS * y + j, m, m2);
                    for (int q = 0; q < 4; q++) {
                        double sm[3], sm2[3];
                        pixel_moments(&f8, 2 * (KS * x + i) + q % 2,
                                      2 * (KS * y + j) + q / 2, sm, sm2);
                        for (int c = 0; c < 3; c++)
                            mb[c] += sm[c] / 4, m2b[c] += sm2[c] / 4;
                    }
                    for (int c = 0; c < 3; c++) {
                        sum_a[c] += m2[c] - m[c] * m[c];
                        sum_b[c] += m2b[c] - mb[c] * mb[c];
                        cell_mean[c] += m[c] / (KS * KS);
                        between[c] += (m[c] - pm[c]) * (m[c] - pm[c]) / (KS * KS);
                    }
                }
            for (int c = 0; c < 3; c++) {
                double scale = (double)KS * KS * KS * KS * P;
                double var_pixel = pm2[c] - pm[c] * pm[c];
                worst_a = fmax(worst_a, fabs(sum_a[c] / scale - v[c]));
                worst_b = fmax(worst_b, fabs(sum_b[c] / scale - v[c]));
                worst_mean = fmax(worst_mean, fabs(cell_mean[c] - pm[c]));
                worst_total = fmax(worst_total,
                                   fabs(sum_a[c] / (KS * KS) + between[c] - var_pixel));
                gain_max = fmax(gain_max, var_pixel / spp / v[c]);
                /* the image is the per-pixel value in float */
                assert_true(mcp_image_px(img, x, y)[c] == (float)v[c]);
            }
        }
    print_message(
        "fireflies %g: var of mean vs 4x finer %.2g, vs 8x finer %.2g; "
        "cells' mean %.2g, total variance %.2g; largest (sigma2 / n) / V %.1f\n",
        ff, worst_a, worst_b, worst_mean, worst_total, gain_max);
    /* (a) is the library's own sum, in the same order */
    assert_true(worst_a < 1e-15);
    /* V is ~sigma2 / 48: 1e-11 on the moments is ~2e-13 on it */
    assert_true(worst_b < 2e-13);
    assert_true(worst_mean < 1e-11);
    assert_true(worst_total < 1e-11);
    mcp_image_free(img);
    return gain_max;
}

static void
test_var_of_mean_against_finer_truths(void **state)
{
    (void)state;
    /* with fireflies (large second moments), and without: there edges gain up to
     * k^2 = 16, so the cells' bookkeeping matters */
    check_cells(1e-3);
    assert_true(check_cells(0.0) > 4.0);
}

static void
test_independent_var_of_mean_is_per_sample_over_n(void **state)
{
    (void)state;
    /* The independent sampler, and the jittered one with a single cell (k = 1, the
     * same sampler), have V = sigma2 / n exactly, for any n. */
    mcp_proc_scene ind = scene_of(12, 10, MCP_PROC_SAMPLER_INDEPENDENT, 4, 1e-3);
    mcp_proc_scene one = scene_of(12, 10, MCP_PROC_SAMPLER_JITTERED, 1, 1e-3);
    for (int y = 0; y < 10; y++)
        for (int x = 0; x < 12; x++) {
            double m[3], var[3], v7[3], v1[3];
            assert_int_equal(mcp_proc_truth_pixel(&ind, x, y, m, var), 0);
            assert_int_equal(mcp_proc_truth_pixel_var_of_mean(&ind, x, y, 7, v7), 0);
            assert_int_equal(mcp_proc_truth_pixel_var_of_mean(&one, x, y, 7, v1), 0);
            for (int c = 0; c < 3; c++) {
                assert_true(v7[c] == var[c] / 7);
                assert_true(v1[c] == v7[c]);
            }
        }
    mcp_image *a = NULL, *b = NULL;
    assert_int_equal(mcp_proc_truth_var_of_mean(&ind, 5, &a), 0);
    assert_int_equal(mcp_proc_truth_var_of_mean(&one, 5, &b), 0);
    assert_memory_equal(a->data, b->data, 12 * 10 * 3 * sizeof(float));
    mcp_image_free(a);
    mcp_image_free(b);
}

static void
test_stratification_gain_of_the_default_scene(void **state)
{
    (void)state;
    /* The figures of samples/procedural/README.md: the default scene (64x64) at one
     * pass (the ratios do not depend on n), with and without fireflies, k = 2, 4, 8.
     * "Gain" is
     * (sigma2 / n) / V: the image mean of the numerator over the image mean of V per
     * channel, and per pixel (green) the mean, median and largest ratio and how
     * often it reaches 2. The k = 4 figures are pinned: they are exact (to float). */
    static const double fireflies[2] = {1e-3, 0.0};
    static const int strata[3] = {2, 4, 8};
    static const double pinned_g[2] = {1.001, 1.249}; /* k = 4, green */
    enum { N = 64 * 64 };
    for (int f = 0; f < 2; f++)
        for (int k = 0; k < 3; k++) {
            const int spp = strata[k] * strata[k];
            mcp_proc_scene s =
                scene_of(64, 64, MCP_PROC_SAMPLER_JITTERED, strata[k], fireflies[f]);
            mcp_image *truth = NULL, *tvar = NULL, *tvm = NULL;
            truth_or_fail(&s, spp, &truth, &tvar, &tvm);
            double naive[3] = {0}, exact[3] = {0}, mean_ratio = 0;
            static double ratio[N], sorted[N];
            int above2 = 0;
            for (int p = 0; p < N; p++) {
                for (int c = 0; c < 3; c++) {
                    naive[c] += tvar->data[3 * p + c] / spp;
                    exact[c] += tvm->data[3 * p + c];
                    /* stratification never hurts, pixel by pixel */
                    assert_true(tvm->data[3 * p + c] <=
                                tvar->data[3 * p + c] / spp * (1 + 1e-6));
                }
                ratio[p] = tvar->data[3 * p + 1] / spp / tvm->data[3 * p + 1];
                mean_ratio += ratio[p] / N;
                above2 += ratio[p] >= 2.0;
            }
            memcpy(sorted, ratio, sizeof ratio);
            qsort(sorted, N, sizeof *sorted, compare_doubles);
            double median = 0.5 * (sorted[N / 2 - 1] + sorted[N / 2]),
                   top = sorted[N - 1];
            print_message("fireflies %g, k %d: gain of image means R %.3f, G %.3f, "
                          "B %.3f; per pixel (G) mean %.3f, median %.3f, max %.1f, "
                          ">= 2 in %.1f%% of pixels\n",
                          fireflies[f], strata[k], naive[0] / exact[0],
                          naive[1] / exact[1], naive[2] / exact[2], mean_ratio, median,
                          top, 100.0 * above2 / N);
            if (strata[k] == 4) assert_close(naive[1] / exact[1], pinned_g[f], 0.0, 5e-4);
            mcp_image_free(truth);
            mcp_image_free(tvar);
            mcp_image_free(tvm);
        }
}

/* ---- the independent sampler is unchanged; determinism ---- */

static void
test_independent_sampler_unchanged(void **state)
{
    (void)state;
    /* The independent sampler ignores strata, and the jittered sampler with one cell
     * (k = 1) is the independent sampler bit for bit: the same uniforms, the same
     * footprint point. (test_procedural.c checks the independent sampler's own
     * behaviour, unchanged.) */
    const size_t bytes = (size_t)W * H * 3 * sizeof(float);
    mcp_proc_scene ind = scene_of(W, H, MCP_PROC_SAMPLER_INDEPENDENT, 4, 1e-3);
    mcp_proc_scene ind9 = ind, one = ind, jit = ind;
    ind9.strata = 9;
    one.sampler = jit.sampler = MCP_PROC_SAMPLER_JITTERED;
    one.strata = 1;
    mcp_dump *a = render_or_fail(&ind, 16, 3), *b = render_or_fail(&ind9, 16, 3),
             *c = render_or_fail(&one, 16, 3), *d = render_or_fail(&jit, 16, 3);
    for (int k = 0; k < 2; k++) {
        const mcp_dump *o = k ? c : b;
        assert_memory_equal(a->color->data, o->color->data, bytes);
        assert_memory_equal(a->var_of_mean->data, o->var_of_mean->data, bytes);
        assert_memory_equal(a->albedo->data, o->albedo->data, bytes);
    }
    /* only a jittered dump says so */
    assert_null(mcp_attrs_find(&a->attrs, "mcpost.procedural.sampler"));
    const mcp_attr *at = mcp_attrs_find(&c->attrs, "mcpost.procedural.sampler");
    assert_non_null(at);
    assert_string_equal(at->s, "jittered 1x1");
    at = mcp_attrs_find(&d->attrs, "mcpost.procedural.sampler");
    assert_non_null(at);
    assert_string_equal(at->s, "jittered 4x4");
    /* k = 4 moves the footprint points: every pixel differs */
    int same = 0;
    for (int i = 0; i < W * H * 3; i++)
        same += a->color->data[i] == d->color->data[i];
    assert_true(same < W * H * 3 / 20);
    mcp_dump_free(a);
    mcp_dump_free(b);
    mcp_dump_free(c);
    mcp_dump_free(d);

    mcp_image *sa[2], *sc[2];
    assert_int_equal(mcp_proc_render_samples(&ind, 2, 3, 8, NULL, sa), 0);
    assert_int_equal(mcp_proc_render_samples(&one, 2, 3, 8, NULL, sc), 0);
    for (int k = 0; k < 2; k++) {
        assert_memory_equal(sa[k]->data, sc[k]->data, bytes);
        mcp_image_free(sa[k]);
        mcp_image_free(sc[k]);
    }
    mcp_proc_pixel pa, pc;
    assert_int_equal(mcp_proc_render_pixel(&ind, 5, 6, 7, 8, 3, 4, 11, &pa), 0);
    assert_int_equal(mcp_proc_render_pixel(&one, 5, 6, 7, 8, 3, 4, 11, &pc), 0);
    assert_memory_equal(&pa, &pc, sizeof pa);
}

static void
test_jittered_samples_pixels_and_threads(void **state)
{
    (void)state;
    /* Jittered renders keep the properties of the independent ones: images of whole
     * passes are consecutive samples of the same streams, a pixel rendered alone is
     * the pixel of the image, and nothing depends on the thread count. */
    mcp_proc_scene s = scene_of(37, H, MCP_PROC_SAMPLER_JITTERED, 3, 1e-3);
    mcp_image *two[2];
    mcp_dump *d = render_or_fail(&s, 18, 5);
    assert_int_equal(mcp_proc_render_samples(&s, 2, 9, 5, NULL, two), 0);
    for (int i = 0; i < 37 * H * 3; i++)
        assert_close(0.5 * (two[0]->data[i] + two[1]->data[i]), d->color->data[i], 1e-6,
                     1e-6);
    mcp_proc_pixel p;
    assert_int_equal(mcp_proc_render_pixel(&s, 30, 17, 30, 17, 9, 5, 9, &p), 0);
    for (int c = 0; c < 3; c++)
        assert_true(mcp_image_px(two[1], 30, 17)[c] == (float)p.mean[c]);
    mcp_image_free(two[0]);
    mcp_image_free(two[1]);

    mcp_dump *t[2];
    mcp_image *v[2];
    int saved = omp_get_max_threads();
    for (int k = 0; k < 2; k++) {
        omp_set_num_threads(2 * k + 1);
        t[k] = render_or_fail(&s, 18, 5);
        assert_int_equal(mcp_proc_truth_var_of_mean(&s, 18, &v[k]), 0);
    }
    omp_set_num_threads(saved);
    size_t bytes = (size_t)37 * H * 3 * sizeof(float);
    assert_memory_equal(d->color->data, t[0]->color->data, bytes);
    assert_memory_equal(t[0]->color->data, t[1]->color->data, bytes);
    assert_memory_equal(t[0]->var_of_mean->data, t[1]->var_of_mean->data, bytes);
    assert_memory_equal(v[0]->data, v[1]->data, bytes);
    for (int k = 0; k < 2; k++) {
        mcp_dump_free(t[k]);
        mcp_image_free(v[k]);
    }
    mcp_dump_free(d);
}

/* ---- errors ---- */

static void
test_errors(void **state)
{
    (void)state;
    mcp_proc_scene s = scene_of(16, 16, MCP_PROC_SAMPLER_JITTERED, 4, 1e-3);
    mcp_dump *d = (mcp_dump *)1;
    mcp_image *img = (mcp_image *)1, *imgs[2] = {(mcp_image *)1, (mcp_image *)1};
    mcp_proc_pixel p;
    double v[3];
    assert_error_contains(mcp_proc_render(&s, 24, 1, NULL, &d),
                          "procedural: the jittered sampler takes whole passes of "
                          "strata^2 = 16 samples; spp must be a multiple of 16 (got 24)");
    assert_null(d);
    assert_error_contains(mcp_proc_render_samples(&s, 2, 1, 1, NULL, imgs),
                          "spp must be a multiple of 16 (got 1)");
    assert_null(imgs[0]);
    assert_null(imgs[1]);
    assert_error_contains(mcp_proc_render_pixel(&s, 0, 0, 0, 0, 16, 1, 8, &p),
                          "first_sample must be a multiple of 16 (got 8)");
    assert_error_contains(mcp_proc_render_pixel(&s, 0, 0, 0, 0, 8, 1, 16, &p),
                          "spp must be a multiple of 16 (got 8)");
    assert_error_contains(mcp_proc_truth_var_of_mean(&s, 40, &img),
                          "spp must be a multiple of 16 (got 40)");
    assert_null(img);
    assert_error_contains(mcp_proc_truth_var_of_mean(&s, 0, &img),
                          "procedural: spp must be >= 1 (got 0)");
    assert_error_contains(mcp_proc_truth_pixel_var_of_mean(&s, 16, 0, 16, v),
                          "procedural truth: pixel (16, 0) outside the 16x16 image");
    s.width = 20000;
    assert_error_contains(mcp_proc_truth_var_of_mean(&s, 16, &img),
                          "procedural truth: the cells of 4 strata of a 20000x16 image "
                          "would be pixels of a 80000x64 one, more than 65536 a side");
    s = scene_of(16, 16, MCP_PROC_SAMPLER_JITTERED, 0, 1e-3);
    assert_error_contains(mcp_proc_scene_check(&s),
                          "procedural: strata must be in 1..64 (got 0)");
    s.strata = 65;
    assert_error_contains(mcp_proc_render(&s, 16, 1, NULL, &d), "(got 65)");
    /* strata is checked for the independent sampler too, which otherwise ignores it */
    s.sampler = MCP_PROC_SAMPLER_INDEPENDENT;
    assert_error_contains(mcp_proc_truth_var_of_mean(&s, 16, &img), "strata must be");
    s = scene_of(16, 16, (mcp_proc_sampler)2, 4, 1e-3);
    assert_error_contains(mcp_proc_scene_check(&s),
                          "procedural: sampler must be MCP_PROC_SAMPLER_INDEPENDENT or "
                          "MCP_PROC_SAMPLER_JITTERED (got 2)");
}

/* ---- the command line ---- */

static int
run_cli(const char *args, char **log)
{
    char cmd[8192];
    snprintf(cmd, sizeof cmd, "'%s' %s > '%s' 2>&1", MCP_TEST_PROCEDURAL, args,
             mcp_test_path("cli.log"));
    int rc = system(cmd);
    *log = mcp_test_read_text(mcp_test_path("cli.log"));
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

static mcp_image *
read_rgb(const char *prefix, const char *suffix)
{
    char path[4096];
    mcp_image *img = NULL, *rgb = NULL;
    int idx[3];
    snprintf(path, sizeof path, "%s%s", prefix, suffix);
    if (mcp_image_read(path, NULL, &img) ||
        mcp_image_channels(img, (const char *[]){"R", "G", "B"}, 3, idx) ||
        mcp_image_copy_channels(img, idx, 3, &rgb))
        fail_msg("%s", mcp_error_message());
    mcp_image_free(img);
    return rgb;
}

static void
test_cli_jittered(void **state)
{
    (void)state;
    char args[4096], *log;
    const char *prefix = mcp_test_path("jit");
    snprintf(args, sizeof args,
             "--width 24 --height 16 --spp 18 --seed 42 --sampler jittered --strata 3 "
             "--truth --singles 2 --single-spp 9 -o '%s'",
             prefix);
    assert_int_equal(run_cli(args, &log), 0);
    free(log);
    mcp_proc_scene s = scene_of(24, 16, MCP_PROC_SAMPLER_JITTERED, 3, 1e-3);
    mcp_dump *file = NULL, *mem = render_or_fail(&s, 18, 42);
    snprintf(args, sizeof args, "%s_0000.exr", prefix);
    if (mcp_dump_read(args, &file)) fail_msg("%s", mcp_error_message());
    assert_true(file->spp == 18);
    assert_true(mcp_test_max_abs_diff(file->color, mem->color) == 0);
    /* per-sample variance in the file: * 18 then / 18, in float */
    for (int i = 0; i < 24 * 16 * 3; i++)
        assert_close(file->var_of_mean->data[i], mem->var_of_mean->data[i], 1e-6, 0.0);
    const mcp_attr *at = mcp_attrs_find(&file->attrs, "mcpost.procedural.sampler");
    assert_non_null(at);
    assert_string_equal(at->s, "jittered 3x3");
    mcp_dump_free(file);
    mcp_dump_free(mem);

    mcp_image *vm = NULL, *read = read_rgb(prefix, "_truth_var_of_mean.exr");
    assert_int_equal(mcp_proc_truth_var_of_mean(&s, 18, &vm), 0);
    assert_true(mcp_test_max_abs_diff(read, vm) == 0);
    mcp_image_free(read);
    mcp_image_free(vm);
    mcp_image *single[2];
    assert_int_equal(mcp_proc_render_samples(&s, 2, 9, 42, NULL, single), 0);
    read = read_rgb(prefix, "_single_0001.exr");
    assert_true(mcp_test_max_abs_diff(read, single[1]) == 0);
    mcp_image_free(read);
    mcp_image_free(single[0]);
    mcp_image_free(single[1]);

    /* the independent sampler's var_of_mean truth is the per-sample variance / spp */
    prefix = mcp_test_path("ind");
    snprintf(args, sizeof args,
             "--width 8 --height 8 --spp 5 --realizations 0 --truth -o '%s'", prefix);
    assert_int_equal(run_cli(args, &log), 0);
    free(log);
    vm = read_rgb(prefix, "_truth_var_of_mean.exr");
    read = read_rgb(prefix, "_truth_variance.exr");
    for (int i = 0; i < 8 * 8 * 3; i++)
        assert_close(vm->data[i], read->data[i] / 5.0, 1e-6, 0.0);
    mcp_image_free(vm);
    mcp_image_free(read);

    static const struct {
        const char *args, *message;
    } bad[] = {
        {"--sampler sobol -o x",
         "--sampler must be independent or jittered (got 'sobol')"},
        {"--sampler -o x", "--sampler must be independent or jittered (got '-o')"},
        {"--sampler jittered --spp 24 -o x",
         "mcpost-procedural: --spp must be a multiple of --strata^2 = 16 with the "
         "jittered sampler (got 24)"},
        {"--sampler jittered --strata 2 --spp 8 --singles 2 -o x",
         "--single-spp must be a multiple of --strata^2 = 4 with the jittered sampler "
         "(got 1)"},
        {"--strata 0 -o x", "--strata must be an integer >= 1 (got '0')"},
        {"--strata 65 -o x", "strata must be in 1..64 (got 65)"},
    };
    for (size_t k = 0; k < sizeof bad / sizeof *bad; k++) {
        assert_int_equal(run_cli(bad[k].args, &log), 1);
        if (!strstr(log, bad[k].message))
            fail_msg("'%s' printed '%s', not '%s'", bad[k].args, log, bad[k].message);
        free(log);
    }
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_jittered_variance_of_mean_over_seeds),
        cmocka_unit_test(test_jittered_image_mean_with_fireflies),
        cmocka_unit_test(test_var_of_mean_against_finer_truths),
        cmocka_unit_test(test_independent_var_of_mean_is_per_sample_over_n),
        cmocka_unit_test(test_stratification_gain_of_the_default_scene),
        cmocka_unit_test(test_independent_sampler_unchanged),
        cmocka_unit_test(test_jittered_samples_pixels_and_threads),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_cli_jittered),
    };
    return cmocka_run_group_tests_name("samples/procedural (jittered)", tests, NULL,
                                       NULL);
}
