/* stages.c: the job-stage table. A module adds its stage here, one line. */
#include "cli.h"

extern const mcp_stage mcp_stage_info, mcp_stage_convert;
extern const mcp_stage mcp_stage_metrics;

extern const mcp_stage mcp_stage_perceptual;
extern const mcp_stage mcp_stage_estimate;
extern const mcp_stage mcp_stage_blend;
extern const mcp_stage mcp_stage_adaptive;
const mcp_stage *const mcp_stages[] = {
    &mcp_stage_info,
    &mcp_stage_convert,
    &mcp_stage_metrics,
    &mcp_stage_perceptual,
    &mcp_stage_estimate,
    &mcp_stage_blend,
    &mcp_stage_adaptive,
    NULL,
};
