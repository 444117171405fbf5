/* test_job.c: job files -- YAML (and JSON) parsing with line numbers, typed access,
 * unknown keys, missing inputs, and the runner calling stages from a table. */
#include "testing.h"

#include <unistd.h>

#include <mcpost/imageio.h>
#include <mcpost/job.h>
#include <mcpost/progress.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static void
test_yaml_tree_and_lines(void **state)
{
    (void)state;
    const char *text = "title: demo\n"
                       "inputs:\n"
                       "  noisy: {dump: a.exr, spp: 64}\n"
                       "stages:\n"
                       "  - info: {input: noisy}\n"
                       "  - metrics:\n"
                       "      percentiles: [0.5, 0.9, 0.99]\n"
                       "      quoted: \"12\"\n";
    mcp_node *root = NULL;
    assert_int_equal(mcp_yaml_parse_string(text, "job.yaml", &root), 0);
    const mcp_node *stages = mcp_node_get(root, "stages");
    assert_int_equal(stages->kind, MCP_NODE_SEQ);
    assert_int_equal(stages->count, 2);
    const mcp_node *m = stages->items[1]->items[0];
    double *p = NULL;
    int n = 0;
    assert_int_equal(mcp_node_opt_doubles(m, "percentiles", &p, &n), 0);
    assert_int_equal(n, 3);
    assert_true(p[2] == 0.99);
    free(p);
    assert_int_equal(mcp_node_get(m, "percentiles")->line, 7);
    int spp = 0;
    assert_int_equal(mcp_node_opt_int(mcp_node_get(mcp_node_get(root, "inputs"), "noisy"),
                                      "spp", &spp),
                     0);
    assert_int_equal(spp, 64);
    /* a quoted number is a string, not a number */
    assert_error_contains(mcp_node_opt_int(m, "quoted", &spp),
                          "job.yaml:8: quoted must be an integer (got '12')");
    const char *allowed[] = {"percentiles", NULL};
    assert_error_contains(
        mcp_node_check_keys(m, allowed, "stage 'metrics'"),
        "job.yaml:8: unknown key 'quoted' in stage 'metrics' (known: percentiles)");
    mcp_node_free(root);
}

static void
test_json_parses_too(void **state)
{
    (void)state;
    mcp_node *root = NULL;
    assert_int_equal(
        mcp_yaml_parse_string("{\"a\": [1, 2.5, true], \"b\": {\"c\": \"x\"}}", "j.json",
                              &root),
        0);
    int b = 0;
    double d = 0;
    assert_int_equal(mcp_node_bool(mcp_node_get(root, "a")->items[2], "a", &b), 0);
    assert_true(b);
    assert_int_equal(mcp_node_double(mcp_node_get(root, "a")->items[1], "a", &d), 0);
    assert_true(d == 2.5);
    mcp_node_free(root);
}

static void
test_yaml_errors_name_the_line(void **state)
{
    (void)state;
    mcp_node *root = NULL;
    assert_error_contains(
        mcp_yaml_parse_string("a: 1\nb: [1, 2\nc: 3\n", "bad.yaml", &root), "bad.yaml:");
    assert_error_contains(mcp_yaml_parse_string("a: 1\na: 2\n", "dup.yaml", &root),
                          "dup.yaml:2: key 'a' appears twice (first at line 1)");
    assert_error_contains(mcp_yaml_parse_string("a: &x 1\nb: *x\n", "al.yaml", &root),
                          "al.yaml:2: aliases are not supported");
    assert_error_contains(mcp_yaml_parse_string("", "empty.yaml", &root),
                          "empty job file");
    assert_error_contains(mcp_yaml_parse_file("/nonexistent/job.yaml", &root),
                          "/nonexistent/job.yaml: cannot open");
}

/* "<prefix>" followed by `depth` '[' and as many ']' (malloc'd). */
static char *
nested_lists(const char *prefix, int depth)
{
    size_t n = strlen(prefix);
    char *text = malloc(n + 2 * (size_t)depth + 2);
    assert_non_null(text);
    memcpy(text, prefix, n);
    memset(text + n, '[', (size_t)depth);
    memset(text + n + depth, ']', (size_t)depth);
    strcpy(text + n + 2 * (size_t)depth, "\n");
    return text;
}

/* Regression (issue 15): 50,000 nested lists overflowed the stack of the recursive
 * parser (a segfault in `mcpost run`); nesting now stops at 64 levels, with the line. */
static void
test_yaml_nesting_is_bounded(void **state)
{
    (void)state;
    mcp_node *root = NULL;
    /* the root map is level 0: 63 lists below it are the most allowed */
    char *text = nested_lists("a: ", 63);
    assert_int_equal(mcp_yaml_parse_string(text, "ok.yaml", &root), 0);
    mcp_node_free(root);
    free(text);
    root = NULL;
    text = nested_lists("a: ", 64);
    assert_error_contains(mcp_yaml_parse_string(text, "deep.yaml", &root),
                          "deep.yaml:1: lists and maps nested deeper than 64 levels");
    assert_null(root);
    free(text);
    text = nested_lists("stages: ", 50000);
    assert_error_contains(mcp_yaml_parse_string(text, "deep.yaml", &root),
                          "deep.yaml:1: lists and maps nested deeper than 64 levels");
    free(text);
    /* the fuzzer's input, through a file and through the tool */
    text = nested_lists("stages:\n  ", 50000);
    const char *path = mcp_test_path("deep.yaml");
    mcp_test_write_text(path, text);
    free(text);
    assert_error_contains(mcp_yaml_parse_file(path, &root),
                          "deep.yaml:2: lists and maps nested deeper than 64 levels");
    char args[4200], out[4096], err[4096], want[4200];
    snprintf(args, sizeof args, "run '%s'", path);
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 1);
    snprintf(want, sizeof want,
             "mcpost: %s:2: lists and maps nested deeper than 64 levels\n", path);
    assert_string_equal(err, want);
}

/* ---- the runner, with stages defined here ---- */

static int calls;
static double seen_mean;

static int
stage_probe(mcp_job *job, const mcp_node *settings)
{
    const mcp_dump *d = NULL;
    int scale = 1;
    if (mcp_node_opt_int(settings, "scale", &scale) ||
        mcp_job_dump(job, settings, "input", &d))
        return -1;
    seen_mean = d->color->data[0] * scale;
    calls++;
    mcp_image *copy;
    if (mcp_image_copy(d->color, &copy) || mcp_job_put_image(job, "probed", copy))
        return -1;
    cJSON *s = mcp_report_section(mcp_job_report(job), "probe", "probe");
    cJSON_AddNumberToObject(s, "value", seen_mean);
    return 0;
}

static char subdir_seen[4096];

static int
stage_consume(mcp_job *job, const mcp_node *settings)
{
    const mcp_image *img = NULL;
    if (mcp_job_image(job, settings, "input", &img)) return -1;
    char path[4096], dir[4096];
    if (mcp_job_output_path(job, "sub/out.exr", path, sizeof path)) return -1;
    /* a stage's own folder, made with its parents: <output>/made/here */
    if (mcp_job_output_subdir(job, "made/here", dir, sizeof dir)) return -1;
    snprintf(subdir_seen, sizeof subdir_seen, "%s", dir);
    calls++;
    return mcp_image_write(img, path, NULL);
}

static const char *const probe_keys[] = {"input", "scale", NULL};
static const mcp_stage probe = {"probe", "test stage", probe_keys, stage_probe, NULL};
static const mcp_stage consume = {"consume", "test stage", probe_keys, stage_consume,
                                  NULL};
static const mcp_stage *const table[] = {&probe, &consume, NULL};

static const char *
write_job(const char *name, const char *text)
{
    const char *path = mcp_test_path(name);
    mcp_test_write_text(path, text);
    return path;
}

static void
setup_input(void)
{
    const char *names[] = {"R", "G", "B"};
    mcp_image *img = mcp_test_constant(4, 3, 3, 0.25f, names);
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 8);
    assert_int_equal(mcp_image_write(img, mcp_test_path("in.exr"), NULL), 0);
    mcp_image_free(img);
}

static void
test_runner_runs_stages_in_order(void **state)
{
    (void)state;
    setup_input();
    mcp_progress_set_quiet(1);
    const char *job = write_job("ok.yaml", "inputs:\n"
                                           "  noisy: {dump: in.exr}\n"
                                           "output: out/ok\n"
                                           "stages:\n"
                                           "  - probe: {input: noisy, scale: 4}\n"
                                           "  - consume: {input: probed}\n");
    calls = 0;
    assert_int_equal(mcp_job_run_file(job, table, NULL), 0);
    assert_int_equal(calls, 2);
    assert_true(seen_mean == 1.0);
    mcp_image *back = NULL;
    assert_int_equal(mcp_image_read(mcp_test_path("out/ok/sub/out.exr"), NULL, &back), 0);
    assert_true(back->data[5] == 0.25f);
    mcp_image_free(back);
    /* mcp_job_output_subdir: the folder's path, made, in the output folder in the
       making (the hidden one beside it, renamed when the job is done) */
    const char *tail = "/made/here";
    size_t n = strlen(subdir_seen);
    assert_true(n > strlen(tail) && !strcmp(subdir_seen + n - strlen(tail), tail));
    assert_non_null(strstr(subdir_seen, "/out/.ok.tmp-"));
    struct stat st;
    assert_int_equal(stat(mcp_test_path("out/ok/made/here"), &st), 0);
    assert_true(S_ISDIR(st.st_mode));
    char *report = mcp_test_read_text(mcp_test_path("out/ok/report.json"));
    assert_non_null(strstr(report, "\"value\":\t1"));
    free(report);
}

static void
test_runner_checks_everything_first(void **state)
{
    (void)state;
    setup_input();
    mcp_progress_set_quiet(1);
    struct {
        const char *text, *error;
    } cases[] = {
        {"inputs:\n  noisy: {dump: in.exr}\nstages:\n  - probe: {input: noisy}\n"
         "  - probe: {input: noisy, scael: 2}\n",
         "bad.yaml:5: unknown key 'scael' in stage 'probe' (known: input, scale)"},
        {"inputs:\n  noisy: {dump: in.exr}\nstages:\n  - probe: {input: noisy}\n  - "
         "frobnicate:\n",
         "bad.yaml:5: unknown stage 'frobnicate' (known: probe, consume)"},
        {"inputs:\n  noisy: {dump: missing.exr}\nstages:\n  - probe: {input: noisy}\n",
         "bad.yaml:2: input file"},
        {"inputs:\n  noisy: {dump: in.exr, spp: many}\nstages:\n  - probe: {input: "
         "noisy}\n",
         "bad.yaml:2: spp must be a number (got 'many')"},
        {"inputs:\n  noisy: {dump: in.exr}\nstages:\n  - probe: {input: nosiy}\n",
         "bad.yaml:4: no input or result called 'nosiy'"},
        {"inputs:\n  noisy: {dump: in.exr}\nstages:\n  - probe: {input: noisy, scale: "
         "1.5}\n",
         "bad.yaml:4: scale must be an integer (got '1.5')"},
        {"inptus:\n  noisy: {dump: in.exr}\nstages:\n  - probe: {input: noisy}\n",
         "bad.yaml:1: unknown key 'inptus' in the job file"},
        {"inputs:\n  s: {series: 'x_%04d.exr', spp: [1, 2]}\nstages:\n  - probe: {input: "
         "s}\n",
         "bad.yaml:2: input file"},
        {"inputs:\n  noisy: {dump: in.exr, convention: povray}\nstages:\n  - probe: "
         "{input: noisy}\n",
         "bad.yaml:2: unknown convention 'povray'"},
        /* spp of a dump is one number: a list or a map is an error, not ignored */
        {"inputs:\n  noisy: {dump: in.exr, spp: [1]}\nstages:\n  - probe: {input: "
         "noisy}\n",
         "bad.yaml:2: spp must be a number, not a list"},
        {"inputs:\n  noisy:\n    dump: in.exr\n    spp: {a: 1}\nstages:\n  - probe: "
         "{input: noisy}\n",
         "bad.yaml:4: spp must be a number, not a map"},
        {"inputs:\n  noisy: {dump: in.exr, spp: 0}\nstages:\n  - probe: {input: noisy}\n",
         "bad.yaml:2: spp must be > 0 (got 0)"},
        /* a series' spp is its list of counts: a map is an error there too */
        {"inputs:\n  s: {series: [in.exr], spp: {a: 1}}\nstages:\n  - probe: {input: "
         "s}\n",
         "bad.yaml:2: spp must be a number or a list of numbers"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
        calls = 0;
        const char *job = write_job("bad.yaml", cases[i].text);
        rmdir(mcp_test_path("out/bad")); /* a stage's failure leaves it (empty) */
        assert_error_contains(mcp_job_run_file(job, table, NULL), cases[i].error);
        /* nothing ran: the failing line could be the last one */
        assert_int_equal(calls, 0);
        /* the check alone finds the same, except what only a stage knows (which input
           names it reads, the types of its own settings); neither makes the output
           folder then, which comes after the checks */
        int stage_knows = strstr(cases[i].error, "no input or result") ||
                          strstr(cases[i].error, "scale must be");
        if (!stage_knows) assert_int_equal(access(mcp_test_path("out/bad"), F_OK), -1);
        rmdir(mcp_test_path("out/bad"));
        if (!stage_knows)
            assert_error_contains(mcp_job_check(job, table), cases[i].error);
        else
            assert_int_equal(mcp_job_check(job, table), 0);
        assert_int_equal(access(mcp_test_path("out/bad"), F_OK), -1);
    }
}

/* mcp_job_check validates and does nothing else: no stage runs, no folder is made. */
static void
test_check_has_no_side_effects(void **state)
{
    (void)state;
    setup_input();
    const char *job = write_job("check.yaml", "inputs:\n"
                                              "  noisy: {dump: in.exr}\n"
                                              "output: out/checked\n"
                                              "stages:\n"
                                              "  - probe: {input: noisy, scale: 4}\n");
    calls = 0;
    assert_int_equal(mcp_job_check(job, table), 0);
    assert_int_equal(calls, 0);
    assert_int_equal(access(mcp_test_path("out/checked"), F_OK), -1);
    char out[4096], err[4096], args[4400];
    snprintf(args, sizeof args, "run --check '%s'", mcp_test_path("missing.yaml"));
    assert_int_not_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 0);
    assert_non_null(strstr(err, "missing.yaml"));
}

/* A frame job's stages are checked once; its inputs frame by frame, and only when a
 * path names the frame. A job of 50,000 frames whose inputs do not change checks as
 * fast as one frame (the job fuzz target's corpus had such files, 0.8 s each). */
static int check_calls;

static int
check_counted(mcp_job *job, const mcp_node *settings)
{
    check_calls++;
    return mcp_job_check_input(job, settings, "input", MCP_JOB_DUMP);
}

/* A frame job over one dump input, probed. */
static const char *
frame_job(const char *name, const char *frames, const char *dump)
{
    char text[512];
    snprintf(text, sizeof text,
             "frames: %s\ninputs:\n  noisy: {dump: %s}\n"
             "stages:\n  - probe: {input: noisy}\n",
             frames, dump);
    return write_job(name, text);
}

static const mcp_stage counted = {"probe", "test stage", probe_keys, stage_probe,
                                  check_counted};
static const mcp_stage *const counted_table[] = {&counted, NULL};

static void
test_frames_are_checked_by_their_inputs(void **state)
{
    (void)state;
    setup_input();
    const char *same = frame_job("same.yaml", "1-50000", "in.exr");
    check_calls = 0;
    assert_int_equal(mcp_job_check(same, counted_table), 0);
    assert_int_equal(check_calls, 1);
    /* f_0001 and f_0002 present, f_0003 missing: found, in the frame named */
    for (int f = 1; f <= 2; f++) {
        char cmd[8400], from[4096];
        snprintf(from, sizeof from, "%s", mcp_test_path("in.exr"));
        snprintf(cmd, sizeof cmd, "cp '%s' '%s/f_%04d.exr'", from, mcp_test_path(""), f);
        assert_int_equal(system(cmd), 0);
    }
    const char *token = frame_job("token.yaml", "1-3", "f_####.exr");
    check_calls = 0;
    assert_error_contains(mcp_job_check(token, counted_table), "frame 3: ");
    assert_error_contains(-1, "f_0003.exr");
    assert_int_equal(check_calls, 1);
    const char *two = frame_job("two.yaml", "1-2", "f_####.exr");
    assert_int_equal(mcp_job_check(two, counted_table), 0);
}

/* mcp_job_check_settings: what every frame shares, without the inputs' files -- a
 * frame whose render is not there yet passes, a bad key or a bad frame token fails
 * with its line, and a replicates pattern need match nothing yet. */
static void
test_settings_check_skips_the_input_files(void **state)
{
    (void)state;
    const char *later = frame_job("later.yaml", "1-3", "never_####.exr");
    assert_error_contains(mcp_job_check(later, counted_table), "never_0001.exr");
    check_calls = 0;
    assert_int_equal(mcp_job_check_settings(later, counted_table), 0);
    assert_int_equal(check_calls, 1);

    const char *bad_key =
        write_job("bad_key.yaml", "frames: 1-3\n"
                                  "inputs:\n"
                                  "  noisy: {dump: never_####.exr}\n"
                                  "stages:\n"
                                  "  - probe: {input: noisy, scael: 2}\n");
    assert_error_contains(mcp_job_check_settings(bad_key, counted_table),
                          "bad_key.yaml:5: unknown key 'scael'");
    const char *bad_token = frame_job("bad_token.yaml", "1-3", "never_%s.exr");
    assert_int_not_equal(mcp_job_check_settings(bad_token, counted_table), 0);
    assert_error_contains(-1, "bad_token.yaml:3:");
    const char *glob =
        write_job("glob.yaml", "frames: 1-3\n"
                               "inputs:\n"
                               "  noisy: {replicates: \"never_####_s*.exr\"}\n"
                               "stages:\n"
                               "  - probe: {input: noisy}\n");
    assert_error_contains(mcp_job_check(glob, counted_table), "no file matches");
    assert_int_equal(mcp_job_check_settings(glob, counted_table), 0);
}

/* mcp_job_options.quiet silences the job's own notes ("[1/2] probe", "results in")
 * and its stages' (they print through the process-wide switch), and leaves that
 * switch as the caller had it. */
static void
test_quiet_option_silences_the_job(void **state)
{
    (void)state;
    setup_input();
    const char *job = write_job("quiet.yaml", "inputs:\n"
                                              "  noisy: {dump: in.exr}\n"
                                              "output: out/quiet\n"
                                              "stages:\n"
                                              "  - probe: {input: noisy, scale: 4}\n"
                                              "  - consume: {input: probed}\n");
    mcp_progress_set_quiet(0);
    mcp_job_options opt = mcp_job_defaults();
    opt.quiet = 1;
    /* stderr into a file for the run */
    fflush(stderr);
    int saved = dup(2);
    FILE *capture = fopen(mcp_test_path("quiet.stderr"), "w+");
    assert_non_null(capture);
    assert_int_not_equal(dup2(fileno(capture), 2), -1);
    int rc = mcp_job_run_file(job, table, &opt);
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    long written =
        ftell(capture) >= 0 && fseek(capture, 0, SEEK_END) == 0 ? ftell(capture) : -1;
    fclose(capture);
    assert_int_equal(rc, 0);
    assert_int_equal(written, 0);
    assert_int_equal(mcp_progress_quiet(), 0);
    mcp_progress_set_quiet(1);
}

/* Regression (issue 15): a field width of 2147483640 overflowed snprintf's int count,
 * and the path buffer came out 1 byte long and unterminated. */
static void
test_series_pattern_is_bounded(void **state)
{
    (void)state;
    setup_input();
    mcp_progress_set_quiet(1);
    const char *job =
        write_job("series.yaml", "inputs:\n"
                                 "  s: {series: 'renders/x_%2147483640d.exr', "
                                 "spp: [1]}\n"
                                 "stages:\n"
                                 "  - probe: {input: s}\n");
    calls = 0;
    assert_error_contains(mcp_job_run_file(job, table, NULL),
                          "series.yaml:2: series pattern '");
    assert_non_null(
        strstr(mcp_error_message(),
               "/renders/x_%2147483640d.exr': field widths over 16 are refused"));
    assert_null(strchr(mcp_error_message(), '\n'));
    assert_int_equal(calls, 0);
    /* the tool says the same in one line and exits 1 */
    char args[4200], out[4096], err[4096];
    snprintf(args, sizeof args, "run '%s'", job);
    assert_int_equal(mcp_test_run_mcpost(args, out, sizeof out, err, sizeof err), 1);
    assert_non_null(strstr(err, "series.yaml:2: series pattern '"));
    assert_non_null(strstr(err, "field widths over 16 are refused\n"));
    assert_int_equal(strchr(err, '\n') - err, (ptrdiff_t)strlen(err) - 1);
}

/* Counts the occurrences of needle in the last error message. */
static int
count_in_error(const char *needle)
{
    int n = 0;
    for (const char *p = mcp_error_message(); (p = strstr(p, needle));
         p += strlen(needle))
        n++;
    return n;
}

static void
test_wrong_types_name_the_line_once(void **state)
{
    (void)state;
    setup_input();
    mcp_progress_set_quiet(1);
    static const char *const keys[] = {"convention", "variance", "bad_values"};
    for (int k = 0; k < 3; k++) {
        char text[512], want[128];
        /* a wrong type (a list) and a wrong name: both carry "bad.yaml:3:" once */
        snprintf(text, sizeof text,
                 "inputs:\n  noisy:\n    %s: [pbrt]\n    dump: in.exr\n"
                 "stages:\n  - probe: {input: noisy}\n",
                 keys[k]);
        snprintf(want, sizeof want, "bad.yaml:3: %s must be a string, not a list",
                 keys[k]);
        assert_error_contains(mcp_job_run_file(write_job("bad.yaml", text), table, NULL),
                              want);
        assert_int_equal(count_in_error("bad.yaml:"), 1);
        snprintf(text, sizeof text,
                 "inputs:\n  noisy:\n    %s: nonsense\n    dump: in.exr\n"
                 "stages:\n  - probe: {input: noisy}\n",
                 keys[k]);
        assert_error_contains(mcp_job_run_file(write_job("bad.yaml", text), table, NULL),
                              "bad.yaml:3: unknown ");
        assert_int_equal(count_in_error("bad.yaml:"), 1);
    }
}

/* ---- explicit channel mapping of a dump ---- */

static void
check_mapped(const mcp_image *part, int first, const char *a, const char *b,
             const char *c)
{
    assert_non_null(part);
    assert_int_equal(part->channels, 3);
    assert_string_equal(part->names[0], a);
    assert_string_equal(part->names[1], b);
    assert_string_equal(part->names[2], c);
    /* the ramp's value is x + 10 y + 100 channel, in the file's channel order */
    for (int y = 0; y < part->height; y++)
        for (int x = 0; x < part->width; x++)
            for (int k = 0; k < 3; k++)
                assert_true(mcp_image_px(part, x, y)[k] ==
                            (float)(x + 10 * y + 100 * (first + k)));
}

/* The dump lives as long as the job: a stage checks it. */
static int
stage_mapped(mcp_job *job, const mcp_node *settings)
{
    const mcp_dump *d = NULL;
    if (mcp_job_dump(job, settings, "input", &d)) return -1;
    calls++;
    assert_int_equal(d->color->width, 5);
    assert_int_equal(d->color->height, 4);
    check_mapped(d->color, 3, "R", "G", "B");       /* beauty.*, not the decoy R,G,B */
    check_mapped(d->var_of_mean, 6, "R", "G", "B"); /* of-mean: kept as written */
    check_mapped(d->albedo, 9, "R", "G", "B");
    check_mapped(d->normal, 12, "X", "Y", "Z");
    assert_true(d->spp == 16);
    return 0;
}

static void
test_channel_mapping_overrides_detection(void **state)
{
    (void)state;
    mcp_progress_set_quiet(1);
    /* names no convention knows, and a decoy R,G,B that detection would pick */
    const char *names[] = {"R",        "G",     "B",     "beauty.x", "beauty.y",
                           "beauty.z", "v.0",   "v.1",   "v.2",      "alb.a",
                           "alb.b",    "alb.c", "nrm.u", "nrm.v",    "nrm.w"};
    mcp_image *img = mcp_test_ramp(5, 4, 15, names);
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 16);
    assert_int_equal(mcp_image_write(img, mcp_test_path("odd.exr"), NULL), 0);
    mcp_image_free(img);
    static const mcp_stage mapped = {"mapped", "test stage", probe_keys, stage_mapped,
                                     NULL};
    static const mcp_stage *const mapped_table[] = {&mapped, NULL};
    const char *job =
        write_job("map.yaml", "inputs:\n"
                              "  d:\n"
                              "    dump: odd.exr\n"
                              "    variance: of-mean\n"
                              "    channels:\n"
                              "      color: [beauty.x, beauty.y, beauty.z]\n"
                              "      variance: [v.0, v.1, v.2]\n"
                              "      albedo: [alb.a, alb.b, alb.c]\n"
                              "      normal: [nrm.u, nrm.v, nrm.w]\n"
                              "output: out/map\n"
                              "stages:\n"
                              "  - mapped: {input: d}\n");
    calls = 0;
    assert_int_equal(mcp_job_run_file(job, mapped_table, NULL), 0);
    assert_int_equal(calls, 1);

    /* a channel the file lacks: the error names the job line that uses the input
     * (the dump is read there, not while checking) and the missing channel */
    job = write_job("map.yaml", "inputs:\n"
                                "  d:\n"
                                "    dump: odd.exr\n"
                                "    channels:\n"
                                "      albedo: [alb.a, alb.b, alb.z]\n"
                                "output: out/map\n"
                                "stages:\n"
                                "  - mapped: {input: d}\n");
    calls = 0;
    assert_error_contains(mcp_job_run_file(job, mapped_table, NULL), "map.yaml:8: ");
    assert_non_null(strstr(mcp_error_message(), "alb.z"));
    assert_int_equal(count_in_error("map.yaml:"), 1);
    assert_int_equal(calls, 0);
    /* a mapping that is not 3 names is caught while checking, at its own line */
    job = write_job("map.yaml", "inputs:\n"
                                "  d:\n"
                                "    dump: odd.exr\n"
                                "    channels:\n"
                                "      normal: [nrm.u, nrm.v]\n"
                                "stages:\n"
                                "  - mapped: {input: d}\n");
    assert_error_contains(mcp_job_run_file(job, mapped_table, NULL),
                          "map.yaml:5: channels.normal must list 3 channel names");
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_yaml_tree_and_lines),
        cmocka_unit_test(test_json_parses_too),
        cmocka_unit_test(test_yaml_errors_name_the_line),
        cmocka_unit_test(test_yaml_nesting_is_bounded),
        cmocka_unit_test(test_runner_runs_stages_in_order),
        cmocka_unit_test(test_runner_checks_everything_first),
        cmocka_unit_test(test_check_has_no_side_effects),
        cmocka_unit_test(test_quiet_option_silences_the_job),
        cmocka_unit_test(test_wrong_types_name_the_line_once),
        cmocka_unit_test(test_series_pattern_is_bounded),
        cmocka_unit_test(test_channel_mapping_overrides_detection),
        cmocka_unit_test(test_frames_are_checked_by_their_inputs),
        cmocka_unit_test(test_settings_check_skips_the_input_files),
    };
    return cmocka_run_group_tests_name("common/job", tests, NULL, NULL);
}
