/* test_frames.c: frame sets ("1-240:2") and frame tokens ("####", "%04d") in paths
 * (jobs/frames.c), against sets and paths written out by hand. */
#include "testing.h"

#include <mcpost/error.h>
#include <mcpost/frames.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include "../../jobs/internal.h"

static void
assert_set(const char *text, const int *want, int n_want)
{
    int *got = NULL, n = -1;
    if (mcp_frames_parse(text, &got, &n)) fail_msg("'%s': %s", text, mcp_error_message());
    assert_int_equal(n, n_want);
    for (int i = 0; i < n; i++)
        if (got[i] != want[i])
            fail_msg("'%s': frame %d is %d, want %d", text, i, got[i], want[i]);
    free(got);
}

static void
test_sets_parse_ranges_steps_and_lists(void **state)
{
    (void)state;
    assert_set("7", (int[]){7}, 1);
    assert_set("1-4", (int[]){1, 2, 3, 4}, 4);
    assert_set("1-9:3", (int[]){1, 4, 7}, 3);
    assert_set("1-10x4", (int[]){1, 5, 9}, 3);
    /* lists are sorted, each frame once, spaces allowed */
    assert_set("12, 3-5,4, 0", (int[]){0, 3, 4, 5, 12}, 5);
    assert_set("1001-1003", (int[]){1001, 1002, 1003}, 3);
    int *f = NULL, n;
    assert_int_equal(mcp_frames_parse("1-240", &f, &n), 0);
    assert_int_equal(n, 240);
    assert_int_equal(f[239], 240);
    free(f);
}

static void
test_bad_sets_name_the_text(void **state)
{
    (void)state;
    int *f = NULL, n;
    assert_error_contains(mcp_frames_parse("4-1", &f, &n),
                          "frames '4-1': range 4-1 runs backwards");
    assert_error_contains(mcp_frames_parse("1-9:0", &f, &n), "a step must be >= 1");
    assert_error_contains(mcp_frames_parse("1-x", &f, &n),
                          "expected a frame number at 'x'");
    assert_error_contains(mcp_frames_parse("", &f, &n), "expected a frame number");
    assert_error_contains(mcp_frames_parse("-3", &f, &n), "frames '-3'");
    assert_error_contains(mcp_frames_parse("1;2", &f, &n), "unexpected ';'");
    assert_error_contains(mcp_frames_parse("99999999", &f, &n), "frame numbers go up to");
    assert_error_contains(mcp_frames_parse("0-9999999", &f, &n),
                          "more than 100000 frames");
    assert_null(f);
}

static void
test_sets_format_compactly_and_parse_back(void **state)
{
    (void)state;
    struct {
        const char *in, *out;
    } cases[] = {{"1-4", "1-4"},
                 {"1-9:2", "1-9:2"},
                 {"1,2", "1-2"},
                 {"1,3", "1,3"},
                 {"1-4,7", "1-4,7"},
                 {"5", "5"},
                 {"1-3,10-20:5", "1-3,10-20:5"}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int *f, n, *back, m;
        char buf[256];
        assert_int_equal(mcp_frames_parse(cases[i].in, &f, &n), 0);
        assert_int_equal(mcp_frames_format(f, n, buf, sizeof buf), 0);
        assert_string_equal(buf, cases[i].out);
        assert_int_equal(mcp_frames_parse(buf, &back, &m), 0);
        assert_int_equal(m, n);
        assert_memory_equal(back, f, (size_t)n * sizeof *f);
        assert_true(mcp_frames_contains(f, n, f[n - 1]));
        assert_false(mcp_frames_contains(f, n, f[n - 1] + 1));
        free(f), free(back);
    }
    char small[4];
    assert_error_contains(mcp_frames_format((int[]){1, 3, 5, 8}, 4, small, sizeof small),
                          "too long");
}

static void
assert_expands(const char *path, int series, int frame, const char *want)
{
    char buf[256];
    if (mcp_frame_expand(path, series, frame, buf, sizeof buf))
        fail_msg("'%s': %s", path, mcp_error_message());
    assert_string_equal(buf, want);
}

static void
test_tokens_expand_as_written(void **state)
{
    (void)state;
    assert_expands("r/shot_####.exr", 0, 17, "r/shot_0017.exr");
    assert_expands("r/shot_#.exr", 0, 17, "r/shot_17.exr");
    assert_expands("r/shot_##.exr", 0, 12345, "r/shot_12345.exr"); /* never cut */
    assert_expands("r/shot_%04d.exr", 0, 17, "r/shot_0017.exr");
    assert_expands("r/shot_%d.exr", 0, 17, "r/shot_17.exr");
    assert_expands("r/shot_%06u.exr", 0, 3, "r/shot_000003.exr");
    /* a path without a token is every frame's */
    assert_expands("r/reference.exr", 0, 3, "r/reference.exr");
    /* a plain path's %% is a literal %; a series keeps it for its own formatting */
    assert_expands("r/100%%_####.exr", 0, 5, "r/100%_0005.exr");
    assert_expands("r/100%%_####_%04d.exr", 1, 5, "r/100%%_0005_%04d.exr");
    /* series: '#' is the frame and the conversion the spp ... */
    assert_expands("r/shot_####_spp%04d.exr", 1, 9, "r/shot_0009_spp%04d.exr");
    /* ... else the first of two conversions is the frame ... */
    assert_expands("r/shot_%04d_spp%04d.exr", 1, 9, "r/shot_0009_spp%04d.exr");
    assert_expands("r/spp%04d/shot_%03d.exr", 1, 9, "r/spp0009/shot_%03d.exr");
    /* ... and one conversion alone is the spp: no frame token */
    assert_expands("r/shot_spp%04d.exr", 1, 9, "r/shot_spp%04d.exr");
    /* printf's own '#' flag is part of the conversion, not a frame token */
    assert_expands("r/x_%#d.exr", 0, 8, "r/x_8.exr");

    assert_int_equal(mcp_frame_token_check("r/shot_####.exr", 0), 1);
    assert_int_equal(mcp_frame_token_check("r/shot_spp%04d.exr", 1), 0);
    assert_int_equal(mcp_frame_token_check("r/shot_%04d_spp%04d.exr", 1), 1);
    assert_int_equal(mcp_frame_token_check("r/plain.exr", 0), 0);
}

static void
test_ambiguous_tokens_are_refused(void **state)
{
    (void)state;
    char buf[256];
    assert_error_contains(mcp_frame_expand("r/##_##.exr", 0, 1, buf, sizeof buf),
                          "two '#' frame tokens");
    assert_error_contains(mcp_frame_expand("r/%04d_%04d.exr", 0, 1, buf, sizeof buf),
                          "2 frame tokens");
    assert_error_contains(mcp_frame_expand("r/####_%04d.exr", 0, 1, buf, sizeof buf),
                          "2 frame tokens");
    assert_error_contains(mcp_frame_expand("r/%d_%d_%d.exr", 1, 1, buf, sizeof buf),
                          "3 % conversions");
    assert_error_contains(mcp_frame_expand("r/####_%d_%d.exr", 1, 1, buf, sizeof buf),
                          "2 % conversions");
    assert_error_contains(mcp_frame_expand("r/%s.exr", 0, 1, buf, sizeof buf),
                          "only integer conversions");
    assert_error_contains(mcp_frame_expand("r/%099d.exr", 0, 1, buf, sizeof buf),
                          "field widths over 16");
    assert_error_contains(
        mcp_frame_expand("r/#################.exr", 0, 1, buf, sizeof buf),
        "wider than 16");
    assert_error_contains(mcp_frame_expand("r/####.exr", 0, 1, buf, 8),
                          "too long for frame 1");
    assert_error_contains(mcp_frame_expand("r/####.exr", 0, -1, buf, sizeof buf),
                          "frames are >= 0");
}

static void
test_a_frame_is_complete_when_its_report_json_exists(void **state)
{
    (void)state;
    const char *dir = mcp_test_path("frames-out");
    char frame_dir[4096], path[4200];
    mkdir(dir, 0777);
    assert_int_equal(mcp_frame_dir(dir, 17, frame_dir, sizeof frame_dir), 0);
    snprintf(path, sizeof path, "%s/0017", dir);
    assert_string_equal(frame_dir, path);
    snprintf(path, sizeof path, "%s/report.json", frame_dir);
    unlink(path); /* from an earlier run of this test */
    assert_false(mcp_frame_complete(dir, 17));
    mkdir(frame_dir, 0777);
    snprintf(path, sizeof path, "%s/report.html", frame_dir);
    mcp_test_write_text(path, "<html></html>");
    assert_false(mcp_frame_complete(dir, 17)); /* the page alone: killed before the end */
    snprintf(path, sizeof path, "%s/report.json", frame_dir);
    mcp_test_write_text(path, "{}");
    assert_true(mcp_frame_complete(dir, 17));
    assert_false(mcp_frame_complete(dir, 18));
}

/* A frame killed outright leaves "<stem>.tmp-<pid>-<n><ext>" files (the atomic
 * writes of common/io/imageio.c); the next run of the frame removes those of processes
 * that are gone, at any depth, and keeps a live process's and every other file. */
static void
test_stale_temporaries_are_cleared(void **state)
{
    (void)state;
    char dir[4096], sub[4200], path[4400];
    snprintf(dir, sizeof dir, "%s", mcp_test_path("stale-frame"));
    snprintf(sub, sizeof sub, "%s/estimate", dir);
    /* a fresh folder: an earlier run's "live" temporary is a dead process's now */
    snprintf(path, sizeof path, "rm -rf '%s'", dir);
    assert_int_equal(system(path), 0);
    mkdir(dir, 0777);
    mkdir(sub, 0777);
    pid_t gone = fork(); /* a pid that has certainly ended */
    if (gone == 0) _exit(0);
    assert_true(gone > 0);
    waitpid(gone, NULL, 0);
    const char *stale[2] = {"report.tmp-%d-0.json", "estimate/sure.tmp-%d-3.exr"};
    for (int k = 0; k < 2; k++) {
        char name[256];
        snprintf(name, sizeof name, stale[k], (int)gone);
        snprintf(path, sizeof path, "%s/%s", dir, name);
        mcp_test_write_text(path, "partial");
    }
    char live[4400], plain[4400], odd[4400];
    snprintf(live, sizeof live, "%s/map.tmp-%d-1.exr", dir, (int)getpid());
    snprintf(plain, sizeof plain, "%s/estimate/sure.exr", dir);
    snprintf(odd, sizeof odd, "%s/notes.tmp-x.txt", dir);
    mcp_test_write_text(live, "writing");
    mcp_test_write_text(plain, "done");
    mcp_test_write_text(odd, "kept");
    assert_int_equal(mcp_frame_clear_temporaries(dir), 2);
    snprintf(path, sizeof path, "%s/estimate/sure.tmp-%d-3.exr", dir, (int)gone);
    assert_int_equal(access(path, F_OK), -1);
    assert_int_equal(access(live, F_OK), 0);
    assert_int_equal(access(plain, F_OK), 0);
    assert_int_equal(access(odd, F_OK), 0);
    assert_int_equal(mcp_frame_clear_temporaries(dir), 0);
    assert_int_equal(mcp_frame_clear_temporaries(mcp_test_path("no-such-frame")), 0);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sets_parse_ranges_steps_and_lists),
        cmocka_unit_test(test_bad_sets_name_the_text),
        cmocka_unit_test(test_sets_format_compactly_and_parse_back),
        cmocka_unit_test(test_tokens_expand_as_written),
        cmocka_unit_test(test_ambiguous_tokens_are_refused),
        cmocka_unit_test(test_a_frame_is_complete_when_its_report_json_exists),
        cmocka_unit_test(test_stale_temporaries_are_cleared),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
