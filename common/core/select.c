/* select.c: the values of given ranks among n floats, without sorting them.
 *
 * A percentile report needs a handful of order statistics of millions of values; a sort
 * spends n log n comparisons on the order of values nobody asks for (about 0.6 s for a
 * 1080p RGB image). This is a radix select instead: each float's bits are mapped to an
 * unsigned key that orders as the floats do, one parallel pass histograms the keys' top
 * 16 bits, and for each bin that holds a wanted rank a second pass gathers that bin's
 * values and histograms their low 16 bits, which pins the exact key. Two passes over the
 * data, exact (the value returned is one of the inputs, the one a sort would put at that
 * rank), and independent of the thread count. NaN is the caller's to reject. */
#include "internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define BINS 65536

/* Keys that order as the floats: negative floats reversed below the positive ones. */
static inline uint32_t
float_key(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

static inline float
key_float(uint32_t k)
{
    uint32_t u = (k & 0x80000000u) ? (k & 0x7fffffffu) : ~k;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* hist[b] = how many of v[0..n) have top 16 key bits b; per-thread tables summed. */
static int
histogram_top(const float *v, size_t n, uint64_t *hist)
{
    int failed = 0;
    memset(hist, 0, BINS * sizeof *hist);
#pragma omp parallel reduction(+ : failed)
    {
        uint64_t *mine = mcp_calloc(BINS, sizeof *mine);
        if (!mine) failed++;
#pragma omp for schedule(static)
        for (size_t i = 0; i < n; i++)
            if (mine) mine[float_key(v[i]) >> 16]++;
        if (mine) {
#pragma omp critical
            for (int b = 0; b < BINS; b++)
                hist[b] += mine[b];
        }
        free(mine);
    }
    return failed ? mcp_error("out of memory (selection histograms)") : 0;
}

/* The value of rank r (0-based) among the m values of keys whose top bits are `top`:
 * a histogram of their low 16 bits. */
static float
select_in_bin(const uint32_t *low, size_t m, uint32_t top, size_t r, uint32_t *count)
{
    memset(count, 0, BINS * sizeof *count);
    for (size_t i = 0; i < m; i++)
        count[low[i]]++;
    size_t below = 0;
    uint32_t b = 0;
    for (; b < BINS - 1 && below + count[b] <= r; b++)
        below += count[b];
    return key_float(top << 16 | b);
}

/* The nearest-rank index of p in [0, 1] among n values: ceil(p n) - 1, clamped. */
static size_t
nearest_rank(double p, size_t n)
{
    double r = ceil(p * (double)n) - 1.0;
    if (r < 0.0) r = 0.0;
    if (r > (double)(n - 1)) r = (double)(n - 1);
    return (size_t)r;
}

int
mcp__select_percentiles(const float *v, size_t n, const double *p, int k, double *out)
{
    enum { BATCH = 64 }; /* ranks per selection: any k in a few passes */
    size_t ranks[BATCH];
    float at[BATCH];
    if (n == 0) return mcp_error("selection: no values");
    for (int j0 = 0; j0 < k; j0 += BATCH) {
        int m = k - j0 < BATCH ? k - j0 : BATCH;
        for (int j = 0; j < m; j++)
            ranks[j] = nearest_rank(p[j0 + j], n);
        if (mcp__select_ranks(v, n, ranks, m, at)) return -1;
        for (int j = 0; j < m; j++)
            out[j0 + j] = at[j];
    }
    return 0;
}

int
mcp__select_ranks(const float *v, size_t n, const size_t *ranks, int k, float *out)
{
    if (k <= 0) return 0;
    if (n == 0) return mcp_error("selection: no values");
    for (int j = 0; j < k; j++)
        if (ranks[j] >= n)
            return mcp_error("selection: rank %zu of %zu values", ranks[j], n);
    uint64_t *hist = mcp_malloc(BINS * sizeof *hist);
    uint32_t *count = mcp_malloc(BINS * sizeof *count);
    int16_t *slot = mcp_malloc(BINS * sizeof *slot); /* bin -> gathered list, or -1 */
    uint32_t *top = mcp_calloc((size_t)k, sizeof *top);
    size_t *below = mcp_calloc((size_t)k, sizeof *below), *got = NULL;
    uint32_t **low = mcp_calloc((size_t)k, sizeof *low);
    int rc = -1, lists = 0;
    if (!hist || !count || !slot || !top || !below || !low || histogram_top(v, n, hist))
        goto done;
    /* the bin of each rank and the values below it; ranks that share a bin share its
     * list */
    memset(slot, 0xff, BINS * sizeof *slot);
    for (int j = 0; j < k; j++) {
        uint64_t b = 0;
        uint32_t t = 0;
        while (b + hist[t] <= ranks[j])
            b += hist[t++];
        top[j] = t;
        below[j] = (size_t)b;
        if (slot[t] < 0) {
            if (!(low[lists] = mcp_malloc((size_t)hist[t] * sizeof **low))) goto done;
            slot[t] = (int16_t)lists++;
        }
    }
    /* one pass gathers the low key bits of every value in those bins */
    if (!(got = mcp_calloc((size_t)lists, sizeof *got))) goto done;
    for (size_t i = 0; i < n; i++) {
        uint32_t key = float_key(v[i]);
        int s = slot[key >> 16];
        if (s >= 0) low[s][got[s]++] = key & 0xffffu;
    }
    for (int j = 0; j < k; j++) {
        int s = slot[top[j]];
        out[j] = select_in_bin(low[s], got[s], top[j], ranks[j] - below[j], count);
    }
    rc = 0;
done:
    for (int j = 0; low && j < lists; j++)
        free(low[j]);
    free(low);
    free(got);
    free(below);
    free(top);
    free(slot);
    free(count);
    free(hist);
    return rc;
}

int
mcp__image_channel_spread(const mcp_image *img, int channel, double p, float out[3])
{
    const size_t n = (size_t)img->width * img->height;
    float *v = mcp_malloc(n * sizeof *v);
    if (!v) return -1;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            v[(size_t)y * img->width + x] = mcp_image_px(img, x, y)[channel];
    const size_t ranks[3] = {0, (size_t)(p * (double)(n - 1)), n - 1};
    int rc = mcp__select_ranks(v, n, ranks, 3, out);
    free(v);
    return rc;
}
