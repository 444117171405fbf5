/* blockavg.c: kd-tree block averaging of SURE (docs/mathematics.md §2.7; Firmino 2024
 * Alg. 1, Eq. 13).
 *
 * A block whose longest side is > 1 is cut at the middle of that side (the width on
 * ties; the paper does not say) and the cut is kept when both halves pass, for all
 * three channels, Σ Σ̂^r / sqrt(|B_j ∩ C_k|) < Σ SURE^r.
 *
 * Sums: §2.7 asks for per-channel summed-area tables in double so that each test is
 * O(1). A full-resolution table of the 6 quantities is 48 bytes a pixel (50 MB at
 * 1024²), and writing it costs more than everything else here, so the table is kept
 * over CELL x CELL cells (3 MB at 1024²) and the few rows and columns of partial
 * cells at a block's edges are summed directly, also in double: a test costs
 * O(perimeter) instead of O(1) and the sums are exact to double rounding. Cells are
 * summed by one thread each in a fixed order, so the results do not depend on the
 * thread count.
 *
 * The estimate's variant (mcp__block_average_quiet) leaves a quiet block whole: one
 * whose every pixel has Σ̂^r and s² at 0, found by a count of the other, loud pixels
 * kept in the same table (an integer, exact in double sums and differences). Its values
 * all have s = 0, so the distribution does not depend on how it is cut
 * (docs/mathematics.md, "Quiet blocks are not cut"). */
#include "estimate.h"
#include "internal.h"

#include <mcpost/filter.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define CELL 4
/* SURE^r R, G, B, Σ̂^r R, G, B, and the count of loud pixels (below), an integer that
 * double sums and differences hold exactly */
#define NQ 7
#define LOUD 6

mcp_block_options
mcp_block_defaults(void)
{
    mcp_block_options o;
    memset(&o, 0, sizeof o);
    o.tile_size = 0;
    return o;
}

void
mcp_blocks_free(mcp_blocks *b)
{
    if (!b) return;
    free(b->items);
    free(b);
}

/* ---- sums over rectangles ---- */

typedef struct sums {
    const mcp_image *sure, *sigma;
    const mcp_image *s2; /* the model's s² (mcp__block_average_quiet), or NULL */
    int w, h, cw, ch;    /* pixels; cells (the last ones may be partial) */
    double *table;       /* (ch + 1) x (cw + 1) x NQ: sums over cells [0, cx) x [0, cy) */
} sums;

/* The non-finite values in cell (cx, cy) (only called where its sum is not finite). */
static long
count_bad(const mcp_image *sure, const mcp_image *sigma, int cx, int cy)
{
    long bad = 0;
    for (int y = cy * CELL; y < (cy + 1) * CELL && y < sure->height; y++)
        for (int x = cx * CELL; x < (cx + 1) * CELL && x < sure->width; x++)
            for (int c = 0; c < 3; c++)
                bad += !isfinite(mcp_image_px(sure, x, y)[c]) +
                       !isfinite(mcp_image_px(sigma, x, y)[c]);
    return bad;
}

/* 1 when a pixel's Σ̂^r (g) or s² (v) is other than 0 in some channel. */
static inline int
loud_values(const float *g, const float *v)
{
    return (g[0] != 0.0f) | (g[1] != 0.0f) | (g[2] != 0.0f) | (v[0] != 0.0f) |
           (v[1] != 0.0f) | (v[2] != 0.0f);
}

/* The same for pixel (x, y); with no s² image every pixel is loud (Alg. 1 as the paper
 * has it). */
static inline int
loud(const sums *s, int x, int y)
{
    return !s->s2 || loud_values(mcp_image_px(s->sigma, x, y), mcp_image_px(s->s2, x, y));
}

static int
sums_build(const mcp_image *sure, const mcp_image *sigma, const mcp_image *s2, sums *s,
           long *n_bad)
{
    s->sure = sure;
    s->sigma = sigma;
    s->s2 = s2;
    s->w = sure->width;
    s->h = sure->height;
    s->cw = (s->w + CELL - 1) / CELL;
    s->ch = (s->h + CELL - 1) / CELL;
    size_t row = (size_t)(s->cw + 1) * NQ;
    s->table = mcp_calloc(row * (size_t)(s->ch + 1), sizeof(double));
    if (!s->table) return -1;
    long bad = 0;
    int packed = sure->pixel_stride == 3 && sigma->pixel_stride == 3;
    const int s2_packed = s2 && s2->pixel_stride == 3;
    /* cell sums, stored at (cy + 1, cx + 1); a NaN or Inf makes its cell sum
     * non-finite, which is how they are found */
#pragma omp parallel for schedule(static) reduction(+ : bad)
    for (int cy = 0; cy < s->ch; cy++) {
        double *cells = s->table + (size_t)(cy + 1) * row;
        int y1 = (cy + 1) * CELL < s->h ? (cy + 1) * CELL : s->h;
        for (int cx = 0; cx < s->cw; cx++) {
            double acc[NQ] = {0};
            int x1 = (cx + 1) * CELL < s->w ? (cx + 1) * CELL : s->w;
            if (packed && x1 - cx * CELL == CELL) {
                /* a whole cell row is 3 CELL contiguous floats: add them lane by lane
                 * (the compiler vectorises this), then fold the lanes per channel */
                double ls[3 * CELL] = {0}, lg[3 * CELL] = {0};
                int n_loud = 0;
                for (int y = cy * CELL; y < y1; y++) {
                    const float *ps = mcp_image_px(sure, cx * CELL, y);
                    const float *pg = mcp_image_px(sigma, cx * CELL, y);
                    for (int i = 0; i < 3 * CELL; i++) {
                        ls[i] += ps[i];
                        lg[i] += pg[i];
                    }
                    if (s2_packed) { /* loud(), on the row's packed values */
                        const float *pv = mcp_image_px(s2, cx * CELL, y);
                        for (int x = 0; x < CELL; x++)
                            n_loud += loud_values(pg + 3 * x, pv + 3 * x);
                    } else {
                        for (int x = cx * CELL; x < x1; x++)
                            n_loud += loud(s, x, y);
                    }
                }
                for (int i = 0; i < 3 * CELL; i++) {
                    acc[i % 3] += ls[i];
                    acc[3 + i % 3] += lg[i];
                }
                acc[LOUD] = n_loud;
            } else {
                for (int y = cy * CELL; y < y1; y++)
                    for (int x = cx * CELL; x < x1; x++) {
                        const float *ps = mcp_image_px(sure, x, y);
                        const float *pg = mcp_image_px(sigma, x, y);
                        for (int c = 0; c < 3; c++) {
                            acc[c] += ps[c];
                            acc[3 + c] += pg[c];
                        }
                        acc[LOUD] += loud(s, x, y);
                    }
            }
            int finite = 1;
            for (int q = 0; q < NQ; q++)
                finite &= isfinite(acc[q]) != 0;
            if (!finite) bad += count_bad(sure, sigma, cx, cy);
            memcpy(cells + (size_t)(cx + 1) * NQ, acc, sizeof acc);
        }
    }
    /* prefix sums along each row, then down the columns (small: sequential) */
    for (int cy = 1; cy <= s->ch; cy++) {
        double *r = s->table + (size_t)cy * row;
        for (int cx = 1; cx <= s->cw; cx++)
            for (int q = 0; q < NQ; q++)
                r[cx * NQ + q] += r[(cx - 1) * NQ + q];
        const double *up = r - row;
        for (size_t i = 0; i < row; i++)
            r[i] += up[i];
    }
    *n_bad = bad;
    return 0;
}

/* Direct sums over pixels [x0, x1) x [y0, y1), added to out. */
static void
sums_direct(const sums *s, int x0, int x1, int y0, int y1, double out[NQ])
{
    for (int y = y0; y < y1; y++)
        for (int x = x0; x < x1; x++) {
            const float *ps = mcp_image_px(s->sure, x, y),
                        *pg = mcp_image_px(s->sigma, x, y);
            for (int c = 0; c < 3; c++) {
                out[c] += ps[c];
                out[3 + c] += pg[c];
            }
            out[LOUD] += loud(s, x, y);
        }
}

/* The sums of the 6 quantities over the block (x, y, w, h). */
static void
sums_rect(const sums *s, int x, int y, int w, int h, double out[NQ])
{
    memset(out, 0, NQ * sizeof *out);
    int x1 = x + w, y1 = y + h;
    /* cells wholly inside: from ceil(x / CELL) to floor(x1 / CELL), or to the last
     * (partial) cell when the block reaches the image edge */
    int cx0 = (x + CELL - 1) / CELL, cx1 = x1 == s->w ? s->cw : x1 / CELL;
    int cy0 = (y + CELL - 1) / CELL, cy1 = y1 == s->h ? s->ch : y1 / CELL;
    if (cx0 >= cx1 || cy0 >= cy1) {
        sums_direct(s, x, x1, y, y1, out);
        return;
    }
    size_t row = (size_t)(s->cw + 1) * NQ;
    const double *t = s->table;
    for (int q = 0; q < NQ; q++)
        out[q] = t[cy1 * row + cx1 * NQ + q] - t[cy1 * row + cx0 * NQ + q] -
                 t[cy0 * row + cx1 * NQ + q] + t[cy0 * row + cx0 * NQ + q];
    int px0 = cx0 * CELL, px1 = cx1 * CELL < s->w ? cx1 * CELL : s->w;
    int py0 = cy0 * CELL, py1 = cy1 * CELL < s->h ? cy1 * CELL : s->h;
    sums_direct(s, x, x1, y, py0, out);     /* above the cells */
    sums_direct(s, x, x1, py1, y1, out);    /* below */
    sums_direct(s, x, px0, py0, py1, out);  /* left */
    sums_direct(s, px1, x1, py0, py1, out); /* right */
}

/* ---- the kd-tree ---- */

typedef struct builder {
    const sums *s;
    mcp_block *items;
    int count, cap;
    int failed;
} builder;

static void
emit(builder *b, int x, int y, int w, int h, const double sums[NQ])
{
    if (b->count == b->cap) {
        int cap = b->cap ? 2 * b->cap : 256;
        mcp_block *n = mcp_realloc(b->items, (size_t)cap * sizeof *n);
        if (!n) {
            b->failed = 1;
            return;
        }
        b->items = n;
        b->cap = cap;
    }
    mcp_block *k = &b->items[b->count++];
    k->x = x, k->y = y, k->w = w, k->h = h;
    for (int c = 0; c < 3; c++) {
        k->sure_sum[c] = sums[c];
        k->var_sum[c] = 0.0;
    }
}

/* Eq. 13 for one child: Σ Σ̂^r / sqrt(n) < Σ SURE^r in every channel. */
static int
reliable(const double sums[NQ], double n)
{
    double root = sqrt(n);
    for (int c = 0; c < 3; c++)
        if (!(sums[3 + c] / root < sums[c])) return 0;
    return 1;
}

static void
split(builder *b, int x, int y, int w, int h, const double sums[NQ])
{
    if (b->failed) return;
    /* a quiet block (no pixel with a Σ̂^r or an s² other than 0) is not cut */
    if ((w > 1 || h > 1) && sums[LOUD] > 0.0) {
        int x2 = x, y2 = y, w1 = w, h1 = h, w2 = w, h2 = h;
        if (w >= h) {
            w1 = w / 2;
            w2 = w - w1;
            x2 = x + w1;
        } else {
            h1 = h / 2;
            h2 = h - h1;
            y2 = y + h1;
        }
        double s1[NQ], s2[NQ];
        sums_rect(b->s, x, y, w1, h1, s1);
        sums_rect(b->s, x2, y2, w2, h2, s2);
        if (reliable(s1, (double)w1 * h1) && reliable(s2, (double)w2 * h2)) {
            split(b, x, y, w1, h1, s1);
            split(b, x2, y2, w2, h2, s2);
            return;
        }
    }
    emit(b, x, y, w, h, sums);
}

static int
check_pair(const mcp_image *a, const mcp_image *b)
{
    if (!a || !b) return mcp_error("block averaging: missing SURE or variance image");
    if (a->channels < 3 || b->channels < 3)
        return mcp_error(
            "block averaging: SURE and variance need 3 channels (got %d, %d)",
            a->channels, b->channels);
    if (a->width != b->width || a->height != b->height)
        return mcp_error("block averaging: SURE is %dx%d but the variance %dx%d",
                         a->width, a->height, b->width, b->height);
    return 0;
}

/* Alg. 1, with quiet blocks left whole where s2 is given (internal.h). */
int
mcp__block_average_quiet(const mcp_image *sure_rel, const mcp_image *sigma_rel,
                         const mcp_image *s2, const mcp_block_options *opt,
                         mcp_blocks **out)
{
    *out = NULL;
    mcp_block_options o = opt ? *opt : mcp_block_defaults();
    if (o.tile_size < 0)
        return mcp_error("block averaging: tile_size must be >= 0 (got %d)", o.tile_size);
    if (check_pair(sure_rel, sigma_rel) || (s2 && check_pair(sure_rel, s2))) return -1;
    int w = sure_rel->width, h = sure_rel->height;
    sums s;
    long bad = 0;
    if (sums_build(sure_rel, sigma_rel, s2, &s, &bad)) return -1;
    if (bad) {
        free(s.table);
        return mcp_error("block averaging: %ld values of SURE or variance are not finite",
                         bad);
    }
    builder b = {&s, NULL, 0, 0, 0};
    int tile = o.tile_size > 0 ? o.tile_size : (w > h ? w : h);
    for (int ty = 0; ty < h; ty += tile)
        for (int tx = 0; tx < w; tx += tile) {
            int tw = tx + tile < w ? tile : w - tx, th = ty + tile < h ? tile : h - ty;
            double sum[NQ];
            sums_rect(&s, tx, ty, tw, th, sum);
            split(&b, tx, ty, tw, th, sum);
        }
    free(s.table);
    mcp_blocks *r = b.failed ? NULL : mcp_calloc(1, sizeof *r);
    if (!r) {
        free(b.items);
        return b.failed ? mcp_error("out of memory (block list)") : -1;
    }
    r->width = w;
    r->height = h;
    r->count = b.count;
    r->items = b.items;
    *out = r;
    return 0;
}

int
mcp_block_average(const mcp_image *sure_rel, const mcp_image *sigma_rel,
                  const mcp_block_options *opt, mcp_blocks **out)
{
    return mcp__block_average_quiet(sure_rel, sigma_rel, NULL, opt, out);
}

int
mcp_blocks_label(const mcp_blocks *blocks, int32_t **label)
{
    *label = NULL;
    if (!blocks) return mcp_error("block label: missing blocks");
    int32_t *l = mcp_calloc((size_t)blocks->width * blocks->height, sizeof *l);
    if (!l) return -1;
    int w = blocks->width;
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < blocks->count; i++) {
        const mcp_block *k = &blocks->items[i];
        for (int y = k->y; y < k->y + k->h; y++)
            for (int x = k->x; x < k->x + k->w; x++)
                l[(size_t)y * w + x] = i;
    }
    *label = l;
    return 0;
}

float *
mcp__blocks_means(const mcp_blocks *blocks, const mcp_image *values)
{
    float *m = mcp_malloc(((size_t)blocks->count * 3 + 1) * sizeof *m);
    if (!m) return NULL;
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < blocks->count; i++) {
        const mcp_block *k = &blocks->items[i];
        double sum[3] = {0, 0, 0};
        for (int y = k->y; y < k->y + k->h; y++)
            for (int x = k->x; x < k->x + k->w; x++)
                for (int c = 0; c < 3; c++)
                    sum[c] += mcp_image_px(values, x, y)[c];
        const double n = (double)k->w * k->h;
        for (int c = 0; c < 3; c++)
            m[3 * i + c] = (float)(sum[c] / n);
    }
    return m;
}

int
mcp_blocks_mean_image(const mcp_blocks *blocks, const mcp_image *values, mcp_image **out)
{
    *out = NULL;
    if (!blocks || !values || values->channels < 3)
        return mcp_error("block mean: missing blocks or a 3-channel image");
    if (values->width != blocks->width || values->height != blocks->height)
        return mcp_error("block mean: %s is %dx%d but the blocks cover %dx%d",
                         values->source ? values->source : "image", values->width,
                         values->height, blocks->width, blocks->height);
    float *means = mcp__blocks_means(blocks, values);
    if (!means ||
        mcp__image_new(values->width, values->height, 3, NULL, "block mean", out)) {
        free(means);
        return -1;
    }
    mcp_image *o = *out;
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < blocks->count; i++) {
        const mcp_block *k = &blocks->items[i];
        for (int y = k->y; y < k->y + k->h; y++)
            for (int x = k->x; x < k->x + k->w; x++)
                memcpy(mcp_image_px(o, x, y), means + 3 * i, 3 * sizeof *means);
    }
    free(means);
    return 0;
}

int
mcp_blocks_picture(const mcp_blocks *blocks, unsigned char *rgb8)
{
    if (!blocks || !rgb8) return mcp_error("block picture: missing blocks or buffer");
    static const char *const name[1] = {"block"};
    mcp_image *v = NULL;
    int32_t *label = NULL;
    if (mcp_blocks_label(blocks, &label) ||
        mcp__image_new(blocks->width, blocks->height, 1, name, "blocks", &v)) {
        free(label);
        return -1;
    }
    size_t n = (size_t)blocks->width * blocks->height;
    for (size_t i = 0; i < n;
         i++) /* a hash of the index: neighbours get unlike colours */
        v->data[i] = (float)((mcp__mix64((uint64_t)label[i] + 1) >> 11) * 0x1.0p-53);
    int rc = mcp_colormap_apply(v, 0, 0.0, 1.0, MCP_COLORMAP_TURBO, rgb8);
    mcp_image_free(v);
    free(label);
    return rc;
}
