/* test_outputs_whole.c: a command that writes a folder (estimate -o, perceptual -o,
 * blend -o, compare -o, metrics -o, adaptive -o, a job's output: and each frame's
 * folder) makes it appear whole or not at all (docs/conventions.md, "Output folders"):
 * a failure found late leaves no folder, a run killed mid-way (SIGKILL, SIGTERM)
 * leaves no DIR, the next run clears what a SIGKILL left, a rerun replaces an earlier
 * output, and a folder that mcpost did not make is refused, as is an input inside the
 * folder that the run would replace (metrics, estimate, blend, perceptual, compare). */
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

/* Starts `mcpost ARGS` in the background and waits until the command it runs has
 * written its shell's pid into pidfile: mcpost is then mid-way, its output folder
 * begun. Returns mcpost's pid; *shell the command's. */
static pid_t
start_until_pidfile(const char *args, const char *pidfile, pid_t *shell)
{
    char cmd[9000];
    snprintf(cmd, sizeof cmd, "rm -f '%s'; '%s' %s >/dev/null 2>&1 & echo $!", pidfile,
             MCP_TEST_MCPOST, args);
    FILE *f = popen(cmd, "r");
    assert_non_null(f);
    int pid = 0;
    assert_int_equal(fscanf(f, "%d", &pid), 1);
    pclose(f);
    /* wait (up to 20 s) until the command runs and its pid is written */
    struct stat st;
    for (int i = 0; i < 2000 && (stat(pidfile, &st) != 0 || st.st_size == 0); i++)
        nanosleep(&(struct timespec){0, 10000000}, NULL);
    char *text = mcp_test_read_text(pidfile);
    *shell = (pid_t)atoi(text);
    free(text);
    assert_true(*shell > 0);
    return (pid_t)pid;
}

/* Starts `estimate -o DIR/est` with an external denoiser that records its shell's pid
 * and sleeps: the output folder is begun and the run is mid-way. The denoiser's files
 * go in DIR/mcpost-external-*. Returns mcpost's pid; *shell the denoiser's. */
static pid_t
start_slow_estimate(const char *dir, pid_t *shell)
{
    char pidfile[4200], args[9000];
    snprintf(pidfile, sizeof pidfile, "%s/denoiser.pid", dir);
    snprintf(args, sizeof args,
             "estimate " CORNELL "/series/cornell_spp0064.exr --quiet -o '%s/est' "
             "--denoiser external --denoiser-command 'echo $$ > %s; exec sleep 60 # "
             "{color} {output}' --denoiser-opt 'workdir=%s'",
             dir, pidfile, dir);
    return start_until_pidfile(args, pidfile, shell);
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
    assert_int_equal(count_named(dir, "mcpost-external-"), 1);
    kill(pid, SIGTERM); /* the handler removes the temporary folders */
    wait_gone(pid);
    kill(shell, SIGKILL);
    assert_false(exists(est));
    assert_int_equal(count_named(dir, ".est."), 0);
    /* and the denoiser's scratch folder */
    assert_int_equal(count_named(dir, "mcpost-external-"), 0);
}

static void
test_rerun_replaces_and_foreign_folder_is_refused(void **state)
{
    (void)state;
    const char *dir = fresh_dir("estimate_rerun");
    char est[4200], path[4400];
    snprintf(est, sizeof est, "%s/est", dir);
    const char *args =
        "estimate " CORNELL "/series/cornell_spp0064.exr --quiet --denoiser "
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

/* The text of DIR/NAME (malloc'd). */
static char *
read_in(const char *dir, const char *name)
{
    char path[4400];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    return mcp_test_read_text(path);
}

static void
test_metrics_output_appears_whole(void **state)
{
    (void)state;
    const char *dir = fresh_dir("metrics_whole");
    char m[4200], bad[4200], path[4400];
    snprintf(m, sizeof m, "%s/m", dir);
    snprintf(bad, sizeof bad, "%s/broken.exr", dir);
    mcp_test_write_text(bad, "not an image");
    const char *two =
        CORNELL "/series/cornell_spp0016.exr " CORNELL
                "/series/cornell_spp0064.exr " CORNELL "/cornell_reference.exr";
    /* the second test cannot be read: the first one's maps were written, but no folder */
    assert_int_equal(run("metrics " CORNELL "/series/cornell_spp0016.exr '%s' " CORNELL
                         "/cornell_reference.exr --flip ldr --no-spectra -o '%s'",
                         bad, m),
                     1);
    assert_non_null(strstr(err, "broken.exr"));
    assert_false(exists(m));
    assert_int_equal(count_named(dir, ".m."), 0);
    /* a good run writes it whole, the CSV asked for inside it included */
    assert_int_equal(
        run("metrics %s --flip ldr --no-spectra -o '%s' --csv '%s/figures.csv'", two, m,
            m),
        0);
    char *first = read_in(m, "metrics.json");
    snprintf(path, sizeof path, "%s/cornell_spp0016.flip_ldr.exr", m);
    assert_true(exists(path));
    snprintf(path, sizeof path, "%s/figures.csv", m);
    assert_true(exists(path));
    /* a failed rerun leaves the old output as it was; a good one replaces it (its
       metrics.json marks it as mcpost's) */
    assert_int_equal(
        run("metrics '%s' " CORNELL "/cornell_reference.exr -o '%s'", bad, m), 1);
    char *same = read_in(m, "metrics.json");
    assert_string_equal(same, first);
    free(same);
    assert_int_equal(run("metrics " CORNELL "/series/cornell_spp0064.exr " CORNELL
                         "/cornell_reference.exr --flip ldr --no-spectra -o '%s'",
                         m),
                     0);
    char *second = read_in(m, "metrics.json");
    assert_string_not_equal(second, first);
    assert_false(exists(path)); /* the old run's CSV went with the old folder */
    free(first), free(second);
    assert_int_equal(count_named(dir, ".m."), 0);
    /* an input inside the folder that the run would replace is refused, and kept */
    char inside[4400];
    snprintf(inside, sizeof inside, "%s/ref.exr", m);
    char cmd[9000];
    snprintf(cmd, sizeof cmd, "cp " CORNELL "/cornell_reference.exr '%s'", inside);
    assert_int_equal(system(cmd), 0);
    assert_int_equal(
        run("metrics " CORNELL "/series/cornell_spp0064.exr '%s' -o '%s'", inside, m), 1);
    assert_non_null(strstr(err, "is inside the output folder"));
    assert_true(exists(inside));
    assert_int_equal(count_named(dir, ".m."), 0);
}

static void
test_adaptive_output_appears_whole(void **state)
{
    (void)state;
    const char *dir = fresh_dir("adaptive_whole");
    char a[4200], path[4400];
    snprintf(a, sizeof a, "%s/a", dir);
    /* the renderer fails in the second pass, after the first pass's files were written */
    const char *args =
        "adaptive --size 16x16 --budget 32 --spp-per-iteration 16 "
        "--denoiser gauss --quiet -o '%s' --render \"test {pass} -lt %d && "
        "'" MCP_TEST_PROCEDURAL "' --sample-counts {counts} --pass {pass} "
        "--seed {seed} -o {output}\"";
    assert_int_equal(run(args, a, 1), 1);
    assert_non_null(strstr(err, "pass 1: the render command"));
    assert_false(exists(a));
    assert_int_equal(count_named(dir, ".a."), 0);
    /* whole when it succeeds, and a rerun replaces it (adaptive.json marks it) */
    assert_int_equal(run(args, a, 9), 0);
    snprintf(path, sizeof path, "%s/adaptive.json", a);
    assert_true(exists(path));
    snprintf(path, sizeof path, "%s/stale.txt", a);
    mcp_test_write_text(path, "old");
    assert_int_equal(run(args, a, 9), 0);
    assert_false(exists(path));
    snprintf(path, sizeof path, "%s/denoised.exr", a);
    assert_true(exists(path));
    assert_int_equal(count_named(dir, ".a."), 0);
}

/* An input inside the folder that a rerun would replace (common/io/outdir.c's check, as
 * metrics has it above): `CMD -o DIR/o` writes the folder; SOURCE is copied into it as
 * NAME; `BEFORE 'DIR/o/NAME' AFTER -o DIR/o` must then fail with the one line naming
 * that input, keep it, leave the old output's report.json byte for byte, and leave no
 * hidden temporary folder. */
static void
assert_input_inside_refused(const char *folder, const char *cmd, const char *source,
                            const char *name, const char *before, const char *after)
{
    const char *dir = fresh_dir(folder);
    char o[4200], inside[4400], copy[9000];
    snprintf(o, sizeof o, "%s/o", dir);
    assert_int_equal(run("%s --quiet -o '%s'", cmd, o), 0);
    char *first = read_in(o, "report.json");
    snprintf(inside, sizeof inside, "%s/%s", o, name);
    snprintf(copy, sizeof copy, "cp '%s' '%s'", source, inside);
    assert_int_equal(system(copy), 0);
    assert_int_equal(run("%s '%s' %s --quiet -o '%s'", before, inside, after, o), 1);
    char want[4600];
    snprintf(want, sizeof want, "%s: is inside the output folder %s,", inside, o);
    assert_non_null(strstr(err, want));
    assert_null(strchr(strchr(err, '\n') + 1, '\n')); /* one line */
    assert_true(exists(inside));
    char *kept = read_in(o, "report.json");
    assert_string_equal(kept, first);
    free(first), free(kept);
    assert_int_equal(count_named(dir, ".o."), 0);
}

#define ESTIMATE_EXTERNAL "--denoiser external --denoiser-command 'cp {color} {output}'"

static void
test_estimate_refuses_an_input_inside_its_output(void **state)
{
    (void)state;
    assert_input_inside_refused(
        "estimate_inside",
        "estimate " CORNELL "/series/cornell_spp0064.exr " ESTIMATE_EXTERNAL,
        CORNELL "/series/cornell_spp0064.exr", "dump.exr", "estimate", ESTIMATE_EXTERNAL);
}

static void
test_blend_refuses_an_input_inside_its_output(void **state)
{
    (void)state;
    assert_input_inside_refused("blend_inside",
                                "blend " CORNELL "/series/cornell_spp0004.exr " CORNELL
                                "/series/cornell_spp0016.exr --denoiser gauss",
                                CORNELL "/series/cornell_spp0016.exr", "spp16.exr",
                                "blend " CORNELL "/series/cornell_spp0004.exr",
                                "--denoiser gauss");
}

static void
test_perceptual_refuses_an_input_inside_its_output(void **state)
{
    (void)state;
    assert_input_inside_refused("perceptual_inside",
                                "perceptual " CORNELL "/singles/cornell_single0[0-3].exr "
                                "-m permutation -s denoise --denoiser gauss",
                                CORNELL "/singles/cornell_single00.exr", "single00.exr",
                                "perceptual",
                                CORNELL "/singles/cornell_single0[1-3].exr "
                                        "-m permutation -s denoise --denoiser gauss");
}

static void
test_compare_refuses_an_input_inside_its_output(void **state)
{
    (void)state;
    /* the reference inside: compare reads it first */
    assert_input_inside_refused("compare_inside",
                                "compare " CORNELL "/cornell_reference.exr " CORNELL
                                "/series/cornell_spp0016.exr --flip none",
                                CORNELL "/cornell_reference.exr", "ref.exr", "compare",
                                CORNELL "/series/cornell_spp0016.exr --flip none");
}

/* A frame job whose estimate runs an external denoiser that, until DIR/go exists,
 * records its shell's pid and sleeps: a run of it can be killed mid-frame. While
 * DIR/fail exists it fails. */
static void
write_slow_frame_job(const char *dir)
{
    char job[4200], text[8192];
    snprintf(job, sizeof job, "%s/shot.yaml", dir);
    snprintf(
        text, sizeof text,
        "frames: 1-2\n"
        "inputs:\n"
        "  noisy: {dump: r/f_####_0000.exr}\n"
        "output: out\n"
        "stages:\n"
        "  - estimate:\n"
        "      input: noisy\n"
        "      denoiser:\n"
        "        name: external\n"
        "        workdir: %s\n"
        "        command: 'if [ -e %s/fail ]; then exit 3; elif [ -e %s/go ]; then cp "
        "{color} {output}; else echo $$ > %s/denoiser.pid; exec sleep 60; fi'\n",
        dir, dir, dir, dir);
    mcp_test_write_text(job, text);
    for (int f = 1; f <= 2; f++) {
        char cmd[8400];
        snprintf(cmd, sizeof cmd,
                 "mkdir -p '%s/r' && '%s' --width 16 --height 16 --spp 4 --seed %d "
                 "-o '%s/r/f_%04d' >/dev/null",
                 dir, MCP_TEST_PROCEDURAL, f, dir, f);
        assert_int_equal(system(cmd), 0);
    }
}

/* Kills `mcpost run DIR/shot.yaml ARGS` in its first frame's denoiser (SIGKILL). */
static void
kill_frame_run(const char *dir, const char *args)
{
    char run_args[9000], pidfile[4200];
    snprintf(run_args, sizeof run_args, "run '%s/shot.yaml' %s", dir, args);
    snprintf(pidfile, sizeof pidfile, "%s/denoiser.pid", dir);
    pid_t shell, pid = start_until_pidfile(run_args, pidfile, &shell);
    kill(pid, SIGKILL);
    kill(shell, SIGKILL);
    wait_gone(pid);
}

static void
test_killed_frame_leaves_no_folder(void **state)
{
    (void)state;
    const char *dir = fresh_dir("frames_killed");
    char out_dir[4200], go[4200];
    snprintf(out_dir, sizeof out_dir, "%s/out", dir);
    snprintf(go, sizeof go, "%s/go", dir);
    write_slow_frame_job(dir);
    kill_frame_run(dir, "--quiet");
    /* frame 1 was mid-way: hidden, no 0001/; collect calls it unfinished */
    assert_false(exists((snprintf(out, sizeof out, "%s/0001", out_dir), out)));
    assert_int_equal(count_named(out_dir, ".0001.tmp-"), 1);
    assert_int_equal(run("collect '%s'", out_dir), 1);
    assert_non_null(
        strstr(err, "2 of 2 frames not complete: 1 (unfinished), 2 (missing)"));
    /* the next run removes what the killed one left, says so, and runs both */
    mcp_test_write_text(go, "");
    assert_int_equal(run("run '%s/shot.yaml'", dir), 0);
    assert_non_null(strstr(err, "left by an earlier run that was killed"));
    assert_int_equal(count_named(out_dir, ".0001."), 0);
    char *before = read_in(out_dir, "0001/report.json");
    /* a rerun (--force) killed mid-frame: the complete frame stays as it was */
    unlink(go);
    kill_frame_run(dir, "--quiet --force");
    assert_int_equal(count_named(out_dir, ".0001.tmp-"), 1);
    char *still = read_in(out_dir, "0001/report.json");
    assert_string_equal(still, before);
    free(still);
    /* a plain rerun skips both complete frames and clears their leftovers */
    assert_int_equal(run("run '%s/shot.yaml'", dir), 0);
    assert_non_null(strstr(err, "2 of 2 frames already complete, skipped"));
    assert_non_null(strstr(err, "left by an earlier run that was killed"));
    assert_int_equal(count_named(out_dir, ".0001."), 0);
    assert_int_equal(run("collect '%s' --quiet", out_dir), 0);
    /* a rerun that fails leaves the complete frame as it was, without an error.txt */
    char fail_flag[4200];
    snprintf(fail_flag, sizeof fail_flag, "%s/fail", dir);
    mcp_test_write_text(fail_flag, "");
    assert_int_equal(run("run '%s/shot.yaml' --force --frames 1", dir), 1);
    assert_non_null(strstr(err, "1 of 1 frames failed (1)"));
    still = read_in(out_dir, "0001/report.json");
    assert_string_equal(still, before);
    free(still);
    assert_false(exists((snprintf(out, sizeof out, "%s/0001/error.txt", out_dir), out)));
    assert_int_equal(count_named(out_dir, ".0001."), 0);
    free(before);
}

static void
test_failed_job_leaves_no_folder(void **state)
{
    (void)state;
    const char *dir = fresh_dir("job_fails");
    char job[4200], text[8192], result[4200];
    snprintf(job, sizeof job, "%s/job.yaml", dir);
    snprintf(result, sizeof result, "%s/out", dir);
    /* the second stage's denoiser fails after the first stage wrote its files */
    snprintf(text, sizeof text,
             "inputs:\n"
             "  noisy: {dump: " CORNELL "/series/cornell_spp0064.exr}\n"
             "output: out\n"
             "stages:\n"
             "  - convert: {input: noisy, output: noisy.png}\n"
             "  - estimate:\n"
             "      input: noisy\n"
             "      denoiser: {name: external, command: 'exit 3 # {color} {output}'}\n");
    mcp_test_write_text(job, text);
    assert_int_equal(run("run '%s' --quiet", job), 1);
    assert_non_null(strstr(err, "job.yaml:6: stage 'estimate'"));
    assert_false(exists(result));
    assert_int_equal(count_named(dir, ".out."), 0);
    /* the job fixed: the folder appears whole, named by its real path in the report */
    snprintf(text, sizeof text,
             "inputs:\n"
             "  noisy: {dump: " CORNELL "/series/cornell_spp0064.exr}\n"
             "output: out\n"
             "stages:\n"
             "  - convert: {input: noisy, output: noisy.png}\n"
             "  - estimate:\n"
             "      input: noisy\n"
             "      denoiser: {name: external, command: 'cp {color} {output}'}\n");
    mcp_test_write_text(job, text);
    assert_int_equal(run("run '%s' --json", job), 0);
    assert_null(strstr(out, ".tmp-"));
    assert_null(strstr(err, ".tmp-"));
    char *report = read_in(result, "report.json");
    assert_null(strstr(report, ".tmp-"));
    free(report);
    char path[4400];
    snprintf(path, sizeof path, "%s/noisy.png", result);
    assert_true(exists(path));
    assert_int_equal(count_named(dir, ".out."), 0);
    /* an input inside the output folder, which the run would replace with the old
       folder, is refused at its line, and kept */
    char cmd[9000];
    snprintf(cmd, sizeof cmd, "cp " CORNELL "/series/cornell_spp0064.exr '%s/in.exr'",
             result);
    assert_int_equal(system(cmd), 0);
    mcp_test_write_text(job, "inputs:\n"
                             "  noisy: {dump: out/in.exr}\n"
                             "output: out\n"
                             "stages:\n"
                             "  - info: {input: noisy}\n");
    assert_int_equal(run("run '%s' --quiet", job), 1);
    assert_non_null(strstr(err, "job.yaml:2: "));
    assert_non_null(strstr(err, "is inside the output folder"));
    snprintf(path, sizeof path, "%s/in.exr", result);
    assert_true(exists(path));
    assert_int_equal(count_named(dir, ".out."), 0);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_failed_perceptual_leaves_no_folder),
        cmocka_unit_test(test_killed_estimate_leaves_no_folder),
        cmocka_unit_test(test_terminated_estimate_cleans_up),
        cmocka_unit_test(test_rerun_replaces_and_foreign_folder_is_refused),
        cmocka_unit_test(test_metrics_output_appears_whole),
        cmocka_unit_test(test_adaptive_output_appears_whole),
        cmocka_unit_test(test_estimate_refuses_an_input_inside_its_output),
        cmocka_unit_test(test_blend_refuses_an_input_inside_its_output),
        cmocka_unit_test(test_perceptual_refuses_an_input_inside_its_output),
        cmocka_unit_test(test_compare_refuses_an_input_inside_its_output),
        cmocka_unit_test(test_killed_frame_leaves_no_folder),
        cmocka_unit_test(test_failed_job_leaves_no_folder),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
