/* internal.h: helpers shared inside common/ (not installed). */
#ifndef MCP_COMMON_INTERNAL_H
#define MCP_COMMON_INTERNAL_H

#include <stddef.h>

#include "hidden_internal.h"
#include "oiio_internal.h"

#include <mcpost/image.h>

/* Reorders img's channel names only (order as mcp_image_colour_order gives it), for a
 * reader that has made the image but not yet placed its pixels by name (image.c). */
int mcp__image_permute_names(mcp_image *img, const int *order);

/* Fault injection, for tests only (alloc.c): allocation number n (0-based) through
 * mcp_malloc, mcp_calloc, mcp_realloc and mcp_strdup from now on fails as if memory
 * were out, the others succeed; n < 0 turns it off. mcp__alloc_count() is how many
 * allocations were counted since (a run that finishes with count <= n met no
 * failure). */
void mcp__alloc_fail_after(long n);
long mcp__alloc_count(void);

/* Window sums over 3 channels (stats.c): a summed-area table of (width + 1) x
 * (height + 1) x 3 doubles (malloc'd), and the sum over the (2r + 1)² window around
 * (x, y) clipped at the borders, with its pixel count. */
double *mcp__window_table(const mcp_image *img);
void mcp__window_sum(const double *table, int w, int h, int x, int y, int r,
                     double out[3], int *count);

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

/* Output folders that appear whole (outdir.c; docs/conventions.md, "Output folders"):
 * begin makes the hidden temporary folder o->tmp beside dir (first removing what killed
 * runs left there) and refuses a dir that exists and is neither empty nor an mcpost
 * output; the command writes into o->tmp; commit renames it onto dir (swapping with an
 * old one, then removing that); abort removes it (safe after commit, and twice).
 * fix_paths rewrites strings that start with o->tmp to start with dir. */
#include <cjson/cJSON.h>
typedef struct mcp__outdir {
    char final[4096], tmp[4200];
    int active;
} mcp__outdir;
int mcp__outdir_begin(mcp__outdir *o, const char *dir);
/* The same for a dir that is mcpost's by its place, whatever it holds (a frame's folder
 * in a shot's output, beside frames.json: an unfinished one of an older version, or one
 * whose report.json was removed to run it again): it is replaced, never refused. */
int mcp__outdir_begin_owned(mcp__outdir *o, const char *dir);
/* -1 with "INPUT: is inside the output folder DIR, which this run replaces whole" when
 * the file input (or the folder of a pattern that names no file) lies in o->final (an
 * earlier output): the commit would remove it. */
int mcp__outdir_check_input(const mcp__outdir *o, const char *input);
/* The same for each of inputs[0..n) that is not NULL; the first inside fails. */
int mcp__outdir_check_inputs(const mcp__outdir *o, const char *const *inputs, int n);
/* Removes parent/.BASE.tmp-PID and .BASE.old-PID whose process is gone (what a SIGKILL
 * left; begin does it for its own dir), saying so for each. */
void mcp__outdir_clear_stale(const char *parent, const char *base);
int mcp__outdir_commit(mcp__outdir *o);
void mcp__outdir_abort(mcp__outdir *o);
int mcp__outdir_fix_paths(const mcp__outdir *o, cJSON *json);
/* A function the handler of SIGINT, SIGTERM and SIGHUP calls after removing the
 * temporary files in flight (imageio.c); it must be async-signal-safe. */
void mcp__signal_cleanup_hook(void (*hook)(void));

/* Until called again with NULL, every section made takes this title (borrowed) in
 * place of the one its stage gives: a job stage's `title:` (job.c, report.c). */
#include <mcpost/report.h>
void mcp__report_set_heading(mcp_report *r, const char *title);

#include <mcpost/dump.h>

/* Whether a dump's variance is a renderer's per-sample one divided by n (Mitsuba's XYZ
 * moments are too): what a stratified sampler makes an overstatement. */
static inline int
mcp__variance_is_per_sample(mcp_variance_source s)
{
    return s == MCP_VARSRC_PER_SAMPLE || s == MCP_VARSRC_XYZ_MOMENTS;
}

/* A series member as its file holds it, whatever the series' variance_from (dump.c). */
int mcp__series_load_file(const mcp_series *s, int i, mcp_dump **out);
/* mcp_series_increment_variance of member i with that member already read (borrowed),
 * the members before it read from their files (replicates.c). */
int mcp__series_increments_with(const mcp_series *s, int i, const mcp_dump *member,
                                const mcp_increment_options *opt, mcp_dump **out,
                                double *ratio);
/* What to do about a dump without variance, for the end of its one-line error: the
 * recipe for a Cycles render (convention blender), else `otherwise` (dump.c). */
const char *mcp__no_variance_hint(const mcp_dump *d, const char *otherwise);

/* Format back ends behind mcp_image_read / mcp_image_write (imageio.c). The writers
 * write exactly `path` (imageio.c passes a temporary name and renames). */
#include <mcpost/imageio.h>
/* 0 when path exists and is no folder; else -1 and "PATH: cannot open: ..." or "PATH: is
 * a directory, not an image" (imageio.c) */
int mcp__check_readable(const char *path);
int mcp__exr_read(const char *path, mcp_image **out);
/* 1 when the first bytes (size of them) are OpenEXR's magic number. */
int mcp__exr_magic(const void *data, size_t size);
/* The same from a buffer (name labels it in messages); the dump loader uses it too. */
int mcp__exr_read_memory(const void *data, size_t size, const char *name,
                         mcp_image **out);
int mcp__exr_write(const mcp_image *img, const char *path, const mcp_write_options *opt);
/* Reading an EXR's channels straight to where a caller wants them (the dump loader: no
 * whole image to copy the parts out of). Once the header is read and checked, the
 * router gets it as `header` (the channel names in the file's order, the attributes
 * and the source, with 1x1 pixels that are not read) and the data window's size, and
 * fills routes[c] for each channel c it wants: the value at pixel (x, y) goes to
 * base[y * row_stride + x * pixel_stride] (in floats); a channel left with base NULL
 * is skipped. It returns 0, or -1 with the error set, which the read returns. */
typedef struct mcp__exr_route {
    float *base;
    ptrdiff_t pixel_stride, row_stride;
} mcp__exr_route;
typedef int (*mcp__exr_router)(const mcp_image *header, int width, int height, void *ctx,
                               mcp__exr_route *routes);
int mcp__exr_read_routed(const char *path, mcp__exr_router router, void *ctx);
int mcp__exr_read_memory_routed(const void *data, size_t size, const char *name,
                                mcp__exr_router router, void *ctx);
int mcp__pfm_read(const char *path, mcp_image **out);
int mcp__pfm_read_memory(const void *data, size_t size, const char *name,
                         mcp_image **out);
int mcp__pfm_write(const mcp_image *img, const char *path);
int mcp__png_read(const char *path, const mcp_read_options *opt, mcp_image **out);
int mcp__png_write(const mcp_image *img, const char *path, const mcp_write_options *opt);
/* 8-bit samples, c = 1, 3 or 4 channels interleaved, written as they are */
int mcp__png_write_bytes(const unsigned char *bytes, int w, int h, int c,
                         const char *path);

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
int mcp__strbuf_printf(mcp__strbuf *b, const char *fmt, ...) MCP_PRINTF(2, 3);
int mcp__strbuf_vprintf(mcp__strbuf *b, const char *fmt, va_list ap);
char *mcp__strbuf_take(mcp__strbuf *b);
void mcp__strbuf_free(mcp__strbuf *b);
int mcp__strbuf_read_file(mcp__strbuf *b, FILE *f);
#endif
