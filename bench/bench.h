/* bench.h: timing helpers shared by the benchmark programs (header-only: each bench is
 * one executable built from one file). */
#ifndef MCP_BENCH_H
#define MCP_BENCH_H

#ifdef _OPENMP
#include <omp.h>
#endif
#include <stdlib.h>
#include <time.h>

/* Wall-clock milliseconds. */
static inline double
now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* CPU milliseconds of the whole process (all threads): on a machine shared with other
 * work, CPU time / threads estimates the wall time a call would take alone. */
static inline double
cpu_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* OpenMP's thread count for what follows (nothing without OpenMP). */
static inline void
bench_set_threads(int n)
{
#ifdef _OPENMP
    omp_set_num_threads(n);
#else
    (void)n;
#endif
}

/* qsort comparison for doubles (for medians). */
static inline int
cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

#endif
