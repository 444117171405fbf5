/* bench_estimate.c: timings of the error estimation beyond the denoiser (no pass/fail).
 *
 * At 1024x1024 with a synthetic dump (smooth image with edges, heteroscedastic noise,
 * diagonal variance) and a stand-in linear denoiser (a separable 5x5 box with an
 * exact jvp) that only supplies F(X) and Jε, it times what Firmino 2024 §4 reports
 * separately from denoising: the SURE + variance maps (Alg. 2 lines 3-6), block
 * averaging (Alg. 1; paper 29 ms) and the distribution + stopping predicate (lines
 * 8-16; paper 11 ms); target: these three together <= 10 ms on 2 cores. Also shown:
 * drawing the probes, the stand-in denoiser, the sampling map with counts, and the
 * percentile curve. Each figure is the median of `repeats` runs after one warm-up.
 * Usage: bench_estimate [repeats (default 15)] [side (default 1024)] */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#include <mcpost/estimate.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>

#include "bench.h"
#endif

static int side = 1024;

static double
median(double *t, int n)
{
    qsort(t, (size_t)n, sizeof *t, cmp_double);
    return t[n / 2];
}

/* ---- the stand-in denoiser: separable 5x5 box, replicate borders ---- */

static void
box5(const mcp_image *in, mcp_image *out)
{
    int w = in->width, h = in->height;
    float *tmp = malloc((size_t)w * h * 3 * sizeof *tmp);
#pragma omp parallel for
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                float s = 0;
                for (int d = -2; d <= 2; d++) {
                    int xx = x + d < 0 ? 0 : x + d >= w ? w - 1 : x + d;
                    s += mcp_image_px(in, xx, y)[c];
                }
                tmp[((size_t)y * w + x) * 3 + c] = s / 5;
            }
#pragma omp parallel for
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                float s = 0;
                for (int d = -2; d <= 2; d++) {
                    int yy = y + d < 0 ? 0 : y + d >= h ? h - 1 : y + d;
                    s += tmp[((size_t)yy * w + x) * 3 + c];
                }
                mcp_image_px(out, x, y)[c] = s / 5;
            }
    free(tmp);
}

static const char *const RGB[] = {"R", "G", "B"};

static int
box_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    (void)self;
    if (mcp_image_new(in->color->width, in->color->height, 3, RGB, out)) return -1;
    box5(in->color, *out);
    return 0;
}

static int
box_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
        const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    if (primal && box_apply(self, at, primal)) return -1;
    for (int k = 0; k < n; k++) {
        if (mcp_image_new(at->color->width, at->color->height, 3, RGB, &out[k]))
            return -1;
        box5(t[k].color, out[k]);
    }
    return 0;
}

static const mcp_denoiser box_denoiser = {
    .name = "box5", .exact = 1, .apply = box_apply, .jvp = box_jvp};

static mcp_dump *
make_dump(void)
{
    mcp_dump *d = calloc(1, sizeof *d);
    if (!d || mcp_image_new(side, side, 3, RGB, &d->color) ||
        mcp_image_new(side, side, 3, RGB, &d->var_of_mean))
        return NULL;
    d->spp = 32;
    uint64_t s = 1;
    for (int y = 0; y < side; y++)
        for (int x = 0; x < side; x++)
            for (int c = 0; c < 3; c++) {
                double mu = 0.3 + 0.2 * c + 0.4 * sin(x * 0.01) * cos(y * 0.013) +
                            ((x / 64 + y / 64) % 2 ? 0.5 : 0.0);
                double sigma = 0.02 + 0.1 * x / side + (y > side / 2 ? 0.05 : 0.0);
                /* a cheap normal: sum of 4 uniforms, centred and scaled */
                double z = 0.0;
                for (int i = 0; i < 4; i++) {
                    s = s * 6364136223846793005ULL + 1442695040888963407ULL;
                    z += (double)(s >> 11) * 0x1.0p-53;
                }
                z = (z - 2.0) * sqrt(3.0);
                mcp_image_px(d->color, x, y)[c] = (float)(mu + sigma * z);
                mcp_image_px(d->var_of_mean, x, y)[c] = (float)(sigma * sigma);
            }
    return d;
}

int
main(int argc, char **argv)
{
    int repeats = argc > 1 ? atoi(argv[1]) : 15;
    if (argc > 2) side = atoi(argv[2]);
    if (repeats < 1 || side < 16) {
        fprintf(stderr, "usage: bench_estimate [repeats] [side]\n");
        return 2;
    }
    mcp_dump *d = make_dump();
    if (!d) {
        fprintf(stderr, "bench_estimate: %s\n", mcp_error_message());
        return 1;
    }
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    double *t_probe = calloc(repeats, sizeof(double)),
           *t_den = calloc(repeats, sizeof(double)),
           *t_maps = calloc(repeats, sizeof(double)),
           *t_blocks = calloc(repeats, sizeof(double)),
           *t_stop = calloc(repeats, sizeof(double)),
           *t_sum = calloc(repeats, sizeof(double)),
           *t_map = calloc(repeats, sizeof(double)),
           *t_pct = calloc(repeats, sizeof(double)),
           *t_dist = calloc(repeats, sizeof(double)),
           *t_cdf = calloc(repeats, sizeof(double)),
           *t_bs = calloc(repeats, sizeof(double));
    mcp_sure_options so = mcp_sure_defaults();
    long n_blocks = 0;
    double cdf = 0.0;
    for (int r = -1; r < repeats; r++) {
        int i = r < 0 ? 0 : r;
        double t0 = now_ms();
        mcp_probe p;
        if (mcp_probe_gaussian(d, NULL, 7, 0, &p)) goto fail;
        double t1 = now_ms();
        mcp_denoise_input in = {0};
        in.color = d->color;
        mcp_denoise_tangent tan = {0};
        tan.color = p.color;
        mcp_image *f = NULL, *jv = NULL;
        if (box_denoiser.jvp(&box_denoiser, &in, &tan, 1, &f, &jv)) goto fail;
        double t2 = now_ms();
        mcp_error_maps m;
        const mcp_image *eps[1] = {p.color}, *jeps[1] = {jv};
        if (mcp_error_maps_from_probes(d, f, eps, jeps, 1, &so, &m)) goto fail;
        double t3 = now_ms();
        mcp_blocks *b = NULL;
        if (mcp_block_average(m.sure_rel, m.sigma_rel, NULL, &b)) goto fail;
        double t4 = now_ms();
        mcp_error_dist *dist = NULL;
        if (mcp_error_distribution(b, m.var_rel, &dist)) goto fail;
        double t4b = now_ms();
        mcp_error_should_stop(dist, 0.01, 0.999, &cdf);
        double t5 = now_ms();
        mcp_image *map = NULL, *counts = NULL;
        if (mcp_sampling_map(d, m.denoised, m.var, NULL, &map) ||
            mcp_sample_counts(map, (int64_t)32 * side * side, &counts))
            goto fail;
        double t6 = now_ms();
        const double pct[5] = {0.5, 0.9, 0.99, 0.999, 0.9999};
        double tau[5];
        if (mcp_error_percentiles(dist, pct, 5, tau)) goto fail;
        double t7 = now_ms();
        t_probe[i] = t1 - t0;
        t_den[i] = t2 - t1;
        t_maps[i] = t3 - t2;
        t_blocks[i] = t4 - t3;
        t_stop[i] = t5 - t4;
        t_dist[i] = t4b - t4;
        t_cdf[i] = t5 - t4b;
        t_sum[i] = t5 - t2;
        t_bs[i] = t5 - t3;
        t_map[i] = t6 - t5;
        t_pct[i] = t7 - t6;
        n_blocks = b->count;
        mcp_image_free(map);
        mcp_image_free(counts);
        mcp_error_dist_free(dist);
        mcp_blocks_free(b);
        mcp_error_maps_free(&m);
        mcp_image_free(f);
        mcp_image_free(jv);
        mcp_probe_clear(&p);
    }
    printf("bench_estimate: %dx%d, %d threads, median of %d runs (%ld blocks, F(0.01) = "
           "%.6f)\n",
           side, side, threads, repeats, n_blocks, cdf);
    printf("  draw Gaussian probe (K=1)            %8.2f ms\n", median(t_probe, repeats));
    printf("  stand-in denoiser apply + jvp        %8.2f ms   (not counted)\n",
           median(t_den, repeats));
    printf("  SURE + variance maps                 %8.2f ms\n", median(t_maps, repeats));
    printf("  block averaging (Alg. 1)             %8.2f ms   (paper: 29 ms)\n",
           median(t_blocks, repeats));
    printf("  distribution + stopping F(tau)>=p    %8.2f ms   (paper: 11 ms)\n",
           median(t_stop, repeats));
    printf("    of which: lambda per block (Eq. 14) %6.2f ms, F(tau) (Eq. 15) %6.2f ms\n",
           median(t_dist, repeats), median(t_cdf, repeats));
    printf("  blocks + stopping                    %8.2f ms   (target: <= 10 ms)\n",
           median(t_bs, repeats));
    printf("  total beyond the denoiser            %8.2f ms   \n",
           median(t_sum, repeats));
    printf("  sampling map + counts                %8.2f ms\n", median(t_map, repeats));
    printf("  5 percentiles (bisection in log tau) %8.2f ms\n", median(t_pct, repeats));
    mcp_dump_free(d);
    return 0;
fail:
    fprintf(stderr, "bench_estimate: %s\n", mcp_error_message());
    return 1;
}
