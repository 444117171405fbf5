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

/* Radix sort of n keys (a, with scratch b) in three passes of 11 bits, each pass's
 * counts taken in one read beforehand; a pass whose digit is the same for every key is
 * skipped. Returns the array that holds the sorted keys (a or b). */
#define DIGIT_BITS 11
#define DIGITS (1u << DIGIT_BITS)

static uint32_t *
radix_sort(uint32_t *a, uint32_t *b, size_t n, size_t (*count)[DIGITS])
{
    for (int pass = 0; pass < 3; pass++) {
        const int shift = pass * DIGIT_BITS;
        size_t *c = count[pass];
        if (c[(a[0] >> shift) & (DIGITS - 1)] == n) continue;
        size_t at = 0;
        for (unsigned d = 0; d < DIGITS; d++) { /* counts -> first index of each digit */
            size_t k = c[d];
            c[d] = at;
            at += k;
        }
        for (size_t i = 0; i < n; i++)
            b[c[(a[i] >> shift) & (DIGITS - 1)]++] = a[i];
        uint32_t *t = a;
        a = b, b = t;
    }
    return a;
}

/* The tool's weighted percentiles at the k ascending p (pooling.h getPercentile,
 * weighted): for each, the first sorted value at which the float running sum exceeds
 * p * total, all in float; 0 when none does. One running sum serves all k: it is the
 * same sequence of float additions the tool makes for each. */
static void
weighted_from_keys(const uint32_t *sorted, size_t n, float total, const float *p,
                   double *out, int k)
{
    float running = 0.0f;
    int next = 0;
    for (int j = 0; j < k; j++)
        out[j] = 0.0;
    for (size_t i = 0; i < n && next < k; i++) {
        const float v = value_of(sorted[i]);
        running += v;
        while (next < k && running > p[next] * total)
            out[next++] = v;
    }
}

/* Keys, counts of their digits, and the float total in row-major order (pooling.h
 * update) in one read of the values. NULL when out of memory. */
static uint32_t *
sorted_keys(const float *values, size_t n, float *total, uint32_t **scratch)
{
    uint32_t *a = mcp_malloc(n * sizeof *a), *b = mcp_malloc(n * sizeof *b);
    size_t(*count)[DIGITS] = mcp_calloc(3, sizeof *count);
    if (!a || !b || !count) {
        free(a), free(b), free(count);
        return NULL;
    }
    float sum = 0.0f;
    for (size_t i = 0; i < n; i++) {
        const uint32_t k = key_of(values[i]);
        a[i] = k;
        sum += values[i];
        count[0][k & (DIGITS - 1)]++;
        count[1][(k >> DIGIT_BITS) & (DIGITS - 1)]++;
        count[2][k >> (2 * DIGIT_BITS)]++;
    }
    uint32_t *sorted = radix_sort(a, b, n, count);
    free(count);
    *total = sum;
    *scratch = sorted == a ? b : a;
    return sorted;
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
    float total, fp = (float)p;
    uint32_t *scratch, *sorted = sorted_keys(values, n, &total, &scratch);
    if (!sorted) return mcp_error("flip statistics: out of memory (%zu values)", n);
    weighted_from_keys(sorted, n, total, &fp, out, 1);
    free(sorted);
    free(scratch);
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
    float total;
    uint32_t *scratch, *sorted = sorted_keys(values, n, &total, &scratch);
    if (!sorted) return mcp_error("flip statistics: out of memory (%zu values)", n);
    /* the tool asks for 0.5f, 0.25f and 0.75f; ascending here for one running sum */
    const float p[3] = {0.25f, 0.5f, 0.75f};
    double q[3];
    weighted_from_keys(sorted, n, total, p, q, 3);
    out->weighted_q1 = q[0];
    out->weighted_median = q[1];
    out->weighted_q3 = q[2];
    free(sorted);
    free(scratch);
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
