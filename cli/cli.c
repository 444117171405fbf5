/* cli.c: helpers shared by the subcommands (see cli.h). */
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

int
mcp_cli_double(const char *flag, const char *text, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    if (end == text || *end || errno || !isfinite(v))
        return mcp_error("%s must be a number (got '%s')", flag, text);
    *out = v;
    return 0;
}

int
mcp_cli_int(const char *flag, const char *text, int *out)
{
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (end == text || *end || errno || v < -2147483647L || v > 2147483647L)
        return mcp_error("%s must be an integer (got '%s')", flag, text);
    *out = (int)v;
    return 0;
}

int
mcp_cli_split(const char *text, char ***words, int *count)
{
    char *copy = mcp_strdup(text), *save = NULL;
    if (!copy)
        return -1;
    int n = 1;
    for (const char *p = text; *p; p++)
        n += *p == ',';
    char **w = mcp_calloc((size_t)n, sizeof *w);
    int k = 0;
    for (char *tok = strtok_r(copy, ",", &save); w && tok; tok = strtok_r(NULL, ",", &save))
        w[k++] = mcp_strdup(tok);
    free(copy);
    if (!w)
        return -1;
    *words = w;
    *count = k;
    return 0;
}

void
mcp_cli_free_words(char **words, int count)
{
    for (int i = 0; i < count; i++)
        free(words[i]);
    free(words);
}

void
mcp_cli_print_json(cJSON *json)
{
    char *text = cJSON_Print(json);
    if (text)
        puts(text);
    free(text);
    cJSON_Delete(json);
}

int
mcp_cli_read_dump(const char *path, const char *spp, const char *convention,
                  const char *variance, mcp_dump **out)
{
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    if ((spp && mcp_cli_double("--spp", spp, &spec.spp)) ||
        (convention && mcp_convention_from_name(convention, &spec.convention)) ||
        (variance && mcp_variance_kind_from_name(variance, &spec.variance)))
        return -1;
    if (spp && spec.spp <= 0)
        return mcp_error("--spp must be > 0 (got %s)", spp);
    return mcp_dump_load(&spec, out);
}
