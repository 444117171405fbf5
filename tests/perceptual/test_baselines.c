/* test_baselines.c: perceptual/baselines.c -- Heitz & Belcour's histogram method takes
 * the estimate at index floor(B M) of the luminance order, and their permutation method
 * gives, per tile, the k-th darkest pixel's seed to the k-th smallest threshold (a
 * bijection within each tile, partial tiles at the edges included); both worked against
 * direct computations with given masks, and run with the generated one. */
#include "perc_testing.h"

#include <math.h>
#include <stdlib.h>
#include "../../perceptual/internal.h"

static float
lum_at(const mcp_image *img, int x, int y)
{
    const float *p = mcp_image_px(img, x, y);
    return mcp_luminance(p[0], p[1], p[2]);
}

static void
test_histogram(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(20, 5, 1, 51, 1, &c);
    mcp_image *mask = mcp_test_random(7, 3, 1, 0.0f, 0.999f, 2, NULL);
    mcp_perc_options o = mcp_perc_defaults();
    o.mask_image = mask;
    o.mask.use_cache = 0; /* tests leave ~/.cache alone */
    mcp_perc_result r;
    assert_int_equal(mcp_perc_histogram(perc_cands(&c), c.m, &o, &r), 0);
    perc_assert_from_candidates(r.image, r.index, perc_cands(&c), c.m);
    for (int y = 0; y < 20; y++)
        for (int x = 0; x < 20; x++) {
            int k = (int)(mcp_image_px(mask, x % 7, y % 3)[0] * c.m),
                j = (int)r.index->data[y * 20 + x];
            /* j must have exactly k candidates below it in (luminance, index) order */
            int below = 0;
            for (int i = 0; i < c.m; i++) {
                float li = lum_at(c.cand[i], x, y), lj = lum_at(c.cand[j], x, y);
                below += li < lj || (li == lj && i < j);
            }
            assert_int_equal(below, k);
        }
    mcp_perc_result_free(&r);
    /* B near 0 takes the darkest; the generated mask runs */
    mcp_image *zero = mcp_test_constant(1, 1, 1, 0.0f, NULL);
    o.mask_image = zero;
    assert_int_equal(mcp_perc_histogram(perc_cands(&c), c.m, &o, &r), 0);
    for (int p = 0; p < 400; p++)
        for (int i = 0; i < c.m; i++)
            assert_true(lum_at(c.cand[(int)r.index->data[p]], p % 20, p / 20) <=
                        lum_at(c.cand[i], p % 20, p / 20));
    mcp_perc_result_free(&r);
    o.mask_image = NULL;
    assert_int_equal(mcp_perc_histogram(perc_cands(&c), c.m, &o, &r), 0);
    double ours = perc_pmse(r.image, c.truth), mean = perc_mean_pmse(&c);
    print_message(
        "histogram (Heitz & Belcour 2019): pMSE %.5f vs mean %.5f (ratio %.3f)\n", ours,
        mean, ours / mean);
    mcp_perc_result_free(&r);
    mcp_image_free(zero);
    mcp_image_free(mask);
    perc_case_free(&c);
}

static void
test_permutation(void **state)
{
    (void)state;
    int w = 19, h = 13, tile = 8; /* partial tiles at the right and bottom */
    mcp_image *q =
        mcp_test_random(w, h, 3, 0.0f, 1.0f, 3, (const char *[]){"R", "G", "B"});
    mcp_image *mask = mcp_test_random(16, 16, 1, 0.0f, 0.999f, 4, NULL);
    mcp_perc_options o = mcp_perc_defaults();
    o.mask_image = mask;
    mcp_perc_result r;
    assert_int_equal(mcp_perc_permutation(q, &o, &r), 0);
    assert_null(r.index);
    for (int ty = 0; ty < h; ty += tile)
        for (int tx = 0; tx < w; tx += tile) {
            int tw = tx + tile <= w ? tile : w - tx, th = ty + tile <= h ? tile : h - ty;
            for (int y = ty; y < ty + th; y++)
                for (int x = tx; x < tx + tw; x++) {
                    const float *m = mcp_image_px(r.permutation, x, y);
                    int sx = (int)m[0], sy = (int)m[1];
                    assert_true(sx >= tx && sx < tx + tw && sy >= ty && sy < ty + th);
                    /* rank of the position's threshold == rank of the source's luminance
                     */
                    int rank_b = 0, rank_l = 0;
                    float b = mcp_image_px(mask, x % 16, y % 16)[0],
                          l = lum_at(q, sx, sy);
                    for (int yy = ty; yy < ty + th; yy++)
                        for (int xx = tx; xx < tx + tw; xx++) {
                            float bb = mcp_image_px(mask, xx % 16, yy % 16)[0];
                            float ll = lum_at(q, xx, yy);
                            int k = (yy - ty) * tw + xx - tx, kp = (y - ty) * tw + x - tx;
                            int ks = (sy - ty) * tw + sx - tx;
                            rank_b += bb < b || (bb == b && k < kp);
                            rank_l += ll < l || (ll == l && k < ks);
                        }
                    assert_int_equal(rank_b, rank_l);
                    for (int ch = 0; ch < 3; ch++)
                        assert_true(mcp_image_px(r.image, x, y)[ch] ==
                                    mcp_image_px(q, sx, sy)[ch]);
                }
        }
    mcp_perc_result_free(&r);
    o.tile = 1;
    assert_error_contains(mcp_perc_permutation(q, &o, &r),
                          "tile must be in [2, 256] (got 1)");
    mcp_image_free(mask);
    mcp_image_free(q);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_histogram),
        cmocka_unit_test(test_permutation),
    };
    return cmocka_run_group_tests_name("perceptual/baselines", tests, NULL, NULL);
}
