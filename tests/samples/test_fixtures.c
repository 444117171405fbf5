/* test_fixtures.c: the committed Blender Cycles fixtures are what samples/README.md
 * says -- every file reads with the right sample count, each series converges like
 * 1/spp against its reference, and the dumps' variance of the mean agrees with the
 * spread of independent realizations. */
#include "testing.h"

#include <mcpost/dump.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

static const char *scenes[] = {"cornell", "texture"};
enum { N_SERIES = 11, N_SINGLES = 16, N_REAL = 8 };

static mcp_dump *
load(const char *fmt, const char *scene, int a, int b)
{
    char rel[512], path[4096];
    snprintf(rel, sizeof rel, fmt, scene, scene, a, b);
    snprintf(path, sizeof path, "%s/samples/fixtures/%s", MCP_TEST_SOURCE_DIR, rel);
    mcp_dump *d = NULL;
    if (mcp_dump_read(path, &d)) fail_msg("%s", mcp_error_message());
    return d;
}

static void
test_every_file_reads_with_its_sample_count(void **state)
{
    (void)state;
    for (int s = 0; s < 2; s++) {
        for (int i = 0; i < N_SERIES; i++) {
            mcp_dump *d = load("%s/series/%s_spp%04d.exr", scenes[s], 1 << i, 0);
            assert_true(d->spp == (1 << i));
            assert_non_null(d->var_of_mean);
            assert_non_null(d->albedo);
            assert_non_null(d->normal);
            assert_int_equal(d->color->width, 128);
            mcp_dump_free(d);
        }
        for (int i = 0; i < N_SINGLES; i++) {
            mcp_dump *d = load("%s/singles/%s_single%02d.exr", scenes[s], i, 0);
            assert_true(d->spp == 1);
            mcp_dump_free(d);
        }
        for (int n = 32; n <= 128; n *= 4)
            for (int r = 0; r < N_REAL; r++) {
                mcp_dump *d = load("%s/realizations/%s_spp%04d_r%d.exr", scenes[s], n, r);
                assert_true(d->spp == n);
                mcp_dump_free(d);
            }
        mcp_dump *ref = load("%s/%s_reference.exr", scenes[s], 0, 0);
        assert_true(ref->spp >= 8192);
        mcp_dump_free(ref);
    }
}

static double
relmse(const mcp_image *a, const mcp_image *r)
{
    double sum = 0;
    size_t n = (size_t)a->width * a->height * 3;
    for (size_t i = 0; i < n; i++) {
        double d = (double)a->data[i] - r->data[i];
        sum += d * d / ((double)r->data[i] * r->data[i] + 1e-2);
    }
    return sum / (double)n;
}

/* Least-squares slope of log relMSE against log spp over the whole series: Monte
 * Carlo error falls as 1/spp, so the slope must be near -1; [-1.2, -0.8] allows for
 * the reference's own error at the top and rare bright paths at the bottom. */
static void
test_series_converge_like_one_over_spp(void **state)
{
    (void)state;
    for (int s = 0; s < 2; s++) {
        mcp_dump *ref = load("%s/%s_reference.exr", scenes[s], 0, 0);
        double sx = 0, sy = 0, sxx = 0, sxy = 0;
        for (int i = 0; i < N_SERIES; i++) {
            mcp_dump *d = load("%s/series/%s_spp%04d.exr", scenes[s], 1 << i, 0);
            double x = log((double)(1 << i)), y = log(relmse(d->color, ref->color));
            sx += x, sy += y, sxx += x * x, sxy += x * y;
            mcp_dump_free(d);
        }
        double slope = (N_SERIES * sxy - sx * sy) / (N_SERIES * sxx - sx * sx);
        print_message("%s: relMSE slope %.3f\n", scenes[s], slope);
        assert_true(slope > -1.2 && slope < -0.8);
        mcp_dump_free(ref);
    }
}

/* The image mean of Variance/spp in the series at n against the unbiased variance of
 * 8 independent n-spp realizations, averaged over all pixels and channels. With 8
 * realizations each pixel's estimate is noisy (chi-square, 7 dof) but the mean over
 * 128*128*3 values is stable: [0.8, 1.25]. */
static void
test_variance_matches_realizations(void **state)
{
    (void)state;
    for (int s = 0; s < 2; s++)
        for (int n = 32; n <= 128; n *= 4) {
            mcp_dump *real[N_REAL];
            for (int r = 0; r < N_REAL; r++)
                real[r] = load("%s/realizations/%s_spp%04d_r%d.exr", scenes[s], n, r);
            int k = 0;
            while ((1 << k) != n)
                k++;
            mcp_dump *d = load("%s/series/%s_spp%04d.exr", scenes[s], n, 0);
            size_t count = (size_t)128 * 128 * 3;
            double empirical = 0, claimed = 0;
            for (size_t i = 0; i < count; i++) {
                double mean = 0, ss = 0;
                for (int r = 0; r < N_REAL; r++)
                    mean += real[r]->color->data[i] / (double)N_REAL;
                for (int r = 0; r < N_REAL; r++) {
                    double e = real[r]->color->data[i] - mean;
                    ss += e * e;
                }
                empirical += ss / (N_REAL - 1);
                claimed += d->var_of_mean->data[i];
            }
            double ratio = claimed / empirical;
            print_message("%s at %d spp: variance ratio %.3f\n", scenes[s], n, ratio);
            assert_true(ratio >= 0.8 && ratio <= 1.25);
            mcp_dump_free(d);
            for (int r = 0; r < N_REAL; r++)
                mcp_dump_free(real[r]);
        }
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_file_reads_with_its_sample_count),
        cmocka_unit_test(test_series_converge_like_one_over_spp),
        cmocka_unit_test(test_variance_matches_realizations),
    };
    return cmocka_run_group_tests_name("samples/fixtures", tests, NULL, NULL);
}
