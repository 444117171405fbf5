/* test_model.c: perceptual/model.c and inputs.c -- the kernel and its border
 * footprints, the incremental energy of direct binary search against a full
 * recomputation after random sequences of changes and swaps (every kernel kind, h = g,
 * scalar and per-pixel confidence, degenerate image sizes), the energy against
 * metrics.h's pMSE, and every error path. */
#include "testing.h"

#include "../../perceptual/internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/metrics.h>

/* The incremental energy adds one rounded dE per change to a sum of ~N terms; both it
 * and the full recomputation are double sums of values of order 1, so after a few
 * thousand changes they agree to ~1e-13 relative. 1e-9 (the brief's bound) leaves
 * four orders of margin. */
#define EXACT_RTOL 1e-9
#define PI_D 3.14159265358979323846

static void
random_rgb(double *v, size_t n, double lo, double hi, uint64_t *st)
{
    for (size_t i = 0; i < n; i++)
        v[i] = lo + (hi - lo) * mcp_test_rand_uniform(st);
}

static float *
random_rgbf(size_t n, double lo, double hi, uint64_t *st)
{
    float *v = malloc(n * sizeof *v);
    assert_non_null(v);
    for (size_t i = 0; i < n; i++)
        v[i] = (float)(lo + (hi - lo) * mcp_test_rand_uniform(st));
    return v;
}

/* Random single-pixel changes and neighbour swaps; after each, the incremental energy
 * and the predicted dE must match the full recomputation. */
static void
check_incremental(int w, int h, const mcp_perc_model *model, int n_steps, uint64_t seed)
{
    uint64_t st = seed;
    size_t n3 = (size_t)w * h * 3;
    float *surr = random_rgbf(n3, 0.0, 1.0, &st), *qinit = random_rgbf(n3, 0.0, 1.0, &st);
    double *o = malloc(n3 * sizeof *o);
    assert_non_null(o);
    random_rgb(o, n3, -0.2, 1.2, &st);
    mcp__perc_state s;
    assert_int_equal(mcp__state_init(&s, model, w, h, surr, qinit, o), 0);
    assert_close(s.energy, mcp__state_energy_full(&s), 1e-12, 0);
    int r = s.g.r;
    for (int step = 0; step < n_steps; step++) {
        double before = mcp__state_energy_full(&s), de;
        int x = (int)(mcp_test_rand_u64(&st) % (uint64_t)w);
        int y = (int)(mcp_test_rand_u64(&st) % (uint64_t)h);
        if (step % 3 == 2 && w * h > 1) { /* a swap with a pixel within 2r */
            int xj, yj;
            do {
                xj = x + (int)(mcp_test_rand_u64(&st) % (uint64_t)(4 * r + 1)) - 2 * r;
                yj = y + (int)(mcp_test_rand_u64(&st) % (uint64_t)(4 * r + 1)) - 2 * r;
            } while (xj < 0 || yj < 0 || xj >= w || yj >= h || (xj == x && yj == y));
            de = mcp__state_swap_delta(&s, x, y, xj, yj);
            double oi[3], oj[3];
            memcpy(oi, s.o + ((size_t)y * w + x) * 3, sizeof oi);
            memcpy(oj, s.o + ((size_t)yj * w + xj) * 3, sizeof oj);
            double d1 = mcp__state_delta(&s, x, y, oj);
            mcp__state_set(&s, x, y, oj, d1);
            mcp__state_set(&s, xj, yj, oi, mcp__state_delta(&s, xj, yj, oi));
        } else {
            double v[3];
            random_rgb(v, 3, -0.2, 1.2, &st);
            de = mcp__state_delta(&s, x, y, v);
            mcp__state_set(&s, x, y, v, de);
        }
        double after = mcp__state_energy_full(&s);
        /* dE is a difference of two energies: compare it on their scale */
        assert_close(de, after - before, 0, EXACT_RTOL * (before + 1e-30));
        assert_close(s.energy, after, EXACT_RTOL, 0);
    }
    mcp__state_free(&s);
    free(o), free(surr), free(qinit);
}

static const int sizes[][2] = {{16, 12}, {1, 1}, {2, 3}, {5, 1}, {7, 7}, {9, 4}};

static void
test_incremental_default(void **state)
{
    (void)state;
    mcp_perc_model m = mcp_perc_model_defaults();
    for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++)
        check_incremental(sizes[i][0], sizes[i][1], &m, 300, 11 + i);
}

static void
test_incremental_gaussian_h_g(void **state)
{
    (void)state;
    mcp_perc_model m = mcp_perc_model_defaults();
    m.kernel.kind = MCP_PKERNEL_GAUSSIAN; /* sigma 0.80 px, radius 3 */
    m.filter_surrogate = 1;
    for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++)
        check_incremental(sizes[i][0], sizes[i][1], &m, 200, 21 + i);
}

static void
test_incremental_user_kernel_confidence(void **state)
{
    (void)state;
    /* a non-symmetric, non-normalised 5x3 kernel: convolution, not correlation */
    static const double k[15] = {0.0, 0.1,  0.3, 0.05, 0.0, 0.2, -0.1, 0.5,
                                 0.1, 0.02, 0.0, 0.3,  0.0, 0.0, 0.07};
    mcp_perc_model m = mcp_perc_model_defaults();
    m.user_kernel = k;
    m.user_kernel_width = 5;
    m.user_kernel_height = 3;
    m.confidence = 0.3;
    for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++)
        check_incremental(sizes[i][0], sizes[i][1], &m, 200, 31 + i);
}

static void
test_incremental_confidence_map(void **state)
{
    (void)state;
    for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++) {
        int w = sizes[i][0], h = sizes[i][1];
        mcp_image *cmap = mcp_test_random(w, h, 1, 0.0f, 1.0f, 41 + i, NULL);
        mcp_perc_model m = mcp_perc_model_defaults();
        m.confidence_map = cmap;
        check_incremental(w, h, &m, 200, 51 + i);
        m.kernel.kind = MCP_PKERNEL_GAUSSIAN;
        check_incremental(w, h, &m, 100, 61 + i);
        mcp_image_free(cmap);
    }
}

/* Footprints away from the borders are g itself; at a corner of the default kernel
 * they gather the clamped taps: pixel (0, 0) enters (g * X)(0, 0) with
 * (g0 + g1)^2 where g0 = 1/pi, g1 = 1 - 2/pi (two taps of each axis clamp onto it). */
static void
test_footprints(void **state)
{
    (void)state;
    mcp_perc_model m = mcp_perc_model_defaults();
    mcp__pkern g;
    mcp__footprints f;
    assert_int_equal(mcp__pkern_build(&m, &g), 0);
    assert_int_equal(mcp__footprints_build(&g, 10, 8, &f), 0);
    assert_int_equal(f.nx, 3);
    assert_int_equal(f.ny, 3);
    const double *a = mcp__footprint(&f, 4, 4);
    for (int i = 0; i < 9; i++)
        assert_close(a[i], g.taps[i], 0, 1e-15);
    double g0 = 1.0 / PI_D, g1 = 1.0 - 2.0 / PI_D;
    a = mcp__footprint(&f, 0, 0);
    assert_close(a[4], (g0 + g1) * (g0 + g1), 1e-14, 0);
    assert_close(a[5], (g0 + g1) * g0, 1e-14, 0); /* (1, 0): x tap g0, y clamped */
    assert_close(a[0], 0.0, 0, 0);                /* (-1, -1) lies outside */
    /* every pixel's footprint sums to |g|_1 (each tap lands on some pixel) minus what
     * falls on pixels outside the image, which replicate borders never do */
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 10; x++) {
            double sum = 0.0;
            a = mcp__footprint(&f, x, y);
            for (int i = 0; i < 9; i++)
                sum += a[i];
            assert_true(sum > 0.99);
        }
    mcp__footprints_free(&f);
    mcp__pkern_free(&g);
}

/* With C = 1, h = delta and the truth as surrogate, E / (N C) is metrics.h's pMSE
 * (which filters in float: 1e-6). */
static void
test_energy_is_pmse(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_random(23, 17, 3, -0.1f, 1.3f, 5, NULL);
    mcp_image *ref = mcp_test_random(23, 17, 3, 0.0f, 1.0f, 6, NULL);
    double e, pmse;
    assert_int_equal(mcp_perc_energy(img, ref, NULL, NULL, &e), 0);
    assert_int_equal(mcp_pmse(img, ref, NULL, &pmse), 0);
    assert_close(e / (23.0 * 17.0 * 3.0), pmse, 1e-6, 0);
    mcp_pmse_options po = mcp_pmse_defaults();
    mcp_perc_model m = mcp_perc_model_defaults();
    po.kernel.kind = m.kernel.kind = MCP_PKERNEL_GAUSSIAN;
    po.tone_map = m.tone_map = MCP_TONEMAP_ACES;
    po.filter_reference = m.filter_surrogate = 1;
    assert_int_equal(mcp_perc_energy(img, ref, NULL, &m, &e), 0);
    assert_int_equal(mcp_pmse(img, ref, &po, &pmse), 0);
    assert_close(e / (23.0 * 17.0 * 3.0), pmse, 1e-6, 0);
    /* C = 0: only the distance to Q_init, |g|_1^2 |T(O) - T(Q)|^2 */
    m = mcp_perc_model_defaults();
    m.confidence = 0.0;
    assert_int_equal(mcp_perc_energy(img, ref, img, &m, &e), 0);
    assert_close(e, 0.0, 0, 1e-12);
    mcp_image_free(img);
    mcp_image_free(ref);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_image *a = mcp_test_random(8, 8, 3, 0.0f, 1.0f, 1, NULL);
    mcp_image *b = mcp_test_random(8, 9, 3, 0.0f, 1.0f, 2, NULL);
    mcp_image *grey2 =
        mcp_test_random(8, 8, 2, 0.0f, 1.0f, 3, (const char *[]){"X", "Y"});
    double e;
    mcp_image_set_source(b, "b.exr");
    assert_error_contains(mcp_perc_energy(a, b, NULL, NULL, &e), "does not match");
    assert_error_contains(mcp_perc_energy(a, grey2, NULL, NULL, &e), "no channel 'R'");
    assert_error_contains(mcp_perc_energy(a, NULL, NULL, NULL, &e), "needs an image");
    mcp_perc_model m = mcp_perc_model_defaults();
    m.confidence = 1.5;
    assert_error_contains(mcp_perc_energy(a, a, a, &m, &e),
                          "confidence must be in [0, 1]");
    m.confidence = 0.5;
    assert_error_contains(mcp_perc_energy(a, a, NULL, &m, &e),
                          "needs the initial estimate");
    m = mcp_perc_model_defaults();
    static const double k4[4] = {1, 1, 1, 1};
    m.user_kernel = k4;
    m.user_kernel_width = 2;
    m.user_kernel_height = 2;
    assert_error_contains(mcp_perc_energy(a, a, NULL, &m, &e), "odd-sized (got 2x2)");
    m = mcp_perc_model_defaults();
    m.kernel.kind = MCP_PKERNEL_GAUSSIAN;
    m.kernel.dpi = 0;
    assert_error_contains(mcp_perc_energy(a, a, NULL, &m, &e), "dpi must be > 0");
    m.kernel.dpi = 3000; /* sigma ~8 px: radius 24 */
    assert_error_contains(mcp_perc_energy(a, a, NULL, &m, &e), "too wide");
    m = mcp_perc_model_defaults();
    mcp_image *cm = mcp_test_constant(8, 8, 1, 2.0f, NULL);
    mcp_image_set_source(cm, "c.exr");
    m.confidence_map = cm;
    assert_error_contains(mcp_perc_energy(a, a, a, &m, &e), "c.exr: confidence must be");
    mcp_image *nan = mcp_test_constant(8, 8, 3, NAN, NULL);
    mcp_image_set_source(nan, "nan.exr");
    assert_error_contains(mcp_perc_energy(nan, a, NULL, NULL, &e),
                          "nan.exr: 192 non-finite values (the first at pixel 0, 0)");
    mcp_image_free(nan);
    mcp_image_free(cm);
    mcp_image_free(grey2);
    mcp_image_free(b);
    mcp_image_free(a);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_incremental_default),
        cmocka_unit_test(test_incremental_gaussian_h_g),
        cmocka_unit_test(test_incremental_user_kernel_confidence),
        cmocka_unit_test(test_incremental_confidence_map),
        cmocka_unit_test(test_footprints),
        cmocka_unit_test(test_energy_is_pmse),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("perceptual/model", tests, NULL, NULL);
}
