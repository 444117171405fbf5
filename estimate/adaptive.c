/* adaptive.c: the adaptive-sampling loop (Firmino 2023 §4: render -> denoise ->
 * variance of the denoised image -> sampling map -> render more), with the renderer
 * behind a callback.
 *
 * Every pass renders integer per-pixel counts that sum exactly to its share of the
 * budget (mcp_sample_counts, largest remainders) from samples no earlier pass used;
 * the passes are merged as passes of one render (mcp_dump_merge, pooled), so the
 * accumulated mean and variance of the mean are those of one render of all the
 * samples with the per-pixel n. The first pass is uniform: the map needs a variance to
 * start from. */
#include "estimate.h"
#include "internal.h"

#include <mcpost/metrics.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

static const char *const map_names[] = {"variance", "tonemapped", "mc-sure", "uniform"};

const mcp_wordlist mcp_adaptive_map_words = {"map", map_names, 4};

int
mcp_adaptive_map_from_name(const char *name, mcp_adaptive_map *out)
{
    return mcp_wordlist_find(&mcp_adaptive_map_words, name, (int *)out);
}

const char *
mcp_adaptive_map_name(mcp_adaptive_map map)
{
    return (unsigned)map < 4 ? map_names[map] : "unknown";
}

mcp_adaptive_options
mcp_adaptive_defaults(void)
{
    mcp_adaptive_options o;
    memset(&o, 0, sizeof o);
    o.est = mcp_estimate_defaults();
    o.est.n_percentiles = 0; /* the loop needs the stop decision, not the curve */
    o.map = MCP_ADAPTIVE_VARIANCE;
    o.spp_per_iteration = 32.0; /* Firmino 2023 §5: 32 spp per iteration on average */
    o.initial_spp = 0.0;
    o.budget_spp = 0.0;
    o.stop_on_estimate = 0;
    o.max_iterations = 1000;
    o.quantum = 1;
    return o;
}

int
mcp_adaptive_check(const mcp_adaptive_options *o)
{
    if ((unsigned)o->map > MCP_ADAPTIVE_UNIFORM)
        return mcp_error("adaptive: unknown map %d", (int)o->map);
    if (!(o->spp_per_iteration > 0.0) || !isfinite(o->spp_per_iteration))
        return mcp_error("adaptive: spp_per_iteration must be > 0 (got %g)",
                         o->spp_per_iteration);
    if (!(o->initial_spp >= 0.0) || !isfinite(o->initial_spp))
        return mcp_error("adaptive: initial_spp must be >= 0 (got %g)", o->initial_spp);
    if (!(o->budget_spp >= 0.0) || !isfinite(o->budget_spp))
        return mcp_error("adaptive: budget must be >= 0 (got %g)", o->budget_spp);
    if (o->budget_spp == 0.0 && !o->stop_on_estimate)
        return mcp_error("adaptive: no stop rule: give a budget or stop on the estimate");
    if (o->max_iterations < 1)
        return mcp_error("adaptive: max_iterations must be >= 1 (got %d)",
                         o->max_iterations);
    if (!(o->uniform_mix >= 0.0 && o->uniform_mix <= 1.0))
        return mcp_error("adaptive: uniform_mix must be in [0, 1] (got %g)",
                         o->uniform_mix);
    if (o->quantum < 1 || o->quantum > 1 << 20)
        return mcp_error("adaptive: quantum must be in [1, 2^20] (got %d)", o->quantum);
    return mcp_estimate_check(&o->est);
}

void
mcp_adaptive_result_free(mcp_adaptive_result *r)
{
    if (!r) return;
    free(r->iterations);
    mcp_dump_free(r->accumulated);
    mcp_image_free(r->denoised);
    free(r);
}

/* Counts for `samples` samples (a multiple of quantum) proportional to weights, or
 * uniform when weights is NULL, with the share `mix` of them spread evenly: largest
 * remainders in units of quantum. */
static int
counts_for(int w, int h, const mcp_image *weights, double mix, int64_t samples,
           int quantum, mcp_image **out)
{
    static const char *const name[1] = {"weight"};
    mcp_image *flat = NULL;
    const size_t npix = (size_t)w * h;
    *out = NULL;
    if (!weights) {
        if (mcp__image_new(w, h, 1, name, "uniform map", &flat)) return -1;
        for (size_t i = 0; i < npix; i++)
            flat->data[i] = 1.0f;
        weights = flat;
    } else if (mix > 0.0) {
        /* (1 - mix) of the map's share plus mix of an even one, per pixel */
        double sum = 0.0;
        for (size_t i = 0; i < npix; i++)
            sum += mcp_image_px(weights, (int)(i % w), (int)(i / w))[0];
        if (mcp__image_new(w, h, 1, name, "mixed map", &flat)) return -1;
        for (size_t i = 0; i < npix; i++) {
            double share =
                sum > 0.0 ? mcp_image_px(weights, (int)(i % w), (int)(i / w))[0] / sum
                          : 1.0 / npix;
            flat->data[i] = (float)((1.0 - mix) * share + mix / npix);
        }
        weights = flat;
    }
    int rc = mcp_sample_counts(weights, samples / quantum, out);
    mcp_image_free(flat);
    if (rc) return -1;
    if (quantum > 1)
        for (size_t i = 0; i < (size_t)w * h; i++)
            (*out)->data[i] *= (float)quantum;
    return 0;
}

/* The pass's own count must be what it was asked to render: a renderer that ignores
 * the counts would make every figure after it wrong without a sign. */
int
mcp__adaptive_check_pass(const mcp_dump *part, const mcp_image *counts, int pass)
{
    const mcp_image *c = part->color;
    const char *src = part->source ? part->source : "the pass";
    if (c->width != counts->width || c->height != counts->height)
        return mcp_error("adaptive: pass %d: %s is %dx%d, but the counts are %dx%d", pass,
                         src, c->width, c->height, counts->width, counts->height);
    for (int y = 0; y < c->height; y++)
        for (int x = 0; x < c->width; x++) {
            double want = mcp_image_px(counts, x, y)[0],
                   got = mcp_dump_spp_at(part, x, y);
            if (got != want)
                return mcp_error("adaptive: pass %d: %s has %g samples at pixel (%d, %d) "
                                 "but was given %g (does the render command read "
                                 "{counts} and write a SampleCount?)",
                                 pass, src, got, x, y, want);
        }
    return 0;
}

/* Merges part into *acc (taking it when *acc is empty). Takes ownership of part. */
int
mcp__adaptive_accumulate(mcp_dump **acc, mcp_dump *part)
{
    if (!*acc) {
        *acc = part;
        return 0;
    }
    const mcp_merge_options mo = {MCP_MERGE_POOLED, 0};
    const mcp_dump *parts[2] = {*acc, part};
    mcp_dump *merged = NULL;
    int rc = mcp_dump_merge(parts, 2, &mo, &merged);
    mcp_dump_free(part);
    if (rc) return -1;
    mcp_dump_free(*acc);
    *acc = merged;
    return 0;
}

static int64_t
round_to_quantum(double samples, int quantum)
{
    int64_t q = (int64_t)floor(samples / quantum + 0.5);
    return (q < 1 ? 1 : q) * quantum;
}

int
mcp_adaptive_run(int width, int height, const mcp_denoiser *den,
                 const mcp_adaptive_options *opt, mcp_adaptive_render_fn render,
                 void *render_ctx, const mcp_image *reference,
                 int (*on_iteration)(const mcp_adaptive_state *, void *), void *ctx,
                 mcp_adaptive_result **out)
{
    *out = NULL;
    mcp_adaptive_options o = opt ? *opt : mcp_adaptive_defaults();
    if (mcp_adaptive_check(&o)) return -1;
    if (width < 1 || height < 1 || width > MCP_MAX_DIM || height > MCP_MAX_DIM)
        return mcp_error("adaptive: bad image size %dx%d", width, height);
    if (!den || !render) return mcp_error("adaptive: missing denoiser or renderer");
    if (reference && (reference->width != width || reference->height != height))
        return mcp_error("adaptive: the reference %s is %dx%d, the image %dx%d",
                         reference->source ? reference->source : "", reference->width,
                         reference->height, width, height);
    const double npix = (double)width * height;
    const int64_t per_pass = round_to_quantum(o.spp_per_iteration * npix, o.quantum);
    const int64_t first = round_to_quantum(
        (o.initial_spp > 0 ? o.initial_spp : o.spp_per_iteration) * npix, o.quantum);
    /* the budget in whole quanta, and never below the first pass */
    int64_t budget = INT64_MAX;
    if (o.budget_spp > 0) {
        budget = (int64_t)floor(o.budget_spp * npix / o.quantum) * o.quantum;
        if (budget < first) budget = first;
    }
    o.est.budget = 0; /* the loop makes the counts itself, in quanta */
    if (o.map != MCP_ADAPTIVE_UNIFORM) o.est.sampling.kind = (mcp_sampling_kind)o.map;

    mcp_adaptive_result *r = mcp_calloc(1, sizeof *r);
    if (!r) return -1;
    r->iterations = mcp_calloc((size_t)o.max_iterations, sizeof *r->iterations);
    mcp_image *counts = NULL, *next = NULL;
    mcp_estimate *est = NULL;
    int rc = -1;
    if (!r->iterations || counts_for(width, height, NULL, 0.0, first, o.quantum, &counts))
        goto done;
    int64_t total = 0, samples = first;
    for (int pass = 0;; pass++) {
        mcp_adaptive_iteration *it = &r->iterations[pass];
        it->pass = pass;
        it->samples = samples;
        double t0 = mcp__now_ms();
        mcp_dump *part = NULL;
        if (render(pass, counts, &part, render_ctx)) {
            mcp_error_prefix("adaptive: pass %d: ", pass);
            goto done;
        }
        if (!part || !part->color) {
            mcp_dump_free(part);
            mcp_error("adaptive: pass %d: the renderer gave no image", pass);
            goto done;
        }
        double t1 = mcp__now_ms();
        if (mcp__adaptive_check_pass(part, counts, pass)) {
            mcp_dump_free(part);
            goto done;
        }
        if (mcp__adaptive_accumulate(&r->accumulated, part)) {
            mcp_error_prefix("adaptive: pass %d: ", pass);
            goto done;
        }
        double t2 = mcp__now_ms();
        total += samples;
        it->total_samples = total;
        it->mean_spp = (double)total / npix;
        mcp_estimate_free(est);
        est = NULL;
        if (mcp_estimate_compute(r->accumulated, den, &o.est, &est)) {
            mcp_error_prefix("adaptive: pass %d: ", pass);
            goto done;
        }
        double t3 = mcp__now_ms();
        it->est_error = mcp_error_dist_mean(est->dist);
        it->cdf_at_tau = est->cdf_at_tau;
        it->stop = est->stop;
        it->relmse = it->relmse_noisy = NAN;
        if (reference &&
            (mcp_relmse(est->maps.denoised, reference, MCP_EPS_REL, &it->relmse) ||
             mcp_relmse(r->accumulated->color, reference, MCP_EPS_REL,
                        &it->relmse_noisy)))
            goto done;
        /* the stop rules, then the next pass's counts */
        r->count = pass + 1;
        int64_t left = budget == INT64_MAX ? INT64_MAX : budget - total;
        if (left <= 0)
            r->stopped_by = MCP_ADAPTIVE_STOP_BUDGET;
        else if (o.stop_on_estimate && est->stop)
            r->stopped_by = MCP_ADAPTIVE_STOP_ESTIMATE;
        else if (pass + 1 >= o.max_iterations)
            r->stopped_by = MCP_ADAPTIVE_STOP_ITERATIONS;
        int last = left <= 0 || (o.stop_on_estimate && est->stop) ||
                   pass + 1 >= o.max_iterations;
        double t4 = mcp__now_ms();
        if (!last) {
            samples = left < per_pass ? left : per_pass;
            if (counts_for(width, height,
                           o.map == MCP_ADAPTIVE_UNIFORM ? NULL : est->sampling_map,
                           o.uniform_mix, samples, o.quantum, &next))
                goto done;
        }
        it->ms_render = t1 - t0;
        it->ms_merge = t2 - t1;
        it->ms_denoise = est->ms_denoise;
        it->ms_estimate = (t3 - t2) - est->ms_denoise;
        it->ms_counts = mcp__now_ms() - t4;
        if (on_iteration) {
            mcp_adaptive_state st = {it, counts, r->accumulated, est, next};
            if (on_iteration(&st, ctx)) goto done;
        }
        mcp_image_free(counts);
        counts = next;
        next = NULL;
        if (last) break;
    }
    r->denoised = est->maps.denoised;
    est->maps.denoised = NULL;
    rc = 0;
done:
    mcp_estimate_free(est);
    mcp_image_free(counts);
    mcp_image_free(next);
    if (rc)
        mcp_adaptive_result_free(r);
    else
        *out = r;
    return rc;
}

double
mcp_equal_error_spp(const double *spp, const double *error, int n, double target)
{
    if (n < 1 || !(target > 0.0)) return NAN;
    if (error[0] <= target) return error[0] == target ? spp[0] : NAN;
    for (int i = 1; i < n; i++) {
        if (!(error[i] <= target)) continue;
        /* error[i - 1] > target >= error[i]: log-log between them */
        double x0 = log(spp[i - 1]), x1 = log(spp[i]);
        double y0 = log(error[i - 1]), y1 = log(error[i]), yt = log(target);
        double f = y0 == y1 ? 1.0 : (y0 - yt) / (y0 - y1);
        return exp(x0 + f * (x1 - x0));
    }
    return NAN;
}
