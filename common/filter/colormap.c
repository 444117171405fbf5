/* colormap.c: false colour for one channel as 8-bit RGB (docs/mathematics.md §4.11: the
 * blue-noise spectra; FLIP: error maps and the viridis exposure map).
 *
 * Values are scaled so lo -> level 0 and hi -> level 255 (rounded, clamped; NaN -> 0),
 * then looked up in the 256-entry table of OpenCV's cv::applyColorMap (via
 * cv_shim.cpp, which also turns OpenCV's BGR into RGB). GRAY is the level itself on
 * all three channels. */
#include "internal.h"

#include "cv_shim.h"

#include <math.h>
#include <string.h>

#define ERR_CAP 256

static const struct {
    const char *name;
    mcp_colormap map;
    int cv_map; /* -1: not an OpenCV map */
} colormaps[] = {
    {"viridis", MCP_COLORMAP_VIRIDIS, MCP__CV_COLORMAP_VIRIDIS},
    {"magma", MCP_COLORMAP_MAGMA, MCP__CV_COLORMAP_MAGMA},
    {"inferno", MCP_COLORMAP_INFERNO, MCP__CV_COLORMAP_INFERNO},
    {"turbo", MCP_COLORMAP_TURBO, MCP__CV_COLORMAP_TURBO},
    {"gray", MCP_COLORMAP_GRAY, -1},
};

#define N_COLORMAPS ((int)(sizeof colormaps / sizeof colormaps[0]))

/* The 8-bit level of v: lo -> 0, hi -> top (scale = top / (hi - lo)), rounded to
 * nearest, clamped; NaN -> 0. */
static unsigned char
level_of(double v, double lo, double scale, int top)
{
    double t = (v - lo) * scale;
    if (!(t > 0)) /* also NaN */
        return 0;
    if (t >= top) return (unsigned char)top;
    return (unsigned char)(t + 0.5);
}

/* in mcp_colormap's order */
static const char *const colormap_names[] = {"viridis", "magma", "inferno", "turbo",
                                             "gray"};
const mcp_wordlist mcp_colormap_words = {"colour map", colormap_names, 5};

int
mcp_colormap_from_name(const char *name, mcp_colormap *map)
{
    return mcp_wordlist_find(&mcp_colormap_words, name, (int *)map);
}

const char *
mcp_colormap_name(mcp_colormap map)
{
    for (int i = 0; i < N_COLORMAPS; i++)
        if (colormaps[i].map == map) return colormaps[i].name;
    return NULL;
}

int
mcp_colormap_apply(const mcp_image *img, int channel, double lo, double hi,
                   mcp_colormap map, unsigned char *rgb8)
{
    return mcp__colormap_apply_levels(img, channel, lo, hi, map, 256, rgb8);
}

int
mcp__colormap_apply_levels(const mcp_image *img, int channel, double lo, double hi,
                           mcp_colormap map, int levels, unsigned char *rgb8)
{
    const char *op = "colormap";
    int which = -1;
    for (int i = 0; i < N_COLORMAPS; i++)
        if (colormaps[i].map == map) which = i;
    if (which < 0)
        return mcp_error("%s: %s: unknown colour map %d", img->source, op, (int)map);
    if (!rgb8) return mcp_error("%s: %s: no output buffer", img->source, op);
    if (channel < 0 || channel >= img->channels)
        return mcp_error("%s: %s: channel %d outside its %d channels", img->source, op,
                         channel, img->channels);
    if (!isfinite(lo) || !isfinite(hi) || !(lo < hi))
        return mcp_error("%s: %s: need finite lo < hi (got lo %g, hi %g)", img->source,
                         op, lo, hi);
    if (levels < 2 || levels > 256)
        return mcp_error("%s: %s: levels must be in [2, 256] (got %d)", img->source, op,
                         levels);
    const int top = levels - 1;
    double scale = top / (hi - lo);
    if (!isfinite(hi - lo) || !isfinite(scale))
        return mcp_error("%s: %s: range lo %g to hi %g is too narrow or too wide",
                         img->source, op, lo, hi);

    unsigned char lut[256 * 3];
    if (colormaps[which].cv_map < 0) {
        for (int i = 0; i < 256; i++)
            memset(lut + 3 * i, i, 3);
    } else {
        char err[ERR_CAP];
        if (mcp__cv_colormap_lut(colormaps[which].cv_map, lut, err, sizeof err))
            return mcp_error("%s: %s", img->source, err);
    }

    int w = img->width, h = img->height;
#pragma omp parallel for if ((size_t)w * h >= (1 << 16))
    for (int y = 0; y < h; y++) {
        unsigned char *d = rgb8 + (size_t)y * w * 3;
        for (int x = 0; x < w; x++) {
            int l = level_of(mcp_image_px(img, x, y)[channel], lo, scale, top);
            memcpy(d + (size_t)x * 3, lut + 3 * l, 3);
        }
    }
    return 0;
}
