/* op_estimate.c: the options of `estimate` (docs/estimate.md), once for the command
 * line, the job stage and Python (options.h). */
#include "internal.h"

#include <stddef.h>
#include <string.h>

#define S mcp_estimate_settings
#define EST(f) offsetof(S, so.est.f)

static const mcp_option estimate_options[] = {
    {.name = "input",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, input),
     .doc = "the input: a dump or a series (the command line: DUMP..., Python: dump)"},
    {.name = "denoiser",
     .type = MCP_OPT_DENOISER,
     .meta = "NAME",
     .def = "default",
     .doc = "the denoiser: `default` is unet with the shipped weights, nlm for dumps "
            "without albedo and normal"},
    {.name = "metric",
     .type = MCP_OPT_ENUM,
     .offset = EST(sure.metric),
     .meta = "NAME",
     .def = "relse",
     .doc = "the error metric",
     .words = &mcp_error_metric_words},
    {.name = "tau",
     .type = MCP_OPT_NUMBER,
     .offset = EST(tau),
     .meta = "T",
     .def = "0.01",
     .doc = "error threshold",
     .bounds = MCP_OPT_LO_OPEN},
    {.name = "percentile",
     .type = MCP_OPT_NUMBER,
     .offset = EST(p),
     .meta = "P",
     .def = "0.999",
     .doc = "fraction of values that must be below tau",
     .lo = 0,
     .hi = 1,
     .bounds = MCP_OPT_LO_OPEN | MCP_OPT_HI_OPEN},
    {.name = "percentiles",
     .type = MCP_OPT_LIST,
     .offset = EST(percentiles),
     .count_offset = EST(n_percentiles),
     .max_count = MCP_ESTIMATE_MAX_PERCENTILES,
     .meta = "LIST",
     .def = "0.5,0.9,0.99,0.999,0.9999",
     .doc = "the estimated percentile curve",
     .lo = 0,
     .hi = 1,
     .bounds = MCP_OPT_LO | MCP_OPT_HI_OPEN},
    {.name = "probes",
     .type = MCP_OPT_INT,
     .offset = EST(sure.n_probes),
     .meta = "K|auto",
     .def = "auto",
     .doc = "random probes for SURE and the variance (each costs one JVP); auto: 3 for "
            "unet, else 4",
     .lo = 1,
     .hi = 1024,
     .bounds = MCP_OPT_LO | MCP_OPT_HI,
     .auto_word = "auto",
     .auto_value = -1},
    {.name = "seed",
     .type = MCP_OPT_SEED,
     .offset = EST(sure.seed),
     .meta = "S",
     .def = "0",
     .doc = "seed of the probes"},
    {.name = "mc_sure",
     .type = MCP_OPT_FLAG,
     .offset = EST(sure.mc_sure),
     .def = "false",
     .doc = "J.eps by finite differences (MC-SURE) instead of the exact JVP"},
    {.name = "delta",
     .type = MCP_OPT_NUMBER,
     .offset = EST(sure.fd_delta),
     .meta = "D",
     .def = "0.1",
     .doc = "MC-SURE's finite-difference step, unitless",
     .bounds = MCP_OPT_LO_OPEN},
    {.name = "variance_probes",
     .type = MCP_OPT_ENUM,
     .offset = EST(variance_rademacher),
     .meta = "KIND",
     .def = "sure",
     .doc = "sure (reuse the SURE probes, Firmino 2024) or rademacher (Firmino 2023)",
     .words = &mcp_variance_probes_words},
    {.name = "ppd",
     .type = MCP_OPT_NUMBER,
     .offset = EST(sure.ppd),
     .meta = "X",
     .def = "0",
     .doc = "relse-perceptual: pixels per degree (0: 67.02)",
     .bounds = MCP_OPT_LO},
    {.name = "tile",
     .type = MCP_OPT_INT,
     .offset = EST(blocks.tile_size),
     .meta = "N",
     .def = "0",
     .doc = "pre-split into NxN tiles before block averaging (0: none)",
     .bounds = MCP_OPT_LO},
    {.name = "sampling",
     .type = MCP_OPT_ENUM,
     .offset = EST(sampling.kind),
     .meta = "KIND",
     .def = "variance",
     .doc = "the sampling map (tonemapped: ACES)",
     .words = &mcp_sampling_kind_words},
    {.name = "budget",
     .type = MCP_OPT_WHOLE,
     .offset = EST(budget),
     .meta = "N",
     .def = "0",
     .doc = "samples for the next pass: write integer counts (0: none)"},
    {.name = "s2_pool",
     .type = MCP_OPT_INT,
     .offset = EST(s2_pool),
     .meta = "R|auto",
     .def = "auto",
     .doc = "pool s^2 = (J eps)^2 over (2R+1)^2 pixels; auto: 1, or 0 for bilateral on a "
            "per-sample variance",
     .lo = 0,
     .hi = 16,
     .bounds = MCP_OPT_LO | MCP_OPT_HI,
     .auto_word = "auto",
     .auto_value = -1},
    {.name = "probe_floor",
     .type = MCP_OPT_INT,
     .offset = EST(probe_floor),
     .meta = "R|auto",
     .def = "auto",
     .doc = "raise the probes' variance to its median over (2R+1)^2 pixels where below "
            "it (a variance of 0 stays 0); auto: 1 for unet, else 0",
     .lo = 0,
     .hi = 16,
     .bounds = MCP_OPT_LO | MCP_OPT_HI,
     .auto_word = "auto",
     .auto_value = -1},
    {.name = "sure_groups",
     .type = MCP_OPT_INT,
     .where = MCP_OPT_CLI | MCP_OPT_JOB | MCP_OPT_PY,
     .offset = EST(sure_groups),
     .meta = "G|auto",
     .def = "auto",
     .doc = "over a series: SURE's covariance term and variance from G groups of each "
            "member's own checkpoints (G denoiser applies) instead of the probes' "
            "divergence, no stop before the groups start, and a per-sample variance "
            "off from theirs replaced for the probes; 0: the probes' everywhere; auto: 4",
     .lo = 0,
     .hi = 8,
     .bounds = MCP_OPT_LO | MCP_OPT_HI,
     .auto_word = "auto",
     .auto_value = -1},
    {.name = "exit_status",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, exit_status),
     .def = "false",
     .doc = "exit 0 to stop, 10 to continue rendering (a series: the last member and "
            "every tau)"},
    {.name = "reference",
     .type = MCP_OPT_INPUT,
     .offset = offsetof(S, reference),
     .meta = "FILE",
     .alias = "ref",
     .doc = "the reference image: the true error and, over a series, the true stops"},
    {.name = "series",
     .type = MCP_OPT_TEXT,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, series),
     .meta = "PATTERN",
     .group = "Series",
     .doc = "dump files from a printf pattern, with --spp LIST"},
    {.name = "spp",
     .type = MCP_OPT_TEXT,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spp),
     .meta = "LIST",
     .group = "Series",
     .doc = "sample counts for --series (e.g. 1,2,4,8)"},
    {.name = "taus",
     .type = MCP_OPT_LIST,
     .where = MCP_OPT_CLI | MCP_OPT_JOB | MCP_OPT_PY,
     .offset = offsetof(S, so.taus),
     .count_offset = offsetof(S, so.n_taus),
     .max_count = MCP_ESTIMATE_MAX_TAUS,
     .meta = "LIST",
     .def = "0.05,0.02,0.01",
     .group = "Series",
     .doc = "thresholds to report over a series (or the one tau given)",
     .bounds = MCP_OPT_LO_OPEN},
    {.name = "variance_from",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI | MCP_OPT_PY,
     .offset = offsetof(S, variance_from),
     .meta = "KIND",
     .def = "auto",
     .group = "Series",
     .doc = "a series' variance: auto (each member's own, or the spread between its "
            "increments where they show Variance/n off), file or increments (a job: the "
            "series input's variance_from)",
     .words = &mcp_series_variance_words},
    {.name = "convention",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, convention),
     .meta = "NAME",
     .def = "auto",
     .group = "Reading dumps",
     .doc = "the render-dump convention (a job: the input's)",
     .words = &mcp_convention_words},
    {.name = "variance",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, variance),
     .meta = "KIND",
     .def = "default",
     .group = "Reading dumps",
     .doc = "per-sample or of-mean: overrides what the convention says (a job: the "
            "input's)",
     .words = &mcp_variance_kind_words},
    {0}};

static void
estimate_defaults(void *p)
{
    S *s = p;
    s->so = mcp_series_estimate_defaults();
    s->variance_from = MCP_SERIES_VARIANCE_AUTO;
}

/* A series checks the one tau given, unless taus are given too. */
static int
estimate_finish(void *p)
{
    S *s = p;
    const mcp_operation *op = &mcp__op_estimate;
    if (mcp_operation_given(op, mcp_operation_option(op, "tau"), s) &&
        !mcp_operation_given(op, mcp_operation_option(op, "taus"), s)) {
        s->so.n_taus = 1;
        s->so.taus[0] = s->so.est.tau;
    }
    return mcp_estimate_check(&s->so.est);
}

const mcp_operation mcp__op_estimate = {
    .name = "estimate",
    .summary = "estimate the error of a denoised render and decide when to stop",
    .options = estimate_options,
    .size = sizeof(S),
    .defaults = estimate_defaults,
    .finish = estimate_finish,
    .given_offset = offsetof(S, given),
    .shared = MCP_SHARED_QUIET | MCP_SHARED_JSON | MCP_SHARED_OUTPUT | MCP_SHARED_THREADS,
    .output_doc = "write the images, estimate.json and a report into this folder (a job: "
                  "a folder in the job's output)",
    .output_def = "nothing written (a job: estimate)",
};

const mcp_operation *
mcp_operation_estimate(void)
{
    return &mcp__op_estimate;
}
