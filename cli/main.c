/* main.c: `mcpost SUBCOMMAND ...` -- finds the subcommand in the table and runs it. */
#define _POSIX_C_SOURCE 200809L /* readlink, setenv */
#include "cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

/* The pipelines allocate and free frame-sized images over and over (a blend step
 * makes four 25 MB images at 1080p). By default glibc maps each one fresh and
 * unmaps it on free, so that every step pays tens of thousands of page faults
 * (bench_blend: 47 ms a step instead of 34). A command-line run keeps what it freed
 * for reuse instead; the memory returns to the system when the process ends.
 * bench_blend sets the same two options to time a step as mcpost runs it. */
static void
keep_freed_memory(void)
{
#ifdef __GLIBC__
    mallopt(M_MMAP_THRESHOLD, 1 << 30);
    mallopt(M_TRIM_THRESHOLD, 0x7fffffff);
#endif
}

/* The commands mcpost runs (an adaptive stage's render:, an external denoiser) find
 * the programs installed beside it -- mcpost-procedural, the renderer the demo's
 * adaptive stage drives -- as git finds its own: the folder that holds this
 * executable goes at the end of PATH, so that the user's PATH still wins. */
static void
find_programs_beside(void)
{
    char self[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    if (n <= 0)
        return;
    self[n] = '\0';
    char *slash = strrchr(self, '/');
    if (!slash)
        return;
    *slash = '\0';
    const char *path = getenv("PATH");
    char joined[16384];
    int w = snprintf(joined, sizeof joined, "%s%s%s", path && *path ? path : "",
                     path && *path ? ":" : "", self);
    if (w > 0 && (size_t)w < sizeof joined)
        setenv("PATH", joined, 1);
}

static void
print_help(void)
{
    printf("mcpost %s: post-processing of Monte Carlo renderings\n\n"
           "usage: mcpost SUBCOMMAND [options]   (mcpost SUBCOMMAND --help for its own)\n\n"
           "subcommands:\n",
           MCP_VERSION);
    for (const mcp_command *const *c = mcp_commands; *c; c++)
        printf("  %-10s %s\n", (*c)->name, (*c)->summary);
    printf("\noptions:\n  --help      this text\n  --version   the version\n");
}

int
main(int argc, char **argv)
{
    keep_freed_memory();
    find_programs_beside();
    if (argc < 2) {
        print_help();
        return 2;
    }
    if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
        print_help();
        return 0;
    }
    if (strcmp(argv[1], "--version") == 0) {
        printf("mcpost %s\n", MCP_VERSION);
        return 0;
    }
    for (const mcp_command *const *c = mcp_commands; *c; c++)
        if (strcmp((*c)->name, argv[1]) == 0)
            return (*c)->run(argc - 1, argv + 1);
    fprintf(stderr, "mcpost: unknown subcommand '%s'; see 'mcpost --help'\n", argv[1]);
    return 2;
}
