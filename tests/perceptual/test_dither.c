/* test_dither.c: perceptual/dither.c -- threshold dithering against results worked by
 * hand on a tiny image with a given mask (lower/upper choice by the threshold, only a
 * lower or only an upper candidate, ties, the mask tiled), the generated blue-noise
 * mask in use, the same as a plain reimplementation for 1-6 candidates with every
 * thread count, and the error paths. */
#include "perc_testing.h"

#include <math.h>
#include <omp.h>
#include "../../perceptual/internal.h"

static mcp_image *
grey_row(int w, const float *v)
{
    mcp_image *img = mcp_test_constant(w, 1, 3, 0.0f, (const char *[]){"R", "G", "B"});
    for (int x = 0; x < w; x++)
        for (int c = 0; c < 3; c++)
            img->data[x * 3 + c] = v[x];
    return img;
}

/* Five pixels, grey, T = none (luminance = the grey value up to float rounding, far
 * from every decision below):
 *  x0  s 0.5,  candidates 0.2 0.9 0.6, B 0.8: lower 0.2, upper 0.6;
 *      s - lower = 0.3 < 0.8 * 0.4 = 0.32 -> lower 0.2
 *  x1  s 0.1,  candidates 0.3 0.5 0.4: no lower -> the smallest upper, 0.3
 *  x2  s 0.95, candidates 0.3 0.9 0.5: no upper -> the largest lower, 0.9
 *  x3  s 0.5,  candidates 0.2 0.9 0.6, B 0.7: 0.3 >= 0.7 * 0.4 = 0.28 -> upper 0.6
 *  x4  s 0.5,  candidates 0.2 0.2 0.6, B 0.8 (tiled: the mask is 4 wide) -> the first
 *      of the equal lowers, candidate 0 */
static void
test_hand(void **state)
{
    (void)state;
    const float s[5] = {0.5f, 0.1f, 0.95f, 0.5f, 0.5f};
    const float c0[5] = {0.2f, 0.3f, 0.3f, 0.2f, 0.2f};
    const float c1[5] = {0.9f, 0.5f, 0.9f, 0.9f, 0.2f};
    const float c2[5] = {0.6f, 0.4f, 0.5f, 0.6f, 0.6f};
    const float b[4] = {0.8f, 0.5f, 0.5f, 0.7f};
    const int want_index[5] = {0, 0, 1, 2, 0};
    mcp_image *c[3] = {grey_row(5, c0), grey_row(5, c1), grey_row(5, c2)};
    mcp_image *sur = grey_row(5, s), *mask = mcp_test_constant(4, 1, 1, 0.0f, NULL);
    memcpy(mask->data, b, sizeof b);
    mcp_perc_options o = mcp_perc_defaults();
    o.model.tone_map = MCP_TONEMAP_NONE;
    o.mask_image = mask;
    mcp_perc_result r;
    assert_int_equal(mcp_perc_dither((const mcp_image *const *)c, 3, sur, &o, &r), 0);
    for (int x = 0; x < 5; x++)
        assert_int_equal((int)r.index->data[x], want_index[x]);
    perc_assert_from_candidates(r.image, r.index, (const mcp_image *const *)c, 3);
    mcp_perc_result_free(&r);
    /* with the default clamp, 1.5 and 2.0 both display as 1: equal luminances above s
     * 0.7, no lower -> the first of the uppers */
    const float hi0[1] = {1.5f}, hi1[1] = {2.0f}, s1[1] = {0.7f};
    mcp_image *h[2] = {grey_row(1, hi0), grey_row(1, hi1)}, *s7 = grey_row(1, s1);
    o.model.tone_map = MCP_TONEMAP_CLAMP;
    assert_int_equal(mcp_perc_dither((const mcp_image *const *)h, 2, s7, &o, &r), 0);
    assert_int_equal((int)r.index->data[0], 0);
    mcp_perc_result_free(&r);
    for (int j = 0; j < 3; j++)
        mcp_image_free(c[j]);
    mcp_image_free(h[0]), mcp_image_free(h[1]), mcp_image_free(s7);
    mcp_image_free(sur), mcp_image_free(mask);
}

/* The generated void-and-cluster mask, on the procedural scene. */
static void
test_generated_mask(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(64, 4, 1, 31, 1, &c);
    mcp_perc_options o = mcp_perc_defaults();
    o.mask.use_cache = 0;
    mcp_perc_result r;
    assert_int_equal(mcp_perc_dither(perc_cands(&c), c.m, c.truth, &o, &r), 0);
    perc_assert_from_candidates(r.image, r.index, perc_cands(&c), c.m);
    double ours = perc_pmse(r.image, c.truth), mean = perc_mean_pmse(&c);
    print_message("dither, reference surrogate: pMSE %.5f vs mean %.5f (ratio %.3f)\n",
                  ours, mean, ours / mean);
    mcp_perc_result_free(&r);
    perc_case_free(&c);
}

/* A plain per-pixel reimplementation (sort-free bracket, tiled mask) on a 45x45
 * procedural input for 1 to 6 candidates and a 7x5 mask (so that neither the rows
 * nor the mask are multiples of the library's four-pixel groups), indices compared
 * exactly, with one and two threads. */
static void
test_against_plain(void **state)
{
    (void)state;
    int w = 45, h = 45, mw = 7, mh = 5;
    mcp_image *mask = mcp_test_constant(mw, mh, 1, 0.0f, NULL);
    for (int i = 0; i < mw * mh; i++)
        mask->data[i] = (float)((i * 37 % 35) / 35.0);
    int threads = omp_get_max_threads();
    for (int m = 1; m <= 6; m++) {
        perc_case c;
        perc_procedural(w, m, 1, 40 + m, 1, &c);
        mcp_perc_options o = mcp_perc_defaults();
        o.mask_image = mask;
        for (int nt = 1; nt <= 2; nt++) {
            omp_set_num_threads(nt);
            mcp_perc_result r;
            assert_int_equal(mcp_perc_dither(perc_cands(&c), m, c.truth, &o, &r), 0);
            for (int y = 0; y < h; y++)
                for (int x = 0; x < w; x++) {
                    const float *sp = mcp_image_px(c.truth, x, y);
                    float s = mcp_luminance(mcp_tonemap_value(MCP_TONEMAP_CLAMP, sp[0]),
                                            mcp_tonemap_value(MCP_TONEMAP_CLAMP, sp[1]),
                                            mcp_tonemap_value(MCP_TONEMAP_CLAMP, sp[2]));
                    int lo = -1, hi = -1;
                    float l[6];
                    for (int j = 0; j < m; j++) {
                        const float *cp = mcp_image_px(c.cand[j], x, y);
                        l[j] = mcp_luminance(mcp_tonemap_value(MCP_TONEMAP_CLAMP, cp[0]),
                                             mcp_tonemap_value(MCP_TONEMAP_CLAMP, cp[1]),
                                             mcp_tonemap_value(MCP_TONEMAP_CLAMP, cp[2]));
                        if (l[j] <= s && (lo < 0 || l[j] > l[lo])) lo = j;
                        if (l[j] > s && (hi < 0 || l[j] < l[hi])) hi = j;
                    }
                    int want;
                    if (lo < 0)
                        want = hi < 0 ? 0 : hi;
                    else if (hi < 0)
                        want = lo;
                    else
                        want = s - l[lo] < mask->data[(y % mh) * mw + x % mw] *
                                               (l[hi] - l[lo])
                                   ? lo
                                   : hi;
                    if ((int)r.index->data[(size_t)y * w + x] != want)
                        fail_msg("M = %d, %d threads, pixel %d, %d: %d, plain %d", m, nt,
                                 x, y, (int)r.index->data[(size_t)y * w + x], want);
                }
            perc_assert_from_candidates(r.image, r.index, perc_cands(&c), m);
            mcp_perc_result_free(&r);
        }
        perc_case_free(&c);
    }
    omp_set_num_threads(threads);
    mcp_image_free(mask);
}

static void
test_errors(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(8, 2, 1, 1, 0, &c);
    mcp_perc_result r;
    mcp_perc_options o = mcp_perc_defaults();
    assert_error_contains(mcp_perc_dither(perc_cands(&c), c.m, NULL, &o, &r),
                          "needs a surrogate");
    mcp_image *bad = mcp_test_constant(4, 4, 1, 1.0f, NULL);
    mcp_image_set_source(bad, "mask.exr");
    o.mask_image = bad;
    assert_error_contains(
        mcp_perc_dither(perc_cands(&c), c.m, c.truth, &o, &r),
        "mask.exr: mask values must be in [0, 1) (got 1 at pixel 0, 0)");
    o = mcp_perc_defaults();
    o.mask.size = 3;
    assert_error_contains(mcp_perc_dither(perc_cands(&c), c.m, c.truth, &o, &r),
                          "mask_size must be in [4, 1024] (got 3)");
    assert_null(r.image);
    mcp_image_free(bad);
    perc_case_free(&c);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hand),
        cmocka_unit_test(test_generated_mask),
        cmocka_unit_test(test_against_plain),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("perceptual/dither", tests, NULL, NULL);
}
