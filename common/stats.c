/* stats.c: per-channel statistics (see stats.h). */
#include <mcpost/stats.h>

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
    if (!rows)
        return -1;
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
