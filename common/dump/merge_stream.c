/* merge_stream.c: `mcpost merge` of EXR dumps a band of rows at a time, so that
 * neither the inputs nor the result are ever held whole (issue 31: memory bounded
 * whatever the image size; docs/conventions.md, "Files larger than memory").
 * Eight replicates of an 8K render are 13 GB of dumps; read whole, two of them took
 * 7.1 GB.
 *
 * Every input is read in bands (dump.c's mcp__dump_bands: the parts laid out,
 * converted and checked by the code of a whole read) and its rows held while a band of
 * the output needs them (rows_held.c); each band's rows merged by mcp_dump_merge, and
 * written at once into the output EXR under a temporary name, renamed when every row
 * is written and removed on failure (common/io's mcp__exr_band_file). A merged value
 * depends on its own pixel only, except with pooling (--pool R), whose window reaches
 * R rows above and below: a band is then merged from its rows and the R rows on each
 * side, whose window sums are those of the whole image (common/core/stats.c adds each
 * window's rows in one order whatever the image's extent), and only its own rows are
 * written. So the pixels and the header are those of mcp_dump_merge and mcp_dump_write
 * on the whole dumps (tests/common/test_merge_stream.c checks them value for value).
 * Inputs a band reader cannot take (parts in other files, another format) are read
 * whole by the caller. */
#include "internal.h"
#include "../io/internal.h" /* the bands, the output */

#include <mcpost/imageio.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct merge_stream {
    int count, band_rows, radius;
    mcp__dump_held *held; /* each input's rows (rows_held.c) */
    mcp__exr_band_file out;
} merge_stream;

/* Every input's rows [y0 - radius, y1 + radius) within the image, read as needed. */
static int
hold_rows(merge_stream *m, int y0, int y1, int height)
{
    const int lo = y0 - m->radius > 0 ? y0 - m->radius : 0,
              hi = y1 + m->radius < height ? y1 + m->radius : height;
    for (int k = 0; k < m->count; k++)
        if (mcp__dump_held_rows(&m->held[k], lo, hi)) return -1;
    return 0;
}

/* What a band of the merge needs beside the inputs. */
typedef struct band_ctx {
    merge_stream *m;
    const mcp_merge_options *opt;
    const char *out_path;
    int height;
    mcp_dump **last; /* the last band's merge */
} band_ctx;

/* Merges rows [y0, y1) (with pooling, from the rows around them) and writes them. */
static int
merge_band(void *ctx, int y0, int y1)
{
    const band_ctx *c = ctx;
    merge_stream *m = c->m;
    mcp_image *img = NULL;
    mcp_dump *held[64],
        **parts = m->count <= 64 ? held : mcp_calloc((size_t)m->count, sizeof *parts);
    mcp_dump band;
    int rc = -1, have_band = 0;
    mcp_dump_free(*c->last);
    *c->last = NULL;
    if (!parts || hold_rows(m, y0, y1, c->height)) goto done;
    for (int k = 0; k < m->count; k++)
        parts[k] = m->held[k].d;
    rc = mcp_dump_merge((const mcp_dump *const *)parts, m->count, c->opt, c->last) ||
         !(have_band = !mcp__dump_rows_view(*c->last, y0 - m->held[0].lo,
                                            y1 - m->held[0].lo, &band)) ||
         mcp__dump_image(&band, MCP_CONV_MCPOST, c->out_path, &img) ||
         mcp__exr_band_file_rows(&m->out, img, y0);
done:
    if (have_band) mcp__dump_rows_view_free(&band);
    if (parts != held) free(parts);
    mcp_image_free(img);
    return rc ? -1 : 0;
}

/* Opens every input; 0 with *streamable 0 when one must be read whole. The sizes are
 * checked in mcp_dump_merge's words. */
static int
open_inputs(merge_stream *m, const mcp_dump_spec *specs, int *width, int *height,
            int *streamable)
{
    *streamable = 0;
    for (int k = 0; k < m->count; k++) {
        mcp__dump_bands **in = &m->held[k].in;
        if (mcp__dump_bands_open(&specs[k], in)) return -1;
        if (!*in) return 0;
        int w, h;
        mcp__dump_bands_size(*in, &w, &h);
        if (k == 0) {
            *width = w;
            *height = h;
        } else if (w != *width || h != *height) {
            return mcp_error("merge: %s is %dx%d, but %s is %dx%d",
                             mcp__dump_bands_source(*in), w, h,
                             mcp__dump_bands_source(m->held[0].in), *width, *height);
        }
        /* a band's rows and the radius above and below, and the next band read */
        m->held[k].cap = 2 * m->band_rows + 2 * m->radius;
        m->held[k].read_rows = m->band_rows;
        m->held[k].height = h;
    }
    *streamable = 1;
    return 0;
}

int
mcp__dump_merge_streamed(const mcp_dump_spec *specs, int count,
                         const mcp_merge_options *opt, const char *out_path,
                         const mcp_write_options *wo, mcp_dump **last, int *done)
{
    *last = NULL;
    *done = 0;
    const int rows = mcp__stream_band_rows();
    /* what the whole merge says in its own words: no inputs, too few replicates */
    if (!rows || count < 1 || (opt->variance == MCP_MERGE_REPLICATES && count < 2) ||
        opt->pool_radius < 0 || wo->exr_tiled ||
        mcp_format_from_path(out_path) != MCP_FORMAT_EXR)
        return 0;
    merge_stream m = {.count = count, .band_rows = rows, .radius = opt->pool_radius};
    m.held = mcp_calloc((size_t)count, sizeof *m.held);
    int rc = -1, streamable = 0, width = 0, height = 0;
    if (!m.held || open_inputs(&m, specs, &width, &height, &streamable)) goto done;
    if (!streamable) { /* read whole by the caller */
        rc = 0;
        goto done;
    }
    *done = 1;
    if (mcp__exr_band_file_begin(&m.out, out_path, width, height, wo)) goto done;
    band_ctx c = {&m, opt, out_path, height, last};
    char label[96];
    snprintf(label, sizeof label, "merge %s", out_path);
    rc = mcp__exr_band_file_end(
        &m.out, mcp__stream_bands(label, width, height, rows, merge_band, &c) != 0);
done:
    if (rc) {
        mcp_dump_free(*last);
        *last = NULL;
    }
    for (int k = 0; m.held && k < count; k++) {
        mcp__dump_bands_close(m.held[k].in);
        mcp__dump_held_clear(&m.held[k]);
    }
    free(m.held);
    return rc ? -1 : 0;
}
