/* options.c: the blend options, their defaults (docs/mathematics.md §3 [brackets]),
 * checks and names. */
#include "blend.h"

#include <math.h>
#include <string.h>

mcp_blend_options
mcp_blend_defaults(void)
{
    mcp_blend_options o;
    memset(&o, 0, sizeof o);
    o.fit = MCP_CURVE_FIT_ON_THE_FLY;
    o.curve = MCP_CURVE_LOG;
    o.far_spp = 1e6;
    o.filter = MCP_BLEND_FILTER_GAUSS;
    o.filter_window = 11;
    o.filter_sigma_scale = 100;
    o.stop_filtering = 1;
    o.negative_sure = MCP_NEG_SURE_SWITCH;
    o.denoiser_keeps_zeros = 0;
    o.max_weight = 0;
    o.powerlaw_offset = 100;
    o.js_window = 15;
    o.safeguard = 1;
    o.weights = MCP_BLEND_WEIGHTS_JAMES_STEIN;
    return o;
}

int
mcp_blend_options_check(const mcp_blend_options *o)
{
    if (o->fit != MCP_CURVE_FIT_ON_THE_FLY && o->fit != MCP_CURVE_FIT_RETROSPECTIVE &&
        o->fit != MCP_CURVE_FIT_LAST_TWO)
        return mcp_error(
            "blend: fit must be on_the_fly, retrospective or last_two (got %d)",
            (int)o->fit);
    if (o->curve != MCP_CURVE_LOG && o->curve != MCP_CURVE_POWERLAW)
        return mcp_error("blend: curve must be log or powerlaw (got %d)", (int)o->curve);
    if (!(o->far_spp > 1) || !isfinite(o->far_spp))
        return mcp_error("blend: far_spp must be finite and > 1 (got %g)", o->far_spp);
    if (o->filter != MCP_BLEND_FILTER_GAUSS && o->filter != MCP_BLEND_FILTER_DENOISER &&
        o->filter != MCP_BLEND_FILTER_NONE)
        return mcp_error("blend: filter must be gauss, denoiser or none (got %d)",
                         (int)o->filter);
    if (o->filter_window < 1 || o->filter_window % 2 == 0 || o->filter_window > 255)
        return mcp_error("blend: filter_window must be odd and in [1, 255] (got %d)",
                         o->filter_window);
    if (!(o->filter_sigma_scale >= 0) || !isfinite(o->filter_sigma_scale))
        return mcp_error("blend: filter_sigma_scale must be finite and >= 0 (got %g)",
                         o->filter_sigma_scale);
    if (o->negative_sure != MCP_NEG_SURE_SWITCH &&
        o->negative_sure != MCP_NEG_SURE_ZERO &&
        o->negative_sure != MCP_NEG_SURE_MAGNITUDE)
        return mcp_error(
            "blend: negative_sure must be switch, zero or magnitude (got %d)",
            (int)o->negative_sure);
    if (!(o->max_weight >= 0))
        return mcp_error("blend: max_weight must be >= 0 (got %g)", o->max_weight);
    if (!(o->powerlaw_offset > 0) || !isfinite(o->powerlaw_offset))
        return mcp_error("blend: powerlaw_offset must be finite and > 0 (got %g)",
                         o->powerlaw_offset);
    if (o->js_window < 3 || o->js_window % 2 == 0 || o->js_window > 255)
        return mcp_error("blend: js_window must be odd and in [3, 255] (got %d)",
                         o->js_window);
    if (o->safeguard != 0 && o->safeguard != 1)
        return mcp_error("blend: safeguard must be 0 or 1 (got %d)", o->safeguard);
    if (o->weights != MCP_BLEND_WEIGHTS_JAMES_STEIN &&
        o->weights != MCP_BLEND_WEIGHTS_CURVES)
        return mcp_error("blend: weights must be james_stein or curves (got %d)",
                         (int)o->weights);
    return 0;
}

/* ---- names: the enums' words (<mcpost/wordlist.h>) ---- */

static const char *const fit_names[] = {"on_the_fly", "retrospective", "last_two"};
static const char *const curve_names[] = {"log", "powerlaw"};
static const char *const filter_names[] = {"gauss", "denoiser", "none"};
static const char *const neg_names[] = {"switch", "zero", "magnitude"};
static const char *const weighting_names[] = {"james_stein", "curves"};

const mcp_wordlist mcp_curve_fit_words = {"curve fit", fit_names, 3};
const mcp_wordlist mcp_curve_model_words = {"curve", curve_names, 2};
const mcp_wordlist mcp_blend_filter_words = {"estimate filter", filter_names, 3};
const mcp_wordlist mcp_neg_sure_words = {"negative-SURE rule", neg_names, 3};
const mcp_wordlist mcp_blend_weighting_words = {"blend weights", weighting_names, 2};

int
mcp_curve_fit_from_name(const char *name, mcp_curve_fit *out)
{
    return mcp_wordlist_find(&mcp_curve_fit_words, name, (int *)out);
}

int
mcp_curve_model_from_name(const char *name, mcp_curve_model *out)
{
    return mcp_wordlist_find(&mcp_curve_model_words, name, (int *)out);
}

int
mcp_blend_filter_from_name(const char *name, mcp_blend_filter *out)
{
    return mcp_wordlist_find(&mcp_blend_filter_words, name, (int *)out);
}

int
mcp_neg_sure_from_name(const char *name, mcp_neg_sure *out)
{
    return mcp_wordlist_find(&mcp_neg_sure_words, name, (int *)out);
}

int
mcp_blend_weighting_from_name(const char *name, mcp_blend_weighting *out)
{
    return mcp_wordlist_find(&mcp_blend_weighting_words, name, (int *)out);
}

const char *
mcp_curve_fit_name(mcp_curve_fit f)
{
    return mcp_wordlist_name(&mcp_curve_fit_words, (int)f);
}

const char *
mcp_curve_model_name(mcp_curve_model m)
{
    return mcp_wordlist_name(&mcp_curve_model_words, (int)m);
}

const char *
mcp_blend_filter_name(mcp_blend_filter f)
{
    return mcp_wordlist_name(&mcp_blend_filter_words, (int)f);
}

const char *
mcp_neg_sure_name(mcp_neg_sure n)
{
    return mcp_wordlist_name(&mcp_neg_sure_words, (int)n);
}

const char *
mcp_blend_weighting_name(mcp_blend_weighting w)
{
    return mcp_wordlist_name(&mcp_blend_weighting_words, (int)w);
}
