/* srgb8.c: linear values to 8-bit sRGB bytes, the conversion of every PNG and
 * 8-bit picture mcpost writes from floats.
 *
 * A byte is (unsigned char)(mcp_linear_to_srgb(v) * 255 + 0.5) of v clamped to
 * [0, 1] (NaN to 0): a powf per value, which took 40 ms of CPU for a 1080p picture.
 * That function of v is a staircase of 256 steps, so a byte is the number of step
 * edges at or below v: the edges are found once by bisection over the floats, on the
 * formula itself, and a table over each float's top 16 bits (7 of mantissa) gives the
 * step at the start of its range, which no range crosses more than once (a range is at
 * most 2^-8 wide, where the steps are 1/112 apart at the top, and 2^-16 where they are
 * 1/3295 apart below 0.0031308), so one comparison finishes the byte. The result
 * is the formula's byte for every float, which tests/common/test_png.c checks for
 * every float in [2^-9, 1] (below 0.0031308 the formula is 12.92 v, monotone). */
#include "internal.h"

#include <pthread.h>
#include <string.h>

static mcp__srgb8_table table;
static pthread_once_t table_once = PTHREAD_ONCE_INIT;

unsigned char
mcp__srgb8_formula(float v)
{
    v = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f; /* NaN to 0 */
    return (unsigned char)(mcp_linear_to_srgb(v) * 255.0f + 0.5f);
}

static float
float_of(uint32_t bits)
{
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

static void
build_table(void)
{
    const uint32_t one = 0x3f800000u; /* 1.0f */
    /* edge k: the smallest float in [0, 1] whose byte is >= k */
    for (int k = 1; k < 256; k++) {
        uint32_t lo = 0, hi = one; /* byte(lo) < k <= byte(hi) */
        while (hi - lo > 1) {
            const uint32_t mid = lo + (hi - lo) / 2;
            if (mcp__srgb8_formula(float_of(mid)) >= k)
                hi = mid;
            else
                lo = mid;
        }
        table.edge[k] = float_of(hi);
    }
    table.edge[0] = 0.0f;
    table.edge[256] = 2.0f; /* above any clamped value: the search stops at 255 */
    for (uint32_t key = 0; key < MCP__SRGB8_KEYS; key++)
        table.start[key] = mcp__srgb8_formula(float_of(key << 16));
}

const mcp__srgb8_table *
mcp__srgb8_table_get(void)
{
    pthread_once(&table_once, build_table);
    return &table;
}

void
mcp__srgb8_bytes(const mcp_image *img, const int *channels, int n, int srgb,
                 unsigned char *out)
{
    const mcp__srgb8_table *t = mcp__srgb8_table_get();
    const int w = img->width, h = img->height;
#pragma omp parallel for schedule(static) if ((size_t)w * h >= 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *p = mcp_image_px(img, x, y);
            unsigned char *o = out + ((size_t)y * w + x) * n;
            for (int k = 0; k < n; k++) {
                float v = p[channels[k]];
                if (srgb && !(n == 4 && k == 3)) { /* alpha stays linear */
                    o[k] = mcp__srgb8_byte(t, v);
                    continue;
                }
                v = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f; /* NaN to 0 */
                o[k] = (unsigned char)(v * 255.0f + 0.5f);
            }
        }
}
