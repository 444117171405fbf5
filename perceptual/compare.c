/* compare.c: scoring an optimised image and comparing every method on one input
 * (Chizhov et al. 2022 Table 1; docs/mathematics.md §4.3: pMSE = E / (N C) against the
 * ground truth, and the blue-noise analysis of the error). pMSE, MSE and the spectra come
 * from common/ (metrics.h, spectra.h); only a user kernel, which metrics.h does not
 * know, is scored with this module's own energy (the same formula). */
#include "../common/core/internal.h" /* progress on a terminal */
#include "internal.h"

#include <mcpost/metrics.h>
#include <mcpost/report.h>
#include <mcpost/spectra.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

int
mcp_perc_score(const mcp_image *img, const mcp_image *surrogate, const mcp_image *qinit,
               const mcp_image *reference, const mcp_perc_model *model, int spectra_tile,
               mcp_perc_scores *out, mcp_image **spectrum)
{
    mcp_perc_model d = mcp_perc_model_defaults();
    if (!model) model = &d;
    out->energy = out->pmse = out->mse = NAN;
    out->low_freq_fraction = out->white_fraction = NAN;
    if (spectrum) *spectrum = NULL;
    double e, nc = 3.0 * img->width * img->height;
    if (surrogate) {
        if (mcp_perc_energy(img, surrogate, qinit, model, &e)) return -1;
        out->energy = e / nc;
    }
    if (!reference) return 0;
    if (mcp_mse(img, reference, &out->mse)) return -1;
    if (model->user_kernel) {
        mcp_perc_model truth = *model; /* pMSE: the model at C = 1 against the truth */
        truth.confidence = 1.0;
        truth.confidence_map = NULL;
        if (mcp_perc_energy(img, reference, NULL, &truth, &e)) return -1;
        out->pmse = e / nc;
    } else {
        mcp_pmse_options po = mcp_pmse_defaults();
        po.kernel = model->kernel;
        po.filter_reference = model->filter_surrogate;
        po.tone_map = model->tone_map;
        if (mcp_pmse(img, reference, &po, &out->pmse)) return -1;
    }
    mcp_spectra_options so = mcp_spectra_defaults();
    so.tile_size = spectra_tile > 0 ? spectra_tile : so.tile_size;
    so.tone_map = model->tone_map;
    if (img->width < so.tile_size || img->height < so.tile_size)
        return 0; /* too small to analyse: the fraction stays NaN */
    mcp_spectra_result sr;
    if (mcp_spectra_blue_noise(img, reference, &so, &sr, spectrum)) return -1;
    out->low_freq_fraction = sr.low_fraction;
    out->white_fraction = sr.white_fraction;
    return 0;
}

mcp_perc_compare_options
mcp_perc_compare_defaults(void)
{
    mcp_perc_compare_options o;
    memset(&o, 0, sizeof o);
    o.base = mcp_perc_defaults();
    o.spectra_tile = 32;
    return o;
}

static int
add_row(cJSON *table, const char *method, const mcp_image *img,
        const mcp_image *surrogate, const mcp_image *mean,
        const mcp_perc_compare_options *opt, const mcp_perc_result *r, int rerendered)
{
    mcp_perc_scores sc;
    if (mcp_perc_score(img, surrogate, mean, opt->reference, &opt->base.model,
                       opt->spectra_tile, &sc, NULL))
        return mcp_error_prefix("compare: %s: ", method);
    cJSON *row = cJSON_CreateObject();
    if (!row) return mcp_error("out of memory");
    cJSON_AddStringToObject(row, "method", method);
    mcp_report_add_number(row, "energy", sc.energy);
    if (opt->reference) {
        mcp_report_add_number(row, "pmse", sc.pmse);
        mcp_report_add_number(row, "mse", sc.mse);
        mcp_report_add_number(row, "low_freq_fraction", sc.low_freq_fraction);
    }
    if (r) {
        mcp_report_add_number(row, "seconds", r->seconds);
        cJSON_AddNumberToObject(row, "passes", r->passes);
        cJSON_AddNumberToObject(row, "changes", (double)r->changes);
    }
    if (rerendered >= 0) cJSON_AddBoolToObject(row, "rerendered", rerendered);
    cJSON_AddItemToArray(table, row);
    return 0;
}

int
mcp_perc_compare(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                 const mcp_perc_compare_options *opt, cJSON **table)
{
    mcp_perc_compare_options d = mcp_perc_compare_defaults();
    if (!opt) opt = &d;
    *table = NULL;
    if (!surrogate) return mcp_error("compare: needs a surrogate");
    if (mcp__check_run(&opt->base, cands, m, surrogate) ||
        (opt->reference && !mcp_image_same_size(opt->reference, cands[0])))
        return -1;
    mcp_image *mean = NULL;
    mcp_progress bar;
    int shown = 0;
    cJSON *t = cJSON_CreateArray();
    if (!t) return mcp_error("out of memory");
    if (mcp_perc_mean(cands, m, &mean) ||
        add_row(t, "mean", mean, surrogate, mean, opt, NULL, -1) ||
        (opt->reference &&
         add_row(t, "surrogate", surrogate, surrogate, mean, opt, NULL, -1)))
        goto fail;
    /* on a terminal for a quarter megapixel or more (every method on 4 candidates of
       1080p takes 8 s): a step per method */
    shown = (double)cands[0]->width * cands[0]->height >= 262144.0;
    if (shown) mcp_progress_begin(&bar, "every method", MCP_PERC_N_METHODS);
    for (int k = 0; k < MCP_PERC_N_METHODS; k++) {
        if (shown && k) mcp_progress_update(&bar, k);
        mcp_perc_options o = opt->base;
        o.method = (mcp_perc_method)k;
        mcp_perc_result r;
        mcp_image *again = NULL;
        if (mcp_perc_optimize(cands, m, surrogate, &o, &r)) {
            mcp_error_prefix("compare: %s: ", mcp_perc_method_name(o.method));
            goto fail;
        }
        int horizontal = mcp_perc_method_is_horizontal(o.method), bad = 0;
        if (horizontal && opt->rerender &&
            opt->rerender(opt->rerender_ctx, o.method, r.permutation, &again))
            bad = mcp_error_prefix("compare: %s: re-rendering: ",
                                   mcp_perc_method_name(o.method));
        bad = bad || add_row(t, mcp_perc_method_name(o.method), again ? again : r.image,
                             surrogate, mean, opt, &r, horizontal ? again != NULL : -1);
        bad = bad ||
              (opt->on_result && opt->on_result(opt->on_result_ctx, o.method, &r, again));
        mcp_image_free(again);
        mcp_perc_result_free(&r);
        if (bad) goto fail;
    }
    if (shown) mcp_progress_end(&bar);
    mcp_image_free(mean);
    *table = t;
    return 0;
fail:
    if (shown) mcp__progress_stop(&bar);
    mcp_image_free(mean);
    cJSON_Delete(t);
    return -1;
}
