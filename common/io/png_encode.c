/* png_encode.c: the PNG writer: rows filtered in parallel, one deflate stream by
 * libdeflate, chunks written by hand.
 *
 * Reports write their previews, colour maps and spectra while the user waits. Through
 * libpng a 1080p colour map of a noisy error took 140 ms on one thread, nearly all of
 * it zlib's deflate and libpng's filter search; here the filter search runs over rows
 * in parallel and libdeflate's level 1 compresses the rows in a third of zlib's time,
 * into a smaller file (docs/benchmarks.md, "PNG"). The format is simple enough to
 * write directly (PNG specification, 2nd edition, sections 5, 9 and 11): the signature,
 * IHDR, sRGB (the pixels are sRGB-encoded, as libpng's writer said too), the zlib stream
 * in IDAT chunks, IEND. Reading stays with libpng (png.c). */
#include "internal.h"

#include <libdeflate.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* libdeflate's level 1 (its own fast matcher) is the fastest of its levels on noisy
 * colour maps and makes them smaller than zlib's level 3 did; on flat pictures
 * (blocks.png) levels 2-4 are a little faster, but such files take milliseconds. */
#define PNG_DEFLATE_LEVEL 1
/* IDAT chunks of at most this many bytes: any size up to 2^31 - 1 is valid, but
 * decoders that stream a file read a chunk at a time */
#define IDAT_BYTES (1 << 20)

enum { FILTER_NONE, FILTER_SUB, FILTER_UP, FILTER_AVERAGE, FILTER_PAETH, N_FILTERS };

static inline int
paeth_predictor(int a, int b, int c)
{
    /* p = a + b - c; the predictor is whichever of a, b, c is closest to p */
    int pa = abs(b - c), pb = abs(a - c), pc = abs(a + b - 2 * c);
    return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

/* The five filters' sums of the filtered bytes' magnitudes, read as signed, over one
 * row: libpng's measure for choosing a filter for 8-bit images (the specification's
 * section 12.8 recommends it). One pass computes all five; up is the row above (zeros
 * above the first row), bpp bytes per pixel, and the bytes left of the row count as 0
 * (PNG 2nd ed., section 9.2). n <= 2^24, so that each sum fits an int. */
static void
filter_sums(const unsigned char *row, const unsigned char *up, int n, int bpp,
            int sum[N_FILTERS])
{
    int s0 = 0, s1 = 0, s2 = 0, s3 = 0, s4 = 0;
    for (int i = 0; i < bpp && i < n; i++) {
        int x = row[i], b = up[i];
        s0 += abs((signed char)x);
        s1 += abs((signed char)x);
        s2 += abs((signed char)(x - b));
        s3 += abs((signed char)(x - (b >> 1)));
        s4 += abs((signed char)(x - b));
    }
#pragma omp simd reduction(+ : s0, s1, s2, s3, s4)
    for (int i = bpp; i < n; i++) {
        int x = row[i], a = row[i - bpp], b = up[i], c = up[i - bpp];
        s0 += abs((signed char)x);
        s1 += abs((signed char)(x - a));
        s2 += abs((signed char)(x - b));
        s3 += abs((signed char)(x - ((a + b) >> 1)));
        s4 += abs((signed char)(x - paeth_predictor(a, b, c)));
    }
    sum[FILTER_NONE] = s0;
    sum[FILTER_SUB] = s1;
    sum[FILTER_UP] = s2;
    sum[FILTER_AVERAGE] = s3;
    sum[FILTER_PAETH] = s4;
}

/* Filters one row into out (its filter-type byte, then n bytes) with the filter of the
 * smallest sum, as libpng's writer chose, so that files keep their sizes. */
static void
filter_row(const unsigned char *row, const unsigned char *up, int n, int bpp,
           unsigned char *out)
{
    int sum[N_FILTERS], f = FILTER_NONE;
    filter_sums(row, up, n, bpp, sum);
    for (int k = 1; k < N_FILTERS; k++)
        if (sum[k] < sum[f]) f = k;
    out[0] = (unsigned char)f;
    unsigned char *o = out + 1;
    int first = bpp < n ? bpp : n;
    for (int i = 0; i < first; i++) { /* a = c = 0 */
        int x = row[i], b = up[i];
        o[i] = (unsigned char)(f == FILTER_NONE || f == FILTER_SUB ? x
                               : f == FILTER_AVERAGE               ? x - (b >> 1)
                                                                   : x - b);
    }
    switch (f) {
    case FILTER_NONE:
        memcpy(o + first, row + first, (size_t)(n - first));
        break;
    case FILTER_SUB:
        for (int i = first; i < n; i++)
            o[i] = (unsigned char)(row[i] - row[i - bpp]);
        break;
    case FILTER_UP:
        for (int i = first; i < n; i++)
            o[i] = (unsigned char)(row[i] - up[i]);
        break;
    case FILTER_AVERAGE:
        for (int i = first; i < n; i++)
            o[i] = (unsigned char)(row[i] - ((row[i - bpp] + up[i]) >> 1));
        break;
    default:
#pragma omp simd
        for (int i = first; i < n; i++)
            o[i] = (unsigned char)(row[i] -
                                   paeth_predictor(row[i - bpp], up[i], up[i - bpp]));
    }
}

static void
put_u32(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)(v >> 24);
    p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);
    p[3] = (unsigned char)v;
}

/* One chunk: length, type, data, CRC-32 of type and data. */
static int
put_chunk(FILE *f, const char type[4], const unsigned char *data, size_t n)
{
    unsigned char head[8], tail[4];
    put_u32(head, (uint32_t)n);
    memcpy(head + 4, type, 4);
    uint32_t crc = (uint32_t)libdeflate_crc32(0, type, 4);
    if (n) crc = (uint32_t)libdeflate_crc32(crc, data, n);
    put_u32(tail, crc);
    return fwrite(head, 1, 8, f) == 8 && (n == 0 || fwrite(data, 1, n, f) == n) &&
                   fwrite(tail, 1, 4, f) == 4
               ? 0
               : -1;
}

/* An RGB picture of at most 256 colours (a colour map's, a false-colour one) as a
 * palette and an index a pixel, PNG's colour type 3: a third of the bytes to filter
 * and compress, and the same pixels once decoded. The palette is in the order the
 * colours first appear; 0 when the picture has more colours, which a photograph shows
 * within its first pixels. */
#define PALETTE_SLOTS 1024 /* a hash of up to 256 colours, a quarter full */

static int
palette_of(const unsigned char *rgb, size_t n, unsigned char plte[3 * 256], int *colours,
           unsigned char *index)
{
    uint32_t key[PALETTE_SLOTS]; /* colour + 1; 0: empty */
    unsigned char slot_index[PALETTE_SLOTS];
    memset(key, 0, sizeof key);
    int count = 0;
    uint32_t last = 0;
    unsigned char last_index = 0;
    for (size_t i = 0; i < n; i++) {
        const unsigned char *p = rgb + 3 * i;
        const uint32_t k = ((uint32_t)p[0] << 16 | (uint32_t)p[1] << 8 | p[2]) + 1;
        if (k != last) { /* runs of one colour skip the hash */
            uint32_t s = (k * 2654435761u) >> 22;
            while (key[s] && key[s] != k)
                s = (s + 1) & (PALETTE_SLOTS - 1);
            if (!key[s]) {
                if (count == 256) return 0;
                key[s] = k;
                slot_index[s] = (unsigned char)count;
                memcpy(plte + 3 * count, p, 3);
                count++;
            }
            last = k;
            last_index = slot_index[s];
        }
        index[i] = last_index;
    }
    *colours = count;
    return 1;
}

int
mcp__png_write_bytes(const unsigned char *bytes, int w, int h, int c, const char *path)
{
    /* colour types by channel count: grey, grey + alpha, RGB, RGBA */
    static const unsigned char colour_type[] = {0, 0, 4, 2, 6};
    if (w <= 0 || h <= 0 || c < 1 || c > 4 || (long long)w * c > (1 << 24))
        return mcp_error("%s: cannot write a %dx%d PNG of %d channels", path, w, h, c);
    size_t row_bytes = (size_t)w * (size_t)c, n = (row_bytes + 1) * (size_t)h;
    const size_t pixels = (size_t)w * (size_t)h;
    unsigned char *filtered = mcp_malloc(n), *zeros = mcp_calloc(row_bytes, 1),
                  *stream = NULL, *index = NULL, plte[3 * 256];
    struct libdeflate_compressor *z = NULL;
    FILE *f = NULL;
    int rc = -1, colours = 0;
    if (!filtered || !zeros) goto done;
    /* few colours: one index a pixel, unfiltered (the filters predict values, and
       indices in order of appearance are not values: on a colour map's indices the
       filter search made the file a quarter larger), but for a row that repeats the
       one above, which "up" turns into zeros (a false-colour picture's blocks) */
    if (c == 3 && (index = mcp_malloc(pixels)) &&
        palette_of(bytes, pixels, plte, &colours, index)) {
        n = (size_t)(w + 1) * (size_t)h;
#pragma omp parallel for schedule(static) if (n >= 65536)
        for (int y = 0; y < h; y++) {
            const unsigned char *row = index + (size_t)y * w;
            unsigned char *o = filtered + (size_t)y * (w + 1);
            const int repeats = y && !memcmp(row, row - w, (size_t)w);
            o[0] = repeats ? FILTER_UP : FILTER_NONE;
            if (repeats)
                memset(o + 1, 0, (size_t)w);
            else
                memcpy(o + 1, row, (size_t)w);
        }
    } else {
        if (c == 3 && !index) goto done; /* out of memory */
#pragma omp parallel for schedule(static) if (n >= 65536)
        for (int y = 0; y < h; y++) {
            const unsigned char *row = bytes + (size_t)y * row_bytes;
            filter_row(row, y ? row - row_bytes : zeros, (int)row_bytes, c,
                       filtered + (size_t)y * (row_bytes + 1));
        }
    }
    if (!(z = libdeflate_alloc_compressor(PNG_DEFLATE_LEVEL))) {
        mcp_error("%s: out of memory (PNG writer)", path);
        goto done;
    }
    size_t cap = libdeflate_zlib_compress_bound(z, n);
    if (!(stream = mcp_malloc(cap))) goto done;
    size_t stream_bytes = libdeflate_zlib_compress(z, filtered, n, stream, cap);
    if (stream_bytes == 0) { /* cannot happen with the bound's room */
        mcp_error("%s: cannot compress the pixels", path);
        goto done;
    }
    if (!(f = fopen(path, "wb"))) {
        mcp_error("%s: cannot create", path);
        goto done;
    }
    static const unsigned char signature[8] = {0x89, 'P',  'N',  'G',
                                               '\r', '\n', 0x1a, '\n'};
    unsigned char ihdr[13] = {0};
    put_u32(ihdr, (uint32_t)w);
    put_u32(ihdr + 4, (uint32_t)h);
    ihdr[8] = 8; /* bits per sample; compression, filter method and interlace are 0 */
    ihdr[9] = colours ? 3 : colour_type[c];
    const unsigned char perceptual_intent = 0;
    int ok = fwrite(signature, 1, 8, f) == 8 && !put_chunk(f, "IHDR", ihdr, 13) &&
             !put_chunk(f, "sRGB", &perceptual_intent, 1) &&
             (!colours || !put_chunk(f, "PLTE", plte, 3 * (size_t)colours));
    for (size_t at = 0; ok && at < stream_bytes; at += IDAT_BYTES) {
        size_t len = stream_bytes - at < IDAT_BYTES ? stream_bytes - at : IDAT_BYTES;
        ok = !put_chunk(f, "IDAT", stream + at, len);
    }
    ok = ok && !put_chunk(f, "IEND", NULL, 0);
    int closed = fclose(f) == 0;
    f = NULL;
    if (!ok || !closed) {
        mcp_error("%s: write failed (disk full?)", path);
        goto done;
    }
    rc = 0;
done:
    if (f) fclose(f);
    libdeflate_free_compressor(z);
    free(stream);
    free(index);
    free(zeros);
    free(filtered);
    return rc;
}
