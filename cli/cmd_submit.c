/* cmd_submit.c: `mcpost submit JOB.yaml --slurm` -- a job's frames as a Slurm job array.
 *
 * No scheduler of our own: the command writes an sbatch script whose array tasks each
 * run `mcpost run JOB --frames $SLURM_ARRAY_TASK_ID` (or a chunk of frames), submits it
 * with sbatch, and submits `mcpost collect` as a job that starts after the array
 * (afterany: it also runs when frames failed, and lists them). The per-frame command
 * is the whole contract, so any other scheduler runs the same (docs/frames.md). */
#define _XOPEN_SOURCE 700 /* readlink */
#include "cli.h"
#include "shot.h"

#include <mcpost/frames.h>
#include <mcpost/imageio.h>
#include <mcpost/progress.h>

#include <errno.h>
#include <getopt.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

static const char usage[] =
    "usage: mcpost submit JOB.yaml --slurm [--partition P] [--time T]\n"
    "                     [--cpus-per-task C] [--array-parallel N] [--chunk K]\n"
    "                     [--frames SET] [--force] [--output DIR] [--dry-run]\n"
    "  Runs a job's frames on a Slurm cluster: writes OUTPUT/slurm/frames.sbatch, an\n"
    "  array job with one task per frame (or per chunk of K frames) that runs\n"
    "  `mcpost run JOB.yaml --frames $SLURM_ARRAY_TASK_ID`, and "
    "OUTPUT/slurm/collect.sbatch,\n"
    "  which runs `mcpost collect OUTPUT` after the array; submits both with sbatch and\n"
    "  prints their job ids. Frames already complete are left out (--force: not).\n"
    "  --partition P         sbatch --partition\n"
    "  --time T              sbatch --time, per task (e.g. 1:00:00)\n"
    "  --cpus-per-task C     cores per task; OMP_NUM_THREADS is set to it [1]\n"
    "  --array-parallel N    at most N tasks at once (--array=...%N)\n"
    "  --chunk K             K frames per array task [1]\n"
    "  --frames SET          only these of the job's frames\n"
    "  --dry-run             write the scripts and print the sbatch commands; submit "
    "nothing\n"
    "  On a cluster: mcpost submit shot.yaml --slurm --partition cpu --time 2:00:00\n"
    "  --cpus-per-task 8 --array-parallel 50\n"
    "\n"
    "examples (from the source folder, on the sample renders; --dry-run submits "
    "nothing):\n"
    "  mcpost submit samples/jobs/shot.yaml --slurm --dry-run --force\n"
    "  mcpost submit samples/jobs/shot.yaml --slurm --chunk 2 --cpus-per-task 2 "
    "--dry-run --force\n";

typedef struct submit_opts {
    const char *partition, *time, *output, *frames;
    int cpus, parallel, chunk, force, dry_run, slurm;
} submit_opts;

/* s in single quotes for /bin/sh (a ' becomes '\''), appended to buf. */
static int
shell_quote(const char *s, char *buf, size_t cap)
{
    size_t len = strlen(buf);
    if (len + 1 >= cap) return mcp_error("command too long");
    buf[len++] = '\'';
    for (; *s; s++) {
        const char *piece = *s == '\'' ? "'\\''" : NULL;
        size_t n = piece ? 4 : 1;
        if (len + n + 2 >= cap) return mcp_error("command too long");
        memcpy(buf + len, piece ? piece : s, n);
        len += n;
    }
    buf[len++] = '\'';
    buf[len] = '\0';
    return 0;
}

/* The sbatch settings must stay on their own #SBATCH line. */
static int
check_setting(const char *flag, const char *v)
{
    if (v && strpbrk(v, "\n\r")) return mcp_error("%s: a line break in the value", flag);
    return 0;
}

/* This program's own path, for the scripts (the nodes run the same build). */
static int
self_path(char *buf, size_t cap)
{
    ssize_t n = readlink("/proc/self/exe", buf, cap - 1);
    if (n <= 0)
        return mcp_error("cannot find the mcpost executable (/proc/self/exe): %s",
                         strerror(errno));
    buf[n] = '\0';
    return 0;
}

/* Runs argv, its stdout into out (trimmed); fails with its stderr's last words. */
static int
run_capture(char *const argv[], char *out, size_t cap)
{
    int fd[2];
    if (pipe(fd)) return mcp_error("pipe: %s", strerror(errno));
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0) {
        close(fd[0]), close(fd[1]);
        return mcp_error("cannot start %s: %s", argv[0], strerror(errno));
    }
    if (pid == 0) {
        dup2(fd[1], 1);
        close(fd[0]), close(fd[1]);
        execvp(argv[0], argv);
        fprintf(stderr, "mcpost: cannot run %s: %s\n", argv[0], strerror(errno));
        _exit(127);
    }
    close(fd[1]);
    size_t len = 0;
    ssize_t n;
    while ((n = read(fd[0], out + len, cap - 1 - len)) > 0)
        if ((len += (size_t)n) == cap - 1) break;
    close(fd[0]);
    out[len] = '\0';
    while (len && (out[len - 1] == '\n' || out[len - 1] == ' '))
        out[--len] = '\0';
    int status;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR)
        ;
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
        return mcp_error("%s failed (exit status %d): is Slurm installed and its "
                         "controller reachable?",
                         argv[0], WIFEXITED(status) ? WEXITSTATUS(status) : -1);
    return 0;
}

static int append(char *buf, size_t cap, const char *fmt, ...) MCP_PRINTF(3, 4);
static int
append(char *buf, size_t cap, const char *fmt, ...)
{
    size_t len = strlen(buf);
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(buf + len, cap - len, fmt, ap);
    va_end(ap);
    if (n < 0 || (size_t)n >= cap - len) return mcp_error("sbatch script too long");
    return 0;
}

/* The array script. Task ids are the frame numbers when each task runs one frame and
 * they fit Slurm's default MaxArraySize (1001); otherwise task i runs chunk i, named in
 * the script. */
static int
array_script(const submit_opts *o, const mcp_cli_shot *s, const int *todo, int n_todo,
             const char *self, const char *log_dir, char *script, size_t cap, int *tasks)
{
    int direct = o->chunk == 1 && todo[n_todo - 1] <= 1000;
    int n_chunks = (n_todo + o->chunk - 1) / o->chunk;
    char array[8192] = "", set[8192];
    if (direct) {
        if (mcp_frames_format(todo, n_todo, array, sizeof array)) return -1;
    } else {
        snprintf(array, sizeof array, "0-%d", n_chunks - 1);
    }
    if (o->parallel > 0) append(array, sizeof array, "%%%d", o->parallel);
    script[0] = '\0';
    char cmd[16384] = "";
    if (shell_quote(self, cmd, sizeof cmd) || append(cmd, sizeof cmd, " run ") ||
        shell_quote(s->job, cmd, sizeof cmd) ||
        append(cmd, sizeof cmd, " --frames \"%s\" --quiet%s",
               direct ? "$SLURM_ARRAY_TASK_ID" : "${FRAMES[$SLURM_ARRAY_TASK_ID]}",
               o->force ? " --force" : ""))
        return -1;
    if (o->output && (append(cmd, sizeof cmd, " --output ") ||
                      shell_quote(s->output_dir, cmd, sizeof cmd)))
        return -1;
    if (append(script, cap,
               "#!/bin/bash\n"
               "# written by mcpost submit: one array task per %s of %s\n"
               "#SBATCH --job-name=mcpost-frames\n"
               "#SBATCH --array=%s\n"
               "#SBATCH --output=%s/frames-%%A_%%a.log\n",
               o->chunk == 1 ? "frame" : "chunk of frames", s->job, array, log_dir))
        return -1;
    if (o->partition && append(script, cap, "#SBATCH --partition=%s\n", o->partition))
        return -1;
    if (o->time && append(script, cap, "#SBATCH --time=%s\n", o->time)) return -1;
    if (o->cpus > 0 && append(script, cap, "#SBATCH --cpus-per-task=%d\n", o->cpus))
        return -1;
    if (append(script, cap,
               "set -eu\n"
               "# OpenMP takes the task's cores, not the node's\n"
               "export OMP_NUM_THREADS=${SLURM_CPUS_PER_TASK:-1}\n"))
        return -1;
    if (!direct) {
        if (append(script, cap, "FRAMES=(")) return -1;
        for (int c = 0; c < n_chunks; c++) {
            int first = c * o->chunk,
                n = n_todo - first < o->chunk ? n_todo - first : o->chunk;
            if (mcp_frames_format(todo + first, n, set, sizeof set) ||
                append(script, cap, "%s\"%s\"", c ? " " : "", set))
                return -1;
        }
        if (append(script, cap, ")\n")) return -1;
    }
    *tasks = direct ? n_todo : n_chunks;
    return append(script, cap, "exec %s\n", cmd);
}

static int
collect_script(const submit_opts *o, const mcp_cli_shot *s, const char *self,
               const char *log_dir, char *script, size_t cap)
{
    char cmd[8192] = "";
    script[0] = '\0';
    if (shell_quote(self, cmd, sizeof cmd) || append(cmd, sizeof cmd, " collect ") ||
        shell_quote(s->output_dir, cmd, sizeof cmd) ||
        append(script, cap,
               "#!/bin/bash\n"
               "# written by mcpost submit: gathers the frames' reports after the array\n"
               "#SBATCH --job-name=mcpost-collect\n"
               "#SBATCH --output=%s/collect-%%j.log\n",
               log_dir))
        return -1;
    if (o->partition && append(script, cap, "#SBATCH --partition=%s\n", o->partition))
        return -1;
    return append(script, cap, "exec %s\n", cmd);
}

static int
submit(const submit_opts *o, const char *job)
{
    mcp_cli_shot s;
    int rc = -1, *todo = NULL, n_todo = 0, tasks = 0;
    char self[4096], log_dir[4200], frames_path[4300], collect_path[4300];
    static char script[1 << 20];
    if (mcp_cli_shot_open(job, o->output, o->frames, &s)) return -1;
    if (!s.n_all) {
        mcp_error("%s: the job has no frames: (submit runs frame jobs; mcpost run runs "
                  "this one)",
                  job);
        goto done;
    }
    if (!(todo = mcp_calloc((size_t)s.n_chosen, sizeof *todo))) goto done;
    for (int i = 0; i < s.n_chosen; i++)
        if (o->force || !mcp_frame_complete(s.output_dir, s.chosen[i]))
            todo[n_todo++] = s.chosen[i];
    if (!n_todo) {
        printf("all %d frames are complete: nothing to submit (--force runs them again; "
               "mcpost collect %s gathers them)\n",
               s.n_chosen, s.output_dir);
        rc = 0;
        goto done;
    }
    snprintf(log_dir, sizeof log_dir, "%s/slurm", s.output_dir);
    snprintf(frames_path, sizeof frames_path, "%s/frames.sbatch", log_dir);
    snprintf(collect_path, sizeof collect_path, "%s/collect.sbatch", log_dir);
    if (self_path(self, sizeof self) || mcp_cli_shot_write_manifest(&s) ||
        (mkdir(log_dir, 0777) != 0 && errno != EEXIST &&
         mcp_error("%s: cannot create folder: %s", log_dir, strerror(errno))) ||
        array_script(o, &s, todo, n_todo, self, log_dir, script, sizeof script, &tasks) ||
        mcp_write_file_atomic(frames_path, script, strlen(script)) ||
        collect_script(o, &s, self, log_dir, script, sizeof script) ||
        mcp_write_file_atomic(collect_path, script, strlen(script)))
        goto done;
    if (o->dry_run) {
        printf("wrote %s (%d array tasks, %d frames) and %s\n", frames_path, tasks,
               n_todo, collect_path);
        printf("would run: sbatch --parsable %s\n", frames_path);
        printf("           sbatch --parsable --dependency=afterany:JOBID %s\n",
               collect_path);
        rc = 0;
        goto done;
    }
    char array_id[256], collect_id[256], dep[300];
    char *argv1[] = {"sbatch", "--parsable", frames_path, NULL};
    if (run_capture(argv1, array_id, sizeof array_id)) goto done;
    /* --parsable prints "JOBID" or "JOBID;CLUSTER" */
    array_id[strcspn(array_id, ";\n")] = '\0';
    snprintf(dep, sizeof dep, "--dependency=afterany:%s", array_id);
    char *argv2[] = {"sbatch", "--parsable", dep, collect_path, NULL};
    if (run_capture(argv2, collect_id, sizeof collect_id)) {
        mcp_error_prefix("array job %s submitted, but its collect job not: ", array_id);
        goto done;
    }
    collect_id[strcspn(collect_id, ";\n")] = '\0';
    printf("submitted job %s: %d array tasks for %d frames (script %s)\n", array_id,
           tasks, n_todo, frames_path);
    printf("submitted job %s: mcpost collect %s, after job %s\n", collect_id,
           s.output_dir, array_id);
    rc = 0;
done:
    free(todo);
    mcp_cli_shot_free(&s);
    return rc;
}

static int
cmd_submit(int argc, char **argv)
{
    static const struct option longs[] = {{"slurm", no_argument, 0, 'S'},
                                          {"partition", required_argument, 0, 'p'},
                                          {"time", required_argument, 0, 't'},
                                          {"cpus-per-task", required_argument, 0, 'c'},
                                          {"array-parallel", required_argument, 0, 'P'},
                                          {"chunk", required_argument, 0, 'k'},
                                          {"frames", required_argument, 0, 'f'},
                                          {"force", no_argument, 0, 'F'},
                                          {"output", required_argument, 0, 'o'},
                                          {"dry-run", no_argument, 0, 'n'},
                                          {"help", no_argument, 0, 'h'},
                                          {0, 0, 0, 0}};
    submit_opts o = {.chunk = 1};
    int opt;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "o:h", longs, NULL)) != -1) {
        int *count = NULL;
        const char *flag = NULL;
        switch (opt) {
        case 'S':
            o.slurm = 1;
            break;
        case 'p':
            o.partition = optarg;
            break;
        case 't':
            o.time = optarg;
            break;
        case 'c':
            count = &o.cpus, flag = "--cpus-per-task";
            break;
        case 'P':
            count = &o.parallel, flag = "--array-parallel";
            break;
        case 'k':
            count = &o.chunk, flag = "--chunk";
            break;
        case 'f':
            o.frames = optarg;
            break;
        case 'F':
            o.force = 1;
            break;
        case 'o':
            o.output = optarg;
            break;
        case 'n':
            o.dry_run = 1;
            break;
        case 'h':
            fputs(usage, stdout);
            return 0;
        default:
            return mcp_cli_usage("submit", "bad option");
        }
        if (count && (mcp__parse_int(flag, optarg, count) || *count < 1))
            return mcp_cli_usage("submit", "%s takes a count >= 1 (got '%s')", flag,
                                 optarg);
    }
    if (argc - optind != 1) return mcp_cli_usage("submit", "give one job file");
    if (!o.slurm)
        return mcp_cli_usage("submit", "name the scheduler: --slurm (the only one for "
                                       "now; docs/frames.md says how others run frames)");
    if (check_setting("--partition", o.partition) || check_setting("--time", o.time))
        return mcp_cli_usage("submit", "%s", mcp_error_message());
    return submit(&o, argv[optind]) ? mcp_cli_fail() : 0;
}

const mcp_command mcp_command_submit = {"submit", "run a frame job on a Slurm cluster",
                                        cmd_submit, 0};
