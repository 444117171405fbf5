/* wordlist.h: the words of an enum -- one list per enum, read and written the same way
 * by every front end (the command line, job files, Python) and by the operation table
 * (<mcpost/options.h>). Value i is words[i]; reading is case-insensitive and takes '-'
 * and '_' alike, so that `--fit last-two` and `fit: last_two` are one word.
 *
 *   static const char *const fit_words[] = {"on_the_fly", "retrospective", "last_two"};
 *   const mcp_wordlist mcp_curve_fit_words = {"curve fit", fit_words, 3};
 *   int i;
 *   if (mcp_wordlist_find(&mcp_curve_fit_words, "last-two", &i)) ...   // i == 2
 *
 * An unknown word fails with "unknown WHAT 'W' (known: a, b, c)". */
#ifndef MCP_WORDLIST_H
#define MCP_WORDLIST_H

#include <mcpost/error.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct mcp_wordlist {
    const char *what;         /* what a word names, for messages: "curve fit" */
    const char *const *words; /* words[value], the spellings written out */
    int count;
} mcp_wordlist;

/* The value of text in w (case-insensitive, '-' = '_') into *out; else -1 with
 * "unknown WHAT 'TEXT' (known: ...)" as the current error and *out unchanged. */
MCP_API int mcp_wordlist_find(const mcp_wordlist *w, const char *text, int *out);

/* The word of value v, or "?" when v is out of range. */
MCP_API const char *mcp_wordlist_name(const mcp_wordlist *w, int v);

/* "a, b, c" (sep ", ") or "a|b|c" (sep "|") into buf (truncated to cap). */
MCP_API void mcp_wordlist_join(const mcp_wordlist *w, const char *sep, char *buf,
                               unsigned long cap);

#ifdef __cplusplus
}
#endif
#endif
