/* test_procedural_half.c: the procedural renderer's half buffer
 * (mcp_proc_render_counts_half), what a renderer's own adaptive stopping rule keeps
 * beside the full mean -- over many seeds the class-A mean is unbiased (its average
 * is the exact pixel value) and the difference D = I - A of the full mean and the
 * half mean has the variance the closed form gives: D = (B - A) / 2 with A and B the
 * means of two independent halves, so Var D = Var(mean of n/2 samples) / 2, the exact
 * variance of the mean (mcp_proc_truth_var_of_mean) at n/2 over 2. With the
 * independent sampler at n = 16 that is sigma^2 / 16; with the jittered 4x4 one at
 * n = 32 (two passes, one class-A sample in every cell) it is the stratified variance
 * at 16 over 2. And the pass itself is the plain one, bit for bit.
 *
 * Fixed seeds: deterministic; each tolerance is explained where it is used. */
#include "testing.h"

#include "procedural.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/dump.h>

#define W 16
#define H 16
#define NV (W * H * 3)
#define R 600 /* realizations */

static mcp_proc_scene
scene_of(mcp_proc_sampler sampler)
{
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = W;
    s.height = H;
    s.sampler = sampler;
    /* No fireflies: a 1e-3 chance of a 100x value makes any variance of a variance
       over a few hundred seeds a matter of luck; the half buffer does not care. */
    s.firefly_probability = 0.0;
    return s;
}

static mcp_image *
constant_counts(int n)
{
    static const char *const name[1] = {"SampleCount"};
    mcp_image *c = mcp_test_constant(W, H, 1, (float)n, name);
    assert_non_null(c);
    return c;
}

/* Renders R realizations of n samples (passes 0 .. of a counts image; n a whole
 * number of passes of 16 for the jittered sampler, as one pass here) and checks the
 * class-A mean and the difference. */
static void
check_half_over_seeds(mcp_proc_sampler sampler, int n)
{
    mcp_proc_scene s = scene_of(sampler);
    mcp_image *truth = NULL, *var_half = NULL;
    assert_int_equal(mcp_proc_truth(&s, &truth, NULL), 0);
    /* the exact variance of a mean of n/2 samples under the sampler */
    assert_int_equal(mcp_proc_truth_var_of_mean(&s, n / 2, &var_half), 0);
    mcp_image *counts = constant_counts(n);
    /* per value the sum of A over the seeds; per pixel the sums of q = sum over the
       channels of D^2, and of q^2 */
    static double sum_a[NV], sum_q[W * H], sum_q2[W * H];
    memset(sum_a, 0, sizeof sum_a);
    memset(sum_q, 0, sizeof sum_q);
    memset(sum_q2, 0, sizeof sum_q2);
    for (int r = 0; r < R; r++) {
        mcp_dump *d = NULL;
        mcp_image *half = NULL;
        if (mcp_proc_render_counts_half(&s, counts, 0, mcp_proc_realization_seed(5, r),
                                        &d, &half))
            fail_msg("mcp_proc_render_counts_half: %s", mcp_error_message());
        for (int p = 0; p < W * H; p++) {
            const float *hp = mcp_image_px(half, p % W, p / W);
            const float *ip = mcp_image_px(d->color, p % W, p / W);
            assert_int_equal((int)hp[3], n / 2); /* exactly half the samples */
            double q = 0;
            for (int c = 0; c < 3; c++) {
                double dd = (double)ip[c] - hp[c];
                sum_a[3 * p + c] += hp[c];
                q += dd * dd;
            }
            sum_q[p] += q;
            sum_q2[p] += q * q;
        }
        mcp_dump_free(d);
        mcp_image_free(half);
    }
    /* Unbiased: the average of the R class-A means within 5 of its exact standard
     * errors sqrt(V(n/2) / R), plus two lit samples' worth for the umbra's border
     * (test_procedural.c explains it), plus float storage. */
    double all_v = 0;
    for (int i = 0; i < NV; i++) {
        double v = var_half->data[i];
        double avg = sum_a[i] / R, err = avg - truth->data[i];
        double tol = 5.0 * sqrt(v / R) + 2.0 * 0.8 / (R * n / 2.0) + 1e-6;
        if (!(fabs(err) <= tol))
            fail_msg("value %d (pixel (%d, %d)): class-A average %.6f, truth %.6f, "
                     "tolerance %.2g",
                     i, (i / 3) % W, (i / 3) / W, avg, truth->data[i], tol);
        all_v += v / 2.0; /* Var D = V(n/2) / 2 */
    }
    /* E D = 0 exactly (A and I are both unbiased), so the average of D^2 over the
     * seeds estimates Var D without a mean taken out. Summed over every value it is a
     * sum over independent pixels of means of R independent q's, so by the central
     * limit theorem it lies within 5 of its standard errors (estimated from the q's
     * themselves, whatever their tails) of the closed form; here that is 3-4%
     * (over 600 seeds the sums came within 1.1% and 0.3%), where a wrong closed form
     * (sigma^2 / n/2, or the overlap of A with I left out) would be off by a factor 2. */
    double all_s2 = 0, var_sum = 0;
    for (int p = 0; p < W * H; p++) {
        double mq = sum_q[p] / R;
        all_s2 += mq;
        var_sum += (sum_q2[p] / R - mq * mq) / (R - 1);
    }
    double tol = 5.0 * sqrt(var_sum);
    if (!(fabs(all_s2 - all_v) <= tol))
        fail_msg("sum of Var(I - A) over %d seeds %.6g, the closed form %.6g, tolerance "
                 "%.2g",
                 R, all_s2, all_v, tol);
    mcp_image_free(truth);
    mcp_image_free(var_half);
    mcp_image_free(counts);
}

static void
test_independent_half_over_seeds(void **state)
{
    (void)state;
    check_half_over_seeds(MCP_PROC_SAMPLER_INDEPENDENT, 16);
}

static void
test_jittered_half_over_seeds(void **state)
{
    (void)state;
    check_half_over_seeds(MCP_PROC_SAMPLER_JITTERED, 32);
}

/* The pass with its half buffer is the plain pass, bit for bit; a pixel given no
 * samples has an empty half; one jittered pass of 16 has 8 class-A samples; a later
 * pass starts its class where the stream index says. */
static void
test_half_pass_is_the_plain_pass(void **state)
{
    (void)state;
    for (int smp = 0; smp < 2; smp++) {
        mcp_proc_scene s =
            scene_of(smp ? MCP_PROC_SAMPLER_JITTERED : MCP_PROC_SAMPLER_INDEPENDENT);
        s.firefly_probability = 1e-3;
        mcp_image *counts = constant_counts(16);
        mcp_image_px(counts, 3, 2)[0] = 0.0f;
        mcp_image_px(counts, 5, 7)[0] = 48.0f;
        mcp_dump *plain = NULL, *d = NULL;
        mcp_image *half = NULL;
        assert_int_equal(mcp_proc_render_counts(&s, counts, 2, 9, &plain), 0);
        assert_int_equal(mcp_proc_render_counts_half(&s, counts, 2, 9, &d, &half), 0);
        assert_int_equal(memcmp(plain->color->data, d->color->data, NV * sizeof(float)),
                         0);
        assert_int_equal(
            memcmp(plain->var_of_mean->data, d->var_of_mean->data, NV * sizeof(float)),
            0);
        assert_int_equal(mcp_image_channel(half, "SampleCount"), 3);
        assert_true(mcp_image_px(half, 3, 2)[3] == 0.0f);
        assert_true(mcp_image_px(half, 3, 2)[0] == 0.0f);
        assert_true(mcp_image_px(half, 0, 0)[3] == 8.0f);
        assert_true(mcp_image_px(half, 5, 7)[3] == 24.0f);
        mcp_dump_free(plain);
        mcp_dump_free(d);
        mcp_image_free(half);
        mcp_image_free(counts);
    }
    mcp_proc_scene s = scene_of(MCP_PROC_SAMPLER_INDEPENDENT);
    mcp_image *counts = constant_counts(4);
    mcp_dump *d = NULL;
    assert_error_contains(mcp_proc_render_counts_half(&s, counts, 0, 1, &d, NULL),
                          "half buffer");
    mcp_image_free(counts);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_independent_half_over_seeds),
        cmocka_unit_test(test_jittered_half_over_seeds),
        cmocka_unit_test(test_half_pass_is_the_plain_pass),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
