/* tza.c: reader of OIDN's .tza tensor archives (docs/oidn-network.md §2): version 2.x
 * archives with float32 ('f', OIDN 1.x) or float16 ('h', OIDN 2.x) tensors. The whole
 * file is read, every tensor is converted to float32, and the file buffer is dropped. */
#include "unet_internal.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define TZA_MAGIC 0x41D7

typedef struct reader {
    const unsigned char *p;
    size_t size, pos;
} reader;

static int
take(reader *r, size_t n, const unsigned char **at)
{
    if (n > r->size - r->pos) return -1;
    *at = r->p + r->pos;
    r->pos += n;
    return 0;
}

static uint64_t
le(const unsigned char *p, int n)
{
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--)
        v = (v << 8) | p[i];
    return v;
}

float
mcp__half_to_float(unsigned short h)
{
    unsigned sign = (h >> 15) & 1u, e = (h >> 10) & 31u, m = h & 1023u;
    uint32_t bits;
    if (e == 0) {
        if (m == 0) {
            bits = sign << 31;
        } else { /* subnormal: normalise */
            int shift = 0;
            while (!(m & 1024u)) {
                m <<= 1;
                shift++;
            }
            m &= 1023u;
            bits = (sign << 31) | ((uint32_t)(127 - 15 + 1 - shift) << 23) | (m << 13);
        }
    } else if (e == 31) {
        bits = (sign << 31) | (255u << 23) | (m << 13);
    } else {
        bits = (sign << 31) | ((e - 15 + 127) << 23) | (m << 13);
    }
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

void
mcp__tza_free(mcp__tza *tza)
{
    if (!tza) return;
    for (int i = 0; i < tza->count; i++) {
        free(tza->tensors[i].name);
        free(tza->tensors[i].data);
    }
    free(tza->tensors);
    free(tza);
}

const mcp__tza_tensor *
mcp__tza_find(const mcp__tza *tza, const char *name)
{
    for (int i = 0; i < tza->count; i++)
        if (!strcmp(tza->tensors[i].name, name)) return &tza->tensors[i];
    return NULL;
}

static int
parse_tensor(reader *r, const char *src, int k, mcp__tza_tensor *t)
{
    const unsigned char *at;
    if (take(r, 2, &at))
        return mcp_error("%s: truncated tensor table (tensor %d)", src, k);
    size_t len = (size_t)le(at, 2);
    if (take(r, len, &at))
        return mcp_error("%s: truncated tensor table (tensor %d)", src, k);
    if (!(t->name = mcp_malloc(len + 1))) return -1;
    memcpy(t->name, at, len);
    t->name[len] = 0;
    if (take(r, 1, &at))
        return mcp_error("%s: truncated tensor table (tensor '%s')", src, t->name);
    t->ndims = at[0];
    if (t->ndims < 1 || t->ndims > 4)
        return mcp_error("%s: tensor '%s': unsupported rank %d", src, t->name, t->ndims);
    size_t count = 1;
    for (int d = 0; d < t->ndims; d++) {
        if (take(r, 4, &at))
            return mcp_error("%s: truncated tensor table (tensor '%s')", src, t->name);
        uint64_t v = le(at, 4);
        if (v < 1 || v > (1u << 24) || mcp_size_mul(count, (size_t)v, &count) ||
            count > ((size_t)1 << 31))
            return mcp_error("%s: tensor '%s': bad dimension %llu", src, t->name,
                             (unsigned long long)v);
        t->dims[d] = (int)v;
    }
    t->count = count;
    if (take(r, (size_t)t->ndims, &at))
        return mcp_error("%s: truncated tensor table (tensor '%s')", src, t->name);
    memcpy(t->layout, at, (size_t)t->ndims);
    t->layout[t->ndims] = 0;
    if (strcmp(t->layout, t->ndims == 4 ? "oihw" : "x") ||
        (t->ndims != 4 && t->ndims != 1))
        return mcp_error("%s: tensor '%s': unsupported layout '%s'", src, t->name,
                         t->layout);
    if (take(r, 1, &at))
        return mcp_error("%s: truncated tensor table (tensor '%s')", src, t->name);
    t->dtype = (char)at[0];
    if (t->dtype != 'f' && t->dtype != 'h')
        return mcp_error("%s: tensor '%s': unsupported dtype '%c' (0x%02x; only f and h)",
                         src, t->name, at[0] >= 32 && at[0] < 127 ? at[0] : '?', at[0]);
    if (take(r, 8, &at))
        return mcp_error("%s: truncated tensor table (tensor '%s')", src, t->name);
    uint64_t off = le(at, 8);
    size_t elem = t->dtype == 'f' ? 4 : 2, bytes = count * elem;
    if (off > r->size || bytes > r->size - off)
        return mcp_error("%s: tensor '%s': data truncated (%zu bytes at offset %llu, "
                         "file is %zu bytes)",
                         src, t->name, bytes, (unsigned long long)off, r->size);
    if (!(t->data = mcp_malloc(count * sizeof(float)))) return -1;
    const unsigned char *d = r->p + off;
    for (size_t i = 0; i < count; i++) {
        if (t->dtype == 'f') {
            uint32_t bits = (uint32_t)le(d + 4 * i, 4);
            memcpy(&t->data[i], &bits, 4);
        } else {
            t->data[i] = mcp__half_to_float((unsigned short)le(d + 2 * i, 2));
        }
    }
    return 0;
}

int
mcp__tza_parse(const unsigned char *bytes, size_t size, const char *source,
               mcp__tza **out)
{
    *out = NULL;
    const char *src = source ? source : "tza";
    if (size < 12) return mcp_error("%s: truncated .tza header (%zu bytes)", src, size);
    unsigned magic = (unsigned)le(bytes, 2);
    if (magic != TZA_MAGIC)
        return mcp_error("%s: not a .tza file (magic 0x%04x, expected 0x%04x)", src,
                         magic, TZA_MAGIC);
    if (bytes[2] != 2)
        return mcp_error("%s: unsupported .tza version %d.%d (only 2.x)", src, bytes[2],
                         bytes[3]);
    uint64_t table = le(bytes + 4, 8);
    if (table < 12 || table > size || size - table < 4)
        return mcp_error(
            "%s: truncated .tza file (table at offset %llu, file is %zu bytes)", src,
            (unsigned long long)table, size);
    reader r = {bytes, size, (size_t)table};
    const unsigned char *at = NULL;
    if (take(&r, 4, &at)) /* cannot fail after the size check above */
        return mcp_error("%s: truncated tensor table", src);
    uint64_t n = le(at, 4);
    if (n < 1 || n > 4096)
        return mcp_error("%s: bad tensor count %llu", src, (unsigned long long)n);
    mcp__tza *tza = mcp_calloc(1, sizeof *tza);
    if (!tza) return -1;
    if (!(tza->tensors = mcp_calloc((size_t)n, sizeof *tza->tensors))) {
        free(tza);
        return -1;
    }
    for (int k = 0; k < (int)n; k++) {
        tza->count = k + 1;
        if (parse_tensor(&r, src, k, &tza->tensors[k])) {
            mcp__tza_free(tza);
            return -1;
        }
    }
    *out = tza;
    return 0;
}

int
mcp__tza_read(const char *path, mcp__tza **out)
{
    *out = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) return mcp_error("%s: cannot open weights", path);
    unsigned char *buf = NULL;
    long size = -1;
    if (fseek(f, 0, SEEK_END) == 0) size = ftell(f);
    if (size < 0 || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        return mcp_error("%s: cannot read weights", path);
    }
    if (!(buf = mcp_malloc(size ? (size_t)size : 1))) {
        fclose(f);
        return -1;
    }
    size_t got = fread(buf, 1, (size_t)size, f);
    fclose(f);
    if (got != (size_t)size) {
        free(buf);
        return mcp_error("%s: cannot read weights (%zu of %ld bytes)", path, got, size);
    }
    int rc = mcp__tza_parse(buf, (size_t)size, path, out);
    free(buf);
    return rc;
}
