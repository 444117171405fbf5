/* shot.c: the frames of a job for `mcpost run`, `submit` and `collect` (shot.h):
 * choosing frames, skipping complete ones, running the rest in N processes. Each
 * frame is one call of mcp_job_run_file with its frame set, the same work as
 * `mcpost run JOB --frames F` on any machine: processes here, array tasks on Slurm. */
#define _XOPEN_SOURCE 700 /* realpath */
#include "shot.h"

#include "cli.h"

#include <mcpost/frames.h>
#include <mcpost/imageio.h>
#include <mcpost/progress.h>

#include <errno.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

int
mcp_cli_shot_open(const char *job, const char *output, const char *select,
                  mcp_cli_shot *s)
{
    memset(s, 0, sizeof *s);
    mcp_job_options jo = mcp_job_defaults();
    jo.output_dir = output;
    if (!(s->job = realpath(job, NULL))) return mcp_error("%s: %s", job, strerror(errno));
    /* the real path: output folders then come out absolute, for scripts run elsewhere */
    if (mcp_job_frames(s->job, &jo, &s->all, &s->n_all, &s->output_dir)) goto fail;
    /* a frame job's settings are the same for every frame: a bad key is one error
       now, not one per frame (or one Slurm task per frame) later */
    if (s->n_all && mcp_job_check_settings(s->job, mcp_job_stages())) goto fail;
    if (s->output_dir[0] != '/') { /* --output relative to here */
        char cwd[4096], *abs = NULL;
        size_t n = strlen(s->output_dir) + sizeof cwd + 2;
        if (!getcwd(cwd, sizeof cwd)) {
            mcp_error("cannot tell the current folder: %s", strerror(errno));
            goto fail;
        }
        if (!(abs = mcp_malloc(n))) goto fail;
        snprintf(abs, n, "%s/%s", cwd, s->output_dir);
        free(s->output_dir);
        s->output_dir = abs;
    }
    if (!select) {
        if (s->n_all && !(s->chosen = mcp_calloc((size_t)s->n_all, sizeof *s->chosen)))
            goto fail;
        if (s->n_all) memcpy(s->chosen, s->all, (size_t)s->n_all * sizeof *s->chosen);
        s->n_chosen = s->n_all;
        return 0;
    }
    if (!s->n_all) {
        mcp_error("%s: --frames given, but the job has no frames:", job);
        goto fail;
    }
    if (mcp_frames_parse(select, &s->chosen, &s->n_chosen)) {
        mcp_error_prefix("--frames: ");
        goto fail;
    }
    for (int i = 0; i < s->n_chosen; i++)
        if (!mcp_frames_contains(s->all, s->n_all, s->chosen[i])) {
            char set[256];
            if (mcp_frames_format(s->all, s->n_all, set, sizeof set))
                snprintf(set, sizeof set, "%d frames", s->n_all);
            mcp_error("--frames: frame %d is not among the frames of %s (%s)",
                      s->chosen[i], job, set);
            goto fail;
        }
    return 0;
fail:
    mcp_cli_shot_free(s);
    return -1;
}

void
mcp_cli_shot_free(mcp_cli_shot *s)
{
    free(s->job);
    free(s->all);
    free(s->chosen);
    free(s->output_dir);
    memset(s, 0, sizeof *s);
}

int
mcp_cli_shot_write_manifest(mcp_cli_shot *s)
{
    cJSON *m = cJSON_CreateObject(), *list = cJSON_CreateIntArray(s->all, s->n_all);
    char path[4200], *text = NULL;
    int rc = -1;
    if (!m || !list || !cJSON_AddStringToObject(m, "job", s->job) ||
        !cJSON_AddItemToObject(m, "frames", list)) {
        cJSON_Delete(list);
        mcp_error("out of memory");
        goto done;
    }
    if (!(text = cJSON_Print(m))) {
        mcp_error("out of memory");
        goto done;
    }
    snprintf(path, sizeof path, "%s/frames.json", s->output_dir);
    rc = mcp_make_dirs(s->output_dir) || mcp_write_file_atomic(path, text, strlen(text))
             ? -1
             : 0;
    char *real = rc ? NULL : realpath(s->output_dir, NULL);
    if (real) {
        free(s->output_dir);
        s->output_dir = real;
    }
done:
    cJSON_Delete(m);
    free(text);
    return rc;
}

/* One frame, in this process. On failure its message also goes to the frame's
 * error.txt, for collect; a success removes an old one. */
static int
run_frame(const mcp_cli_shot *s, const mcp_job_options *jo, int frame)
{
    mcp_job_options o = *jo;
    o.frame = frame;
    char dir[4096], err_path[4200];
    if (mcp_frame_dir(s->output_dir, frame, dir, sizeof dir)) return -1;
    snprintf(err_path, sizeof err_path, "%s/error.txt", dir);
    unlink(err_path);
    /* a run of this frame killed outright (SIGKILL, a node lost) left its temporaries */
    int stale = mcp_frame_clear_temporaries(dir);
    if (stale > 0) mcp_note("frame %d: removed %d stale temporary files", frame, stale);
    if (mcp_job_run_file(s->job, mcp_job_stages(), &o) == 0) return 0;
    mcp_error_prefix("frame %d: ", frame);
    char message[1100];
    snprintf(message, sizeof message, "%s\n", mcp_error_message());
    /* a frame run again (--force) that failed keeps its earlier complete folder
       (common/io/outdir.c): it is complete, not failed, and gets no error.txt */
    if (!mcp_frame_complete(s->output_dir, frame) && !mcp_make_dirs(dir))
        mcp_write_file_atomic(err_path, message, strlen(message));
    fprintf(stderr, "mcpost: %s", message);
    return -1;
}

/* The frames to run: the chosen ones, less the complete ones unless forced. */
static int
frames_to_run(const mcp_cli_shot *s, int force, int **todo, int *n_todo)
{
    *n_todo = 0;
    if (!(*todo = mcp_calloc((size_t)s->n_chosen + 1, sizeof **todo))) return -1;
    for (int i = 0; i < s->n_chosen; i++)
        if (force || !mcp_frame_complete(s->output_dir, s->chosen[i]))
            (*todo)[(*n_todo)++] = s->chosen[i];
    return 0;
}

int
mcp_cli_shot_run(const mcp_cli_shot *s, const mcp_job_options *jo, int jobs, int force)
{
    int *todo, n_todo, n_failed = 0, first_failed[8];
    /* what runs of these frames killed outright left: their hidden folders
       (.0017.tmp-PID, common/io/outdir.c), a complete frame's too (killed in --force) */
    for (int i = 0; i < s->n_chosen; i++) {
        char base[32];
        snprintf(base, sizeof base, "%04d", s->chosen[i]);
        mcp__outdir_clear_stale(s->output_dir, base);
    }
    if (frames_to_run(s, force, &todo, &n_todo)) return -1;
    int skipped = s->n_chosen - n_todo;
    if (skipped)
        mcp_note("%d of %d frames already complete, skipped (--force runs them again)",
                 skipped, s->n_chosen);
    if (!n_todo) {
        free(todo);
        mcp_note("nothing to run; mcpost collect %s gathers the frames", s->output_dir);
        return 0;
    }
    if (jobs > n_todo) jobs = n_todo;
    if (jobs == 1) {
        for (int i = 0; i < n_todo; i++) {
            mcp_note("frame %d (%d of %d)", todo[i], i + 1, n_todo);
            if (run_frame(s, jo, todo[i]) && n_failed++ < 8)
                first_failed[n_failed - 1] = todo[i];
        }
    } else {
        /* one process per frame, `jobs` at a time, each with its share of the cores
         * (unless OMP_NUM_THREADS says otherwise); only the progress of the whole set
         * shows, and each failure as one line */
        pid_t *pids = mcp_calloc((size_t)jobs, sizeof *pids);
        int *slot_frame = mcp_calloc((size_t)jobs, sizeof *slot_frame);
        if (!pids || !slot_frame) {
            free(pids), free(slot_frame), free(todo);
            return -1;
        }
        mcp_progress p;
        mcp_progress_begin(&p, "frames", n_todo);
        int next = 0, running = 0, finished = 0;
        while (next < n_todo || running) {
            while (running < jobs && next < n_todo) {
                int slot = 0;
                while (pids[slot])
                    slot++;
                fflush(NULL);
                pid_t pid = fork();
                if (pid < 0) {
                    fprintf(stderr, "mcpost: frame %d: cannot start a process: %s\n",
                            todo[next], strerror(errno));
                    if (n_failed++ < 8) first_failed[n_failed - 1] = todo[next];
                    next++, finished++;
                    continue;
                }
                if (pid == 0) {
                    mcp_progress_set_quiet(1);
                    if (!getenv("OMP_NUM_THREADS")) {
                        int share = omp_get_num_procs() / jobs;
                        omp_set_num_threads(share > 0 ? share : 1);
                    }
                    int rc = run_frame(s, jo, todo[next]);
                    fflush(NULL);
                    _exit(rc ? 1 : 0);
                }
                pids[slot] = pid, slot_frame[slot] = todo[next++];
                running++;
            }
            if (!running) break;
            int status;
            pid_t done = wait(&status);
            if (done < 0) {
                if (errno == EINTR) continue;
                break;
            }
            for (int k = 0; k < jobs; k++)
                if (pids[k] == done) {
                    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
                        if (WIFSIGNALED(status))
                            fprintf(stderr, "mcpost: frame %d: killed by signal %d\n",
                                    slot_frame[k], WTERMSIG(status));
                        if (n_failed++ < 8) first_failed[n_failed - 1] = slot_frame[k];
                    }
                    pids[k] = 0;
                    running--, finished++;
                    mcp_progress_update(&p, finished);
                }
        }
        mcp_progress_end(&p);
        free(pids);
        free(slot_frame);
    }
    free(todo);
    if (n_failed) {
        char list[128] = "";
        size_t len = 0;
        for (int i = 0; i < n_failed && i < 8; i++)
            len += (size_t)snprintf(list + len, sizeof list - len, "%s%d", i ? ", " : "",
                                    first_failed[i]);
        return mcp_error("%d of %d frames failed (%s%s); their messages are in %s/FRAME/"
                         "error.txt; running the job again retries them",
                         n_failed, n_todo, list, n_failed > 8 ? ", ..." : "",
                         s->output_dir);
    }
    mcp_note("%d frames run, results in %s (mcpost collect %s gathers them)", n_todo,
             s->output_dir, s->output_dir);
    return 0;
}
