/* test_select.c: common/core/select.c (order statistics by radix select) against qsort,
 * on values chosen to stress the key mapping and the bins: negatives, both zeros,
 * infinities, denormals, ties, every value in one bin, and random sets. */
#include "testing.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../../common/core/internal.h"
#include <mcpost/metrics.h>

static int
cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* Every rank of v (n small) or a spread of ranks, selected and sorted, compared bit
 * for bit (a zero's sign aside: -0 and +0 are equal, either may be the one returned). */
static void
check_against_sort(const float *v, size_t n)
{
    float *sorted = malloc(n * sizeof *sorted);
    memcpy(sorted, v, n * sizeof *sorted);
    qsort(sorted, n, sizeof *sorted, cmp_float);
    size_t ranks[64];
    float got[64];
    int k = 0;
    if (n <= 64)
        for (size_t i = 0; i < n; i++)
            ranks[k++] = i;
    else
        for (; k < 64; k++)
            ranks[k] = (size_t)((double)(n - 1) * k / 63.0);
    assert_int_equal(mcp__select_ranks(v, n, ranks, k, got), 0);
    for (int j = 0; j < k; j++) {
        float want = sorted[ranks[j]];
        if (want == 0.0f)
            assert_true(got[j] == 0.0f);
        else
            assert_memory_equal(&got[j], &want, sizeof want);
    }
    free(sorted);
}

static void
test_special_values(void **state)
{
    (void)state;
    const float v[] = {3.0f,    -0.0f,   0.0f,       -2.5f,     INFINITY, -INFINITY,
                       1e-42f,  -1e-42f, 3.0f,       3.0f,      FLT_MIN,  -FLT_MAX,
                       FLT_MAX, 1.0f,    1.0000001f, 0.9999999f};
    check_against_sort(v, sizeof v / sizeof *v);
    check_against_sort(v, 1);
}

static void
test_one_bin_and_ties(void **state)
{
    (void)state;
    /* 10^5 values in [1, 1 + 2^-7): one top-16-bit bin; then all equal */
    size_t n = 100000;
    float *v = malloc(n * sizeof *v);
    uint64_t s = 7;
    for (size_t i = 0; i < n; i++) {
        s = s * 6364136223846793005ull + 1442695040888963407ull;
        v[i] = 1.0f + (float)(s >> 40) / (float)(1 << 24) / 128.0f;
    }
    check_against_sort(v, n);
    for (size_t i = 0; i < n; i++)
        v[i] = 0.25f;
    check_against_sort(v, n);
    free(v);
}

static void
test_random_sets(void **state)
{
    (void)state;
    for (int seed = 1; seed <= 20; seed++) {
        size_t n = 1 + (size_t)seed * 9973;
        float *v = malloc(n * sizeof *v);
        uint64_t s = (uint64_t)seed;
        for (size_t i = 0; i < n; i++) {
            s = s * 6364136223846793005ull + 1442695040888963407ull;
            double u = (double)(s >> 11) / 9007199254740992.0;
            /* log-uniform magnitudes over 60 decades, a third of them negative */
            v[i] = (float)((s & 3) == 0 ? -1.0 : 1.0) * (float)pow(10.0, 60.0 * u - 30.0);
        }
        check_against_sort(v, n);
        free(v);
    }
}

static void
test_image_percentiles(void **state)
{
    (void)state;
    /* a packed image and a crop view of one: the nearest-rank percentiles a sort gives */
    mcp_image *img = mcp_test_random(61, 47, 3, -1.0f, 4.0f, 3, NULL), *view = NULL;
    assert_int_equal(mcp_image_crop_view(img, 5, 7, 40, 30, &view), 0);
    const double p[] = {0.0, 0.25, 0.5, 0.9, 0.999, 1.0};
    for (int pass = 0; pass < 2; pass++) {
        const mcp_image *im = pass ? view : img;
        size_t n = (size_t)im->width * im->height * 3, i = 0;
        float *sorted = malloc(n * sizeof *sorted);
        for (int y = 0; y < im->height; y++)
            for (int x = 0; x < im->width; x++)
                for (int c = 0; c < 3; c++)
                    sorted[i++] = mcp_image_px(im, x, y)[c];
        qsort(sorted, n, sizeof *sorted, cmp_float);
        double got[6];
        assert_int_equal(mcp_image_percentiles(im, p, 6, got), 0);
        for (int k = 0; k < 6; k++) {
            double r = ceil(p[k] * (double)n) - 1.0;
            size_t at = r < 0.0 ? 0 : r > (double)(n - 1) ? n - 1 : (size_t)r;
            assert_true(got[k] == sorted[at]);
        }
        free(sorted);
        /* one channel's smallest, rank 0.99 (n - 1) and largest (a false-colour
           scale's top) */
        for (int c = 0; c < 3; c++) {
            size_t m = (size_t)im->width * im->height, j = 0;
            float *one = malloc(m * sizeof *one), spread[3];
            for (int y = 0; y < im->height; y++)
                for (int x = 0; x < im->width; x++)
                    one[j++] = mcp_image_px(im, x, y)[c];
            qsort(one, m, sizeof *one, cmp_float);
            assert_int_equal(mcp__image_channel_spread(im, c, 0.99, spread), 0);
            assert_true(spread[0] == one[0]);
            assert_true(spread[1] == one[(size_t)(0.99 * (double)(m - 1))]);
            assert_true(spread[2] == one[m - 1]);
            free(one);
        }
    }
    mcp_image_free(view);
    mcp_image_free(img);
}

static void
test_errors(void **state)
{
    (void)state;
    const float v[] = {1.0f, 2.0f};
    float out;
    size_t rank = 2;
    assert_error_contains(mcp__select_ranks(v, 2, &rank, 1, &out),
                          "selection: rank 2 of 2 values");
    rank = 0;
    assert_error_contains(mcp__select_ranks(v, 0, &rank, 1, &out),
                          "selection: no values");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_special_values), cmocka_unit_test(test_one_bin_and_ties),
        cmocka_unit_test(test_random_sets),    cmocka_unit_test(test_image_percentiles),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("common/select", tests, NULL, NULL);
}
