/* dump.c: render dumps -- recognising renderer conventions, loading, checking and
 * writing them (see dump.h; the conventions are in docs/conventions.md). */
#define _POSIX_C_SOURCE 200809L
#include <mcpost/dump.h>

#include "internal.h"
#include "../io/internal.h"
#include <mcpost/imageio.h>

#include <ctype.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* ---- names of things ---- */

#define COUNT(a) ((int)(sizeof(a) / sizeof *(a)))

static const char *const convention_names[] = {"auto",    "pbrt",   "mitsuba",
                                               "blender", "mcpost", "plain"};

const char *
mcp_convention_name(mcp_convention c)
{
    return (unsigned)c < (unsigned)COUNT(convention_names) ? convention_names[c]
                                                           : "unknown";
}

const mcp_wordlist mcp_convention_words = {"convention", convention_names,
                                           (int)COUNT(convention_names)};

int
mcp_convention_from_name(const char *name, mcp_convention *out)
{
    return mcp_wordlist_find(&mcp_convention_words, name, (int *)out);
}

static const char *const variance_kind_names[] = {"default", "per-sample", "of-mean"};
const mcp_wordlist mcp_variance_kind_words = {"variance semantics", variance_kind_names,
                                              3};

int
mcp_variance_kind_from_name(const char *name, mcp_variance_kind *out)
{
    return mcp_wordlist_find(&mcp_variance_kind_words, name, (int *)out);
}

static const char *const variance_source_names[] = {
    "none", "per-sample", "of-mean", "replicates", "increments", "xyz-moments"};
const mcp_wordlist mcp_variance_source_words = {"variance source", variance_source_names,
                                                (int)COUNT(variance_source_names)};

const char *
mcp_variance_source_name(mcp_variance_source s)
{
    return (unsigned)s < (unsigned)COUNT(variance_source_names) ? variance_source_names[s]
                                                                : "?";
}

int
mcp_variance_source_from_name(const char *name, mcp_variance_source *out)
{
    return mcp_wordlist_find(&mcp_variance_source_words, name, (int *)out);
}

/* The header attributes that carry a dump's variance source through a file. */
#define ATTR_VARIANCE_SOURCE "mcpost:varianceSource"
#define ATTR_VARIANCE_DOF "mcpost:varianceDof"
#define ATTR_REPLICATES "mcpost:replicates"
#define ATTR_VARIANCE_POOL "mcpost:variancePool"

static double
attr_number(const mcp_attrs *attrs, const char *name)
{
    const mcp_attr *a = mcp_attrs_find(attrs, name);
    if (!a) return 0;
    return a->type == MCP_ATTR_INT ? (double)a->i : a->type == MCP_ATTR_STRING ? 0 : a->f;
}

/* Where the variance came from: the header's word when mcpost wrote the file (and
 * the file has a variance), else what the convention stored. */
static void
read_variance_source(mcp_dump *d)
{
    d->variance_source = !d->var_of_mean ? MCP_VARSRC_NONE
                         : d->variance_in_file == MCP_VAR_PER_SAMPLE
                             ? MCP_VARSRC_PER_SAMPLE
                             : MCP_VARSRC_OF_MEAN;
    const mcp_attr *a = mcp_attrs_find(&d->attrs, ATTR_VARIANCE_SOURCE);
    mcp_variance_source s;
    if (!d->var_of_mean || !a || a->type != MCP_ATTR_STRING ||
        mcp_variance_source_from_name(a->s, &s)) {
        mcp_error_clear();
        return;
    }
    d->variance_source = s;
    d->variance_dof = attr_number(&d->attrs, ATTR_VARIANCE_DOF);
    d->replicates = (int)attr_number(&d->attrs, ATTR_REPLICATES);
    d->variance_pool = attr_number(&d->attrs, ATTR_VARIANCE_POOL);
}

static const char *const badval_names[] = {"fail", "zero"};
const mcp_wordlist mcp_badval_policy_words = {"bad-value policy", badval_names, 2};

int
mcp_badval_policy_from_name(const char *name, mcp_badval_policy *out)
{
    return mcp_wordlist_find(&mcp_badval_policy_words, name, (int *)out);
}

mcp_dump_spec
mcp_dump_spec_defaults(void)
{
    mcp_dump_spec s;
    memset(&s, 0, sizeof s);
    return s;
}

/* ---- detection ---- */

/* The Blender view-layer prefix ("ViewLayer" in "ViewLayer.Combined.R"), or NULL. */
static char *
blender_layer(const mcp_image *img)
{
    for (int c = 0; c < img->channels; c++) {
        const char *at = strstr(img->names[c], ".Combined.R");
        if (at && at[strlen(".Combined.R")] == '\0') {
            size_t n = (size_t)(at - img->names[c]);
            char *layer = mcp_malloc(n + 1);
            if (layer) {
                memcpy(layer, img->names[c], n);
                layer[n] = '\0';
            }
            return layer;
        }
    }
    return NULL;
}

static int
has(const mcp_image *img, const char *name)
{
    return mcp_image_channel(img, name) >= 0;
}

static int
contains_ci(const char *s, const char *needle)
{
    size_t n = strlen(needle);
    for (; *s; s++)
        if (strncasecmp(s, needle, n) == 0) return 1;
    return 0;
}

/* The prefix P of the first triple P.<s0>, P.<s1>, P.<s2> whose P contains `word`
 * (case-insensitive); written into buf. */
static int
find_triple(const mcp_image *img, const char *word, const char *const sfx[3], char *buf,
            size_t cap)
{
    for (int c = 0; c < img->channels; c++) {
        const char *name = img->names[c], *dot = strrchr(name, '.');
        if (!dot || strcmp(dot + 1, sfx[0]) != 0) continue;
        int plen = (int)(dot - name);
        snprintf(buf, cap, "%.*s", plen, name);
        /* a Mitsuba moment integrator's second-moment twin is no feature */
        if (strncmp(buf, "m2_", 3) == 0) continue;
        const char *last = strrchr(buf, '.');
        last = last ? last + 1 : buf;
        /* "nn" is the shading normal in Mitsuba 3's own aov example ("nn:sh_normal") */
        if (!contains_ci(buf, word) &&
            !(strcmp(word, "normal") == 0 && strcmp(last, "nn") == 0))
            continue;
        char other[512];
        int ok = 1;
        for (int k = 1; k < 3; k++) {
            snprintf(other, sizeof other, "%s.%s", buf, sfx[k]);
            ok &= has(img, other);
        }
        if (ok) return 1;
    }
    return 0;
}

/* Mitsuba 3's moment integrator: for each nested integrator NAME it writes the
 * sample's colour in CIE XYZ as NAME.X/Y/Z and its second moment as m2_NAME.X/Y/Z
 * (the nested integrator's own AOVs are NAME.<aov>.*, with a dot in their prefix).
 * The first such NAME (channel order) goes into buf. */
static int
find_moment_prefix(const mcp_image *img, char *buf, size_t cap)
{
    static const char *const xyz[3] = {"X", "Y", "Z"};
    for (int c = 0; c < img->channels; c++) {
        const char *name = img->names[c], *dot = strrchr(name, '.');
        if (strncmp(name, "m2_", 3) != 0 || !dot || strcmp(dot + 1, "X") != 0) continue;
        int plen = (int)(dot - name) - 3;
        if (plen <= 0 || memchr(name + 3, '.', (size_t)plen)) continue;
        snprintf(buf, cap, "%.*s", plen, name + 3);
        char other[600];
        int ok = 1;
        for (int k = 0; k < 3; k++) {
            snprintf(other, sizeof other, "%s.%s", buf, xyz[k]);
            ok &= has(img, other);
            snprintf(other, sizeof other, "m2_%s.%s", buf, xyz[k]);
            ok &= has(img, other);
        }
        if (ok) return 1;
    }
    return 0;
}

mcp_convention
mcp_dump_detect(const mcp_image *img)
{
    char moment[512];
    char *layer = blender_layer(img);
    if (layer) {
        free(layer);
        return MCP_CONV_BLENDER;
    }
    const mcp_attr *gen = mcp_attrs_find(&img->attrs, "generatedBy");
    if (has(img, "m2_R") || find_moment_prefix(img, moment, sizeof moment) ||
        (gen && gen->type == MCP_ATTR_STRING && strstr(gen->s, "Mitsuba")))
        return MCP_CONV_MITSUBA;
    if (has(img, "Covariance.RG") || has(img, "SampleCount")) return MCP_CONV_MCPOST;
    if (has(img, "Variance.R") || has(img, "Albedo.R") || has(img, "N.X") ||
        mcp_attrs_find(&img->attrs, "samplesPerPixel"))
        return MCP_CONV_PBRT;
    char buf[512];
    static const char *const rgb[3] = {"R", "G", "B"}, *const xyz[3] = {"X", "Y", "Z"};
    if (find_triple(img, "albedo", rgb, buf, sizeof buf) ||
        find_triple(img, "normal", xyz, buf, sizeof buf))
        return MCP_CONV_MITSUBA;
    return MCP_CONV_PLAIN;
}

/* ---- the channel layout of one convention ---- */

/* Three channel names (colour R,G,B or normal X,Y,Z). */
typedef struct name3 {
    char c[3][512];
} name3;

typedef struct layout {
    name3 color, var, m2, cov, albedo, normal, xyz;
    int has_var, has_m2, has_cov, has_albedo, has_normal;
    int has_xyz;        /* m2 holds Mitsuba 3's XYZ second moments, xyz their mean */
    int color_from_xyz; /* no R,G,B: the mean colour is the XYZ mean in linear sRGB */
    mcp_variance_kind var_kind;
    double spp; /* from the header, 0 if none */
    char spp_channel[64];
} layout;

static void
set3(name3 *dst, const char *prefix, const char *const sfx[3])
{
    for (int k = 0; k < 3; k++)
        snprintf(dst->c[k], sizeof dst->c[k], "%s%s", prefix, sfx[k]);
}

static int
has3(const mcp_image *img, const name3 *names)
{
    return has(img, names->c[0]) && has(img, names->c[1]) && has(img, names->c[2]);
}

static double
header_spp(const mcp_image *img, const char *blender_layer_name)
{
    static const char *keys[] = {"samplesPerPixel", "spp", "samples"};
    for (size_t i = 0; i < sizeof keys / sizeof *keys; i++) {
        const mcp_attr *a = mcp_attrs_find(&img->attrs, keys[i]);
        if (a && a->type != MCP_ATTR_STRING) return a->f;
    }
    if (blender_layer_name) {
        char key[600];
        snprintf(key, sizeof key, "cycles.%s.samples", blender_layer_name);
        const mcp_attr *a = mcp_attrs_find(&img->attrs, key);
        if (a && a->type == MCP_ATTR_STRING) return atof(a->s);
    }
    return 0;
}

static int
layout_for(const mcp_image *img, mcp_convention conv, layout *L)
{
    static const char *const rgb[3] = {"R", "G", "B"}, *const xyz[3] = {"X", "Y", "Z"},
                             *const offdiag[3] = {"RG", "RB", "GB"};
    char prefix[600];
    memset(L, 0, sizeof *L);
    L->var_kind = MCP_VAR_PER_SAMPLE;
    switch (conv) {
    case MCP_CONV_BLENDER: {
        char *layer = blender_layer(img);
        if (!layer)
            return mcp_error("%s: no Blender '<layer>.Combined.R' channels", img->source);
        snprintf(prefix, sizeof prefix, "%s.Combined.", layer);
        set3(&L->color, prefix, rgb);
        snprintf(prefix, sizeof prefix, "%s.Variance.", layer);
        set3(&L->var, prefix, rgb);
        snprintf(prefix, sizeof prefix, "%s.Denoising Albedo.", layer);
        set3(&L->albedo, prefix, rgb);
        snprintf(prefix, sizeof prefix, "%s.Denoising Normal.", layer);
        set3(&L->normal, prefix, xyz);
        L->spp = header_spp(img, layer);
        free(layer);
        break;
    }
    case MCP_CONV_MITSUBA: {
        set3(&L->color, "", rgb);
        set3(&L->m2, "m2_", rgb);
        L->has_m2 = has3(img, &L->m2);
        char p[512];
        if (!L->has_m2 && find_moment_prefix(img, p, sizeof p)) {
            snprintf(prefix, sizeof prefix, "%s.", p);
            set3(&L->xyz, prefix, xyz);
            snprintf(prefix, sizeof prefix, "m2_%s.", p);
            set3(&L->m2, prefix, xyz);
            L->has_m2 = L->has_xyz = 1;
            L->color_from_xyz = !has3(img, &L->color);
        }
        if (find_triple(img, "albedo", rgb, p, sizeof p)) {
            snprintf(prefix, sizeof prefix, "%s.", p);
            set3(&L->albedo, prefix, rgb);
        }
        if (find_triple(img, "sh_normal", xyz, p, sizeof p) ||
            find_triple(img, "normal", xyz, p, sizeof p)) {
            snprintf(prefix, sizeof prefix, "%s.", p);
            set3(&L->normal, prefix, xyz);
        }
        L->spp = header_spp(img, NULL);
        break;
    }
    default: /* pbrt, mcpost, plain */
        set3(&L->color, "", rgb);
        set3(&L->var, "Variance.", rgb);
        set3(&L->cov, "Covariance.", offdiag);
        set3(&L->albedo, "Albedo.", rgb);
        set3(&L->normal, "N.", xyz);
        if (!has3(img, &L->normal)) set3(&L->normal, "Ns.", xyz);
        snprintf(L->spp_channel, sizeof L->spp_channel, "SampleCount");
        L->spp = header_spp(img, NULL);
        break;
    }
    L->has_var = L->var.c[0][0] && has3(img, &L->var);
    L->has_cov = L->cov.c[0][0] && has3(img, &L->cov);
    L->has_albedo = L->albedo.c[0][0] && has3(img, &L->albedo);
    L->has_normal = L->normal.c[0][0] && has3(img, &L->normal);
    return 0;
}

/* ---- loading ---- */

static int
rename3(mcp_image *img, const char *a, const char *b, const char *c)
{
    return mcp_image_set_channel_name(img, 0, a) ||
           mcp_image_set_channel_name(img, 1, b) || mcp_image_set_channel_name(img, 2, c);
}

/* Where the main file's channels come from: a whole image in memory, whose triples
 * are copied out, or (an EXR file on disk) images the reader decoded those triples
 * straight into (read_direct), with no whole image to copy them from. */
enum {
    PART_COLOR,
    PART_ALBEDO,
    PART_NORMAL,
    PART_COV,
    PART_VAR,
    PART_M2,
    PART_SPP,
    PART_XYZ,
    N_PARTS
};

/* The checks of a dump read a band of rows at a time (mcp__dump_bands, below). */
typedef struct band_check band_check;

typedef struct channel_source {
    const mcp_image *img; /* names, attributes and source; pixels unless header_only */
    int header_only;
    mcp_image *direct[N_PARTS];
    band_check *band; /* the parts are rows of the dump (mcp__dump_bands); NULL: whole */
} channel_source;

/* Part `part` as an image of its n channels `names` (1 or 3), from the source. */
static int
take_part(channel_source *src, int part, const char *const *names, int n, mcp_image **out)
{
    if (src->direct[part]) {
        *out = src->direct[part];
        src->direct[part] = NULL;
        return 0;
    }
    if (src->header_only) /* route_parts and dump_fill disagree on the parts */
        return mcp_error("%s: part %d was not read", src->img->source, part);
    int idx[3];
    return mcp_image_channels(src->img, names, n, idx) ||
           mcp_image_copy_channels(src->img, idx, n, out);
}

static int
take3(channel_source *src, int part, const name3 *names, mcp_image **out)
{
    const char *n[3] = {names->c[0], names->c[1], names->c[2]};
    return take_part(src, part, n, 3, out);
}

static int
in_memory(const mcp_dump_buffer *buf)
{
    return buf->data != NULL;
}

/* Reads one file of a dump: from its buffer when it has one (named by path, or by its
 * role when there is none), else from path. */
static int
read_part(const char *path, const mcp_dump_buffer *buf, const char *role,
          const mcp_read_options *ro, mcp_image **out)
{
    if (!in_memory(buf)) return mcp_image_read(path, ro, out);
    char name[64];
    if (!path) snprintf(name, sizeof name, "%s (in memory)", role);
    return mcp_image_read_memory(buf->data, buf->size, path ? path : name, out);
}

/* Reads a separate part file and takes its colour-like triple (R,G,B / X,Y,Z or the
 * first three channels). */
static int
load_part(const char *path, const mcp_dump_buffer *buf, const char *role,
          const char *const names[3], const mcp_image *like, mcp_image **out)
{
    mcp_image *img = NULL;
    mcp_read_options ro = mcp_read_defaults();
    ro.srgb_decode = 0; /* data, not colour */
    if (read_part(path, buf, role, &ro, &img)) return -1;
    int idx[3] = {0, 1, 2}, rc = -1;
    if (mcp_image_channels(img, names, 3, idx) && img->channels >= 3) {
        idx[0] = 0, idx[1] = 1, idx[2] = 2;
    } else if (img->channels < 3) {
        mcp_error("%s: needs 3 channels (%s,%s,%s), has %d", img->source, names[0],
                  names[1], names[2], img->channels);
        goto done;
    }
    if (!mcp_image_same_size(img, like)) goto done;
    rc = mcp_image_copy_channels(img, idx, 3, out);
done:
    mcp_image_free(img);
    return rc;
}

/* How many of n values are NaN/Inf or, for variance, negative (below -0), from their
 * bits, so that the loop vectorises: exponent all ones is NaN or Inf, and a value
 * above 0x80000000 has its sign set and is not -0. */
static long
count_bad(const float *v, size_t n, int is_variance)
{
    long bad = 0;
    const uint32_t negative_above = is_variance ? 0x80000000u : UINT32_MAX;
#pragma omp simd reduction(+ : bad)
    for (size_t i = 0; i < n; i++) {
        uint32_t b;
        memcpy(&b, &v[i], sizeof b);
        bad += (b & 0x7f800000u) == 0x7f800000u || b > negative_above;
    }
    return bad;
}

/* The bad values of one channel found so far: how many, and the first (in rows
 * read top to bottom, pixel coordinates in the whole image). */
typedef struct bad_tally {
    long bad;
    int fx, fy;
    float first;
} bad_tally;

/* Tallies img's NaN/Inf (and, for variance, negative values) per channel into
 * tally[c], img's row 0 being row y_off of the whole image, and zeroes them under
 * policy zero. */
static void
scan_values(mcp_image *img, int is_variance, mcp_badval_policy policy, int y_off,
            bad_tally *tally)
{
    /* bad values are rare: a parallel count over every value first, and the serial
       pass that finds the first and replaces them only when there are some */
    long any_bad = 0;
    const int nc = img->channels;
    const int packed = img->pixel_stride == nc;
#pragma omp parallel for reduction(+ : any_bad) schedule(static) \
    if ((long long)img->width * img->height * nc > 65536)
    for (int y = 0; y < img->height; y++) {
        if (packed) {
            any_bad +=
                count_bad(mcp_image_px(img, 0, y), (size_t)img->width * nc, is_variance);
            continue;
        }
        for (int x = 0; x < img->width; x++)
            any_bad += count_bad(mcp_image_px(img, x, y), (size_t)nc, is_variance);
    }
    if (!any_bad) return;
    for (int c = 0; c < img->channels; c++) {
        bad_tally *t = &tally[c];
        for (int y = 0; y < img->height; y++)
            for (int x = 0; x < img->width; x++) {
                float *v = &mcp_image_px(img, x, y)[c];
                if (isfinite(*v) && !(is_variance && *v < 0)) continue;
                if (!t->bad++) t->fx = x, t->fy = y + y_off, t->first = *v;
                if (policy == MCP_BADVAL_ZERO) *v = 0;
            }
    }
}

/* Under policy fail, the error naming the first channel (in img's order) with bad
 * values; else the count of those replaced, added to *replaced. */
static int
report_values(const mcp_image *img, const char *part, int is_variance,
              mcp_badval_policy policy, const bad_tally *tally, long *replaced)
{
    for (int c = 0; c < img->channels; c++) {
        const bad_tally *t = &tally[c];
        if (t->bad && policy == MCP_BADVAL_FAIL)
            return mcp_error("%s: %s channel '%s' has %ld %s value%s (first %g at pixel "
                             "%d,%d; set bad_values: zero to replace them)",
                             img->source, part, img->names[c], t->bad,
                             is_variance && isfinite(t->first) ? "negative" : "NaN/Inf",
                             t->bad == 1 ? "" : "s", t->first, t->fx, t->fy);
        *replaced += t->bad;
    }
    return 0;
}

/* A dump read in bands, top to bottom: the parts checked (colour, albedo, normal,
 * variance, covariance) have their bad values tallied band after band, with pixel
 * coordinates in the whole image, and reported with the last band, so that the error
 * is the line a whole read gives (the same count, the same first value). */
enum { CHECK_COLOR, CHECK_ALBEDO, CHECK_NORMAL, CHECK_VAR, CHECK_COV, N_CHECKS };

struct band_check {
    int y_off; /* the band's first row in the image */
    int last;  /* the band ends the image: report */
    bad_tally tally[N_CHECKS][3];
};

/* NaN/Inf (and, for variance, negative values): fail naming the first, or zero them.
 * band: the part is a band of the dump's rows (which: its CHECK_*), or NULL. */
static int
check_values(mcp_image *img, const char *part, int is_variance, mcp_badval_policy policy,
             band_check *band, int which, long *replaced)
{
    if (!img) return 0;
    if (band) {
        scan_values(img, is_variance, policy, band->y_off, band->tally[which]);
        return band->last ? report_values(img, part, is_variance, policy,
                                          band->tally[which], replaced)
                          : 0;
    }
    bad_tally *tally = mcp_calloc((size_t)img->channels, sizeof *tally);
    if (!tally) return -1;
    scan_values(img, is_variance, policy, 0, tally);
    int rc = report_values(img, part, is_variance, policy, tally, replaced);
    free(tally);
    return rc;
}

static int
load_spp(mcp_dump *d, channel_source *src, const mcp_dump_spec *spec,
         const mcp_dump_buffers *parts, const layout *L)
{
    const mcp_image *img = src->img;
    if (spec->spp_map_path || in_memory(&parts->spp_map)) {
        mcp_image *m = NULL;
        if (read_part(spec->spp_map_path, &parts->spp_map, "spp map", NULL, &m))
            return -1;
        int idx = 0;
        int ok = mcp_image_same_size(m, d->color) &&
                 !mcp_image_copy_channels(m, &idx, 1, &d->spp_map);
        mcp_image_free(m);
        if (!ok) return -1;
    } else if (L->spp_channel[0] && has(img, L->spp_channel)) {
        const char *name = L->spp_channel;
        if (take_part(src, PART_SPP, &name, 1, &d->spp_map)) return -1;
    }
    if (d->spp_map) {
        for (int y = 0; y < d->spp_map->height; y++)
            for (int x = 0; x < d->spp_map->width; x++) {
                float n = mcp_image_px(d->spp_map, x, y)[0];
                /* 0 is a pixel that a pass of an adaptive render left out */
                if (!(n >= 0) || !isfinite(n))
                    return mcp_error("%s: sample count %g at pixel %d,%d (must be >= 0)",
                                     d->spp_map->source, n, x,
                                     y + (src->band ? src->band->y_off : 0));
            }
        d->spp = 0;
        return 0;
    }
    d->spp = spec->spp > 0 ? spec->spp : L->spp;
    if (spec->spp < 0 || !isfinite(spec->spp))
        return mcp_error("%s: sample count %g given (must be > 0)", d->source, spec->spp);
    if (d->spp == 0 && (d->var_of_mean || d->cov_of_mean) &&
        d->variance_in_file == MCP_VAR_PER_SAMPLE)
        return mcp_error("%s: no sample count: the file has none (%s) and none was given "
                         "(spp, --spp)",
                         d->source,
                         d->convention == MCP_CONV_MITSUBA
                             ? "Mitsuba writes no sample count in its EXR"
                             : "samplesPerPixel");
    if (d->spp < 0 || !isfinite(d->spp))
        return mcp_error("%s: sample count %g in the file (must be > 0)", d->source,
                         d->spp);
    return 0;
}

/* Divides per-sample variance (and covariance) by the sample count. */
static void
to_variance_of_mean(mcp_dump *d)
{
    mcp_image *parts[2] = {d->var_of_mean, d->cov_of_mean};
    for (int p = 0; p < 2; p++) {
        if (!parts[p]) continue;
#pragma omp parallel for schedule(                                                       \
    static) if ((long long)parts[p]->width * parts[p]->height > 65536)
        for (int y = 0; y < parts[p]->height; y++)
            for (int x = 0; x < parts[p]->width; x++) {
                double n = mcp_dump_spp_at(d, x, y);
                float *v = mcp_image_px(parts[p], x, y);
                for (int c = 0; c < 3; c++) /* no samples: no variance */
                    v[c] = n > 0 ? (float)(v[c] / n) : 0.0f;
            }
    }
}

/* The dump's convention, source, attributes and channel layout, from the main file's
 * channel names and header (img's pixels are not read). */
static int
dump_layout(const mcp_image *img, const mcp_dump_spec *spec, mcp_dump *d, layout *L)
{
    d->convention = spec->convention ? spec->convention : mcp_dump_detect(img);
    if (!(d->source = mcp_strdup(img->source)) ||
        mcp_attrs_copy(&img->attrs, &d->attrs) || layout_for(img, d->convention, L))
        return -1;
    /* explicit names win over the convention */
    for (int k = 0; k < 3; k++) {
        if (spec->color[k])
            snprintf(L->color.c[k], sizeof L->color.c[k], "%s", spec->color[k]);
        if (spec->var[k]) snprintf(L->var.c[k], 512, "%s", spec->var[k]), L->has_var = 1;
        if (spec->albedo[k])
            snprintf(L->albedo.c[k], 512, "%s", spec->albedo[k]), L->has_albedo = 1;
        if (spec->normal[k])
            snprintf(L->normal.c[k], 512, "%s", spec->normal[k]), L->has_normal = 1;
    }
    return 0;
}

/* Everything after the layout: the parts from the source (renamed to R,G,B / X,Y,Z),
 * Mitsuba's moments, the separate part files, the sample count, the bad-value
 * checks and the variance of the mean. */
/* XYZ to linear sRGB (D65), the inverse of the sRGB-to-XYZ matrix that Mitsuba 3
 * converts with (its srgb_to_xyz, and its film's XYZ output). */
static const double xyz_to_rgb[3][3] = {{3.240479, -1.537150, -0.498535},
                                        {-0.969256, 1.875991, 0.041556},
                                        {0.055648, -0.204043, 1.057311}};

/* Which parts of Mitsuba 3's moment layout dump_fill takes (route_parts must agree). */
static int
wants_xyz(const layout *L)
{
    return L->has_xyz && (L->color_from_xyz || !L->has_var);
}

static int
wants_m2(const layout *L)
{
    return L->has_m2 && !L->has_var;
}

/* Mitsuba 3's moment integrator: the XYZ mean xyz and second moments m2 (both
 * replaced in place) into the per-sample RGB variance in m2 and, when color_from_xyz,
 * the RGB mean in xyz. The XYZ covariances are not stored, so the RGB variance is
 * the one with perfectly correlated X, Y, Z: (sum_j M_rj sd_j)^2, exact when a
 * pixel's samples share one chromaticity (and for grey), never above the bound
 * (sum_j |M_rj| sd_j)^2 (docs/conventions.md, "Mitsuba 3"). */
static void
xyz_moments_to_rgb(mcp_image *xyz, mcp_image *m2, int color_from_xyz)
{
    for (int y = 0; y < xyz->height; y++)
        for (int x = 0; x < xyz->width; x++) {
            float *m = mcp_image_px(xyz, x, y), *v = mcp_image_px(m2, x, y);
            double sd[3], worst = 0;
            for (int j = 0; j < 3; j++) {
                /* float rounding can make m2 - m^2 slightly negative at ~0 variance */
                double var = (double)v[j] - (double)m[j] * m[j];
                double tol = 1e-6 * fabs((double)v[j]) + 1e-30;
                if (var < 0 && var > -tol) var = 0;
                if (var < worst || isnan(var)) worst = isnan(var) ? NAN : var;
                sd[j] = var > 0 ? sqrt(var) : 0;
            }
            double rgb[3];
            for (int r = 0; r < 3; r++) {
                double a = 0;
                rgb[r] = 0;
                for (int j = 0; j < 3; j++) {
                    a += xyz_to_rgb[r][j] * sd[j];
                    rgb[r] += xyz_to_rgb[r][j] * m[j];
                }
                /* a negative or NaN XYZ variance stays so, for check_values */
                v[r] = (float)(worst < 0 || isnan(worst) ? worst : a * a);
            }
            if (color_from_xyz)
                for (int r = 0; r < 3; r++)
                    m[r] = (float)rgb[r];
        }
}

static int
dump_fill(mcp_dump *d, channel_source *src, const mcp_dump_spec *spec,
          const mcp_dump_buffers *parts, const layout *L)
{
    if (wants_xyz(L)) {
        mcp_image *xyz = NULL;
        if (take3(src, PART_XYZ, &L->xyz, &xyz)) return -1;
        int rc = 0;
        if (wants_m2(L)) {
            rc = take3(src, PART_M2, &L->m2, &d->var_of_mean) ||
                 rename3(d->var_of_mean, "R", "G", "B");
            if (!rc) xyz_moments_to_rgb(xyz, d->var_of_mean, L->color_from_xyz);
        }
        if (!rc && L->color_from_xyz) {
            d->color = xyz;
            xyz = NULL;
            rc = rename3(d->color, "R", "G", "B");
        }
        mcp_image_free(xyz);
        if (rc) return -1;
    }
    if (!L->color_from_xyz && (take3(src, PART_COLOR, &L->color, &d->color) ||
                               rename3(d->color, "R", "G", "B")))
        return -1;
    if (L->has_albedo && (take3(src, PART_ALBEDO, &L->albedo, &d->albedo) ||
                          rename3(d->albedo, "R", "G", "B")))
        return -1;
    if (L->has_normal && (take3(src, PART_NORMAL, &L->normal, &d->normal) ||
                          rename3(d->normal, "X", "Y", "Z")))
        return -1;
    if (L->has_cov && (take3(src, PART_COV, &L->cov, &d->cov_of_mean) ||
                       rename3(d->cov_of_mean, "RG", "RB", "GB")))
        return -1;
    d->variance_in_file = spec->variance ? spec->variance : L->var_kind;
    if (L->has_var) {
        if (take3(src, PART_VAR, &L->var, &d->var_of_mean) ||
            rename3(d->var_of_mean, "R", "G", "B"))
            return -1;
    } else if (L->has_xyz) {
        d->variance_in_file = MCP_VAR_PER_SAMPLE; /* taken above, from XYZ */
    } else if (L->has_m2) {
        /* Mitsuba's moment integrator: per-sample variance = E[x^2] - E[x]^2; float
         * rounding can make it slightly negative where the variance is ~0 */
        if (take3(src, PART_M2, &L->m2, &d->var_of_mean) ||
            rename3(d->var_of_mean, "R", "G", "B"))
            return -1;
        for (int y = 0; y < d->color->height; y++)
            for (int x = 0; x < d->color->width; x++) {
                float *v = mcp_image_px(d->var_of_mean, x, y);
                const float *m = mcp_image_px(d->color, x, y);
                for (int c = 0; c < 3; c++) {
                    double var = (double)v[c] - (double)m[c] * m[c];
                    double tol = 1e-6 * fabs((double)v[c]) + 1e-30;
                    v[c] = (float)(var < 0 && var > -tol ? 0 : var);
                }
            }
        d->variance_in_file = MCP_VAR_PER_SAMPLE;
    }
    if (spec->variance_path || in_memory(&parts->variance)) {
        mcp_image_free(d->var_of_mean);
        d->var_of_mean = NULL;
        if (load_part(spec->variance_path, &parts->variance, "variance",
                      (const char *const[]){"R", "G", "B"}, d->color, &d->var_of_mean) ||
            rename3(d->var_of_mean, "R", "G", "B"))
            return -1;
        d->variance_in_file = spec->variance ? spec->variance : MCP_VAR_OF_MEAN;
    }
    if (spec->albedo_path || in_memory(&parts->albedo)) {
        mcp_image_free(d->albedo);
        d->albedo = NULL;
        if (load_part(spec->albedo_path, &parts->albedo, "albedo",
                      (const char *const[]){"R", "G", "B"}, d->color, &d->albedo) ||
            rename3(d->albedo, "R", "G", "B"))
            return -1;
    }
    if (spec->normal_path || in_memory(&parts->normal)) {
        mcp_image_free(d->normal);
        d->normal = NULL;
        if (load_part(spec->normal_path, &parts->normal, "normal",
                      (const char *const[]){"X", "Y", "Z"}, d->color, &d->normal) ||
            rename3(d->normal, "X", "Y", "Z"))
            return -1;
    }
    if (load_spp(d, src, spec, parts, L) ||
        check_values(d->color, "colour", 0, spec->bad_values, src->band, CHECK_COLOR,
                     &d->n_bad_values) ||
        check_values(d->albedo, "albedo", 0, spec->bad_values, src->band, CHECK_ALBEDO,
                     &d->n_bad_values) ||
        check_values(d->normal, "normal", 0, spec->bad_values, src->band, CHECK_NORMAL,
                     &d->n_bad_values) ||
        check_values(d->var_of_mean, "variance", 1, spec->bad_values, src->band,
                     CHECK_VAR, &d->n_bad_values) ||
        check_values(d->cov_of_mean, "covariance", 0, spec->bad_values, src->band,
                     CHECK_COV, &d->n_bad_values))
        return -1;
    if (d->variance_in_file == MCP_VAR_PER_SAMPLE) to_variance_of_mean(d);
    read_variance_source(d);
    if (wants_m2(L) && L->has_xyz && d->variance_source == MCP_VARSRC_PER_SAMPLE &&
        !(spec->variance_path || in_memory(&parts->variance)))
        d->variance_source = MCP_VARSRC_XYZ_MOMENTS;
    return 0;
}

/* The parts a caller does without (mcp__dump_load_without) leave the layout: they are
 * neither decoded nor checked. */
static void
drop_parts(layout *L, unsigned without)
{
    if (without & MCP__DUMP_NO_ALBEDO) L->has_albedo = 0;
    if (without & MCP__DUMP_NO_NORMAL) L->has_normal = 0;
}

/* mcp_dump_from_image, with the separate parts from parts' buffers or spec's paths. */
static int
from_image(const mcp_image *img, const mcp_dump_spec *spec, const mcp_dump_buffers *parts,
           unsigned without, mcp_dump **out)
{
    *out = NULL;
    mcp_dump *d = mcp_calloc(1, sizeof *d);
    if (!d) return -1;
    layout L;
    channel_source src = {.img = img};
    int rc = dump_layout(img, spec, d, &L);
    drop_parts(&L, without);
    if (rc || dump_fill(d, &src, spec, parts, &L)) {
        mcp_dump_free(d);
        return -1;
    }
    *out = d;
    return 0;
}

int
mcp_dump_from_image(const mcp_image *img, const mcp_dump_spec *spec, mcp_dump **out)
{
    mcp_dump_spec defaults = mcp_dump_spec_defaults();
    static const mcp_dump_buffers none;
    return from_image(img, spec ? spec : &defaults, &none, 0, out);
}

/* ---- reading an EXR's parts directly ---- */

/* What the router of read_direct works with: it lays out the dump from the header and
 * makes an image for each part the main file gives, and the reader decodes the
 * channels into them. clash: two parts want one channel (names given in the spec), so
 * the whole image must be read and copied from instead. */
typedef struct direct_read {
    const mcp_dump_spec *spec;
    const mcp_dump_buffers *parts;
    mcp_dump *d;
    layout L;
    channel_source src;
    mcp_image *header; /* a copy of the header, for dump_fill's names and attributes */
    int clash;
    unsigned without; /* MCP__DUMP_NO_*: parts left out */
} direct_read;

/* An image of the n channels `names` of the header for part `part`, and the routes
 * that send the file's channels into it. */
static int
route_part(direct_read *r, const mcp_image *header, int w, int h, int part,
           const char *const *names, int n, mcp__exr_route *routes)
{
    int idx[3];
    const char *own[3];
    mcp_image *img = NULL;
    if (mcp_image_channels(header, names, n, idx)) return -1;
    for (int k = 0; k < n; k++) {
        if (routes[idx[k]].base) {
            r->clash = 1;
            return mcp_error("%s: channel '%s' is wanted twice", header->source,
                             names[k]);
        }
        own[k] = header->names[idx[k]];
    }
    if (mcp_image_new(w, h, n, own, &img) || mcp_image_set_source(img, header->source) ||
        mcp_attrs_copy(&header->attrs, &img->attrs)) {
        mcp_image_free(img);
        return -1;
    }
    for (int k = 0; k < n; k++)
        routes[idx[k]] =
            (mcp__exr_route){img->data + k, img->pixel_stride, img->row_stride};
    r->src.direct[part] = img;
    return 0;
}

static int
route_parts(const mcp_image *header, int w, int h, void *ctx, mcp__exr_route *routes)
{
    direct_read *r = ctx;
    layout *L = &r->L;
    /* the header outlives the read: dump_fill looks up names in a copy of it */
    if (mcp_image_new(1, 1, header->channels, (const char *const *)header->names,
                      &r->header) ||
        mcp_image_set_source(r->header, header->source) ||
        mcp_attrs_copy(&header->attrs, &r->header->attrs))
        return -1;
    r->src.img = r->header;
    r->src.header_only = 1;
    if (dump_layout(header, r->spec, r->d, L)) return -1;
    drop_parts(L, r->without);
    const struct {
        int part, wanted;
        const name3 *names;
    } parts[] = {
        {PART_COLOR, !L->color_from_xyz, &L->color},
        {PART_XYZ, wants_xyz(L), &L->xyz},
        {PART_ALBEDO, L->has_albedo, &L->albedo},
        {PART_NORMAL, L->has_normal, &L->normal},
        {PART_COV, L->has_cov, &L->cov},
        {PART_VAR, L->has_var, &L->var},
        {PART_M2, wants_m2(L), &L->m2},
    };
    for (size_t i = 0; i < sizeof parts / sizeof *parts; i++) {
        const char *n[3] = {parts[i].names->c[0], parts[i].names->c[1],
                            parts[i].names->c[2]};
        if (parts[i].wanted && route_part(r, header, w, h, parts[i].part, n, 3, routes))
            return -1;
    }
    if (!r->spec->spp_map_path && !in_memory(&r->parts->spp_map) && L->spp_channel[0] &&
        has(header, L->spp_channel)) {
        const char *n = L->spp_channel;
        if (route_part(r, header, w, h, PART_SPP, &n, 1, routes)) return -1;
    }
    return 0;
}

/* Loads an EXR dump (a file, or parts->main in memory) with its parts decoded straight
 * from it: no whole image and no copies, which took a third of reading a 1080p dump
 * (docs/benchmarks.md, "EXR speed"). 1 in *fallback when the whole image must be read
 * instead. */
static int
read_direct(const mcp_dump_spec *spec, const mcp_dump_buffers *parts, unsigned without,
            mcp_dump **out, int *fallback)
{
    direct_read r = {.spec = spec, .parts = parts, .without = without};
    *fallback = 0;
    int rc = -1;
    if (!(r.d = mcp_calloc(1, sizeof *r.d))) return -1;
    int read = -1;
    if (in_memory(&parts->main))
        read = mcp__exr_read_memory_routed(parts->main.data, parts->main.size,
                                           spec->path ? spec->path : "main (in memory)",
                                           route_parts, &r);
    else
        read = mcp__exr_read_routed(spec->path, route_parts, &r);
    if (read == 0 && dump_fill(r.d, &r.src, spec, parts, &r.L) == 0) {
        *out = r.d;
        r.d = NULL;
        rc = 0;
    }
    *fallback = r.clash;
    for (int i = 0; i < N_PARTS; i++)
        mcp_image_free(r.src.direct[i]);
    mcp_image_free(r.header);
    mcp_dump_free(r.d);
    return rc;
}

/* An EXR main part, read directly: in memory by its magic number (as
 * mcp_image_read_memory tells formats), on disk by its extension (as mcp_image_read). */
static int
main_is_exr(const mcp_dump_spec *spec, const mcp_dump_buffers *parts)
{
    if (in_memory(&parts->main))
        return mcp__exr_magic(parts->main.data, parts->main.size);
    return mcp_format_from_path(spec->path) == MCP_FORMAT_EXR;
}

/* mcp_dump_read_memory without the parts in `without`; their separate files, if any,
 * are not read either. */
static int
read_memory(const mcp_dump_spec *spec_, const mcp_dump_buffers *parts, unsigned without,
            mcp_dump **out)
{
    mcp_dump_spec spec = spec_ ? *spec_ : mcp_dump_spec_defaults();
    static const mcp_dump_buffers none;
    mcp_dump_buffers kept = parts ? *parts : none;
    *out = NULL;
    if (without & MCP__DUMP_NO_ALBEDO) spec.albedo_path = NULL, kept.albedo = none.albedo;
    if (without & MCP__DUMP_NO_NORMAL) spec.normal_path = NULL, kept.normal = none.normal;
    if (!spec.path && !in_memory(&kept.main))
        return mcp_error("render dump: no file given");
    if (main_is_exr(&spec, &kept)) {
        int fallback;
        if (!in_memory(&kept.main) && mcp__check_readable(spec.path)) return -1;
        if (read_direct(&spec, &kept, without, out, &fallback) == 0) return 0;
        if (!fallback) return -1;
    }
    mcp_image *img = NULL;
    mcp_read_options ro = mcp_read_defaults();
    if (read_part(spec.path, &kept.main, "main", &ro, &img)) return -1;
    int rc = from_image(img, &spec, &kept, without, out);
    mcp_image_free(img);
    return rc;
}

int
mcp_dump_read_memory(const mcp_dump_spec *spec, const mcp_dump_buffers *parts,
                     mcp_dump **out)
{
    return read_memory(spec, parts, 0, out);
}

int
mcp_dump_load(const mcp_dump_spec *spec, mcp_dump **out)
{
    return read_memory(spec, NULL, 0, out);
}

int
mcp__dump_load_without(const mcp_dump_spec *spec, unsigned without, mcp_dump **out)
{
    return read_memory(spec, NULL, without, out);
}

int
mcp_dump_read(const char *path, mcp_dump **out)
{
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    return mcp_dump_load(&spec, out);
}

void
mcp_dump_free(mcp_dump *d)
{
    if (!d) return;
    mcp_image_free(d->color);
    mcp_image_free(d->var_of_mean);
    mcp_image_free(d->cov_of_mean);
    mcp_image_free(d->albedo);
    mcp_image_free(d->normal);
    mcp_image_free(d->spp_map);
    mcp_attrs_clear(&d->attrs);
    free(d->source);
    free(d);
}

double
mcp_dump_spp_at(const mcp_dump *d, int x, int y)
{
    return d->spp_map ? (double)mcp_image_px(d->spp_map, x, y)[0] : d->spp;
}

/* ---- reading an EXR dump's colour, albedo and normal rows at a time ---- */

/* The parts a streamed denoise reads (docs/denoisers.md, "Images larger than
 * memory"): colour, albedo, normal, by the layout a whole read finds, named as a whole
 * read names them, with their values checked as it checks them (the first pass over
 * the rows tallies; the last row of it reports). */
enum { ROW_COLOR, ROW_ALBEDO, ROW_NORMAL, ROW_PARTS };

struct mcp__dump_rows {
    mcp__exr_rows *exr;
    const mcp_image *header;
    mcp_dump *d; /* source, attributes, convention */
    mcp_badval_policy policy;
    int width, height;
    int idx[ROW_PARTS][3]; /* the parts' channels in the file; -1: no such part */
    int checked;           /* rows [0, checked) tallied */
    bad_tally tally[ROW_PARTS][3];
};

void
mcp__dump_rows_close(mcp__dump_rows *r)
{
    if (!r) return;
    mcp__exr_rows_close(r->exr);
    mcp_dump_free(r->d);
    free(r);
}

int
mcp__dump_rows_open(const mcp_dump_spec *spec, mcp__dump_rows **out)
{
    *out = NULL;
    /* a dump whose parts come from other files, or from a Mitsuba XYZ mean, is read
       whole */
    if (!spec->path || spec->variance_path || spec->albedo_path || spec->normal_path ||
        spec->spp_map_path || mcp_format_from_path(spec->path) != MCP_FORMAT_EXR)
        return 0;
    mcp__dump_rows *r = mcp_calloc(1, sizeof *r);
    if (!r || !(r->d = mcp_calloc(1, sizeof *r->d))) {
        free(r);
        return -1;
    }
    r->policy = spec->bad_values;
    layout L;
    if (mcp__exr_rows_open(spec->path, &r->exr)) {
        mcp__dump_rows_close(r);
        return -1;
    }
    r->header = mcp__exr_rows_header(r->exr, &r->width, &r->height);
    if (dump_layout(r->header, spec, r->d, &L)) {
        mcp__dump_rows_close(r);
        return -1;
    }
    const name3 *names[ROW_PARTS] = {&L.color, L.has_albedo ? &L.albedo : NULL,
                                     L.has_normal ? &L.normal : NULL};
    int clash = L.color_from_xyz;
    for (int p = 0; p < ROW_PARTS; p++) {
        for (int k = 0; k < 3; k++)
            r->idx[p][k] = -1;
        if (!names[p]) continue;
        const char *n[3] = {names[p]->c[0], names[p]->c[1], names[p]->c[2]};
        if (mcp_image_channels(r->header, n, 3, r->idx[p])) {
            mcp__dump_rows_close(r);
            return -1;
        }
        for (int q = 0; q < p; q++) /* two parts from one channel: read whole */
            for (int k = 0; k < 3; k++)
                for (int j = 0; j < 3; j++)
                    clash |= r->idx[p][k] == r->idx[q][j];
    }
    if (clash) {
        mcp__dump_rows_close(r);
        return 0;
    }
    *out = r;
    return 0;
}

void
mcp__dump_rows_size(const mcp__dump_rows *r, int *width, int *height, int *has_albedo,
                    int *has_normal)
{
    *width = r->width;
    *height = r->height;
    *has_albedo = r->idx[ROW_ALBEDO][0] >= 0;
    *has_normal = r->idx[ROW_NORMAL][0] >= 0;
}

const mcp_dump *
mcp__dump_rows_dump(const mcp__dump_rows *r)
{
    return r->d;
}

double
mcp__dump_rows_whole_bytes(const mcp__dump_rows *r)
{
    return (double)r->width * r->height * sizeof(float) * r->header->channels;
}

int
mcp__dump_rows_read(mcp__dump_rows *r, int y0, int y1, mcp_image **parts)
{
    static const char *const rgb[3] = {"R", "G", "B"}, *const xyz[3] = {"X", "Y", "Z"};
    static const char *const part_words[ROW_PARTS] = {"colour", "albedo", "normal"};
    for (int p = 0; p < ROW_PARTS; p++)
        parts[p] = NULL;
    int a0, a1, rc = -1;
    mcp__exr_rows_span(r->exr, y0, y1, &a0, &a1);
    mcp__exr_route *routes = mcp_calloc((size_t)r->header->channels, sizeof *routes);
    if (!routes) return -1;
    for (int p = 0; p < ROW_PARTS; p++) {
        if (r->idx[p][0] < 0) continue;
        if (mcp_image_new(r->width, a1 - a0, 3, p == ROW_NORMAL ? xyz : rgb, &parts[p]) ||
            mcp_image_set_source(parts[p], r->d->source))
            goto done;
        for (int k = 0; k < 3; k++)
            routes[r->idx[p][k]] = (mcp__exr_route){
                parts[p]->data + k, parts[p]->pixel_stride, parts[p]->row_stride};
    }
    if (mcp__exr_rows_read(r->exr, y0, y1, a0, routes)) goto done;
    /* the chunks' rows around [y0, y1) go */
    for (int p = 0; p < ROW_PARTS; p++)
        if (parts[p]) mcp__exr_rows_trim(parts[p], a0, y0, y1);
    /* the first pass over the rows tallies, as a whole read checks the whole parts;
       policy zero replaces in every read */
    const int first_pass = y0 == r->checked;
    for (int p = 0; p < ROW_PARTS; p++) {
        /* after the first pass, policy fail knows there are none */
        if (!parts[p] || (!first_pass && r->policy == MCP_BADVAL_FAIL)) continue;
        bad_tally scratch[3] = {{0}};
        scan_values(parts[p], 0, r->policy, y0, first_pass ? r->tally[p] : scratch);
    }
    if (first_pass) r->checked = y1;
    if (first_pass && r->checked == r->height) {
        long replaced = 0;
        for (int p = 0; p < ROW_PARTS; p++)
            if (parts[p] && report_values(parts[p], part_words[p], 0, r->policy,
                                          r->tally[p], &replaced))
                goto done;
        r->d->n_bad_values = replaced;
    }
    rc = 0;
done:
    free(routes);
    if (rc)
        for (int p = 0; p < ROW_PARTS; p++) {
            mcp_image_free(parts[p]);
            parts[p] = NULL;
        }
    return rc;
}

/* ---- reading a whole EXR dump, a band of rows at a time ---- */

/* For the commands that stream a dump (merge, convert --dump, info: docs/
 * conventions.md, "Files larger than memory"): every part, laid out, converted and
 * checked by the code a whole read runs (route_parts, dump_fill), on images of the
 * band's rows; the bands follow each other once, top to bottom. (The U-Net's streamed
 * denoise reads overlapping bands of three parts instead: mcp__dump_rows, above.) */
struct mcp__dump_bands {
    mcp_dump_spec spec;
    unsigned without; /* MCP__DUMP_NO_*: parts left out */
    mcp__exr_rows *exr;
    const mcp_image *header;
    int width, height;
    int next_row;
    band_check check;
};

void
mcp__dump_bands_close(mcp__dump_bands *b)
{
    if (!b) return;
    mcp__exr_rows_close(b->exr);
    free(b);
}

/* The parts of rows [y0, y1) decoded into r's images (route_parts), the rows of the
 * chunks around them dropped. *clash as route_parts sets it. */
static int
read_band_parts(mcp__dump_bands *b, int y0, int y1, direct_read *r, int *clash)
{
    int a0, a1, rc = -1;
    mcp__exr_rows_span(b->exr, y0, y1, &a0, &a1);
    mcp__exr_route *routes = mcp_calloc((size_t)b->header->channels, sizeof *routes);
    if (!routes) return -1;
    if (route_parts(b->header, b->width, a1 - a0, r, routes) ||
        mcp__exr_rows_read(b->exr, y0, y1, a0, routes))
        goto done;
    for (int i = 0; i < N_PARTS; i++)
        if (r->src.direct[i]) mcp__exr_rows_trim(r->src.direct[i], a0, y0, y1);
    rc = 0;
done:
    *clash = r->clash;
    free(routes);
    return rc;
}

static void
direct_read_clear(direct_read *r)
{
    for (int i = 0; i < N_PARTS; i++)
        mcp_image_free(r->src.direct[i]);
    mcp_image_free(r->header);
    mcp_dump_free(r->d);
    memset(r, 0, sizeof *r);
}

int
mcp__dump_bands_open(const mcp_dump_spec *spec, mcp__dump_bands **out)
{
    return mcp__dump_bands_open_without(spec, 0, out);
}

/* spec for a reader that does without some parts (they are not looked for), and
 * whether the band reader takes it: one EXR that holds every part. */
static int
spec_for_bands(const mcp_dump_spec *spec, unsigned without, mcp_dump_spec *kept)
{
    *kept = *spec;
    if (without & MCP__DUMP_NO_ALBEDO) kept->albedo_path = NULL;
    if (without & MCP__DUMP_NO_NORMAL) kept->normal_path = NULL;
    return kept->path && !kept->variance_path && !kept->albedo_path &&
           !kept->normal_path && !kept->spp_map_path &&
           mcp_format_from_path(kept->path) == MCP_FORMAT_EXR;
}

int
mcp__dump_bands_size_of(const mcp_dump_spec *spec, unsigned without, int *width,
                        int *height)
{
    *width = *height = 0;
    mcp_dump_spec kept;
    if (!spec_for_bands(spec, without, &kept)) return 0;
    mcp__exr_rows *r = NULL;
    if (mcp__exr_rows_open(kept.path, &r)) return -1;
    mcp__exr_rows_header(r, width, height);
    mcp__exr_rows_close(r);
    return 0;
}

int
mcp__dump_bands_open_without(const mcp_dump_spec *spec_, unsigned without,
                             mcp__dump_bands **out)
{
    *out = NULL;
    mcp_dump_spec kept;
    if (!spec_for_bands(spec_, without, &kept)) return 0;
    const mcp_dump_spec *spec = &kept;
    mcp__dump_bands *b = mcp_calloc(1, sizeof *b);
    if (!b) return -1;
    b->spec = *spec;
    b->without = without;
    if (mcp__exr_rows_open(spec->path, &b->exr)) {
        mcp__dump_bands_close(b);
        return -1;
    }
    b->header = mcp__exr_rows_header(b->exr, &b->width, &b->height);
    /* the layout of the first row: two parts on one channel are read whole, and what
       is wrong with the header is said here, in a whole read's words */
    static const mcp_dump_buffers none;
    direct_read r = {.spec = &b->spec, .parts = &none, .without = without};
    int clash = 0, rc = -1;
    if ((r.d = mcp_calloc(1, sizeof *r.d)))
        rc = read_band_parts(b, 0, b->height > 0 ? 1 : 0, &r, &clash);
    direct_read_clear(&r);
    if (rc || clash) {
        if (clash) mcp_error_clear();
        mcp__dump_bands_close(b);
        return clash ? 0 : -1;
    }
    *out = b;
    return 0;
}

int
mcp__dump_bands_for_rows(const mcp_dump_spec *spec, int height, mcp__dump_bands **out)
{
    *out = mcp_calloc(1, sizeof **out);
    if (!*out) return -1;
    (*out)->spec = *spec;
    (*out)->height = height;
    return 0;
}

int
mcp__dump_bands_from_rows(mcp__dump_bands *b, const mcp_image *rows, int y0,
                          mcp_dump **out)
{
    *out = NULL;
    const int y1 = y0 + rows->height;
    if (y0 != b->next_row || y1 > b->height)
        return mcp_error("%s: rows %d..%d do not follow row %d of %d", rows->source, y0,
                         y1, b->next_row, b->height);
    static const mcp_dump_buffers none;
    mcp_dump *d = mcp_calloc(1, sizeof *d);
    if (!d) return -1;
    layout L;
    channel_source src = {.img = rows, .band = &b->check};
    b->check.y_off = y0;
    b->check.last = y1 == b->height;
    if (dump_layout(rows, &b->spec, d, &L) || dump_fill(d, &src, &b->spec, &none, &L)) {
        mcp_dump_free(d);
        return -1;
    }
    b->next_row = y1;
    *out = d;
    return 0;
}

void
mcp__dump_bands_size(const mcp__dump_bands *b, int *width, int *height)
{
    *width = b->width;
    *height = b->height;
}

const char *
mcp__dump_bands_source(const mcp__dump_bands *b)
{
    return b->header->source;
}

int
mcp__dump_bands_read(mcp__dump_bands *b, int y0, int y1, mcp_dump **out)
{
    *out = NULL;
    if (y0 != b->next_row || y1 <= y0 || y1 > b->height)
        return mcp_error("%s: rows %d..%d do not follow row %d of %d", b->header->source,
                         y0, y1, b->next_row, b->height);
    static const mcp_dump_buffers none;
    direct_read r = {.spec = &b->spec, .parts = &none, .without = b->without};
    int clash = 0, rc = -1;
    b->check.y_off = y0;
    b->check.last = y1 == b->height;
    r.src.band = &b->check;
    if ((r.d = mcp_calloc(1, sizeof *r.d)) &&
        read_band_parts(b, y0, y1, &r, &clash) == 0 &&
        dump_fill(r.d, &r.src, &b->spec, &none, &r.L) == 0) {
        *out = r.d;
        r.d = NULL;
        b->next_row = y1;
        rc = 0;
    }
    direct_read_clear(&r);
    return rc;
}

/* ---- a dump's rows as views ---- */

int
mcp__dump_rows_view(const mcp_dump *d, int y0, int y1, mcp_dump *out)
{
    *out = *d;
    mcp_image *const src[] = {d->color,  d->var_of_mean, d->cov_of_mean,
                              d->albedo, d->normal,      d->spp_map};
    mcp_image **dst[] = {&out->color,  &out->var_of_mean, &out->cov_of_mean,
                         &out->albedo, &out->normal,      &out->spp_map};
    for (size_t p = 0; p < sizeof dst / sizeof *dst; p++)
        *dst[p] = NULL;
    for (size_t p = 0; p < sizeof dst / sizeof *dst; p++) {
        const mcp_image *img = src[p];
        if (img && (mcp_image_crop_view(img, 0, y0, img->width, y1 - y0, dst[p]) ||
                    mcp_attrs_copy(&img->attrs, &(*dst[p])->attrs))) {
            mcp__dump_rows_view_free(out);
            return -1;
        }
    }
    return 0;
}

void
mcp__dump_rows_view_free(mcp_dump *view)
{
    mcp_image *parts[] = {view->color,  view->var_of_mean, view->cov_of_mean,
                          view->albedo, view->normal,      view->spp_map};
    for (size_t p = 0; p < sizeof parts / sizeof *parts; p++)
        mcp_image_free(parts[p]);
    memset(view, 0, sizeof *view);
}

/* ---- writing ---- */

/* Copies 3 channels of part (times the per-pixel sample count when per_sample, plus
 * the squared mean when add_mean_sq) into channels [at, at+3) of out. */
static void
put3(mcp_image *out, int at, const mcp_image *part, const mcp_dump *d, int per_sample,
     int add_mean_sq)
{
#pragma omp parallel for schedule(static) if ((long long)out->width * out->height > 65536)
    for (int y = 0; y < out->height; y++)
        for (int x = 0; x < out->width; x++) {
            const float *s = mcp_image_px(part, x, y), *m = mcp_image_px(d->color, x, y);
            float *o = mcp_image_px(out, x, y) + at;
            double n = per_sample ? mcp_dump_spp_at(d, x, y) : 1.0;
            for (int c = 0; c < 3; c++)
                o[c] = (float)(s[c] * n + (add_mean_sq ? (double)m[c] * m[c] : 0.0));
        }
}

int
mcp__dump_image(const mcp_dump *d, mcp_convention conv, const char *path, mcp_image **out)
{
    *out = NULL;
    static const char *const rgb[3] = {"R", "G", "B"}, *const xyz[3] = {"X", "Y", "Z"},
                             *const offdiag[3] = {"RG", "RB", "GB"};
    const char *L = "ViewLayer";
    char names[20][128];
    int n = 0, at_var = -1, at_cov = -1, at_alb = -1, at_nrm = -1, at_spp = -1;
    if (conv == MCP_CONV_AUTO || conv == MCP_CONV_PLAIN)
        conv = d->spp_map || d->cov_of_mean ? MCP_CONV_MCPOST : MCP_CONV_PBRT;
    if (d->spp_map && conv != MCP_CONV_MCPOST)
        return mcp_error("%s: per-pixel sample counts can only be written in the mcpost "
                         "convention",
                         path);
    for (int k = 0; k < 3; k++) {
        if (conv == MCP_CONV_BLENDER)
            snprintf(names[n++], 128, "%s.Combined.%s", L, rgb[k]);
        else
            snprintf(names[n++], 128, "%s", rgb[k]);
    }
    if (d->var_of_mean) {
        at_var = n;
        for (int k = 0; k < 3; k++)
            snprintf(names[n++], 128,
                     conv == MCP_CONV_MITSUBA   ? "m2_%s%s"
                     : conv == MCP_CONV_BLENDER ? "ViewLayer.Variance.%s%s"
                                                : "Variance.%s%s",
                     rgb[k], "");
    }
    if (d->cov_of_mean && conv == MCP_CONV_MCPOST) {
        at_cov = n;
        for (int k = 0; k < 3; k++)
            snprintf(names[n++], 128, "Covariance.%s", offdiag[k]);
    }
    if (d->albedo) {
        at_alb = n;
        for (int k = 0; k < 3; k++)
            snprintf(names[n++], 128,
                     conv == MCP_CONV_MITSUBA   ? "albedo.%s"
                     : conv == MCP_CONV_BLENDER ? "ViewLayer.Denoising Albedo.%s"
                                                : "Albedo.%s",
                     rgb[k]);
    }
    if (d->normal) {
        at_nrm = n;
        for (int k = 0; k < 3; k++)
            snprintf(names[n++], 128,
                     conv == MCP_CONV_MITSUBA   ? "sh_normal.%s"
                     : conv == MCP_CONV_BLENDER ? "ViewLayer.Denoising Normal.%s"
                                                : "N.%s",
                     xyz[k]);
    }
    if (d->spp_map) at_spp = n, snprintf(names[n++], 128, "SampleCount");
    const char *np[20];
    for (int i = 0; i < n; i++)
        np[i] = names[i];
    mcp_image *img;
    if (mcp_image_new(d->color->width, d->color->height, n, np, &img)) return -1;
    int rc = -1;
    put3(img, 0, d->color, d, 0, 0);
    if (at_var >= 0) put3(img, at_var, d->var_of_mean, d, 1, conv == MCP_CONV_MITSUBA);
    if (at_cov >= 0) put3(img, at_cov, d->cov_of_mean, d, 1, 0);
    if (at_alb >= 0) put3(img, at_alb, d->albedo, d, 0, 0);
    if (at_nrm >= 0) put3(img, at_nrm, d->normal, d, 0, 0);
    if (at_spp >= 0)
        for (int y = 0; y < img->height; y++)
            for (int x = 0; x < img->width; x++)
                mcp_image_px(img, x, y)[at_spp] = mcp_image_px(d->spp_map, x, y)[0];
    if (mcp_attrs_copy(&d->attrs, &img->attrs)) goto done;
    /* a variance that is not the renderer's own says where it came from, so that a
       later run does not take it for a per-sample variance */
    if (d->var_of_mean &&
        (d->variance_source == MCP_VARSRC_REPLICATES ||
         d->variance_source == MCP_VARSRC_INCREMENTS ||
         d->variance_source == MCP_VARSRC_XYZ_MOMENTS || d->variance_pool > 0)) {
        if (mcp_attrs_set_string(&img->attrs, ATTR_VARIANCE_SOURCE,
                                 mcp_variance_source_name(d->variance_source)) ||
            mcp_attrs_set_double(&img->attrs, ATTR_VARIANCE_DOF, d->variance_dof) ||
            mcp_attrs_set_int(&img->attrs, ATTR_REPLICATES, d->replicates) ||
            mcp_attrs_set_double(&img->attrs, ATTR_VARIANCE_POOL, d->variance_pool))
            goto done;
    }
    if (d->spp > 0) {
        char text[64];
        snprintf(text, sizeof text, "%.0f", d->spp);
        if (conv == MCP_CONV_BLENDER
                ? mcp_attrs_set_string(&img->attrs, "cycles.ViewLayer.samples", text)
            : conv == MCP_CONV_MITSUBA ? 0 /* Mitsuba writes no sample count */
                                       : mcp_attrs_set_int(&img->attrs, "samplesPerPixel",
                                                           (int64_t)llround(d->spp)))
            goto done;
    }
    *out = img;
    img = NULL;
    rc = 0;
done:
    mcp_image_free(img);
    return rc;
}

int
mcp_dump_write(const mcp_dump *d, const char *path, mcp_convention conv,
               const mcp_write_options *opt)
{
    mcp_image *img = NULL;
    int rc = mcp__dump_image(d, conv, path, &img) || mcp_image_write(img, path, opt);
    mcp_image_free(img);
    return rc ? -1 : 0;
}

/* ---- series ---- */

void
mcp_series_free(mcp_series *s)
{
    if (!s) return;
    /* paths is NULL when its own allocation failed (series_new) */
    for (int i = 0; s->paths && i < s->count; i++)
        free(s->paths[i]);
    free(s->paths);
    free(s->spp);
    mcp__series_colours_free(s->colours);
    free(s);
}

static int
series_new(int count, mcp_series **out)
{
    *out = NULL;
    if (count < 1) return mcp_error("a series needs at least one dump");
    mcp_series *s = mcp_calloc(1, sizeof *s);
    if (!s) return -1;
    s->count = count;
    s->paths = mcp_calloc((size_t)count, sizeof *s->paths);
    s->spp = mcp_calloc((size_t)count, sizeof *s->spp);
    if (!s->paths || !s->spp || mcp__series_colours_new(count, &s->colours)) {
        mcp_series_free(s);
        return -1;
    }
    s->spec = mcp_dump_spec_defaults();
    *out = s;
    return 0;
}

/* The widest field a series pattern may ask for (an int needs 11 characters; more is
 * only padding), and the longest path it may produce: an unbounded width would format
 * paths of gigabytes, and one past INT_MAX makes snprintf fail. */
#define SERIES_MAX_WIDTH 16
#define SERIES_MAX_PATH 4096

/* Accepts exactly one integer conversion (%d, %i, %u with flags and a width of at most
 * SERIES_MAX_WIDTH) and no other conversion but "%%", so a pattern can never read a
 * missing argument. */
static int
check_pattern(const char *pattern)
{
    int conversions = 0;
    for (const char *p = pattern; *p; p++) {
        if (*p != '%') continue;
        if (p[1] == '%') {
            p++;
            continue;
        }
        p++;
        while (*p && strchr("0-+ #", *p))
            p++;
        int width = 0;
        for (; isdigit((unsigned char)*p); p++)
            if ((width = width * 10 + (*p - '0')) > SERIES_MAX_WIDTH)
                return mcp_error("series pattern '%s': field widths over %d are refused",
                                 pattern, SERIES_MAX_WIDTH);
        if (!*p || !strchr("diu", *p)) {
            conversions = 0;
            break;
        }
        conversions++;
    }
    if (conversions != 1)
        return mcp_error("series pattern '%s' must hold exactly one integer conversion "
                         "such as %%04d",
                         pattern);
    return 0;
}

int
mcp_series_from_pattern(const char *pattern, const int *spps, int count, mcp_series **out)
{
    if (check_pattern(pattern)) return -1;
    mcp_series *s;
    if (series_new(count, &s)) return -1;
    for (int i = 0; i < count; i++) {
        if (spps[i] < 1) {
            mcp_series_free(s);
            return mcp_error("series '%s': sample count %d (must be >= 1)", pattern,
                             spps[i]);
        }
        if (i && spps[i] <= spps[i - 1]) {
            mcp_series_free(s);
            return mcp_error("series '%s': sample counts must increase (%d after %d)",
                             pattern, spps[i], spps[i - 1]);
        }
        int n = snprintf(NULL, 0, pattern, spps[i]);
        if (n < 0 || n >= SERIES_MAX_PATH) {
            mcp_series_free(s);
            /* the pattern last: a long one is cut off at the end of the message */
            return mcp_error("series: the path for %d spp is longer than %d characters "
                             "(pattern '%s')",
                             spps[i], SERIES_MAX_PATH - 1, pattern);
        }
        if (!(s->paths[i] = mcp_malloc((size_t)n + 1))) {
            mcp_series_free(s);
            return -1;
        }
        snprintf(s->paths[i], (size_t)n + 1, pattern, spps[i]);
        s->spp[i] = spps[i];
    }
    *out = s;
    return 0;
}

int
mcp_series_from_paths(const char *const *paths, const double *spps, int count,
                      mcp_series **out)
{
    mcp_series *s;
    if (series_new(count, &s)) return -1;
    for (int i = 0; i < count; i++) {
        if (!(s->paths[i] = mcp_strdup(paths[i]))) {
            mcp_series_free(s);
            return -1;
        }
        s->spp[i] = spps ? spps[i] : 0;
    }
    *out = s;
    return 0;
}

/* The first member of a series without variance (auto): the per-sample spread that
 * the first two blocks show (member 1's increments' variance, of its mean) scaled to
 * the first member's count, Var X_0 = Var X_1 n_1 / n_0: the same blocks, the same
 * estimate of the per-sample variance. Left as it is when that cannot be formed. */
static int
first_member_from_increments(const mcp_series *s, mcp_dump *first)
{
    mcp_dump *incr = NULL;
    if (mcp__series_increment_variance(s, 1, MCP__DUMP_NO_ALBEDO | MCP__DUMP_NO_NORMAL,
                                       &s->increments, &incr, NULL)) {
        if (strstr(mcp_error_message(), "out of memory")) return -1;
        mcp_error_clear();
        return 0;
    }
    if (first->spp > 0 && incr->spp > 0 && !first->spp_map && !incr->spp_map &&
        incr->var_of_mean) {
        double scale = incr->spp / first->spp;
        size_t n = (size_t)incr->var_of_mean->width * incr->var_of_mean->height *
                   incr->var_of_mean->channels;
        for (size_t k = 0; k < n; k++)
            incr->var_of_mean->data[k] = (float)(incr->var_of_mean->data[k] * scale);
        first->var_of_mean = incr->var_of_mean;
        incr->var_of_mean = NULL;
        first->variance_source = incr->variance_source;
        first->variance_dof = incr->variance_dof;
        first->replicates = incr->replicates;
    }
    mcp_dump_free(incr);
    return 0;
}

int
mcp_series_load(const mcp_series *s, int i, mcp_dump **out)
{
    return mcp__series_load_without(s, i, 0, out);
}

int
mcp__series_load_without(const mcp_series *s, int i, unsigned without, mcp_dump **out)
{
    *out = NULL;
    if (i < 0 || i >= s->count)
        return mcp_error("series member %d of %d does not exist", i, s->count);
    if (s->variance_from == MCP_SERIES_VARIANCE_INCREMENTS && i > 0) {
        /* the increments need two blocks; a member before that keeps its own */
        double ratio;
        if (mcp__series_increment_variance(s, i, without, &s->increments, out, &ratio) ==
            0)
            return 0;
        if (!strstr(mcp_error_message(), "needs two blocks")) return -1;
        mcp_error_clear();
    }
    if (mcp__series_load_file(s, i, without, out)) return -1;
    /* a member without any variance (a plain Cycles render) takes its increments'
       whatever they say: there is nothing else */
    int none = !(*out)->var_of_mean;
    if (s->variance_from == MCP_SERIES_VARIANCE_AUTO && i == 0 && none && s->count > 1)
        return first_member_from_increments(s, *out);
    if (s->variance_from != MCP_SERIES_VARIANCE_AUTO || i == 0 ||
        (!mcp__variance_is_per_sample((*out)->variance_source) && !none))
        return 0;
    /* auto: a per-sample variance is checked against the series' own increments, and
       replaced by theirs where it is off (docs/variance-sources.md) */
    mcp_dump *incr = NULL;
    double ratio = 0;
    if (mcp__series_increments_with(s, i, *out, &s->increments, &incr, &ratio)) {
        /* no increments to compare with (one block, members out of order, another
           member unreadable): the file's own variance stands, and whatever is wrong
           with the series is reported where it is used */
        if (strstr(mcp_error_message(), "out of memory")) {
            mcp_dump_free(*out);
            *out = NULL;
            return -1;
        }
        mcp_error_clear();
        return 0;
    }
    /* only an overstatement (a stratified sampler) is taken as the increments' cue: a
       Variance/n below their spread can also mean members that are not checkpoints of
       one render, whose differences are no increments at all */
    if (none || (mcp_variance_ratio_off(ratio) && ratio > 1)) {
        mcp_dump_free(*out);
        *out = incr;
    } else {
        mcp_dump_free(incr);
    }
    return 0;
}

static const char *const series_variance_names[] = {"auto", "file", "increments"};
const mcp_wordlist mcp_series_variance_words = {"variance_from", series_variance_names,
                                                3};

const char *
mcp_series_variance_name(mcp_series_variance v)
{
    return mcp_wordlist_name(&mcp_series_variance_words, (int)v);
}

int
mcp_series_variance_from_name(const char *name, mcp_series_variance *out)
{
    if (mcp_wordlist_find(&mcp_series_variance_words, name, (int *)out))
        return mcp_error("variance_from must be auto, file or increments (got '%s')",
                         name);
    return 0;
}

int
mcp_variance_ratio_off(double ratio)
{
    return ratio > 0 && (ratio > 1.25 || ratio < 0.8);
}

const char *
mcp__no_variance_hint(const mcp_dump *d, const char *otherwise)
{
    return d && d->convention == MCP_CONV_BLENDER
               ? ": Cycles writes none; render the .blend with "
                 "tools/mcpost-cycles-render.py "
                 "(docs/conventions.md, \"From a .blend to an estimate\")"
               : otherwise;
}

int
mcp__series_load_file(const mcp_series *s, int i, unsigned without, mcp_dump **out)
{
    *out = NULL;
    mcp_dump_spec spec = s->spec;
    spec.path = s->paths[i];
    if (s->spp[i] > 0) spec.spp = s->spp[i];
    return mcp__dump_load_without(&spec, without, out);
}
