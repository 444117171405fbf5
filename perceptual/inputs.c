/* inputs.c: checking and packing the perceptual methods' inputs -- candidates,
 * surrogate and confidence map -- into tone-mapped float buffers (docs/mathematics.md
 * §4.2: the error lives in display space, T applied per channel), and building their
 * outputs (the chosen candidates, the index map). */
#include "internal.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *
src(const mcp_image *img)
{
    return img->source ? img->source : "image";
}

int
mcp__check_candidates(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                      int *rgb)
{
    int idx[3];
    if (!cands || m < 1)
        return mcp_error("perceptual: give at least one candidate image (got %d)", m);
    for (int j = 0; j < m; j++) {
        if (!cands[j]) return mcp_error("perceptual: candidate %d is missing", j);
        if (mcp_rgb_channels(cands[j], rgb ? rgb + 3 * j : idx)) return -1;
        if (cands[j]->width < 1 || cands[j]->height < 1)
            return mcp_error("%s: empty image", src(cands[j]));
        if (j > 0 && !mcp_image_same_size(cands[j], cands[0])) return -1;
    }
    if (surrogate &&
        (mcp_rgb_channels(surrogate, idx) || !mcp_image_same_size(surrogate, cands[0])))
        return -1;
    return 0;
}

/* T of one image's RGB into dst[n][3] (any strides); returns the number of
 * non-finite values and the first one's pixel in *bad (row-major index). */
static long
tone_into(const mcp_image *img, const int rgb[3], mcp_tonemap tm, float *dst,
          size_t stride3, long *bad)
{
    int w = img->width, h = img->height;
    long n_bad = 0, first = -1;
#pragma omp parallel for reduction(+ : n_bad) if ((size_t)w * h >= 65536)
    for (int y = 0; y < h; y++) {
        long row_bad = 0, row_first = -1;
        for (int x = 0; x < w; x++) {
            const float *p = mcp_image_px(img, x, y);
            float *d = dst + ((size_t)y * w + x) * stride3;
            for (int c = 0; c < 3; c++) {
                float v = p[rgb[c]];
                if (!isfinite(v)) {
                    if (row_first < 0) row_first = (long)y * w + x;
                    row_bad++;
                }
                d[c] = mcp__tone(tm, v);
            }
        }
        if (row_bad) {
#pragma omp critical(perc_bad)
            if (first < 0 || row_first < first) first = row_first;
        }
        n_bad += row_bad;
    }
    *bad = first;
    return n_bad;
}

static int
bad_value(const mcp_image *img, long n_bad, long first)
{
    return mcp_error("%s: %ld non-finite values (the first at pixel %ld, %ld)", src(img),
                     n_bad, first % img->width, first / img->width);
}

int
mcp__rgb_tone(const mcp_image *img, mcp_tonemap tm, float **out)
{
    int rgb[3];
    size_t n;
    *out = NULL;
    if (mcp_rgb_channels(img, rgb)) return -1;
    if (mcp_size_mul3((size_t)img->width, (size_t)img->height, 3, &n))
        return mcp_error("%s: bad size %dx%d", src(img), img->width, img->height);
    float *t = mcp_malloc(n * sizeof *t);
    if (!t) return -1;
    long first, n_bad = tone_into(img, rgb, tm, t, 3, &first);
    if (n_bad) {
        free(t);
        return bad_value(img, n_bad, first);
    }
    *out = t;
    return 0;
}

int
mcp__stack_tone(const mcp_image *const *cands, int m, mcp_tonemap tm, float **out)
{
    size_t n, total;
    *out = NULL;
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    if (!rgb) return -1;
    if (mcp__check_candidates(cands, m, NULL, rgb)) {
        free(rgb);
        return -1;
    }
    if (mcp_size_mul3((size_t)cands[0]->width, (size_t)cands[0]->height, 3, &n) ||
        mcp_size_mul(n, (size_t)m, &total)) {
        free(rgb);
        return mcp_error("perceptual: %d candidates of %dx%d are too many", m,
                         cands[0]->width, cands[0]->height);
    }
    float *t = mcp_malloc(total * sizeof *t);
    int rc = t ? 0 : -1;
    for (int j = 0; j < m && !rc; j++) {
        long first, n_bad = tone_into(cands[j], rgb + 3 * j, tm, t + 3 * (size_t)j,
                                      3 * (size_t)m, &first);
        if (n_bad) rc = bad_value(cands[j], n_bad, first);
    }
    free(rgb);
    if (rc) {
        free(t);
        return -1;
    }
    *out = t;
    return 0;
}

int
mcp__mean_rgb(const mcp_image *const *cands, int m, float **out)
{
    size_t n;
    *out = NULL;
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    if (!rgb) return -1;
    if (mcp__check_candidates(cands, m, NULL, rgb)) {
        free(rgb);
        return -1;
    }
    int w = cands[0]->width, h = cands[0]->height;
    if (mcp_size_mul3((size_t)w, (size_t)h, 3, &n)) {
        free(rgb);
        return mcp_error("perceptual: bad size %dx%d", w, h);
    }
    float *mean = mcp_malloc(n * sizeof *mean);
    if (!mean) {
        free(rgb);
        return -1;
    }
    long n_bad = 0;
#pragma omp parallel for reduction(+ : n_bad) if ((size_t)w * h >= 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                double s = 0.0;
                for (int j = 0; j < m; j++)
                    s += mcp_image_px(cands[j], x, y)[rgb[3 * j + c]];
                n_bad += !isfinite(s);
                mean[((size_t)y * w + x) * 3 + c] = (float)(s / m);
            }
    free(rgb);
    if (n_bad) {
        free(mean);
        return mcp_error("perceptual: the candidates hold %ld non-finite values", n_bad);
    }
    *out = mean;
    return 0;
}

int
mcp__image_from_rgb(int w, int h, const float *rgb, mcp_image **out)
{
    static const char *const names[] = {"R", "G", "B"};
    if (mcp_image_new(w, h, 3, names, out)) return -1;
    memcpy((*out)->data, rgb, (size_t)w * h * 3 * sizeof *rgb);
    return 0;
}

int
mcp__confidence_map(const mcp_perc_model *model, int w, int h, float **out)
{
    *out = NULL;
    const mcp_image *c = model->confidence_map;
    if (!c) {
        if (!(model->confidence >= 0.0 && model->confidence <= 1.0))
            return mcp_error("perceptual: confidence must be in [0, 1] (got %g)",
                             model->confidence);
        return 0;
    }
    if (c->width != w || c->height != h)
        return mcp_error("%s: confidence map is %dx%d, the images %dx%d", src(c),
                         c->width, c->height, w, h);
    if (c->channels < 1) return mcp_error("%s: confidence map has no channel", src(c));
    float *map = mcp_malloc((size_t)w * h * sizeof *map);
    if (!map) return -1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float v = mcp_image_px(c, x, y)[0];
            if (!(v >= 0.0f && v <= 1.0f)) {
                free(map);
                return mcp_error(
                    "%s: confidence must be in [0, 1] (got %g at pixel %d, %d)", src(c),
                    v, x, y);
            }
            map[(size_t)y * w + x] = v;
        }
    *out = map;
    return 0;
}

int
mcp__tone_rgb(const float *rgb, size_t n, mcp_tonemap tm, float **out)
{
    size_t n3;
    *out = NULL;
    if (mcp_size_mul(n, 3, &n3)) return mcp_error("perceptual: bad size");
    float *t = mcp_malloc(n3 * sizeof *t);
    if (!t) return -1;
#pragma omp parallel for if (n3 >= 196608)
    for (size_t i = 0; i < n3; i++)
        t[i] = mcp__tone(tm, rgb[i]);
    *out = t;
    return 0;
}

int
mcp__index_image(int w, int h, const int *choice, mcp_image **out)
{
    static const char *const names[] = {"index"};
    if (mcp_image_new(w, h, 1, names, out)) return -1;
    float *d = (*out)->data;
#pragma omp parallel for if ((size_t)w * h >= 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            d[(size_t)y * w + x] = (float)choice[(size_t)y * w + x];
    return 0;
}

/* Packed RGB rows, the common case, are one contiguous (vectorised) loop. */
long
mcp__tone_row(const mcp_image *img, const int ch[3], int y, mcp_tonemap tm, float *dst)
{
    int w = img->width;
    long bad = 0;
    const float *src = mcp_image_px(img, 0, y);
    if (img->pixel_stride == 3 && ch[0] == 0 && ch[1] == 1 && ch[2] == 2) {
        /* omp simd: -O2's cheap vectoriser leaves these scalar */
#pragma omp simd reduction(+ : bad)
        for (int i = 0; i < 3 * w; i++)
            bad += !(fabsf(src[i]) <= FLT_MAX);
        if (tm == MCP_TONEMAP_CLAMP) /* unswitched, so that it vectorises */
#pragma omp simd
            for (int i = 0; i < 3 * w; i++)
                dst[i] = src[i] > 0.0f ? (src[i] < 1.0f ? src[i] : 1.0f) : 0.0f;
        else if (tm == MCP_TONEMAP_NONE)
            memcpy(dst, src, (size_t)w * 3 * sizeof *dst);
        else
            for (int i = 0; i < 3 * w; i++)
                dst[i] = mcp__tone(tm, src[i]);
        return bad;
    }
    for (int x = 0; x < w; x++)
        for (int c = 0; c < 3; c++) {
            float v = src[x * img->pixel_stride + ch[c]];
            bad += !isfinite(v);
            dst[x * 3 + c] = mcp__tone(tm, v);
        }
    return bad;
}

int
mcp__pick_image(const mcp_image *const *cands, int m, const int *choice, mcp_image **out)
{
    static const char *const names[] = {"R", "G", "B"};
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    *out = NULL;
    if (!rgb) return -1;
    if (mcp__check_candidates(cands, m, NULL, rgb) ||
        mcp_image_new(cands[0]->width, cands[0]->height, 3, names, out)) {
        free(rgb);
        return -1;
    }
    int w = cands[0]->width, h = cands[0]->height;
#pragma omp parallel for if ((size_t)w * h >= 65536)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int j = choice[(size_t)y * w + x];
            const float *p = mcp_image_px(cands[j], x, y);
            float *d = (*out)->data + ((size_t)y * w + x) * 3;
            d[0] = p[rgb[3 * j]], d[1] = p[rgb[3 * j + 1]], d[2] = p[rgb[3 * j + 2]];
        }
    free(rgb);
    return 0;
}

int
mcp__rgb_image(const mcp_image *img, mcp_image **out)
{
    static const char *const names[] = {"R", "G", "B"};
    int rgb[3];
    *out = NULL;
    if (mcp_rgb_channels(img, rgb) || mcp_image_copy_channels(img, rgb, 3, out))
        return -1;
    for (int c = 0; c < 3; c++)
        if (mcp_image_set_channel_name(*out, c, names[c])) {
            mcp_image_free(*out);
            *out = NULL;
            return -1;
        }
    return 0;
}
