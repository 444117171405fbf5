/* bench_perceptual.c: the perceptual methods at 512x512 RGB with M = 4 candidates
 * (Chizhov et al. 2022 Table 2 sizes), each beside a straightforward implementation
 * (naive_perceptual.h) that recomputes the local energy from scratch, as a speed-up in
 * the same run. Prints ms (best of several runs for the library; one run of the naive
 * version), passes, pMSE against the truth for both (they run the same algorithm, so
 * the figures should agree), and the targets.
 * Usage: bench_perceptual [size [runs [methods]]], methods a comma-separated list of
 * method names (e.g. error-diffusion,dither; default: all). */
#include <mcpost/metrics.h>
#include <mcpost/perceptual.h>

#include "naive_perceptual.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>

#include "bench.h"

#include "../common/core/rng_internal.h"
#endif

#define M 4

static double
uniform(uint64_t *s)
{
    return (double)(mcp__splitmix64_next(s) >> 11) * 0x1.0p-53;
}

static void
die(const char *what)
{
    fprintf(stderr, "bench_perceptual: %s: %s\n", what, mcp_error_message());
    exit(1);
}

/* A smooth "scene" with edges, and M one-sample-like renders of it: each value is the
 * truth times an exponential variate (mean 1), with rare fireflies (x50). */
static void
make_scene(int s, mcp_image **truth, mcp_image **cands)
{
    const char *const rgb[] = {"R", "G", "B"};
    uint64_t seed = 7;
    if (mcp_image_new(s, s, 3, rgb, truth)) die("image");
    for (int j = 0; j < M; j++)
        if (mcp_image_new(s, s, 3, rgb, &cands[j])) die("image");
    for (int y = 0; y < s; y++)
        for (int x = 0; x < s; x++)
            for (int c = 0; c < 3; c++) {
                double v = 0.45 + 0.3 * sin(0.02 * x + c) * cos(0.017 * y - c);
                if ((x / 64 + y / 64) % 2) v *= 0.5;
                mcp_image_px(*truth, x, y)[c] = (float)v;
            }
    for (int j = 0; j < M; j++)
        for (int y = 0; y < s; y++)
            for (int x = 0; x < s; x++) {
                double e = -log(1.0 - uniform(&seed)),
                       ff = uniform(&seed) < 1e-3 ? 50.0 : 1.0;
                for (int c = 0; c < 3; c++)
                    mcp_image_px(cands[j], x, y)[c] =
                        (float)(mcp_image_px(*truth, x, y)[c] * e * ff);
            }
}

static double
pmse_of(const mcp_image *img, const mcp_image *truth)
{
    double v;
    if (mcp_pmse(img, truth, NULL, &v)) die("pmse");
    return v;
}

static double
pmse_of_rgb(const float *rgb, int s, const mcp_image *truth)
{
    const char *const names[] = {"R", "G", "B"};
    mcp_image *img = NULL;
    if (mcp_image_new(s, s, 3, names, &img)) die("image");
    memcpy(img->data, rgb, (size_t)s * s * 3 * sizeof *rgb);
    double v = pmse_of(img, truth);
    mcp_image_free(img);
    return v;
}

typedef struct {
    const char *name;
    double ms, naive_ms, pmse, naive_pmse;
    int passes, naive_passes;
} row;

static void
print_row(const row *r, const char *paper)
{
    printf("%-20s %9.2f ms %4d passes  pMSE %.6f | naive %10.1f ms %4d passes  pMSE %.6f"
           " | speed-up %7.1fx | paper %s\n",
           r->name, r->ms, r->passes, r->pmse, r->naive_ms, r->naive_passes,
           r->naive_pmse, r->naive_ms / r->ms, paper);
}

/* Best of `runs` calls of the library method. */
static void
run_lib(const mcp_image *const *c, int m, const mcp_image *surr, const mcp_image *truth,
        mcp_perc_method method, int runs, row *r)
{
    mcp_perc_options o = mcp_perc_defaults();
    o.method = method;
    r->ms = INFINITY;
    for (int k = 0; k < runs; k++) {
        mcp_perc_result res;
        double t0 = now_ms();
        if (mcp_perc_optimize(c, m, surr, &o, &res)) die(mcp_perc_method_name(method));
        double t = now_ms() - t0;
        r->ms = t < r->ms ? t : r->ms;
        r->passes = res.passes;
        r->pmse = pmse_of(res.image, truth);
        mcp_perc_result_free(&res);
    }
}

static const char *
verdict(double ms, double target)
{
    return isnan(ms) ? "not run" : ms <= target ? "met" : "MISSED";
}

/* Whether method is in the comma-separated list (NULL: every method). */
static int
wanted(const char *list, const char *method)
{
    if (!list) return 1;
    size_t n = strlen(method);
    for (const char *p = list; *p;) {
        const char *end = strchr(p, ',');
        size_t len = end ? (size_t)(end - p) : strlen(p);
        if (len == n && strncmp(p, method, n) == 0) return 1;
        p += len + (end != NULL);
    }
    return 0;
}

int
main(int argc, char **argv)
{
    int s = argc > 1 ? atoi(argv[1]) : 512, runs = argc > 2 ? atoi(argv[2]) : 5;
    const char *methods = argc > 3 ? argv[3] : NULL;
    if (s < 32 || runs < 1) {
        fprintf(stderr, "usage: bench_perceptual [size >= 32 [runs >= 1 [methods]]]\n");
        return 2;
    }
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    mcp_image *truth = NULL, *c[M], *mask = NULL, *mean = NULL;
    make_scene(s, &truth, c);
    const mcp_image *const *cands = (const mcp_image *const *)c;
    mcp_blue_noise_options bo = mcp_blue_noise_defaults();
    double t0 = now_ms();
    if (mcp_blue_noise_mask(&bo, &mask) || mcp_perc_mean(cands, M, &mean)) die("mask");
    double mask_ms = now_ms() - t0;
    bo.use_cache = 0;
    t0 = now_ms();
    int *rank = malloc((size_t)bo.size * bo.size * sizeof *rank);
    if (!rank || mcp_void_and_cluster(bo.size, bo.sigma, bo.seed, rank))
        die("void and cluster");
    double vc_ms = now_ms() - t0;
    free(rank);
    printf(
        "bench_perceptual: %dx%d RGB, M = %d, %d threads, surrogate = truth, best of %d "
        "(naive: one run)\n",
        s, s, M, threads, runs);
    printf(
        "void-and-cluster 128x128 mask: %.1f ms to generate, %.1f ms through the cache\n",
        vc_ms, mask_ms);
    printf("candidates' mean: pMSE %.6f\n\n", pmse_of(mean, truth));

    /* the naive versions' inputs, in plain arrays */
    size_t n = (size_t)s * s;
    float *cand = malloc((size_t)M * n * 3 * sizeof *cand), *subsets = NULL;
    float *surr = malloc(n * 3 * sizeof *surr), *out = malloc(n * 3 * sizeof *out);
    for (int j = 0; j < M; j++)
        memcpy(cand + (size_t)j * n * 3, c[j]->data, n * 3 * sizeof *cand);
    memcpy(surr, truth->data, n * 3 * sizeof *surr);
    naive_input in = {s, s, M, cand, surr, mask->data, mask->width, 1};
    uint64_t masks[15];
    int k;
    if (mcp_perc_subset_masks(M, 15, masks, &k)) die("subsets");
    subsets = malloc((size_t)k * n * 3 * sizeof *subsets);
    for (int j = 0; j < k; j++)
        for (size_t p = 0; p < n; p++)
            for (int ch = 0; ch < 3; ch++) {
                double sum = 0.0;
                int cnt = 0;
                for (int i = 0; i < M; i++)
                    if ((masks[j] >> i) & 1)
                        sum += cand[((size_t)i * n + p) * 3 + ch], cnt++;
                subsets[((size_t)j * n + p) * 3 + ch] = (float)(sum / cnt);
            }

    row r;
    double vertical_ms = NAN, ed_ms = NAN, dither_ms = NAN;
    if (wanted(methods, "vertical-iterative")) {
        r = (row){.name = "vertical-iterative"};
        run_lib(cands, M, truth, truth, MCP_PERC_VERTICAL_ITERATIVE, runs, &r);
        t0 = now_ms();
        r.naive_passes = naive_vertical(&in, cand, M, 100, out);
        r.naive_ms = now_ms() - t0;
        r.naive_pmse = pmse_of_rgb(out, s, truth);
        print_row(&r, "18.4 s (to convergence; target <= 250 ms)");
        vertical_ms = r.ms;
    }

    if (wanted(methods, "power-set")) {
        r = (row){.name = "power-set (15)"};
        run_lib(cands, M, truth, truth, MCP_PERC_POWER_SET, runs > 3 ? 3 : runs, &r);
        t0 = now_ms();
        r.naive_passes = naive_vertical(&in, subsets, k, 100, out);
        r.naive_ms = now_ms() - t0;
        r.naive_pmse = pmse_of_rgb(out, s, truth);
        print_row(&r, "95 s");
    }

    if (wanted(methods, "error-diffusion")) {
        r = (row){.name = "error-diffusion"};
        run_lib(cands, M, truth, truth, MCP_PERC_ERROR_DIFFUSION, runs * 4, &r);
        t0 = now_ms();
        naive_error_diffusion(&in, out);
        r.naive_ms = now_ms() - t0;
        r.naive_passes = 1;
        r.naive_pmse = pmse_of_rgb(out, s, truth);
        print_row(&r, "0.04 s (target <= 5 ms)");
        ed_ms = r.ms;
    }

    if (wanted(methods, "dither")) {
        r = (row){.name = "dither"};
        run_lib(cands, M, truth, truth, MCP_PERC_DITHER, runs * 4, &r);
        t0 = now_ms();
        naive_dither(&in, out);
        r.naive_ms = now_ms() - t0;
        r.naive_passes = 1;
        r.naive_pmse = pmse_of_rgb(out, s, truth);
        print_row(&r, "0.04 s (target <= 5 ms)");
        dither_ms = r.ms;
    }

    if (wanted(methods, "horizontal")) {
        r = (row){.name = "horizontal (10)"};
        run_lib(cands, M, truth, truth, MCP_PERC_HORIZONTAL, runs > 3 ? 3 : runs, &r);
        t0 = now_ms();
        r.naive_passes = naive_horizontal(&in, mean->data, 10, out);
        r.naive_ms = now_ms() - t0;
        r.naive_pmse = pmse_of_rgb(out, s, truth);
        print_row(&r, "23 s");
    }

    printf("\ntargets (512x512 on 2 cores): vertical-iterative %.1f ms <= 250 ms: %s; "
           "error-diffusion %.2f ms <= 5 ms: %s; dither %.2f ms <= 5 ms: %s\n",
           vertical_ms, verdict(vertical_ms, 250.0), ed_ms, verdict(ed_ms, 5.0),
           dither_ms, verdict(dither_ms, 5.0));
    free(cand), free(subsets), free(surr), free(out);
    for (int j = 0; j < M; j++)
        mcp_image_free(c[j]);
    mcp_image_free(truth), mcp_image_free(mask), mcp_image_free(mean);
    return 0;
}
