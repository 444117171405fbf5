/* test_adaptive_cli.c: `mcpost adaptive` and the `adaptive` job stage against the
 * procedural renderer's command line: the outputs against the library loop run in
 * process with the same seeds, exact sample totals, the relMSE against the metrics
 * module, and the one-line errors. */
#include "testing.h"

#include <mcpost/estimate.h>
#include <mcpost/imageio.h>
#include <mcpost/metrics.h>

#include "procedural.h"

#include <cjson/cJSON.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static char out[1 << 16], err[1 << 14];

#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

static void
assert_one_line_error(int status, const char *needle)
{
    if (status == 0 || strncmp(err, "mcpost: ", 8) != 0 || !strstr(err, needle) ||
        strchr(err, '\n') != err + strlen(err) - 1)
        fail_msg("status %d, stderr \"%s\", wanted one line with \"%s\"", status, err,
                 needle);
}

/* The render command of the procedural renderer, for a shell argument. */
static const char *
render_command(void)
{
    static char cmd[4096];
    snprintf(cmd, sizeof cmd,
             "\"'%s' --sample-counts {counts} --pass {pass} --seed {seed} -o {output}\"",
             MCP_TEST_PROCEDURAL);
    return cmd;
}

static int
render(int pass, const mcp_image *counts, mcp_dump **d, void *ctx)
{
    return mcp_proc_render_counts(ctx, counts, pass, 1, d);
}

static void
test_cli_matches_library(void **state)
{
    (void)state;
    char cmd[8192], path[4400];
    snprintf(cmd, sizeof cmd,
             "'%s' --width 32 --height 32 --realizations 0 --truth -o '%s'",
             MCP_TEST_PROCEDURAL, mcp_test_path("t"));
    assert_int_equal(system(cmd), 0);
    const char *dir = mcp_test_path("out");
    assert_int_equal(run("adaptive --size 32x32 --budget 40 --spp-per-iteration 16 "
                         "--denoiser gauss --reference '%s' --json -o '%s' --render %s",
                         mcp_test_path("t_truth.exr"), dir, render_command()),
                     0);
    /* the JSON: 16 + 16 + the last 8 spp */
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    cJSON *its = cJSON_GetObjectItem(j, "iterations");
    assert_int_equal(cJSON_GetArraySize(its), 3);
    cJSON *last = cJSON_GetArrayItem(its, 2);
    assert_true(cJSON_GetObjectItem(last, "total_samples")->valuedouble == 40.0 * 1024);
    assert_true(cJSON_GetObjectItem(last, "samples")->valuedouble == 8.0 * 1024);
    assert_string_equal(cJSON_GetObjectItem(j, "stopped_by")->valuestring, "budget");
    double relmse = cJSON_GetObjectItem(last, "relmse")->valuedouble;
    /* the accumulated dump holds exactly the total, per pixel as a whole number */
    mcp_dump *acc = NULL;
    snprintf(path, sizeof path, "%s/accumulated.exr", dir);
    assert_int_equal(mcp_dump_read(path, &acc), 0);
    double total = 0;
    for (int i = 0; i < 32 * 32; i++)
        total += acc->spp_map->data[i];
    assert_true(total == 40.0 * 1024);
    /* the relMSE is the metrics module's, of the written denoised image */
    mcp_image *den_img = NULL, *truth = NULL;
    snprintf(path, sizeof path, "%s/denoised.exr", dir);
    assert_int_equal(mcp_image_read(path, NULL, &den_img), 0);
    assert_int_equal(mcp_image_read(mcp_test_path("t_truth.exr"), NULL, &truth), 0);
    double check;
    assert_int_equal(mcp_relmse(den_img, truth, MCP_EPS_REL, &check), 0);
    assert_close(relmse, check, 1e-9, 0);
    /* the same loop in process (same renderer seed, same probe seed): the same counts,
       so the same accumulated image up to the files' float rounding of the variance */
    mcp_proc_scene scene = mcp_proc_scene_defaults();
    scene.width = scene.height = 32;
    mcp_adaptive_options o = mcp_adaptive_defaults();
    o.budget_spp = 40;
    o.spp_per_iteration = 16;
    o.est.sure.seed = 1;
    mcp_denoiser *den = NULL;
    mcp_adaptive_result *r = NULL;
    assert_int_equal(mcp_denoiser_create_from_args("gauss", NULL, 0, &den), 0);
    assert_int_equal(
        mcp_adaptive_run(32, 32, den, &o, render, &scene, truth, NULL, NULL, &r), 0);
    for (int i = 0; i < 32 * 32; i++)
        assert_true(r->accumulated->spp_map->data[i] == acc->spp_map->data[i]);
    for (int y = 0; y < 32; y++)
        for (int x = 0; x < 32; x++)
            for (int c = 0; c < 3; c++)
                assert_close(mcp_image_px(acc->color, x, y)[c],
                             mcp_image_px(r->accumulated->color, x, y)[c], 1e-6, 1e-7);
    assert_close(relmse, r->iterations[2].relmse, 1e-3, 0);
    /* the curves and the maps */
    snprintf(path, sizeof path, "%s/adaptive.csv", dir);
    char *csv = mcp_test_read_text(path);
    int lines = 0;
    for (char *p = csv; *p; p++)
        lines += *p == '\n';
    assert_int_equal(lines, 4);
    free(csv);
    snprintf(path, sizeof path, "%s/adaptive.svg", dir);
    assert_int_equal(access(path, R_OK), 0);
    snprintf(path, sizeof path, "%s/maps/sampling_map_0001.png", dir);
    assert_int_equal(access(path, R_OK), 0);
    snprintf(path, sizeof path, "%s/pass_0000.exr", dir); /* passes are not kept */
    assert_int_equal(access(path, F_OK), -1);
    mcp_adaptive_result_free(r);
    mcp_denoiser_free(den);
    mcp_image_free(den_img);
    mcp_image_free(truth);
    mcp_dump_free(acc);
    cJSON_Delete(j);
}

static void
test_job_stage(void **state)
{
    (void)state;
    char job[8192], path[4400];
    snprintf(job, sizeof job,
             "output: jobout\n"
             "stages:\n"
             "  - adaptive:\n"
             "      render: \"'%s' --sample-counts {counts} --pass {pass} --seed {seed} "
             "-o {output}\"\n"
             "      size: 24x16\n"
             "      map: tonemapped\n"
             "      budget: 24\n"
             "      spp_per_iteration: 8\n"
             "      denoiser: gauss\n",
             MCP_TEST_PROCEDURAL);
    mcp_test_write_text(mcp_test_path("job.yaml"), job);
    assert_int_equal(run("run '%s'", mcp_test_path("job.yaml")), 0);
    snprintf(path, sizeof path, "%s/adaptive/adaptive.json", mcp_test_path("jobout"));
    char *text = mcp_test_read_text(path);
    cJSON *j = cJSON_Parse(text);
    assert_string_equal(cJSON_GetObjectItem(j, "map")->valuestring, "tonemapped");
    cJSON *its = cJSON_GetObjectItem(j, "iterations");
    assert_int_equal(cJSON_GetArraySize(its), 3);
    assert_true(
        cJSON_GetObjectItem(cJSON_GetArrayItem(its, 2), "total_samples")->valuedouble ==
        24.0 * 24 * 16);
    cJSON_Delete(j);
    free(text);
    snprintf(path, sizeof path, "%s/report.json", mcp_test_path("jobout"));
    text = mcp_test_read_text(path);
    assert_non_null(strstr(text, "\"stage\":\t\"adaptive\""));
    /* both heat maps have their colour bar: inferno from 0 to a positive top */
    j = cJSON_Parse(text);
    free(text);
    const cJSON *im;
    int maps = 0;
    cJSON_ArrayForEach(
        im, cJSON_GetObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0),
                                "images"))
    {
        const cJSON *sc = cJSON_GetObjectItem(im, "scale");
        assert_non_null(sc);
        assert_string_equal(cJSON_GetObjectItem(sc, "colormap")->valuestring, "inferno");
        assert_true(cJSON_GetObjectItem(sc, "min")->valuedouble == 0);
        assert_true(cJSON_GetObjectItem(sc, "max")->valuedouble > 0);
        maps++;
    }
    assert_int_equal(maps, 2);
    cJSON_Delete(j);
    /* an unknown key names its line */
    mcp_test_write_text(mcp_test_path("bad.yaml"), "stages:\n"
                                                   "  - adaptive:\n"
                                                   "      render: x {counts} {output}\n"
                                                   "      budjet: 4\n");
    assert_one_line_error(run("run '%s'", mcp_test_path("bad.yaml")), "bad.yaml:4");
}

/* Uniform sampling gives every pixel one count: the page says the value instead of
 * showing a flat square. */
static void
test_uniform_counts_say_so(void **state)
{
    (void)state;
    char job[8192], path[4400];
    snprintf(job, sizeof job,
             "output: uniform\n"
             "stages:\n"
             "  - adaptive:\n"
             "      render: \"'%s' --sample-counts {counts} --pass {pass} --seed {seed} "
             "-o {output}\"\n"
             "      size: 16x16\n"
             "      map: uniform\n"
             "      budget: 16\n"
             "      spp_per_iteration: 8\n"
             "      denoiser: gauss\n",
             MCP_TEST_PROCEDURAL);
    mcp_test_write_text(mcp_test_path("uniform.yaml"), job);
    assert_int_equal(run("run '%s' --quiet", mcp_test_path("uniform.yaml")), 0);
    snprintf(path, sizeof path, "%s/report.json", mcp_test_path("uniform"));
    char *text = mcp_test_read_text(path);
    cJSON *j = cJSON_Parse(text);
    free(text);
    const cJSON *s = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0);
    assert_string_equal(cJSON_GetObjectItem(s, "last_pass_samples")->valuestring,
                        "8 in every pixel (one value: no map to show)");
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(s, "images")), 0);
    cJSON_Delete(j);
}

static void
test_errors(void **state)
{
    (void)state;
    const char *dir = mcp_test_path("err");
    assert_one_line_error(run("adaptive --size 8x8 --budget 8 -o '%s' --render 'false "
                              "{counts} {output}' --denoiser gauss",
                              dir),
                          "failed (exit status 1)");
    assert_non_null(strstr(err, "adaptive: pass 0: the render command 'false "));
    /* a program that is nowhere: the shell's own line ("not found"), then ours,
       which says what 127 means and where mcpost looked besides the PATH */
    assert_int_equal(run("adaptive --size 8x8 --budget 8 -o '%s' --render "
                         "'no-such-renderer {counts} {output}' --denoiser gauss",
                         dir),
                     1);
    assert_non_null(strstr(err, "\nmcpost: adaptive: pass 0: the render command "
                                "'no-such-renderer "));
    assert_non_null(strstr(err, "failed (exit status 127: a program not found; looked "
                                "on the PATH, then in "));
    assert_one_line_error(run("adaptive --size 8x8 --budget 8 -o '%s' --render 'true "
                              "{counts} {output}' --denoiser gauss",
                              dir),
                          "the render command wrote no {output} file");
    assert_one_line_error(run("adaptive --size 8x8 --budget 8 -o '%s' --render 'true "
                              "{output}' --denoiser gauss",
                              dir),
                          "must name {counts} and {output}");
    assert_one_line_error(
        run("adaptive --size 8x8 -o '%s' --render 'x {counts} {output}' "
            "--denoiser gauss",
            dir),
        "adaptive: no stop rule");
    assert_one_line_error(run("adaptive --size 8 --budget 8 -o '%s' --render 'x {counts} "
                              "{output}'",
                              dir),
                          "--size must be WIDTHxHEIGHT");
    assert_one_line_error(run("adaptive --map blue --size 8x8 --budget 8 -o '%s' "
                              "--render 'x {counts} {output}'",
                              dir),
                          "unknown map 'blue'");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cli_matches_library),
        cmocka_unit_test(test_job_stage),
        cmocka_unit_test(test_uniform_counts_say_so),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
