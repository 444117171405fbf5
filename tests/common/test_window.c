/* test_window.c: window sums a band of rows at a time (common/core/stats.c) and the
 * pooling that uses them, against window sums added pixel by pixel in long double:
 * bands that overwrite their rows in place, radii up to 16 (the estimate's limit),
 * windows clipped at every border, a last band shorter than the radius, fireflies
 * beside tiny values. */
#include "testing.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../common/core/internal.h"
#include <mcpost/stats.h>

/* The window sum of channel c at (x, y), clipped, and its pixel count. */
static long double
brute_sum(const mcp_image *img, int x, int y, int r, int c, int *count)
{
    long double s = 0;
    int n = 0;
    for (int yy = y - r; yy <= y + r; yy++)
        for (int xx = x - r; xx <= x + r; xx++)
            if (xx >= 0 && xx < img->width && yy >= 0 && yy < img->height) {
                s += mcp_image_px(img, xx, yy)[c];
                n++;
            }
    *count = n;
    return s;
}

/* Values over eight decades with a few fireflies 1e4 beside values of 1e-6. */
static mcp_image *
wide_values(int w, int h, int channels, uint64_t seed)
{
    mcp_image *img = mcp_test_random(w, h, channels, 0.0f, 1.0f, seed, NULL);
    for (size_t i = 0; i < (size_t)w * h * channels; i++)
        img->data[i] = powf(10.0f, 8.0f * img->data[i] - 6.0f);
    for (int k = 0; k < 7; k++) {
        const int x = (37 * k + 11) % w, y = (53 * k + 5) % h;
        mcp_image_px(img, x, y)[k % 3] = 1e4f;
        if (x + 1 < w) mcp_image_px(img, x + 1, y)[k % 3] = 1e-6f;
    }
    return img;
}

/* mcp_pool_window: each value the mean of its clipped window, from the values as they
 * were (the pooling writes in place, band by band); a 4th channel stays as it was. */
static void
test_pool_window_is_the_window_mean(void **state)
{
    (void)state;
    const int sizes[][2] = {{200, 150}, {97, 140}, {5, 3}};
    const int radii[] = {1, 3, 16};
    for (size_t s = 0; s < sizeof sizes / sizeof *sizes; s++)
        for (size_t k = 0; k < sizeof radii / sizeof *radii; k++) {
            const int w = sizes[s][0], h = sizes[s][1], r = radii[k];
            mcp_image *orig = wide_values(w, h, 4, 17 + s), *pooled = NULL;
            assert_int_equal(mcp_image_copy(orig, &pooled), 0);
            assert_int_equal(mcp_pool_window(pooled, NULL, r), 0);
            for (int y = 0; y < h; y++)
                for (int x = 0; x < w; x++) {
                    for (int c = 0; c < 3; c++) {
                        int n;
                        const long double sum = brute_sum(orig, x, y, r, c, &n);
                        assert_close(mcp_image_px(pooled, x, y)[c], (double)(sum / n),
                                     2e-7, 0);
                    }
                    assert_true(mcp_image_px(pooled, x, y)[3] ==
                                mcp_image_px(orig, x, y)[3]);
                }
            mcp_image_free(orig);
            mcp_image_free(pooled);
        }
}

/* With a shape: shape x (window sum of values / window sum of the shape). */
static void
test_pool_window_with_shape(void **state)
{
    (void)state;
    const int w = 130, h = 141, r = 2;
    mcp_image *orig = wide_values(w, h, 3, 5), *pooled = NULL;
    mcp_image *shape = mcp_test_random(w, h, 3, 0.5f, 2.0f, 9, NULL);
    assert_int_equal(mcp_image_copy(orig, &pooled), 0);
    assert_int_equal(mcp_pool_window(pooled, shape, r), 0);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                int n;
                const long double sv = brute_sum(orig, x, y, r, c, &n),
                                  ss = brute_sum(shape, x, y, r, c, &n);
                assert_close(mcp_image_px(pooled, x, y)[c],
                             (double)(mcp_image_px(shape, x, y)[c] * (sv / ss)), 3e-7, 0);
            }
    mcp_image_free(orig);
    mcp_image_free(pooled);
    mcp_image_free(shape);
}

/* The band interface itself: three images, bands of the most rows and a short last
 * one (140 = 2 x 64 + 12 rows, under the radius 16), each overwritten with garbage
 * after its call; the counts are the clipped windows'. */
static void
test_bands_in_place(void **state)
{
    (void)state;
    const int w = 61, h = 140, r = 16;
    mcp_image *orig[3], *work[3];
    for (int i = 0; i < 3; i++) {
        orig[i] = wide_values(w, h, 3, 100 + i);
        assert_int_equal(mcp_image_copy(orig[i], &work[i]), 0);
    }
    mcp__window wb;
    assert_int_equal(mcp__window_begin(&wb, (const mcp_image *const *)work, 3, r), 0);
    assert_int_equal(wb.rows, MCP__WINDOW_BAND);
    for (int y0 = 0; y0 < h; y0 += wb.rows) {
        const int y1 = y0 + wb.rows < h ? y0 + wb.rows : h;
        assert_int_equal(mcp__window_band(&wb, y0, y1), 0);
        for (int i = 0; i < 3; i++)
            for (int y = y0; y < y1; y++)
                for (int x = 0; x < w; x++) {
                    for (int c = 0; c < 3; c++) {
                        int n;
                        const long double sum = brute_sum(orig[i], x, y, r, c, &n);
                        assert_close(mcp__window_at(&wb, i, x, y)[c], (double)sum, 1e-12,
                                     1e-9);
                        assert_int_equal(mcp__window_count(&wb, x, y), n);
                    }
                    float *p = mcp_image_px(work[i], x, y);
                    p[0] = p[1] = p[2] = -1e30f; /* the caller's writes */
                }
    }
    assert_error_contains(mcp__window_band(&wb, 0, wb.rows + 1), "a band of 65 rows");
    mcp__window_end(&wb);
    assert_error_contains(mcp__window_begin(&wb, (const mcp_image *const *)work, 4, 1),
                          "1 to 3 images");
    for (int i = 0; i < 3; i++) {
        mcp_image_free(orig[i]);
        mcp_image_free(work[i]);
    }
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pool_window_is_the_window_mean),
        cmocka_unit_test(test_pool_window_with_shape),
        cmocka_unit_test(test_bands_in_place),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
