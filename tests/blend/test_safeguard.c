/* test_safeguard.c: blend/safeguard.c -- the cap on the weight of the denoised image
 * (docs/blend.md "The safeguard"), against its closed form on constant images, and
 * against its guarantee by Monte Carlo over seeds: with SURE claiming the denoised
 * image perfect (curve weights infinite), a smoother that wipes out fine texture
 * (self-influence 1/9 <= 1/2) must leave the blend within 10% of the noisy image's
 * error at every noise level, while a perfect denoiser keeps nearly all its weight. */
#include "blend_testing.h"
#include "../../blend/internal.h"

#include <math.h>

#define W 48
#define H 48

/* A truth with detail at every scale down to one pixel: what a blur gets wrong. */
static mcp_image *
texture_truth(void)
{
    mcp_image *mu = rgb_constant(W, H, 0);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int k = 0; k < 3; k++)
                mcp_image_px(mu, x, y)[k] =
                    (float)(0.5 + 0.3 * (((x + y + k) & 1) ? 1 : -1) +
                            0.1 * sin(0.7 * x + 0.3 * k) * cos(0.45 * y));
    return mu;
}

/* n = mu + N(0, sigma2) per value, from seed. */
static mcp_image *
noisy_of(const mcp_image *mu, double sigma2, uint64_t seed)
{
    mcp_image *n = rgb_constant(W, H, 0);
    uint64_t st = seed;
    for (size_t i = 0; i < (size_t)W * H * 3; i++)
        n->data[i] = (float)(mu->data[i] + sqrt(sigma2) * mcp_test_rand_normal(&st));
    return n;
}

/* A 3x3 box blur with clamped borders: a linear denoiser whose self-influence is 1/9. */
static mcp_image *
box3(const mcp_image *n)
{
    mcp_image *d = rgb_constant(W, H, 0);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int k = 0; k < 3; k++) {
                double s = 0;
                for (int j = -1; j <= 1; j++)
                    for (int i = -1; i <= 1; i++) {
                        int xx = x + i < 0 ? 0 : x + i >= W ? W - 1 : x + i;
                        int yy = y + j < 0 ? 0 : y + j >= H ? H - 1 : y + j;
                        s += mcp_image_px(n, xx, yy)[k];
                    }
                mcp_image_px(d, x, y)[k] = (float)(s / 9);
            }
    return d;
}

static double
mse(const mcp_image *a, const mcp_image *b)
{
    double s = 0;
    for (size_t i = 0; i < (size_t)W * H * 3; i++) {
        double e = (double)a->data[i] - b->data[i];
        s += e * e;
    }
    return s / ((double)W * H * 3);
}

/* One blend step with SURE ~ 0 (W ~ inf: d trusted everywhere), the safeguard as
 * given; returns the blend's MSE against mu and the share pulled back. */
static double
blend_mse(const mcp_image *mu, const mcp_image *n, const mcp_image *d, double sigma2,
          int safeguard, double *pulled)
{
    mcp_image *v = rgb_constant(W, H, (float)sigma2), *sure = rgb_constant(W, H, 1e-30f);
    mcp_blend_options o = mcp_blend_defaults();
    o.weights = MCP_BLEND_WEIGHTS_CURVES;
    o.safeguard = safeguard;
    o.filter = MCP_BLEND_FILTER_NONE;
    mcp_blend_input in = {n, v, 64, d, sure, NULL, NULL};
    mcp_blend_result r;
    assert_int_equal(mcp_blend_step(&in, &o, NULL, NULL, &r), 0);
    double e = mse(r.blend, mu);
    if (pulled) *pulled = r.safeguard_pulled;
    mcp_blend_result_free(&r);
    mcp_image_free(v);
    mcp_image_free(sure);
    return e;
}

static void
test_closed_form(void **state)
{
    (void)state;
    /* n - d = 0.5, v = 0.1: inside a 7x7 window rho_max = 47 * 0.1 / (49 * 0.25) */
    const double spp = 16, rho_max = 47 * 0.1 / (49 * 0.25);
    mcp_image *n = rgb_constant(20, 20, 1.5f), *d = rgb_constant(20, 20, 1.0f);
    mcp_image *v = rgb_constant(20, 20, 0.1f), *js = NULL, *rho = NULL;
    assert_int_equal(mcp_blend_james_stein(n, d, v, 7, NULL, &js, &rho), 0);
    /* weights: inf at (10, 10), a share of 0.1 (W = spp / 9) at (11, 10), 0 at (12, 10)
     */
    mcp_image *wt = rgb_constant(20, 20, 0), *b = rgb_constant(20, 20, 0);
    for (int k = 0; k < 3; k++) {
        mcp_image_px(wt, 10, 10)[k] = INFINITY;
        mcp_image_px(wt, 11, 10)[k] = (float)(spp / 9);
        mcp_image_px(b, 10, 10)[k] = 1.0f;
        mcp_image_px(b, 11, 10)[k] = 1.45f;
        mcp_image_px(b, 12, 10)[k] = 1.5f;
    }
    double pulled = -1;
    assert_int_equal(mcp_blend_safeguard(n, spp, d, rho, wt, b, &pulled), 0);
    assert_close(pulled, 1.0 / 400, 1e-12, 0);
    for (int k = 0; k < 3; k++) {
        assert_close(mcp_image_px(b, 10, 10)[k], 1.5 - 0.5 * rho_max, 1e-6, 0);
        assert_close(mcp_image_px(wt, 10, 10)[k], spp * rho_max / (1 - rho_max), 1e-5, 0);
        /* under the cap: untouched, bit for bit */
        assert_true(mcp_image_px(b, 11, 10)[k] == 1.45f);
        assert_true(mcp_image_px(wt, 11, 10)[k] == (float)(spp / 9));
        assert_true(mcp_image_px(b, 12, 10)[k] == 1.5f);
        assert_true(mcp_image_px(wt, 12, 10)[k] == 0.0f);
    }
    /* bad input: a cap of another size, spp 0 */
    mcp_image *small = rgb_constant(10, 20, 1.0f);
    assert_error_contains(mcp_blend_safeguard(n, spp, d, small, wt, b, NULL), "size");
    assert_error_contains(mcp_blend_safeguard(n, 0, d, rho, wt, b, NULL), "spp must be");
    mcp_image_free(small);
    mcp_image_free(wt);
    mcp_image_free(b);
    mcp_image_free(js);
    mcp_image_free(rho);
    mcp_image_free(n);
    mcp_image_free(d);
    mcp_image_free(v);
}

/* The guarantee: a blurring denoiser trusted everywhere by its (wrong) SURE. Over 16
 * seeds per noise level, the mean MSE of the blend over the noisy image's is <= 1.10
 * at every level (the guarantee is <= 1 in expectation for a window-constant weight;
 * the estimated cap varies within a window), while without the safeguard it is the
 * blur's, many times the noisy error once the noise is below the texture. */
static void
test_biased_denoiser_converges(void **state)
{
    (void)state;
    mcp_image *mu = texture_truth();
    const double levels[4] = {1e-1, 1e-2, 1e-3, 1e-4};
    for (int l = 0; l < 4; l++) {
        double noisy = 0, guarded = 0, unguarded = 0;
        for (uint64_t seed = 1; seed <= 16; seed++) {
            mcp_image *n = noisy_of(mu, levels[l], 1000 * (uint64_t)l + seed),
                      *d = box3(n);
            noisy += mse(n, mu);
            guarded += blend_mse(mu, n, d, levels[l], 1, NULL);
            unguarded += blend_mse(mu, n, d, levels[l], 0, NULL);
            mcp_image_free(n);
            mcp_image_free(d);
        }
        print_message("sigma2 %g: blend/noisy %.3f with the safeguard, %.3f without\n",
                      levels[l], guarded / noisy, unguarded / noisy);
        assert_true(guarded <= 1.10 * noisy);
        if (levels[l] <= 1e-2) assert_true(unguarded > 5 * noisy);
    }
    mcp_image_free(mu);
}

/* A perfect denoiser (d = mu): the cap binds only by the chi-square spread of
 * |n - d|^2 over a window, and the blend keeps nearly all the gain. */
static void
test_good_denoiser_keeps_its_weight(void **state)
{
    (void)state;
    mcp_image *mu = texture_truth();
    double noisy = 0, guarded = 0, pulled_sum = 0;
    for (uint64_t seed = 1; seed <= 8; seed++) {
        mcp_image *n = noisy_of(mu, 1e-2, seed);
        double pulled;
        noisy += mse(n, mu);
        guarded += blend_mse(mu, n, mu, 1e-2, 1, &pulled);
        pulled_sum += pulled;
        mcp_image_free(n);
    }
    print_message("perfect denoiser: blend/noisy %.4f, pulled back %.2f\n",
                  guarded / noisy, pulled_sum / 8);
    /* a pulled-back value keeps (1 - rho)^2 of its noise: over the default 15 x 15
     * window 0.0047 of it on average (test_post_correction.c, the closed form) */
    assert_true(guarded <= 0.008 * noisy);
    mcp_image_free(mu);
}

/* The options: the safeguard on by default and checked; the James-Stein weights the
 * default, and mcp_blend_step's blend then the combiner's, with W = I rho / (1 - rho). */
static void
test_option(void **state)
{
    (void)state;
    mcp_blend_options o = mcp_blend_defaults();
    assert_int_equal(o.safeguard, 1);
    assert_int_equal(o.weights, MCP_BLEND_WEIGHTS_JAMES_STEIN);
    o.safeguard = 2;
    assert_error_contains(mcp_blend_options_check(&o), "safeguard must be 0 or 1");
    mcp_blend_weighting wt;
    assert_int_equal(mcp_blend_weighting_from_name("james-stein", &wt), 0);
    assert_int_equal(wt, MCP_BLEND_WEIGHTS_JAMES_STEIN);
    assert_int_equal(mcp_blend_weighting_from_name("curves", &wt), 0);
    assert_string_equal(mcp_blend_weighting_name(wt), "curves");
    assert_error_contains(mcp_blend_weighting_from_name("mean", &wt),
                          "unknown blend weights 'mean'");

    mcp_image *mu = texture_truth(), *n = noisy_of(mu, 1e-2, 7), *d = box3(n);
    mcp_image *v = rgb_constant(W, H, 1e-2f), *sure = rgb_constant(W, H, 1e-3f);
    mcp_image *js = NULL, *rho = NULL;
    assert_int_equal(mcp_blend_james_stein(n, d, v, o.js_window, NULL, &js, &rho), 0);
    mcp_blend_input in = {n, v, 64, d, sure, NULL, NULL};
    mcp_blend_result r;
    assert_int_equal(mcp_blend_step(&in, NULL, NULL, NULL, &r), 0);
    for (size_t i = 0; i < (size_t)W * H * 3; i++) {
        assert_true(r.blend->data[i] == js->data[i]);
        double want =
            rho->data[i] >= 1 ? INFINITY : 64 * rho->data[i] / (1 - rho->data[i]);
        if (isinf(want))
            assert_true(isinf(r.weights->data[i]));
        else
            assert_close(r.weights->data[i], want, 1e-6, 1e-9);
    }
    mcp_blend_result_free(&r);
    mcp_image_free(js);
    mcp_image_free(rho);
    mcp_image_free(mu);
    mcp_image_free(n);
    mcp_image_free(d);
    mcp_image_free(v);
    mcp_image_free(sure);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_closed_form),
        cmocka_unit_test(test_biased_denoiser_converges),
        cmocka_unit_test(test_good_denoiser_keeps_its_weight),
        cmocka_unit_test(test_option),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
