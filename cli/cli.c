/* cli.c: helpers shared by the subcommands (see cli.h). */
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

int
mcp_cli_fail(void)
{
    fprintf(stderr, "mcpost: %s\n", mcp_error_message());
    return 1;
}

int
mcp_cli_usage(const char *cmd, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "mcpost %s: ", cmd);
    vfprintf(stderr, fmt, ap);
    fprintf(stderr, "; see 'mcpost %s --help'\n", cmd);
    va_end(ap);
    return 2;
}

void
mcp_cli_print_json(cJSON *json)
{
    char *text = cJSON_Print(json);
    if (text) puts(text);
    free(text);
    cJSON_Delete(json);
}

int
mcp_cli_dump_spec(const char *path, const char *spp, const char *convention,
                  const char *variance, mcp_dump_spec *spec)
{
    *spec = mcp_dump_spec_defaults();
    spec->path = path;
    if ((spp && mcp__parse_double("--spp", spp, &spec->spp)) ||
        (convention && mcp_convention_from_name(convention, &spec->convention)) ||
        (variance && mcp_variance_kind_from_name(variance, &spec->variance)))
        return -1;
    if (spp && spec->spp <= 0) return mcp_error("--spp must be > 0 (got %s)", spp);
    return 0;
}

int
mcp_cli_read_dump(const char *path, const char *spp, const char *convention,
                  const char *variance, mcp_dump **out)
{
    mcp_dump_spec spec;
    *out = NULL;
    if (mcp_cli_dump_spec(path, spp, convention, variance, &spec)) return -1;
    return mcp_dump_load(&spec, out);
}

int
mcp_cli_output_is_not_input(const char *cmd, const char *out, const char *const *inputs,
                            int n)
{
    struct stat so, si;
    if (!out || stat(out, &so) != 0) return 0; /* a new file cannot be an input */
    for (int i = 0; i < n; i++)
        if (inputs[i] && stat(inputs[i], &si) == 0 && si.st_dev == so.st_dev &&
            si.st_ino == so.st_ino)
            return mcp_error("%s: the output %s is the input %s; give another output",
                             cmd, out, inputs[i]);
    return 0;
}
