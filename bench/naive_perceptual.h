/* naive_perceptual.h: straightforward versions of the perceptual methods, the yardstick
 * of bench_perceptual.c (included by it; bench/ builds each bench_*.c alone).
 *
 * Same algorithms and defaults as perceptual/ (docs/mathematics.md §4: 3-tap kernel g,
 * h = delta, clamp tone map, C = 1, replicate borders, serpentine order), written the
 * obvious way: every decision recomputes the local energy sum_q |(g * T(O))(q) -
 * T(I')(q)|^2 over the pixels q it can affect, from scratch, by direct convolution;
 * dithering sorts each pixel's candidates; nothing is cached or run in parallel. */
#ifndef NAIVE_PERCEPTUAL_H
#define NAIVE_PERCEPTUAL_H

#include <mcpost/perceptual.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../common/core/rng_internal.h"

typedef struct {
    int w, h, m;
    const float *cand; /* candidate j at pixel p, channel c: cand[(j * n + p) * 3 + c] */
    const float *surr; /* [n][3] linear */
    const float *mask; /* blue-noise thresholds, mask_size^2 */
    int mask_size;
    uint64_t seed;
} naive_input;

static float
naive_tone(float x) /* clamp */
{
    return x > 0.0f ? (x < 1.0f ? x : 1.0f) : 0.0f;
}

static int
naive_clamp(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

/* sum over q in [x0, x1] x [y0, y1] of |(g * o)(q) - t(q)|^2, o and t in T-space */
static double
naive_box_energy(const float *o, const float *t, int w, int h, int x0, int y0, int x1,
                 int y1)
{
    const double pi = 3.14159265358979323846;
    const double g[3] = {1.0 / pi, 1.0 - 2.0 / pi, 1.0 / pi};
    double e = 0.0;
    for (int y = y0 < 0 ? 0 : y0; y <= y1 && y < h; y++)
        for (int x = x0 < 0 ? 0 : x0; x <= x1 && x < w; x++)
            for (int c = 0; c < 3; c++) {
                double s = 0.0;
                for (int ky = -1; ky <= 1; ky++)
                    for (int kx = -1; kx <= 1; kx++)
                        s += g[ky + 1] * g[kx + 1] *
                             o[((size_t)naive_clamp(y - ky, 0, h - 1) * w +
                                naive_clamp(x - kx, 0, w - 1)) *
                                   3 +
                               c];
                double d = s - t[((size_t)y * w + x) * 3 + c];
                e += d * d;
            }
    return e;
}

static uint64_t
naive_hash(uint64_t seed, uint64_t i) /* the library's per-pixel random start */
{
    return mcp__mix64(seed ^ (MCP__SPLITMIX64_GAMMA * (i + 1)));
}

/* Vertical iterative minimisation over m candidate images (cand as in naive_input,
 * possibly the power set's subset means); random start; out[n][3] linear. Returns the
 * number of passes. */
static int
naive_vertical(const naive_input *in, const float *cand, int m, int max_passes,
               float *out)
{
    int w = in->w, h = in->h;
    size_t n = (size_t)w * h;
    float *o = malloc(n * 3 * sizeof *o), *t = malloc(n * 3 * sizeof *t);
    int *choice = malloc(n * sizeof *choice), passes = 0;
    for (size_t p = 0; p < n; p++) {
        choice[p] = (int)(naive_hash(in->seed, p) % (uint64_t)m);
        for (int c = 0; c < 3; c++) {
            o[p * 3 + c] = naive_tone(cand[((size_t)choice[p] * n + p) * 3 + c]);
            t[p * 3 + c] = naive_tone(in->surr[p * 3 + c]);
        }
    }
    for (int pass = 0; pass < max_passes; pass++) {
        long changes = 0;
        for (int y = 0; y < h; y++)
            for (int i = 0; i < w; i++) {
                int x = y % 2 ? w - 1 - i : i;
                size_t p = (size_t)y * w + x;
                float keep[3] = {o[p * 3], o[p * 3 + 1], o[p * 3 + 2]};
                double before = naive_box_energy(o, t, w, h, x - 1, y - 1, x + 1, y + 1);
                double best = 0.0;
                int bj = -1;
                for (int j = 0; j < m; j++) {
                    if (j == choice[p]) continue;
                    for (int c = 0; c < 3; c++)
                        o[p * 3 + c] = naive_tone(cand[((size_t)j * n + p) * 3 + c]);
                    double after =
                        naive_box_energy(o, t, w, h, x - 1, y - 1, x + 1, y + 1);
                    double de = after - before;
                    if (de < best && de < -1e-12 * (before + after)) best = de, bj = j;
                }
                if (bj >= 0) {
                    choice[p] = bj;
                    changes++;
                }
                for (int c = 0; c < 3; c++)
                    o[p * 3 + c] = bj >= 0
                                       ? naive_tone(cand[((size_t)bj * n + p) * 3 + c])
                                       : keep[c];
            }
        passes++;
        if (changes == 0) break;
    }
    for (size_t p = 0; p < n; p++)
        for (int c = 0; c < 3; c++)
            out[p * 3 + c] = cand[((size_t)choice[p] * n + p) * 3 + c];
    free(o), free(t), free(choice);
    return passes;
}

/* Floyd-Steinberg error diffusion over a full-image error buffer. */
static void
naive_error_diffusion(const naive_input *in, float *out)
{
    int w = in->w, h = in->h;
    size_t n = (size_t)w * h;
    double *o = malloc(n * 3 * sizeof *o);
    for (size_t i = 0; i < n * 3; i++)
        o[i] = mcp_tonemap_value(MCP_TONEMAP_CLAMP, in->surr[i]);
    for (int y = 0; y < h; y++)
        for (int i = 0; i < w; i++) {
            int dir = y % 2 ? -1 : 1, x = y % 2 ? w - 1 - i : i, best = 0;
            size_t p = (size_t)y * w + x;
            double bd = INFINITY;
            for (int j = 0; j < in->m; j++) {
                double d = 0.0;
                for (int c = 0; c < 3; c++) {
                    double v = mcp_tonemap_value(MCP_TONEMAP_CLAMP,
                                                 in->cand[((size_t)j * n + p) * 3 + c]);
                    d += (o[p * 3 + c] - v) * (o[p * 3 + c] - v);
                }
                if (d < bd) bd = d, best = j;
            }
            static const int nx[4] = {1, -1, 0, 1}, ny[4] = {0, 1, 1, 1};
            static const double wt[4] = {7.0 / 16, 3.0 / 16, 5.0 / 16, 1.0 / 16};
            for (int c = 0; c < 3; c++) {
                float lin = in->cand[((size_t)best * n + p) * 3 + c];
                double e = o[p * 3 + c] - mcp_tonemap_value(MCP_TONEMAP_CLAMP, lin);
                out[p * 3 + c] = lin;
                for (int k = 0; k < 4; k++) {
                    int qx = x + nx[k] * dir, qy = y + ny[k];
                    if (qx >= 0 && qx < w && qy < h)
                        o[((size_t)qy * w + qx) * 3 + c] += e * wt[k];
                }
            }
        }
    free(o);
}

typedef struct {
    float lum;
    int j;
} naive_keyed;

static int
naive_by_lum(const void *a, const void *b)
{
    const naive_keyed *p = a, *q = b;
    return p->lum < q->lum ? -1 : p->lum > q->lum ? 1 : p->j - q->j;
}

/* Dithering: per pixel, sort the candidates by luminance and find the interval. */
static void
naive_dither(const naive_input *in, float *out)
{
    int w = in->w, h = in->h, m = in->m;
    size_t n = (size_t)w * h;
    naive_keyed *k = malloc((size_t)m * sizeof *k);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            const float *s = in->surr + p * 3;
            float sl =
                mcp_luminance(naive_tone(s[0]), naive_tone(s[1]), naive_tone(s[2]));
            for (int j = 0; j < m; j++) {
                const float *v = in->cand + ((size_t)j * n + p) * 3;
                k[j].lum =
                    mcp_luminance(naive_tone(v[0]), naive_tone(v[1]), naive_tone(v[2]));
                k[j].j = j;
            }
            qsort(k, (size_t)m, sizeof *k, naive_by_lum);
            int lo = -1;
            while (lo + 1 < m && k[lo + 1].lum <= sl)
                lo++;
            /* lower = the largest <= s (first of equals), upper = the next larger */
            while (lo > 0 && k[lo - 1].lum == k[lo].lum)
                lo--;
            int hi = lo + 1;
            while (lo >= 0 && hi < m && k[hi].lum == k[lo].lum)
                hi++;
            int pick;
            float b = in->mask[(y % in->mask_size) * in->mask_size + x % in->mask_size];
            if (lo < 0)
                pick = k[0].j;
            else if (hi >= m)
                pick = k[lo].j;
            else
                pick = sl - k[lo].lum < b * (k[hi].lum - k[lo].lum) ? k[lo].j : k[hi].j;
            memcpy(out + p * 3, in->cand + ((size_t)pick * n + p) * 3, 3 * sizeof *out);
        }
    free(k);
}

/* Horizontal swaps in 3x3 windows, travel 1: each candidate swap recomputes the
 * energy of the box of pixels it can affect. q is [n][3] linear; out the prediction. */
static int
naive_horizontal(const naive_input *in, const float *q, int max_passes, float *out)
{
    int w = in->w, h = in->h, passes = 0;
    size_t n = (size_t)w * h;
    float *o = malloc(n * 3 * sizeof *o), *t = malloc(n * 3 * sizeof *t);
    int *src = malloc(n * sizeof *src);
    for (size_t p = 0; p < n; p++) {
        src[p] = (int)p;
        for (int c = 0; c < 3; c++) {
            o[p * 3 + c] = naive_tone(q[p * 3 + c]);
            t[p * 3 + c] = naive_tone(in->surr[p * 3 + c]);
        }
    }
    for (int pass = 0; pass < max_passes; pass++) {
        long swaps = 0;
        for (int y = 0; y < h; y++)
            for (int i = 0; i < w; i++) {
                int x = y % 2 ? w - 1 - i : i, bx = -1, by = -1;
                size_t pi = (size_t)y * w + x;
                double best = 0.0;
                for (int yj = y - 1; yj <= y + 1; yj++)
                    for (int xj = x - 1; xj <= x + 1; xj++) {
                        if (xj < 0 || yj < 0 || xj >= w || yj >= h ||
                            (xj == x && yj == y))
                            continue;
                        size_t pj = (size_t)yj * w + xj;
                        int sj = src[pj], si = src[pi];
                        if (abs(sj % w - x) > 1 || abs(sj / w - y) > 1 ||
                            abs(si % w - xj) > 1 || abs(si / w - yj) > 1)
                            continue;
                        int x0 = (x < xj ? x : xj) - 1, x1 = (x > xj ? x : xj) + 1;
                        int y0 = (y < yj ? y : yj) - 1, y1 = (y > yj ? y : yj) + 1;
                        double before = naive_box_energy(o, t, w, h, x0, y0, x1, y1);
                        float tmp[3];
                        memcpy(tmp, o + pi * 3, sizeof tmp);
                        memcpy(o + pi * 3, o + pj * 3, sizeof tmp);
                        memcpy(o + pj * 3, tmp, sizeof tmp);
                        double after = naive_box_energy(o, t, w, h, x0, y0, x1, y1);
                        memcpy(o + pj * 3, o + pi * 3, sizeof tmp);
                        memcpy(o + pi * 3, tmp, sizeof tmp);
                        double de = after - before;
                        if (de < best && de < -1e-12 * (before + after))
                            best = de, bx = xj, by = yj;
                    }
                if (bx < 0) continue;
                size_t pj = (size_t)by * w + bx;
                float tmp[3];
                memcpy(tmp, o + pi * 3, sizeof tmp);
                memcpy(o + pi * 3, o + pj * 3, sizeof tmp);
                memcpy(o + pj * 3, tmp, sizeof tmp);
                int s = src[pi];
                src[pi] = src[pj], src[pj] = s;
                swaps++;
            }
        passes++;
        if (swaps == 0) break;
    }
    for (size_t p = 0; p < n; p++)
        memcpy(out + p * 3, q + (size_t)src[p] * 3, 3 * sizeof *out);
    free(o), free(t), free(src);
    return passes;
}

#endif
