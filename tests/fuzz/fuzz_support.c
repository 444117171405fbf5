/* fuzz_support.c: scratch files and the error contract for the fuzz targets (fuzz.h).
 * The readers are fuzzed from memory; files (in /dev/shm) remain for what takes a
 * path: the image targets' check that the file readers agree, and the job check. */
#define _POSIX_C_SOURCE 200809L
#include "fuzz.h"

#include <mcpost/imageio.h>
#include <mcpost/progress.h>

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char dir[256];

static void
remove_dir(void)
{
    /* only the targets write here: empty the folder, then remove it */
    DIR *d = opendir(dir);
    char path[700];
    for (struct dirent *e; d && (e = readdir(d));) {
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
            unlink(path);
        }
    }
    if (d) closedir(d);
    rmdir(dir);
}

/* libFuzzer calls this once before the first input (replay.c's main() too). The image
 * ceiling is lowered to 256 MiB so that an input that gets past the size checks
 * stays under libFuzzer's own malloc limit (-rss_limit_mb, 2 GiB): the ceiling is
 * one of the things under test, and an allocation it lets through would otherwise
 * be reported as an out-of-memory finding. */
int
LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc, (void)argv;
    setenv("MCPOST_MAX_BYTES", "268435456", 0);
    mcp_progress_set_quiet(1);
    return 0;
}

const char *
mcp_fuzz_dir(void)
{
    if (dir[0]) return dir;
    struct stat st;
    const char *base = stat("/dev/shm", &st) == 0 && S_ISDIR(st.st_mode) ? "/dev/shm"
                       : getenv("TMPDIR") ? getenv("TMPDIR")
                                          : "/tmp";
    snprintf(dir, sizeof dir, "%s/mcpost-fuzz-%ld", base, (long)getpid());
    if (mkdir(dir, 0700) != 0 && stat(dir, &st) != 0) {
        fprintf(stderr, "fuzz: cannot create %s\n", dir);
        abort();
    }
    atexit(remove_dir);
    return dir;
}

const char *
mcp_fuzz_file(int slot, const char *name, const void *data, size_t size)
{
    static char paths[8][400];
    if (slot < 0 || slot >= 8) abort();
    snprintf(paths[slot], sizeof paths[slot], "%s/%s", mcp_fuzz_dir(), name);
    FILE *f = fopen(paths[slot], "wb");
    if (!f || (size && fwrite(data, 1, size, f) != size) || fclose(f) != 0) {
        fprintf(stderr, "fuzz: cannot write %s\n", paths[slot]);
        abort();
    }
    return paths[slot];
}

void
mcp_fuzz_check_error(int rc, const char *what)
{
    if (rc == 0) return;
    const char *msg = mcp_error_message();
    if (rc != -1 || !msg || !msg[0] || strchr(msg, '\n')) {
        fprintf(stderr, "fuzz: %s broke the error contract: rc %d, message '%s'\n", what,
                rc, msg ? msg : "(null)");
        abort();
    }
}

void
mcp_fuzz_same_as_file(int rc, const mcp_image *img, const void *data, size_t size,
                      const char *name)
{
    const char *path = mcp_fuzz_file(0, name, data, size);
    mcp_image *from_file = NULL;
    int rc_file = mcp_image_read(path, NULL, &from_file);
    mcp_fuzz_check_error(rc_file, "read from a file");
    int same = (rc == 0) == (rc_file == 0);
    if (same && rc == 0) {
        same = img->width == from_file->width && img->height == from_file->height &&
               img->channels == from_file->channels;
        for (int y = 0; same && y < img->height; y++)
            same = memcmp(mcp_image_px(img, 0, y), mcp_image_px(from_file, 0, y),
                          (size_t)img->width * img->channels * sizeof(float)) == 0;
    }
    mcp_image_free(from_file);
    if (!same) {
        fprintf(stderr, "fuzz: %s read from memory and from a file differ (rc %d, %d)\n",
                name, rc, rc_file);
        abort();
    }
}
