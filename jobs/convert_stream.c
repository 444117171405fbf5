/* convert_stream.c: `mcpost convert` of an EXR into an EXR a band of rows at a time, so
 * that the image is never held whole (issue 31: memory bounded whatever the image size;
 * docs/conventions.md, "Files larger than memory"): each band is read as a whole read
 * gives it (common/io's mcp__exr_rows_read_image; with --dump, common/dump's
 * mcp__dump_bands), its channels picked (mcp__convert_pick_channels) or the dump's rows
 * laid out in the convention asked for (mcp__dump_image), and written at once
 * (mcp__exr_band_file). Every step is per pixel, so the file holds the whole conversion's
 * values. */
#include "internal.h"
#include "../common/dump/internal.h"
#include "../common/io/internal.h"

#include <stdio.h>

typedef struct convert_ctx {
    mcp__exr_rows *image;  /* an image's rows, or */
    mcp__dump_bands *dump; /* a dump's, laid out in conv */
    mcp_convention conv;
    char **names;
    int count;
    const char *out_path;
    mcp__exr_band_file out;
} convert_ctx;

static int
convert_band(void *ctx, int y0, int y1)
{
    convert_ctx *c = ctx;
    mcp_image *rows = NULL, *picked = NULL;
    mcp_dump *d = NULL;
    int rc;
    if (c->image)
        rc = mcp__exr_rows_read_image(c->image, y0, y1, &rows) ||
             mcp__convert_pick_channels(rows, c->names, c->count, c->out_path, &picked);
    else
        rc = mcp__dump_bands_read(c->dump, y0, y1, &d) ||
             mcp__dump_image(d, c->conv, c->out_path, &picked);
    rc = rc || mcp__exr_band_file_rows(&c->out, picked, y0);
    mcp_dump_free(d);
    mcp_image_free(picked);
    mcp_image_free(rows);
    return rc ? -1 : 0;
}

int
mcp__convert_streamed(const char *in, const char *out, char **names, int count,
                      const mcp_dump_spec *dump, mcp_convention conv,
                      const mcp_write_options *wo, int *done)
{
    *done = 0;
    const int rows = mcp__stream_band_rows();
    if (!rows || wo->exr_tiled || mcp_format_from_path(in) != MCP_FORMAT_EXR ||
        mcp_format_from_path(out) != MCP_FORMAT_EXR)
        return 0;
    convert_ctx c = {.conv = conv, .names = names, .count = count, .out_path = out};
    int width = 0, height = 0, rc = -1;
    if (dump) {
        mcp_dump_spec spec = *dump;
        spec.path = in;
        if (mcp__dump_bands_open(&spec, &c.dump)) return -1;
        if (!c.dump) return 0; /* read whole */
        mcp__dump_bands_size(c.dump, &width, &height);
    } else {
        if (mcp__exr_rows_open(in, &c.image)) return -1;
        mcp__exr_rows_header(c.image, &width, &height);
    }
    *done = 1;
    char label[96];
    snprintf(label, sizeof label, "convert %s", in);
    if (mcp__exr_band_file_begin(&c.out, out, width, height, wo) == 0)
        rc = mcp__exr_band_file_end(
            &c.out, mcp__stream_bands(label, width, height, rows, convert_band, &c) != 0);
    mcp__exr_rows_close(c.image);
    mcp__dump_bands_close(c.dump);
    return rc;
}
