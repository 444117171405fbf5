/* test_curves.c: blend/curves.c against closed forms (docs/mathematics.md §3.1, §3.4:
 * convergence curve, Eq. 11, weight; Denisova & Bocchi 2024 Eqs. 7, 11, 14). */
#include "blend_testing.h"
#include "../../blend/internal.h"

#include <math.h>

static void
test_far_point_eq11(void **state)
{
    (void)state;
    /* Eq. 11: V_K = (N/K - 1)^2 V_{N-K}; with K = 4, N = 1e6: N - K = 999996 and
     * V_{N-K} = V_K / 249999^2. */
    double spp2, v2;
    assert_int_equal(mcp_curve_far_point(4, 0.2, 1e6, &spp2, &v2), 0);
    assert_true(spp2 == 999996.0);
    assert_close(v2, 0.2 / (249999.0 * 249999.0), 1e-14, 0);
    /* N settable: N = 100, K = 20 -> (80, v / 16) */
    assert_int_equal(mcp_curve_far_point(20, 1.6, 100, &spp2, &v2), 0);
    assert_true(spp2 == 80.0);
    assert_close(v2, 0.1, 1e-15, 0);
    /* N must exceed K */
    assert_int_equal(mcp_curve_far_point(4, 0.2, 4, &spp2, &v2), -1);
    assert_int_equal(mcp_curve_far_point(0, 0.2, 10, &spp2, &v2), -1);
}

static void
test_on_the_fly_line_and_weight(void **state)
{
    (void)state;
    /* The line through (K, v) and the Eq. 11 point has slope -2 (N/K - 1 = (N-K)/K)
     * and intercept ln v + 2 ln K, for any N; so W = K sqrt(v / SURE). */
    const double Ks[] = {1, 16, 1000}, vs[] = {0.5, 0.01, 3e-7}, Ns[] = {1e6, 1e4, 1e9};
    for (int i = 0; i < 3; i++) {
        double x[2] = {Ks[i], 0}, v[2] = {vs[i], 0}, a, b;
        assert_int_equal(mcp_curve_far_point(Ks[i], vs[i], Ns[i], &x[1], &v[1]), 0);
        assert_int_equal(mcp_curve_fit_points(MCP_CURVE_LOG, 100, x, v, 2, &a, &b), 2);
        /* tolerance: two logs of numbers up to 1e18 in double, ~1e-15 relative */
        assert_close(a, -2.0, 1e-12, 0);
        assert_close(b, log(vs[i]) + 2 * log(Ks[i]), 1e-12, 1e-12);
        double sure = vs[i] / 9; /* d as good as 9x the noisy samples' variance */
        assert_close(mcp_curve_weight(MCP_CURVE_LOG, 100, a, b, sure, INFINITY),
                     Ks[i] * 3.0, 1e-10, 0);
    }
    /* the worked example for docs: K = 16, v = 0.01, SURE = 0.0025 -> W = 32 */
    double x[2] = {16, 0}, v[2] = {0.01, 0}, a, b;
    mcp_curve_far_point(16, 0.01, 1e6, &x[1], &v[1]);
    mcp_curve_fit_points(MCP_CURVE_LOG, 100, x, v, 2, &a, &b);
    assert_close(mcp_curve_weight(MCP_CURVE_LOG, 100, a, b, 0.0025, INFINITY), 32, 1e-10,
                 0);
}

static void
test_log_weight_closed_form(void **state)
{
    (void)state;
    /* v(I) = 0.5 / I: a = -1, b = ln 0.5. SURE = 0.05 is v at I = 10, so W = 10. */
    double a = -1, b = log(0.5);
    assert_close(mcp_curve_weight(MCP_CURVE_LOG, 100, a, b, 0.05, INFINITY), 10, 1e-12,
                 0);
    /* SURE 0: a perfect d, W = inf; capped when asked */
    assert_true(isinf(mcp_curve_weight(MCP_CURVE_LOG, 100, a, b, 0, INFINITY)));
    assert_true(mcp_curve_weight(MCP_CURVE_LOG, 100, a, b, 0, 500) == 500);
    assert_true(mcp_curve_weight(MCP_CURVE_LOG, 100, a, b, 1e-9, 500) == 500);
    /* no curve, or one that does not fall: NaN (the caller decides) */
    assert_true(isnan(mcp_curve_weight(MCP_CURVE_LOG, 100, NAN, NAN, 0.05, INFINITY)));
    assert_true(isnan(mcp_curve_weight(MCP_CURVE_LOG, 100, 0.5, b, 0.05, INFINITY)));
}

static void
test_least_squares_recovers_line(void **state)
{
    (void)state;
    /* exact points of v = 3 I^-1.3 at I = 1..1024 (powers of 2) */
    double x[11], v[11], a, b;
    for (int i = 0; i < 11; i++) {
        x[i] = ldexp(1, i);
        v[i] = 3 * pow(x[i], -1.3);
    }
    assert_int_equal(mcp_curve_fit_points(MCP_CURVE_LOG, 100, x, v, 11, &a, &b), 11);
    assert_close(a, -1.3, 1e-12, 0);
    assert_close(b, log(3), 1e-12, 0);
    /* zeros are skipped; a single usable point gives no curve */
    v[3] = 0;
    v[7] = -1;
    assert_int_equal(mcp_curve_fit_points(MCP_CURVE_LOG, 100, x, v, 11, &a, &b), 9);
    assert_close(a, -1.3, 1e-12, 0);
    assert_int_equal(mcp_curve_fit_points(MCP_CURVE_LOG, 100, x, v, 1, &a, &b), 0);
    double same_x[2] = {4, 4}, two_v[2] = {1, 2};
    assert_int_equal(mcp_curve_fit_points(MCP_CURVE_LOG, 100, same_x, two_v, 2, &a, &b),
                     0);
}

static void
test_select_points(void **state)
{
    (void)state;
    /* walk back from 0.05: 0.2 > 0.05 kept, 0.1 < 0.2 skipped, 0.4 kept, 0.3 skipped,
     * 0 dropped, 0.5 kept */
    const double v[7] = {0.5, 0, 0.3, 0.4, 0.1, 0.2, 0.05};
    const unsigned char want[7] = {1, 0, 0, 1, 0, 1, 1};
    unsigned char keep[7];
    assert_int_equal(mcp_curve_select_points(v, 7, keep), 4);
    assert_memory_equal(keep, want, 7);
    /* newest zero: the first positive one before it starts the walk */
    const double z[3] = {0.4, 0.2, 0};
    assert_int_equal(mcp_curve_select_points(z, 3, keep), 2);
    assert_true(keep[0] && keep[1] && !keep[2]);
    const double all0[2] = {0, 0};
    assert_int_equal(mcp_curve_select_points(all0, 2, keep), 0);
}

static void
test_powerlaw(void **state)
{
    (void)state;
    /* ln v + 100 = a I^b with a = 100, b = -0.01: points on it are fitted exactly, and
     * the SURE that equals v(64) gets W = 64. */
    const double A = 100, B = -0.01;
    double x[6], v[6], a, b;
    for (int i = 0; i < 6; i++) {
        x[i] = ldexp(1, 2 * i);
        v[i] = exp(A * pow(x[i], B) - 100);
    }
    assert_int_equal(mcp_curve_fit_points(MCP_CURVE_POWERLAW, 100, x, v, 6, &a, &b), 6);
    assert_close(a, A, 1e-10, 0);
    assert_close(b, B, 1e-10, 0);
    double sure64 = exp(A * pow(64, B) - 100);
    assert_close(mcp_curve_weight(MCP_CURVE_POWERLAW, 100, A, B, sure64, 65536), 64,
                 1e-10, 0);
    /* W = ((ln SURE + 100) / a)^(1/b), capped: a tiny SURE and SURE 0 give the cap */
    assert_true(mcp_curve_weight(MCP_CURVE_POWERLAW, 100, A, B, 1e-40, 65536) == 65536);
    assert_true(mcp_curve_weight(MCP_CURVE_POWERLAW, 100, A, B, 0, 65536) == 65536);
    /* a rising curve gives none */
    assert_true(isnan(mcp_curve_weight(MCP_CURVE_POWERLAW, 100, A, 0.01, 0.1, 65536)));
}

static void
test_curves_image_on_the_fly(void **state)
{
    (void)state;
    /* 2x1 image: pixel 0 has v = 0.01, 0.02, 0.04; pixel 1 is black (v = 0) */
    const float vals[6] = {0.01f, 0.02f, 0.04f, 0, 0, 0};
    mcp_image *v = rgb_from(2, 1, vals), *curves = NULL;
    const mcp_image *list[1] = {v};
    double spp[1] = {16};
    assert_int_equal(mcp_blend_curves(list, spp, 1, NULL, &curves), 0);
    assert_int_equal(curves->channels, 6);
    assert_string_equal(curves->names[0], "a.R");
    assert_string_equal(curves->names[5], "b.B");
    for (int k = 0; k < 3; k++) {
        /* float storage: 1e-6 relative */
        assert_close(curves->data[k], -2.0, 1e-6, 0);
        assert_close(curves->data[3 + k], log((double)vals[k]) + 2 * log(16.0), 1e-6, 0);
        assert_true(isnan(curves->data[6 + k]) && isnan(curves->data[9 + k]));
    }
    mcp_image_free(curves);
    /* far_spp must exceed the newest spp */
    mcp_blend_options o = mcp_blend_defaults();
    o.far_spp = 16;
    assert_error_contains(mcp_blend_curves(list, spp, 1, &o, &curves), "far_spp (16)");
    assert_null(curves);
    mcp_image_free(v);
}

static void
test_curves_image_retrospective(void **state)
{
    (void)state;
    /* 3 points of v = 0.8 / I (a = -1, b = ln 0.8) at I = 2, 8, 32, plus a noisy value
     * in channel G at I = 8 that the selection drops (smaller than v(32)). */
    mcp_image *v[3];
    const double spp[3] = {2, 8, 32};
    for (int i = 0; i < 3; i++)
        v[i] = rgb_constant(3, 2, (float)(0.8 / spp[i]));
    mcp_image_px(v[1], 1, 1)[1] = 0.01f;
    mcp_blend_options o = mcp_blend_defaults();
    o.fit = MCP_CURVE_FIT_RETROSPECTIVE;
    mcp_image *curves = NULL;
    assert_int_equal(mcp_blend_curves((const mcp_image *const *)v, spp, 3, &o, &curves),
                     0);
    for (int p = 0; p < 6; p++)
        for (int k = 0; k < 3; k++) {
            assert_close(curves->data[p * 6 + k], -1.0, 1e-6, 0);
            assert_close(curves->data[p * 6 + 3 + k], log(0.8), 1e-6, 0);
        }
    mcp_image_free(curves);
    /* spp must increase; sizes must match */
    const double bad[3] = {2, 8, 8};
    assert_error_contains(
        mcp_blend_curves((const mcp_image *const *)v, bad, 3, &o, &curves),
        "spp must increase");
    mcp_image *small = rgb_constant(2, 2, 0.1f);
    const mcp_image *mixed[2] = {v[0], small};
    assert_error_contains(mcp_blend_curves(mixed, spp, 2, &o, &curves), "does not match");
    assert_null(curves);
    mcp_image *grey2 = mcp_test_constant(3, 2, 2, 0.1f, NULL);
    const mcp_image *two[1] = {grey2};
    assert_error_contains(mcp_blend_curves(two, spp, 1, &o, &curves), "blend: variance:");
    mcp_image_free(grey2);
    mcp_image_free(small);
    for (int i = 0; i < 3; i++)
        mcp_image_free(v[i]);
}

static void
test_curves_image_last_two(void **state)
{
    (void)state;
    /* spp 2, 8, 16, 32. Pixel 0: v = 0.8 / I with a dropped low value at 16 spp, so the
     * two newest kept points are 8 and 32: a = -1, b = ln 0.8. Pixel 1: v rises with I,
     * only the newest survives and the Eq. 11 point joins it: a = -2,
     * b = ln 0.05 + 2 ln 32. */
    const double spp[4] = {2, 8, 16, 32};
    const float p0[4] = {0.4f, 0.1f, 0.01f, 0.025f}, p1[4] = {0.01f, 0.02f, 0.03f, 0.05f};
    mcp_image *v[4];
    for (int i = 0; i < 4; i++) {
        v[i] = rgb_constant(2, 1, p0[i]);
        for (int k = 0; k < 3; k++)
            mcp_image_px(v[i], 1, 0)[k] = p1[i];
    }
    mcp_blend_options o = mcp_blend_defaults();
    o.fit = MCP_CURVE_FIT_LAST_TWO;
    mcp_image *curves = NULL;
    assert_int_equal(mcp_blend_curves((const mcp_image *const *)v, spp, 4, &o, &curves),
                     0);
    for (int k = 0; k < 3; k++) {
        /* float storage: 1e-6 */
        assert_close(curves->data[k], -1.0, 1e-6, 0);
        assert_close(curves->data[3 + k], log(0.8), 1e-6, 1e-6);
        assert_close(curves->data[6 + k], -2.0, 1e-6, 0);
        assert_close(curves->data[9 + k], log((double)0.05f) + 2 * log(32.0), 1e-6, 0);
    }
    mcp_image_free(curves);
    for (int i = 0; i < 4; i++)
        mcp_image_free(v[i]);
}

static void
test_options(void **state)
{
    (void)state;
    mcp_blend_options o = mcp_blend_defaults();
    assert_int_equal(mcp_blend_options_check(&o), 0);
    assert_true(o.far_spp == 1e6 && o.filter_window == 11 &&
                o.filter_sigma_scale == 100 && o.js_window == 15 &&
                o.fit == MCP_CURVE_FIT_ON_THE_FLY && o.curve == MCP_CURVE_LOG);
    o.filter_window = 10;
    assert_error_contains(mcp_blend_options_check(&o), "filter_window must be odd");
    o = mcp_blend_defaults();
    o.js_window = 1;
    assert_error_contains(mcp_blend_options_check(&o), "js_window");
    o = mcp_blend_defaults();
    o.far_spp = NAN;
    assert_error_contains(mcp_blend_options_check(&o), "far_spp must be finite");
    mcp_curve_fit f;
    mcp_curve_model m;
    mcp_neg_sure ns;
    mcp_blend_filter bf;
    assert_int_equal(mcp_curve_fit_from_name("on-the-fly", &f), 0);
    assert_int_equal(f, MCP_CURVE_FIT_ON_THE_FLY);
    assert_int_equal(mcp_curve_fit_from_name("Retrospective", &f), 0);
    assert_int_equal(f, MCP_CURVE_FIT_RETROSPECTIVE);
    assert_int_equal(mcp_curve_fit_from_name("last-two", &f), 0);
    assert_int_equal(f, MCP_CURVE_FIT_LAST_TWO);
    assert_error_contains(mcp_curve_fit_from_name("all", &f),
                          "unknown curve fit 'all' (known: on_the_fly, retrospective, "
                          "last_two)");
    assert_int_equal(mcp_curve_model_from_name("powerlaw", &m), 0);
    assert_int_equal(m, MCP_CURVE_POWERLAW);
    assert_int_equal(mcp_neg_sure_from_name("magnitude", &ns), 0);
    assert_int_equal(mcp_blend_filter_from_name("none", &bf), 0);
    assert_error_contains(mcp_curve_model_from_name("cubic", &m),
                          "unknown curve 'cubic' (known: log, powerlaw)");
    assert_string_equal(mcp_neg_sure_name(MCP_NEG_SURE_SWITCH), "switch");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_far_point_eq11),
        cmocka_unit_test(test_on_the_fly_line_and_weight),
        cmocka_unit_test(test_log_weight_closed_form),
        cmocka_unit_test(test_least_squares_recovers_line),
        cmocka_unit_test(test_select_points),
        cmocka_unit_test(test_powerlaw),
        cmocka_unit_test(test_curves_image_on_the_fly),
        cmocka_unit_test(test_curves_image_retrospective),
        cmocka_unit_test(test_curves_image_last_two),
        cmocka_unit_test(test_options),
    };
    return cmocka_run_group_tests_name("blend/curves", tests, NULL, NULL);
}
