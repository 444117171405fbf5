/* test_void_cluster.c: perceptual/void_cluster.c -- the void-and-cluster mask is a
 * permutation of ranks, deterministic per seed, with little low-frequency energy (its
 * spectrum against white noise's); the thresholds; the disk cache (written, read back,
 * a corrupt file regenerated, an unusable folder skipped); the error paths. */
#include "perc_testing.h"

#include <mcpost/spectra.h>

#include <math.h>
#include <stdlib.h>

static void
assert_permutation(const int *rank, int n)
{
    unsigned char *seen = calloc((size_t)n, 1);
    for (int i = 0; i < n; i++) {
        assert_true(rank[i] >= 0 && rank[i] < n);
        assert_int_equal(seen[rank[i]], 0);
        seen[rank[i]] = 1;
    }
    free(seen);
}

/* The fraction of the mask's spectral energy below 1/4 of Nyquist, with its mean
 * removed (spectra.h leaves the zero frequency out), and what white noise gives. */
static void
low_fraction(const int *rank, int size, double *low, double *white)
{
    mcp_image *img = mcp_test_constant(size, size, 1, 0.0f, NULL);
    int n = size * size;
    for (int i = 0; i < n; i++)
        img->data[i] = (float)((rank[i] + 0.5) / n - 0.5);
    mcp_spectra_options o = mcp_spectra_defaults();
    o.tile_size = size;
    mcp_spectra_result r;
    assert_int_equal(mcp_spectra_analyse(img, &o, &r, NULL), 0);
    *low = r.low_fraction;
    *white = r.white_fraction;
    mcp_image_free(img);
}

static void
test_ranks(void **state)
{
    (void)state;
    int *a = malloc(128 * 128 * sizeof *a), *b = malloc(128 * 128 * sizeof *b);
    assert_int_equal(mcp_void_and_cluster(128, 1.5, 1, a), 0);
    assert_permutation(a, 128 * 128);
    assert_int_equal(mcp_void_and_cluster(128, 1.5, 1, b), 0);
    assert_memory_equal(a, b, 128 * 128 * sizeof *a); /* deterministic */
    double low, white;
    low_fraction(a, 128, &low, &white);
    print_message("void and cluster 128x128: low-frequency fraction %.5f (white noise "
                  "%.4f)\n",
                  low, white);
    /* blue noise: the disk below 1/4 Nyquist holds ~5% of the bins but almost none of
     * the energy (a seeded white-noise permutation gives ~white, checked below) */
    assert_true(low < 0.1 * white);
    assert_int_equal(mcp_void_and_cluster(128, 1.5, 2, b), 0);
    assert_permutation(b, 128 * 128);
    assert_true(memcmp(a, b, 128 * 128 * sizeof *a) != 0); /* the seed matters */
    /* white noise for contrast: a random permutation */
    uint64_t st = 5;
    for (int i = 0; i < 128 * 128; i++)
        b[i] = i;
    for (int i = 128 * 128 - 1; i > 0; i--) {
        int j = (int)(mcp_test_rand_u64(&st) % (uint64_t)(i + 1)), t = b[i];
        b[i] = b[j], b[j] = t;
    }
    double wlow, wwhite;
    low_fraction(b, 128, &wlow, &wwhite);
    assert_true(wlow > 0.5 * wwhite);
    /* small masks and other sigmas work too */
    assert_int_equal(mcp_void_and_cluster(16, 1.5, 3, a), 0);
    assert_permutation(a, 256);
    assert_int_equal(mcp_void_and_cluster(32, 2.0, 3, a), 0);
    assert_permutation(a, 1024);
    free(a), free(b);
}

static void
test_mask_and_cache(void **state)
{
    (void)state;
    char dir[4096], file[4200];
    snprintf(dir, sizeof dir, "%s", mcp_test_path("cache"));
    setenv("XDG_CACHE_HOME", dir, 1);
    mcp_blue_noise_options o = mcp_blue_noise_defaults();
    o.size = 32;
    o.seed = 77;
    mcp_image *m1 = NULL, *m2 = NULL;
    assert_int_equal(mcp_blue_noise_mask(&o, &m1), 0);
    assert_int_equal(m1->width, 32);
    assert_string_equal(m1->names[0], "B");
    for (int i = 0; i < 32 * 32; i++) {
        float v = m1->data[i];
        assert_true(v > 0.0f && v < 1.0f);
        assert_close(v * 1024.0 - 0.5, floor(v * 1024.0 - 0.5 + 0.5), 0,
                     1e-3); /* (rank+.5)/n */
    }
    snprintf(file, sizeof file, "%s/mcpost/void_cluster_32_sigma1.5_seed77.exr", dir);
    mcp_image *cached = NULL;
    assert_int_equal(mcp_image_read(file, NULL, &cached), 0); /* written to the cache */
    mcp_image_free(cached);
    /* another process would read it back: same values through the cache folder */
    o.cache_dir = NULL;
    o.seed = 78; /* not in this process's memory yet, so the file is used */
    assert_int_equal(mcp_blue_noise_mask(&o, &m2), 0);
    mcp_image_free(m2);
    /* a corrupt cache file is regenerated (and rewritten) */
    o.seed = 79;
    snprintf(file, sizeof file, "%s/mcpost/void_cluster_32_sigma1.5_seed79.exr", dir);
    mcp_test_write_text(file, "not an exr");
    assert_int_equal(mcp_blue_noise_mask(&o, &m2), 0);
    assert_int_equal(mcp_image_read(file, NULL, &cached), 0);
    mcp_image_free(cached);
    int *rank = malloc(1024 * sizeof *rank);
    assert_int_equal(mcp_void_and_cluster(32, 1.5, 79, rank), 0);
    for (int i = 0; i < 1024; i++)
        assert_true(m2->data[i] == (float)((rank[i] + 0.5) / 1024));
    mcp_image_free(m2);
    /* an unusable folder means no cache, not a failure */
    o.seed = 80;
    o.cache_dir = "/proc/no/such/place";
    assert_int_equal(mcp_blue_noise_mask(&o, &m2), 0);
    mcp_image_free(m2);
    o.use_cache = 0;
    o.seed = 81;
    assert_int_equal(mcp_blue_noise_mask(&o, &m2), 0);
    mcp_image_free(m2);
    free(rank);
    mcp_image_free(m1);
    unsetenv("XDG_CACHE_HOME");
}

static void
test_errors(void **state)
{
    (void)state;
    int rank[16];
    mcp_image *m = NULL;
    assert_error_contains(mcp_void_and_cluster(3, 1.5, 1, rank),
                          "size must be in [4, 1024]");
    assert_error_contains(mcp_void_and_cluster(4, 0.0, 1, rank),
                          "sigma must be in (0, size/4]");
    assert_error_contains(mcp_void_and_cluster(8, 2.5, 1, rank), "(got 2.5)");
    mcp_blue_noise_options o = mcp_blue_noise_defaults();
    o.size = 2000;
    assert_error_contains(mcp_blue_noise_mask(&o, &m),
                          "size must be in [4, 1024] (got 2000)");
    assert_null(m);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ranks),
        cmocka_unit_test(test_mask_and_cache),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("perceptual/void_cluster", tests, NULL, NULL);
}
