/* test_surrogate.c: perceptual/surrogate.c -- the candidates' mean; what the denoiser
 * is given (the mean, the variance of the mean from the candidates' spread, the
 * features) through a recording denoiser; and, with the built-in denoiser's surrogate,
 * vertical iterative minimisation beating the candidates' mean in pMSE on the fixtures
 * (ratios printed). */
#include "perc_testing.h"

#include <mcpost/denoiser.h>

#include <math.h>
#include "../../perceptual/internal.h"

typedef struct {
    mcp_image *color, *variance;
    const mcp_image *albedo, *normal;
    int fail;
} recorder;

static int
record_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    recorder *r = self->state;
    if (r->fail) return mcp_error("broken");
    mcp_image_copy(in->color, &r->color);
    if (in->variance) mcp_image_copy(in->variance, &r->variance);
    r->albedo = in->albedo;
    r->normal = in->normal;
    return mcp_image_copy(in->color, out);
}

static void
test_mean_and_inputs(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(12, 3, 2, 61, 1, &c);
    mcp_image *mean = NULL, *sur = NULL;
    assert_int_equal(mcp_perc_mean(perc_cands(&c), c.m, &mean), 0);
    for (int p = 0; p < 144 * 3; p++)
        assert_true(mean->data[p] == (float)(((double)c.cand[0]->data[p] +
                                              c.cand[1]->data[p] + c.cand[2]->data[p]) /
                                             3.0));
    recorder rec = {0};
    mcp_denoiser den = {.name = "recorder", .apply = record_apply, .state = &rec};
    mcp_image *alb = mcp_test_constant(12, 12, 3, 0.5f, NULL);
    assert_int_equal(
        mcp_perc_surrogate_denoise(perc_cands(&c), c.m, alb, NULL, &den, &sur), 0);
    assert_true(mcp_test_max_abs_diff(rec.color, mean) == 0.0);
    assert_true(rec.albedo == alb && rec.normal == NULL);
    assert_non_null(rec.variance);
    for (int p = 0; p < 144 * 3; p++) {
        double s = 0.0;
        for (int j = 0; j < 3; j++)
            s += (c.cand[j]->data[p] - (double)mean->data[p]) *
                 (c.cand[j]->data[p] - (double)mean->data[p]);
        assert_close(rec.variance->data[p], s / 6.0, 1e-6, 1e-12); /* float storage */
    }
    assert_true(mcp_test_max_abs_diff(sur, mean) == 0.0);
    mcp_image_free(sur);
    sur = NULL;
    rec.fail = 1;
    assert_error_contains(
        mcp_perc_surrogate_denoise(perc_cands(&c), c.m, NULL, NULL, &den, &sur),
        "surrogate: denoiser 'recorder': broken");
    assert_null(sur);
    assert_error_contains(
        mcp_perc_surrogate_denoise(perc_cands(&c), c.m, NULL, NULL, NULL, &sur),
        "no denoiser");
    mcp_image_free(rec.color), mcp_image_free(rec.variance);
    mcp_image_free(alb), mcp_image_free(mean);
    perc_case_free(&c);
}

/* The built-in denoiser on the candidates' mean as the surrogate (the paper's
 * practical setting; nlm guided by the singles' albedo and normal, the CLI's default):
 * the optimised image beats the plain mean on every fixture, with 4 single-sample
 * candidates and with 4 candidates of 4 samples. */
static void
fixture_denoised(const char *scene, int m, int group)
{
    perc_case c;
    if (perc_fixture(scene, m, group, &c)) return;
    mcp_denoiser *den = NULL;
    mcp_image *sur = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("nlm", NULL, 0, &den), 0);
    assert_int_equal(
        mcp_perc_surrogate_denoise(perc_cands(&c), c.m, c.albedo, c.normal, den, &sur),
        0);
    mcp_perc_options o = mcp_perc_defaults();
    mcp_perc_result r, ps;
    assert_int_equal(mcp_perc_vertical_iterative(perc_cands(&c), c.m, sur, &o, &r), 0);
    assert_int_equal(mcp_perc_power_set(perc_cands(&c), c.m, sur, &o, &ps), 0);
    perc_assert_from_candidates(r.image, r.index, perc_cands(&c), c.m);
    double ours = perc_pmse(r.image, c.truth), mean = perc_mean_pmse(&c);
    double pset = perc_pmse(ps.image, c.truth), surr = perc_pmse(sur, c.truth);
    print_message(
        "fixture %s, %d x %d spp, denoised surrogate (nlm): vertical pMSE %.5f vs "
        "mean %.5f (ratio %.3f); power set %.5f (ratio %.3f); the surrogate itself "
        "%.5f\n",
        scene, m, group, ours, mean, ours / mean, pset, pset / mean, surr);
    assert_true(ours < mean);
    assert_true(pset < mean);
    mcp_perc_result_free(&r);
    mcp_perc_result_free(&ps);
    mcp_image_free(sur);
    mcp_denoiser_free(den);
    perc_case_free(&c);
}

static void
test_fixtures_denoised(void **state)
{
    (void)state;
    fixture_denoised("cornell", 4, 1);
    fixture_denoised("cornell", 4, 4);
    fixture_denoised("texture", 4, 1);
    fixture_denoised("texture", 4, 4);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mean_and_inputs),
        cmocka_unit_test(test_fixtures_denoised),
    };
    return cmocka_run_group_tests_name("perceptual/surrogate", tests, NULL, NULL);
}
