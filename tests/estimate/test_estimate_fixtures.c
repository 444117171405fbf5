/* test_estimate_fixtures.c: estimate/estimate.c end to end -- the pipeline on one dump,
 * stopping over progressive series against the ground-truth stopping spp (Firmino 2024
 * Table 1), the `estimate` subcommand and job stage.
 *
 * Three sources of series:
 *  - synthetic, written here: smooth scenes with Gaussian noise of known per-pixel
 *    variance σ²/n at n = 1, 2, 4, ..., 1024 spp and the exact mean as the reference,
 *    denoised by a 3x3 box filter defined here (its bias on smooth scenes is far below
 *    the thresholds, so τ is reached by variance alone, as the paper assumes);
 *  - the committed fixtures samples/fixtures/{cornell,texture}, with the built-in
 *    `bilateral` denoiser; skipped with a message while their reference or the
 *    denoiser is missing.
 * Agreement follows Firmino 2024 §5: the estimated stopping spp is within one step
 * (adjacent member) or a third of the true one. The paper reaches 87% on 60 cases; the
 * synthetic cases must never stop early and agree in half the cases with one probe and
 * in 11 of 12 with four; the fixtures must agree in half the cases. */
#include "box_denoiser.h"
#include "testing.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include <mcpost/estimate.h>
#include <mcpost/imageio.h>

/* ---- synthetic scenes ---- */

#define S 64

typedef struct scene {
    double freq, amp, sigma_lo, sigma_hi;
} scene;

static double
scene_mu(const scene *s, int x, int y, int c)
{
    return 0.4 + 0.2 * c + s->amp * sin(s->freq * x) * cos(0.7 * s->freq * y);
}

static double
scene_sigma(const scene *s, int x, int y, int c)
{
    (void)y;
    return (x > 40 ? s->sigma_hi : s->sigma_lo) * (1.0 + 0.1 * c);
}

static mcp_dump *
scene_dump(const scene *s, int spp, uint64_t *rng)
{
    mcp_dump *d = calloc(1, sizeof *d);
    d->color = mcp_test_rgb(S, S);
    d->var_of_mean = mcp_test_rgb(S, S);
    d->spp = spp;
    d->source = strdup("synthetic");
    for (int y = 0; y < S; y++)
        for (int x = 0; x < S; x++)
            for (int c = 0; c < 3; c++) {
                double sg = scene_sigma(s, x, y, c) / sqrt((double)spp);
                mcp_image_px(d->color, x, y)[c] =
                    (float)(scene_mu(s, x, y, c) + sg * mcp_test_rand_normal(rng));
                mcp_image_px(d->var_of_mean, x, y)[c] = (float)(sg * sg);
            }
    return d;
}

static mcp_image *
scene_reference(const scene *s)
{
    mcp_image *m = mcp_test_rgb(S, S);
    for (int y = 0; y < S; y++)
        for (int x = 0; x < S; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(m, x, y)[c] = (float)scene_mu(s, x, y, c);
    return m;
}

/* ---- one dump ---- */

static void
test_pipeline_one_dump(void **state)
{
    (void)state;
    scene sc = {0.1, 0.15, 0.3, 0.9};
    uint64_t rng = 1;
    mcp_dump *d = scene_dump(&sc, 16, &rng);
    mcp_estimate_options o = mcp_estimate_defaults();
    o.budget = 12345;
    o.blocks.tile_size = 32;
    mcp_estimate *e = NULL;
    assert_int_equal(mcp_estimate_compute(d, &mcp_test_box_denoiser, &o, &e), 0);
    assert_true(e->cdf_at_tau >= 0.0 && e->cdf_at_tau <= 1.0);
    assert_int_equal(e->stop, e->cdf_at_tau >= 0.999);
    double sum = 0.0, wsum = 0.0;
    for (int i = 0; i < S * S; i++) {
        sum += e->sample_counts->data[i];
        wsum += e->sampling_map->data[i];
    }
    assert_true(sum == 12345.0);
    assert_close(wsum, 1.0, 1e-5, 0);
    for (int k = 0; k < e->n_percentiles; k++) {
        if (k) assert_true(e->percentile_tau[k] >= e->percentile_tau[k - 1]);
        if (e->percentile_tau[k] > 0) /* within the promised 1e-3 of F's root */
            assert_true(mcp_error_cdf(e->dist, e->percentile_tau[k] * (1 + 1e-3)) >=
                        e->percentiles[k]);
    }
    for (int i = 0; i < e->blocks->count; i++) /* pre-split: no block crosses a tile */
        assert_true(e->blocks->items[i].x / 32 ==
                    (e->blocks->items[i].x + e->blocks->items[i].w - 1) / 32);
    print_message("16 spp: F(0.01) = %.5f, %d blocks, p99.9 %.4g\n", e->cdf_at_tau,
                  e->blocks->count, e->percentile_tau[3]);
    mcp_estimate_free(e);
    /* a dump without any variance (1 spp): never stop */
    memset(d->var_of_mean->data, 0, (size_t)S * S * 3 * sizeof(float));
    assert_int_equal(mcp_estimate_compute(d, &mcp_test_box_denoiser, &o, &e), 0);
    assert_int_equal(e->no_variance, 1);
    assert_int_equal(e->stop, 0);
    /* every s_i is 0, so F(τ) is 1 and every percentile 0 whatever the blocks; Alg. 1
       would cut wherever SURE is above 0 (its Σ̂ are 0), so each tile is one block */
    assert_true(e->cdf_at_tau == 1.0);
    for (int k = 0; k < e->n_percentiles; k++)
        assert_true(e->percentile_tau[k] == 0.0);
    const int tiles = ((S + 31) / 32) * ((S + 31) / 32);
    assert_int_equal(e->blocks->count, tiles);
    mcp_blocks *tree = NULL;
    mcp_error_dist *tree_dist = NULL;
    assert_int_equal(
        mcp_block_average(e->maps.sure_rel, e->maps.sigma_rel, &o.blocks, &tree), 0);
    assert_true(tree->count > 4 * tiles);
    assert_int_equal(mcp_error_distribution(tree, e->maps.var_rel, &tree_dist), 0);
    assert_true(mcp_error_cdf(tree_dist, o.tau) == e->cdf_at_tau);
    double whole = 0, cut = 0; /* the one block's sums are the cut blocks' */
    for (int i = 0; i < e->blocks->count; i++)
        whole += e->blocks->items[i].sure_sum[0];
    for (int i = 0; i < tree->count; i++)
        cut += tree->items[i].sure_sum[0];
    assert_close(whole, cut, 1e-9, 1e-12);
    mcp_error_dist_free(tree_dist);
    mcp_blocks_free(tree);
    mcp_estimate_free(e);
    /* options are checked, naming the field */
    o.tau = -1;
    assert_error_contains(mcp_estimate_compute(d, &mcp_test_box_denoiser, &o, &e),
                          "estimate: tau must be > 0 (got -1)");
    o = mcp_estimate_defaults();
    o.p = 1.0;
    assert_error_contains(mcp_estimate_compute(d, &mcp_test_box_denoiser, &o, &e),
                          "estimate: percentile must be in (0, 1) (got 1)");
    mcp_dump_free(d);
}

static void
test_pipeline_thread_count_independent(void **state)
{
    (void)state;
#ifdef _OPENMP
    scene sc = {0.2, 0.3, 0.2, 0.6};
    uint64_t rng = 2;
    mcp_dump *d = scene_dump(&sc, 8, &rng);
    mcp_estimate_options o = mcp_estimate_defaults();
    o.budget = 1000;
    o.sure.n_probes = 2;
    o.variance_rademacher = 1;
    int saved = omp_get_max_threads();
    mcp_estimate *a = NULL, *b = NULL;
    omp_set_num_threads(1);
    assert_int_equal(mcp_estimate_compute(d, &mcp_test_box_denoiser, &o, &a), 0);
    omp_set_num_threads(3);
    assert_int_equal(mcp_estimate_compute(d, &mcp_test_box_denoiser, &o, &b), 0);
    omp_set_num_threads(saved);
    assert_true(a->cdf_at_tau == b->cdf_at_tau);
    assert_int_equal(a->blocks->count, b->blocks->count);
    assert_memory_equal(a->blocks->items, b->blocks->items,
                        (size_t)a->blocks->count * sizeof *a->blocks->items);
    assert_memory_equal(a->percentile_tau, b->percentile_tau, sizeof a->percentile_tau);
    assert_true(mcp_test_max_abs_diff(a->maps.sure_rel, b->maps.sure_rel) == 0.0);
    assert_true(mcp_test_max_abs_diff(a->sample_counts, b->sample_counts) == 0.0);
    mcp_estimate_free(a);
    mcp_estimate_free(b);
    mcp_dump_free(d);
#endif
}

/* ---- series against the truth ---- */

/* Runs a series with the truth (sure_groups as the option; -1 the default); counts
 * agreements, cases, and early stops that disagree (the dangerous kind: stopping
 * before the threshold is met). */
static int
run_series_groups(const mcp_series *series, const mcp_denoiser *den, const mcp_image *ref,
                  int probes, int sure_groups, const char *label, int *agree, int *cases,
                  int *early)
{
    mcp_series_estimate_options so = mcp_series_estimate_defaults();
    so.est.sure.n_probes = probes;
    so.est.sure_groups = sure_groups;
    mcp_series_estimate *s = NULL;
    if (mcp_estimate_series(series, den, &so, ref, NULL, NULL, &s)) {
        print_message("%s: %s\n", label, mcp_error_message());
        return -1;
    }
    for (int j = 0; j < s->n_taus; j++) {
        print_message("%-24s tau %-5g stop at %5g spp, true %5g spp: %s\n", label,
                      s->taus[j], s->first_spp[j], s->true_first_spp[j],
                      s->agree[j] ? "agree" : "DIFFER");
        *agree += s->agree[j];
        (*cases)++;
        if (!s->agree[j] && s->first_spp[j] > 0 &&
            (s->true_first_spp[j] == 0 || s->first_spp[j] < s->true_first_spp[j]))
            (*early)++;
    }
    mcp_series_estimate_free(s);
    return 0;
}

static int
run_series(const mcp_series *series, const mcp_denoiser *den, const mcp_image *ref,
           int probes, const char *label, int *agree, int *cases, int *early)
{
    return run_series_groups(series, den, ref, probes, -1, label, agree, cases, early);
}

static void
test_series_synthetic_agreement(void **state)
{
    (void)state;
    const scene scenes[4] = {{0.1, 0.15, 0.3, 0.9},
                             {0.05, 0.3, 0.5, 0.5},
                             {0.15, 0.1, 0.2, 1.2},
                             {0.08, 0.25, 0.6, 1.0}};
    int agree = 0, cases = 0, early = 0, agree4 = 0, cases4 = 0, early4 = 0;
    uint64_t rng = 2024;
    for (int k = 0; k < 4; k++) {
        int spps[11];
        for (int i = 0; i < 11; i++) {
            spps[i] = 1 << i;
            char name[64];
            snprintf(name, sizeof name, "syn%d_spp%04d.exr", k, spps[i]);
            mcp_dump *d = scene_dump(&scenes[k], spps[i], &rng);
            assert_int_equal(mcp_dump_write(d, mcp_test_path(name), MCP_CONV_PBRT, NULL),
                             0);
            mcp_dump_free(d);
        }
        char pattern[64], label[32];
        snprintf(pattern, sizeof pattern, "syn%d_spp%%04d.exr", k);
        mcp_series *series = NULL;
        assert_int_equal(
            mcp_series_from_pattern(mcp_test_path(pattern), spps, 11, &series), 0);
        mcp_image *ref = scene_reference(&scenes[k]);
        snprintf(label, sizeof label, "synthetic %d (box, K=1)", k);
        assert_int_equal(run_series(series, &mcp_test_box_denoiser, ref, 1, label, &agree,
                                    &cases, &early),
                         0);
        snprintf(label, sizeof label, "synthetic %d (box, K=4)", k);
        assert_int_equal(run_series(series, &mcp_test_box_denoiser, ref, 4, label,
                                    &agree4, &cases4, &early4),
                         0);
        mcp_image_free(ref);
        mcp_series_free(series);
    }
    print_message("synthetic agreement, K=1: %d of %d (%.0f%%, %d early), K=4: %d of %d "
                  "(%.0f%%, %d early); the paper: 87%%\n",
                  agree, cases, 100.0 * agree / cases, early, agree4, cases4,
                  100.0 * agree4 / cases4, early4);
    /* K = 1 (the base model, docs/mathematics.md §2.8) stops late rather than early:
     * s_i² = (Jε)_i² from one probe is itself spread like χ²_1 around the true variance,
     * which fattens the model's upper tail. So: no early misses, and at least half
     * agree; K = 4 tightens the tail: at most one miss in 12. */
    assert_int_equal(early, 0);
    assert_true(agree * 2 >= cases);
    assert_int_equal(early4, 0);
    assert_true(agree4 * 12 >= cases4 * 11);
}

static void
test_fixtures_agreement(void **state)
{
    (void)state;
    const char *scenes[2] = {"cornell", "texture"};
    mcp_denoiser *den = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("bilateral", NULL, 0, &den), 0);
    int agree = 0, cases = 0, early = 0, scenes_run = 0;
    for (int k = 0; k < 2; k++) {
        char ref_path[4096], pattern[4096];
        snprintf(ref_path, sizeof ref_path, "%s/samples/fixtures/%s/%s_reference.exr",
                 MCP_TEST_SOURCE_DIR, scenes[k], scenes[k]);
        snprintf(pattern, sizeof pattern, "%s/samples/fixtures/%s/series/%s_spp%%04d.exr",
                 MCP_TEST_SOURCE_DIR, scenes[k], scenes[k]);
        if (access(ref_path, R_OK) != 0) {
            print_message("skipped %s: no reference %s yet\n", scenes[k], ref_path);
            continue;
        }
        int spps[11];
        for (int i = 0; i < 11; i++)
            spps[i] = 1 << i;
        mcp_series *series = NULL;
        mcp_image *ref = NULL;
        assert_int_equal(mcp_series_from_pattern(pattern, spps, 11, &series), 0);
        assert_int_equal(mcp_image_read(ref_path, NULL, &ref), 0);
        char label[64];
        snprintf(label, sizeof label, "%s (bilateral)", scenes[k]);
        assert_int_equal(run_series(series, den, ref, 1, label, &agree, &cases, &early),
                         0);
        scenes_run++;
        mcp_image_free(ref);
        mcp_series_free(series);
    }
    mcp_denoiser_free(den);
    if (!scenes_run) skip();
    print_message("fixture agreement: %d of %d (%.0f%%, %d early; the paper: 87%%)\n",
                  agree, cases, 100.0 * agree / cases, early);
    assert_true(agree * 2 >= cases);
}

/* The stratified texture render (samples/fixtures/strat: Cycles, one seed, Sobol-Burley;
 * render 0 as a series of 32 to 1024 spp) with nlm: its Variance/n overstates the
 * spread of its own increments about 2x; with the variance from the increments the
 * stops agree with the truth more often than with Variance/n kept and the probes
 * drawn from it (--sure-groups 0), and with Variance/n kept but the groups on (the
 * probes then take the groups' variance from the third member) as often as with the
 * increments (docs/fidelity.md has the whole protocol); none stops early. A fixed
 * seed and one probe: these are regression figures of a measured claim (measured:
 * per-sample without the groups 2 of 3, late or never; with them 3 of 3; increments 3
 * of 3). */
static void
test_stratified_series(void **state)
{
    (void)state;
    char ref_path[4096], pattern[4096];
    snprintf(ref_path, sizeof ref_path,
             "%s/samples/fixtures/strat/texture/texture_reference.exr",
             MCP_TEST_SOURCE_DIR);
    snprintf(pattern, sizeof pattern,
             "%s/samples/fixtures/strat/texture/series/texture_spp%%04d.exr",
             MCP_TEST_SOURCE_DIR);
    const int spps[6] = {32, 64, 128, 256, 512, 1024};
    mcp_series *series = NULL;
    mcp_image *ref = NULL;
    mcp_denoiser *den = NULL;
    assert_int_equal(mcp_series_from_pattern(pattern, spps, 6, &series), 0);
    assert_int_equal(mcp_image_read(ref_path, NULL, &ref), 0);
    assert_int_equal(mcp_denoiser_create_from_args("nlm", NULL, 0, &den), 0);
    int agree_own = 0, agree_plain = 0, agree_incr = 0, cases = 0, early = 0;
    series->variance_from = MCP_SERIES_VARIANCE_FILE;
    assert_int_equal(run_series_groups(series, den, ref, 1, 0, "texture, per-sample",
                                       &agree_plain, &cases, &early),
                     0);
    assert_int_equal(run_series(series, den, ref, 1, "texture, per-sample, groups",
                                &agree_own, &cases, &early),
                     0);
    series->variance_from = MCP_SERIES_VARIANCE_INCREMENTS;
    assert_int_equal(run_series(series, den, ref, 1, "texture, increments", &agree_incr,
                                &cases, &early),
                     0);
    series->variance_from = MCP_SERIES_VARIANCE_AUTO; /* the default picks them itself */
    mcp_series_estimate_options so = mcp_series_estimate_defaults();
    so.n_taus = 1;
    mcp_series_estimate *s = NULL;
    assert_int_equal(mcp_estimate_series(series, den, &so, NULL, NULL, NULL, &s), 0);
    print_message("stratified texture: Variance/n over the increments' spread %.3f; "
                  "agreement per-sample %d (with the groups %d), increments %d of 3, %d "
                  "early\n",
                  s->variance_ratio, agree_plain, agree_own, agree_incr, early);
    assert_int_equal(s->variance_source, MCP_VARSRC_INCREMENTS);
    assert_true(s->variance_ratio > 1.7 && s->variance_ratio < 2.3);
    assert_int_equal(early, 0);
    assert_true(agree_incr >= 2 && agree_incr > agree_plain);
    assert_true(agree_own >= 2 && agree_own > agree_plain);
    mcp_series_estimate_free(s);
    mcp_denoiser_free(den);
    mcp_image_free(ref);
    mcp_series_free(series);
}

/* ---- the subcommand and the job stage ---- */

static char out[1 << 16], err[1 << 16];

#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

/* Skips while `mcpost estimate` or the `gauss` denoiser is not built in. */
static void
need_cli(int status)
{
    if (status != 0 && status != 10 &&
        (strstr(err, "unknown command") || strstr(err, "unknown subcommand") ||
         strstr(err, "unknown denoiser") || strstr(err, "unknown stage"))) {
        print_message("skipped: %s", err);
        skip();
    }
}

static void
test_cli_single_and_series(void **state)
{
    (void)state;
    scene sc = {0.1, 0.15, 0.3, 0.9};
    uint64_t rng = 5;
    int spps[4] = {4, 16, 64, 256};
    for (int i = 0; i < 4; i++) {
        char name[64];
        snprintf(name, sizeof name, "cli_spp%04d.exr", spps[i]);
        mcp_dump *d = scene_dump(&sc, spps[i], &rng);
        assert_int_equal(mcp_dump_write(d, mcp_test_path(name), MCP_CONV_PBRT, NULL), 0);
        mcp_dump_free(d);
    }
    mcp_image *ref = scene_reference(&sc);
    assert_int_equal(mcp_image_write(ref, mcp_test_path("cli_ref.exr"), NULL), 0);
    mcp_image_free(ref);
    int st =
        run("estimate '%s' --denoiser gauss -o '%s' --budget 5000 --json --exit-status "
            "--tau 0.05",
            mcp_test_path("cli_spp0064.exr"), mcp_test_path("cli_out"));
    need_cli(st);
    if (st != 0 && st != 10) fail_msg("status %d: %s", st, err);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    int stop = cJSON_IsTrue(cJSON_GetObjectItem(j, "stop"));
    assert_int_equal(st, stop ? 0 : 10);
    assert_true(cJSON_GetObjectItem(j, "cdf_at_tau")->valuedouble >= 0.0);
    int blocks = cJSON_GetObjectItem(j, "blocks")->valueint;
    cJSON_Delete(j);
    const char *files[] = {"denoised.exr",     "sure.exr",         "sure_rel.exr",
                           "variance.exr",     "sampling_map.exr", "sample_counts.exr",
                           "distribution.exr", "estimate.json",    "report.html",
                           "denoised.png",     "sampling_map.png", "blocks_error.png"};
    for (size_t i = 0; i < sizeof files / sizeof *files; i++) {
        char p[256];
        snprintf(p, sizeof p, "cli_out/%s", files[i]);
        assert_int_equal(access(mcp_test_path(p), R_OK), 0);
    }
    /* blocks.png only when there are blocks to tell apart (one is a flat square) */
    assert_int_equal(access(mcp_test_path("cli_out/blocks.png"), R_OK) == 0, blocks > 1);
    mcp_image *counts = NULL;
    assert_int_equal(
        mcp_image_read(mcp_test_path("cli_out/sample_counts.exr"), NULL, &counts), 0);
    double sum = 0.0;
    for (int i = 0; i < counts->width * counts->height; i++)
        sum += counts->data[i];
    assert_true(sum == 5000.0);
    mcp_image_free(counts);
    /* a series with the truth */
    st = run(
        "estimate --series '%s' --spp 4,16,64,256 --denoiser gauss --ref '%s' -o '%s' "
        "--taus 0.05,0.01",
        mcp_test_path("cli_spp%04d.exr"), mcp_test_path("cli_ref.exr"),
        mcp_test_path("cli_series"));
    if (st != 0) fail_msg("status %d: %s", st, err);
    assert_non_null(strstr(out, "agreement:"));
    char *text = mcp_test_read_text(mcp_test_path("cli_series/estimate.json"));
    j = cJSON_Parse(text);
    assert_non_null(j);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(j, "members")), 4);
    assert_non_null(cJSON_GetObjectItem(j, "agreement_rate"));
    cJSON_Delete(j);
    free(text);
    /* usage and bad values */
    /* no --denoiser: the default -- nlm for this dump, which has no albedo and normal
       (said once), the U-Net with the shipped weights for a render that has them */
    st = run("estimate '%s'", mcp_test_path("cli_spp0064.exr"));
    assert_int_equal(st, 0);
    assert_non_null(strstr(out, "denoiser:    default (nlm)"));
    assert_non_null(strstr(err, "the default denoiser is nlm instead of the U-Net"));
    st = run("estimate '%s/samples/fixtures/cornell/series/cornell_spp0064.exr'",
             MCP_TEST_SOURCE_DIR);
    assert_int_equal(st, 0);
    assert_non_null(strstr(out, "denoiser:    default (unet)"));
    st = run("estimate '%s' --denoiser gauss --metric mse",
             mcp_test_path("cli_spp0064.exr"));
    assert_int_equal(st, 1);
    assert_non_null(strstr(err, "mcpost: unknown metric 'mse'"));
    st = run("estimate '%s' --denoiser gauss --probes 0",
             mcp_test_path("cli_spp0064.exr"));
    assert_int_equal(st, 1);
    assert_non_null(
        strstr(err, "--probes must be auto or a number in [1, 1024] (got 0)"));
    /* the probe count is the denoiser's (docs/fidelity.md "The defaults"): 3 for the
       U-Net, whose tangents cost over half an apply, 4 for the others; the default
       denoiser's is that of the one it runs (the U-Net on a dump with albedo and
       normal, nlm on one without); the automatic estimate is the explicit one, to
       the bit */
    char features[4200], plain[4200];
    snprintf(features, sizeof features,
             "%s/samples/fixtures/strat/texture/series/texture_spp0032.exr",
             MCP_TEST_SOURCE_DIR);
    snprintf(plain, sizeof plain, "%s", mcp_test_path("cli_spp0064.exr"));
    const struct {
        const char *denoiser, *dump;
        int probes;
    } auto_probes[] = {{"gauss", features, 4},
                       {"unet", features, 3},
                       {"default", features, 3},
                       {"default", plain, 4}};
    for (int i = 0; i < 4; i++) {
        double cdf[2];
        for (int explicit_k = 0; explicit_k < 2; explicit_k++) {
            char probes[32] = "";
            if (explicit_k)
                snprintf(probes, sizeof probes, "--probes %d", auto_probes[i].probes);
            st = run("estimate '%s' --denoiser %s %s --json", auto_probes[i].dump,
                     auto_probes[i].denoiser, probes);
            assert_int_equal(st, 0);
            cJSON *j = cJSON_Parse(out);
            assert_non_null(j);
            assert_int_equal(cJSON_GetObjectItem(j, "probes")->valueint,
                             auto_probes[i].probes);
            cdf[explicit_k] = cJSON_GetObjectItem(j, "cdf_at_tau")->valuedouble;
            cJSON_Delete(j);
        }
        assert_true(cdf[0] == cdf[1]);
    }
}

static void
test_job_stage(void **state)
{
    (void)state;
    scene sc = {0.1, 0.15, 0.3, 0.9};
    uint64_t rng = 6;
    for (int i = 0; i < 3; i++) {
        char name[64];
        snprintf(name, sizeof name, "job_spp%04d.exr", 8 << (2 * i));
        mcp_dump *d = scene_dump(&sc, 8 << (2 * i), &rng);
        assert_int_equal(mcp_dump_write(d, mcp_test_path(name), MCP_CONV_PBRT, NULL), 0);
        mcp_dump_free(d);
    }
    mcp_image *ref = scene_reference(&sc);
    assert_int_equal(mcp_image_write(ref, mcp_test_path("job_ref.exr"), NULL), 0);
    mcp_image_free(ref);
    mcp_test_write_text(
        mcp_test_path("estimate.yaml"),
        "inputs:\n"
        "  noisy: {dump: job_spp0032.exr}\n"
        "  progress: {series: job_spp%04d.exr, spp: [8, 32, 128]}\n"
        "  truth: {image: job_ref.exr}\n"
        "output: job_out\n"
        "stages:\n"
        "  - estimate: {input: noisy, denoiser: {name: gauss}, tau: 0.02,\n"
        "               budget: 4096, probes: 2, output: one, reference: truth,\n"
        "               s2_pool: auto}\n"
        "  - estimate: {input: progress, denoiser: gauss, reference: truth,\n"
        "               taus: [0.05, 0.02], output: series}\n");
    int st = run("run '%s' --quiet", mcp_test_path("estimate.yaml"));
    need_cli(st);
    if (st != 0) fail_msg("status %d: %s", st, err);
    assert_int_equal(access(mcp_test_path("job_out/one/sample_counts.exr"), R_OK), 0);
    assert_int_equal(access(mcp_test_path("job_out/series/estimate.json"), R_OK), 0);
    char *report = mcp_test_read_text(mcp_test_path("job_out/report.json"));
    assert_non_null(strstr(report, "\"stage\":\t\"estimate\""));
    free(report);
    /* one dump with reference: the true percentiles, the same as `mcpost estimate
       --ref` gives for the same dump and settings */
    char *text = mcp_test_read_text(mcp_test_path("job_out/one/estimate.json"));
    cJSON *job_json = cJSON_Parse(text);
    free(text);
    const cJSON *job_truth = cJSON_GetObjectItem(job_json, "true_percentiles");
    assert_non_null(job_truth);
    st = run("estimate '%s' --denoiser gauss --tau 0.02 --probes 2 --ref '%s' --json",
             mcp_test_path("job_spp0032.exr"), mcp_test_path("job_ref.exr"));
    assert_int_equal(st, 0);
    cJSON *cli_json = cJSON_Parse(out);
    const cJSON *cli_truth = cJSON_GetObjectItem(cli_json, "true_percentiles");
    assert_non_null(cli_truth);
    assert_int_equal(cJSON_GetArraySize(job_truth), 5);
    for (int k = 0; k < 5; k++)
        assert_true(cJSON_GetArrayItem(job_truth, k)->valuedouble ==
                    cJSON_GetArrayItem(cli_truth, k)->valuedouble);
    cJSON_Delete(job_json);
    cJSON_Delete(cli_json);
    /* an unknown key names the line */
    mcp_test_write_text(mcp_test_path("bad.yaml"),
                        "inputs:\n"
                        "  noisy: {dump: job_spp0032.exr}\n"
                        "stages:\n"
                        "  - estimate: {input: noisy, denoiser: gauss, probs: 2}\n");
    st = run("run '%s' --quiet", mcp_test_path("bad.yaml"));
    assert_int_equal(st, 1);
    assert_non_null(strstr(err, "bad.yaml:4"));
    assert_non_null(strstr(err, "probs"));
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pipeline_one_dump),
        cmocka_unit_test(test_pipeline_thread_count_independent),
        cmocka_unit_test(test_series_synthetic_agreement),
        cmocka_unit_test(test_fixtures_agreement),
        cmocka_unit_test(test_stratified_series),
        cmocka_unit_test(test_cli_single_and_series),
        cmocka_unit_test(test_job_stage),
    };
    return cmocka_run_group_tests_name("estimate/estimate", tests, NULL, NULL);
}
