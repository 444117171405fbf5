/* test_demo_job.c: README's main command, samples/jobs/demo.yaml, end to end on the
 * Blender fixtures: every module's stage runs, in order, and the figures it reports
 * hold up -- the metrics stage's MSE equals the MSE recomputed here from the two files,
 * the converging blend at 1024 spp is at least as good as the noisy image, and the
 * perceptual optimisation lowers pMSE below the candidates' mean, with its energy
 * falling. */
#include "testing.h"

#include <mcpost/dump.h>
#include <mcpost/imageio.h>

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const cJSON *
item(const cJSON *o, const char *key)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!v) fail_msg("report.json: no '%s'", key);
    return v;
}

static double
number(const cJSON *o, const char *key)
{
    const cJSON *v = item(o, key);
    assert_true(cJSON_IsNumber(v));
    return v->valuedouble;
}

/* Plain MSE over R, G, B of a dump's colour against the reference image. */
static double
mse_of_files(const char *dump_path, const char *ref_path)
{
    mcp_dump *dump = NULL;
    mcp_image *ref = NULL;
    int ri[3];
    if (mcp_dump_read(dump_path, &dump) || mcp_image_read(ref_path, NULL, &ref) ||
        mcp_image_channels(ref, (const char *[]){"R", "G", "B"}, 3, ri))
        fail_msg("%s", mcp_error_message());
    double s = 0;
    const mcp_image *c = dump->color;
    for (int y = 0; y < c->height; y++)
        for (int x = 0; x < c->width; x++)
            for (int k = 0; k < 3; k++) {
                double d =
                    (double)mcp_image_px(c, x, y)[k] - mcp_image_px(ref, x, y)[ri[k]];
                s += d * d;
            }
    double n = 3.0 * c->width * c->height;
    mcp_dump_free(dump);
    mcp_image_free(ref);
    return s / n;
}

static void
test_demo_job(void **state)
{
    (void)state;
    char out[8192], err[8192], args[8192], report[4200];
    const char *dir = mcp_test_path("demo");
    snprintf(args, sizeof args, "run '%s/samples/jobs/demo.yaml' --quiet --output '%s'",
             MCP_TEST_SOURCE_DIR, dir);
    int rc = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    if (rc != 0) fail_msg("mcpost %s: exit %d: %s", args, rc, err);
    snprintf(report, sizeof report, "%s/report.json", dir);
    char *text = mcp_test_read_text(report);
    cJSON *json = cJSON_Parse(text);
    free(text);
    assert_non_null(json);
    const cJSON *sections = item(json, "sections");
    static const char *const stages[] = {"info",     "convert",  "convert", "metrics",
                                         "estimate", "info",     "estimate", "estimate",
                                         "blend",    "perceptual"};
    const int n = (int)(sizeof stages / sizeof *stages);
    assert_int_equal(cJSON_GetArraySize(sections), n);
    for (int i = 0; i < n; i++)
        assert_string_equal(item(cJSON_GetArrayItem(sections, i), "stage")->valuestring,
                            stages[i]);

    /* metrics: the 64-spp render against the reference */
    const cJSON *metrics = cJSON_GetArrayItem(sections, 3);
    double want = mse_of_files(
        MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell/series/cornell_spp0064.exr",
        MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell/cornell_reference.exr");
    assert_close(number(metrics, "mse"), want, 1e-9, 0);

    /* estimate: a decision and an error CDF value */
    const cJSON *estimate = cJSON_GetArrayItem(sections, 4);
    double cdf = number(estimate, "cdf_at_tau");
    assert_true(cdf >= 0.0 && cdf <= 1.0);
    assert_true(cJSON_IsBool(item(estimate, "stop")));

    /* a stratified render: four renders merged (the variance from their spread), and
       a progressive series estimated with the variance from its increments, which
       also measures how far its Variance/n overstates (about 2x on texture) */
    const cJSON *merged = cJSON_GetArrayItem(sections, 5);
    assert_string_equal(item(merged, "variance_source")->valuestring, "replicates");
    assert_true(number(merged, "variance_dof") == 3);
    assert_true(number(merged, "spp") == 128);
    const cJSON *strat = cJSON_GetArrayItem(sections, 6);
    assert_string_equal(item(strat, "variance_source")->valuestring, "increments");
    assert_non_null(strstr(item(strat, "variance_warning")->valuestring, "overstates"));

    /* the default denoiser: the U-Net with the weights mcpost ships, no setting */
    const cJSON *unet = cJSON_GetArrayItem(sections, 7);
    assert_string_equal(item(unet, "denoiser")->valuestring, "default (unet)");
    assert_true(cJSON_IsBool(item(unet, "stop")));

    /* blend: converging -- the last member's blend is no worse than the noisy image */
    const cJSON *final = item(cJSON_GetArrayItem(sections, 8), "final");
    assert_int_equal((int)number(final, "spp"), 1024);
    double noisy = number(item(final, "noisy"), "mse"),
           curves = number(item(final, "curves"), "mse");
    print_message("demo: blend at 1024 spp: curves MSE %.3g, noisy %.3g\n", curves,
                  noisy);
    assert_true(curves <= noisy);

    /* perceptual: lower pMSE than the candidates' mean, energy falling */
    const cJSON *perc = cJSON_GetArrayItem(sections, 9);
    print_message("demo: perceptual pMSE / mean %.4f\n", number(perc, "pmse_ratio"));
    assert_true(number(perc, "pmse") < number(perc, "mean_pmse"));
    assert_true(number(perc, "energy_final") < number(perc, "energy_initial"));
    cJSON_Delete(json);

    snprintf(report, sizeof report, "%s/report.html", dir);
    text = mcp_test_read_text(report);
    assert_true(strlen(text) > 1000);
    free(text);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {cmocka_unit_test(test_demo_job)};
    return cmocka_run_group_tests_name("samples/demo_job", tests, NULL, NULL);
}
