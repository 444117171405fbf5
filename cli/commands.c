/* commands.c: the subcommand table. A module adds its subcommand here, one line. */
#include "cli.h"

extern const mcp_command mcp_command_info, mcp_command_convert, mcp_command_run;
extern const mcp_command mcp_command_metrics, mcp_command_compare;
extern const mcp_command mcp_command_denoise;

extern const mcp_command mcp_command_perceptual;
extern const mcp_command mcp_command_estimate;
extern const mcp_command mcp_command_blend;
extern const mcp_command mcp_command_merge;
extern const mcp_command mcp_command_adaptive;
extern const mcp_command mcp_command_help;
extern const mcp_command mcp_command_submit, mcp_command_collect;
const mcp_command *const mcp_commands[] = {
    &mcp_command_info,       &mcp_command_convert,  &mcp_command_merge,
    &mcp_command_run,        &mcp_command_submit,   &mcp_command_collect,
    &mcp_command_metrics,    &mcp_command_compare,  &mcp_command_denoise,
    &mcp_command_perceptual, &mcp_command_estimate, &mcp_command_blend,
    &mcp_command_adaptive,   &mcp_command_help,     NULL,
};
