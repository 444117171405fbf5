/* test_diffusion.c: perceptual/diffusion.c -- Floyd-Steinberg error diffusion against
 * results computed by hand on tiny images (serpentine direction, mirrored weights,
 * dropped weights at the borders), outputs drawn from the candidates, and the same as
 * a plain reimplementation on a larger image with every thread count. */
#include "perc_testing.h"

#include <math.h>
#include <omp.h>
#include "../../perceptual/internal.h"

static mcp_image *
grey(int w, int h, const float *v)
{
    mcp_image *img = mcp_test_constant(w, h, 3, 0.0f, (const char *[]){"R", "G", "B"});
    for (int i = 0; i < w * h; i++)
        for (int c = 0; c < 3; c++)
            img->data[i * 3 + c] = v[i];
    return img;
}

static void
run_grey(int w, int h, const float *surr, const float *levels, int m, const float *want)
{
    mcp_image *c[4], *s = grey(w, h, surr);
    for (int j = 0; j < m; j++) {
        float *v = malloc((size_t)w * h * sizeof *v);
        for (int i = 0; i < w * h; i++)
            v[i] = levels[j];
        c[j] = grey(w, h, v);
        free(v);
    }
    mcp_perc_options o = mcp_perc_defaults();
    o.model.tone_map = MCP_TONEMAP_NONE;
    mcp_perc_result r;
    assert_int_equal(mcp_perc_error_diffusion((const mcp_image *const *)c, m, s, &o, &r),
                     0);
    for (int i = 0; i < w * h; i++)
        for (int ch = 0; ch < 3; ch++)
            if (r.image->data[i * 3 + ch] != want[i])
                fail_msg("pixel %d: %g, by hand %g", i, r.image->data[i * 3 + ch],
                         want[i]);
    perc_assert_from_candidates(r.image, r.index, (const mcp_image *const *)c, m);
    assert_int_equal(r.passes, 1);
    mcp_perc_result_free(&r);
    for (int j = 0; j < m; j++)
        mcp_image_free(c[j]);
    mcp_image_free(s);
}

/* 2x2, surrogate 0.4, candidates 0 and 1 (grey, T = none):
 *  (0,0) v = 0.4 -> 0, e = 0.4: (1,0) += 0.175, (0,1) += 0.125, (1,1) += 0.025
 *        ((-1,1) falls outside: dropped)
 *  (1,0) v = 0.575 -> 1, e = -0.425: (0,1) += -0.0796875, (1,1) += -0.1328125
 *  row 1 runs right to left:
 *  (1,1) v = 0.4 + 0.025 - 0.1328125 = 0.2921875 -> 0: (0,1) += 7/16 e = 0.127832..
 *  (0,1) v = 0.4 + 0.125 - 0.0796875 + 0.1278320 = 0.5731445 -> 1 */
static void
test_hand_2x2(void **state)
{
    (void)state;
    const float surr[4] = {0.4f, 0.4f, 0.4f, 0.4f}, levels[2] = {0.0f, 1.0f};
    const float want[4] = {0.0f, 1.0f, 1.0f, 0.0f};
    run_grey(2, 2, surr, levels, 2, want);
}

/* One row, surrogate 0.3, candidates 0, 0.5, 1: v = 0.3 -> 0.5 (e = -0.2); next
 * v = 0.3 - 0.0875 = 0.2125 -> 0 (e = 0.2125); next v = 0.3 + 0.0929688 = 0.3929688
 * -> 0.5 (e = -0.1070313); next v = 0.3 - 0.0468262 = 0.2531738 -> 0.5 (0.2531738 is
 * nearer 0.5 than 0 by 0.0063). */
static void
test_hand_row(void **state)
{
    (void)state;
    const float surr[4] = {0.3f, 0.3f, 0.3f, 0.3f}, levels[3] = {0.0f, 0.5f, 1.0f};
    const float want[4] = {0.5f, 0.0f, 0.5f, 0.5f};
    run_grey(4, 1, surr, levels, 3, want);
}

/* 2x3 column-first check of the mirrored weights: surrogate 0.5 in a 1-wide column
 * image: each pixel pushes only 5/16 down (ahead and the diagonals fall outside):
 *  y0 v = 0.5 -> tie between 0 and 1: the first candidate (0), e = 0.5
 *  y1 v = 0.5 + 0.15625 = 0.65625 -> 1, e = -0.34375
 *  y2 v = 0.5 - 0.107421875 = 0.392578125 -> 0 */
static void
test_hand_column(void **state)
{
    (void)state;
    const float surr[3] = {0.5f, 0.5f, 0.5f}, levels[2] = {0.0f, 1.0f};
    const float want[3] = {0.0f, 1.0f, 0.0f};
    run_grey(1, 3, surr, levels, 2, want);
}

/* A plain reimplementation on procedural inputs (45x45, 100x100) with the default clamp
 * tone map: a full-image buffer of the error pushed to the next rows, the 7/16 share
 * carried to the next pixel, one candidate after another, summed in the same order as the
 * library (so that no near-tie can round differently); then the library with one and
 * two threads. */
static void
against_plain(int m, int size)
{
    perc_case c;
    perc_procedural(size, m, 1, 17, 1, &c);
    int w = size, h = size;
    double *err = calloc((size_t)w * h * 3, sizeof *err);
    int *want = malloc((size_t)w * h * sizeof *want);
    for (int y = 0; y < h; y++) {
        double ahead[3] = {0.0, 0.0, 0.0};
        for (int i = 0; i < w; i++) {
            int x = y % 2 ? w - 1 - i : i, dir = y % 2 ? -1 : 1, best = 0;
            /* q: the error arriving here; the distance to candidate j is that of q
             * to T(Q_j) - T(I') (the library's association of the same sums) */
            double q[3], s[3], bd = INFINITY, e[3];
            for (int ch = 0; ch < 3; ch++) {
                s[ch] =
                    mcp_tonemap_value(MCP_TONEMAP_CLAMP, mcp_image_px(c.truth, x, y)[ch]);
                q[ch] = err[((size_t)y * w + x) * 3 + ch] + ahead[ch];
            }
            for (int j = 0; j < c.m; j++) {
                double d = 0.0;
                for (int ch = 0; ch < 3; ch++) {
                    double t = mcp_tonemap_value(MCP_TONEMAP_CLAMP,
                                                 mcp_image_px(c.cand[j], x, y)[ch]);
                    double dc = q[ch] - (t - s[ch]);
                    d += dc * dc;
                }
                if (d < bd) bd = d, best = j;
            }
            for (int ch = 0; ch < 3; ch++) {
                double t = mcp_tonemap_value(MCP_TONEMAP_CLAMP,
                                             mcp_image_px(c.cand[best], x, y)[ch]);
                e[ch] = q[ch] - (t - s[ch]);
                ahead[ch] = e[ch] * (7.0 / 16.0);
            }
            static const int dx[3] = {-1, 0, 1};
            static const double wt[3] = {3.0 / 16, 5.0 / 16, 1.0 / 16};
            for (int k = 0; k < 3 && y + 1 < h; k++) {
                int qx = x + dx[k] * dir;
                if (qx >= 0 && qx < w)
                    for (int ch = 0; ch < 3; ch++)
                        err[((size_t)(y + 1) * w + qx) * 3 + ch] += e[ch] * wt[k];
            }
            want[(size_t)y * w + x] = best;
        }
    }
    int threads = omp_get_max_threads();
    for (int nt = 1; nt <= 2; nt++) {
        omp_set_num_threads(nt);
        mcp_perc_result r;
        assert_int_equal(mcp_perc_error_diffusion(perc_cands(&c), c.m, c.truth, NULL, &r),
                         0);
        for (size_t p = 0; p < (size_t)w * h; p++)
            assert_int_equal((int)r.index->data[p], want[p]);
        perc_assert_from_candidates(r.image, r.index, perc_cands(&c), c.m);
        double ours = perc_pmse(r.image, c.truth), mean = perc_mean_pmse(&c);
        if (nt == 1)
            print_message(
                "error diffusion, %dx%d, M = %d, reference surrogate: pMSE %.5f "
                "vs mean %.5f (ratio %.3f)\n",
                size, size, m, ours, mean, ours / mean);
        mcp_perc_result_free(&r);
    }
    omp_set_num_threads(threads);
    free(err), free(want);
    perc_case_free(&c);
}

/* every path of the scan: one candidate, pairs, a pair and a single one, and the
 * general count; rows of at least 256 candidate values run the two-thread pipeline
 * (with two threads): M = 6 here, and M = 4 on 100x100 (the ring wraps many times) */
static void
test_against_plain(void **state)
{
    (void)state;
    for (int m = 1; m <= 6; m++)
        against_plain(m, 45);
    against_plain(4, 100);
}

static void
test_errors(void **state)
{
    (void)state;
    perc_case c;
    perc_procedural(8, 2, 1, 1, 0, &c);
    mcp_perc_result r;
    assert_error_contains(mcp_perc_error_diffusion(perc_cands(&c), c.m, NULL, NULL, &r),
                          "needs a surrogate");
    mcp_image *nan = mcp_test_constant(8, 8, 3, NAN, (const char *[]){"R", "G", "B"});
    assert_error_contains(mcp_perc_error_diffusion(perc_cands(&c), c.m, nan, NULL, &r),
                          "192 non-finite values");
    assert_null(r.image);
    mcp_image_free(nan);
    perc_case_free(&c);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_hand_2x2),    cmocka_unit_test(test_hand_row),
        cmocka_unit_test(test_hand_column), cmocka_unit_test(test_against_plain),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("perceptual/diffusion", tests, NULL, NULL);
}
