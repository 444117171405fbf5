/* op_blend.c: the options of `blend` (docs/blend.md), once for the command line, the
 * job stage and Python (options.h). */
#include "internal.h"

#include <math.h>
#include <stddef.h>

#define S mcp_blend_settings
#define B(f) offsetof(S, o.blend.f)

static const mcp_option blend_options[] = {
    {.name = "input",
     .type = MCP_OPT_INPUT,
     .where = MCP_OPT_JOB,
     .offset = offsetof(S, input),
     .doc = "the series input (the command line: SERIES..., Python: dumps)"},
    {.name = "denoiser",
     .type = MCP_OPT_DENOISER,
     .meta = "NAME",
     .def = "default",
     .doc = "the denoiser: `default` is unet with the shipped weights, nlm for dumps "
            "without albedo and normal"},
    {.name = "spp",
     .type = MCP_OPT_TEXT,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, spp),
     .meta = "LIST",
     .doc = "the pattern's sample counts, e.g. 1,2,4,8"},
    {.name = "stop_denoising_at",
     .type = MCP_OPT_NUMBER,
     .offset = offsetof(S, o.stop_denoising_at),
     .meta = "SPP",
     .def = "0",
     .doc = "denoise up to this spp; later members reuse d and SURE (0: every member)",
     .bounds = MCP_OPT_LO},
    {.name = "reference",
     .type = MCP_OPT_INPUT,
     .offset = offsetof(S, reference),
     .meta = "REF",
     .alias = "ref",
     .doc = "reference: errors of every method, ideal blending, tables and plots of MSE, "
            "relMSE, HDR-FLIP per spp"},
    {.name = "all_images",
     .type = MCP_OPT_FLAG,
     .offset = offsetof(S, all_images),
     .def = "false",
     .doc = "also write the denoised, easy, James-Stein and ideal images"},
    {.name = "weights",
     .type = MCP_OPT_ENUM,
     .offset = B(weights),
     .meta = "NAME",
     .def = "james_stein",
     .group = "Curves and weights",
     .doc = "james_stein (the weight of d from how far it is from n, against n's noise) "
            "or curves (Denisova & Bocchi's convergence curves from SURE)",
     .words = &mcp_blend_weighting_words},
    {.name = "fit",
     .type = MCP_OPT_ENUM,
     .offset = B(fit),
     .meta = "NAME",
     .def = "on_the_fly",
     .group = "Curves and weights",
     .doc = "on_the_fly (newest point + Eq. 11 point), last_two (the paper's) or "
            "retrospective (least squares over every member)",
     .words = &mcp_curve_fit_words},
    {.name = "curve",
     .type = MCP_OPT_ENUM,
     .offset = B(curve),
     .meta = "NAME",
     .def = "log",
     .group = "Curves and weights",
     .doc =
         "log (log v = a log I + b) or powerlaw (the authors' code: ln v + 100 = a I^b, "
         "W capped at 65536)",
     .words = &mcp_curve_model_words},
    {.name = "far_spp",
     .type = MCP_OPT_NUMBER,
     .offset = B(far_spp),
     .meta = "N",
     .def = "1e+06",
     .group = "Curves and weights",
     .doc = "N of Eq. 11",
     .lo = 1,
     .bounds = MCP_OPT_LO_OPEN},
    {.name = "max_weight",
     .type = MCP_OPT_NUMBER,
     .offset = B(max_weight),
     .meta = "W",
     .def = "0",
     .group = "Curves and weights",
     .doc = "cap on W in spp (0: none; powerlaw 65536)",
     .bounds = MCP_OPT_LO},
    {.name = "denoiser_keeps_zeros",
     .type = MCP_OPT_FLAG,
     .offset = B(denoiser_keeps_zeros),
     .def = "false",
     .group = "Curves and weights",
     .doc = "all-black pixels take d (else n)"},
    {.name = "filter",
     .type = MCP_OPT_ENUM,
     .offset = B(filter),
     .meta = "NAME",
     .def = "gauss",
     .group = "Estimates",
     .doc = "the filter of v and SURE",
     .words = &mcp_blend_filter_words},
    {.name = "filter_window",
     .type = MCP_OPT_INT,
     .offset = B(filter_window),
     .meta = "N",
     .def = "11",
     .group = "Estimates",
     .doc = "Gaussian window, odd",
     .lo = 1,
     .hi = 255,
     .bounds = MCP_OPT_LO | MCP_OPT_HI},
    {.name = "filter_sigma_scale",
     .type = MCP_OPT_NUMBER,
     .offset = B(filter_sigma_scale),
     .meta = "X",
     .def = "100",
     .group = "Estimates",
     .doc = "sigma = min(sqrt(mean v), 1) x X",
     .bounds = MCP_OPT_LO},
    {.name = "stop_filtering",
     .type = MCP_OPT_FLAG,
     .offset = B(stop_filtering),
     .def = "true",
     .group = "Estimates",
     .doc = "stop filtering for good once mean v < mean SURE"},
    {.name = "negative_sure",
     .type = MCP_OPT_ENUM,
     .offset = B(negative_sure),
     .meta = "NAME",
     .def = "switch",
     .group = "Estimates",
     .doc = "switch (zero, then magnitude once mean v < mean SURE), zero or magnitude",
     .words = &mcp_neg_sure_words},
    {.name = "n_probes",
     .type = MCP_OPT_INT,
     .offset = offsetof(S, o.sure.n_probes),
     .meta = "K",
     .def = "1",
     .group = "Estimates",
     .doc = "SURE probes",
     .lo = 1,
     .hi = 1024,
     .bounds = MCP_OPT_LO | MCP_OPT_HI},
    {.name = "seed",
     .type = MCP_OPT_SEED,
     .offset = offsetof(S, o.sure.seed),
     .meta = "S",
     .def = "0",
     .group = "Estimates",
     .doc = "SURE probe seed"},
    {.name = "js_window",
     .type = MCP_OPT_INT,
     .offset = B(js_window),
     .meta = "N",
     .def = "15",
     .group = "Estimates",
     .doc = "James-Stein window, odd (also the safeguard's)",
     .lo = 3,
     .hi = 255,
     .bounds = MCP_OPT_LO | MCP_OPT_HI},
    {.name = "safeguard",
     .type = MCP_OPT_FLAG,
     .offset = B(safeguard),
     .def = "true",
     .group = "Estimates",
     .doc =
         "cap the curve weights where the denoised image differs from the noisy one by "
         "more than its noise explains (docs/blend.md \"The safeguard\")"},
    {.name = "flip",
     .type = MCP_OPT_FLAG,
     .offset = offsetof(S, o.flip),
     .def = "true",
     .group = "Estimates",
     .doc = "HDR-FLIP against the reference"},
    {.name = "variance_from",
     .type = MCP_OPT_ENUM,
     .where = MCP_OPT_CLI | MCP_OPT_PY,
     .offset = offsetof(S, variance_from),
     .meta = "KIND",
     .def = "auto",
     .group = "Estimates",
     .doc = "auto (a member's own variance, or the spread between the series' increments "
            "where they show Variance/n off: stratified samplers), file (each member's "
            "own) or increments (a job: the series input's variance_from)",
     .words = &mcp_series_variance_words},
    {0}};

static void
blend_defaults(void *p)
{
    S *s = p;
    s->o = mcp_blend_series_defaults();
    s->variance_from = MCP_SERIES_VARIANCE_AUTO;
}

static int
blend_finish(void *p)
{
    S *s = p;
    return mcp_blend_options_check(&s->o.blend);
}

const mcp_operation mcp__op_blend = {
    .name = "blend",
    .summary = "blend a progressive render with its denoised images so that it converges "
               "(Denisova & Bocchi)",
    .options = blend_options,
    .size = sizeof(S),
    .defaults = blend_defaults,
    .finish = blend_finish,
    .given_offset = offsetof(S, given),
    .shared = MCP_SHARED_QUIET | MCP_SHARED_JSON | MCP_SHARED_OUTPUT | MCP_SHARED_THREADS,
    .output_doc = "the output folder (a job: a folder in the job's output)",
    .output_def = "blend-out (a job: blend)",
};

const mcp_operation *
mcp_operation_blend(void)
{
    return &mcp__op_blend;
}
