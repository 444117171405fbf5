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
 * floor, no joint features, no Rademacher probes, no groups).
 *
 * Streamed (mcp__error_maps_streamed, for `mcpost estimate` of a large EXR), the dump
 * too is read a band at a time (common/dump's mcp__dump_held), and of the maps only
 * those Alg. 1 reads whole are kept: F(X), SURE and Var[F] go to the caller band by
 * band, Var[F] pooled in the band. Pooling reads s2_pool rows above and below, so each
 * band's maps are made for those rows too, whose window sums are the whole image's
 * (common/core/stats.c adds a window's rows in one order whatever the image's extent). */
#include "internal.h"
#include "../common/dump/internal.h" /* the dump's rows as views, and held */

#include <mcpost/stats.h>

#include <stdlib.h>
#include <string.h>

/* The band working set's bound: probes, JVPs and F of a crop (12 bytes a pixel
 * each), and streamed, the band's own maps too (76 bytes a pixel): at 8K with gauss
 * bands of 128 rows (bands of 64 recompute twice the share of halo rows, 6% of the
 * whole command: docs/benchmarks.md, "The estimate in bands"). */
#define BAND_BYTES (256.0 * 1048576.0)
/* Bands only where the whole evaluation's probes and JVPs would take more. */
#define WHOLE_BYTES (1024.0 * 1048576.0)

int
mcp__estimate_band_rows(int W, int H, const mcp_denoiser *den,
                        const mcp_estimate_options *o, int streamed)
{
    const int halo = den->band_halo;
    if (halo <= 0 || den->pick || o->sure.metric == MCP_METRIC_RELSE_PERCEPTUAL ||
        o->variance_rademacher || o->probe_floor > 0 || o->sure.features)
        return 0;
    const int k = o->sure.n_probes;
    const char *env = getenv("MCPOST_ESTIMATE_BAND_ROWS");
    if (env && *env) {
        if (strcmp(env, "whole") == 0) return 0;
        const int n = atoi(env);
        if (n > 0) return n < H ? n : 0;
    }
    const double per_row = ((2.0 * k + 1) * 12.0 + (streamed ? 76.0 : 0.0)) * W;
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

/* A band's rows: [y0, y1) its own, [e0, e1) those its maps are made for (its own and,
 * streamed, the pooling's reach), [c0, c1) the crop it is evaluated on (those and the
 * denoiser's halo), all within the image; the dump d holds rows from lo. */
typedef struct band_rows {
    int y0, y1, e0, e1, c0, c1;
    const mcp_dump *d;
    int lo;
} band_rows;

/* What the streamed bands hand out and keep beside the maps. */
typedef struct streamed {
    const mcp__estimate_sink *sink;
    int pool;
    mcp_image *weights;
    int any_variance;
} streamed;

/* Rows [y0, y1) of a whole map from the band's own maps (rows from e0). */
static int
keep_rows(const mcp_image *band, const band_rows *b, mcp_image *whole)
{
    mcp_image *v = NULL;
    if (mcp__rows_view(band, b->y0 - b->e0, b->y1 - b->e0, &v)) return -1;
    copy_rows(v, 0, whole, b->y0, b->y1);
    mcp_image_free(v);
    return 0;
}

/* The streamed band's maps, made in L for rows [e0, e1): the whole ones kept, Var[F]
 * pooled, and the band's own rows handed out. */
static int
streamed_rows(const band_rows *b, const mcp_image *f, const mcp_estimate_options *o,
              mcp_error_maps *L, streamed *st, mcp_error_maps *m)
{
    const int W = f->width, H = m->sure_rel->height;
    mcp_image *vf = NULL, *vs = NULL, *vv = NULL, *vw = NULL;
    mcp_dump own = {0};
    int have_own = 0;
    int rc = keep_rows(L->sure_rel, b, m->sure_rel) ||
             keep_rows(L->var_rel, b, m->var_rel) ||
             keep_rows(L->sigma_rel, b, m->sigma_rel) ||
             mcp_pool_window(L->var, NULL, st->pool) ||
             mcp__rows_view(f, b->y0 - b->c0, b->y1 - b->c0, &vf) ||
             mcp__rows_view(L->sure, b->y0 - b->e0, b->y1 - b->e0, &vs) ||
             mcp__rows_view(L->var, b->y0 - b->e0, b->y1 - b->e0, &vv) ||
             mcp__rows_view(st->weights, b->y0, b->y1, &vw) ||
             !(have_own = !mcp__dump_rows_view(b->d, b->y0 - b->lo, b->y1 - b->lo, &own));
    if (!rc) {
        st->any_variance = st->any_variance || mcp__any_variance(own.var_of_mean);
        mcp__sampling_weights_rows(&own, vf,
                                   o->sampling.kind == MCP_SAMPLING_MC_SURE ? vs : vv,
                                   &o->sampling, vw);
        const mcp__estimate_rows r = {b->y0, b->y1, W, H, vf, vs, vv, &f->attrs};
        rc = st->sink && st->sink->rows ? st->sink->rows(st->sink->ctx, &r) : 0;
    }
    if (have_own) mcp__dump_rows_view_free(&own);
    mcp_image_free(vf);
    mcp_image_free(vs);
    mcp_image_free(vv);
    mcp_image_free(vw);
    return rc ? -1 : 0;
}

/* One band: its maps from the crop's evaluation, into m (whole) or, streamed (st), as
 * streamed_rows says. */
static int
band(const band_rows *b, const mcp_denoiser *den, const mcp_estimate_options *o,
     streamed *st, mcp_error_maps *m)
{
    const int k = o->sure.n_probes, W = b->d->color->width;
    mcp_dump crop = {0}, rows = {0};
    mcp_error_maps L = {.metric = m->metric};
    mcp_probe *probes = mcp_calloc((size_t)k, sizeof *probes);
    mcp_denoise_tangent *t = mcp_calloc((size_t)k, sizeof *t);
    mcp_image **jv = mcp_calloc((size_t)k, sizeof *jv), *f = NULL;
    mcp_image **eps_rows = mcp_calloc((size_t)k, sizeof *eps_rows);
    mcp_image **jv_rows = mcp_calloc((size_t)k, sizeof *jv_rows), *f_rows = NULL;
    int rc = -1;
    if (!probes || !t || !jv || !eps_rows || !jv_rows ||
        mcp__dump_rows_view(b->d, b->c0 - b->lo, b->c1 - b->lo, &crop) ||
        mcp__dump_rows_view(b->d, b->e0 - b->lo, b->e1 - b->lo, &rows))
        goto done;
    for (int j = 0; j < k; j++) {
        if (mcp__probe_gaussian_rows(&crop, b->c0, NULL, o->sure.seed, j, &probes[j]))
            goto done;
        t[j].color = probes[j].color;
    }
    mcp_denoise_input in = mcp_denoise_input_of(&crop);
    if (mcp__jvp(den, &in, t, k, o->sure.mc_sure, o->sure.fd_delta, &f, jv)) goto done;
    if (!f && den->apply(den, &in, &f)) {
        mcp_error_prefix("%s: ", den->name);
        goto done;
    }
    if (!st && !m->denoised && denoised_begin(f, W, m->sure->height, &m->denoised))
        goto done;
    const int r0 = b->e0 - b->c0, r1 = b->e1 - b->c0;
    if (mcp__rows_view(f, r0, r1, &f_rows)) goto done;
    for (int j = 0; j < k; j++)
        if (mcp__rows_view(probes[j].color, r0, r1, &eps_rows[j]) ||
            mcp__rows_view(jv[j], r0, r1, &jv_rows[j]))
            goto done;
    if (!st) {
        copy_rows(f, b->y0 - b->c0, m->denoised, b->y0, b->y1);
        rc = mcp__error_maps_rows(&rows, f_rows, (const mcp_image *const *)eps_rows,
                                  (const mcp_image *const *)jv_rows, k, b->y0, m);
    } else {
        rc = mcp__error_maps_begin(W, b->e1 - b->e0, m->metric, &L) ||
             mcp__error_maps_rows(&rows, f_rows, (const mcp_image *const *)eps_rows,
                                  (const mcp_image *const *)jv_rows, k, 0, &L) ||
             streamed_rows(b, f, o, &L, st, m);
    }
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
    mcp_error_maps_free(&L);
    mcp__dump_rows_view_free(&crop);
    mcp__dump_rows_view_free(&rows);
    return rc ? -1 : 0;
}

/* Band b's rows for the band starting at y0 of an image of height H. */
static band_rows
rows_of(int y0, int band_rows_n, int H, int halo, int pool)
{
    band_rows b;
    b.y0 = y0;
    b.y1 = y0 + band_rows_n < H ? y0 + band_rows_n : H;
    b.e0 = b.y0 - pool > 0 ? b.y0 - pool : 0;
    b.e1 = b.y1 + pool < H ? b.y1 + pool : H;
    b.c0 = b.e0 - halo > 0 ? b.e0 - halo : 0;
    b.c1 = b.e1 + halo < H ? b.e1 + halo : H;
    b.d = NULL;
    b.lo = 0;
    return b;
}

int
mcp__error_maps_in_bands(const mcp_dump *dump, const mcp_denoiser *den,
                         const mcp_estimate_options *o, int band_rows_n,
                         void (*progress)(void *ctx, double done), void *ctx,
                         mcp_error_maps *out)
{
    const int W = dump->color->width, H = dump->color->height, halo = den->band_halo;
    if (mcp__error_maps_begin(W, H, o->sure.metric, out)) return -1;
    for (int y0 = 0; y0 < H; y0 += band_rows_n) {
        band_rows b = rows_of(y0, band_rows_n, H, halo, 0);
        b.d = dump;
        if (band(&b, den, o, NULL, out)) {
            mcp_error_maps_free(out);
            return -1;
        }
        if (progress) progress(ctx, (double)b.y1 / H);
    }
    return 0;
}

/* SURE^r, Var^r and Σ̂^r of a w x h image, the maps kept whole when streamed. */
static int
kept_maps_begin(int w, int h, mcp_error_metric metric, mcp_error_maps *m)
{
    memset(m, 0, sizeof *m);
    m->metric = metric;
    if (mcp__image_new(w, h, 3, NULL, "relative SURE", &m->sure_rel) ||
        mcp__image_new(w, h, 3, NULL, "relative variance", &m->var_rel) ||
        mcp__image_new(w, h, 3, NULL, "relative input variance", &m->sigma_rel)) {
        mcp_error_maps_free(m);
        return -1;
    }
    return 0;
}

int
mcp__error_maps_streamed(mcp__dump_held *held, const mcp_denoiser *den,
                         const mcp_estimate_options *o, int band_rows_n, int pool,
                         const mcp__estimate_sink *sink,
                         void (*progress)(void *ctx, double done), void *ctx,
                         mcp_error_maps *out, mcp_image **weights, int *any_variance)
{
    *weights = NULL;
    *any_variance = 0;
    int W, H;
    mcp__dump_bands_size(held->in, &W, &H);
    const int halo = den->band_halo;
    streamed st = {.sink = sink, .pool = pool};
    if (kept_maps_begin(W, H, o->sure.metric, out) ||
        mcp__sampling_weights_begin(W, H, &st.weights))
        goto fail;
    for (int y0 = 0; y0 < H; y0 += band_rows_n) {
        band_rows b = rows_of(y0, band_rows_n, H, halo, pool);
        if (mcp__dump_held_rows(held, b.c0, b.c1)) goto fail;
        b.d = held->d;
        b.lo = held->lo;
        if (band(&b, den, o, &st, out)) goto fail;
        if (progress) progress(ctx, (double)b.y1 / H);
    }
    *weights = st.weights;
    *any_variance = st.any_variance;
    return 0;
fail:
    mcp_image_free(st.weights);
    mcp_error_maps_free(out);
    return -1;
}
