/* bench_denoise.c: timings of every built-in denoiser (estimate/denoise_*.c; no
 * pass/fail): apply, and apply + JVP with 1 and with 4 tangents in one pass, on a
 * 1024x1024 render-like input (noisy colour with its variance, albedo with edges,
 * normals of two planes); the U-Net has bench_unet, and an external command is not
 * timed. Each figure is the median of `repeats` runs after one
 * warm-up: wall-clock ms and ms per megapixel with the default OpenMP team (set
 * OMP_NUM_THREADS to change it), and the CPU time of all threads per megapixel, which
 * shows the work when other jobs share the machine.
 * Usage: bench_denoise [repeats (default 5)] [side (default 1024)] */
#include <mcpost/denoiser.h>

#include "denoiser_bench.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>
#endif

int
main(int argc, char **argv)
{
    int repeats = argc > 1 ? atoi(argv[1]) : 5, side = argc > 2 ? atoi(argv[2]) : 1024;
    if (repeats < 1 || side < 8 || side > 8192) {
        fprintf(stderr, "usage: bench_denoise [repeats >= 1] [side in 8..8192]\n");
        return 2;
    }
    bench_scene sc;
    bench_scene_make(side, side, 4, &sc); /* the most bench_call_tangents asks for */
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    double mp = (double)side * side / 1e6;
    printf("denoisers at %dx%d, %d thread(s), median of %d\n", side, side, threads,
           repeats);
    printf("%-10s %-24s %10s %10s %12s\n", "kind", "call", "ms", "ms/MP", "CPU ms/MP");
    int status = 0;
    for (const mcp_denoiser_kind *const *k = mcp_denoiser_kinds(); *k; k++) {
        /* these wrap a command or a weights file: bench_unet times the U-Net, and an
         * external command's cost is its own */
        if (strcmp((*k)->name, "external") == 0 || strcmp((*k)->name, "unet") == 0) {
            printf("%-10s (see bench_unet)\n", (*k)->name);
            continue;
        }
        mcp_denoiser *d = NULL;
        if (mcp_denoiser_create_from_args((*k)->name, NULL, 0, &d)) {
            fprintf(stderr, "bench_denoise: %s\n", mcp_error_message());
            status = 1;
            continue;
        }
        for (int c = 0; c < BENCH_N_CALLS; c++) {
            double cpu = 0, ms = bench_denoiser_median_ms(
                                d, &sc.in, sc.t, bench_call_tangents[c], repeats, &cpu);
            if (ms < 0)
                status = 1;
            else
                printf("%-10s %-24s %10.1f %10.1f %12.1f\n", (*k)->name,
                       bench_call_labels[c], ms, ms / mp, cpu / mp);
        }
        mcp_denoiser_free(d);
    }
    bench_scene_free(&sc);
    return status;
}
