/* series.c: the blend of a whole progressive render and the comparison of the paper's
 * Fig. 4 (docs/mathematics.md §3; Denisova & Bocchi 2024 Sections 2-3).
 *
 * For each member I of the series: d(I) and SURE(I) from one denoiser evaluation with
 * probes (estimate's mcp_error_maps_compute, plain SURE), or d(I') and SURE(I') kept
 * from the last member at or below stop_denoising_at; the estimates prepared with the
 * series' rule state; curves; weights; the curve, easy and James-Stein blends; and,
 * with a reference, ideal blending and MSE, relMSE and HDR-FLIP of every method.
 *
 * On the fly this is one pass that holds one member at a time; last_two also keeps
 * every member's filtered v (one image each). Retrospective curves need every member's
 * filtered v first, so a first pass prepares all members and keeps their estimates (two
 * images each) and the denoised images and SUREs (two images per denoised member); the
 * second pass reloads each dump and finishes it. */
#include "blend.h"
#include "internal.h"
#include "../common/dump/internal.h" /* members without the parts nothing reads */
#include "../estimate/internal.h"

#include <mcpost/metrics.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const method_names[MCP_BLEND_N_METHODS] = {
    "noisy", "denoised", "easy", "curves", "ideal", "james_stein"};

const char *
mcp_blend_method_name(mcp_blend_method m)
{
    return (unsigned)m < MCP_BLEND_N_METHODS ? method_names[m] : "?";
}

mcp_blend_series_options
mcp_blend_series_defaults(void)
{
    mcp_blend_series_options o;
    memset(&o, 0, sizeof o);
    o.blend = mcp_blend_defaults();
    o.stop_denoising_at = 0;
    o.sure = mcp_sure_defaults();
    o.sure.metric = MCP_METRIC_SE;
    o.flip = 1;
    o.flip_opt = mcp_flip_defaults();
    return o;
}

void
mcp_blend_series_result_free(mcp_blend_series_result *r)
{
    if (!r) return;
    free(r->rows);
    free(r);
}

/* ---- the run ---- */

/* A denoised image and its raw SURE, from member `from`. */
typedef struct {
    mcp_image *denoised, *sure;
    double kappa[3]; /* the denoiser's self-influence at `from` (self_influence.c) */
} den_pair;

typedef struct {
    const mcp_series *series;
    const mcp_denoiser *den;
    const mcp_image *reference;
    const mcp_blend_series_options *o;
    mcp_blend_series_result *res;
    den_pair *pairs;          /* per member; non-NULL where the denoiser ran */
    int *pair_of;             /* the member whose pair member i uses */
    mcp_blend_estimates *est; /* per member (retrospective keeps them all) */
    mcp_blend_state state;
    double stop_spp; /* I' limit (inf: never stop) */
} run;

static void
pair_free(den_pair *p)
{
    mcp_image_free(p->denoised);
    mcp_image_free(p->sure);
    p->denoised = p->sure = NULL;
}

/* Loads member i and checks what blending needs of it. */
static int
load_member(const run *r, int i, mcp_dump **out)
{
    mcp_dump *d = NULL;
    /* the features only when the denoiser or joint SURE reads them */
    if (mcp__series_load_without(
            r->series, i, mcp__dump_parts_unread(r->den, r->o->sure.features != NULL),
            &d))
        return -1;
    const char *why = !d->var_of_mean               ? "has no variance"
                      : d->spp_map || !(d->spp > 0) ? "has no scalar sample count"
                                                    : NULL;
    const char *hint =
        !d->var_of_mean
            ? mcp__no_variance_hint(d, " (blend needs the variance of the mean)")
            : "";
    if (!why && r->reference && !mcp_image_same_size(d->color, r->reference))
        why = "does not match the reference's size";
    if (why) {
        mcp_error("blend: %s %s%s", d->source, why, hint);
        mcp_dump_free(d);
        return -1;
    }
    r->res->variance_source = d->variance_source; /* the last member's, in the end */
    if (i > 0 && !(d->spp > r->res->rows[i - 1].spp)) {
        mcp_error("blend: %s: spp %g does not increase (the member before has %g)",
                  d->source, d->spp, r->res->rows[i - 1].spp);
        mcp_dump_free(d);
        return -1;
    }
    *out = d;
    return 0;
}

/* Step 1 of member i: d and SURE (new or kept) and the prepared estimates. */
static int
prepare_member(run *r, int i, const mcp_dump *dump)
{
    mcp_blend_row *row = &r->res->rows[i];
    row->spp = dump->spp;
    /* The denoiser runs up to I' (and always on the first member, so that d exists). */
    int last = i > 0 ? r->pair_of[i - 1] : -1;
    if (last < 0 || dump->spp <= r->stop_spp) {
        mcp_error_maps maps;
        mcp_sure_options so = r->o->sure;
        so.metric = MCP_METRIC_SE; /* blending compares SURE with v: absolute units */
        if (mcp_error_maps_compute(dump, r->den, &so, &maps))
            return mcp_error_prefix("%s: ", dump->source);
        r->pairs[i].denoised = maps.denoised;
        r->pairs[i].sure = maps.sure;
        maps.denoised = maps.sure = NULL;
        mcp_error_maps_free(&maps);
        /* read at I' and kept with d(I'): in a progressive render n(I) holds n(I')'s
           samples with weight I'/I, so Cov(n(I), d(I')) / sum v(I) is the same ratio */
        if (mcp_blend_self_influence(dump->color, r->pairs[i].denoised, dump->var_of_mean,
                                     r->pairs[i].sure, r->pairs[i].kappa))
            return mcp_error_prefix("%s: ", dump->source);
        r->pair_of[i] = i;
        /* on the fly, the older pair is no longer needed */
        if (last >= 0 && r->o->blend.fit != MCP_CURVE_FIT_RETROSPECTIVE)
            pair_free(&r->pairs[last]);
    } else {
        r->pair_of[i] = last;
    }
    row->denoised_spp = r->res->rows[r->pair_of[i]].spp;
    const double *kappa = r->pairs[r->pair_of[i]].kappa;
    row->self_influence = (kappa[0] + kappa[1] + kappa[2]) / 3;
    const mcp_blend_estimates *e = &r->est[i];
    if (mcp_blend_prepare(dump->var_of_mean, r->pairs[r->pair_of[i]].sure, &r->o->blend,
                          r->den, &r->state, &r->est[i]))
        return mcp_error_prefix("%s: ", dump->source);
    row->mean_var = e->mean_var;
    row->mean_sure = e->mean_sure;
    row->filtered = e->filtered;
    row->magnitude = e->magnitude;
    return 0;
}

/* The errors of img against the reference. */
static int
errors_of(const run *r, const mcp_image *img, mcp_blend_errors *e)
{
    e->flip_hdr = NAN;
    if (mcp_mse(img, r->reference, &e->mse) ||
        mcp_relmse(img, r->reference, MCP_EPS_REL, &e->relmse))
        return -1;
    if (r->o->flip) {
        mcp_flip_result fr;
        if (mcp_flip_hdr(img, r->reference, &r->o->flip_opt, &fr, NULL, NULL)) return -1;
        e->flip_hdr = fr.mean;
    }
    return 0;
}

/* The mean share of d, W / (I + W). */
static double
mean_rho(const mcp_image *weights, double spp)
{
    size_t n = (size_t)weights->width * weights->height * 3;
    double sum = 0;
    for (size_t i = 0; i < n; i++)
        sum += mcp__rho_of_weight(spp, weights->data[i]);
    return sum / (double)n;
}

/* Step 2 of member i: weights, the blends, errors and the caller's turn. */
static int
finish_member(run *r, int i, const mcp_dump *dump, const mcp_image *curves,
              mcp_blend_point_fn on_point, void *ctx)
{
    mcp_blend_row *row = &r->res->rows[i];
    const den_pair *pair = &r->pairs[r->pair_of[i]];
    mcp_blend_estimates *e = &r->est[i];
    mcp_image *weights = NULL, *img[MCP_BLEND_N_METHODS] = {NULL}, *ideal_w = NULL,
              *js_rho = NULL;
    int rc = -1;
    mcp_blend_input in = {dump->color,    dump->var_of_mean, dump->spp,
                          pair->denoised, pair->sure,        curves,
                          pair->kappa};
    if ((curves ? mcp_blend_weights(curves, e->sure, &r->o->blend, &weights) ||
                      mcp_blend_mix(dump->color, dump->spp, pair->denoised, weights,
                                    &img[MCP_BLEND_CURVES])
                : mcp__blend_on_the_fly(&in, &r->o->blend, e, &weights,
                                        &img[MCP_BLEND_CURVES])) ||
        mcp_blend_easy(dump->color, pair->denoised, e->var_of_mean, e->sure,
                       &img[MCP_BLEND_EASY]) ||
        mcp_blend_james_stein(dump->color, pair->denoised, dump->var_of_mean,
                              r->o->blend.js_window, pair->kappa,
                              &img[MCP_BLEND_JAMES_STEIN], &js_rho) ||
        (r->o->blend.safeguard &&
         mcp_blend_safeguard(dump->color, dump->spp, pair->denoised, js_rho, weights,
                             img[MCP_BLEND_CURVES], &row->safeguard_pulled)) ||
        (r->reference && mcp_blend_ideal(dump->color, dump->spp, pair->denoised,
                                         r->reference, &img[MCP_BLEND_IDEAL], &ideal_w)))
        goto fail;
    if (r->res->method == MCP_BLEND_JAMES_STEIN) {
        /* the blend is the combiner's: its W replaces the curves' */
        mcp_image *w = NULL;
        if (mcp__blend_weights_from_rho(js_rho, dump->spp, &w)) goto fail;
        mcp_image_free(weights);
        weights = w;
    }
    row->mean_rho = mean_rho(weights, dump->spp);
    const mcp_image *all[MCP_BLEND_N_METHODS];
    for (int m = 0; m < MCP_BLEND_N_METHODS; m++)
        all[m] = img[m];
    all[MCP_BLEND_NOISY] = dump->color;
    all[MCP_BLEND_DENOISED] = pair->denoised;
    for (int m = 0; m < MCP_BLEND_N_METHODS; m++) {
        row->err[m].mse = row->err[m].relmse = row->err[m].flip_hdr = NAN;
        if (r->reference && errors_of(r, all[m], &row->err[m])) goto fail;
    }
    if (on_point) {
        mcp_blend_point p;
        memset(&p, 0, sizeof p);
        p.index = i;
        p.count = r->series->count;
        p.source = dump->source;
        p.row = row;
        for (int m = 0; m < MCP_BLEND_N_METHODS; m++)
            p.images[m] = all[m];
        p.weights = weights;
        p.method = r->res->method;
        p.ideal_weights = ideal_w;
        p.est = e;
        rc = on_point(&p, ctx) ? -1 : 0; /* the caller's message, unchanged */
    } else {
        rc = 0;
    }
    goto done;
fail:
    mcp_error_prefix("%s: ", dump->source);
done:
    mcp_image_free(weights);
    mcp_image_free(ideal_w);
    mcp_image_free(js_rho);
    for (int m = 0; m < MCP_BLEND_N_METHODS; m++)
        mcp_image_free(img[m]);
    return rc;
}

static int
run_series(run *r, mcp_blend_point_fn on_point, void *ctx)
{
    int n = r->series->count;
    mcp_curve_fit fit = r->o->blend.fit;
    mcp_image *curves = NULL;
    mcp_dump *dump = NULL;
    const mcp_image **v = mcp_calloc((size_t)n, sizeof *v);
    double *spp = mcp_calloc((size_t)n, sizeof *spp);
    int rc = -1;
    if (!v || !spp) goto done;
    for (int i = 0; i < n; i++) {
        if (load_member(r, i, &dump) || prepare_member(r, i, dump)) goto done;
        v[i] = r->est[i].var_of_mean;
        spp[i] = r->res->rows[i].spp;
        if (fit == MCP_CURVE_FIT_ON_THE_FLY) {
            /* weights in closed form, no curve image */
            if (finish_member(r, i, dump, NULL, on_point, ctx)) goto done;
            mcp_blend_estimates_free(&r->est[i]);
        } else if (fit == MCP_CURVE_FIT_LAST_TWO) {
            /* curves from the filtered v of this member and the ones before */
            if (mcp_blend_curves(v, spp, i + 1, &r->o->blend, &curves) ||
                finish_member(r, i, dump, curves, on_point, ctx))
                goto done;
            mcp_image_free(curves);
            curves = NULL;
            mcp_image_free(r->est[i].sure); /* v stays for the next members */
            r->est[i].sure = NULL;
        }
        mcp_dump_free(dump);
        dump = NULL;
    }
    if (fit == MCP_CURVE_FIT_RETROSPECTIVE) {
        if (mcp_blend_curves(v, spp, n, &r->o->blend, &curves)) goto done;
        for (int i = 0; i < n; i++) {
            if (load_member(r, i, &dump) ||
                finish_member(r, i, dump, curves, on_point, ctx))
                goto done;
            mcp_dump_free(dump);
            dump = NULL;
        }
    }
    rc = 0;
done:
    free(v);
    free(spp);
    mcp_image_free(curves);
    mcp_dump_free(dump);
    return rc;
}

int
mcp_blend_series(const mcp_series *series, const mcp_denoiser *den,
                 const mcp_image *reference, const mcp_blend_series_options *opt,
                 mcp_blend_point_fn on_point, void *ctx, mcp_blend_series_result **out)
{
    *out = NULL;
    mcp_blend_series_options defaults = mcp_blend_series_defaults();
    const mcp_blend_series_options *o = opt ? opt : &defaults;
    if (!series || series->count < 1)
        return mcp_error("blend: the series has no members");
    if (!den) return mcp_error("blend: a denoiser is required");
    if (mcp_blend_options_check(&o->blend)) return -1;
    if (!(o->stop_denoising_at >= 0) || isinf(o->stop_denoising_at))
        return mcp_error("blend: stop_denoising_at must be finite and >= 0 (got %g)",
                         o->stop_denoising_at);
    if (reference) {
        mcp__rgb rgb;
        if (mcp__blend_rgb(reference, "reference", &rgb)) return -1;
    }
    int n = series->count, rc = -1;
    run r;
    memset(&r, 0, sizeof r);
    r.series = series;
    r.den = den;
    r.reference = reference;
    r.o = o;
    r.stop_spp = o->stop_denoising_at > 0 ? o->stop_denoising_at : INFINITY;
    r.res = mcp_calloc(1, sizeof *r.res);
    r.pairs = mcp_calloc((size_t)n, sizeof *r.pairs);
    r.pair_of = mcp_calloc((size_t)n, sizeof *r.pair_of);
    r.est = mcp_calloc((size_t)n, sizeof *r.est);
    if (!r.res || !r.pairs || !r.pair_of || !r.est ||
        !(r.res->rows = mcp_calloc((size_t)n, sizeof *r.res->rows)))
        goto done;
    r.res->count = n;
    r.res->has_reference = reference != NULL;
    r.res->has_flip = reference != NULL && o->flip;
    r.res->method = o->blend.weights == MCP_BLEND_WEIGHTS_JAMES_STEIN
                        ? MCP_BLEND_JAMES_STEIN
                        : MCP_BLEND_CURVES;
    if (run_series(&r, on_point, ctx)) goto done;
    *out = r.res;
    r.res = NULL;
    rc = 0;
done:
    if (r.pairs)
        for (int i = 0; i < n; i++)
            pair_free(&r.pairs[i]);
    if (r.est)
        for (int i = 0; i < n; i++)
            mcp_blend_estimates_free(&r.est[i]);
    free(r.pairs);
    free(r.pair_of);
    free(r.est);
    mcp_blend_series_result_free(r.res);
    return rc;
}
