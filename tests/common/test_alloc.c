/* test_alloc.c: running out of memory and out of disk (common/core/alloc.c's failure
 * hook, issue 15). A small estimate (whole, and in bands), blend and perceptual run,
 * each made to fail at every
 * one of its allocations in turn, must end with an error (non-zero status, one line
 * set) and no crash; the ASan build adds: no leak, whichever allocation failed. Then
 * the same runs with a file-size limit, as on a full disk. Either way no partial
 * output may be left: a failed run leaves no output folder at all, nor its hidden
 * temporary one (docs/conventions.md, "Output folders"), and every file of a folder
 * that was written reads back whole, with no temporary file (*.tmp-*) left behind.
 * `compare` runs the same way.
 *
 * The commands run in this process (the CLI's own table, cli/commands.c), so that
 * the hook and the leak checker see them; their stdout and stderr go to a file. */
#define _GNU_SOURCE /* dirent's d_type, nftw */
#include "testing.h"

#include "../../cli/cli.h"
#include "../../common/core/internal.h"

#include <mcpost/error.h>
#include <mcpost/imageio.h>
#include <mcpost/progress.h>

#include <dirent.h>
#include <ftw.h>
#include <limits.h>
#include <omp.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

static char dir[4096];

/* Renders the inputs once: an 8x8 dump of 4 and one of 8 samples per pixel, and 4
 * single-sample renders (mcpost-procedural, the tests' source of known renders). */
static int
setup(void **state)
{
    (void)state;
    /* one thread: the allocations come in the same order in every run, so that
       "allocation n" means the same one each time, and a few thousand runs do not pay
       for waking a team of threads each (slow on a loaded machine) */
    omp_set_num_threads(1);
    snprintf(dir, sizeof dir, "%s", mcp_test_path("alloc"));
    char cmd[8192];
    snprintf(
        cmd, sizeof cmd,
        "mkdir -p '%s' && '%s' --width 8 --height 8 --spp 4 --singles 4 -o '%s/p' "
        ">/dev/null && '%s' --width 8 --height 8 --spp 8 --seed 2 -o '%s/q' >/dev/null "
        "&& '%s' --width 8 --height 150 --spp 4 --seed 3 -o '%s/tall' >/dev/null",
        dir, MCP_TEST_PROCEDURAL, dir, MCP_TEST_PROCEDURAL, dir, MCP_TEST_PROCEDURAL,
        dir);
    return system(cmd) == 0 ? 0 : -1;
}

/* Runs `mcpost ARGS` (words split on spaces) in this process; returns its status. */
static int
run_command(const char *args)
{
    char buf[4096], *argv[32];
    int argc = 0;
    snprintf(buf, sizeof buf, "%s", args);
    for (char *w = strtok(buf, " "); w && argc < 31; w = strtok(NULL, " "))
        argv[argc++] = w;
    argv[argc] = NULL;
    const mcp_command *cmd = NULL;
    for (const mcp_command *const *c = mcp_commands; *c; c++)
        if (!strcmp((*c)->name, argv[0])) cmd = *c;
    assert_non_null(cmd);
    /* the commands print results and notes: into a file, not the test's output */
    fflush(stdout);
    fflush(stderr);
    int out = dup(1), err = dup(2);
    FILE *sink = fopen(mcp_test_path("alloc.out"), "w");
    assert_non_null(sink);
    dup2(fileno(sink), 1);
    dup2(fileno(sink), 2);
    int status = cmd->run(argc, argv);
    fflush(stdout);
    fflush(stderr);
    dup2(out, 1);
    dup2(err, 2);
    close(out);
    close(err);
    fclose(sink);
    return status;
}

static int
remove_entry(const char *path, const struct stat *st, int flag, struct FTW *ftw)
{
    (void)st, (void)flag, (void)ftw;
    return remove(path);
}

/* rm -rf, in this process (a shell per run would be most of the test's time) */
static void
remove_tree(const char *path)
{
    if (access(path, F_OK) == 0)
        assert_int_equal(nftw(path, remove_entry, 16, FTW_DEPTH | FTW_PHYS), 0);
}

/* Every file under path is whole: EXR reads back, JSON parses, HTML ends, and no
 * temporary file of an interrupted atomic write is left. */
static void
assert_no_partial_files(const char *path)
{
    DIR *d = opendir(path);
    if (!d) return; /* no folder: nothing written */
    for (struct dirent *e; (e = readdir(d));) {
        if (e->d_name[0] == '.') continue;
        char file[4400];
        snprintf(file, sizeof file, "%s/%s", path, e->d_name);
        if (e->d_type == DT_DIR) {
            assert_no_partial_files(file);
            continue;
        }
        if (strstr(e->d_name, ".tmp-"))
            fail_msg("a temporary file is left behind: %s", file);
        const char *ext = strrchr(e->d_name, '.');
        if (ext && !strcmp(ext, ".exr")) {
            mcp_image *img = NULL;
            /* reading needs memory: no failure injected while checking */
            if (mcp_image_read(file, NULL, &img))
                fail_msg("partial output %s: %s", file, mcp_error_message());
            mcp_image_free(img);
        } else if (ext && (!strcmp(ext, ".json") || !strcmp(ext, ".html"))) {
            char *text = mcp_test_read_text(file);
            size_t n = strlen(text);
            while (n > 0 && strchr(" \n\r\t", text[n - 1]))
                n--;
            int whole = !strcmp(ext, ".json") ? n > 0 && strchr("}]", text[n - 1]) != NULL
                                              : strstr(text, "</html>") != NULL;
            free(text);
            if (!whole) fail_msg("partial output %s", file);
        }
    }
    closedir(d);
}

/* A failed run left nothing: no output folder, and no hidden ".NAME.tmp-PID" beside
 * it. */
static void
assert_nothing_left(const char *outdir, const char *args)
{
    if (access(outdir, F_OK) == 0)
        fail_msg("`mcpost %s` failed and left its output folder %s", args, outdir);
    const char *slash = strrchr(outdir, '/');
    char parent[4096], prefix[600];
    snprintf(parent, sizeof parent, "%.*s", (int)(slash - outdir), outdir);
    snprintf(prefix, sizeof prefix, ".%s.tmp-", slash + 1);
    DIR *d = opendir(parent);
    assert_non_null(d);
    for (struct dirent *e; (e = readdir(d));)
        if (!strncmp(e->d_name, prefix, strlen(prefix)))
            fail_msg("`mcpost %s` failed and left %s/%s", args, parent, e->d_name);
    closedir(d);
}

/* Makes allocation 0, 1, 2, ... of the command fail in turn, until a run meets no
 * failure (it then ran to the end). Returns how many runs failed. */
static long
fail_each_allocation(const char *args, const char *outdir)
{
    mcp_progress_set_quiet(1);
    long failed = 0;
    for (long n = 0;; n++) {
        remove_tree(outdir);
        mcp_error_clear();
        mcp__alloc_fail_after(n);
        int status = run_command(args);
        long counted = mcp__alloc_count();
        mcp__alloc_fail_after(-1);
        if (counted <= n) { /* no allocation failed: the run is whole */
            assert_int_equal(status, 0);
            break;
        }
        if (status == 0 || !mcp_error_message()[0] || strchr(mcp_error_message(), '\n'))
            fail_msg("`mcpost %s` with allocation %ld failing: status %d, message '%s'",
                     args, n, status, mcp_error_message());
        assert_nothing_left(outdir, args);
        failed++;
    }
    assert_no_partial_files(outdir);
    return failed;
}

/* `mcpost estimate INPUT --denoiser gauss -o DIR/OUT` made to fail at every
 * allocation. */
static void
assert_estimate_fails_cleanly(const char *input, const char *out_name)
{
    char args[4096], out[4096];
    snprintf(out, sizeof out, "%s/%s", dir, out_name);
    snprintf(args, sizeof args, "estimate %s/%s --denoiser gauss -o %s", dir, input, out);
    assert_true(fail_each_allocation(args, out) > 10);
}

static void
test_estimate_fails_cleanly_at_every_allocation(void **state)
{
    (void)state;
    assert_estimate_fails_cleanly("p_0000.exr", "estimate-out");
}

/* The estimate of a dump read and written in bands (estimate/estimate.c's
 * mcp__estimate_streamed): bands of 64 rows of a dump of 150. */
static void
test_estimate_in_bands_fails_cleanly_at_every_allocation(void **state)
{
    (void)state;
    setenv("MCPOST_ESTIMATE_BAND_ROWS", "64", 1);
    assert_estimate_fails_cleanly("tall_0000.exr", "estimate-bands-out");
    unsetenv("MCPOST_ESTIMATE_BAND_ROWS");
}

static void
test_blend_fails_cleanly_at_every_allocation(void **state)
{
    (void)state;
    char args[4096], out[4096];
    snprintf(out, sizeof out, "%s/blend-out", dir);
    snprintf(args, sizeof args,
             "blend %s/p_0000.exr %s/q_0000.exr --denoiser gauss -o %s", dir, dir, out);
    assert_true(fail_each_allocation(args, out) > 10);
}

static void
test_perceptual_fails_cleanly_at_every_allocation(void **state)
{
    (void)state;
    char args[4096], out[4096];
    snprintf(out, sizeof out, "%s/perceptual-out", dir);
    snprintf(
        args, sizeof args,
        "perceptual --denoiser gauss -o %s %s/p_single_0000.exr %s/p_single_0001.exr "
        "%s/p_single_0002.exr %s/p_single_0003.exr",
        out, dir, dir, dir, dir);
    assert_true(fail_each_allocation(args, out) > 10);
}

static void
test_compare_fails_cleanly_at_every_allocation(void **state)
{
    (void)state;
    char args[4096], out[4096];
    snprintf(out, sizeof out, "%s/compare-out", dir);
    snprintf(args, sizeof args, "compare %s/p_0000.exr %s/q_0000.exr --flip ldr -o %s",
             dir, dir, out);
    assert_true(fail_each_allocation(args, out) > 10);
}

/* A full disk, as a file-size limit: writes past it fail with EFBIG (SIGXFSZ is
 * ignored, as a shell would not). At each limit the run either fits or fails with
 * one line, and leaves only whole files. */
static void
test_full_disk_leaves_no_partial_output(void **state)
{
    (void)state;
    char args[4][4096], out[4096];
    snprintf(out, sizeof out, "%s/disk-out", dir);
    snprintf(args[0], sizeof args[0], "estimate %s/p_0000.exr --denoiser gauss -o %s",
             dir, out);
    snprintf(args[1], sizeof args[1],
             "blend %s/p_0000.exr %s/q_0000.exr --denoiser gauss -o %s", dir, dir, out);
    snprintf(
        args[2], sizeof args[2],
        "perceptual --denoiser gauss -o %s %s/p_single_0000.exr %s/p_single_0001.exr "
        "%s/p_single_0002.exr %s/p_single_0003.exr",
        out, dir, dir, dir, dir);
    snprintf(args[3], sizeof args[3], "compare %s/p_0000.exr %s/q_0000.exr -o %s", dir,
             dir, out);
    mcp_progress_set_quiet(1);
    void (*old)(int) = signal(SIGXFSZ, SIG_IGN);
    struct rlimit saved;
    assert_int_equal(getrlimit(RLIMIT_FSIZE, &saved), 0);
    static const rlim_t limits[] = {1, 200, 1000, 3000, 10000, 30000};
    for (int a = 0; a < 4; a++) {
        int failures = 0;
        for (size_t i = 0; i < sizeof limits / sizeof *limits; i++) {
            remove_tree(out);
            mcp_error_clear();
            struct rlimit lim = {limits[i], saved.rlim_max};
            assert_int_equal(setrlimit(RLIMIT_FSIZE, &lim), 0);
            int status = run_command(args[a]);
            assert_int_equal(setrlimit(RLIMIT_FSIZE, &saved), 0);
            if (status != 0) {
                failures++;
                if (!mcp_error_message()[0] || strchr(mcp_error_message(), '\n'))
                    fail_msg("`mcpost %s` at %ld bytes: status %d, message '%s'", args[a],
                             (long)limits[i], status, mcp_error_message());
                assert_nothing_left(out, args[a]);
            }
            assert_no_partial_files(out);
        }
        /* the smallest limits cannot hold the report: those runs must have failed */
        assert_true(failures >= 2);
    }
    signal(SIGXFSZ, old);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_estimate_fails_cleanly_at_every_allocation),
        cmocka_unit_test(test_estimate_in_bands_fails_cleanly_at_every_allocation),
        cmocka_unit_test(test_blend_fails_cleanly_at_every_allocation),
        cmocka_unit_test(test_perceptual_fails_cleanly_at_every_allocation),
        cmocka_unit_test(test_compare_fails_cleanly_at_every_allocation),
        cmocka_unit_test(test_full_disk_leaves_no_partial_output),
    };
    return cmocka_run_group_tests(tests, setup, NULL);
}
