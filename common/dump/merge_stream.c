/* merge_stream.c: `mcpost merge` of EXR dumps a band of rows at a time, so that
 * neither the inputs nor the result are ever held whole (issue 31: memory bounded
 * whatever the image size; docs/conventions.md, "Merging renders larger than memory").
 * Eight replicates of an 8K render are 13 GB of dumps; read whole, two of them took
 * 7.1 GB.
 *
 * Every input is read in bands (dump.c's mcp__dump_bands: the parts laid out,
 * converted and checked by the code of a whole read), each band's dumps merged by
 * mcp_dump_merge, whose every value depends on its own pixel only, and the band written
 * at once into the output EXR (mcp__exr_writer) under a temporary name, renamed when
 * every row is written and removed on failure. So the pixels and the header are those
 * of mcp_dump_merge and mcp_dump_write on the whole dumps (tests/common/
 * test_merge_stream.c checks them value for value). Pooling the variance reads a
 * window around each pixel; that merge, and inputs a band reader cannot take (parts in
 * other files, another format), are read whole by the caller. */
#include "internal.h"
#include "../core/internal.h" /* progress stopped on a failure */
#include "../io/internal.h"   /* mcp__exr_writer */

#include <mcpost/imageio.h>
#include <mcpost/progress.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* 64 rows end on a chunk of every compression mcpost writes (zip and pxr24 16 rows, piz
 * 32, the others 1); at 8K a band of a 12-channel dump is 24 MB. */
#define MERGE_BAND_ROWS 64

/* The band height: MCPOST_MERGE_BAND_ROWS (a multiple of 32, for tests; "whole": no
 * bands), else MERGE_BAND_ROWS; 0 for whole. */
static int
band_rows(void)
{
    const char *e = getenv("MCPOST_MERGE_BAND_ROWS");
    if (!e || !*e) return MERGE_BAND_ROWS;
    if (strcmp(e, "whole") == 0) return 0;
    int n = atoi(e);
    return n > 0 && n % 32 == 0 ? n : MERGE_BAND_ROWS;
}

typedef struct merge_stream {
    int count;
    mcp__dump_bands **in;
    mcp_dump **band; /* each input's current band */
    mcp__exr_writer *out;
} merge_stream;

static void
free_bands(merge_stream *m)
{
    for (int k = 0; k < m->count; k++) {
        mcp_dump_free(m->band[k]);
        m->band[k] = NULL;
    }
}

/* Merges rows [y0, y1) and writes them; *merged: the band's result. */
static int
merge_band(merge_stream *m, int y0, int y1, const mcp_merge_options *opt, int width,
           int height, const char *tmp_path, const char *out_path,
           const mcp_write_options *wo, mcp_dump **merged)
{
    mcp_image *img = NULL;
    int rc = -1;
    for (int k = 0; k < m->count; k++)
        if (mcp__dump_bands_read(m->in[k], y0, y1, &m->band[k])) goto done;
    if (mcp_dump_merge((const mcp_dump *const *)m->band, m->count, opt, merged) ||
        mcp__dump_image(*merged, MCP_CONV_MCPOST, out_path, &img))
        goto done;
    /* the header is the first band's: the channels and attributes every band has */
    if (!m->out && mcp__exr_writer_open(tmp_path, width, height, img->channels,
                                        img->names, &img->attrs, wo, &m->out))
        goto done;
    rc = mcp__exr_writer_rows(m->out, img, y0);
done:
    free_bands(m);
    mcp_image_free(img);
    return rc;
}

/* The inputs' bands merged and written, top to bottom; *last the last band's merge. */
static int
merge_all(merge_stream *m, const mcp_merge_options *opt, int width, int height, int rows,
          const char *tmp_path, const char *out_path, const mcp_write_options *wo,
          mcp_dump **last)
{
    mcp_progress bar_store, *bar = NULL;
    const int n_bands = (height + rows - 1) / rows;
    if ((double)width * height >= 1048576.0 && !mcp_progress_quiet()) {
        bar = &bar_store;
        mcp_progress_begin(bar, "merge", n_bands);
    }
    int rc = 0;
    for (int b = 0; b < n_bands && !rc; b++) {
        const int y0 = b * rows, y1 = y0 + rows < height ? y0 + rows : height;
        mcp_dump_free(*last);
        *last = NULL;
        rc = merge_band(m, y0, y1, opt, width, height, tmp_path, out_path, wo, last);
        if (bar) mcp_progress_update(bar, b + 1);
    }
    if (bar) {
        if (rc)
            mcp__progress_stop(bar);
        else
            mcp_progress_end(bar);
    }
    return rc;
}

/* Opens every input; 0 with *streamable 0 when one must be read whole. The sizes are
 * checked in mcp_dump_merge's words. */
static int
open_inputs(merge_stream *m, const mcp_dump_spec *specs, int *width, int *height,
            int *streamable)
{
    *streamable = 0;
    for (int k = 0; k < m->count; k++) {
        if (mcp__dump_bands_open(&specs[k], &m->in[k])) return -1;
        if (!m->in[k]) return 0;
        int w, h;
        mcp__dump_bands_size(m->in[k], &w, &h);
        if (k == 0) {
            *width = w;
            *height = h;
        } else if (w != *width || h != *height) {
            return mcp_error("merge: %s is %dx%d, but %s is %dx%d",
                             mcp__dump_bands_source(m->in[k]), w, h,
                             mcp__dump_bands_source(m->in[0]), *width, *height);
        }
    }
    *streamable = 1;
    return 0;
}

/* The merge written under a temporary name, renamed once every row is written. */
static int
write_merged(merge_stream *m, const mcp_merge_options *opt, int width, int height,
             int rows, const char *out_path, const mcp_write_options *wo, mcp_dump **last)
{
    mcp_atomic_file af;
    if (mcp_atomic_begin(&af, out_path)) return -1;
    int rc = merge_all(m, opt, width, height, rows, af.tmp_path, out_path, wo, last);
    /* closed even after a failure, before the temporary is removed; the failure's
       message stays */
    char why[1024];
    snprintf(why, sizeof why, "%s", rc ? mcp_error_message() : "");
    if (m->out && mcp__exr_writer_close(m->out) && !rc) rc = -1;
    m->out = NULL;
    if (*why) mcp_error("%s", why);
    if (rc)
        mcp_atomic_abort(&af);
    else
        rc = mcp_atomic_commit(&af);
    return rc ? -1 : 0;
}

int
mcp__dump_merge_streamed(const mcp_dump_spec *specs, int count,
                         const mcp_merge_options *opt, const char *out_path,
                         const mcp_write_options *wo, mcp_dump **last, int *done)
{
    *last = NULL;
    *done = 0;
    const int rows = band_rows();
    /* what the whole merge says in its own words: no inputs, too few replicates */
    if (!rows || count < 1 || (opt->variance == MCP_MERGE_REPLICATES && count < 2) ||
        opt->pool_radius > 0 || wo->exr_tiled ||
        mcp_format_from_path(out_path) != MCP_FORMAT_EXR)
        return 0;
    merge_stream m = {.count = count};
    m.in = mcp_calloc((size_t)count, sizeof *m.in);
    m.band = mcp_calloc((size_t)count, sizeof *m.band);
    int rc = -1, streamable = 0, width = 0, height = 0;
    if (!m.in || !m.band || open_inputs(&m, specs, &width, &height, &streamable))
        goto done;
    if (!streamable) { /* read whole by the caller */
        rc = 0;
        goto done;
    }
    *done = 1;
    rc = write_merged(&m, opt, width, height, rows, out_path, wo, last);
done:
    if (rc) {
        mcp_dump_free(*last);
        *last = NULL;
    }
    for (int k = 0; m.in && k < count; k++)
        mcp__dump_bands_close(m.in[k]);
    free(m.in);
    free(m.band);
    return rc ? -1 : 0;
}
