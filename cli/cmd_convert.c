/* cmd_convert.c: `mcpost convert IN OUT` -- change format, pick channels (the library's
 * pick, shared with the `convert` job stage: jobs/stage_convert.c), change pixel type
 * and compression, or rewrite a render dump in another renderer's convention. */
#include "cli.h"

#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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
            mcp__free_words(channels, n_channels);
            rc = mcp__split_words(optarg, &channels, &n_channels);
            break;
        case 'H': wo.exr_pixel = MCP_EXR_HALF; break;
        case 'z': rc = mcp_exr_compression_from_name(optarg, &wo.compression); break;
        case 't':
            wo.exr_tiled = 1;
            rc = mcp__parse_int("--tiled", optarg, &wo.exr_tile_size);
            break;
        case 'l': wo.srgb_encode = 0; break;
        case 'd': dump_conv = optarg; break;
        case 's': spp = optarg; break;
        case 'h':
            fputs(usage, stdout);
            return 0;
        default:
            mcp__free_words(channels, n_channels);
            return mcp_cli_usage("convert", "bad option");
        }
        if (rc) {
            mcp__free_words(channels, n_channels);
            return mcp_cli_fail();
        }
    }
    if (argc - optind != 2) {
        mcp__free_words(channels, n_channels);
        return mcp_cli_usage("convert", "give one input and one output file");
    }
    const char *in = argv[optind], *out = argv[optind + 1];
    if (mcp_cli_output_is_not_input("convert", out, &in, 1)) {
        mcp__free_words(channels, n_channels);
        return mcp_cli_fail();
    }
    mcp_image *img = NULL, *picked = NULL;
    mcp_dump *dump = NULL;
    mcp_convention conv;
    if (dump_conv) {
        if (!mcp_convention_from_name(dump_conv, &conv) &&
            !mcp_cli_read_dump(in, spp, NULL, NULL, &dump) &&
            !mcp_dump_write(dump, out, conv, &wo))
            status = 0;
    } else if (!mcp_image_read(in, NULL, &img) &&
               !mcp__convert_pick_channels(img, channels, n_channels, out, &picked) &&
               !mcp_image_write(picked, out, &wo)) {
        status = 0;
    }
    if (status)
        mcp_cli_fail();
    mcp_dump_free(dump);
    mcp_image_free(picked);
    mcp_image_free(img);
    mcp__free_words(channels, n_channels);
    return status;
}

const mcp_command mcp_command_convert = {"convert", "convert images and render dumps "
                                                    "between formats and conventions",
                                         cmd_convert, 0};
