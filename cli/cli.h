/* cli.h: the command table and helpers every subcommand shares. What a subcommand
 * shares with its job stage (outputs, reports, settings words) is the library's, in
 * jobs/internal.h. */
#ifndef MCP_CLI_H
#define MCP_CLI_H

#include <mcpost/job.h>
#include <mcpost/imageio.h>
#include <mcpost/denoiser.h>
#include <mcpost/operations.h>
#include <mcpost/options.h>
#include <cjson/cJSON.h>

#include "../jobs/internal.h"

typedef struct mcp_command {
    const char *name;
    const char *summary;
    int (*run)(int argc, char **argv); /* argv[0] is the subcommand's name */
    /* 1: it parses --quiet itself; otherwise main takes --quiet for it (no progress
     * on stderr), so that every subcommand accepts it */
    int parses_quiet;
} mcp_command;

/* cli/commands.c: every subcommand, in --help order (NULL-terminated). */
extern const mcp_command *const mcp_commands[];

/* cli/heap.c: at the start of a subcommand, glibc's heap kept for reuse and backed by
 * transparent huge pages; the latter executes mcpost again, with argv, once. */
void mcp_cli_tune_heap(char **argv);

/* Prints "mcpost: <current error>" and returns the failure exit status (1). */
int mcp_cli_fail(void);
/* Prints a usage error "mcpost CMD: <msg>; see mcpost CMD --help" and returns 2. */
int mcp_cli_usage(const char *cmd, const char *fmt, ...) MCP_PRINTF(2, 3);

/* Refuses an output that is one of the inputs (the same file, by device and inode,
 * whatever the spelling): "CMD: the output OUT is the input IN; give another
 * output" as the current error and -1; 0 when out is new or another file. inputs may
 * hold NULLs. */
int mcp_cli_output_is_not_input(const char *cmd, const char *out,
                                const char *const *inputs, int n);

/* Prints JSON on stdout (pretty) and frees it. */
void mcp_cli_print_json(cJSON *json);

/* The spec of a render dump in a file, with the common flags (--spp, --convention,
 * --variance); any may be NULL. */
int mcp_cli_dump_spec(const char *path, const char *spp, const char *convention,
                      const char *variance, mcp_dump_spec *spec);
/* Reads a render dump from a file, with the common flags (--spp, --convention,
 * --variance); any may be NULL. */
int mcp_cli_read_dump(const char *path, const char *spp, const char *convention,
                      const char *variance, mcp_dump **out);

/* cli/denoiser_flags.c: the denoiser flags of every subcommand that takes one
 * (denoise, estimate, blend, perceptual), parsed in one place so that they read the
 * same everywhere. --denoiser-opt KEY=VALUE is one key of the job file's denoiser map;
 * the shorthands are the same words as those keys:
 *   --weights PATH           --denoiser-opt weights=PATH      (unet)
 *   --input-scale auto|N     --denoiser-opt input_scale=...   (unet)
 *   --denoiser-command CMD   --denoiser-opt command=CMD       (external)
 * A key given twice, by either spelling, fails when the denoiser is created
 * (mcp_denoiser_create_from_args: "key 'weights' given twice"). */
typedef struct mcp_cli_denoiser_flags {
    const char *name; /* --denoiser, borrowed from argv; a command may preset a default */
    char **opts;      /* "key=value", owned, in command-line order */
    int n_opts, cap;
} mcp_cli_denoiser_flags;

/* getopt_long values of the denoiser flags: above any command's own. */
enum {
    MCP_CLI_OPT_DENOISER = 0x4000,
    MCP_CLI_OPT_DENOISER_OPT,
    MCP_CLI_OPT_WEIGHTS,
    MCP_CLI_OPT_INPUT_SCALE,
    MCP_CLI_OPT_DENOISER_COMMAND
};

/* The struct option entries, for a command's longs[] (needs <getopt.h>). */
#define MCP_CLI_DENOISER_LONGOPTS                                                        \
    {"denoiser", required_argument, 0, MCP_CLI_OPT_DENOISER},                            \
        {"denoiser-opt", required_argument, 0, MCP_CLI_OPT_DENOISER_OPT},                \
        {"weights", required_argument, 0, MCP_CLI_OPT_WEIGHTS},                          \
        {"input-scale", required_argument, 0, MCP_CLI_OPT_INPUT_SCALE},                  \
    {                                                                                    \
        "denoiser-command", required_argument, 0, MCP_CLI_OPT_DENOISER_COMMAND           \
    }

/* Help lines for the flags besides --denoiser NAME (whose default each command tells
 * itself). The descriptions start in column 26 + strlen(PAD): PAD is a string literal
 * of spaces that lines them up with the command's own. */
#define MCP_CLI_DENOISER_USAGE(PAD)                                                      \
    "  --denoiser-opt KEY=VAL  " PAD                                                     \
    "a denoiser setting, a key of the job file's denoiser\n"                             \
    "                          " PAD                                                     \
    "map (repeatable; e.g. sigma=3). Shorthands for keys:\n"                             \
    "  --weights PATH          " PAD "unet: OIDN weights, a .tza (weights=PATH)\n"       \
    "                          " PAD "[$MCPOST_OIDN_WEIGHTS]\n"                          \
    "  --input-scale auto|N    " PAD                                                     \
    "unet: N maps the colour to 1 = 100 cd/m^2; auto is\n"                               \
    "                          " PAD "OIDN's autoexposure (input_scale=N) [auto]\n"      \
    "  --denoiser-command CMD  " PAD                                                     \
    "external: a /bin/sh command with {color} {albedo}\n"                                \
    "                          " PAD "{normal} {output} for its files (command=CMD)\n"

/* Takes one getopt_long result: 1 when opt is a denoiser flag (taken), 0 when it is
 * not, -1 on failure (out of memory; mcp_error is set). */
int mcp_cli_denoiser_flag(mcp_cli_denoiser_flags *f, int opt, const char *arg);
/* Creates the denoiser named by the flags (mcp_denoiser_create_from_args); with no
 * --denoiser, `default` (the U-Net with the shipped weights, nlm for inputs without
 * albedo and normal), or `unet` when U-Net settings such as --weights are given. */
int mcp_cli_denoiser_create(const mcp_cli_denoiser_flags *f, mcp_denoiser **out);
/* What the help texts say about the default denoiser. */
#define MCP_CLI_DEFAULT_DENOISER                                                         \
    "[default: unet with the shipped weights; nlm for dumps without albedo and normal]"

/* Frees the options (the name is borrowed); safe on a zeroed struct, and twice. */
void mcp_cli_denoiser_flags_free(mcp_cli_denoiser_flags *f);

/* cli/options.c: a subcommand's flags through its operation's table
 * (<mcpost/options.h>): every option the command line takes (--NAME with '-' for '_',
 * --no-NAME for a flag, the alias), the shared flags op takes (--quiet, --json,
 * -o/--output, --threads, and --print-settings), and the denoiser flags when op has a
 * denoiser. argv's values go through mcp_operation_set into settings (defaults first)
 * and sh; then op's finish. An option of the table spelt like a denoiser shorthand
 * (blend's --weights) takes its own words, and any other value goes to the shorthand
 * (--weights PATH). Returns -1 to go on (*first: the first positional argument), or
 * the status to exit with: 0 after --help (head, the options, examples) or
 * --print-settings (the settings as read, mcp_operation_dump), 1 or 2 after an error
 * (printed). Quiet and threads take effect here. */
int mcp_cli_parse(const mcp_operation *op, const char *head, const char *examples,
                  int argc, char **argv, void *settings, mcp_shared_settings *sh,
                  mcp_cli_denoiser_flags *df, int *first);
/* The --help text: head, the option list from op's table, examples. */
void mcp_cli_print_help(const mcp_operation *op, const char *head, const char *examples);

#endif
