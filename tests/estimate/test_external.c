/* test_external.c: the `external` denoiser (estimate/denoise_external.c;
 * docs/mathematics.md §2.1). The external command is mcpost's own gauss denoiser run
 * through tests/estimate/external_gauss.sh, so the truth is the built-in gauss: apply
 * must give the same pixels (PFM is float32), and the finite-difference JVP must match
 * gauss's exact JVP (gauss is linear, so only float rounding divided by delta separates
 * them). Also: failing commands, missing albedo, unknown keys, and no temporary files
 * left. */
#define _POSIX_C_SOURCE 200809L
#include "denoiser_settings.h"
#include "testing.h"

#include <mcpost/denoiser.h>
#include <mcpost/imageio.h>

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* A fresh (empty) working folder whose name has a space in it. */
static const char *
workdir(const char *name)
{
    const char *dir = mcp_test_path(name);
    mkdir(dir, 0777);
    return dir;
}

static int
count_entries(const char *dir)
{
    DIR *d = opendir(dir);
    assert_non_null(d);
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) n++;
    closedir(d);
    return n;
}

/* The external gauss denoiser, with its temporary folders under dir. */
static mcp_denoiser *
external_gauss(const char *dir, const char *extra)
{
    char yaml[4096];
    setenv("MCPOST", MCP_TEST_MCPOST, 1);
    snprintf(yaml, sizeof yaml,
             "{name: external, command: \"sh '%s/tests/estimate/external_gauss.sh' "
             "{color} {output}\", workdir: \"%s\"%s}",
             MCP_TEST_SOURCE_DIR, dir, extra);
    return mcp_test_denoiser(yaml);
}

static void
test_apply_equals_gauss(void **state)
{
    (void)state;
    static const char *const rgb[] = {"R", "G", "B"};
    const char *dir = workdir("apply dir");
    mcp_image *color = mcp_test_random(23, 17, 3, 0.0f, 1.0f, 7, rgb);
    mcp_denoise_input in = {color, NULL, NULL, NULL};
    mcp_denoiser *ext = external_gauss(dir, ""), *gauss = mcp_test_denoiser("gauss");
    assert_int_equal(ext->exact, 0);
    mcp_image *a = NULL, *b = NULL;
    if (ext->apply(ext, &in, &a)) fail_msg("%s", mcp_error_message());
    assert_int_equal(gauss->apply(gauss, &in, &b), 0);
    assert_int_equal(a->channels, 3);
    assert_int_equal(a->width, 23);
    assert_int_equal(a->height, 17);
    assert_true(mcp_test_max_abs_diff(a, b) <= 1e-6);
    assert_int_equal(count_entries(dir), 0); /* no temporary files left */
    mcp_image_free(a);
    mcp_image_free(b);
    mcp_denoiser_free(ext);
    mcp_denoiser_free(gauss);
    mcp_image_free(color);
}

/* The finite difference (F(x + delta t) - F(x)) / delta of a linear F equals F(t) up to
 * float rounding of values near 1 (about 2.4e-7) over delta = 0.1: tolerance
 * 1e-3 relative + 1e-5 absolute. */
static void
test_jvp_matches_exact(void **state)
{
    (void)state;
    static const char *const rgb[] = {"R", "G", "B"};
    const char *dir = workdir("jvp dir");
    mcp_image *color = mcp_test_random(20, 16, 3, 0.0f, 1.0f, 11, rgb);
    mcp_image *t0 = mcp_test_random(20, 16, 3, -0.5f, 0.5f, 12, rgb);
    mcp_image *t1 = mcp_test_random(20, 16, 3, -0.05f, 0.05f, 13, rgb);
    mcp_denoise_input in = {color, NULL, NULL, NULL};
    mcp_denoise_tangent t[2] = {{t0, NULL, NULL}, {t1, NULL, NULL}};
    mcp_denoiser *ext = external_gauss(dir, ", delta: 0.1"),
                 *gauss = mcp_test_denoiser("gauss");
    mcp_image *fe = NULL, *fg = NULL, *je[2] = {0}, *jg[2] = {0};
    if (ext->jvp(ext, &in, t, 2, &fe, je)) fail_msg("%s", mcp_error_message());
    assert_int_equal(gauss->jvp(gauss, &in, t, 2, &fg, jg), 0);
    assert_true(mcp_test_max_abs_diff(fe, fg) <= 1e-6);
    for (int k = 0; k < 2; k++)
        for (int y = 0; y < 16; y++)
            for (int x = 0; x < 20; x++)
                for (int c = 0; c < 3; c++)
                    assert_close(mcp_image_px(je[k], x, y)[c],
                                 mcp_image_px(jg[k], x, y)[c], 1e-3, 1e-5);
    assert_int_equal(count_entries(dir), 0);
    for (int k = 0; k < 2; k++) {
        mcp_image_free(je[k]);
        mcp_image_free(jg[k]);
    }
    mcp_image_free(fe);
    mcp_image_free(fg);
    mcp_denoiser_free(ext);
    mcp_denoiser_free(gauss);
    mcp_image_free(t0);
    mcp_image_free(t1);
    mcp_image_free(color);
}

static void
test_errors(void **state)
{
    (void)state;
    static const char *const rgb[] = {"R", "G", "B"};
    const char *dir = workdir("error dir");
    char yaml[4096];
    mcp_image *color = mcp_test_random(8, 6, 3, 0.0f, 1.0f, 3, rgb);
    mcp_denoise_input in = {color, NULL, NULL, NULL};
    mcp_image *out = NULL;

    /* a failing command: one line naming it and its status */
    snprintf(yaml, sizeof yaml,
             "{name: external, command: \"false {color} {output}\", workdir: \"%s\"}",
             dir);
    mcp_denoiser *d = mcp_test_denoiser(yaml);
    assert_error_contains(d->apply(d, &in, &out), "command 'false {color} {output}'");
    assert_error_contains(-1, "exit status 1");
    assert_null(strchr(mcp_error_message(), '\n'));
    assert_null(out);
    assert_int_equal(count_entries(dir), 0);
    mcp_denoiser_free(d);

    /* a command that succeeds but writes nothing */
    snprintf(yaml, sizeof yaml,
             "{name: external, command: \"true {color} {output}\", workdir: \"%s\"}",
             dir);
    d = mcp_test_denoiser(yaml);
    assert_error_contains(d->apply(d, &in, &out), "wrote no {output}");
    assert_int_equal(count_entries(dir), 0);
    mcp_denoiser_free(d);

    /* the template needs {albedo}, the input has none */
    snprintf(yaml, sizeof yaml,
             "{name: external, command: \"cp {albedo} {output} # {color}\", "
             "workdir: \"%s\"}",
             dir);
    d = mcp_test_denoiser(yaml);
    assert_int_equal(d->uses_albedo, 1);
    assert_error_contains(d->apply(d, &in, &out), "no albedo");
    assert_null(out);
    /* ... and with one it runs (cp copies the albedo through) */
    mcp_image *albedo = mcp_test_random(8, 6, 3, 0.0f, 1.0f, 4, rgb);
    in.albedo = albedo;
    if (d->apply(d, &in, &out)) fail_msg("%s", mcp_error_message());
    assert_true(mcp_test_max_abs_diff(out, albedo) == 0.0);
    assert_int_equal(count_entries(dir), 0);
    mcp_image_free(out);
    mcp_denoiser_free(d);
    mcp_image_free(albedo);

    /* settings errors name the line */
    const char *bad[][2] = {
        {"{name: external,\n command: \"x {color} {output}\",\n colour: 1}",
         "job.yaml:3: unknown key 'colour'"},
        {"{name: external}", "missing key 'command'"},
        {"external", "needs settings"},
        {"{name: external, command: \"x {color}\"}", "must name {color} and {output}"},
        {"{name: external, command: \"x {color} {output}\", format: png}", "pfm or exr"},
        {"{name: external, command: \"x {color} {output}\", delta: 0}",
         "delta must be > 0"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        mcp_node *node = NULL;
        mcp_denoiser *dd = NULL;
        if (mcp_yaml_parse_string(bad[i][0], "job.yaml", &node))
            fail_msg("%s", mcp_error_message());
        assert_error_contains(mcp_denoiser_create(node, NULL, &dd), bad[i][1]);
        assert_null(dd);
        mcp_node_free(node);
    }
    mcp_image_free(color);
}

/* From the command line, in exr format. */
static void
test_cli(void **state)
{
    (void)state;
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *color = mcp_test_random(12, 9, 3, 0.0f, 1.0f, 5, rgb);
    const char *in = mcp_test_path("cli in.exr");
    if (mcp_image_write(color, in, NULL)) fail_msg("%s", mcp_error_message());
    char args[8192], out[4096], err[4096];
    setenv("MCPOST", MCP_TEST_MCPOST, 1);
    snprintf(args, sizeof args,
             "denoise --color '%s' --denoiser external --denoiser-opt format=exr "
             "--denoiser-opt \"command=sh '%s/tests/estimate/external_gauss.sh' {color} "
             "{output}\" -o '%s'",
             in, MCP_TEST_SOURCE_DIR, mcp_test_path("cli out.exr"));
    int rc = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    if (rc != 0) fail_msg("rc %d: %s", rc, err);
    snprintf(args, sizeof args,
             "denoise --color '%s' --denoiser external --denoiser-opt 'command=false "
             "{color} {output}' -o '%s'",
             in, mcp_test_path("cli fail.exr"));
    rc = mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err);
    assert_int_equal(rc, 1);
    assert_non_null(strstr(err, "mcpost: external: command 'false {color} {output}'"));
    mcp_image_free(color);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_apply_equals_gauss),
        cmocka_unit_test(test_jvp_matches_exact),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_cli),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
