/* merge_stream.c: `mcpost merge` of EXR dumps a band of rows at a time, so that
 * neither the inputs nor the result are ever held whole (issue 31: memory bounded
 * whatever the image size; docs/conventions.md, "Files larger than memory").
 * Eight replicates of an 8K render are 13 GB of dumps; read whole, two of them took
 * 7.1 GB.
 *
 * Every input is read in bands (dump.c's mcp__dump_bands: the parts laid out,
 * converted and checked by the code of a whole read), each band's dumps merged by
 * mcp_dump_merge, whose every value depends on its own pixel only, and the band written
 * at once into the output EXR under a temporary name, renamed when every row is
 * written and removed on failure (common/io's mcp__exr_band_file). So the pixels and the
 * header are those of mcp_dump_merge and mcp_dump_write on the whole dumps (tests/common/
 * test_merge_stream.c checks them value for value). Pooling the variance reads a
 * window around each pixel; that merge, and inputs a band reader cannot take (parts in
 * other files, another format), are read whole by the caller. */
#include "internal.h"
#include "../io/internal.h" /* the bands, the output */

#include <mcpost/imageio.h>

#include <stdio.h>
#include <stdlib.h>

typedef struct merge_stream {
    int count;
    mcp__dump_bands **in;
    mcp_dump **band; /* each input's current band */
    mcp__exr_band_file out;
} merge_stream;

static void
free_bands(merge_stream *m)
{
    for (int k = 0; k < m->count; k++) {
        mcp_dump_free(m->band[k]);
        m->band[k] = NULL;
    }
}

/* What a band of the merge needs beside the inputs. */
typedef struct band_ctx {
    merge_stream *m;
    const mcp_merge_options *opt;
    const char *out_path;
    mcp_dump **last; /* the last band's merge */
} band_ctx;

/* Merges rows [y0, y1) and writes them. */
static int
merge_band(void *ctx, int y0, int y1)
{
    const band_ctx *c = ctx;
    merge_stream *m = c->m;
    mcp_image *img = NULL;
    int rc = -1;
    mcp_dump_free(*c->last);
    *c->last = NULL;
    for (int k = 0; k < m->count; k++)
        if (mcp__dump_bands_read(m->in[k], y0, y1, &m->band[k])) goto done;
    rc = mcp_dump_merge((const mcp_dump *const *)m->band, m->count, c->opt, c->last) ||
         mcp__dump_image(*c->last, MCP_CONV_MCPOST, c->out_path, &img) ||
         mcp__exr_band_file_rows(&m->out, img, y0);
done:
    free_bands(m);
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
    if (mcp__exr_band_file_begin(&m.out, out_path, width, height, wo)) goto done;
    band_ctx c = {&m, opt, out_path, last};
    char label[96];
    snprintf(label, sizeof label, "merge %s", out_path);
    rc = mcp__exr_band_file_end(
        &m.out, mcp__stream_bands(label, width, height, rows, merge_band, &c) != 0);
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
