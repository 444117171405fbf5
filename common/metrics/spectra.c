/* spectra.c: tiled power spectra of an error image and its low-frequency energy
 * fraction (docs/mathematics.md §4.11). The DFTs come from
 * mcp_tile_power_spectra (filter.h), which centres the zero frequency at n/2. */
#include <mcpost/spectra.h>
#include <mcpost/filter.h>
#include <mcpost/metrics.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "internal.h"

mcp_spectra_options
mcp_spectra_defaults(void)
{
    return (mcp_spectra_options){
        .tile_size = 32, .tone_map = MCP_TONEMAP_CLAMP, .cutoff = 0.25};
}

/* Signed frequency index of shifted position p in an n-point spectrum. */
static int
freq(int p, int n)
{
    return p - n / 2;
}

/* 1 when bin (u, v) of an n x n tile lies strictly below cutoff x Nyquist. Radial
 * frequency in cycles per pixel is |(u, v)| / n and Nyquist is 1/2. */
static int
below(int u, int v, int n, double cutoff)
{
    double r = sqrt((double)u * u + (double)v * v) / n;
    return r < cutoff * 0.5;
}

int
mcp_spectra_analyse(const mcp_image *error, const mcp_spectra_options *opt,
                    mcp_spectra_result *res, mcp_image **picture)
{
    mcp_spectra_options d = mcp_spectra_defaults();
    if (!opt) opt = &d;
    if (picture) *picture = NULL;
    const int t = opt->tile_size;
    if (t < 4 || t > 4096)
        return mcp_error("spectra: tile_size must be in [4, 4096] (got %d)", t);
    if (!(opt->cutoff > 0.0 && opt->cutoff <= 1.0))
        return mcp_error("spectra: cutoff must be in (0, 1] (got %g)", opt->cutoff);
    if (error->width < t || error->height < t)
        return mcp_error("%s: spectra: image %dx%d is smaller than one %dx%d tile",
                         error->source ? error->source : "image", error->width,
                         error->height, t, t);
    mcp_image *sum = NULL, *one = NULL;
    int rc = -1;
    for (int c = 0; c < error->channels; c++) {
        if (mcp_tile_power_spectra(error, c, t, c == 0 ? &sum : &one)) goto done;
        if (c > 0) {
            size_t n = (size_t)sum->width * sum->height;
            for (size_t i = 0; i < n; i++)
                sum->data[i] += one->data[i];
            mcp_image_free(one);
            one = NULL;
        }
    }
    const int tx = sum->width / t, ty = sum->height / t, w = sum->width;
    double low = 0.0, all = 0.0;
    long n_low = 0;
    for (int v = 0; v < t; v++)
        for (int u = 0; u < t; u++)
            if ((freq(u, t) || freq(v, t)) &&
                below(freq(u, t), freq(v, t), t, opt->cutoff))
                n_low++;
    for (int j = 0; j < ty; j++)
        for (int i = 0; i < tx; i++) {
            double tile_low = 0.0, tile_all = 0.0, vmax = 0.0;
            for (int v = 0; v < t; v++)
                for (int u = 0; u < t; u++) {
                    float *p = sum->data + (size_t)(j * t + v) * w + (size_t)i * t + u;
                    int fu = freq(u, t), fv = freq(v, t);
                    if (!fu && !fv) {
                        *p = 0.0f; /* the tile's mean (bias): not shown, not counted */
                        continue;
                    }
                    double e = *p;
                    tile_all += e;
                    if (below(fu, fv, t, opt->cutoff)) tile_low += e;
                    double lv = log1p(sqrt(e));
                    *p = (float)lv;
                    vmax = lv > vmax ? lv : vmax;
                }
            low += tile_low;
            all += tile_all;
            /* c ln(1 + |eps^|) with c = 1 / the tile's largest value */
            for (int v = 0; v < t; v++) {
                float *row = sum->data + (size_t)(j * t + v) * w + (size_t)i * t;
                for (int u = 0; u < t; u++)
                    row[u] = vmax > 0.0 ? (float)(row[u] / vmax) : 0.0f;
            }
        }
    if (res) {
        memset(res, 0, sizeof *res);
        res->low_fraction = all > 0.0 ? low / all : 0.0;
        res->white_fraction = (double)n_low / ((double)t * t - 1.0);
        res->energy = all / ((double)tx * ty * t * t * t * t);
        res->tiles_x = tx;
        res->tiles_y = ty;
        res->tile_size = t;
    }
    if (picture) {
        if (mcp_image_set_channel_name(sum, 0, "spectrum") ||
            mcp_image_set_source(sum, "error spectra"))
            goto done;
        *picture = sum;
        sum = NULL;
    }
    rc = 0;
done:
    mcp_image_free(one);
    mcp_image_free(sum);
    return rc;
}

int
mcp_spectra_blue_noise(const mcp_image *test, const mcp_image *ref,
                       const mcp_spectra_options *opt, mcp_spectra_result *res,
                       mcp_image **picture)
{
    mcp_spectra_options d = mcp_spectra_defaults();
    if (!opt) opt = &d;
    if (picture) *picture = NULL;
    int it[3], ir[3];
    if ((unsigned)opt->tone_map > MCP_TONEMAP_REINHARD)
        return mcp_error("spectra: unknown tone map %d", (int)opt->tone_map);
    if (mcp_metrics_check_pair(test, ref, it, ir)) return -1;
    mcp_image *e = NULL;
    if (mcp_image_new(test->width, test->height, 3, (const char *const[]){"R", "G", "B"},
                      &e))
        return -1;
    for (int y = 0; y < test->height; y++)
        for (int x = 0; x < test->width; x++) {
            const float *pt = mcp_image_px(test, x, y), *pr = mcp_image_px(ref, x, y);
            float *q = mcp_image_px(e, x, y);
            for (int c = 0; c < 3; c++)
                q[c] = mcp_tonemap_value(opt->tone_map, pt[it[c]]) -
                       mcp_tonemap_value(opt->tone_map, pr[ir[c]]);
        }
    int rc = mcp_image_set_source(e, test->source ? test->source : "error")
                 ? -1
                 : mcp_spectra_analyse(e, opt, res, picture);
    mcp_image_free(e);
    return rc;
}
