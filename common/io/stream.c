/* stream.c: what the commands that stream an EXR a band of rows at a time share (merge,
 * convert, info: issue 31, memory bounded whatever the image size): the bands' height,
 * the loop over them with its progress, and the output written band by band under a
 * temporary name (mcp_atomic_file), renamed when every row is in and removed on
 * failure, as mcp_image_write does with a whole image; its header (channels and
 * attributes) is the first band's. */
#include "internal.h"
#include "../core/internal.h" /* progress stopped on a failure */

#include <mcpost/progress.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* 64 rows end on a chunk of every compression mcpost writes (zip and pxr24 16 rows, piz
 * 32, the others 1); at 8K a band of a 12-channel dump is 24 MB. */
#define STREAM_BAND_ROWS 64

int
mcp__stream_band_rows(void)
{
    const char *e = getenv("MCPOST_BAND_ROWS");
    if (!e || !*e) return STREAM_BAND_ROWS;
    if (strcmp(e, "whole") == 0) return 0;
    const int n = atoi(e);
    return n > 0 && n % 32 == 0 ? n : STREAM_BAND_ROWS;
}

int
mcp__exr_band_file_begin(mcp__exr_band_file *f, const char *path, int width, int height,
                         const mcp_write_options *opt)
{
    *f = (mcp__exr_band_file){.path = path, .width = width, .height = height};
    f->opt = *opt;
    return mcp_atomic_begin(&f->af, path);
}

int
mcp__exr_band_file_rows(mcp__exr_band_file *f, const mcp_image *rows, int y0)
{
    if (!f->wr && mcp__exr_writer_open(
                      f->af.tmp_path, f->width, f->height, rows->channels, rows->names,
                      f->attrs ? f->attrs : &rows->attrs, &f->opt, &f->wr))
        return -1;
    return mcp__exr_writer_rows(f->wr, rows, y0);
}

int
mcp__exr_band_file_end(mcp__exr_band_file *f, int failed)
{
    /* closed even after a failure, before the temporary is removed; the failure's
       message stays */
    char why[1024];
    snprintf(why, sizeof why, "%s", failed ? mcp_error_message() : "");
    int rc = failed;
    if (f->wr && mcp__exr_writer_close(f->wr) && !rc) rc = 1;
    f->wr = NULL;
    if (*why) mcp_error("%s", why);
    if (rc) {
        mcp__name_output_in_error(f->af.tmp_path, f->path);
        mcp_atomic_abort(&f->af);
        return -1;
    }
    return mcp_atomic_commit(&f->af) ? -1 : 0;
}

int
mcp__stream_bands(const char *label, int width, int height, int rows,
                  int (*band)(void *ctx, int y0, int y1), void *ctx)
{
    mcp_progress bar_store, *bar = NULL;
    const int n_bands = (height + rows - 1) / rows;
    if ((double)width * height >= 1048576.0 && !mcp_progress_quiet()) {
        bar = &bar_store;
        mcp_progress_begin(bar, label, n_bands);
    }
    int rc = 0;
    for (int b = 0; b < n_bands && !rc; b++) {
        const int y0 = b * rows;
        rc = band(ctx, y0, y0 + rows < height ? y0 + rows : height);
        if (bar) mcp_progress_update(bar, b + 1);
    }
    if (bar) {
        if (rc)
            mcp__progress_stop(bar);
        else
            mcp_progress_end(bar);
    }
    return rc ? -1 : 0;
}
