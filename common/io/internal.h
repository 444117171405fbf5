/* internal.h: the helpers of common/io/ -- the format back ends behind imageio.h,
 * output folders that appear whole -- that the library's other files and the tests
 * call (hidden visibility; not installed). */
#ifndef MCP_IO_INTERNAL_H
#define MCP_IO_INTERNAL_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cjson/cJSON.h>
#include <mcpost/imageio.h>

/* Output folders that appear whole (outdir.c; docs/conventions.md, "Output folders"):
 * begin makes the hidden temporary folder o->tmp beside dir (first removing what killed
 * runs left there) and refuses a dir that exists and is neither empty nor an mcpost
 * output; the command writes into o->tmp; commit renames it onto dir (swapping with an
 * old one, then removing that); abort removes it (safe after commit, and twice).
 * fix_paths rewrites strings that start with o->tmp to start with dir. */
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
/* A scratch folder that no command outputs (an external denoiser's files): made by
 * mkdtemp as PARENT/PREFIXxxxxxx into dir, and removed by end, or by the handler of
 * SIGINT, SIGTERM and SIGHUP if the process is stopped first (outdir.c). */
int mcp__scratch_dir_begin(const char *parent, const char *prefix, char *dir, size_t cap);
void mcp__scratch_dir_end(const char *dir);
/* A function the handler of SIGINT, SIGTERM and SIGHUP calls after removing the
 * temporary files in flight (imageio.c); it must be async-signal-safe. */
void mcp__signal_cleanup_hook(void (*hook)(void));

/* Format back ends behind mcp_image_read / mcp_image_write (imageio.c). The writers
 * write exactly `path` (imageio.c passes a temporary name and renames). */
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
/* Reading an EXR rows [y0, y1) at a time (a streamed denoise, docs/denoisers.md): open
 * reads the header and checks, as a whole read does, that the chunks lie in the file;
 * header gives it (channel names in the file's order, attributes, source; 1 x 1) and
 * the data window's size; span widens [y0, y1) to the rows of the chunks that hold
 * them, [*a0, *a1), which read decodes: the value at pixel (x, y) goes to
 * routes[c].base[(y - a0) * row_stride + x * pixel_stride] for y in [*a0, *a1). */
typedef struct mcp__exr_rows mcp__exr_rows;
int mcp__exr_rows_open(const char *path, mcp__exr_rows **out);
const mcp_image *mcp__exr_rows_header(const mcp__exr_rows *r, int *width, int *height);
void mcp__exr_rows_span(const mcp__exr_rows *r, int y0, int y1, int *a0, int *a1);
int mcp__exr_rows_read(mcp__exr_rows *r, int y0, int y1, int a0,
                       const mcp__exr_route *routes);
void mcp__exr_rows_close(mcp__exr_rows *r);
/* Rows [y0, y1) as a new image of every channel, named, ordered and with the attributes
 * and source of a whole read (mcp_image_read): for a command that streams a file. */
int mcp__exr_rows_read_image(mcp__exr_rows *r, int y0, int y1, mcp_image **out);
/* An image decoded from the chunks' rows [a0, ...) cut to rows [y0, y1): the rows
 * above y0 dropped, the height set. */
void mcp__exr_rows_trim(mcp_image *img, int a0, int y0, int y1);
/* Writing an EXR rows at a time, top to bottom, with what mcp__exr_write writes (the
 * pixels; zip chunks that do not shrink are stored raw, decided for each call's rows):
 * open creates path exactly (the caller writes a temporary name and renames it, as
 * mcp_image_write does) with the header; rows takes the next rows->height rows, whose
 * channels are found by name, and must end on a chunk's last row or the image's; close
 * finishes the file, -1 when it fails or rows are missing. */
typedef struct mcp__exr_writer mcp__exr_writer;
int mcp__exr_writer_open(const char *path, int width, int height, int nc,
                         char *const *names, const mcp_attrs *attrs,
                         const mcp_write_options *opt, mcp__exr_writer **out);
int mcp__exr_writer_rows(mcp__exr_writer *wr, const mcp_image *rows, int y0);
int mcp__exr_writer_close(mcp__exr_writer *wr);

/* The current error names the real output path, not the temporary file tmp_path
 * written for it (imageio.c). */
void mcp__name_output_in_error(const char *tmp_path, const char *path);

/* An EXR written band by band under a temporary name (stream.c): begin picks the
 * name (failing early when the folder is not writable); rows writes the next band
 * (rows->height rows from y0, ending on a chunk's last row or the image's), the first
 * band's channels and attributes making the header, or `attrs` when the caller sets it
 * after begin; end with failed 0 closes the file and renames it (-1 when that fails),
 * with failed 1 closes and removes it and keeps the error the failure set. */
typedef struct mcp__exr_band_file {
    mcp_atomic_file af;
    mcp__exr_writer *wr;
    const char *path;
    int width, height;
    mcp_write_options opt;
    const mcp_attrs *attrs;
} mcp__exr_band_file;
int mcp__exr_band_file_begin(mcp__exr_band_file *f, const char *path, int width,
                             int height, const mcp_write_options *opt);
int mcp__exr_band_file_rows(mcp__exr_band_file *f, const mcp_image *rows, int y0);
int mcp__exr_band_file_end(mcp__exr_band_file *f, int failed);
/* The rows of a band of the commands that stream an EXR (merge, convert, info): 64, a
 * multiple of 32 from MCPOST_BAND_ROWS (for tests), or 0 for none (MCPOST_BAND_ROWS=
 * whole: the command reads its images whole). */
int mcp__stream_band_rows(void);
/* Calls band(ctx, y0, y1) for the bands of `rows` rows of an image of height rows,
 * top to bottom, until one fails (-1); a progress bar labelled label on a terminal for
 * a megapixel or more (stream.c). */
int mcp__stream_bands(const char *label, int width, int height, int rows,
                      int (*band)(void *ctx, int y0, int y1), void *ctx);
int mcp__pfm_read(const char *path, mcp_image **out);
int mcp__pfm_read_memory(const void *data, size_t size, const char *name,
                         mcp_image **out);
int mcp__pfm_write(const mcp_image *img, const char *path);
int mcp__png_read(const char *path, const mcp_read_options *opt, mcp_image **out);
int mcp__png_write(const mcp_image *img, const char *path, const mcp_write_options *opt);
/* Linear floats to 8-bit sRGB (srgb8.c): mcp__srgb8_byte(t, v) is
 * mcp__srgb8_formula(v), (unsigned char)(mcp_linear_to_srgb(v) * 255 + 0.5) of v
 * clamped to [0, 1] (NaN to 0), from the step edges instead of a powf. */
#define MCP__SRGB8_KEYS 16257 /* top 16 bits of the floats in [0, 1] */
typedef struct mcp__srgb8_table {
    float edge[257];                      /* edge[k]: the least v of byte k */
    unsigned char start[MCP__SRGB8_KEYS]; /* the byte at each key's first float */
} mcp__srgb8_table;
const mcp__srgb8_table *mcp__srgb8_table_get(void);
unsigned char mcp__srgb8_formula(float v);
static inline unsigned char
mcp__srgb8_byte(const mcp__srgb8_table *t, float v)
{
    v = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f;
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    const int k = t->start[bits >> 16];
    return (unsigned char)(k + (v >= t->edge[k + 1])); /* no range spans two edges */
}
/* The bytes of an 8-bit picture of img (srgb8.c): byte k of each pixel from channel
 * channels[k] of n (1, 3 or 4), clamped to [0, 1] (NaN to 0), sRGB-encoded when srgb
 * (a fourth channel, alpha, stays linear), else scaled; the PNG writer's and the
 * estimate's screen picture. */
void mcp__srgb8_bytes(const mcp_image *img, const int *channels, int n, int srgb,
                      unsigned char *out);
/* 8-bit samples, c = 1, 3 or 4 channels interleaved, written as they are */
int mcp__png_write_bytes(const unsigned char *bytes, int w, int h, int c,
                         const char *path);

#endif
