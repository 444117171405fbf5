/* test_series.c: blend/series.c -- the driver on the fixture series (Cornell box and
 * texture, 1..1024 spp, Blender renders) against their 16384-spp references: the curve
 * blend converges and beats both inputs from 16 spp (docs/mathematics.md §3; Denisova &
 * Bocchi 2024 Fig. 4), denoising that stops early, retrospective curves, the errors of
 * bad series, and the driver through `mcpost blend` and the `blend` job stage. */
#include "blend_testing.h"

#include <mcpost/imageio.h>

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

#define FIXTURES MCP_TEST_SOURCE_DIR "/samples/fixtures"
#define N_SPP 11 /* 1, 2, 4, ..., 1024 */

static const char *const SCENES[2] = {"cornell", "texture"};

/* The built-in denoiser of the fixture tests. */
static mcp_denoiser *
fixture_denoiser(void)
{
    mcp_denoiser *den = NULL;
    if (mcp_denoiser_create_from_args("gauss", NULL, 0, &den))
        fail_msg("%s", mcp_error_message());
    return den;
}

/* The fixture series of a scene and its reference; skips when they are not there. */
static int
load_fixture(const char *scene, mcp_series **series, mcp_image **ref)
{
    char pattern[1024], ref_path[1024];
    snprintf(pattern, sizeof pattern, FIXTURES "/%s/series/%s_spp%%04d.exr", scene,
             scene);
    snprintf(ref_path, sizeof ref_path, FIXTURES "/%s/%s_reference.exr", scene, scene);
    struct stat st;
    if (stat(ref_path, &st) != 0) return -1;
    int spps[N_SPP];
    for (int i = 0; i < N_SPP; i++)
        spps[i] = 1 << i;
    assert_int_equal(mcp_series_from_pattern(pattern, spps, N_SPP, series), 0);
    assert_int_equal(mcp_image_read(ref_path, NULL, ref), 0);
    return 0;
}

static void
print_table(const char *title, const mcp_blend_series_result *r)
{
    printf(
        "  %s\n     spp    I'  filt  mag    W/(I+W)   MSE noisy   denoised   easy       "
        "curves     ideal      james-stein  FLIP noisy curves\n",
        title);
    for (int i = 0; i < r->count; i++) {
        const mcp_blend_row *w = &r->rows[i];
        printf("  %6g %5g  %d     %d     %.3f     ", w->spp, w->denoised_spp, w->filtered,
               w->magnitude, w->mean_rho);
        for (int m = 0; m < MCP_BLEND_N_METHODS; m++)
            printf(" %.3e", w->err[m].mse);
        printf("   %.4f %.4f\n", w->err[MCP_BLEND_NOISY].flip_hdr,
               w->err[MCP_BLEND_CURVES].flip_hdr);
    }
}

/* How a curve blend did against the better input from 16 spp on. */
typedef struct {
    int points, wins; /* points from 16 spp; where curves <= min(noisy, denoised) */
    double worst;     /* largest curves / min(noisy, denoised) there */
    double top_noisy; /* curves / noisy at the highest spp */
    double top_den;   /* curves / denoised there */
} blend_score;

static blend_score
score(const mcp_blend_series_result *r)
{
    blend_score sc = {0, 0, 0, 0, 0};
    for (int i = 0; i < r->count; i++) {
        const mcp_blend_row *w = &r->rows[i];
        if (w->spp < 16) continue;
        double best = fmin(w->err[MCP_BLEND_NOISY].mse, w->err[MCP_BLEND_DENOISED].mse);
        double c = w->err[MCP_BLEND_CURVES].mse;
        sc.points++;
        sc.wins += c <= best;
        sc.worst = fmax(sc.worst, c / best);
    }
    const mcp_blend_row *top = &r->rows[r->count - 1];
    sc.top_noisy = top->err[MCP_BLEND_CURVES].mse / top->err[MCP_BLEND_NOISY].mse;
    sc.top_den = top->err[MCP_BLEND_CURVES].mse / top->err[MCP_BLEND_DENOISED].mse;
    return sc;
}

static void
test_fixtures_converge(void **state)
{
    (void)state;
    mcp_denoiser *den = fixture_denoiser();
    const mcp_curve_fit fits[3] = {MCP_CURVE_FIT_ON_THE_FLY, MCP_CURVE_FIT_LAST_TWO,
                                   MCP_CURVE_FIT_RETROSPECTIVE};
    for (int s = 0; s < 2; s++) {
        mcp_series *series = NULL;
        mcp_image *ref = NULL;
        if (load_fixture(SCENES[s], &series, &ref)) {
            printf("  %s: fixtures missing, skipped\n", SCENES[s]);
            continue;
        }
        for (int f = 0; f < 3; f++) {
            mcp_blend_series_options o = mcp_blend_series_defaults();
            o.blend.fit = fits[f];
            mcp_blend_series_result *r = NULL;
            char title[128];
            snprintf(title, sizeof title, "%s, gauss, %s", SCENES[s],
                     mcp_curve_fit_name(fits[f]));
            assert_int_equal(mcp_blend_series(series, den, ref, &o, NULL, NULL, &r), 0);
            print_table(title, r);
            assert_int_equal(r->count, N_SPP);
            assert_true(r->has_reference && r->has_flip);
            blend_score sc = score(r);
            printf("  %s: from 16 spp curves <= min(noisy, denoised) at %d of %d, worst "
                   "%.3fx; at %g spp curves/noisy %.3f, curves/denoised %.4f\n",
                   title, sc.wins, sc.points, sc.worst, r->rows[r->count - 1].spp,
                   sc.top_noisy, sc.top_den);
            /* the gauss denoiser is biased: far worse than noisy at the top */
            assert_true(sc.top_den < 0.5);
            if (fits[f] == MCP_CURVE_FIT_ON_THE_FLY) {
                /* The on-the-fly curve (§3.1) has slope -2 (Eq. 11): W / I = sqrt(v /
                 * SURE), and where d is biased (B^2 >> v) the blend's error tends to
                 * (1 - rho)^2 v + rho^2 B^2 ~ 2 v (test_weights.c). It converges at the
                 * noisy image's rate but may stay up to twice above it; on the texture
                 * scene, biased almost everywhere, it ends 1.5x above. */
                assert_true(sc.worst <= 2.0 && sc.top_noisy <= 2.0);
                assert_true(r->rows[4].err[MCP_BLEND_CURVES].mse <=
                            fmin(r->rows[4].err[MCP_BLEND_NOISY].mse,
                                 r->rows[4].err[MCP_BLEND_DENOISED].mse));
            } else {
                /* The paper's curves (the last two kept points; all points): from 16
                 * spp the blend is at most the better input at >= 80% of the points
                 * and never more than 10% above it; at the highest spp it has
                 * converged to the noisy image (at most 10% above it). */
                assert_true(sc.wins >= 0.8 * sc.points);
                assert_true(sc.worst <= 1.1);
                assert_true(sc.top_noisy <= 1.1);
            }
            mcp_blend_series_result_free(r);
        }
        mcp_image_free(ref);
        mcp_series_free(series);
    }
    mcp_denoiser_free(den);
}

/* The other built-in denoisers are better than the noisy image even at 1024 spp on
 * these small scenes; the blend then trades a little of d's advantage for convergence.
 * Figures are printed; the assertion is convergence: never above the noisy image. */
static void
test_fixtures_other_denoisers(void **state)
{
    (void)state;
    const char *names[2] = {"nlm", "bilateral"};
    const mcp_curve_fit fits[2] = {MCP_CURVE_FIT_ON_THE_FLY, MCP_CURVE_FIT_LAST_TWO};
    for (int s = 0; s < 2; s++) {
        mcp_series *series = NULL;
        mcp_image *ref = NULL;
        if (load_fixture(SCENES[s], &series, &ref)) continue;
        for (int d = 0; d < 2; d++) {
            mcp_denoiser *den = NULL;
            assert_int_equal(mcp_denoiser_create_from_args(names[d], NULL, 0, &den), 0);
            for (int f = 0; f < 2; f++) {
                mcp_blend_series_options o = mcp_blend_series_defaults();
                o.blend.fit = fits[f];
                o.flip = 0;
                mcp_blend_series_result *r = NULL;
                assert_int_equal(mcp_blend_series(series, den, ref, &o, NULL, NULL, &r),
                                 0);
                blend_score sc = score(r);
                printf("  %s, %s, %s: from 16 spp wins %d of %d, worst %.3fx the better; "
                       "at %g spp curves/noisy %.3f, curves/denoised %.3f\n",
                       SCENES[s], names[d], mcp_curve_fit_name(fits[f]), sc.wins,
                       sc.points, sc.worst, r->rows[r->count - 1].spp, sc.top_noisy,
                       sc.top_den);
                for (int i = 4; i < r->count; i++)
                    assert_true(r->rows[i].err[MCP_BLEND_CURVES].mse <=
                                r->rows[i].err[MCP_BLEND_NOISY].mse);
                mcp_blend_series_result_free(r);
            }
            mcp_denoiser_free(den);
        }
        mcp_image_free(ref);
        mcp_series_free(series);
    }
}

/* A callback that checks what the driver hands over. */
typedef struct {
    int calls;
    double last_spp;
    int fail_at; /* -1: never */
} point_check;

static int
check_point(const mcp_blend_point *p, void *ctx)
{
    point_check *c = ctx;
    c->calls++;
    assert_int_equal(p->index, c->calls - 1);
    assert_true(p->row->spp > c->last_spp);
    c->last_spp = p->row->spp;
    for (int m = 0; m < MCP_BLEND_N_METHODS; m++)
        assert_true(m == MCP_BLEND_IDEAL ? p->images[m] != NULL || !p->ideal_weights
                                         : p->images[m] != NULL);
    assert_non_null(p->weights);
    assert_non_null(p->est);
    assert_non_null(p->source);
    if (p->index == c->fail_at) return mcp_error("callback says stop at %d", p->index);
    return 0;
}

static void
test_stop_denoising_and_retrospective(void **state)
{
    (void)state;
    mcp_series *series = NULL;
    mcp_image *ref = NULL;
    if (load_fixture("cornell", &series, &ref)) skip();
    mcp_denoiser *den = fixture_denoiser();
    mcp_blend_series_options o = mcp_blend_series_defaults();
    o.stop_denoising_at = 64;
    mcp_blend_series_result *r = NULL;
    point_check pc = {0, 0, -1};
    assert_int_equal(mcp_blend_series(series, den, ref, &o, check_point, &pc, &r), 0);
    print_table("cornell, denoising stopped at 64 spp", r);
    assert_int_equal(pc.calls, N_SPP);
    for (int i = 0; i < r->count; i++) {
        const mcp_blend_row *w = &r->rows[i];
        assert_true(w->denoised_spp == fmin(w->spp, 64));
        /* a stopped denoiser's error stays put */
        if (w->spp > 64)
            assert_true(w->err[MCP_BLEND_DENOISED].mse ==
                        r->rows[6].err[MCP_BLEND_DENOISED].mse);
    }
    /* v keeps falling while SURE(I') stays: W / I falls as 1 / sqrt(I) and the blend
     * goes on converging with the noisy image, though more slowly (here within 30%
     * of it at 1024 spp, against a denoised image 80x worse). */
    const mcp_blend_row *top = &r->rows[r->count - 1];
    assert_true(top->err[MCP_BLEND_CURVES].mse <= 1.3 * top->err[MCP_BLEND_NOISY].mse);
    assert_true(top->err[MCP_BLEND_CURVES].mse < 0.1 * top->err[MCP_BLEND_DENOISED].mse);
    mcp_blend_series_result_free(r);

    /* retrospective curves over all members: the same guarantees from 16 spp */
    o = mcp_blend_series_defaults();
    o.blend.fit = MCP_CURVE_FIT_RETROSPECTIVE;
    o.flip = 0;
    assert_int_equal(mcp_blend_series(series, den, ref, &o, NULL, NULL, &r), 0);
    print_table("cornell, retrospective curves", r);
    assert_true(!r->has_flip && isnan(r->rows[0].err[MCP_BLEND_CURVES].flip_hdr));
    for (int i = 4; i < r->count; i++) {
        const mcp_blend_row *w = &r->rows[i];
        double best = fmin(w->err[MCP_BLEND_NOISY].mse, w->err[MCP_BLEND_DENOISED].mse);
        assert_true(w->err[MCP_BLEND_CURVES].mse <= 1.1 * best);
    }
    mcp_blend_series_result_free(r);

    /* without a reference: no errors, no ideal image; the callback can stop the run */
    pc = (point_check){0, 0, 2};
    assert_error_contains(mcp_blend_series(series, den, NULL, NULL, check_point, &pc, &r),
                          "callback says stop at 2");
    assert_null(r);
    assert_int_equal(pc.calls, 3);
    mcp_denoiser_free(den);
    mcp_image_free(ref);
    mcp_series_free(series);
}

static void
test_bad_series(void **state)
{
    (void)state;
    mcp_series *series = NULL;
    mcp_image *ref = NULL;
    if (load_fixture("cornell", &series, &ref)) skip();
    mcp_denoiser *den = fixture_denoiser();
    mcp_blend_series_result *r = NULL;
    /* members out of order */
    const char *paths[2] = {series->paths[3], series->paths[2]};
    mcp_series *rev = NULL;
    assert_int_equal(mcp_series_from_paths(paths, NULL, 2, &rev), 0);
    assert_error_contains(mcp_blend_series(rev, den, NULL, NULL, NULL, NULL, &r),
                          "spp 4 does not increase (the member before has 8)");
    mcp_series_free(rev);
    /* a member without variance: the reference file */
    const char *nov[1] = {FIXTURES "/cornell/cornell_reference.exr"};
    assert_int_equal(mcp_series_from_paths(nov, NULL, 1, &rev), 0);
    assert_error_contains(mcp_blend_series(rev, den, NULL, NULL, NULL, NULL, &r),
                          "cornell_reference.exr has no variance");
    mcp_series_free(rev);
    /* a reference of another size */
    mcp_image *small = rgb_constant(16, 16, 0.5f);
    assert_error_contains(mcp_blend_series(series, den, small, NULL, NULL, NULL, &r),
                          "does not match the reference's size");
    /* no denoiser; bad options */
    assert_error_contains(mcp_blend_series(series, NULL, ref, NULL, NULL, NULL, &r),
                          "a denoiser is required");
    mcp_blend_series_options o = mcp_blend_series_defaults();
    o.stop_denoising_at = -1;
    assert_error_contains(mcp_blend_series(series, den, ref, &o, NULL, NULL, &r),
                          "stop_denoising_at must be finite and >= 0 (got -1)");
    o = mcp_blend_series_defaults();
    o.blend.far_spp = 100;
    assert_error_contains(mcp_blend_series(series, den, ref, &o, NULL, NULL, &r),
                          "far_spp (100) must be larger than the newest spp (128)");
    assert_null(r);
    mcp_image_free(small);
    mcp_denoiser_free(den);
    mcp_image_free(ref);
    mcp_series_free(series);
}

static void
test_driver_options(void **state)
{
    (void)state;
    mcp_series *series = NULL;
    mcp_image *ref = NULL;
    if (load_fixture("cornell", &series, &ref)) skip();
    mcp_denoiser *den = fixture_denoiser();
    /* v and SURE through the denoiser, the authors' power law, magnitude throughout */
    mcp_blend_series_options o = mcp_blend_series_defaults();
    o.blend.filter = MCP_BLEND_FILTER_DENOISER;
    o.blend.curve = MCP_CURVE_POWERLAW;
    o.blend.negative_sure = MCP_NEG_SURE_MAGNITUDE;
    o.flip = 0;
    mcp_blend_series_result *r = NULL;
    assert_int_equal(mcp_blend_series(series, den, ref, &o, NULL, NULL, &r), 0);
    print_table("cornell, denoiser-filtered estimates, power law", r);
    for (int i = 0; i < r->count; i++) {
        const mcp_blend_row *w = &r->rows[i];
        assert_true(w->magnitude);
        /* filtered until mean v < mean SURE (after the 1-spp member, which has no v) */
        assert_int_equal(w->filtered, !(w->mean_var > 0 && w->mean_var < w->mean_sure) &&
                                          (i == 0 || r->rows[i - 1].filtered));
        if (w->spp >= 16) {
            double best =
                fmin(w->err[MCP_BLEND_NOISY].mse, w->err[MCP_BLEND_DENOISED].mse);
            assert_true(w->err[MCP_BLEND_CURVES].mse <= 1.1 * best);
        }
    }
    mcp_blend_series_result_free(r);
    mcp_denoiser_free(den);
    mcp_image_free(ref);
    mcp_series_free(series);
}

/* ---- through the command line and a job ---- */

static int
file_exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

static void
test_cli_and_job(void **state)
{
    (void)state;
    struct stat st;
    if (stat(FIXTURES "/cornell/cornell_reference.exr", &st) != 0) skip();
    static char out[1 << 16], err[1 << 16];
    char args[8192], path[4200];
    const char *dir = mcp_test_path("cli");
    snprintf(args, sizeof args,
             "blend '" FIXTURES "/cornell/series/cornell_spp%%04d.exr' --spp 4,16,64 "
             "--denoiser gauss --ref '" FIXTURES "/cornell/cornell_reference.exr' "
             "-o '%s' --quiet --all-images",
             dir);
    int rc = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    if (rc != 0) fail_msg("mcpost blend: %d: %s", rc, err);
    const char *files[] = {"cornell_spp0004.blend.exr",
                           "cornell_spp0064.weights.exr",
                           "cornell_spp0016.curves.exr", /* the other weights' blend */
                           "cornell_spp0064.ideal.exr",
                           "cornell_spp0064.james_stein.png", /* the blend, shown */
                           "blend.json",
                           "report.html"};
    for (int i = 0; i < 7; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, files[i]);
        if (!file_exists(path)) fail_msg("missing %s", path);
    }
    snprintf(path, sizeof path, "%s/blend.json", dir);
    char *text = mcp_test_read_text(path);
    cJSON *j = cJSON_Parse(text);
    assert_non_null(j);
    assert_int_equal(cJSON_GetObjectItem(j, "members")->valueint, 3);
    cJSON *fin = cJSON_GetObjectItem(j, "final");
    assert_non_null(cJSON_GetObjectItem(cJSON_GetObjectItem(fin, "curves"), "flip_hdr"));
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(j, "plots")), 3);
    cJSON_Delete(j);
    free(text);
    /* the weight map is what the blend used: r = (I n + W d) / (I + W) */
    mcp_image *w = NULL, *blend = NULL;
    snprintf(path, sizeof path, "%s/cornell_spp0064.weights.exr", dir);
    assert_int_equal(mcp_image_read(path, NULL, &w), 0);
    snprintf(path, sizeof path, "%s/cornell_spp0064.blend.exr", dir);
    assert_int_equal(mcp_image_read(path, NULL, &blend), 0);
    assert_int_equal(w->channels, 3);
    assert_true(mcp_image_same_size(w, blend));
    mcp_image_free(w);
    mcp_image_free(blend);

    /* usage errors */
    /* no --denoiser is no usage error (the default denoiser): the missing file is */
    rc = mcp_test_run_mcpost("blend x.exr", out, sizeof out, err, sizeof err);
    assert_int_equal(rc, 1);
    assert_non_null(strstr(err, "x.exr"));
    rc = mcp_test_run_mcpost("blend a.exr b.exr --spp 1,2 --denoiser gauss", out,
                             sizeof out, err, sizeof err);
    assert_int_equal(rc, 2);
    rc = mcp_test_run_mcpost("blend x_%04d.exr --spp 1,2 --denoiser gauss --curve cubic",
                             out, sizeof out, err, sizeof err);
    assert_int_equal(rc, 1);
    assert_non_null(strstr(err, "unknown curve 'cubic'"));

    /* the job stage, with an unknown key reported at its line */
    char job_dir[4200], job[4096], job_path[4200];
    snprintf(job_dir, sizeof job_dir, "%s", mcp_test_path("job"));
    snprintf(job, sizeof job,
             "inputs:\n"
             "  progress: {series: " FIXTURES "/cornell/series/cornell_spp%%04d.exr, "
             "spp: [8, 32, 128]}\n"
             "  reference: {image: " FIXTURES "/cornell/cornell_reference.exr}\n"
             "output: %s/out\n"
             "stages:\n"
             "  - blend:\n"
             "      input: progress\n"
             "      denoiser: gauss\n"
             "      reference: reference\n"
             "      stop_denoising_at: 32\n"
             "      curve: powerlaw\n"
             "      flip: false\n",
             job_dir);
    snprintf(job_path, sizeof job_path, "%s", mcp_test_path("blend.yaml"));
    mcp_test_write_text(job_path, job);
    snprintf(args, sizeof args, "run '%s' --quiet", job_path);
    rc = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    if (rc != 0) fail_msg("mcpost run: %d: %s", rc, err);
    snprintf(path, sizeof path, "%s/out/blend/cornell_spp0128.blend.exr", job_dir);
    assert_true(file_exists(path));
    snprintf(path, sizeof path, "%s/out/report.json", job_dir);
    text = mcp_test_read_text(path);
    assert_non_null(strstr(text, "\"curve\":\t\"powerlaw\""));
    free(text);
    mcp_test_write_text(job_path,
                        "inputs:\n"
                        "  p: {series: " FIXTURES "/cornell/series/cornell_spp%04d.exr,"
                        " spp: [1]}\n"
                        "stages:\n"
                        "  - blend: {input: p, denoiser: gauss, curvature: 1}\n");
    snprintf(args, sizeof args, "run '%s' --quiet", job_path);
    rc = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    assert_int_equal(rc, 1);
    assert_non_null(strstr(err, "blend.yaml:4"));
    assert_non_null(strstr(err, "unknown key 'curvature'"));
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fixtures_converge),
        cmocka_unit_test(test_fixtures_other_denoisers),
        cmocka_unit_test(test_stop_denoising_and_retrospective),
        cmocka_unit_test(test_driver_options),
        cmocka_unit_test(test_bad_series),
        cmocka_unit_test(test_cli_and_job),
    };
    return cmocka_run_group_tests_name("blend/series", tests, NULL, NULL);
}
