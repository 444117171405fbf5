/* stages.c: the job-stage table. A module adds its stage here, one line. */
#include "internal.h"

#include <pthread.h>
#include <string.h>

extern const mcp_stage mcp_stage_info, mcp_stage_convert;
extern const mcp_stage mcp_stage_metrics;

extern const mcp_stage mcp_stage_perceptual;
extern const mcp_stage mcp_stage_estimate;
extern const mcp_stage mcp_stage_blend;
extern const mcp_stage mcp_stage_adaptive;
static const mcp_stage *const stages[] = {
    &mcp_stage_info,     &mcp_stage_convert, &mcp_stage_metrics,  &mcp_stage_perceptual,
    &mcp_stage_estimate, &mcp_stage_blend,   &mcp_stage_adaptive, NULL,
};

/* The keys of the stages that read their settings through an operation's table
 * (every stage_*.c): derived from the table, once, before the stage table is handed
 * out. */
extern const char *mcp__estimate_keys[MCP__OPTION_KEYS_MAX];
extern const char *mcp__blend_keys[MCP__OPTION_KEYS_MAX];
extern const char *mcp__adaptive_keys[MCP__OPTION_KEYS_MAX];
extern const char *mcp__info_keys[MCP__OPTION_KEYS_MAX];
extern const char *mcp__convert_keys[MCP__OPTION_KEYS_MAX];
extern const char *mcp__metrics_keys[MCP__OPTION_KEYS_MAX];
extern const char *mcp__perceptual_keys[MCP__OPTION_KEYS_MAX];
static const char *const stage_extras[] = {"title", NULL};

static void
fill_keys(void)
{
    mcp__op_job_keys(mcp_operation_estimate(), stage_extras, mcp__estimate_keys,
                     MCP__OPTION_KEYS_MAX);
    mcp__op_job_keys(mcp_operation_blend(), stage_extras, mcp__blend_keys,
                     MCP__OPTION_KEYS_MAX);
    mcp__op_job_keys(mcp_operation_adaptive(), stage_extras, mcp__adaptive_keys,
                     MCP__OPTION_KEYS_MAX);
    mcp__op_job_keys(mcp_operation_info(), stage_extras, mcp__info_keys,
                     MCP__OPTION_KEYS_MAX);
    mcp__op_job_keys(mcp_operation_convert(), stage_extras, mcp__convert_keys,
                     MCP__OPTION_KEYS_MAX);
    mcp__op_job_keys(mcp_operation_metrics(), stage_extras, mcp__metrics_keys,
                     MCP__OPTION_KEYS_MAX);
    mcp__op_job_keys(mcp_operation_perceptual(), stage_extras, mcp__perceptual_keys,
                     MCP__OPTION_KEYS_MAX);
}

const mcp_stage *const *
mcp_job_stages(void)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, fill_keys);
    return stages;
}

const mcp_stage *
mcp_job_stage_find(const char *name)
{
    for (const mcp_stage *const *s = mcp_job_stages(); name && *s; s++)
        if (!strcmp((*s)->name, name)) return *s;
    return NULL;
}
