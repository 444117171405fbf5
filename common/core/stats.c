/* stats.c: per-channel statistics (see stats.h). */
#include <mcpost/stats.h>

#include "internal.h"

#include <math.h>
#include <stdlib.h>

int
mcp_channel_stats_compute(const mcp_image *img, int c, mcp_channel_stats *out)
{
    if (c < 0 || c >= img->channels)
        return mcp_error("%s: channel index %d outside its %d channels", img->source, c,
                         img->channels);
    int h = img->height;
    mcp_channel_stats *rows = mcp_calloc((size_t)h, sizeof *rows);
    if (!rows) return -1;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        mcp_channel_stats s = {INFINITY, -INFINITY, 0, 0, 0, 0, 0};
        for (int x = 0; x < img->width; x++) {
            float v = mcp_image_px(img, x, y)[c];
            if (isnan(v)) {
                s.n_nan++;
                continue;
            }
            if (isinf(v)) {
                s.n_inf++;
                s.n_negative += v < 0;
                continue;
            }
            s.n_negative += v < 0;
            s.n_finite++;
            s.mean += v; /* row sum for now */
            s.min = v < s.min ? v : s.min;
            s.max = v > s.max ? v : s.max;
        }
        rows[y] = s;
    }
    mcp_channel_stats t = {INFINITY, -INFINITY, 0, 0, 0, 0, 0};
    for (int y = 0; y < h; y++) {
        t.mean += rows[y].mean;
        t.min = rows[y].min < t.min ? rows[y].min : t.min;
        t.max = rows[y].max > t.max ? rows[y].max : t.max;
        t.n_nan += rows[y].n_nan;
        t.n_inf += rows[y].n_inf;
        t.n_negative += rows[y].n_negative;
        t.n_finite += rows[y].n_finite;
    }
    free(rows);
    if (t.n_finite) {
        t.mean /= (double)t.n_finite;
    } else {
        t.min = t.max = t.mean = 0;
    }
    *out = t;
    return 0;
}

/* ---- window sums and pooling ---- */

/* Window sums of a 3-channel image over (2r+1)² clipped at the borders, in double:
 * a summed-area table of (width+1) x (height+1) x 3. */
double *
mcp__window_table(const mcp_image *img)
{
    int w = img->width, h = img->height;
    double *t = mcp_calloc((size_t)(w + 1) * (h + 1) * 3, sizeof *t);
    if (!t) return NULL;
    for (int y = 0; y < h; y++) {
        double row[3] = {0, 0, 0};
        for (int x = 0; x < w; x++) {
            const float *v = mcp_image_px(img, x, y);
            double *o = t + ((size_t)(y + 1) * (w + 1) + x + 1) * 3;
            const double *up = o - (size_t)(w + 1) * 3;
            for (int c = 0; c < 3; c++) {
                row[c] += v[c];
                o[c] = up[c] + row[c];
            }
        }
    }
    return t;
}

void
mcp__window_sum(const double *t, int w, int h, int x, int y, int r, double out[3],
                int *count)
{
    int x0 = x - r < 0 ? 0 : x - r, x1 = x + r + 1 > w ? w : x + r + 1;
    int y0 = y - r < 0 ? 0 : y - r, y1 = y + r + 1 > h ? h : y + r + 1;
    size_t W = (size_t)w + 1;
    for (int c = 0; c < 3; c++)
        out[c] = t[(y1 * W + x1) * 3 + c] - t[(y0 * W + x1) * 3 + c] -
                 t[(y1 * W + x0) * 3 + c] + t[(y0 * W + x0) * 3 + c];
    *count = (x1 - x0) * (y1 - y0);
}

int
mcp_pool_window(mcp_image *values, const mcp_image *shape, int radius)
{
    if (radius < 0) return mcp_error("pooling: radius must be >= 0 (got %d)", radius);
    if (values->channels < 3 ||
        (shape && (shape->width != values->width || shape->height != values->height ||
                   shape->channels < 3)))
        return mcp_error("pooling: the values (%dx%d, %d channels) and the shape need 3 "
                         "channels of one size",
                         values->width, values->height, values->channels);
    if (radius == 0) return 0;
    int w = values->width, h = values->height;
    double *tv = mcp__window_table(values), *ts = shape ? mcp__window_table(shape) : NULL;
    if (!tv || (shape && !ts)) {
        free(tv);
        free(ts);
        return -1;
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double sv[3], ss[3];
            int n;
            mcp__window_sum(tv, w, h, x, y, radius, sv, &n);
            float *v = mcp_image_px(values, x, y);
            if (ts) {
                mcp__window_sum(ts, w, h, x, y, radius, ss, &n);
                const float *sh = mcp_image_px(shape, x, y);
                for (int c = 0; c < 3; c++)
                    v[c] = ss[c] > 0 ? (float)(sh[c] * (fmax(sv[c], 0) / ss[c]))
                                     : (float)(fmax(sv[c], 0) / n);
            } else {
                /* a window sum of non-negative values from the table's differences can
                   come out a rounding below zero beside large ones (a black region next
                   to a firefly): a variance must not */
                for (int c = 0; c < 3; c++)
                    v[c] = (float)(fmax(sv[c], 0) / n);
            }
        }
    free(tv);
    free(ts);
    return 0;
}
