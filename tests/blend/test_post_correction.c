/* test_post_correction.c: blend/post_correction.c -- the James-Stein combiner against
 * its closed form on constant images and a naive window loop on random ones, its leak
 * of noise where d is right against the chi-square closed form (the reason for the
 * default window, docs/blend.md "The window"), and its rho in estimate's
 * post-correction variance (docs/mathematics.md §3.8). */
#include "blend_testing.h"

#include <math.h>

/* The naive combiner: every window summed directly, in double. */
static double
naive_js(const mcp_image *n, const mcp_image *d, const mcp_image *v, int window, int x,
         int y, int k)
{
    int r = window / 2;
    double p = 0, sv = 0, sq = 0;
    for (int j = y - r; j <= y + r; j++)
        for (int i = x - r; i <= x + r; i++) {
            if (i < 0 || j < 0 || i >= n->width || j >= n->height) continue;
            double e = (double)mcp_image_px(n, i, j)[k] - mcp_image_px(d, i, j)[k];
            p++;
            sv += mcp_image_px(v, i, j)[k];
            sq += e * e;
        }
    double s = sq > 0 ? fmax(0, 1 - (p - 2) * (sv / p) / sq) : 0;
    double dv = mcp_image_px(d, x, y)[k];
    return dv + s * (mcp_image_px(n, x, y)[k] - dv);
}

static void
test_closed_form(void **state)
{
    (void)state;
    /* n - d = delta everywhere, v = sigma2: s = 1 - (p - 2) sigma2 / (p delta^2), with
     * p = 49 inside a 7x7 window and 16 at a corner (4x4 clipped). */
    const double delta = 0.5, sigma2 = 0.1;
    mcp_image *n = rgb_constant(20, 20, 1.5f), *d = rgb_constant(20, 20, 1.0f);
    mcp_image *v = rgb_constant(20, 20, (float)sigma2), *r = NULL, *rho = NULL;
    assert_int_equal(mcp_blend_james_stein(n, d, v, 7, NULL, &r, &rho), 0);
    double s_in = 1 - 47 * sigma2 / (49 * delta * delta);
    double s_corner = 1 - 14 * sigma2 / (16 * delta * delta);
    for (int k = 0; k < 3; k++) {
        assert_close(mcp_image_px(r, 10, 10)[k], 1.0 + s_in * delta, 1e-6, 0);
        assert_close(mcp_image_px(rho, 10, 10)[k], 1 - s_in, 1e-6, 0);
        assert_close(mcp_image_px(r, 0, 0)[k], 1.0 + s_corner * delta, 1e-6, 0);
    }
    mcp_image_free(r);
    mcp_image_free(rho);
    /* large noise: s clamps at 0, r = d; no noise: s = 1, r = n; n = d: r = d */
    mcp_image *big = rgb_constant(20, 20, 10.0f), *zero = rgb_constant(20, 20, 0);
    assert_int_equal(mcp_blend_james_stein(n, d, big, 7, NULL, &r, NULL), 0);
    assert_true(r->data[0] == 1.0f && r->data[600] == 1.0f);
    mcp_image_free(r);
    assert_int_equal(mcp_blend_james_stein(n, d, zero, 7, NULL, &r, NULL), 0);
    assert_true(r->data[0] == 1.5f && r->data[600] == 1.5f);
    mcp_image_free(r);
    assert_int_equal(mcp_blend_james_stein(d, d, v, 7, NULL, &r, NULL), 0);
    assert_true(r->data[0] == 1.0f);
    mcp_image_free(r);
    mcp_image_free(big);
    mcp_image_free(zero);
    mcp_image_free(n);
    mcp_image_free(d);
    mcp_image_free(v);
}

static void
test_matches_naive(void **state)
{
    (void)state;
    const int w = 37, h = 23;
    mcp_image *n = mcp_test_random(w, h, 3, 0, 2, 21, RGB);
    mcp_image *d = mcp_test_random(w, h, 3, 0.5f, 1.5f, 22, RGB);
    mcp_image *v = mcp_test_random(w, h, 3, 0, 0.2f, 23, RGB), *r = NULL;
    const int windows[3] = {3, 5, 9};
    for (int t = 0; t < 3; t++) {
        assert_int_equal(mcp_blend_james_stein(n, d, v, windows[t], NULL, &r, NULL), 0);
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++)
                for (int k = 0; k < 3; k++)
                    /* summed-area differences lose ~1e-13 of sums up to ~2000; the
                     * result is rounded to float (values <= 2: 2.4e-7) */
                    assert_close(mcp_image_px(r, x, y)[k],
                                 naive_js(n, d, v, windows[t], x, y, k), 0, 5e-7);
        mcp_image_free(r);
    }
    assert_error_contains(mcp_blend_james_stein(n, d, v, 4, NULL, &r, NULL),
                          "window must be odd and >= 3 (got 4)");
    assert_null(r);
    mcp_image *small = rgb_constant(3, 3, 0);
    assert_error_contains(mcp_blend_james_stein(n, small, v, 7, NULL, &r, NULL),
                          "does not match");
    mcp_image_free(small);
    mcp_image_free(n);
    mcp_image_free(d);
    mcp_image_free(v);
}

/* E[(X - (p - 2))^2 / X; X > p - 2] / p for X ~ chi-square with p degrees of freedom:
 * the mean squared error per value, in units of v, that the combiner keeps where d is
 * the truth (Simpson's rule on the density, 4000 intervals up to 30 deviations). */
static double
leak_closed_form(int p)
{
    const double a = p - 2, b = p + 30 * sqrt(2.0 * p);
    const int steps = 4000;
    const double hstep = (b - a) / steps, lg = lgamma(p / 2.0) + p / 2.0 * log(2.0);
    double sum = 0;
    for (int i = 0; i <= steps; i++) {
        const double x = a + i * hstep;
        const double f = (x - a) * (x - a) / x * exp((p / 2.0 - 1) * log(x) - x / 2 - lg);
        sum += f * (i == 0 || i == steps ? 1 : i % 2 ? 4 : 2);
    }
    return sum * hstep / 3 / p;
}

/* With d the truth and v exact, the combiner's output is mu + s (n - mu), and by the
 * exchangeability of a window's values E[(s e_i)^2] = E[s^2 |e|^2] / p: the leak above.
 * Monte Carlo over 16 seeds of a 64 x 64 image (values whose window lies inside), the
 * mean within 4 standard errors of the seeds' means: 0.0226 v at 7 x 7, 0.0047 v at
 * 15 x 15. The blend's default window is the larger: at 32 spp a network's error can be
 * 1/34 of the noisy one (docs/blend.md), where the smaller window's leak alone is 0.77
 * of the denoised error. */
static void
test_leak_where_d_is_right(void **state)
{
    (void)state;
    enum { S = 64, SEEDS = 16 };
    const double sigma2 = 0.04;
    const int windows[2] = {7, 15};
    mcp_image *mu = rgb_constant(S, S, 0.5f), *v = rgb_constant(S, S, (float)sigma2);
    for (int t = 0; t < 2; t++) {
        const int r = windows[t] / 2;
        double sum = 0, sum2 = 0;
        for (uint64_t seed = 1; seed <= SEEDS; seed++) {
            mcp_image *n = rgb_constant(S, S, 0), *out = NULL;
            uint64_t st = 77 * seed + (uint64_t)t;
            for (size_t i = 0; i < (size_t)S * S * 3; i++)
                n->data[i] = (float)(0.5 + sqrt(sigma2) * mcp_test_rand_normal(&st));
            assert_int_equal(
                mcp_blend_james_stein(n, mu, v, windows[t], NULL, &out, NULL), 0);
            double e2 = 0;
            int count = 0;
            for (int y = r; y < S - r; y++)
                for (int x = r; x < S - r; x++)
                    for (int k = 0; k < 3; k++, count++) {
                        const double e = mcp_image_px(out, x, y)[k] - 0.5;
                        e2 += e * e;
                    }
            const double leak = e2 / count / sigma2;
            sum += leak;
            sum2 += leak * leak;
            mcp_image_free(out);
            mcp_image_free(n);
        }
        const double mean = sum / SEEDS,
                     se = sqrt(fmax(0, sum2 / SEEDS - mean * mean) / (SEEDS - 1)),
                     want = leak_closed_form(windows[t] * windows[t]);
        print_message("window %d: leak %.5f v (closed form %.5f, SE %.5f)\n", windows[t],
                      mean, want, se);
        assert_true(fabs(mean - want) <= 4 * se + 1e-4);
    }
    assert_close(leak_closed_form(49), 0.022635, 0, 1e-5);
    assert_close(leak_closed_form(225), 0.004668, 0, 1e-5);
    mcp_image_free(mu);
    mcp_image_free(v);
}

static void
test_variance_for_sampling_maps(void **state)
{
    (void)state;
    /* rho from the combiner into Firmino 2023 Eq. 4 with one denoised input:
     * Var[r] = rho^2 Var[d] + (1 - rho)^2 v. Closed-form case as above: rho = 1 - s. */
    const double delta = 0.5, sigma2 = 0.1, var_d = 0.004;
    mcp_image *n = rgb_constant(20, 20, 1.5f), *d = rgb_constant(20, 20, 1.0f);
    mcp_image *v = rgb_constant(20, 20, (float)sigma2),
              *vd = rgb_constant(20, 20, (float)var_d);
    mcp_image *r = NULL, *rho = NULL, *var = NULL;
    assert_int_equal(mcp_blend_james_stein(n, d, v, 7, NULL, &r, &rho), 0);
    assert_int_equal(mcp_blend_james_stein_variance(rho, vd, v, &var), 0);
    double s = 1 - 47 * sigma2 / (49 * delta * delta), p = 1 - s;
    assert_close(mcp_image_px(var, 10, 10)[1], p * p * var_d + s * s * sigma2, 1e-6, 0);
    mcp_image_free(var);
    assert_error_contains(mcp_blend_james_stein_variance(rho, vd, NULL, &var),
                          "needs rho, Var[d] and v");
    mcp_image_free(rho);
    mcp_image_free(r);
    mcp_image_free(n);
    mcp_image_free(d);
    mcp_image_free(v);
    mcp_image_free(vd);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_closed_form),
        cmocka_unit_test(test_matches_naive),
        cmocka_unit_test(test_leak_where_d_is_right),
        cmocka_unit_test(test_variance_for_sampling_maps),
    };
    return cmocka_run_group_tests_name("blend/post_correction", tests, NULL, NULL);
}
