/* cli.h: the command table, the stage table, and helpers every subcommand shares. */
#ifndef MCP_CLI_H
#define MCP_CLI_H

#include <mcpost/job.h>
#include <mcpost/imageio.h>
#include <cjson/cJSON.h>

typedef struct mcp_command {
    const char *name;
    const char *summary;
    int (*run)(int argc, char **argv); /* argv[0] is the subcommand's name */
} mcp_command;

/* cli/commands.c: every subcommand, in --help order (NULL-terminated). */
extern const mcp_command *const mcp_commands[];
/* cli/stages.c: every job stage (NULL-terminated). */
extern const mcp_stage *const mcp_stages[];

/* Prints "mcpost: <current error>" and returns the failure exit status (1). */
int mcp_cli_fail(void);
/* Prints a usage error "mcpost CMD: <msg>; see mcpost CMD --help" and returns 2. */
int mcp_cli_usage(const char *cmd, const char *fmt, ...) MCP_PRINTF(2, 3);

/* Parses a number / positive integer option value, naming the flag on error. */
int mcp_cli_double(const char *flag, const char *text, double *out);
int mcp_cli_int(const char *flag, const char *text, int *out);
/* Splits "a,b,c" into a malloc'd array of strdup'd words. */
int mcp_cli_split(const char *text, char ***words, int *count);
void mcp_cli_free_words(char **words, int count);

/* Prints JSON on stdout (pretty) and frees it. */
void mcp_cli_print_json(cJSON *json);

/* Reads a render dump from a file, with the common flags (--spp, --convention,
 * --variance); any may be NULL. */
int mcp_cli_read_dump(const char *path, const char *spp, const char *convention,
                      const char *variance, mcp_dump **out);

#endif
