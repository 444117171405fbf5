/* frames.c: frame sets ("1-240:2") and frame tokens ("####", "%04d") in paths (see
 * frames.h and docs/frames.md). */
#define _XOPEN_SOURCE 700 /* nftw */
#include <mcpost/frames.h>

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <ftw.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---- frame sets ---- */

static int
cmp_int(const void *a, const void *b)
{
    int x = *(const int *)a, y = *(const int *)b;
    return (x > y) - (x < y);
}

/* A frame number at *p (digits only), advancing *p. */
static int
parse_frame(const char *text, const char **p, int *out)
{
    if (!isdigit((unsigned char)**p))
        return mcp_error("frames '%s': expected a frame number at '%s'", text, *p);
    long v = 0;
    for (; isdigit((unsigned char)**p); (*p)++)
        if ((v = v * 10 + (**p - '0')) > MCP_FRAME_MAX)
            return mcp_error("frames '%s': frame numbers go up to %d", text,
                             MCP_FRAME_MAX);
    *out = (int)v;
    return 0;
}

int
mcp_frames_parse(const char *text, int **frames, int *count)
{
    *frames = NULL, *count = 0;
    int *set = NULL, n = 0, cap = 0;
    const char *p = text;
    for (;;) {
        while (isspace((unsigned char)*p))
            p++;
        int first, last, step = 1;
        if (parse_frame(text, &p, &first)) goto fail;
        last = first;
        if (*p == '-') {
            p++;
            if (parse_frame(text, &p, &last)) goto fail;
            if (last < first) {
                mcp_error("frames '%s': range %d-%d runs backwards", text, first, last);
                goto fail;
            }
            if (*p == ':' || *p == 'x') {
                p++;
                if (parse_frame(text, &p, &step)) goto fail;
                if (step < 1) {
                    mcp_error("frames '%s': a step must be >= 1", text);
                    goto fail;
                }
            }
        }
        for (long f = first; f <= last; f += step) {
            if (n == cap) {
                if (n >= MCP_FRAMES_MAX_COUNT) {
                    mcp_error("frames '%s': more than %d frames", text,
                              MCP_FRAMES_MAX_COUNT);
                    goto fail;
                }
                cap = cap ? 2 * cap : 64;
                int *grown = mcp_realloc(set, (size_t)cap * sizeof *grown);
                if (!grown) goto fail;
                set = grown;
            }
            set[n++] = (int)f;
        }
        while (isspace((unsigned char)*p))
            p++;
        if (!*p) break;
        if (*p != ',') {
            mcp_error("frames '%s': unexpected '%c' (a set is like 1-240, 1-240:2 or "
                      "1,5,9-12)",
                      text, *p);
            goto fail;
        }
        p++;
    }
    qsort(set, (size_t)n, sizeof *set, cmp_int);
    int kept = 0;
    for (int i = 0; i < n; i++)
        if (!kept || set[kept - 1] != set[i]) set[kept++] = set[i];
    *frames = set, *count = kept;
    return 0;
fail:
    free(set);
    return -1;
}

int
mcp_frames_format(const int *frames, int count, char *buf, size_t cap)
{
    size_t len = 0;
    if (cap) buf[0] = '\0';
    for (int i = 0; i < count;) {
        /* the longest run with one step from here: a range when it holds 3 or more
         * frames (or 2 adjacent ones), single numbers otherwise */
        int j = i + 1, step = i + 1 < count ? frames[i + 1] - frames[i] : 1;
        while (j < count && frames[j] - frames[j - 1] == step)
            j++;
        int run = j - i, n;
        if (run >= 3 || (run == 2 && step == 1)) {
            n = step == 1 ? snprintf(buf + len, cap - len, "%s%d-%d", i ? "," : "",
                                     frames[i], frames[j - 1])
                          : snprintf(buf + len, cap - len, "%s%d-%d:%d", i ? "," : "",
                                     frames[i], frames[j - 1], step);
            i = j;
        } else {
            n = snprintf(buf + len, cap - len, "%s%d", i ? "," : "", frames[i]);
            i++;
        }
        if (n < 0 || (size_t)n >= cap - len)
            return mcp_error("frame set too long to write (%d frames)", count);
        len += (size_t)n;
    }
    return 0;
}

int
mcp_frames_contains(const int *frames, int count, int frame)
{
    return bsearch(&frame, frames, (size_t)count, sizeof *frames, cmp_int) != NULL;
}

/* ---- frame tokens ---- */

/* The widest field a token may ask for (as series patterns: more is only padding). */
#define TOKEN_MAX_WIDTH 16
#define MAX_CONVERSIONS 3

/* Where the tokens of a path are: its printf conversions and its '#' run. */
typedef struct tokens {
    int n_conv;
    const char *conv[MAX_CONVERSIONS];
    size_t conv_len[MAX_CONVERSIONS];
    const char *hash; /* the '#' run, or NULL */
    size_t hash_len;
    const char *frame; /* the frame token (one of the above), or NULL */
    size_t frame_len;
} tokens;

static int
scan_tokens(const char *path, int series, tokens *t)
{
    memset(t, 0, sizeof *t);
    for (const char *p = path; *p; p++) {
        if (*p == '#') {
            if (t->hash)
                return mcp_error("path '%s': two '#' frame tokens (a frame has one)",
                                 path);
            t->hash = p;
            while (p[1] == '#')
                p++;
            t->hash_len = (size_t)(p - t->hash) + 1;
            if (t->hash_len > TOKEN_MAX_WIDTH)
                return mcp_error("path '%s': frame tokens wider than %d '#' are refused",
                                 path, TOKEN_MAX_WIDTH);
            continue;
        }
        if (*p != '%') continue;
        if (p[1] == '%') {
            p++;
            continue;
        }
        const char *start = p++;
        while (*p && strchr("0-+ #", *p))
            p++;
        int width = 0;
        for (; isdigit((unsigned char)*p); p++)
            if ((width = width * 10 + (*p - '0')) > TOKEN_MAX_WIDTH)
                return mcp_error("path '%s': field widths over %d are refused", path,
                                 TOKEN_MAX_WIDTH);
        if (!*p || !strchr("diu", *p))
            return mcp_error(
                "path '%s': only integer conversions such as %%04d are taken "
                "(write %%%% for a literal %%)",
                path);
        if (t->n_conv == MAX_CONVERSIONS)
            return mcp_error("path '%s': too many %% conversions", path);
        t->conv[t->n_conv] = start;
        t->conv_len[t->n_conv++] = (size_t)(p - start) + 1;
    }
    /* which token is the frame (frames.h) */
    int allowed = series ? 1 : 0; /* conversions besides the frame's */
    if (t->hash) {
        t->frame = t->hash, t->frame_len = t->hash_len;
    } else if (t->n_conv > allowed) {
        t->frame = t->conv[0], t->frame_len = t->conv_len[0];
        allowed++;
    }
    if (t->n_conv > allowed)
        return series
                   ? mcp_error("series pattern '%s': %d %% conversions; a frame job's "
                               "series has at most two, the frame's then the spp's (or "
                               "a '#' frame token and the spp's)",
                               path, t->n_conv)
                   : mcp_error("path '%s': %d frame tokens; give one (####, or %%04d)",
                               path, t->n_conv + (t->hash != NULL));
    return 0;
}

int
mcp_frame_token_check(const char *path, int series)
{
    tokens t;
    if (scan_tokens(path, series, &t)) return -1;
    return t.frame != NULL;
}

int
mcp_frame_expand(const char *path, int series, int frame, char *buf, size_t cap)
{
    tokens t;
    if (scan_tokens(path, series, &t)) return -1;
    if (frame < 0) return mcp_error("path '%s': frame %d (frames are >= 0)", path, frame);
    size_t len = 0;
    for (const char *p = path; *p;) {
        char piece[64];
        const char *src = p;
        size_t n = 1;
        if (p == t.frame && t.frame == t.hash) {
            snprintf(piece, sizeof piece, "%0*d", (int)t.frame_len, frame);
            src = piece, n = strlen(piece);
            p += t.frame_len;
        } else if (p == t.frame) {
            char spec[32];
            snprintf(spec, sizeof spec, "%.*s", (int)t.frame_len, p);
            /* the spec was checked: one integer conversion, width <= 16 */
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wformat-nonliteral"
#endif
            snprintf(piece, sizeof piece, spec, frame);
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
            src = piece, n = strlen(piece);
            p += t.frame_len;
        } else if (p[0] == '%' && p[1] == '%') {
            /* kept for the series' own formatting; a plain path's literal '%' */
            n = series ? 2 : 1;
            p += 2;
        } else {
            p++;
        }
        if (len + n >= cap)
            return mcp_error("path '%s': too long for frame %d", path, frame);
        memcpy(buf + len, src, n);
        len += n;
    }
    buf[len] = '\0';
    return 0;
}

int
mcp_frame_dir(const char *output_dir, int frame, char *buf, size_t cap)
{
    int n = snprintf(buf, cap, "%s/%04d", output_dir, frame);
    if (n < 0 || (size_t)n >= cap)
        return mcp_error("%s: output path too long", output_dir);
    return 0;
}

int
mcp_frame_complete(const char *output_dir, int frame)
{
    char dir[4096], path[4200];
    struct stat st;
    if (mcp_frame_dir(output_dir, frame, dir, sizeof dir)) return 0;
    snprintf(path, sizeof path, "%s/report.json", dir);
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* nftw has no user pointer: the count of one walk (frames run one per process). */
static int cleared;

static int
clear_one(const char *path, const struct stat *st, int type, struct FTW *ftw)
{
    (void)st;
    if (type != FTW_F) return 0;
    /* mcp__atomic_open's names: "<stem>.tmp-<pid>-<n><ext>" (common/io/imageio.c) */
    const char *tag = strstr(path + ftw->base, ".tmp-");
    if (!tag) return 0;
    char *end = NULL;
    long pid = strtol(tag + 5, &end, 10);
    if (pid <= 0 || !end || *end != '-') return 0;
    if (kill((pid_t)pid, 0) == 0 || errno != ESRCH) return 0; /* alive, or not ours */
    if (unlink(path) == 0) cleared++;
    return 0;
}

int
mcp_frame_clear_temporaries(const char *dir)
{
    struct stat st;
    if (stat(dir, &st) != 0) return 0;
    cleared = 0;
    if (nftw(dir, clear_one, 16, FTW_PHYS) != 0)
        return mcp_error("%s: cannot walk the folder to clear stale temporaries", dir);
    return cleared;
}
