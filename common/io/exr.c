/* exr.c: OpenEXR read/write through the OpenEXR Core C API (3.1).
 *
 * Reads the first part, scanline or tiled (level 0), any compression Core decodes
 * (not DWAA/DWAB: Core 3.1 cannot, and we say so), float/half/uint channels, data
 * windows with offsets (the image covers the data window; its origin is kept as the
 * int attributes "dataWindowX"/"dataWindowY" when not 0), and int/float/double/string
 * header attributes, from a file or from memory (read_fn). Writes scanline or tiled,
 * float or half. Chunks are decoded and encoded in parallel (OpenMP), each thread with
 * its own Core pipeline; zip chunks that would not shrink enough are stored raw
 * (store_raw_after_probe). docs/libraries.md §2 lists the Core pitfalls this file
 * works around; docs/benchmarks.md ("EXR speed") has the measurements. */
#define _POSIX_C_SOURCE 200809L
#include "internal.h"
#include "../core/internal.h"
#include "exr_zip.h"

#include <openexr.h>

#include <sys/stat.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

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

/* What went wrong, for a message: out of memory in our words (callers tell it from a
 * corrupt file by them: replicates.c), else Core's last message. */
static const char *
exr_detail(exr_result_t rc)
{
    if (rc == EXR_ERR_OUT_OF_MEMORY) return "out of memory";
    return exr_last_message[0] ? exr_last_message : exr_get_default_error_message(rc);
}

static int
exr_fail(const char *path, const char *what, exr_result_t rc)
{
    return mcp_error("%s: %s: %s", path, what, exr_detail(rc));
}

static const char *
compression_name(exr_compression_t c)
{
    static const char *names[] = {"none",  "rle", "zips", "zip",  "piz",
                                  "pxr24", "b44", "b44a", "dwaa", "dwab"};
    return (unsigned)c < sizeof names / sizeof *names ? names[c] : "unknown";
}

/* ---- reading ---- */

static int
read_attributes(exr_context_t f, mcp_attrs *attrs)
{
    int32_t count = 0;
    if (exr_get_attribute_count(f, 0, &count) != EXR_ERR_SUCCESS) return 0;
    for (int i = 0; i < count; i++) {
        const exr_attribute_t *a = NULL;
        if (exr_get_attribute_by_index(f, 0, EXR_ATTR_LIST_FILE_ORDER, i, &a) || !a)
            continue;
        int rc = 0;
        switch (a->type) {
        case EXR_ATTR_INT:
            rc = mcp_attrs_set_int(attrs, a->name, a->i);
            break;
        case EXR_ATTR_FLOAT:
            rc = mcp_attrs_set_float(attrs, a->name, a->f);
            break;
        case EXR_ATTR_DOUBLE:
            rc = mcp_attrs_set_double(attrs, a->name, a->d);
            break;
        case EXR_ATTR_STRING: {
            /* the part's own "name" and "type" attributes are structure, not metadata */
            if (strcmp(a->name, "name") == 0 || strcmp(a->name, "type") == 0) break;
            char *s = mcp_malloc((size_t)a->string->length + 1);
            if (!s) return -1;
            memcpy(s, a->string->str, (size_t)a->string->length);
            s[a->string->length] = '\0';
            rc = mcp_attrs_set_string(attrs, a->name, s);
            free(s);
            break;
        }
        default:
            break; /* matrices, boxes, chromaticities: not needed downstream */
        }
        if (rc) return -1;
    }
    return 0;
}

/* ---- chunks ---- */

/* One level-0 chunk of part 0 and its place (x0, y0) in the image. */
typedef struct chunk_at {
    exr_chunk_info_t ci;
    int x0, y0;
} chunk_at;

/* Lists the level-0 chunks of part 0 of a w x h data window in file order (reading or
 * writing: the chunk-info calls differ). At most max_chunks of them, so that a header
 * cannot make us allocate more than the file's chunk count allows. The list is made
 * once, on one thread, so that the parallel loops below only read it. */
static int
list_chunks(exr_context_t f, exr_storage_t storage, const exr_attr_box2i_t *dw, int w,
            int h, int writing, long long max_chunks, const char *path, chunk_at **out,
            int *count)
{
    long long n;
    int32_t lines = 1;
    uint32_t tw = 1, th = 1;
    int nx = 1;
    *out = NULL;
    *count = 0;
    if (storage == EXR_STORAGE_SCANLINE) {
        if (exr_get_scanlines_per_chunk(f, 0, &lines) != EXR_ERR_SUCCESS || lines < 1)
            lines = 1;
        n = (h + (long long)lines - 1) / lines;
    } else {
        exr_tile_level_mode_t level;
        exr_tile_round_mode_t round;
        exr_result_t r = exr_get_tile_descriptor(f, 0, &tw, &th, &level, &round);
        if (r != EXR_ERR_SUCCESS) return exr_fail(path, "bad tile description", r);
        if (tw < 1 || th < 1 || tw > (uint32_t)MCP_MAX_DIM || th > (uint32_t)MCP_MAX_DIM)
            return mcp_error("%s: bad tile size %ux%u", path, tw, th);
        nx = (w + (int)tw - 1) / (int)tw;
        n = (long long)nx * ((h + (int)th - 1) / (int)th);
    }
    if (n > max_chunks)
        return mcp_error("%s: %lld chunks of %dx%d pixels, but the file has %lld "
                         "(truncated or corrupt)",
                         path, n, w, h, max_chunks);
    chunk_at *c = mcp_calloc((size_t)n, sizeof *c);
    if (!c) return -1;
    for (long long i = 0; i < n; i++) {
        exr_result_t r;
        if (storage == EXR_STORAGE_SCANLINE) {
            /* long long: max.y may be INT32_MAX, and y + lines must not overflow */
            long long y = dw->min.y + i * lines;
            r = writing ? exr_write_scanline_chunk_info(f, 0, (int)y, &c[i].ci)
                        : exr_read_scanline_chunk_info(f, 0, (int)y, &c[i].ci);
            c[i].y0 = c[i].ci.start_y - dw->min.y;
        } else {
            int tx = (int)(i % nx), ty = (int)(i / nx);
            r = writing ? exr_write_tile_chunk_info(f, 0, tx, ty, 0, 0, &c[i].ci)
                        : exr_read_tile_chunk_info(f, 0, tx, ty, 0, 0, &c[i].ci);
            c[i].x0 = tx * (int)tw;
            c[i].y0 = ty * (int)th;
        }
        if (r != EXR_ERR_SUCCESS) {
            free(c);
            return exr_fail(path,
                            writing ? "cannot write"
                            : storage == EXR_STORAGE_SCANLINE
                                ? "corrupt or truncated chunk table"
                                : "corrupt or truncated tile table",
                            r);
        }
    }
    *out = c;
    *count = (int)n;
    return 0;
}

/* The first chunk (in file order) that failed inside a parallel loop. Workers cannot
 * set mcpost's error (it is per thread), so they note what failed, with Core's message
 * from their own thread, and the calling thread reports it after the loop. Keeping the
 * lowest index makes the message the same whatever the thread count. */
typedef struct chunk_failure {
    int idx; /* -1: none */
    exr_result_t rc;
    const char *what;
    char detail[512];
} chunk_failure;

static void
note_failure(chunk_failure *fail, int idx, exr_result_t rc, const char *what)
{
#pragma omp critical(mcp_exr_chunk_failure)
    if (fail->idx < 0 || idx < fail->idx) {
        /* atomic: other threads poll idx (failed()) outside this critical section */
#pragma omp atomic write
        fail->idx = idx;
        fail->rc = rc;
        fail->what = what;
        snprintf(fail->detail, sizeof fail->detail, "%s", exr_detail(rc));
    }
}

static int
failed(const chunk_failure *fail)
{
    int idx;
#pragma omp atomic read
    idx = fail->idx;
    return idx >= 0;
}

static int
report_failure(const chunk_failure *fail, const char *path)
{
    return mcp_error("%s: %s: %s", path, fail->what, fail->detail);
}

/* ---- what the file can hold, checked before the image is allocated ---- */

/* Checks that the chunk table and every chunk of the w x h data window lie inside the
 * file of file_bytes bytes, so that a small file cannot make us allocate a large
 * image; lists the chunks for the decoder. A compressed chunk can still expand a lot
 * (zip about 1000 times): mcp_image_new's ceiling bounds that. */
static int
check_file_holds(exr_context_t f, exr_storage_t storage, exr_compression_t comp,
                 const exr_attr_box2i_t *dw, int w, int h, unsigned long long file_bytes,
                 const char *path, chunk_at **chunks_out, int *count)
{
    int32_t chunks = 0;
    exr_result_t r = exr_get_chunk_count(f, 0, &chunks);
    if (r != EXR_ERR_SUCCESS) return exr_fail(path, "bad chunk count", r);
    /* each chunk costs 8 bytes of table and at least 8 (scanline) or 20 (tile) bytes
       of its own header */
    unsigned long long per_chunk = storage == EXR_STORAGE_TILED ? 28 : 16;
    if (chunks < 1 || (unsigned long long)chunks * per_chunk > file_bytes)
        return mcp_error("%s: %d chunks of %lldx%lld pixels cannot fit in a file of %llu "
                         "bytes (truncated or corrupt)",
                         path, chunks, (long long)w, (long long)h, file_bytes);
    chunk_at *c;
    int n;
    if (list_chunks(f, storage, dw, w, h, 0, chunks, path, &c, &n)) return -1;
    unsigned long long packed_bytes = 0;
    for (int i = 0; i < n; i++) {
        const exr_chunk_info_t *ci = &c[i].ci;
        unsigned long long at = ci->data_offset, size = ci->packed_size;
        int bad = 0;
        if (at > file_bytes || size > file_bytes - at)
            bad = mcp_error("%s: chunk %d (%llu bytes at offset %llu) lies outside the "
                            "file (%llu bytes)",
                            path, ci->idx, size, at, file_bytes);
        /* chunks do not overlap in a valid file, so together they fit in it; stored
           uncompressed, each holds all its pixels */
        else if ((packed_bytes += size) > file_bytes)
            bad = mcp_error("%s: the chunks hold more bytes than the file (%llu)", path,
                            file_bytes);
        else if (comp == EXR_COMPRESSION_NONE && size < ci->unpacked_size)
            bad = mcp_error("%s: truncated chunk %d (%llu of %llu bytes)", path, ci->idx,
                            size, (unsigned long long)ci->unpacked_size);
        if (bad) {
            free(c);
            return -1;
        }
    }
    *chunks_out = c;
    *count = n;
    return 0;
}

/* ---- decoding ---- */

/* Zip chunks are inflated by exr_zip.c (libdeflate) instead of Core's zlib; Core has
 * read the chunk into packed_buffer and sized unpacked_buffer for it. A chunk whose
 * size equals its raw size was stored raw. */
static exr_result_t
decompress_zip_chunk(exr_decode_pipeline_t *dec)
{
    uint64_t packed = dec->chunk.packed_size, unpacked = dec->chunk.unpacked_size;
    if (packed == unpacked) {
        if (dec->unpacked_buffer != dec->packed_buffer)
            memcpy(dec->unpacked_buffer, dec->packed_buffer, unpacked);
        return EXR_ERR_SUCCESS;
    }
    int rc = mcp__zip_decode(dec->decoding_user_data, dec->packed_buffer, packed,
                             dec->unpacked_buffer, unpacked);
    return rc == 0    ? EXR_ERR_SUCCESS
           : rc == -2 ? EXR_ERR_OUT_OF_MEMORY
                      : EXR_ERR_CORRUPT_CHUNK;
}

/* Decodes one chunk at (x0, y0) of the data window to where routes say, with this
 * thread's pipeline; on failure *what says which step failed. named holds the file's
 * channel names in the routes' order. zip: this thread's zip decoder for a zip file,
 * NULL otherwise. */
static exr_result_t
decode_chunk(exr_context_t f, const chunk_at *c, exr_decode_pipeline_t *dec,
             int *initialised, mcp__zip_codec *zip, const mcp_image *named,
             const mcp__exr_route *routes, const char **what)
{
    *what = "cannot decode";
    exr_result_t rc = *initialised ? exr_decoding_update(f, 0, &c->ci, dec)
                                   : exr_decoding_initialize(f, 0, &c->ci, dec);
    if (rc != EXR_ERR_SUCCESS) return rc;
    for (int k = 0; k < dec->channel_count; k++) {
        exr_coding_channel_info_t *ch = &dec->channels[k];
        /* Core sorts channels by name: map them back by name, not position */
        const mcp__exr_route *r = &routes[mcp_image_channel(named, ch->channel_name)];
        /* a channel without a place is skipped: Core unpacks none of it */
        ch->decode_to_ptr = r->base
                                ? (uint8_t *)(r->base + (ptrdiff_t)c->y0 * r->row_stride +
                                              (ptrdiff_t)c->x0 * r->pixel_stride)
                                : NULL;
        ch->user_pixel_stride = (int32_t)(r->pixel_stride * (ptrdiff_t)sizeof(float));
        ch->user_line_stride = (int32_t)(r->row_stride * (ptrdiff_t)sizeof(float));
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = 4;
    }
    if (!*initialised) {
        if ((rc = exr_decoding_choose_default_routines(f, 0, dec)) != EXR_ERR_SUCCESS) {
            /* not initialised for the caller, who would not destroy it: undone here */
            exr_decoding_destroy(f, dec);
            *dec = (exr_decode_pipeline_t)EXR_DECODE_PIPELINE_INITIALIZER;
            return rc;
        }
        if (zip && dec->decompress_fn) {
            dec->decompress_fn = decompress_zip_chunk;
            dec->decoding_user_data = zip;
        }
        *initialised = 1;
    }
    *what = "corrupt or truncated pixel data";
    return exr_decoding_run(f, 0, dec);
}

/* ---- progress ---- */

/* A read or write of this many bytes of pixels or more takes about a second here and
 * shows a bar, "reading NAME" or "writing NAME" (a 4K dump of 12 float channels, 400 MB
 * of pixels, read in 1 to 3 s on the 2-core build machine under load). */
#define BAR_MIN_BYTES (128.0 * 1048576.0)

typedef struct chunk_bar {
    mcp_progress bar;
    int shown, finished;
} chunk_bar;

static void
chunk_bar_begin(chunk_bar *b, const char *verb, const char *path, double bytes, int n)
{
    memset(b, 0, sizeof *b);
    b->shown = bytes >= BAR_MIN_BYTES && n > 1 && !mcp_progress_quiet();
    if (!b->shown) return;
    const char *slash = strrchr(path, '/'), *base = slash ? slash + 1 : path;
    /* a file written under imageio.c's temporary name "<stem>.tmp-<pid>-<n><ext>" is
       named by its own */
    const char *tag = strstr(base, ".tmp-"), *ext = tag ? strrchr(tag, '.') : NULL;
    char label[96];
    if (tag && ext > tag)
        snprintf(label, sizeof label, "%s %.*s%s", verb, (int)(tag - base), base, ext);
    else
        snprintf(label, sizeof label, "%s %s", verb, base);
    mcp_progress_begin(&b->bar, label, n);
}

/* A chunk is done; called by every thread, the bar drawn by the one that owns it
 * (progress.h: one thread). */
static void
chunk_bar_step(chunk_bar *b)
{
    if (!b->shown) return;
    int n;
#pragma omp atomic capture
    n = ++b->finished;
#ifdef _OPENMP
    if (omp_get_thread_num() != 0) return;
#endif
    mcp_progress_update(&b->bar, n);
}

static void
chunk_bar_end(chunk_bar *b, int failed)
{
    if (!b->shown) return;
    if (failed)
        mcp__progress_stop(&b->bar);
    else
        mcp_progress_end(&b->bar);
}

/* Decodes the chunks in parallel: Core decodes each chunk on its own, reading its
 * bytes through the context is safe from many threads (pread, or read_fn, which must
 * be), and the chunks fill disjoint rectangles. Each thread keeps one
 * pipeline for all its chunks, as Core intends (update instead of initialise). */
static int
read_pixels(exr_context_t f, const chunk_at *chunks, int n, exr_compression_t comp,
            const mcp_image *named, const mcp__exr_route *routes, const char *path,
            int show_bar)
{
    chunk_failure fail = {.idx = -1};
    int zip = comp == EXR_COMPRESSION_ZIP || comp == EXR_COMPRESSION_ZIPS;
    double bytes = 0;
    for (int i = 0; i < n; i++)
        bytes += (double)chunks[i].ci.unpacked_size;
    chunk_bar bar;
    chunk_bar_begin(&bar, "reading", path, show_bar ? bytes : 0, n);
#pragma omp parallel if (n > 1)
    {
        exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
        int initialised = 0;
        mcp__zip_codec *decoder = zip ? mcp__zip_decoder_new() : NULL;
        /* chunks cost about the same; dynamic in ones keeps a slow thread (this
           machine is shared) from holding up the rest */
#pragma omp for schedule(dynamic, 1)
        for (int i = 0; i < n; i++) {
            if (failed(&fail)) continue;
            const char *what = "out of memory";
            exr_last_message[0] = '\0';
            exr_result_t rc = zip && !decoder
                                  ? EXR_ERR_OUT_OF_MEMORY
                                  : decode_chunk(f, &chunks[i], &dec, &initialised,
                                                 decoder, named, routes, &what);
            if (rc != EXR_ERR_SUCCESS) note_failure(&fail, i, rc, what);
            chunk_bar_step(&bar);
        }
        if (initialised) exr_decoding_destroy(f, &dec);
        mcp__zip_codec_free(decoder);
    }
    chunk_bar_end(&bar, fail.idx >= 0);
    return fail.idx >= 0 ? report_failure(&fail, path) : 0;
}

/* The channels' places when a whole image is read: its own pixels. */
static int
route_to_image(mcp_image *img, mcp__exr_route **routes)
{
    if (!(*routes = mcp_calloc((size_t)img->channels, sizeof **routes))) return -1;
    for (int c = 0; c < img->channels; c++)
        (*routes)[c] =
            (mcp__exr_route){img->data + c, img->pixel_stride, img->row_stride};
    return 0;
}

/* Puts the channel names of a new image, whose pixels are not read yet, in
 * mcp_image_colour_order. */
static int
reorder_names(mcp_image *img)
{
    int *order = mcp_calloc((size_t)img->channels, sizeof *order);
    int moved = order ? mcp_image_colour_order(img, order) : -1;
    int rc = moved < 0 ? -1 : moved ? mcp__image_permute_names(img, order) : 0;
    free(order);
    return rc;
}

/* Part 0's header as read_context and the row reader need it: the chunks listed and
 * checked against the file, and an image with the channel names (in the file's order
 * unless whole), the attributes and the source: w x h pixels, not read yet, when
 * whole, else 1 x 1. */
typedef struct exr_part {
    exr_compression_t comp;
    int w, h, n_chunks;
    chunk_at *chunks;
    mcp_image *img;
} exr_part;

static void
part_free(exr_part *p)
{
    free(p->chunks);
    mcp_image_free(p->img);
    memset(p, 0, sizeof *p);
}

static int
read_part_header(exr_context_t f, unsigned long long file_bytes, const char *path,
                 int whole, exr_part *p)
{
    int rc = -1;
    const char **names = NULL;
    exr_storage_t storage;
    exr_attr_box2i_t dw;
    const exr_attr_chlist_t *chans = NULL;
    exr_result_t r;
    memset(p, 0, sizeof *p);
    if ((r = exr_get_storage(f, 0, &storage)) || (r = exr_get_data_window(f, 0, &dw)) ||
        (r = exr_get_compression(f, 0, &p->comp)) ||
        (r = exr_get_channels(f, 0, &chans))) {
        exr_fail(path, "bad header", r);
        goto done;
    }
    if (storage != EXR_STORAGE_SCANLINE && storage != EXR_STORAGE_TILED) {
        mcp_error("%s: deep EXR images are not supported", path);
        goto done;
    }
    if (p->comp == EXR_COMPRESSION_DWAA || p->comp == EXR_COMPRESSION_DWAB) {
        mcp_error("%s: %s compression cannot be read by the OpenEXR Core library; "
                  "re-save it with zip or piz compression",
                  path, compression_name(p->comp));
        goto done;
    }
    long long w = (long long)dw.max.x - dw.min.x + 1,
              h = (long long)dw.max.y - dw.min.y + 1;
    if (w < 1 || h < 1 || w > MCP_MAX_DIM || h > MCP_MAX_DIM || chans->num_channels < 1) {
        mcp_error("%s: bad data window %lldx%lld with %d channels", path, w, h,
                  chans->num_channels);
        goto done;
    }
    p->w = (int)w;
    p->h = (int)h;
    /* the ceiling first (cheap), then what the file can hold, then the allocation */
    if (mcp_image_check_size(p->w, p->h, chans->num_channels)) {
        mcp_error_prefix("%s: ", path);
        goto done;
    }
    if (check_file_holds(f, storage, p->comp, &dw, p->w, p->h, file_bytes, path,
                         &p->chunks, &p->n_chunks))
        goto done;
    names = mcp_calloc((size_t)chans->num_channels, sizeof *names);
    if (!names) goto done;
    for (int c = 0; c < chans->num_channels; c++) {
        const exr_attr_chlist_entry_t *e = &chans->entries[c];
        if (e->x_sampling != 1 || e->y_sampling != 1) {
            mcp_error("%s: channel '%s' is subsampled (%dx%d), which is not supported",
                      path, e->name.str, e->x_sampling, e->y_sampling);
            goto done;
        }
        names[c] = e->name.str;
    }
    /* the header's attributes before the pixels, so that a router sees them */
    if (mcp_image_new(whole ? p->w : 1, whole ? p->h : 1, chans->num_channels, names,
                      &p->img) ||
        mcp_image_set_source(p->img, path) || read_attributes(f, &p->img->attrs))
        goto done;
    /* EXR lists channels alphabetically (B, G, R): a whole image comes back with its
       colour first (docs/conventions.md, "Channel order"). Only the names move: the
       pixels are placed by name below. A router places channels itself, by name. */
    if (whole && reorder_names(p->img)) goto done;
    if ((dw.min.x || dw.min.y) &&
        (mcp_attrs_set_int(&p->img->attrs, "dataWindowX", dw.min.x) ||
         mcp_attrs_set_int(&p->img->attrs, "dataWindowY", dw.min.y)))
        goto done;
    rc = 0;
done:
    free(names);
    if (rc) part_free(p);
    return rc;
}

/* Reads part 0 of an opened context f; file_bytes is the size of what it reads, name
 * names it in messages and becomes the image's source. Closes f. Without a router the
 * whole image goes to *out; with one, the header (channel names, attributes, 1x1
 * unread pixels) goes to the router, which says where each channel's values go. */
static int
read_context(exr_context_t f, unsigned long long file_bytes, const char *name,
             mcp__exr_router router, void *ctx, mcp_image **out)
{
    const char *path = name;
    int rc = -1;
    exr_part p;
    mcp__exr_route *routes = NULL;
    if (read_part_header(f, file_bytes, path, !router, &p)) goto done;
    if (router) {
        if (!(routes = mcp_calloc((size_t)p.img->channels, sizeof *routes)) ||
            router(p.img, p.w, p.h, ctx, routes))
            goto done;
    } else if (route_to_image(p.img, &routes))
        goto done;
    if (read_pixels(f, p.chunks, p.n_chunks, p.comp, p.img, routes, path, 1)) goto done;
    if (!router) {
        *out = p.img;
        p.img = NULL;
    }
    rc = 0;
done:
    free(routes);
    part_free(&p);
    exr_finish(&f);
    return rc;
}

static int
read_file(const char *path, mcp__exr_router router, void *ctx, mcp_image **out)
{
    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    exr_last_message[0] = '\0';
    struct stat st;
    if (stat(path, &st) || st.st_size < 0)
        return mcp_error("%s: cannot stat: %s", path, strerror(errno));
    exr_result_t r = exr_start_read(&f, path, &init);
    if (r != EXR_ERR_SUCCESS) return exr_fail(path, "cannot read as OpenEXR", r);
    return read_context(f, (unsigned long long)st.st_size, path, router, ctx, out);
}

int
mcp__exr_read(const char *path, mcp_image **out)
{
    *out = NULL;
    return read_file(path, NULL, NULL, out);
}

int
mcp__exr_read_routed(const char *path, mcp__exr_router router, void *ctx)
{
    return read_file(path, router, ctx, NULL);
}

/* ---- reading rows [y0, y1) at a time (a streamed denoise: docs/denoisers.md) ---- */

struct mcp__exr_rows {
    exr_context_t f;
    exr_part part; /* the header, 1 x 1, channels in the file's order */
};

int
mcp__exr_rows_open(const char *path, mcp__exr_rows **out)
{
    *out = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    exr_last_message[0] = '\0';
    struct stat st;
    if (mcp__check_readable(path)) return -1;
    if (stat(path, &st) || st.st_size < 0)
        return mcp_error("%s: cannot stat: %s", path, strerror(errno));
    mcp__exr_rows *r = mcp_calloc(1, sizeof *r);
    if (!r) return -1;
    exr_result_t e = exr_start_read(&r->f, path, &init);
    if (e != EXR_ERR_SUCCESS) {
        free(r);
        return exr_fail(path, "cannot read as OpenEXR", e);
    }
    /* the same checks as a whole read: the chunks must lie in the file before any
       row is allocated */
    if (read_part_header(r->f, (unsigned long long)st.st_size, path, 0, &r->part)) {
        mcp__exr_rows_close(r);
        return -1;
    }
    *out = r;
    return 0;
}

const mcp_image *
mcp__exr_rows_header(const mcp__exr_rows *r, int *width, int *height)
{
    *width = r->part.w;
    *height = r->part.h;
    return r->part.img;
}

/* Whether chunk c holds any of rows [y0, y1). */
static int
chunk_meets(const chunk_at *c, int y0, int y1)
{
    return c->y0 < y1 && c->y0 + c->ci.height > y0;
}

void
mcp__exr_rows_span(const mcp__exr_rows *r, int y0, int y1, int *a0, int *a1)
{
    *a0 = y0;
    *a1 = y1;
    for (int i = 0; i < r->part.n_chunks; i++) {
        const chunk_at *c = &r->part.chunks[i];
        if (!chunk_meets(c, y0, y1)) continue;
        if (c->y0 < *a0) *a0 = c->y0;
        if (c->y0 + c->ci.height > *a1) *a1 = c->y0 + c->ci.height;
    }
}

int
mcp__exr_rows_read(mcp__exr_rows *r, int y0, int y1, int a0, const mcp__exr_route *routes)
{
    const exr_part *p = &r->part;
    if (y0 < 0 || y1 > p->h || y0 >= y1)
        return mcp_error("%s: rows %d..%d are not in the image's %d", p->img->source, y0,
                         y1, p->h);
    chunk_at *sub = mcp_calloc((size_t)p->n_chunks, sizeof *sub);
    if (!sub) return -1;
    int n = 0;
    for (int i = 0; i < p->n_chunks; i++)
        if (chunk_meets(&p->chunks[i], y0, y1)) {
            sub[n] = p->chunks[i];
            sub[n++].y0 -= a0; /* the routes' row 0 is row a0 */
        }
    int rc = read_pixels(r->f, sub, n, p->comp, p->img, routes, p->img->source, 0);
    free(sub);
    return rc;
}

void
mcp__exr_rows_trim(mcp_image *img, int a0, int y0, int y1)
{
    /* bands on multiples of 64 need no move with zip's 16 or piz's 32 rows a chunk */
    if (y0 > a0)
        memmove(img->data, img->data + (ptrdiff_t)(y0 - a0) * img->row_stride,
                (size_t)(y1 - y0) * (size_t)img->row_stride * sizeof(float));
    img->height = y1 - y0;
}

int
mcp__exr_rows_read_image(mcp__exr_rows *r, int y0, int y1, mcp_image **out)
{
    *out = NULL;
    const mcp_image *h = r->part.img;
    int a0, a1, rc = -1;
    mcp__exr_rows_span(r, y0, y1, &a0, &a1);
    mcp_image *img = NULL;
    mcp__exr_route *routes = mcp_calloc((size_t)h->channels, sizeof *routes);
    if (!routes ||
        mcp_image_new(r->part.w, a1 - a0, h->channels, (const char *const *)h->names,
                      &img) ||
        mcp_image_set_source(img, h->source) || mcp_attrs_copy(&h->attrs, &img->attrs) ||
        reorder_names(img))
        goto done;
    /* the file's channel c goes where its name went */
    for (int c = 0; c < h->channels; c++) {
        const int at = mcp_image_channel(img, h->names[c]);
        routes[c] = (mcp__exr_route){img->data + at, img->pixel_stride, img->row_stride};
    }
    if (mcp__exr_rows_read(r, y0, y1, a0, routes)) goto done;
    mcp__exr_rows_trim(img, a0, y0, y1);
    *out = img;
    img = NULL;
    rc = 0;
done:
    free(routes);
    mcp_image_free(img);
    return rc;
}

void
mcp__exr_rows_close(mcp__exr_rows *r)
{
    if (!r) return;
    part_free(&r->part);
    if (r->f) exr_finish(&r->f);
    free(r);
}

/* ---- reading from memory ---- */

typedef struct memory_stream {
    const unsigned char *data;
    size_t size;
} memory_stream;

/* pread on a buffer: what lies in [offset, offset + sz) of it; a short count past the
 * end (Core reports that as a short read). Many threads may call it at once. */
static int64_t
memory_read(exr_const_context_t ctxt, void *userdata, void *buffer, uint64_t sz,
            uint64_t offset, exr_stream_error_func_ptr_t error_cb)
{
    (void)ctxt;
    (void)error_cb;
    const memory_stream *m = userdata;
    if (offset >= m->size) return 0;
    uint64_t n = m->size - offset < sz ? m->size - offset : sz;
    memcpy(buffer, m->data + offset, (size_t)n);
    return (int64_t)n;
}

static int64_t
memory_size(exr_const_context_t ctxt, void *userdata)
{
    (void)ctxt;
    return (int64_t)((const memory_stream *)userdata)->size;
}

static int
read_memory(const void *data, size_t size, const char *name, mcp__exr_router router,
            void *ctx, mcp_image **out)
{
    if (!data || size > (size_t)INT64_MAX) return mcp_error("%s: no data to read", name);
    /* Core keeps the pointer to the stream for the context's life: read_context closes
       the context before this frame returns */
    memory_stream m = {data, size};
    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    init.user_data = &m;
    init.read_fn = memory_read;
    init.size_fn = memory_size;
    exr_last_message[0] = '\0';
    exr_result_t r = exr_start_read(&f, name, &init);
    if (r != EXR_ERR_SUCCESS) return exr_fail(name, "cannot read as OpenEXR", r);
    return read_context(f, (unsigned long long)size, name, router, ctx, out);
}

int
mcp__exr_magic(const void *data, size_t size)
{
    static const unsigned char magic[4] = {0x76, 0x2f, 0x31, 0x01};
    return data && size >= 4 && memcmp(data, magic, 4) == 0;
}

int
mcp__exr_read_memory(const void *data, size_t size, const char *name, mcp_image **out)
{
    *out = NULL;
    return read_memory(data, size, name, NULL, NULL, out);
}

int
mcp__exr_read_memory_routed(const void *data, size_t size, const char *name,
                            mcp__exr_router router, void *ctx)
{
    return read_memory(data, size, name, router, ctx, NULL);
}

/* ---- writing ---- */

static const exr_compression_t compression_of[] = {
    [MCP_EXR_NONE] = EXR_COMPRESSION_NONE, [MCP_EXR_RLE] = EXR_COMPRESSION_RLE,
    [MCP_EXR_ZIPS] = EXR_COMPRESSION_ZIPS, [MCP_EXR_ZIP] = EXR_COMPRESSION_ZIP,
    [MCP_EXR_PIZ] = EXR_COMPRESSION_PIZ,   [MCP_EXR_PXR24] = EXR_COMPRESSION_PXR24,
    [MCP_EXR_B44] = EXR_COMPRESSION_B44,   [MCP_EXR_B44A] = EXR_COMPRESSION_B44A,
    [MCP_EXR_DWAA] = EXR_COMPRESSION_DWAA, [MCP_EXR_DWAB] = EXR_COMPRESSION_DWAB,
};

static int
write_attributes(exr_context_t f, const mcp_attrs *attrs)
{
    for (int i = 0; i < attrs->count; i++) {
        const mcp_attr *a = &attrs->items[i];
        /* structural attributes are written by Core itself */
        static const char *reserved[] = {"channels",
                                         "compression",
                                         "dataWindow",
                                         "displayWindow",
                                         "lineOrder",
                                         "pixelAspectRatio",
                                         "screenWindowCenter",
                                         "screenWindowWidth",
                                         "tiles",
                                         "type",
                                         "name",
                                         "chunkCount",
                                         "dataWindowX",
                                         "dataWindowY",
                                         NULL};
        int skip = 0;
        for (const char **r = reserved; *r; r++)
            skip |= strcmp(*r, a->name) == 0;
        if (skip) continue;
        exr_result_t r = EXR_ERR_SUCCESS;
        switch (a->type) {
        case MCP_ATTR_INT:
            if (a->i >= INT32_MIN && a->i <= INT32_MAX)
                r = exr_attr_set_int(f, 0, a->name, (int32_t)a->i);
            else
                r = exr_attr_set_double(f, 0, a->name, (double)a->i);
            break;
        case MCP_ATTR_FLOAT:
            r = exr_attr_set_float(f, 0, a->name, (float)a->f);
            break;
        case MCP_ATTR_DOUBLE:
            r = exr_attr_set_double(f, 0, a->name, a->f);
            break;
        case MCP_ATTR_STRING:
            r = exr_attr_set_string(f, 0, a->name, a->s);
            break;
        }
        if (r != EXR_ERR_SUCCESS)
            return mcp_error("cannot write attribute '%s': %s", a->name,
                             exr_get_default_error_message(r));
    }
    return 0;
}

/* Compresses one chunk: the bytes to write are then out[0 .. out_bytes). Zip chunks go
 * to exr_zip.c (libdeflate); other compressions to Core's compress_fn, wrapped: Core
 * 3.1.5 writes a corrupt chunk when its output is not smaller than the raw data (the
 * file must then hold the raw bytes; Core stores something else, and both Core and
 * the C++ library read garbage back), so keep the raw packed bytes, and where
 * compression did not pay, put exactly those out. A chunk is stored raw for every
 * compression when its compressed form is not smaller: readers (ours, Core, the C++
 * library) take a chunk whose size equals its raw size as raw. */
typedef struct chunk_coder {
    exr_result_t (*core_compress)(exr_encode_pipeline_t *); /* NULL for zip */
    mcp__zip_codec *zip;                                    /* zip's encoder */
    void *raw;                                              /* core_compress's copy */
    size_t raw_cap;
    int store_raw; /* store without trying (see store_raw_after_probe) */
    const void *out;
    uint64_t out_bytes;
    /* zip: this thread's last chunk, packed, and its stream (see repeat_of_last) */
    unsigned char *last, *last_stream;
    size_t last_bytes, last_stream_bytes, last_cap, last_stream_cap;
} chunk_coder;

static void
chunk_coder_free(chunk_coder *coder)
{
    mcp__zip_codec_free(coder->zip);
    free(coder->raw);
    free(coder->last);
    free(coder->last_stream);
}

/* Maps that are constant per block or region (an estimate's distribution.exr and block
 * means, a render's black border) repeat whole chunks, and libdeflate takes 0.5 ms to
 * compress 360 kB of one repeated value (its matches stop at 258 bytes): a chunk whose
 * packed bytes are this thread's last chunk's takes that chunk's stream, the same bytes
 * a compression would give. 1 when it did. */
static int
repeat_of_last(chunk_coder *coder, const exr_encode_pipeline_t *enc)
{
    if (!coder->last || coder->last_bytes != enc->packed_bytes ||
        memcmp(coder->last, enc->packed_buffer, enc->packed_bytes))
        return 0;
    coder->out = coder->last_stream;
    coder->out_bytes = coder->last_stream_bytes;
    return 1;
}

/* Keeps a chunk and its stream for repeat_of_last; without memory it keeps none. */
static void
keep_last(chunk_coder *coder, const exr_encode_pipeline_t *enc, const void *stream,
          size_t stream_bytes)
{
    if (coder->last_cap < enc->packed_bytes) {
        free(coder->last);
        coder->last_cap = enc->packed_bytes;
        coder->last = malloc(coder->last_cap);
    }
    if (coder->last_stream_cap < stream_bytes) {
        free(coder->last_stream);
        coder->last_stream_cap = stream_bytes;
        coder->last_stream = malloc(coder->last_stream_cap);
    }
    if (!coder->last || !coder->last_stream) {
        free(coder->last), free(coder->last_stream);
        coder->last = coder->last_stream = NULL;
        coder->last_cap = coder->last_stream_cap = 0;
        return;
    }
    memcpy(coder->last, enc->packed_buffer, enc->packed_bytes);
    memcpy(coder->last_stream, stream, stream_bytes);
    coder->last_bytes = enc->packed_bytes;
    coder->last_stream_bytes = stream_bytes;
}

static exr_result_t
compress_chunk(exr_encode_pipeline_t *enc)
{
    chunk_coder *coder = enc->encoding_user_data;
    coder->out = enc->packed_buffer;
    coder->out_bytes = enc->packed_bytes;
    if (coder->store_raw) return EXR_ERR_SUCCESS;
    if (coder->zip) {
        if (repeat_of_last(coder, enc)) return EXR_ERR_SUCCESS;
        const void *stream;
        long long size =
            mcp__zip_encode(coder->zip, enc->packed_buffer, enc->packed_bytes, &stream);
        if (size < 0) return EXR_ERR_OUT_OF_MEMORY;
        if ((uint64_t)size < enc->packed_bytes) {
            coder->out = stream;
            coder->out_bytes = (uint64_t)size;
            keep_last(coder, enc, stream, (size_t)size);
        }
        return EXR_ERR_SUCCESS;
    }
    if (coder->raw_cap < enc->packed_bytes) {
        void *grown = mcp_realloc(coder->raw, enc->packed_bytes);
        if (!grown) return EXR_ERR_OUT_OF_MEMORY;
        coder->raw = grown;
        coder->raw_cap = enc->packed_bytes;
    }
    memcpy(coder->raw, enc->packed_buffer, enc->packed_bytes);
    coder->out = coder->raw;
    exr_result_t rc = coder->core_compress(enc);
    if (rc == EXR_ERR_SUCCESS && enc->compressed_bytes < enc->packed_bytes) {
        coder->out = enc->compressed_buffer;
        coder->out_bytes = enc->compressed_bytes;
    }
    return rc;
}

/* exr_encoding_run's last steps wait for this chunk's turn and write it; here the
 * chunks are packed and compressed in parallel and written afterwards, in file order,
 * by write_pixels: these stand in for both steps and leave the bytes in the pipeline. */
static exr_result_t
keep_in_pipeline(exr_encode_pipeline_t *enc)
{
    (void)enc;
    return EXR_ERR_SUCCESS;
}

/* Packs and compresses one chunk of img with this thread's pipeline and coder; the
 * bytes to write are then coder->out[0 .. out_bytes). zip_level > 0 for zip files. */
static exr_result_t
encode_chunk(exr_context_t f, const chunk_at *c, exr_encode_pipeline_t *enc,
             int *initialised, chunk_coder *coder, int zip_level, const mcp_image *img)
{
    exr_result_t rc = *initialised ? exr_encoding_update(f, 0, &c->ci, enc)
                                   : exr_encoding_initialize(f, 0, &c->ci, enc);
    if (rc != EXR_ERR_SUCCESS) return rc;
    for (int k = 0; k < enc->channel_count; k++) {
        exr_coding_channel_info_t *ch = &enc->channels[k];
        /* Core sorts channels by name: map them back by name, not position */
        int ic = mcp_image_channel(img, ch->channel_name);
        ch->encode_from_ptr = (const uint8_t *)(mcp_image_px(img, c->x0, c->y0) + ic);
        ch->user_pixel_stride = (int32_t)(img->pixel_stride * (ptrdiff_t)sizeof(float));
        ch->user_line_stride = (int32_t)(img->row_stride * (ptrdiff_t)sizeof(float));
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = 4;
    }
    if (!*initialised) {
        rc = exr_encoding_choose_default_routines(f, 0, enc);
        if (rc == EXR_ERR_SUCCESS && zip_level > 0 && !coder->zip &&
            !(coder->zip = mcp__zip_encoder_new(zip_level)))
            rc = EXR_ERR_OUT_OF_MEMORY;
        if (rc != EXR_ERR_SUCCESS) {
            /* not initialised for the caller, who would not destroy it: undone here */
            exr_encoding_destroy(f, enc);
            *enc = (exr_encode_pipeline_t)EXR_ENCODE_PIPELINE_INITIALIZER;
            return rc;
        }
        if (zip_level > 0) {
            enc->compress_fn = compress_chunk;
        } else if (enc->compress_fn) {
            coder->core_compress = enc->compress_fn;
            enc->compress_fn = compress_chunk;
        }
        enc->yield_until_ready_fn = keep_in_pipeline;
        enc->write_fn = keep_in_pipeline;
        *initialised = 1;
    }
    enc->encoding_user_data = coder;
    coder->out = NULL;
    rc = exr_encoding_run(f, 0, enc);
    if (rc == EXR_ERR_SUCCESS && !coder->out) { /* no compression: Core's bytes */
        coder->out = enc->compressed_buffer ? enc->compressed_buffer : enc->packed_buffer;
        coder->out_bytes =
            enc->compressed_buffer ? enc->compressed_bytes : enc->packed_bytes;
    }
    return rc;
}

/* Zip costs about as much per byte as the rest of writing put together, and a
 * renderer's float noise barely compresses (an estimate's maps: 24.8 of 24.9 MB). A
 * chunk whose compressed form is not smaller is stored raw, which every EXR reader
 * takes for any compression, so pixels never change; this decides that for a whole
 * image from a sample of its chunks instead of compressing every one to find out.
 * It compresses every 16th chunk (at least one), spread over the image, and says raw
 * when they shrink by less than min_saving of their bytes (1/8 by default). The sample is
 * fixed, so the file does not depend on the thread count; when the data does compress,
 * the cost is those chunks compressed twice (about 6%). The probe compresses at
 * libdeflate's level 1 whatever the file's level: its sizes are within 0.1% of level 4's
 * on renders and maps, and on float noise it runs about three times as fast, which took
 * the probe from a third of writing an incompressible 1080p map to a tenth
 * (docs/benchmarks.md, "EXR speed"). */
#define PROBE_EVERY 16
#define PROBE_ZIP_LEVEL 1

static int
store_raw_after_probe(exr_context_t f, const mcp_image *img, const chunk_at *chunks,
                      int n, double min_saving)
{
    int probes = n / PROBE_EVERY > 0 ? n / PROBE_EVERY : 1;
    unsigned long long raw_bytes = 0, zip_bytes = 0;
    int errors = 0;
#pragma omp parallel if (probes > 1) reduction(+ : raw_bytes, zip_bytes, errors)
    {
        exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
        chunk_coder coder = {0};
        int initialised = 0;
#pragma omp for schedule(dynamic, 1)
        for (int j = 0; j < probes; j++) {
            /* the middle chunk of each of `probes` equal runs */
            int i = (int)(((2LL * j + 1) * n) / (2LL * probes));
            if (encode_chunk(f, &chunks[i], &enc, &initialised, &coder, PROBE_ZIP_LEVEL,
                             img) != EXR_ERR_SUCCESS) {
                errors++;
                continue;
            }
            raw_bytes += enc.packed_bytes;
            zip_bytes += coder.out_bytes;
        }
        if (initialised) exr_encoding_destroy(f, &enc);
        chunk_coder_free(&coder);
    }
    /* on an error, compress as asked: the real pass reports it */
    return !errors && (double)zip_bytes > (1.0 - min_saving) * (double)raw_bytes;
}

/* Compresses the chunks in parallel, each thread with its own pipeline, and writes
 * them in file order (a scanline file in INCREASING_Y order must hold its chunks in
 * that order, and Core checks it): the ordered region hands the chunks to Core one
 * after the other while the other threads compress the next ones, so at most one
 * chunk per thread is held in memory. */
static int
write_chunks(exr_context_t f, const mcp_image *img, const chunk_at *chunks, int n,
             exr_storage_t storage, exr_compression_t comp, int zip_level,
             double min_saving, int show_bar, const char *path)
{
    /* below PROBE_EVERY chunks the probe would cost more than it could save */
    int zip = comp == EXR_COMPRESSION_ZIP || comp == EXR_COMPRESSION_ZIPS;
    if (!zip) zip_level = 0;
    int store_raw = zip && min_saving > 0 && n >= PROBE_EVERY &&
                    store_raw_after_probe(f, img, chunks, n, min_saving);
    chunk_failure fail = {.idx = -1};
    chunk_bar bar;
    chunk_bar_begin(
        &bar, "writing", path,
        show_bar ? (double)img->width * img->height * img->channels * sizeof(float) : 0,
        n);
#pragma omp parallel if (n > 1)
    {
        exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
        chunk_coder coder = {.store_raw = store_raw};
        int initialised = 0;
#pragma omp for ordered schedule(dynamic, 1)
        for (int i = 0; i < n; i++) {
            exr_result_t rc = EXR_ERR_SUCCESS;
            const char *what = "cannot encode";
            exr_last_message[0] = '\0';
            if (!failed(&fail))
                rc = encode_chunk(f, &chunks[i], &enc, &initialised, &coder, zip_level,
                                  img);
#pragma omp ordered
            {
                /* a chunk after a failed one is not written: Core would refuse it */
                if (rc == EXR_ERR_SUCCESS && !failed(&fail)) {
                    const exr_chunk_info_t *ci = &chunks[i].ci;
                    const void *bytes = coder.out;
                    uint64_t size = coder.out_bytes;
                    what = "cannot write pixel data";
                    rc = storage == EXR_STORAGE_SCANLINE
                             ? exr_write_scanline_chunk(f, 0, ci->start_y, bytes, size)
                             : exr_write_tile_chunk(f, 0, ci->start_x, ci->start_y, 0, 0,
                                                    bytes, size);
                }
                if (rc != EXR_ERR_SUCCESS) note_failure(&fail, i, rc, what);
            }
            chunk_bar_step(&bar);
        }
        if (initialised) exr_encoding_destroy(f, &enc);
        chunk_coder_free(&coder);
    }
    chunk_bar_end(&bar, fail.idx >= 0);
    return fail.idx >= 0 ? report_failure(&fail, path) : 0;
}

/* Creates path (exactly: the callers write a temporary name and rename it) and writes
 * the header of a w x h image with the channels names[0 .. nc) and the attributes
 * attrs, as opt says. The chunks, listed in file order, follow in *chunks. */
static int
start_write(const char *path, int w, int h, int nc, char *const *names,
            const mcp_attrs *attrs, const mcp_write_options *opt, exr_context_t *out,
            chunk_at **chunks, int *n_chunks, int *zip_level_out)
{
    *out = NULL;
    *chunks = NULL;
    *n_chunks = 0;
    if (opt->compression == MCP_EXR_DWAA || opt->compression == MCP_EXR_DWAB ||
        opt->compression == MCP_EXR_B44 || opt->compression == MCP_EXR_B44A)
        /* Core 3.1.5 cannot encode DWA and writes corrupt B44 (docs/libraries.md §2) */
        return mcp_error("%s: cannot write %s compression with the OpenEXR Core library; "
                         "use zip, piz, rle, zips, pxr24 or none",
                         path, compression_name(compression_of[opt->compression]));
    if (opt->exr_tiled && (opt->exr_tile_size < 1 || opt->exr_tile_size > 4096))
        return mcp_error("%s: bad tile size %d", path, opt->exr_tile_size);
    if (opt->exr_zip_level < 0 || opt->exr_zip_level > 9)
        return mcp_error("%s: bad zip level %d (1..9, or 0 for the default)", path,
                         opt->exr_zip_level);
    int zip_level = opt->exr_zip_level ? opt->exr_zip_level : MCP_EXR_ZIP_LEVEL_DEFAULT;
    *zip_level_out = zip_level;
    if (!(opt->exr_min_saving < 1)) /* NaN too */
        return mcp_error("%s: bad exr_min_saving %g (below 1; 0 for the default, "
                         "negative to compress every chunk)",
                         path, opt->exr_min_saving);

    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_capture_error;
    exr_last_message[0] = '\0';
    /* imageio.c already writes to a temporary name and renames */
    exr_result_t r = exr_start_write(&f, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (r != EXR_ERR_SUCCESS) return exr_fail(path, "cannot create", r);
    int part, rc = -1;
    exr_attr_box2i_t dw;
    dw.min.x = opt->exr_data_x;
    dw.min.y = opt->exr_data_y;
    dw.max.x = opt->exr_data_x + w - 1;
    dw.max.y = opt->exr_data_y + h - 1;
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
                                      EXR_TILE_ROUND_DOWN))) ||
        (r = exr_set_zip_compression_level(f, part, zip_level))) {
        exr_fail(path, "cannot write header", r);
        goto done;
    }
    for (int c = 0; c < nc; c++) {
        for (int d = 0; d < c; d++)
            if (strcmp(names[c], names[d]) == 0) {
                mcp_error("%s: channel name '%s' appears twice", path, names[c]);
                goto done;
            }
        r = exr_add_channel(f, part, names[c],
                            opt->exr_pixel == MCP_EXR_HALF ? EXR_PIXEL_HALF
                                                           : EXR_PIXEL_FLOAT,
                            EXR_PERCEPTUALLY_LINEAR, 1, 1);
        if (r != EXR_ERR_SUCCESS) {
            exr_fail(path, "bad channel name", r);
            goto done;
        }
    }
    if (write_attributes(f, attrs)) {
        mcp_error_prefix("%s: ", path);
        goto done;
    }
    if ((r = exr_write_header(f)) != EXR_ERR_SUCCESS) {
        exr_fail(path, "cannot write header", r);
        goto done;
    }
    rc = list_chunks(f, opt->exr_tiled ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE, &dw, w,
                     h, 1, (long long)INT32_MAX, path, chunks, n_chunks);
done:
    if (rc)
        exr_finish(&f);
    else
        *out = f;
    return rc;
}

static double
min_saving_of(const mcp_write_options *opt)
{
    return opt->exr_min_saving ? opt->exr_min_saving : MCP_EXR_MIN_SAVING_DEFAULT;
}

int
mcp__exr_write(const mcp_image *img, const char *path, const mcp_write_options *opt)
{
    exr_context_t f;
    chunk_at *chunks;
    int n, zip_level;
    if (start_write(path, img->width, img->height, img->channels, img->names, &img->attrs,
                    opt, &f, &chunks, &n, &zip_level))
        return -1;
    int rc = write_chunks(
        f, img, chunks, n, opt->exr_tiled ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE,
        compression_of[opt->compression], zip_level, min_saving_of(opt), 1, path);
    free(chunks);
    exr_result_t r = exr_finish(&f);
    if (!rc && r != EXR_ERR_SUCCESS) rc = exr_fail(path, "cannot finish writing", r);
    return rc;
}

/* ---- writing rows [y0, y1) at a time, top to bottom (a streamed denoise) ---- */

struct mcp__exr_writer {
    exr_context_t f;
    char *path;
    mcp_write_options opt;
    chunk_at *chunks;
    int n_chunks, next_chunk, next_row, width, height, zip_level;
};

int
mcp__exr_writer_open(const char *path, int width, int height, int nc, char *const *names,
                     const mcp_attrs *attrs, const mcp_write_options *opt,
                     mcp__exr_writer **out)
{
    *out = NULL;
    mcp__exr_writer *wr = mcp_calloc(1, sizeof *wr);
    if (!wr || !(wr->path = mcp_strdup(path))) {
        free(wr);
        return -1;
    }
    wr->opt = *opt;
    wr->width = width;
    wr->height = height;
    if (start_write(path, width, height, nc, names, attrs, opt, &wr->f, &wr->chunks,
                    &wr->n_chunks, &wr->zip_level)) {
        free(wr->path);
        free(wr);
        return -1;
    }
    *out = wr;
    return 0;
}

int
mcp__exr_writer_rows(mcp__exr_writer *wr, const mcp_image *rows, int y0)
{
    const int y1 = y0 + rows->height;
    if (y0 != wr->next_row || y1 > wr->height || rows->width != wr->width)
        return mcp_error("%s: rows %d..%d (%d wide) do not follow row %d of %dx%d",
                         wr->path, y0, y1, rows->width, wr->next_row, wr->width,
                         wr->height);
    /* the chunks that start before y1, which must end by then */
    int i1 = wr->next_chunk;
    while (i1 < wr->n_chunks && wr->chunks[i1].y0 < y1)
        i1++;
    const int n = i1 - wr->next_chunk;
    chunk_at *sub = mcp_calloc((size_t)(n > 0 ? n : 1), sizeof *sub);
    if (!sub) return -1;
    for (int i = 0; i < n; i++) {
        sub[i] = wr->chunks[wr->next_chunk + i];
        if (sub[i].y0 + sub[i].ci.height > y1) {
            const int rows_in_chunk = sub[i].ci.height;
            free(sub);
            return mcp_error("%s: rows %d..%d end inside a chunk of %d rows", wr->path,
                             y0, y1, rows_in_chunk);
        }
        sub[i].y0 -= y0; /* rows' row 0 is row y0 */
    }
    const mcp_write_options *opt = &wr->opt;
    int rc = write_chunks(
        wr->f, rows, sub, n, opt->exr_tiled ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE,
        compression_of[opt->compression], wr->zip_level, min_saving_of(opt), 0, wr->path);
    free(sub);
    if (!rc) {
        wr->next_chunk = i1;
        wr->next_row = y1;
    }
    return rc;
}

int
mcp__exr_writer_close(mcp__exr_writer *wr)
{
    if (!wr) return 0;
    int rc = 0;
    if (wr->next_row < wr->height)
        rc = mcp_error("%s: %d of %d rows written", wr->path, wr->next_row, wr->height);
    exr_result_t r = exr_finish(&wr->f);
    if (!rc && r != EXR_ERR_SUCCESS) rc = exr_fail(wr->path, "cannot finish writing", r);
    free(wr->chunks);
    free(wr->path);
    free(wr);
    return rc;
}
