/* op_metrics.c: the options of `metrics` (docs/metrics.md), once for the command line,
 * the job stage and Python (options.h), and of `compare`, which takes the same figures'
 * options and gates (docs/report.md, "The compare page"): its settings begin with
 * metrics' settings, so the rows below serve both tables at the same offsets. */
#include "internal.h"

#include <mcpost/report.h>

#include <math.h>
#include <stddef.h>

#define S mcp_metrics_settings
#define O(f) offsetof(S, o.f)

static const char *const flip_kind_names[] = {"ldr", "hdr"};
/* which FLIPs: bit 0 LDR-FLIP, bit 1 HDR-FLIP */
const mcp_wordlist mcp__flip_kind_words = {"FLIP", flip_kind_names, 2};

#define FLIP_GROUP "FLIP (NVIDIA FLIP v1.6)"
#define REL_GROUP "Relative errors"
#define PMSE_GROUP "pMSE (Chizhov et al. 2022)"
#define SPECTRA_GROUP "Blue noise"
#define GATE_GROUP "Gates (CI; docs/metrics.md, \"Gates\")"

/* A gate's conditions: repeatable on the command line, a list in a job. */
#define GATE_ROW(NAME, WHERE, META, DOC)                                                 \
    {                                                                                    \
        .name = #NAME, .type = MCP_OPT_TEXTS, .where = WHERE,                            \
        .offset = offsetof(S, NAME), .count_offset = offsetof(S, n_##NAME),              \
        .max_count = MCP_METRICS_MAX_GATES, .meta = META, .group = GATE_GROUP,           \
        .doc = DOC                                                                       \
    }

/* The four gate rows, taken where GW says: metrics', compare's and collect's. */
#define GATE_ROWS(GW)                                                                    \
    GATE_ROW(fail, GW, "'EXPR'",                                                         \
             "FAILURE when EXPR holds: FIGURE OP NUMBER, OP one of > >= < <=, "          \
             "FIGURE a number of the JSON, dots for nesting (flip_ldr.mean)"),           \
        GATE_ROW(warn, GW, "'EXPR'", "WARNING when EXPR holds"),                         \
        GATE_ROW(fail_percent, GW, "'MAP T P'",                                          \
                 "FAILURE when more than P% of the pixels have MAP (flip_ldr, "          \
                 "flip_hdr, relse) above T (idiff's -failpercent)"),                     \
        GATE_ROW(warn_percent, GW, "'MAP T P'",                                          \
                 "WARNING when more than P% of the pixels have MAP above T")

/* The figures' options and the gates, the rows metrics and compare share: W is where
 * the figures' options are taken, GW the gates' (metrics: everywhere and not in Python;
 * compare: the command line). */
#define FIGURE_ROWS(W, GW)                                                               \
    {.name = "flip",                                                                     \
     .type = MCP_OPT_WORDSET,                                                            \
     .where = W,                                                                         \
     .offset = offsetof(S, flip),                                                        \
     .meta = "LIST",                                                                     \
     .def = "ldr,hdr",                                                                   \
     .group = FLIP_GROUP,                                                                \
     .doc = "which FLIPs: ldr, hdr, both or none",                                       \
     .words = &mcp__flip_kind_words},                                                    \
        {.name = "ppd",                                                                  \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(flip.ppd),                                                          \
         .meta = "X",                                                                    \
         .def = "0",                                                                     \
         .group = FLIP_GROUP,                                                            \
         .doc = "pixels per degree (0: from the viewing condition below, 67.02 with "    \
                "its defaults)",                                                         \
         .hi = 10000,                                                                    \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "distance_m",                                                           \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(flip.distance_m),                                                   \
         .meta = "X",                                                                    \
         .def = "0.7",                                                                   \
         .group = FLIP_GROUP,                                                            \
         .doc = "viewing distance in metres",                                            \
         .bounds = MCP_OPT_LO_OPEN},                                                     \
        {.name = "display_width_m",                                                      \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(flip.display_width_m),                                              \
         .meta = "X",                                                                    \
         .def = "0.7",                                                                   \
         .group = FLIP_GROUP,                                                            \
         .doc = "display width in metres",                                               \
         .bounds = MCP_OPT_LO_OPEN},                                                     \
        {.name = "display_width_px",                                                     \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(flip.display_width_px),                                             \
         .meta = "N",                                                                    \
         .def = "3840",                                                                  \
         .group = FLIP_GROUP,                                                            \
         .doc = "display width in pixels",                                               \
         .bounds = MCP_OPT_LO_OPEN},                                                     \
        {.name = "tone_mapper",                                                          \
         .where = W,                                                                     \
         .type = MCP_OPT_ENUM,                                                           \
         .offset = O(flip.tone_mapper),                                                  \
         .meta = "NAME",                                                                 \
         .def = "aces",                                                                  \
         .group = FLIP_GROUP,                                                            \
         .doc = "HDR-FLIP's tone mapper: aces, hable or reinhard",                       \
         .words = &mcp_tonemap_words},                                                   \
        {.name = "start_exposure",                                                       \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(flip.start_exposure),                                               \
         .meta = "X",                                                                    \
         .def = "auto",                                                                  \
         .group = FLIP_GROUP,                                                            \
         .doc = "HDR-FLIP's first exposure in stops (auto: from the reference)",         \
         .auto_word = "auto",                                                            \
         .auto_value = NAN},                                                             \
        {.name = "stop_exposure",                                                        \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(flip.stop_exposure),                                                \
         .meta = "X",                                                                    \
         .def = "auto",                                                                  \
         .group = FLIP_GROUP,                                                            \
         .doc = "HDR-FLIP's last exposure in stops (auto: from the reference)",          \
         .auto_word = "auto",                                                            \
         .auto_value = NAN},                                                             \
        {.name = "num_exposures",                                                        \
         .where = W,                                                                     \
         .type = MCP_OPT_INT,                                                            \
         .offset = O(flip.num_exposures),                                                \
         .meta = "N",                                                                    \
         .def = "auto",                                                                  \
         .group = FLIP_GROUP,                                                            \
         .doc = "HDR-FLIP's exposures (auto: max(2, ceil(stop - start)))",               \
         .lo = 2,                                                                        \
         .hi = 1000,                                                                     \
         .bounds = MCP_OPT_LO | MCP_OPT_HI,                                              \
         .auto_word = "auto",                                                            \
         .auto_value = 0},                                                               \
        {.name = "percentiles",                                                          \
         .where = W,                                                                     \
         .type = MCP_OPT_LIST,                                                           \
         .offset = O(percentiles),                                                       \
         .count_offset = O(n_percentiles),                                               \
         .max_count = MCP_METRICS_MAX_PERCENTILES,                                       \
         .meta = "LIST",                                                                 \
         .def = "0.5,0.9,0.99",                                                          \
         .group = REL_GROUP,                                                             \
         .doc = "RelSE percentiles",                                                     \
         .hi = 1,                                                                        \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "eps_rel",                                                              \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(eps_rel),                                                           \
         .meta = "X",                                                                    \
         .def = "0.01",                                                                  \
         .group = REL_GROUP,                                                             \
         .doc = "epsilon of relMSE and RelSE",                                           \
         .bounds = MCP_OPT_LO_OPEN},                                                     \
        {.name = "pmse_kernel",                                                          \
         .where = W,                                                                     \
         .type = MCP_OPT_ENUM,                                                           \
         .offset = O(pmse.kernel.kind),                                                  \
         .meta = "NAME",                                                                 \
         .def = "tap3",                                                                  \
         .group = PMSE_GROUP,                                                            \
         .doc = "the kernel g: tap3 ([1/pi, 1-2/pi, 1/pi]) or gaussian",                 \
         .words = &mcp_pkernel_kind_words},                                              \
        {.name = "pmse_dpi",                                                             \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(pmse.kernel.dpi),                                                   \
         .meta = "X",                                                                    \
         .def = "300",                                                                   \
         .group = PMSE_GROUP,                                                            \
         .doc = "gaussian: screen resolution",                                           \
         .bounds = MCP_OPT_LO_OPEN},                                                     \
        {.name = "pmse_distance_in",                                                     \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(pmse.kernel.distance_in),                                           \
         .meta = "X",                                                                    \
         .def = "16",                                                                    \
         .group = PMSE_GROUP,                                                            \
         .doc = "gaussian: viewing distance in inches",                                  \
         .bounds = MCP_OPT_LO_OPEN},                                                     \
        {.name = "pmse_filter_reference",                                                \
         .where = W,                                                                     \
         .type = MCP_OPT_FLAG,                                                           \
         .offset = O(pmse.filter_reference),                                             \
         .def = "false",                                                                 \
         .group = PMSE_GROUP,                                                            \
         .doc = "filter the reference with g too (h = g, not delta)"},                   \
        {.name = "pmse_tone_map",                                                        \
         .where = W,                                                                     \
         .type = MCP_OPT_ENUM,                                                           \
         .offset = O(pmse.tone_map),                                                     \
         .meta = "NAME",                                                                 \
         .def = "clamp",                                                                 \
         .group = PMSE_GROUP,                                                            \
         .doc = "the tone map T",                                                        \
         .words = &mcp_tonemap_words},                                                   \
        {.name = "spectra",                                                              \
         .where = W,                                                                     \
         .type = MCP_OPT_FLAG,                                                           \
         .offset = O(spectra),                                                           \
         .def = "true",                                                                  \
         .group = SPECTRA_GROUP,                                                         \
         .doc = "the tiled error spectra and the blue-noise fraction"},                  \
        {.name = "spectra_tile_size",                                                    \
         .where = W,                                                                     \
         .type = MCP_OPT_INT,                                                            \
         .offset = O(spectra_opt.tile_size),                                             \
         .meta = "N",                                                                    \
         .def = "32",                                                                    \
         .group = SPECTRA_GROUP,                                                         \
         .doc = "tile size",                                                             \
         .lo = 4,                                                                        \
         .hi = 4096,                                                                     \
         .bounds = MCP_OPT_LO | MCP_OPT_HI},                                             \
        {.name = "spectra_cutoff",                                                       \
         .where = W,                                                                     \
         .type = MCP_OPT_NUMBER,                                                         \
         .offset = O(spectra_opt.cutoff),                                                \
         .meta = "X",                                                                    \
         .def = "0.25",                                                                  \
         .group = SPECTRA_GROUP,                                                         \
         .doc = "the low frequencies' share of Nyquist",                                 \
         .hi = 1,                                                                        \
         .bounds = MCP_OPT_LO_OPEN | MCP_OPT_HI},                                        \
        GATE_ROWS(GW)

static const mcp_option metrics_options[] = {
    {.name = "input",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, input),
     .doc = "the image under test (the command line: TEST..., Python: test)"},
    {.name = "reference",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, reference),
     .doc = "the reference (the command line: REF, the last file; Python: ref)"},
    {.name = "series",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, series),
     .doc = "a series: error-against-spp curves of every member"},
    {.name = "estimate",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, estimate),
     .doc = "an estimated RelSE map of input, drawn beside the true one"},
    {.name = "compare",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, compare),
     .doc = "a second test whose FLIP histograms overlap input's"},
    {.name = "maps",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, maps),
     .def = "true",
     .doc = "write the maps and previews (Python: maps=True returns the maps)"},
    {.name = "csv",
     .type = MCP_OPT_TEXT,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, csv),
     .meta = "FILE",
     .doc = "also write the figures as CSV, a row per test"},
    FIGURE_ROWS(0, MCP_OPT_CLI | MCP_OPT_JOB),
    {0}};

static void
metrics_defaults(void *p)
{
    S *s = p;
    s->o = mcp_metrics_defaults();
    s->flip = (s->o.flip_ldr ? 1 : 0) | (s->o.flip_hdr ? 2 : 0);
    s->maps = 1;
}

/* The FLIPs from flip; HDR-FLIP's tone mapper is one of FLIP's own three. */
static int
metrics_finish(void *p)
{
    S *s = p;
    s->o.flip_ldr = (s->flip & 1) != 0;
    s->o.flip_hdr = (s->flip & 2) != 0;
    if (s->o.flip_hdr &&
        mcp_tonemap_flip_coefficients(s->o.flip.tone_mapper, (float[6]){0}))
        return -1;
    return 0;
}

const mcp_operation mcp__op_metrics = {
    .name = "metrics",
    .summary =
        "compare test images with a reference (MSE, relMSE, PSNR, pMSE, FLIP, ...)",
    .options = metrics_options,
    .size = sizeof(S),
    .defaults = metrics_defaults,
    .finish = metrics_finish,
    .given_offset = offsetof(S, given),
    .shared = MCP_SHARED_QUIET | MCP_SHARED_JSON | MCP_SHARED_OUTPUT | MCP_SHARED_THREADS,
    .output_doc = "a folder for the maps: flip_ldr/flip_hdr (.exr and magma .png), "
                  "flip_hdr_exposure, relse, sq_error, spectra, the FLIP histograms and "
                  "metrics.json (a job: a folder in the job's output for them and the "
                  "previews)",
    .output_def = "none (a job: the input's name)",
};

const mcp_operation *
mcp_operation_metrics(void)
{
    return &mcp__op_metrics;
}

/* ---- compare ---- */

#undef S
#define C mcp_compare_settings

/* the metrics rows read C's first member at their own offsets */
_Static_assert(offsetof(C, m) == 0, "compare's settings begin with metrics'");
#define S mcp_metrics_settings

static const mcp_option compare_options[] = {
    {.name = "exposure",
     .type = MCP_OPT_NUMBER,
     .where = MCP_OPT_CLI,
     .offset = offsetof(C, exposure),
     .meta = "X",
     .def = "0",
     .doc = "the page's starting exposure, stops",
     .lo = -20,
     .hi = 20,
     .bounds = MCP_OPT_LO | MCP_OPT_HI},
    {.name = "display",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(C, display),
     .meta = "NAME",
     .def = "clamp",
     .doc = "the page's starting display",
     .words = &mcp_report_display_words},
    FIGURE_ROWS(MCP_OPT_CLI, MCP_OPT_CLI),
    {0}};

static void
compare_defaults(void *p)
{
    C *c = p;
    metrics_defaults(&c->m);
}

static int
compare_finish(void *p)
{
    C *c = p;
    return metrics_finish(&c->m);
}

const mcp_operation mcp__op_compare = {
    .name = "compare",
    .summary =
        "a page to look at renders against a reference (wipe, error maps, figures, "
        "gates)",
    .options = compare_options,
    .size = sizeof(C),
    .defaults = compare_defaults,
    .finish = compare_finish,
    .given_offset = offsetof(S, given),
    .shared = MCP_SHARED_JSON | MCP_SHARED_OUTPUT | MCP_SHARED_QUIET | MCP_SHARED_THREADS,
    .output_doc =
        "the page's folder: report.html, report.json, the previews and maps (one "
        "TEST: in it; several: in test1, test2, ...), written whole",
    .output_def = "compare",
};

const mcp_operation *
mcp_operation_compare(void)
{
    return &mcp__op_compare;
}

/* ---- collect: the gates alone, judged on every frame of a shot (cli/cmd_collect.c) ----
 */

static const mcp_option collect_options[] = {GATE_ROWS(MCP_OPT_CLI), {0}};

const mcp_operation mcp__op_collect = {
    .name = "collect",
    .summary = "gather a frame job's reports into one (the gates of metrics over every "
               "frame)",
    .options = collect_options,
    .size = sizeof(S),
    .defaults = metrics_defaults,
    .given_offset = offsetof(S, given),
    .shared = MCP_SHARED_JSON | MCP_SHARED_QUIET,
};
