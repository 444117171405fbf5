/* bench_fidelity.c: do the estimates and blends hold on renders as renderers make
 * them? Firmino et al. 2024's protocol on the stratified Cycles fixtures
 * (samples/fixtures/strat: one progressive render as 32 blocks of 32 samples, 7 more
 * renders with other seeds, a 16384-spp reference), for every variance source:
 *
 *   auto         what a user gets: the render's checkpoints with their per-sample
 *                variance, read as a series with mcp_series_load's default choice
 *                (the increments' variance where Variance/n overstates their spread)
 *   per-sample   the renderer's per-sample variance / n (what the render carries)
 *   increments   the spread between the render's 32-spp increments
 *                (mcp_dump_increment_variance)
 *   replicates4  4 renders with other seeds merged (mcp_dump_merge), each
 *   replicates8  advancing 32 spp per iteration (so 4 or 8 x 32 spp in all)
 *   oracle       the render with the variance of its mean measured from all 8
 *                renders' spread (7 dof, ratio-pooled over 5x5 pixels with the
 *                render's own Variance as the pattern): what a near-true variance
 *                gives
 *
 * For each scene, denoiser and source: iterations of 32 spp per render, up to 1024
 * for one render and to 2048 in all for replicates (16 iterations of 4 x 32, 8 of
 * 8 x 32), so that the reference stays at least 8 times the last image's samples;
 * the renders a source does not use are merged into the reference. Three τ from the
 * true 99.9th-percentile RelSE of the denoised image at iterations 2, 6 and 16 of 32
 * (scaled to the sequence's length), raised to twice the reference's noise floor
 * where below it; p = 0.999; a stop agrees when it is within one iteration or a third
 * of the true count (mcp_stop_agrees); an early stop is one before half the true
 * count.
 * Then the curve blend on the same sequence: where it is <= min(noisy, denoised), its
 * MSE over the noisy image's at the last iteration, and beside it the window-optimal
 * blend computed with the reference (an oracle: the most any weights can reach).
 *
 * Denoisers: any kind, and js-NAME for NAME followed by the James-Stein
 * post-correction (the `james-stein` denoiser: the error of what the user keeps).
 *
 *   build/bench/bench_fidelity [--scenes a,b] [--denoisers nlm,unet,js-unet]
 *                              [--sources LIST] [--fixtures DIR] [--weights TZA]
 *                              [--iterations N] [--probes K] [--s2-pool R]
 *                              [--probe-floor R] [--sure-groups G]
 *                              [--fit on_the_fly|last_two|retrospective]
 *                              [--no-blend | --blend-only] [--curves]
 *
 * Scenes: any folder of --fixtures with that layout, by name. The default list is
 * cornell,texture,interior; `window` (sun and sky through a window, glossy floor, glass),
 * `lamp` (a room lit by a shaded lamp off its ceiling; heavy-tailed noise), `corridor`
 * (shielded ceiling lights, glossy floor, brick walls), `fog` (a room filled with fog,
 * sun shafts through a slatted window, glass), `courtyard` (an open courtyard at dusk:
 * a sky and a low sun, brick walls, steel bollards, a pool of water), `stilllife` (a
 * still life on a table through a shallow depth of field: a checkered cloth, fruit, a
 * glass tumbler, a metal cup, a blurred striped wall) and `bathroom` (a bathroom at
 * night under one small downlight: a mirror, chrome, glossy tiles, subsurface soap and
 * wax, frosted glass; the largest error at 32 spp of all) are held out for checking tuned
 * defaults and run only when named, e.g.
 * --scenes window,lamp,corridor,fog,courtyard,stilllife,bathroom.
 *
 * It prints figures; it is not a timed test. Run it from the repository root (the
 * defaults are relative to it). */
#define _POSIX_C_SOURCE 200809L
#include <mcpost/blend.h>
#include <mcpost/dump.h>
#include <mcpost/estimate.h>
#include <mcpost/imageio.h>
#include <mcpost/job.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bench.h"

#define BLOCKS 32
#define RENDERS 8
#define MAX_ITER 32

typedef enum {
    SRC_PER_SAMPLE,
    SRC_INCREMENTS,
    SRC_REP4,
    SRC_REP8,
    SRC_ORACLE,
    SRC_AUTO,
    N_SRC
} source;
static const char *const source_names[N_SRC] = {
    "per-sample", "increments", "replicates4", "replicates8", "oracle", "auto"};

/* One scene's fixture: blocks[r][b] (r = 0 carries Variance), features, reference. */
typedef struct scene {
    const char *name;
    mcp_dump *blocks[RENDERS][BLOCKS];
    mcp_image *albedo, *normal, *reference;
} scene;

static void
die(const char *what)
{
    fprintf(stderr, "bench_fidelity: %s: %s\n", what, mcp_error_message());
    exit(1);
}

static int
load_scene(const char *dir, const char *name, scene *s)
{
    char path[4096];
    memset(s, 0, sizeof *s);
    s->name = name;
    for (int r = 0; r < RENDERS; r++)
        for (int b = 0; b < BLOCKS; b++) {
            snprintf(path, sizeof path, "%s/%s/blocks/%s_r%d_b%02d.exr", dir, name, name,
                     r, b);
            if (mcp_dump_read(path, &s->blocks[r][b])) return -1;
        }
    snprintf(path, sizeof path, "%s/%s/%s_features.exr", dir, name, name);
    /* the features file has no colour: read it as an image and pick the channels */
    mcp_image *img = NULL;
    if (mcp_image_read(path, NULL, &img)) return -1;
    int ia[3], in[3];
    if (mcp_image_channels(img, (const char *const[]){"Albedo.R", "Albedo.G", "Albedo.B"},
                           3, ia) ||
        mcp_image_channels(img, (const char *const[]){"N.X", "N.Y", "N.Z"}, 3, in) ||
        mcp_image_copy_channels(img, ia, 3, &s->albedo) ||
        mcp_image_copy_channels(img, in, 3, &s->normal)) {
        mcp_image_free(img);
        return -1;
    }
    mcp_image_free(img);
    snprintf(path, sizeof path, "%s/%s/%s_reference.exr", dir, name, name);
    mcp_image *ref = NULL;
    int rgb[3];
    if (mcp_image_read(path, NULL, &ref) || mcp_rgb_channels(ref, rgb) ||
        mcp_image_copy_channels(ref, rgb, 3, &s->reference)) {
        mcp_image_free(ref);
        return -1;
    }
    mcp_image_free(ref);
    return 0;
}

static void
free_scene(scene *s)
{
    for (int r = 0; r < RENDERS; r++)
        for (int b = 0; b < BLOCKS; b++)
            mcp_dump_free(s->blocks[r][b]);
    mcp_image_free(s->albedo);
    mcp_image_free(s->normal);
    mcp_image_free(s->reference);
}

/* A copy of a block's colour, variance (if any) and sample count. */
static mcp_dump *
copy_block(const mcp_dump *b)
{
    mcp_dump *d = calloc(1, sizeof *d);
    if (!d || mcp_image_copy(b->color, &d->color) ||
        (b->var_of_mean && mcp_image_copy(b->var_of_mean, &d->var_of_mean)) ||
        !(d->source = strdup(b->source)))
        die("copy");
    d->spp = b->spp;
    d->convention = b->convention;
    d->variance_source = b->variance_source;
    return d;
}

/* Render r after j blocks: the mean of its first j blocks; render 0 with its exact
 * per-sample variance (blocks pooled), the others without variance. */
static mcp_dump *
running(const scene *s, int r, int j)
{
    mcp_dump *d = NULL;
    if (j == 1) return copy_block(s->blocks[r][0]);
    mcp_merge_options mo = {r == 0 ? MCP_MERGE_POOLED : MCP_MERGE_REPLICATES, 0};
    if (mcp_dump_merge((const mcp_dump *const *)s->blocks[r], j, &mo, &d)) die("merge");
    if (r > 0) {
        /* only the mean is wanted: the blocks' spread is not this render's variance */
        mcp_image_free(d->var_of_mean);
        mcp_image_free(d->cov_of_mean);
        d->var_of_mean = d->cov_of_mean = NULL;
        d->variance_source = MCP_VARSRC_NONE;
        d->variance_dof = 0, d->replicates = 0;
    }
    return d;
}

static void
set_features(const scene *s, mcp_dump *d)
{
    mcp_image_free(d->albedo);
    mcp_image_free(d->normal);
    if (mcp_image_copy(s->albedo, &d->albedo) || mcp_image_copy(s->normal, &d->normal))
        die("features");
}

/* The dump of iteration j (1-based) of a source; NULL where it has none. */
static mcp_dump *
iteration_dump(const scene *s, source src, int j, double *ratio)
{
    mcp_dump *d = NULL;
    *ratio = 0;
    switch (src) {
    case SRC_PER_SAMPLE:
    case SRC_AUTO:
        d = running(s, 0, j);
        break;
    case SRC_INCREMENTS: {
        mcp_dump *m[MAX_ITER];
        for (int k = 0; k < j; k++)
            m[k] = running(s, 0, k + 1);
        if (j == 1) {
            d = m[0]; /* one block: nothing to compare; the per-sample variance stays */
        } else {
            if (mcp_dump_increment_variance((const mcp_dump *const *)m, j, NULL, &d,
                                            ratio))
                die("increments");
            for (int k = 0; k < j; k++)
                mcp_dump_free(m[k]);
        }
        break;
    }
    case SRC_REP4:
    case SRC_REP8: {
        int K = src == SRC_REP4 ? 4 : 8;
        mcp_dump *parts[RENDERS];
        for (int r = 0; r < K; r++)
            parts[r] = running(s, r, j);
        if (mcp_dump_merge((const mcp_dump *const *)parts, K, NULL, &d))
            die("merge replicates");
        for (int r = 0; r < K; r++)
            mcp_dump_free(parts[r]);
        break;
    }
    case SRC_ORACLE: {
        mcp_dump *parts[RENDERS], *all = NULL;
        for (int r = 0; r < RENDERS; r++)
            parts[r] = running(s, r, j);
        if (mcp_dump_merge((const mcp_dump *const *)parts, RENDERS, NULL, &all))
            die("merge oracle");
        d = parts[0];
        /* the spread of 8 renders of n samples: Var of one = 8 x that of their mean;
           pooled with the render's own per-sample variance as the pattern */
        mcp_image *shape = d->var_of_mean;
        d->var_of_mean = all->var_of_mean, all->var_of_mean = NULL;
        for (size_t i = 0; i < (size_t)d->color->width * d->color->height * 3; i++)
            d->var_of_mean->data[i] *= RENDERS;
        d->variance_source = MCP_VARSRC_REPLICATES;
        d->variance_dof = RENDERS - 1;
        d->replicates = RENDERS;
        if (mcp_dump_pool_variance(d, shape, 2)) die("pool");
        mcp_image_free(shape);
        mcp_dump_free(all);
        for (int r = 1; r < RENDERS; r++)
            mcp_dump_free(parts[r]);
        break;
    }
    default:
        break;
    }
    set_features(s, d);
    return d;
}

/* The iteration dumps of a source, written as a series in dir. */
static mcp_series *
write_series(const scene *s, source src, int iters, const char *dir, double *ratio_last)
{
    char **paths = calloc((size_t)iters, sizeof *paths);
    double *spp = calloc((size_t)iters, sizeof *spp);
    for (int j = 1; j <= iters; j++) {
        double ratio;
        mcp_dump *d = iteration_dump(s, src, j, &ratio);
        if (ratio > 0) *ratio_last = ratio;
        char path[4096];
        snprintf(path, sizeof path, "%s/%s_%s_%04d.exr", dir, s->name, source_names[src],
                 j);
        paths[j - 1] = strdup(path);
        spp[j - 1] = d->spp;
        if (mcp_dump_write(d, path,
                           d->variance_source == MCP_VARSRC_PER_SAMPLE ? MCP_CONV_PBRT
                                                                       : MCP_CONV_MCPOST,
                           NULL))
            die("write");
        mcp_dump_free(d);
    }
    mcp_series *series = NULL;
    if (mcp_series_from_paths((const char *const *)paths, spp, iters, &series))
        die("series");
    /* each source as it is, except auto: what a user gets from the render's own
       checkpoints (mcp_series_load's default choice) */
    series->variance_from =
        src == SRC_AUTO ? MCP_SERIES_VARIANCE_AUTO : MCP_SERIES_VARIANCE_FILE;
    for (int j = 0; j < iters; j++)
        free(paths[j]);
    free(paths);
    free(spp);
    return series;
}

/* The renders a source does not use (render 0's sources leave 1-7, four replicates
 * leave 4-7) are independent of it: merged into the reference, weighted by their
 * sample counts, they lower its noise floor. *ref_spp receives its sample count. */
static mcp_image *
reference_for(const scene *s, source src, double *ref_spp)
{
    int first_unused = src == SRC_PER_SAMPLE || src == SRC_INCREMENTS || src == SRC_AUTO
                           ? 1
                       : src == SRC_REP4 ? 4
                                         : RENDERS;
    mcp_image *ref = NULL;
    if (mcp_image_copy(s->reference, &ref)) die("copy");
    *ref_spp = 16384;
    size_t n = (size_t)ref->width * ref->height * 3;
    for (int i = 0; i < (int)n; i++)
        ref->data[i] *= 16384;
    for (int r = first_unused; r < RENDERS; r++) {
        mcp_dump *d = running(s, r, BLOCKS);
        for (size_t i = 0; i < n; i++)
            ref->data[i] += (float)(1024.0 * d->color->data[i]);
        *ref_spp += 1024;
        mcp_dump_free(d);
    }
    for (size_t i = 0; i < n; i++)
        ref->data[i] = (float)(ref->data[i] / *ref_spp);
    return ref;
}

/* The true p-percentile RelSE of the denoised member i. */
static double
true_percentile(const mcp_series *series, int i, const mcp_denoiser *den,
                const mcp_image *reference, double p)
{
    mcp_dump *d = NULL;
    mcp_image *f = NULL, *err = NULL;
    if (mcp_series_load(series, i, &d)) die("load");
    mcp_denoise_input in = mcp_denoise_input_of(d);
    double tau = NAN;
    if (den->apply(den, &in, &f) ||
        mcp_true_error(f, reference, MCP_METRIC_RELSE, 0, &err) ||
        mcp_true_percentiles(err, &p, 1, &tau))
        die("truth");
    mcp_image_free(f);
    mcp_image_free(err);
    mcp_dump_free(d);
    return tau;
}

/* The reference's own noise floor at p: the p-percentile RelSE of the 1024-spp render
 * of render 0 scaled by 1024 / ref_spp (its error shrinks as 1/n). */
static double
reference_floor(const scene *s, double p, double ref_spp)
{
    mcp_dump *d = running(s, 0, BLOCKS);
    mcp_image *err = NULL;
    double v = NAN;
    if (mcp_true_error(d->color, s->reference, MCP_METRIC_RELSE, 0, &err) ||
        mcp_true_percentiles(err, &p, 1, &v))
        die("floor");
    mcp_image_free(err);
    mcp_dump_free(d);
    return v * 1024.0 / ref_spp;
}

typedef struct tally {
    int cases, agree, early, never_est, blend_points, blend_good, blend_cases;
    int blend_near; /* members with the blend <= 1.10 x min(noisy, denoised) */
    int js_near;    /* the same for the James-Stein combiner, beside it */
    double js_worst_member, js_worst_final;
    double worst_final, worst_member; /* over noisy at the end; over min at any member */
    double curves_over_min, oracle_over_min; /* sums over the points, for the means */
} tally;

/* What every case shares: the settings from the command line. */
typedef struct run_settings {
    double p;
    int probes, s2_pool, curves, safeguard;
    mcp_curve_fit fit;
    double floor;
    const int *tau_it;
    int probe_floor; /* -2: the estimate's own (automatic) */
    int sure_groups; /* -2: the estimate's own (automatic) */
} run_settings;

/* The stopping protocol on one sequence: τ from its truth, the estimated and true
 * first spp per τ, and (with --curves) the percentile and mean-error curves. */
static void
run_estimate(const run_settings *rs, const mcp_series *series, const mcp_denoiser *den,
             const mcp_image *reference, const char *label, tally *tl)
{
    const double p = rs->p, floor = rs->floor;
    const int *tau_it = rs->tau_it;
    mcp_series_estimate_options eo = mcp_series_estimate_defaults();
    eo.est.p = p;
    if (rs->probes > 0) eo.est.sure.n_probes = rs->probes;
    eo.n_taus = 3;
    for (int t = 0; t < 3; t++) {
        double tau = true_percentile(series, tau_it[t] - 1, den, reference, p);
        eo.taus[t] = tau > 2 * floor ? tau : 2 * floor;
    }
    eo.est.n_percentiles = 1;
    eo.est.percentiles[0] = p;
    mcp_series_estimate *se = NULL;
    if (rs->s2_pool != -2) eo.est.s2_pool = rs->s2_pool;
    if (rs->probe_floor != -2) eo.est.probe_floor = rs->probe_floor;
    if (rs->sure_groups != -2) eo.est.sure_groups = rs->sure_groups;
    if (mcp_estimate_series(series, den, &eo, reference, NULL, NULL, &se))
        die("estimate series");
    for (int t = 0; t < 3; t++) {
        double est = se->first_spp[t], tru = se->true_first_spp[t];
        int early = est > 0 && (tru == 0 || est < tru / 2);
        tl->cases++;
        tl->agree += se->agree[t];
        tl->early += early;
        tl->never_est += est == 0;
        char e[32], tr[32];
        snprintf(e, sizeof e, est > 0 ? "%.0f" : "never", est);
        snprintf(tr, sizeof tr, tru > 0 ? "%.0f" : "never", tru);
        printf("| %s | %.4g%s | %s (%s) | %s | %s |\n", label, eo.taus[t],
               eo.taus[t] == 2 * floor ? " (floor)" : "", e, tr,
               se->agree[t] ? "yes" : "no", early ? "EARLY" : "");
    }
    if (rs->curves) {
        printf("|  | spp: est. / true 99.9th pct, est. / true mean error: ");
        for (int i = 0; i<se->count; i += se->count / 8> 0 ? se->count / 8 : 1)
            printf("%.0f: %.3g/%.3g, %.3g/%.3g; ", se->points[i].spp,
                   se->points[i].est_percentile[0], se->points[i].true_percentile[0],
                   se->points[i].est_mean_error, se->points[i].true_mean_error);
        printf("| | | |\n");
    }
    mcp_series_estimate_free(se);
}

/* The best any blend of n and d can do, given the reference: per value the weight
 * rho = <(n - R)(n - d)> / <(n - d)^2>, both averaged over the blend's own Gaussian
 * window (the window-optimal linear blend (1 - rho) n + rho d, rho in [0, 1]). It
 * bounds what weights from estimates can reach: where it is barely below
 * min(noisy, denoised), so must every blend be. */
typedef struct oracle_ctx {
    const mcp_image *reference;
    const mcp_blend_options *blend;
    double *oracle_mse; /* per member */
} oracle_ctx;

static int
oracle_point(const mcp_blend_point *p, void *vctx)
{
    oracle_ctx *c = vctx;
    const mcp_image *n = p->images[MCP_BLEND_NOISY], *d = p->images[MCP_BLEND_DENOISED];
    const mcp_image *ref = c->reference;
    size_t np = (size_t)n->width * n->height;
    mcp_image *num = NULL, *den = NULL, *num_f = NULL, *den_f = NULL;
    static const char *const rgb[] = {"R", "G", "B"};
    if (mcp_image_new(n->width, n->height, 3, rgb, &num) ||
        mcp_image_new(n->width, n->height, 3, rgb, &den))
        die("oracle blend");
    for (size_t i = 0; i < np; i++)
        for (int k = 0; k < 3; k++) {
            double e = n->data[i * n->channels + k] - ref->data[i * ref->channels + k];
            double g = n->data[i * n->channels + k] - d->data[i * d->channels + k];
            num->data[i * 3 + k] = (float)(e * g);
            den->data[i * 3 + k] = (float)(g * g);
        }
    /* the window the blend filters its estimates with at this member */
    if (p->est->filtered &&
        (mcp_blend_filter_image(num, p->est->mean_var, c->blend, NULL, &num_f) ||
         mcp_blend_filter_image(den, p->est->mean_var, c->blend, NULL, &den_f)))
        die("oracle blend");
    const mcp_image *a = num_f ? num_f : num, *b = den_f ? den_f : den;
    double sum = 0;
    for (size_t i = 0; i < np; i++)
        for (int k = 0; k < 3; k++) {
            double q = b->data[i * 3 + k];
            double rho = q > 0 ? fmin(1, fmax(0, a->data[i * 3 + k] / q)) : 1;
            double nv = n->data[i * n->channels + k];
            double e = nv + rho * (d->data[i * d->channels + k] - nv) -
                       ref->data[i * ref->channels + k];
            sum += e * e;
        }
    c->oracle_mse[p->index] = sum / (3.0 * (double)np);
    mcp_image_free(num);
    mcp_image_free(den);
    mcp_image_free(num_f);
    mcp_image_free(den_f);
    return 0;
}

/* The curve blend on the same sequence: where it is <= min(noisy, denoised), its MSE
 * over the noisy image's at the last member, and both it and the window-optimal
 * oracle over min(noisy, denoised). */
static void
run_blend(const run_settings *rs, const mcp_series *series, const mcp_denoiser *den,
          const mcp_image *reference, const char *label, tally *tl)
{
    mcp_blend_series_options bo = mcp_blend_series_defaults();
    bo.flip = 0;
    bo.blend.fit = rs->fit;
    bo.blend.safeguard = rs->safeguard;
    oracle_ctx oc = {reference, &bo.blend, calloc((size_t)series->count, sizeof(double))};
    if (!oc.oracle_mse) die("out of memory");
    mcp_blend_series_result *br = NULL;
    if (mcp_blend_series(series, den, reference, &bo, oracle_point, &oc, &br))
        die("blend series");
    int good = 0, near = 0, js_near = 0;
    double curves_sum = 0, oracle_sum = 0, worst = 0, js_worst = 0;
    for (int i = 0; i < br->count; i++) {
        const mcp_blend_errors *e = br->rows[i].err;
        double lo = fmin(e[MCP_BLEND_NOISY].mse, e[MCP_BLEND_DENOISED].mse);
        good += e[MCP_BLEND_CURVES].mse <= lo;
        near += e[MCP_BLEND_CURVES].mse <= 1.10 * lo;
        worst = fmax(worst, e[MCP_BLEND_CURVES].mse / lo);
        js_near += e[MCP_BLEND_JAMES_STEIN].mse <= 1.10 * lo;
        js_worst = fmax(js_worst, e[MCP_BLEND_JAMES_STEIN].mse / lo);
        curves_sum += e[MCP_BLEND_CURVES].mse / lo;
        oracle_sum += oc.oracle_mse[i] / lo;
    }
    const mcp_blend_errors *last = br->rows[br->count - 1].err;
    double final = last[MCP_BLEND_CURVES].mse / last[MCP_BLEND_NOISY].mse;
    tl->blend_points += br->count;
    tl->blend_good += good;
    tl->blend_near += near;
    tl->js_near += js_near;
    tl->js_worst_member = fmax(tl->js_worst_member, js_worst);
    tl->js_worst_final = fmax(tl->js_worst_final, last[MCP_BLEND_JAMES_STEIN].mse /
                                                      last[MCP_BLEND_NOISY].mse);
    tl->blend_cases++;
    if (worst > tl->worst_member) tl->worst_member = worst;
    tl->curves_over_min += curves_sum;
    tl->oracle_over_min += oracle_sum;
    if (final > tl->worst_final) tl->worst_final = final;
    printf("| %s blend | | <= min(noisy, denoised) at %d of %d, <= 1.10x min at %d; over "
           "min: "
           "%.3fx on average, %.3fx at worst (window-optimal oracle %.3fx); last: %.3fx "
           "noisy MSE (denoised %.3fx); James-Stein <= 1.10x min at %d, %.3fx at worst, "
           "last %.3fx noisy | | |\n",
           label, good, br->count, near, curves_sum / br->count, worst,
           oracle_sum / br->count, final,
           last[MCP_BLEND_DENOISED].mse / last[MCP_BLEND_NOISY].mse, js_near, js_worst,
           last[MCP_BLEND_JAMES_STEIN].mse / last[MCP_BLEND_NOISY].mse);
    if (rs->curves) { /* per member: the James-Stein blend, noisy and denoised MSE */
        printf("|  | spp: James-Stein / min, noisy / min, denoised / min:");
        for (int i = 0; i < br->count; i++) {
            const mcp_blend_errors *e = br->rows[i].err;
            double lo = fmin(e[MCP_BLEND_NOISY].mse, e[MCP_BLEND_DENOISED].mse);
            printf(" %g: %.3f, %.2f, %.2f;", br->rows[i].spp,
                   e[MCP_BLEND_JAMES_STEIN].mse / lo, e[MCP_BLEND_NOISY].mse / lo,
                   e[MCP_BLEND_DENOISED].mse / lo);
        }
        printf(" | | |\n");
    }
    mcp_blend_series_result_free(br);
    free(oc.oracle_mse);
}

static int
split(char *text, char **words, int max)
{
    int n = 0;
    for (char *t = strtok(text, ","); t; t = strtok(NULL, ",")) {
        if (n == max) return -1; /* more than the tables hold: say so, drop none */
        words[n++] = t;
    }
    return n;
}

int
main(int argc, char **argv)
{
    const char *fixtures = "samples/fixtures/strat",
               *weights = getenv("MCPOST_OIDN_WEIGHTS");
    char scenes_arg[256] = "cornell,texture,interior",
         dens_arg[256] = "nlm,bilateral,unet";
    char srcs_arg[256] = "auto,per-sample,increments,replicates4,replicates8,oracle";
    int iters = MAX_ITER, blend = 1, estimate = 1, curves = 0, probes = 0, s2_pool = -2,
        probe_floor = -2, sure_groups = -2, safeguard = 1;
    mcp_curve_fit fit = mcp_blend_defaults().fit;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--scenes") && v)
            snprintf(scenes_arg, sizeof scenes_arg, "%s", v), i++;
        else if (!strcmp(a, "--denoisers") && v)
            snprintf(dens_arg, sizeof dens_arg, "%s", v), i++;
        else if (!strcmp(a, "--sources") && v)
            snprintf(srcs_arg, sizeof srcs_arg, "%s", v), i++;
        else if (!strcmp(a, "--fixtures") && v)
            fixtures = v, i++;
        else if (!strcmp(a, "--weights") && v)
            weights = v, i++;
        else if (!strcmp(a, "--iterations") && v)
            iters = atoi(v), i++;
        else if (!strcmp(a, "--fit") && v) {
            if (mcp_curve_fit_from_name(v, &fit)) die("--fit");
            i++;
        } else if (!strcmp(a, "--s2-pool") && v)
            s2_pool = atoi(v), i++;
        else if (!strcmp(a, "--probe-floor") && v)
            probe_floor = atoi(v), i++;
        else if (!strcmp(a, "--sure-groups") && v)
            sure_groups = atoi(v), i++;
        else if (!strcmp(a, "--probes") && v)
            probes = atoi(v), i++;
        else if (!strcmp(a, "--blend-only"))
            estimate = 0;
        else if (!strcmp(a, "--no-blend"))
            blend = 0;
        else if (!strcmp(a, "--curves"))
            curves = 1;
        else if (!strcmp(a, "--no-safeguard"))
            safeguard = 0;
        else {
            fprintf(stderr,
                    "usage: bench_fidelity [--scenes LIST] [--denoisers LIST] "
                    "[--sources LIST] [--fixtures DIR] [--weights TZA] "
                    "[--iterations N] [--probes K] [--s2-pool R] [--probe-floor R] "
                    "[--sure-groups G] [--fit NAME] [--no-blend | "
                    "--blend-only] [--curves] [--no-safeguard]\n");
            return 2;
        }
    }
    if (iters < 4 || iters > MAX_ITER) iters = MAX_ITER;
    char *scenes[16], *dens[8], *srcs[8];
    int n_scenes = split(scenes_arg, scenes, 16), n_dens = split(dens_arg, dens, 8),
        n_srcs = split(srcs_arg, srcs, 8);
    if (n_scenes < 0 || n_dens < 0 || n_srcs < 0) {
        fprintf(stderr, "bench_fidelity: at most 16 scenes, 8 denoisers and 8 sources\n");
        return 2;
    }
    source src_ids[8];
    for (int k = 0; k < n_srcs; k++) {
        src_ids[k] = N_SRC;
        for (int q = 0; q < N_SRC; q++)
            if (!strcmp(srcs[k], source_names[q])) src_ids[k] = (source)q;
        if (src_ids[k] == N_SRC) {
            fprintf(stderr, "bench_fidelity: unknown source '%s'\n", srcs[k]);
            return 2;
        }
    }
    char tmp[] = "/tmp/mcpost-fidelity-XXXXXX";
    if (!mkdtemp(tmp)) {
        perror("mkdtemp");
        return 1;
    }
    const double p = 0.999;
    const int tau_iters[3] = {2, 6, 16};
    tally total[N_SRC][8];
    memset(total, 0, sizeof total);
    printf("bench_fidelity: %d iterations of 32 spp, p = %g, fixtures %s\n", iters, p,
           fixtures);
    for (int si = 0; si < n_scenes; si++) {
        scene s;
        if (load_scene(fixtures, scenes[si], &s)) {
            fprintf(stderr, "bench_fidelity: scene %s skipped: %s\n", scenes[si],
                    mcp_error_message());
            continue;
        }
        printf("\n## %s\n", s.name);
        for (int k = 0; k < n_srcs; k++) {
            source src = src_ids[k];
            double ratio = 0, ref_spp = 0;
            double t0 = now_ms();
            /* replicates advance 32 spp each per iteration: stop at 2048 in all, an
               eighth of the reference, as the single render's 1024 is a sixteenth */
            int n_it = src == SRC_REP4 ? iters / 2 : src == SRC_REP8 ? iters / 4 : iters;
            mcp_image *reference = reference_for(&s, src, &ref_spp);
            double floor = reference_floor(&s, p, ref_spp);
            int tau_it[3];
            for (int t = 0; t < 3; t++) {
                tau_it[t] = (int)lround(tau_iters[t] * n_it / 32.0);
                if (tau_it[t] < 1) tau_it[t] = 1;
            }
            mcp_series *series = write_series(&s, src, n_it, tmp, &ratio);
            run_settings run = {p,   probes, s2_pool, curves,      safeguard,
                                fit, floor,  tau_it,  probe_floor, sure_groups};
            printf("\n### %s, %s%s; reference %.0f spp, its noise floor at p %.3g",
                   s.name, source_names[src],
                   src == SRC_REP4 || src == SRC_REP8 ? " (spp: all renders together)"
                                                      : "",
                   ref_spp, floor);
            if (ratio > 0)
                printf(
                    "; Variance/n over the increments' spread at the last member: %.2f",
                    ratio);
            printf("\n\n| denoiser | τ | estimated spp (true) | agree | early |\n"
                   "|---|---|---|---|---|\n");
            for (int di = 0; di < n_dens; di++) {
                /* js-NAME: NAME followed by the James-Stein post-correction */
                const char *opts[2] = {NULL, NULL}, *kind = dens[di], *base = dens[di];
                char wopt[4200], inner[64];
                int n_opts = 0;
                if (!strncmp(dens[di], "js-", 3)) {
                    base = dens[di] + 3;
                    snprintf(inner, sizeof inner, "inner=%s", base);
                    kind = "james-stein";
                    opts[n_opts++] = inner;
                }
                if (!strcmp(base, "unet") && weights) {
                    snprintf(wopt, sizeof wopt, "weights=%s", weights);
                    opts[n_opts++] = wopt;
                }
                mcp_denoiser *den = NULL;
                if (mcp_denoiser_create_from_args(kind, opts, n_opts, &den))
                    die(dens[di]);
                tally *tl = &total[src][di];
                if (estimate) run_estimate(&run, series, den, reference, dens[di], tl);
                if (blend) run_blend(&run, series, den, reference, dens[di], tl);
                mcp_denoiser_free(den);
            }
            printf("\n(%.1f s)\n", (now_ms() - t0) / 1e3);
            fflush(stdout);
            for (int j = 0; j < series->count; j++)
                unlink(series->paths[j]);
            mcp_series_free(series);
            mcp_image_free(reference);
        }
        free_scene(&s);
    }
    printf("\n## Summary over the scenes\n\n| source | denoiser | agree | early stops | "
           "never stops | blend <= min | blend <= 1.10x min | blend / min (mean) | "
           "blend / min (worst member) | oracle / min (mean) | blend / noisy at the end "
           "(worst) | James-Stein <= 1.10x min | its worst member | its end |\n"
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int k = 0; k < n_srcs; k++)
        for (int di = 0; di < n_dens; di++) {
            const tally *t = &total[src_ids[k]][di];
            if (!t->cases && !t->blend_cases) continue;
            if (t->cases)
                printf("| %s | %s | %d of %d (%.0f%%) | %d | %d |",
                       source_names[src_ids[k]], dens[di], t->agree, t->cases,
                       100.0 * t->agree / t->cases, t->early, t->never_est);
            else /* --blend-only */
                printf("| %s | %s | | | |", source_names[src_ids[k]], dens[di]);
            if (t->blend_cases)
                printf(" %d of %d (%.0f%%) | %d of %d (%.0f%%) | %.3fx | %.3fx | %.3fx | "
                       "%.3fx |",
                       t->blend_good, t->blend_points,
                       100.0 * t->blend_good / t->blend_points, t->blend_near,
                       t->blend_points, 100.0 * t->blend_near / t->blend_points,
                       t->curves_over_min / t->blend_points, t->worst_member,
                       t->oracle_over_min / t->blend_points, t->worst_final);
            if (t->blend_cases)
                printf(" %d of %d (%.0f%%) | %.3fx | %.3fx |\n", t->js_near,
                       t->blend_points, 100.0 * t->js_near / t->blend_points,
                       t->js_worst_member, t->js_worst_final);
            else
                printf(" | | | | | | | | |\n");
        }
    rmdir(tmp);
    return 0;
}
