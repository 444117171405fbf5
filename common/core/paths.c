/* paths.c: where mcpost's own files are -- the plug-ins (imageio.c, cv.c) and data
 * files such as OIDN's weights (estimate/denoise_unet.c) -- relative to the code itself,
 * so that an installed tree can move, then the build tree and the configured install
 * folders. */
#define _GNU_SOURCE /* dladdr */
#include "internal.h"

#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int
mcp__code_dir(char *buf, size_t cap)
{
    Dl_info info;
    buf[0] = '\0';
    if (!dladdr((void *)&mcp__code_dir, &info) || !info.dli_fname) return -1;
    const char *slash = strrchr(info.dli_fname, '/');
    if (!slash) return -1;
    snprintf(buf, cap, "%.*s", (int)(slash - info.dli_fname), info.dli_fname);
    return 0;
}

int
mcp__find_data_file(const char *name, char *buf, size_t cap)
{
    char code[4096];
    char from_lib[4200] = "", from_bin[4200] = "";
    if (mcp__code_dir(code, sizeof code) == 0) {
        /* the code is the shared library (<libdir>) or an executable it is linked
           into (<bindir>): the data folder is the same relative path from either */
        snprintf(from_lib, sizeof from_lib, "%s/%s", code, MCP_DATA_FROM_LIB);
        snprintf(from_bin, sizeof from_bin, "%s/%s", code, MCP_DATA_FROM_BIN);
    }
    const char *dirs[] = {from_lib, from_bin, MCP_DATA_BUILD_DIR, MCP_DATA_INSTALL_DIR};
    for (size_t i = 0; i < sizeof dirs / sizeof *dirs; i++) {
        if (!*dirs[i]) continue;
        snprintf(buf, cap, "%s/%s", dirs[i], name);
        if (access(buf, R_OK) == 0) return 0;
    }
    buf[0] = '\0';
    return -1;
}

static int one_blas_thread;

void
mcp__plugins_one_blas_thread(void)
{
    one_blas_thread = 1;
}

/* OpenCV links LAPACK, so both plug-ins load the system's BLAS, and where that is
 * OpenBLAS (Debian's libblas.so.3 alternative once libopenblas0 is installed) it
 * starts a thread per core as it loads, each spinning on sched_yield for about 0.1 s
 * of CPU waiting for work. mcpost calls no BLAS through the plug-ins, and on two cores
 * that spin took 2-3% of a 0.6 s gauss estimate (docs/benchmarks.md, "BLAS threads").
 * OPENBLAS_NUM_THREADS=1 while the plug-in loads starts none; a value the user set
 * is left alone, and the variable is removed again, so that the programs mcpost runs
 * (an external denoiser, a renderer) see the user's environment. Only the command
 * line asks for this: a program that links the library may load OpenBLAS for its own
 * work after the plug-in, and keeps its threads. */
static void *
load(const char *path)
{
    const int set = one_blas_thread && !getenv("OPENBLAS_NUM_THREADS");
    if (set) setenv("OPENBLAS_NUM_THREADS", "1", 1);
    void *h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (set) unsetenv("OPENBLAS_NUM_THREADS");
    return h;
}

/* The plug-in folders: $MCPOST_PLUGIN_DIR; beside the mcpost library that this code is
 * in (<libdir>/mcpost/, found with dladdr, so an installed tree can move); the build
 * tree; the configured install folder. */
void *
mcp__plugin_open(const char *file, char *err, size_t cap)
{
    char code[4096], beside_lib[4200] = "";
    if (mcp__code_dir(code, sizeof code) == 0)
        snprintf(beside_lib, sizeof beside_lib, "%s/mcpost", code);
    const char *dirs[] = {getenv("MCPOST_PLUGIN_DIR"), beside_lib, MCP_PLUGIN_BUILD_DIR,
                          MCP_PLUGIN_INSTALL_DIR};
    size_t n = 0;
    err[0] = '\0';
    for (size_t i = 0; i < sizeof dirs / sizeof *dirs; i++) {
        if (!dirs[i] || !*dirs[i]) continue;
        char path[4200];
        snprintf(path, sizeof path, "%s/%s", dirs[i], file);
        if (access(path, R_OK) != 0) continue;
        void *h = load(path);
        if (h) return h;
        n += (size_t)snprintf(err + n, n < cap ? cap - n : 0, "%s; ", dlerror());
    }
    if (!n) snprintf(err, cap, "%s not found (set MCPOST_PLUGIN_DIR)", file);
    return NULL;
}
