/* flip_stats.c: the statistics NVIDIA's FLIP tool reports beside the mean -- weighted
 * median and quartiles, min, max and the (weighted) histogram -- with the tool's
 * definitions (flip.h, docs/metrics.md "FLIP's statistics"): the weighted percentiles
 * take float running sums exactly as the tool does, so they agree with its printout to
 * the last digit on the same map. */
#include <mcpost/flip.h>

#include "internal.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Float bits as an unsigned key with the same order as the values (negatives
 * flipped), so that a radix sort on keys sorts the values. */
static uint32_t
key_of(float v)
{
    uint32_t b;
    memcpy(&b, &v, sizeof b);
    return b & 0x80000000u ? ~b : b | 0x80000000u;
}

static float
value_of(uint32_t k)
{
    uint32_t b = k & 0x80000000u ? k & 0x7fffffffu : ~k;
    float v;
    memcpy(&v, &b, sizeof v);
    return v;
}

/* The n values in ascending order (a radix sort on the keys: 8 bits a pass, passes
 * whose byte is the same everywhere skipped -- FLIP's values share their top byte). */
static float *
sorted_copy(const float *values, size_t n)
{
    uint32_t *a = mcp_malloc(n * sizeof *a), *b = mcp_malloc(n * sizeof *b);
    if (!a || !b) {
        free(a), free(b);
        return NULL;
    }
    for (size_t i = 0; i < n; i++)
        a[i] = key_of(values[i]);
    for (int shift = 0; shift < 32; shift += 8) {
        size_t count[257] = {0};
        for (size_t i = 0; i < n; i++)
            count[((a[i] >> shift) & 0xffu) + 1]++;
        if (count[((a[0] >> shift) & 0xffu) + 1] == n) continue;
        for (int d = 0; d < 256; d++)
            count[d + 1] += count[d];
        for (size_t i = 0; i < n; i++)
            b[count[(a[i] >> shift) & 0xffu]++] = a[i];
        uint32_t *t = a;
        a = b, b = t;
    }
    free(b);
    float *out = (float *)a; /* same size: the keys turn back into values in place */
    for (size_t i = 0; i < n; i++)
        out[i] = value_of(a[i]);
    return out;
}

/* The tool's weighted percentile (pooling.h getPercentile, weighted): the first sorted
 * value at which the float running sum exceeds p * total, all in float. */
static double
weighted_at(const float *sorted, size_t n, float total, float p)
{
    const float target = p * total;
    float running = 0.0f;
    for (size_t i = 0; i < n; i++) {
        running += sorted[i];
        if (running > target) return sorted[i];
    }
    return 0.0;
}

/* The tool's total: a float running sum in row-major order (pooling.h update). */
static float
float_total(const float *values, size_t n)
{
    float sum = 0.0f;
    for (size_t i = 0; i < n; i++)
        sum += values[i];
    return sum;
}

static int
check_values(const float *values, size_t n)
{
    if (!values || n == 0) return mcp_error("flip statistics: no values");
    for (size_t i = 0; i < n; i++)
        if (!isfinite(values[i]))
            return mcp_error("flip statistics: value %zu is not finite", i);
    return 0;
}

int
mcp_flip_weighted_percentile(const float *values, size_t n, double p, double *out)
{
    if (!(p >= 0.0 && p <= 1.0))
        return mcp_error("flip statistics: p must be in [0, 1] (got %g)", p);
    if (check_values(values, n)) return -1;
    float *sorted = sorted_copy(values, n);
    if (!sorted) return mcp_error("flip statistics: out of memory (%zu values)", n);
    *out = weighted_at(sorted, n, float_total(values, n), (float)p);
    free(sorted);
    return 0;
}

int
mcp_flip_statistics(const float *values, size_t n, mcp_flip_stats *out)
{
    memset(out, 0, sizeof *out);
    if (check_values(values, n)) return -1;
    /* the tool's bucket width is a float, (1.0f - 0.0f) / 100, and the index divides
     * in double (pooling.h histogram::valueBucketId) */
    const double width = (double)(1.0f / (float)MCP_FLIP_HISTOGRAM_BUCKETS);
    float lo = values[0], hi = values[0];
    for (size_t i = 0; i < n; i++) {
        float v = values[i];
        lo = v < lo ? v : lo;
        hi = v > hi ? v : hi;
        if (v < 0.0f || v > 1.0f) continue;
        size_t b = (size_t)((double)v / width);
        out->histogram[b >= MCP_FLIP_HISTOGRAM_BUCKETS ? MCP_FLIP_HISTOGRAM_BUCKETS - 1
                                                       : b]++;
    }
    out->min = lo;
    out->max = hi;
    out->pixels = (long long)n;
    float *sorted = sorted_copy(values, n);
    if (!sorted) return mcp_error("flip statistics: out of memory (%zu values)", n);
    const float total = float_total(values, n);
    out->weighted_median = weighted_at(sorted, n, total, 0.5f);
    out->weighted_q1 = weighted_at(sorted, n, total, 0.25f);
    out->weighted_q3 = weighted_at(sorted, n, total, 0.75f);
    free(sorted);
    return 0;
}

double
mcp_flip_weighted_bucket(const mcp_flip_stats *s, int i)
{
    if (i < 0 || i >= MCP_FLIP_HISTOGRAM_BUCKETS || s->pixels <= 0) return NAN;
    /* the tool's plot script: weight (i + 0.5) * bucketStep, per n / (1024 * 1024) */
    return (double)s->histogram[i] * ((i + 0.5) * 0.01) /
           ((double)s->pixels / (1024.0 * 1024.0));
}
