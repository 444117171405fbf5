/* image.h: the one image type every mcpost module shares.
 *
 * float32, interleaved, with a name per channel and a list of header attributes.
 * Pixel (x, y), channel c lives at data[y * row_stride + x * pixel_stride + c].
 * An image made by mcp_image_new() is packed: pixel_stride == channels and
 * row_stride == width * channels. Views (crops, contiguous channel ranges) share the
 * parent's pixels through the strides and must not outlive it.
 *
 * The owner frees; mcp_image_free(NULL) is safe. Results come back through
 * `mcp_image **out`, which stays NULL on failure. */
#ifndef MCP_IMAGE_H
#define MCP_IMAGE_H

#include <stddef.h>
#include <stdint.h>
#include <mcpost/error.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    MCP_ATTR_INT,    /* int64 value in .i */
    MCP_ATTR_FLOAT,  /* float32 value in .f */
    MCP_ATTR_DOUBLE, /* float64 value in .f */
    MCP_ATTR_STRING  /* text in .s */
} mcp_attr_type;

typedef struct mcp_attr {
    char *name;
    mcp_attr_type type;
    int64_t i;
    double f;
    char *s;
} mcp_attr;

/* Header attributes, as EXR files carry them (other formats carry none). */
typedef struct mcp_attrs {
    int count;
    mcp_attr *items;
} mcp_attrs;

typedef struct mcp_image {
    int width, height, channels;
    ptrdiff_t pixel_stride; /* floats from one pixel to the next in a row */
    ptrdiff_t row_stride;   /* floats from one row to the next */
    float *data;
    char **names;    /* channels names, owned by this image (views copy them) */
    mcp_attrs attrs; /* owned by this image */
    char *source;    /* the file it came from, or a label, for messages; owned */
    int owns_data;   /* 0 for views */
} mcp_image;

/* The ceiling on one image, so that a corrupt or hostile header fails with a message
 * instead of a huge allocation: at most MCPOST_MAX_PIXELS pixels (width x height) and
 * MCPOST_MAX_BYTES bytes of float32 values, read from the environment at each call,
 * else these defaults (a 16384 x 16384 image; 16 channels of it). */
#define MCP_MAX_PIXELS_DEFAULT (1ull << 28)
#define MCP_MAX_BYTES_DEFAULT (1ull << 34)

/* A new zero-filled packed image (within the ceiling above). names may be NULL
 * (channels are then called "C0", "C1", ...). */
MCP_API int mcp_image_new(int width, int height, int channels, const char *const *names,
                          mcp_image **out);

MCP_API void mcp_image_free(mcp_image *img);

/* A view of pixels the caller owns (a numpy array, a renderer's buffer): channel c of
 * pixel (x, y) at data[y * row_stride + x * pixel_stride + c]. names may be NULL
 * ("C0", ...); source labels messages (NULL: "(image)"). Within the ceiling above;
 * the pixels must outlive the view, and mcp_image_free frees only the header. */
MCP_API int mcp_image_wrap(float *data, int width, int height, int channels,
                           ptrdiff_t pixel_stride, ptrdiff_t row_stride,
                           const char *const *names, const char *source, mcp_image **out);

/* A deep, packed copy (pixels, names, attributes, source). */
MCP_API int mcp_image_copy(const mcp_image *img, mcp_image **out);

/* A view of the rectangle (x0, y0, w, h), all channels, sharing pixels. */
MCP_API int mcp_image_crop_view(const mcp_image *img, int x0, int y0, int w, int h,
                                mcp_image **out);

/* A view of the contiguous channel range [first, first + count), sharing pixels. */
MCP_API int mcp_image_channel_view(const mcp_image *img, int first, int count,
                                   mcp_image **out);

/* The index of the channel called name, or -1 (no error is set). */
MCP_API int mcp_image_channel(const mcp_image *img, const char *name);

/* Looks up several channels at once; on a missing one sets
 * "<source>: no channel '<name>'" and returns -1. */
MCP_API int mcp_image_channels(const mcp_image *img, const char *const *names, int count,
                               int *index);

/* The three channels that make up a colour (or a vector): the first of the n name
 * triples that img has all of (e.g. {R,G,B}, {X,Y,Z}), else 0, 1, 2 when img has
 * exactly 3 channels. Returns -1 (no error is set) when neither holds. */
MCP_API int mcp_image_find_triple(const mcp_image *img, const char *const (*triples)[3],
                                  int n, int index[3]);

/* Colour by channel name (docs/conventions.md, "Channel order"): R, G, B are the
 * channels called "R", "G", "B" (exactly, else in any case), else Blender's
 * "<layer>.Combined.R/G/B" when one layer has each. Returns how many of the three
 * plain names were found (3 also for Blender's triple, when no plain name is); rgb[k]
 * is -1 for one not found. No error is set. mcp_rgb_channels (tonemap.h) adds the
 * fallbacks for unnamed 3- and 1-channel images and the message. */
MCP_API int mcp_image_rgb_by_name(const mcp_image *img, int rgb[3]);

/* The channel order with colour first: the R, G, B of mcp_image_rgb_by_name (when all
 * three are distinct channels), then every other channel in its order, except that a
 * layer's "<p>.R", "<p>.G", "<p>.B" (all three present) come together, as R, G, B, at
 * the place of the first of them. order[c] (img->channels entries) is the channel
 * that goes to place c. Returns 1 when that moves a channel, 0 when it is img's own
 * order, -1 when out of memory. */
MCP_API int mcp_image_colour_order(const mcp_image *img, int *order);

/* Puts img's channels (names and pixels, in place) in mcp_image_colour_order. EXR
 * lists channels alphabetically (B, G, R); every image mcp_image_read returns is in
 * this order, so that code taking channels by position sees R, G, B first. */
MCP_API int mcp_image_colour_first(mcp_image *img);

/* A new packed image holding the listed channels (by index), in that order. */
MCP_API int mcp_image_copy_channels(const mcp_image *img, const int *index, int count,
                                    mcp_image **out);

/* Renames channel c (copies name). */
MCP_API int mcp_image_set_channel_name(mcp_image *img, int c, const char *name);

/* Replaces the source label used in messages. */
MCP_API int mcp_image_set_source(mcp_image *img, const char *source);

/* 1 when pixel_stride == channels and row_stride == width * channels. */
MCP_API int mcp_image_is_packed(const mcp_image *img);

/* 1 when both have the same width and height; otherwise sets
 * "<a>: size WxH does not match <b> (WxH)" and returns 0. */
MCP_API int mcp_image_same_size(const mcp_image *a, const mcp_image *b);

static inline float *
mcp_image_px(const mcp_image *img, int x, int y)
{
    return img->data + (ptrdiff_t)y * img->row_stride + (ptrdiff_t)x * img->pixel_stride;
}

/* ---- attributes ---- */

MCP_API const mcp_attr *mcp_attrs_find(const mcp_attrs *attrs, const char *name);
MCP_API int mcp_attrs_set_int(mcp_attrs *attrs, const char *name, int64_t value);
MCP_API int mcp_attrs_set_float(mcp_attrs *attrs, const char *name, float value);
MCP_API int mcp_attrs_set_double(mcp_attrs *attrs, const char *name, double value);
MCP_API int mcp_attrs_set_string(mcp_attrs *attrs, const char *name, const char *value);
MCP_API int mcp_attrs_copy(const mcp_attrs *from, mcp_attrs *to);
MCP_API void mcp_attrs_clear(mcp_attrs *attrs);

#ifdef __cplusplus
}
#endif
#endif
