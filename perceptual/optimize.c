/* optimize.c: the perceptual options, their checks, method names, and running a
 * method by name (docs/mathematics.md §4). */
#define _POSIX_C_SOURCE 200809L /* strcasecmp */
#include "internal.h"

#include <stdlib.h>
#include <string.h>
#include <strings.h>

static const char *const method_names[MCP_PERC_N_METHODS] = {
    "vertical-iterative", "power-set", "error-diffusion", "dither",
    "horizontal",         "histogram", "permutation"};

const mcp_wordlist mcp_perc_method_words = {"perceptual method", method_names,
                                            MCP_PERC_N_METHODS};

int
mcp_perc_method_from_name(const char *name, mcp_perc_method *out)
{
    return mcp_wordlist_find(&mcp_perc_method_words, name, (int *)out);
}

const char *
mcp_perc_method_name(mcp_perc_method method)
{
    return (unsigned)method < MCP_PERC_N_METHODS ? method_names[method] : "unknown";
}

int
mcp_perc_method_is_horizontal(mcp_perc_method method)
{
    return method == MCP_PERC_HORIZONTAL || method == MCP_PERC_PERMUTATION;
}

static const char *const init_names[] = {"random", "mean"};
const mcp_wordlist mcp_perc_init_words = {"start", init_names, 2};

int
mcp_perc_init_from_name(const char *name, mcp_perc_init *out)
{
    return mcp_wordlist_find(&mcp_perc_init_words, name, (int *)out);
}

const char *
mcp_perc_init_name(mcp_perc_init init)
{
    return init == MCP_PERC_INIT_MEAN ? "mean" : "random";
}

mcp_perc_options
mcp_perc_defaults(void)
{
    mcp_perc_options o;
    memset(&o, 0, sizeof o);
    o.method = MCP_PERC_VERTICAL_ITERATIVE;
    o.model = mcp_perc_model_defaults();
    o.passes = 0;
    o.init = MCP_PERC_INIT_RANDOM;
    o.seed = 1;
    o.max_subsets = 64;
    o.radius = 1;
    o.travel = 1;
    o.tile = 8;
    o.mask = mcp_blue_noise_defaults();
    return o;
}

int
mcp_perc_check(const mcp_perc_options *o)
{
    if ((unsigned)o->method >= MCP_PERC_N_METHODS)
        return mcp_error("perceptual: unknown method %d", (int)o->method);
    if ((unsigned)o->model.tone_map > MCP_TONEMAP_REINHARD)
        return mcp_error("perceptual: unknown tone map %d", (int)o->model.tone_map);
    if (!o->model.confidence_map &&
        !(o->model.confidence >= 0.0 && o->model.confidence <= 1.0))
        return mcp_error("perceptual: confidence must be in [0, 1] (got %g)",
                         o->model.confidence);
    if (o->passes < 0)
        return mcp_error(
            "perceptual: passes must be >= 0 (got %d; 0: the method's default)",
            o->passes);
    if ((unsigned)o->init > MCP_PERC_INIT_MEAN)
        return mcp_error("perceptual: unknown start %d", (int)o->init);
    if (o->max_subsets < 1)
        return mcp_error("perceptual: max_subsets must be >= 1 (got %d)", o->max_subsets);
    if (o->radius < 1 || o->radius > 8)
        return mcp_error("perceptual: radius must be in [1, 8] (got %d)", o->radius);
    if (o->travel < o->radius)
        return mcp_error(
            "perceptual: travel must be >= radius (got travel %d, radius %d)", o->travel,
            o->radius);
    if (o->tile < 2 || o->tile > 256)
        return mcp_error("perceptual: tile must be in [2, 256] (got %d)", o->tile);
    if (o->mask.size < 4 || o->mask.size > 1024)
        return mcp_error("perceptual: mask_size must be in [4, 1024] (got %d)",
                         o->mask.size);
    if (!(o->mask.sigma > 0.0 && o->mask.sigma <= o->mask.size / 4.0))
        return mcp_error("perceptual: mask_sigma must be in (0, mask_size/4] (got %g)",
                         o->mask.sigma);
    return 0;
}

int
mcp__check_run(const mcp_perc_options *opt, const mcp_image *const *cands, int m,
               const mcp_image *surrogate)
{
    if (mcp_perc_check(opt) || mcp__check_candidates(cands, m, surrogate, NULL))
        return -1;
    if (opt->model.confidence_map &&
        !mcp_image_same_size(opt->model.confidence_map, cands[0]))
        return -1;
    return 0;
}

void
mcp_perc_result_free(mcp_perc_result *r)
{
    if (!r) return;
    mcp_image_free(r->image);
    mcp_image_free(r->index);
    mcp_image_free(r->permutation);
    memset(r, 0, sizeof *r);
}

int
mcp_perc_optimize(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                  const mcp_perc_options *opt, mcp_perc_result *out)
{
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    if (mcp_perc_check(opt)) return -1;
    mcp_image *mean = NULL;
    int rc = -1;
    switch (opt->method) {
    case MCP_PERC_VERTICAL_ITERATIVE:
        return mcp_perc_vertical_iterative(cands, m, surrogate, opt, out);
    case MCP_PERC_POWER_SET:
        return mcp_perc_power_set(cands, m, surrogate, opt, out);
    case MCP_PERC_ERROR_DIFFUSION:
        return mcp_perc_error_diffusion(cands, m, surrogate, opt, out);
    case MCP_PERC_DITHER:
        return mcp_perc_dither(cands, m, surrogate, opt, out);
    case MCP_PERC_HISTOGRAM:
        return mcp_perc_histogram(cands, m, opt, out);
    case MCP_PERC_HORIZONTAL:
    case MCP_PERC_PERMUTATION:
        /* one estimate per pixel: the candidates' mean */
        if (mcp_perc_mean(cands, m, &mean)) return -1;
        rc = opt->method == MCP_PERC_HORIZONTAL
                 ? mcp_perc_horizontal(mean, surrogate, opt, out)
                 : mcp_perc_permutation(mean, opt, out);
        mcp_image_free(mean);
        return rc;
    default:
        return mcp_error("perceptual: unknown method %d", (int)opt->method);
    }
}
