/* op_denoise.c: the options of `denoise` (one denoiser alone, and its Jacobian-vector
 * product), for the command line and Python's denoise and jvp (options.h): the inputs
 * are files on the command line and arrays in Python (python/denoise.c), and the
 * denoiser's settings are its own table's (--denoiser-opt KEY=VALUE, KEY=VALUE). */
#include "internal.h"

#include <stddef.h>

#define S mcp_denoise_settings
#define TEXT_ROW(NAME, META, GROUP, DOC)                                                 \
    {                                                                                    \
        .name = #NAME, .type = MCP_OPT_TEXT, .where = MCP_OPT_CLI,                       \
        .offset = offsetof(S, NAME), .meta = META, .group = GROUP, .doc = DOC            \
    }
#define INPUT_ROW(NAME, META, GROUP, DOC)                                                \
    {                                                                                    \
        .name = #NAME, .type = MCP_OPT_INPUT, .where = MCP_OPT_CLI | MCP_OPT_PY,         \
        .offset = offsetof(S, NAME), .meta = META, .group = GROUP, .doc = DOC            \
    }
#define FLAG_ROW(NAME, GROUP, DOC)                                                       \
    {                                                                                    \
        .name = #NAME, .type = MCP_OPT_FLAG, .where = MCP_OPT_CLI,                       \
        .offset = offsetof(S, NAME), .def = "false", .group = GROUP, .doc = DOC          \
    }

static const mcp_option denoise_options[] = {
    {.name = "denoiser",
     .type = MCP_OPT_DENOISER,
     .where = MCP_OPT_CLI | MCP_OPT_PY,
     .meta = "NAME",
     .def = "default",
     .doc = "the denoiser (see --list): `default` is unet with the shipped weights, nlm "
            "for dumps without albedo and normal"},
    TEXT_ROW(
        tangent, "FILE", NULL,
        "also write J.T, the Jacobian-vector product of the denoiser at the input in "
        "direction T (channels R,G,B, or 3 channels), computed in the same pass"),
    TEXT_ROW(tangent_out, "FILE", NULL, "where J.T goes [<output stem>_jvp.exr]"),
    FLAG_ROW(list, NULL, "print the denoisers and their settings"),
    INPUT_ROW(color, "FILE", "Separate inputs instead of DUMP",
              "the colour (R,G,B channels, or exactly 3; Python: the first argument)"),
    INPUT_ROW(albedo, "FILE", "Separate inputs instead of DUMP",
              "the albedo (R,G,B, or exactly 3 channels)"),
    INPUT_ROW(normal, "FILE", "Separate inputs instead of DUMP",
              "the normal (X,Y,Z, or exactly 3 channels)"),
    INPUT_ROW(variance_of_mean, "FILE", "Separate inputs instead of DUMP",
              "the variance of the colour mean, R,G,B (Python: also variance=)"),
    FLAG_ROW(no_albedo, "Parts of the input", "ignore the input's albedo"),
    FLAG_ROW(no_normal, "Parts of the input", "ignore the input's normal"),
    FLAG_ROW(no_variance, "Parts of the input", "ignore the input's variance"),
    TEXT_ROW(spp, "N", "Reading DUMP", "the sample count, for files that hold none"),
    TEXT_ROW(convention, "NAME", "Reading DUMP",
             "pbrt, mitsuba, blender, mcpost or plain [auto]"),
    TEXT_ROW(variance, "KIND", "Reading DUMP", "per-sample or of-mean [per convention]"),
    {0}};

const mcp_operation mcp__op_denoise = {
    .name = "denoise",
    .summary = "run one denoiser (and its Jacobian-vector product) alone",
    .options = denoise_options,
    .size = sizeof(S),
    .shared = MCP_SHARED_QUIET | MCP_SHARED_OUTPUT | MCP_SHARED_THREADS,
    .output_doc = "the denoised image",
    .output_def = "<input stem>_<NAME>.exr, here",
};

const mcp_operation *
mcp_operation_denoise(void)
{
    return &mcp__op_denoise;
}
