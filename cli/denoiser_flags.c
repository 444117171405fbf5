/* denoiser_flags.c: --denoiser, --denoiser-opt and the shorthands for denoiser keys,
 * shared by every subcommand that takes a denoiser (see cli.h). */
#include "cli.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Appends "key=value" (key NULL: text is already "key=value"). Every option is a copy,
 * so that a shorthand's joined string and a --denoiser-opt word are freed alike. */
static int
add_opt(mcp_cli_denoiser_flags *f, const char *key, const char *text)
{
    if (f->n_opts == f->cap) {
        int cap = f->cap ? 2 * f->cap : 8;
        char **o = realloc(f->opts, (size_t)cap * sizeof *o);
        if (!o) return mcp_error("out of memory (%d denoiser options)", cap);
        f->opts = o;
        f->cap = cap;
    }
    char *s;
    if (key) {
        size_t n = strlen(key) + 1 + strlen(text) + 1;
        if ((s = mcp_malloc(n))) snprintf(s, n, "%s=%s", key, text);
    } else {
        s = mcp_strdup(text);
    }
    if (!s) return -1;
    f->opts[f->n_opts++] = s;
    return 0;
}

int
mcp_cli_denoiser_flag(mcp_cli_denoiser_flags *f, int opt, const char *arg)
{
    switch (opt) {
    case MCP_CLI_OPT_DENOISER:
        f->name = arg;
        return 1;
    case MCP_CLI_OPT_DENOISER_OPT:
        return add_opt(f, NULL, arg) ? -1 : 1;
    case MCP_CLI_OPT_WEIGHTS:
        return add_opt(f, "weights", arg) ? -1 : 1;
    case MCP_CLI_OPT_INPUT_SCALE:
        return add_opt(f, "input_scale", arg) ? -1 : 1;
    case MCP_CLI_OPT_DENOISER_COMMAND:
        return add_opt(f, "command", arg) ? -1 : 1;
    default:
        return 0;
    }
}

int
mcp_cli_denoiser_create(const mcp_cli_denoiser_flags *f, mcp_denoiser **out)
{
    /* the duplicate check (a shorthand and --denoiser-opt naming one key) and the
     * unknown-key check are create_from_args', with its messages. No name: the
     * default (the U-Net, or nlm without features), which create_from_args makes the
     * U-Net when its settings (--weights, ...) are given */
    const char *name = f->name ? f->name : "default";
    return mcp_denoiser_create_from_args(name, (const char *const *)f->opts, f->n_opts,
                                         out);
}

void
mcp_cli_denoiser_flags_free(mcp_cli_denoiser_flags *f)
{
    for (int i = 0; i < f->n_opts; i++)
        free(f->opts[i]);
    free(f->opts);
    f->opts = NULL;
    f->n_opts = f->cap = 0;
}
