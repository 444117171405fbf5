/* test_replicates.c: variance of the mean from replicates, from the increments of a
 * progressive series, and its pooling -- against closed forms, against one render of
 * all the samples, and (Monte Carlo, fixed seeds) against the procedural renderer's
 * exact per-sample variance. */
#include "testing.h"

#include <mcpost/dump.h>
#include <mcpost/stats.h>
#include <math.h>
#include <procedural.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "../../common/dump/internal.h"

/* The procedural scene at 24x24 without fireflies, with the independent sampler or the
 * jittered one (4x4 strata per pass of 16 samples): what the series tests render. */
static mcp_proc_scene
small_scene(int jittered)
{
    mcp_proc_scene scene = mcp_proc_scene_defaults();
    scene.width = scene.height = 24;
    scene.firefly_probability = 0;
    if (jittered) {
        scene.sampler = MCP_PROC_SAMPLER_JITTERED;
        scene.strata = 4;
    }
    return scene;
}

static const char *const rgb[3] = {"R", "G", "B"};

/* A dump of constant colour (r, g, b) with spp samples and no variance. */
static mcp_dump *
constant_dump(int w, int h, const float v[3], double spp)
{
    mcp_dump *d = calloc(1, sizeof *d);
    d->color = mcp_test_constant(w, h, 3, 0, rgb);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            memcpy(mcp_image_px(d->color, x, y), v, 3 * sizeof(float));
    d->spp = spp;
    d->source = strdup("made");
    return d;
}

/* Three replicates of unequal sizes: mean Σ n_k X_k / N and the spread
 * Σ n_k (X_k - X)² / ((K - 1) N), worked by hand. */
static void
test_merge_replicates_closed_form(void **state)
{
    (void)state;
    const float v[3][3] = {{1, 0, 2}, {2, 1, 2}, {4, 3, 2}};
    const double n[3] = {10, 10, 20};
    mcp_dump *parts[3];
    for (int k = 0; k < 3; k++)
        parts[k] = constant_dump(5, 4, v[k], n[k]);
    mcp_dump *m = NULL;
    assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, 3, NULL, &m), 0);
    assert_true(m->spp == 40);
    assert_int_equal(m->variance_source, MCP_VARSRC_REPLICATES);
    assert_true(m->variance_dof == 2);
    assert_int_equal(m->replicates, 3);
    const float *x = mcp_image_px(m->color, 2, 3),
                *var = mcp_image_px(m->var_of_mean, 2, 3),
                *cov = mcp_image_px(m->cov_of_mean, 2, 3);
    /* R: mean (10 + 20 + 80) / 40 = 2.75; spread (10·1.75² + 10·0.75² + 20·1.25²) / 80 */
    assert_close(x[0], 2.75, 1e-7, 0);
    assert_close(var[0], 67.5 / 80, 1e-7, 0);
    /* G: mean (0 + 10 + 60) / 40 = 1.75; deviations -1.75, -0.75, 1.25 */
    assert_close(x[1], 1.75, 1e-7, 0);
    assert_close(var[1], 67.5 / 80, 1e-7, 0);
    /* B is the same everywhere: no spread; RG: the same deviations as RR */
    assert_close(var[2], 0, 0, 1e-12);
    assert_close(cov[0], 67.5 / 80, 1e-7, 0);
    assert_close(cov[1], 0, 0, 1e-12);
    mcp_dump_free(m);
    for (int k = 0; k < 3; k++)
        mcp_dump_free(parts[k]);
}

/* Passes of one render merged with `pooled` give what one render of all the samples
 * reports: the mean and the unbiased per-sample variance over all of them, / N. */
static void
test_merge_pooled_is_one_render(void **state)
{
    (void)state;
    enum { W = 7, H = 3, PASSES = 4 };
    const int n[PASSES] = {1, 5, 8, 18};
    double sum[W * H * 3] = {0}, sum2[W * H * 3] = {0};
    mcp_dump *parts[PASSES];
    uint64_t rng = 42;
    for (int k = 0; k < PASSES; k++) {
        mcp_dump *d = calloc(1, sizeof *d);
        d->color = mcp_test_constant(W, H, 3, 0, rgb);
        d->var_of_mean = mcp_test_constant(W, H, 3, 0, rgb);
        d->spp = n[k];
        d->source = strdup("pass");
        d->variance_source = MCP_VARSRC_PER_SAMPLE;
        for (int i = 0; i < W * H * 3; i++) {
            double s = 0, s2 = 0;
            for (int j = 0; j < n[k]; j++) {
                double t = 1 + (i % 3) + (1 + i % 5) * mcp_test_rand_normal(&rng);
                s += t, s2 += t * t;
            }
            sum[i] += s, sum2[i] += s2;
            double mean = s / n[k];
            d->color->data[i] = (float)mean;
            d->var_of_mean->data[i] =
                n[k] > 1 ? (float)((s2 - n[k] * mean * mean) / (n[k] - 1) / n[k]) : 0.0f;
        }
        parts[k] = d;
    }
    mcp_merge_options opt = mcp_merge_defaults();
    opt.variance = MCP_MERGE_POOLED;
    mcp_dump *m = NULL;
    assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, PASSES, &opt, &m), 0);
    assert_true(m->spp == 32);
    assert_int_equal(m->variance_source, MCP_VARSRC_PER_SAMPLE);
    for (int i = 0; i < W * H * 3; i++) {
        double N = 32, mean = sum[i] / N;
        double var = (sum2[i] - N * mean * mean) / (N - 1) / N;
        /* float parts: a few ulp of the values */
        assert_close(m->color->data[i], mean, 2e-6, 1e-6);
        assert_close(m->var_of_mean->data[i], var, 2e-5, 1e-7);
    }
    mcp_dump_free(m);
    for (int k = 0; k < PASSES; k++)
        mcp_dump_free(parts[k]);
}

/* Monte Carlo over fixed seeds on the procedural renderer (independent sampler, no
 * fireflies): the replicates' variance of the mean is unbiased for the exact
 * per-sample variance / N, at K = 2, 4 and 8. */
static void
test_merge_replicates_unbiased(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(0);
    mcp_image *truth_mean = NULL, *truth_var = NULL;
    assert_int_equal(mcp_proc_truth(&scene, &truth_mean, &truth_var), 0);
    const int ks[3] = {2, 4, 8};
    for (int t = 0; t < 3; t++) {
        int K = ks[t], spp = 4, trials = 96 / K;
        double est = 0, truth = 0;
        for (int trial = 0; trial < trials; trial++) {
            mcp_dump *parts[8];
            for (int k = 0; k < K; k++)
                assert_int_equal(
                    mcp_proc_render(&scene, spp,
                                    mcp_proc_realization_seed(7 + 1000 * trial, k + 1),
                                    NULL, &parts[k]),
                    0);
            mcp_dump *m = NULL;
            assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, K, NULL, &m),
                             0);
            for (int i = 0; i < scene.width * scene.height * 3; i++) {
                est += m->var_of_mean->data[i];
                truth += truth_var->data[i] / (K * spp);
            }
            mcp_dump_free(m);
            for (int k = 0; k < K; k++)
                mcp_dump_free(parts[k]);
        }
        /* 96 / K trials x 1728 values with K - 1 dof each: the image-mean ratio has a
           relative standard error near sqrt(2 / (96 / K (K - 1) 1728)) × (spread of
           the variances) < 1.5%; 5% is > 3 SE */
        assert_close(est / truth, 1.0, 0.05, 0);
    }
    mcp_image_free(truth_mean);
    mcp_image_free(truth_var);
}

/* Pooling: a variance that is c times the shape comes back exactly; without a shape,
 * the window mean clipped at the borders. */
static void
test_pool_variance(void **state)
{
    (void)state;
    mcp_dump *d = calloc(1, sizeof *d);
    d->source = strdup("made");
    d->color = mcp_test_constant(9, 6, 3, 1, rgb);
    mcp_image *shape = mcp_test_random(9, 6, 3, 0.1f, 2.0f, 5, rgb);
    assert_int_equal(mcp_image_copy(shape, &d->var_of_mean), 0);
    for (int i = 0; i < 9 * 6 * 3; i++)
        d->var_of_mean->data[i] *= (i % 3 + 1) * 0.5f;
    assert_int_equal(mcp_dump_pool_variance(d, shape, 2), 0);
    for (int i = 0; i < 9 * 6 * 3; i++)
        assert_close(d->var_of_mean->data[i], shape->data[i] * (i % 3 + 1) * 0.5, 1e-6,
                     0);
    assert_true(d->variance_pool == 25);
    /* the covariance: the window's correlation times the pooled deviations. With a
       constant shape s and V = k_c s, a constant covariance c0 stays c0:
       (n c0 / (n s sqrt(k_a k_b))) sqrt(k_a s k_b s) */
    mcp_image *flat = mcp_test_constant(9, 6, 3, 0.5f, rgb);
    for (int i = 0; i < 9 * 6 * 3; i++)
        d->var_of_mean->data[i] = 0.5f * (float)(i % 3 + 1);
    d->cov_of_mean =
        mcp_test_constant(9, 6, 3, 0.125f, (const char *[]){"RG", "RB", "GB"});
    assert_int_equal(mcp_dump_pool_variance(d, flat, 2), 0);
    for (int i = 0; i < 9 * 6 * 3; i++)
        assert_close(d->cov_of_mean->data[i], 0.125, 1e-6, 0);
    mcp_image_free(flat);
    /* no shape: one value of 25 at (0, 0) spreads over the 3x3 window cells that
       see it, each window clipped at the corner */
    memset(d->var_of_mean->data, 0, 9 * 6 * 3 * sizeof(float));
    mcp_image_px(d->var_of_mean, 0, 0)[1] = 36;
    assert_int_equal(mcp_dump_pool_variance(d, NULL, 1), 0);
    assert_close(mcp_image_px(d->var_of_mean, 0, 0)[1], 36.0 / 4, 1e-7, 0);
    assert_close(mcp_image_px(d->var_of_mean, 1, 0)[1], 36.0 / 6, 1e-7, 0);
    assert_close(mcp_image_px(d->var_of_mean, 1, 1)[1], 36.0 / 9, 1e-7, 0);
    assert_close(mcp_image_px(d->var_of_mean, 2, 0)[1], 0, 0, 0);
    assert_int_equal(mcp_variance_pool_radius(3, 100), 3); /* 7x7: 147 >= 100 */
    assert_int_equal(mcp_variance_pool_radius(200, 100), 0);
    assert_int_equal(mcp_variance_pool_radius(1, 100), 5); /* 11x11 */
    mcp_image_free(shape);
    mcp_dump_free(d);
}

/* The degrees of freedom that pooling claims: K = 4 replicates of Gaussian noise of
 * known variance give a variance with 3 dof (relative spread sqrt(2/3) = 0.816 per
 * value); pooled over 7x7 the spread of an interior value falls to sqrt(2/(3·49)) =
 * 0.117, and the mean stays unbiased. */
static void
test_pool_degrees_of_freedom(void **state)
{
    (void)state;
    enum { W = 96, H = 96, K = 4 };
    const double sigma2 = 0.25; /* per-sample variance; 16 spp per replicate */
    mcp_dump *parts[K];
    uint64_t rng = 7;
    for (int k = 0; k < K; k++) {
        parts[k] = calloc(1, sizeof *parts[k]);
        parts[k]->color = mcp_test_constant(W, H, 3, 0, rgb);
        parts[k]->spp = 16;
        parts[k]->source = strdup("noise");
        for (int i = 0; i < W * H * 3; i++)
            parts[k]->color->data[i] =
                (float)(1.0 + sqrt(sigma2 / 16) * mcp_test_rand_normal(&rng));
    }
    mcp_dump *m = NULL;
    assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, K, NULL, &m), 0);
    const double truth = sigma2 / (16 * K);
    double spread[2];
    for (int pass = 0; pass < 2; pass++) {
        /* pass 0: raw; pass 1: pooled 7x7. Interior values only (full windows). */
        if (pass == 1) assert_int_equal(mcp_dump_pool_variance(m, NULL, 3), 0);
        double s = 0, s2 = 0;
        long n = 0;
        for (int y = 3; y < H - 3; y++)
            for (int x = 3; x < W - 3; x++)
                for (int c = 0; c < 3; c++) {
                    double r = mcp_image_px(m->var_of_mean, x, y)[c] / truth;
                    s += r, s2 += r * r, n++;
                }
        double mean = s / n;
        spread[pass] = sqrt(s2 / n - mean * mean);
        /* 24k values: the mean to about 0.5% raw, less pooled */
        assert_close(mean, 1.0, 0.03, 0);
    }
    print_message("relative spread of the variance: raw %.3f (sqrt(2/3) = 0.816), pooled "
                  "7x7 %.3f (sqrt(2/147) = 0.117)\n",
                  spread[0], spread[1]);
    assert_close(spread[0], sqrt(2.0 / 3.0), 0.05, 0);
    assert_close(spread[1], sqrt(2.0 / 147.0), 0.08, 0);
    mcp_dump_free(m);
    for (int k = 0; k < K; k++)
        mcp_dump_free(parts[k]);
}

/* Writes the nested series spp[0..count) of one procedural render to files. */
static mcp_series *
procedural_series(const mcp_proc_scene *scene, const int *spp, int count, uint64_t seed,
                  const char *stem)
{
    char **paths = calloc((size_t)count, sizeof *paths);
    for (int i = 0; i < count; i++) {
        mcp_dump *d = NULL;
        assert_int_equal(mcp_proc_render(scene, spp[i], seed, NULL, &d), 0);
        char name[64];
        snprintf(name, sizeof name, "%s_%04d.exr", stem, spp[i]);
        paths[i] = strdup(mcp_test_path(name));
        assert_int_equal(mcp_dump_write(d, paths[i], MCP_CONV_PBRT, NULL), 0);
        mcp_dump_free(d);
    }
    mcp_series *s = NULL;
    assert_int_equal(mcp_series_from_paths((const char *const *)paths, NULL, count, &s),
                     0);
    for (int i = 0; i < count; i++)
        free(paths[i]);
    free(paths);
    return s;
}

/* Increments of an independent-sample render: unbiased for the exact variance of the
 * mean (Monte Carlo over seeds), and the renderer's own Variance/n agrees with them
 * (ratio near 1). */
static void
test_increments_independent(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(0);
    mcp_image *truth_mean = NULL, *truth_var = NULL;
    assert_int_equal(mcp_proc_truth(&scene, &truth_mean, &truth_var), 0);
    const int spp[5] = {4, 8, 12, 16, 20};
    double est = 0, truth = 0, ratio_sum = 0;
    const int trials = 12;
    mcp_increment_options opt = mcp_increment_defaults();
    opt.pool_radius = -1; /* the raw estimate: unbiased per value */
    for (int trial = 0; trial < trials; trial++) {
        mcp_series *s = procedural_series(&scene, spp, 5, 100 + trial, "inc");
        mcp_dump *d = NULL;
        double ratio = 0;
        assert_int_equal(mcp_series_increment_variance(s, 4, &opt, &d, &ratio), 0);
        assert_int_equal(d->variance_source, MCP_VARSRC_INCREMENTS);
        assert_true(d->variance_dof == 4);
        for (int i = 0; i < scene.width * scene.height * 3; i++) {
            est += d->var_of_mean->data[i];
            truth += truth_var->data[i] / 20;
        }
        ratio_sum += ratio;
        mcp_dump_free(d);
        mcp_series_free(s);
    }
    /* 12 trials x 1728 values x 4 dof: a few percent at most */
    assert_close(est / truth, 1.0, 0.05, 0);
    assert_close(ratio_sum / trials, 1.0, 0.05, 0);
    /* the member with the fewest blocks that still has two: member 1 (4 and 4 more) */
    mcp_series *s = procedural_series(&scene, spp, 2, 5, "inc2");
    mcp_dump *d = NULL;
    opt.first_spp = 1;
    assert_int_equal(mcp_series_increment_variance(s, 1, &opt, &d, NULL), 0);
    assert_true(d->variance_dof == 1);
    mcp_dump_free(d);
    assert_error_contains(mcp_series_increment_variance(s, 0, &opt, &d, NULL),
                          "needs two blocks");
    assert_null(d);
    mcp_series_free(s);
    mcp_image_free(truth_mean);
    mcp_image_free(truth_var);
}

/* The series' increments, read member by member, are the bits of the increments of the
 * members held at once (mcp_dump_increment_variance), for every member; and where the
 * series gives the counts, members below the first block's count are not read at all:
 * with the first member's file gone, the last member's increments are the same. */
static void
test_increments_streamed(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(0);
    enum { N = 6 };
    const int spp[N] = {1, 2, 4, 8, 16, 128};
    mcp_series *s = procedural_series(&scene, spp, N, 77, "stream");
    mcp_dump *members[N];
    for (int k = 0; k < N; k++) {
        mcp_dump_spec spec = mcp_dump_spec_defaults();
        spec.path = s->paths[k];
        assert_int_equal(mcp_dump_load(&spec, &members[k]), 0);
    }
    mcp_increment_options opt = mcp_increment_defaults();
    mcp_dump *whole[N] = {0};
    for (int i = 1; i < N; i++) {
        mcp_dump *read = NULL;
        double r_read = -1, r_whole = -2;
        assert_int_equal(mcp_series_increment_variance(s, i, &opt, &read, &r_read), 0);
        assert_int_equal(mcp_dump_increment_variance((const mcp_dump *const *)members,
                                                     i + 1, &opt, &whole[i], &r_whole),
                         0);
        assert_true(r_read == r_whole);
        assert_true(read->variance_dof == whole[i]->variance_dof);
        const size_t n = (size_t)scene.width * scene.height * 3;
        assert_memory_equal(read->var_of_mean->data, whole[i]->var_of_mean->data,
                            n * sizeof(float));
        assert_memory_equal(read->cov_of_mean->data, whole[i]->cov_of_mean->data,
                            n * sizeof(float));
        mcp_dump_free(read);
    }
    /* 128 spp: the first block starts at 2 spp, so the 1-spp member is not needed */
    assert_true(whole[N - 1]->variance_dof == N - 2);
    const double counts[N] = {1, 2, 4, 8, 16, 128};
    mcp_series *given = NULL;
    assert_int_equal(
        mcp_series_from_paths((const char *const *)s->paths, counts, N, &given), 0);
    assert_int_equal(remove(s->paths[0]), 0);
    mcp_dump *read = NULL;
    assert_int_equal(mcp_series_increment_variance(given, N - 1, &opt, &read, NULL), 0);
    assert_memory_equal(read->var_of_mean->data, whole[N - 1]->var_of_mean->data,
                        (size_t)scene.width * scene.height * 3 * sizeof(float));
    mcp_dump_free(read);
    mcp_series_free(given);
    for (int k = 0; k < N; k++) {
        mcp_dump_free(members[k]);
        mcp_dump_free(whole[k]);
    }
    mcp_series_free(s);
}

/* The members' colours are kept for the next member's increments (series_colours.c):
 * read again they are the same bits, and a kept member is not read from its file
 * again. With the files of the two members before the last overwritten, the last
 * member's increments are the same where all colours were kept and where a budget of
 * two colours kept those two (the lower ones were dropped first); with no budget the
 * files are read again, and the overwritten one fails. */
static void
test_increments_kept(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(0);
    enum { N = 6 };
    const int spp[N] = {1, 2, 4, 8, 16, 32};
    mcp_series *all = procedural_series(&scene, spp, N, 31, "kept");
    mcp_series *two = NULL, *none = NULL;
    assert_int_equal(
        mcp_series_from_paths((const char *const *)all->paths, NULL, N, &two), 0);
    assert_int_equal(
        mcp_series_from_paths((const char *const *)all->paths, NULL, N, &none), 0);
    const size_t colour = (size_t)scene.width * scene.height * 3 * sizeof(float);
    mcp__series_colours_budget(two, 2 * colour);
    mcp__series_colours_budget(none, 0);
    mcp_increment_options opt = mcp_increment_defaults();
    mcp_dump *truth = NULL, *d = NULL;
    assert_int_equal(mcp_series_increment_variance(all, N - 1, &opt, &truth, NULL), 0);
    mcp_series *each[3] = {all, two, none};
    for (int j = 0; j < 3; j++) {
        assert_int_equal(mcp_series_increment_variance(each[j], N - 1, &opt, &d, NULL),
                         0);
        assert_memory_equal(d->var_of_mean->data, truth->var_of_mean->data, colour);
        assert_memory_equal(d->cov_of_mean->data, truth->cov_of_mean->data, colour);
        mcp_dump_free(d);
    }
    for (int k = N - 3; k < N - 1; k++)
        mcp_test_write_text(all->paths[k], "not an EXR");
    for (int j = 0; j < 2; j++) {
        if (mcp_series_increment_variance(each[j], N - 1, &opt, &d, NULL))
            fail_msg("%d: %s", j, mcp_error_message());
        assert_memory_equal(d->var_of_mean->data, truth->var_of_mean->data, colour);
        mcp_dump_free(d);
    }
    assert_error_contains(mcp_series_increment_variance(none, N - 1, &opt, &d, NULL),
                          "kept_0008.exr");
    assert_null(d);
    mcp_dump_free(truth);
    mcp_series_free(none);
    mcp_series_free(two);
    mcp_series_free(all);
}

/* A member read without its albedo and normal (a blend or series estimate whose
 * denoiser reads neither, mcp__series_load_without) has the colour and variance of the
 * member read whole, bit for bit, whatever the series' variance_from. */
static void
test_series_load_without(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(1); /* stratified: auto takes the increments */
    enum { N = 4 };
    const int spp[N] = {16, 32, 48, 64};
    mcp_series *s = procedural_series(&scene, spp, N, 41, "without");
    const size_t n = (size_t)scene.width * scene.height * 3 * sizeof(float);
    const mcp_series_variance from[3] = {MCP_SERIES_VARIANCE_FILE,
                                         MCP_SERIES_VARIANCE_INCREMENTS,
                                         MCP_SERIES_VARIANCE_AUTO};
    for (int f = 0; f < 3; f++) {
        s->variance_from = from[f];
        for (int i = 0; i < N; i++) {
            mcp_dump *whole = NULL, *part = NULL;
            assert_int_equal(mcp_series_load(s, i, &whole), 0);
            assert_int_equal(mcp__series_load_without(
                                 s, i, MCP__DUMP_NO_ALBEDO | MCP__DUMP_NO_NORMAL, &part),
                             0);
            assert_non_null(whole->albedo);
            assert_null(part->albedo);
            assert_null(part->normal);
            assert_int_equal(part->variance_source, whole->variance_source);
            assert_memory_equal(part->color->data, whole->color->data, n);
            assert_memory_equal(part->var_of_mean->data, whole->var_of_mean->data, n);
            mcp_dump_free(whole);
            mcp_dump_free(part);
        }
    }
    mcp_series_free(s);
}

/* The same on a stratified render (the procedural renderer's jittered sampler, 4x4
 * strata per pass of 16 samples, no fireflies), against its exact variance of the
 * mean: the renderer's Variance/n overstates it, the increments between passes and
 * the spread of independent renders do not. */
static void
test_stratified_sources(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(1);
    mcp_image *v64 = NULL, *v16 = NULL;
    assert_int_equal(mcp_proc_truth_var_of_mean(&scene, 64, &v64), 0);
    assert_int_equal(mcp_proc_truth_var_of_mean(&scene, 16, &v16), 0);
    const int spp[4] = {16, 32, 48, 64};
    const int n = scene.width * scene.height * 3, trials = 12;
    double truth64 = 0, truth16 = 0, incr = 0, own = 0, rep = 0, ratio_sum = 0;
    for (int i = 0; i < n; i++)
        truth64 += v64->data[i], truth16 += v16->data[i];
    mcp_increment_options opt = mcp_increment_defaults();
    opt.pool_radius = -1;
    for (int trial = 0; trial < trials; trial++) {
        mcp_series *s = procedural_series(&scene, spp, 4, 300 + trial, "strat");
        mcp_dump *d = NULL, *last = NULL;
        double ratio = 0;
        assert_int_equal(mcp_series_increment_variance(s, 3, &opt, &d, &ratio), 0);
        s->variance_from = MCP_SERIES_VARIANCE_FILE; /* the render's own Variance/n */
        assert_int_equal(mcp_series_load(s, 3, &last), 0);
        for (int i = 0; i < n; i++)
            incr += d->var_of_mean->data[i], own += last->var_of_mean->data[i];
        ratio_sum += ratio;
        mcp_dump_free(d);
        mcp_dump_free(last);
        mcp_series_free(s);
        /* four independent 16-spp renders, merged */
        mcp_dump *parts[4], *m = NULL;
        for (int k = 0; k < 4; k++)
            assert_int_equal(
                mcp_proc_render(&scene, 16, mcp_proc_realization_seed(900 + trial, k + 1),
                                NULL, &parts[k]),
                0);
        assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, 4, NULL, &m), 0);
        for (int i = 0; i < n; i++)
            rep += m->var_of_mean->data[i];
        mcp_dump_free(m);
        for (int k = 0; k < 4; k++)
            mcp_dump_free(parts[k]);
    }
    incr /= trials, own /= trials, rep /= trials;
    print_message("stratified, image sums over the exact variance of the mean: "
                  "increments %.3f, replicates %.3f, Variance/n %.3f (ratio %.3f)\n",
                  incr / truth64, rep / (truth16 / 4), own / truth64, ratio_sum / trials);
    /* 12 trials x 1728 values x 3 dof: a few percent; Variance/n is well above */
    assert_close(incr / truth64, 1.0, 0.06, 0);
    assert_close(rep / (truth16 / 4), 1.0, 0.06, 0);
    assert_true(own / truth64 > 1.15);
    assert_true(ratio_sum / trials > 1.15);
    mcp_image_free(v64);
    mcp_image_free(v16);
}

/* The source travels through a file: merged, written, read back. */
static void
test_source_roundtrip(void **state)
{
    (void)state;
    const float v[2][3] = {{1, 2, 3}, {2, 2, 5}};
    mcp_dump *parts[2] = {constant_dump(4, 4, v[0], 8), constant_dump(4, 4, v[1], 8)};
    mcp_dump *m = NULL, *back = NULL;
    assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, 2, NULL, &m), 0);
    const char *path = mcp_test_path("merged.exr");
    assert_int_equal(mcp_dump_write(m, path, MCP_CONV_AUTO, NULL), 0);
    assert_int_equal(mcp_dump_read(path, &back), 0);
    assert_int_equal(back->variance_source, MCP_VARSRC_REPLICATES);
    assert_true(back->variance_dof == 1);
    assert_int_equal(back->replicates, 2);
    assert_true(back->spp == 16);
    /* (8·0.5² + 8·0.5²) / (1 · 16) = 0.25 */
    assert_close(mcp_image_px(back->var_of_mean, 1, 1)[0], 0.25, 1e-6, 0);
    assert_close(mcp_image_px(back->var_of_mean, 1, 1)[2], 1.0, 1e-6, 0);
    assert_string_equal(mcp_variance_source_name(back->variance_source), "replicates");
    mcp_dump_free(back);
    mcp_dump_free(m);
    for (int k = 0; k < 2; k++)
        mcp_dump_free(parts[k]);
}

static void
test_merge_errors(void **state)
{
    (void)state;
    const float v[3] = {1, 1, 1};
    mcp_dump *a = constant_dump(4, 4, v, 8), *b = constant_dump(5, 4, v, 8), *m = NULL;
    const mcp_dump *one[1] = {a}, *two[2] = {a, b}, *same[2] = {a, a};
    assert_error_contains(mcp_dump_merge(one, 1, NULL, &m), "at least 2");
    assert_error_contains(mcp_dump_merge(two, 2, NULL, &m), "is 5x4");
    mcp_merge_options pooled = {MCP_MERGE_POOLED, 0};
    assert_error_contains(mcp_dump_merge(same, 2, &pooled, &m), "no variance");
    assert_null(m);
    mcp_merge_variance kind;
    assert_error_contains(mcp_merge_variance_from_name("spread", &kind), "unknown");
    mcp_dump_free(a);
    mcp_dump_free(b);
}

/* The default choice (MCP_SERIES_VARIANCE_AUTO): a stratified series (the jittered
 * sampler: Variance/n about 1.5x the truth) takes its increments' variance from the
 * second block on; an independent one keeps its per-sample variance (ratio near 1);
 * the first member always keeps its own; `file` and `increments` force either. */
static void
test_series_variance_auto(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(0);
    const int spp[4] = {16, 32, 48, 64};
    mcp_series *indep = procedural_series(&scene, spp, 4, 41, "auto_iid");
    scene = small_scene(1);
    mcp_series *strat = procedural_series(&scene, spp, 4, 42, "auto_strat");
    assert_int_equal(strat->variance_from, MCP_SERIES_VARIANCE_AUTO);
    static const struct {
        int stratified;
        mcp_series_variance from;
        mcp_variance_source first, last;
    } cases[] = {
        {1, MCP_SERIES_VARIANCE_AUTO, MCP_VARSRC_PER_SAMPLE, MCP_VARSRC_INCREMENTS},
        {0, MCP_SERIES_VARIANCE_AUTO, MCP_VARSRC_PER_SAMPLE, MCP_VARSRC_PER_SAMPLE},
        {1, MCP_SERIES_VARIANCE_FILE, MCP_VARSRC_PER_SAMPLE, MCP_VARSRC_PER_SAMPLE},
        {0, MCP_SERIES_VARIANCE_INCREMENTS, MCP_VARSRC_PER_SAMPLE, MCP_VARSRC_INCREMENTS},
    };
    for (size_t c = 0; c < sizeof cases / sizeof *cases; c++) {
        mcp_series *s = cases[c].stratified ? strat : indep;
        s->variance_from = cases[c].from;
        mcp_dump *first = NULL, *last = NULL, *incr = NULL;
        assert_int_equal(mcp_series_load(s, 0, &first), 0);
        assert_int_equal(mcp_series_load(s, 3, &last), 0);
        assert_int_equal(first->variance_source, cases[c].first);
        assert_int_equal(last->variance_source, cases[c].last);
        if (cases[c].last == MCP_VARSRC_INCREMENTS) { /* the same as asked directly */
            assert_int_equal(
                mcp_series_increment_variance(s, 3, &s->increments, &incr, NULL), 0);
            assert_true(mcp_test_max_abs_diff(incr->var_of_mean, last->var_of_mean) == 0);
        }
        double ratio = 0;
        assert_int_equal(mcp_series_variance_ratio(s, &ratio), 0);
        assert_int_equal(mcp_variance_ratio_off(ratio), cases[c].stratified);
        mcp_dump_free(first);
        mcp_dump_free(last);
        mcp_dump_free(incr);
    }
    assert_int_equal(mcp_variance_ratio_off(0), 0);
    assert_int_equal(mcp_variance_ratio_off(1.26), 1);
    assert_int_equal(mcp_variance_ratio_off(0.79), 1);
    assert_int_equal(mcp_variance_ratio_off(1.0), 0);
    mcp_series_variance v;
    assert_int_equal(mcp_series_variance_from_name("increments", &v), 0);
    assert_int_equal(v, MCP_SERIES_VARIANCE_INCREMENTS);
    assert_string_equal(mcp_series_variance_name(MCP_SERIES_VARIANCE_AUTO), "auto");
    assert_error_contains(mcp_series_variance_from_name("spread", &v),
                          "variance_from must be auto, file or increments");
    mcp_series_free(indep);
    mcp_series_free(strat);
}

/* Pooling a variance that is zero beside very large values (a black region next to a
 * firefly, as the held-out `window` fixture has at 32 spp): the table's differences
 * must not turn the zeros negative, which the error distribution refuses; every value
 * is the naive window mean (in double) to the table's rounding. */
static void
test_pool_window_beside_large_values(void **state)
{
    (void)state;
    const int w = 40, h = 30;
    static const char *const names[3] = {"R", "G", "B"};
    for (int radius = 1; radius <= 3; radius++) {
        mcp_image *img = mcp_test_constant(w, h, 3, 0, names), *orig = NULL;
        uint64_t st = 77;
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w / 2; x++) /* the left half: values over many scales */
                for (int c = 0; c < 3; c++)
                    mcp_image_px(img, x, y)[c] =
                        (float)(exp(20 * mcp_test_rand_uniform(&st) - 8));
        mcp_image_px(img, 5, 5)[0] = 3e9f;
        assert_int_equal(mcp_image_copy(img, &orig), 0);
        assert_int_equal(mcp_pool_window(img, NULL, radius), 0);
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++)
                for (int c = 0; c < 3; c++) {
                    double sum = 0;
                    int n = 0;
                    for (int j = y - radius; j <= y + radius; j++)
                        for (int i = x - radius; i <= x + radius; i++)
                            if (i >= 0 && j >= 0 && i < w && j < h)
                                sum += mcp_image_px(orig, i, j)[c], n++;
                    float got = mcp_image_px(img, x, y)[c];
                    assert_true(got >= 0);
                    /* the table's sums reach ~1e12: rounding ~1e-4 absolute */
                    assert_close(got, sum / n, 1e-6, 1e-3);
                }
        mcp_image_free(img);
        mcp_image_free(orig);
    }
}

/* A series whose files hold no variance (a plain Cycles render's checkpoints): by
 * default every member takes its variance from the increments, the first one the
 * per-sample spread of the first two blocks scaled to its count; unbiased for the
 * exact variance of the mean (independent samples, Monte Carlo over 12 renders). */
static void
test_series_without_variance(void **state)
{
    (void)state;
    mcp_proc_scene scene = small_scene(0);
    mcp_image *truth_mean = NULL, *truth_var = NULL;
    assert_int_equal(mcp_proc_truth(&scene, &truth_mean, &truth_var), 0);
    const int spp[3] = {8, 16, 32};
    const int n = scene.width * scene.height * 3, trials = 12;
    double est[3] = {0, 0, 0}, truth = 0;
    for (int i = 0; i < n; i++)
        truth += truth_var->data[i];
    for (int t = 0; t < trials; t++) {
        mcp_series *s = procedural_series(&scene, spp, 3, 500 + t, "novar");
        s->increments.pool_radius = -1; /* the raw estimate: unbiased per value */
        for (int i = 0; i < 3; i++) {   /* the files without their variance */
            mcp_dump *d = NULL;
            assert_int_equal(mcp_dump_read(s->paths[i], &d), 0);
            mcp_image_free(d->var_of_mean);
            mcp_image_free(d->cov_of_mean);
            d->var_of_mean = d->cov_of_mean = NULL;
            d->variance_source = MCP_VARSRC_NONE;
            assert_int_equal(mcp_dump_write(d, s->paths[i], MCP_CONV_MCPOST, NULL), 0);
            mcp_dump_free(d);
        }
        for (int i = 0; i < 3; i++) {
            mcp_dump *d = NULL;
            assert_int_equal(mcp_series_load(s, i, &d), 0);
            assert_non_null(d->var_of_mean);
            assert_int_equal(d->variance_source, MCP_VARSRC_INCREMENTS);
            for (int k = 0; k < n; k++)
                est[i] += d->var_of_mean->data[k] * spp[i]; /* per sample */
            mcp_dump_free(d);
        }
        s->variance_from = MCP_SERIES_VARIANCE_FILE; /* file: no variance at all */
        mcp_dump *d = NULL;
        assert_int_equal(mcp_series_load(s, 1, &d), 0);
        assert_null(d->var_of_mean);
        mcp_dump_free(d);
        mcp_series_free(s);
    }
    print_message(
        "no variance in the files: the increments' per-sample variance over the "
        "truth %.3f, %.3f, %.3f\n",
        est[0] / trials / truth, est[1] / trials / truth, est[2] / trials / truth);
    /* 1-2 dof per value over 12 x 1728 values: a few percent */
    for (int i = 0; i < 3; i++)
        assert_close(est[i] / trials / truth, 1.0, 0.05, 0);
    mcp_image_free(truth_mean);
    mcp_image_free(truth_var);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_merge_replicates_closed_form),
        cmocka_unit_test(test_merge_pooled_is_one_render),
        cmocka_unit_test(test_merge_replicates_unbiased),
        cmocka_unit_test(test_pool_variance),
        cmocka_unit_test(test_pool_degrees_of_freedom),
        cmocka_unit_test(test_increments_independent),
        cmocka_unit_test(test_increments_streamed),
        cmocka_unit_test(test_series_load_without),
        cmocka_unit_test(test_stratified_sources),
        cmocka_unit_test(test_increments_kept),
        cmocka_unit_test(test_series_variance_auto),
        cmocka_unit_test(test_pool_window_beside_large_values),
        cmocka_unit_test(test_series_without_variance),
        cmocka_unit_test(test_source_roundtrip),
        cmocka_unit_test(test_merge_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
