/* test_job_checks.c: a job file is checked whole before its first stage runs -- every
 * stage's keys, value types and values, the inputs and earlier results it names, and
 * the files it reads -- with the job file's line, by `mcpost run` (nothing runs,
 * nothing is written) and by `mcpost run --check`. One bad value per stage of the
 * tool's table, each after stages that would otherwise have run. */
#include "testing.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static char out[1 << 16], err[1 << 16];

#define FIXTURES MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell"

/* The job's head: inputs from the fixtures (a dump, a reference, a series of three
 * members, four single-sample renders) and an output folder in the scratch area. The
 * stages follow from line 13 on. */
static void
write_job(const char *path, const char *outdir, const char *stages)
{
    char text[8192];
    snprintf(text, sizeof text,
             "inputs:\n"                                                  /* 1 */
             "  noisy: {dump: " FIXTURES "/series/cornell_spp0016.exr}\n" /* 2 */
             "  reference: {image: " FIXTURES "/cornell_reference.exr}\n" /* 3 */
             "  progress:\n"                                              /* 4 */
             "    series: " FIXTURES "/series/cornell_spp%%04d.exr\n"     /* 5 */
             "    spp: [16, 32, 64]\n"                                    /* 6 */
             "  s0: {dump: " FIXTURES "/singles/cornell_single00.exr}\n"  /* 7 */
             "  s1: {dump: " FIXTURES "/singles/cornell_single01.exr}\n"  /* 8 */
             "output: %s\n"                                               /* 9 */
             "stages:\n"                                                  /* 10 */
             "  - info: {input: noisy}\n"                                 /* 11 */
             "  - convert: {input: reference, output: reference.png}\n"   /* 12 */
             "%s",
             outdir, stages);
    mcp_test_write_text(path, text);
}

static int
exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

/* Runs the job and checks it failed before anything ran: one error line that starts
 * with "mcpost: JOB:LINE: " and holds `needle`, no stage's progress note, and no output
 * folder (so no report.json); then `run --check` gives the same line. */
static void
assert_fails_up_front(const char *stages, int line, const char *needle)
{
    const char *job = mcp_test_path("job.yaml");
    char job_copy[4096], outdir[4096], want[4300];
    snprintf(job_copy, sizeof job_copy, "%s", job);
    snprintf(outdir, sizeof outdir, "%s", mcp_test_path("out_never_made"));
    write_job(job_copy, outdir, stages);
    snprintf(want, sizeof want, "mcpost: %s:%d: ", job_copy, line);

    char args[4400];
    snprintf(args, sizeof args, "run '%s'", job_copy);
    int status = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    if (status == 0 || strncmp(err, want, strlen(want)) != 0 || !strstr(err, needle) ||
        strchr(err, '\n') != err + strlen(err) - 1)
        fail_msg("run: status %d, stderr \"%s\", wanted one line \"%s...%s\"", status,
                 err, want, needle);
    if (strstr(err + strlen(want), job_copy))
        fail_msg("the job file's place is given twice: %s", err);
    if (strstr(err, "[1/") || strstr(out, "[1/"))
        fail_msg("a stage ran before the error: %s", err);
    if (exists(outdir)) fail_msg("the output folder %s was made", outdir);

    char first_error[1 << 12];
    snprintf(first_error, sizeof first_error, "%s", err);
    snprintf(args, sizeof args, "run --check '%s'", job_copy);
    status = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    if (status == 0 || strcmp(err, first_error) != 0)
        fail_msg("run --check: status %d, stderr \"%s\", wanted \"%s\"", status, err,
                 first_error);
    if (exists(outdir)) fail_msg("run --check made the output folder %s", outdir);
}

/* The case: the third stage is wrong; the first two (info, convert: they
 * would print and write reference.png) must not run. */
static void
test_third_stage_wrong_nothing_runs(void **state)
{
    (void)state;
    assert_fails_up_front("  - estimate:\n"         /* 13 */
                          "      input: noisy\n"    /* 14 */
                          "      denoiser: gauss\n" /* 15 */
                          "      tau: 0.01\n"       /* 16 */
                          "      probes: many\n",   /* 17 */
                          17, "probes must be");
}

/* One bad value per stage, at its own line. */
static void
test_info_names_a_missing_input(void **state)
{
    (void)state;
    assert_fails_up_front("  - info: {input: noisy}\n"   /* 13 */
                          "  - info: {input: nosuch}\n", /* 14 */
                          14, "no input or result called 'nosuch'");
}

static void
test_convert_bad_pixel_type(void **state)
{
    (void)state;
    assert_fails_up_front("  - convert:\n"            /* 13 */
                          "      input: noisy\n"      /* 14 */
                          "      output: noisy.exr\n" /* 15 */
                          "      pixel: double\n",    /* 16 */
                          16, "unknown pixel type 'double' (known: float, half)");
    assert_fails_up_front("  - convert: {input: noisy, output: noisy.xyz}\n", /* 13 */
                          13, "unknown image format");
}

static void
test_metrics_bad_tone_mapper_and_kinds(void **state)
{
    (void)state;
    assert_fails_up_front("  - metrics:\n"               /* 13 */
                          "      input: noisy\n"         /* 14 */
                          "      reference: reference\n" /* 15 */
                          "      tone_mapper: sepia\n",  /* 16 */
                          16, "sepia");
    /* a dump where a series is wanted */
    assert_fails_up_front("  - metrics:\n"                /* 13 */
                          "      series: noisy\n"         /* 14 */
                          "      reference: reference\n", /* 15 */
                          14, "'noisy' is not a series");
}

static void
test_estimate_bad_metric(void **state)
{
    (void)state;
    assert_fails_up_front("  - estimate:\n"              /* 13 */
                          "      input: noisy\n"         /* 14 */
                          "      denoiser: gauss\n"      /* 15 */
                          "      metric: relse-wrong\n", /* 16 */
                          16, "unknown metric 'relse-wrong'");
    /* the denoiser's settings are checked too */
    assert_fails_up_front("  - estimate:\n"                             /* 13 */
                          "      input: noisy\n"                        /* 14 */
                          "      denoiser: {name: gauss, sigma: -1}\n", /* 15 */
                          15, "sigma");
    /* an unknown setting of the denoiser, named at its line once */
    assert_fails_up_front("  - estimate:\n"                             /* 13 */
                          "      input: noisy\n"                        /* 14 */
                          "      denoiser: {name: gauss, sigmaa: 2}\n", /* 15 */
                          15, "unknown key 'sigmaa' in denoiser 'gauss'");
}

static void
test_blend_bad_fit(void **state)
{
    (void)state;
    assert_fails_up_front("  - blend:\n"                 /* 13 */
                          "      input: progress\n"      /* 14 */
                          "      reference: reference\n" /* 15 */
                          "      denoiser: gauss\n"      /* 16 */
                          "      fit: sideways\n",       /* 17 */
                          17, "sideways");
    assert_fails_up_front("  - blend: {input: noisy, denoiser: gauss}\n", /* 13 */
                          13, "'noisy' is not a series");
}

static void
test_perceptual_bad_method_and_missing_kernel_file(void **state)
{
    (void)state;
    assert_fails_up_front("  - perceptual:\n"            /* 13 */
                          "      candidates: [s0, s1]\n" /* 14 */
                          "      surrogate: reference\n" /* 15 */
                          "      reference: reference\n" /* 16 */
                          "      method: sideways\n",    /* 17 */
                          17, "sideways");
    assert_fails_up_front("  - perceptual:\n"                   /* 13 */
                          "      candidates: [s0, s1]\n"        /* 14 */
                          "      surrogate: reference\n"        /* 15 */
                          "      reference: reference\n"        /* 16 */
                          "      kernel: no_such_kernel.exr\n", /* 17 */
                          17, "no such file");
}

/* A stage may name the result of a stage before it, not after it. */
static void
test_results_of_earlier_stages_only(void **state)
{
    (void)state;
    assert_fails_up_front("  - metrics: {input: p, reference: reference}\n" /* 13 */
                          "  - perceptual:\n"                               /* 14 */
                          "      name: p\n"                                 /* 15 */
                          "      candidates: [s0, s1]\n"                    /* 16 */
                          "      surrogate: reference\n"                    /* 17 */
                          "      reference: reference\n",                   /* 18 */
                          13, "no input or result called 'p'");
    const char *job = mcp_test_path("ordered.yaml");
    char job_copy[4096], args[4400];
    snprintf(job_copy, sizeof job_copy, "%s", job);
    write_job(job_copy, mcp_test_path("out_ordered"),
              "  - perceptual:\n"
              "      name: p\n"
              "      candidates: [s0, s1]\n"
              "      surrogate: reference\n"
              "      reference: reference\n"
              "  - metrics: {input: p, reference: reference}\n");
    snprintf(args, sizeof args, "run --check '%s'", job_copy);
    int status = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    if (status != 0 || !strstr(out, ": valid"))
        fail_msg("status %d, stdout \"%s\", stderr \"%s\"", status, out, err);
}

/* Every stage takes title: (its report section's heading), and it must be text. */
static void
test_every_stage_title_is_text(void **state)
{
    (void)state;
    static const char *const stages[] = {
        "  - info: {input: noisy, title: [a, b]}\n",
        "  - convert: {input: noisy, output: n.png, title: [a, b]}\n",
        "  - metrics: {input: noisy, reference: reference, title: [a, b]}\n",
        "  - estimate: {input: noisy, denoiser: gauss, title: [a, b]}\n",
        "  - blend: {input: progress, denoiser: gauss, title: [a, b]}\n",
        "  - perceptual: {candidates: [s0, s1], title: [a, b]}\n",
        "  - adaptive: {render: \"x {counts} {output}\", size: 8x8, title: [a, b]}\n"};
    for (size_t i = 0; i < sizeof stages / sizeof *stages; i++)
        assert_fails_up_front(stages[i], 13, "title must be a string, not a list");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_stage_title_is_text),
        cmocka_unit_test(test_third_stage_wrong_nothing_runs),
        cmocka_unit_test(test_info_names_a_missing_input),
        cmocka_unit_test(test_convert_bad_pixel_type),
        cmocka_unit_test(test_metrics_bad_tone_mapper_and_kinds),
        cmocka_unit_test(test_estimate_bad_metric),
        cmocka_unit_test(test_blend_bad_fit),
        cmocka_unit_test(test_perceptual_bad_method_and_missing_kernel_file),
        cmocka_unit_test(test_results_of_earlier_stages_only),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
