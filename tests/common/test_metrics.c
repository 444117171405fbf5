/* test_metrics.c: common/metrics/metrics.c and common/filter/tonemap.c against closed
 * forms on small constructed images (docs/mathematics.md §5, §4). */
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>
#include <mcpost/imageio.h>
#include <mcpost/metrics.h>
#include <mcpost/tonemap.h>

#define PI_D 3.14159265358979323846

static const char *const RGB[] = {"R", "G", "B"};

static void
test_identical_all_zero(void **state)
{
    (void)state;
    mcp_image *a = mcp_test_random(23, 19, 3, 0.0f, 3.0f, 1, RGB);
    mcp_metrics m;
    mcp_metrics_maps maps;
    /* pMSE is 0 for identical images when both sides are filtered (h = g); with the
     * default h = delta it is |g * T(I) - T(I)|^2, checked in test_pmse_closed_form. */
    mcp_metrics_options o = mcp_metrics_defaults();
    o.pmse.filter_reference = 1;
    assert_int_equal(mcp_metrics_compute(a, a, &o, &m, &maps), 0);
    assert_true(m.mse == 0 && m.rmse == 0 && m.relmse == 0 && m.pmse == 0);
    assert_true(isinf(m.psnr) && m.psnr > 0);
    assert_int_equal(m.n_percentiles, 3);
    for (int k = 0; k < 3; k++)
        assert_true(m.relse[k] == 0);
    assert_true(m.has_flip_ldr && m.has_flip_hdr);
    assert_true(m.flip_ldr.mean == 0 && m.flip_hdr.mean == 0);
    assert_int_equal(m.n_values, 23 * 19 * 3);
    assert_non_null(maps.sq_error);
    assert_non_null(maps.relse);
    assert_non_null(maps.flip_ldr);
    assert_non_null(maps.flip_hdr);
    assert_non_null(maps.flip_hdr_exposure);
    for (int i = 0; i < 23 * 19 * 3; i++)
        assert_true(maps.sq_error->data[i] == 0 && maps.relse->data[i] == 0);
    mcp_metrics_maps_free(&maps);
    mcp_image_free(a);
}

static void
test_mse_relmse_closed_form(void **state)
{
    (void)state;
    /* 2x2 reference (0.5 everywhere); test differs by 0.1, -0.2, 0.3, 0 on pixel k,
     * channel k % 3 only. */
    mcp_image *ref = mcp_test_constant(2, 2, 3, 0.5f, RGB);
    mcp_image *test = mcp_test_constant(2, 2, 3, 0.5f, RGB);
    const double d[4] = {0.1, -0.2, 0.3, 0.0};
    for (int k = 0; k < 4; k++)
        mcp_image_px(test, k % 2, k / 2)[k % 3] = (float)(0.5 + d[k]);
    double sum = 0;
    for (int k = 0; k < 4; k++) {
        double dk = (float)(0.5 + d[k]) - 0.5; /* the float the image holds */
        sum += dk * dk;
    }
    double mse, relmse;
    assert_int_equal(mcp_mse(test, ref, &mse), 0);
    assert_close(mse, sum / 12, 1e-12, 0);
    assert_int_equal(mcp_relmse(test, ref, MCP_EPS_REL, &relmse), 0);
    assert_close(relmse, sum / (0.25 + 0.01) / 12, 1e-12, 0);
    /* Swapping the roles changes relMSE (it divides by the reference). */
    assert_int_equal(mcp_relmse(ref, test, MCP_EPS_REL, &relmse), 0);
    double sw = 0;
    for (int k = 0; k < 4; k++) {
        double t = (float)(0.5 + d[k]), dk = 0.5 - t;
        sw += dk * dk / (t * t + 0.01);
    }
    assert_close(relmse, sw / 12, 1e-12, 0);
    mcp_metrics m;
    assert_int_equal(mcp_metrics_compute(test, ref, NULL, &m, NULL), 0);
    assert_close(m.mse, sum / 12, 1e-12, 0);
    assert_close(m.rmse, sqrt(sum / 12), 1e-12, 0);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_psnr_8bit(void **state)
{
    (void)state;
    /* 8-bit grey 128 vs 140, decoded to linear as a PNG read would: PSNR of the file
     * values is 20 log10(255 / 12). */
    float a = mcp_srgb_to_linear(128.0f / 255.0f),
          b = mcp_srgb_to_linear(140.0f / 255.0f);
    mcp_image *ref = mcp_test_constant(5, 4, 3, a, RGB);
    mcp_image *test = mcp_test_constant(5, 4, 3, b, RGB);
    double psnr;
    assert_int_equal(mcp_psnr(test, ref, &psnr), 0);
    assert_close(psnr, 20 * log10(255.0 / 12.0), 0, 1e-4);
    /* HDR values clamp to 1 for display: 2 vs 3 are the same white. */
    mcp_image *w2 = mcp_test_constant(5, 4, 3, 2.0f, RGB);
    mcp_image *w3 = mcp_test_constant(5, 4, 3, 3.0f, RGB);
    assert_int_equal(mcp_psnr(w2, w3, &psnr), 0);
    assert_true(isinf(psnr));
    mcp_image_free(w2);
    mcp_image_free(w3);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_pmse_closed_form(void **state)
{
    (void)state;
    /* Constants: every kernel has unit sum, so pMSE = (T(a) - T(b))^2. */
    mcp_image *ca = mcp_test_constant(9, 7, 3, 0.3f, RGB);
    mcp_image *cb = mcp_test_constant(9, 7, 3, 0.7f, RGB);
    mcp_pmse_options o = mcp_pmse_defaults();
    double p;
    assert_int_equal(mcp_pmse(ca, cb, &o, &p), 0);
    assert_close(p, 0.16, 1e-6, 0);
    o.filter_reference = 1;
    assert_int_equal(mcp_pmse(ca, cb, &o, &p), 0);
    assert_close(p, 0.16, 1e-6, 0);
    o.tone_map = MCP_TONEMAP_ACES;
    assert_int_equal(mcp_pmse(ca, cb, &o, &p), 0);
    /* Narkowicz's ACES fit x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14). */
    double ta = 0.3 * (2.51 * 0.3 + 0.03) / (0.3 * (2.43 * 0.3 + 0.59) + 0.14);
    double tb = 0.7 * (2.51 * 0.7 + 0.03) / (0.7 * (2.43 * 0.7 + 0.59) + 0.14);
    assert_close(p, (ta - tb) * (ta - tb), 1e-5, 0);

    /* An impulse v at an interior pixel of channel G against 0, h = delta:
     * E = v^2 (sum_i g_i^2)^2 (the 2D kernel is the outer product). */
    mcp_image *imp = mcp_test_constant(11, 9, 3, 0.0f, RGB);
    mcp_image *zero = mcp_test_constant(11, 9, 3, 0.0f, RGB);
    mcp_image_px(imp, 5, 4)[1] = 2.0f;
    double g0 = 1 / PI_D, g1 = 1 - 2 / PI_D, s2 = 2 * g0 * g0 + g1 * g1;
    o = mcp_pmse_defaults();
    o.tone_map = MCP_TONEMAP_NONE;
    assert_int_equal(mcp_pmse(imp, zero, &o, &p), 0);
    assert_close(p, 4.0 * s2 * s2 / (11 * 9 * 3), 1e-6, 0);
    o.tone_map = MCP_TONEMAP_CLAMP; /* 2 clamps to 1 */
    assert_int_equal(mcp_pmse(imp, zero, &o, &p), 0);
    assert_close(p, 1.0 * s2 * s2 / (11 * 9 * 3), 1e-6, 0);
    /* h = g on both: the same impulse filtered on each side cancels nothing here
     * (the reference is 0), so the value is unchanged. */
    o.filter_reference = 1;
    assert_int_equal(mcp_pmse(imp, zero, &o, &p), 0);
    assert_close(p, 1.0 * s2 * s2 / (11 * 9 * 3), 1e-6, 0);
    /* Identical impulses with h = g give 0; with h = delta they do not. */
    assert_int_equal(mcp_pmse(imp, imp, &o, &p), 0);
    assert_close(p, 0, 0, 1e-15);
    o.filter_reference = 0;
    assert_int_equal(mcp_pmse(imp, imp, &o, &p), 0);
    /* |g*x - x|^2 for a unit impulse: (sum g_i g_j)^2 over (i,j) != centre plus
     * (g1^2 - 1)^2 at the centre. */
    double e = s2 * s2 - g1 * g1 * g1 * g1 + (g1 * g1 - 1) * (g1 * g1 - 1);
    assert_close(p, e / (11 * 9 * 3), 1e-6, 0);
    mcp_image_free(imp);
    mcp_image_free(zero);
    mcp_image_free(ca);
    mcp_image_free(cb);
}

static void
test_pkernel(void **state)
{
    (void)state;
    /* Chizhov et al. Sec. 8: the 3-tap kernel's sigma sqrt(2/pi) corresponds to
     * D = 4792 / R inches (Eq. 11 inverted). */
    assert_close(mcp_pkernel_sigma_px(300, 4792.0 / 300), sqrt(2 / PI_D), 1e-3, 0);
    mcp_pkernel k = mcp_pkernel_defaults();
    double *taps = NULL;
    int r;
    assert_int_equal(mcp_pkernel_taps(&k, &taps, &r), 0);
    assert_int_equal(r, 1);
    assert_close(taps[0], 1 / PI_D, 1e-15, 0);
    assert_close(taps[1], 1 - 2 / PI_D, 1e-15, 0);
    /* variance 2/pi */
    assert_close(2 * taps[0], 2 / PI_D, 1e-15, 0);
    free(taps);
    k.kind = MCP_PKERNEL_GAUSSIAN;
    k.dpi = 300;
    k.distance_in = 40;
    assert_int_equal(mcp_pkernel_taps(&k, &taps, &r), 0);
    double sigma = mcp_pkernel_sigma_px(300, 40), sum = 0, var = 0;
    assert_int_equal(r, (int)ceil(3 * sigma));
    for (int i = -r; i <= r; i++) {
        sum += taps[i + r];
        var += i * i * taps[i + r];
    }
    assert_close(sum, 1, 1e-12, 0);
    assert_close(var, sigma * sigma, 0.02, 0); /* truncated at 3 sigma */
    free(taps);
    k.dpi = 0;
    assert_error_contains(mcp_pkernel_taps(&k, &taps, &r),
                          "pkernel: dpi must be > 0 (got 0)");
    k.dpi = 300;
    k.distance_in = -1;
    assert_error_contains(mcp_pkernel_taps(&k, &taps, &r),
                          "pkernel: distance_in must be > 0 (got -1)");
    mcp_pkernel_kind kind;
    assert_error_contains(mcp_pkernel_kind_from_name("box", &kind),
                          "unknown perceptual kernel 'box'");
}

static void
test_tonemaps(void **state)
{
    (void)state;
    mcp_tonemap tm;
    assert_int_equal(mcp_tonemap_from_name("ACES", &tm), 0);
    assert_int_equal(tm, MCP_TONEMAP_ACES);
    assert_error_contains(mcp_tonemap_from_name("filmic", &tm),
                          "unknown tone map 'filmic'");
    assert_true(mcp_tonemap_value(MCP_TONEMAP_CLAMP, 1.5f) == 1.0f);
    assert_true(mcp_tonemap_value(MCP_TONEMAP_CLAMP, -0.5f) == 0.0f);
    assert_true(mcp_tonemap_value(MCP_TONEMAP_CLAMP, NAN) == 0.0f);
    assert_true(mcp_tonemap_value(MCP_TONEMAP_NONE, -0.5f) == -0.5f);
    assert_close(mcp_tonemap_value(MCP_TONEMAP_REINHARD, 3.0f), 0.75, 1e-7, 0);
    /* Hable: the FLIP rational with white 11.2 maps 11.2 to 1. */
    assert_close(mcp_tonemap_value(MCP_TONEMAP_HABLE, 11.2f), 1.0, 2e-5, 0);
    /* Slopes against central differences, inside the unclamped range. */
    const mcp_tonemap all[4] = {MCP_TONEMAP_NONE, MCP_TONEMAP_ACES, MCP_TONEMAP_HABLE,
                                MCP_TONEMAP_REINHARD};
    for (int i = 0; i < 4; i++)
        for (float x = 0.05f; x < 2.0f; x += 0.3f) {
            double h = 1e-3;
            double fd = (mcp_tonemap_value(all[i], x + (float)h) -
                         mcp_tonemap_value(all[i], x - (float)h)) /
                        (2 * h);
            assert_close(mcp_tonemap_slope(all[i], x), fd, 2e-3, 2e-4);
        }
    assert_true(mcp_tonemap_slope(MCP_TONEMAP_CLAMP, 2.0f) == 0.0f);
    mcp_image *img = mcp_test_constant(3, 2, 4, 2.0f, NULL), *out = NULL;
    assert_int_equal(mcp_tonemap_apply(img, MCP_TONEMAP_REINHARD, &out), 0);
    assert_int_equal(out->channels, 4);
    assert_close(out->data[5], 2.0 / 3.0, 1e-6, 0);
    mcp_image_free(out);
    mcp_image_free(img);
}

static void
test_relse_percentiles(void **state)
{
    (void)state;
    /* 10x1: test 1 everywhere (maxc 1, denominator 1.01); reference 1 - i/10 in every
     * channel, so RelSE = (i/10)^2 / 1.01, each value three times (30 values). */
    mcp_image *test = mcp_test_constant(10, 1, 3, 1.0f, RGB);
    mcp_image *ref = mcp_test_constant(10, 1, 3, 0.0f, RGB);
    for (int i = 0; i < 10; i++)
        for (int c = 0; c < 3; c++)
            mcp_image_px(ref, i, 0)[c] = (float)(1.0 - i / 10.0);
    mcp_metrics_options o = mcp_metrics_defaults();
    const double p[5] = {0.0, 0.5, 0.9, 0.95, 1.0};
    assert_int_equal(mcp_metrics_set_percentiles(&o, p, 5), 0);
    o.flip_ldr = o.flip_hdr = 0;
    mcp_metrics m;
    assert_int_equal(mcp_metrics_compute(test, ref, &o, &m, NULL), 0);
    assert_false(m.has_flip_ldr || m.has_flip_hdr);
    /* nearest rank: index ceil(30 p) - 1 -> i = index / 3 */
    const int idx[5] = {0, 14, 26, 28, 29};
    for (int k = 0; k < 5; k++) {
        double ri = (float)(1.0 - (idx[k] / 3) / 10.0);
        double expect = (1 - ri) * (1 - ri) / 1.01;
        assert_close(m.relse[k], expect, 1e-6, 1e-9);
    }
    /* maxc comes from the test image: a test pixel (2, 0, 0) has denominator 4.01. */
    mcp_image *t2 = mcp_test_constant(1, 1, 3, 0.0f, RGB);
    mcp_image *r2 = mcp_test_constant(1, 1, 3, 0.0f, RGB);
    mcp_image_px(t2, 0, 0)[0] = 2.0f;
    mcp_image_px(r2, 0, 0)[1] = 1.0f;
    mcp_image *map = NULL;
    assert_int_equal(mcp_relse_map(t2, r2, MCP_EPS_REL, &map), 0);
    assert_close(map->data[0], 4.0 / 4.01, 1e-6, 0);
    assert_close(map->data[1], 1.0 / 4.01, 1e-6, 0);
    assert_close(map->data[2], 0.0, 0, 0);
    mcp_image_free(map);
    mcp_image_free(t2);
    mcp_image_free(r2);
    mcp_image_free(test);
    mcp_image_free(ref);
}

static void
test_channel_names(void **state)
{
    (void)state;
    /* Lower-case names and extra channels are accepted; order follows the names. */
    mcp_image *a =
        mcp_test_constant(4, 4, 4, 0.0f, (const char *const[]){"a", "b", "g", "r"});
    mcp_image *b = mcp_test_constant(4, 4, 3, 0.0f, RGB);
    for (int i = 0; i < 16; i++) {
        a->data[4 * i + 3] = 1.0f; /* r */
        b->data[3 * i + 0] = 1.0f; /* R */
    }
    double mse;
    assert_int_equal(mcp_mse(a, b, &mse), 0);
    assert_close(mse, 0, 0, 0);
    mcp_image_free(a);
    mcp_image_free(b);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_image *a = mcp_test_constant(8, 8, 3, 0.5f, RGB);
    mcp_image *b = mcp_test_constant(8, 9, 3, 0.5f, RGB);
    mcp_image *rb = mcp_test_constant(8, 8, 2, 0.5f, (const char *const[]){"R", "B"});
    mcp_image_set_source(a, "test.exr");
    mcp_image_set_source(b, "ref.exr");
    mcp_image_set_source(rb, "rb.png");
    double v;
    mcp_metrics m;
    mcp_metrics_maps maps;
    assert_error_contains(mcp_mse(a, b, &v),
                          "test.exr: size 8x8 does not match ref.exr (8x9)");
    assert_error_contains(mcp_relmse(a, b, 0.01, &v), "does not match");
    assert_error_contains(mcp_psnr(a, b, &v), "does not match");
    assert_error_contains(mcp_pmse(a, b, NULL, &v), "does not match");
    assert_error_contains(mcp_metrics_compute(a, b, NULL, &m, &maps), "does not match");
    assert_null(maps.relse);
    assert_error_contains(mcp_mse(a, rb, &v), "rb.png: no channel 'G'");
    mcp_image *nan = NULL;
    assert_int_equal(mcp_image_copy(a, &nan), 0);
    mcp_image_set_source(nan, "nan.exr");
    mcp_image_px(nan, 1, 2)[1] = NAN;
    assert_error_contains(mcp_mse(nan, a, &v),
                          "nan.exr: non-finite value nan at pixel (1, 2) channel G");
    mcp_image_px(nan, 1, 2)[1] = -INFINITY;
    assert_error_contains(mcp_metrics_compute(a, nan, NULL, &m, NULL),
                          "nan.exr: non-finite value -inf at pixel (1, 2) channel G");
    assert_error_contains(mcp_relmse(a, a, 0, &v),
                          "metrics: eps_rel must be > 0 (got 0)");
    mcp_metrics_options o = mcp_metrics_defaults();
    const double bad[1] = {1.5};
    assert_error_contains(mcp_metrics_set_percentiles(&o, bad, 1),
                          "percentiles: each p must be in [0, 1] (got 1.5)");
    assert_error_contains(mcp_metrics_set_percentiles(&o, bad, 0),
                          "percentiles: give 1 to 64 values (got 0)");
    o.percentiles[1] = -0.1;
    assert_error_contains(mcp_metrics_compute(a, a, &o, &m, NULL),
                          "percentiles: each p must be in [0, 1] (got -0.1)");
    o = mcp_metrics_defaults();
    o.pmse.kernel.kind = MCP_PKERNEL_GAUSSIAN;
    o.pmse.kernel.dpi = -3;
    assert_error_contains(mcp_metrics_compute(a, a, &o, &m, NULL),
                          "pkernel: dpi must be > 0 (got -3)");
    o = mcp_metrics_defaults();
    o.flip.ppd = -2;
    assert_error_contains(mcp_metrics_compute(a, a, &o, &m, NULL),
                          "flip: ppd must be in");
    double pct;
    mcp_image_px(nan, 1, 2)[1] = NAN;
    assert_error_contains(mcp_image_percentiles(nan, (const double[]){0.5}, 1, &pct),
                          "nan.exr: NaN value");
    mcp_image_free(nan);
    mcp_image_free(rb);
    mcp_image_free(b);
    mcp_image_free(a);
}

/* mcp_metrics_compute's one fused pass gives the single metrics' values bit for bit, and
 * the maps of mcp_relse_map and (t - r)². */
static void
test_fused_matches_single(void **state)
{
    (void)state;
    mcp_image *t = mcp_test_random(70, 41, 3, 0.0f, 2.0f, 11, RGB);
    mcp_image *r = mcp_test_random(70, 41, 3, 0.0f, 2.0f, 12, RGB);
    mcp_metrics m;
    mcp_metrics_maps maps;
    mcp_metrics_options o = mcp_metrics_defaults();
    assert_int_equal(mcp_metrics_compute(t, r, &o, &m, &maps), 0);
    double mse, relmse, psnr;
    assert_int_equal(mcp_mse(t, r, &mse), 0);
    assert_int_equal(mcp_relmse(t, r, o.eps_rel, &relmse), 0);
    assert_int_equal(mcp_psnr(t, r, &psnr), 0);
    assert_memory_equal(&m.mse, &mse, sizeof mse);
    assert_memory_equal(&m.relmse, &relmse, sizeof relmse);
    assert_memory_equal(&m.psnr, &psnr, sizeof psnr);
    mcp_image *relse = NULL;
    assert_int_equal(mcp_relse_map(t, r, o.eps_rel, &relse), 0);
    assert_memory_equal(maps.relse->data, relse->data, 70 * 41 * 3 * sizeof(float));
    for (int i = 0; i < 70 * 41 * 3; i++) {
        double d = (double)t->data[i] - r->data[i];
        assert_true(maps.sq_error->data[i] == (float)(d * d));
    }
    mcp_image_free(relse);
    mcp_metrics_maps_free(&maps);
    mcp_image_free(r);
    mcp_image_free(t);
}

/* ---- the command line and the job stage ---- */

static char out_buf[1 << 16], err_buf[1 << 14];

static const char *
write_exr(const char *name, mcp_image *img)
{
    const char *path = mcp_test_path(name);
    assert_int_equal(mcp_image_write(img, path, NULL), 0);
    mcp_image_free(img);
    return path;
}

static void
test_cli(void **state)
{
    (void)state;
    char test_path[4200], ref_path[4200], args[9000];
    mcp_image *ref = mcp_test_random(40, 36, 3, 0.0f, 2.0f, 3, RGB), *test = NULL;
    assert_int_equal(mcp_image_copy(ref, &test), 0);
    for (int i = 0; i < 40 * 36 * 3; i += 7)
        test->data[i] *= 1.5f;
    mcp_metrics expect;
    assert_int_equal(mcp_metrics_compute(test, ref, NULL, &expect, NULL), 0);
    snprintf(test_path, sizeof test_path, "%s", write_exr("cli_test.exr", test));
    snprintf(ref_path, sizeof ref_path, "%s", write_exr("cli_ref.exr", ref));

    snprintf(args, sizeof args, "metrics '%s' '%s' --json", test_path, ref_path);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    cJSON *doc = cJSON_Parse(out_buf);
    assert_non_null(doc);
    assert_close(cJSON_GetObjectItem(doc, "mse")->valuedouble, expect.mse, 1e-12, 0);
    assert_close(cJSON_GetObjectItem(doc, "relmse")->valuedouble, expect.relmse, 1e-12,
                 0);
    assert_close(
        cJSON_GetObjectItem(cJSON_GetObjectItem(doc, "flip_hdr"), "mean")->valuedouble,
        expect.flip_hdr.mean, 0, 1e-15);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(
                         cJSON_GetObjectItem(doc, "relse_percentiles"), "value")),
                     3);
    cJSON_Delete(doc);

    /* Options, the table, and maps. */
    const char *dir = mcp_test_path("cli_maps");
    snprintf(args, sizeof args,
             "metrics '%s' '%s' --ppd 30 --tone-mapper reinhard --num-exposures 3 "
             "--percentiles 0.25,0.75 --pmse-kernel gaussian --pmse-dpi 100 "
             "--pmse-distance-in 30 --flip hdr -o '%s'",
             test_path, ref_path, dir);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    assert_non_null(strstr(out_buf, "RelSE p25"));
    assert_non_null(strstr(out_buf, "RelSE p75"));
    assert_non_null(strstr(out_buf, "(reinhard, exposures"));
    assert_non_null(strstr(out_buf, "in 3 steps"));
    assert_null(strstr(out_buf, "LDR-FLIP"));
    assert_non_null(strstr(out_buf, "g gaussian"));
    const char *files[] = {"flip_hdr.exr", "flip_hdr.png", "flip_hdr_exposure.png",
                           "relse.exr",    "relse.png",    "sq_error.exr",
                           "spectra.png",  "metrics.json"};
    for (int i = 0; i < 8; i++) {
        char path[4300];
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        FILE *f = fopen(path, "rb");
        assert_non_null(f);
        fclose(f);
    }
    mcp_image *map = NULL;
    char path[4300];
    snprintf(path, sizeof path, "%s/flip_hdr.exr", dir);
    assert_int_equal(mcp_image_read(path, NULL, &map), 0);
    assert_int_equal(map->channels, 1);
    assert_string_equal(map->names[0], "FLIP");
    mcp_image_free(map);

    /* Errors: one line naming the file, exit status 1. */
    char other[4200], nan_path[4200], xy_path[4200];
    snprintf(other, sizeof other, "%s",
             write_exr("cli_small.exr", mcp_test_constant(8, 8, 3, 0.5f, RGB)));
    mcp_image *bad = mcp_test_constant(40, 36, 3, 0.5f, RGB);
    mcp_image_px(bad, 4, 5)[2] = NAN;
    snprintf(nan_path, sizeof nan_path, "%s", write_exr("cli_nan.exr", bad));
    snprintf(xy_path, sizeof xy_path, "%s",
             write_exr("cli_xy.exr", mcp_test_constant(40, 36, 2, 0.5f,
                                                       (const char *const[]){"X", "Y"})));
    snprintf(args, sizeof args, "metrics '%s' '%s'", test_path, other);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 1);
    assert_non_null(strstr(err_buf, "cli_test.exr: size 40x36 does not match"));
    assert_non_null(strstr(err_buf, "cli_small.exr (8x8)"));
    snprintf(args, sizeof args, "metrics '%s' '%s'", nan_path, ref_path);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 1);
    assert_non_null(
        strstr(err_buf, "cli_nan.exr: non-finite value nan at pixel (4, 5) channel B"));
    snprintf(args, sizeof args, "metrics '%s' '%s'", xy_path, ref_path);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 1);
    assert_non_null(strstr(err_buf, "cli_xy.exr: no channel 'R'"));
    snprintf(args, sizeof args, "metrics '%s' '%s' --tone-mapper clamp", test_path,
             ref_path);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 1);
    assert_non_null(
        strstr(err_buf, "tone mapper must be aces, hable or reinhard (got 'clamp')"));
    snprintf(args, sizeof args, "metrics '%s' '%s' --percentiles 0.5,2", test_path,
             ref_path);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 1);
    assert_non_null(
        strstr(err_buf, "metrics: --percentiles must be >= 0 and <= 1 (got 2)"));
    snprintf(args, sizeof args, "metrics '%s'", test_path);
    assert_int_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 2);
    assert_non_null(strstr(err_buf, "give TEST... and REF"));
}

static void
test_job_stage(void **state)
{
    (void)state;
    char dir[4200], job[4200], text[12000], args[9000];
    snprintf(dir, sizeof dir, "%s", mcp_test_path("job"));
    snprintf(args, sizeof args, "mkdir -p '%s'", dir);
    assert_int_equal(system(args), 0);
    mcp_image *ref = mcp_test_random(48, 40, 3, 0.0f, 1.5f, 8, RGB), *test = NULL;
    assert_int_equal(mcp_image_copy(ref, &test), 0);
    for (int i = 0; i < 48 * 40 * 3; i += 5)
        test->data[i] += 0.3f;
    char p[4300];
    snprintf(p, sizeof p, "%s/test.exr", dir);
    assert_int_equal(mcp_image_write(test, p, NULL), 0);
    snprintf(p, sizeof p, "%s/ref.exr", dir);
    assert_int_equal(mcp_image_write(ref, p, NULL), 0);
    /* The estimate: the true RelSE scaled by 2 (an overestimate by 2x). */
    mcp_image *relse = NULL;
    assert_int_equal(mcp_relse_map(test, ref, MCP_EPS_REL, &relse), 0);
    for (int i = 0; i < 48 * 40 * 3; i++)
        relse->data[i] *= 2.0f;
    snprintf(p, sizeof p, "%s/est.exr", dir);
    assert_int_equal(mcp_image_write(relse, p, NULL), 0);
    mcp_image_free(relse);
    mcp_image_free(test);
    mcp_image_free(ref);
    /* A series: the pbrt convention with two members. */
    snprintf(job, sizeof job, "%s/job.yaml", dir);
    snprintf(text, sizeof text,
             "inputs:\n"
             "  t: {image: test.exr}\n"
             "  r: {image: ref.exr}\n"
             "  e: {image: est.exr}\n"
             "output: out\n"
             "stages:\n"
             "  - metrics:\n"
             "      input: t\n"
             "      reference: r\n"
             "      estimate: e\n"
             "      percentiles: [0.5, 0.99]\n"
             "      ppd: 40\n"
             "      flip: ldr\n"
             "      output: maps\n");
    mcp_test_write_text(job, text);
    snprintf(args, sizeof args, "run '%s'", job);
    int rc = mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf);
    if (rc) print_message("stderr: %s\n", err_buf);
    assert_int_equal(rc, 0);
    snprintf(p, sizeof p, "%s/out/report.json", dir);
    char *json = mcp_test_read_text(p);
    cJSON *doc = cJSON_Parse(json);
    free(json);
    const cJSON *sec = cJSON_GetArrayItem(cJSON_GetObjectItem(doc, "sections"), 0);
    assert_string_equal(cJSON_GetObjectItem(sec, "stage")->valuestring, "metrics");
    assert_non_null(cJSON_GetObjectItem(sec, "flip_ldr"));
    assert_null(cJSON_GetObjectItem(sec, "flip_hdr"));
    assert_close(
        cJSON_GetObjectItem(cJSON_GetObjectItem(sec, "flip_ldr"), "ppd")->valuedouble, 40,
        1e-6, 0);
    const cJSON *plot = cJSON_GetArrayItem(cJSON_GetObjectItem(sec, "plots"), 0);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(plot, "series")), 2);
    /* The dashed estimate lies at twice the truth at every percentile. */
    const cJSON *st = cJSON_GetArrayItem(cJSON_GetObjectItem(plot, "series"), 0);
    const cJSON *se = cJSON_GetArrayItem(cJSON_GetObjectItem(plot, "series"), 1);
    assert_true(cJSON_IsTrue(cJSON_GetObjectItem(se, "dashed")));
    for (int i = 0; i < cJSON_GetArraySize(cJSON_GetObjectItem(st, "y")); i++)
        assert_close(cJSON_GetArrayItem(cJSON_GetObjectItem(se, "y"), i)->valuedouble,
                     2 * cJSON_GetArrayItem(cJSON_GetObjectItem(st, "y"), i)->valuedouble,
                     1e-6, 0);
    assert_true(cJSON_GetArraySize(cJSON_GetObjectItem(sec, "images")) ==
                5); /* test, reference, LDR-FLIP, RelSE, spectra */
    cJSON_Delete(doc);
    snprintf(p, sizeof p, "%s/out/report.html", dir);
    char *html = mcp_test_read_text(p);
    assert_non_null(strstr(html, "<svg"));
    assert_non_null(strstr(html, "data:image/png;base64,"));
    free(html);
    snprintf(p, sizeof p, "%s/out/maps/flip_ldr.png", dir);
    FILE *f = fopen(p, "rb");
    assert_non_null(f);
    fclose(f);

    /* An unknown key fails at its line; so does a bad value. */
    snprintf(text, sizeof text,
             "inputs:\n  t: {image: test.exr}\n  r: {image: ref.exr}\nstages:\n"
             "  - metrics:\n      input: t\n      reference: r\n      bogus: 1\n");
    mcp_test_write_text(job, text);
    assert_int_not_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    assert_non_null(strstr(err_buf, "job.yaml:8:"));
    assert_non_null(strstr(err_buf, "bogus"));
    snprintf(text, sizeof text,
             "inputs:\n  t: {image: test.exr}\n  r: {image: ref.exr}\nstages:\n"
             "  - metrics:\n      input: t\n      reference: r\n"
             "      tone_mapper: filmic\n");
    mcp_test_write_text(job, text);
    assert_int_not_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    assert_non_null(strstr(err_buf, "job.yaml:8: unknown tone map 'filmic'"));
    snprintf(text, sizeof text,
             "inputs:\n  t: {image: test.exr}\n  r: {image: ref.exr}\nstages:\n"
             "  - metrics:\n      input: t\n      reference: r\n"
             "      percentiles: [0.5, 7]\n");
    mcp_test_write_text(job, text);
    assert_int_not_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    assert_non_null(strstr(
        err_buf, "job.yaml:8: metrics: percentiles must be >= 0 and <= 1 (got 7)"));
    snprintf(text, sizeof text,
             "inputs:\n  t: {image: test.exr}\nstages:\n  - metrics:\n      input: t\n");
    mcp_test_write_text(job, text);
    assert_int_not_equal(
        mcp_test_run_mcpost(args, out_buf, sizeof out_buf, err_buf, sizeof err_buf), 0);
    assert_non_null(strstr(err_buf, "missing key 'reference'"));
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_identical_all_zero),
        cmocka_unit_test(test_mse_relmse_closed_form),
        cmocka_unit_test(test_psnr_8bit),
        cmocka_unit_test(test_pmse_closed_form),
        cmocka_unit_test(test_pkernel),
        cmocka_unit_test(test_tonemaps),
        cmocka_unit_test(test_relse_percentiles),
        cmocka_unit_test(test_channel_names),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_fused_matches_single),
        cmocka_unit_test(test_cli),
        cmocka_unit_test(test_job_stage),
    };
    return cmocka_run_group_tests_name("common/metrics", tests, NULL, NULL);
}
