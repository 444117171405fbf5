/* options.c: reading, writing and listing an operation's options (options.h). Every
 * front end ends here with a value as text, so that all of them accept and refuse the
 * same values with the same messages. */
#include "options.h"

#include "../common/core/internal.h"

#include <errno.h>
#include <stdarg.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* budgets and counts are kept exact in a double (and in JSON) up to 2^52 */
#define WHOLE_MAX 4503599627370496.0

static void *
field(void *settings, size_t offset)
{
    return (char *)settings + offset;
}

static const void *
cfield(const void *settings, size_t offset)
{
    return (const char *)settings + offset;
}

int
mcp_option_takes(const mcp_option *o, unsigned where)
{
    return !o->where || (o->where & where);
}

void
mcp_option_flag(const char *name, char *buf, size_t cap)
{
    size_t n = (size_t)snprintf(buf, cap, "--%s", name);
    for (size_t i = 2; i < n && i < cap; i++)
        if (buf[i] == '_') buf[i] = '-';
}

/* "%.15g" when it reads back as v, else "%.17g": 0.01 stays "0.01" */
static void
format_double(double v, char *buf, size_t cap)
{
    snprintf(buf, cap, "%.15g", v);
    if (strtod(buf, NULL) != v) snprintf(buf, cap, "%.17g", v);
}

/* " in [lo, hi]", " > lo", ... as the bounds say; "" when unbounded */
static void
range_text(const mcp_option *o, char *buf, size_t cap)
{
    char lo[32], hi[32];
    format_double(o->lo, lo, sizeof lo);
    format_double(o->hi, hi, sizeof hi);
    int has_lo = (o->bounds & MCP_OPT_LO) != 0, has_hi = (o->bounds & MCP_OPT_HI) != 0;
    int lo_open = (o->bounds & (MCP_OPT_LO_OPEN & ~MCP_OPT_LO)) != 0;
    int hi_open = (o->bounds & (MCP_OPT_HI_OPEN & ~MCP_OPT_HI)) != 0;
    if (has_lo && has_hi && o->type == MCP_OPT_INT)
        snprintf(buf, cap, "in %c%s, %s%c", lo_open ? '(' : '[', lo, hi,
                 hi_open ? ')' : ']');
    else if (has_lo && has_hi)
        snprintf(buf, cap, "%s %s and %s %s", lo_open ? ">" : ">=", lo,
                 hi_open ? "<" : "<=", hi);
    else if (has_lo)
        snprintf(buf, cap, "%s %s", lo_open ? ">" : ">=", lo);
    else if (has_hi)
        snprintf(buf, cap, "%s %s", hi_open ? "<" : "<=", hi);
    else if (cap)
        buf[0] = '\0';
}

static int
in_range(const mcp_option *o, double v)
{
    int lo_open = (o->bounds & (MCP_OPT_LO_OPEN & ~MCP_OPT_LO)) != 0;
    int hi_open = (o->bounds & (MCP_OPT_HI_OPEN & ~MCP_OPT_HI)) != 0;
    if ((o->bounds & MCP_OPT_LO) && (lo_open ? !(v > o->lo) : !(v >= o->lo))) return 0;
    if ((o->bounds & MCP_OPT_HI) && (hi_open ? !(v < o->hi) : !(v <= o->hi))) return 0;
    return 1;
}

/* "OP: LABEL must be RANGE (got TEXT)", as the library's own checks say it
 * ("estimate: tau must be > 0"); with an auto word "... must be auto or a number ..." */
static int
out_of_range(const mcp_operation *op, const mcp_option *o, const char *label,
             const char *text)
{
    char r[96];
    range_text(o, r, sizeof r);
    return mcp_error("%s%s%s must be %s%s%s (got %s)", op ? op->name : "", op ? ": " : "",
                     label, o->auto_word ? o->auto_word : "",
                     o->auto_word ? " or a number " : "", r, text);
}

static int
parse_number(const mcp_operation *op, const mcp_option *o, const char *label,
             const char *text, double *out)
{
    if (o->auto_word && !strcasecmp(text, o->auto_word)) {
        *out = o->auto_value;
        return 0;
    }
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    if (end == text || *end || errno || !isfinite(v)) {
        if (o->auto_word)
            return mcp_error("%s must be %s or a number (got '%s')", label, o->auto_word,
                             text);
        return mcp_error("%s must be a number (got '%s')", label, text);
    }
    if (!in_range(o, v)) return out_of_range(op, o, label, text);
    *out = v;
    return 0;
}

static int
parse_int(const mcp_operation *op, const mcp_option *o, const char *label,
          const char *text, int *out)
{
    if (o->auto_word && !strcasecmp(text, o->auto_word)) {
        *out = (int)o->auto_value;
        return 0;
    }
    char *end;
    errno = 0;
    long v = strtol(text, &end, 10);
    if (end == text || *end || errno || v < -2147483647L || v > 2147483647L) {
        if (o->auto_word)
            return mcp_error("%s must be an integer or %s (got '%s')", label,
                             o->auto_word, text);
        return mcp_error("%s must be an integer (got '%s')", label, text);
    }
    if (!in_range(o, (double)v)) return out_of_range(op, o, label, text);
    *out = (int)v;
    return 0;
}

static int
parse_seed(const char *label, const char *text, uint64_t *out)
{
    char *end;
    errno = 0;
    unsigned long long v = strtoull(text, &end, 10);
    if (end == text || *end || errno || text[0] == '-' || text[0] == '+' ||
        text[0] == ' ')
        return mcp_error("%s must be a non-negative integer (got '%s')", label, text);
    *out = (uint64_t)v;
    return 0;
}

static int
parse_whole(const char *label, const char *text, int64_t *out)
{
    char *end;
    errno = 0;
    double v = strtod(text, &end);
    if (end == text || *end || errno || !(v >= 0) || v != floor(v) || v > WHOLE_MAX)
        return mcp_error("%s must be a whole number >= 0 (got '%s')", label, text);
    *out = (int64_t)v;
    return 0;
}

static int
parse_flag(const char *label, const char *text, int *out)
{
    static const char *const yes[] = {"true", "yes", "on", "1"}, *const no[] = {
                                                                     "false", "no", "off",
                                                                     "0"};
    for (int i = 0; i < 4; i++) {
        if (!strcasecmp(text, yes[i])) return *out = 1, 0;
        if (!strcasecmp(text, no[i])) return *out = 0, 0;
    }
    return mcp_error("%s must be true or false (got '%s')", label, text);
}

/* The next item of a comma-separated list at *p, without its surrounding blanks: its
 * start and length; *p moves past the comma, or to NULL after the last item. */
static const char *
list_item(const char **p, size_t *len)
{
    const char *start = *p, *comma = strchr(start, ',');
    size_t n = comma ? (size_t)(comma - start) : strlen(start);
    while (n && *start == ' ')
        start++, n--;
    while (n && start[n - 1] == ' ')
        n--;
    *p = comma ? comma + 1 : NULL;
    *len = n;
    return start;
}

static int
parse_list(const mcp_operation *op, const mcp_option *o, const char *label,
           const char *text, double *out, int *count)
{
    double v[64];
    int n = 0, max = o->max_count < 64 ? o->max_count : 64;
    for (const char *p = text; p;) {
        size_t len;
        const char *item = list_item(&p, &len);
        char word[64];
        if (len == 0 && !p && n == 0 && !*text) break; /* "": no values */
        if (len >= sizeof word)
            return mcp_error("%s must be a number (got '%.*s')", label, (int)len, item);
        memcpy(word, item, len);
        word[len] = '\0';
        if (n < 64) {
            if (parse_number(op, o, label, word, &v[n])) return -1;
        }
        n++;
    }
    if (n < 1 || n > max)
        return mcp_error("%s needs 1 to %d values (got %d)", label, max, n);
    memcpy(out, v, (size_t)n * sizeof *v);
    *count = n;
    return 0;
}

/* "ldr,hdr" into bits of o->words (1 << i for words[i]); "none" alone is 0 */
static int
parse_wordset(const mcp_option *o, const char *label, const char *text, int *out)
{
    int bits = 0, n = 0, none = 0;
    for (const char *p = text; p;) {
        size_t len;
        const char *item = list_item(&p, &len);
        char word[64];
        if (len >= sizeof word) len = sizeof word - 1;
        memcpy(word, item, len);
        word[len] = '\0';
        int v = 0;
        if (!strcasecmp(word, "none")) {
            none = 1;
        } else if (mcp_wordlist_find(o->words, word, &v)) {
            char known[256];
            mcp_wordlist_join(o->words, ", ", known, sizeof known);
            return mcp_error("%s: unknown '%s' (use %s or none)", label, word, known);
        } else {
            bits |= 1 << v;
        }
        n++;
    }
    if (none && n > 1) return mcp_error("%s: none goes alone (got '%s')", label, text);
    *out = bits;
    return 0;
}

/* one more text of a repeatable option */
static int
add_text(const mcp_option *o, const char *label, const char *text, const char **out,
         int *count)
{
    if (*count >= o->max_count)
        return mcp_error("%s: at most %d values (got more)", label, o->max_count);
    out[(*count)++] = text;
    return 0;
}

int
mcp_operation_set(const mcp_operation *op, const mcp_option *o, const char *label,
                  const char *text, void *settings)
{
    void *f = field(settings, o->offset);
    int rc = 0;
    if (!text) return mcp_error("%s: no value given", label);
    switch (o->type) {
    case MCP_OPT_NUMBER:
        rc = parse_number(op, o, label, text, f);
        break;
    case MCP_OPT_INT:
        rc = parse_int(op, o, label, text, f);
        break;
    case MCP_OPT_SEED:
        rc = parse_seed(label, text, f);
        break;
    case MCP_OPT_WHOLE:
        rc = parse_whole(label, text, f);
        break;
    case MCP_OPT_FLAG:
        rc = parse_flag(label, text, f);
        break;
    case MCP_OPT_ENUM: {
        int v = 0;
        rc = mcp_wordlist_find(o->words, text, &v);
        if (!rc) *(int *)f = v;
        break;
    }
    case MCP_OPT_LIST:
        rc = parse_list(op, o, label, text, f, field(settings, o->count_offset));
        break;
    case MCP_OPT_TEXT:
    case MCP_OPT_INPUT:
        *(const char **)f = text;
        break;
    case MCP_OPT_DENOISER:
        return mcp_error("%s: a denoiser is read by the front end, not as text", label);
    case MCP_OPT_TEXTS:
        rc = add_text(o, label, text, f, field(settings, o->count_offset));
        break;
    case MCP_OPT_WORDSET:
        rc = parse_wordset(o, label, text, f);
        break;
    }
    if (rc) return -1;
    if (op && op->given_offset) {
        long i = o - op->options;
        if (i >= 0 && i < 64)
            *(uint64_t *)field(settings, op->given_offset) |= UINT64_C(1) << i;
    }
    return 0;
}

int
mcp_operation_given(const mcp_operation *op, const mcp_option *o, const void *settings)
{
    long i = o - op->options;
    if (!op->given_offset || i < 0 || i >= 64) return 0;
    return (*(const uint64_t *)cfield(settings, op->given_offset) >> i) & 1;
}

int
mcp_operation_finish(const mcp_operation *op, void *settings)
{
    return op->finish ? op->finish(settings) : 0;
}

void
mcp_operation_defaults(const mcp_operation *op, void *settings)
{
    memset(settings, 0, op->size);
    if (op->defaults) op->defaults(settings);
}

const mcp_option *
mcp_operation_option(const mcp_operation *op, const char *name)
{
    for (const mcp_option *o = op->options; name && o->name; o++) {
        size_t i = 0;
        for (; name[i] && o->name[i]; i++)
            if ((name[i] == '-' ? '_' : name[i]) != o->name[i]) break;
        if (!name[i] && !o->name[i]) return o;
    }
    return NULL;
}

void
mcp_option_format(const mcp_option *o, const void *settings, char *buf, size_t cap)
{
    const void *f = cfield(settings, o->offset);
    if (!cap) return;
    buf[0] = '\0';
    switch (o->type) {
    case MCP_OPT_NUMBER:
        if (o->auto_word && (*(const double *)f == o->auto_value ||
                             (isnan(*(const double *)f) && isnan(o->auto_value))))
            snprintf(buf, cap, "%s", o->auto_word);
        else
            format_double(*(const double *)f, buf, cap);
        break;
    case MCP_OPT_INT:
        if (o->auto_word && *(const int *)f == o->auto_value)
            snprintf(buf, cap, "%s", o->auto_word);
        else
            snprintf(buf, cap, "%d", *(const int *)f);
        break;
    case MCP_OPT_SEED:
        snprintf(buf, cap, "%llu", (unsigned long long)*(const uint64_t *)f);
        break;
    case MCP_OPT_WHOLE:
        snprintf(buf, cap, "%lld", (long long)*(const int64_t *)f);
        break;
    case MCP_OPT_FLAG:
        snprintf(buf, cap, "%s", *(const int *)f ? "true" : "false");
        break;
    case MCP_OPT_ENUM:
        snprintf(buf, cap, "%s", mcp_wordlist_name(o->words, *(const int *)f));
        break;
    case MCP_OPT_LIST: {
        const double *v = f;
        int n = *(const int *)cfield(settings, o->count_offset);
        size_t len = 0;
        for (int i = 0; i < n && len + 1 < cap; i++) {
            char one[32];
            format_double(v[i], one, sizeof one);
            len += (size_t)snprintf(buf + len, cap - len, "%s%s", i ? "," : "", one);
        }
        break;
    }
    case MCP_OPT_TEXT:
    case MCP_OPT_INPUT: {
        const char *s = *(const char *const *)f;
        snprintf(buf, cap, "%s", s ? s : "~");
        break;
    }
    case MCP_OPT_DENOISER:
        snprintf(buf, cap, "~");
        break;
    case MCP_OPT_TEXTS: {
        const char *const *t = f;
        int n = *(const int *)cfield(settings, o->count_offset);
        size_t len = 0;
        for (int i = 0; i < n && len + 1 < cap; i++)
            len += (size_t)snprintf(buf + len, cap - len, "%s%s", i ? "; " : "", t[i]);
        if (!n) snprintf(buf, cap, "~");
        break;
    }
    case MCP_OPT_WORDSET: {
        int bits = *(const int *)f;
        size_t len = 0;
        for (int i = 0; i < o->words->count && len + 1 < cap; i++)
            if (bits & (1 << i))
                len += (size_t)snprintf(buf + len, cap - len, "%s%s", len ? "," : "",
                                        o->words->words[i]);
        if (!len) snprintf(buf, cap, "none");
        break;
    }
    }
}

/* ---- text for people: the dump and the docs' table ---- */

char *
mcp_operation_dump(const mcp_operation *op, const void *settings, unsigned where)
{
    mcp__strbuf b = {0}; /* common/core/strbuf.c */
    int rc = 0;
    for (const mcp_option *o = op->options; o->name && !rc; o++) {
        if (!mcp_option_takes(o, where) || o->type == MCP_OPT_INPUT ||
            o->type == MCP_OPT_DENOISER)
            continue;
        char v[1024];
        mcp_option_format(o, settings, v, sizeof v);
        rc = mcp__strbuf_printf(&b, "%s: %s\n", o->name, v);
    }
    if (rc) {
        mcp__strbuf_free(&b);
        return NULL;
    }
    return mcp__strbuf_take(&b);
}

/* "(command line only)", "(not in Python)" for where */
static const char *
where_text(unsigned where)
{
    static const char *const t[] = {"",
                                    "command line only",
                                    "job only",
                                    "not in Python",
                                    "Python only",
                                    "not in a job",
                                    "not on the command line",
                                    ""};
    return t[where & 7];
}

/* text with '|' as "\|", which a markdown table cell needs */
static int
add_cell(mcp__strbuf *b, const char *text)
{
    for (const char *p = text; *p; p++)
        if (*p == '|' ? mcp__strbuf_str(b, "\\|") : mcp__strbuf_put(b, p, 1)) return -1;
    return 0;
}

/* One row of the docs' table. */
static int
markdown_row(mcp__strbuf *b, const mcp_operation *op, const mcp_option *o,
             const char *doc, const char *def)
{
    char flag[96] = "—", meta[96] = "", range[96] = "";
    const char *value = o->meta                   ? o->meta
                        : o->type == MCP_OPT_FLAG ? "true|false"
                        : o->type == MCP_OPT_INT  ? "N"
                                                  : "X";
    if (op->denoiser)
        snprintf(flag, sizeof flag, "`--denoiser-opt %s=%s`", o->name, value);
    else if (mcp_option_takes(o, MCP_OPT_CLI)) {
        char f[80];
        mcp_option_flag(o->name, f, sizeof f);
        if (o->type == MCP_OPT_FLAG && def && !strcmp(def, "true"))
            snprintf(flag, sizeof flag, "`--no-%s`", f + 2);
        else if (o->type == MCP_OPT_FLAG)
            snprintf(flag, sizeof flag, "`%s`", f);
        else
            snprintf(flag, sizeof flag, "`%s %s`%s%s%s", f, value,
                     o->alias ? ", `--" : "", o->alias ? o->alias : "",
                     o->alias ? "`" : "");
        if (o->letter) {
            snprintf(meta, sizeof meta, "`-%c`, ", o->letter);
            size_t n = strlen(meta);
            snprintf(meta + n, sizeof meta - n, "%s", flag);
            snprintf(flag, sizeof flag, "%s", meta);
        }
    }
    if ((o->type == MCP_OPT_NUMBER || o->type == MCP_OPT_INT) && o->bounds) {
        char r[80];
        range_text(o, r, sizeof r);
        snprintf(range, sizeof range, " (%s)", r);
    }
    int rc = mcp__strbuf_printf(b, "| `%s` | ", o->name) || add_cell(b, flag) ||
             mcp__strbuf_str(b, " | ") || add_cell(b, def ? def : "—") ||
             mcp__strbuf_str(b, " | ") || add_cell(b, doc) || mcp__strbuf_str(b, range);
    if (!rc && (o->type == MCP_OPT_ENUM || o->type == MCP_OPT_WORDSET)) {
        char words[512];
        mcp_wordlist_join(o->words, "`, `", words, sizeof words);
        rc = mcp__strbuf_printf(
            b, o->type == MCP_OPT_ENUM ? "; one of `%s`" : "; any of `%s`, or `none`",
            words);
    }
    if (!rc && o->type == MCP_OPT_TEXTS)
        rc = mcp__strbuf_str(b, " (repeatable: a job gives a list)");
    /* which front ends it misses, of those the operation has at all */
    unsigned all = 0;
    for (const mcp_option *p = op->options; p->name; p++)
        all |= p->where ? p->where : MCP_OPT_ALL;
    if (!rc && o->where && (o->where & all) != all)
        rc = mcp__strbuf_printf(b, " (%s)", where_text(o->where | (MCP_OPT_ALL & ~all)));
    return rc || mcp__strbuf_str(b, " |\n");
}

char *
mcp_operation_markdown(const mcp_operation *op)
{
    mcp__strbuf b = {0};
    int rc = mcp__strbuf_str(
        &b, "| option | command line | default | meaning |\n|---|---|---|---|\n");
    for (const mcp_option *o = op->options; o->name && !rc; o++)
        rc = markdown_row(&b, op, o, o->doc, o->def);
    const mcp_operation *sh = mcp_shared_operation();
    for (const mcp_option *o = sh->options; o->name && !rc; o++) {
        unsigned bit = 0;
        for (unsigned k = 1; k <= MCP_SHARED_THREADS; k <<= 1)
            if (mcp_shared_option(k) == o) bit = k;
        if (!(op->shared & bit)) continue;
        int is_output = bit == MCP_SHARED_OUTPUT;
        rc =
            markdown_row(&b, op, o, is_output && op->output_doc ? op->output_doc : o->doc,
                         is_output ? op->output_def : o->def);
    }
    if (rc) {
        mcp__strbuf_free(&b);
        return NULL;
    }
    return mcp__strbuf_take(&b);
}
