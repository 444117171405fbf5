/* test_james_stein.c: the `james-stein` denoiser (blend/denoise_james_stein.c) -- its
 * output is the combiner's on the inner denoiser's, its JVP the closed form with the
 * weights held constant, its settings reach the inner denoiser, and it estimates like
 * any other denoiser. */
#include "blend_testing.h"

#include <mcpost/estimate.h>
#include <mcpost/job.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

static mcp_denoiser *
make(const char *const *opts, int n)
{
    mcp_denoiser *d = NULL;
    if (mcp_denoiser_create_from_args("james-stein", opts, n, &d))
        fail_msg("%s", mcp_error_message());
    return d;
}

static void
test_apply_and_jvp(void **state)
{
    (void)state;
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *x = mcp_test_random(21, 13, 3, 0.0f, 2.0f, 1, rgb);
    mcp_image *v = mcp_test_random(21, 13, 3, 0.01f, 0.2f, 2, rgb);
    mcp_image *t = mcp_test_random(21, 13, 3, -1.0f, 1.0f, 3, rgb);
    const char *opts[] = {"inner=gauss", "sigma=1.5", "window=5"};
    mcp_denoiser *js = make(opts, 3), *g = NULL;
    const char *gopts[] = {"sigma=1.5"};
    assert_int_equal(mcp_denoiser_create_from_args("gauss", gopts, 1, &g), 0);
    mcp_denoise_input in = {.color = x, .variance = v};
    mcp_image *f = NULL, *d = NULL, *want = NULL, *rho = NULL, *gt = NULL;
    assert_int_equal(js->apply(js, &in, &f), 0);
    assert_int_equal(g->apply(g, &in, &d), 0);
    assert_int_equal(mcp_blend_james_stein(x, d, v, 5, NULL, &want, &rho), 0);
    assert_true(mcp_test_max_abs_diff(f, want) < 1e-6);
    /* J t = rho (G t) + (1 - rho) t, G the (linear) Gaussian blur */
    mcp_denoise_tangent tan = {.color = t};
    mcp_image *jt = NULL, *primal = NULL;
    assert_int_equal(js->jvp(js, &in, &tan, 1, &primal, &jt), 0);
    mcp_denoise_input tin = {.color = t};
    assert_int_equal(g->apply(g, &tin, &gt), 0);
    for (int y = 0; y < 13; y++)
        for (int xx = 0; xx < 21; xx++)
            for (int c = 0; c < 3; c++) {
                double r = mcp_image_px(rho, xx, y)[rho->channels >= 3 ? c : 0];
                double e =
                    r * mcp_image_px(gt, xx, y)[c] + (1 - r) * mcp_image_px(t, xx, y)[c];
                assert_close(mcp_image_px(jt, xx, y)[c], e, 1e-5, 1e-6);
            }
    assert_true(mcp_test_max_abs_diff(primal, f) < 1e-6);
    /* no variance: the combiner cannot weigh */
    mcp_denoise_input novar = {.color = x};
    mcp_image *none = NULL;
    assert_error_contains(js->apply(js, &novar, &none), "no variance");
    assert_null(none);
    mcp_image *imgs[] = {x, v, t, f, d, want, rho, gt, jt, primal};
    for (size_t i = 0; i < sizeof imgs / sizeof *imgs; i++)
        mcp_image_free(imgs[i]);
    mcp_denoiser_free(js);
    mcp_denoiser_free(g);
}

/* Every built-in kind's keys are accepted and passed on; a key the inner kind lacks
 * fails naming it; james-stein cannot wrap itself; its summary states the blend's
 * default window, which it shares. */
static void
test_settings(void **state)
{
    (void)state;
    const mcp_denoiser_kind *const *kinds = mcp_denoiser_kinds(), *js = NULL;
    for (int i = 0; kinds[i]; i++)
        if (!strcmp(kinds[i]->name, "james-stein")) js = kinds[i];
    assert_non_null(js);
    char window[32];
    snprintf(window, sizeof window, "(window [%d]", mcp_blend_defaults().js_window);
    if (!strstr(js->summary, window))
        fail_msg("james-stein's summary does not say %s: %s", window, js->summary);
    for (int i = 0; kinds[i]; i++)
        for (const char *const *k = kinds[i]->keys; k && *k; k++) {
            int found = 0;
            for (const char *const *j = js->keys; *j; j++)
                found |= !strcmp(*j, *k);
            if (!found)
                fail_msg("james-stein does not pass on %s's key '%s'", kinds[i]->name,
                         *k);
        }
    mcp_denoiser *d = NULL;
    const char *bad[] = {"inner=gauss", "weights=x.tza"};
    assert_error_contains(mcp_denoiser_create_from_args("james-stein", bad, 2, &d),
                          "unknown key 'weights' in denoiser 'gauss'");
    const char *self[] = {"inner=james-stein"};
    assert_error_contains(mcp_denoiser_create_from_args("james-stein", self, 1, &d),
                          "cannot be james-stein");
    const char *even[] = {"inner=gauss", "window=4"};
    assert_error_contains(mcp_denoiser_create_from_args("james-stein", even, 2, &d),
                          "window must be odd");
    assert_null(d);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_apply_and_jvp),
        cmocka_unit_test(test_settings),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
