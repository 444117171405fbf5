/* cmd_convert.c: `mcpost convert IN OUT` and the `convert` job stage -- change format,
 * pick channels, change pixel type and compression, or rewrite a render dump in
 * another renderer's convention. */
#include "cli.h"

#include <mcpost/progress.h>
#include <mcpost/tonemap.h>

#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The channels of img named in `names`, as a new image. With no names: all channels,
 * except that an 8-bit or RGBE output of a many-channel file (a render dump) gets its
 * colour, which is what a person converting to PNG means. */
static int
pick_channels(const mcp_image *img, char **names, int count, const char *out_path,
              mcp_image **out)
{
    mcp_format f = mcp_format_from_path(out_path);
    int ldr = f == MCP_FORMAT_PNG || f == MCP_FORMAT_JPEG || f == MCP_FORMAT_HDR;
    if (count == 0 && ldr && img->channels != 1 && img->channels != 3 &&
        img->channels != 4) {
        int rgb[3];
        if (mcp_rgb_channels(img, rgb) == 0)
            return mcp_image_copy_channels(img, rgb, 3, out);
    }
    if (count == 0)
        return mcp_image_copy(img, out);
    int *idx = mcp_calloc((size_t)count, sizeof *idx);
    if (!idx)
        return -1;
    int rc = mcp_image_channels(img, (const char *const *)names, count, idx) ||
             mcp_image_copy_channels(img, idx, count, out);
    free(idx);
    return rc ? -1 : 0;
}

static const char usage[] =
    "usage: mcpost convert IN OUT [options]\n"
    "  Formats by extension: .exr .pfm (built in), .png .jpg .hdr .tif (OpenImageIO).\n"
    "  --channels A,B,C       keep these channels, in this order (default: all)\n"
    "  --half                 EXR: store half floats (default float)\n"
    "  --compression NAME     EXR: none, rle, zips, zip (default), piz, pxr24\n"
    "  --tiled N              EXR: tiles of NxN instead of scanlines\n"
    "  --linear               LDR outputs: write values as they are (default: sRGB-encode)\n"
    "  --dump CONVENTION      read IN as a render dump and write it in CONVENTION\n"
    "                         (pbrt, mitsuba, blender, mcpost); with --spp N for files\n"
    "                         that hold no sample count\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost convert samples/fixtures/cornell/cornell_reference.exr /tmp/cornell.png --channels R,G,B\n"
    "  mcpost convert samples/fixtures/cornell/series/cornell_spp0016.exr /tmp/cornell_mitsuba.exr --dump mitsuba\n"
    "  mcpost convert samples/fixtures/cornell/cornell_reference.exr /tmp/cornell_half.exr --half --compression piz\n";

static int
cmd_convert(int argc, char **argv)
{
    static const struct option longs[] = {
        {"channels", required_argument, 0, 'c'}, {"half", no_argument, 0, 'H'},
        {"compression", required_argument, 0, 'z'}, {"tiled", required_argument, 0, 't'},
        {"linear", no_argument, 0, 'l'},         {"dump", required_argument, 0, 'd'},
        {"spp", required_argument, 0, 's'},      {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    mcp_write_options wo = mcp_write_defaults();
    char **channels = NULL;
    int n_channels = 0, opt, status = 1;
    const char *dump_conv = NULL, *spp = NULL;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "h", longs, NULL)) != -1) {
        int rc = 0;
        switch (opt) {
        case 'c':
            mcp_cli_free_words(channels, n_channels);
            rc = mcp_cli_split(optarg, &channels, &n_channels);
            break;
        case 'H': wo.exr_pixel = MCP_EXR_HALF; break;
        case 'z': rc = mcp_exr_compression_from_name(optarg, &wo.compression); break;
        case 't':
            wo.exr_tiled = 1;
            rc = mcp_cli_int("--tiled", optarg, &wo.exr_tile_size);
            break;
        case 'l': wo.srgb_encode = 0; break;
        case 'd': dump_conv = optarg; break;
        case 's': spp = optarg; break;
        case 'h': fputs(usage, stdout); return 0;
        default: mcp_cli_free_words(channels, n_channels); return mcp_cli_usage("convert", "bad option");
        }
        if (rc) {
            mcp_cli_free_words(channels, n_channels);
            return mcp_cli_fail();
        }
    }
    if (argc - optind != 2) {
        mcp_cli_free_words(channels, n_channels);
        return mcp_cli_usage("convert", "give one input and one output file");
    }
    const char *in = argv[optind], *out = argv[optind + 1];
    mcp_image *img = NULL, *picked = NULL;
    mcp_dump *dump = NULL;
    mcp_convention conv;
    if (dump_conv) {
        if (!mcp_convention_from_name(dump_conv, &conv) &&
            !mcp_cli_read_dump(in, spp, NULL, NULL, &dump) &&
            !mcp_dump_write(dump, out, conv, &wo))
            status = 0;
    } else if (!mcp_image_read(in, NULL, &img) &&
               !pick_channels(img, channels, n_channels, out, &picked) &&
               !mcp_image_write(picked, out, &wo)) {
        status = 0;
    }
    if (status)
        mcp_cli_fail();
    mcp_dump_free(dump);
    mcp_image_free(picked);
    mcp_image_free(img);
    mcp_cli_free_words(channels, n_channels);
    return status;
}

const mcp_command mcp_command_convert = {"convert", "convert images and render dumps "
                                                    "between formats and conventions",
                                         cmd_convert};

/* ---- the job stage ---- */

static const char *const convert_keys[] = {"input", "output", "channels", "pixel",
                                           "compression", NULL};

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): the output file's name and how to write it, and the
 * channels to keep (names borrowed from the settings; free `names`). */
typedef struct convert_plan {
    const char *out;
    mcp_write_options wo;
    const char **names;
    int count;
} convert_plan;

static int
parse_convert(mcp_job *job, const mcp_node *settings, convert_plan *pl)
{
    const mcp_node *out_node = NULL, *chan = mcp_node_get(settings, "channels");
    const char *pixel = NULL, *comp = NULL;
    memset(pl, 0, sizeof *pl);
    pl->wo = mcp_write_defaults();
    if (mcp_job_check_input(job, settings, "input", MCP_JOB_IMAGE) ||
        mcp_node_require(settings, "output", "stage 'convert'", &out_node) ||
        mcp_node_string(out_node, "output", &pl->out) ||
        mcp_node_opt_string(settings, "pixel", &pixel) ||
        mcp_node_opt_string(settings, "compression", &comp))
        return -1;
    if (mcp_format_from_path(pl->out) == MCP_FORMAT_UNKNOWN)
        return mcp_node_error(out_node, "output: unknown image format '%s'", pl->out);
    if (pixel && strcmp(pixel, "half") && strcmp(pixel, "float"))
        return mcp_node_error(mcp_node_get(settings, "pixel"),
                              "pixel must be half or float (got '%s')", pixel);
    if (pixel && !strcmp(pixel, "half"))
        pl->wo.exr_pixel = MCP_EXR_HALF;
    if (comp && mcp_exr_compression_from_name(comp, &pl->wo.compression))
        return mcp_node_error(mcp_node_get(settings, "compression"), "%s",
                              mcp_error_message());
    if (chan) {
        if (chan->kind != MCP_NODE_SEQ || chan->count == 0)
            return mcp_node_error(chan, "channels must be a list of channel names");
        if (!(pl->names = mcp_calloc((size_t)chan->count, sizeof *pl->names)))
            return -1;
        pl->count = chan->count;
        for (int i = 0; i < pl->count; i++)
            if (mcp_node_string(chan->items[i], "channels", &pl->names[i])) {
                free(pl->names);
                pl->names = NULL;
                return -1;
            }
    }
    return 0;
}

static int
check_convert(mcp_job *job, const mcp_node *settings)
{
    convert_plan pl;
    int rc = parse_convert(job, settings, &pl);
    free(pl.names);
    return rc;
}

static int
stage_convert(mcp_job *job, const mcp_node *settings)
{
    const mcp_image *img = NULL;
    const mcp_node *chan = mcp_node_get(settings, "channels");
    convert_plan pl;
    if (parse_convert(job, settings, &pl))
        return -1;
    if (mcp_job_image(job, settings, "input", &img)) {
        free(pl.names);
        return -1;
    }
    const char *out = pl.out;
    const char **names = pl.names;
    int count = pl.count;
    mcp_write_options wo = pl.wo;
    char path[4096];
    mcp_image *picked = NULL;
    int rc = mcp_job_output_path(job, out, path, sizeof path) ||
             pick_channels(img, (char **)names, count, path, &picked) ||
             mcp_image_write(picked, path, &wo);
    free(names);
    mcp_image_free(picked);
    if (rc)
        return chan ? mcp_node_error(chan, "%s", mcp_error_message()) : -1;
    cJSON *section = mcp_report_section(mcp_job_report(job), "convert", out);
    if (!section || mcp_report_add_image(section, out, out))
        return -1;
    mcp_note("wrote %s", path);
    return 0;
}

const mcp_stage mcp_stage_convert = {"convert", "write an input in another format, with "
                                                "chosen channels",
                                     convert_keys, stage_convert, check_convert};
