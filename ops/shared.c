/* shared.c: the flags every command shares, declared once for all of them (options.h):
 * --quiet, --json, -o/--output (a job stage's output: key), --threads, and
 * --print-settings, which every command with a table takes to show what it read. */
#include "options.h"

#include <stddef.h>

#define S mcp_shared_settings

static const mcp_option shared_options[] = {
    {.name = "output",
     .type = MCP_OPT_TEXT,
     .where = MCP_OPT_CLI | MCP_OPT_JOB,
     .offset = offsetof(S, output),
     .meta = "PATH",
     .letter = 'o',
     .doc = "where the results go"},
    {.name = "json",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, json),
     .def = "false",
     .doc = "print the result's JSON on stdout"},
    {.name = "quiet",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, quiet),
     .def = "false",
     .doc = "no progress on stderr"},
    {.name = "threads",
     .type = MCP_OPT_INT,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, threads),
     .meta = "N",
     .def = "0",
     .doc = "OpenMP threads (0: OMP_NUM_THREADS, else every core)",
     .lo = 0,
     .hi = 4096,
     .bounds = MCP_OPT_LO | MCP_OPT_HI},
    {.name = "print_settings",
     .type = MCP_OPT_FLAG,
     .where = MCP_OPT_CLI,
     .offset = offsetof(S, print_settings),
     .def = "false",
     .doc = "print the settings as read, one `name: value` a line, and stop"},
    {0}};

static const mcp_operation shared_op = {
    .name = "shared",
    .summary = "the flags every command shares",
    .options = shared_options,
    .size = sizeof(S),
};

const mcp_operation *
mcp_shared_operation(void)
{
    return &shared_op;
}

const mcp_option *
mcp_shared_option(unsigned bit)
{
    switch (bit) {
    case MCP_SHARED_OUTPUT:
        return &shared_options[0];
    case MCP_SHARED_JSON:
        return &shared_options[1];
    case MCP_SHARED_QUIET:
        return &shared_options[2];
    case MCP_SHARED_THREADS:
        return &shared_options[3];
    default:
        return NULL;
    }
}
