/* test_stages.c: the library's job stages (jobs/stages.c) with the library alone, no
 * object of cli/: the table, and jobs checked and run through mcp_job_check and
 * mcp_job_run_file with stages NULL on the committed fixtures. Their figures are
 * compared with the same work done by the `mcpost` executable and with values
 * computed here. */
#include "testing.h"

#include <mcpost/dump.h>
#include <mcpost/job.h>
#include <mcpost/progress.h>
#include <mcpost/stages.h>

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CORNELL MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell"

static char out[1 << 16], err[1 << 16];

#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

static cJSON *
read_json(const char *path)
{
    char *text = mcp_test_read_text(path);
    cJSON *j = cJSON_Parse(text);
    free(text);
    assert_non_null(j);
    return j;
}

static double
number(const cJSON *o, const char *key)
{
    const cJSON *v = cJSON_GetObjectItem(o, key);
    assert_true(cJSON_IsNumber(v));
    return v->valuedouble;
}

static void
test_table_lists_every_stage(void **state)
{
    (void)state;
    static const char *const names[] = {"info",     "convert", "metrics", "perceptual",
                                        "estimate", "blend",   "adaptive"};
    const mcp_stage *const *s = mcp_job_stages();
    char listed[2048] = "";
    int n = 0;
    for (; s[n]; n++) {
        assert_true(n < 7);
        assert_string_equal(s[n]->name, names[n]);
        assert_non_null(s[n]->summary);
        assert_non_null(s[n]->keys);
        assert_non_null(s[n]->run);
        assert_non_null(s[n]->check);
        assert_ptr_equal(mcp_job_stage_find(names[n]), s[n]);
        size_t len = strlen(listed);
        snprintf(listed + len, sizeof listed - len, "%-12s %s\n", s[n]->name,
                 s[n]->summary);
    }
    assert_int_equal(n, 7);
    assert_null(mcp_job_stage_find("nope"));
    assert_null(mcp_job_stage_find(NULL));
    /* `mcpost run --list` prints this very table */
    assert_int_equal(run("run --list"), 0);
    assert_string_equal(out, listed);
}

/* A NULL table is the built-in one: the demo job checks, and a bad value fails with
 * the message `mcpost run --check` prints. */
static void
test_check_with_the_builtin_table(void **state)
{
    (void)state;
    const char *demo = MCP_TEST_SOURCE_DIR "/samples/jobs/demo.yaml";
    assert_int_equal(mcp_job_check(demo, NULL), 0);
    assert_int_equal(mcp_job_check(demo, mcp_job_stages()), 0);

    const char *bad = mcp_test_path("bad.yaml");
    mcp_test_write_text(bad,
                        "inputs:\n"
                        "  noisy: {dump: " CORNELL "/series/cornell_spp0064.exr}\n"
                        "stages:\n"
                        "  - info: {input: noisy}\n"
                        "  - estimate: {input: noisy, denoiser: nlm, probes: many}\n");
    assert_error_contains(mcp_job_check(bad, NULL), "bad.yaml:5: probes");
    char expected[1024];
    snprintf(expected, sizeof expected, "mcpost: %s\n", mcp_error_message());
    assert_int_equal(run("run --check '%s'", bad), 1);
    assert_string_equal(err, expected);
    /* an unknown stage names the built-in ones */
    mcp_test_write_text(bad, "inputs:\n"
                             "  noisy: {dump: " CORNELL "/series/cornell_spp0064.exr}\n"
                             "stages:\n"
                             "  - estimat: {input: noisy}\n");
    assert_error_contains(mcp_job_check(bad, NULL), "estimate");
}

/* info and estimate through mcp_job_run_file(path, NULL, ...): the estimate's figures
 * are those of `mcpost estimate` on the same dump (the same code and seed, so equal
 * up to the printing of the JSON), and the info stage's mean of R is the mean
 * computed here. */
static void
test_run_with_the_builtin_table(void **state)
{
    (void)state;
    const char *dump = CORNELL "/series/cornell_spp0064.exr";
    const char *job = mcp_test_path("lib.yaml");
    char text[1024];
    snprintf(text, sizeof text,
             "inputs:\n"
             "  noisy: {dump: %s}\n"
             "output: out/lib\n"
             "stages:\n"
             "  - info: {input: noisy}\n"
             "  - estimate: {input: noisy, denoiser: nlm, tau: 0.01, output: est}\n",
             dump);
    mcp_test_write_text(job, text);
    mcp_job_options o = mcp_job_defaults();
    o.quiet = 1;
    assert_int_equal(mcp_job_run_file(job, NULL, &o), 0);
    assert_int_equal(mcp_progress_quiet(), 0); /* put back as it was */

    cJSON *lib = read_json(mcp_test_path("out/lib/est/estimate.json"));
    assert_int_equal(run("estimate '%s' --denoiser nlm --tau 0.01 --json", dump), 0);
    cJSON *cli = cJSON_Parse(out);
    assert_non_null(cli);
    const char *keys[] = {"cdf_at_tau", "expected_mean_error", "blocks", "s2_pool"};
    for (int k = 0; k < 4; k++)
        assert_close(number(lib, keys[k]), number(cli, keys[k]), 1e-12, 0);
    assert_true(number(lib, "cdf_at_tau") > 0 && number(lib, "cdf_at_tau") < 1);
    assert_int_equal(cJSON_IsTrue(cJSON_GetObjectItem(lib, "stop")),
                     cJSON_IsTrue(cJSON_GetObjectItem(cli, "stop")));
    cJSON_Delete(cli);
    cJSON_Delete(lib);

    /* the info section: the mean of R, summed here in double */
    mcp_dump *d = NULL;
    assert_int_equal(mcp_dump_read(dump, &d), 0);
    int r = mcp_image_channel(d->color, "R");
    assert_true(r >= 0);
    double sum = 0;
    for (int y = 0; y < d->color->height; y++)
        for (int x = 0; x < d->color->width; x++)
            sum += mcp_image_px(d->color, x, y)[r];
    double mean = sum / ((double)d->color->width * d->color->height);
    cJSON *report = read_json(mcp_test_path("out/lib/report.json"));
    const cJSON *info = cJSON_GetArrayItem(cJSON_GetObjectItem(report, "sections"), 0);
    assert_string_equal(cJSON_GetObjectItem(info, "stage")->valuestring, "info");
    assert_int_equal((int)number(info, "width"), d->color->width);
    const cJSON *ch = cJSON_GetArrayItem(cJSON_GetObjectItem(info, "channels"), r);
    assert_string_equal(cJSON_GetObjectItem(ch, "name")->valuestring, "R");
    /* the same sum in another order: rounding of 16k doubles, far below 1e-9 */
    assert_close(number(ch, "mean"), mean, 1e-9, 0);
    cJSON_Delete(report);
    mcp_dump_free(d);
}

/* The library runs a render command that names mcpost-procedural without a path, with
 * a PATH that lacks the build folder: it is found among mcpost's programs (common/
 * shell.c), as it is for Python's run_job. A program of the same name on the PATH
 * comes first. */
static void
test_commands_find_mcposts_programs(void **state)
{
    (void)state;
    char *saved = strdup(getenv("PATH") ? getenv("PATH") : "");
    const char *job = mcp_test_path("programs.yaml");
    mcp_test_write_text(job, "output: out/programs\n"
                             "stages:\n"
                             "  - adaptive:\n"
                             "      render: \"mcpost-procedural --sample-counts {counts} "
                             "--pass {pass} --seed {seed} -o {output}\"\n"
                             "      size: 16x16\n"
                             "      budget: 8\n"
                             "      spp_per_iteration: 4\n"
                             "      denoiser: gauss\n");
    mcp_job_options o = mcp_job_defaults();
    o.quiet = 1;
    setenv("PATH", "/usr/bin:/bin", 1);
    int rc = mcp_job_run_file(job, NULL, &o);
    if (rc) fail_msg("%s", mcp_error_message());
    cJSON *a = read_json(mcp_test_path("out/programs/adaptive/adaptive.json"));
    const cJSON *its = cJSON_GetObjectItem(a, "iterations");
    assert_int_equal(cJSON_GetArraySize(its), 2);
    assert_int_equal((int)number(cJSON_GetArrayItem(its, 1), "total_samples"),
                     8 * 16 * 16);
    cJSON_Delete(a);

    /* the user's PATH first: a stand-in of the same name that fails with status 3 */
    const char *bin = mcp_test_path("fake-bin");
    char path[4400], cmd[4600];
    snprintf(cmd, sizeof cmd,
             "mkdir -p '%s' && printf '#!/bin/sh\\nexit 3\\n' > "
             "'%s/mcpost-procedural' && chmod +x '%s/mcpost-procedural'",
             bin, bin, bin);
    assert_int_equal(system(cmd), 0);
    snprintf(path, sizeof path, "%s:/usr/bin:/bin", bin);
    setenv("PATH", path, 1);
    rc = mcp_job_run_file(job, NULL, &o);
    setenv("PATH", saved, 1);
    free(saved);
    assert_error_contains(rc, "failed (exit status 3)");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_table_lists_every_stage),
        cmocka_unit_test(test_check_with_the_builtin_table),
        cmocka_unit_test(test_run_with_the_builtin_table),
        cmocka_unit_test(test_commands_find_mcposts_programs),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
