/* bench_unet.c: timings of the `unet` denoiser (OIDN's RT U-Net, estimate/unet.c; no
 * pass/fail): apply, and apply + JVP with 1 and with 4 tangents in one pass, on a
 * render-like input (noisy colour, albedo with edges, normals of two planes, as
 * bench_denoise), with the official colour + albedo + normal weights from
 * $MCPOST_OIDN_WEIGHTS, else the shipped weights/rt_hdr_alb_nrm.tza of the source
 * tree; without them it prints a skip line and exits 0.
 * Each figure is the median of `repeats` runs after one warm-up: wall-clock ms and ms
 * per megapixel with the default OpenMP team (set OMP_NUM_THREADS to change it), the
 * CPU time of all threads per megapixel (the work, which other jobs on the machine
 * change less), and the convolution rate: 125406 multiply-adds per pixel of the input
 * padded to a multiple of 16, per image of the batch (the primal and each tangent),
 * per wall-clock second and per CPU second.
 * Usage: bench_unet [repeats (default 3)] [side (default 512)] */
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
    int repeats = argc > 1 ? atoi(argv[1]) : 3, side = argc > 2 ? atoi(argv[2]) : 512;
    if (repeats < 1 || side < 8 || side > 8192) {
        fprintf(stderr, "usage: bench_unet [repeats >= 1] [side in 8..8192]\n");
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
    bench_scene_make(side, &sc);
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    const double mp = (double)side * side / 1e6, padded = (double)((side + 15) / 16 * 16);
    printf("unet at %dx%d, %d thread(s), median of %d\n", side, side, threads, repeats);
    printf("%-24s %10s %10s %12s %10s %12s\n", "call", "ms", "ms/MP", "CPU ms/MP",
           "GMAC/s", "GMAC/CPU-s");
    int status = 0;
    for (int c = 0; c < BENCH_N_CALLS; c++) {
        const int nt = bench_call_tangents[c];
        double cpu = 0, ms = bench_denoiser_median_ms(d, &sc.in, sc.t, nt, repeats, &cpu);
        if (ms < 0) {
            status = 1;
            continue;
        }
        const double gmac =
            MAC_PER_PIXEL * padded * padded * (nt < 0 ? 1 : 1 + nt) * 1e-9;
        printf("%-24s %10.1f %10.1f %12.1f %10.2f %12.2f\n", bench_call_labels[c], ms,
               ms / mp, cpu / mp, gmac / (ms * 1e-3), gmac / (cpu * 1e-3));
    }
    bench_scene_free(&sc);
    mcp_denoiser_free(d);
    return status;
}
