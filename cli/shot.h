/* shot.h: the frames of a job as the commands see them (cli/shot.c): which frames a
 * command works on, the manifest that `mcpost collect` reads, and running frames in
 * parallel processes. docs/frames.md. */
#ifndef MCP_CLI_SHOT_H
#define MCP_CLI_SHOT_H

#include <mcpost/job.h>

typedef struct mcp_cli_shot {
    char *job;       /* the job file's real path */
    int *all, n_all; /* the job's frames: (n_all 0: not a frame job) */
    int *chosen;     /* --frames of them (all when none given) */
    int n_chosen;
    char *output_dir; /* the job's output folder (frame F in its 4-digit subfolder) */
} mcp_cli_shot;

/* Reads the job's frames and output folder (output overrides it when not NULL) and
 * picks the frames of `select` (a set, "10-20"; NULL: all), each of which must be
 * one of the job's. */
int mcp_cli_shot_open(const char *job, const char *output, const char *select,
                      mcp_cli_shot *s);
void mcp_cli_shot_free(mcp_cli_shot *s);

/* Writes <output>/frames.json: the job and all its frames, so that collect can list
 * the ones that never ran. Atomic; any number of processes may write it at once. The
 * folder made, s->output_dir names it by its real path from then on (no
 * "jobs/../../out" in messages). */
int mcp_cli_shot_write_manifest(mcp_cli_shot *s);

/* Runs the chosen frames that are not complete (all of them with force) in `jobs`
 * processes, with a progress line for the set. A failed frame does not stop the
 * others; its message goes to <frame folder>/error.txt. Fails when any frame failed. */
int mcp_cli_shot_run(const mcp_cli_shot *s, const mcp_job_options *jo, int jobs,
                     int force);

#endif
