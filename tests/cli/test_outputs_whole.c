/* test_outputs_whole.c: a command that writes a folder (estimate -o, perceptual -o,
 * blend -o, compare -o) makes it appear whole or not at all (docs/conventions.md,
 * "Output folders"): a failure found late leaves no folder, a run killed mid-way
 * (SIGKILL, SIGTERM) leaves no DIR, the next run clears what a SIGKILL left, a rerun
 * replaces an earlier output, and a folder that mcpost did not make is refused. */
#include "testing.h"

#include <dirent.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

static char out[1 << 16], err[1 << 16];

#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

#define CORNELL MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell"

static int
exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

/* Entries of dir whose name starts with prefix. */
static int
count_named(const char *dir, const char *prefix)
{
    DIR *d = opendir(dir);
    assert_non_null(d);
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)))
        n += !strncmp(e->d_name, prefix, strlen(prefix));
    closedir(d);
    return n;
}

/* A fresh empty folder under the scratch directory (a copy: mcp_test_path's buffers
 * rotate, and run() takes some). */
static const char *
fresh_dir(const char *name)
{
    static char dir[4096];
    snprintf(dir, sizeof dir, "%s", mcp_test_path(name));
    char cmd[4200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s' && mkdir -p '%s'", dir, dir);
    assert_int_equal(system(cmd), 0);
    return dir;
}

static void
test_failed_perceptual_leaves_no_folder(void **state)
{
    (void)state;
    const char *dir = fresh_dir("perceptual_fails");
    /* the re-render command fails after the optimisation has written its images */
    int rc = run("perceptual -o '%s/p' " CORNELL "/singles/cornell_single0[0-3].exr "
                 "-m permutation -s denoise --denoiser nlm --rerender 'exit 3' --quiet",
                 dir);
    assert_int_equal(rc, 1);
    assert_non_null(strstr(err, "rerender"));
    char p[4200];
    snprintf(p, sizeof p, "%s/p", dir);
    assert_false(exists(p));
    assert_int_equal(count_named(dir, ".p."), 0); /* no hidden temporary either */
}

/* Starts `estimate -o DIR/est` with an external denoiser that records its shell's pid
 * and sleeps: the output folder is begun and the run is mid-way. Returns mcpost's pid;
 * *shell the denoiser's. */
static pid_t
start_slow_estimate(const char *dir, pid_t *shell)
{
    char pidfile[4200], cmd[9000];
    snprintf(pidfile, sizeof pidfile, "%s/denoiser.pid", dir);
    snprintf(cmd, sizeof cmd,
             "'%s' estimate " CORNELL "/series/cornell_spp0064.exr --quiet -o '%s/est' "
             "--denoiser external --denoiser-command 'echo $$ > %s; exec sleep 60 # {color} {output}' "
             ">/dev/null 2>&1 & echo $!",
             MCP_TEST_MCPOST, dir, pidfile);
    FILE *f = popen(cmd, "r");
    assert_non_null(f);
    int pid = 0;
    assert_int_equal(fscanf(f, "%d", &pid), 1);
    pclose(f);
    /* wait (up to 20 s) until the denoiser runs */
    for (int i = 0; i < 2000 && !exists(pidfile); i++)
        nanosleep(&(struct timespec){0, 10000000}, NULL);
    char *text = mcp_test_read_text(pidfile);
    *shell = (pid_t)atoi(text);
    free(text);
    assert_true(*shell > 0);
    return (pid_t)pid;
}

static void
wait_gone(pid_t pid)
{
    for (int i = 0; i < 2000 && kill(pid, 0) == 0; i++)
        nanosleep(&(struct timespec){0, 10000000}, NULL);
    assert_int_not_equal(kill(pid, 0), 0);
}

static void
test_killed_estimate_leaves_no_folder(void **state)
{
    (void)state;
    const char *dir = fresh_dir("estimate_killed");
    char est[4200];
    snprintf(est, sizeof est, "%s/est", dir);
    pid_t shell, pid = start_slow_estimate(dir, &shell);
    assert_int_equal(count_named(dir, ".est.tmp-"), 1); /* it writes, hidden */
    assert_false(exists(est));
    kill(pid, SIGKILL);
    kill(shell, SIGKILL);
    wait_gone(pid);
    /* SIGKILL cannot be caught: the hidden temporary stays, but no DIR */
    assert_false(exists(est));
    assert_int_equal(count_named(dir, ".est.tmp-"), 1);
    /* the next run into the same parent removes it, says so, and writes DIR whole */
    assert_int_equal(run("estimate " CORNELL "/series/cornell_spp0064.exr --denoiser "
                         "external --denoiser-command 'cp {color} {output}' -o '%s'",
                         est),
                     0);
    assert_non_null(strstr(err, "left by an earlier run that was killed"));
    assert_int_equal(count_named(dir, ".est."), 0);
    char path[4400];
    snprintf(path, sizeof path, "%s/report.html", est);
    assert_true(exists(path));
    snprintf(path, sizeof path, "%s/estimate.json", est);
    assert_true(exists(path));
}

static void
test_terminated_estimate_cleans_up(void **state)
{
    (void)state;
    const char *dir = fresh_dir("estimate_terminated");
    char est[4200];
    snprintf(est, sizeof est, "%s/est", dir);
    pid_t shell, pid = start_slow_estimate(dir, &shell);
    kill(pid, SIGTERM); /* the handler removes the temporary folder */
    wait_gone(pid);
    kill(shell, SIGKILL);
    assert_false(exists(est));
    assert_int_equal(count_named(dir, ".est."), 0);
}

static void
test_rerun_replaces_and_foreign_folder_is_refused(void **state)
{
    (void)state;
    const char *dir = fresh_dir("estimate_rerun");
    char est[4200], path[4400];
    snprintf(est, sizeof est, "%s/est", dir);
    const char *args = "estimate " CORNELL "/series/cornell_spp0064.exr --quiet --denoiser "
                       "external --denoiser-command 'cp {color} {output}' -o";
    assert_int_equal(run("%s '%s'", args, est), 0);
    /* a file of the old output that the new one does not write goes with the old one */
    snprintf(path, sizeof path, "%s/stale.txt", est);
    mcp_test_write_text(path, "old");
    assert_int_equal(run("%s '%s'", args, est), 0);
    assert_false(exists(path));
    snprintf(path, sizeof path, "%s/report.json", est);
    assert_true(exists(path));
    assert_int_equal(count_named(dir, ".est."), 0);
    /* a folder that is not an mcpost output is left alone, with a one-line error */
    char mine[4200];
    snprintf(mine, sizeof mine, "%s/mine", dir);
    mkdir(mine, 0777);
    snprintf(path, sizeof path, "%s/notes.txt", mine);
    mcp_test_write_text(path, "keep me");
    assert_int_equal(run("%s '%s'", args, mine), 1);
    assert_non_null(strstr(err, "is not an mcpost output"));
    assert_true(exists(path));
    /* and "." is no folder of its own */
    assert_int_equal(run("%s .", args), 1);
    assert_non_null(strstr(err, "must be a folder of its own"));
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_failed_perceptual_leaves_no_folder),
        cmocka_unit_test(test_killed_estimate_leaves_no_folder),
        cmocka_unit_test(test_terminated_estimate_cleans_up),
        cmocka_unit_test(test_rerun_replaces_and_foreign_folder_is_refused),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
