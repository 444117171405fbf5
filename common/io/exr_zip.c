/* exr_zip.c: the ZIP and ZIPS chunk codec of OpenEXR, on libdeflate.
 *
 * OpenEXR Core compresses and decompresses zip chunks with zlib. Reading a renderer's
 * dump and writing an estimate's maps spent about half their CPU time in zlib
 * (README.md, "EXR speed"); libdeflate produces and accepts the same zlib streams
 * (RFC 1950, with its Adler-32 check) two to three times faster. exr.c hands the zip
 * chunks to this file instead of Core's compress_fn/decompress_fn; every other
 * compression stays with Core.
 *
 * A zip chunk, as the OpenEXR file layout describes it, is the zlib stream of the
 * chunk's packed bytes after two reversible steps that make float data compress:
 *   1. split: the bytes at even offsets, then the bytes at odd offsets (the first
 *      half has ceil(n/2) bytes);
 *   2. delta: t[0] is kept, t[i] becomes t[i] - t[i-1] + 128 (mod 256).
 * Decoding undoes them in the reverse order. A chunk stored raw (its compressed size
 * equals its packed size) is not a zlib stream; exr.c deals with that case. */
#include "exr_zip.h"

#include <mcpost/error.h>

#include <libdeflate.h>

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
#include <emmintrin.h>
#endif

struct mcp__zip_codec {
    struct libdeflate_compressor *compressor;     /* NULL for a decoder */
    struct libdeflate_decompressor *decompressor; /* NULL for an encoder */
    uint8_t *scratch;                             /* the split and delta-coded bytes */
    size_t scratch_cap;
    uint8_t *out; /* an encoder's zlib stream */
    size_t out_cap;
};

mcp__zip_codec *
mcp__zip_encoder_new(int level)
{
    mcp__zip_codec *c = mcp_calloc(1, sizeof *c);
    if (!c) return NULL;
    if (!(c->compressor = libdeflate_alloc_compressor(level))) {
        free(c);
        return NULL;
    }
    return c;
}

mcp__zip_codec *
mcp__zip_decoder_new(void)
{
    mcp__zip_codec *c = mcp_calloc(1, sizeof *c);
    if (!c) return NULL;
    if (!(c->decompressor = libdeflate_alloc_decompressor())) {
        free(c);
        return NULL;
    }
    return c;
}

void
mcp__zip_codec_free(mcp__zip_codec *c)
{
    if (!c) return;
    libdeflate_free_compressor(c->compressor);
    libdeflate_free_decompressor(c->decompressor);
    free(c->scratch);
    free(c->out);
    free(c);
}

/* Grows *buf to hold n bytes; 0 or -1 when out of memory. */
static int
reserve(uint8_t **buf, size_t *cap, size_t n)
{
    if (*cap >= n) return 0;
    uint8_t *grown = mcp_realloc(*buf, n);
    if (!grown) return -1;
    *buf = grown;
    *cap = n;
    return 0;
}

/* The split: t[i] = src[2i], t[half+i] = src[2i+1]. Sixteen pairs at a time, the low
 * and the high byte of each 16-bit lane packed apart. */
static void
split(uint8_t *t, const uint8_t *src, size_t n)
{
    size_t half = (n + 1) / 2, pairs = n / 2, i = 0;
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
    const __m128i low = _mm_set1_epi16(0xff);
    for (; i + 16 <= pairs; i += 16) {
        __m128i a = _mm_loadu_si128((const __m128i *)(src + 2 * i));
        __m128i b = _mm_loadu_si128((const __m128i *)(src + 2 * i + 16));
        __m128i even = _mm_packus_epi16(_mm_and_si128(a, low), _mm_and_si128(b, low));
        __m128i odd = _mm_packus_epi16(_mm_srli_epi16(a, 8), _mm_srli_epi16(b, 8));
        _mm_storeu_si128((__m128i *)(t + i), even);
        _mm_storeu_si128((__m128i *)(t + half + i), odd);
    }
#endif
    for (; i < pairs; i++) {
        t[i] = src[2 * i];
        t[half + i] = src[2 * i + 1];
    }
    if (n & 1) t[half - 1] = src[n - 1];
}

/* The delta step in place, t[i] = t[i] - t[i-1] + 128 for i > 0: from the end, so that
 * each difference reads the byte before it still unchanged. */
static void
delta(uint8_t *t, size_t n)
{
    size_t i = n;
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
    const __m128i bias = _mm_set1_epi8((char)128);
    for (; i >= 17; i -= 16) {
        __m128i cur = _mm_loadu_si128((const __m128i *)(t + i - 16));
        __m128i prev = _mm_loadu_si128((const __m128i *)(t + i - 17));
        _mm_storeu_si128((__m128i *)(t + i - 16),
                         _mm_add_epi8(_mm_sub_epi8(cur, prev), bias));
    }
#endif
    for (; i > 1; i--)
        t[i - 1] = (uint8_t)(t[i - 1] - t[i - 2] + 128);
}

long long
mcp__zip_encode(mcp__zip_codec *c, const void *packed, size_t n, const void **out)
{
    const uint8_t *src = packed;
    if (n == 0) return 0;
    size_t bound = libdeflate_zlib_compress_bound(c->compressor, n);
    if (reserve(&c->scratch, &c->scratch_cap, n) || reserve(&c->out, &c->out_cap, bound))
        return -1;
    uint8_t *t = c->scratch;
    split(t, src, n);
    delta(t, n);
    size_t size = libdeflate_zlib_compress(c->compressor, t, n, c->out, c->out_cap);
    if (size == 0) /* cannot happen with the bound's space; say "not smaller" */
        return 0;
    *out = c->out;
    return (long long)size;
}

/* Undoes the delta step in place: t[i] = t[i-1] + t[i] - 128, a running sum of
 * bytes. Sixteen at a time, the sum within a block takes four shifted adds, and the
 * block's last byte carries into the next (the scalar loop below is the definition;
 * MCP_NO_SIMD builds use it alone). */
static void
undo_delta(uint8_t *t, size_t n)
{
    size_t i = 1;
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
    const __m128i bias = _mm_set1_epi8((char)128);
    __m128i carry = _mm_set1_epi8((char)t[0]);
    for (; i + 16 <= n; i += 16) {
        __m128i x = _mm_sub_epi8(_mm_loadu_si128((const __m128i *)(t + i)), bias);
        x = _mm_add_epi8(x, _mm_slli_si128(x, 1));
        x = _mm_add_epi8(x, _mm_slli_si128(x, 2));
        x = _mm_add_epi8(x, _mm_slli_si128(x, 4));
        x = _mm_add_epi8(x, _mm_slli_si128(x, 8));
        x = _mm_add_epi8(x, carry);
        _mm_storeu_si128((__m128i *)(t + i), x);
        /* the last byte, in every lane */
        __m128i last = _mm_unpackhi_epi8(x, x);
        last = _mm_shufflehi_epi16(last, 0xff);
        carry = _mm_unpackhi_epi64(last, last);
    }
#endif
    for (; i < n; i++)
        t[i] = (uint8_t)(t[i - 1] + t[i] - 128);
}

/* Undoes the split: dst[2i] = t[i], dst[2i+1] = t[half+i]. */
static void
undo_split(uint8_t *dst, const uint8_t *t, size_t n)
{
    size_t half = (n + 1) / 2, pairs = n / 2, i = 0;
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
    for (; i + 16 <= pairs; i += 16) {
        __m128i even = _mm_loadu_si128((const __m128i *)(t + i));
        __m128i odd = _mm_loadu_si128((const __m128i *)(t + half + i));
        _mm_storeu_si128((__m128i *)(dst + 2 * i), _mm_unpacklo_epi8(even, odd));
        _mm_storeu_si128((__m128i *)(dst + 2 * i + 16), _mm_unpackhi_epi8(even, odd));
    }
#endif
    for (; i < pairs; i++) {
        dst[2 * i] = t[i];
        dst[2 * i + 1] = t[half + i];
    }
    if (n & 1) dst[n - 1] = t[half - 1];
}

int
mcp__zip_decode(mcp__zip_codec *c, const void *in, size_t in_bytes, void *out,
                size_t out_bytes)
{
    if (out_bytes == 0) return in_bytes == 0 ? 0 : -1;
    if (reserve(&c->scratch, &c->scratch_cap, out_bytes)) return -2;
    uint8_t *t = c->scratch;
    /* no actual-size pointer: libdeflate then fails unless the stream inflates to
       exactly out_bytes, which is what the chunk table promised */
    if (libdeflate_zlib_decompress(c->decompressor, in, in_bytes, t, out_bytes, NULL) !=
        LIBDEFLATE_SUCCESS)
        return -1;
    undo_delta(t, out_bytes);
    undo_split(out, t, out_bytes);
    return 0;
}
