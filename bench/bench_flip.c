/* bench_flip.c: HDR-FLIP and LDR-FLIP on a synthetic 1920x1080 pair; prints ms and ms
 * per megapixel (best of several runs), and the CSF operator M and its transpose.
 * Usage: bench_flip [width height [runs]] */
#include <mcpost/flip.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>

#include "bench.h"

#include "../common/core/rng_internal.h"
#endif

/* CPU time of the whole process (all threads): on a machine shared with other work,
 * CPU time / threads estimates the wall time the call would take alone. */
static uint64_t
next(uint64_t *s)
{
    return mcp__splitmix64_next(s);
}

/* An HDR "render": smooth gradients over four decades, a bright square, and a noisy
 * test copy (multiplicative noise, like a low-spp render). */
static void
make_pair(int w, int h, mcp_image **test, mcp_image **ref)
{
    const char *const rgb[] = {"R", "G", "B"};
    uint64_t seed = 1;
    if (mcp_image_new(w, h, 3, rgb, ref) || mcp_image_new(w, h, 3, rgb, test)) {
        fprintf(stderr, "bench_flip: %s\n", mcp_error_message());
        exit(1);
    }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                double v = pow(10.0, 4.0 * x / w - 2.0) * (0.5 + 0.5 * sin(0.01 * y + c));
                if (x > w / 3 && x < w / 2 && y > h / 3 && y < h / 2) v = 50.0;
                double u = (double)(next(&seed) >> 11) * 0x1.0p-53;
                mcp_image_px(*ref, x, y)[c] = (float)v;
                mcp_image_px(*test, x, y)[c] = (float)(v * (0.5 + u));
            }
}

int
main(int argc, char **argv)
{
    int w = argc > 2 ? atoi(argv[1]) : 1920, h = argc > 2 ? atoi(argv[2]) : 1080;
    int runs = argc > 3 ? atoi(argv[3]) : 5;
    mcp_image *test, *ref, *m = NULL;
    make_pair(w, h, &test, &ref);
    double mp = (double)w * h / 1e6;
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    printf("bench_flip: %dx%d (%.2f MP), %d threads, best of %d\n", w, h, mp, threads,
           runs);

    mcp_flip_result res;
    double best = 1e30, best_cpu = 1e30;
    for (int i = 0; i < runs; i++) {
        double t0 = now_ms(), c0 = cpu_ms();
        if (mcp_flip_hdr(test, ref, NULL, &res, NULL, NULL)) {
            fprintf(stderr, "bench_flip: %s\n", mcp_error_message());
            return 1;
        }
        double t = now_ms() - t0, c = cpu_ms() - c0;
        best = t < best ? t : best;
        best_cpu = c < best_cpu ? c : best_cpu;
    }
    printf("hdr-flip (aces, %d exposures %.3f..%.3f): %.1f ms, %.1f ms/MP, "
           "%.1f ms/MP/exposure, mean %.6f\n",
           res.num_exposures, res.start_exposure, res.stop_exposure, best, best / mp,
           best / mp / res.num_exposures, res.mean);
    printf("hdr-flip cpu time: %.1f ms (%.1f ms per thread)\n", best_cpu,
           best_cpu / threads);

    best = 1e30;
    for (int i = 0; i < runs; i++) {
        double t0 = now_ms();
        if (mcp_flip_ldr(test, ref, NULL, &res, NULL)) {
            fprintf(stderr, "bench_flip: %s\n", mcp_error_message());
            return 1;
        }
        double t = now_ms() - t0;
        best = t < best ? t : best;
    }
    printf("ldr-flip: %.1f ms, %.1f ms/MP, mean %.6f\n", best, best / mp, res.mean);

    for (int adj = 0; adj < 2; adj++) {
        best = 1e30;
        for (int i = 0; i < runs; i++) {
            double t0 = now_ms();
            int rc = adj ? mcp_flip_csf_apply_transpose(ref, 0, &m)
                         : mcp_flip_csf_apply(ref, 0, &m);
            if (rc) {
                fprintf(stderr, "bench_flip: %s\n", mcp_error_message());
                return 1;
            }
            double t = now_ms() - t0;
            mcp_image_free(m);
            best = t < best ? t : best;
        }
        printf("csf %s: %.1f ms, %.1f ms/MP\n", adj ? "M^T" : "M", best, best / mp);
    }
    mcp_image_free(test);
    mcp_image_free(ref);
    return 0;
}
