/* test_frames_cli.c: frame jobs through the executable (docs/frames.md) -- `run` over
 * frames in parallel into OUTPUT/NNNN/, resuming (complete frames skipped, a killed
 * frame run again), --force and --frames, a failed frame that does not stop the others,
 * a series pattern with frame and spp tokens, `collect` (figures per frame equal to each
 * frame's own, worst first, the failed frame listed), and `submit --slurm` (the scripts,
 * and the sbatch calls through a stand-in sbatch). The real Slurm runs in
 * tests/cli/slurm_frames.sh. The frames are 4 renders of the procedural scene with other
 * seeds; their MSE is recomputed here from the files. */
#include "testing.h"

#include <cjson/cJSON.h>
#include <mcpost/imageio.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char out[1 << 16], err[1 << 16];
static char dir[4096];

#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

static void
sh(const char *fmt, ...)
{
    char cmd[8192];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(cmd, sizeof cmd, fmt, ap);
    va_end(ap);
    if (system(cmd) != 0) fail_msg("failed: %s", cmd);
}

static cJSON *
read_json(const char *fmt, ...)
{
    char path[4200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(path, sizeof path, fmt, ap);
    va_end(ap);
    char *text = mcp_test_read_text(path);
    cJSON *j = cJSON_Parse(text);
    free(text);
    if (!j) fail_msg("%s: not JSON", path);
    return j;
}

static int
exists(const char *fmt, ...)
{
    char path[4200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(path, sizeof path, fmt, ap);
    va_end(ap);
    struct stat st;
    return stat(path, &st) == 0;
}

/* The metrics section's figure of a frame's report.json. */
static double
frame_figure(cJSON *rep, const char *key)
{
    cJSON *sec;
    cJSON_ArrayForEach(sec, cJSON_GetObjectItem(rep, "sections"))
    {
        cJSON *v = cJSON_GetObjectItem(sec, key);
        if (cJSON_IsNumber(v)) return v->valuedouble;
    }
    fail_msg("no figure %s", key);
    return NAN;
}

/* MSE of the frame's dump against its truth, recomputed from the files. */
static double
recomputed_mse(int frame)
{
    char a[4200], b[4200];
    snprintf(a, sizeof a, "%s/r/shot_%04d_0000.exr", dir, frame);
    snprintf(b, sizeof b, "%s/r/shot_%04d_truth.exr", dir, frame);
    mcp_image *x = NULL, *y = NULL;
    assert_int_equal(mcp_image_read(a, NULL, &x), 0);
    assert_int_equal(mcp_image_read(b, NULL, &y), 0);
    int cx[3], cy[3];
    assert_int_equal(mcp_image_channels(x, (const char *[]){"R", "G", "B"}, 3, cx), 0);
    assert_int_equal(mcp_image_channels(y, (const char *[]){"R", "G", "B"}, 3, cy), 0);
    double sum = 0;
    for (int j = 0; j < x->height; j++)
        for (int i = 0; i < x->width; i++)
            for (int c = 0; c < 3; c++) {
                double d = (double)mcp_image_px(x, i, j)[cx[c]] -
                           (double)mcp_image_px(y, i, j)[cy[c]];
                sum += d * d;
            }
    double mse = sum / (3.0 * x->width * x->height);
    mcp_image_free(x);
    mcp_image_free(y);
    return mse;
}

static void
write_job(const char *name, const char *frames)
{
    char path[4200], text[2048];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    snprintf(text, sizeof text,
             "title: test shot\n"
             "frames: %s\n"
             "inputs:\n"
             "  noisy: {dump: r/shot_####_0000.exr}\n"
             "  reference: {image: r/shot_%%04d_truth.exr}\n"
             "output: out/%s\n"
             "stages:\n"
             "  - metrics: {input: noisy, reference: reference}\n",
             frames, name);
    mcp_test_write_text(path, text);
}

static int
setup(void **state)
{
    (void)state;
    snprintf(dir, sizeof dir, "%s", mcp_test_path("shot"));
    sh("rm -rf '%s' && mkdir -p '%s/r'", dir, dir);
    for (int f = 1; f <= 4; f++)
        sh("'%s' --width 24 --height 16 --spp 4 --seed %d --truth -o '%s/r/shot_%04d' "
           ">/dev/null",
           MCP_TEST_PROCEDURAL, 10 + f, dir, f);
    return 0;
}

static void
test_run_frames_in_parallel_and_resume(void **state)
{
    (void)state;
    write_job("shot.yaml", "1-4");
    assert_int_equal(run("run '%s/shot.yaml' -j 2", dir), 0);
    for (int f = 1; f <= 4; f++) {
        cJSON *rep = read_json("%s/out/shot.yaml/%04d/report.json", dir, f);
        assert_int_equal(cJSON_GetObjectItem(rep, "frame")->valueint, f);
        assert_true(exists("%s/out/shot.yaml/%04d/report.html", dir, f));
        /* the frame's own files, not another's: MSE as recomputed from them */
        assert_close(frame_figure(rep, "mse"), recomputed_mse(f), 1e-6, 0);
        cJSON_Delete(rep);
    }
    /* the four frames differ (other seeds), so a mix-up would show */
    assert_true(fabs(recomputed_mse(1) - recomputed_mse(2)) > 1e-6 * recomputed_mse(1));
    cJSON *m = read_json("%s/out/shot.yaml/frames.json", dir);
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(m, "frames")), 4);
    cJSON_Delete(m);

    /* a run killed in frame 3: its page written, its report.json not */
    char keep[4200];
    snprintf(keep, sizeof keep, "%s/out/shot.yaml/0001/report.json", dir);
    char *before = mcp_test_read_text(keep);
    sh("rm '%s/out/shot.yaml/0003/report.json' && touch -d '2001-01-01' '%s'", dir, keep);
    struct stat st_before, st_after;
    assert_int_equal(stat(keep, &st_before), 0);
    assert_int_equal(run("run '%s/shot.yaml' -j 2", dir), 0);
    assert_non_null(strstr(err, "3 of 4 frames already complete, skipped"));
    assert_non_null(strstr(err, "1 frames run"));
    assert_true(exists("%s/out/shot.yaml/0003/report.json", dir));
    assert_int_equal(stat(keep, &st_after), 0);
    assert_true(st_after.st_mtime == st_before.st_mtime); /* frame 1 untouched */

    /* --force runs them all again; --frames picks some */
    assert_int_equal(run("run '%s/shot.yaml' --force", dir), 0);
    assert_null(strstr(err, "already complete"));
    assert_non_null(strstr(err, "4 frames run"));
    assert_int_equal(stat(keep, &st_after), 0);
    assert_true(st_after.st_mtime != st_before.st_mtime);
    char *after = mcp_test_read_text(keep);
    assert_string_equal(after, before); /* the same frame gives the same report */
    free(before), free(after);
    assert_int_equal(run("run '%s/shot.yaml' --frames 2,4 --force", dir), 0);
    assert_non_null(strstr(err, "frame 2 (1 of 2)"));
    assert_non_null(strstr(err, "frame 4 (2 of 2)"));
    /* the output folder is named by its real path, whatever the job calls it */
    char up[4200];
    snprintf(up, sizeof up, "%s/r/up.yaml", dir);
    mcp_test_write_text(up, "frames: 1-2\n"
                            "inputs:\n"
                            "  noisy: {dump: shot_####_0000.exr}\n"
                            "output: ../out/up\n"
                            "stages:\n"
                            "  - info: {input: noisy}\n");
    assert_int_equal(run("run '%s' -j 2", up), 0);
    assert_non_null(strstr(err, "/out/up (mcpost collect"));
    assert_null(strstr(err, "/../"));

    /* errors: a frame the job lacks, -j on a job without frames */
    assert_int_equal(run("run '%s/shot.yaml' --frames 7", dir), 1);
    assert_non_null(strstr(err, "frame 7 is not among the frames of"));
    assert_non_null(strstr(err, "(1-4)"));
    assert_int_equal(run("run '%s/shot.yaml' -j 0", dir), 2);
}

static void
test_a_failed_frame_is_listed_by_run_and_collect(void **state)
{
    (void)state;
    write_job("gap.yaml", "1-5"); /* frame 5 was never rendered */
    assert_int_equal(run("run '%s/gap.yaml' --check", dir), 1);
    assert_non_null(strstr(err, "frame 5: "));
    assert_non_null(strstr(err, "gap.yaml:4: input file"));
    assert_int_equal(run("run '%s/gap.yaml' -j 3", dir), 1);
    assert_non_null(strstr(err, "mcpost: frame 5: "));
    assert_non_null(strstr(err, "1 of 5 frames failed (5)"));
    for (int f = 1; f <= 4; f++)
        assert_true(exists("%s/out/gap.yaml/%04d/report.json", dir, f));
    char *why = mcp_test_read_text(
        (snprintf(out, sizeof out, "%s/out/gap.yaml/0005/error.txt", dir), out));
    assert_non_null(strstr(why, "shot_0005_0000.exr"));
    free(why);

    /* collect: 4 complete frames with their own figures, worst first; frame 5 failed,
     * with its reason; frame 6 is not in the job and has no folder: not there */
    assert_int_equal(run("collect '%s/out/gap.yaml'", dir), 1);
    assert_non_null(strstr(err, "1 of 5 frames not complete: 5 (failed)"));
    cJSON *rep = read_json("%s/out/gap.yaml/report.json", dir);
    cJSON *sec = cJSON_GetArrayItem(cJSON_GetObjectItem(rep, "sections"), 0);
    assert_int_equal(cJSON_GetObjectItem(sec, "frames")->valueint, 5);
    assert_int_equal(cJSON_GetObjectItem(sec, "complete")->valueint, 4);
    assert_int_equal(cJSON_GetObjectItem(sec, "failed")->valueint, 1);
    const char *mse_key = "metrics: noisy against reference: MSE";
    const char *rel_key = "metrics: noisy against reference: relMSE";
    cJSON *list = cJSON_GetObjectItem(sec, "frame_list"), *f;
    double rel[6] = {0};
    cJSON_ArrayForEach(f, list)
    {
        int n = cJSON_GetObjectItem(f, "frame")->valueint;
        const char *status = cJSON_GetObjectItem(f, "status")->valuestring;
        if (n == 5) {
            assert_string_equal(status, "failed");
            assert_non_null(strstr(cJSON_GetObjectItem(f, "message")->valuestring,
                                   "shot_0005_0000.exr"));
            continue;
        }
        assert_string_equal(status, "complete");
        cJSON *own = read_json("%s/out/gap.yaml/%04d/report.json", dir, n);
        cJSON *fig = cJSON_GetObjectItem(f, "figures");
        assert_true(cJSON_GetObjectItem(fig, mse_key)->valuedouble ==
                    frame_figure(own, "mse"));
        rel[n] = cJSON_GetObjectItem(fig, rel_key)->valuedouble;
        assert_true(rel[n] == frame_figure(own, "relmse"));
        cJSON_Delete(own);
    }
    assert_int_equal(cJSON_GetArraySize(list), 5);
    /* the table: complete frames by relMSE, largest first, each with its page */
    cJSON *table = NULL, *t;
    cJSON_ArrayForEach(
        t, cJSON_GetObjectItem(
               sec, "tables")) if (!strcmp(cJSON_GetObjectItem(t, "title")->valuestring,
                                           "frames, worst first")) table = t;
    assert_non_null(table);
    cJSON *rows = cJSON_GetObjectItem(table, "rows");
    assert_int_equal(cJSON_GetArraySize(rows), 4);
    double last = INFINITY;
    int rel_col = 2; /* frame, MSE, relMSE, ... */
    assert_string_equal(
        cJSON_GetArrayItem(cJSON_GetObjectItem(table, "columns"), rel_col)->valuestring,
        rel_key);
    cJSON *row;
    cJSON_ArrayForEach(row, rows)
    {
        int n = cJSON_GetArrayItem(row, 0)->valueint;
        double v = cJSON_GetArrayItem(row, rel_col)->valuedouble;
        assert_true(v == rel[n]);
        assert_true(v <= last);
        last = v;
        char page[32];
        snprintf(page, sizeof page, "%04d/report.html", n);
        assert_string_equal(
            cJSON_GetArrayItem(row, cJSON_GetArraySize(row) - 1)->valuestring, page);
    }
    /* a plot per figure, against the frame number */
    assert_true(cJSON_GetArraySize(cJSON_GetObjectItem(sec, "plots")) >= 4);
    cJSON_Delete(rep);
    char *html = mcp_test_read_text(
        (snprintf(out, sizeof out, "%s/out/gap.yaml/report.html", dir), out));
    /* the page: each complete frame's page linked from the table, the failed frame
       in the table of frames not complete, and a red verdict that says so */
    assert_non_null(strstr(html, "<a href=\"0004/report.html\">0004/report.html</a>"));
    assert_null(strstr(html, "0005/report.html"));
    assert_non_null(strstr(html, "<td>failed</td>"));
    assert_non_null(strstr(html, "class=\"verdict bad\">1 of 5 frames not complete "
                                 "(1 failed, 0 unfinished, 0 missing); running the job "
                                 "again retries them; the worst by "));
    free(html);

    /* the missing frame rendered: a rerun runs it alone, and collect is content */
    sh("cp '%s/r/shot_0004_0000.exr' '%s/r/shot_0005_0000.exr' && "
       "cp '%s/r/shot_0004_truth.exr' '%s/r/shot_0005_truth.exr'",
       dir, dir, dir, dir);
    assert_int_equal(run("run '%s/gap.yaml'", dir), 0);
    assert_non_null(strstr(err, "4 of 5 frames already complete"));
    assert_false(exists("%s/out/gap.yaml/0005/error.txt", dir));
    assert_int_equal(run("collect '%s/out/gap.yaml' --quiet", dir), 0);
    assert_int_equal(run("collect '%s/nowhere'", dir), 1);
    assert_non_null(strstr(err, "nowhere: cannot read the folder"));
    assert_int_equal(run("collect '%s/r'", dir), 1);
    assert_non_null(strstr(err, "r: no frames here"));
}

/* collect's gates judge each frame's metrics section as `mcpost metrics` judges a test:
 * a relMSE threshold between the frames' own values warns for exactly the frames
 * above it; a share of pixels above a FLIP threshold, counted here over each frame's
 * flip_ldr.exr, fails exactly the frames whose share exceeds P (taken from their own
 * counts, so both verdicts are seen); the last line names them; a figure the sections
 * lack is one error naming the frame. */
static void
test_collect_gates(void **state)
{
    (void)state;
    write_job("gates.yaml", "1-4");
    assert_int_equal(run("run '%s/gates.yaml' --quiet", dir), 0);
    double rel[5], share[5];
    for (int f = 1; f <= 4; f++) {
        cJSON *own = read_json("%s/out/gates.yaml/%04d/report.json", dir, f);
        rel[f] = frame_figure(own, "relmse");
        cJSON_Delete(own);
        char path[4300];
        snprintf(path, sizeof path, "%s/out/gates.yaml/%04d/noisy/flip_ldr.exr", dir, f);
        mcp_image *map = NULL;
        assert_int_equal(mcp_image_read(path, NULL, &map), 0);
        long above = 0, n = (long)map->width * map->height;
        for (int y = 0; y < map->height; y++)
            for (int x = 0; x < map->width; x++)
                above += mcp_image_px(map, x, y)[0] > 0.4f;
        share[f] = 100.0 * above / n;
        mcp_image_free(map);
    }
    /* thresholds between the frames' values: the middle of the sorted four */
    double r_sorted[4] = {rel[1], rel[2], rel[3], rel[4]},
           s_sorted[4] = {share[1], share[2], share[3], share[4]};
    for (int i = 0; i < 4; i++)
        for (int j = i + 1; j < 4; j++) {
            if (r_sorted[j] < r_sorted[i]) {
                double t = r_sorted[i];
                r_sorted[i] = r_sorted[j];
                r_sorted[j] = t;
            }
            if (s_sorted[j] < s_sorted[i]) {
                double t = s_sorted[i];
                s_sorted[i] = s_sorted[j];
                s_sorted[j] = t;
            }
        }
    double r_cut = 0.5 * (r_sorted[1] + r_sorted[2]),
           s_cut = 0.5 * (s_sorted[1] + s_sorted[2]);
    assert_true(r_sorted[1] < r_sorted[2]);
    assert_true(s_sorted[1] < s_sorted[2]);
    assert_int_equal(
        run("collect '%s/out/gates.yaml' --quiet --warn 'relmse > %.9g'", dir, r_cut), 3);
    char want[512];
    int len = snprintf(want, sizeof want, "WARNING");
    for (int f = 1, shown = 0; f <= 4; f++)
        if (rel[f] > r_cut)
            len += snprintf(want + len, sizeof want - len,
                            "%s frame %d: noisy: relmse > %g (%.6g)", shown++ ? ";" : ":",
                            f, r_cut, rel[f]);
    assert_string_equal(out, (strcat(want, "\n"), want));
    /* a failure outranks it: only the failing frames are named */
    assert_int_equal(run("collect '%s/out/gates.yaml' --quiet --warn 'relmse > %.9g' "
                         "--fail-percent 'flip_ldr 0.4 %.9g'",
                         dir, r_cut, s_cut),
                     4);
    cJSON *rep = read_json("%s/out/gates.yaml/report.json", dir);
    cJSON *sec = cJSON_GetArrayItem(cJSON_GetObjectItem(rep, "sections"), 0), *f;
    cJSON_ArrayForEach(f, cJSON_GetObjectItem(sec, "frame_list"))
    {
        int n = cJSON_GetObjectItem(f, "frame")->valueint;
        const char *g = cJSON_GetObjectItem(f, "gate")->valuestring;
        assert_string_equal(g, share[n] > s_cut ? "failure"
                               : rel[n] > r_cut ? "warning"
                                                : "pass");
        snprintf(want, sizeof want, "frame %d: noisy: flip_ldr > 0.4 on more than", n);
        assert_true((strstr(out, want) != NULL) == (share[n] > s_cut));
    }
    assert_string_equal(
        cJSON_GetObjectItem(cJSON_GetObjectItem(sec, "verdict"), "level")->valuestring,
        "bad");
    cJSON_Delete(rep);
    /* every frame within bounds: PASS and 0 */
    assert_int_equal(
        run("collect '%s/out/gates.yaml' --quiet --fail 'relmse > 1e9'", dir), 0);
    assert_string_equal(out, "PASS\n");
    /* a figure no section has: exit 1, naming the frame */
    assert_int_equal(
        run("collect '%s/out/gates.yaml' --quiet --fail 'flip_ldr.median > 0.1'", dir),
        1);
    assert_non_null(strstr(
        err, "frame 1, metrics of noisy: --fail 'flip_ldr.median > 0.1': no figure"));
    assert_int_equal(run("collect '%s/out/gates.yaml' --fail-percent 'flip 1 2'", dir),
                     2);
}

/* A series with both tokens: '#' (or the first %d) is the frame, the other the spp. */
/* A mistake every frame shares (a misspelt key) is one error before any frame starts,
 * from run and from submit: no frame's error.txt, no output folder, no Slurm script. */
static void
test_a_shared_mistake_stops_the_shot_before_its_frames(void **state)
{
    (void)state;
    char path[4200];
    snprintf(path, sizeof path, "%s/typo.yaml", dir);
    mcp_test_write_text(
        path, "frames: 1-4\n"
              "inputs:\n"
              "  noisy: {dump: r/shot_####_0000.exr}\n"
              "  reference: {image: r/shot_%04d_truth.exr}\n"
              "output: out/typo\n"
              "stages:\n"
              "  - metrics: {input: noisy, reference: reference, flp: [ldr]}\n");
    const char *cmds[] = {"run '%s' -j 2", "submit '%s' --slurm --dry-run"};
    for (int i = 0; i < 2; i++) {
        assert_int_equal(run(cmds[i], path), 1);
        assert_non_null(strstr(err, "typo.yaml:7: unknown key 'flp' in stage 'metrics'"));
        assert_null(strstr(err, "mcpost: frame ")); /* not a frame's failure */
        assert_null(strstr(err, "frames failed"));
        assert_int_equal((int)(strchr(err, '\n') - err), (int)strlen(err) - 1);
        assert_false(exists("%s/out/typo", dir));
    }
}

static void
test_series_pattern_holds_frame_and_spp(void **state)
{
    (void)state;
    /* frames 1 and 2 at 4 and 8 spp: the 4-spp member is the frame's own render; frame
     * 2 lacks its 8-spp file */
    for (int f = 1; f <= 2; f++)
        sh("cp '%s/r/shot_%04d_0000.exr' '%s/r/ser_%04d_spp0004.exr'", dir, f, dir, f);
    sh("cp '%s/r/shot_0003_0000.exr' '%s/r/ser_0001_spp0008.exr'", dir, dir);
    const char *patterns[] = {"r/ser_####_spp%04d.exr", "r/ser_%04d_spp%04d.exr"};
    for (int p = 0; p < 2; p++) {
        char path[4200], text[2048];
        snprintf(path, sizeof path, "%s/series%d.yaml", dir, p);
        snprintf(text, sizeof text,
                 "frames: 1-2\n"
                 "inputs:\n"
                 "  progress: {series: \"%s\", spp: [4, 8]}\n"
                 "  noisy: {dump: r/shot_####_0000.exr}\n"
                 "  reference: {image: r/shot_####_truth.exr}\n"
                 "stages:\n"
                 "  - metrics: {input: noisy, reference: reference, series: progress}\n",
                 patterns[p]);
        mcp_test_write_text(path, text);
        assert_int_equal(run("run '%s' --check", path), 1);
        assert_non_null(strstr(err, "frame 2: "));
        assert_non_null(strstr(err, "ser_0002_spp0008.exr"));
        assert_int_equal(run("run '%s' --frames 1 --force -q", path), 0);
        cJSON *rep = read_json("%s/out/series%d/0001/report.json", dir, p), *sec, *t;
        double mse4 = NAN;
        cJSON_ArrayForEach(sec, cJSON_GetObjectItem(rep, "sections"))
            cJSON_ArrayForEach(t, cJSON_GetObjectItem(sec, "tables"))
        {
            cJSON *row = cJSON_GetArrayItem(cJSON_GetObjectItem(t, "rows"), 0);
            if (!strcmp(cJSON_GetObjectItem(t, "title")->valuestring,
                        "error against the reference per sample count") &&
                cJSON_GetArrayItem(row, 0)->valueint == 4)
                mse4 = cJSON_GetArrayItem(row, 1)->valuedouble;
        }
        /* frame 1's 4-spp member is frame 1's render, against frame 1's truth */
        assert_close(mse4, recomputed_mse(1), 1e-6, 0);
        cJSON_Delete(rep);
    }
}

static void
test_submit_writes_an_array_job_and_its_collect_job(void **state)
{
    (void)state;
    write_job("sub.yaml", "1-4,10");
    char job[4200], outdir[4200];
    snprintf(job, sizeof job, "%s/sub.yaml", dir);
    snprintf(outdir, sizeof outdir, "%s/out/sub.yaml", dir);
    assert_int_equal(run("submit '%s' --slurm --dry-run --partition cpu --time 1:00:00 "
                         "--cpus-per-task 3 --array-parallel 2",
                         job),
                     0);
    assert_non_null(strstr(out, "5 array tasks"));
    char *s = mcp_test_read_text(
        (snprintf(out, sizeof out, "%s/slurm/frames.sbatch", outdir), out));
    assert_non_null(strstr(s, "#SBATCH --array=1-4,10%2\n"));
    assert_non_null(strstr(s, "#SBATCH --partition=cpu\n"));
    assert_non_null(strstr(s, "#SBATCH --time=1:00:00\n"));
    assert_non_null(strstr(s, "#SBATCH --cpus-per-task=3\n"));
    assert_non_null(strstr(s, "export OMP_NUM_THREADS=${SLURM_CPUS_PER_TASK:-1}\n"));
    char want[8192];
    snprintf(want, sizeof want, "run '%s' --frames \"$SLURM_ARRAY_TASK_ID\" --quiet\n",
             job);
    assert_non_null(strstr(s, want));
    free(s);
    s = mcp_test_read_text(
        (snprintf(out, sizeof out, "%s/slurm/collect.sbatch", outdir), out));
    snprintf(want, sizeof want, "collect '%s'\n", outdir);
    assert_non_null(strstr(s, want));
    free(s);

    /* chunks: task i runs chunk i */
    assert_int_equal(run("submit '%s' --slurm --dry-run --chunk 3", job), 0);
    s = mcp_test_read_text(
        (snprintf(out, sizeof out, "%s/slurm/frames.sbatch", outdir), out));
    assert_non_null(strstr(s, "#SBATCH --array=0-1\n"));
    assert_non_null(strstr(s, "FRAMES=(\"1-3\" \"4,10\")\n"));
    assert_non_null(strstr(s, "--frames \"${FRAMES[$SLURM_ARRAY_TASK_ID]}\""));
    free(s);

    /* submission, through a stand-in sbatch that logs its arguments */
    char bin[4200];
    snprintf(bin, sizeof bin, "%s/fakebin", dir);
    sh("mkdir -p '%s' && printf '#!/bin/sh\\necho \"$*\" >> \"%s/sbatch.log\"\\n"
       "n=$(wc -l < \"%s/sbatch.log\"); echo $((41 + n))\\n' > '%s/sbatch' && "
       "chmod +x '%s/sbatch' && rm -f '%s/sbatch.log'",
       bin, bin, bin, bin, bin, bin);
    assert_int_equal(run("run '%s' --frames 1-2 -q", job), 0); /* 2 complete already */
    char args[8192];
    snprintf(args, sizeof args, "submit '%s' --slurm", job);
    char cmd[8400];
    snprintf(cmd, sizeof cmd, "PATH='%s':\"$PATH\" '%s' %s > '%s/submit.out' 2>&1", bin,
             MCP_TEST_MCPOST, args, dir);
    assert_int_equal(system(cmd), 0);
    char *printed =
        mcp_test_read_text((snprintf(out, sizeof out, "%s/submit.out", dir), out));
    assert_non_null(strstr(printed, "submitted job 42: 3 array tasks for 3 frames"));
    assert_non_null(strstr(printed, "submitted job 43: mcpost collect"));
    free(printed);
    char *log =
        mcp_test_read_text((snprintf(out, sizeof out, "%s/sbatch.log", bin), out));
    snprintf(want, sizeof want, "--parsable %s/slurm/frames.sbatch\n", outdir);
    assert_non_null(strstr(log, want));
    snprintf(want, sizeof want,
             "--parsable --dependency=afterany:42 %s/slurm/collect.sbatch\n", outdir);
    assert_non_null(strstr(log, want));
    free(log);
    s = mcp_test_read_text(
        (snprintf(out, sizeof out, "%s/slurm/frames.sbatch", outdir), out));
    assert_non_null(strstr(s, "#SBATCH --array=3-4,10\n")); /* 1 and 2 were complete */
    free(s);

    /* errors */
    assert_int_equal(run("submit '%s'", job), 2);
    assert_non_null(strstr(err, "--slurm"));
    assert_int_equal(run("submit '%s' --slurm --chunk 0", job), 2);
    assert_int_equal(run("submit '%s' --slurm --frames 11", job), 1);
    assert_non_null(strstr(err, "frame 11 is not among"));
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_run_frames_in_parallel_and_resume),
        cmocka_unit_test(test_a_failed_frame_is_listed_by_run_and_collect),
        cmocka_unit_test(test_collect_gates),
        cmocka_unit_test(test_a_shared_mistake_stops_the_shot_before_its_frames),
        cmocka_unit_test(test_series_pattern_holds_frame_and_spp),
        cmocka_unit_test(test_submit_writes_an_array_job_and_its_collect_job),
    };
    return cmocka_run_group_tests(tests, setup, NULL);
}
