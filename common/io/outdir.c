/* outdir.c: output folders that appear whole (docs/conventions.md, "Output folders").
 *
 * A command that writes a folder (estimate -o, blend -o, perceptual -o, compare -o,
 * metrics -o, adaptive -o, and the job runner's output: folder, a frame's folder of a
 * shot) writes it under a hidden temporary name beside it, ".NAME.tmp-PID", and renames
 * it into place once every file is written. A failed command removes its temporary
 * folder; one stopped by SIGINT, SIGTERM or SIGHUP removes it in the signal handler;
 * one killed outright (SIGKILL, a crash) leaves it, hidden, and the next command that
 * writes a folder beside it removes it (its process is gone). So DIR is either absent,
 * the old complete folder or the new complete one, never a half-written one.
 *
 * A rerun onto an existing DIR replaces it: the new folder and the old one swap names
 * in one step (renameat2 RENAME_EXCHANGE; where the file system lacks it, the old one
 * is renamed away first), then the old one is removed. Only a folder that mcpost made
 * (it holds report.json, metrics.json or adaptive.json), an empty one, or one that is
 * mcpost's by its place (a frame's folder in a shot's output) is replaced; any other is
 * refused, so that `-o ~/renders` cannot delete someone's files.
 *
 * The signal handler also removes the scratch folders in flight that no command outputs
 * (an external denoiser's files: mcp__scratch_dir_begin / _end). */
#define _GNU_SOURCE /* renameat2, nftw's FTW_DEPTH */
#include "internal.h"

#include <mcpost/progress.h>

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <ftw.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---- removing a folder tree ---- */

static int
remove_one(const char *path, const struct stat *st, int type, struct FTW *ftw)
{
    (void)st;
    (void)ftw;
    if (type == FTW_DP)
        rmdir(path);
    else
        unlink(path);
    return 0;
}

static void
remove_tree(const char *path)
{
    nftw(path, remove_one, 16, FTW_DEPTH | FTW_PHYS);
}

/* The same with async-signal-safe calls only (openat, getdents64, unlinkat: no
 * malloc, no stdio), for the signal handler; our folders are shallow. */
static void
remove_tree_at(int parent, const char *name, int depth)
{
    if (unlinkat(parent, name, 0) == 0 || depth > 6) return;
    int fd = openat(parent, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
    if (fd < 0) return;
    char buf[4096];
    for (;;) {
        long n = (long)getdents64(fd, buf, sizeof buf);
        if (n <= 0) break;
        for (long off = 0; off < n;) {
            const struct dirent64 *d = (const struct dirent64 *)(buf + off);
            off += d->d_reclen;
            if (!strcmp(d->d_name, ".") || !strcmp(d->d_name, "..")) continue;
            remove_tree_at(fd, d->d_name, depth + 1);
        }
    }
    close(fd);
    unlinkat(parent, name, AT_REMOVEDIR);
}

/* ---- the folder in flight, for the signal handler ---- */

static char in_flight[4096];
static volatile sig_atomic_t have_in_flight;

/* Scratch folders in flight (an external denoiser's files, estimate/
 * denoise_external.c): the handler removes them too. A slot is claimed under the lock
 * and its path written before `used` says so; the handler only reads. */
#define MAX_SCRATCH 8
static char scratch[MAX_SCRATCH][4096];
static volatile sig_atomic_t scratch_used[MAX_SCRATCH];
static pthread_mutex_t scratch_lock = PTHREAD_MUTEX_INITIALIZER;

static void
on_signal(void)
{
    if (have_in_flight) remove_tree_at(AT_FDCWD, in_flight, 0);
    for (int i = 0; i < MAX_SCRATCH; i++)
        if (scratch_used[i]) remove_tree_at(AT_FDCWD, scratch[i], 0);
}

int
mcp__scratch_dir_begin(const char *parent, const char *prefix, char *dir, size_t cap)
{
    if ((size_t)snprintf(dir, cap, "%s/%sXXXXXX", parent, prefix) >= cap ||
        strlen(dir) >= sizeof scratch[0])
        return mcp_error("%s: path too long for a temporary folder", parent);
    if (!mkdtemp(dir))
        return mcp_error("%s: cannot make a temporary folder: %s", parent,
                         strerror(errno));
    pthread_mutex_lock(&scratch_lock);
    int slot = -1;
    for (int i = 0; i < MAX_SCRATCH && slot < 0; i++)
        if (!scratch_used[i]) slot = i;
    if (slot >= 0) {
        snprintf(scratch[slot], sizeof scratch[slot], "%s", dir);
        scratch_used[slot] = 1;
    }
    pthread_mutex_unlock(&scratch_lock);
    /* more than MAX_SCRATCH at once: still removed at the end, but not on a signal */
    mcp__signal_cleanup_hook(on_signal);
    return 0;
}

void
mcp__scratch_dir_end(const char *dir)
{
    pthread_mutex_lock(&scratch_lock);
    for (int i = 0; i < MAX_SCRATCH; i++)
        if (scratch_used[i] && strcmp(scratch[i], dir) == 0) {
            scratch_used[i] = 0;
            break;
        }
    pthread_mutex_unlock(&scratch_lock);
    remove_tree(dir);
}

/* ---- leftovers of killed runs ---- */

/* Removes ".BASE.tmp-PID" and ".BASE.old-PID" in parent whose process is gone. */
void
mcp__outdir_clear_stale(const char *parent, const char *base)
{
    DIR *d = opendir(parent);
    if (!d) return;
    char prefix[1100];
    int plen = snprintf(prefix, sizeof prefix, ".%s.", base);
    struct dirent *e;
    while ((e = readdir(d))) {
        if (strncmp(e->d_name, prefix, (size_t)plen)) continue;
        const char *tag = e->d_name + plen;
        if (strncmp(tag, "tmp-", 4) && strncmp(tag, "old-", 4)) continue;
        char *end = NULL;
        long pid = strtol(tag + 4, &end, 10);
        if (pid <= 0 || !end || *end) continue;
        if (kill((pid_t)pid, 0) == 0 || errno != ESRCH) continue; /* alive, or not ours */
        char path[4400];
        snprintf(path, sizeof path, "%s/%s", parent, e->d_name);
        remove_tree(path);
        mcp_note("removed %s, left by an earlier run that was killed", path);
    }
    closedir(d);
}

/* 1 when the folder is empty or holds a file that only mcpost writes there: report.json
 * (a page: estimate, blend, perceptual, compare, a job), metrics.json (metrics -o),
 * adaptive.json (adaptive -o); 0 otherwise. */
static int
replaceable(const char *dir)
{
    static const char *const marks[] = {"report.json", "metrics.json", "adaptive.json"};
    char path[4200];
    struct stat st;
    for (size_t i = 0; i < sizeof marks / sizeof marks[0]; i++) {
        snprintf(path, sizeof path, "%s/%s", dir, marks[i]);
        if (stat(path, &st) == 0 && S_ISREG(st.st_mode)) return 1;
    }
    DIR *d = opendir(dir);
    if (!d) return 0;
    struct dirent *e;
    int empty = 1;
    while (empty && (e = readdir(d)))
        empty = !strcmp(e->d_name, ".") || !strcmp(e->d_name, "..");
    closedir(d);
    return empty;
}

static int
begin(mcp__outdir *o, const char *dir, int owned)
{
    memset(o, 0, sizeof *o);
    size_t n = strlen(dir);
    while (n > 1 && dir[n - 1] == '/') /* "out/est/" is "out/est" */
        n--;
    if (n == 0 || n >= sizeof o->final - 64)
        return mcp_error("output folder name too long or empty");
    memcpy(o->final, dir, n);
    o->final[n] = 0;
    const char *slash = strrchr(o->final, '/');
    const char *base = slash ? slash + 1 : o->final;
    if (!*base || !strcmp(base, ".") || !strcmp(base, ".."))
        return mcp_error(
            "%s: the output must be a folder of its own (it is written whole "
            "and renamed into place), e.g. %s/out",
            dir, dir);
    char parent[4096];
    if (slash) {
        snprintf(parent, sizeof parent, "%.*s",
                 slash == o->final ? 1 : (int)(slash - o->final), o->final);
    } else {
        snprintf(parent, sizeof parent, ".");
    }
    struct stat st;
    if (stat(o->final, &st) == 0) {
        if (!S_ISDIR(st.st_mode))
            return mcp_error("%s: exists and is not a folder; give another output",
                             o->final);
        if (!owned && !replaceable(o->final))
            return mcp_error(
                "%s: exists and is not an mcpost output (no report.json); give "
                "a new folder, or remove this one",
                o->final);
    }
    if (mcp_make_dirs(parent)) return -1;
    mcp__outdir_clear_stale(parent, base);
    snprintf(o->tmp, sizeof o->tmp, "%s/.%s.tmp-%d", parent, base, (int)getpid());
    remove_tree(o->tmp); /* ours from an earlier call in this process, if any */
    if (mkdir(o->tmp, 0777) != 0)
        return mcp_error("%s: cannot create the output folder: %s", o->final,
                         strerror(errno));
    /* the handler of imageio.c removes the files in flight, then calls on_signal */
    memcpy(in_flight, o->tmp,
           sizeof o->tmp < sizeof in_flight ? sizeof o->tmp : sizeof in_flight);
    in_flight[sizeof in_flight - 1] = 0;
    have_in_flight = 1;
    mcp__signal_cleanup_hook(on_signal);
    o->active = 1;
    return 0;
}

int
mcp__outdir_begin(mcp__outdir *o, const char *dir)
{
    return begin(o, dir, 0);
}

int
mcp__outdir_begin_owned(mcp__outdir *o, const char *dir)
{
    return begin(o, dir, 1);
}

int
mcp__outdir_commit(mcp__outdir *o)
{
    if (!o->active) return mcp_error("output folder: commit without begin");
    struct stat st;
    int rc = 0;
    if (lstat(o->final, &st) != 0) {
        if (rename(o->tmp, o->final) != 0)
            rc = mcp_error("%s: cannot rename the finished folder into place: %s",
                           o->final, strerror(errno));
    } else if (renameat2(AT_FDCWD, o->tmp, AT_FDCWD, o->final, RENAME_EXCHANGE) == 0) {
        have_in_flight = 0;
        remove_tree(o->tmp); /* the old folder, under the temporary name now */
    } else {
        /* no atomic swap on this file system: the old one away, the new one in */
        char old[sizeof o->tmp + 8];
        const char *slash = strrchr(o->final, '/');
        snprintf(old, sizeof old, "%.*s.%s.old-%d",
                 slash ? (int)(slash - o->final + 1) : 0, o->final,
                 slash ? slash + 1 : o->final, (int)getpid());
        if (rename(o->final, old) != 0)
            rc = mcp_error("%s: cannot move the old folder away: %s", o->final,
                           strerror(errno));
        else if (rename(o->tmp, o->final) != 0) {
            rc = mcp_error("%s: cannot rename the finished folder into place: %s",
                           o->final, strerror(errno));
            rename(old, o->final); /* the old one back */
        } else
            remove_tree(old);
    }
    if (rc) {
        mcp__outdir_abort(o);
        return -1;
    }
    have_in_flight = 0;
    o->active = 0;
    return 0;
}

void
mcp__outdir_abort(mcp__outdir *o)
{
    if (!o->active) return;
    have_in_flight = 0;
    remove_tree(o->tmp);
    o->active = 0;
}

int
mcp__outdir_check_input(const mcp__outdir *o, const char *input)
{
    char *dir = realpath(o->final, NULL), *file = dir ? realpath(input, NULL) : NULL;
    if (dir && !file) { /* a pattern (a series' "%04d"): the folder it names */
        char parent[4096];
        const char *slash = strrchr(input, '/');
        int len = slash ? (int)(slash - input) + (slash == input) : 1;
        snprintf(parent, sizeof parent, "%.*s", len, slash ? input : ".");
        file = realpath(parent, NULL);
    }
    size_t n = dir ? strlen(dir) : 0;
    int inside = file && !strncmp(file, dir, n) && (file[n] == '/' || !file[n]);
    free(file);
    free(dir);
    if (inside)
        return mcp_error("%s: is inside the output folder %s, which this run replaces "
                         "whole; give another output folder",
                         input, o->final);
    return 0;
}

int
mcp__outdir_check_inputs(const mcp__outdir *o, const char *const *inputs, int n)
{
    for (int i = 0; i < n; i++)
        if (inputs[i] && mcp__outdir_check_input(o, inputs[i])) return -1;
    return 0;
}

static int
fix_one(const mcp__outdir *o, cJSON *it)
{
    size_t n = strlen(o->tmp);
    if (cJSON_IsString(it) && !strncmp(it->valuestring, o->tmp, n) &&
        (it->valuestring[n] == '/' || !it->valuestring[n])) {
        size_t len = strlen(o->final) + strlen(it->valuestring + n) + 1;
        char *s = mcp_malloc(len);
        if (!s) return -1;
        snprintf(s, len, "%s%s", o->final, it->valuestring + n);
        char *set = cJSON_SetValuestring(it, s);
        free(s);
        if (!set) return mcp_error("out of memory");
    }
    for (cJSON *c = it->child; c; c = c->next)
        if (fix_one(o, c)) return -1;
    return 0;
}

/* Replaces the leading temporary folder name in every string of json by the final
 * one, so that figures and messages name the folder the user asked for. */
int
mcp__outdir_fix_paths(const mcp__outdir *o, cJSON *json)
{
    return json && o->active ? fix_one(o, json) : 0;
}
