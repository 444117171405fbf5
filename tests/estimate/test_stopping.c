/* test_stopping.c: estimate/stopping.c against independent truths.
 *
 * The closed-form noncentral χ² CDF (one degree of freedom, via Φ) is checked against
 * numerical integration of a different representation of the density, the Poisson
 * mixture of central χ² densities, Σ_j Pois(j; λ/2) f_{χ²(1 + 2j)}(x), integrated by
 * Simpson's rule in u = sqrt(x) (which removes the x^(-1/2) singularity; 4000 panels
 * give ~1e-12), and against Monte Carlo draws of (Z + √λ)². The distribution
 * parameters are checked on hand-built blocks (Eq. 14), F(τ) against a direct mean,
 * and the percentiles by inverting them. */
#include "testing.h"

#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/estimate.h>

#include "../../estimate/internal.h" /* mcp__error_dist_image */

static const char *const RGB[] = {"R", "G", "B"};

/* ∫_0^x of the Poisson-mixture density. */
static double
mixture_cdf(double x, double lambda)
{
    const int panels = 4000; /* even */
    double umax = sqrt(x), h = umax / panels, total = 0.0;
    int jmax = (int)(lambda / 2 + 12 * sqrt(lambda / 2 + 1) + 40);
    for (int j = 0; j <= jmax; j++) {
        double k = 1.0 + 2.0 * j;
        double logw =
            (lambda > 0 ? -lambda / 2 + j * log(lambda / 2) : (j ? -INFINITY : 0)) -
            lgamma(j + 1.0);
        if (logw < -60) continue;
        /* f_k(u²) 2u = 2 u^(k-1) e^(-u²/2) / (2^(k/2) Γ(k/2)) */
        double logc = log(2.0) - (k / 2) * log(2.0) - lgamma(k / 2);
        double s = 0.0;
        for (int i = 0; i <= panels; i++) {
            double u = i * h;
            double g =
                (u == 0.0 ? (k == 1.0 ? 1.0 : 0.0) : pow(u, k - 1)) * exp(-u * u / 2);
            s += g * (i == 0 || i == panels ? 1 : i % 2 ? 4 : 2);
        }
        total += exp(logw + logc) * s * h / 3;
    }
    return total;
}

static void
test_ncx2_against_integration(void **state)
{
    (void)state;
    const double lambdas[] = {0.0, 0.3, 1.0, 4.0, 20.0, 90.0};
    const double xs[] = {1e-4, 0.05, 0.5, 1.0, 3.0, 10.0, 40.0, 150.0};
    double worst = 0.0;
    for (int a = 0; a < 6; a++)
        for (int b = 0; b < 8; b++) {
            double got = mcp_ncx2_cdf(xs[b], lambdas[a]);
            double want = mixture_cdf(xs[b], lambdas[a]);
            worst = fmax(worst, fabs(got - want));
            assert_close(got, want, 0, 1e-9);
        }
    print_message("noncentral chi2 CDF vs integrated Poisson-mixture density: max |diff| "
                  "%.2g\n",
                  worst);
    assert_true(mcp_ncx2_cdf(0.0, 3.0) == 0.0);
    assert_true(mcp_ncx2_cdf(-1.0, 3.0) == 0.0);
    assert_true(mcp_ncx2_cdf(INFINITY, 3.0) == 1.0);
    assert_true(mcp_ncx2_cdf(1e6, 3.0) == 1.0);
    /* the far upper tail keeps its precision: 1 - F = Q(√x - √λ) + Φ(-√x - √λ) */
    double x = 100.0, l = 4.0;
    double tail = 0.5 * erfc((sqrt(x) - sqrt(l)) / sqrt(2.0)) +
                  0.5 * erfc((sqrt(x) + sqrt(l)) / sqrt(2.0));
    assert_close(1.0 - mcp_ncx2_cdf(x, l), tail, 0, 2.3e-16); /* 1 ulp of 1.0 */
}

static void
test_ncx2_against_sampling(void **state)
{
    (void)state;
    const int n = 200000;
    const double lambdas[] = {0.0, 2.0, 15.0};
    uint64_t rng = 123;
    for (int a = 0; a < 3; a++) {
        double *v = malloc(n * sizeof *v);
        for (int i = 0; i < n; i++) {
            double z = mcp_test_rand_normal(&rng) + sqrt(lambdas[a]);
            v[i] = z * z;
        }
        const double xs[] = {0.1, 1.0, 5.0, 20.0};
        for (int b = 0; b < 4; b++) {
            int below = 0;
            for (int i = 0; i < n; i++)
                below += v[i] <= xs[b];
            double f = mcp_ncx2_cdf(xs[b], lambdas[a]), emp = (double)below / n;
            /* binomial standard error; 5 of them */
            assert_close(emp, f, 0, 5 * sqrt(f * (1 - f) / n) + 1e-6);
        }
        free(v);
    }
}

/* Two blocks over a 4x2 image: left 2x2, right 2x2. */
static mcp_blocks *
two_blocks(void)
{
    mcp_blocks *b = calloc(1, sizeof *b);
    b->width = 4;
    b->height = 2;
    b->count = 2;
    b->items = calloc(2, sizeof *b->items);
    b->items[0] = (mcp_block){0, 0, 2, 2, {4.0, 0.1, 1.0}, {0}};
    b->items[1] = (mcp_block){2, 0, 2, 2, {0.0, 8.0, 2.0}, {0}};
    return b;
}

static void
test_distribution_parameters(void **state)
{
    (void)state;
    mcp_blocks *b = two_blocks();
    mcp_image *var = NULL;
    assert_int_equal(mcp_image_new(4, 2, 3, RGB, &var), 0);
    for (int y = 0; y < 2; y++)
        for (int x = 0; x < 4; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(var, x, y)[c] = (float)(0.25 * (c + 1) * (1 + x + y));
    mcp_error_dist *d = NULL;
    assert_int_equal(mcp_error_distribution(b, var, &d), 0);
    mcp_image *img = NULL;
    assert_int_equal(mcp_error_dist_image(d, &img), 0);
    assert_string_equal(img->names[0], "lambda.R");
    assert_string_equal(img->names[5], "s2.B");
    for (int k = 0; k < 2; k++)
        for (int c = 0; c < 3; c++) {
            double vs = 0.0;
            for (int y = 0; y < 2; y++)
                for (int x = 2 * k; x < 2 * k + 2; x++)
                    vs += 0.25 * (c + 1) * (1 + x + y);
            assert_close(b->items[k].var_sum[c], vs, 1e-12, 0);
            double lambda = fmax(b->items[k].sure_sum[c] / (vs + 1e-6), 1.0) - 1.0;
            for (int y = 0; y < 2; y++)
                for (int x = 2 * k; x < 2 * k + 2; x++) {
                    assert_close(mcp_image_px(img, x, y)[c], lambda, 1e-6, 1e-7);
                    assert_close(mcp_image_px(img, x, y)[3 + c],
                                 mcp_image_px(var, x, y)[c], 1e-6, 0);
                }
        }
    /* block 0 channel G has SURE < Var: λ = 0 */
    assert_true(mcp_image_px(img, 0, 0)[1] == 0.0f);
    /* λ alone (distribution.exr): the same values as the first three channels */
    mcp_image *lambda = NULL;
    assert_int_equal(mcp__error_dist_image(d, 0, &lambda), 0);
    assert_int_equal(lambda->channels, 3);
    assert_string_equal(lambda->names[2], "lambda.B");
    for (int y = 0; y < 2; y++)
        for (int x = 0; x < 4; x++)
            assert_memory_equal(mcp_image_px(lambda, x, y), mcp_image_px(img, x, y),
                                3 * sizeof(float));
    mcp_image_free(lambda);
    /* F(τ) is the mean of the per-value CDFs */
    const double taus[] = {0.01, 0.3, 2.0, 50.0};
    for (int t = 0; t < 4; t++) {
        double want = 0.0;
        for (int p = 0; p < 8; p++)
            for (int c = 0; c < 3; c++)
                want += mcp_ncx2_cdf(taus[t] / img->data[6 * p + 3 + c],
                                     img->data[6 * p + c]) /
                        24;
        /* the image CDF runs in float with a tail approximation good to 2e-7 */
        assert_close(mcp_error_cdf(d, taus[t]), want, 0, 3e-7);
        double cdf;
        int stop = mcp_error_should_stop(d, taus[t], 0.9, &cdf);
        assert_int_equal(stop, cdf >= 0.9);
        assert_close(cdf, want, 0, 3e-7);
    }
    /* percentiles invert F */
    const double p[] = {0.1, 0.5, 0.9, 0.999};
    double tau[4];
    assert_int_equal(mcp_error_percentiles(d, p, 4, tau), 0);
    for (int k = 0; k < 4; k++) {
        /* within the stated 1e-3 of the exact root (stopping.c: binned s², 4.9e-4, and
         * the search's 1e-4) */
        assert_true(mcp_error_cdf(d, tau[k] * (1 + 1e-3)) >= p[k]);
        assert_true(mcp_error_cdf(d, tau[k] * (1 - 1e-3)) < p[k]);
        if (k) assert_true(tau[k] > tau[k - 1]);
    }
    print_message("percentiles 0.1/0.5/0.9/0.999: %.4g %.4g %.4g %.4g\n", tau[0], tau[1],
                  tau[2], tau[3]);
    mcp_image_free(img);
    mcp_error_dist_free(d);
    /* no variance anywhere: no error, F = 1 */
    memset(var->data, 0, 24 * sizeof(float));
    assert_int_equal(mcp_error_distribution(b, var, &d), 0);
    assert_true(mcp_error_cdf(d, 1e-9) == 1.0);
    assert_int_equal(mcp_error_percentiles(d, p, 4, tau), 0);
    assert_true(tau[3] == 0.0);
    mcp_error_dist_free(d);
    mcp_image_free(var);
    mcp_blocks_free(b);
}

/* nx x ny equal blocks covering a w x h image (w, h divisible), sums zero. */
static mcp_blocks *
grid_blocks(int w, int h, int nx, int ny)
{
    mcp_blocks *b = calloc(1, sizeof *b);
    b->width = w;
    b->height = h;
    b->count = nx * ny;
    b->items = calloc((size_t)b->count, sizeof *b->items);
    for (int i = 0; i < b->count; i++)
        b->items[i] = (mcp_block){
            (i % nx) * (w / nx), (i / nx) * (h / ny), w / nx, h / ny, {0}, {0}};
    return b;
}

/* The model calibrates itself: values drawn from s²(Z + √λ)² have the percentiles the
 * model predicts (nearest rank of 60000 draws within a few % at p <= 0.99). */
static void
test_percentiles_match_draws(void **state)
{
    (void)state;
    const int w = 100, h = 200;
    mcp_blocks *b = grid_blocks(w, h, 1, 1);
    mcp_image *var = NULL, *err = NULL;
    assert_int_equal(mcp_image_new(w, h, 3, RGB, &var), 0);
    assert_int_equal(mcp_image_new(w, h, 3, RGB, &err), 0);
    uint64_t rng = 77;
    const double lambda = 3.0;
    for (int i = 0; i < w * h * 3; i++) {
        double s2 = 1e-4 * (1 + 9 * mcp_test_rand_uniform(&rng));
        var->data[i] = (float)s2;
        double z = mcp_test_rand_normal(&rng) + sqrt(lambda);
        err->data[i] = (float)(s2 * z * z);
    }
    double vs = 0.0;
    for (int i = 0; i < w * h * 3; i++)
        vs += var->data[i];
    for (int c = 0; c < 3; c++) /* SURE sums giving λ = 3 exactly (Eq. 14) */
        b->items[0].sure_sum[c] = 4.0 * (vs / 3 + 1e-6);
    /* per-channel Var sums differ slightly from vs / 3; recompute after the fact */
    mcp_error_dist *d = NULL;
    assert_int_equal(mcp_error_distribution(b, var, &d), 0);
    for (int c = 0; c < 3; c++) {
        b->items[0].sure_sum[c] = 4.0 * (b->items[0].var_sum[c] + 1e-6);
    }
    mcp_error_dist_free(d);
    assert_int_equal(mcp_error_distribution(b, var, &d), 0);
    const double p[] = {0.5, 0.9, 0.99};
    double est[3], tru[3];
    assert_int_equal(mcp_error_percentiles(d, p, 3, est), 0);
    assert_int_equal(mcp_true_percentiles(err, p, 3, tru), 0);
    for (int k = 0; k < 3; k++) {
        print_message("p %.2f: model %.5g, draws %.5g\n", p[k], est[k], tru[k]);
        assert_close(est[k], tru[k], 0.05, 0);
    }
    mcp_error_dist_free(d);
    mcp_image_free(var);
    mcp_image_free(err);
    mcp_blocks_free(b);
}

/* The percentiles against an exact bisection on mcp_error_cdf (every value, to 1e-6):
 * nx x ny blocks with their own λ, s² log-uniform over 12 decades with some zeros, so
 * that the compressed search meets many bins per block and bins of 0; with a block per
 * pixel, the bins of 15360 blocks binned by each thread into its own growing arena. */
static void
check_exact_search(int nx, int ny)
{
    const int w = 160, h = 96;
    mcp_blocks *b = grid_blocks(w, h, nx, ny);
    mcp_image *var = NULL;
    assert_int_equal(mcp_image_new(w, h, 3, RGB, &var), 0);
    uint64_t rng = 2026;
    for (int i = 0; i < w * h * 3; i++)
        var->data[i] = i % 97 == 0
                           ? 0.0f
                           : (float)pow(10.0, 12.0 * mcp_test_rand_uniform(&rng) - 9.0);
    mcp_error_dist *d = NULL;
    assert_int_equal(mcp_error_distribution(b, var, &d), 0);
    for (int i = 0; i < b->count; i++) /* λ from 0 to 15 per block and channel */
        for (int c = 0; c < 3; c++)
            b->items[i].sure_sum[c] =
                (1.0 + (i + c) % 16) * (b->items[i].var_sum[c] + 1e-6);
    mcp_error_dist_free(d);
    assert_int_equal(mcp_error_distribution(b, var, &d), 0);
    const double p[] = {0.0, 0.01, 0.5, 0.9, 0.99, 0.999, 0.9999};
    double tau[7];
    assert_int_equal(mcp_error_percentiles(d, p, 7, tau), 0);
    for (int k = 0; k < 7; k++) {
        double lo = 1e-30, hi = 1e10;
        while (log(hi / lo) > 1e-6) {
            double mid = sqrt(lo * hi);
            if (mcp_error_cdf(d, mid) >= p[k])
                hi = mid;
            else
                lo = mid;
        }
        print_message("p %.4f: %.6g, exact %.6g\n", p[k], tau[k], hi);
        if (p[k] == 0.0 || mcp_error_cdf(d, 1e-30) >= p[k])
            assert_true(tau[k] <= 1e-30 * 1.001 || tau[k] == 0.0);
        else
            assert_close(tau[k], hi, 1e-3, 0);
    }
    /* the same bits on 1 and 3 threads (chunked sums in a fixed order) */
    double one[7], three[7];
    omp_set_num_threads(1);
    assert_int_equal(mcp_error_percentiles(d, p, 7, one), 0);
    omp_set_num_threads(3);
    assert_int_equal(mcp_error_percentiles(d, p, 7, three), 0);
    assert_memory_equal(one, three, sizeof one);
    assert_memory_equal(one, tau, sizeof one);
    mcp_error_dist_free(d);
    mcp_image_free(var);
    mcp_blocks_free(b);
}

static void
test_percentiles_match_exact_search(void **state)
{
    (void)state;
    check_exact_search(4, 4);
}

static void
test_percentiles_block_per_pixel(void **state)
{
    (void)state;
    check_exact_search(160, 96);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_blocks *b = two_blocks();
    mcp_image *var = NULL;
    assert_int_equal(mcp_image_new(5, 2, 3, RGB, &var), 0);
    mcp_error_dist *d = NULL;
    assert_error_contains(
        mcp_error_distribution(b, var, &d),
        "error distribution: the variance is 5x2 but the blocks cover 4x2");
    assert_null(d);
    mcp_image_free(var);
    assert_int_equal(mcp_image_new(4, 2, 3, RGB, &var), 0);
    assert_int_equal(mcp_error_distribution(b, var, &d), 0);
    double p = 1.0, tau;
    assert_error_contains(mcp_error_percentiles(d, &p, 1, &tau),
                          "error percentiles: p must be in [0, 1) (got 1)");
    assert_true(mcp_error_cdf(d, 0.0) == 0.0);
    mcp_error_dist_free(d);
    mcp_image_free(var);
    mcp_blocks_free(b);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ncx2_against_integration),
        cmocka_unit_test(test_ncx2_against_sampling),
        cmocka_unit_test(test_distribution_parameters),
        cmocka_unit_test(test_percentiles_match_draws),
        cmocka_unit_test(test_percentiles_match_exact_search),
        cmocka_unit_test(test_percentiles_block_per_pixel),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("estimate/stopping", tests, NULL, NULL);
}
