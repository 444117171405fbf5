/* stage_denoiser.c: the denoiser of a job stage, from its `denoiser:` setting (a name,
 * or a map of a name and its keys), `default` when it has none. */
#include "internal.h"

int
mcp__stage_denoiser(mcp_job *job, const mcp_node *settings, mcp_denoiser **out)
{
    const mcp_node *given = mcp_node_get(settings, "denoiser");
    mcp_node fallback = {.kind = MCP_NODE_SCALAR,
                         .value = (char *)"default",
                         .line = settings->line,
                         .file = settings->file};
    char base[4096];
    /* relative paths in the settings (weights) resolve against the job file's folder */
    if (mcp_job_resolve(job, ".", base, sizeof base)) return -1;
    return mcp_denoiser_create(given ? given : &fallback, base, out);
}
