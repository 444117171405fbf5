/* test_estimate_bands.c: the estimate's evaluation in bands of rows
 * (estimate/estimate_bands.c) gives the whole evaluation's maps, F(X), blocks and
 * stop, bit for bit: gauss of small and large reach (a halo wider than a band), the
 * metrics se and relse, exact and finite-difference JVPs, a dump with a colour
 * covariance (the probes drawn per pixel) and one without (rows of normals), and bands
 * of 7, 16 and 33 rows of a 64x75 render (the last band short). And the rule that picks
 * bands: only for a denoiser that states its reach, and only where the whole
 * evaluation's probes and JVPs would pass 1 GB. */
#include "testing.h"

#include <mcpost/denoiser.h>
#include <mcpost/estimate.h>
#include <math.h>
#include <procedural.h>
#include <stdlib.h>
#include <string.h>
#include "../../estimate/internal.h"

static mcp_denoiser *
gauss(const char *sigma)
{
    const char *opts[1] = {sigma};
    mcp_denoiser *d = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("gauss", opts, 1, &d), 0);
    return d;
}

static mcp_estimate *
estimate_with(const mcp_dump *d, const mcp_denoiser *den, const mcp_estimate_options *o,
              const char *rows)
{
    setenv("MCPOST_ESTIMATE_BAND_ROWS", rows, 1);
    mcp_estimate *e = NULL;
    if (mcp_estimate_compute(d, den, o, &e)) fail_msg("%s", mcp_error_message());
    unsetenv("MCPOST_ESTIMATE_BAND_ROWS");
    return e;
}

static void
test_bands_are_the_whole_estimate(void **state)
{
    (void)state;
    mcp_proc_scene scene = mcp_proc_scene_defaults();
    scene.width = 64;
    scene.height = 75;
    mcp_dump *d = NULL;
    assert_int_equal(mcp_proc_render(&scene, 8, 5, NULL, &d), 0);
    mcp_denoiser *dens[3] = {gauss("sigma=1.5"), gauss("sigma=6"),
                             NULL}; /* reach 5, 18 */
    const char *nlm_opts[2] = {"radius=3", "patch_radius=1"};
    assert_int_equal(mcp_denoiser_create_from_args("nlm", nlm_opts, 2, &dens[2]), 0);
    static const char *const rows[3] = {"7", "16", "33"};
    int runs = 0;
    for (int with_cov = 0; with_cov < 2; with_cov++) {
        if (with_cov) { /* a covariance: R and G correlated */
            assert_int_equal(mcp_image_new(64, 75, 3,
                                           (const char *const[]){"RG", "RB", "GB"},
                                           &d->cov_of_mean),
                             0);
            for (int y = 0; y < 75; y++)
                for (int x = 0; x < 64; x++) {
                    const float *v = mcp_image_px(d->var_of_mean, x, y);
                    float *c = mcp_image_px(d->cov_of_mean, x, y);
                    c[0] = 0.5f * sqrtf(v[0] * v[1]);
                    c[1] = c[2] = 0.0f;
                }
        }
        for (int di = 0; di < 3; di++)
            for (int metric = 0; metric < 2; metric++)
                for (int fd = 0; fd < 2; fd++) {
                    mcp_estimate_options o = mcp_estimate_defaults();
                    o.sure.metric = metric ? MCP_METRIC_SE : MCP_METRIC_RELSE;
                    o.sure.mc_sure = fd;
                    mcp_estimate *whole = estimate_with(d, dens[di], &o, "whole");
                    for (int r = 0; r < 3; r++) {
                        setenv("MCPOST_ESTIMATE_BAND_ROWS", rows[r], 1);
                        assert_int_equal(mcp__estimate_band_rows(64, 75, dens[di], &o, 0),
                                         atoi(rows[r])); /* bands indeed */
                        mcp_estimate *b = estimate_with(d, dens[di], &o, rows[r]);
                        const mcp_error_maps *m = &b->maps, *w = &whole->maps;
                        mcp_test_assert_same_image(m->denoised, w->denoised);
                        mcp_test_assert_same_image(m->sure, w->sure);
                        mcp_test_assert_same_image(m->sure_rel, w->sure_rel);
                        mcp_test_assert_same_image(m->var, w->var);
                        mcp_test_assert_same_image(m->var_rel, w->var_rel);
                        mcp_test_assert_same_image(m->sigma_rel, w->sigma_rel);
                        mcp_test_assert_same_image(m->denominator, w->denominator);
                        assert_true(b->cdf_at_tau == whole->cdf_at_tau);
                        assert_int_equal(b->stop, whole->stop);
                        for (int i = 0; i < b->n_percentiles; i++)
                            assert_true(b->percentile_tau[i] == whole->percentile_tau[i]);
                        mcp_estimate_free(b);
                        runs++;
                    }
                    mcp_estimate_free(whole);
                }
    }
    assert_int_equal(runs, 2 * 3 * 2 * 2 * 3);
    for (int di = 0; di < 3; di++)
        mcp_denoiser_free(dens[di]);
    mcp_dump_free(d);
}

static void
test_when_bands(void **state)
{
    (void)state;
    mcp_denoiser *g = gauss("sigma=2");
    mcp_denoiser *nlm = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("nlm", NULL, 0, &nlm), 0);
    mcp_estimate_options o = mcp_estimate_defaults();
    o.sure.n_probes = 4;
    o.probe_floor = 0;
    /* 8K: 3.2 GB of probes and JVPs whole; bands of 256 MB, less the halo (6 rows) */
    const int rows = mcp__estimate_band_rows(7680, 4320, g, &o, 0);
    assert_int_equal(rows, (int)(256.0 * 1048576.0 / (9 * 12.0 * 7680)) - 12);
    /* 4K: 0.8 GB whole, under the 1 GB that bands are for */
    assert_int_equal(mcp__estimate_band_rows(3840, 2160, g, &o, 0), 0);
    /* nlm's reach: its window (7) and patches (2), its variance prefilter (3), a row */
    assert_int_equal(nlm->band_halo, 7 + 2 + 3 + 1);
    assert_int_equal(mcp__estimate_band_rows(7680, 4320, nlm, &o, 0),
                     (int)(256.0 * 1048576.0 / (9 * 12.0 * 7680)) - 2 * 13);
    /* a denoiser of unstated reach, or maps that are not exact in bands */
    mcp_denoiser *unet = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("unet", NULL, 0, &unet), 0);
    assert_int_equal(mcp__estimate_band_rows(7680, 4320, unet, &o, 0), 0);
    mcp_denoiser_free(unet);
    mcp_estimate_options p = o;
    p.sure.metric = MCP_METRIC_RELSE_PERCEPTUAL;
    assert_int_equal(mcp__estimate_band_rows(7680, 4320, g, &p, 0), 0);
    p = o;
    p.variance_rademacher = 1;
    assert_int_equal(mcp__estimate_band_rows(7680, 4320, g, &p, 0), 0);
    p = o;
    p.probe_floor = 1;
    assert_int_equal(mcp__estimate_band_rows(7680, 4320, g, &p, 0), 0);
    mcp_denoiser_free(nlm);
    mcp_denoiser_free(g);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_bands_are_the_whole_estimate),
        cmocka_unit_test(test_when_bands),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
