/* pfm.c: Portable Float Map read/write, done by hand because OpenImageIO 2.4 cannot
 * write PFM (docs/libraries.md §3). Rows are stored bottom to top; a negative scale
 * means little-endian. Colour files ("PF") hold R,G,B; grey files ("Pf") hold Y. */
#define _POSIX_C_SOURCE 200809L /* fmemopen */
#include "internal.h"
#include "../core/internal.h"

#include <ctype.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int
host_is_little_endian(void)
{
    const uint16_t one = 1;
    return *(const uint8_t *)&one == 1;
}

static void
swap_floats(float *v, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        uint8_t *b = (uint8_t *)&v[i], t;
        t = b[0], b[0] = b[3], b[3] = t;
        t = b[1], b[1] = b[2], b[2] = t;
    }
}

/* Bytes from the current position to the end of f, or -1. */
static long
bytes_left(FILE *f)
{
    long at = ftell(f), end;
    if (at < 0 || fseek(f, 0, SEEK_END) || (end = ftell(f)) < 0 || fseek(f, at, SEEK_SET))
        return -1;
    return end - at;
}

/* Reads a PFM from the stream f (a file or a buffer), named path in messages. */
static int
read_stream(FILE *f, const char *path, mcp_image **out)
{
    char magic[3] = {0};
    int w = 0, h = 0, rc = -1;
    double scale = 0;
    mcp_image *img = NULL;
    /* "PF" or "Pf", whitespace (so "PFx" or "Pf3 2" is no PFM), width, height, scale,
       and exactly one whitespace character before the data */
    if (fread(magic, 1, 2, f) != 2 || (strcmp(magic, "PF") && strcmp(magic, "Pf")) ||
        !isspace(fgetc(f)) || fscanf(f, "%d %d %lf", &w, &h, &scale) != 3 || scale == 0 ||
        !isfinite(scale) || !isspace(fgetc(f))) {
        mcp_error("%s: not a PFM file (bad header)", path);
        goto done;
    }
    int channels = magic[1] == 'F' ? 3 : 1;
    static const char *rgb[] = {"R", "G", "B"}, *grey[] = {"Y"};
    if (mcp_image_check_size(w, h, channels)) {
        mcp_error_prefix("%s: ", path);
        goto done;
    }
    /* the file must hold the pixels before they are allocated: a 16-byte header can
       claim gigabytes */
    size_t bytes = (size_t)w * (size_t)h * (size_t)channels * sizeof(float);
    long left = bytes_left(f);
    if (left < 0 || (unsigned long)left < bytes) {
        mcp_error(
            "%s: truncated PFM data (%dx%d pixels need %zu bytes, the file holds %ld)",
            path, w, h, bytes, left < 0 ? 0L : left);
        goto done;
    }
    if (mcp_image_new(w, h, channels, channels == 3 ? rgb : grey, &img) ||
        mcp_image_set_source(img, path))
        goto done;
    size_t row = (size_t)w * channels;
    for (int y = h - 1; y >= 0; y--)
        if (fread(mcp_image_px(img, 0, y), sizeof(float), row, f) != row) {
            mcp_error("%s: truncated PFM data (row %d of %d missing)", path, h - y, h);
            goto done;
        }
    if ((scale < 0) != host_is_little_endian()) swap_floats(img->data, row * (size_t)h);
    *out = img;
    img = NULL;
    rc = 0;
done:
    mcp_image_free(img);
    return rc;
}

int
mcp__pfm_read(const char *path, mcp_image **out)
{
    *out = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) return mcp_error("%s: cannot open", path);
    int rc = read_stream(f, path, out);
    fclose(f);
    return rc;
}

int
mcp__pfm_read_memory(const void *data, size_t size, const char *name, mcp_image **out)
{
    *out = NULL;
    if (!data || !size) return mcp_error("%s: not a PFM file (bad header)", name);
    /* a read-only stream over the caller's bytes, so that one parser serves both; "r"
       never writes through the cast-away const */
    FILE *f = fmemopen((void *)(uintptr_t)data, size, "rb");
    if (!f) return mcp_error("%s: cannot read from memory", name);
    int rc = read_stream(f, name, out);
    fclose(f);
    return rc;
}

int
mcp__pfm_write(const mcp_image *img, const char *path)
{
    if (img->channels != 1 && img->channels != 3)
        return mcp_error("%s: PFM holds 1 or 3 channels, not %d (pick channels first)",
                         path, img->channels);
    FILE *f = fopen(path, "wb");
    if (!f) return mcp_error("%s: cannot create", path);
    size_t row = (size_t)img->width * img->channels;
    float *buf = mcp_malloc(row * sizeof(float));
    int ok = buf != NULL;
    ok = ok && fprintf(f, "%s\n%d %d\n%s\n", img->channels == 3 ? "PF" : "Pf", img->width,
                       img->height, host_is_little_endian() ? "-1.0" : "1.0") > 0;
    for (int y = img->height - 1; ok && y >= 0; y--) {
        for (int x = 0; x < img->width; x++)
            memcpy(buf + (size_t)x * img->channels, mcp_image_px(img, x, y),
                   (size_t)img->channels * sizeof(float));
        ok = fwrite(buf, sizeof(float), row, f) == row;
    }
    free(buf);
    if (fclose(f) != 0 || !ok) return mcp_error("%s: write failed (disk full?)", path);
    return 0;
}
