/* exr.c: OpenEXR read/write through the OpenEXR Core C API (3.1).
 *
 * Reads the first part, scanline or tiled (level 0), any compression Core decodes
 * (not DWAA/DWAB: Core 3.1 cannot, and we say so), float/half/uint channels, data
 * windows with offsets (the image covers the data window; its origin is kept as the
 * int attributes "dataWindowX"/"dataWindowY" when not 0), and int/float/double/string
 * header attributes. Writes scanline or tiled, float or half. notes/libraries.md 2a
 * lists the Core pitfalls this file works around. */
#define _POSIX_C_SOURCE 200809L
#include "internal.h"

#include <openexr.h>

#include <sys/stat.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Core reports detail through a callback; keep the last message per thread so that
 * our one-line error can carry it (the default handler prints to stderr). */
static _Thread_local char exr_last_message[512];

static void
exr_capture_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void)ctxt;
    snprintf(exr_last_message, sizeof exr_last_message, "%s",
             msg ? msg : exr_get_default_error_message(code));
}

static int
exr_fail(const char *path, const char *what, exr_result_t rc)
{
    const char *detail = exr_last_message[0] ? exr_last_message
                                               : exr_get_default_error_message(rc);
    return mcp_error("%s: %s: %s", path, what, detail);
}

static const char *
compression_name(exr_compression_t c)
{
    static const char *names[] = {"none", "rle",  "zips", "zip", "piz",
                                  "pxr24", "b44", "b44a", "dwaa", "dwab"};
    return (unsigned)c < sizeof names / sizeof *names ? names[c] : "unknown";
}

/* ---- reading ---- */

static int
read_attributes(exr_context_t f, mcp_attrs *attrs)
{
    int32_t count = 0;
    if (exr_get_attribute_count(f, 0, &count) != EXR_ERR_SUCCESS)
        return 0;
    for (int i = 0; i < count; i++) {
        const exr_attribute_t *a = NULL;
        if (exr_get_attribute_by_index(f, 0, EXR_ATTR_LIST_FILE_ORDER, i, &a) ||
            !a)
            continue;
        int rc = 0;
        switch (a->type) {
        case EXR_ATTR_INT: rc = mcp_attrs_set_int(attrs, a->name, a->i); break;
        case EXR_ATTR_FLOAT: rc = mcp_attrs_set_float(attrs, a->name, a->f); break;
        case EXR_ATTR_DOUBLE: rc = mcp_attrs_set_double(attrs, a->name, a->d); break;
        case EXR_ATTR_STRING: {
            /* the part's own "name" and "type" attributes are structure, not metadata */
            if (strcmp(a->name, "name") == 0 || strcmp(a->name, "type") == 0)
                break;
            char *s = mcp_malloc((size_t)a->string->length + 1);
            if (!s)
                return -1;
            memcpy(s, a->string->str, (size_t)a->string->length);
            s[a->string->length] = '\0';
            rc = mcp_attrs_set_string(attrs, a->name, s);
            free(s);
            break;
        }
        default: break; /* matrices, boxes, chromaticities: not needed downstream */
        }
        if (rc)
            return -1;
    }
    return 0;
}

/* Decodes one chunk into img at (x0, y0) of the data window. */
static int
decode_chunk(exr_context_t f, const exr_chunk_info_t *ci, exr_decode_pipeline_t *dec,
             int *initialised, mcp_image *img, int x0, int y0, const char *path)
{
    exr_result_t rc = *initialised ? exr_decoding_update(f, 0, ci, dec)
                                   : exr_decoding_initialize(f, 0, ci, dec);
    if (rc != EXR_ERR_SUCCESS)
        return exr_fail(path, "cannot decode", rc);
    for (int k = 0; k < dec->channel_count; k++) {
        exr_coding_channel_info_t *ch = &dec->channels[k];
        int c = mcp_image_channel(img, ch->channel_name);
        ch->decode_to_ptr = (uint8_t *)mcp_image_px(img, x0, y0) + (size_t)c * sizeof(float);
        ch->user_pixel_stride = (int32_t)(img->pixel_stride * (ptrdiff_t)sizeof(float));
        ch->user_line_stride = (int32_t)(img->row_stride * (ptrdiff_t)sizeof(float));
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = 4;
    }
    if (!*initialised) {
        if ((rc = exr_decoding_choose_default_routines(f, 0, dec)) != EXR_ERR_SUCCESS)
            return exr_fail(path, "cannot decode", rc);
        *initialised = 1;
    }
    if ((rc = exr_decoding_run(f, 0, dec)) != EXR_ERR_SUCCESS)
        return exr_fail(path, "corrupt or truncated pixel data", rc);
    return 0;
}

/* Called for each level-0 chunk with its info and its place (x0, y0) in the image. */
typedef int (*chunk_visit)(exr_context_t f, const exr_chunk_info_t *ci, int x0, int y0,
                           void *ctx);

/* Visits every level-0 chunk of part 0 of a w x h data window, in order. */
static int
each_chunk(exr_context_t f, exr_storage_t storage, const exr_attr_box2i_t *dw, int w,
           int h, const char *path, chunk_visit visit, void *ctx)
{
    exr_chunk_info_t ci;
    int rc = 0;
    if (storage == EXR_STORAGE_SCANLINE) {
        int32_t lines = 1;
        if (exr_get_scanlines_per_chunk(f, 0, &lines) != EXR_ERR_SUCCESS || lines < 1)
            lines = 1;
        /* long long: max.y may be INT32_MAX, and y + lines must not overflow */
        for (long long y = dw->min.y; y <= dw->max.y && !rc; y += lines) {
            exr_result_t r = exr_read_scanline_chunk_info(f, 0, (int)y, &ci);
            rc = r != EXR_ERR_SUCCESS
                     ? exr_fail(path, "corrupt or truncated chunk table", r)
                     : visit(f, &ci, 0, ci.start_y - dw->min.y, ctx);
        }
    } else {
        uint32_t tw, th;
        exr_tile_level_mode_t level;
        exr_tile_round_mode_t round;
        exr_result_t r = exr_get_tile_descriptor(f, 0, &tw, &th, &level, &round);
        if (r != EXR_ERR_SUCCESS)
            return exr_fail(path, "bad tile description", r);
        if (tw < 1 || th < 1 || tw > (uint32_t)MCP_MAX_DIM || th > (uint32_t)MCP_MAX_DIM)
            return mcp_error("%s: bad tile size %ux%u", path, tw, th);
        int nx = (w + (int)tw - 1) / (int)tw, ny = (h + (int)th - 1) / (int)th;
        for (int ty = 0; ty < ny && !rc; ty++)
            for (int tx = 0; tx < nx && !rc; tx++) {
                r = exr_read_tile_chunk_info(f, 0, tx, ty, 0, 0, &ci);
                rc = r != EXR_ERR_SUCCESS
                         ? exr_fail(path, "corrupt or truncated tile table", r)
                         : visit(f, &ci, tx * (int)tw, ty * (int)th, ctx);
            }
    }
    return rc;
}

/* ---- what the file can hold, checked before the image is allocated ---- */

typedef struct chunk_budget {
    const char *path;
    unsigned long long file_bytes;   /* the file's size */
    unsigned long long packed_bytes; /* the chunks' stored bytes so far */
    int uncompressed;
} chunk_budget;

static int
chunk_fits(exr_context_t f, const exr_chunk_info_t *ci, int x0, int y0, void *ctx)
{
    (void)f;
    (void)x0;
    (void)y0;
    chunk_budget *b = ctx;
    unsigned long long at = ci->data_offset, n = ci->packed_size;
    if (at > b->file_bytes || n > b->file_bytes - at)
        return mcp_error("%s: chunk %d (%llu bytes at offset %llu) lies outside the file "
                         "(%llu bytes)",
                         b->path, ci->idx, n, at, b->file_bytes);
    /* chunks do not overlap in a valid file, so together they fit in it; stored
       uncompressed, each holds all its pixels */
    b->packed_bytes += n;
    if (b->packed_bytes > b->file_bytes)
        return mcp_error("%s: the chunks hold more bytes than the file (%llu)", b->path,
                         b->file_bytes);
    if (b->uncompressed && n < ci->unpacked_size)
        return mcp_error("%s: truncated chunk %d (%llu of %llu bytes)", b->path, ci->idx,
                         n, (unsigned long long)ci->unpacked_size);
    return 0;
}

/* Checks that the chunk table and every chunk of the w x h data window lie inside the
 * file, so that a small file cannot make us allocate a large image. A compressed
 * chunk can still expand a lot (zip about 1000 times): mcp_image_new's ceiling bounds
 * that. */
static int
check_file_holds(exr_context_t f, exr_storage_t storage, exr_compression_t comp,
                 const exr_attr_box2i_t *dw, int w, int h, const char *path)
{
    struct stat st;
    int32_t chunks = 0;
    if (stat(path, &st) || st.st_size < 0)
        return mcp_error("%s: cannot stat: %s", path, strerror(errno));
    chunk_budget b = {path, (unsigned long long)st.st_size, 0,
                      comp == EXR_COMPRESSION_NONE};
    exr_result_t r = exr_get_chunk_count(f, 0, &chunks);
    if (r != EXR_ERR_SUCCESS) return exr_fail(path, "bad chunk count", r);
    /* each chunk costs 8 bytes of table and at least 8 (scanline) or 20 (tile) bytes
       of its own header */
    unsigned long long per_chunk = storage == EXR_STORAGE_TILED ? 28 : 16;
    if (chunks < 1 || (unsigned long long)chunks * per_chunk > b.file_bytes)
        return mcp_error("%s: %d chunks of %lldx%lld pixels cannot fit in a file of %llu "
                         "bytes (truncated or corrupt)",
                         path, chunks, (long long)w, (long long)h, b.file_bytes);
    return each_chunk(f, storage, dw, w, h, path, chunk_fits, &b);
}

/* ---- decoding ---- */

typedef struct decoder {
    exr_decode_pipeline_t dec;
    int initialised;
    mcp_image *img;
    const char *path;
} decoder;

static int
chunk_decode(exr_context_t f, const exr_chunk_info_t *ci, int x0, int y0, void *ctx)
{
    decoder *d = ctx;
    return decode_chunk(f, ci, &d->dec, &d->initialised, d->img, x0, y0, d->path);
}

static int
read_pixels(exr_context_t f, exr_storage_t storage, const exr_attr_box2i_t *dw,
            mcp_image *img, const char *path)
{
    decoder d = {EXR_DECODE_PIPELINE_INITIALIZER, 0, img, path};
    int rc = each_chunk(f, storage, dw, img->width, img->height, path, chunk_decode, &d);
    if (d.initialised) exr_decoding_destroy(f, &d.dec);
    return rc;
}

int
mcp__exr_read(const char *path, mcp_image **out)
{
    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    exr_last_message[0] = '\0';
    *out = NULL;
    exr_result_t r = exr_start_read(&f, path, &init);
    if (r != EXR_ERR_SUCCESS)
        return exr_fail(path, "cannot read as OpenEXR", r);

    int rc = -1;
    mcp_image *img = NULL;
    const char **names = NULL;
    exr_storage_t storage;
    exr_attr_box2i_t dw;
    exr_compression_t comp;
    const exr_attr_chlist_t *chans = NULL;
    if ((r = exr_get_storage(f, 0, &storage)) || (r = exr_get_data_window(f, 0, &dw)) ||
        (r = exr_get_compression(f, 0, &comp)) || (r = exr_get_channels(f, 0, &chans))) {
        exr_fail(path, "bad header", r);
        goto done;
    }
    if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) {
        mcp_error("%s: deep EXR images are not supported", path);
        goto done;
    }
    if (comp == EXR_COMPRESSION_DWAA || comp == EXR_COMPRESSION_DWAB) {
        mcp_error("%s: %s compression cannot be read by the OpenEXR Core library; "
                  "re-save it with zip or piz compression",
                  path, compression_name(comp));
        goto done;
    }
    long long w = (long long)dw.max.x - dw.min.x + 1, h = (long long)dw.max.y - dw.min.y + 1;
    if (w < 1 || h < 1 || w > MCP_MAX_DIM || h > MCP_MAX_DIM || chans->num_channels < 1) {
        mcp_error("%s: bad data window %lldx%lld with %d channels", path, w, h,
                  chans->num_channels);
        goto done;
    }
    /* the ceiling first (cheap), then what the file can hold, then the allocation */
    if (mcp_image_check_size((int)w, (int)h, chans->num_channels)) {
        mcp_error_prefix("%s: ", path);
        goto done;
    }
    if (check_file_holds(f, storage, comp, &dw, (int)w, (int)h, path)) goto done;
    names = mcp_calloc((size_t)chans->num_channels, sizeof *names);
    if (!names)
        goto done;
    for (int c = 0; c < chans->num_channels; c++) {
        const exr_attr_chlist_entry_t *e = &chans->entries[c];
        if (e->x_sampling != 1 || e->y_sampling != 1) {
            mcp_error("%s: channel '%s' is subsampled (%dx%d), which is not supported",
                      path, e->name.str, e->x_sampling, e->y_sampling);
            goto done;
        }
        names[c] = e->name.str;
    }
    if (mcp_image_new((int)w, (int)h, chans->num_channels, names, &img) ||
        mcp_image_set_source(img, path) || read_pixels(f, storage, &dw, img, path) ||
        read_attributes(f, &img->attrs))
        goto done;
    if ((dw.min.x || dw.min.y) &&
        (mcp_attrs_set_int(&img->attrs, "dataWindowX", dw.min.x) ||
         mcp_attrs_set_int(&img->attrs, "dataWindowY", dw.min.y)))
        goto done;
    *out = img;
    img = NULL;
    rc = 0;
done:
    free(names);
    mcp_image_free(img);
    exr_finish(&f);
    return rc;
}

/* ---- writing ---- */

static const exr_compression_t compression_of[] = {
    [MCP_EXR_NONE] = EXR_COMPRESSION_NONE,   [MCP_EXR_RLE] = EXR_COMPRESSION_RLE,
    [MCP_EXR_ZIPS] = EXR_COMPRESSION_ZIPS,   [MCP_EXR_ZIP] = EXR_COMPRESSION_ZIP,
    [MCP_EXR_PIZ] = EXR_COMPRESSION_PIZ,     [MCP_EXR_PXR24] = EXR_COMPRESSION_PXR24,
    [MCP_EXR_B44] = EXR_COMPRESSION_B44,     [MCP_EXR_B44A] = EXR_COMPRESSION_B44A,
    [MCP_EXR_DWAA] = EXR_COMPRESSION_DWAA,   [MCP_EXR_DWAB] = EXR_COMPRESSION_DWAB,
};

static int
write_attributes(exr_context_t f, const mcp_attrs *attrs)
{
    for (int i = 0; i < attrs->count; i++) {
        const mcp_attr *a = &attrs->items[i];
        /* structural attributes are written by Core itself */
        static const char *reserved[] = {"channels", "compression", "dataWindow",
                                         "displayWindow", "lineOrder", "pixelAspectRatio",
                                         "screenWindowCenter", "screenWindowWidth",
                                         "tiles", "type", "name", "chunkCount",
                                         "dataWindowX", "dataWindowY", NULL};
        int skip = 0;
        for (const char **r = reserved; *r; r++)
            skip |= strcmp(*r, a->name) == 0;
        if (skip)
            continue;
        exr_result_t r = EXR_ERR_SUCCESS;
        switch (a->type) {
        case MCP_ATTR_INT:
            if (a->i >= INT32_MIN && a->i <= INT32_MAX)
                r = exr_attr_set_int(f, 0, a->name, (int32_t)a->i);
            else
                r = exr_attr_set_double(f, 0, a->name, (double)a->i);
            break;
        case MCP_ATTR_FLOAT: r = exr_attr_set_float(f, 0, a->name, (float)a->f); break;
        case MCP_ATTR_DOUBLE: r = exr_attr_set_double(f, 0, a->name, a->f); break;
        case MCP_ATTR_STRING: r = exr_attr_set_string(f, 0, a->name, a->s); break;
        }
        if (r != EXR_ERR_SUCCESS)
            return mcp_error("cannot write attribute '%s': %s", a->name,
                             exr_get_default_error_message(r));
    }
    return 0;
}

/* OpenEXR Core 3.1.5 writes a corrupt chunk when ZIP/ZIPS output is not smaller than
 * the raw data (the file must then hold the raw bytes; Core stores something else, and
 * both Core and the C++ library read garbage back). Wrap the compressor: keep the raw
 * packed bytes, and where compression did not pay, put exactly those bytes out. */
typedef struct raw_copy {
    exr_result_t (*compress)(exr_encode_pipeline_t *);
    void *bytes;
    size_t cap;
} raw_copy;

static exr_result_t
compress_or_store_raw(exr_encode_pipeline_t *enc)
{
    raw_copy *raw = enc->encoding_user_data;
    if (raw->cap < enc->packed_bytes) {
        void *grown = realloc(raw->bytes, enc->packed_bytes);
        if (!grown)
            return EXR_ERR_OUT_OF_MEMORY;
        raw->bytes = grown;
        raw->cap = enc->packed_bytes;
    }
    memcpy(raw->bytes, enc->packed_buffer, enc->packed_bytes);
    exr_result_t rc = raw->compress(enc);
    if (rc == EXR_ERR_SUCCESS && enc->compressed_bytes >= enc->packed_bytes) {
        if (enc->compressed_alloc_size < enc->packed_bytes)
            return EXR_ERR_CORRUPT_CHUNK;
        memcpy(enc->compressed_buffer, raw->bytes, enc->packed_bytes);
        enc->compressed_bytes = enc->packed_bytes;
    }
    return rc;
}

static int
encode_chunk(exr_context_t f, const exr_chunk_info_t *ci, exr_encode_pipeline_t *enc,
             int *initialised, raw_copy *raw, const mcp_image *img, int x0, int y0,
             const char *path)
{
    exr_result_t rc = *initialised ? exr_encoding_update(f, 0, ci, enc)
                                   : exr_encoding_initialize(f, 0, ci, enc);
    if (rc != EXR_ERR_SUCCESS)
        return exr_fail(path, "cannot encode", rc);
    for (int k = 0; k < enc->channel_count; k++) {
        exr_coding_channel_info_t *ch = &enc->channels[k];
        /* Core sorts channels by name: map them back by name, not position */
        int c = mcp_image_channel(img, ch->channel_name);
        ch->encode_from_ptr =
            (const uint8_t *)(mcp_image_px(img, x0, y0) + c);
        ch->user_pixel_stride = (int32_t)(img->pixel_stride * (ptrdiff_t)sizeof(float));
        ch->user_line_stride = (int32_t)(img->row_stride * (ptrdiff_t)sizeof(float));
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = 4;
    }
    if (!*initialised) {
        if ((rc = exr_encoding_choose_default_routines(f, 0, enc)) != EXR_ERR_SUCCESS)
            return exr_fail(path, "cannot encode", rc);
        if (enc->compress_fn && raw) {
            raw->compress = enc->compress_fn;
            enc->compress_fn = compress_or_store_raw;
        }
        *initialised = 1;
    }
    enc->encoding_user_data = raw;
    if ((rc = exr_encoding_run(f, 0, enc)) != EXR_ERR_SUCCESS)
        return exr_fail(path, "cannot write pixel data", rc);
    return 0;
}

static int
write_pixels(exr_context_t f, const mcp_image *img, const mcp_write_options *opt,
             const char *path)
{
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    exr_chunk_info_t ci;
    raw_copy raw = {NULL, NULL, 0};
    int initialised = 0, rc = 0;
    if (!opt->exr_tiled) {
        int32_t lines = 1;
        exr_get_scanlines_per_chunk(f, 0, &lines);
        for (int y = 0; y < img->height && !rc; y += lines) {
            exr_result_t r = exr_write_scanline_chunk_info(f, 0, y + opt->exr_data_y, &ci);
            rc = r != EXR_ERR_SUCCESS ? exr_fail(path, "cannot write", r)
                                      : encode_chunk(f, &ci, &enc, &initialised, &raw, img,
                                                     0, y, path);
        }
    } else {
        int t = opt->exr_tile_size;
        for (int ty = 0; ty * t < img->height && !rc; ty++)
            for (int tx = 0; tx * t < img->width && !rc; tx++) {
                exr_result_t r = exr_write_tile_chunk_info(f, 0, tx, ty, 0, 0, &ci);
                rc = r != EXR_ERR_SUCCESS ? exr_fail(path, "cannot write", r)
                                          : encode_chunk(f, &ci, &enc, &initialised, &raw,
                                                         img, tx * t, ty * t, path);
            }
    }
    if (initialised)
        exr_encoding_destroy(f, &enc);
    free(raw.bytes);
    return rc;
}

int
mcp__exr_write(const mcp_image *img, const char *path, const mcp_write_options *opt)
{
    if (opt->compression == MCP_EXR_DWAA || opt->compression == MCP_EXR_DWAB ||
        opt->compression == MCP_EXR_B44 || opt->compression == MCP_EXR_B44A)
        /* Core 3.1.5 cannot encode DWA and writes corrupt B44 (notes/libraries.md) */
        return mcp_error("%s: cannot write %s compression with the OpenEXR Core library; "
                         "use zip, piz, rle, zips, pxr24 or none",
                         path, compression_name(compression_of[opt->compression]));
    if (opt->exr_tiled && (opt->exr_tile_size < 1 || opt->exr_tile_size > 4096))
        return mcp_error("%s: bad tile size %d", path, opt->exr_tile_size);

    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    exr_last_message[0] = '\0';
    /* imageio.c already writes to a temporary name and renames */
    exr_result_t r = exr_start_write(&f, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (r != EXR_ERR_SUCCESS)
        return exr_fail(path, "cannot create", r);
    int part, rc = -1;
    exr_attr_box2i_t dw;
    dw.min.x = opt->exr_data_x;
    dw.min.y = opt->exr_data_y;
    dw.max.x = opt->exr_data_x + img->width - 1;
    dw.max.y = opt->exr_data_y + img->height - 1;
    exr_attr_box2i_t disp = dw;
    exr_attr_v2f_t centre;
    centre.x = centre.y = 0.0f;
    if ((r = exr_add_part(f, "main",
                          opt->exr_tiled ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE,
                          &part)) ||
        (r = exr_initialize_required_attr(f, part, &disp, &dw, 1.0f, &centre, 1.0f,
                                          EXR_LINEORDER_INCREASING_Y,
                                          compression_of[opt->compression])) ||
        (opt->exr_tiled &&
         (r = exr_set_tile_descriptor(f, part, (uint32_t)opt->exr_tile_size,
                                      (uint32_t)opt->exr_tile_size, EXR_TILE_ONE_LEVEL,
                                      EXR_TILE_ROUND_DOWN)))) {
        exr_fail(path, "cannot write header", r);
        goto done;
    }
    for (int c = 0; c < img->channels; c++) {
        for (int d = 0; d < c; d++)
            if (strcmp(img->names[c], img->names[d]) == 0) {
                mcp_error("%s: channel name '%s' appears twice", path, img->names[c]);
                goto done;
            }
        r = exr_add_channel(f, part, img->names[c],
                            opt->exr_pixel == MCP_EXR_HALF ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT,
                            EXR_PERCEPTUALLY_LINEAR, 1, 1);
        if (r != EXR_ERR_SUCCESS) {
            exr_fail(path, "bad channel name", r);
            goto done;
        }
    }
    if (write_attributes(f, &img->attrs)) {
        mcp_error_prefix("%s: ", path);
        goto done;
    }
    if ((r = exr_write_header(f)) != EXR_ERR_SUCCESS) {
        exr_fail(path, "cannot write header", r);
        goto done;
    }
    rc = write_pixels(f, img, opt, path);
done:
    r = exr_finish(&f);
    if (!rc && r != EXR_ERR_SUCCESS)
        rc = exr_fail(path, "cannot finish writing", r);
    return rc;
}
