/* main.c: `mcpost SUBCOMMAND ...` -- finds the subcommand in the table and runs it. */
#include "cli.h"
#include "../common/core/internal.h" /* the plug-ins without BLAS threads */

#include <stdio.h>
#include <string.h>

static void
print_help(void)
{
    printf(
        "mcpost %s: post-processing of Monte Carlo renderings\n\n"
        "usage: mcpost SUBCOMMAND [options]   (mcpost SUBCOMMAND --help for its own)\n\n"
        "subcommands:\n",
        MCP_VERSION);
    for (const mcp_command *const *c = mcp_commands; *c; c++)
        printf("  %-10s %s\n", (*c)->name, (*c)->summary);
    printf("\noptions:\n  --help      this text\n  --version   the version\n"
           "  --quiet     (after any subcommand) no progress on stderr\n");
}

/* --quiet, which every subcommand accepts: taken out of argv (up to a "--") for the
 * subcommands that do not parse it themselves, and progress silenced. Returns the new
 * argc. */
static int
take_quiet(int argc, char **argv)
{
    int n = 2;
    for (int i = 2; i < argc; i++) {
        if (strcmp(argv[i], "--") == 0) {
            while (i < argc)
                argv[n++] = argv[i++];
            break;
        }
        if (strcmp(argv[i], "--quiet") == 0)
            mcp_progress_set_quiet(1);
        else
            argv[n++] = argv[i];
    }
    argv[n] = NULL;
    return n;
}

int
main(int argc, char **argv)
{
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
        if (strcmp((*c)->name, argv[1]) == 0) {
            mcp_cli_tune_heap(argv);
            mcp__plugins_one_blas_thread();
            if (!(*c)->parses_quiet) argc = take_quiet(argc, argv);
            return (*c)->run(argc - 1, argv + 1);
        }
    fprintf(stderr, "mcpost: unknown subcommand '%s'; see 'mcpost --help'\n", argv[1]);
    return 2;
}
