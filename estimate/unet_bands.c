/* unet_bands.c: OIDN's U-Net over an image that is read and written in bands of rows,
 * so that neither the inputs nor the output are ever held whole (issue 31: an 8K
 * `mcpost denoise` within 2 GB; docs/denoisers.md, "Images larger than memory").
 *
 * A band is output rows [y0, y1), y0 on a multiple of 64; it is computed from input
 * rows [y0 - 352 rounded down to 64, y1 + 352) within the image, in tiles as wide as
 * the plan says and as tall as that crop (unet.c's mcp__unet_run_crop). Those are the
 * margins of unet.c's tiles (mcp__unet_tile_margins), which give the whole image's bits:
 * every pixel of the band sees what it sees in the whole image (docs/denoisers.md,
 * "tiles give the same bits"), so the bands do too. The autoexposure is a pre-pass over
 * the colour in bands (mcp__unet_exposure_*: the same sums in the same order as on the
 * whole image), and every band runs at that one scale.
 *
 * The plan picks the band height and the tiles' width that compute the fewest pixels
 * (the overlap is computed twice) among those whose inputs, output and network fit in
 * the memory bound (max_memory_mb, 2048 MB by default), which here bounds the whole
 * process, images included. */
#include "unet_internal.h"
#include "internal.h"

#include <mcpost/progress.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* What a band holds besides the network, per pixel of its crop: colour, albedo and
 * normal as read (36 bytes) and the crop's result (12). The reader's buffers cover
 * whole EXR chunks (up to 32 rows on each side of the crop: BAND_READ_SLACK). */
#define BAND_BYTES_PER_PIXEL 48.0
#define BAND_READ_SLACK 64
/* What the process holds besides the images and the network: the weights, the
 * threads' stacks and scratch, the EXR codecs' buffers, the program itself (75 to 90 MB
 * resident between two bands of the 8K run, docs/denoisers.md). */
#define BAND_FIXED_BYTES (128.0 * 1048576.0)

/* The sum and the largest of the crops' extents when [0, n) is cut into runs of step
 * (run_tiled's geometry in x; the bands' in y). */
static void
crops_of(int n, int step, int overlap, int align, double *sum, int *largest)
{
    *sum = 0;
    *largest = 0;
    for (int a = 0; a < n; a += step) {
        int c0, c1;
        mcp__unet_crop_of(a, a + step < n ? a + step : n, n, overlap, align, &c0, &c1);
        *sum += c1 - c0;
        if (c1 - c0 > *largest) *largest = c1 - c0;
    }
}

/* The bytes a plan holds at its peak. */
static double
plan_bytes(int W, int crop_h, int crop_w)
{
    return BAND_FIXED_BYTES + BAND_BYTES_PER_PIXEL * W * (double)crop_h +
           36.0 * W * BAND_READ_SLACK + mcp__unet_batch_bytes(crop_w, crop_h, 1);
}

/* MCPOST_UNET_BAND_ROWS: the tests' way to force bands of that many rows (rounded up to
 * a multiple of 64) on images that would run whole, or with "whole" the whole-image
 * run on images that would run in bands (-1). 0 when unset. */
static int
forced_band_rows(void)
{
    const char *env = getenv("MCPOST_UNET_BAND_ROWS");
    if (!env || !*env) return 0;
    if (strcmp(env, "whole") == 0) return -1;
    int rows = atoi(env);
    return rows > 0 ? (rows + 63) / 64 * 64 : 0;
}

int
mcp__unet_bands_plan(const mcp__unet *net, int W, int H, double whole_bytes, int tile,
                     mcp__unet_bands *plan)
{
    memset(plan, 0, sizeof *plan);
    const double bound = mcp__unet_memory_bound(net), have = mcp__unet_memory_available();
    const double budget = have > 0 && have < bound ? have : bound;
    plan->budget = budget;
    const int forced = forced_band_rows();
    if (forced < 0) return 0;
    int overlap, align;
    mcp__unet_tile_margins(net, &overlap, &align);
    /* the whole image as before: its images, and its network whole or in the tiles
       mcp__unet_run_tiled picks */
    int whole_tile =
        tile ? tile : mcp__unet_auto_tile(net, W, H, mcp__unet_tile_limit(net, have));
    if (!forced && whole_tile > 0) {
        const int m = whole_tile >= W && whole_tile >= H ? 0 : 2 * overlap + align;
        const int cw = whole_tile + m < W ? whole_tile + m : W,
                  ch = whole_tile + m < H ? whole_tile + m : H;
        plan->bytes = BAND_FIXED_BYTES + whole_bytes + mcp__unet_batch_bytes(cw, ch, 1);
        if (plan->bytes <= budget) return 0;
    }
    double best = HUGE_VAL, least = HUGE_VAL;
    mcp__unet_bands smallest = {0};
    const int rows_hi = forced ? forced : (H + 63) / 64 * 64;
    for (int rows = forced ? forced : 64; rows <= rows_hi; rows += 64) {
        double sum_h;
        int crop_h;
        crops_of(H, rows, overlap, align, &sum_h, &crop_h);
        const int tw_hi = tile ? tile : (W + 15) / 16 * 16;
        for (int tw = tile ? tile : 16; tw <= tw_hi; tw += 16) {
            double sum_w;
            int crop_w;
            crops_of(W, tw, overlap, align, &sum_w, &crop_w);
            const double bytes = plan_bytes(W, crop_h, crop_w);
            if (bytes < least) {
                least = bytes;
                smallest = (mcp__unet_bands){rows, tw, bytes, budget};
            }
            /* the fewest pixels computed; among equals, the fewest bands and tiles */
            if (bytes > budget || sum_h * sum_w >= best) continue;
            best = sum_h * sum_w;
            *plan = (mcp__unet_bands){rows, tw, bytes, budget};
        }
    }
    /* forced bands that do not fit: the smallest tiles (the tests' small images) */
    if (!plan->band_rows && forced) *plan = smallest;
    if (!plan->band_rows)
        return mcp_error("unet: a %dx%d image does not fit even in bands of 64 rows "
                         "within %.0f MB (max_memory_mb, or what is available)",
                         W, H, budget / 1048576.0);
    return 0;
}

/* The pre-pass: every row read once, top to bottom, in bands of `rows`: the reader
 * checks the values as a whole read would, and the colour goes to the autoexposure. */
static int
prepass(const mcp__unet *net, int W, int H, int rows, const mcp__unet_band_io *io,
        int exposure, double *scale)
{
    mcp__unet_exposure e;
    if (exposure && mcp__unet_exposure_begin(&e, W, H, net->v2)) return -1;
    int rc = 0;
    for (int y0 = 0; y0 < H && !rc; y0 += rows) {
        const int y1 = y0 + rows < H ? y0 + rows : H;
        mcp_image *c = NULL, *a = NULL, *n = NULL;
        rc = io->read(io->ctx, y0, y1, &c, &a, &n);
        if (!rc && exposure) mcp__unet_exposure_rows(&e, c);
        mcp_image_free(c), mcp_image_free(a), mcp_image_free(n);
    }
    if (exposure) {
        const double s = mcp__unet_exposure_end(&e);
        if (!rc) *scale = s;
    }
    return rc;
}

int
mcp__unet_bands_run(const mcp__unet *net, double input_scale, int W, int H,
                    const mcp__unet_bands *plan, const mcp__unet_band_io *io)
{
    const int rows = plan->band_rows;
    if (rows < 64 || rows % 64 || plan->tile_w < 16 || plan->tile_w % 16)
        return mcp_error("unet: bad band plan (%d rows, tiles of %d)", rows,
                         plan->tile_w);
    int overlap, align;
    mcp__unet_tile_margins(net, &overlap, &align);
    /* the pre-pass reads in bands as tall as the largest crop, which the plan holds */
    double sum_h;
    int crop_h;
    crops_of(H, rows, overlap, align, &sum_h, &crop_h);
    double scale = input_scale;
    if (prepass(net, W, H, crop_h, io, !(input_scale > 0), &scale)) return -1;
    if (!(scale > 0 && scale < 1e30)) return mcp_error("unet: bad input scale %g", scale);
    mcp_progress bar;
    const long bands = (H + rows - 1) / rows,
               tiles = (W + plan->tile_w - 1) / plan->tile_w;
    char label[64];
    snprintf(label, sizeof label, "U-Net in %ld bands", bands);
    const int shown = mcp__unet_progress_begin(
        &bar, label, (long)MCP__UNET_NCONV * bands * tiles, W, H);
    int rc = 0;
    for (int y0 = 0; y0 < H && !rc; y0 += rows) {
        const int y1 = y0 + rows < H ? y0 + rows : H;
        int c0, c1;
        mcp__unet_crop_of(y0, y1, H, overlap, align, &c0, &c1);
        mcp_image *c = NULL, *a = NULL, *n = NULL, *res = NULL, *keep = NULL;
        rc = io->read(io->ctx, c0, c1, &c, &a, &n) ||
             mcp__unet_run_crop(net, c, net->ic >= 6 ? a : NULL, net->ic >= 9 ? n : NULL,
                                scale, plan->tile_w, &res);
        /* the inputs go before the result is written: the writer's buffers come on top */
        mcp_image_free(c), mcp_image_free(a), mcp_image_free(n);
        rc = rc || mcp__rows_view(res, y0 - c0, y1 - c0, &keep) ||
             io->write(io->ctx, keep, y0);
        mcp_image_free(keep);
        mcp_image_free(res);
    }
    mcp__unet_progress_finish(&bar, shown, rc);
    return rc;
}
