/* bench_startup.c: whole-process times of `mcpost --version` and `mcpost info` on a
 * 1024x1024 EXR (the cost a render-farm script pays per call), the same `info` in one
 * process (MCPOST_HUGE_PAGES=0: without the second process that puts the heap on huge
 * pages, cli/heap.c), and `info` on a PNG, which loads the OpenImageIO plug-in. Prints
 * figures; passes nothing. */
#define _POSIX_C_SOURCE 200809L
#include <mcpost/imageio.h>

#include <stdio.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <time.h>

static double
now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

/* CPU seconds (user + system) used by finished children so far. */
static double
children_cpu(void)
{
    struct rusage ru;
    getrusage(RUSAGE_CHILDREN, &ru);
    return ru.ru_utime.tv_sec + ru.ru_utime.tv_usec * 1e-6 + ru.ru_stime.tv_sec +
           ru.ru_stime.tv_usec * 1e-6;
}

/* Median wall time of `reps` runs of a shell command, in milliseconds; *cpu_ms gets
 * the mean CPU time per run, which a busy machine does not inflate. */
static double
time_command(const char *cmd, int reps, double *cpu_ms)
{
    double t[64], c0 = children_cpu();
    for (int i = 0; i < reps; i++) {
        double t0 = now();
        if (system(cmd) != 0) {
            fprintf(stderr, "bench_startup: '%s' failed\n", cmd);
            exit(1);
        }
        t[i] = (now() - t0) * 1e3;
    }
    *cpu_ms = (children_cpu() - c0) * 1e3 / reps;
    for (int i = 1; i < reps; i++) /* insertion sort: reps is small */
        for (int j = i; j > 0 && t[j] < t[j - 1]; j--) {
            double s = t[j];
            t[j] = t[j - 1];
            t[j - 1] = s;
        }
    return t[reps / 2];
}

int
main(int argc, char **argv)
{
    const char *mcpost = argc > 1 ? argv[1] : "./mcpost";
    const char *dir = argc > 2 ? argv[2] : "/tmp";
    char exr[4096], png[4096], cmd[8300];
    snprintf(exr, sizeof exr, "%s/bench_startup.exr", dir);
    snprintf(png, sizeof png, "%s/bench_startup.png", dir);
    mcp_image *img;
    const char *names[] = {"R", "G", "B", "Variance.R", "Variance.G", "Variance.B"};
    if (mcp_image_new(1024, 1024, 6, names, &img)) return 1;
    uint64_t s = 1;
    for (size_t i = 0; i < (size_t)1024 * 1024 * 6; i++) {
        s = s * 6364136223846793005ull + 1442695040888963407ull;
        img->data[i] = (float)(s >> 40) / (float)(1 << 24);
    }
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 64);
    mcp_image *rgb;
    if (mcp_image_write(img, exr, NULL) || mcp_image_channel_view(img, 0, 3, &rgb) ||
        mcp_image_write(rgb, png, NULL)) {
        fprintf(stderr, "bench_startup: %s\n", mcp_error_message());
        return 1;
    }
    mcp_image_free(rgb);
    mcp_image_free(img);
    const int reps = 11;
    printf("whole-process times over %d runs: wall (median) and CPU (mean), ms\n", reps);
    struct {
        const char *label, *env, *args, *file;
    } runs[] = {{"mcpost --version", "", "--version", ""},
                {"mcpost info 1024x1024x6 EXR (zip)", "", "info", exr},
                {"  the same in one process", "MCPOST_HUGE_PAGES=0 ", "info", exr},
                {"mcpost info 1024x1024 PNG (OIIO)", "", "info", png}};
    for (size_t i = 0; i < sizeof runs / sizeof *runs; i++) {
        double cpu;
        snprintf(cmd, sizeof cmd, "%s'%s' %s '%s' >/dev/null", runs[i].env, mcpost,
                 runs[i].args, runs[i].file);
        if (!runs[i].file[0])
            snprintf(cmd, sizeof cmd, "%s'%s' %s >/dev/null", runs[i].env, mcpost,
                     runs[i].args);
        double wall = time_command(cmd, reps, &cpu);
        printf("  %-36s wall %8.1f   cpu %8.1f\n", runs[i].label, wall, cpu);
    }
    return 0;
}
