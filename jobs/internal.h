/* internal.h: what the job stages share with the subcommands of cli/ (not installed).
 * A stage and its subcommand read the same words, write the same files and fill the
 * same report sections; the code for that lives here, in the library, so that the
 * stage table (stages.c) needs nothing from cli/. The tool links the static library,
 * which keeps these hidden symbols reachable. */
#ifndef MCP_JOBS_INTERNAL_H
#define MCP_JOBS_INTERNAL_H

#include <mcpost/blend.h>
#include <mcpost/denoiser.h>
#include <mcpost/estimate.h>
#include <mcpost/imageio.h>
#include <mcpost/job.h>
#include <mcpost/metrics.h>
#include <mcpost/operations.h>
#include <mcpost/options.h>
#include <mcpost/perceptual.h>
#include <mcpost/progress.h>
#include <mcpost/stats.h>
#include <mcpost/stages.h>

#include "../common/core/internal.h"
#include "../common/io/internal.h" /* output folders that appear whole (common/io/outdir.c) */
#include "../ops/internal.h"

#include <cjson/cJSON.h>
#include <stddef.h>
#include <stdint.h>

/* ---- frames.c: frame tokens in paths (hidden; public once) ---- */

/* Whether path holds a frame token (1) or not (0), by the rules of frames.h; -1
 * (error set) when the path breaks them. series: the path is a series pattern. */
int mcp_frame_token_check(const char *path, int series);

/* Replaces the frame token of path by the frame number into buf. In a series pattern
 * the spp conversion (and any "%%") is kept for mcp_series_from_pattern; elsewhere
 * "%%" becomes '%'. A path without a token is copied. */
int mcp_frame_expand(const char *path, int series, int frame, char *buf, size_t cap);

/* ---- commands (common/core/shell.c, declared in common/core/internal.h) ---- */

/* A command under /bin/sh with mcpost's programs on the end of its PATH, and its
 * status checked into one error line. */
int mcp__shell(const char *command);
int mcp__shell_check(int status, const char *what, const char *command);
int mcp__shell_fill(const char *tmpl, int n, const char *const *names,
                    const char *const *values, unsigned quoted, char **out);

/* ---- words.c: values as the flags and the job keys read them ---- */

/* A number / an integer, naming the flag or key on error. */
int mcp__parse_double(const char *flag, const char *text, double *out);
int mcp__parse_int(const char *flag, const char *text, int *out);
/* Splits "a,b,c" into a malloc'd array of strdup'd words. */
int mcp__split_words(const char *text, char ***words, int *count);
void mcp__free_words(char **words, int count);

/* ---- settings.c: a stage's settings ---- */

/* A stage's settings through its operation's table: ops/internal.h's
 * mcp__options_from_node and mcp__options_node_keys. */
#define mcp__job_settings mcp__options_from_node
#define mcp__op_job_keys mcp__options_node_keys

/* The current error put at the line of settings' key ("FILE:LINE: ..."); -1, and the
 * error unchanged when settings has no such key. */
int mcp__at_line(const mcp_node *settings, const char *key);

/* ---- variance_source.c: what a variance rests on, said the same way everywhere ---- */

/* "variance_source" (and "variance_dof" when known) into a JSON object, with a
 * "variance_note" when the source is an assumption (per-sample). */
void mcp__add_variance_source(cJSON *j, mcp_variance_source src, double dof);
/* The source in words, for the text output. */
const char *mcp__variance_source_words(mcp_variance_source src);
/* What a series estimate's SURE covariance term rests on, in words: the groups its last
 * member took, or the probes' divergence (variance_source.c). */
const char *mcp__sure_source_words(const mcp_series_estimate *s);
/* The one line that says Variance/n is off the increments' spread
 * (mcp_variance_ratio_off), and whether the increments are used. */
const char *mcp__variance_ratio_warning(double ratio, int using_increments);
/* A series' ratio into its JSON object / report section ("variance_ratio", and when
 * off "variance_choice" if the increments are used, else "variance_warning"), and that
 * line once on stderr (also when quiet: it says what the figures rest on) unless the
 * increments are used because the series asked for them (asked: variance_from
 * increments). j may be NULL. */
void mcp__report_variance_ratio(double ratio, int using_increments, int asked, cJSON *j);

/* ---- stage_denoiser.c ---- */

/* The denoiser of a job stage: its `denoiser:` setting, or `default` when it has none.
 * Relative paths in the settings resolve against the job file's folder. */
int mcp__stage_denoiser(mcp_job *job, const mcp_node *settings, mcp_denoiser **out);

/* ---- stage_info.c ---- */

/* Appends statistics of every channel of img to the array, names prefixed. */
int mcp__info_add_channels(cJSON *array, const mcp_image *img, const char *prefix);
/* One channel's statistics, as mcp__info_add_channels adds each. */
void mcp__info_add_channel(cJSON *array, const char *name, const mcp_channel_stats *s);
/* What a render dump means: convention, spp, variance and its source, features. */
void mcp__info_add_dump(cJSON *o, const mcp_dump *d);

/* ---- stage_convert.c ---- */

/* The channels' names of convert's settings, each value split at commas ("R,G,B" on
 * the command line, a list in a job), malloc'd: free with mcp__free_words. */
int mcp__convert_channel_names(const mcp_convert_settings *s, char ***names, int *count);
/* The channels of img named in `names`, as a new image. With no names: all channels,
 * except that a PNG, JPEG, HDR or PFM output (out_path's format) of an image with
 * R, G, B by name gets those (and A, for PNG and JPEG), which is what a person
 * converting to PNG means (docs/conventions.md, "Channel order"). */
int mcp__convert_pick_channels(const mcp_image *img, char **names, int count,
                               const char *out_path, mcp_image **out);

/* ---- convert_stream.c ---- */

/* `mcpost convert` of an EXR into an EXR a band of rows at a time: the image's channels
 * `names` (mcp__convert_pick_channels), or with dump (its sample count and convention;
 * path unused) the render dump rewritten in conv (mcp_dump_write's image), with wo.
 * -1 on failure, said as the whole conversion says it, with no output left; 0 and
 * *done 1 when written; 0 and *done 0 when it must be made whole (a file of another
 * format, a tiled output, a dump a band reader cannot take, MCPOST_BAND_ROWS=whole). */
int mcp__convert_streamed(const char *in, const char *out, char **names, int count,
                          const mcp_dump_spec *dump, mcp_convention conv,
                          const mcp_write_options *wo, int *done);

/* ---- estimate_output.c: what an estimate writes ---- */

/* Where outputs go: a folder and a prefix for report paths ("" or "estimate/"). */
typedef struct mcp__estimate_dir {
    char dir[4096];
    char rel[256];
} mcp__estimate_dir;

/* dir/name into buf. */
int mcp__estimate_path(const mcp__estimate_dir *o, const char *name, char *buf,
                       size_t cap);
/* The figures of one estimate (estimate.json). */
/* The truth beside a single estimate: "true_percentiles" (the nearest-rank percentiles
 * of the denoised image's true error against ref, at the estimate's percentiles) into
 * summary, as `mcpost estimate --ref` and the job stage's `reference:` give them. */
int mcp__estimate_add_truth(const mcp_estimate *e, const mcp_image *ref,
                            const mcp_estimate_options *eo, cJSON *summary);
cJSON *mcp__estimate_json(const mcp_estimate *e, const char *input, const char *denoiser,
                          const mcp_estimate_options *o);
/* The files a streamed estimate writes band by band (estimate_stream.c; the sink of
 * estimate/'s mcp__estimate_streamed, with this as its ctx): denoised.exr, sure.exr
 * and variance.exr into dir, opened at the first band; with want_picture the denoised
 * picture's bytes too, for the report. end closes them, renamed when failed is 0 and
 * every row was written, else removed; free frees the rest. */
#define MCP__ESTIMATE_STREAMED 3
typedef struct mcp__estimate_files {
    const mcp__estimate_dir *dir;
    int want_picture;
    char paths[MCP__ESTIMATE_STREAMED][4352];
    mcp__exr_band_file files[MCP__ESTIMATE_STREAMED];
    mcp_image *gather[MCP__ESTIMATE_STREAMED]; /* each file's rows before written */
    mcp_attrs attrs;                           /* F(X)'s, for denoised.exr */
    int begun, width, height;
    unsigned char *denoised_rgb;
} mcp__estimate_files;
struct mcp__estimate_rows;
int mcp__estimate_files_rows(void *ctx, const struct mcp__estimate_rows *rows);
int mcp__estimate_files_end(mcp__estimate_files *f, int failed);
void mcp__estimate_files_free(mcp__estimate_files *f);
/* distribution.exr (each block's λ, lambda: 3 a block) and blocks_sure_rel.exr (each
 * block's mean SURE^r) of a streamed estimate into o->dir, a band of rows at a time:
 * the pixels of the images mcp__error_dist_image and mcp_blocks_mean_image make whole
 * (estimate_stream.c). */
int mcp__estimate_block_files(const mcp_estimate *e, const float *lambda,
                              const mcp__estimate_dir *o);
/* Every image of one estimate and the block pictures into o->dir (made), and with a
 * section its block map in the report. The maps that are NULL (a streamed estimate's
 * F(X), SURE and Var[F]) are not written: they were; denoised_rgb, when not NULL, is
 * the denoised picture's bytes, made from F(X) otherwise. */
int mcp__estimate_write_single(const mcp_estimate *e, const mcp__estimate_dir *o,
                               cJSON *section, const cJSON *summary,
                               const unsigned char *denoised_rgb);
/* The report section of one estimate: key figures, the percentile table and curve. */
int mcp__estimate_report_single(cJSON *section, const cJSON *summary,
                                const mcp_estimate *e);
/* Runs a series and writes estimate.json (o may be NULL: nothing written) and the
 * section (may be NULL); the figures and the result come back. */
int mcp__estimate_run_series(const mcp_series *series, const mcp_denoiser *den,
                             const mcp_series_estimate_options *so, const mcp_image *ref,
                             const mcp__estimate_dir *o, cJSON *section, cJSON **json_out,
                             mcp_series_estimate **out);

/* ---- blend_run.c: a blend over a series, its files and its report section ---- */

/* Where a run writes, and what it reports. */
typedef struct {
    char dir[4096];  /* the output folder (exists) */
    const char *rel; /* the folder relative to the report's folder ("" or "x/") */
    int all_images;  /* also denoised, easy, james_stein, ideal */
    cJSON *members;  /* per-member file list for the JSON */
    mcp_progress prog;
    char last_base[512]; /* the last member's file name without extension */
} mcp__blend_sink;

/* Runs the driver into the sink and fills section. */
int mcp__blend_run(const mcp_series *series, const mcp_denoiser *den,
                   const mcp_image *ref, const mcp_blend_series_options *o,
                   const char *denoiser_name, mcp__blend_sink *s, cJSON *section);

/* ---- adaptive_loop.c: the adaptive-sampling loop around a render command ---- */

typedef struct mcp__adaptive_loop {
    const char *render; /* the command template */
    char dir[4096];     /* output folder */
    char rel[256];      /* prefix of report paths ("" or "adaptive/") */
    int width, height;
    uint64_t seed;
    int keep_passes;
    mcp_adaptive_options ao;
    const mcp_image *reference;
    const mcp_denoiser *den;
    cJSON *section; /* the job report's section, or NULL */
    /* the top of the colour scale of the maps written last (their colour bars):
     * counts and sampling map of the last pass, sampling map of the one before */
    double counts_hi, map_hi, prev_map_hi;
    int counts_flat; /* the last pass's counts are one value (counts_hi): no picture */
} mcp__adaptive_loop;

/* Runs the loop and writes every output; *json (may be NULL) receives the figures. */
int mcp__adaptive_run_loop(mcp__adaptive_loop *c, cJSON **json);
/* "WIDTHxHEIGHT". */
int mcp__parse_size(const char *text, int *w, int *h);

/* ---- perceptual_run.c: settings and the run of perceptual optimisation ---- */

typedef struct {
    mcp_perc_options opt;
    double *kernel;          /* user kernel taps, owned (separable list or 2D file) */
    const char *kernel_file; /* a 2D kernel image, loaded before the run */
    const char *surrogate;   /* "denoise" [default], "reference", or a file/input name */
    const char *confidence;  /* a file/input name for a map, or NULL (the number) */
    int group;               /* files averaged into one candidate [1] */
    int compare;             /* the comparison table [0] */
    const char *rerender;    /* command with {permutation} {output} {method} [NULL] */
    int spectra_tile;        /* [32] */
} mcp__perc_args;

typedef struct {
    mcp_image **files;   /* colour (R, G, B) of every candidate file, owned */
    mcp_image **albedos; /* each file's albedo and normal, or NULL; owned */
    mcp_image **normals;
    int n_files;
    mcp_image *albedo; /* mean albedo of the files, or NULL; owned */
    mcp_image *normal; /* mean normal, or NULL; owned */
    const mcp_image *reference, *surrogate_img, *confidence_map, *kernel_img;
    mcp_denoiser *den;  /* for surrogate: denoise */
    char out_dir[4096]; /* where the files go */
    char rel[256];      /* their path relative to the report's folder: rel + name */
    cJSON *section;     /* the report section to fill */
} mcp__perc_run;

void mcp__perc_args_init(mcp__perc_args *a);
void mcp__perc_args_free(mcp__perc_args *a);
/* The run's settings from perceptual's (<mcpost/operations.h>): the options, the
 * confidence as a number or a map's name, the kernel as a word, taps or a file; then
 * the library's check. Free with mcp__perc_args_free, also after a failure. */
int mcp__perc_args_from_settings(const mcp_perceptual_settings *s, mcp__perc_args *a);
/* A separable kernel's taps (an odd count). */
int mcp__perc_set_taps(mcp__perc_args *a, const double *t, int n);
void mcp__perc_run_free(mcp__perc_run *r);
/* Adds one file's colour (by its render-dump convention when it has one) and its
 * features to the run; finish_features averages the features once all are in. */
int mcp__perc_add_file(mcp__perc_run *r, const mcp_image *img);
int mcp__perc_finish_features(mcp__perc_run *r);
/* Runs the optimisation and writes its files; *summary gets the figures, *result
 * (may be NULL) the optimised image. */
int mcp__perceptual_run(mcp__perc_args *a, mcp__perc_run *r, cJSON **summary,
                        mcp_image **result);
/* Copies the summary's members into the report section, with a verdict. */
void mcp__perc_fill_section(cJSON *section, const cJSON *summary);

/* ---- gate.c: pass/warn/fail conditions on the metrics' figures ---- */

/* A gate is a set of conditions "FIGURE OP NUMBER" (OP one of > >= < <=; FIGURE a
 * number of the metrics JSON, dots for nesting, e.g. flip_ldr.mean), each a --fail or
 * a --warn one (job keys fail: and warn:). A condition that holds fails or warns, as
 * idiff's -fail / -warn thresholds do; none holding is a pass. Shared by
 * `mcpost metrics` and the metrics stage so both read and judge alike. */
#define MCP__GATE_MAX 16

typedef enum { MCP__GATE_PASS, MCP__GATE_WARNING, MCP__GATE_FAILURE } mcp__gate_verdict;

/* Exit statuses of a gate. idiff uses 1 (warning) and 2 (failure), which mcpost already
 * uses for errors (1) and usage errors (2); a script must tell a missing file from a
 * warning, so gates take the next free numbers (docs/metrics.md, "Gates"). */
#define MCP__GATE_EXIT_WARNING 3
#define MCP__GATE_EXIT_FAILURE 4

typedef struct {
    char figure[128]; /* a percent condition: the map, flip_ldr, flip_hdr or relse */
    int op;           /* '>', 'G' (>=), '<', 'L' (<=) */
    double value;     /* a percent condition: the share allowed, in percent */
    int is_fail;      /* 1: --fail / fail:, 0: --warn / warn: */
    /* A percent condition (--fail-percent 'MAP THRESHOLD PERCENT', idiff's
     * -failpercent): it holds when more than value percent of the pixels have the
     * map above threshold (the metrics' pixels_above). */
    int percent;
    double threshold;
    char text[192]; /* normalised: "flip_ldr.mean > 0.05",
                       "flip_ldr > 0.1 on more than 1% of the pixels" */
} mcp__gate_cond;

typedef struct {
    mcp__gate_cond c[MCP__GATE_MAX];
    int n;
} mcp__gate;

/* Parses one expression into the gate; a malformed one is an error naming it. */
int mcp__gate_add(mcp__gate *g, const char *expr, int is_fail);
/* The same for a percent condition, "MAP THRESHOLD PERCENT" with an optional '%'
 * (--fail-percent / --warn-percent, fail_percent: / warn_percent:). */
int mcp__gate_add_percent(mcp__gate *g, const char *expr, int is_fail);
/* Asks o for the shares of pixels that the percent conditions judge
 * (mcp_metrics_add_above); an error names the condition. */
int mcp__gate_request(const mcp__gate *g, mcp_metrics_options *o);
/* The figures that a metrics result with options o will hold (numbers all zero), with
 * width and height as the CLI's JSON and the report section have them: for checking
 * the names before anything is computed. The caller deletes it. */
cJSON *mcp__gate_metrics_names(const mcp_metrics_options *o);
/* Every condition's figure is a number in figures; else an error naming the first
 * unknown one and listing known names, and *bad (may be NULL) its index. */
int mcp__gate_check(const mcp__gate *g, const cJSON *figures, int *bad);
/* Judges the figures: the verdict, a "gate" object {"verdict", "failed", "warned"}
 * (may be NULL: not made), and the final line ("PASS", "WARNING: ...", "FAILURE: ...")
 * into line. A figure missing is an error (-1; check first). */
int mcp__gate_eval(const mcp__gate *g, const cJSON *figures, mcp__gate_verdict *verdict,
                   cJSON **gate_json, char *line, size_t cap);
int mcp__gate_exit_code(mcp__gate_verdict v);
/* The gate of metrics' settings (<mcpost/operations.h>): every condition of fail, warn,
 * fail_percent and warn_percent, in that order, parsed, its share of pixels requested
 * in o and its figure checked against what o computes, one at a time. On failure the
 * current error is the command line's ("--fail 'x > 1': no figure 'x' ..."), and
 * *bad_key and *bad_index name the condition ("fail", 0) for a job's line. With o NULL
 * (collect, whose frames' sections were computed with their job's options) the
 * conditions are only parsed; each section's figures judge them later. */
int mcp__gate_from_settings(const mcp_metrics_settings *s, mcp_metrics_options *o,
                            mcp__gate *g, const char **bad_key, int *bad_index);
/* The worst verdict of the gates judged in this process since the last reset: what
 * `mcpost run` exits with. */
void mcp__gate_record(mcp__gate_verdict v);
mcp__gate_verdict mcp__gate_worst(void);
void mcp__gate_reset(void);

/* The metrics section's verdict from its figures (stage_metrics.c): the gate's line
 * first when there is a gate (its colour: pass good, warning info, failure bad), then
 * relMSE as a relative error, FLIP in words and a series' MSE slope; `mcpost compare`
 * gives its sections the same line. */
/* FLIP's weighted histograms as plots in section (a second test's bars overlapped:
 * cmp and compare_name, else NULL), the counts kept for report.json only
 * (stage_metrics.c; the compare page draws them too). */
int mcp__metrics_flip_histograms(cJSON *section, const mcp_metrics *m, const char *input,
                                 const mcp_flip_result cmp[2], const char *compare_name);
int mcp__metrics_verdict(cJSON *section, const mcp__gate *gate, mcp__gate_verdict gv,
                         const char *gate_line);

/* ---- estimate/denoise_stream.c: `mcpost denoise` of a dump larger than memory ---- */

/* Denoises the EXR dump of spec into out_path (EXR) in bands of rows when den is the
 * U-Net (or the default denoiser running it) and the dump read whole would not fit
 * beside the network within its memory bound (docs/denoisers.md, "Images larger than
 * memory"): the same pixels and header as the whole run. *done 0 (and 0 returned):
 * nothing was done, run it whole; else 0 or -1 with the error set. */
int mcp__denoise_dump_streamed(const mcp_denoiser *den, const mcp_dump_spec *spec,
                               const char *out_path, int *done);

#endif
