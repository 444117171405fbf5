/* image.c: the shared float32 interleaved image with named channels (see image.h). */
#define _POSIX_C_SOURCE 200809L /* strcasecmp */
#include <mcpost/image.h>

#include <ctype.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

static int
names_new(int channels, const char *const *names, char ***out)
{
    char **n = mcp_calloc((size_t)channels, sizeof *n);
    if (!n) return -1;
    for (int c = 0; c < channels; c++) {
        char fallback[32];
        snprintf(fallback, sizeof fallback, "C%d", c);
        n[c] = mcp_strdup(names && names[c] ? names[c] : fallback);
        if (!n[c]) {
            while (c--)
                free(n[c]);
            free(n);
            return -1;
        }
    }
    *out = n;
    return 0;
}

/* An image header with names and source but no pixels. */
static mcp_image *
header_new(int width, int height, int channels, const char *const *names,
           const char *source)
{
    mcp_image *img = mcp_calloc(1, sizeof *img);
    if (!img) return NULL;
    img->width = width;
    img->height = height;
    img->channels = channels;
    img->pixel_stride = channels;
    img->row_stride = (ptrdiff_t)width * channels;
    if (names_new(channels, names, &img->names) ||
        !(img->source = mcp_strdup(source ? source : "(image)"))) {
        mcp_image_free(img);
        return NULL;
    }
    return img;
}

/* The limit in environment variable `name`, else `fallback`. */
static int
env_limit(const char *name, unsigned long long fallback, unsigned long long *out)
{
    const char *s = getenv(name);
    *out = fallback;
    if (!s || !*s) return 0;
    char *end;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (!isdigit((unsigned char)*s) || *end || errno || v == 0)
        return mcp_error("%s must be a positive whole number (got '%s')", name, s);
    *out = v;
    return 0;
}

int
mcp_image_check_size(int width, int height, int channels)
{
    if (width < 1 || height < 1 || channels < 1 || width > MCP_MAX_DIM ||
        height > MCP_MAX_DIM || channels > 4096)
        return mcp_error("bad image size %dx%dx%d", width, height, channels);
    /* at most 2^16 x 2^16 x 2^12 x 4 = 2^46: no overflow in 64 bits */
    unsigned long long pixels = (unsigned long long)width * (unsigned long long)height;
    unsigned long long bytes = pixels * (unsigned long long)channels * sizeof(float);
    unsigned long long max_pixels, max_bytes;
    if (env_limit("MCPOST_MAX_PIXELS", MCP_MAX_PIXELS_DEFAULT, &max_pixels) ||
        env_limit("MCPOST_MAX_BYTES", MCP_MAX_BYTES_DEFAULT, &max_bytes))
        return -1;
    if (pixels > max_pixels)
        return mcp_error("image of %dx%d pixels is over the limit of %llu pixels "
                         "(MCPOST_MAX_PIXELS raises it)",
                         width, height, max_pixels);
    if (bytes > max_bytes || bytes > SIZE_MAX)
        return mcp_error(
            "image of %dx%dx%d values (%llu bytes) is over the limit of %llu "
            "bytes (MCPOST_MAX_BYTES raises it)",
            width, height, channels, bytes, max_bytes);
    return 0;
}

int
mcp_image_new(int width, int height, int channels, const char *const *names,
              mcp_image **out)
{
    *out = NULL;
    if (mcp_image_check_size(width, height, channels)) return -1;
    size_t n = (size_t)width * (size_t)height * (size_t)channels * sizeof(float);
    mcp_image *img = header_new(width, height, channels, names, NULL);
    if (!img) return -1;
    img->data = mcp_calloc(n / sizeof(float), sizeof(float));
    if (!img->data) {
        mcp_image_free(img);
        return mcp_error("out of memory for a %dx%dx%d image", width, height, channels);
    }
    img->owns_data = 1;
    *out = img;
    return 0;
}

int
mcp_image_wrap(float *data, int width, int height, int channels, ptrdiff_t pixel_stride,
               ptrdiff_t row_stride, const char *const *names, const char *source,
               mcp_image **out)
{
    *out = NULL;
    if (mcp_image_check_size(width, height, channels)) return -1;
    if (!data || pixel_stride < channels || row_stride < (ptrdiff_t)width * pixel_stride)
        return mcp_error("%s: bad pixel layout (pixel stride %td, row stride %td for "
                         "%dx%dx%d)",
                         source ? source : "(image)", pixel_stride, row_stride, width,
                         height, channels);
    mcp_image *img = header_new(width, height, channels, names, source);
    if (!img) return -1;
    img->pixel_stride = pixel_stride;
    img->row_stride = row_stride;
    img->data = data;
    img->owns_data = 0;
    *out = img;
    return 0;
}

void
mcp_image_free(mcp_image *img)
{
    if (!img) return;
    if (img->names)
        for (int c = 0; c < img->channels; c++)
            free(img->names[c]);
    free(img->names);
    mcp_attrs_clear(&img->attrs);
    free(img->source);
    if (img->owns_data) free(img->data);
    free(img);
}

int
mcp_image_copy(const mcp_image *img, mcp_image **out)
{
    mcp_image *copy;
    if (mcp_image_new(img->width, img->height, img->channels,
                      (const char *const *)img->names, &copy))
        return -1;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            memcpy(mcp_image_px(copy, x, y), mcp_image_px(img, x, y),
                   (size_t)img->channels * sizeof(float));
    if (mcp_attrs_copy(&img->attrs, &copy->attrs) ||
        mcp_image_set_source(copy, img->source)) {
        mcp_image_free(copy);
        return -1;
    }
    *out = copy;
    return 0;
}

/* A view sharing img's pixels from `first`, with `channels` channels named after
 * img's channels first..first+channels-1. */
static int
view_new(const mcp_image *img, float *first, int width, int height, int channels,
         const char *const *names, mcp_image **out)
{
    mcp_image *v = header_new(width, height, channels, names, img->source);
    if (!v) return -1;
    v->pixel_stride = img->pixel_stride;
    v->row_stride = img->row_stride;
    v->data = first;
    v->owns_data = 0;
    *out = v;
    return 0;
}

int
mcp_image_crop_view(const mcp_image *img, int x0, int y0, int w, int h, mcp_image **out)
{
    *out = NULL;
    if (x0 < 0 || y0 < 0 || w < 1 || h < 1 || x0 + w > img->width || y0 + h > img->height)
        return mcp_error("%s: crop %dx%d+%d+%d lies outside the %dx%d image", img->source,
                         w, h, x0, y0, img->width, img->height);
    return view_new(img, mcp_image_px(img, x0, y0), w, h, img->channels,
                    (const char *const *)img->names, out);
}

int
mcp_image_channel_view(const mcp_image *img, int first, int count, mcp_image **out)
{
    *out = NULL;
    if (first < 0 || count < 1 || first + count > img->channels)
        return mcp_error("%s: channel range [%d, %d) outside its %d channels",
                         img->source, first, first + count, img->channels);
    return view_new(img, img->data + first, img->width, img->height, count,
                    (const char *const *)img->names + first, out);
}

int
mcp_image_channel(const mcp_image *img, const char *name)
{
    for (int c = 0; c < img->channels; c++)
        if (strcmp(img->names[c], name) == 0) return c;
    return -1;
}

int
mcp_image_channels(const mcp_image *img, const char *const *names, int count, int *index)
{
    for (int i = 0; i < count; i++) {
        index[i] = mcp_image_channel(img, names[i]);
        if (index[i] < 0) return mcp_error("%s: no channel '%s'", img->source, names[i]);
    }
    return 0;
}

int
mcp_image_find_triple(const mcp_image *img, const char *const (*triples)[3], int n,
                      int index[3])
{
    for (int t = 0; t < n; t++) {
        int found = 1;
        for (int c = 0; c < 3 && found; c++)
            found = (index[c] = mcp_image_channel(img, triples[t][c])) >= 0;
        if (found) return 0;
    }
    if (img->channels != 3) return -1;
    for (int c = 0; c < 3; c++)
        index[c] = c;
    return 0;
}

/* ---- colour by channel name (docs/conventions.md, "Channel order") ---- */

/* The channel called name, else one called so in any case ("r", "g", "b"). */
static int
channel_nocase(const mcp_image *img, const char *name)
{
    int c = mcp_image_channel(img, name);
    for (int i = 0; c < 0 && i < img->channels; i++)
        if (img->names && img->names[i] && !strcasecmp(img->names[i], name)) c = i;
    return c;
}

/* The channel whose name ends with suffix (e.g. ".Combined.R"), when exactly one
 * does. */
static int
channel_suffix(const mcp_image *img, const char *suffix)
{
    int found = -1, n = 0;
    size_t ls = strlen(suffix);
    for (int i = 0; i < img->channels; i++) {
        const char *name = img->names ? img->names[i] : NULL;
        size_t ln = name ? strlen(name) : 0;
        if (ln >= ls && !strcmp(name + ln - ls, suffix)) {
            found = i;
            n++;
        }
    }
    return n == 1 ? found : -1;
}

int
mcp_image_rgb_by_name(const mcp_image *img, int rgb[3])
{
    static const char *const names[3] = {"R", "G", "B"};
    static const char *const blender[3] = {".Combined.R", ".Combined.G", ".Combined.B"};
    int n_found = 0, n_blender = 0, bl[3];
    for (int k = 0; k < 3; k++) {
        n_found += (rgb[k] = channel_nocase(img, names[k])) >= 0;
        n_blender += (bl[k] = channel_suffix(img, blender[k])) >= 0;
    }
    if (n_found == 0 && n_blender == 3) { /* Blender: <layer>.Combined.R/G/B */
        memcpy(rgb, bl, sizeof bl);
        return 3;
    }
    return n_found;
}

/* The channel called "<prefix>.<letter>" where prefix is name[0 .. len). */
static int
layer_channel(const mcp_image *img, const char *name, size_t len, char letter)
{
    for (int c = 0; c < img->channels; c++) {
        const char *n = img->names[c];
        if (!strncmp(n, name, len) && n[len] == '.' && n[len + 1] == letter &&
            !n[len + 2])
            return c;
    }
    return -1;
}

int
mcp_image_colour_order(const mcp_image *img, int *order)
{
    int n = img->channels, k = 0, rgb[3], moved = 0;
    unsigned char *placed = mcp_calloc((size_t)n, 1);
    if (!placed) return -1;
    /* the colour first; a duplicated name can make two of R, G, B one channel, and
       then the order is left alone */
    if (mcp_image_rgb_by_name(img, rgb) == 3 && rgb[0] != rgb[1] && rgb[0] != rgb[2] &&
        rgb[1] != rgb[2])
        for (int j = 0; j < 3; j++) {
            order[k++] = rgb[j];
            placed[rgb[j]] = 1;
        }
    for (int c = 0; c < n; c++) {
        if (placed[c]) continue;
        /* a layer's "<p>.R", "<p>.G", "<p>.B" together as R, G, B, where the first of
           them stands (EXR lists them B, G, R) */
        const char *name = img->names[c];
        size_t len = strlen(name);
        int t[3] = {-1, -1, -1};
        if (len > 2 && name[len - 2] == '.' && strchr("RGB", name[len - 1]))
            for (int j = 0; j < 3; j++)
                t[j] = layer_channel(img, name, len - 2, "RGB"[j]);
        if (t[0] >= 0 && t[1] >= 0 && t[2] >= 0 && !placed[t[0]] && !placed[t[1]] &&
            !placed[t[2]]) {
            for (int j = 0; j < 3; j++) {
                order[k++] = t[j];
                placed[t[j]] = 1;
            }
        } else {
            order[k++] = c;
            placed[c] = 1;
        }
    }
    free(placed);
    for (int c = 0; c < n; c++)
        moved |= order[c] != c;
    return moved;
}

int
mcp__image_permute_names(mcp_image *img, const int *order)
{
    char **names = mcp_calloc((size_t)img->channels, sizeof *names);
    if (!names) return -1;
    for (int c = 0; c < img->channels; c++)
        names[c] = img->names[order[c]];
    free(img->names);
    img->names = names;
    return 0;
}

int
mcp_image_colour_first(mcp_image *img)
{
    int n = img->channels, rc = -1;
    int *order = mcp_calloc((size_t)n, sizeof *order);
    float *tmp = mcp_calloc((size_t)n, sizeof *tmp);
    int moved = order && tmp ? mcp_image_colour_order(img, order) : -1;
    if (moved == 0)
        rc = 0;
    else if (moved > 0 && !mcp__image_permute_names(img, order)) {
        /* one pixel at a time through tmp: only files whose channels were out of order
           (an OpenImageIO read) pay for this pass */
        for (int y = 0; y < img->height; y++)
            for (int x = 0; x < img->width; x++) {
                float *p = mcp_image_px(img, x, y);
                for (int c = 0; c < n; c++)
                    tmp[c] = p[order[c]];
                memcpy(p, tmp, (size_t)n * sizeof *tmp);
            }
        rc = 0;
    }
    free(tmp);
    free(order);
    return rc;
}

int
mcp_image_copy_channels(const mcp_image *img, const int *index, int count,
                        mcp_image **out)
{
    *out = NULL;
    if (count < 1) return mcp_error("%s: no channels to copy", img->source);
    const char **names = mcp_calloc((size_t)count, sizeof *names);
    if (!names) return -1;
    for (int i = 0; i < count; i++) {
        if (index[i] < 0 || index[i] >= img->channels) {
            free(names);
            return mcp_error("%s: channel index %d outside its %d channels", img->source,
                             index[i], img->channels);
        }
        names[i] = img->names[index[i]];
    }
    mcp_image *sub;
    int rc = mcp_image_new(img->width, img->height, count, names, &sub);
    free(names);
    if (rc) return -1;
#pragma omp parallel for schedule(                                                       \
    static) if ((long long)img->width * img->height * count > 65536)
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++) {
            const float *s = mcp_image_px(img, x, y);
            float *d = mcp_image_px(sub, x, y);
            for (int i = 0; i < count; i++)
                d[i] = s[index[i]];
        }
    if (mcp_attrs_copy(&img->attrs, &sub->attrs) ||
        mcp_image_set_source(sub, img->source)) {
        mcp_image_free(sub);
        return -1;
    }
    *out = sub;
    return 0;
}

int
mcp_image_set_channel_name(mcp_image *img, int c, const char *name)
{
    if (c < 0 || c >= img->channels)
        return mcp_error("%s: channel index %d outside its %d channels", img->source, c,
                         img->channels);
    char *copy = mcp_strdup(name);
    if (!copy) return -1;
    free(img->names[c]);
    img->names[c] = copy;
    return 0;
}

int
mcp_image_set_source(mcp_image *img, const char *source)
{
    char *copy = mcp_strdup(source ? source : "(image)");
    if (!copy) return -1;
    free(img->source);
    img->source = copy;
    return 0;
}

int
mcp_image_is_packed(const mcp_image *img)
{
    return img->pixel_stride == img->channels &&
           img->row_stride == (ptrdiff_t)img->width * img->channels;
}

int
mcp_image_same_size(const mcp_image *a, const mcp_image *b)
{
    if (a->width == b->width && a->height == b->height) return 1;
    mcp_error("%s: size %dx%d does not match %s (%dx%d)", a->source, a->width, a->height,
              b->source, b->width, b->height);
    return 0;
}

/* ---- attributes ---- */

const mcp_attr *
mcp_attrs_find(const mcp_attrs *attrs, const char *name)
{
    for (int i = 0; i < attrs->count; i++)
        if (strcmp(attrs->items[i].name, name) == 0) return &attrs->items[i];
    return NULL;
}

static void
attr_clear(mcp_attr *a)
{
    free(a->name);
    free(a->s);
    memset(a, 0, sizeof *a);
}

/* The slot for name: the existing one (cleared of its value) or a new one. */
static mcp_attr *
attr_slot(mcp_attrs *attrs, const char *name)
{
    mcp_attr *a = (mcp_attr *)mcp_attrs_find(attrs, name);
    if (a) {
        free(a->s);
        a->s = NULL;
        return a;
    }
    mcp_attr *items =
        mcp_realloc(attrs->items, (size_t)(attrs->count + 1) * sizeof *items);
    if (!items) {
        mcp_error("out of memory for attribute '%s'", name);
        return NULL;
    }
    attrs->items = items;
    a = &items[attrs->count];
    memset(a, 0, sizeof *a);
    if (!(a->name = mcp_strdup(name))) return NULL;
    attrs->count++;
    return a;
}

int
mcp_attrs_set_int(mcp_attrs *attrs, const char *name, int64_t value)
{
    mcp_attr *a = attr_slot(attrs, name);
    if (!a) return -1;
    a->type = MCP_ATTR_INT;
    a->i = value;
    a->f = (double)value;
    return 0;
}

int
mcp_attrs_set_float(mcp_attrs *attrs, const char *name, float value)
{
    mcp_attr *a = attr_slot(attrs, name);
    if (!a) return -1;
    a->type = MCP_ATTR_FLOAT;
    a->f = value;
    return 0;
}

int
mcp_attrs_set_double(mcp_attrs *attrs, const char *name, double value)
{
    mcp_attr *a = attr_slot(attrs, name);
    if (!a) return -1;
    a->type = MCP_ATTR_DOUBLE;
    a->f = value;
    return 0;
}

int
mcp_attrs_set_string(mcp_attrs *attrs, const char *name, const char *value)
{
    mcp_attr *a = attr_slot(attrs, name);
    if (!a) return -1;
    a->type = MCP_ATTR_STRING;
    return (a->s = mcp_strdup(value)) ? 0 : -1;
}

int
mcp_attrs_copy(const mcp_attrs *from, mcp_attrs *to)
{
    for (int i = 0; i < from->count; i++) {
        const mcp_attr *a = &from->items[i];
        int rc = 0;
        switch (a->type) {
        case MCP_ATTR_INT:
            rc = mcp_attrs_set_int(to, a->name, a->i);
            break;
        case MCP_ATTR_FLOAT:
            rc = mcp_attrs_set_float(to, a->name, (float)a->f);
            break;
        case MCP_ATTR_DOUBLE:
            rc = mcp_attrs_set_double(to, a->name, a->f);
            break;
        case MCP_ATTR_STRING:
            rc = mcp_attrs_set_string(to, a->name, a->s);
            break;
        }
        if (rc) return -1;
    }
    return 0;
}

void
mcp_attrs_clear(mcp_attrs *attrs)
{
    for (int i = 0; i < attrs->count; i++)
        attr_clear(&attrs->items[i]);
    free(attrs->items);
    attrs->items = NULL;
    attrs->count = 0;
}
