/* bench_adaptive.c: the equal-error speed-up of adaptive sampling over uniform
 * sampling (Firmino 2023 Table 1), on the procedural scene with its exact truth, with
 * the independent and the jittered (stratified 4x4) sampler, per denoiser and map;
 * and the time mcpost adds per iteration (merge, estimate besides the denoiser,
 * counts) against the denoiser's own.
 *
 * Speed-up, as in the paper: every map runs to the budget B; the uniform run goes on
 * to 4 B; the uniform spp at which the uniform curve (relMSE of the denoised image
 * after each pass) reaches the map's final relMSE, interpolated log-log between the
 * passes that bracket it, divided by B.
 *
 *   bench_adaptive [--size N] [--budget SPP] [--spp-per-iteration N]
 *                  [--denoisers nlm,unet] [--seeds K] [--plot FILE.svg]
 *                  [--firefly-probability P] [--probes K]
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
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct scene_ctx {
    mcp_proc_scene scene;
    uint64_t seed;
} scene_ctx;

static int g_probes = 0; /* --probes: the estimate's (0: its default, as users get it) */
/* what every run's passes spent, per denoiser: mcpost's part and the denoiser's */
static double g_ms_added, g_ms_denoise;
static long g_passes;

static int
render(int pass, const mcp_image *counts, mcp_dump **out, void *ctx)
{
    const scene_ctx *s = ctx;
    return mcp_proc_render_counts(&s->scene, counts, pass, s->seed, out);
}

static void
die(const char *what)
{
    fprintf(stderr, "bench_adaptive: %s: %s\n", what, mcp_error_message());
    exit(1);
}

/* One run; returns the result (the caller frees it). */
static mcp_adaptive_result *
run(scene_ctx *s, const mcp_denoiser *den, mcp_adaptive_map map, double budget,
    double spp_it, const mcp_image *ref)
{
    mcp_adaptive_options o = mcp_adaptive_defaults();
    o.map = map;
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
    mcp_adaptive_result *r = run(&s, den, MCP_ADAPTIVE_VARIANCE, 96, 32, NULL);
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

#define MAX_CURVES 64

int
main(int argc, char **argv)
{
    int size = 128, seeds = 1, over = 0;
    double fireflies = -1; /* < 0: the scene's default */
    double budget = 128, spp_it = 32;
    const char *denoisers = "nlm", *plot_path = NULL;
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
        else {
            fprintf(stderr, "bench_adaptive: unknown option %s\n", argv[i]);
            return 2;
        }
    }
    if (over > 0) return overhead(over);
    static const mcp_adaptive_map maps[] = {
        MCP_ADAPTIVE_VARIANCE, MCP_ADAPTIVE_TONEMAPPED, MCP_ADAPTIVE_MC_SURE};
    static const char *const sampler_names[] = {"independent", "jittered 4x4"};
    double sum_speedup[3] = {0, 0, 0};
    int n_speedup[3] = {0, 0, 0};
    /* the curves of the first seed, for the plot */
    static double px[MAX_CURVES][256], py[MAX_CURVES][256];
    static char names[MAX_CURVES][96];
    mcp_plot_series series[MAX_CURVES];
    int n_series = 0, bounded = 0;
    printf("adaptive vs uniform at %g spp (%g per pass), %dx%d procedural scene, "
           "%d seed(s)\n",
           budget, spp_it, size, size, seeds);
    printf("%-20s %-9s %-11s %11s %11s %9s\n", "scene", "denoiser", "map", "relMSE",
           "uniform@B", "speed-up");
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
                    run(&s, den, MCP_ADAPTIVE_UNIFORM, 4 * budget, spp_it, ref);
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
                if (sd == 0 && smp == 0 && n_series < MAX_CURVES && nu <= 256) {
                    snprintf(names[n_series], 96, "uniform (%s, %s)", dn, sname);
                    memcpy(px[n_series], us, sizeof(double) * nu);
                    memcpy(py[n_series], ue, sizeof(double) * nu);
                    series[n_series] = (mcp_plot_series){names[n_series],
                                                         MCP_SERIES_LINE_POINTS,
                                                         px[n_series],
                                                         py[n_series],
                                                         nu,
                                                         1};
                    n_series++;
                }
                for (int m = 0; m < 3; m++) {
                    mcp_adaptive_result *r = run(&s, den, maps[m], budget, spp_it, ref);
                    const mcp_adaptive_iteration *last = &r->iterations[r->count - 1];
                    double eq = mcp_equal_error_spp(us, ue, nu, last->relmse);
                    double speedup = eq / last->mean_spp;
                    char text[32];
                    snprintf(text, sizeof text, "%.2fx", speedup);
                    /* worse than uniform's first pass: the speed-up is below
                       first / B; counted in the mean as that bound */
                    if (isnan(speedup) && last->relmse > ue[0]) {
                        speedup = us[0] / last->mean_spp;
                        snprintf(text, sizeof text, "<%.2fx", speedup);
                        bounded = 1;
                    }
                    printf("%-20s %-9s %-11s %11.5g %11.5g %9s\n", sname, dn,
                           mcp_adaptive_map_name(maps[m]), last->relmse, at_b, text);
                    if (isfinite(speedup)) {
                        sum_speedup[m] += speedup;
                        n_speedup[m]++;
                    }
                    if (sd == 0 && smp == 0 && n_series < MAX_CURVES && r->count <= 256) {
                        snprintf(names[n_series], 96, "%s (%s, %s)",
                                 mcp_adaptive_map_name(maps[m]), dn, sname);
                        for (int i = 0; i < r->count; i++) {
                            px[n_series][i] = r->iterations[i].mean_spp;
                            py[n_series][i] = r->iterations[i].relmse;
                        }
                        series[n_series] =
                            (mcp_plot_series){names[n_series], MCP_SERIES_LINE_POINTS,
                                              px[n_series],    py[n_series],
                                              r->count,        0};
                        n_series++;
                    }
                    mcp_adaptive_result_free(r);
                }
                fprintf(stderr, "  (%s, %s, seed %d: uniform run %.1f s)\n", dn, sname,
                        sd + 1, t_uniform / 1e3);
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
    printf("mean equal-error speed-up over the runs%s:",
           bounded ? " (an upper bound: '<' runs count as their bound)" : "");
    for (int m = 0; m < 3; m++)
        printf(" %s %.2fx%s", mcp_adaptive_map_name(maps[m]),
               n_speedup[m] ? sum_speedup[m] / n_speedup[m] : NAN, m < 2 ? "," : "\n");
    if (plot_path) {
        mcp_plot p = {"relMSE of the denoised image against samples per pixel",
                      "samples per pixel",
                      "relMSE",
                      MCP_AXIS_LOG,
                      MCP_AXIS_LOG,
                      series,
                      n_series,
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
