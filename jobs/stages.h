/* stages.h: the library's job stages -- info, convert, metrics, perceptual, estimate,
 * blend and adaptive, the ones `mcpost run` knows (docs/jobs.md).
 *
 *   if (mcp_job_run_file("job.yaml", NULL, NULL))          // NULL: these stages
 *       fprintf(stderr, "%s\n", mcp_error_message());
 *
 * mcp_job_run_file and mcp_job_check take this table when given NULL for stages. A
 * program with stages of its own passes its own table, which may hold these entries
 * too (each is an `mcp_stage`, <mcpost/job.h>). */
#ifndef MCP_STAGES_H
#define MCP_STAGES_H

#include <mcpost/job.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Every built-in stage, in `mcpost run --list` order; NULL-terminated, static. */
MCP_API const mcp_stage *const *mcp_job_stages(void);

/* The built-in stage called name, or NULL (no error set). */
MCP_API const mcp_stage *mcp_job_stage_find(const char *name);

#ifdef __cplusplus
}
#endif
#endif
