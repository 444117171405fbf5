/* error.c: the thread-local error line (see error.h). */
#include <mcpost/error.h>

#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MCP_ERROR_MAX 1024

static _Thread_local char error_line[MCP_ERROR_MAX];

/* Messages name channels, tensors, keys and paths as the files spell them: a control
 * character there (a newline in a channel name) would break the one-line contract
 * that callers and scripts rely on, so every one is shown as '?'. Found by the fuzz
 * targets (tests/fuzz/regressions/dump, tza). */
static void
keep_one_line(char *s)
{
    for (; *s; s++)
        if ((unsigned char)*s < 0x20 || *s == 0x7f) *s = '?';
}

int
mcp_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(error_line, sizeof error_line, fmt, ap);
    va_end(ap);
    keep_one_line(error_line);
    return -1;
}

int
mcp_error_prefix(const char *fmt, ...)
{
    char prefix[MCP_ERROR_MAX / 2], old[MCP_ERROR_MAX];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(prefix, sizeof prefix, fmt, ap);
    va_end(ap);
    memcpy(old, error_line, sizeof old);
    size_t n = strlen(prefix);
    /* truncation of an over-long message is acceptable: it stays one line */
    memcpy(error_line, prefix, n);
    size_t rest = sizeof error_line - 1 - n;
    size_t m = strlen(old) < rest ? strlen(old) : rest;
    memcpy(error_line + n, old, m);
    error_line[n + m] = '\0';
    keep_one_line(error_line);
    return -1;
}

const char *
mcp_error_message(void)
{
    return error_line;
}

void
mcp_error_clear(void)
{
    error_line[0] = '\0';
}

int
mcp_size_mul(size_t a, size_t b, size_t *out)
{
    if (b != 0 && a > SIZE_MAX / b) return -1;
    *out = a * b;
    return 0;
}

int
mcp_size_mul3(size_t a, size_t b, size_t c, size_t *out)
{
    size_t ab;
    return mcp_size_mul(a, b, &ab) ? -1 : mcp_size_mul(ab, c, out);
}
