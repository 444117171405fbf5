/* op_convert.c: the options of `convert` (docs/formats.md), once for the command line
 * and the job stage (options.h). */
#include "internal.h"

#include <stddef.h>

#define S mcp_convert_settings

static const mcp_option convert_options[] = {
    {.name = "input",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, input),
     .doc = "the image to write (the command line: IN)"},
    {.name = "output",
     .type = MCP_OPT_TEXT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, output),
     .meta = "FILE",
     .doc = "the file to write, in the job's output; its extension picks the format "
            "(the command line: OUT)"},
    {.name = "channels",
     .type = MCP_OPT_TEXTS,
     .where = MCP_OPT_CLI | MCP_OPT_JOB,
     .offset = offsetof(S, channels),
     .count_offset = offsetof(S, n_channels),
     .max_count = 64,
     .meta = "A,B,C",
     .doc = "keep these channels, in this order (a job: a list) [all; R, G, B (and A) "
            "for PNG, JPEG, HDR and PFM]"},
    {.name = "pixel",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI | MCP_OPT_JOB,
     .offset = offsetof(S, wo.exr_pixel),
     .meta = "TYPE",
     .def = "float",
     .doc = "EXR: the pixel type",
     .words = &mcp_exr_pixel_words},
    {.name = "half",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, half),
     .def = "false",
     .doc = "EXR: store half floats (pixel half)"},
    {.name = "compression",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI | MCP_OPT_JOB,
     .offset = offsetof(S, wo.compression),
     .meta = "NAME",
     .def = "zip",
     .doc = "EXR: the compression",
     .words = &mcp_exr_compression_words},
    {.name = "tiled",
     .type = MCP_OPT_INT,
     .where = MCP_OPT_CLI | MCP_OPT_JOB,
     .offset = offsetof(S, tiled),
     .meta = "N",
     .def = "0",
     .doc = "EXR: tiles of N x N instead of scanlines (0: scanlines)",
     .hi = 65536,
     .bounds = MCP_OPT_LO | MCP_OPT_HI},
    {.name = "linear",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_CLI | MCP_OPT_JOB,
     .offset = offsetof(S, linear),
     .def = "false",
     .doc = "LDR outputs: write values as they are (else sRGB-encoded)"},
    {.name = "dump",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, dump),
     .meta = "CONVENTION",
     .doc = "read IN as a render dump and write it in this convention",
     .words = &mcp_convention_words},
    {.name = "spp",
     .type = MCP_OPT_TEXT,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spp),
     .meta = "N",
     .doc = "with --dump: the sample count of files that hold none"},
    {0}};

static void
convert_defaults(void *p)
{
    S *s = p;
    s->wo = mcp_write_defaults();
}

static int
convert_finish(void *p)
{
    S *s = p;
    if (s->half) s->wo.exr_pixel = MCP_EXR_HALF;
    s->wo.exr_tiled = s->tiled > 0;
    if (s->tiled > 0) s->wo.exr_tile_size = s->tiled;
    s->wo.srgb_encode = !s->linear;
    return 0;
}

const mcp_operation mcp__op_convert = {
    .name = "convert",
    .summary = "convert images and render dumps between formats and conventions",
    .options = convert_options,
    .size = sizeof(S),
    .defaults = convert_defaults,
    .finish = convert_finish,
    .given_offset = offsetof(S, given),
    .shared = MCP_SHARED_QUIET,
};

const mcp_operation *
mcp_operation_convert(void)
{
    return &mcp__op_convert;
}
