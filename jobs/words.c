/* words.c: numbers and comma-separated lists as the flags and the job keys read them
 * (the subcommands of cli/ and the stages' shared settings, e.g. perceptual's). */
#define _POSIX_C_SOURCE 200809L /* strtok_r */

#include "internal.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

int
mcp__parse_double(const char *flag, const char *text, double *out)
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
mcp__parse_int(const char *flag, const char *text, int *out)
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
mcp__split_words(const char *text, char ***words, int *count)
{
    char *copy = mcp_strdup(text), *save = NULL;
    if (!copy) return -1;
    int n = 1;
    for (const char *p = text; *p; p++)
        n += *p == ',';
    char **w = mcp_calloc((size_t)n, sizeof *w);
    int k = 0;
    int lost = 0; /* a word whose copy ran out of memory */
    for (char *tok = strtok_r(copy, ",", &save); w && tok;
         tok = strtok_r(NULL, ",", &save))
        lost |= !(w[k++] = mcp_strdup(tok));
    free(copy);
    if (w && lost) {
        mcp__free_words(w, k);
        w = NULL;
    }
    if (!w) return -1;
    *words = w;
    *count = k;
    return 0;
}

void
mcp__free_words(char **words, int count)
{
    for (int i = 0; i < count; i++)
        free(words[i]);
    free(words);
}
