/* bench_filter.c: timings for common/filter/filter.c and common/filter/colormap.c (no
 * pass/fail).
 *
 * Gaussian 5x5 and 11x11 blurs of a 1024x1024x3 random image through
 * mcp_gaussian_blur (OpenCV sepFilter2D in OpenMP strips; one thread and the default
 * team) against a straightforward naive C loop (window^2 taps per pixel, replicate
 * borders, one thread); the tile power spectra of a 1024^2 channel in 32^2 tiles; and
 * a 1024^2 viridis colour mapping. Each figure is the median of `repeats` runs after
 * two warm-ups. Usage: bench_filter [repeats (default 11)] */
#include <mcpost/filter.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>

#include "bench.h"
#endif

#define SIDE 1024
#define CHANNELS 3

typedef int (*bench_fn)(void *ctx);

typedef struct {
    const mcp_image *img;
    int window;
    double sigma;
    const float *kernel; /* naive: window x window, row-major */
    mcp_image *out;
} blur_ctx;

/* The median time of fn over `repeats` runs after two warm-ups, or -1 on failure. */
static double
median_ms(bench_fn fn, void *ctx, int repeats)
{
    double *t = malloc((size_t)repeats * sizeof *t), med;
    if (!t) return -1;
    for (int i = 0; i < 2; i++)
        if (fn(ctx)) {
            free(t);
            return -1;
        }
    for (int i = 0; i < repeats; i++) {
        double t0 = now_ms();
        if (fn(ctx)) {
            free(t);
            return -1;
        }
        t[i] = now_ms() - t0;
    }
    qsort(t, (size_t)repeats, sizeof *t, cmp_double);
    med = t[repeats / 2];
    free(t);
    return med;
}

static int
clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

/* The naive reference: a 2D correlation with the outer-product kernel, clamped
 * (replicate) indices, float accumulation, one thread. */
static int
naive_blur(void *p)
{
    blur_ctx *b = p;
    const mcp_image *img = b->img;
    int w = img->width, h = img->height, c = img->channels, r = b->window / 2;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float acc[CHANNELS] = {0};
            for (int j = -r; j <= r; j++) {
                int yy = clampi(y + j, 0, h - 1);
                const float *krow = b->kernel + (size_t)(j + r) * b->window + r;
                for (int i = -r; i <= r; i++) {
                    const float *s = mcp_image_px(img, clampi(x + i, 0, w - 1), yy);
                    for (int k = 0; k < c; k++)
                        acc[k] += krow[i] * s[k];
                }
            }
            float *d = mcp_image_px(b->out, x, y);
            for (int k = 0; k < c; k++)
                d[k] = acc[k];
        }
    return 0;
}

static int
mcp_blur(void *p)
{
    blur_ctx *b = p;
    mcp_image_free(b->out);
    return mcp_gaussian_blur(b->img, b->window, b->sigma, &b->out);
}

static int
spectra(void *p)
{
    mcp_image *out = NULL;
    int rc = mcp_tile_power_spectra(p, 0, 32, &out);
    mcp_image_free(out);
    return rc;
}

static int
colormap(void *p)
{
    static unsigned char rgb[SIDE * SIDE * 3];
    return mcp_colormap_apply(p, 0, 0, 1, MCP_COLORMAP_VIRIDIS, rgb);
}

int
main(int argc, char **argv)
{
    int repeats = argc > 1 ? atoi(argv[1]) : 11, max_threads = 1;
    if (repeats < 1) repeats = 1;
#ifdef _OPENMP
    max_threads = omp_get_max_threads();
#endif
    mcp_image *img = NULL, *naive_out = NULL;
    if (mcp_image_new(SIDE, SIDE, CHANNELS, NULL, &img) ||
        mcp_image_new(SIDE, SIDE, CHANNELS, NULL, &naive_out)) {
        fprintf(stderr, "bench_filter: %s\n", mcp_error_message());
        return 1;
    }
    uint64_t s = 12345;
    for (size_t i = 0; i < (size_t)SIDE * SIDE * CHANNELS; i++) {
        s = s * 6364136223846793005u + 1442695040888963407u;
        img->data[i] = (float)((s >> 40) * (1.0 / (1 << 24)));
    }
    printf("bench_filter: %dx%dx%d float32, median of %d runs, OpenMP threads %d\n", SIDE,
           SIDE, CHANNELS, repeats, max_threads);

    const int windows[] = {5, 11};
    for (int wi = 0; wi < 2; wi++) {
        int win = windows[wi], r = win / 2;
        float *k1 = malloc((size_t)win * sizeof *k1);
        float *k2 = malloc((size_t)win * win * sizeof *k2);
        blur_ctx b = {img, win, (win - 1) / 6.0, k2, NULL};
        if (!k1 || !k2 || mcp_gaussian_kernel(b.sigma, r, k1)) return 1;
        for (int j = 0; j < win; j++)
            for (int i = 0; i < win; i++)
                k2[j * win + i] = k1[i] * k1[j];

        bench_set_threads(1);
        double one = median_ms(mcp_blur, &b, repeats);
        bench_set_threads(max_threads);
        double all = median_ms(mcp_blur, &b, repeats);
        blur_ctx n = b;
        n.out = naive_out;
        double naive = median_ms(naive_blur, &n, repeats > 3 ? 3 : repeats);
        if (one < 0 || all < 0 || naive < 0) {
            fprintf(stderr, "bench_filter: %s\n", mcp_error_message());
            return 1;
        }
        double maxdiff = 0;
        for (size_t i = 0; i < (size_t)SIDE * SIDE * CHANNELS; i++)
            maxdiff = fmax(maxdiff, fabs(b.out->data[i] - naive_out->data[i]));
        printf("gaussian %2dx%-2d (sigma %.3f): mcp_gaussian_blur %7.2f ms (1 thread) "
               "%7.2f ms (%d threads); naive C %8.2f ms; naive/mcp %.1fx (1 thread) "
               "%.1fx; max |diff| %.2g\n",
               win, win, b.sigma, one, all, max_threads, naive, naive / one, naive / all,
               maxdiff);
        mcp_image_free(b.out);
        free(k2);
        free(k1);
    }

    bench_set_threads(1);
    double sp1 = median_ms(spectra, img, repeats);
    bench_set_threads(max_threads);
    double spn = median_ms(spectra, img, repeats);
    printf("tile power spectra 1024^2 in 32^2 tiles: %7.2f ms (1 thread) %7.2f ms "
           "(%d threads)\n",
           sp1, spn, max_threads);
    bench_set_threads(1);
    double cm1 = median_ms(colormap, img, repeats);
    bench_set_threads(max_threads);
    double cmn = median_ms(colormap, img, repeats);
    printf("colormap viridis 1024^2: %7.2f ms (1 thread) %7.2f ms (%d threads)\n", cm1,
           cmn, max_threads);
    mcp_image_free(naive_out);
    mcp_image_free(img);
    return 0;
}
