/* test_filter.c: common/filter/filter.c and common/filter/colormap.c -- separable and 2D
 * filters against a naive replicate-border correlation, the Gaussian kernel against its
 * closed form, tile power spectra against closed forms and Parseval, colour-map
 * endpoints, and every error path. */
#include "testing.h"

#include <mcpost/filter.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "../../common/filter/internal.h"

/* Filter results vs. the naive reference: both sum at most ~150 products whose
 * magnitudes add up to about 1 (kernels are scaled to sum(|k|) <= 1, pixels in [0, 1)),
 * so float32 rounding stays below 150 * 2^-24 ~ 1e-5 even in the worst case. */
#define FILTER_TOL 1e-5

static int
clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

static float
px(const mcp_image *img, int x, int y, int c)
{
    x = clampi(x, 0, img->width - 1); /* replicate border */
    y = clampi(y, 0, img->height - 1);
    return mcp_image_px(img, x, y)[c];
}

/* The naive 2D correlation sum_{i,j} k[j][i] img(x + i - rx, y + j - ry) in double,
 * with replicate borders. A separable kernel is passed as its outer product. */
static mcp_image *
naive_filter(const mcp_image *img, const float *k, int kw, int kh)
{
    mcp_image *out = NULL;
    int w = img->width, h = img->height;
    assert_int_equal(mcp_image_new(w, h, img->channels, NULL, &out), 0);
    int rx = kw / 2, ry = kh / 2;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < img->channels; c++) {
                double s = 0;
                for (int j = 0; j < kh; j++)
                    for (int i = 0; i < kw; i++)
                        s += (double)k[j * kw + i] * px(img, x + i - rx, y + j - ry, c);
                mcp_image_px(out, x, y)[c] = (float)s;
            }
    return out;
}

/* n random taps in [-1, 1), scaled so sum |k| = scale; deliberately asymmetric so
 * that a flipped (convolution) kernel would fail. */
static float *
random_kernel(int n, double scale, uint64_t seed)
{
    float *k = malloc((size_t)n * sizeof *k);
    double sum = 0;
    assert_non_null(k);
    for (int i = 0; i < n; i++) {
        k[i] = (float)(2 * mcp_test_rand_uniform(&seed) - 1);
        sum += fabs(k[i]);
    }
    for (int i = 0; i < n; i++)
        k[i] = (float)(k[i] * scale / sum);
    return k;
}

static float *
outer(const float *kx, int kx_len, const float *ky, int ky_len)
{
    float *k = malloc((size_t)kx_len * ky_len * sizeof *k);
    assert_non_null(k);
    for (int j = 0; j < ky_len; j++)
        for (int i = 0; i < kx_len; i++)
            k[j * kx_len + i] = kx[i] * ky[j];
    return k;
}

static void
check_separable(const mcp_image *img, int kx_len, int ky_len, uint64_t seed)
{
    float *kx = random_kernel(kx_len, 1, seed), *ky = random_kernel(ky_len, 1, seed + 1);
    float *k2 = outer(kx, kx_len, ky, ky_len);
    mcp_image *got = NULL, *want = naive_filter(img, k2, kx_len, ky_len);
    assert_int_equal(mcp_filter_separable(img, kx, kx_len, ky, ky_len, &got), 0);
    assert_true(mcp_image_is_packed(got));
    assert_string_equal(got->names[img->channels - 1], img->names[img->channels - 1]);
    assert_close(mcp_test_max_abs_diff(got, want), 0, 0, FILTER_TOL);
    mcp_image_free(got);
    mcp_image_free(want);
    free(k2);
    free(ky);
    free(kx);
}

static void
check_2d(const mcp_image *img, int kw, int kh, uint64_t seed)
{
    float *k = random_kernel(kw * kh, 1, seed);
    mcp_image *got = NULL, *want = naive_filter(img, k, kw, kh);
    assert_int_equal(mcp_filter_2d(img, k, kw, kh, &got), 0);
    assert_true(mcp_image_is_packed(got));
    assert_close(mcp_test_max_abs_diff(got, want), 0, 0, FILTER_TOL);
    mcp_image_free(got);
    mcp_image_free(want);
    free(k);
}

/* Runs check(img) on a packed image, a crop view (packed pixels, wider rows), a
 * channel view (pixel_stride != channels) and a channel view of a crop. */
static void
check_on_views(void (*check)(const mcp_image *, int, int, uint64_t), int channels, int kw,
               int kh)
{
    const char *names[] = {"R", "G", "B", "A", "N.X", "N.Y", "N.Z", "V"};
    mcp_image *parent = mcp_test_random(41, 33, channels, 0, 1, 7, names);
    mcp_image *crop = NULL, *chan = NULL, *both = NULL;
    assert_int_equal(mcp_image_crop_view(parent, 3, 5, 30, 21, &crop), 0);
    assert_int_equal(mcp_image_channel_view(parent, 1, channels - 1, &chan), 0);
    assert_int_equal(mcp_image_channel_view(crop, 1, channels - 1, &both), 0);
    check(parent, kw, kh, 11);
    check(crop, kw, kh, 12);
    check(chan, kw, kh, 13);
    check(both, kw, kh, 14);
    mcp_image_free(both);
    mcp_image_free(chan);
    mcp_image_free(crop);
    mcp_image_free(parent);
}

static void
test_separable_matches_naive(void **state)
{
    (void)state;
    check_on_views(check_separable, 3, 5, 7);
    check_on_views(check_separable, 4, 1, 3);
    check_on_views(check_separable, 8, 9, 5); /* 8 and 7 channels: groups of 4 */
    check_on_views(check_separable, 2, 3, 1);
}

static void
test_2d_matches_naive(void **state)
{
    (void)state;
    check_on_views(check_2d, 3, 5, 3);
    check_on_views(check_2d, 8, 3, 7);
    /* 13 x 11 = 143 taps: OpenCV correlates whole images this large by DFT */
    check_on_views(check_2d, 2, 13, 11);
}

/* Several strips of rows, run by several threads, must agree with the reference too
 * (and so with each other). */
static void
test_filters_on_many_strips(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_random(157, 211, 3, 0, 1, 3, NULL);
    check_separable(img, 11, 11, 5);
    check_2d(img, 5, 7, 6);
    check_2d(img, 13, 13, 7);
    mcp_image_free(img);
}

/* Kernels wider and taller than the image see mostly replicated edge pixels. */
static void
test_kernel_larger_than_image(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_random(3, 2, 5, 0, 1, 9, NULL);
    check_separable(img, 9, 11, 1);
    check_2d(img, 7, 9, 2);
    check_2d(img, 15, 13, 3);
    mcp_image_free(img);
    img = mcp_test_random(1, 1, 1, 0, 1, 10, NULL);
    check_separable(img, 5, 3, 4);
    check_2d(img, 3, 5, 5);
    check_2d(img, 13, 11, 6);
    mcp_image_free(img);
    img = mcp_test_random(20, 1, 3, 0, 1, 11, NULL); /* one row */
    check_separable(img, 13, 11, 7);
    check_2d(img, 13, 11, 8);
    mcp_image_free(img);
}

/* An Inf pixel may only reach outputs whose kernel footprint covers it. (OpenCV's DFT
 * method for big kernels on whole images would make every output NaN.) */
static void
test_inf_stays_in_footprint(void **state)
{
    (void)state;
    const int sizes[][2] = {{40, 30}, {40, 1}, {157, 211}};
    float k[13 * 13];
    for (int i = 0; i < 13 * 13; i++)
        k[i] = 1.0f / (13 * 13);
    for (int s = 0; s < 3; s++) {
        int w = sizes[s][0], h = sizes[s][1], x0 = 5, y0 = h / 2;
        mcp_image *img = mcp_test_constant(w, h, 1, 0.5f, NULL), *out = NULL;
        mcp_image_px(img, x0, y0)[0] = INFINITY;
        assert_int_equal(mcp_filter_2d(img, k, 13, 13, &out), 0);
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                int inside = abs(x - x0) <= 6 && abs(y - y0) <= 6;
                float v = mcp_image_px(out, x, y)[0];
                if (inside)
                    assert_true(isinf(v));
                else
                    assert_close(v, 0.5, 0, FILTER_TOL); /* 169 float taps */
            }
        mcp_image_free(out);
        mcp_image_free(img);
    }
}

static void
test_gaussian_kernel_closed_form(void **state)
{
    (void)state;
    const double sigmas[] = {0.3, 1.0, 2.5, 100.0};
    for (int s = 0; s < 4; s++) {
        int r = 6;
        float k[13];
        double norm = 0, sum = 0;
        assert_int_equal(mcp_gaussian_kernel(sigmas[s], r, k), 0);
        for (int i = -r; i <= r; i++)
            norm += exp(-i * i / (2 * sigmas[s] * sigmas[s]));
        for (int i = -r; i <= r; i++) {
            double want = exp(-i * i / (2 * sigmas[s] * sigmas[s])) / norm;
            /* one float rounding of each tap */
            assert_close(k[i + r], want, 1e-7, 1e-12);
            assert_true(k[i + r] == k[r - i]);
            sum += k[i + r];
        }
        assert_close(sum, 1, 0, 13 * 6e-8); /* 13 roundings to float */
    }
    float k[5];
    assert_int_equal(mcp_gaussian_kernel(0, 2, k), 0); /* sigma 0: the identity */
    assert_true(k[0] == 0 && k[1] == 0 && k[2] == 1 && k[3] == 0 && k[4] == 0);
    assert_int_equal(mcp_gaussian_kernel(1, 0, k), 0);
    assert_true(k[0] == 1);
}

static void
test_gaussian_blur(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_constant(20, 13, 3, 0.75f, NULL), *out = NULL;
    mcp_image_set_source(img, "c.exr");
    assert_int_equal(mcp_gaussian_blur(img, 11, 2.0, &out), 0);
    assert_string_equal(out->source, "c.exr (blurred)");
    for (size_t i = 0; i < 20 * 13 * 3; i++)
        assert_close(out->data[i], 0.75, 1e-6, 0); /* weights sum to 1 within 1e-6 */
    mcp_image_free(out);
    mcp_image_free(img);

    /* the blur is the separable filter with mcp_gaussian_kernel, bit for bit */
    img = mcp_test_random(64, 90, 3, 0, 1, 5, NULL);
    float k[7];
    mcp_image *sep = NULL;
    assert_int_equal(mcp_gaussian_kernel(1.5, 3, k), 0);
    assert_int_equal(mcp_gaussian_blur(img, 7, 1.5, &out), 0);
    assert_int_equal(mcp_filter_separable(img, k, 7, k, 7, &sep), 0);
    assert_true(mcp_test_max_abs_diff(out, sep) == 0);
    mcp_image_free(sep);
    mcp_image_free(out);
    /* window 1 is the identity */
    assert_int_equal(mcp_gaussian_blur(img, 1, 3.0, &out), 0);
    assert_true(mcp_test_max_abs_diff(out, img) == 0);
    mcp_image_free(out);
    mcp_image_free(img);
}

/* Tiles of A cos(2 pi (kx x + ky y) / N): |DFT|^2 = (A N^2 / 2)^2 = A^2 N^4 / 4 at
 * +-(kx, ky) and 0 elsewhere (the 2D form of the 1D A^2 N^2 / 4). */
static void
test_spectra_of_cosine(void **state)
{
    (void)state;
    const int n = 32, kx = 3, ky = -5;
    const double a = 0.8, pi = 3.14159265358979323846;
    /* 70 x 40: two tiles across, one down; the rest is dropped. Channel 1 of 3. */
    mcp_image *img = mcp_test_constant(70, 40, 3, 9.0f, NULL), *out = NULL;
    for (int y = 0; y < 40; y++)
        for (int x = 0; x < 70; x++)
            mcp_image_px(img, x, y)[1] = (float)(a * cos(2 * pi * (kx * x + ky * y) / n));
    assert_int_equal(mcp_tile_power_spectra(img, 1, n, &out), 0);
    assert_int_equal(out->width, 64);
    assert_int_equal(out->height, 32);
    assert_int_equal(out->channels, 1);
    assert_string_equal(out->names[0], "power");
    double peak = a * a * pow(n, 4) / 4;
    for (int t = 0; t < 2; t++)
        for (int v = 0; v < n; v++)
            for (int u = 0; u < n; u++) {
                int fu = u - n / 2, fv = v - n / 2; /* zero frequency at (16, 16) */
                int hit = (fu == kx && fv == ky) || (fu == -kx && fv == -ky);
                /* inputs were rounded to float: leakage ~ (N^2 * 6e-8)^2 of the peak */
                assert_close(mcp_image_px(out, t * n + u, v)[0], hit ? peak : 0, 1e-6,
                             peak * 1e-9);
            }
    mcp_image_free(out);
    mcp_image_free(img);
}

static void
test_spectra_dc_and_parseval(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_constant(10, 12, 1, 0.5f, NULL), *out = NULL;
    /* odd tile: zero frequency at (2, 2) */
    assert_int_equal(mcp_tile_power_spectra(img, 0, 5, &out), 0);
    assert_int_equal(out->width, 10);
    assert_int_equal(out->height, 10);
    for (int y = 0; y < 10; y++)
        for (int x = 0; x < 10; x++) {
            double want = x % 5 == 2 && y % 5 == 2 ? pow(25 * 0.5, 2) : 0;
            assert_close(mcp_image_px(out, x, y)[0], want, 1e-6, 1e-9);
        }
    mcp_image_free(out);
    mcp_image_free(img);

    /* Parseval per tile: sum |X|^2 = N^2 sum x^2 (double DFT, float output) */
    img = mcp_test_random(64, 48, 2, -1, 1, 3, NULL);
    assert_int_equal(mcp_tile_power_spectra(img, 1, 16, &out), 0);
    for (int ty = 0; ty < 3; ty++)
        for (int tx = 0; tx < 4; tx++) {
            double power = 0, energy = 0;
            for (int y = 0; y < 16; y++)
                for (int x = 0; x < 16; x++) {
                    power += mcp_image_px(out, tx * 16 + x, ty * 16 + y)[0];
                    double v = mcp_image_px(img, tx * 16 + x, ty * 16 + y)[1];
                    energy += v * v;
                }
            assert_close(power, 256 * energy, 1e-6, 0);
        }
    mcp_image_free(out);
    mcp_image_free(img);
}

/* First and last colours of the maps: matplotlib's and Google's published tables, x 255
 * and rounded. OpenCV 4.6 reproduces them exactly; a BGR/RGB mix-up would not. */
static void
test_colormap_endpoints(void **state)
{
    (void)state;
    const struct {
        mcp_colormap map;
        unsigned char first[3], last[3];
    } maps[] = {
        {MCP_COLORMAP_VIRIDIS, {68, 1, 84}, {253, 231, 37}},
        {MCP_COLORMAP_MAGMA, {0, 0, 4}, {252, 253, 191}},
        {MCP_COLORMAP_INFERNO, {0, 0, 4}, {252, 255, 164}},
        {MCP_COLORMAP_TURBO, {48, 18, 59}, {122, 4, 3}},
        {MCP_COLORMAP_GRAY, {0, 0, 0}, {255, 255, 255}},
    };
    /* a channel view: pixel stride 2 */
    mcp_image *parent = mcp_test_constant(4, 1, 2, 0, NULL), *img = NULL;
    assert_int_equal(mcp_image_channel_view(parent, 1, 1, &img), 0);
    float *p = img->data;
    p[0] = -1;     /* lo */
    p[2] = NAN;    /* -> first colour */
    p[4] = 3;      /* hi */
    p[6] = -1e30f; /* clamped */
    for (int m = 0; m < 5; m++) {
        unsigned char rgb[12];
        assert_int_equal(mcp_colormap_apply(img, 0, -1, 3, maps[m].map, rgb), 0);
        for (int c = 0; c < 3; c++) {
            assert_int_equal(rgb[c], maps[m].first[c]);
            assert_int_equal(rgb[3 + c], rgb[c]);
            assert_int_equal(rgb[6 + c], maps[m].last[c]);
            assert_int_equal(rgb[9 + c], rgb[c]);
        }
    }
    mcp_image_free(img);
    mcp_image_free(parent);
}

/* GRAY is the 8-bit level itself: lo + L (hi - lo) / 255 -> L, rounded to nearest. */
static void
test_colormap_gray_exact(void **state)
{
    (void)state;
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(256, 2, 1, NULL, &img), 0);
    for (int l = 0; l < 256; l++) {
        img->data[l] = (float)(-2.0 + l * 6.0 / 255);
        img->data[256 + l] = (float)(-2.0 + (l + 0.3) * 6.0 / 255);
    }
    img->data[256 + 255] = INFINITY;
    unsigned char *rgb = malloc(256 * 2 * 3);
    assert_int_equal(mcp_colormap_apply(img, 0, -2, 4, MCP_COLORMAP_GRAY, rgb), 0);
    for (int i = 0; i < 512; i++)
        for (int c = 0; c < 3; c++)
            assert_int_equal(rgb[3 * i + c], i % 256);
    free(rgb);
    mcp_image_free(img);
}

static void
test_colormap_names(void **state)
{
    (void)state;
    const char *names[] = {"viridis", "magma", "inferno", "turbo", "gray"};
    const mcp_colormap maps[] = {MCP_COLORMAP_VIRIDIS, MCP_COLORMAP_MAGMA,
                                 MCP_COLORMAP_INFERNO, MCP_COLORMAP_TURBO,
                                 MCP_COLORMAP_GRAY};
    for (int i = 0; i < 5; i++) {
        mcp_colormap m = (mcp_colormap)-1;
        assert_int_equal(mcp_colormap_from_name(names[i], &m), 0);
        assert_int_equal(m, maps[i]);
    }
    mcp_colormap m;
    assert_error_contains(mcp_colormap_from_name("jet", &m), "unknown colour map 'jet'");
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_random(8, 6, 2, 0, 1, 1, NULL);
    mcp_image *out = (mcp_image *)1;
    float k[9] = {0, 0, 0, 0, 1, 0, 0, 0, 0};
    unsigned char rgb[8 * 6 * 3];
    mcp_image_set_source(img, "e.exr");

    assert_error_contains(mcp_gaussian_blur(img, 4, 1.0, &out),
                          "e.exr: gaussian blur: window must be odd and >= 1 (got 4)");
    assert_null(out);
    assert_error_contains(mcp_gaussian_blur(img, -3, 1.0, &out), "(got -3)");
    assert_error_contains(
        mcp_gaussian_blur(img, 5, -0.5, &out),
        "e.exr: gaussian blur: sigma must be finite and >= 0 (got -0.5)");
    assert_error_contains(mcp_gaussian_blur(img, 5, NAN, &out), "(got nan)");
    assert_error_contains(mcp_gaussian_kernel(-1, 2, k),
                          "gaussian kernel: sigma must be finite and >= 0 (got -1)");
    assert_error_contains(mcp_gaussian_kernel(1, -2, k), "radius must be between");

    assert_error_contains(mcp_filter_separable(img, k, 4, k, 3, &out),
                          "e.exr: separable filter: kx length must be odd");
    assert_null(out);
    assert_error_contains(mcp_filter_separable(img, k, 3, k, 0, &out),
                          "ky length must be odd and between 1 and 131073 (got 0)");
    assert_error_contains(mcp_filter_separable(img, NULL, 3, k, 3, &out), "no kernel");
    assert_error_contains(mcp_filter_2d(img, k, 3, 2, &out),
                          "e.exr: 2d filter: kernel height must be odd");
    assert_null(out);

    assert_error_contains(
        mcp_tile_power_spectra(img, 0, 7, &out),
        "e.exr: tile power spectra: tile size 7 larger than the 8x6 image");
    assert_null(out);
    assert_error_contains(mcp_tile_power_spectra(img, 0, 0, &out),
                          "tile size must be >= 1 (got 0)");
    assert_error_contains(mcp_tile_power_spectra(img, 2, 4, &out),
                          "e.exr: tile power spectra: channel 2 outside its 2 channels");
    assert_error_contains(mcp_tile_power_spectra(img, -1, 4, &out), "channel -1 outside");
    assert_null(out);

    assert_error_contains(mcp_colormap_apply(img, 5, 0, 1, MCP_COLORMAP_VIRIDIS, rgb),
                          "e.exr: colormap: channel 5 outside its 2 channels");
    assert_error_contains(mcp_colormap_apply(img, 0, 1, 1, MCP_COLORMAP_VIRIDIS, rgb),
                          "e.exr: colormap: need finite lo < hi (got lo 1, hi 1)");
    assert_error_contains(mcp_colormap_apply(img, 0, 0, INFINITY, MCP_COLORMAP_GRAY, rgb),
                          "hi inf");
    assert_error_contains(
        mcp_colormap_apply(img, 0, 0, 1, (mcp_colormap)(MCP_COLORMAP_GRAY + 1), rgb),
        "e.exr: colormap: unknown colour map 5");
    mcp_image_free(img);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_separable_matches_naive),
        cmocka_unit_test(test_2d_matches_naive),
        cmocka_unit_test(test_filters_on_many_strips),
        cmocka_unit_test(test_kernel_larger_than_image),
        cmocka_unit_test(test_inf_stays_in_footprint),
        cmocka_unit_test(test_gaussian_kernel_closed_form),
        cmocka_unit_test(test_gaussian_blur),
        cmocka_unit_test(test_spectra_of_cosine),
        cmocka_unit_test(test_spectra_dc_and_parseval),
        cmocka_unit_test(test_colormap_endpoints),
        cmocka_unit_test(test_colormap_gray_exact),
        cmocka_unit_test(test_colormap_names),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("common/filter", tests, NULL, NULL);
}
