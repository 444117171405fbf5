/* test_spectra.c: common/metrics/spectra.c on errors whose spectra are known: white noise
 * (flat: the low fraction is the share of bins below the cutoff), a pure low
 * frequency (all energy low), the Nyquist checkerboard (none low), and
 * differentiated white noise (blue: less than white). */
#include "testing.h"

#include <math.h>
#include <stdlib.h>

#include <mcpost/spectra.h>

#define PI_D 3.14159265358979323846

static const char *const RGB[] = {"R", "G", "B"};

static mcp_image *
noise(int w, int h, int c, uint64_t seed)
{
    mcp_image *img = mcp_test_constant(w, h, c, 0.0f, c == 3 ? RGB : NULL);
    for (size_t i = 0; i < (size_t)w * h * c; i++)
        img->data[i] = (float)mcp_test_rand_normal(&seed);
    return img;
}

static void
test_white_fraction(void **state)
{
    (void)state;
    mcp_spectra_result r;
    mcp_image *e = noise(256, 256, 3, 1), *pic = NULL;
    assert_int_equal(mcp_spectra_analyse(e, NULL, &r, &pic), 0);
    /* 32x32 tiles, cutoff Nyquist/4: bins with u^2 + v^2 < 16, DC excluded: 44/1023. */
    assert_close(r.white_fraction, 44.0 / 1023.0, 1e-12, 0);
    /* 64 tiles x 3 channels x 44 bins of exponential(1)-distributed power: the
     * fraction's relative spread is about 1/sqrt(8448) ~ 1%; allow 6%. */
    assert_close(r.low_fraction, r.white_fraction, 0.06, 0);
    assert_int_equal(r.tiles_x, 8);
    assert_int_equal(r.tiles_y, 8);
    /* Parseval: the energy per pixel is the variance, 1 per channel x 3 channels. */
    assert_close(r.energy, 3.0, 0.05, 0);
    assert_int_equal(pic->width, 256);
    assert_int_equal(pic->channels, 1);
    for (int j = 0; j < 8; j++)
        for (int i = 0; i < 8; i++) {
            double mx = 0;
            for (int v = 0; v < 32; v++)
                for (int u = 0; u < 32; u++) {
                    float p = mcp_image_px(pic, i * 32 + u, j * 32 + v)[0];
                    assert_true(p >= 0.0f && p <= 1.0f);
                    mx = p > mx ? p : mx;
                }
            assert_close(mx, 1.0, 1e-6, 0); /* normalised per tile */
            assert_true(mcp_image_px(pic, i * 32 + 16, j * 32 + 16)[0] == 0.0f); /* DC */
        }
    mcp_image_free(pic);
    mcp_image_free(e);
}

static void
test_low_and_high_frequency(void **state)
{
    (void)state;
    mcp_spectra_result r;
    /* A sinusoid of period 16 px (2 cycles per 32-px tile, 1/16 cycles/px < 1/8):
     * all energy below the cutoff, plus a constant offset that DC takes. */
    mcp_image *low = mcp_test_constant(64, 64, 1, 0.0f, NULL);
    for (int y = 0; y < 64; y++)
        for (int x = 0; x < 64; x++)
            mcp_image_px(low, x, y)[0] = (float)(0.3 + sin(2 * PI_D * x / 16.0));
    assert_int_equal(mcp_spectra_analyse(low, NULL, &r, NULL), 0);
    assert_close(r.low_fraction, 1.0, 1e-6, 0);
    /* The checkerboard sits at Nyquist: nothing below the cutoff. */
    mcp_image *check = mcp_test_constant(64, 64, 1, 0.0f, NULL);
    for (int y = 0; y < 64; y++)
        for (int x = 0; x < 64; x++)
            mcp_image_px(check, x, y)[0] = (x + y) % 2 ? 1.0f : -1.0f;
    assert_int_equal(mcp_spectra_analyse(check, NULL, &r, NULL), 0);
    assert_close(r.low_fraction, 0.0, 0, 1e-9);
    /* A constant error has no non-DC energy: fraction 0, energy 0. */
    mcp_image *flat = mcp_test_constant(64, 64, 1, 0.5f, NULL);
    assert_int_equal(mcp_spectra_analyse(flat, NULL, &r, NULL), 0);
    assert_close(r.low_fraction, 0.0, 0, 0);
    assert_close(r.energy, 0.0, 0, 1e-9);
    /* Cutoff 1 (Nyquist): everything inside the inscribed circle counts. */
    mcp_spectra_options o = mcp_spectra_defaults();
    o.cutoff = 1.0;
    assert_int_equal(mcp_spectra_analyse(low, &o, &r, NULL), 0);
    assert_close(r.low_fraction, 1.0, 1e-6, 0);
    mcp_image_free(flat);
    mcp_image_free(check);
    mcp_image_free(low);
}

static void
test_blue_noise_below_white(void **state)
{
    (void)state;
    /* Blue noise by differencing white noise in x and y (a high-pass): its
     * low-frequency share falls well below white noise's. The images are the test
     * and the reference of a pair: error = T(test) - T(ref) with T = none. */
    mcp_image *white = noise(129, 129, 3, 7);
    mcp_image *test = mcp_test_constant(128, 128, 3, 0.0f, RGB);
    mcp_image *ref = mcp_test_constant(128, 128, 3, 0.0f, RGB);
    for (int y = 0; y < 128; y++)
        for (int x = 0; x < 128; x++)
            for (int c = 0; c < 3; c++) {
                float a = mcp_image_px(white, x + 1, y + 1)[c],
                      b = mcp_image_px(white, x, y + 1)[c],
                      d = mcp_image_px(white, x + 1, y)[c],
                      e = mcp_image_px(white, x, y)[c];
                mcp_image_px(test, x, y)[c] = 20.0f + (a - b - d + e);
                mcp_image_px(ref, x, y)[c] = 20.0f;
            }
    mcp_spectra_options o = mcp_spectra_defaults();
    o.tone_map = MCP_TONEMAP_NONE;
    mcp_spectra_result r;
    assert_int_equal(mcp_spectra_blue_noise(test, ref, &o, &r, NULL), 0);
    assert_true(r.low_fraction < 0.25 * r.white_fraction);
    /* With the default clamp the values (around 20) all clamp to 1: no error. */
    assert_int_equal(mcp_spectra_blue_noise(test, ref, NULL, &r, NULL), 0);
    assert_close(r.energy, 0.0, 0, 0);
    mcp_image_free(ref);
    mcp_image_free(test);
    mcp_image_free(white);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_spectra_result r;
    mcp_spectra_options o = mcp_spectra_defaults();
    mcp_image *small = mcp_test_constant(20, 40, 3, 0.0f, RGB);
    mcp_image_set_source(small, "small.exr");
    mcp_image *pic = (mcp_image *)&r;
    assert_error_contains(
        mcp_spectra_analyse(small, NULL, &r, &pic),
        "small.exr: spectra: image 20x40 is smaller than one 32x32 tile");
    assert_null(pic);
    o.tile_size = 2;
    assert_error_contains(mcp_spectra_analyse(small, &o, &r, NULL),
                          "spectra: tile_size must be in [4, 4096] (got 2)");
    o = mcp_spectra_defaults();
    o.cutoff = 0;
    assert_error_contains(mcp_spectra_analyse(small, &o, &r, NULL),
                          "spectra: cutoff must be in (0, 1] (got 0)");
    mcp_image *other = mcp_test_constant(20, 41, 3, 0.0f, RGB);
    mcp_image_set_source(other, "other.exr");
    assert_error_contains(mcp_spectra_blue_noise(small, other, NULL, &r, NULL),
                          "small.exr: size 20x40 does not match other.exr (20x41)");
    mcp_image_px(other, 0, 0)[0] = NAN;
    assert_error_contains(mcp_spectra_blue_noise(other, other, NULL, &r, NULL),
                          "other.exr: non-finite value nan at pixel (0, 0) channel R");
    mcp_image_free(other);
    mcp_image_free(small);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_white_fraction),
        cmocka_unit_test(test_low_and_high_frequency),
        cmocka_unit_test(test_blue_noise_below_white),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("common/spectra", tests, NULL, NULL);
}
