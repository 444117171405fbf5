/* bench_unet.c: timings and peak memory of the `unet` denoiser (OIDN's RT U-Net,
 * estimate/unet.c; no pass/fail) beside two baselines measured in the same run, on as
 * many threads: OpenBLAS's cblas_sgemm at the network's layer shapes (M = cout,
 * K = 9 cin, N = 65536, as an im2col convolution would call it), and, where the build
 * made it (libdnnl-dev and the anchor program dnnl_unet.cpp, kept outside the tree:
 * MCPOST_ONEDNN_ANCHOR, bench/CMakeLists.txt), oneDNN running the same network the way
 * OIDN 1.4 does on the CPU (direct convolutions in its layout), and with oneDNN's
 * Winograd; without it, one line says how to get it.
 *
 * The U-Net runs on a render-like input (noisy colour, albedo with edges, normals of
 * two planes, as bench_denoise) with the official colour + albedo + normal weights
 * from $MCPOST_OIDN_WEIGHTS, else the shipped weights/rt_hdr_alb_nrm.tza of the source
 * tree (without them it prints a skip line and exits 0): apply, and apply + JVP with 1,
 * 4 and 8 tangents in one pass, in the default (Winograd) mode and in the fixed-bit
 * mode (MCPOST_UNET_FIXED=1: the direct loops, the same bits on every x86-64). Each
 * row is a fresh process (this program run again with --one, or the anchor), so that
 * its peak resident memory is that of a process doing only that call on that input;
 * oneDNN's process holds its 9-channel input and 3-channel output, ours the colour,
 * albedo, normal and variance images, the tangents and the outputs. Each time is the
 * median of `repeats` runs after one warm-up: wall-clock ms and ms per megapixel with
 * the default OpenMP team (OMP_NUM_THREADS changes it), CPU ms (all threads) per
 * megapixel, and the direct-convolution-equivalent rate: 125406 multiply-adds per
 * pixel of the input padded to a multiple of 16, per image of the batch (the primal
 * and each tangent), per wall-clock second, and that rate over sgemm's.
 * With the anchor, and the default mode timed, a head-to-head follows: `rounds` times
 * our apply then oneDNN's Winograd apply, one run each in a fresh process, and the
 * median and range of the ratio of each pair (this machine drifts between the tables'
 * medians).
 * Usage: bench_unet [repeats (default 3)] [width (default 512)] [height (default width)]
 *                   [both | default | fixed (the modes timed; default both)]
 *                   [rounds (of the head-to-head; default 5)]
 *        (1080p: bench_unet 3 1920 1080) */
/* wait4: the peak memory of each child process */
#define _DEFAULT_SOURCE

#include <mcpost/denoiser.h>

#include "denoiser_bench.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#define MAC_PER_PIXEL 125406.0 /* the RT U-Net's 3x3 convolutions, 9 input channels */

#ifdef MCP_BENCH_OPENBLAS
/* The RT U-Net's convolutions: input and output channels, and the resolution as a
 * fraction of the input's pixels (MACs per input pixel: 9 cin cout / frac). */
static const struct {
    int cin, cout, frac;
} layers[] = {{9, 32, 1},     {32, 32, 1},   {32, 48, 4},   {48, 64, 16},
              {64, 80, 64},   {80, 96, 256}, {96, 96, 256}, {160, 112, 64},
              {112, 112, 64}, {160, 96, 16}, {96, 96, 16},  {128, 64, 4},
              {64, 64, 4},    {73, 64, 1},   {64, 32, 1},   {32, 3, 1}};
#define N_LAYERS ((int)(sizeof layers / sizeof layers[0]))

#include <cblas.h>
void openblas_set_num_threads(int n);

/* sgemm's rate in GMAC/s for M x K times K x N (median of 3 after a warm-up). */
static double
sgemm_rate(int m, int k, int n)
{
    float *a = malloc((size_t)m * k * sizeof(float)),
          *b = malloc((size_t)k * n * sizeof(float));
    float *c = malloc((size_t)m * n * sizeof(float));
    if (!a || !b || !c) {
        free(a), free(b), free(c);
        return -1;
    }
    uint64_t st = 7;
    for (size_t i = 0; i < (size_t)m * k; i++)
        a[i] = (float)bench_uniform(&st) - 0.5f;
    for (size_t i = 0; i < (size_t)k * n; i++)
        b[i] = (float)bench_uniform(&st) - 0.5f;
    double t[4];
    for (int r = 0; r < 4; r++) {
        double t0 = now_ms();
        cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, m, n, k, 1.0f, a, k, b, n,
                    0.0f, c, n);
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
    printf(
        "OpenBLAS cblas_sgemm, %d thread(s), N = 65536 (an im2col convolution's call)\n",
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

/* The calls timed: apply (-1 tangents), and apply + JVP with 1, 4 and 8 tangents. */
#define N_CALLS 4
static const char *const call_labels[N_CALLS] = {"apply", "apply + JVP, 1 tangent",
                                                 "apply + JVP, 4 tangents",
                                                 "apply + JVP, 8 tangents"};
static const int call_tangents[N_CALLS] = {-1, 1, 4, 8};

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

/* The child's side of one row (bench_unet --one TANGENTS REPEATS WIDTH HEIGHT, the mode
 * from MCPOST_UNET_FIXED): the scene with only the tangents the call needs, the call
 * timed, and "ms cpu_ms" on stdout. */
static int
time_one_call(const char *weights, int tangents, int repeats, int width, int height)
{
    char opt[4200];
    snprintf(opt, sizeof opt, "weights=%s", weights);
    mcp_denoiser *d = NULL;
    if (mcp_denoiser_create_from_args("unet", (const char *[]){opt}, 1, &d)) {
        fprintf(stderr, "bench_unet: %s\n", mcp_error_message());
        return 1;
    }
    bench_scene sc;
    bench_scene_make(width, height, tangents < 0 ? 0 : tangents, &sc);
    double cpu = 0,
           ms = bench_denoiser_median_ms(d, &sc.in, sc.t, tangents, repeats, &cpu);
    bench_scene_free(&sc);
    mcp_denoiser_free(d);
    if (ms < 0) return 1;
    printf("%.17g %.17g\n", ms, cpu);
    return 0;
}

/* Runs path with argv (environment inherited) and its stdout into out (cap bytes,
 * NUL-terminated); returns its exit status (-1 when it could not run or was killed),
 * and in *peak_mb its peak resident memory in MB (1e6 bytes). */
static int
run_child(const char *path, char *const argv[], char *out, size_t cap, double *peak_mb)
{
    int fd[2];
    *peak_mb = -1, out[0] = 0;
    fflush(stdout);
    if (pipe(fd)) return -1;
    pid_t pid = fork();
    if (pid < 0) {
        close(fd[0]), close(fd[1]);
        return -1;
    }
    if (pid == 0) {
        dup2(fd[1], STDOUT_FILENO);
        close(fd[0]), close(fd[1]);
        execv(path, argv);
        _exit(127);
    }
    close(fd[1]);
    /* what does not fit is read and dropped, so that the child never blocks on a full
     * pipe */
    char drop[256];
    size_t len = 0;
    ssize_t got;
    while ((got = read(fd[0], len < cap - 1 ? out + len : drop,
                       len < cap - 1 ? cap - 1 - len : sizeof drop)) > 0)
        if (len < cap - 1) len += (size_t)got;
    out[len] = 0;
    close(fd[0]);
    int status = 0;
    struct rusage ru;
    if (wait4(pid, &status, 0, &ru) != pid) return -1;
    *peak_mb = (double)ru.ru_maxrss * 1024 / 1e6; /* ru_maxrss is in KiB on Linux */
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

/* One row of the tables: times, rates and peak memory. */
static void
print_row(const char *label, double ms, double cpu, double gmac, double sgemm, double mp,
          double peak_mb)
{
    const double rate = gmac / (ms * 1e-3);
    printf("%-32s %10.1f %10.1f %12.1f %10.2f", label, ms, ms / mp, cpu / mp, rate);
    if (sgemm > 0)
        printf(" %10.2f", rate / sgemm);
    else
        printf(" %10s", "-");
    printf(" %10.0f\n", peak_mb);
}

static void
print_header(void)
{
    printf("%-32s %10s %10s %12s %10s %10s %10s\n", "call", "ms", "ms/MP", "CPU ms/MP",
           "GMAC/s", "x sgemm", "peak MB");
}

#ifndef MCP_BENCH_ONEDNN_WHY /* CMake says why it did not build the anchor */
#define MCP_BENCH_ONEDNN_WHY "this build does not look for it"
#endif

#ifdef MCP_BENCH_ONEDNN
/* One run of the anchor with --algo algo and --reps reps: its wall and CPU ms, peak
 * MB, the title ("oneDNN 2.6.3") and the kernels it names; 0, or 1 with a line on
 * stderr. */
static int
onednn_run(const char *weights, const char *algo, int reps, int width, int height,
           double *ms, double *cpu, double *peak, char *title, size_t title_cap,
           char *impl, size_t impl_cap)
{
    char w[16], h[16], r[16], out[1024];
    snprintf(w, sizeof w, "%d", width), snprintf(h, sizeof h, "%d", height);
    snprintf(r, sizeof r, "%d", reps);
    char *argv[] = {(char *)MCP_BENCH_ONEDNN,
                    (char *)weights,
                    w,
                    h,
                    "--reps",
                    r,
                    "--layout",
                    "oidn",
                    "--algo",
                    (char *)algo,
                    NULL};
    const int rc = run_child(MCP_BENCH_ONEDNN, argv, out, sizeof out, peak);
    /* "oneDNN 2.6.3 apply [direct, oidn; jit:avx512_corex16]  1920x1088 2 thr
     *  3500.0 ms  75.00 GMAC/s  7000.0 CPU ms  (runs ...)" */
    const char *apply = strstr(out, " apply ["), *open = strchr(out, '['),
               *close = open ? strchr(open, ']') : NULL, *thr = strstr(out, " thr ");
    double gmac;
    if (rc != 0 || !apply || !close || !thr ||
        sscanf(thr + 5, "%lf ms %lf GMAC/s %lf CPU ms", ms, &gmac, cpu) != 3) {
        fprintf(stderr, "bench_unet: the oneDNN anchor (%s, --algo %s) failed%s%s\n",
                MCP_BENCH_ONEDNN, algo, out[0] ? ": " : "", out);
        return 1;
    }
    snprintf(title, title_cap, "%.*s", (int)(apply - out), out);
    snprintf(impl, impl_cap, "%.*s", (int)(close - open - 1), open + 1);
    return 0;
}

/* The anchor's two runs (OIDN 1.4's direct convolutions in its layout, and oneDNN's
 * Winograd), their rows, and their times in ms[0], ms[1] (-1 when a run failed). */
static int
onednn_rows(const char *weights, int repeats, int width, int height, int threads,
            double sgemm, double mp, double gmac, double ms[2])
{
    static const char *const algos[2] = {"direct", "winograd"};
    static const char *const labels[2] = {"apply, direct (as OIDN 1.4)",
                                          "apply, Winograd"};
    char title[256] = "", impl[2][256] = {"", ""};
    double cpu[2], peak[2];
    int status = 0;
    for (int a = 0; a < 2; a++)
        if (onednn_run(weights, algos[a], repeats, width, height, &ms[a], &cpu[a],
                       &peak[a], title, sizeof title, impl[a], sizeof impl[a])) {
            ms[a] = -1;
            status = 1;
        }
    printf("%s (the anchor dnnl_unet.cpp: OIDN 1.4's RT U-Net, primal only) at %dx%d, "
           "%d thread(s), median of %d\n",
           title[0] ? title : "oneDNN", width, height, threads, repeats);
    print_header();
    for (int a = 0; a < 2; a++)
        if (ms[a] > 0) print_row(labels[a], ms[a], cpu[a], gmac, sgemm, mp, peak[a]);
    for (int a = 0; a < 2; a++) /* oneDNN's kernels, as the anchor names them */
        if (ms[a] > 0) printf("  --algo %s --layout oidn: %s\n", algos[a], impl[a]);
    printf("\n");
    return status;
}

static int
by_value(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Our apply (default mode) and oneDNN's Winograd apply in turn, `rounds` times, each a
 * fresh process timing one run after its warm-up. The tables above take each median
 * minutes apart, and this machine's speed drifts by tens of percent in that time (a
 * 1080p apply measured 0.95 and 1.25 s, oneDNN's Winograd 1.27 and 0.97 s, in two runs
 * of this program on December 5): the ratio of neighbouring runs is what holds. */
static int
head_to_head(const char *self, const char *weights, int rounds, int width, int height)
{
    enum { MAX_ROUNDS = 64 };
    char w[16], h[16], out[256], title[256], impl[256];
    snprintf(w, sizeof w, "%d", width), snprintf(h, sizeof h, "%d", height);
    double ours[MAX_ROUNDS], theirs[MAX_ROUNDS], ratio[MAX_ROUNDS];
    int n = 0;
    rounds = rounds < MAX_ROUNDS ? rounds : MAX_ROUNDS;
    setenv("MCPOST_UNET_FIXED", "0", 1);
    for (int r = 0; r < rounds; r++) {
        char *args[] = {(char *)self, "--one", "-1", "1", w, h, NULL};
        double ms, cpu, peak, dnn;
        if (run_child("/proc/self/exe", args, out, sizeof out, &peak) != 0 ||
            sscanf(out, "%lf %lf", &ms, &cpu) != 2 ||
            onednn_run(weights, "winograd", 1, width, height, &dnn, &cpu, &peak, title,
                       sizeof title, impl, sizeof impl)) {
            fprintf(stderr, "bench_unet: head to head: round %d failed\n", r + 1);
            unsetenv("MCPOST_UNET_FIXED");
            return 1;
        }
        ours[n] = ms, theirs[n] = dnn, ratio[n] = ms / dnn, n++;
    }
    unsetenv("MCPOST_UNET_FIXED");
    qsort(ours, (size_t)n, sizeof *ours, by_value);
    qsort(theirs, (size_t)n, sizeof *theirs, by_value);
    qsort(ratio, (size_t)n, sizeof *ratio, by_value);
    printf(
        "head to head at %dx%d, %d rounds of unet's apply (default mode) then oneDNN's "
        "Winograd, one run each after its warm-up:\n",
        width, height, n);
    printf("  unet %.1f ms [%.1f, %.1f], oneDNN Winograd %.1f ms [%.1f, %.1f] "
           "(medians [ranges])\n",
           ours[n / 2], ours[0], ours[n - 1], theirs[n / 2], theirs[0], theirs[n - 1]);
    printf("  unet's time over oneDNN's, round by round: median %.2fx [%.2f, %.2f]; "
           "unet's rate %.2fx oneDNN Winograd's\n\n",
           ratio[n / 2], ratio[0], ratio[n - 1], 1.0 / ratio[n / 2]);
    return 0;
}
#endif

int
main(int argc, char **argv)
{
    if (argc == 6 && !strcmp(argv[1], "--one")) {
        const char *path = weights_path();
        return path ? time_one_call(path, atoi(argv[2]), atoi(argv[3]), atoi(argv[4]),
                                    atoi(argv[5]))
                    : 1;
    }
    int repeats = argc > 1 ? atoi(argv[1]) : 3, width = argc > 2 ? atoi(argv[2]) : 512;
    int height = argc > 3 ? atoi(argv[3]) : width;
    const char *modes = argc > 4 ? argv[4] : "both";
    const int rounds = argc > 5 ? atoi(argv[5]) : 5;
    const int first = !strcmp(modes, "fixed") ? 1 : 0,
              last = !strcmp(modes, "default") ? 0 : 1;
    if (repeats < 1 || width < 8 || width > 8192 || height < 8 || height > 8192 ||
        (strcmp(modes, "both") && strcmp(modes, "default") && strcmp(modes, "fixed")) ||
        rounds < 1 || rounds > 64) {
        fprintf(stderr,
                "usage: bench_unet [repeats >= 1] [width in 8..8192] "
                "[height in 8..8192] [both | default | fixed] [rounds in 1..64]\n");
        return 2;
    }
    const char *path = weights_path();
    if (!path || access(path, R_OK) != 0) {
        printf("bench_unet: skipped: no OIDN weights at %s (set MCPOST_OIDN_WEIGHTS)\n",
               path ? path : "(unknown)");
        return 0;
    }
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    /* every child (our rows and the anchor's) runs on the same team */
    char threads_s[16];
    snprintf(threads_s, sizeof threads_s, "%d", threads);
    setenv("OMP_NUM_THREADS", threads_s, 1);
    double sgemm = -1;
#ifdef MCP_BENCH_OPENBLAS
    sgemm = sgemm_baseline(threads);
#else
    printf("(built without OpenBLAS: no sgemm baseline)\n\n");
#endif
    const double mp = (double)width * height / 1e6;
    const double padded = (double)((width + 15) / 16 * 16) * ((height + 15) / 16 * 16);
    const double gmac_apply = MAC_PER_PIXEL * padded * 1e-9;
    char w[16], h[16], reps[16], nt[16], out[256];
    snprintf(w, sizeof w, "%d", width), snprintf(h, sizeof h, "%d", height);
    snprintf(reps, sizeof reps, "%d", repeats);
    int status = 0;
    double apply_ms[2] = {-1, -1}; /* the default and fixed-bit modes' apply */
    for (int fixed = first; fixed <= last; fixed++) {
        setenv("MCPOST_UNET_FIXED", fixed ? "1" : "0", 1);
        printf("unet at %dx%d, %d thread(s), median of %d, %s\n", width, height, threads,
               repeats,
               fixed ? "fixed-bit mode (MCPOST_UNET_FIXED=1: direct loops)"
                     : "default mode (Winograd F(4x4,3x3))");
        print_header();
        for (int c = 0; c < N_CALLS; c++) {
            const int n = call_tangents[c];
            snprintf(nt, sizeof nt, "%d", n);
            char *args[] = {argv[0], "--one", nt, reps, w, h, NULL};
            double ms, cpu, peak;
            if (run_child("/proc/self/exe", args, out, sizeof out, &peak) != 0 ||
                sscanf(out, "%lf %lf", &ms, &cpu) != 2) {
                fprintf(stderr, "bench_unet: %s failed\n", call_labels[c]);
                status = 1;
                continue;
            }
            if (n < 0) apply_ms[fixed] = ms;
            print_row(call_labels[c], ms, cpu, gmac_apply * (n < 0 ? 1 : 1 + n), sgemm,
                      mp, peak);
        }
        printf("\n");
    }
    unsetenv("MCPOST_UNET_FIXED");
#ifdef MCP_BENCH_ONEDNN
    double onednn_ms[2];
    status |= onednn_rows(path, repeats, width, height, threads, sgemm, mp, gmac_apply,
                          onednn_ms);
    for (int fixed = 0; fixed <= 1; fixed++)
        if (apply_ms[fixed] > 0 && onednn_ms[0] > 0 && onednn_ms[1] > 0)
            printf("unet's apply (%s mode) takes %.2fx oneDNN direct's time, %.2fx "
                   "Winograd's\n",
                   fixed ? "fixed-bit" : "default", apply_ms[fixed] / onednn_ms[0],
                   apply_ms[fixed] / onednn_ms[1]);
    printf("\n");
    if (first == 0) status |= head_to_head(argv[0], path, rounds, width, height);
#else
    printf("bench_unet: no oneDNN baseline: the anchor was not built: %s "
           "(docs/benchmarks.md, U-Net)\n",
           MCP_BENCH_ONEDNN_WHY);
    (void)apply_ms, (void)rounds;
#endif
    return status;
}
