/* imageio.h: reading and writing images.
 *
 * EXR goes through the OpenEXR Core C API and PFM is read and written directly; both
 * are always available. PNG, JPEG, HDR and TIFF go through OpenImageIO, in a plug-in
 * (mcpost_oiio.so) that is dlopen()ed only when such a file is used, because linking
 * OpenImageIO costs about half a second per process start.
 *
 * Writers write to "<path>.tmp-<pid>" and rename, so a failed or interrupted write
 * never leaves a partial file at <path>. */
#ifndef MCP_IMAGEIO_H
#define MCP_IMAGEIO_H

#include <mcpost/image.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    MCP_FORMAT_UNKNOWN,
    MCP_FORMAT_EXR,
    MCP_FORMAT_PFM,
    MCP_FORMAT_PNG,
    MCP_FORMAT_JPEG,
    MCP_FORMAT_HDR,
    MCP_FORMAT_TIFF
} mcp_format;

/* The format named by a path's extension (case-insensitive). */
MCP_API mcp_format mcp_format_from_path(const char *path);
MCP_API const char *mcp_format_name(mcp_format format);

typedef struct mcp_read_options {
    /* 8-bit (and 16-bit integer) inputs are sRGB-encoded: decode them to linear. [1] */
    int srgb_decode;
} mcp_read_options;

MCP_API mcp_read_options mcp_read_defaults(void);

/* Reads every channel of the first part/subimage; sets img->source = path and copies
 * header attributes. opt may be NULL. */
MCP_API int mcp_image_read(const char *path, const mcp_read_options *opt,
                           mcp_image **out);

/* Reads an EXR or PFM image held in memory (data[0 .. size)), the format told by its
 * first bytes; name labels it in messages and becomes img->source. Other formats fail
 * with a message (the OpenImageIO plug-in reads files only). The same size checks as
 * the file readers apply, and the buffer is only read. */
MCP_API int mcp_image_read_memory(const void *data, size_t size, const char *name,
                                  mcp_image **out);

typedef enum { MCP_EXR_FLOAT, MCP_EXR_HALF } mcp_exr_pixel;

typedef enum {
    MCP_EXR_NONE,
    MCP_EXR_RLE,
    MCP_EXR_ZIPS,
    MCP_EXR_ZIP,
    MCP_EXR_PIZ,
    MCP_EXR_PXR24,
    MCP_EXR_B44,
    MCP_EXR_B44A,
    MCP_EXR_DWAA,
    MCP_EXR_DWAB
} mcp_exr_compression;

typedef struct mcp_write_options {
    mcp_exr_pixel exr_pixel;         /* [float] */
    mcp_exr_compression compression; /* [zip] */
    int exr_tiled;     /* write tiles of exr_tile_size instead of scanlines [0] */
    int exr_tile_size; /* [64] */
    int exr_data_x, exr_data_y; /* data-window origin [0, 0] */
    /* zlib level of zip and zips, 1 (fastest) .. 9 (smallest); 0 is
       MCP_EXR_ZIP_LEVEL_DEFAULT [0] */
    int exr_zip_level;
    /* zip and zips: when a sample of the chunks (every 16th) shrinks by less than this
       fraction, every chunk is stored raw (lossless: readers take raw chunks in any
       file, and they write and read far faster); 0 is MCP_EXR_MIN_SAVING_DEFAULT, a
       negative value compresses every chunk [0] */
    double exr_min_saving;
    /* LDR outputs: encode linear values to sRGB before quantising [1] */
    int srgb_encode;
} mcp_write_options;

/* The zip level and raw-storage threshold EXR files are written with unless the
 * options say otherwise (docs/benchmarks.md, "EXR speed", has the measurements). Level 1:
 * with libdeflate (common/io/exr_zip.c) it is the fastest level on every file measured
 * (renders, dumps, an estimate's maps, a perceptual result: 3-28% less time than 4) and
 * within 0.7% of level 4's size, the blocky maps included (zlib's levels 1-3 had made
 * those twice as large as its 4, which is why 4 was the default until December 2026).
 * 1/8: renders' float noise saves about 11% under zip, for about 12 times the writing
 * and 5 times the reading time of raw. */
#define MCP_EXR_ZIP_LEVEL_DEFAULT 1
#define MCP_EXR_MIN_SAVING_DEFAULT (1.0 / 8)

MCP_API mcp_write_options mcp_write_defaults(void);
MCP_API extern const mcp_wordlist mcp_exr_compression_words;
/* "float", "half": mcp_exr_pixel's words */
MCP_API extern const mcp_wordlist mcp_exr_pixel_words;
MCP_API int mcp_exr_compression_from_name(const char *name, mcp_exr_compression *out);

/* Writes img (any strides) in the format the extension names. EXR keeps every
 * channel and the attributes; LDR formats take 1, 3 or 4 channels. opt may be NULL. */
MCP_API int mcp_image_write(const mcp_image *img, const char *path,
                            const mcp_write_options *opt);

/* Writes an 8-bit RGB buffer (e.g. from mcp_colormap_apply) as PNG. */
MCP_API int mcp_write_rgb8(const unsigned char *rgb8, int width, int height,
                           const char *path);

/* One file of a batch for mcp_write_files: an image (any format by extension, with
 * opt, which may be NULL) or, when image is NULL, an 8-bit RGB buffer (as
 * mcp_write_rgb8). */
typedef struct mcp_file_write {
    const char *path;
    const mcp_image *image;
    const mcp_write_options *opt;
    const unsigned char *rgb8;
    int width, height;
} mcp_file_write;

/* Writes n files at once, one per thread (each file on its own thread: a single
 * file's parallel chunks spend much of their time waiting for the one writer, so
 * whole files in parallel finish a command's outputs sooner). List the costliest
 * first. Every file is written or left alone as by mcp_image_write; on failure the
 * error line is the first failed file's (in list order), and the other files are
 * still written. */
MCP_API int mcp_write_files(const mcp_file_write *files, int n);

/* 1 once the OpenImageIO plug-in has been loaded in this process. */
MCP_API int mcp_oiio_loaded(void);

/* ---- atomic output files (used by every writer, usable by anyone) ---- */

typedef struct mcp_atomic_file {
    char *final_path;
    char *tmp_path;
} mcp_atomic_file;

/* Picks a temporary name next to path; fails early when the directory is not
 * writable, naming path. */
MCP_API int mcp_atomic_begin(mcp_atomic_file *f, const char *path);
/* Renames the temporary file onto the final path. */
MCP_API int mcp_atomic_commit(mcp_atomic_file *f);
/* Removes the temporary file (safe after commit, and twice). */
MCP_API void mcp_atomic_abort(mcp_atomic_file *f);

/* Writes a whole text/binary buffer atomically. */
MCP_API int mcp_write_file_atomic(const char *path, const void *data, size_t size);

/* Creates the folder path and any missing parents (mkdir -p); 0, or -1 with a one-line
 * error naming the folder that could not be made. */
MCP_API int mcp_make_dirs(const char *path);

/* sRGB transfer functions (IEC 61966-2-1, as FLIP uses them). */
MCP_API float mcp_srgb_to_linear(float c);
MCP_API float mcp_linear_to_srgb(float l);

#ifdef __cplusplus
}
#endif
#endif
