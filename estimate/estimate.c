/* estimate.c: the whole error-estimation pipeline on one dump and over a progressive
 * series (docs/mathematics.md §2; Firmino 2024 Alg. 2 and Table 1, Firmino 2023 Eq. 3).
 *
 * One dump: probes -> denoiser with J·ε (one call, all probes) -> SURE, Var, Σ̂ maps
 * -> sampling map and counts -> blocks (Alg. 1) -> λ, s² (Eq. 14) -> F(τ), the stop
 * decision (Eq. 16) and the estimated percentile curve.
 * A series: the same per member, the first spp at which F(τ) >= p for each τ, and,
 * with a reference, the truth beside it: the nearest-rank percentile of the true
 * error at p, and whether it is <= τ. */
#include "../common/core/internal.h" /* progress on a terminal */
#include "../common/dump/internal.h" /* mcp__variance_is_per_sample */
#include "estimate.h"
#include "internal.h"

#include <mcpost/flip.h>
#include <mcpost/stats.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The widest pooling of s² the options take: the streamed estimate holds that many
 * rows above and below a band. */
#define MCP__S2_POOL_MAX 16

static const char *const variance_probes_names[] = {"sure", "rademacher"};
const mcp_wordlist mcp_variance_probes_words = {"variance probes", variance_probes_names,
                                                2};

mcp_estimate_options
mcp_estimate_defaults(void)
{
    static const double pct[] = {0.5, 0.9, 0.99, 0.999, 0.9999};
    mcp_estimate_options o;
    memset(&o, 0, sizeof o);
    o.sure = mcp_sure_defaults();
    /* chosen by the denoiser (mcp_estimate_auto_probes) */
    o.sure.n_probes = -1;
    o.variance_rademacher = 0;
    o.blocks = mcp_block_defaults();
    o.tau = 0.01;
    o.p = 0.999;
    o.n_percentiles = (int)(sizeof pct / sizeof *pct);
    memcpy(o.percentiles, pct, sizeof pct);
    o.sampling = mcp_sampling_defaults();
    o.budget = 0;
    o.s2_pool = -1;
    o.probe_floor = -1;
    o.sure_groups = -1;
    return o;
}

/* The denoiser that runs on this dump: den itself, or the one it hands the dump to */
static const mcp_denoiser *
running(const mcp_dump *dump, const mcp_denoiser *den)
{
    if (!den->pick) return den;
    const mcp_denoise_input in = mcp_denoise_input_of(dump);
    return den->pick(den, &in);
}

int
mcp_estimate_auto_probes(const mcp_dump *dump, const mcp_denoiser *den)
{
    /* four probes with s² pooled agree with the truth as often as eight on the
       stratified fixtures (docs/fidelity.md "The defaults"), at half the JVPs */
    den = running(dump, den);
    return den->estimate_probes > 0 ? den->estimate_probes : MCP_ESTIMATE_PROBES;
}

int
mcp_estimate_auto_s2_pool(const mcp_dump *dump, const mcp_denoiser *den)
{
    /* A variance from few renders or blocks carries its own χ² noise into s², which
       pooling takes out; a per-sample variance has many degrees of freedom, and for a
       denoiser whose Var[F] is sharp pooling then only blurs its pattern (bilateral
       stops early with it: docs/fidelity.md "The defaults"). */
    int few_dof = dump->variance_source == MCP_VARSRC_REPLICATES ||
                  dump->variance_source == MCP_VARSRC_INCREMENTS;
    return running(dump, den)->sharp_variance && !few_dof ? 0 : 1;
}

int
mcp_estimate_auto_probe_floor(const mcp_dump *dump, const mcp_denoiser *den,
                              mcp_error_metric metric)
{
    /* nlm and bilateral, nearly linear in the noise for fixed weights, stop later with
       it and no earlier without it (docs/fidelity.md "The defaults"); relse-perceptual's
       maps take no floor (mcp_estimate_check refuses one) */
    if (metric == MCP_METRIC_RELSE_PERCEPTUAL) return 0;
    return running(dump, den)->estimate_probe_floor;
}

int
mcp_estimate_check(const mcp_estimate_options *o)
{
    const mcp_sure_options *s = &o->sure;
    if ((unsigned)s->metric > MCP_METRIC_SE)
        return mcp_error(
            "estimate: metric must be relse, relse-perceptual or se (got %d)",
            (int)s->metric);
    if ((s->n_probes < 1 && s->n_probes != -1) || s->n_probes > 1024)
        return mcp_error("estimate: probes must be auto or in [1, 1024] (got %d)",
                         s->n_probes);
    if (!(s->fd_delta > 0.0) || !isfinite(s->fd_delta))
        return mcp_error("estimate: delta must be > 0 (got %g)", s->fd_delta);
    if (!(s->ppd >= 0.0) || !isfinite(s->ppd))
        return mcp_error("estimate: ppd must be >= 0 (got %g)", s->ppd);
    if (!(o->tau > 0.0) || !isfinite(o->tau))
        return mcp_error("estimate: tau must be > 0 (got %g)", o->tau);
    if (!(o->p > 0.0 && o->p < 1.0))
        return mcp_error("estimate: percentile must be in (0, 1) (got %g)", o->p);
    if (o->n_percentiles < 0 || o->n_percentiles > MCP_ESTIMATE_MAX_PERCENTILES)
        return mcp_error("estimate: at most %d percentiles (got %d)",
                         MCP_ESTIMATE_MAX_PERCENTILES, o->n_percentiles);
    for (int i = 0; i < o->n_percentiles; i++)
        if (!(o->percentiles[i] >= 0.0 && o->percentiles[i] < 1.0))
            return mcp_error("estimate: percentiles must be in [0, 1) (got %g)",
                             o->percentiles[i]);
    if (o->blocks.tile_size < 0)
        return mcp_error("estimate: tile must be >= 0 (got %d)", o->blocks.tile_size);
    if (o->budget < 0)
        return mcp_error("estimate: budget must be >= 0 (got %lld)",
                         (long long)o->budget);
    if ((unsigned)o->sampling.kind > MCP_SAMPLING_MC_SURE)
        return mcp_error("estimate: unknown sampling map kind %d", (int)o->sampling.kind);
    if (o->s2_pool < -1 || o->s2_pool > MCP__S2_POOL_MAX)
        return mcp_error("estimate: s2_pool must be -1 (automatic) or 0 to %d (got %d)",
                         MCP__S2_POOL_MAX, o->s2_pool);
    if (o->probe_floor < -1 || o->probe_floor > MCP__PROBE_FLOOR_MAX)
        return mcp_error(
            "estimate: probe_floor must be -1 (automatic) or 0 to %d (got %d)",
            MCP__PROBE_FLOOR_MAX, o->probe_floor);
    if (o->sure_groups < -1 || o->sure_groups == 1 || o->sure_groups > MCP__GROUPS_MAX)
        return mcp_error("estimate: sure_groups must be -1 (automatic), 0 (none) or 2 to "
                         "%d (got %d)",
                         MCP__GROUPS_MAX, o->sure_groups);
    if (o->probe_floor > 0 && s->metric == MCP_METRIC_RELSE_PERCEPTUAL)
        return mcp_error("estimate: probe_floor needs the metric relse or se (got "
                         "relse-perceptual)");
    return 0;
}

void
mcp_estimate_free(mcp_estimate *e)
{
    if (!e) return;
    mcp_error_maps_free(&e->maps);
    mcp_blocks_free(e->blocks);
    mcp_error_dist_free(e->dist);
    mcp_image_free(e->sampling_map);
    mcp_image_free(e->sample_counts);
    free(e);
}

/* Probes, then one denoiser call for F and J·t of every probe: K Gaussian probes
 * first, then (variance_rademacher) K Rademacher ones. */
typedef struct evaluation {
    int k, n;          /* Gaussian probes, all tangents */
    mcp_probe *probes; /* k */
    mcp_image **rad;   /* k Rademacher probes or NULL */
    mcp_image **jv;    /* n */
    mcp_image *f;
    mcp_image *probe_var; /* the floored variance the probes were drawn from, or NULL */
} evaluation;

static void
evaluation_free(evaluation *ev)
{
    for (int j = 0; ev->probes && j < ev->k; j++)
        mcp_probe_clear(&ev->probes[j]);
    for (int j = 0; ev->rad && j < ev->k; j++)
        mcp_image_free(ev->rad[j]);
    for (int j = 0; ev->jv && j < ev->n; j++)
        mcp_image_free(ev->jv[j]);
    free(ev->probes);
    free(ev->rad);
    free(ev->jv);
    mcp_image_free(ev->f);
    mcp_image_free(ev->probe_var);
    memset(ev, 0, sizeof *ev);
}

/* What the steps after the error maps do not read, freed as soon as the maps are
 * made, so that the blocks, percentiles and files reuse its memory (at 1080p 75 MB of
 * memory the process would otherwise touch for the first time, which costs more than
 * reusing it): the probes and their variance, and the JVPs but where the Rademacher
 * variance or relse-perceptual's sampling map reads them (sampling_outputs). */
static void
drop_after_maps(evaluation *ev, const mcp_estimate_options *o)
{
    for (int j = 0; ev->probes && j < ev->k; j++)
        mcp_probe_clear(&ev->probes[j]);
    mcp_image_free(ev->probe_var);
    ev->probe_var = NULL;
    if (o->variance_rademacher || o->sure.metric == MCP_METRIC_RELSE_PERCEPTUAL) return;
    for (int j = 0; ev->jv && j < ev->n; j++) {
        mcp_image_free(ev->jv[j]);
        ev->jv[j] = NULL;
    }
}

/* The progress of one estimate, on a terminal, for a megapixel or more: a step for
 * the probes, JVP_STEPS for the denoiser and its JVP (its own bar, if it has one, is a
 * sub-count of this one's line), a step for the error maps and one for the rest
 * (blocks, distribution, sampling map). At 4K with nlm: 3 s, 80 s, 2 s, 1 s. */
enum { JVP_STEPS = 20, ESTIMATE_STEPS = 1 + JVP_STEPS + 1 + 1 };

static void
step(mcp_progress *bar, long done)
{
    if (bar) mcp_progress_update(bar, done);
}

/* The bands' share of the JVP steps (mcp__error_maps_in_bands). */
static void
band_step(void *bar, double done)
{
    step(bar, 1 + (long)(JVP_STEPS * done));
}

static int
evaluate(const mcp_dump *dump, const mcp_dump *probed, const mcp_denoiser *den,
         const mcp_estimate_options *o, evaluation *ev, mcp_progress *bar)
{
    memset(ev, 0, sizeof *ev);
    /* the probes' variance (probed's: the dump's own, or the groups'), floored
       (probe_floor.c); the denoiser sees the dump's own */
    mcp_dump floored = *probed;
    mcp_image *floor_cov = NULL;
    ev->k = o->sure.n_probes;
    ev->n = ev->k * (o->variance_rademacher ? 2 : 1);
    ev->probes = mcp_calloc((size_t)ev->k, sizeof *ev->probes);
    ev->jv = mcp_calloc((size_t)ev->n, sizeof *ev->jv);
    mcp_denoise_tangent *t = mcp_calloc((size_t)ev->n, sizeof *t);
    if (o->variance_rademacher) ev->rad = mcp_calloc((size_t)ev->k, sizeof *ev->rad);
    int rc = -1;
    if (!ev->probes || !ev->jv || !t || (o->variance_rademacher && !ev->rad)) goto done;
    if (o->probe_floor > 0) {
        if (mcp__probe_variance_floor(probed, o->probe_floor, &ev->probe_var, &floor_cov))
            goto done;
        floored.var_of_mean = ev->probe_var;
        if (floor_cov) floored.cov_of_mean = floor_cov;
    }
    for (int j = 0; j < ev->k; j++) {
        if (mcp_probe_gaussian(&floored, o->sure.features, o->sure.seed, j,
                               &ev->probes[j]))
            goto done;
        t[j].color = ev->probes[j].color;
        t[j].albedo = ev->probes[j].albedo;
        t[j].normal = ev->probes[j].normal;
        if (o->variance_rademacher) {
            if (mcp_probe_rademacher(&floored, o->sure.seed, j, &ev->rad[j])) goto done;
            t[ev->k + j].color = ev->rad[j];
        }
    }
    step(bar, 1);
    mcp_denoise_input in = mcp_denoise_input_of(dump);
    if (mcp__jvp(den, &in, t, ev->n, o->sure.mc_sure, o->sure.fd_delta, &ev->f, ev->jv))
        goto done;
    if (!ev->f && den->apply(den, &in, &ev->f)) {
        mcp_error_prefix("%s: ", den->name);
        goto done;
    }
    step(bar, 1 + JVP_STEPS);
    rc = 0;
done:
    mcp_image_free(floor_cov);
    free(t);
    if (rc) evaluation_free(ev);
    return rc;
}

/* The numerator of the sampling map: Var[F] of the denoiser output (not through M),
 * or the metric's SURE for the MC-SURE map. */
static int
sampling_outputs(const mcp_dump *dump, const mcp_estimate_options *o,
                 const evaluation *ev, mcp_estimate *e)
{
    const mcp_image *num = e->maps.sure;
    mcp_image *plain = NULL;
    if (o->sampling.kind != MCP_SAMPLING_MC_SURE) {
        num = e->maps.var;
        if (o->sure.metric == MCP_METRIC_RELSE_PERCEPTUAL || o->variance_rademacher) {
            int first = o->variance_rademacher ? ev->k : 0;
            if (mcp__variance_from_jvps((const mcp_image *const *)ev->jv + first, ev->k,
                                        MCP_METRIC_SE, 0.0, NULL, &plain, NULL))
                return -1;
            num = plain;
        }
    }
    int rc =
        mcp_sampling_map(dump, e->maps.denoised, num, &o->sampling, &e->sampling_map) ||
        (o->budget > 0 &&
         mcp_sample_counts(e->sampling_map, o->budget, &e->sample_counts));
    mcp_image_free(plain);
    return rc ? -1 : 0;
}

/* 1 when some pixel has a positive variance of the mean. Our departure from the
 * paper: with none at all the model has s_i = 0 everywhere and would stop at once. */
int
mcp__any_variance(const mcp_image *v)
{
    for (int y = 0; y < v->height; y++)
        for (int x = 0; x < v->width; x++) {
            const float *p = mcp_image_px(v, x, y);
            if (p[0] > 0.0f || p[1] > 0.0f || p[2] > 0.0f) return 1;
        }
    return 0;
}

/* SURE with its covariance term and the variance beside it measured on the member's
 * own groups (group_jackknife.c) instead of the probes' divergence and the dump's
 * variance: (d - n)² - V + 2C, and over the denominator for the relative map. V and C
 * come from the same groups, so that their errors cancel as the probes' do. */
static void
sure_from_groups(const mcp_dump *dump, const mcp__group_terms *g, mcp_error_maps *m)
{
    const int w = dump->color->width, h = dump->color->height;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *pf = mcp_image_px(m->denoised, x, y),
                        *pn = mcp_image_px(dump->color, x, y),
                        *pv = mcp_image_px(g->var, x, y),
                        *pc = mcp_image_px(g->cov, x, y);
            const double inv = 1.0 / mcp_image_px(m->denominator, x, y)[0];
            float *s = mcp_image_px(m->sure, x, y), *sr = mcp_image_px(m->sure_rel, x, y);
            for (int c = 0; c < 3; c++) {
                const double diff = (double)pf[c] - pn[c];
                const double sure = diff * diff - pv[c] + 2.0 * pc[c];
                s[c] = (float)sure;
                sr[c] = (float)(sure * inv);
            }
        }
}

unsigned
mcp__dump_parts_unread(const mcp_denoiser *den, int sure_features)
{
    return (den->uses_albedo || sure_features ? 0u : MCP__DUMP_NO_ALBEDO) |
           (den->uses_normal || sure_features ? 0u : MCP__DUMP_NO_NORMAL);
}

/* The options the denoiser and the dump choose where o leaves them automatic: the
 * probes and the probe floor (the s² pooling is chosen with the maps). */
static void
resolve_options(const mcp_dump *dump, const mcp_denoiser *den, mcp_estimate_options *o)
{
    if (o->sure.n_probes < 1) o->sure.n_probes = mcp_estimate_auto_probes(dump, den);
    if (o->probe_floor < 0)
        o->probe_floor = mcp_estimate_auto_probe_floor(dump, den, o->sure.metric);
}

/* What follows the maps, whole or streamed: s² pooled (and Var[F], where held), Alg. 1
 * (but where neither Σ̂ nor s² is above 0 — a dump without variance, or a region
 * without any — the block stays whole: F(τ) is the same, and the tree does not end in
 * a block per pixel there), the distribution, the stop and the percentiles.
 * e->s2_pool and e->no_variance are set; the maps were made by time t1. keep_sigma 0
 * frees Σ̂^r once the blocks are cut, for the percentiles' bins. */
static int
model(mcp_estimate *e, const mcp_estimate_options *o, double t1, int keep_sigma)
{
    if (mcp_pool_window(e->maps.var_rel, NULL, e->s2_pool) ||
        (e->maps.var && mcp_pool_window(e->maps.var, NULL, e->s2_pool)))
        return -1;
    double t2 = mcp__now_ms();
    if (mcp__block_average_quiet(e->maps.sure_rel, e->maps.sigma_rel, e->maps.var_rel,
                                 &o->blocks, &e->blocks))
        return -1;
    double t3 = mcp__now_ms();
    if (!keep_sigma) {
        mcp_image_free(e->maps.sigma_rel);
        e->maps.sigma_rel = NULL;
    }
    if (mcp_error_distribution(e->blocks, e->maps.var_rel, &e->dist)) return -1;
    e->tau = o->tau;
    e->p = o->p;
    int stop = mcp_error_should_stop(e->dist, o->tau, o->p, &e->cdf_at_tau);
    if (stop < 0) return -1;
    e->stop = stop && !e->no_variance;
    double t4 = mcp__now_ms();
    e->n_percentiles = o->n_percentiles;
    memcpy(e->percentiles, o->percentiles, sizeof o->percentiles);
    if (mcp_error_percentiles(e->dist, e->percentiles, e->n_percentiles,
                              e->percentile_tau))
        return -1;
    e->ms_error_terms = t2 - t1;
    e->ms_blocks = t3 - t2;
    e->ms_stopping = t4 - t3;
    e->ms_percentiles = mcp__now_ms() - t4;
    return 0;
}

/* The end of an estimate that ran: its bar stopped where it failed (no "100%") or
 * ended, and e handed out, or freed on failure (rc). */
static int
finish(mcp_progress *bar, int rc, mcp_estimate *e, mcp_estimate **out)
{
    if (bar) {
        if (rc)
            mcp__progress_stop(bar);
        else
            mcp_progress_end(bar);
    }
    if (rc)
        mcp_estimate_free(e);
    else
        *out = e;
    return rc;
}

static int compute(const mcp_dump *dump, const mcp_denoiser *den,
                   const mcp_estimate_options *opt, const mcp__group_terms *groups,
                   mcp_estimate **out);

int
mcp_estimate_compute(const mcp_dump *dump, const mcp_denoiser *den,
                     const mcp_estimate_options *opt, mcp_estimate **out)
{
    return compute(dump, den, opt, NULL, out);
}

int
mcp__estimate_compute_groups(const mcp_dump *dump, const mcp_denoiser *den,
                             const mcp_estimate_options *opt,
                             const mcp__group_terms *groups, mcp_estimate **out)
{
    return compute(dump, den, opt, groups, out);
}

static int
compute(const mcp_dump *dump, const mcp_denoiser *den, const mcp_estimate_options *opt,
        const mcp__group_terms *groups, mcp_estimate **out)
{
    *out = NULL;
    mcp_estimate_options o = opt ? *opt : mcp_estimate_defaults();
    if (mcp_estimate_check(&o) || mcp__check_dump("estimate", dump)) return -1;
    if (!den) return mcp_error("estimate: missing denoiser");
    resolve_options(dump, den, &o);
    mcp_estimate *e = mcp_calloc(1, sizeof *e);
    if (!e) return -1;
    e->probe_floor = o.probe_floor;
    evaluation ev;
    mcp_progress bar_store, *bar = NULL;
    if ((double)dump->color->width * dump->color->height >= 1048576.0 &&
        !mcp_progress_quiet()) {
        bar = &bar_store;
        mcp_progress_begin(bar, "estimate", ESTIMATE_STEPS);
    }
    double t0 = mcp__now_ms();
    /* a renderer's per-sample variance overstates a stratified render's noise; from
       the third member on the groups measure it (V), and where the two differ as far
       as the series' own rule asks (mcp_variance_ratio_off: auto then takes the
       increments, so this is a variance kept on purpose) the probes take V; not for
       a denoiser whose Var[F] is pixel-sharp, which V's few degrees of freedom leave
       noisy unpooled and pooling blurs (bilateral: docs/fidelity.md) */
    mcp_dump probed = *dump;
    mcp_image *probed_cov = NULL;
    int ev_bad = 0;
    if (groups && groups->var && !running(dump, den)->sharp_variance &&
        mcp__variance_is_per_sample(dump->variance_source) && groups->v_over_v > 1.0 &&
        mcp_variance_ratio_off(groups->v_over_v)) {
        ev_bad = mcp__group_probe_variance(dump, groups, &probed_cov);
        probed.var_of_mean = groups->var;
        probed.cov_of_mean = probed_cov;
        e->probes_from_groups = 1;
    }
    /* a large image with a denoiser of bounded reach: the evaluation and the maps a
       band of rows at a time (estimate_bands.c), the same values */
    const mcp_denoiser *runs = running(dump, den);
    const int band_rows = groups || ev_bad
                              ? 0
                              : mcp__estimate_band_rows(dump->color->width,
                                                        dump->color->height, runs, &o, 0);
    memset(&ev, 0, sizeof ev);
    if (band_rows) {
        step(bar, 1);
        ev_bad =
            mcp__error_maps_in_bands(dump, runs, &o, band_rows, band_step, bar, &e->maps);
    } else {
        ev_bad = ev_bad || evaluate(dump, &probed, den, &o, &ev, bar);
    }
    mcp_image_free(probed_cov);
    if (ev_bad) {
        if (bar) mcp__progress_stop(bar);
        free(e);
        return -1;
    }
    double t1 = mcp__now_ms();
    int rc = -1;
    if (!band_rows) {
        /* the maps take F(X) and the Gaussian probes' images, which nothing reads after
           them (the sampling map reads the JVPs only for relse-perceptual, whose maps
           take none, and the Rademacher JVPs, which are not offered) */
        mcp_image **eps = mcp_calloc((size_t)ev.k, sizeof *eps);
        if (!eps) goto done;
        for (int j = 0; j < ev.k; j++)
            eps[j] = ev.probes[j].color;
        int bad = mcp__error_maps_from_own_probes(dump, &ev.f, eps, ev.jv, ev.k, &o.sure,
                                                  ev.probe_var, &e->maps);
        for (int j = 0; j < ev.k; j++)
            ev.probes[j].color = eps[j];
        free(eps);
        if (bad) goto done;
    }
    drop_after_maps(&ev, &o);
    if (groups && groups->cov) { /* the series takes none for relse-perceptual */
        sure_from_groups(dump, groups, &e->maps);
        e->sure_groups = groups->groups;
    }
    step(bar, 2 + JVP_STEPS);
    if (o.variance_rademacher) { /* Var from the Rademacher probes (Firmino 2023) */
        mcp_image *v = NULL, *vr = NULL;
        if (mcp__variance_from_jvps((const mcp_image *const *)ev.jv + ev.k, ev.k,
                                    o.sure.metric, o.sure.ppd, e->maps.denominator, &v,
                                    &vr))
            goto done;
        mcp_image_free(e->maps.var);
        mcp_image_free(e->maps.var_rel);
        e->maps.var = v;
        e->maps.var_rel = vr;
    }
    /* s² from few probes: pooled so that its χ² spread does not fatten the tail */
    e->probes = o.sure.n_probes;
    /* probes from the groups' V: G - 1 degrees of freedom, pooled as any few-dof
       variance is */
    e->s2_pool = o.s2_pool >= 0          ? o.s2_pool
                 : e->probes_from_groups ? 1
                                         : mcp_estimate_auto_s2_pool(dump, den);
    e->variance_source = dump->variance_source;
    e->variance_dof = dump->variance_dof;
    e->no_variance = !mcp__any_variance(dump->var_of_mean);
    if (model(e, &o, t1, 1)) goto done;
    double t5 = mcp__now_ms();
    if (sampling_outputs(dump, &o, &ev, e)) goto done;
    e->ms_sampling = mcp__now_ms() - t5;
    e->ms_denoise = t1 - t0;
    rc = 0;
done:
    evaluation_free(&ev);
    return finish(bar, rc, e, out);
}

/* ---- one dump read a band at a time ---- */

/* The rows read from the dump's file at a time: the EXR chunks of every compression
 * (PIZ's and B44's 32 rows) end on them. */
#define STREAM_READ_ROWS 64

int
mcp__estimate_streamed(const mcp_dump_spec *spec, unsigned without,
                       const mcp_denoiser *den, const mcp_estimate_options *opt,
                       const mcp__estimate_sink *sink, mcp_estimate **out, int *done)
{
    *out = NULL;
    *done = 0;
    mcp_estimate_options o = opt ? *opt : mcp_estimate_defaults();
    /* what the whole run says in its own words: bad options, a denoiser that picks
       another by the dump (the default), a dump the band reader cannot take */
    if (!den || den->pick || mcp_estimate_check(&o) || mcp__sampling_check(&o.sampling)) {
        mcp_error_clear();
        return 0;
    }
    /* the size from the header alone: an estimate that does not go in bands (1080p)
       does not pay for the band reader's first rows (12 ms). A header that cannot be
       read fails in a whole read's words; out of memory fails here as it would there */
    int W, H, rc = -1;
    if (mcp__dump_bands_size_of(spec, without, &W, &H)) return -1;
    if (!W || !H) return 0;
    /* a denoiser that does not pick another chooses the probes and their floor by
       itself */
    resolve_options(NULL, den, &o);
    int band_rows = mcp__estimate_band_rows(W, H, den, &o, 1);
    /* bands that end on the output files' chunks (mcp__exr_band_file) */
    band_rows = band_rows / STREAM_READ_ROWS * STREAM_READ_ROWS;
    if (band_rows < STREAM_READ_ROWS && band_rows > 0) band_rows = STREAM_READ_ROWS;
    if (!band_rows || band_rows >= H) return 0;
    /* the rows held for the bands: a band, its pooling's reach and the denoiser's halo
       on each side, and the next rows read */
    mcp__dump_held held = {.read_rows = STREAM_READ_ROWS, .height = H};
    held.cap = band_rows + 2 * (MCP__S2_POOL_MAX + den->band_halo) + STREAM_READ_ROWS;
    if (mcp__dump_bands_open_without(spec, without, &held.in)) return -1;
    if (!held.in) return 0;
    mcp_estimate *e = NULL;
    mcp_progress bar_store, *bar = NULL;
    /* the first rows: the dump's parts, and its variance's source for the pooling; a
       dump that the estimate refuses is refused by the whole run, whose read may find
       something else wrong first */
    *done = 1;
    if (mcp__dump_held_rows(&held, 0, H < STREAM_READ_ROWS ? H : STREAM_READ_ROWS))
        goto done;
    if (mcp__check_dump("estimate", held.d)) { /* the caller reads it whole */
        mcp_error_clear();
        *done = 0;
        rc = 0;
        goto done;
    }
    mcp__unmap_freed_blocks();
    if (!(e = mcp_calloc(1, sizeof *e))) goto done;
    e->probe_floor = o.probe_floor;
    e->probes = o.sure.n_probes;
    e->variance_source = held.d->variance_source;
    e->variance_dof = held.d->variance_dof;
    e->s2_pool = o.s2_pool >= 0 ? o.s2_pool : mcp_estimate_auto_s2_pool(held.d, den);
    if ((double)W * H >= 1048576.0 && !mcp_progress_quiet()) {
        bar = &bar_store;
        mcp_progress_begin(bar, "estimate", ESTIMATE_STEPS);
    }
    step(bar, 1);
    double t0 = mcp__now_ms();
    int any_variance = 0;
    if (mcp__error_maps_streamed(&held, den, &o, band_rows, e->s2_pool, sink, band_step,
                                 bar, &e->maps, &e->sampling_map, &any_variance))
        goto done;
    mcp__dump_held_clear(&held);
    double t1 = mcp__now_ms();
    step(bar, 2 + JVP_STEPS);
    e->no_variance = !any_variance;
    /* Σ̂^r only cuts the blocks: its memory goes to the percentiles */
    if (model(e, &o, t1, 0)) goto done;
    double t5 = mcp__now_ms();
    if (mcp__sampling_map_finish(&e->sampling_map, &o.sampling) ||
        (o.budget > 0 && mcp_sample_counts(e->sampling_map, o.budget, &e->sample_counts)))
        goto done;
    e->ms_sampling = mcp__now_ms() - t5;
    e->ms_denoise = t1 - t0;
    rc = 0;
done:
    mcp__dump_held_clear(&held);
    mcp__dump_bands_close(held.in);
    return finish(bar, rc, e, out);
}

/* ---- the truth, for evaluation ---- */

int
mcp_true_error(const mcp_image *denoised, const mcp_image *reference,
               mcp_error_metric metric, double ppd, mcp_image **out)
{
    *out = NULL;
    int rf[3], rr[3];
    if (!denoised || !reference) return mcp_error("true error: missing image");
    if (mcp_rgb_channels(denoised, rf) || mcp_rgb_channels(reference, rr)) return -1;
    if (denoised->width != reference->width || denoised->height != reference->height)
        return mcp_error("true error: %s is %dx%d but the reference %s is %dx%d",
                         denoised->source ? denoised->source : "the image",
                         denoised->width, denoised->height,
                         reference->source ? reference->source : "", reference->width,
                         reference->height);
    int w = denoised->width, h = denoised->height, rc = -1;
    mcp_image *f = NULL, *d = NULL, *mf = NULL, *md = NULL;
    if (mcp__image_new(w, h, 3, NULL, "denoised", &f) ||
        mcp__image_new(w, h, 3, NULL, "true error", &d))
        goto done;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *pf = mcp_image_px(denoised, x, y),
                        *pr = mcp_image_px(reference, x, y);
            float *of = mcp_image_px(f, x, y), *od = mcp_image_px(d, x, y);
            for (int c = 0; c < 3; c++) {
                of[c] = pf[rf[c]];
                od[c] = (float)((double)pf[rf[c]] - pr[rr[c]]);
            }
        }
    const mcp_image *ef = f, *ed = d;
    if (metric == MCP_METRIC_RELSE_PERCEPTUAL) {
        if (mcp_flip_csf_apply(f, ppd, &mf) || mcp_flip_csf_apply(d, ppd, &md)) goto done;
        ef = mf;
        ed = md;
    }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *pf = mcp_image_px(ef, x, y), *pd = mcp_image_px(ed, x, y);
            double m = fmax(fmax(pf[0], pf[1]), pf[2]);
            double den = metric == MCP_METRIC_SE ? 1.0 : m * m + MCP_EPS_REL;
            float *o = mcp_image_px(d, x, y);
            for (int c = 0; c < 3; c++)
                o[c] = (float)((double)pd[c] * pd[c] / den);
        }
    *out = d;
    d = NULL;
    rc = 0;
done:
    mcp_image_free(f);
    mcp_image_free(d);
    mcp_image_free(mf);
    mcp_image_free(md);
    return rc;
}

/* The first 3 channels of an error image as one array of values (malloc'd); NaN is an
 * error. */
static int
error_values(const mcp_image *err, float **out, size_t *n_out)
{
    *out = NULL;
    if (!err || err->channels < 3)
        return mcp_error("percentiles: missing 3-channel error image");
    size_t n = (size_t)err->width * err->height * 3;
    float *v = mcp_calloc(n ? n : 1, sizeof *v);
    if (!v) return -1;
    long nan_at = -1;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < err->height; y++)
        for (int x = 0; x < err->width; x++) {
            const float *e = mcp_image_px(err, x, y);
            size_t k = 3 * ((size_t)y * err->width + x);
            for (int c = 0; c < 3; c++) {
                v[k + c] = e[c];
                if (isnan(e[c])) {
#pragma omp critical
                    if (nan_at < 0 || (long)(k / 3) < nan_at) nan_at = (long)(k / 3);
                }
            }
        }
    if (nan_at >= 0) {
        free(v);
        return mcp_error("percentiles: %s has NaN at pixel (%ld, %ld)",
                         err->source ? err->source : "the error image",
                         nan_at % err->width, nan_at / err->width);
    }
    *out = v;
    *n_out = n;
    return 0;
}

int
mcp_true_percentiles(const mcp_image *err, const double *p, int n, double *out)
{
    float *v;
    size_t m;
    if (error_values(err, &v, &m)) return -1;
    int rc = mcp__select_percentiles(v, m, p, n, out);
    free(v);
    return rc;
}

/* ---- series ---- */

mcp_series_estimate_options
mcp_series_estimate_defaults(void)
{
    static const double taus[] = {0.05, 0.02, 0.01};
    mcp_series_estimate_options o;
    memset(&o, 0, sizeof o);
    o.est = mcp_estimate_defaults();
    o.n_taus = 3;
    memcpy(o.taus, taus, sizeof taus);
    return o;
}

void
mcp_series_estimate_free(mcp_series_estimate *s)
{
    if (!s) return;
    free(s->points);
    free(s);
}

int
mcp_stop_agrees(double est_spp, double true_spp, const double *spps, int n)
{
    if (est_spp <= 0.0 || true_spp <= 0.0) return est_spp <= 0.0 && true_spp <= 0.0;
    if (est_spp == true_spp || fabs(est_spp - true_spp) <= true_spp / 3.0) return 1;
    int ie = -1, it = -1;
    for (int i = 0; i < n; i++) {
        if (spps[i] == est_spp) ie = i;
        if (spps[i] == true_spp) it = i;
    }
    return ie >= 0 && it >= 0 && abs(ie - it) <= 1;
}

static double
mean_spp(const mcp_dump *d)
{
    if (!d->spp_map) return d->spp;
    double s = 0.0;
    for (int y = 0; y < d->spp_map->height; y++)
        for (int x = 0; x < d->spp_map->width; x++)
            s += mcp_image_px(d->spp_map, x, y)[0];
    return s / ((double)d->spp_map->width * d->spp_map->height);
}

/* 1 when member i of a series may not stop, whatever its F(τ): over checkpoints of one
 * render, with the groups on, a member with fewer checkpoints than the groups need
 * (MCP__GROUPS_MIN, or fewer when asked: the first two) has SURE only from the probes'
 * divergence, which Stein's lemma ties to Gaussian noise; under a render's heavy-tailed
 * noise at tens of samples it reads the covariance low and stopped early
 * (docs/fidelity.md, "Holding the first two checkpoints"). A variance from replicates
 * (independent renders merged) is not held: its first member already pools K renders. */
static int
holds_stop(int i, const mcp_dump *d, int groups)
{
    return groups > 1 && i < mcp__groups_min(groups) - 1 && mcp__member_can_group(d) &&
           d->variance_source != MCP_VARSRC_REPLICATES;
}

/* Fills the truth of one member from its denoised image. */
static int
member_truth(const mcp_estimate *e, const mcp_image *reference,
             const mcp_series_estimate_options *o, mcp_series_point *pt)
{
    mcp_image *err = NULL;
    float *v = NULL;
    size_t n = 0;
    if (mcp_true_error(e->maps.denoised, reference, o->est.sure.metric, o->est.sure.ppd,
                       &err) ||
        error_values(err, &v, &n)) {
        mcp_image_free(err);
        return -1;
    }
    mcp_image_free(err);
    double sum = 0.0;
    long at_most[MCP_ESTIMATE_MAX_TAUS] = {0};
    int n_taus = o->n_taus;
    for (size_t i = 0; i < n; i++) { /* in order, so that the sum has fixed bits */
        sum += v[i];
        for (int j = 0; j < n_taus; j++)
            at_most[j] += v[i] <= o->taus[j];
    }
    pt->true_mean_error = sum / (double)n;
    /* the percentile at p and the curve's, in one selection */
    double p[MCP_ESTIMATE_MAX_PERCENTILES + 1], at[MCP_ESTIMATE_MAX_PERCENTILES + 1];
    int k = o->est.n_percentiles;
    memcpy(p, o->est.percentiles, (size_t)k * sizeof *p);
    p[k] = o->est.p;
    int rc = mcp__select_percentiles(v, n, p, k + 1, at);
    free(v);
    if (rc) return -1;
    for (int j = 0; j < n_taus; j++) {
        pt->true_cdf[j] = (double)at_most[j] / (double)n;
        pt->true_stop[j] = at[k] <= o->taus[j];
    }
    for (int j = 0; j < k; j++)
        pt->true_percentile[j] = at[j];
    return 0;
}

/* mcp_estimate_series's progress, as a callback that never ends the series */
typedef struct progress_only {
    void (*progress)(int done, int total, void *ctx);
    void *ctx;
} progress_only;

static int
report_progress(int done, int total, void *ctx)
{
    const progress_only *p = ctx;
    if (p->progress) p->progress(done, total, p->ctx);
    return 0;
}

int
mcp_estimate_series(const mcp_series *series, const mcp_denoiser *den,
                    const mcp_series_estimate_options *opt, const mcp_image *reference,
                    void (*progress)(int done, int total, void *ctx), void *ctx,
                    mcp_series_estimate **out)
{
    progress_only p = {progress, ctx};
    return mcp_estimate_series_each(series, den, opt, reference, report_progress, &p,
                                    out);
}

int
mcp_estimate_series_each(const mcp_series *series, const mcp_denoiser *den,
                         const mcp_series_estimate_options *opt,
                         const mcp_image *reference,
                         int (*on_member)(int done, int total, void *ctx), void *ctx,
                         mcp_series_estimate **out)
{
    *out = NULL;
    mcp_series_estimate_options o = opt ? *opt : mcp_series_estimate_defaults();
    if (!series || series->count < 1)
        return mcp_error("estimate: the series has no members");
    if (o.n_taus < 1 || o.n_taus > MCP_ESTIMATE_MAX_TAUS)
        return mcp_error("estimate: taus needs 1 to %d values (got %d)",
                         MCP_ESTIMATE_MAX_TAUS, o.n_taus);
    for (int j = 0; j < o.n_taus; j++)
        if (!(o.taus[j] > 0.0) || !isfinite(o.taus[j]))
            return mcp_error("estimate: taus must be > 0 (got %g)", o.taus[j]);
    o.est.tau = o.taus[0];
    if (mcp_estimate_check(&o.est)) return -1;
    mcp_series_estimate *s = mcp_calloc(1, sizeof *s);
    if (!s) return -1;
    s->points = mcp_calloc((size_t)series->count, sizeof *s->points);
    if (!s->points) {
        free(s);
        return -1;
    }
    s->count = series->count;
    s->n_taus = o.n_taus;
    memcpy(s->taus, o.taus, sizeof o.taus);
    s->p = o.est.p;
    s->n_percentiles = o.est.n_percentiles;
    memcpy(s->percentiles, o.est.percentiles, sizeof o.est.percentiles);
    s->has_reference = reference != NULL;
    /* the groups asked for; none for relse-perceptual, whose maps take none */
    const int groups = o.est.sure.metric == MCP_METRIC_RELSE_PERCEPTUAL ? 0
                       : o.est.sure_groups >= 0 ? o.est.sure_groups
                                                : MCP_ESTIMATE_SURE_GROUPS;
    for (int i = 0; i < series->count; i++) {
        mcp_dump *d = NULL;
        mcp_estimate *e = NULL;
        mcp_series_point *pt = &s->points[i];
        mcp__group_terms g = {0};
        if (mcp__series_load_without(
                series, i, mcp__dump_parts_unread(den, o.est.sure.features != NULL),
                &d) ||
            (groups > 1 && mcp__series_group_terms(series, i, d, den, groups, &g)) ||
            compute(d, den, &o.est, &g, &e)) {
            mcp_error_prefix("%s: ", series->paths[i]);
            mcp__group_terms_clear(&g);
            mcp_dump_free(d);
            mcp_series_estimate_free(s);
            return -1;
        }
        mcp__group_terms_clear(&g);
        pt->sure_groups = e->sure_groups;
        pt->probes_from_groups = e->probes_from_groups;
        pt->spp = series->spp && series->spp[i] > 0 ? series->spp[i] : mean_spp(d);
        s->variance_source = d->variance_source; /* the last member's, in the end */
        int bad = 0;
        const int hold = holds_stop(i, d, groups);
        for (int j = 0; j < o.n_taus && !bad; j++) {
            int stop = mcp_error_should_stop(e->dist, o.taus[j], o.est.p, &pt->cdf[j]);
            bad = stop < 0;
            const int reached = stop > 0 && !e->no_variance;
            pt->stop[j] = reached && !hold;
            pt->held = pt->held || (reached && hold);
        }
        memcpy(pt->est_percentile, e->percentile_tau, sizeof e->percentile_tau);
        pt->est_mean_error = mcp_error_dist_mean(e->dist);
        pt->true_mean_error = NAN;
        bad = bad || (reference && member_truth(e, reference, &o, pt));
        mcp_estimate_free(e);
        mcp_dump_free(d);
        if (bad) {
            mcp_error_prefix("%s: ", series->paths[i]);
            mcp_series_estimate_free(s);
            return -1;
        }
        if (on_member) {
            mcp_error_clear(); /* what the callback says, if it ends the series */
            if (on_member(i + 1, series->count, ctx)) {
                if (!mcp_error_message()[0])
                    mcp_error("estimate: stopped after member %d", i + 1);
                mcp_series_estimate_free(s);
                return -1;
            }
        }
    }
    /* whether the renderer's Variance/n tracks the spread of the series' own
       increments (a stratified sampler makes it an overstatement) */
    if (mcp_series_variance_ratio(series, &s->variance_ratio)) {
        mcp_series_estimate_free(s);
        return -1;
    }
    double *spps = mcp_calloc((size_t)s->count, sizeof *spps);
    if (!spps) {
        mcp_series_estimate_free(s);
        return -1;
    }
    for (int i = 0; i < s->count; i++)
        spps[i] = s->points[i].spp;
    for (int j = 0; j < o.n_taus; j++) {
        for (int i = s->count - 1; i >= 0; i--) { /* the first member that stops */
            if (s->points[i].stop[j]) s->first_spp[j] = s->points[i].spp;
            if (reference && s->points[i].true_stop[j])
                s->true_first_spp[j] = s->points[i].spp;
        }
        s->agree[j] = reference ? mcp_stop_agrees(s->first_spp[j], s->true_first_spp[j],
                                                  spps, s->count)
                                : 0;
    }
    free(spps);
    *out = s;
    return 0;
}
