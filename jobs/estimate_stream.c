/* estimate_stream.c: the files of `mcpost estimate` on a dump too large to hold whole
 * (issue 31: memory bounded whatever the image size; docs/benchmarks.md, "The estimate
 * in bands"). The estimate reads the dump a band at a time and hands out F(X), SURE
 * and Var[F] band by band (estimate/estimate.c's mcp__estimate_streamed); here each
 * band goes at once into denoised.exr, sure.exr and variance.exr (common/io's
 * mcp__exr_band_file: a temporary name renamed when every row is written, removed on
 * failure), and into the bytes of the report's denoised picture. The files hold the
 * pixels and header a whole estimate writes (mcp__estimate_write_single). The bands
 * are gathered into GATHER_ROWS rows before they are written: the EXR writer decides
 * whether a call's zip chunks pay from a sample of them, and only from 16 chunks on
 * (common/io/exr.c), so the estimate's bands of 64 rows (4 chunks) of noisy maps were
 * each compressed in full, for nothing: 8K took 3 s longer. */
#include "internal.h"
#include "../common/io/internal.h" /* the files in bands, the screen picture */
#include "../estimate/internal.h"  /* the rows handed out */

#include <mcpost/imageio.h>

#include <stdlib.h>
#include <string.h>

static const char *const streamed_names[MCP__ESTIMATE_STREAMED] = {
    "denoised.exr", "sure.exr", "variance.exr"};

#define GATHER_ROWS 256

/* Opens the files at the first band, when the image's size is known, and the rows
 * that gather each file's bands. */
static int
files_begin(mcp__estimate_files *f, const mcp__estimate_rows *r)
{
    const mcp_write_options opt = mcp_write_defaults();
    const mcp_image *first[MCP__ESTIMATE_STREAMED] = {r->denoised, r->sure, r->var};
    const int rows = r->height < GATHER_ROWS ? r->height : GATHER_ROWS;
    if (mcp_make_dirs(f->dir->dir) || mcp_attrs_copy(r->denoised_attrs, &f->attrs))
        return -1;
    for (int i = 0; i < MCP__ESTIMATE_STREAMED; i++) {
        if (mcp__estimate_path(f->dir, streamed_names[i], f->paths[i],
                               sizeof f->paths[i]) ||
            mcp_image_new(r->width, rows, first[i]->channels,
                          (const char *const *)first[i]->names, &f->gather[i]) ||
            mcp__exr_band_file_begin(&f->files[i], f->paths[i], r->width, r->height,
                                     &opt))
            return -1;
        f->begun = i + 1;
    }
    f->files[0].attrs = &f->attrs;
    if (f->want_picture &&
        !(f->denoised_rgb = mcp_malloc((size_t)r->width * r->height * 3)))
        return -1;
    f->width = r->width;
    f->height = r->height;
    return 0;
}

/* Rows [y0, y0 + src->height) into the gathered rows, written whenever they fill up
 * or reach the image's end. */
static int
gather(mcp__estimate_files *f, int i, const mcp_image *src, int y0)
{
    mcp_image *g = f->gather[i];
    const size_t row_bytes = (size_t)g->width * g->channels * sizeof(float);
    for (int y = 0; y < src->height; y++) {
        const int gy = (y0 + y) % GATHER_ROWS;
        memcpy(mcp_image_px(g, 0, gy), mcp_image_px(src, 0, y), row_bytes);
        if (gy == GATHER_ROWS - 1 || y0 + y == f->height - 1) {
            const int full = g->height;
            g->height = gy + 1;
            const int rc = mcp__exr_band_file_rows(&f->files[i], g, y0 + y - gy);
            g->height = full;
            if (rc) return -1;
        }
    }
    return 0;
}

int
mcp__estimate_files_rows(void *ctx, const mcp__estimate_rows *r)
{
    mcp__estimate_files *f = ctx;
    if (!f->begun && files_begin(f, r)) return -1;
    const mcp_image *rows[MCP__ESTIMATE_STREAMED] = {r->denoised, r->sure, r->var};
    for (int i = 0; i < MCP__ESTIMATE_STREAMED; i++)
        if (gather(f, i, rows[i], r->y0)) return -1;
    if (f->denoised_rgb) {
        int rgb[3];
        if (mcp_rgb_channels(r->denoised, rgb)) return -1;
        mcp__srgb8_bytes(r->denoised, rgb, 3, 1,
                         f->denoised_rgb + (size_t)r->y0 * f->width * 3);
    }
    return 0;
}

int
mcp__estimate_files_end(mcp__estimate_files *f, int failed)
{
    int rc = failed;
    for (int i = 0; i < f->begun; i++)
        if (mcp__exr_band_file_end(&f->files[i], rc != 0)) rc = 1;
    f->begun = 0;
    return rc ? -1 : 0;
}

void
mcp__estimate_files_free(mcp__estimate_files *f)
{
    free(f->denoised_rgb);
    f->denoised_rgb = NULL;
    for (int i = 0; i < MCP__ESTIMATE_STREAMED; i++) {
        mcp_image_free(f->gather[i]);
        f->gather[i] = NULL;
    }
    mcp_attrs_clear(&f->attrs);
}

/* Rows [y0, y1) of an image of each block's values (3 a block) by the blocks' labels. */
static void
block_rows(const int32_t *label, const float *values, int w, int y0, mcp_image *rows)
{
#pragma omp parallel for schedule(static)
    for (int y = 0; y < rows->height; y++)
        for (int x = 0; x < w; x++)
            memcpy(mcp_image_px(rows, x, y),
                   values + 3 * (size_t)label[(size_t)(y0 + y) * w + x],
                   3 * sizeof(float));
}

int
mcp__estimate_block_files(const mcp_estimate *e, const float *lambda,
                          const mcp__estimate_dir *o)
{
    enum { ROWS = 64, FILES = 2 };
    static const char *const names[FILES] = {"distribution.exr", "blocks_sure_rel.exr"};
    static const char *const channels[FILES][3] = {{"lambda.R", "lambda.G", "lambda.B"},
                                                   {"R", "G", "B"}};
    const int w = e->blocks->width, h = e->blocks->height;
    const mcp_write_options opt = mcp_write_defaults();
    char paths[FILES][4352];
    mcp__exr_band_file files[FILES];
    mcp_image *rows[FILES] = {NULL, NULL};
    int32_t *label = NULL;
    float *means = mcp__blocks_means(e->blocks, e->maps.sure_rel);
    const float *values[FILES] = {lambda, means};
    int begun = 0, rc = !means || mcp_blocks_label(e->blocks, &label);
    for (int f = 0; f < FILES && !rc; f++) {
        rc = mcp__estimate_path(o, names[f], paths[f], sizeof paths[f]) ||
             mcp_image_new(w, h < ROWS ? h : ROWS, 3, channels[f], &rows[f]) ||
             mcp__exr_band_file_begin(&files[f], paths[f], w, h, &opt);
        begun += !rc;
    }
    for (int y0 = 0; y0 < h && !rc; y0 += ROWS) {
        const int n = y0 + ROWS < h ? ROWS : h - y0;
        for (int f = 0; f < FILES && !rc; f++) {
            rows[f]->height = n;
            block_rows(label, values[f], w, y0, rows[f]);
            rc = mcp__exr_band_file_rows(&files[f], rows[f], y0);
        }
    }
    for (int f = 0; f < begun; f++)
        if (mcp__exr_band_file_end(&files[f], rc != 0)) rc = 1;
    for (int f = 0; f < FILES; f++)
        mcp_image_free(rows[f]);
    free(label);
    free(means);
    return rc ? -1 : 0;
}
