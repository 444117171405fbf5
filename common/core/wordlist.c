/* wordlist.c: reading and writing the words of an enum (wordlist.h). */
#include "wordlist.h"

#include <ctype.h>
#include <stdio.h>
#include <string.h>

/* a and b name the same word: case and '-' against '_' do not count */
static int
same_word(const char *a, const char *b)
{
    for (;; a++, b++) {
        int ca = *a == '-' ? '_' : tolower((unsigned char)*a);
        int cb = *b == '-' ? '_' : tolower((unsigned char)*b);
        if (ca != cb) return 0;
        if (!ca) return 1;
    }
}

void
mcp_wordlist_join(const mcp_wordlist *w, const char *sep, char *buf, unsigned long cap)
{
    size_t n = 0;
    if (cap) buf[0] = '\0';
    for (int i = 0; i < w->count && n < cap; i++)
        n += (size_t)snprintf(buf + n, cap - n, "%s%s", i ? sep : "", w->words[i]);
}

int
mcp_wordlist_find(const mcp_wordlist *w, const char *text, int *out)
{
    for (int i = 0; text && i < w->count; i++)
        if (same_word(text, w->words[i])) {
            *out = i;
            return 0;
        }
    char known[512];
    mcp_wordlist_join(w, ", ", known, sizeof known);
    return mcp_error("unknown %s '%s' (known: %s)", w->what, text ? text : "", known);
}

const char *
mcp_wordlist_name(const mcp_wordlist *w, int v)
{
    return v >= 0 && v < w->count ? w->words[v] : "?";
}
