/* probe_floor.c: the variance the probes are drawn from, raised to its local median
 * (docs/fidelity.md "The probe floor", "SURE and the U-Net on window").
 *
 * The probes' (Jε)² estimate Var[F] with ε ~ N(0, Σ̂), Σ̂ from the render's own
 * samples, and under skewed, heavy-tailed noise Σ̂ is not independent of that noise:
 * where a neighbourhood drew bright samples Σ̂ is high, and a denoiser that adapts to
 * the noise it sees (the U-Net) smooths more there, so the estimate sees too little of
 * Var[F] in the quiet pixels of a noisy neighbourhood and stops early (the held-out
 * `window` and `lamp`). Raising each value of Σ̂ to the median of its (2R + 1)² window,
 * where it is below it, gives those pixels their neighbourhood's level and leaves a
 * lone firefly's own value alone (a median ignores it; a window mean would spread it
 * over its neighbours and stop `cornell` late). The colour covariance is scaled with
 * the variances, so the channels' correlations stay those of Σ̂. SURE reweights the
 * probes back to Σ̂ (sure.c), so only the variance maps and s² carry the floor.
 *
 * A value whose Σ̂ is 0 (every sample equal, nearly always black: no light path found)
 * keeps it. The floor would give it its neighbours' scale, but the JVP linearises the
 * network at the value, and at 0 the U-Net's input transfer is 780 times steeper than
 * at a mid-grey (and the input is clamped there): on the held-out `fog`, whose 32-spp
 * blocks are 12% black, such probes put the estimated mean error at 19.3 against a true
 * 0.0047 (docs/fidelity.md "The probe floor"). */
#include "estimate.h"
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* the median of n values (the upper one for even n), sorting v in place */
static float
median(float *v, int n)
{
    for (int i = 1; i < n; i++) { /* insertion sort: n is 9 for the default radius */
        float x = v[i];
        int j = i - 1;
        for (; j >= 0 && v[j] > x; j--)
            v[j + 1] = v[j];
        v[j + 1] = x;
    }
    return v[n / 2];
}

static inline float
min2(float a, float b)
{
    return a < b ? a : b;
}

static inline float
max2(float a, float b)
{
    return a > b ? a : b;
}

static inline float
med3(float a, float b, float c)
{
    return max2(min2(a, b), min2(max2(a, b), c));
}

/* The median of the clipped (2 radius + 1)² window around (x, y), channel c. */
static float
window_median(const mcp_image *v, int radius, int x, int y, int c, float *window)
{
    const int w = v->width, h = v->height;
    const int y0 = y - radius < 0 ? 0 : y - radius,
              y1 = y + radius >= h ? h - 1 : y + radius,
              x0 = x - radius < 0 ? 0 : x - radius,
              x1 = x + radius >= w ? w - 1 : x + radius;
    int n = 0;
    for (int yy = y0; yy <= y1; yy++)
        for (int xx = x0; xx <= x1; xx++)
            window[n++] = mcp_image_px(v, xx, yy)[c];
    return median(window, n);
}

/* Row y's medians of channel c, radius 1, from the rows above and below: each column's
 * three values sorted once (lo, mid, hi), then a pixel's median of nine is the median
 * of the largest lo, the median mid and the smallest hi of its three columns (exact;
 * the columns are shared by three pixels). Interior pixels only. */
static void
row_medians3(const mcp_image *v, int y, int c, float *lo, float *mid, float *hi,
             float *out)
{
    const int w = v->width;
    for (int x = 0; x < w; x++) {
        const float a = mcp_image_px(v, x, y - 1)[c], b = mcp_image_px(v, x, y)[c],
                    d = mcp_image_px(v, x, y + 1)[c];
        lo[x] = min2(min2(a, b), d);
        hi[x] = max2(max2(a, b), d);
        mid[x] = med3(a, b, d);
    }
    for (int x = 1; x < w - 1; x++)
        out[x] = med3(max2(max2(lo[x - 1], lo[x]), lo[x + 1]),
                      med3(mid[x - 1], mid[x], mid[x + 1]),
                      min2(min2(hi[x - 1], hi[x]), hi[x + 1]));
}

int
mcp__probe_variance_floor(const mcp_dump *d, int radius, mcp_image **var, mcp_image **cov)
{
    *var = NULL;
    if (cov) *cov = NULL;
    if (radius < 0 || radius > MCP__PROBE_FLOOR_MAX)
        return mcp_error("estimate: probe_floor must be 0 to %d (got %d)",
                         MCP__PROBE_FLOOR_MAX, radius);
    if (mcp_image_copy(d->var_of_mean, var)) return -1;
    if (cov && d->cov_of_mean && mcp_image_copy(d->cov_of_mean, cov)) {
        mcp_image_free(*var);
        *var = NULL;
        return -1;
    }
    if (radius == 0) return 0;
    const mcp_image *v0 = d->var_of_mean;
    const int w = v0->width, h = v0->height;
    enum { SIDE = 2 * MCP__PROBE_FLOOR_MAX + 1 };
#ifdef _OPENMP
    const int threads = omp_get_max_threads();
#else
    const int threads = 1;
#endif
    /* per thread: a row of medians per channel and the columns' lo, mid, hi */
    float *rows = mcp_malloc((size_t)threads * 6 * (size_t)w * sizeof(float));
    if (!rows) {
        mcp_image_free(*var);
        if (cov) mcp_image_free(*cov), *cov = NULL;
        *var = NULL;
        return -1;
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
#ifdef _OPENMP
        float *med = rows + (size_t)omp_get_thread_num() * 6 * w;
#else
        float *med = rows;
#endif
        float window[SIDE * SIDE];
        const int fast = radius == 1 && y > 0 && y < h - 1 && w >= 3;
        if (fast)
            for (int c = 0; c < 3; c++)
                row_medians3(v0, y, c, med + 3 * (size_t)w, med + 4 * (size_t)w,
                             med + 5 * (size_t)w, med + (size_t)c * w);
        for (int x = 0; x < w; x++) {
            const float *own = mcp_image_px(v0, x, y);
            float *out = mcp_image_px(*var, x, y);
            const int interior = fast && x > 0 && x < w - 1;
            double scale[3];
            for (int c = 0; c < 3; c++) {
                const float m = interior ? med[(size_t)c * w + x]
                                         : window_median(v0, radius, x, y, c, window);
                /* a value of variance 0 (every sample equal: black, no path found)
                   keeps it */
                out[c] = own[c] > 0.0f && m > own[c] ? m : own[c];
                scale[c] = own[c] > 0.0f ? sqrt((double)out[c] / own[c]) : 0.0;
            }
            if (cov && *cov) { /* RG, RB, GB: the correlations kept */
                float *cv = mcp_image_px(*cov, x, y);
                cv[0] = (float)(cv[0] * scale[0] * scale[1]);
                cv[1] = (float)(cv[1] * scale[0] * scale[2]);
                cv[2] = (float)(cv[2] * scale[1] * scale[2]);
            }
        }
    }
    free(rows);
    return 0;
}
