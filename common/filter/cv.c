/* cv.c: the OpenCV functions of cv_shim.h, from the plug-in mcpost_cv.so, loaded on
 * first use. Linking OpenCV (and the X11, BLAS, TBB and Fortran libraries Debian's
 * build pulls in) made every process spend ~10 ms relocating them at start, which was
 * most of `mcpost --version`, while only filtering, tile DFTs and colour maps need it. */
#include "../core/internal.h"
#include "cv_shim.h"

#include <dlfcn.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>

static struct {
    pthread_once_t once;
    const mcp__cv_table *table;
    char error[1024];
} cv = {PTHREAD_ONCE_INIT, NULL, ""};

static void
cv_load(void)
{
    void *h = mcp__plugin_open("mcpost_cv.so", cv.error, sizeof cv.error);
    if (!h) return;
    mcp__cv_table_fn table = (mcp__cv_table_fn)(uintptr_t)dlsym(h, MCP__CV_TABLE);
    const mcp__cv_table *t = table ? table() : NULL;
    if (!t || t->abi != MCP__CV_ABI) {
        snprintf(cv.error, sizeof cv.error, "mcpost_cv.so is not this version's plug-in");
        dlclose(h);
        return;
    }
    cv.table = t;
}

/* 0 when the plug-in is loaded; otherwise -1 with the reason in err. Safe from many
 * threads (the shim's callers run in OpenMP workers). */
static int
cv_ready(char *err, size_t err_cap)
{
    pthread_once(&cv.once, cv_load);
    if (cv.table) return 0;
    snprintf(err, err_cap, "the OpenCV plug-in: %s", cv.error);
    return -1;
}

int
mcp__cv_sep_filter_rows(const mcp__cv_plane *src, const mcp__cv_plane *dst, int y0,
                        int y1, const float *kx, int kx_len, const float *ky, int ky_len,
                        char *err, size_t err_cap)
{
    return cv_ready(err, err_cap)
               ? -1
               : cv.table->sep_filter_rows(src, dst, y0, y1, kx, kx_len, ky, ky_len, err,
                                           err_cap);
}

int
mcp__cv_filter2d_rows(const mcp__cv_plane *src, const mcp__cv_plane *dst, int y0, int y1,
                      const float *kernel, int kw, int kh, char *err, size_t err_cap)
{
    return cv_ready(err, err_cap)
               ? -1
               : cv.table->filter2d_rows(src, dst, y0, y1, kernel, kw, kh, err, err_cap);
}

int
mcp__cv_dft_power(const double *tile, int n, double *power, char *err, size_t err_cap)
{
    return cv_ready(err, err_cap) ? -1
                                  : cv.table->dft_power(tile, n, power, err, err_cap);
}

int
mcp__cv_colormap_lut(int cv_map, unsigned char *rgb, char *err, size_t err_cap)
{
    return cv_ready(err, err_cap) ? -1
                                  : cv.table->colormap_lut(cv_map, rgb, err, err_cap);
}
