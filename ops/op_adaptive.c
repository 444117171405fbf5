/* op_adaptive.c: the options of `adaptive` (docs/adaptive.md), once for the command
 * line and the job stage (options.h). */
#include "internal.h"

#include <stddef.h>

#define S mcp_adaptive_settings
#define AO(f) offsetof(S, ao.f)
#define CJ (MCP_OPT_CLI | MCP_OPT_JOB)

static const mcp_option adaptive_options[] = {
    {.name = "render",
     .type = MCP_OPT_TEXT,
     .where = CJ,
     .offset = offsetof(S, render),
     .meta = "CMD",
     .doc =
         "the render command, run by /bin/sh once per pass; it must render {counts}(p) "
         "new samples in pixel p (an EXR with channel SampleCount) from samples no "
         "earlier pass used, and write a dump with those counts to {output}; {pass} "
         "(0, 1, ...) and {seed} are numbers for it to use (required)"},
    {.name = "size",
     .type = MCP_OPT_TEXT,
     .where = CJ,
     .offset = offsetof(S, size),
     .meta = "WxH",
     .doc = "the image size [the reference's]"},
    {.name = "map",
     .type = MCP_OPT_ENUM,
     .where = CJ,
     .offset = AO(map),
     .meta = "KIND",
     .def = "variance",
     .doc = "the sampling map",
     .words = &mcp_adaptive_map_words},
    {.name = "spp_per_iteration",
     .type = MCP_OPT_NUMBER,
     .where = CJ,
     .offset = AO(spp_per_iteration),
     .meta = "N",
     .def = "32",
     .doc = "new samples per pixel per pass, on average"},
    {.name = "initial_spp",
     .type = MCP_OPT_NUMBER,
     .where = CJ,
     .offset = AO(initial_spp),
     .meta = "N",
     .def = "0",
     .doc = "the first pass, uniform (0: spp_per_iteration)"},
    {.name = "budget",
     .type = MCP_OPT_NUMBER,
     .where = CJ,
     .offset = AO(budget_spp),
     .meta = "SPP",
     .def = "0",
     .doc = "stop at this many samples per pixel in all, on average (0: none)"},
    {.name = "stop",
     .type = MCP_OPT_FLAG,
     .where = CJ,
     .offset = AO(stop_on_estimate),
     .def = "false",
     .doc = "stop when the estimate says F(tau) >= p (as estimate)"},
    {.name = "tau",
     .type = MCP_OPT_NUMBER,
     .where = CJ,
     .offset = AO(est.tau),
     .meta = "T",
     .def = "0.01",
     .doc = "the stopping criterion's threshold"},
    {.name = "percentile",
     .type = MCP_OPT_NUMBER,
     .where = CJ,
     .offset = AO(est.p),
     .meta = "P",
     .def = "0.999",
     .doc = "the fraction of values that must be below tau"},
    {.name = "max_iterations",
     .type = MCP_OPT_INT,
     .where = CJ,
     .offset = AO(max_iterations),
     .meta = "N",
     .def = "1000",
     .doc = "passes at most"},
    {.name = "quantum",
     .type = MCP_OPT_INT,
     .where = CJ,
     .offset = AO(quantum),
     .meta = "Q",
     .def = "1",
     .doc =
         "counts in multiples of Q: K*K for a renderer that draws stratified passes of "
         "K*K samples"},
    {.name = "uniform_mix",
     .type = MCP_OPT_NUMBER,
     .where = CJ,
     .offset = AO(uniform_mix),
     .meta = "F",
     .def = "0",
     .doc = "share of every pass spread evenly, the rest by the map: a floor for rare "
            "paths no pixel has drawn yet",
     .lo = 0,
     .hi = 1,
     .bounds = MCP_OPT_LO | MCP_OPT_HI},
    {.name = "probes",
     .type = MCP_OPT_INT,
     .where = CJ,
     .offset = AO(est.sure.n_probes),
     .meta = "N|auto",
     .def = "auto",
     .doc = "probes of the estimate; auto: the denoiser's (3 for unet, else 4)",
     .lo = 1,
     .hi = 1024,
     .bounds = MCP_OPT_LO | MCP_OPT_HI,
     .auto_word = "auto",
     .auto_value = -1},
    {.name = "seed",
     .type = MCP_OPT_SEED,
     .where = CJ,
     .offset = offsetof(S, seed),
     .meta = "S",
     .def = "1",
     .doc = "the {seed} of the command, and the probes'"},
    {.name = "reference",
     .type = MCP_OPT_INPUT,
     .where = CJ,
     .offset = offsetof(S, reference),
     .meta = "REF",
     .doc = "the converged image: relMSE per pass"},
    {.name = "keep_passes",
     .type = MCP_OPT_FLAG,
     .where = CJ,
     .offset = offsetof(S, keep_passes),
     .def = "false",
     .doc = "keep every pass's counts and dump in the output folder"},
    {.name = "denoiser",
     .type = MCP_OPT_DENOISER,
     .where = CJ,
     .meta = "NAME",
     .def = "default",
     .doc = "the denoiser: `default` is unet with the shipped weights, nlm for dumps "
            "without albedo and normal"},
    {0}};

static void
adaptive_defaults(void *p)
{
    S *s = p;
    s->ao = mcp_adaptive_defaults();
    s->seed = 1;
}

/* the seed is the command's and the probes'; then the library's check */
static int
adaptive_finish(void *p)
{
    S *s = p;
    s->ao.est.sure.seed = s->seed;
    return mcp_adaptive_check(&s->ao);
}

const mcp_operation mcp__op_adaptive = {
    .name = "adaptive",
    .summary = "the adaptive-sampling loop: render, denoise, map, render more",
    .options = adaptive_options,
    .size = sizeof(S),
    .defaults = adaptive_defaults,
    .finish = adaptive_finish,
    .given_offset = offsetof(S, given),
    .shared = MCP_SHARED_QUIET | MCP_SHARED_JSON | MCP_SHARED_OUTPUT | MCP_SHARED_THREADS,
    .output_doc =
        "the outputs: accumulated.exr, denoised.exr, adaptive.json, adaptive.csv, "
        "adaptive.svg, maps/*.png (a job: a folder in the job's output; required "
        "on the command line)",
    .output_def = "a job: adaptive",
};

const mcp_operation *
mcp_operation_adaptive(void)
{
    return &mcp__op_adaptive;
}
