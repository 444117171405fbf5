/* denoiser_bench.h: what the denoiser benchmarks share (bench_denoise.c, bench_unet.c;
 * header-only: each bench is one executable built from one file): the synthetic
 * render-like input and the median timing of apply / jvp calls. */
#ifndef MCP_BENCH_DENOISER_BENCH_H
#define MCP_BENCH_DENOISER_BENCH_H

#include <mcpost/denoiser.h>

#include "bench.h"

#include "../common/core/rng_internal.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

/* splitmix64 -> uniform in [0, 1) */
static inline double
bench_uniform(uint64_t *s)
{
    return (double)(mcp__splitmix64_next(s) >> 11) * 0x1.0p-53;
}

/* A w x h R,G,B image; exits with a message on failure. */
static inline mcp_image *
bench_rgb(int w, int h)
{
    static const char *const names[] = {"R", "G", "B"};
    mcp_image *img = NULL;
    if (mcp_image_new(w, h, 3, names, &img)) {
        fprintf(stderr, "bench: %s\n", mcp_error_message());
        exit(1);
    }
    return img;
}

/* Albedo cells of 16 px, a smooth light, noise of 20 % with its variance given, and
 * the normals of two planes. */
static inline void
bench_render_like(int w, int h, mcp_image **color, mcp_image **albedo, mcp_image **normal,
                  mcp_image **variance)
{
    *color = bench_rgb(w, h), *albedo = bench_rgb(w, h), *normal = bench_rgb(w, h),
    *variance = bench_rgb(w, h);
    uint64_t st = 1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = ((size_t)y * w + x) * 3;
            int cell = (x / 16 + y / 16) % 3;
            for (int c = 0; c < 3; c++) {
                double a = 0.2 + 0.3 * ((cell + c) % 3),
                       t = a * (1 + 0.5 * sin(0.01 * x));
                double sd = 0.2 * t, u = bench_uniform(&st) + bench_uniform(&st) +
                                         bench_uniform(&st) - 1.5;
                (*albedo)->data[i + c] = (float)a;
                (*normal)->data[i + c] = (float)(c == (y < h / 3 ? 2 : 1));
                (*variance)->data[i + c] = (float)(sd * sd);
                (*color)->data[i + c] = (float)(t + 2 * sd * u);
            }
        }
}

/* Tangents per call at most. */
#define MAX_TANGENTS 8

/* n <= MAX_TANGENTS colour tangents of the noise's scale (uniform, times the standard
 * deviation), as images tan[k] and tangents t[k]. */
static inline void
bench_tangents(int w, int h, const mcp_image *variance, int n, mcp_image **tan,
               mcp_denoise_tangent *t)
{
    for (int k = 0; k < n; k++) {
        tan[k] = bench_rgb(w, h);
        uint64_t st = 100 + k;
        for (size_t i = 0; i < (size_t)w * h * 3; i++)
            tan[k]->data[i] =
                (float)((bench_uniform(&st) - 0.5) * sqrt(variance->data[i]));
        t[k] = (mcp_denoise_tangent){tan[k], NULL, NULL};
    }
}

/* The render-like input and its tangents, as both benchmarks time them (tan[k] is NULL
 * from the number made on). */
typedef struct {
    mcp_image *color, *albedo, *normal, *variance, *tan[MAX_TANGENTS];
    mcp_denoise_tangent t[MAX_TANGENTS];
    mcp_denoise_input in;
} bench_scene;

/* The scene with n_tangents <= MAX_TANGENTS tangents (only those a call needs: the
 * benchmarks that measure peak memory hold no more). */
static inline void
bench_scene_make(int w, int h, int n_tangents, bench_scene *s)
{
    *s = (bench_scene){0};
    bench_render_like(w, h, &s->color, &s->albedo, &s->normal, &s->variance);
    bench_tangents(w, h, s->variance, n_tangents, s->tan, s->t);
    s->in = (mcp_denoise_input){s->color, s->albedo, s->normal, s->variance};
}

static inline void
bench_scene_free(bench_scene *s)
{
    for (int k = 0; k < MAX_TANGENTS; k++)
        mcp_image_free(s->tan[k]);
    mcp_image_free(s->color);
    mcp_image_free(s->albedo);
    mcp_image_free(s->normal);
    mcp_image_free(s->variance);
}

/* The calls each benchmark times: apply (n = -1), and jvp with 1 and 4 tangents. */
#define BENCH_N_CALLS 3
static const char *const bench_call_labels[BENCH_N_CALLS] = {
    "apply", "apply + JVP, 1 tangent", "apply + JVP, 4 tangents"};
static const int bench_call_tangents[BENCH_N_CALLS] = {-1, 1, 4};

/* The median wall-clock time of `repeats` calls of apply (n = -1) or jvp with n
 * tangents, and in *cpu the median CPU time of all threads together. */
static inline double
bench_denoiser_median_ms(const mcp_denoiser *d, const mcp_denoise_input *in,
                         const mcp_denoise_tangent *t, int n, int repeats, double *cpu)
{
    double *times = malloc(2 * (size_t)repeats * sizeof *times), med = -1;
    if (!times) return -1;
    double *cpus = times + repeats;
    for (int r = -1; r < repeats; r++) {
        mcp_image *out = NULL, *jt[MAX_TANGENTS] = {NULL};
        double t0 = now_ms(), c0 = cpu_ms();
        int rc = n < 0 ? d->apply(d, in, &out) : d->jvp(d, in, t, n, &out, jt);
        double dt = now_ms() - t0, dc = cpu_ms() - c0;
        mcp_image_free(out);
        for (int k = 0; k < MAX_TANGENTS; k++)
            mcp_image_free(jt[k]);
        if (rc) {
            fprintf(stderr, "bench: %s\n", mcp_error_message());
            free(times);
            return -1;
        }
        if (r >= 0) {
            times[r] = dt;
            cpus[r] = dc;
        }
    }
    qsort(times, (size_t)repeats, sizeof *times, cmp_double);
    qsort(cpus, (size_t)repeats, sizeof *cpus, cmp_double);
    med = times[repeats / 2];
    *cpu = cpus[repeats / 2];
    free(times);
    return med;
}

#endif
