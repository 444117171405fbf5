/* test_procedural.c: the procedural renderer (samples/procedural) -- its realizations
 * average to its quadrature truth, its variances are right, permuted seeds re-render
 * exactly, and nothing depends on the thread count.
 *
 * The statistical tests use fixed seeds, so they are deterministic; their tolerances
 * are multiples of standard errors with margins checked over 30-40 other seeds, so a
 * correct renderer passes for almost any seed (each is explained where it is used). */
#include "testing.h"

#include "procedural.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include <mcpost/dump.h>
#include <mcpost/imageio.h>

#define W 32
#define H 32
#define K 16   /* realizations */
#define SPP 16 /* samples per pixel of each (64 where said) */

static mcp_proc_scene
small_scene(double firefly_probability)
{
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = W;
    s.height = H;
    s.firefly_probability = firefly_probability;
    return s;
}

static mcp_dump *
render_or_fail(const mcp_proc_scene *s, int spp, uint64_t seed, const mcp_image *perm)
{
    mcp_dump *d = NULL;
    if (mcp_proc_render(s, spp, seed, perm, &d))
        fail_msg("mcp_proc_render: %s", mcp_error_message());
    return d;
}

static void
truth_or_fail(const mcp_proc_scene *s, mcp_image **mean, mcp_image **var)
{
    if (mcp_proc_truth(s, mean, var)) fail_msg("mcp_proc_truth: %s", mcp_error_message());
}

/* Per pixel and channel, over K realizations: the mean of the colours, the mean of
 * the dumps' var_of_mean, and the unbiased spread of the colours. */
typedef struct {
    double avg[W * H * 3], var_of_mean[W * H * 3], spread[W * H * 3];
} stats;

static void
realization_stats(const mcp_proc_scene *s, uint64_t seed, int spp, stats *st)
{
    static double sum2[W * H * 3];
    memset(st, 0, sizeof *st);
    memset(sum2, 0, sizeof sum2);
    for (int r = 0; r < K; r++) {
        mcp_dump *d = render_or_fail(s, spp, mcp_proc_realization_seed(seed, r), NULL);
        assert_true(d->spp == spp);
        for (int i = 0; i < W * H * 3; i++) {
            double v = d->color->data[i];
            st->avg[i] += v / K;
            sum2[i] += v * v;
            st->var_of_mean[i] += d->var_of_mean->data[i] / K;
        }
        mcp_dump_free(d);
    }
    for (int i = 0; i < W * H * 3; i++)
        st->spread[i] = fmax(0.0, (sum2[i] - K * st->avg[i] * st->avg[i]) / (K - 1));
}

/* ---- the realizations average to the truth ---- */

static void
test_realizations_average_to_truth(void **state)
{
    (void)state;
    static stats st;
    /* Per pixel without fireflies: with them a pixel's few rare 100x samples make its
     * mean far from Gaussian (see the image-mean test below). */
    mcp_proc_scene s = small_scene(0.0);
    mcp_image *truth = NULL, *tvar = NULL;
    truth_or_fail(&s, &truth, &tvar);
    const int spp = 64;
    const double n = (double)K * spp; /* samples behind each average */
    realization_stats(&s, 11, spp, &st);
    double worst = 0, mean_err[3] = {0}, mean_var[3] = {0};
    int outside_dump = 0;
    for (int i = 0; i < W * H * 3; i++) {
        double err = fabs(st.avg[i] - truth->data[i]);
        /* The standard error of the average, from the exact per-sample variance and
         * from the dumps' own variance. */
        double se_true = sqrt(tvar->data[i] / n), se_dump = sqrt(st.var_of_mean[i] / K);
        /* 5 exact standard errors, plus two lit samples' worth (2 * 0.8 / n; the
         * direct light adds at most 0.75 to a sample) for the one non-Gaussian case:
         * at the border of the umbra a sample is lit with a probability q << 1/n, and
         * one lit sample is 1 / sqrt(q n) standard errors away. The tolerance then
         * fails with probability < 2e-5 per value (Poisson tail, any q); over 30
         * seeds the largest error / tolerance was 0.82. 1e-6 covers float storage. */
        double tol = 5.0 * se_true + 2.0 * 0.8 / n + 1e-6;
        worst = fmax(worst, err / tol);
        if (!(err <= tol))
            fail_msg("value %d (pixel %d, %d): average %.6f, truth %.6f, se %.2g", i,
                     i / 3 % W, i / 3 / W, st.avg[i], truth->data[i], se_true);
        outside_dump += !(err <= 5.0 * se_dump + 1e-6);
        mean_err[i % 3] += (st.avg[i] - truth->data[i]) / (W * H);
        mean_var[i % 3] += st.var_of_mean[i] / K / ((double)W * H * W * H);
    }
    /* The dumps' own variance is right on average (test_variance_matches_spread) but
     * misses the same rare lit (or shadowed) samples where none was drawn: ~1% of
     * the values (at most 25 of 3072 over 30 seeds) are such penumbra-border pixels;
     * a biased renderer would push most values out. */
    print_message("largest error / tolerance: %.2f; outside 5 dump se: %d of %d\n", worst,
                  outside_dump, W * H * 3);
    assert_true(outside_dump < W * H * 3 / 50);
    /* The image means, within 5 standard errors from the dumps' variances (a bias of
     * ~1e-3 over the image would show). */
    for (int c = 0; c < 3; c++) {
        print_message("channel %d: image mean error %.3g, se %.2g\n", c, mean_err[c],
                      sqrt(mean_var[c]));
        assert_close(mean_err[c], 0.0, 0.0, 5.0 * sqrt(mean_var[c]));
    }
    mcp_image_free(truth);
    mcp_image_free(tvar);
}

static void
test_image_mean_with_fireflies(void **state)
{
    (void)state;
    static stats st;
    mcp_proc_scene s = small_scene(1e-3); /* the default scene */
    mcp_image *truth = NULL;
    truth_or_fail(&s, &truth, NULL);
    realization_stats(&s, 12, SPP, &st);
    /* Per channel, the image mean of the average, against the truth's, within 5
     * standard errors of that mean (pixels are independent: their variances add). The
     * K*W*H*SPP = 262144 samples hold ~260 fireflies, enough for the central limit. */
    for (int c = 0; c < 3; c++) {
        double a = 0, t = 0, v = 0;
        for (int p = 0; p < W * H; p++) {
            a += st.avg[3 * p + c] / (W * H);
            t += truth->data[3 * p + c] / (W * H);
            v += st.var_of_mean[3 * p + c] / K / ((double)W * H * W * H);
        }
        print_message("channel %d: image mean %.6f, truth %.6f, se %.2g\n", c, a, t,
                      sqrt(v));
        assert_close(a, t, 0.0, 5.0 * sqrt(v));
    }
    mcp_image_free(truth);
}

/* ---- variances ---- */

static void
test_variance_matches_spread(void **state)
{
    (void)state;
    static stats st;
    mcp_proc_scene s = small_scene(1e-3);
    mcp_image *truth = NULL, *tvar = NULL;
    truth_or_fail(&s, &truth, &tvar);
    realization_stats(&s, 13, 64, &st);
    for (int c = 0; c < 3; c++) {
        double dump = 0, spread = 0, exact = 0;
        for (int p = 0; p < W * H; p++) {
            dump += st.var_of_mean[3 * p + c];
            spread += st.spread[3 * p + c];
            exact += tvar->data[3 * p + c] / 64;
        }
        print_message("channel %d: var_of_mean %.4g, spread %.4g, exact %.4g\n", c,
                      dump / (W * H), spread / (W * H), exact / (W * H));
        /* The dump's variance and the spread see the same samples: their ratio stays
         * near 1 (0.96..1.02 over 40 seeds at 16 spp). Against the exact variance,
         * both are dominated by the ~1050 fireflies among the 16 * 64 * 1024 samples,
         * whose count varies by ~3%: [0.8, 1.25] leaves more than 6 such standard
         * deviations. */
        assert_in_range((long)(1000 * dump / spread), 800, 1250);
        assert_in_range((long)(1000 * dump / exact), 800, 1250);
    }
    /* Without fireflies the dumps' variance is much steadier: its image mean is the
     * exact one within 5% (over 40 seeds it stayed within 1.6%). */
    s = small_scene(0.0);
    mcp_image_free(tvar);
    mcp_image_free(truth);
    truth_or_fail(&s, &truth, &tvar);
    realization_stats(&s, 14, SPP, &st);
    double dump = 0, exact = 0;
    for (int i = 0; i < W * H * 3; i++) {
        dump += st.var_of_mean[i];
        exact += tvar->data[i] / SPP;
    }
    print_message("no fireflies: var_of_mean / exact, image means: %.4f\n", dump / exact);
    assert_close(dump / exact, 1.0, 0.0, 0.05);
    mcp_image_free(truth);
    mcp_image_free(tvar);
}

/* ---- the truth ---- */

static void
test_truth_precision(void **state)
{
    (void)state;
    /* Orders 8 (the default) and 16 agree to the claimed 1e-12 (absolute, on values of
     * ~1 and variances of ~10) in every pixel: the pieces are smooth, so the error of
     * the coarser rule is the difference. */
    mcp_proc_scene lo = small_scene(1e-3), hi = lo;
    hi.truth_order = 16;
    double worst_mean = 0, worst_var = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double m0[3], v0[3], m1[3], v1[3];
            assert_int_equal(mcp_proc_truth_pixel(&lo, x, y, m0, v0), 0);
            assert_int_equal(mcp_proc_truth_pixel(&hi, x, y, m1, v1), 0);
            for (int c = 0; c < 3; c++) {
                worst_mean = fmax(worst_mean, fabs(m0[c] - m1[c]));
                worst_var = fmax(worst_var, fabs(v0[c] - v1[c]));
            }
        }
    print_message("order 8 vs 16: mean %.2g, variance %.2g\n", worst_mean, worst_var);
    assert_true(worst_mean < 1e-12);
    assert_true(worst_var < 1e-11);
    /* a low order shows the comparison can fail: order 2 is visibly off */
    lo.truth_order = 2;
    double m0[3], v0[3], m1[3], v1[3];
    assert_int_equal(mcp_proc_truth_pixel(&lo, 9, 6, m0, v0), 0);
    assert_int_equal(mcp_proc_truth_pixel(&hi, 9, 6, m1, v1), 0);
    assert_true(fabs(m0[1] - m1[1]) > 1e-9);

    /* the image is the per-pixel truth, rounded to float */
    mcp_image *img = NULL;
    hi.truth_order = 8;
    truth_or_fail(&hi, &img, NULL);
    assert_int_equal(mcp_proc_truth_pixel(&hi, 17, 3, m0, v0), 0);
    for (int c = 0; c < 3; c++)
        assert_true(mcp_image_px(img, 17, 3)[c] == (float)m0[c]);
    mcp_image_free(img);
}

static void
test_truth_is_a_box_filter_of_the_integrand(void **state)
{
    (void)state;
    /* A check independent of how the quadrature cuts pixels: the camera shows the same
     * scene at any image size, so each pixel of an 8x8 image covers exactly 2x2
     * pixels of a 16x16 one, and the 1x1 image (the whole scene in one pixel, crossed
     * by 48 edges, the most of any size) is the mean of the 8x8 one. */
    mcp_proc_scene a = small_scene(1e-3), b = a, one = a;
    a.width = a.height = 8;
    b.width = b.height = 16;
    one.width = one.height = 1;
    mcp_image *ta = NULL, *tb = NULL, *t1 = NULL;
    truth_or_fail(&a, &ta, NULL);
    truth_or_fail(&b, &tb, NULL);
    truth_or_fail(&one, &t1, NULL);
    double worst = 0;
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 8; x++)
            for (int c = 0; c < 3; c++) {
                double sum = 0;
                for (int k = 0; k < 4; k++)
                    sum += mcp_image_px(tb, 2 * x + k % 2, 2 * y + k / 2)[c] / 4.0;
                worst = fmax(worst, fabs(sum - mcp_image_px(ta, x, y)[c]));
            }
    /* float storage of values up to ~2 */
    assert_true(worst < 1e-6);
    for (int c = 0; c < 3; c++) {
        double sum = 0;
        for (int p = 0; p < 64; p++)
            sum += ta->data[3 * p + c] / 64.0;
        assert_close(sum, t1->data[c], 0.0, 1e-6);
    }
    mcp_image_free(t1);
    mcp_image_free(ta);
    mcp_image_free(tb);
}

/* ---- permutations ---- */

static mcp_image *
identity_map(int w, int h)
{
    mcp_image *m = NULL;
    if (mcp_image_new(w, h, 2, (const char *[]){"X", "Y"}, &m))
        fail_msg("%s", mcp_error_message());
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            mcp_image_px(m, x, y)[0] = (float)x;
            mcp_image_px(m, x, y)[1] = (float)y;
        }
    return m;
}

static int
same_pixels(const mcp_image *a, const mcp_image *b, int x, int y)
{
    return !memcmp(mcp_image_px(a, x, y), mcp_image_px(b, x, y), 3 * sizeof(float));
}

static void
test_permutation_rerenders_with_borrowed_seeds(void **state)
{
    (void)state;
    mcp_proc_scene s = small_scene(1e-3);
    mcp_image *map = identity_map(W, H);
    mcp_dump *plain = render_or_fail(&s, 8, 5, NULL);
    mcp_dump *same = render_or_fail(&s, 8, 5, map);
    assert_memory_equal(plain->color->data, same->color->data, W * H * 3 * sizeof(float));
    assert_memory_equal(plain->var_of_mean->data, same->var_of_mean->data,
                        W * H * 3 * sizeof(float));
    mcp_dump_free(same);

    /* swap p = (3, 5) and q = (20, 11) */
    const int px = 3, py = 5, qx = 20, qy = 11;
    mcp_image_px(map, px, py)[0] = qx, mcp_image_px(map, px, py)[1] = qy;
    mcp_image_px(map, qx, qy)[0] = px, mcp_image_px(map, qx, qy)[1] = py;
    mcp_dump *swapped = render_or_fail(&s, 8, 5, map);
    mcp_proc_pixel at_p, at_q;
    assert_int_equal(mcp_proc_render_pixel(&s, px, py, qx, qy, 8, 5, 0, &at_p), 0);
    assert_int_equal(mcp_proc_render_pixel(&s, qx, qy, px, py, 8, 5, 0, &at_q), 0);
    for (int c = 0; c < 3; c++) {
        assert_true(mcp_image_px(swapped->color, px, py)[c] == (float)at_p.mean[c]);
        assert_true(mcp_image_px(swapped->color, qx, qy)[c] == (float)at_q.mean[c]);
        assert_true(mcp_image_px(swapped->var_of_mean, px, py)[c] ==
                    (float)(at_p.var_per_sample[c] / 8));
    }
    /* the integrand stays p's: p rendered with its own seed is the plain pixel */
    mcp_proc_pixel own;
    assert_int_equal(mcp_proc_render_pixel(&s, px, py, px, py, 8, 5, 0, &own), 0);
    for (int c = 0; c < 3; c++)
        assert_true(mcp_image_px(plain->color, px, py)[c] == (float)own.mean[c]);
    assert_false(same_pixels(plain->color, swapped->color, px, py));
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            if (!((x == px && y == py) || (x == qx && y == qy)))
                assert_true(same_pixels(plain->color, swapped->color, x, y));
    mcp_dump_free(swapped);
    mcp_dump_free(plain);

    /* bad maps */
    mcp_dump *d = (mcp_dump *)1;
    mcp_image_set_source(map, "perm.exr");
    mcp_image_px(map, 7, 2)[0] = (float)W;
    assert_error_contains(mcp_proc_render(&s, 4, 5, map, &d),
                          "perm.exr: pixel (7, 2) has source (32, 2), not a pixel");
    assert_null(d);
    mcp_image_px(map, 7, 2)[0] = 1.5f;
    assert_error_contains(mcp_proc_render(&s, 4, 5, map, &d), "source (1.5, 2)");
    mcp_image_free(map);
    map = identity_map(W, H + 1);
    mcp_image_set_source(map, "perm.exr");
    assert_error_contains(mcp_proc_render(&s, 4, 5, map, &d),
                          "perm.exr: permutation size 32x33 does not match the image");
    mcp_image_free(map);
    map = mcp_test_constant(W, H, 2, 0.0f, (const char *[]){"X", "Z"});
    mcp_image_set_source(map, "perm.exr");
    assert_error_contains(mcp_proc_render(&s, 4, 5, map, &d), "no channel 'Y'");
    mcp_image_free(map);
}

/* ---- independent images, threads, errors ---- */

static void
test_single_sample_images(void **state)
{
    (void)state;
    mcp_proc_scene s = small_scene(1e-3);
    enum { M = 8 };
    mcp_image *one[M];
    assert_int_equal(mcp_proc_render_samples(&s, M, 1, 21, NULL, one), 0);
    mcp_dump *d = render_or_fail(&s, M, 21, NULL);
    /* image k holds sample k of every stream, so their mean is the M-sample render */
    for (int i = 0; i < W * H * 3; i++) {
        double mean = 0;
        for (int k = 0; k < M; k++)
            mean += one[k]->data[i] / M;
        assert_close(mean, d->color->data[i], 1e-6, 1e-6);
    }
    /* and they differ from each other */
    assert_true(mcp_test_max_abs_diff(one[0], one[1]) > 0.1);
    /* two-sample images are pairs of the same samples */
    mcp_image *two[M / 2];
    assert_int_equal(mcp_proc_render_samples(&s, M / 2, 2, 21, NULL, two), 0);
    for (int i = 0; i < W * H * 3; i++)
        assert_close(two[1]->data[i], 0.5 * (one[2]->data[i] + one[3]->data[i]), 1e-6,
                     1e-6);
    for (int k = 0; k < M; k++)
        mcp_image_free(one[k]);
    for (int k = 0; k < M / 2; k++)
        mcp_image_free(two[k]);
    mcp_dump_free(d);
}

static void
test_thread_count_does_not_matter(void **state)
{
    (void)state;
    mcp_proc_scene s = small_scene(1e-3);
    s.width = 37; /* rows of unequal cost and an odd size */
    mcp_dump *d[3];
    mcp_image *t[3], *one[3][2];
    int saved = omp_get_max_threads();
    for (int k = 0; k < 3; k++) {
        omp_set_num_threads(k + 1);
        d[k] = render_or_fail(&s, 4, 9, NULL);
        truth_or_fail(&s, &t[k], NULL);
        assert_int_equal(mcp_proc_render_samples(&s, 2, 1, 9, NULL, one[k]), 0);
    }
    omp_set_num_threads(saved);
    size_t bytes = (size_t)37 * H * 3 * sizeof(float);
    for (int k = 1; k < 3; k++) {
        assert_memory_equal(d[0]->color->data, d[k]->color->data, bytes);
        assert_memory_equal(d[0]->var_of_mean->data, d[k]->var_of_mean->data, bytes);
        assert_memory_equal(d[0]->albedo->data, d[k]->albedo->data, bytes);
        assert_memory_equal(t[0]->data, t[k]->data, bytes);
        assert_memory_equal(one[0][1]->data, one[k][1]->data, bytes);
    }
    for (int k = 0; k < 3; k++) {
        mcp_dump_free(d[k]);
        mcp_image_free(t[k]);
        mcp_image_free(one[k][0]);
        mcp_image_free(one[k][1]);
    }
}

static void
test_seeds_and_realizations(void **state)
{
    (void)state;
    assert_true(mcp_proc_realization_seed(77, 0) == 77);
    assert_true(mcp_proc_realization_seed(77, 1) != 77);
    assert_true(mcp_proc_realization_seed(77, 1) != mcp_proc_realization_seed(78, 1));
    mcp_proc_scene s = small_scene(1e-3);
    mcp_dump *a = render_or_fail(&s, 2, 1, NULL), *b = render_or_fail(&s, 2, 2, NULL);
    assert_true(mcp_test_max_abs_diff(a->color, b->color) > 0.1);
    /* a pixel rendered alone is the same pixel of the whole image */
    mcp_proc_pixel p;
    assert_int_equal(mcp_proc_render_pixel(&s, 30, 31, 30, 31, 2, 2, 0, &p), 0);
    assert_true(mcp_image_px(b->color, 30, 31)[2] == (float)p.mean[2]);
    assert_true(mcp_image_px(b->albedo, 30, 31)[0] == (float)p.albedo[0]);
    assert_true(mcp_image_px(b->normal, 30, 31)[1] == 1.0f);
    mcp_dump_free(a);
    mcp_dump_free(b);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_proc_scene s = small_scene(1e-3);
    mcp_dump *d = (mcp_dump *)1;
    mcp_image *img = (mcp_image *)1, *imgs[2] = {(mcp_image *)1, (mcp_image *)1};
    mcp_proc_pixel p;
    double m[3], v[3];
    assert_error_contains(mcp_proc_render(&s, 0, 1, NULL, &d),
                          "procedural: spp must be >= 1 (got 0)");
    assert_null(d);
    s.width = 0;
    assert_error_contains(mcp_proc_render(&s, 1, 1, NULL, &d),
                          "procedural: width must be in 1..65536 (got 0)");
    assert_error_contains(mcp_proc_truth(&s, &img, NULL), "width must be");
    assert_null(img);
    assert_error_contains(mcp_proc_render_samples(&s, 2, 1, 1, NULL, imgs), "width");
    assert_null(imgs[0]);
    assert_null(imgs[1]);
    s = small_scene(1.5);
    assert_error_contains(mcp_proc_scene_check(&s),
                          "firefly_probability must be in [0, 1] (got 1.5)");
    s = small_scene(0.0);
    s.firefly_value = -1;
    assert_error_contains(mcp_proc_scene_check(&s), "firefly_value must be finite");
    s = small_scene(0.0);
    s.truth_order = 33;
    assert_error_contains(mcp_proc_truth(&s, &img, NULL),
                          "truth_order must be in 1..32 (got 33)");
    s = small_scene(0.0);
    s.height = -3;
    assert_error_contains(mcp_proc_scene_check(&s),
                          "height must be in 1..65536 (got -3)");
    s = small_scene(0.0);
    assert_error_contains(mcp_proc_render_pixel(&s, 32, 0, 0, 0, 1, 1, 0, &p),
                          "pixel (32, 0) or source (0, 0) outside the 32x32 image");
    assert_error_contains(mcp_proc_truth_pixel(&s, 0, -1, m, v),
                          "pixel (0, -1) outside the 32x32 image");
    assert_error_contains(mcp_proc_render_samples(&s, 0, 1, 1, NULL, imgs),
                          "count must be >= 1 (got 0)");
}

/* ---- the command line ---- */

static int
run_cli(const char *args)
{
    char cmd[8192];
    snprintf(cmd, sizeof cmd, "'%s' %s > '%s' 2>&1", MCP_TEST_PROCEDURAL, args,
             mcp_test_path("cli.log"));
    int rc = system(cmd);
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

static void
test_cli_writes_dumps_truth_and_singles(void **state)
{
    (void)state;
    char args[4096];
    const char *prefix = mcp_test_path("cli");
    snprintf(args, sizeof args,
             "--width 24 --height 16 --spp 4 --seed 42 --realizations 2 --truth "
             "--singles 3 -o '%s'",
             prefix);
    assert_int_equal(run_cli(args), 0);
    mcp_proc_scene s = small_scene(1e-3);
    s.width = 24;
    s.height = 16;
    for (int r = 0; r < 2; r++) {
        char path[4096];
        snprintf(path, sizeof path, "%s_%04d.exr", prefix, r);
        mcp_dump *file = NULL,
                 *mem = render_or_fail(&s, 4, mcp_proc_realization_seed(42, r), NULL);
        if (mcp_dump_read(path, &file)) fail_msg("%s", mcp_error_message());
        assert_int_equal(file->convention, MCP_CONV_PBRT);
        assert_true(file->spp == 4);
        assert_true(mcp_test_max_abs_diff(file->color, mem->color) == 0);
        assert_true(mcp_test_max_abs_diff(file->albedo, mem->albedo) == 0);
        /* per-sample variance in the file: * 4 then / 4, in float */
        assert_true(mcp_test_max_abs_diff(file->var_of_mean, mem->var_of_mean) < 1e-6);
        mcp_dump_free(file);
        mcp_dump_free(mem);
    }
    mcp_image *truth = NULL, *read = NULL, *single[3];
    truth_or_fail(&s, &truth, NULL);
    snprintf(args, sizeof args, "%s_truth.exr", prefix);
    assert_int_equal(mcp_image_read(args, NULL, &read), 0);
    int rgb[3];
    assert_int_equal(mcp_image_channels(read, (const char *[]){"R", "G", "B"}, 3, rgb),
                     0);
    for (int y = 0; y < 16; y++)
        for (int x = 0; x < 24; x++)
            for (int c = 0; c < 3; c++)
                assert_true(mcp_image_px(read, x, y)[rgb[c]] ==
                            mcp_image_px(truth, x, y)[c]);
    mcp_image_free(read);
    mcp_image_free(truth);
    assert_int_equal(mcp_proc_render_samples(&s, 3, 1, 42, NULL, single), 0);
    snprintf(args, sizeof args, "%s_single_0002.exr", prefix);
    assert_int_equal(mcp_image_read(args, NULL, &read), 0);
    assert_int_equal(mcp_image_channels(read, (const char *[]){"R", "G", "B"}, 3, rgb),
                     0);
    for (int c = 0; c < 3; c++)
        assert_true(mcp_image_px(read, 5, 7)[rgb[c]] == mcp_image_px(single[2], 5, 7)[c]);
    mcp_image_free(read);
    for (int k = 0; k < 3; k++)
        mcp_image_free(single[k]);
}

static void
test_cli_permutation_and_errors(void **state)
{
    (void)state;
    mcp_image *map = identity_map(16, 16);
    const char *map_path = mcp_test_path("perm.exr");
    /* shift every pixel's seed one to the right, cyclically */
    for (int y = 0; y < 16; y++)
        for (int x = 0; x < 16; x++)
            mcp_image_px(map, x, y)[0] = (float)((x + 1) % 16);
    assert_int_equal(mcp_image_write(map, map_path, NULL), 0);
    char args[4096];
    const char *prefix = mcp_test_path("perm");
    snprintf(args, sizeof args,
             "--width 16 --height 16 --spp 2 --seed 3 --permutation '%s' -o '%s'",
             map_path, prefix);
    assert_int_equal(run_cli(args), 0);
    mcp_proc_scene s = small_scene(1e-3);
    s.width = s.height = 16;
    mcp_dump *mem = render_or_fail(&s, 2, 3, map), *file = NULL;
    snprintf(args, sizeof args, "%s_0000.exr", prefix);
    assert_int_equal(mcp_dump_read(args, &file), 0);
    assert_true(mcp_test_max_abs_diff(file->color, mem->color) == 0);
    mcp_dump_free(file);
    mcp_dump_free(mem);
    mcp_image_free(map);

    assert_int_equal(run_cli("--width 0 -o x"), 1);
    char *log = mcp_test_read_text(mcp_test_path("cli.log"));
    assert_non_null(
        strstr(log, "mcpost-procedural: --width must be an integer >= 1 (got '0')"));
    free(log);
    assert_int_equal(run_cli("--firefly-probability 2 -o x"), 1);
    log = mcp_test_read_text(mcp_test_path("cli.log"));
    assert_non_null(strstr(log, "firefly_probability must be in [0, 1] (got 2)"));
    free(log);
    assert_int_equal(run_cli("--bogus 3 -o x"), 1);
    log = mcp_test_read_text(mcp_test_path("cli.log"));
    assert_non_null(strstr(log, "unknown or incomplete option '--bogus'"));
    free(log);
    assert_int_equal(run_cli("--spp 4"), 1);
    log = mcp_test_read_text(mcp_test_path("cli.log"));
    assert_non_null(strstr(log, "no output prefix"));
    free(log);
    assert_int_equal(run_cli("--help"), 0);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_realizations_average_to_truth),
        cmocka_unit_test(test_image_mean_with_fireflies),
        cmocka_unit_test(test_variance_matches_spread),
        cmocka_unit_test(test_truth_precision),
        cmocka_unit_test(test_truth_is_a_box_filter_of_the_integrand),
        cmocka_unit_test(test_permutation_rerenders_with_borrowed_seeds),
        cmocka_unit_test(test_single_sample_images),
        cmocka_unit_test(test_thread_count_does_not_matter),
        cmocka_unit_test(test_seeds_and_realizations),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_cli_writes_dumps_truth_and_singles),
        cmocka_unit_test(test_cli_permutation_and_errors),
    };
    return cmocka_run_group_tests_name("samples/procedural", tests, NULL, NULL);
}
