/* test_powerset.c: perceptual/powerset.c -- the subset order and cap, every output
 * pixel being the mean of the subset its index names (recomputed independently), the
 * energy bookkeeping, and the pMSE against the truth beating the candidates' mean (and,
 * on this scene, the plain vertical method). */
#include "perc_testing.h"

#include <math.h>
#include "../../perceptual/internal.h"

static void
test_subset_masks(void **state)
{
    (void)state;
    uint64_t masks[16];
    int k;
    assert_int_equal(mcp_perc_subset_masks(4, 64, masks, &k), 0);
    assert_int_equal(k, 15);
    /* singles, the full mean, then pairs and triples in lexicographic order */
    static const uint64_t want[15] = {0x1, 0x2, 0x4, 0x8, 0xF, 0x3, 0x5, 0x9,
                                      0x6, 0xA, 0xC, 0x7, 0xB, 0xD, 0xE};
    for (int i = 0; i < 15; i++)
        assert_int_equal(masks[i], want[i]);
    for (int i = 0; i < 15; i++) /* all distinct: the whole power set */
        for (int j = i + 1; j < 15; j++)
            assert_true(masks[i] != masks[j]);
    assert_int_equal(mcp_perc_subset_masks(4, 6, masks, &k), 0);
    assert_int_equal(k, 6);
    assert_int_equal(masks[4], 0xF);
    assert_int_equal(masks[5], 0x3);
    assert_int_equal(mcp_perc_subset_masks(1, 64, masks, &k), 0);
    assert_int_equal(k, 1);
    assert_int_equal(mcp_perc_subset_masks(16, 64, NULL, &k), 0);
    assert_int_equal(k, 64);
    assert_error_contains(mcp_perc_subset_masks(64, 8, masks, &k), "1 to 63 (got 64)");
    assert_error_contains(mcp_perc_subset_masks(4, 0, masks, &k),
                          "max_subsets must be >= 1");
}

static void
test_outputs_are_subset_means(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(40, 4, 1, 21, 1, &c);
    uint64_t masks[15];
    int k;
    assert_int_equal(mcp_perc_subset_masks(4, 15, masks, &k), 0);
    for (int init = 0; init < 2; init++) {
        mcp_perc_options o = mcp_perc_defaults();
        o.init = init ? MCP_PERC_INIT_MEAN : MCP_PERC_INIT_RANDOM;
        mcp_perc_result r;
        assert_int_equal(mcp_perc_power_set(perc_cands(&c), c.m, c.truth, &o, &r), 0);
        for (int y = 0; y < 40; y++)
            for (int x = 0; x < 40; x++) {
                float idx = mcp_image_px(r.index, x, y)[0];
                assert_true(idx >= 0.0f && idx < (float)k);
                uint64_t mask = masks[(int)idx];
                for (int ch = 0; ch < 3; ch++) {
                    double s = 0.0;
                    int n = 0;
                    for (int j = 0; j < 4; j++)
                        if ((mask >> j) & 1) s += mcp_image_px(c.cand[j], x, y)[ch], n++;
                    assert_true(mcp_image_px(r.image, x, y)[ch] == (float)(s / n));
                }
            }
        mcp_image *mean = NULL;
        double e;
        assert_int_equal(mcp_perc_mean(perc_cands(&c), c.m, &mean), 0);
        assert_int_equal(mcp_perc_energy(r.image, c.truth, mean, &o.model, &e), 0);
        /* see test_vertical.c: 1e-9 on the scale of the starting energy */
        assert_close(r.energy_final, e, 0, 1e-9 * r.energy_initial);
        assert_true(r.passes < 100);
        double ours = perc_pmse(r.image, c.truth), base = perc_mean_pmse(&c);
        mcp_perc_result v;
        assert_int_equal(
            mcp_perc_vertical_iterative(perc_cands(&c), c.m, c.truth, &o, &v), 0);
        double vert = perc_pmse(v.image, c.truth);
        print_message(
            "power set (%s start): pMSE %.5f, vertical %.5f, mean %.5f (ratio %.3f)\n",
            init ? "mean" : "random", ours, vert, base, ours / base);
        assert_true(ours < base);
        assert_true(ours < vert); /* a larger search space, here a better fit */
        mcp_perc_result_free(&v);
        mcp_image_free(mean);
        mcp_perc_result_free(&r);
    }
    perc_case_free(&c);
}

/* A cap leaves fewer subsets; index values stay below it. */
static void
test_cap(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(16, 6, 1, 3, 1, &c);
    mcp_perc_options o = mcp_perc_defaults();
    o.max_subsets = 10;
    mcp_perc_result r;
    assert_int_equal(mcp_perc_power_set(perc_cands(&c), c.m, c.truth, &o, &r), 0);
    for (size_t p = 0; p < 16 * 16; p++)
        assert_true(r.index->data[p] < 10.0f);
    mcp_perc_result_free(&r);
    assert_error_contains(mcp_perc_power_set(perc_cands(&c), c.m, NULL, &o, &r),
                          "needs a surrogate");
    perc_case_free(&c);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_subset_masks),
        cmocka_unit_test(test_outputs_are_subset_means),
        cmocka_unit_test(test_cap),
    };
    return cmocka_run_group_tests_name("perceptual/powerset", tests, NULL, NULL);
}
