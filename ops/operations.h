/* operations.h: the settings of each operation with an option table (options.h) --
 * what the command line, a job stage and the Python module fill through the table,
 * field for field the same, before the operation runs (docs/library.md, "Adding an
 * option"). A settings struct holds the library's own options struct and what the
 * front ends add around it (inputs, a reference, the denoiser's place). */
#ifndef MCP_OPERATIONS_H
#define MCP_OPERATIONS_H

#include <mcpost/blend.h>
#include <mcpost/dump.h>
#include <mcpost/estimate.h>
#include <mcpost/options.h>

#ifdef __cplusplus
extern "C" {
#endif

/* `estimate`: one dump, or a series (several dumps, a pattern with --spp, or a
 * job's series input). */
typedef struct mcp_estimate_settings {
    mcp_series_estimate_options so; /* so.taus: a single tau when given alone */
    mcp_series_variance variance_from;
    const char *input;      /* a job's input: a dump or a series */
    const char *reference;  /* a file (command line), an input (job) */
    const char *series;     /* command line: a printf pattern, with spp */
    const char *spp;        /* command line: the pattern's sample counts, "1,2,4" */
    mcp_convention convention; /* command line: how to read the dumps */
    mcp_variance_kind variance;
    int exit_status; /* command line: exit 0 to stop, 10 to go on */
    uint64_t given;
} mcp_estimate_settings;

/* `blend`: a series blended with its denoised images. */
typedef struct mcp_blend_settings {
    mcp_blend_series_options o;
    mcp_series_variance variance_from;
    const char *input;     /* a job's series input */
    const char *reference; /* a file (command line), an input (job), array or path */
    const char *spp;       /* command line: the pattern's sample counts */
    int all_images;        /* also the denoised, easy, James-Stein and ideal images */
    uint64_t given;
} mcp_blend_settings;

/* `adaptive`: the adaptive-sampling loop around a render command. */
typedef struct mcp_adaptive_settings {
    mcp_adaptive_options ao;
    const char *render;    /* the command template */
    const char *size;      /* "WxH", or NULL: the reference's */
    const char *reference; /* a file (command line), an input (job) */
    uint64_t seed;         /* {seed}, and the probes' (ao.est.sure.seed) */
    int keep_passes;
    uint64_t given;
} mcp_adaptive_settings;

/* `info`: images and render dumps described. */
typedef struct mcp_info_settings {
    mcp_dump_spec spec;  /* how the command line reads a dump: spp, convention, variance */
    const char *input;   /* a job's input */
} mcp_info_settings;

/* `merge`: render dumps of one frame combined into one (command line only). */
typedef struct mcp_merge_settings {
    mcp_merge_options mo;
    mcp_dump_spec spec; /* how to read the inputs: spp, convention */
    int half;           /* store half floats */
} mcp_merge_settings;

/* `denoise`: one denoiser alone (command line only; Python's denoise and jvp take
 * arrays). */
typedef struct mcp_denoise_settings {
    const char *tangent, *tangent_out;
    const char *color, *albedo, *normal, *variance_of_mean; /* instead of a dump */
    int no_albedo, no_normal, no_variance;
    const char *spp, *convention, *variance; /* how to read a dump */
    int list;
} mcp_denoise_settings;

/* The operations' tables (ops/op_*.c). */
MCP_API const mcp_operation *mcp_operation_estimate(void);
MCP_API const mcp_operation *mcp_operation_blend(void);
MCP_API const mcp_operation *mcp_operation_adaptive(void);
MCP_API const mcp_operation *mcp_operation_info(void);
MCP_API const mcp_operation *mcp_operation_merge(void);
MCP_API const mcp_operation *mcp_operation_denoise(void);

#ifdef __cplusplus
}
#endif
#endif
