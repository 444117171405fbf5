/* png.c: PNG through libpng, without the OpenImageIO plug-in.
 *
 * Reports write a dozen PNGs (previews, colour maps, spectra) and metrics often read PNG
 * pairs; going through OIIO meant loading its plug-in and dependency tree first (a
 * quarter of a second) for a format that libpng reads and writes directly. The values are
 * OIIO's: integer samples are divided by their maximum (255 or 65535), channels are
 * named Y, YA, RGB or RGBA, and the caller decodes sRGB; writing rounds clamped values to
 * 8 bits. libpng reports errors by longjmp, so every object that must be freed on an
 * error lives outside the setjmp frame's locals (volatile or in the context struct). */
#define _POSIX_C_SOURCE 200809L /* fileno */
#include "internal.h"
#include "../core/internal.h"

#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* Deflate expands at most 1032:1, so a file of n bytes holds at most this many bytes of
 * filtered rows; a header that claims more is refused before anything is allocated. */
#define DEFLATE_MAX_RATIO 1032

typedef struct {
    const char *path;
    char message[256];
} png_ctx;

static void
on_error(png_structp png, png_const_charp msg)
{
    png_ctx *ctx = png_get_error_ptr(png);
    snprintf(ctx->message, sizeof ctx->message, "%s", msg);
    png_longjmp(png, 1);
}

static void
on_warning(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg; /* warnings (a bad gamma chunk, say) do not stop the read */
}

static const char *const *
channel_names(int channels)
{
    static const char *const y[] = {"Y"}, *const ya[] = {"Y", "A"},
                             *const rgb[] = {"R", "G", "B"},
                             *const rgba[] = {"R", "G", "B", "A"};
    return channels == 1 ? y : channels == 2 ? ya : channels == 3 ? rgb : rgba;
}

int
mcp__png_read(const char *path, const mcp_read_options *opt, mcp_image **out)
{
    *out = NULL;
    struct stat st;
    FILE *f = fopen(path, "rb");
    if (!f || fstat(fileno(f), &st) != 0) {
        if (f) fclose(f);
        return mcp_error("%s: cannot open", path);
    }
    png_ctx ctx = {path, ""};
    png_structp png =
        png_create_read_struct(PNG_LIBPNG_VER_STRING, &ctx, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    unsigned char *volatile pixels = NULL;
    png_bytep *volatile rows = NULL;
    mcp_image *volatile img = NULL;
    int rc = -1;
    if (!png || !info) {
        mcp_error("%s: out of memory (PNG reader)", path);
        goto done;
    }
    if (setjmp(png_jmpbuf(png))) {
        mcp_error("%s: not a readable PNG file (%s)", path, ctx.message);
        goto done;
    }
    png_init_io(png, f);
    png_read_info(png, info);
    /* palettes and low bit depths to 8 bits, transparency to alpha, 16 bits to host
     * order: the rows then hold plain samples */
    png_set_expand(png);
    if (png_get_bit_depth(png, info) == 16) png_set_swap(png);
    png_read_update_info(png, info);
    int w = (int)png_get_image_width(png, info), h = (int)png_get_image_height(png, info);
    int c = png_get_channels(png, info), bits = png_get_bit_depth(png, info);
    if (mcp_image_check_size(w, h, c)) {
        mcp_error_prefix("%s: ", path);
        goto done;
    }
    size_t row_bytes = png_get_rowbytes(png, info);
    double claimed = ((double)row_bytes + 1.0) * h;
    if (claimed > (double)DEFLATE_MAX_RATIO * (double)st.st_size) {
        mcp_error("%s: truncated PNG (%dx%d pixels cannot come from %lld bytes)", path, w,
                  h, (long long)st.st_size);
        goto done;
    }
    pixels = mcp_malloc(row_bytes * (size_t)h);
    rows = mcp_malloc((size_t)h * sizeof *rows);
    if (!pixels || !rows) goto done;
    for (int y = 0; y < h; y++)
        rows[y] = pixels + (size_t)y * row_bytes;
    png_read_image(png, rows);
    png_read_end(png, NULL);
    mcp_image *im = NULL;
    if (mcp_image_new(w, h, c, channel_names(c), &im)) goto done;
    img = im;
    if (mcp_image_set_source(im, path)) goto done;
    /* every sample value's float, decoded and not, from a table: a powf per value was
     * most of a 1080p read */
    int levels = bits == 16 ? 65536 : 256;
    float *lut = mcp_malloc(2 * (size_t)levels * sizeof *lut);
    if (!lut) goto done;
    for (int k = 0; k < levels; k++) {
        lut[k] = (float)k / (float)(levels - 1);
        lut[levels + k] = opt->srgb_decode ? mcp_srgb_to_linear(lut[k]) : lut[k];
    }
    int alpha = c == 2 || c == 4 ? c - 1 : -1;
#pragma omp parallel for schedule(static) if ((size_t)w * h >= 65536)
    for (int y = 0; y < h; y++) {
        float *o = im->data + (size_t)y * w * c;
        for (int i = 0; i < w * c; i++) {
            int k = bits == 16 ? ((const uint16_t *)rows[y])[i] : rows[y][i];
            /* integer files hold sRGB-encoded values; alpha stays linear */
            o[i] = lut[i % c == alpha ? k : levels + k];
        }
    }
    free(lut);
    *out = im;
    img = NULL;
    rc = 0;
done:
    png_destroy_read_struct(png ? &png : NULL, info ? &info : NULL, NULL);
    mcp_image_free(img);
    free(rows);
    free(pixels);
    fclose(f);
    return rc;
}

int
mcp__png_write(const mcp_image *img, const char *path, const mcp_write_options *opt)
{
    int w = img->width, h = img->height, c = img->channels;
    if (c != 1 && c != 3 && c != 4)
        return mcp_error("%s: png takes 1, 3 or 4 channels, not %d (pick channels first)",
                         path, c);
    unsigned char *bytes = mcp_malloc((size_t)w * h * c);
    if (!bytes) return -1;
    const int in_order[4] = {0, 1, 2, 3};
    mcp__srgb8_bytes(img, in_order, c, opt->srgb_encode, bytes);
    int rc = mcp__png_write_bytes(bytes, w, h, c, path);
    free(bytes);
    return rc;
}
