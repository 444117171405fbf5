/* stages.c: the job-stage table. A module adds its stage here, one line. */
#include "cli.h"

extern const mcp_stage mcp_stage_info, mcp_stage_convert;
extern const mcp_stage mcp_stage_metrics;

const mcp_stage *const mcp_stages[] = {
    &mcp_stage_info,
    &mcp_stage_convert,
    &mcp_stage_metrics,
    NULL,
};
