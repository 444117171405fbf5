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
#include <mcpost/imageio.h>
#include <mcpost/metrics.h>
#include <mcpost/options.h>
#include <mcpost/perceptual.h>

#ifdef __cplusplus
extern "C" {
#endif

/* `estimate`: one dump, or a series (several dumps, a pattern with --spp, or a
 * job's series input). */
typedef struct mcp_estimate_settings {
    mcp_series_estimate_options so; /* so.taus: a single tau when given alone */
    mcp_series_variance variance_from;
    const char *input;         /* a job's input: a dump or a series */
    const char *reference;     /* a file (command line), an input (job) */
    const char *series;        /* command line: a printf pattern, with spp */
    const char *spp;           /* command line: the pattern's sample counts, "1,2,4" */
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
    mcp_dump_spec spec; /* how the command line reads a dump: spp, convention, variance */
    const char *input;  /* a job's input */
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

/* `convert`: an image written in another format, or a render dump in another
 * convention. */
typedef struct mcp_convert_settings {
    mcp_write_options wo;     /* pixel, compression; tiled and linear by finish */
    const char *channels[64]; /* names, or "A,B,C" (each split at commas) */
    int n_channels;
    int half;            /* command line: --half, pixel half */
    int tiled;           /* EXR tiles of tiled x tiled (0: scanlines) */
    int linear;          /* LDR outputs: no sRGB encoding */
    mcp_convention dump; /* command line: rewrite a dump in this convention */
    const char *spp;     /* command line: the dump's sample count */
    const char *input;   /* a job's input */
    const char *output;  /* a job's output file */
    uint64_t given;
} mcp_convert_settings;

/* At most this many conditions of each gate kind (--fail, --warn, ...). */
#define MCP_METRICS_MAX_GATES 16

/* `metrics`: test images against a reference, with gates; also `compare`'s figures
 * and gates (mcp_compare_settings). */
typedef struct mcp_metrics_settings {
    mcp_metrics_options o; /* o.flip_ldr and o.flip_hdr follow flip */
    int flip;              /* bit 0 LDR-FLIP, bit 1 HDR-FLIP */
    /* the gates' conditions as given, parsed by the front ends (jobs/gate.c) */
    const char *fail[MCP_METRICS_MAX_GATES], *warn[MCP_METRICS_MAX_GATES];
    const char *fail_percent[MCP_METRICS_MAX_GATES], *warn_percent[MCP_METRICS_MAX_GATES];
    int n_fail, n_warn, n_fail_percent, n_warn_percent;
    const char *csv; /* command line: the figures as CSV too */
    const char *input, *reference, *series, *estimate, *compare; /* a job's inputs */
    int maps; /* a job: write maps and previews */
    uint64_t given;
} mcp_metrics_settings;

/* `compare`: metrics' figures and gates on a page. */
typedef struct mcp_compare_settings {
    mcp_metrics_settings m; /* first: metrics' rows read it at their own offsets */
    double exposure;        /* the page's starting exposure, stops */
    int display;            /* the page's starting display (mcp_report_display_words) */
} mcp_compare_settings;

/* At most this many kernel items (taps) a job lists. */
#define MCP_PERCEPTUAL_MAX_TAPS 65

/* `perceptual`: perceptual error optimisation of few-sample renders. */
typedef struct mcp_perceptual_settings {
    mcp_perc_options opt;
    const char *surrogate;  /* "denoise", "reference", or an image (file, input) */
    const char *confidence; /* a number in [0, 1], or a per-pixel image */
    /* tap3, gaussian, a 2D kernel image, or separable taps: "a,b,c" (a job: a list,
     * an item each; the items are joined) */
    const char *kernel[MCP_PERCEPTUAL_MAX_TAPS];
    int n_kernel;
    const char *rerender;   /* a command with {permutation} {output} {method} */
    const char *reference;  /* a file (command line), an input (job), an array */
    const char *candidates; /* a job's series input or list of inputs */
    const char *name;       /* a job: the result's name */
    int group;              /* files averaged into one candidate */
    int compare;            /* every method on the input too */
    int spectra_tile;
    uint64_t given;
} mcp_perceptual_settings;

/* The operations' tables (ops/op_*.c). */
MCP_API const mcp_operation *mcp_operation_estimate(void);
MCP_API const mcp_operation *mcp_operation_blend(void);
MCP_API const mcp_operation *mcp_operation_adaptive(void);
MCP_API const mcp_operation *mcp_operation_info(void);
MCP_API const mcp_operation *mcp_operation_merge(void);
MCP_API const mcp_operation *mcp_operation_denoise(void);
MCP_API const mcp_operation *mcp_operation_convert(void);
MCP_API const mcp_operation *mcp_operation_metrics(void);
MCP_API const mcp_operation *mcp_operation_compare(void);
MCP_API const mcp_operation *mcp_operation_perceptual(void);

#ifdef __cplusplus
}
#endif
#endif
