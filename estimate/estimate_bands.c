/* estimate_bands.c: the estimate's evaluation a band of rows at a time (issue 31,
 * memory bounded whatever the image size; docs/benchmarks.md, "The estimate's
 * evaluation in bands").
 *
 * Whole, the evaluation holds K probes, their K JVPs and F(X) at once: at 8K
 * (7680x4320) with gauss's four probes 3.6 GB beside the dump. A denoiser that reads
 * a bounded neighbourhood (band_halo rows above and below a pixel) gives a band's rows
 * from the band and its halo alone, so here each band is evaluated on those rows: its
 * probes drawn for the rows (mcp__probe_gaussian_rows: the whole probe's rows), F and
 * the JVPs of the crop, and the maps of the band's own rows (mcp__error_maps_rows).
 * The maps and F(X) are the whole image's, bit for bit (tests/estimate/
 * test_estimate_bands.c), and held whole as before; what the evaluation holds beyond
 * them is one band's crop. Only where that is exact: the metrics se and relse, a
 * denoiser that states its halo, Gaussian probes of the dump's own variance (no probe
 * floor, no joint features, no Rademacher probes, no groups). */
#include "internal.h"
#include "../common/dump/internal.h" /* the dump's rows as views */

#include <stdlib.h>
#include <string.h>

/* The band working set's bound: probes, JVPs and F of a crop (12 bytes a pixel
 * each). */
#define BAND_BYTES (256.0 * 1048576.0)
/* Bands only where the whole evaluation's probes and JVPs would take more. */
#define WHOLE_BYTES (1024.0 * 1048576.0)

int
mcp__estimate_band_rows(const mcp_dump *dump, const mcp_denoiser *den,
                        const mcp_estimate_options *o)
{
    const int halo = den->band_halo;
    if (halo <= 0 || den->pick || o->sure.metric == MCP_METRIC_RELSE_PERCEPTUAL ||
        o->variance_rademacher || o->probe_floor > 0 || o->sure.features)
        return 0;
    const int W = dump->color->width, H = dump->color->height, k = o->sure.n_probes;
    const char *env = getenv("MCPOST_ESTIMATE_BAND_ROWS");
    if (env && *env) {
        if (strcmp(env, "whole") == 0) return 0;
        const int n = atoi(env);
        if (n > 0) return n < H ? n : 0;
    }
    const double per_row = (2.0 * k + 1) * 12.0 * W;
    if (2.0 * k * 12.0 * W * (double)H <= WHOLE_BYTES) return 0;
    const int rows = (int)(BAND_BYTES / per_row) - 2 * halo;
    return rows >= 16 && rows < H ? rows : 0;
}

/* F(X) whole, its header (names, source, attributes) from the first band's. */
static int
denoised_begin(const mcp_image *first, int W, int H, mcp_image **out)
{
    if (mcp_image_new(W, H, first->channels, (const char *const *)first->names, out))
        return -1;
    if (mcp_image_set_source(*out, first->source) ||
        mcp_attrs_copy(&first->attrs, &(*out)->attrs)) {
        mcp_image_free(*out);
        *out = NULL;
        return -1;
    }
    return 0;
}

/* Rows [y0, y1) of dst from src's rows starting at sy. */
static void
copy_rows(const mcp_image *src, int sy, mcp_image *dst, int y0, int y1)
{
    const size_t n = (size_t)dst->width * dst->channels * sizeof(float);
    for (int y = y0; y < y1; y++)
        memcpy(mcp_image_px(dst, 0, y), mcp_image_px(src, 0, sy + y - y0), n);
}

/* One band: rows [y0, y1), evaluated on the crop [c0, c1). */
static int
band(const mcp_dump *dump, const mcp_denoiser *den, const mcp_estimate_options *o, int y0,
     int y1, int c0, int c1, mcp_error_maps *m)
{
    const int k = o->sure.n_probes;
    mcp_dump crop = {0}, rows = {0};
    mcp_probe *probes = mcp_calloc((size_t)k, sizeof *probes);
    mcp_denoise_tangent *t = mcp_calloc((size_t)k, sizeof *t);
    mcp_image **jv = mcp_calloc((size_t)k, sizeof *jv), *f = NULL;
    mcp_image **eps_rows = mcp_calloc((size_t)k, sizeof *eps_rows);
    mcp_image **jv_rows = mcp_calloc((size_t)k, sizeof *jv_rows), *f_rows = NULL;
    int rc = -1;
    if (!probes || !t || !jv || !eps_rows || !jv_rows ||
        mcp__dump_rows_view(dump, c0, c1, &crop) ||
        mcp__dump_rows_view(dump, y0, y1, &rows))
        goto done;
    for (int j = 0; j < k; j++) {
        if (mcp__probe_gaussian_rows(&crop, c0, NULL, o->sure.seed, j, &probes[j]))
            goto done;
        t[j].color = probes[j].color;
    }
    mcp_denoise_input in = mcp_denoise_input_of(&crop);
    if (mcp__jvp(den, &in, t, k, o->sure.mc_sure, o->sure.fd_delta, &f, jv)) goto done;
    if (!f && den->apply(den, &in, &f)) {
        mcp_error_prefix("%s: ", den->name);
        goto done;
    }
    if (!m->denoised &&
        denoised_begin(f, dump->color->width, dump->color->height, &m->denoised))
        goto done;
    if (mcp__rows_view(f, y0 - c0, y1 - c0, &f_rows)) goto done;
    for (int j = 0; j < k; j++)
        if (mcp__rows_view(probes[j].color, y0 - c0, y1 - c0, &eps_rows[j]) ||
            mcp__rows_view(jv[j], y0 - c0, y1 - c0, &jv_rows[j]))
            goto done;
    copy_rows(f, y0 - c0, m->denoised, y0, y1);
    rc = mcp__error_maps_rows(&rows, f_rows, (const mcp_image *const *)eps_rows,
                              (const mcp_image *const *)jv_rows, k, y0, m);
done:
    for (int j = 0; j < k; j++) {
        if (probes) mcp_probe_clear(&probes[j]);
        if (jv) mcp_image_free(jv[j]);
        if (eps_rows) mcp_image_free(eps_rows[j]);
        if (jv_rows) mcp_image_free(jv_rows[j]);
    }
    free(probes);
    free(t);
    free(jv);
    free(eps_rows);
    free(jv_rows);
    mcp_image_free(f);
    mcp_image_free(f_rows);
    mcp__dump_rows_view_free(&crop);
    mcp__dump_rows_view_free(&rows);
    return rc;
}

int
mcp__error_maps_in_bands(const mcp_dump *dump, const mcp_denoiser *den,
                         const mcp_estimate_options *o, int band_rows,
                         void (*progress)(void *ctx, double done), void *ctx,
                         mcp_error_maps *out)
{
    const int W = dump->color->width, H = dump->color->height, halo = den->band_halo;
    if (mcp__error_maps_begin(W, H, o->sure.metric, out)) return -1;
    for (int y0 = 0; y0 < H; y0 += band_rows) {
        const int y1 = y0 + band_rows < H ? y0 + band_rows : H;
        const int c0 = y0 - halo > 0 ? y0 - halo : 0, c1 = y1 + halo < H ? y1 + halo : H;
        if (band(dump, den, o, y0, y1, c0, c1, out)) {
            mcp_error_maps_free(out);
            return -1;
        }
        if (progress) progress(ctx, (double)y1 / H);
    }
    return 0;
}
