/* bench_io.c: EXR write and read times (no pass/fail), each new setting beside its
 * baseline in the same run, since this machine is shared and timings drift between
 * runs: one thread against all (OpenMP; one thread is the old serial path), and the
 * defaults (zip at MCP_EXR_ZIP_LEVEL_DEFAULT, chunks stored raw where zip does not
 * pay) against what was written before (zlib's 6, Core's own default, on every
 * chunk). Also other levels and the other lossless compressions, for the file size
 * each buys.
 *
 * Inputs from the procedural renderer: a 512x512 RGB float image (16 spp), and a
 * 1920x1080 12-channel dump (colour, variance, albedo, normal; 4 spp) as mcp_dump_write
 * writes it. Targets (issue 16): 512² RGB write <= 30 ms, read <= 20 ms; 1080p dump
 * read <= 100 ms. Each figure is the median of `repeats` runs after one warm-up.
 *
 * PNG: the report's pictures as mcp_write_rgb8 writes them (common/io/png_encode.c:
 * filters chosen in parallel, libdeflate) beside libpng's writer as it was used before
 * (zlib level 3, libpng's filter search, one thread), on a 1080p colour map of a noisy
 * map and on a flat picture of a few colours.
 * Usage: bench_io [repeats (default 7)] [folder for the files (default /tmp)] [png]
 * (png: the PNG table only) */
#define _POSIX_C_SOURCE 200809L /* clock_gettime */
#include <mcpost/dump.h>
#include <mcpost/imageio.h>
#include <mcpost/filter.h>
#include <procedural.h>

#include <png.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include "bench.h"

static int repeats = 7;
static const char *dir = "/tmp";

static int
max_threads(void)
{
#ifdef _OPENMP
    return omp_get_max_threads();
#else
    return 1;
#endif
}

static void
die(const char *what)
{
    fprintf(stderr, "bench_io: %s: %s\n", what, mcp_error_message());
    exit(1);
}

static double
median(double *t, int n)
{
    qsort(t, (size_t)n, sizeof *t, cmp_double);
    return t[n / 2];
}

/* Median milliseconds of writing img to path with o, on `threads` threads; *cpu gets
 * the median CPU time of all threads (on a busy machine, the wall time it would take
 * alone on one thread). */
static double
time_write(const mcp_image *img, const char *path, const mcp_write_options *o,
           int threads, double *cpu)
{
    double t[64], c[64];
    bench_set_threads(threads);
    for (int i = -1; i < repeats; i++) {
        double t0 = now_ms(), c0 = cpu_ms();
        if (mcp_image_write(img, path, o)) die(path);
        if (i >= 0) {
            t[i] = now_ms() - t0;
            c[i] = cpu_ms() - c0;
        }
    }
    *cpu = median(c, repeats);
    return median(t, repeats);
}

/* Median milliseconds of reading path (as an image, or as a dump) on `threads`; *cpu
 * as for time_write. */
static double
time_read(const char *path, int threads, int as_dump, double *cpu)
{
    double t[64], c[64];
    bench_set_threads(threads);
    for (int i = -1; i < repeats; i++) {
        double t0 = now_ms(), c0 = cpu_ms();
        if (as_dump) {
            mcp_dump *d;
            if (mcp_dump_read(path, &d)) die(path);
            mcp_dump_free(d);
        } else {
            mcp_image *img;
            if (mcp_image_read(path, NULL, &img)) die(path);
            mcp_image_free(img);
        }
        if (i >= 0) {
            t[i] = now_ms() - t0;
            c[i] = cpu_ms() - c0;
        }
    }
    *cpu = median(c, repeats);
    return median(t, repeats);
}

static double
file_mb(const char *path)
{
    struct stat st;
    return stat(path, &st) ? -1 : st.st_size / 1e6;
}

typedef struct setting {
    const char *label;
    mcp_exr_compression compression;
    int zip_level;     /* 0: the default */
    double min_saving; /* 0: the default; -1: compress every chunk, as before */
} setting;

/* One row per setting: size, write and read on 1 and on all threads. The dump's rows
 * also read it as a dump (mcp_dump_read: the EXR read plus the dump's checks). */
static void
table(const char *title, const mcp_image *img, const char *path, const setting *s, int n,
      int is_dump, double write_target, double read_target)
{
    int all = max_threads();
    printf("\n%s: %dx%d, %d channels, float; wall ms on 1 and on %d threads, and CPU ms "
           "of the 1-thread runs (what one quiet core would take)\n",
           title, img->width, img->height, img->channels, all);
    printf("  %-27s %6s %21s %21s%s\n", "compression", "MB", "write 1 / N / cpu",
           "read 1 / N / cpu", is_dump ? "   dump read 1 / N / cpu" : "");
    for (int i = 0; i < n; i++) {
        mcp_write_options o = mcp_write_defaults();
        o.compression = s[i].compression;
        o.exr_zip_level = s[i].zip_level;
        o.exr_min_saving = s[i].min_saving;
        double wc, rc, unused;
        double w1 = time_write(img, path, &o, 1, &wc),
               wn = time_write(img, path, &o, all, &unused);
        double r1 = time_read(path, 1, 0, &rc), rn = time_read(path, all, 0, &unused);
        printf("  %-27s %6.2f %6.0f %6.0f %6.0f    %6.1f %6.1f %6.1f", s[i].label,
               file_mb(path), w1, wn, wc, r1, rn, rc);
        if (is_dump) {
            double d1 = time_read(path, 1, 1, &rc), dn = time_read(path, all, 1, &unused);
            printf("    %6.0f %6.0f %6.0f", d1, dn, rc);
        }
        printf("\n");
        fflush(stdout);
    }
    bench_set_threads(all);
    if (write_target > 0)
        printf("  target: write <= %.0f ms, ", write_target);
    else
        printf("  target: ");
    printf("read <= %.0f ms (the default row, N threads)\n", read_target);
    unlink(path);
}

/* The baseline: libpng writing 8-bit RGB at zlib level 3 with its default filters, as
 * common/io/png.c did before png_encode.c. */
static void
libpng_write_rgb8(const unsigned char *rgb, int w, int h, const char *path)
{
    FILE *f = fopen(path, "wb");
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!f || !info || setjmp(png_jmpbuf(png))) {
        fprintf(stderr, "bench_io: libpng cannot write %s\n", path);
        exit(1);
    }
    png_init_io(png, f);
    png_set_compression_level(png, 3);
    png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, 8, PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    for (int y = 0; y < h; y++)
        png_write_row(png, rgb + (size_t)y * w * 3);
    png_write_end(png, info);
    png_destroy_write_struct(&png, &info);
    fclose(f);
}

/* Median wall ms of writing rgb as PNG (ours, or libpng's when baseline) on `threads`;
 * *cpu the median CPU ms of those runs. */
static double
time_png(const unsigned char *rgb, int w, int h, const char *path, int baseline,
         int threads, double *cpu)
{
    double t[64], c[64];
    bench_set_threads(threads);
    for (int i = -1; i < repeats; i++) {
        double t0 = now_ms(), c0 = cpu_ms();
        if (baseline)
            libpng_write_rgb8(rgb, w, h, path);
        else if (mcp_write_rgb8(rgb, w, h, path))
            die(path);
        if (i >= 0) {
            t[i] = now_ms() - t0;
            c[i] = cpu_ms() - c0;
        }
    }
    *cpu = median(c, repeats);
    return median(t, repeats);
}

/* Two report pictures of img's size: an inferno map of log10 of its first channel (a
 * noisy render: every pixel differs, as in blocks_error.png or a RelSE map) and eight
 * flat bands (as blocks.png), each written by both writers. */
static void
png_table(const mcp_image *img, const char *path)
{
    int w = img->width, h = img->height, all = max_threads();
    unsigned char *rgb = malloc((size_t)w * h * 3);
    mcp_image *lg = NULL;
    if (!rgb || mcp_image_new(w, h, 1, (const char *const[]){"Y"}, &lg))
        die("png picture");
    double *sorted = malloc((size_t)w * h * sizeof *sorted);
    if (!sorted) die("png picture");
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float v = mcp_image_px(img, x, y)[0];
            mcp_image_px(lg, x, y)[0] = v > 1e-12f ? log10f(v) : -12.0f;
            sorted[(size_t)y * w + x] = mcp_image_px(lg, x, y)[0];
        }
    /* the colour bar spans the 2nd to the 98th percentile, as a report's maps do */
    qsort(sorted, (size_t)w * h, sizeof *sorted, cmp_double);
    double lo = sorted[(size_t)w * h / 50], hi = sorted[(size_t)w * h * 49 / 50];
    free(sorted);
    printf(
        "\nPNG, %dx%d RGB 8-bit: wall ms on 1 and on %d threads, CPU ms of the 1-thread "
        "runs, file MB\n",
        w, h, all);
    printf("  %-44s %6s %6s %6s %7s\n", "picture, writer", "1", "N", "cpu", "MB");
    for (int picture = 0; picture < 2; picture++) {
        if (picture == 0) {
            if (mcp_colormap_apply(lg, 0, lo, hi, MCP_COLORMAP_INFERNO, rgb))
                die("colour map");
        } else {
            for (int y = 0; y < h; y++)
                for (int x = 0; x < w; x++)
                    memset(rgb + 3 * ((size_t)y * w + x), 30 * ((8 * y / h) + 1), 3);
        }
        for (int baseline = 0; baseline < 2; baseline++) {
            double cpu, unused;
            double t1 = time_png(rgb, w, h, path, baseline, 1, &cpu);
            double tn = time_png(rgb, w, h, path, baseline, all, &unused);
            printf("  %-44s %6.1f %6.1f %6.1f %7.3f\n",
                   picture == 0 ? (baseline ? "noisy colour map, libpng zlib 3 (before)"
                                            : "noisy colour map, mcp_write_rgb8")
                                : (baseline ? "flat bands, libpng zlib 3 (before)"
                                            : "flat bands, mcp_write_rgb8"),
                   t1, tn, cpu, file_mb(path));
            fflush(stdout);
        }
    }
    bench_set_threads(all);
    unlink(path);
    mcp_image_free(lg);
    free(rgb);
}

int
main(int argc, char **argv)
{
    if (argc > 1) repeats = atoi(argv[1]);
    if (argc > 2) dir = argv[2];
    int png_only = argc > 3 && strcmp(argv[3], "png") == 0;
    if (repeats < 1 || repeats > 64 || (argc > 3 && !png_only)) {
        fprintf(stderr, "usage: bench_io [repeats 1..64] [folder] [png]\n");
        return 2;
    }
    char label[64];
    snprintf(label, sizeof label, "zip %d, probe (default)", MCP_EXR_ZIP_LEVEL_DEFAULT);
    const setting settings[] = {
        {label, MCP_EXR_ZIP, 0, 0},
        {"zip 6, all chunks (before)", MCP_EXR_ZIP, 6, -1},
        {"zip 1, all chunks", MCP_EXR_ZIP, 1, -1},
        {"zip 2, all chunks", MCP_EXR_ZIP, 2, -1},
        {"zip 4, all chunks", MCP_EXR_ZIP, 4, -1},
        {"zips, default level", MCP_EXR_ZIPS, 0, 0},
        {"piz", MCP_EXR_PIZ, 0, 0},
        {"rle", MCP_EXR_RLE, 0, 0},
        {"none", MCP_EXR_NONE, 0, 0},
    };
    const int n = (int)(sizeof settings / sizeof *settings);
    char path[4200];

    mcp_proc_scene scene = mcp_proc_scene_defaults();
    scene.width = scene.height = 512;
    mcp_dump *small = NULL, *big = NULL;
    if (mcp_proc_render(&scene, 16, 1, NULL, &small)) die("procedural render");
    snprintf(path, sizeof path, "%s/bench_io_rgb.exr", dir);
    if (!png_only)
        table("512x512 RGB render (16 spp)", small->color, path, settings, n, 0, 30, 20);

    scene.width = 1920;
    scene.height = 1080;
    if (mcp_proc_render(&scene, 4, 1, NULL, &big)) die("procedural render");
    /* the dump as mcpost writes it, read back as the 12-channel image it is */
    snprintf(path, sizeof path, "%s/bench_io_dump.exr", dir);
    mcp_image *dump_img = NULL;
    if (!png_only && (mcp_dump_write(big, path, MCP_CONV_PBRT, NULL) ||
                      mcp_image_read(path, NULL, &dump_img)))
        die(path);
    if (!png_only)
        table("1080p dump (pbrt channels, 4 spp)", dump_img, path, settings, n, 1, 0,
              100);
    mcp_image_free(dump_img);
    snprintf(path, sizeof path, "%s/bench_io_picture.png", dir);
    png_table(big->var_of_mean ? big->var_of_mean : big->color, path);
    mcp_dump_free(big);
    mcp_dump_free(small);
    return 0;
}
