/* op_info.c: the options of `info` (describe images and render dumps), once for the
 * command line and the job stage (options.h). */
#include "internal.h"

#include <stddef.h>

#define S mcp_info_settings

static const mcp_option info_options[] = {
    {.name = "input",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, input),
     .doc = "the input to describe (the command line: FILE...)"},
    {.name = "spp",
     .type = MCP_OPT_NUMBER,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spec.spp),
     .meta = "N",
     .doc = "the sample count of files that hold none (Mitsuba) [from the file] (a job: "
            "the input's)",
     .bounds = MCP_OPT_LO_OPEN},
    {.name = "convention",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spec.convention),
     .meta = "NAME",
     .def = "auto",
     .doc = "the render-dump convention (a job: the input's)",
     .words = &mcp_convention_words},
    {.name = "variance",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spec.variance),
     .meta = "KIND",
     .def = "default",
     .doc = "per-sample or of-mean: overrides what the convention says (a job: the "
            "input's)",
     .words = &mcp_variance_kind_words},
    {0}};

static void
info_defaults(void *p)
{
    S *s = p;
    s->spec = mcp_dump_spec_defaults();
}

const mcp_operation mcp__op_info = {
    .name = "info",
    .summary = "describe images and render dumps",
    .options = info_options,
    .size = sizeof(S),
    .defaults = info_defaults,
    .shared = MCP_SHARED_QUIET | MCP_SHARED_JSON | MCP_SHARED_THREADS,
};

const mcp_operation *
mcp_operation_info(void)
{
    return &mcp__op_info;
}
