/* test_filtering.c: blend/filtering.c -- the Gaussian rule for sigma, the denoiser
 * option, the stopping rule and the negative-SURE rule
 * (docs/mathematics.md §3.2, §3.3). */
#include "blend_testing.h"

#include <math.h>
#include "../../blend/internal.h"

static void
test_fix_sure(void **state)
{
    (void)state;
    const float vals[6] = {-1, 2, -0.5f, 0, -0.0f, 3};
    mcp_image *s = rgb_from(2, 1, vals);
    assert_int_equal(mcp_blend_fix_sure_inplace(s, 0), 0);
    const float zeroed[6] = {0, 2, 0, 0, -0.0f, 3};
    for (int i = 0; i < 6; i++)
        assert_true(s->data[i] == zeroed[i]);
    mcp_image_free(s);
    s = rgb_from(2, 1, vals);
    assert_int_equal(mcp_blend_fix_sure_inplace(s, 1), 0);
    const float mag[6] = {1, 2, 0.5f, 0, 0, 3};
    for (int i = 0; i < 6; i++)
        assert_true(s->data[i] == mag[i]);
    mcp_image_free(s);
}

static void
test_gauss_sigma_rule(void **state)
{
    (void)state;
    /* sigma = min(sqrt(mean v), 1) x 100: mean 1e-4 -> sigma 1; mean 4 -> 100 */
    mcp_image *img = mcp_test_random(23, 17, 3, 0, 1, 7, RGB), *out = NULL, *want = NULL;
    const double means[2] = {1e-4, 4}, sigmas[2] = {1, 100};
    for (int i = 0; i < 2; i++) {
        assert_int_equal(mcp_blend_filter_image(img, means[i], NULL, NULL, &out), 0);
        assert_int_equal(mcp_gaussian_blur(img, 11, sigmas[i], &want), 0);
        assert_true(mcp_test_max_abs_diff(out, want) == 0);
        assert_string_equal(out->names[2], "B");
        mcp_image_free(out);
        mcp_image_free(want);
    }
    /* all-zero variance: sigma 0, the identity; the window is settable */
    assert_int_equal(mcp_blend_filter_image(img, 0, NULL, NULL, &out), 0);
    assert_true(mcp_test_max_abs_diff(out, img) == 0);
    mcp_image_free(out);
    mcp_blend_options o = mcp_blend_defaults();
    o.filter_window = 3;
    assert_int_equal(mcp_blend_filter_image(img, 0.01, &o, NULL, &out), 0);
    assert_int_equal(mcp_gaussian_blur(img, 3, 10, &want), 0);
    assert_true(mcp_test_max_abs_diff(out, want) == 0);
    mcp_image_free(out);
    mcp_image_free(want);
    /* a constant stays constant (the blur is normalised, borders replicate) */
    mcp_image *c = rgb_constant(9, 9, 0.25f);
    assert_int_equal(mcp_blend_filter_image(c, 0.25, NULL, NULL, &out), 0);
    for (int i = 0; i < 9 * 9 * 3; i++)
        assert_close(out->data[i], 0.25, 1e-6, 0);
    mcp_image_free(out);
    mcp_image_free(c);
    mcp_image_free(img);
}

static void
test_denoiser_filter(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_random(16, 12, 3, 0, 1, 3, RGB), *out = NULL, *want = NULL;
    mcp_denoiser *den = blur_denoiser(2.0, 9);
    mcp_blend_options o = mcp_blend_defaults();
    o.filter = MCP_BLEND_FILTER_DENOISER;
    assert_int_equal(mcp_blend_filter_image(img, 0.5, &o, den, &out), 0);
    assert_int_equal(mcp_gaussian_blur(img, 9, 2.0, &want), 0);
    assert_true(mcp_test_max_abs_diff(out, want) == 0);
    mcp_image_free(out);
    mcp_image_free(want);
    assert_error_contains(mcp_blend_filter_image(img, 0.5, &o, NULL, &out),
                          "filter 'denoiser' needs a denoiser");
    assert_null(out);
    den->destroy(den);
    mcp_image_free(img);
}

/* Runs prepare on constant v and SURE images (SURE with one negative value). */
static mcp_blend_estimates
prepare(float v, float s, const mcp_blend_options *o, mcp_blend_state *st)
{
    mcp_image *vi = rgb_constant(8, 8, v), *si = rgb_constant(8, 8, s);
    mcp_image_px(si, 0, 0)[0] = -s; /* mean falls by 2s / 192 */
    mcp_blend_estimates e;
    assert_int_equal(mcp_blend_prepare(vi, si, o, NULL, st, &e), 0);
    mcp_image_free(vi);
    mcp_image_free(si);
    return e;
}

static void
test_rules(void **state)
{
    (void)state;
    /* mean v >= mean SURE: filter, zero negative SURE */
    mcp_blend_estimates e = prepare(0.5f, 0.1f, NULL, NULL);
    assert_true(e.filtered && !e.magnitude);
    assert_close(e.mean_var, 0.5, 1e-7, 0);
    assert_close(e.mean_sure, 0.1 * (1 - 2.0 / 192), 1e-6, 0);
    assert_true(e.sure->data[0] >= 0);
    assert_true(e.sure->data[0] < 0.1f); /* zeroed, then blurred with its neighbours */
    mcp_blend_estimates_free(&e);
    /* mean v < mean SURE: no filtering, negative SURE by magnitude, exactly */
    e = prepare(0.05f, 0.1f, NULL, NULL);
    assert_true(!e.filtered && e.magnitude);
    assert_true(e.sure->data[0] == 0.1f && e.var_of_mean->data[5] == 0.05f);
    mcp_blend_estimates_free(&e);
    /* with a state, once crossed stays crossed */
    mcp_blend_state st = {0, 0};
    e = prepare(0.5f, 0.1f, NULL, &st);
    assert_true(e.filtered && !e.magnitude && !st.filtering_stopped);
    mcp_blend_estimates_free(&e);
    e = prepare(0.05f, 0.1f, NULL, &st);
    assert_true(!e.filtered && e.magnitude && st.filtering_stopped && st.magnitude);
    mcp_blend_estimates_free(&e);
    e = prepare(0.5f, 0.1f, NULL, &st);
    assert_true(!e.filtered && e.magnitude);
    mcp_blend_estimates_free(&e);
    /* the switches can be forced */
    mcp_blend_options o = mcp_blend_defaults();
    o.stop_filtering = 0;
    o.negative_sure = MCP_NEG_SURE_ZERO;
    e = prepare(0.05f, 0.1f, &o, NULL);
    assert_true(e.filtered && !e.magnitude);
    mcp_blend_estimates_free(&e);
    o.negative_sure = MCP_NEG_SURE_MAGNITUDE;
    o.filter = MCP_BLEND_FILTER_NONE;
    e = prepare(0.5f, 0.1f, &o, NULL);
    assert_true(!e.filtered && e.magnitude && e.sure->data[0] == 0.1f);
    mcp_blend_estimates_free(&e);
}

static void
test_prepare_errors(void **state)
{
    (void)state;
    mcp_image *v = rgb_constant(4, 4, 0.1f), *s = rgb_constant(4, 5, 0.1f);
    mcp_blend_estimates e;
    assert_error_contains(mcp_blend_prepare(v, s, NULL, NULL, NULL, &e),
                          "does not match");
    assert_null(e.var_of_mean);
    mcp_image_free(s);
    s = rgb_constant(4, 4, INFINITY);
    assert_error_contains(mcp_blend_prepare(v, s, NULL, NULL, NULL, &e),
                          "mean SURE (inf) must be finite");
    mcp_image_free(s);
    mcp_image_free(v);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fix_sure),        cmocka_unit_test(test_gauss_sigma_rule),
        cmocka_unit_test(test_denoiser_filter), cmocka_unit_test(test_rules),
        cmocka_unit_test(test_prepare_errors),
    };
    return cmocka_run_group_tests_name("blend/filtering", tests, NULL, NULL);
}
