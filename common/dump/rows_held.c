/* rows_held.c: a dump's rows held while the bands that read them need them, read band
 * by band from its EXR (mcp__dump_bands) for the commands that stream a dump whose
 * bands reach beyond their own rows: a merge with pooling (merge_stream.c), an
 * estimate whose denoiser reads a halo of rows (estimate/estimate_bands.c). The rows
 * a band asks for are appended below as they are read and dropped from the top once no
 * later band reads them, in images with room for cap rows, so that no band copies
 * what is held already. */
#include "internal.h"

#include <stdlib.h>
#include <string.h>

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
append(mcp__dump_held *h, mcp_dump *b)
{
    const int n = b->color->height;
    for (int p = 0; p < N_ROW_PARTS; p++) {
        mcp_image **src = part_of(b, p), **dst = h->d ? part_of(h->d, p) : NULL;
        if (!*src) continue;
        if (!h->d) { /* the first band: its parts move into images with room */
            mcp_image *room = NULL;
            if (mcp_image_new((*src)->width, h->cap, (*src)->channels,
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
drop_above(mcp__dump_held *h, int lo)
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

int
mcp__dump_held_rows(mcp__dump_held *h, int lo, int hi)
{
    if (h->d) drop_above(h, lo);
    while (h->hi < hi) {
        const int b1 =
            h->hi + h->read_rows < h->height ? h->hi + h->read_rows : h->height;
        if (b1 - (h->d ? h->lo : h->hi) > h->cap)
            return mcp_error("%s: rows [%d, %d) do not fit the %d held",
                             mcp__dump_bands_source(h->in), h->lo, b1, h->cap);
        mcp_dump *b = NULL;
        if (mcp__dump_bands_read(h->in, h->hi, b1, &b) || append(h, b)) return -1;
    }
    return 0;
}

void
mcp__dump_held_clear(mcp__dump_held *h)
{
    mcp_dump_free(h->d);
    h->d = NULL;
    h->lo = h->hi = 0;
}
