/* render.c: Monte Carlo rendering of the procedural scene from per-pixel random
 * streams, optionally with permuted seeds (docs/mathematics.md §4.9:
 * a renderer re-renders pixel p with pixel pi(p)'s seed), with independent or
 * jittered (stratified) footprint points.
 *
 * Every random number is a hash of (seed, source pixel, sample index, dimension), so a
 * pixel's estimate depends on nothing else: not on the other pixels, the order of
 * work or the thread count. The jittered sampler only moves the footprint point into
 * the cell that the sample index names, so it needs no state either. */
#include "internal.h"

#include "../../common/core/rng_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

/* Dimensions per sample: footprint (2), then the shading dimensions. */
#define DIMS (2 + MCP__PROC_SHADE_DIMS)

/* The key of one pixel's stream. */
static uint64_t
stream_key(uint64_t seed, uint64_t src_index)
{
    return mcp__mix64(mcp__mix64(seed + MCP__SPLITMIX64_GAMMA) ^
                      (src_index * 0xd1b54a32d192ed03u));
}

/* Uniform in [0, 1) with 53 random bits. */
static inline double
stream_uniform(uint64_t key, uint64_t sample, int dim)
{
    uint64_t h =
        mcp__mix64(key ^ mcp__mix64(sample * DIMS + (uint64_t)dim + 0x632be59bd9b4e019u));
    return (double)(h >> 11) * 0x1.0p-53;
}

typedef struct {
    double mean[3], m2[3]; /* Welford: running mean and sum of squared deviations */
    double albedo[3];
    long n;
    double half_sum[3]; /* the samples of class A (sample_in_half) */
    long half_n;
} accum;

/* Whether sample s is in the half buffer ("class A") that a renderer's stopping rule
 * compares with the full mean (docs/adaptive.md, "The renderers' own rule"). The
 * class should itself be as well spread over the pixel as the sampler allows: with
 * the independent sampler every other sample; with the jittered one, within a pass of
 * k^2, the cells of one colour of a checkerboard, the colour alternating from pass to
 * pass, so that two passes put exactly one class-A sample in every cell. One formula
 * does both: k = 1 has a single cell and a pass per sample. */
static inline int
sample_in_half(uint64_t s, int k)
{
    uint64_t pass = (uint64_t)k * (uint64_t)k, cell = s % pass;
    return ((cell % (uint64_t)k) + (cell / (uint64_t)k) + s / pass) % 2 == 0;
}

/* Samples [first, first + n) of stream key, for pixel (x, y). */
static void
render_into(const mcp__proc_geom *g, int x, int y, uint64_t key, uint64_t first, long n,
            accum *a)
{
    const int k = g->strata;
    const uint64_t pass = (uint64_t)k * (uint64_t)k;
    *a = (accum){0};
    for (long i = 0; i < n; i++) {
        uint64_t s = first + (uint64_t)i;
        double u[DIMS];
        for (int d = 0; d < DIMS; d++)
            u[d] = stream_uniform(key, s, d);
        if (k > 1) {
            /* Jittered: sample s is number s mod k^2 of its pass and lies in that cell
             * (row-major) of the k x k grid, at the same uniforms scaled into it. The
             * independent sampler (k = 1) keeps u[0], u[1] untouched, bit for bit. */
            uint64_t cell = s % pass;
            u[0] = ((double)(cell % (uint64_t)k) + u[0]) / k;
            u[1] = ((double)(cell / (uint64_t)k) + u[1]) / k;
        }
        mcp__proc_hit h;
        double rgb[3], alb[3];
        mcp__proc_hit_at(g, x + u[0], y + u[1], &h);
        mcp__proc_shade_sample(g, &h, u + 2, rgb);
        mcp__proc_albedo(&h, alb);
        a->n++;
        for (int c = 0; c < 3; c++) {
            double delta = rgb[c] - a->mean[c];
            a->mean[c] += delta / a->n;
            a->m2[c] += delta * (rgb[c] - a->mean[c]);
            a->albedo[c] += (alb[c] - a->albedo[c]) / a->n;
        }
        if (sample_in_half(s, k)) {
            a->half_n++;
            for (int c = 0; c < 3; c++)
                a->half_sum[c] += rgb[c];
        }
    }
}

/* The source pixel index of every pixel: the pixel itself, or the permutation map's
 * (X, Y). *out is malloc'd. */
static int
source_indices(const mcp__proc_geom *g, const mcp_image *perm, uint64_t **out)
{
    size_t npix = (size_t)g->width * (size_t)g->height;
    *out = NULL;
    uint64_t *src = mcp_malloc(npix * sizeof *src);
    if (!src) return -1;
    if (!perm) {
        for (size_t i = 0; i < npix; i++)
            src[i] = i;
        *out = src;
        return 0;
    }
    int xy[2];
    if (mcp_image_channels(perm, (const char *const[]){"X", "Y"}, 2, xy)) goto fail;
    if (perm->width != g->width || perm->height != g->height) {
        mcp_error("%s: permutation size %dx%d does not match the image (%dx%d)",
                  perm->source ? perm->source : "permutation", perm->width, perm->height,
                  g->width, g->height);
        goto fail;
    }
    for (int y = 0; y < g->height; y++)
        for (int x = 0; x < g->width; x++) {
            const float *p = mcp_image_px(perm, x, y);
            double sx = p[xy[0]], sy = p[xy[1]];
            if (!(sx >= 0 && sx < g->width && sy >= 0 && sy < g->height) ||
                sx != floor(sx) || sy != floor(sy)) {
                mcp_error("%s: pixel (%d, %d) has source (%g, %g), not a pixel of the "
                          "%dx%d image",
                          perm->source ? perm->source : "permutation", x, y, sx, sy,
                          g->width, g->height);
                goto fail;
            }
            src[(size_t)y * g->width + x] = (uint64_t)sy * g->width + (uint64_t)sx;
        }
    *out = src;
    return 0;
fail:
    free(src);
    return -1;
}

static int
new_rgb(const mcp__proc_geom *g, const char *const *names, const char *source,
        mcp_image **out)
{
    static const char *const rgb[3] = {"R", "G", "B"};
    if (mcp_image_new(g->width, g->height, 3, names ? names : rgb, out)) return -1;
    if (mcp_image_set_source(*out, source)) {
        mcp_image_free(*out);
        *out = NULL;
        return -1;
    }
    return 0;
}

/* ---- public ---- */

uint64_t
mcp_proc_realization_seed(uint64_t seed, int realization)
{
    if (realization == 0) return seed;
    return mcp__mix64(seed ^ mcp__mix64((uint64_t)realization * 0xa0761d6478bd642fu));
}

int
mcp_proc_render(const mcp_proc_scene *scene, int spp, uint64_t seed,
                const mcp_image *permutation, mcp_dump **out)
{
    static const char *const xyz[3] = {"X", "Y", "Z"};
    mcp__proc_geom g;
    uint64_t *src = NULL;
    mcp_dump *d = NULL;
    char label[96];
    *out = NULL;
    if (mcp__proc_geom_init(scene, &g)) return -1;
    if (spp < 1) return mcp_error("procedural: spp must be >= 1 (got %d)", spp);
    if (mcp__proc_check_passes(&g, "spp", (uint64_t)spp)) return -1;
    snprintf(label, sizeof label, "procedural(seed %llu, %d spp)",
             (unsigned long long)seed, spp);
    if (source_indices(&g, permutation, &src) || !(d = mcp_calloc(1, sizeof *d)) ||
        new_rgb(&g, NULL, label, &d->color) ||
        new_rgb(&g, NULL, label, &d->var_of_mean) ||
        new_rgb(&g, NULL, label, &d->albedo) || new_rgb(&g, xyz, label, &d->normal) ||
        !(d->source = mcp_strdup(label)))
        goto fail;
    char text[32];
    snprintf(text, sizeof text, "%llu", (unsigned long long)seed);
    if (mcp_attrs_set_string(&d->attrs, "mcpost.procedural.seed", text)) goto fail;
    /* Tells a reader of the file that its variance overstates the variance of the
     * mean; left out for the independent sampler, whose files stay as they were. */
    snprintf(text, sizeof text, "jittered %dx%d", g.strata, g.strata);
    if (scene->sampler == MCP_PROC_SAMPLER_JITTERED &&
        mcp_attrs_set_string(&d->attrs, "mcpost.procedural.sampler", text))
        goto fail;
    d->spp = spp;
    d->convention = MCP_CONV_PBRT;
    d->variance_in_file = MCP_VAR_PER_SAMPLE; /* as it will be written */

#pragma omp parallel for schedule(dynamic)
    for (int y = 0; y < g.height; y++)
        for (int x = 0; x < g.width; x++) {
            accum a;
            uint64_t key = stream_key(seed, src[(size_t)y * g.width + x]);
            render_into(&g, x, y, key, 0, spp, &a);
            float *col = mcp_image_px(d->color, x, y),
                  *var = mcp_image_px(d->var_of_mean, x, y);
            float *alb = mcp_image_px(d->albedo, x, y),
                  *nrm = mcp_image_px(d->normal, x, y);
            for (int c = 0; c < 3; c++) {
                col[c] = (float)a.mean[c];
                /* unbiased per-sample variance, over n for the variance of the mean */
                var[c] = spp > 1 ? (float)(a.m2[c] / (spp - 1) / spp) : 0.0f;
                alb[c] = (float)a.albedo[c];
            }
            /* both surfaces are horizontal and seen from above */
            nrm[0] = 0.0f, nrm[1] = 1.0f, nrm[2] = 0.0f;
        }
    free(src);
    *out = d;
    return 0;
fail:
    free(src);
    mcp_dump_free(d);
    return -1;
}

int
mcp_proc_render_samples(const mcp_proc_scene *scene, int count, int spp, uint64_t seed,
                        const mcp_image *permutation, mcp_image **out)
{
    mcp__proc_geom g;
    uint64_t *src = NULL;
    if (count < 1) return mcp_error("procedural: count must be >= 1 (got %d)", count);
    for (int k = 0; k < count; k++)
        out[k] = NULL;
    if (mcp__proc_geom_init(scene, &g)) return -1;
    if (spp < 1) return mcp_error("procedural: spp must be >= 1 (got %d)", spp);
    if (mcp__proc_check_passes(&g, "spp", (uint64_t)spp) ||
        source_indices(&g, permutation, &src))
        return -1;
    for (int k = 0; k < count; k++) {
        char label[96];
        snprintf(label, sizeof label, "procedural(seed %llu, samples %d of %d spp)",
                 (unsigned long long)seed, k, spp);
        if (new_rgb(&g, NULL, label, &out[k])) goto fail;
    }
#pragma omp parallel for schedule(dynamic)
    for (int y = 0; y < g.height; y++)
        for (int x = 0; x < g.width; x++) {
            uint64_t key = stream_key(seed, src[(size_t)y * g.width + x]);
            for (int k = 0; k < count; k++) {
                accum a;
                render_into(&g, x, y, key, (uint64_t)k * (uint64_t)spp, spp, &a);
                float *col = mcp_image_px(out[k], x, y);
                for (int c = 0; c < 3; c++)
                    col[c] = (float)a.mean[c];
            }
        }
    free(src);
    return 0;
fail:
    free(src);
    for (int k = 0; k < count; k++) {
        mcp_image_free(out[k]);
        out[k] = NULL;
    }
    return -1;
}

int
mcp_proc_render_pixel(const mcp_proc_scene *scene, int x, int y, int src_x, int src_y,
                      int spp, uint64_t seed, uint64_t first_sample, mcp_proc_pixel *out)
{
    mcp__proc_geom g;
    if (mcp__proc_geom_init(scene, &g)) return -1;
    if (spp < 1) return mcp_error("procedural: spp must be >= 1 (got %d)", spp);
    if (x < 0 || x >= g.width || y < 0 || y >= g.height || src_x < 0 ||
        src_x >= g.width || src_y < 0 || src_y >= g.height)
        return mcp_error("procedural: pixel (%d, %d) or source (%d, %d) outside the "
                         "%dx%d image",
                         x, y, src_x, src_y, g.width, g.height);
    if (mcp__proc_check_passes(&g, "spp", (uint64_t)spp) ||
        mcp__proc_check_passes(&g, "first_sample", first_sample))
        return -1;
    accum a;
    uint64_t src = (uint64_t)src_y * g.width + (uint64_t)src_x;
    render_into(&g, x, y, stream_key(seed, src), first_sample, spp, &a);
    for (int c = 0; c < 3; c++) {
        out->mean[c] = a.mean[c];
        out->var_per_sample[c] = spp > 1 ? a.m2[c] / (spp - 1) : 0.0;
        out->albedo[c] = a.albedo[c];
    }
    return 0;
}

/* The count of every pixel from a count map, checked: a whole, non-negative number of
 * the sampler's passes. *out is malloc'd. */
static int
pixel_counts(const mcp__proc_geom *g, const mcp_image *counts, long **out)
{
    const char *src = counts->source ? counts->source : "sample counts";
    *out = NULL;
    if (counts->width != g->width || counts->height != g->height)
        return mcp_error("%s: size %dx%d does not match the image (%dx%d)", src,
                         counts->width, counts->height, g->width, g->height);
    int ch = mcp_image_channel(counts, "SampleCount");
    if (ch < 0 && counts->channels == 1) ch = 0;
    if (ch < 0)
        return mcp_error("%s: no channel 'SampleCount' (and more than one channel)", src);
    size_t npix = (size_t)g->width * (size_t)g->height;
    long *n = mcp_malloc(npix * sizeof *n);
    if (!n) return -1;
    for (int y = 0; y < g->height; y++)
        for (int x = 0; x < g->width; x++) {
            double v = mcp_image_px(counts, x, y)[ch];
            if (!(v >= 0 && v <= (double)(1 << 30)) || v != floor(v)) {
                free(n);
                return mcp_error("%s: pixel (%d, %d) has count %g, not a whole number "
                                 "in [0, 2^30]",
                                 src, x, y, v);
            }
            n[(size_t)y * g->width + x] = (long)v;
            if (mcp__proc_check_passes(g, "a pixel's count", (uint64_t)v)) {
                free(n);
                return mcp_error_prefix("%s: pixel (%d, %d): ", src, x, y);
            }
        }
    *out = n;
    return 0;
}

/* mcp_proc_render_counts, and the half buffer when half is not NULL. */
static int
render_counts(const mcp_proc_scene *scene, const mcp_image *counts, int pass,
              uint64_t seed, mcp_dump **out, mcp_image **half)
{
    static const char *const half_names[4] = {"R", "G", "B", "SampleCount"};
    static const char *const xyz[3] = {"X", "Y", "Z"};
    mcp__proc_geom g;
    long *n = NULL;
    mcp_dump *d = NULL;
    char label[96], text[32];
    *out = NULL;
    if (half) *half = NULL;
    if (mcp__proc_geom_init(scene, &g)) return -1;
    if (!counts) return mcp_error("procedural: missing sample counts");
    if (pass < 0) return mcp_error("procedural: pass must be >= 0 (got %d)", pass);
    if (pixel_counts(&g, counts, &n)) return -1;
    snprintf(label, sizeof label, "procedural(seed %llu, pass %d)",
             (unsigned long long)seed, pass);
    static const char *const count_name[1] = {"SampleCount"};
    if (!(d = mcp_calloc(1, sizeof *d)) || new_rgb(&g, NULL, label, &d->color) ||
        new_rgb(&g, NULL, label, &d->var_of_mean) ||
        new_rgb(&g, NULL, label, &d->albedo) || new_rgb(&g, xyz, label, &d->normal) ||
        mcp_image_new(g.width, g.height, 1, count_name, &d->spp_map) ||
        !(d->source = mcp_strdup(label)))
        goto fail;
    if (half && (mcp_image_new(g.width, g.height, 4, half_names, half) ||
                 mcp_image_set_source(*half, label)))
        goto fail;
    snprintf(text, sizeof text, "%llu", (unsigned long long)seed);
    if (mcp_attrs_set_string(&d->attrs, "mcpost.procedural.seed", text)) goto fail;
    snprintf(text, sizeof text, "%d", pass);
    if (mcp_attrs_set_string(&d->attrs, "mcpost.procedural.pass", text)) goto fail;
    snprintf(text, sizeof text, "jittered %dx%d", g.strata, g.strata);
    if (scene->sampler == MCP_PROC_SAMPLER_JITTERED &&
        mcp_attrs_set_string(&d->attrs, "mcpost.procedural.sampler", text))
        goto fail;
    d->spp = 0;
    d->convention = MCP_CONV_MCPOST;
    d->variance_in_file = MCP_VAR_PER_SAMPLE; /* as it will be written */
    d->variance_source = MCP_VARSRC_PER_SAMPLE;
    const uint64_t first = (uint64_t)pass * MCP_PROC_PASS_STRIDE;

#pragma omp parallel for schedule(dynamic)
    for (int y = 0; y < g.height; y++)
        for (int x = 0; x < g.width; x++) {
            size_t i = (size_t)y * g.width + x;
            accum a;
            render_into(&g, x, y, stream_key(seed, i), first, n[i], &a);
            float *col = mcp_image_px(d->color, x, y),
                  *var = mcp_image_px(d->var_of_mean, x, y);
            float *alb = mcp_image_px(d->albedo, x, y),
                  *nrm = mcp_image_px(d->normal, x, y);
            for (int c = 0; c < 3; c++) {
                col[c] = (float)a.mean[c];
                var[c] = n[i] > 1 ? (float)(a.m2[c] / (n[i] - 1) / n[i]) : 0.0f;
                alb[c] = (float)a.albedo[c];
            }
            nrm[0] = 0.0f, nrm[1] = 1.0f, nrm[2] = 0.0f;
            mcp_image_px(d->spp_map, x, y)[0] = (float)n[i];
            if (half) {
                float *h = mcp_image_px(*half, x, y);
                for (int c = 0; c < 3; c++)
                    h[c] = a.half_n > 0 ? (float)(a.half_sum[c] / a.half_n) : 0.0f;
                h[3] = (float)a.half_n;
            }
        }
    free(n);
    *out = d;
    return 0;
fail:
    free(n);
    mcp_dump_free(d);
    if (half) {
        mcp_image_free(*half);
        *half = NULL;
    }
    return -1;
}

int
mcp_proc_render_counts(const mcp_proc_scene *scene, const mcp_image *counts, int pass,
                       uint64_t seed, mcp_dump **out)
{
    return render_counts(scene, counts, pass, seed, out, NULL);
}

int
mcp_proc_render_counts_half(const mcp_proc_scene *scene, const mcp_image *counts,
                            int pass, uint64_t seed, mcp_dump **out, mcp_image **half)
{
    if (!half) return mcp_error("procedural: missing the half buffer's output");
    return render_counts(scene, counts, pass, seed, out, half);
}
