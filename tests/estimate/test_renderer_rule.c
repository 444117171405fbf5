/* test_renderer_rule.c: estimate/renderer_rule.c -- the renderers' own adaptive
 * stopping rule (Cycles' noise threshold): the per-pixel error against hand-worked
 * values of its formula, Cycles' automatic min samples against the values Cycles'
 * source states, the dilation of the unstopped pixels (which pixels it wakes, that a
 * stopped pixel is not tested again), a whole run in which every pixel's noise has a
 * known size c / sqrt(n) so that it must stop at a sample count the closed form
 * gives, and the options' errors. */
#include "testing.h"

#include <mcpost/estimate.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- the error of one pixel ---- */

static void
test_pixel_error_formula(void **state)
{
    (void)state;
    /* dim: R+G+B = 0.6 < 1, relative to sqrt(0.6); |diff| summed over the channels */
    float mean[3] = {0.1f, 0.2f, 0.3f}, half[3] = {0.11f, 0.18f, 0.3f};
    assert_close(mcp_renderer_rule_pixel_error(mean, half), 0.03 / (1e-4 + sqrt(0.6)),
                 1e-5, 0);
    /* bright: R+G+B = 6 >= 1, relative to 6 itself */
    float bm[3] = {1, 2, 3}, bh[3] = {1.1f, 2, 2.9f};
    assert_close(mcp_renderer_rule_pixel_error(bm, bh), 0.2 / (1e-4 + 6.0), 1e-5, 0);
    /* exactly 1 takes the linear branch: 1 / (1e-4 + 1) per unit of difference */
    float om[3] = {0.5f, 0.25f, 0.25f}, oh[3] = {0.5f, 0.25f, 0.5f};
    assert_close(mcp_renderer_rule_pixel_error(om, oh), 0.25 / (1e-4 + 1.0), 1e-6, 0);
    /* black: 0 / 1e-4 */
    float z[3] = {0, 0, 0};
    assert_true(mcp_renderer_rule_pixel_error(z, z) == 0.0);
    float zh[3] = {1e-3f, 0, 0};
    assert_close(mcp_renderer_rule_pixel_error(z, zh), 1e-3 / 1e-4, 1e-5, 0);
}

/* Cycles' source states its automatic min samples: threshold 0.1 -> 32, 0.01 -> 64,
 * 0.001 -> 128; never below 4, also when given. */
static void
test_automatic_min_samples(void **state)
{
    (void)state;
    mcp_renderer_rule_options o = mcp_renderer_rule_defaults();
    const double t[3] = {0.1, 0.01, 0.001};
    const int m[3] = {32, 64, 128};
    for (int i = 0; i < 3; i++) {
        o.threshold = t[i];
        assert_int_equal(mcp_renderer_rule_min_samples(&o), m[i]);
    }
    o.threshold = 1e6;
    assert_int_equal(mcp_renderer_rule_min_samples(&o), 4);
    o.min_samples = 2;
    assert_int_equal(mcp_renderer_rule_min_samples(&o), 4);
    o.min_samples = 40;
    assert_int_equal(mcp_renderer_rule_min_samples(&o), 40);
}

/* ---- one check: the threshold and the dilation ---- */

#define DW 7
#define DH 5

/* mean 0.2 everywhere, the half buffer equal but at the given pixels, where it is
 * far off (error 0.5 / sqrt(0.6), ~ 13x the limit 5 x 0.01) */
static void
images(mcp_image **mean, mcp_image **half, const int (*noisy)[2], int n)
{
    *mean = mcp_test_constant(DW, DH, 3, 0.2f, NULL);
    *half = mcp_test_constant(DW, DH, 3, 0.2f, NULL);
    for (int i = 0; i < n; i++)
        mcp_image_px(*half, noisy[i][0], noisy[i][1])[0] = 0.2f - 0.5f;
}

static void
test_dilation_wakes_the_neighbours(void **state)
{
    (void)state;
    const int centre[1][2] = {{3, 2}};
    mcp_image *mean, *half;
    images(&mean, &half, centre, 1);
    unsigned char f[DW * DH];
    /* radius 0, 1, 2: exactly the square around (3, 2), clipped by the image */
    const int expect[3] = {1, 9, 25};
    for (int d = 0; d <= 2; d++) {
        memset(f, 0, sizeof f);
        assert_int_equal(mcp_renderer_rule_update(mean, half, 0.01, d, f), expect[d]);
        for (int y = 0; y < DH; y++)
            for (int x = 0; x < DW; x++)
                assert_int_equal(f[y * DW + x], !(abs(x - 3) <= d && abs(y - 2) <= d));
    }
    /* a stopped pixel is not tested again: the noisy one stopped with every
       neighbour stays stopped */
    memset(f, 1, sizeof f);
    assert_int_equal(mcp_renderer_rule_update(mean, half, 0.01, 1, f), 0);
    /* an unstopped corner wakes its three stopped neighbours (Cycles' filter clears
       their flags) and nothing else */
    mcp_image_free(mean);
    mcp_image_free(half);
    const int corner[1][2] = {{0, 0}};
    images(&mean, &half, corner, 1);
    memset(f, 1, sizeof f);
    f[0] = 0;
    assert_int_equal(mcp_renderer_rule_update(mean, half, 0.01, 1, f), 4);
    assert_true(!f[0] && !f[1] && !f[DW] && !f[DW + 1] && f[2] && f[2 * DW]);
    /* a higher threshold lets the same pixel stop: 0.5 / (1e-4 + sqrt(0.6)) < 5 t for
       t = 0.13, not for t = 0.12 */
    memset(f, 0, sizeof f);
    assert_int_equal(mcp_renderer_rule_update(mean, half, 0.13, 1, f), 0);
    memset(f, 0, sizeof f);
    assert_int_equal(mcp_renderer_rule_update(mean, half, 0.12, 1, f), 4);
    mcp_image *small = mcp_test_constant(3, 3, 3, 0.2f, NULL);
    assert_int_equal(mcp_renderer_rule_update(mean, small, 0.01, 1, f), -1);
    mcp_image_free(small);
    mcp_image_free(mean);
    mcp_image_free(half);
}

/* ---- a whole run with noise of known size ---- */

#define RW 6
#define RH 2
#define MU 0.2f

/* Pixel p's noise: its half buffer's mean is below its mean by exactly
 * c_p / sqrt(n) in R after n samples (n = 16 J after J passes), as the noise of a
 * pixel with sigma = c_p would be on average. Pass J adds 16 samples of mean MU and
 * 8 class-A samples of mean MU - d_J, d_J = (c / 4)(sqrt(J) - sqrt(J - 1)), so that
 * the class-A mean after J passes is MU - (c / 4) sqrt(J) / J = MU - c / sqrt(16 J).
 * With dilate 0 a pixel that stops never samples again, so its J is the pass + 1. */
static const double noise_c[RW * RH] = {0.0, 0.3,  0.4, 0.5,  0.55, 0.7,
                                        1.0, 0.45, 0.0, 0.35, 0.52, 2.0};

static int
known_noise_render(int pass, const mcp_image *counts, mcp_dump **out, mcp_image **half,
                   void *ctx)
{
    (void)ctx;
    static const char *const hn[4] = {"R", "G", "B", "SampleCount"};
    static const char *const cn[1] = {"SampleCount"};
    mcp_dump *d = mcp_calloc(1, sizeof *d);
    assert_non_null(d);
    d->color = mcp_test_constant(RW, RH, 3, 0.0f, NULL);
    d->var_of_mean = mcp_test_constant(RW, RH, 3, 0.0f, NULL);
    d->spp_map = mcp_test_constant(RW, RH, 1, 0.0f, cn);
    d->source = mcp_strdup("known noise");
    d->convention = MCP_CONV_MCPOST;
    d->variance_in_file = MCP_VAR_PER_SAMPLE;
    *half = mcp_test_constant(RW, RH, 4, 0.0f, hn);
    const double J = pass + 1;
    for (int p = 0; p < RW * RH; p++) {
        int x = p % RW, y = p / RW;
        float n = mcp_image_px(counts, x, y)[0];
        mcp_image_px(d->spp_map, x, y)[0] = n;
        if (n == 0) continue;
        assert_true(n == 16.0f);
        float *col = mcp_image_px(d->color, x, y), *h = mcp_image_px(*half, x, y);
        double dj = noise_c[p] / 4.0 * (sqrt(J) - sqrt(J - 1.0));
        for (int c = 0; c < 3; c++) {
            col[c] = MU;
            mcp_image_px(d->var_of_mean, x, y)[c] = 1e-4f;
            h[c] = MU;
        }
        h[0] = (float)(MU - dj);
        h[3] = 8.0f;
    }
    *out = d;
    return 0;
}

static void
test_known_noise_stops_where_the_closed_form_says(void **state)
{
    (void)state;
    mcp_renderer_rule_options o = mcp_renderer_rule_defaults();
    o.threshold = 0.01; /* the limit 0.05; min samples 64 (automatic) */
    o.dilate = 0;
    o.max_spp = 256;
    o.record_every = 64;
    mcp_denoiser *den = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("gauss", NULL, 0, &den), 0);
    mcp_renderer_rule_result *r = NULL;
    if (mcp_renderer_rule_run(RW, RH, den, &o, known_noise_render, NULL, NULL, &r))
        fail_msg("%s", mcp_error_message());
    assert_int_equal(r->min_samples, 64);
    /* The closed form: after n samples the error is (c / sqrt n) / (1e-4 + sqrt(3 MU));
     * checks run after n = 16, 32, ... once n - 1 > 64 (n >= 80); a pixel stops at
     * the first check where the error is below 5 x 0.01, and one that never does
     * ends at max_spp. */
    double total = 0;
    for (int p = 0; p < RW * RH; p++) {
        int expect = 256;
        for (int n = 80; n <= 256; n += 16)
            if (noise_c[p] / sqrt(n) / (1e-4 + sqrt(3.0 * MU)) < 0.05) {
                expect = n;
                break;
            }
        double got = mcp_dump_spp_at(r->accumulated, p % RW, p / RW);
        if (got != expect)
            fail_msg("pixel %d (c = %g) stopped at %g samples, the closed form says %d",
                     p, noise_c[p], got, expect);
        total += expect;
    }
    /* 0 and 0.3 stop at the first check; 0.4 at 112, 0.5 at 176, 0.55 at 208, and
       0.7, 1.0 and 2.0 never: the run ends at 256 with a point at 64, 128, 192, 256 */
    assert_int_equal(r->count, 4);
    assert_int_equal(r->points[3].max_spp, 256);
    assert_int_equal(r->points[3].active, 3);
    assert_close(r->points[3].mean_spp, total / (RW * RH), 1e-12, 0);
    assert_close(r->points[0].mean_spp, 64.0, 1e-12, 0);
    assert_true(isnan(r->points[3].relmse));
    mcp_renderer_rule_result_free(r);
    mcp_denoiser_free(den);
}

/* ---- the options ---- */

static void
test_option_errors(void **state)
{
    (void)state;
    mcp_renderer_rule_options o = mcp_renderer_rule_defaults();
    assert_int_equal(mcp_renderer_rule_check(&o), 0);
    o.threshold = 0;
    assert_error_contains(mcp_renderer_rule_check(&o), "threshold");
    o = mcp_renderer_rule_defaults();
    o.step = 0;
    assert_error_contains(mcp_renderer_rule_check(&o), "step");
    o = mcp_renderer_rule_defaults();
    o.max_spp = 0;
    assert_error_contains(mcp_renderer_rule_check(&o), "max_spp");
    o = mcp_renderer_rule_defaults();
    o.dilate = -1;
    assert_error_contains(mcp_renderer_rule_check(&o), "dilate");
    mcp_renderer_rule_result *r = NULL;
    o = mcp_renderer_rule_defaults();
    assert_error_contains(
        mcp_renderer_rule_run(4, 4, NULL, &o, known_noise_render, NULL, NULL, &r),
        "missing denoiser");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pixel_error_formula),
        cmocka_unit_test(test_automatic_min_samples),
        cmocka_unit_test(test_dilation_wakes_the_neighbours),
        cmocka_unit_test(test_known_noise_stops_where_the_closed_form_says),
        cmocka_unit_test(test_option_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
