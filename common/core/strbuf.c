/* strbuf.c: a growing NUL-terminated string, the one buffer behind the text mcpost
 * builds piece by piece (HTML reports, SVG plots, CSV tables, shell command lines,
 * YAML flow maps, settings dumps, files read whole). A failed allocation is sticky:
 * later appends do nothing and return -1, so a builder checks once at the end. */
#include "internal.h"

#include <mcpost/error.h>

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

char *
mcp__strbuf_reserve(mcp__strbuf *b, size_t extra)
{
    if (b->failed) return NULL;
    size_t need = b->len + extra + 1;
    if (need > b->cap) {
        size_t cap = b->cap ? b->cap : 256;
        while (cap < need)
            cap *= 2;
        char *s = mcp_realloc(b->s, cap);
        if (!s) {
            b->failed = 1;
            return NULL;
        }
        b->s = s;
        b->cap = cap;
        b->s[b->len] = '\0';
    }
    return b->s + b->len;
}

int
mcp__strbuf_put(mcp__strbuf *b, const char *s, size_t n)
{
    char *at = mcp__strbuf_reserve(b, n);
    if (!at) return -1;
    memcpy(at, s, n);
    b->len += n;
    b->s[b->len] = '\0';
    return 0;
}

int
mcp__strbuf_str(mcp__strbuf *b, const char *s)
{
    return mcp__strbuf_put(b, s, strlen(s));
}

/* Text for XML and HTML: & < > " as entities (the SVG plots and the report page). */
int
mcp__strbuf_markup_text(mcp__strbuf *b, const char *t)
{
    for (; t && *t; t++) {
        const char *entity = *t == '&'   ? "&amp;"
                             : *t == '<' ? "&lt;"
                             : *t == '>' ? "&gt;"
                             : *t == '"' ? "&quot;"
                                         : NULL;
        if (entity ? mcp__strbuf_str(b, entity) : mcp__strbuf_put(b, t, 1)) return -1;
    }
    return 0;
}

int
mcp__strbuf_vprintf(mcp__strbuf *b, const char *fmt, va_list ap)
{
    if (b->failed) return -1;
    /* format into the room there is; when it does not fit, grow to the length that
     * vsnprintf reported and format again */
    for (int pass = 0; pass < 2; pass++) {
        va_list copy;
        va_copy(copy, ap);
        size_t room = b->s ? b->cap - b->len : 0;
        int n = vsnprintf(b->s ? b->s + b->len : NULL, room, fmt, copy);
        va_end(copy);
        if (n < 0) {
            b->failed = 1;
            return mcp_error("cannot format text");
        }
        if ((size_t)n < room) {
            b->len += (size_t)n;
            return 0;
        }
        if (!mcp__strbuf_reserve(b, (size_t)n)) return -1;
    }
    b->failed = 1;
    return mcp_error("cannot format text");
}

int
mcp__strbuf_printf(mcp__strbuf *b, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int rc = mcp__strbuf_vprintf(b, fmt, ap);
    va_end(ap);
    return rc;
}

char *
mcp__strbuf_take(mcp__strbuf *b)
{
    char *s = b->failed ? NULL : mcp__strbuf_reserve(b, 0) ? b->s : NULL;
    if (!s) free(b->s);
    *b = (mcp__strbuf){0};
    return s;
}

void
mcp__strbuf_free(mcp__strbuf *b)
{
    free(b->s);
    *b = (mcp__strbuf){0};
}

int
mcp__strbuf_read_file(mcp__strbuf *b, FILE *f)
{
    for (;;) {
        char *at = mcp__strbuf_reserve(b, 65536);
        if (!at) return -1;
        size_t n = fread(at, 1, b->cap - b->len - 1, f);
        b->len += n;
        b->s[b->len] = '\0';
        if (n == 0) return ferror(f) ? -1 : 0;
    }
}
