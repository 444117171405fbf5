/* denoise_stream.c: `mcpost denoise DUMP` with the U-Net on a dump too large to hold
 * whole beside the network (issue 31: 8K within 2 GB; docs/denoisers.md, "Images
 * larger than memory"): the dump's colour, albedo and normal are read in bands of rows
 * (common/dump's mcp__dump_rows), each band denoised (unet_bands.c) and written at once
 * into the output EXR (common/io's mcp__exr_band_file: under a temporary name renamed
 * when every row is written and removed on failure, as mcp_image_write does). The file
 * holds the pixels and header attributes the whole run writes. */
#include "internal.h"
#include "unet_internal.h"
#include "../common/dump/internal.h"
#include "../common/io/internal.h"
#include "../jobs/internal.h"

#include <mcpost/imageio.h>

#include <stdlib.h>

typedef struct {
    mcp__dump_rows *in;
    mcp__exr_band_file out;
} stream_io;

static int
read_rows(void *ctx, int y0, int y1, mcp_image **color, mcp_image **albedo,
          mcp_image **normal)
{
    const stream_io *io = ctx;
    mcp_image *parts[3];
    if (mcp__dump_rows_read(io->in, y0, y1, parts)) return -1;
    *color = parts[0];
    *albedo = parts[1];
    *normal = parts[2];
    return 0;
}

static int
write_rows(void *ctx, const mcp_image *rows, int y0)
{
    stream_io *io = ctx;
    return mcp__exr_band_file_rows(&io->out, rows, y0);
}

int
mcp__denoise_dump_streamed(const mcp_denoiser *den, const mcp_dump_spec *spec,
                           const char *out_path, int *done)
{
    *done = 0;
    double input_scale = 0;
    int tile = 0;
    const mcp_denoiser *unet = mcp__default_unet(den);
    const mcp__unet *net = mcp__unet_of(unet ? unet : den, &input_scale, &tile);
    if (!net || mcp_format_from_path(out_path) != MCP_FORMAT_EXR) return 0;
    mcp__dump_rows *in = NULL;
    /* what cannot be opened here is read whole, which says what is wrong with it */
    if (mcp__dump_rows_open(spec, &in) || !in) {
        mcp_error_clear();
        return 0;
    }
    int W, H, has_albedo, has_normal;
    mcp__dump_rows_size(in, &W, &H, &has_albedo, &has_normal);
    mcp__unet_bands plan;
    /* a default denoiser without the features runs nlm, whole */
    if ((net->ic >= 6 && !has_albedo) || (net->ic >= 9 && !has_normal) ||
        mcp__unet_bands_plan(net, W, H,
                             mcp__dump_rows_whole_bytes(in) + 12.0 * W * (double)H, tile,
                             &plan) ||
        !plan.band_rows) {
        /* a plan that fails is the whole run's to report, in its own words */
        mcp_error_clear();
        mcp__dump_rows_close(in);
        return 0;
    }
    *done = 1;
    mcp__unmap_freed_blocks();
    /* the output's header: the dump's attributes and the denoiser's name, as the whole
       run writes them (cli/cmd_denoise.c) */
    mcp_attrs attrs = {0};
    const mcp_write_options opt = mcp_write_defaults();
    stream_io io = {.in = in};
    int rc = mcp_attrs_copy(&mcp__dump_rows_dump(in)->attrs, &attrs) ||
             mcp_attrs_set_string(&attrs, "mcpost.denoiser", den->name) ||
             mcp__exr_band_file_begin(&io.out, out_path, W, H, &opt);
    if (!rc) {
        io.out.attrs = &attrs;
        const mcp__unet_band_io band_io = {&io, read_rows, write_rows};
        rc = mcp__exr_band_file_end(
            &io.out, mcp__unet_bands_run(net, input_scale, W, H, &plan, &band_io) != 0);
    }
    mcp_attrs_clear(&attrs);
    mcp__dump_rows_close(in);
    return rc ? -1 : 0;
}
