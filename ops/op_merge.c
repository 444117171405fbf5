/* op_merge.c: the options of `merge` (render dumps of one frame combined into one;
 * common/dump/replicates.c), for the command line (options.h). A job merges through its
 * replicates input, whose keys are merge: and pool: (docs/jobs.md). */
#include "internal.h"

#include <stddef.h>

#define S mcp_merge_settings

static const mcp_option merge_options[] = {
    {.name = "variance",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, mo.variance),
     .meta = "KIND",
     .def = "replicates",
     .doc = "replicates: the inputs are independent renders (other seeds), the variance "
            "from their spread with K-1 degrees of freedom (right for stratified "
            "samplers); pooled: the inputs are passes of one render, their per-sample "
            "variances combined exactly (a job: the replicates input's merge)",
     .words = &mcp_merge_variance_words},
    {.name = "pool",
     .type = MCP_OPT_INT,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, mo.pool_radius),
     .meta = "R",
     .def = "0",
     .doc = "pool the variance over (2R+1)^2 pixels (its pattern from the inputs' own "
            "per-sample variance where they have one)",
     .bounds = MCP_OPT_LO},
    {.name = "spp",
     .type = MCP_OPT_NUMBER,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spec.spp),
     .meta = "N",
     .group = "Reading dumps",
     .doc = "the sample count of inputs that hold none [from the file]",
     .bounds = MCP_OPT_LO_OPEN},
    {.name = "convention",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spec.convention),
     .meta = "NAME",
     .def = "auto",
     .group = "Reading dumps",
     .doc = "the inputs' render-dump convention",
     .words = &mcp_convention_words},
    {.name = "half",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, half),
     .def = "false",
     .doc = "store half floats"},
    {0}};

static void
merge_defaults(void *p)
{
    S *s = p;
    s->mo = mcp_merge_defaults();
    s->spec = mcp_dump_spec_defaults();
}

const mcp_operation mcp__op_merge = {
    .name = "merge",
    .summary = "combine renders of one frame into a dump (variance from replicates)",
    .options = merge_options,
    .size = sizeof(S),
    .defaults = merge_defaults,
    .shared = MCP_SHARED_QUIET | MCP_SHARED_OUTPUT | MCP_SHARED_THREADS,
    .output_doc =
        "the merged dump (mcpost convention, EXR); the header records the source: "
        "mcpost:varianceSource, :varianceDof, :replicates (required)",
};

const mcp_operation *
mcp_operation_merge(void)
{
    return &mcp__op_merge;
}
