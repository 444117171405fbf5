/* internal.h: functions of common/dump/ that other library files and the tests call
 * but that libmcpost.so does not export (hidden visibility; not installed). */
#ifndef MCP_DUMP_INTERNAL_H
#define MCP_DUMP_INTERNAL_H

#include <mcpost/dump.h>
#include <mcpost/imageio.h> /* mcp_write_options */
#include <mcpost/wordlist.h>

/* ---- dump.c: the words of two dump enums, and the series' variance source ---- */

extern const mcp_wordlist mcp_variance_source_words, mcp_badval_policy_words;
const char *mcp_series_variance_name(mcp_series_variance v);
int mcp_series_variance_from_name(const char *name, mcp_series_variance *out);

/* ---- dump.c, replicates.c ---- */

/* Whether a dump's variance is a renderer's per-sample one divided by n (Mitsuba's XYZ
 * moments are too): what a stratified sampler makes an overstatement. */
static inline int
mcp__variance_is_per_sample(mcp_variance_source s)
{
    return s == MCP_VARSRC_PER_SAMPLE || s == MCP_VARSRC_XYZ_MOMENTS;
}

/* A series member as its file holds it, whatever the series' variance_from, without
 * the parts in `without` (MCP__DUMP_NO_*, below) (dump.c). */
int mcp__series_load_file(const mcp_series *s, int i, unsigned without, mcp_dump **out);
/* mcp_series_load without the parts a caller will not read (MCP__DUMP_NO_*): a blend
 * or series estimate whose denoiser reads no albedo or normal (dump.c). */
int mcp__series_load_without(const mcp_series *s, int i, unsigned without,
                             mcp_dump **out);
/* mcp_series_increment_variance with member i read without those parts (replicates.c). */
int mcp__series_increment_variance(const mcp_series *s, int i, unsigned without,
                                   const mcp_increment_options *opt, mcp_dump **out,
                                   double *ratio);
/* mcp_series_increment_variance of member i with that member already read (borrowed),
 * the members before it read from their files (replicates.c). */
int mcp__series_increments_with(const mcp_series *s, int i, const mcp_dump *member,
                                const mcp_increment_options *opt, mcp_dump **out,
                                double *ratio);
/* The members' colours as the increments read them (series_colours.c): colour is
 * member i read without albedo, normal and variance, kept for the next call up to a
 * budget (512 MB; _budget sets another, for tests); each colour is given back with
 * release, which frees what was not kept. */
typedef struct mcp__series_colours mcp__series_colours;
int mcp__series_colours_new(int count, mcp__series_colours **out);
void mcp__series_colours_free(mcp__series_colours *c);
void mcp__series_colours_budget(const mcp_series *s, size_t bytes);
int mcp__series_colour(const mcp_series *s, int i, const mcp_dump **out);
void mcp__series_colour_release(const mcp_series *s, const mcp_dump *d);
/* Rows [y0, y1) of d as a dump of views (dump.c): each part a view of its rows with
 * that part's header attributes, the rest (counts, convention, the dump's attributes
 * and source) d's, borrowed. Free the views with _free, never with mcp_dump_free. */
int mcp__dump_rows_view(const mcp_dump *d, int y0, int y1, mcp_dump *out);
void mcp__dump_rows_view_free(mcp_dump *view);
/* What to do about a dump without variance, for the end of its one-line error: the
 * recipe for a Cycles render (convention blender), else `otherwise` (dump.c). */
const char *mcp__no_variance_hint(const mcp_dump *d, const char *otherwise);

/* mcp_dump_load without the parts a caller will not read: with MCP__DUMP_NO_ALBEDO
 * (MCP__DUMP_NO_NORMAL) the albedo (normal) is neither decoded, nor read from its own
 * file, nor checked, and stays NULL. An estimate whose denoiser reads neither (gauss,
 * bilateral) touches 50 MB less of a 1080p dump (docs/benchmarks.md, "Fewer first
 * touches"). */
enum { MCP__DUMP_NO_ALBEDO = 1, MCP__DUMP_NO_NORMAL = 2 };
int mcp__dump_load_without(const mcp_dump_spec *spec, unsigned without, mcp_dump **out);

/* ---- dump.c: an EXR dump's colour, albedo and normal, rows at a time ---- */

/* For a streamed denoise (docs/denoisers.md, "Images larger than memory"). open reads
 * the header and finds the parts as mcp_dump_load would; *out stays NULL (and 0 is
 * returned) for a dump that must be read whole: not an EXR, parts in other files, a
 * colour from Mitsuba's XYZ, two parts on one channel. read gives new images of rows
 * [y0, y1): parts[0] the colour (R,G,B), parts[1] the albedo (R,G,B) and parts[2] the
 * normal (X,Y,Z), NULL for a part the dump lacks; the values are checked as
 * mcp_dump_load checks them (bad_values): the first pass over the rows, top to bottom,
 * tallies them, and its last read fails naming the first bad value, the same line as
 * mcp_dump_load's; policy zero replaces them in every read. The variance and sample
 * counts are not read. dump: the source, attributes and convention. whole_bytes: what
 * reading every channel whole takes. */
typedef struct mcp__dump_rows mcp__dump_rows;
int mcp__dump_rows_open(const mcp_dump_spec *spec, mcp__dump_rows **out);
void mcp__dump_rows_size(const mcp__dump_rows *r, int *width, int *height,
                         int *has_albedo, int *has_normal);
const mcp_dump *mcp__dump_rows_dump(const mcp__dump_rows *r);
double mcp__dump_rows_whole_bytes(const mcp__dump_rows *r);
int mcp__dump_rows_read(mcp__dump_rows *r, int y0, int y1, mcp_image **parts);
void mcp__dump_rows_close(mcp__dump_rows *r);

/* ---- dump.c: a whole EXR dump, a band of rows at a time ---- */

/* For a streamed merge (common/dump/merge_stream.c). open reads the header and lays out
 * the dump as mcp_dump_load would, saying in its words what is wrong with the header;
 * *out stays NULL (and 0 is returned) for a dump that must be read whole: not an EXR,
 * parts in other files, two parts on one channel. read gives the dump of rows [y0, y1)
 * (every part mcp_dump_load gives, converted as it converts them: a dump whose images
 * are y1 - y0 rows high); the bands must follow each other from row 0 down. Values are
 * checked as mcp_dump_load checks them (bad_values): tallied band after band and
 * reported with the last band, in the line a whole read gives; policy zero replaces
 * them in every band. */
typedef struct mcp__dump_bands mcp__dump_bands;
int mcp__dump_bands_open(const mcp_dump_spec *spec, mcp__dump_bands **out);
/* open for a reader that does without some parts, as mcp__dump_load_without does;
 * size_of gives the image's size from the header alone (0 x 0 for a dump that open
 * leaves to a whole read), for a caller that decides by it whether to open. */
int mcp__dump_bands_open_without(const mcp_dump_spec *spec, unsigned without,
                                 mcp__dump_bands **out);
int mcp__dump_bands_size_of(const mcp_dump_spec *spec, unsigned without, int *width,
                            int *height);
void mcp__dump_bands_size(const mcp__dump_bands *b, int *width, int *height);
const char *mcp__dump_bands_source(const mcp__dump_bands *b);
int mcp__dump_bands_read(mcp__dump_bands *b, int y0, int y1, mcp_dump **out);
void mcp__dump_bands_close(mcp__dump_bands *b);
/* A dump's rows [lo, hi) read from in band after band of read_rows rows and held in
 * images of room for cap rows (rows_held.c): rows asks for [lo, hi), dropping the rows
 * above lo and reading down to hi (lo and hi never move up; hi - lo plus a read must
 * fit cap); d is the dump of the rows held, its parts hi - lo rows high. Set in, cap,
 * read_rows and height (the image's) before the first call; clear frees the rows. */
typedef struct mcp__dump_held {
    mcp__dump_bands *in;
    int cap, read_rows, height;
    mcp_dump *d;
    int lo, hi;
} mcp__dump_held;
int mcp__dump_held_rows(mcp__dump_held *h, int lo, int hi);
void mcp__dump_held_clear(mcp__dump_held *h);
/* The same checks for a caller that reads the rows itself (`mcpost info`, which reads
 * every channel for its statistics): for_rows opens no file; from_rows gives the dump
 * of rows, an image of rows [y0, y0 + rows->height) of the file as
 * mcp__exr_rows_read_image gives them (mcp_dump_from_image's dump of those rows). */
int mcp__dump_bands_for_rows(const mcp_dump_spec *spec, int height,
                             mcp__dump_bands **out);
int mcp__dump_bands_from_rows(mcp__dump_bands *b, const mcp_image *rows, int y0,
                              mcp_dump **out);

/* mcp_dump_merge of the dumps specs[0, count) written to out_path by mcp_dump_write in
 * the mcpost convention with wo, a band of rows at a time (merge_stream.c): the same
 * pixels and header, in a band's memory per input. -1 on failure, said in a whole
 * merge's words and with no output left; 0 and *done 1 when written, *last then the
 * last band's merged dump, whose sample count, count map and variance source are the
 * result's; 0 and *done 0 when the merge must be made whole: inputs a band reader
 * cannot take (mcp__dump_bands_open), an output other than an untiled EXR, or
 * MCPOST_BAND_ROWS=whole (for tests; a multiple of 32 sets the band height). With
 * pooling each band is merged from its rows and the pool radius's rows on each side. */
int mcp__dump_merge_streamed(const mcp_dump_spec *specs, int count,
                             const mcp_merge_options *opt, const char *out_path,
                             const mcp_write_options *wo, mcp_dump **last, int *done);

/* The image mcp_dump_write writes to path (named in errors): the dump's parts as
 * conv's channels, with its attributes and what it says about its variance. */
int mcp__dump_image(const mcp_dump *d, mcp_convention conv, const char *path,
                    mcp_image **out);

#endif
