/* stages.c: the job-stage table. A module adds its stage here, one line. */
#include "internal.h"

#include <string.h>

extern const mcp_stage mcp_stage_info, mcp_stage_convert;
extern const mcp_stage mcp_stage_metrics;

extern const mcp_stage mcp_stage_perceptual;
extern const mcp_stage mcp_stage_estimate;
extern const mcp_stage mcp_stage_blend;
extern const mcp_stage mcp_stage_adaptive;
static const mcp_stage *const stages[] = {
    &mcp_stage_info,
    &mcp_stage_convert,
    &mcp_stage_metrics,
    &mcp_stage_perceptual,
    &mcp_stage_estimate,
    &mcp_stage_blend,
    &mcp_stage_adaptive,
    NULL,
};

const mcp_stage *const *
mcp_job_stages(void)
{
    return stages;
}

const mcp_stage *
mcp_job_stage_find(const char *name)
{
    for (const mcp_stage *const *s = stages; name && *s; s++)
        if (!strcmp((*s)->name, name))
            return *s;
    return NULL;
}
