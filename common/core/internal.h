/* internal.h: the helpers of common/core/ that the library's other files and the tests
 * call but that libmcpost.so does not export (hidden visibility; not installed). */
#ifndef MCP_CORE_INTERNAL_H
#define MCP_CORE_INTERNAL_H

#include <stddef.h>
#include <stdio.h>

#include <mcpost/image.h>
#include <mcpost/progress.h>
#include <mcpost/stats.h>

/* 0 when a width x height x channels image is within MCP_MAX_DIM per side, 4096
 * channels and the ceiling above; else -1 with a message naming the size and the
 * variable that raises the limit. Readers call it before they look at the data
 * (image.c; public once). */
int mcp_image_check_size(int width, int height, int channels);

/* Reorders img's channel names only (order as mcp_image_colour_order gives it), for a
 * reader that has made the image but not yet placed its pixels by name (image.c). */
int mcp__image_permute_names(mcp_image *img, const int *order);

/* For a command that streams an image too large to hold whole (alloc.c): the command
 * line keeps freed memory in the heap for reuse (cli/heap.c), right for frames of one
 * size, but a band's blocks change size from band to band and, kept, they fragment
 * the heap (a streamed U-Net denoise of 2400x1600 held 3.2 GB instead of 1.3), and what
 * a streamed command frees after its bands (an estimate's maps) would stay resident.
 * Blocks of 32 MB and more are mapped and unmapped instead, for the rest of the
 * process. */
void mcp__unmap_freed_blocks(void);

/* Fault injection, for tests only (alloc.c): allocation number n (0-based) through
 * mcp_malloc, mcp_calloc, mcp_realloc and mcp_strdup from now on fails as if memory
 * were out, the others succeed; n < 0 turns it off. mcp__alloc_count() is how many
 * allocations were counted since (a run that finishes with count <= n met no
 * failure). */
void mcp__alloc_fail_after(long n);
long mcp__alloc_count(void);

/* mcp_channel_stats_compute in steps, for an image read a band of rows at a time
 * (stats.c): each row's statistics of channel c (mean holding the row's sum); a total
 * started, then the rows added to it in order, band after band; the mean made of the
 * sum at the end. The rows added in image order give the whole image's bits. */
void mcp__channel_stats_rows(const mcp_image *img, int c, mcp_channel_stats *rows);
void mcp__channel_stats_start(mcp_channel_stats *t);
void mcp__channel_stats_add(mcp_channel_stats *t, const mcp_channel_stats *rows, int n);
void mcp__channel_stats_finish(mcp_channel_stats *t);

/* Window sums over the first 3 channels of 1 to 3 images of one size (stats.c): the
 * sum over the (2r + 1)² window around each pixel, clipped at the borders, in double,
 * a band of rows at a time. mcp__window_band(wb, y0, y1), for bands in order from the
 * top, of at most wb->rows rows, gives each image's sums for rows [y0, y1)
 * (mcp__window_at) from the values as they were before the caller wrote any band, so
 * that it may overwrite rows [y0, y1) after each call; mcp__window_count is a window's
 * pixel count. */
#define MCP__WINDOW_BAND 64
typedef struct mcp__window {
    const mcp_image *img[3];
    int n, r, w, h, rows;
    double *sums[3];          /* rows x w x 3 */
    float *halo[3], *next[3]; /* r x w x 3: the rows above the band, as they were */
    double *cols;             /* per thread: a row's column sums, w x 3 */
    int y0;
} mcp__window;
int mcp__window_begin(mcp__window *wb, const mcp_image *const *imgs, int n, int r);
int mcp__window_band(mcp__window *wb, int y0, int y1);
static inline const double *
mcp__window_at(const mcp__window *wb, int i, int x, int y)
{
    return wb->sums[i] + ((size_t)(y - wb->y0) * wb->w + x) * 3;
}
int mcp__window_count(const mcp__window *wb, int x, int y);
void mcp__window_end(mcp__window *wb);

/* The values of ranks[0..k) (0-based, each < n) among v[0..n), as a sort would place
 * them, without sorting (select.c: a two-pass radix select). v must hold no NaN. */
int mcp__select_ranks(const float *v, size_t n, const size_t *ranks, int k, float *out);
/* out[j] = the nearest-rank p[j]-percentile of v[0..n) (the value of rank
 * ceil(p n) - 1, clamped), by selection. */
int mcp__select_percentiles(const float *v, size_t n, const double *p, int k,
                            double *out);
/* One channel of an image by selection: out[0] its smallest value, out[1] the value of
 * rank p (n - 1) (rounded down; p = 0.99: the top of a false-colour scale that a few
 * outliers would otherwise set), out[2] its largest. No NaN. */
int mcp__image_channel_spread(const mcp_image *img, int channel, double p, float out[3]);

/* Progress (progress.c). mcp__progress_stop ends a bar where it got, without the 100%
 * of mcp_progress_end: for a run that failed. Safe on a bar never begun (zeroed) or
 * already ended. mcp__progress_set_output points the bars and notes at a stream, with
 * tty saying whether to draw them as on a terminal (tests); NULL: stderr again. */
void mcp__progress_stop(mcp_progress *p);
/* The bar starts again at 0 under a new label, on the same line: a round of work
 * whose rounds are not known beforehand ("vertical-iterative, pass 3"). */
void mcp__progress_restart(mcp_progress *p, const char *label);
void mcp__progress_set_output(FILE *stream, int tty);

/* Where mcpost's own files are (paths.c): the folder of the file that holds this code
 * (the shared library, or the executable it is linked into; -1 when unknown), and a
 * data file of share/mcpost/ found relative to it, else in the build tree, else in the
 * configured install folder (-1 and buf "" when none has it). */
int mcp__code_dir(char *buf, size_t cap);
int mcp__find_data_file(const char *name, char *buf, size_t cap);
/* dlopens the plug-in `file` (mcpost_oiio.so, mcpost_cv.so) from $MCPOST_PLUGIN_DIR,
 * beside the library (<libdir>/mcpost/), the build tree or the install folder, in that
 * order; NULL with the reason in err when none loads. */
void *mcp__plugin_open(const char *file, char *err, size_t cap);
/* The command line's: the plug-ins then load with OpenBLAS's thread pool off (paths.c).
 */
void mcp__plugins_one_blas_thread(void);

/* Runs a command line with /bin/sh as system() does, with mcpost's programs folder
 * (the one holding the mcpost executable: beside the code, its bin/, the build tree or
 * the install folder) at the end of the child's PATH, so that mcpost-procedural and
 * friends are found by name while the user's PATH still wins (shell.c). Returns
 * system()'s status. */
int mcp__shell(const char *command);
/* When status (from mcp__shell) is not a clean exit 0, sets the error "WHAT 'COMMAND'
 * ..." -- could not start, killed by signal N, not found (exit 127, with where it was
 * looked for), or failed with its exit status -- and returns -1. */
int mcp__shell_check(int status, const char *what, const char *command);
/* A command line from a template (an adaptive loop's render:, an external denoiser's
 * command): each names[i] ("{output}") in tmpl becomes values[i], single-quoted for
 * /bin/sh when bit i of quoted is set (paths); other text is kept. *out is malloc'd. */
int mcp__shell_fill(const char *tmpl, int n, const char *const *names,
                    const char *const *values, unsigned quoted, char **out);

/* Growing strings (strbuf.c): a NUL-terminated text s[0..len) in cap bytes, zeroed to
 * start ({0}). A failed allocation sets failed, and every later call then does nothing
 * and returns -1 (NULL), so a builder checks once at the end. reserve makes room for
 * extra more bytes and the NUL and returns where they go (the caller writes them,
 * adds to len and terminates); take hands over s (an empty string when nothing was
 * added; NULL after a failure, the buffer freed) and leaves the buffer zeroed;
 * read_file appends the rest of f (-1 on a read error, what was read kept). */
#include <stdarg.h>
#include <stdio.h>
#include <mcpost/error.h>
typedef struct mcp__strbuf {
    char *s;
    size_t len, cap;
    int failed;
} mcp__strbuf;
char *mcp__strbuf_reserve(mcp__strbuf *b, size_t extra);
int mcp__strbuf_put(mcp__strbuf *b, const char *s, size_t n);
int mcp__strbuf_str(mcp__strbuf *b, const char *s);
int mcp__strbuf_markup_text(mcp__strbuf *b, const char *t); /* & < > " escaped */
int mcp__strbuf_printf(mcp__strbuf *b, const char *fmt, ...) MCP_PRINTF(2, 3);
int mcp__strbuf_vprintf(mcp__strbuf *b, const char *fmt, va_list ap);
char *mcp__strbuf_take(mcp__strbuf *b);
void mcp__strbuf_free(mcp__strbuf *b);
int mcp__strbuf_read_file(mcp__strbuf *b, FILE *f);
#endif
