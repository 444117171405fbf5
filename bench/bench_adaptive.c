/* bench_adaptive.c: the equal-error speed-up of adaptive sampling over uniform
 * sampling (Firmino 2023 Table 1) and over the renderers' own stopping rule (Cycles'
 * noise threshold, estimate/renderer_rule.c), on the procedural scene with its exact
 * truth, with the independent and the jittered (stratified 4x4) sampler, per denoiser
 * and map, each map also with the shares of every pass spread uniformly that
 * --mixes lists (none by default); and the time mcpost adds per iteration (merge,
 * estimate besides the denoiser, counts) against the denoiser's own.
 *
 * Speed-up, as in the paper: every map runs to the budget B; the uniform run goes on
 * to 4 B; the uniform spp at which the uniform curve (relMSE of the denoised image
 * after each pass) reaches the map's final relMSE, interpolated log-log between the
 * passes that bracket it, divided by B.
 *
 * Over the rule, the same against the rule's best curve: the rule runs once per
 * threshold of --thresholds and min samples of --min-samples (checks every 16
 * samples, up to 4 B samples per pixel); after every 32 samples of its unstopped
 * pixels the state is what a render with that threshold and that sample count
 * gives (the passes run in lockstep), so each run gives a point (mean spp, denoised
 * relMSE) per sample count, a curve. The rule at its best for an error is the fewest
 * spp at which any run's curve, or uniform's (adaptive sampling off), reaches it,
 * each interpolated as uniform's is: the best threshold and min samples for that
 * error, chosen knowing the truth (which favours the rule).
 *
 *   bench_adaptive [--size N] [--budget SPP] [--spp-per-iteration N]
 *                  [--denoisers nlm,unet] [--seeds K] [--plot FILE.svg]
 *                  [--firefly-probability P] [--probes K]
 *                  [--thresholds T1,T2,...] [--min-samples N1,N2,...]
 *                  [--mixes M1,M2,...]
 *                  [--verbose 1]    (every point of the rule's runs on stderr)
 *                  [--overhead N]   (only the overhead figure, at NxN with nlm)
 *
 * The plot shows the first seed's curves of the independent sampler's scenes (the
 * jittered ones lie close to them and would crowd it). */
#include "bench.h"

#include <mcpost/estimate.h>
#include <mcpost/plot.h>
#include <mcpost/imageio.h>

#include "procedural.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_LIST 16 /* numbers in a --thresholds, --min-samples or --mixes list */

typedef struct scene_ctx {
    mcp_proc_scene scene;
    uint64_t seed;
} scene_ctx;

static int g_probes = 0;  /* --probes: the estimate's (0: its default, as users get it) */
static int g_verbose = 0; /* --verbose 1: every point of the rule's runs on stderr */
/* what every run's passes spent, per denoiser: mcpost's part and the denoiser's */
static double g_ms_added, g_ms_denoise;
static long g_passes;

static int
render(int pass, const mcp_image *counts, mcp_dump **out, void *ctx)
{
    const scene_ctx *s = ctx;
    return mcp_proc_render_counts(&s->scene, counts, pass, s->seed, out);
}

static int
render_half(int pass, const mcp_image *counts, mcp_dump **out, mcp_image **half,
            void *ctx)
{
    const scene_ctx *s = ctx;
    return mcp_proc_render_counts_half(&s->scene, counts, pass, s->seed, out, half);
}

static void
die(const char *what)
{
    fprintf(stderr, "bench_adaptive: %s: %s\n", what, mcp_error_message());
    exit(1);
}

/* One run; returns the result (the caller frees it). */
static mcp_adaptive_result *
run(scene_ctx *s, const mcp_denoiser *den, mcp_adaptive_map map, double mix,
    double budget, double spp_it, const mcp_image *ref)
{
    mcp_adaptive_options o = mcp_adaptive_defaults();
    o.map = map;
    if (mix >= 0) o.uniform_mix = mix;
    o.budget_spp = budget;
    o.spp_per_iteration = spp_it;
    o.quantum = s->scene.sampler == MCP_PROC_SAMPLER_JITTERED
                    ? s->scene.strata * s->scene.strata
                    : 1;
    o.est.sure.seed = s->seed;
    if (g_probes > 0) o.est.sure.n_probes = g_probes;
    mcp_adaptive_result *r = NULL;
    if (mcp_adaptive_run(s->scene.width, s->scene.height, den, &o, render, s, ref, NULL,
                         NULL, &r))
        die("adaptive run");
    for (int i = 0; i < r->count; i++) {
        const mcp_adaptive_iteration *it = &r->iterations[i];
        g_ms_added += it->ms_merge + it->ms_estimate + it->ms_counts;
        g_ms_denoise += it->ms_denoise;
        g_passes++;
    }
    return r;
}

static int
overhead(int size)
{
    scene_ctx s = {mcp_proc_scene_defaults(), 1};
    s.scene.width = s.scene.height = size;
    mcp_denoiser *den = NULL;
    if (mcp_denoiser_create_from_args("nlm", NULL, 0, &den)) die("nlm");
    mcp_adaptive_result *r = run(&s, den, MCP_ADAPTIVE_VARIANCE, -1, 96, 32, NULL);
    printf("overhead at %dx%d, nlm, variance map, 32 spp per pass (ms per pass):\n", size,
           size);
    printf("%5s %9s %9s %9s %9s %9s %9s\n", "pass", "render", "denoise", "merge",
           "estimate", "counts", "mcpost/den");
    for (int i = 0; i < r->count; i++) {
        const mcp_adaptive_iteration *it = &r->iterations[i];
        double added = it->ms_merge + it->ms_estimate + it->ms_counts;
        printf("%5d %9.1f %9.1f %9.1f %9.1f %9.1f %8.1f%%\n", it->pass, it->ms_render,
               it->ms_denoise, it->ms_merge, it->ms_estimate, it->ms_counts,
               100.0 * added / it->ms_denoise);
    }
    mcp_adaptive_result_free(r);
    mcp_denoiser_free(den);
    return 0;
}

/* A list "a,b,c" of numbers into v (at most cap); returns how many. */
static int
parse_list(const char *text, double *v, int cap)
{
    int n = 0;
    const char *p = text;
    while (*p && n < cap) {
        char *end;
        v[n++] = strtod(p, &end);
        if (end == p) {
            fprintf(stderr, "bench_adaptive: bad number list '%s'\n", text);
            exit(2);
        }
        p = *end == ',' ? end + 1 : end;
    }
    return n;
}

/* The error of a decreasing curve at spp x, log-log between the points that bracket
 * it; NAN outside it. */
static double
curve_at(const double *spp, const double *err, int n, double x)
{
    for (int i = 0; i < n; i++) {
        if (spp[i] == x) return err[i];
        if (i > 0 && spp[i - 1] < x && x < spp[i]) {
            double f = log(x / spp[i - 1]) / log(spp[i] / spp[i - 1]);
            return exp(log(err[i - 1]) + f * log(err[i] / err[i - 1]));
        }
    }
    return NAN;
}

/* A speed-up's text: "1.23x", "<0.25x" when the method is worse than the curve's
 * first point (then *value is that bound), ">4.00x" when better than its last (then
 * *value is NAN: left out of the mean). */
static void
speedup_text(double eq, double spp, const double *cs, const double *ce, int n, double err,
             char *text, size_t cap, double *value, int *bounded)
{
    *value = eq / spp;
    snprintf(text, cap, "%.2fx", *value);
    if (isnan(*value) && n > 0 && err > ce[0]) {
        *value = cs[0] / spp;
        snprintf(text, cap, "<%.2fx", *value);
        *bounded = 1;
    } else if (isnan(*value) && n > 0) {
        snprintf(text, cap, ">%.2fx", cs[n - 1] / spp);
    }
}

/* Curves (mean spp ascending, relMSE): uniform's and one per run of the rule. */
#define MAX_RUNS (MAX_LIST * MAX_LIST + 1)
#define MAX_POINTS 256
typedef struct curves {
    int n, len[MAX_RUNS];
    double spp[MAX_RUNS][MAX_POINTS], err[MAX_RUNS][MAX_POINTS];
} curves;

/* The rule's runs on one scene for every threshold and min samples, after the
 * uniform run's curve (adaptive sampling off, the limit of a zero threshold). */
static void
rule_curves(scene_ctx *s, const mcp_denoiser *den, const double *thresholds, int nt,
            const double *mins, int nmin, double budget, double spp_it,
            const mcp_image *ref, const double *us, const double *ue, int nu, curves *c)
{
    c->n = 1;
    c->len[0] = nu < MAX_POINTS ? nu : MAX_POINTS;
    memcpy(c->spp[0], us, sizeof(double) * c->len[0]);
    memcpy(c->err[0], ue, sizeof(double) * c->len[0]);
    for (int k = 0; k < nt * nmin && c->n < MAX_RUNS; k++) {
        const int t = k / nmin;
        mcp_renderer_rule_options o = mcp_renderer_rule_defaults();
        o.threshold = thresholds[t];
        o.min_samples = (int)mins[k % nmin];
        o.max_spp = (int)(4 * budget);
        o.record_every = (int)spp_it;
        mcp_renderer_rule_result *r = NULL;
        if (mcp_renderer_rule_run(s->scene.width, s->scene.height, den, &o, render_half,
                                  s, ref, &r))
            die("renderer rule");
        int m = 0;
        for (int i = 0; i < r->count && m < MAX_POINTS; i++, m++) {
            c->spp[c->n][m] = r->points[i].mean_spp;
            c->err[c->n][m] = r->points[i].relmse;
            if (g_verbose)
                fprintf(stderr,
                        "    rule t=%g (min %d) at %d spp: mean %.1f spp, "
                        "%ld active, relMSE %.5g\n",
                        thresholds[t], r->min_samples, r->points[i].max_spp,
                        r->points[i].mean_spp, r->points[i].active, r->points[i].relmse);
        }
        c->len[c->n++] = m;
        mcp_renderer_rule_result_free(r);
    }
}

/* The rule at its best for an error: the fewest spp at which any of the curves
 * reaches it (each interpolated log-log between its own points, as for uniform);
 * NAN when none does. *below: some curve is already below it at its first point
 * (then that first point's spp counts, an upper bound). */
static double
best_equal_error(const curves *c, double target, int *below)
{
    double best = NAN;
    *below = 0;
    for (int k = 0; k < c->n; k++) {
        if (c->len[k] < 1) continue;
        double eq = mcp_equal_error_spp(c->spp[k], c->err[k], c->len[k], target);
        if (isnan(eq) && c->err[k][0] <= target) eq = c->spp[k][0], *below = 1;
        if (!isnan(eq) && !(eq >= best)) best = eq;
    }
    return best;
}

/* The rule's error at x spp: the lowest of the curves that reach x. */
static double
best_error_at(const curves *c, double x)
{
    double best = NAN;
    for (int k = 0; k < c->n; k++) {
        double e = curve_at(c->spp[k], c->err[k], c->len[k], x);
        if (!isnan(e) && !(e >= best)) best = e;
    }
    return best;
}

#define MAX_CURVES 64
#define MAX_CURVE_POINTS 256

/* The plot's curves, kept until it is drawn: each one's points and legend. A caller
 * writes a curve's points into x[n], y[n] and then adds it (curve_add). */
typedef struct plot_curves {
    int n;
    double x[MAX_CURVES][MAX_CURVE_POINTS], y[MAX_CURVES][MAX_CURVE_POINTS];
    char name[MAX_CURVES][96];
    mcp_plot_series series[MAX_CURVES];
} plot_curves;

/* Adds the curve of `points` points written at pc->x[pc->n], pc->y[pc->n], its legend
 * from fmt. */
static void
curve_add(plot_curves *pc, int points, int dashed, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(pc->name[pc->n], sizeof pc->name[pc->n], fmt, ap);
    va_end(ap);
    pc->series[pc->n] = (mcp_plot_series){pc->name[pc->n], MCP_SERIES_LINE_POINTS,
                                          pc->x[pc->n],    pc->y[pc->n],
                                          points,          dashed};
    pc->n++;
}
#define MAX_VARIANTS (3 * MAX_LIST)

int
main(int argc, char **argv)
{
    int size = 128, seeds = 1, over = 0;
    double fireflies = -1; /* < 0: the scene's default */
    double budget = 128, spp_it = 32;
    const char *denoisers = "nlm", *plot_path = NULL;
    /* Cycles' noise thresholds (its default is 0.01) and min samples (0: automatic),
       the ones whose runs are the rule's best from about 60 to 300 spp on these
       scenes: in a sweep of 0.0025 to 0.08 with min samples 16, 32 and automatic,
       0.04 and 0.08 were best only below 60 spp, 0.0025 only above 300, and min
       samples 32 within 3% of 16 (docs/adaptive.md) */
    const char *threshold_list = "0.005,0.01,0.02";
    const char *min_list = "0,16";
    const char *mix_list = "0"; /* shares of uniform samples, each beside the maps */
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--size"))
            size = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--budget"))
            budget = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--spp-per-iteration"))
            spp_it = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--denoisers"))
            denoisers = argv[i + 1];
        else if (!strcmp(argv[i], "--seeds"))
            seeds = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--plot"))
            plot_path = argv[i + 1];
        else if (!strcmp(argv[i], "--overhead"))
            over = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--firefly-probability"))
            fireflies = atof(argv[i + 1]);
        else if (!strcmp(argv[i], "--probes"))
            g_probes = atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--thresholds"))
            threshold_list = argv[i + 1];
        else if (!strcmp(argv[i], "--min-samples"))
            min_list = argv[i + 1];
        else if (!strcmp(argv[i], "--mixes"))
            mix_list = argv[i + 1];
        else if (!strcmp(argv[i], "--verbose"))
            g_verbose = atoi(argv[i + 1]);
        else {
            fprintf(stderr, "bench_adaptive: unknown option %s\n", argv[i]);
            return 2;
        }
    }
    if (over > 0) return overhead(over);
    double thresholds[MAX_LIST], mixes[MAX_LIST], mins[MAX_LIST];
    const int nt = parse_list(threshold_list, thresholds, MAX_LIST);
    const int nmin = parse_list(min_list, mins, MAX_LIST);
    const int nm = parse_list(mix_list, mixes, MAX_LIST);
    static const mcp_adaptive_map maps[] = {
        MCP_ADAPTIVE_VARIANCE, MCP_ADAPTIVE_TONEMAPPED, MCP_ADAPTIVE_MC_SURE};
    static const char *const sampler_names[] = {"independent", "jittered 4x4"};
    /* every map with every mix */
    const int nv = 3 * nm;
    double sum_speedup[MAX_VARIANTS] = {0}, sum_over_rule[MAX_VARIANTS] = {0};
    int n_speedup[MAX_VARIANTS] = {0}, n_over_rule[MAX_VARIANTS] = {0};
    double sum_rule = 0;
    int n_rule = 0;
    char vnames[MAX_VARIANTS][48];
    for (int v = 0; v < nv; v++) {
        const char *mn = mcp_adaptive_map_name(maps[v / nm]);
        double mix = mixes[v % nm];
        if (mix > 0)
            snprintf(vnames[v], sizeof vnames[v], "%s+%g%%u", mn, 100 * mix);
        else
            snprintf(vnames[v], sizeof vnames[v], "%s", mn);
    }
    /* the curves of the first seed, for the plot */
    static plot_curves plot;
    static curves rule;
    int bounded = 0;
    printf("adaptive vs uniform and vs the renderer rule at %g spp (%g per pass), "
           "%dx%d procedural scene, %d seed(s)\n",
           budget, spp_it, size, size, seeds);
    printf("renderer rule: Cycles' noise threshold in {%s}, min samples in {%s} (0: "
           "automatic), checks every 16 spp, up to %g spp; at every error the best of "
           "its runs and uniform\n",
           threshold_list, min_list, 4 * budget);
    for (int m = 0; m < nm; m++)
        if (mixes[m] > 0) {
            printf("(map+N%%u: N%% of every adaptive pass spread uniformly)\n");
            break;
        }
    printf("%-20s %-9s %-16s %11s %11s %9s %9s\n", "scene", "denoiser", "map", "relMSE",
           "uniform@B", "speed-up", "vs rule");
    char list[256];
    snprintf(list, sizeof list, "%s", denoisers);
    for (char *dn = strtok(list, ","); dn; dn = strtok(NULL, ",")) {
        mcp_denoiser *den = NULL;
        if (mcp_denoiser_create_from_args(dn, NULL, 0, &den)) die(dn);
        /* four scenes: the default scene (fireflies) and the same without fireflies,
           each with the independent and the jittered sampler */
        for (int sc = 0; sc < (fireflies >= 0 ? 2 : 4); sc++) {
            int smp = sc & 1;
            scene_ctx s = {mcp_proc_scene_defaults(), 1};
            s.scene.width = s.scene.height = size;
            if (fireflies >= 0) s.scene.firefly_probability = fireflies;
            if (sc >= 2) s.scene.firefly_probability = 0;
            char sname[64];
            snprintf(sname, sizeof sname, "%s%s", sampler_names[smp],
                     s.scene.firefly_probability > 0 ? "" : ", no ff");
            s.scene.sampler =
                smp ? MCP_PROC_SAMPLER_JITTERED : MCP_PROC_SAMPLER_INDEPENDENT;
            mcp_image *ref = NULL;
            if (mcp_proc_truth(&s.scene, &ref, NULL)) die("truth");
            for (int sd = 0; sd < seeds; sd++) {
                s.seed = 1 + (uint64_t)sd;
                double t0 = now_ms();
                mcp_adaptive_result *u =
                    run(&s, den, MCP_ADAPTIVE_UNIFORM, -1, 4 * budget, spp_it, ref);
                double t_uniform = now_ms() - t0;
                int nu = u->count;
                double *us = malloc(sizeof(double) * nu),
                       *ue = malloc(sizeof(double) * nu);
                double at_b = NAN;
                for (int i = 0; i < nu; i++) {
                    us[i] = u->iterations[i].mean_spp;
                    ue[i] = u->iterations[i].relmse;
                    if (fabs(us[i] - budget) < 1e-9) at_b = ue[i];
                }
                if (sd == 0 && smp == 0 && plot.n < MAX_CURVES &&
                    nu <= MAX_CURVE_POINTS) {
                    memcpy(plot.x[plot.n], us, sizeof(double) * nu);
                    memcpy(plot.y[plot.n], ue, sizeof(double) * nu);
                    curve_add(&plot, nu, 1, "uniform (%s, %s)", dn, sname);
                }
                /* the renderer rule at its best: its runs' curves, its error at B and
                   its own speed-up over uniform there */
                t0 = now_ms();
                rule_curves(&s, den, thresholds, nt, mins, nmin, budget, spp_it, ref, us,
                            ue, nu, &rule);
                double t_rule = now_ms() - t0;
                double rule_at_b = best_error_at(&rule, budget);
                /* the plot: the rule's best run at each of uniform's sample counts (the
                   lower envelope of its thresholds and min samples) */
                if (sd == 0 && smp == 0 && plot.n < MAX_CURVES) {
                    int k = 0;
                    for (int i = 0; i < nu && k < MAX_CURVE_POINTS; i++) {
                        const double e = best_error_at(&rule, us[i]);
                        if (isnan(e)) continue;
                        plot.x[plot.n][k] = us[i], plot.y[plot.n][k] = e, k++;
                    }
                    if (k > 1)
                        curve_add(&plot, k, 0, "renderer rule, best run (%s, %s)", dn,
                                  sname);
                }
                if (g_verbose) {
                    fprintf(stderr, "    uniform:");
                    for (int i = 0; i < nu; i++)
                        fprintf(stderr, " (%g, %.5g)", us[i], ue[i]);
                    fprintf(stderr, "\n");
                }
                double rule_speedup;
                char text[32], text2[32];
                speedup_text(mcp_equal_error_spp(us, ue, nu, rule_at_b), budget, us, ue,
                             nu, rule_at_b, text, sizeof text, &rule_speedup, &bounded);
                printf("%-20s %-9s %-16s %11.5g %11.5g %9s %9s\n", sname, dn,
                       "renderer rule", rule_at_b, at_b, text, "1.00x");
                if (isfinite(rule_speedup)) sum_rule += rule_speedup, n_rule++;
                for (int v = 0; v < nv; v++) {
                    const mcp_adaptive_map map = maps[v / nm];
                    mcp_adaptive_result *r =
                        run(&s, den, map, mixes[v % nm], budget, spp_it, ref);
                    const mcp_adaptive_iteration *last = &r->iterations[r->count - 1];
                    double speedup, over_rule;
                    speedup_text(mcp_equal_error_spp(us, ue, nu, last->relmse),
                                 last->mean_spp, us, ue, nu, last->relmse, text,
                                 sizeof text, &speedup, &bounded);
                    int below = 0;
                    double eq_rule = best_equal_error(&rule, last->relmse, &below);
                    over_rule = eq_rule / last->mean_spp;
                    snprintf(text2, sizeof text2, "%s%.2fx", below ? "<" : "", over_rule);
                    if (below) bounded = 1;
                    if (isnan(eq_rule)) snprintf(text2, sizeof text2, "> 4B");
                    printf("%-20s %-9s %-16s %11.5g %11.5g %9s %9s\n", sname, dn,
                           vnames[v], last->relmse, at_b, text, text2);
                    if (isfinite(speedup)) sum_speedup[v] += speedup, n_speedup[v]++;
                    if (isfinite(over_rule))
                        sum_over_rule[v] += over_rule, n_over_rule[v]++;
                    if (sd == 0 && smp == 0 && mixes[v % nm] == 0 &&
                        plot.n < MAX_CURVES && r->count <= MAX_CURVE_POINTS) {
                        for (int i = 0; i < r->count; i++) {
                            plot.x[plot.n][i] = r->iterations[i].mean_spp;
                            plot.y[plot.n][i] = r->iterations[i].relmse;
                        }
                        curve_add(&plot, r->count, 0, "%s (%s, %s)",
                                  mcp_adaptive_map_name(map), dn, sname);
                    }
                    mcp_adaptive_result_free(r);
                }
                fprintf(stderr,
                        "  (%s, %s, seed %d: uniform run %.1f s, the rule's %d runs "
                        "%.1f s)\n",
                        dn, sname, sd + 1, t_uniform / 1e3, nt * nmin, t_rule / 1e3);
                free(us);
                free(ue);
                mcp_adaptive_result_free(u);
            }
            mcp_image_free(ref);
        }
        printf("%s: per pass, mcpost adds %.1f ms (merge, estimate besides the denoiser, "
               "counts) to the denoiser's %.1f ms (%.1f%%), over %ld passes\n",
               dn, g_ms_added / g_passes, g_ms_denoise / g_passes,
               100.0 * g_ms_added / g_ms_denoise, g_passes);
        g_ms_added = g_ms_denoise = 0;
        g_passes = 0;
        mcp_denoiser_free(den);
    }
    printf("mean equal-error speed-up over uniform%s: renderer rule %.2fx",
           bounded ? " (an upper bound: '<' runs count as their bound)" : "",
           n_rule ? sum_rule / n_rule : NAN);
    for (int v = 0; v < nv; v++)
        printf(", %s %.2fx", vnames[v],
               n_speedup[v] ? sum_speedup[v] / n_speedup[v] : NAN);
    printf("\nmean equal-error speed-up over the renderer rule:");
    for (int v = 0; v < nv; v++)
        printf(" %s %.2fx%s", vnames[v],
               n_over_rule[v] ? sum_over_rule[v] / n_over_rule[v] : NAN,
               v + 1 < nv ? "," : "\n");
    if (plot_path) {
        mcp_plot p = {"relMSE of the denoised image against samples per pixel",
                      "samples per pixel",
                      "relMSE",
                      MCP_AXIS_LOG,
                      MCP_AXIS_LOG,
                      plot.series,
                      plot.n,
                      720,
                      450};
        char *svg = NULL;
        if (mcp_plot_svg(&p, &svg) || mcp_write_file_atomic(plot_path, svg, strlen(svg)))
            die(plot_path);
        free(svg);
        printf("plot: %s\n", plot_path);
    }
    return 0;
}
