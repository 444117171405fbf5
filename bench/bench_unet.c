/* bench_unet.c: timings of the `unet` denoiser (OIDN's RT U-Net, estimate/unet.c; no
 * pass/fail) beside a baseline measured in the same run: OpenBLAS's cblas_sgemm at
 * the network's layer shapes (M = cout, K = 9 cin, N = 65536, as an im2col
 * convolution would call it), on as many threads as the U-Net.
 *
 * The U-Net runs on a render-like input (noisy colour, albedo with edges, normals of
 * two planes, as bench_denoise) with the official colour + albedo + normal weights
 * from $MCPOST_OIDN_WEIGHTS, else the shipped weights/rt_hdr_alb_nrm.tza of the source
 * tree (without them it prints a skip line and exits 0): apply, and apply + JVP with 1
 * and with 4 tangents in one pass, in the default (Winograd) mode and in the
 * fixed-bit mode (MCPOST_UNET_FIXED=1: the direct loops, the same bits on every
 * x86-64). Each figure is the median of `repeats` runs after one warm-up: wall-clock
 * ms and ms per megapixel with the default OpenMP team (OMP_NUM_THREADS changes it),
 * and the direct-convolution-equivalent rate: 125406 multiply-adds per pixel of the
 * input padded to a multiple of 16, per image of the batch (the primal and each
 * tangent), per wall-clock second, and that rate over sgemm's.
 * Usage: bench_unet [repeats (default 3)] [width (default 512)] [height (default width)]
 *                   [both | default | fixed (the modes timed; default both)]
 *        (1080p: bench_unet 3 1920 1080) */
#include <mcpost/denoiser.h>

#include "denoiser_bench.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#define MAC_PER_PIXEL 125406.0 /* the RT U-Net's 3x3 convolutions, 9 input channels */

/* The RT U-Net's convolutions: input and output channels, and the resolution as a
 * fraction of the input's pixels (MACs per input pixel: 9 cin cout / frac). */
static const struct {
    int cin, cout, frac;
} layers[] = {{9, 32, 1},     {32, 32, 1},    {32, 48, 4},    {48, 64, 16},
              {64, 80, 64},   {80, 96, 256},  {96, 96, 256},  {160, 112, 64},
              {112, 112, 64}, {160, 96, 16},  {96, 96, 16},   {128, 64, 4},
              {64, 64, 4},    {73, 64, 1},    {64, 32, 1},    {32, 3, 1}};
#define N_LAYERS ((int)(sizeof layers / sizeof layers[0]))

#ifdef MCP_BENCH_OPENBLAS
#include <cblas.h>
void openblas_set_num_threads(int n);

/* sgemm's rate in GMAC/s for M x K times K x N (median of 3 after a warm-up). */
static double
sgemm_rate(int m, int k, int n)
{
    float *a = malloc((size_t)m * k * sizeof(float)), *b = malloc((size_t)k * n * sizeof(float));
    float *c = malloc((size_t)m * n * sizeof(float));
    if (!a || !b || !c) {
        free(a), free(b), free(c);
        return -1;
    }
    uint64_t st = 7;
    for (size_t i = 0; i < (size_t)m * k; i++) a[i] = (float)bench_uniform(&st) - 0.5f;
    for (size_t i = 0; i < (size_t)k * n; i++) b[i] = (float)bench_uniform(&st) - 0.5f;
    double t[4];
    for (int r = 0; r < 4; r++) {
        double t0 = now_ms();
        cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, m, n, k, 1.0f, a, k, b, n, 0.0f,
                    c, n);
        t[r] = now_ms() - t0;
    }
    free(a), free(b), free(c);
    /* median of the last three */
    double x = t[1], y = t[2], z = t[3];
    double med = x > y ? (y > z ? y : x > z ? z : x) : (x > z ? x : y > z ? z : y);
    return (double)m * k * n / (med * 1e-3) * 1e-9;
}

/* sgemm at every layer's shape; returns the rate of the whole network's MACs at those
 * rates (their MAC-weighted harmonic mean), or -1. */
static double
sgemm_baseline(int threads)
{
    openblas_set_num_threads(threads);
    printf("OpenBLAS cblas_sgemm, %d thread(s), N = 65536 (an im2col convolution's call)\n",
           threads);
    printf("%-10s %6s %6s %10s\n", "layer", "M", "K", "GMAC/s");
    double macs = 0, secs = 0;
    for (int l = 0; l < N_LAYERS; l++) {
        const int m = layers[l].cout, k = 9 * layers[l].cin;
        const double rate = sgemm_rate(m, k, 65536);
        if (rate <= 0) return -1;
        const double layer_macs = 9.0 * layers[l].cin * layers[l].cout / layers[l].frac;
        macs += layer_macs, secs += layer_macs / rate;
        printf("%-10d %6d %6d %10.2f\n", l, m, k, rate);
    }
    printf("%-10s %6s %6s %10.2f\n\n", "network", "", "", macs / secs);
    return macs / secs;
}
#endif

/* The weights: $MCPOST_OIDN_WEIGHTS, else the shipped weights/ of the source tree this
 * file was compiled from (CMake passes absolute source paths). */
static const char *
weights_path(void)
{
    static char buf[4096];
    const char *env = getenv("MCPOST_OIDN_WEIGHTS");
    if (env && *env) return env;
    const char *file = __FILE__, *tail = strstr(file, "bench/bench_unet.c");
    if (!tail || tail == file) return NULL;
    snprintf(buf, sizeof buf, "%.*sweights/rt_hdr_alb_nrm.tza", (int)(tail - file), file);
    return buf;
}

int
main(int argc, char **argv)
{
    int repeats = argc > 1 ? atoi(argv[1]) : 3, width = argc > 2 ? atoi(argv[2]) : 512;
    int height = argc > 3 ? atoi(argv[3]) : width;
    const char *modes = argc > 4 ? argv[4] : "both";
    const int first = !strcmp(modes, "fixed") ? 1 : 0, last = !strcmp(modes, "default") ? 0 : 1;
    if (repeats < 1 || width < 8 || width > 8192 || height < 8 || height > 8192 ||
        (strcmp(modes, "both") && strcmp(modes, "default") && strcmp(modes, "fixed"))) {
        fprintf(stderr, "usage: bench_unet [repeats >= 1] [width in 8..8192] "
                        "[height in 8..8192] [both | default | fixed]\n");
        return 2;
    }
    const char *path = weights_path();
    if (!path || access(path, R_OK) != 0) {
        printf("bench_unet: skipped: no OIDN weights at %s (set MCPOST_OIDN_WEIGHTS)\n",
               path ? path : "(unknown)");
        return 0;
    }
    char opt[4200];
    snprintf(opt, sizeof opt, "weights=%s", path);
    mcp_denoiser *d = NULL;
    if (mcp_denoiser_create_from_args("unet", (const char *[]){opt}, 1, &d)) {
        fprintf(stderr, "bench_unet: %s\n", mcp_error_message());
        return 1;
    }
    bench_scene sc;
    bench_scene_make(width, height, &sc);
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    double sgemm = -1;
#ifdef MCP_BENCH_OPENBLAS
    sgemm = sgemm_baseline(threads);
#else
    printf("(built without OpenBLAS: no sgemm baseline)\n\n");
#endif
    const double mp = (double)width * height / 1e6;
    const double padded = (double)((width + 15) / 16 * 16) * ((height + 15) / 16 * 16);
    int status = 0;
    for (int fixed = first; fixed <= last; fixed++) {
        setenv("MCPOST_UNET_FIXED", fixed ? "1" : "0", 1);
        printf("unet at %dx%d, %d thread(s), median of %d, %s\n", width, height, threads,
               repeats, fixed ? "fixed-bit mode (MCPOST_UNET_FIXED=1: direct loops)"
                              : "default mode (Winograd F(2x2,3x3))");
        printf("%-24s %10s %10s %12s %10s %10s\n", "call", "ms", "ms/MP", "CPU ms/MP",
               "GMAC/s", "x sgemm");
        for (int c = 0; c < BENCH_N_CALLS; c++) {
            const int nt = bench_call_tangents[c];
            double cpu = 0, ms = bench_denoiser_median_ms(d, &sc.in, sc.t, nt, repeats, &cpu);
            if (ms < 0) {
                status = 1;
                continue;
            }
            const double gmac = MAC_PER_PIXEL * padded * (nt < 0 ? 1 : 1 + nt) * 1e-9;
            const double rate = gmac / (ms * 1e-3);
            printf("%-24s %10.1f %10.1f %12.1f %10.2f", bench_call_labels[c], ms, ms / mp,
                   cpu / mp, rate);
            if (sgemm > 0)
                printf(" %10.2f\n", rate / sgemm);
            else
                printf(" %10s\n", "-");
        }
        printf("\n");
    }
    unsetenv("MCPOST_UNET_FIXED");
    bench_scene_free(&sc);
    mcp_denoiser_free(d);
    return status;
}
