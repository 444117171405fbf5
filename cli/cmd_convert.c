/* cmd_convert.c: `mcpost convert IN OUT` -- change format, pick channels (the library's
 * pick, shared with the `convert` job stage: jobs/stage_convert.c), change pixel type
 * and compression, or rewrite a render dump in another renderer's convention. The flags
 * are the convert table's (ops/op_convert.c), as the job stage's keys. */
#include "cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char head[] =
    "usage: mcpost convert IN OUT [options]\n"
    "  Formats by extension: .exr .pfm (built in), .png .jpg .hdr .tif (OpenImageIO).\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost convert samples/fixtures/cornell/cornell_reference.exr /tmp/cornell.png "
    "--channels R,G,B\n"
    "  mcpost convert samples/fixtures/cornell/series/cornell_spp0016.exr "
    "/tmp/cornell_mitsuba.exr --dump mitsuba\n"
    "  mcpost convert samples/fixtures/cornell/cornell_reference.exr "
    "/tmp/cornell_half.exr --half --compression piz\n";

static int
cmd_convert(int argc, char **argv)
{
    mcp_convert_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    const mcp_operation *op = mcp_operation_convert();
    char **channels = NULL;
    int n_channels = 0, first = 0, status = 1;
    int parsed = mcp_cli_parse(op, head, examples, argc, argv, &st, &sh, &df, &first);
    if (parsed >= 0) return parsed;
    if (argc - first != 2)
        return mcp_cli_usage("convert", "give one input and one output file");
    const char *in = argv[first], *out = argv[first + 1];
    if (mcp_cli_output_is_not_input("convert", out, &in, 1) ||
        mcp__convert_channel_names(&st, &channels, &n_channels))
        return mcp_cli_fail();
    mcp_image *img = NULL, *picked = NULL;
    mcp_dump *dump = NULL;
    mcp_dump_spec spec;
    const int as_dump = mcp_operation_given(op, mcp_operation_option(op, "dump"), &st);
    int streamed = 0;
    /* an EXR into an EXR a band of rows at a time (jobs/convert_stream.c), the others
       whole */
    if ((as_dump && mcp_cli_dump_spec(in, st.spp, NULL, NULL, &spec)) ||
        mcp__convert_streamed(in, out, channels, n_channels, as_dump ? &spec : NULL,
                              st.dump, &st.wo, &streamed)) {
        /* failed */
    } else if (streamed) {
        status = 0;
    } else if (as_dump) {
        if (!mcp_dump_load(&spec, &dump) && !mcp_dump_write(dump, out, st.dump, &st.wo))
            status = 0;
    } else if (!mcp_image_read(in, NULL, &img) &&
               !mcp__convert_pick_channels(img, channels, n_channels, out, &picked) &&
               !mcp_image_write(picked, out, &st.wo)) {
        status = 0;
    }
    if (status) mcp_cli_fail();
    mcp_dump_free(dump);
    mcp_image_free(picked);
    mcp_image_free(img);
    mcp__free_words(channels, n_channels);
    return status;
}

const mcp_command mcp_command_convert = {"convert",
                                         "convert images and render dumps "
                                         "between formats and conventions",
                                         cmd_convert, 1};
