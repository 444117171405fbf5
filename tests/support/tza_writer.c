/* tza_writer.c: a test-only .tza writer following OIDN's training/tza.py layout
 * (docs/oidn-network.md §2): 12-byte header, 64-aligned tensors, 64-aligned table at
 * the end. */
#include "tza_writer.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "testing.h"

unsigned short
mcp_test_float_to_half(float f)
{
    uint32_t x;
    memcpy(&x, &f, 4);
    uint32_t sign = (x >> 16) & 0x8000u, e = (x >> 23) & 255u, m = x & 0x7fffffu;
    if (e == 255) return (unsigned short)(sign | 0x7c00u | (m ? 0x200u : 0));
    int ex = (int)e - 127 + 15;
    if (ex >= 31) return (unsigned short)(sign | 0x7c00u);
    if (ex <= 0) { /* subnormal or zero */
        if (ex < -10) return (unsigned short)sign;
        m |= 0x800000u;
        int shift = 14 - ex;
        uint32_t half = m >> shift, rem = m & ((1u << shift) - 1),
                 mid = 1u << (shift - 1);
        if (rem > mid || (rem == mid && (half & 1u))) half++;
        return (unsigned short)(sign | half);
    }
    uint32_t half = ((uint32_t)ex << 10) | (m >> 13), rem = m & 0x1fffu;
    if (rem > 0x1000u || (rem == 0x1000u && (half & 1u)))
        half++; /* may carry into the exponent, up to infinity: correct */
    return (unsigned short)(sign | half);
}

static void
put(FILE *f, uint64_t v, int n)
{
    for (int i = 0; i < n; i++)
        fputc((int)((v >> (8 * i)) & 255u), f);
}

static void
pad64(FILE *f)
{
    while (ftell(f) % 64)
        fputc(0, f);
}

void
mcp_test_tza_write(const char *path, const mcp_test_tza_tensor *t, int n, char dtype)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    put(f, 0x41D7, 2);
    put(f, 2, 1);
    put(f, 0, 1);
    put(f, 0, 8); /* table offset, patched below */
    uint64_t *off = calloc((size_t)n, sizeof *off);
    assert_non_null(off);
    for (int k = 0; k < n; k++) {
        pad64(f);
        off[k] = (uint64_t)ftell(f);
        size_t count = 1;
        for (int d = 0; d < t[k].ndims; d++)
            count *= (size_t)t[k].dims[d];
        for (size_t i = 0; i < count; i++) {
            if (dtype == 'f') {
                uint32_t bits;
                memcpy(&bits, &t[k].data[i], 4);
                put(f, bits, 4);
            } else if (dtype == 'h') {
                put(f, mcp_test_float_to_half(t[k].data[i]), 2);
            } else {
                put(f, 0, 1);
            }
        }
    }
    pad64(f);
    uint64_t table = (uint64_t)ftell(f);
    put(f, (uint64_t)n, 4);
    for (int k = 0; k < n; k++) {
        size_t len = strlen(t[k].name);
        put(f, len, 2);
        fwrite(t[k].name, 1, len, f);
        put(f, (uint64_t)t[k].ndims, 1);
        for (int d = 0; d < t[k].ndims; d++)
            put(f, (uint64_t)t[k].dims[d], 4);
        fputs(t[k].ndims == 4 ? "oihw" : "x", f);
        fputc(dtype, f);
        put(f, off[k], 8);
    }
    fseek(f, 4, SEEK_SET);
    put(f, table, 8);
    assert_int_equal(fclose(f), 0);
    free(off);
}

void
mcp_test_write_bytes(const char *path, const void *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(data, 1, n, f), n);
    assert_int_equal(fclose(f), 0);
}
