/* heap.c: how the mcpost process asks glibc for memory.
 *
 * A command allocates whole frames (25 MB each at 1080p) and frees them again, dozens
 * of times, and every fresh 4 kB page it touches is a page fault. On the virtual
 * machines we measure on a fault costs several microseconds: the gauss estimate of a
 * 1080p dump spent 0.9 s of its 1.65 s in the kernel. Two settings cut that down:
 *
 *  - freed memory is kept for reuse instead of unmapped on free, so that a step
 *    touches the pages of the step before (bench_blend: 47 ms a step instead of 34);
 *  - the heap is backed by transparent huge pages, 2 MB a fault instead of 4 kB
 *    (the gauss estimate: 1.65 s -> 0.8 s; docs/benchmarks.md "Huge pages").
 *
 * glibc (2.35 and later) backs its heap with huge pages only when the tunable
 * glibc.malloc.hugetlb=1 is in GLIBC_TUNABLES as the process starts, before main, so
 * mcpost adds it and executes itself again, once. The second process puts
 * GLIBC_TUNABLES back as it was, so that the programs it runs (an external denoiser,
 * a renderer) see the user's environment. MCPOST_HUGE_PAGES=0 turns it off (a
 * debugger follows one process more easily), as does a GLIBC_TUNABLES that already
 * names the tunable, a kernel without transparent huge pages or with them set to
 * "never", a sanitizer's build, whose allocator is its own, and an LD_PRELOAD (another
 * malloc such as jemalloc, or a tool that watches this process: valgrind's preload,
 * heaptrack; valgrind would run the second process outside itself). */
#include "cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifdef __GLIBC__
#include <gnu/libc-version.h>
#include <malloc.h>
#endif

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define MCP_CLI_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) ||               \
    __has_feature(memory_sanitizer)
#define MCP_CLI_SANITIZED 1
#endif
#endif

#define TUNABLE "glibc.malloc.hugetlb"
/* What GLIBC_TUNABLES held before mcpost added the tunable ('+' and its value, or '-'
 * when it was unset), for the second process to put back. */
#define SAVED_TUNABLES "MCPOST_SAVED_GLIBC_TUNABLES"

#if defined(__GLIBC__) && !defined(MCP_CLI_SANITIZED)
/* 1 when glibc knows the tunable (2.35 and later). */
static int
glibc_has_hugetlb_tunable(void)
{
    int major = 0, minor = 0;
    if (sscanf(gnu_get_libc_version(), "%d.%d", &major, &minor) != 2) return 0;
    return major > 2 || (major == 2 && minor >= 35);
}

/* 1 when the kernel gives transparent huge pages to a region that asks for them
 * ("always" or "madvise" selected). */
static int
kernel_has_huge_pages(void)
{
    FILE *f = fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
    if (!f) return 0;
    char line[128] = "";
    const int ok = fgets(line, sizeof line, f) != NULL;
    fclose(f);
    return ok && !strstr(line, "[never]");
}

/* In the second process: GLIBC_TUNABLES as the user had it. 1 when this is that
 * process. */
static int
restore_tunables(void)
{
    const char *saved = getenv(SAVED_TUNABLES);
    if (!saved) return 0;
    if (saved[0] == '-')
        unsetenv("GLIBC_TUNABLES");
    else
        setenv("GLIBC_TUNABLES", saved + 1, 1);
    unsetenv(SAVED_TUNABLES);
    return 1;
}

/* Executes mcpost again with the tunable set; returns (with the environment as it
 * was) only when that cannot be done. */
static void
reexec_with_huge_pages(char **argv)
{
    const char *off = getenv("MCPOST_HUGE_PAGES");
    if (off && strcmp(off, "0") == 0) return;
    const char *user = getenv("GLIBC_TUNABLES"), *preload = getenv("LD_PRELOAD");
    if ((user && strstr(user, TUNABLE)) || (preload && *preload)) return;
    if (!glibc_has_hugetlb_tunable() || !kernel_has_huge_pages()) return;

    const size_t n = user ? strlen(user) : 0;
    char *saved = malloc(n + 2), *tunables = malloc(n + sizeof TUNABLE "=1" + 1);
    if (!saved || !tunables) goto out;
    saved[0] = user ? '+' : '-';
    memcpy(saved + 1, user ? user : "", n + 1);
    if (n)
        sprintf(tunables, "%s:" TUNABLE "=1", user);
    else
        strcpy(tunables, TUNABLE "=1");
    if (setenv(SAVED_TUNABLES, saved, 1) == 0 &&
        setenv("GLIBC_TUNABLES", tunables, 1) == 0)
        execv("/proc/self/exe", argv);
    /* not executed (no /proc, say): carry on in this process as it is */
    restore_tunables();
out:
    free(saved);
    free(tunables);
}
#endif

void
mcp_cli_tune_heap(char **argv)
{
#ifdef __GLIBC__
#ifndef MCP_CLI_SANITIZED
    if (!restore_tunables()) reexec_with_huge_pages(argv);
#else
    (void)argv;
#endif
    mallopt(M_MMAP_THRESHOLD, 1 << 30);
    mallopt(M_TRIM_THRESHOLD, 0x7fffffff);
#else
    (void)argv;
#endif
}
