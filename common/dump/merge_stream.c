/* merge_stream.c: `mcpost merge` of EXR dumps a band of rows at a time, so that
 * neither the inputs nor the result are ever held whole (issue 31: memory bounded
 * whatever the image size; docs/conventions.md, "Files larger than memory").
 * Eight replicates of an 8K render are 13 GB of dumps; read whole, two of them took
 * 7.1 GB.
 *
 * Every input is read in bands (dump.c's mcp__dump_bands: the parts laid out,
 * converted and checked by the code of a whole read) and its rows held while a band of
 * the output needs them (rows_held); each band's rows merged by mcp_dump_merge, and
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

/* An input's rows [lo, hi), held for the bands that read them: a band's rows and,
 * with pooling, the radius above and below it (the windows of the pixels at its
 * edges). The parts' images have room for cap rows: a band read from the file is
 * appended below, and the rows no band needs any more are dropped from the top. */
typedef struct rows_held {
    mcp_dump *d; /* the parts hi - lo rows high, and what the dump says of itself */
    int lo, hi;
} rows_held;

typedef struct merge_stream {
    int count, band_rows, radius, cap;
    mcp__dump_bands **in;
    rows_held *held; /* each input's */
    mcp__exr_band_file out;
} merge_stream;

enum { N_ROW_PARTS = 6 };

static mcp_image **
part_of(mcp_dump *d, int p)
{
    mcp_image **parts[N_ROW_PARTS] = {&d->color,  &d->var_of_mean, &d->cov_of_mean,
                                      &d->albedo, &d->normal,      &d->spp_map};
    return parts[p];
}

/* Appends band b (the next rows of the input) to h; takes b. */
static int
hold(rows_held *h, mcp_dump *b, int cap)
{
    const int n = b->color->height;
    for (int p = 0; p < N_ROW_PARTS; p++) {
        mcp_image **src = part_of(b, p), **dst = h->d ? part_of(h->d, p) : NULL;
        if (!*src) continue;
        if (!h->d) { /* the first band: its parts move into images with room */
            mcp_image *room = NULL;
            if (mcp_image_new((*src)->width, cap, (*src)->channels,
                              (const char *const *)(*src)->names, &room) ||
                mcp_image_set_source(room, (*src)->source) ||
                mcp_attrs_copy(&(*src)->attrs, &room->attrs)) {
                mcp_image_free(room);
                mcp_dump_free(b);
                return -1;
            }
            memcpy(room->data, (*src)->data,
                   (size_t)n * (size_t)(*src)->row_stride * sizeof(float));
            room->height = n;
            mcp_image_free(*src);
            *src = room;
            continue;
        }
        memcpy((*dst)->data + (ptrdiff_t)(*dst)->height * (*dst)->row_stride,
               (*src)->data, (size_t)n * (size_t)(*src)->row_stride * sizeof(float));
        (*dst)->height += n;
    }
    if (!h->d) {
        h->d = b;
    } else {
        mcp_dump_free(b);
    }
    h->hi += n;
    return 0;
}

/* Drops the rows above lo. */
static void
drop_above(rows_held *h, int lo)
{
    const int gone = lo - h->lo;
    if (gone <= 0) return;
    for (int p = 0; p < N_ROW_PARTS; p++) {
        mcp_image *img = *part_of(h->d, p);
        if (!img) continue;
        memmove(img->data, img->data + (ptrdiff_t)gone * img->row_stride,
                (size_t)(img->height - gone) * (size_t)img->row_stride * sizeof(float));
        img->height -= gone;
    }
    h->lo = lo;
}

/* Every input's rows [y0 - radius, y1 + radius) within the image, read as needed. */
static int
hold_rows(merge_stream *m, int y0, int y1, int height)
{
    const int lo = y0 - m->radius > 0 ? y0 - m->radius : 0,
              hi = y1 + m->radius < height ? y1 + m->radius : height;
    for (int k = 0; k < m->count; k++) {
        rows_held *h = &m->held[k];
        if (h->d) drop_above(h, lo);
        while (h->hi < hi) {
            const int b1 = h->hi + m->band_rows < height ? h->hi + m->band_rows : height;
            mcp_dump *b = NULL;
            if (mcp__dump_bands_read(m->in[k], h->hi, b1, &b) || hold(h, b, m->cap))
                return -1;
        }
    }
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
        opt->pool_radius < 0 || wo->exr_tiled ||
        mcp_format_from_path(out_path) != MCP_FORMAT_EXR)
        return 0;
    /* a band's rows and the radius above and below, and the next band read */
    merge_stream m = {.count = count, .band_rows = rows, .radius = opt->pool_radius};
    m.cap = 2 * rows + 2 * m.radius;
    m.in = mcp_calloc((size_t)count, sizeof *m.in);
    m.held = mcp_calloc((size_t)count, sizeof *m.held);
    int rc = -1, streamable = 0, width = 0, height = 0;
    if (!m.in || !m.held || open_inputs(&m, specs, &width, &height, &streamable))
        goto done;
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
    for (int k = 0; m.in && k < count; k++)
        mcp__dump_bands_close(m.in[k]);
    for (int k = 0; m.held && k < count; k++)
        mcp_dump_free(m.held[k].d);
    free(m.in);
    free(m.held);
    return rc ? -1 : 0;
}
