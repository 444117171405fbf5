/* job.h: job files (read into node trees, yaml.h) and the stage registry.
 *
 * A job names inputs, an output folder and a list of stages:
 *
 *   inputs:
 *     noisy:     {dump: renders/frame_0064.exr}          # a render dump
 *     progress:  {series: renders/frame_%04d.exr, spp: [1, 2, 4, 8]}
 *     reference: {image: renders/reference.exr}
 *     merged:    {replicates: renders/frame_seed*.exr}      # K renders, other seeds:
 *                                                          # one dump, variance from
 *                                                          # their spread (or a list)
 *   output: out/frame                                     # relative to the job file
 *   frames: 1-240                     # optional: a frame job (frames.h, docs/frames.md);
 *                                     # input paths then hold a frame token (####, %04d)
 *   stages:
 *     - info: {input: noisy}
 *     - convert: {input: reference, output: reference.png}
 *
 * Paths are relative to the job file's folder. Every stage is looked up by name in a
 * table that the caller passes in, or the library's own (jobs/stages.c,
 * <mcpost/stages.h>) when it passes NULL, so a module adds a stage by adding one entry
 * there. Unknown keys, wrong types and missing inputs are errors that name
 * "job.yaml:LINE", and every stage's settings are checked (mcp_stage.check) before the
 * first stage runs. */
#ifndef MCP_JOB_H
#define MCP_JOB_H

#include <mcpost/dump.h>
#include <mcpost/report.h>
#include <mcpost/yaml.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_job mcp_job;

typedef struct mcp_stage {
    const char *name;
    const char *summary;     /* one line for `mcpost run --list` */
    const char *const *keys; /* allowed settings keys, NULL-terminated */
    /* settings is the stage's map (never NULL: an empty map when none given) */
    int (*run)(mcp_job *job, const mcp_node *settings);
    /* Checks the settings as run would read them, without running: every key's type
     * and value, the inputs and results it names (mcp_job_check_input: by name and
     * kind, nothing loaded), the files it reads, the results it makes
     * (mcp_job_declare). Called for every stage before the first one runs, and by
     * mcp_job_check; no side effects. A stage's run reuses the same parse. NULL: the
     * keys alone are checked. */
    int (*check)(mcp_job *job, const mcp_node *settings);
} mcp_stage;

typedef struct mcp_job_options {
    const char *output_dir; /* overrides the job's `output:` [NULL] */
    int json_stdout;        /* print the report JSON on stdout when done [0] */
    int quiet;              /* no progress on stderr [0] */
    int frame;              /* the frame to run, of a job with frames: [-1: none]; its
                             * results go to <output>/<frame, 4 digits>/ (frames.h) */
} mcp_job_options;

MCP_API mcp_job_options mcp_job_defaults(void);

/* Parses, validates (every stage known, its keys allowed, every input's file
 * present) and runs a job. stages is NULL-terminated; NULL means the library's own
 * (mcp_job_stages, <mcpost/stages.h>: the stages `mcpost run` knows). Writes
 * report.json (and what the stages add) to the output folder, which appears whole:
 * the stages write into a hidden folder beside it, renamed into place after
 * report.json, so a failed run leaves none (docs/conventions.md, "Output folders");
 * opt NULL: defaults. */
MCP_API int mcp_job_run_file(const char *path, const mcp_stage *const *stages,
                             const mcp_job_options *opt);

/* The frames of a job (its `frames:`, sorted; *count 0 when it has none; *frames
 * malloc'd) and, when output_dir is not NULL, its output folder (malloc'd; frame F's
 * results go to its subfolder mcp_frame_dir). opt may give output_dir; its frame is
 * ignored. */
MCP_API int mcp_job_frames(const char *path, const mcp_job_options *opt, int **frames,
                           int *count, char **output_dir);

/* Parses and validates a job as mcp_job_run_file does before its first stage (every
 * stage known, its keys allowed, every input's keys, types and files), and nothing
 * else: no stage runs, no folder is made, nothing is written. stages NULL: the
 * library's own, as for mcp_job_run_file. */
MCP_API int mcp_job_check(const char *path, const mcp_stage *const *stages);

/* mcp_job_check without looking for the inputs' files (nor expanding a replicates
 * pattern): for a frame job, everything its frames share -- the stages, their keys
 * and values, the inputs' definitions and the files the stages read -- checked once,
 * with its first frame's paths, before any frame starts, when some frames' renders
 * may not be there yet. `mcpost run` and `submit` call it before starting a shot. */
MCP_API int mcp_job_check_settings(const char *path, const mcp_stage *const *stages);

/* For stages: the job file (for messages), the folder relative paths resolve to, and
 * the output folder (created on first use). While the job runs, that is the hidden
 * folder that becomes the output folder (".NAME.tmp-PID" beside it): paths a stage
 * puts into its report section are given the final folder's name when the report is
 * written; other files that hold the folder's path would name the hidden one. */
MCP_API const char *mcp_job_path(const mcp_job *job);
MCP_API const char *mcp_job_output_dir(mcp_job *job);

/* Resolves a path written in the job file (relative to its folder) into buf. */
MCP_API int mcp_job_resolve(const mcp_job *job, const char *rel, char *buf, size_t cap);
/* The path of an output file `name` inside the output folder (folders created). */
MCP_API int mcp_job_output_path(mcp_job *job, const char *name, char *buf, size_t cap);
/* The path of the folder `sub` (may hold slashes) inside the output folder, made with
 * its parents: where a stage puts its files ("estimate", "blend", ...). */
MCP_API int mcp_job_output_subdir(mcp_job *job, const char *sub, char *buf, size_t cap);

/* Named inputs and results. Lookups take the settings map and the key whose value
 * names the input (e.g. "input"), so that a missing name is reported at its line.
 * Returned objects are borrowed from the job (loaded once, freed with the job). */
MCP_API int mcp_job_dump(mcp_job *job, const mcp_node *settings, const char *key,
                         const mcp_dump **out);
MCP_API int mcp_job_image(mcp_job *job, const mcp_node *settings, const char *key,
                          const mcp_image **out);
MCP_API int mcp_job_series(mcp_job *job, const mcp_node *settings, const char *key,
                           const mcp_series **out);
/* What an input or result provides, for checks. A dump is also an image. */
enum { MCP_JOB_DUMP = 1, MCP_JOB_IMAGE = 2, MCP_JOB_SERIES = 4 };

/* For stages' checks, before anything is loaded: the scalar `name` (a value in the
 * settings) names an input or a result of an earlier stage that provides one of
 * `kinds`; fails with "FILE:LINE: no input or result called 'N'" or "'N' is not a
 * series" (or a render dump, an image). mcp_job_check_input does the same for the
 * value of settings' `key`, which must be there. */
MCP_API int mcp_job_check_name(mcp_job *job, const mcp_node *name, unsigned kinds);
MCP_API int mcp_job_check_input(mcp_job *job, const mcp_node *settings, const char *key,
                                unsigned kinds);
/* The kinds the input or result `name` provides (0: none such). */
MCP_API unsigned mcp_job_kinds(mcp_job *job, const char *name);
/* For stages' checks: a later stage may name this stage's result `name` (one of
 * MCP_JOB_*). While the job runs it does nothing (mcp_job_put_* publishes). */
MCP_API int mcp_job_declare(mcp_job *job, const char *name, unsigned kind);
/* A file the job reads (a kernel, a map, weights): the path relative to the job file
 * must exist, else "FILE:LINE: KEY: no such file: PATH". */
MCP_API int mcp_job_check_file(const mcp_job *job, const mcp_node *path_node,
                               const char *key);

/* By name, without a settings line (NULL when absent; no error). */
MCP_API const mcp_image *mcp_job_find_image(mcp_job *job, const char *name);

/* Stages publish results for later stages (the job takes ownership). A dump's colour
 * is also visible as an image of the same name. */
MCP_API int mcp_job_put_image(mcp_job *job, const char *name, mcp_image *img);
MCP_API int mcp_job_put_dump(mcp_job *job, const char *name, mcp_dump *dump);

/* The job's report (figures and sections that stages add). */
MCP_API mcp_report *mcp_job_report(mcp_job *job);
MCP_API int mcp_job_quiet(const mcp_job *job);

#ifdef __cplusplus
}
#endif
#endif
