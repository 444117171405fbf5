/* test_fastpow.c: the vectorisable x^y of common/metrics/fastpow.h against double pow:
 * the relative error stays below (1 + |y log2 x|) * 1.5e-7 over exponents and bases
 * spread across float's range (the powers FLIP takes: 1/3, 0.7, 1 - fd in [0, 1], and
 * others), and the edges are powf's. */
#include "testing.h"

#include "../../common/metrics/fastpow.h"

#include <float.h>
#include <math.h>

static void
test_relative_error_bound(void **state)
{
    (void)state;
    const float ys[] = {1.0f / 3.0f, 0.7f, 0.5f,        0.999f, 0.01f, 1e-4f, 1.0f,
                        2.0f,        2.4f, 1.0f / 2.4f, -0.5f,  -1.0f, -3.7f};
    uint64_t seed = 7;
    double worst = 0;
    for (size_t k = 0; k < sizeof ys / sizeof *ys; k++)
        for (int i = 0; i < 200000; i++) {
            /* x log-uniform over 2^-60 .. 2^60, and some near 1 */
            double u = (double)(mcp_test_rand_u64(&seed) >> 11) / 9007199254740992.0;
            float x =
                i % 4 == 0 ? (float)(1.0 + (u - 0.5) * 1e-3) : (float)exp2(120 * u - 60);
            float y = ys[k];
            double exact = pow((double)x, (double)y);
            double zl = fabs((double)y * log2((double)x));
            if (zl > 16) continue;
            double rel = fabs((double)mcp__powf_pos(x, y) - exact) / exact;
            double bound = (1 + zl) * 1.5e-7;
            if (rel > bound)
                fail_msg("%.9g^%.9g: relative error %.3g above %.3g", x, y, rel, bound);
            if (rel / bound > worst) worst = rel / bound;
        }
    print_message("worst error: %.2f of the bound\n", worst);
}

static void
test_edges_as_powf(void **state)
{
    (void)state;
    assert_true(mcp__powf_pos(0.0f, 0.7f) == 0.0f);
    assert_true(mcp__powf_pos(0.0f, 0.0f) == 1.0f);
    assert_true(isinf(mcp__powf_pos(0.0f, -0.3f)));
    assert_true(mcp__powf_pos(1.0f, 0.37f) == 1.0f);
    assert_true(mcp__powf_pos(8.0f, 1.0f / 3.0f) > 1.9999995f);
    assert_true(mcp__powf_pos(8.0f, 1.0f / 3.0f) < 2.0000005f);
    /* out of float's range: flushed to 0, or +Inf */
    assert_true(mcp__powf_pos(1e-30f, 5.0f) == 0.0f);
    assert_true(isinf(mcp__powf_pos(1e30f, 5.0f)));
    assert_true(isinf(mcp__powf_pos(FLT_MAX, 2.0f)));
    /* denormal inputs are positive numbers, taken as such */
    float tiny = 1e-45f;
    assert_true(fabs(mcp__powf_pos(tiny, 0.25f) / pow(tiny, 0.25) - 1) < 1e-6);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_relative_error_bound),
        cmocka_unit_test(test_edges_as_powf),
    };
    return cmocka_run_group_tests_name("common/fastpow", tests, NULL, NULL);
}
