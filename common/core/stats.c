/* stats.c: per-channel statistics (see stats.h). */
#include <mcpost/stats.h>

#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

void
mcp__channel_stats_rows(const mcp_image *img, int c, mcp_channel_stats *rows)
{
#pragma omp parallel for schedule(static)
    for (int y = 0; y < img->height; y++) {
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
}

void
mcp__channel_stats_start(mcp_channel_stats *t)
{
    *t = (mcp_channel_stats){INFINITY, -INFINITY, 0, 0, 0, 0, 0};
}

void
mcp__channel_stats_add(mcp_channel_stats *t, const mcp_channel_stats *rows, int n)
{
    for (int y = 0; y < n; y++) {
        t->mean += rows[y].mean;
        t->min = rows[y].min < t->min ? rows[y].min : t->min;
        t->max = rows[y].max > t->max ? rows[y].max : t->max;
        t->n_nan += rows[y].n_nan;
        t->n_inf += rows[y].n_inf;
        t->n_negative += rows[y].n_negative;
        t->n_finite += rows[y].n_finite;
    }
}

void
mcp__channel_stats_finish(mcp_channel_stats *t)
{
    if (t->n_finite)
        t->mean /= (double)t->n_finite;
    else
        t->min = t->max = t->mean = 0;
}

int
mcp_channel_stats_compute(const mcp_image *img, int c, mcp_channel_stats *out)
{
    if (c < 0 || c >= img->channels)
        return mcp_error("%s: channel index %d outside its %d channels", img->source, c,
                         img->channels);
    mcp_channel_stats *rows = mcp_calloc((size_t)img->height, sizeof *rows);
    if (!rows) return -1;
    mcp__channel_stats_rows(img, c, rows);
    mcp__channel_stats_start(out);
    mcp__channel_stats_add(out, rows, img->height);
    mcp__channel_stats_finish(out);
    free(rows);
    return 0;
}

/* ---- window sums and pooling ---- */

/* Window sums, a band of rows at a time (internal.h). A summed-area table did this
 * before: (w + 1)(h + 1) x 3 doubles (50 MB at 1080p, filled by one thread), whose
 * window sums are differences of prefix sums over most of the image. Here each row's
 * sums are the column sums over the window's rows, added directly, then a running sum
 * across them, so a sum's rounding is that of the values along one row, not of the
 * image's total; a band's buffers are a few MB, its rows run in parallel, and only the
 * r rows above a band are kept aside, as they were, for a caller that overwrites the
 * images band by band. */

/* Row yy of image i as it was before the band at y0 was written: the kept copy above
 * the band (3 floats a pixel), else the image's own row; *stride: floats per pixel. */
static const float *
window_row(const mcp__window *wb, int i, int y0, int yy, ptrdiff_t *stride)
{
    if (yy < y0) {
        *stride = 3;
        return wb->halo[i] + (size_t)(yy - (y0 - wb->r)) * wb->w * 3;
    }
    *stride = wb->img[i]->pixel_stride;
    return mcp_image_px(wb->img[i], 0, yy);
}

int
mcp__window_begin(mcp__window *wb, const mcp_image *const *imgs, int n, int r)
{
    memset(wb, 0, sizeof *wb);
    if (n < 1 || n > 3) return mcp_error("window sums: 1 to 3 images (got %d)", n);
    wb->n = n;
    wb->r = r;
    wb->w = imgs[0]->width;
    wb->h = imgs[0]->height;
    wb->rows = MCP__WINDOW_BAND > r ? MCP__WINDOW_BAND : r;
    size_t threads = 1;
#ifdef _OPENMP
    threads = (size_t)omp_get_max_threads();
#endif
    /* each thread's column sums of one row */
    if (!(wb->cols = mcp_malloc(threads * (size_t)wb->w * 3 * sizeof *wb->cols)))
        return -1;
    for (int i = 0; i < n; i++) {
        wb->img[i] = imgs[i];
        wb->sums[i] = mcp_malloc((size_t)wb->rows * wb->w * 3 * sizeof(double));
        wb->halo[i] = mcp_malloc(((size_t)r * wb->w * 3 + 1) * sizeof(float));
        wb->next[i] = mcp_malloc(((size_t)r * wb->w * 3 + 1) * sizeof(float));
        if (!wb->sums[i] || !wb->halo[i] || !wb->next[i]) {
            mcp__window_end(wb);
            return -1;
        }
    }
    return 0;
}

int
mcp__window_band(mcp__window *wb, int y0, int y1)
{
    const int w = wb->w, h = wb->h, r = wb->r;
    if (y1 - y0 > wb->rows) return mcp_error("window sums: a band of %d rows", y1 - y0);
    wb->y0 = y0;
#pragma omp parallel for collapse(2) schedule(static)
    for (int i = 0; i < wb->n; i++)
        for (int y = y0; y < y1; y++) {
            size_t t = 0;
#ifdef _OPENMP
            t = (size_t)omp_get_thread_num();
#endif
            double *col = wb->cols + t * w * 3;
            const int a = y - r < 0 ? 0 : y - r, b = y + r + 1 > h ? h : y + r + 1;
            for (int k = 0; k < 3 * w; k++)
                col[k] = 0.0;
            for (int yy = a; yy < b; yy++) {
                ptrdiff_t stride;
                const float *row = window_row(wb, i, y0, yy, &stride);
                for (int x = 0; x < w; x++)
                    for (int c = 0; c < 3; c++)
                        col[3 * x + c] += row[x * stride + c];
            }
            /* across: the running sum over columns [x - r, x + r] */
            double run[3] = {0, 0, 0};
            for (int x = 0; x < r && x < w; x++)
                for (int c = 0; c < 3; c++)
                    run[c] += col[3 * x + c];
            double *out = wb->sums[i] + (size_t)(y - y0) * w * 3;
            for (int x = 0; x < w; x++) {
                for (int c = 0; c < 3; c++) {
                    if (x + r < w) run[c] += col[3 * (x + r) + c];
                    if (x - r - 1 >= 0) run[c] -= col[3 * (x - r - 1) + c];
                    out[3 * x + c] = run[c];
                }
            }
        }
    /* the r rows above the next band, as they are now (before the caller writes this
       band): from this band's rows, or the rows kept for it */
    for (int i = 0; i < wb->n && r > 0; i++) {
        for (int k = 0; k < r; k++) {
            const int yy = y1 - r + k;
            float *dst = wb->next[i] + (size_t)k * w * 3;
            if (yy < 0) continue;
            ptrdiff_t stride;
            const float *row = window_row(wb, i, y0, yy, &stride);
            for (int x = 0; x < w; x++)
                for (int c = 0; c < 3; c++)
                    dst[3 * x + c] = row[x * stride + c];
        }
        float *t = wb->halo[i];
        wb->halo[i] = wb->next[i];
        wb->next[i] = t;
    }
    return 0;
}

int
mcp__window_count(const mcp__window *wb, int x, int y)
{
    const int r = wb->r;
    const int x0 = x - r < 0 ? 0 : x - r, x1 = x + r + 1 > wb->w ? wb->w : x + r + 1;
    const int y0 = y - r < 0 ? 0 : y - r, y1 = y + r + 1 > wb->h ? wb->h : y + r + 1;
    return (x1 - x0) * (y1 - y0);
}

void
mcp__window_end(mcp__window *wb)
{
    free(wb->cols);
    for (int i = 0; i < 3; i++) {
        free(wb->sums[i]);
        free(wb->halo[i]);
        free(wb->next[i]);
    }
    memset(wb, 0, sizeof *wb);
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
    const int w = values->width, h = values->height;
    const mcp_image *imgs[2] = {values, shape};
    mcp__window wb;
    if (mcp__window_begin(&wb, imgs, shape ? 2 : 1, radius)) return -1;
    for (int y0 = 0; y0 < h; y0 += wb.rows) {
        const int y1 = y0 + wb.rows < h ? y0 + wb.rows : h;
        if (mcp__window_band(&wb, y0, y1)) {
            mcp__window_end(&wb);
            return -1;
        }
#pragma omp parallel for schedule(static)
        for (int y = y0; y < y1; y++)
            for (int x = 0; x < w; x++) {
                const double *sv = mcp__window_at(&wb, 0, x, y);
                const int n = mcp__window_count(&wb, x, y);
                float *v = mcp_image_px(values, x, y);
                if (shape) {
                    const double *ss = mcp__window_at(&wb, 1, x, y);
                    const float *sh = mcp_image_px(shape, x, y);
                    for (int c = 0; c < 3; c++)
                        v[c] = ss[c] > 0 ? (float)(sh[c] * (fmax(sv[c], 0) / ss[c]))
                                         : (float)(fmax(sv[c], 0) / n);
                } else {
                    /* a running sum of non-negative values can come out a rounding
                       below zero beside large ones (a black region next to a
                       firefly): a variance must not */
                    for (int c = 0; c < 3; c++)
                        v[c] = (float)(fmax(sv[c], 0) / n);
                }
            }
    }
    mcp__window_end(&wb);
    return 0;
}
