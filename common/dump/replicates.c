/* replicates.c: a variance of the mean that rests on what the renders show, not on
 * the renderer's per-sample variance: the spread between independent renders of a
 * frame (mcp_dump_merge), between the increments of one progressive render
 * (mcp_series_increment_variance), and the pooling that gives such a few-dof
 * estimate enough degrees of freedom (mcp_dump_pool_variance). The derivations are
 * in docs "Variance sources". */
#include "internal.h"
#include "../core/internal.h"

#include <mcpost/dump.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const char *const merge_variance_names[] = {"replicates", "pooled"};
const mcp_wordlist mcp_merge_variance_words = {"merge variance", merge_variance_names, 2};

int
mcp_merge_variance_from_name(const char *name, mcp_merge_variance *out)
{
    return mcp_wordlist_find(&mcp_merge_variance_words, name, (int *)out);
}

mcp_merge_options
mcp_merge_defaults(void)
{
    mcp_merge_options o = {MCP_MERGE_REPLICATES, 0};
    return o;
}

mcp_increment_options
mcp_increment_defaults(void)
{
    mcp_increment_options o = {0, 0};
    return o;
}

int
mcp_variance_pool_radius(double dof, double min_dof)
{
    if (!(dof > 0) || dof >= min_dof) return 0;
    /* the smallest odd window side 2r + 1 with dof (2r + 1)² >= min_dof */
    int side = (int)ceil(sqrt(min_dof / dof));
    return side / 2;
}

static int
new3(const mcp_image *like, const char *a, const char *b, const char *c, mcp_image **out)
{
    return mcp_image_new(like->width, like->height, 3, (const char *const[]){a, b, c},
                         out);
}

/* ---- merging ---- */

/* The colour pairs of a covariance's channels RG, RB, GB. */
static const int cov_pair[3][2] = {{0, 1}, {0, 2}, {1, 2}};

/* Adds w times the outer product of a deviation from the mean: its diagonal to ss
 * (R, G, B) and its off-diagonal to sc (RG, RB, GB). */
static void
add_spread(double w, const double dev[3], double ss[3], double sc[3])
{
    for (int c = 0; c < 3; c++)
        ss[c] += w * dev[c] * dev[c];
    for (int j = 0; j < 3; j++)
        sc[j] += w * dev[cov_pair[j][0]] * dev[cov_pair[j][1]];
}

static int
check_parts(const mcp_dump *const *parts, int count, const mcp_merge_options *opt)
{
    if (count < 1) return mcp_error("merge: no dumps given");
    if (opt->variance == MCP_MERGE_REPLICATES && count < 2)
        return mcp_error("merge: replicates need at least 2 dumps (got 1): the spread "
                         "of one render says nothing");
    const mcp_image *c0 = parts[0]->color;
    for (int k = 0; k < count; k++) {
        const mcp_dump *d = parts[k];
        if (d->color->width != c0->width || d->color->height != c0->height)
            return mcp_error("merge: %s is %dx%d, but %s is %dx%d", d->source,
                             d->color->width, d->color->height, parts[0]->source,
                             c0->width, c0->height);
        if (!d->spp_map && !(d->spp > 0))
            return mcp_error("merge: %s has no sample count (give it with spp)",
                             d->source);
        if (opt->variance == MCP_MERGE_POOLED && !d->var_of_mean)
            return mcp_error("merge: %s has no variance, which pooling needs (merge it "
                             "as replicates instead)",
                             d->source);
    }
    return 0;
}

/* The weighted mean of one 3-channel part over all dumps (albedo, normal, colour),
 * or NULL when some dump lacks it (features) -- colour is always there. */
static int
merge_mean(const mcp_dump *const *parts, int count, size_t offset,
           const char *const *names, mcp_image **out)
{
    *out = NULL;
    for (int k = 0; k < count; k++)
        if (!*(mcp_image *const *)((const char *)parts[k] + offset)) return 0;
    const mcp_image *c0 = parts[0]->color;
    if (new3(c0, names[0], names[1], names[2], out)) return -1;
    mcp_image *m = *out;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < c0->height; y++)
        for (int x = 0; x < c0->width; x++) {
            double sum[3] = {0, 0, 0}, n = 0;
            for (int k = 0; k < count; k++) {
                const mcp_image *part =
                    *(mcp_image *const *)((const char *)parts[k] + offset);
                double nk = mcp_dump_spp_at(parts[k], x, y);
                const float *v = mcp_image_px(part, x, y);
                for (int c = 0; c < 3; c++)
                    sum[c] += nk * v[c];
                n += nk;
            }
            float *o = mcp_image_px(m, x, y);
            for (int c = 0; c < 3; c++)
                o[c] = n > 0 ? (float)(sum[c] / n) : 0.0f;
        }
    return 0;
}

/* The variance and covariance of the merged mean, per opt->variance. */
static void
merge_variance(const mcp_dump *const *parts, int count, const mcp_merge_options *opt,
               const mcp_image *mean, mcp_image *var, mcp_image *cov)
{
#pragma omp parallel for schedule(static)
    for (int y = 0; y < mean->height; y++)
        for (int x = 0; x < mean->width; x++) {
            const float *m = mcp_image_px(mean, x, y);
            double ss[3] = {0, 0, 0}, sc[3] = {0, 0, 0}, n = 0;
            int k_used = 0;
            for (int k = 0; k < count; k++) {
                const mcp_dump *d = parts[k];
                double nk = mcp_dump_spp_at(d, x, y);
                if (!(nk > 0)) continue;
                k_used++;
                n += nk;
                const float *v = mcp_image_px(d->color, x, y);
                double dev[3];
                for (int c = 0; c < 3; c++)
                    dev[c] = (double)v[c] - m[c];
                add_spread(nk, dev, ss, sc);
                if (opt->variance == MCP_MERGE_POOLED) {
                    /* the part's own sum of squared deviations, (n_k - 1) s_k² with
                       s_k² = n_k × its variance of the mean */
                    const float *vk = mcp_image_px(d->var_of_mean, x, y);
                    for (int c = 0; c < 3; c++)
                        ss[c] += (nk - 1) * nk * vk[c];
                    if (d->cov_of_mean) {
                        const float *ck = mcp_image_px(d->cov_of_mean, x, y);
                        for (int j = 0; j < 3; j++)
                            sc[j] += (nk - 1) * nk * ck[j];
                    }
                }
            }
            /* replicates: Σ n_k dev² / (K - 1) estimates σ², the variance of the mean
               is σ² / N; pooled: M2 / (N - 1) is the per-sample variance, / N again */
            double denom = opt->variance == MCP_MERGE_REPLICATES
                               ? (double)(k_used - 1) * n
                               : (n - 1) * n;
            float *o = mcp_image_px(var, x, y);
            float *oc = cov ? mcp_image_px(cov, x, y) : NULL;
            for (int c = 0; c < 3; c++)
                o[c] = denom > 0 ? (float)(ss[c] / denom) : 0.0f;
            for (int j = 0; oc && j < 3; j++)
                oc[j] = denom > 0 ? (float)(sc[j] / denom) : 0.0f;
        }
}

/* A per-pixel count map as the sum of the parts' counts, or NULL when all are scalar. */
static int
merge_spp(const mcp_dump *const *parts, int count, mcp_dump *out)
{
    int any_map = 0;
    out->spp = 0;
    for (int k = 0; k < count; k++) {
        any_map |= parts[k]->spp_map != NULL;
        out->spp += parts[k]->spp;
    }
    if (!any_map) return 0;
    out->spp = 0;
    const mcp_image *c0 = parts[0]->color;
    if (mcp_image_new(c0->width, c0->height, 1, (const char *const[]){"SampleCount"},
                      &out->spp_map))
        return -1;
    for (int y = 0; y < c0->height; y++)
        for (int x = 0; x < c0->width; x++) {
            double n = 0;
            for (int k = 0; k < count; k++)
                n += mcp_dump_spp_at(parts[k], x, y);
            mcp_image_px(out->spp_map, x, y)[0] = (float)n;
        }
    return 0;
}

int
mcp_dump_merge(const mcp_dump *const *parts, int count, const mcp_merge_options *opt,
               mcp_dump **out)
{
    mcp_merge_options defaults = mcp_merge_defaults();
    if (!opt) opt = &defaults;
    *out = NULL;
    if (check_parts(parts, count, opt)) return -1;
    mcp_dump *d = mcp_calloc(1, sizeof *d);
    if (!d) return -1;
    static const char *const rgb[3] = {"R", "G", "B"}, *const xyz[3] = {"X", "Y", "Z"};
    int want_cov = opt->variance == MCP_MERGE_REPLICATES;
    for (int k = 0; k < count && !want_cov; k++)
        want_cov = parts[k]->cov_of_mean != NULL;
    if (merge_mean(parts, count, offsetof(mcp_dump, color), rgb, &d->color) ||
        merge_mean(parts, count, offsetof(mcp_dump, albedo), rgb, &d->albedo) ||
        merge_mean(parts, count, offsetof(mcp_dump, normal), xyz, &d->normal) ||
        new3(d->color, "R", "G", "B", &d->var_of_mean) ||
        (want_cov && new3(d->color, "RG", "RB", "GB", &d->cov_of_mean)) ||
        merge_spp(parts, count, d) || !(d->source = mcp_strdup(parts[0]->source)) ||
        mcp_attrs_copy(&parts[0]->attrs, &d->attrs))
        goto fail;
    merge_variance(parts, count, opt, d->color, d->var_of_mean, d->cov_of_mean);
    d->convention = MCP_CONV_MCPOST;
    d->variance_in_file = MCP_VAR_OF_MEAN;
    if (opt->variance == MCP_MERGE_REPLICATES) {
        d->variance_source = MCP_VARSRC_REPLICATES;
        d->variance_dof = count - 1;
        d->replicates = count;
    } else {
        /* passes of one render: the per-sample variance keeps its meaning */
        d->variance_source = parts[0]->variance_source;
        d->variance_dof = parts[0]->variance_dof;
        d->replicates = parts[0]->replicates;
    }
    if (opt->pool_radius > 0) {
        /* the renderers' own per-sample variances, pooled exactly, are the shape */
        mcp_merge_options pooled = {MCP_MERGE_POOLED, 0};
        mcp_dump *shape = NULL;
        int have_shape = opt->variance == MCP_MERGE_REPLICATES;
        for (int k = 0; k < count; k++)
            have_shape &= parts[k]->var_of_mean != NULL &&
                          mcp__variance_is_per_sample(parts[k]->variance_source);
        if (have_shape && mcp_dump_merge(parts, count, &pooled, &shape)) goto fail;
        int rc = mcp_dump_pool_variance(d, shape ? shape->var_of_mean : NULL,
                                        opt->pool_radius);
        mcp_dump_free(shape);
        if (rc) goto fail;
    }
    *out = d;
    return 0;
fail:
    mcp_dump_free(d);
    return -1;
}

/* ---- pooling ---- */

int
mcp_dump_pool_variance(mcp_dump *d, const mcp_image *shape, int radius)
{
    if (!d->var_of_mean) return mcp_error("%s: no variance to pool", d->source);
    if (radius < 0)
        return mcp_error("variance pooling: radius must be >= 0 (got %d)", radius);
    if (radius == 0) return 0;
    int w = d->var_of_mean->width, h = d->var_of_mean->height;
    if (shape && (shape->width != w || shape->height != h || shape->channels < 3))
        return mcp_error("variance pooling: the shape is %dx%d with %d channels, the "
                         "variance %dx%d with 3",
                         shape->width, shape->height, shape->channels, w, h);
    /* the window sums of a band come from the values as they were, so the band can
       be overwritten in place */
    const mcp_image *imgs[3] = {d->var_of_mean};
    int n_imgs = 1, is = -1, ic = -1;
    if (shape) imgs[is = n_imgs++] = shape;
    if (d->cov_of_mean) imgs[ic = n_imgs++] = d->cov_of_mean;
    mcp__window wb;
    int rc = mcp__window_begin(&wb, imgs, n_imgs, radius);
    for (int y0 = 0; !rc && y0 < h; y0 += wb.rows) {
        const int y1 = y0 + wb.rows < h ? y0 + wb.rows : h;
        if ((rc = mcp__window_band(&wb, y0, y1))) break;
#pragma omp parallel for schedule(static)
        for (int y = y0; y < y1; y++)
            for (int x = 0; x < w; x++) {
                const double *sv = mcp__window_at(&wb, 0, x, y);
                const double *ss = is >= 0 ? mcp__window_at(&wb, is, x, y) : NULL;
                const int n = mcp__window_count(&wb, x, y);
                /* the factor that turns the shape into the pooled level, per channel */
                double ratio[3];
                const float *sh = shape ? mcp_image_px(shape, x, y) : NULL;
                for (int c = 0; c < 3; c++)
                    ratio[c] = ss && ss[c] > 0 ? sv[c] / ss[c] : -1;
                float *v = mcp_image_px(d->var_of_mean, x, y);
                for (int c = 0; c < 3; c++)
                    v[c] = sh && ratio[c] >= 0 ? (float)(sh[c] * ratio[c])
                                               : (float)(sv[c] / n);
                if (ic >= 0) {
                    /* the covariance as a pooled correlation times the pooled standard
                       deviations: Σ_W cov / sqrt(Σ_W V_a Σ_W V_b) is within [-1, 1]
                       (Cauchy-Schwarz), so the matrix stays a covariance; without a
                       shape this is the window mean */
                    const double *sc = mcp__window_at(&wb, ic, x, y);
                    float *cv = mcp_image_px(d->cov_of_mean, x, y);
                    for (int j = 0; j < 3; j++) {
                        int a = cov_pair[j][0], b = cov_pair[j][1];
                        double norm = sqrt(sv[a] * sv[b]);
                        cv[j] = norm > 0
                                    ? (float)(sc[j] / norm * sqrt((double)v[a] * v[b]))
                                    : 0.0f;
                    }
                }
            }
    }
    mcp__window_end(&wb);
    if (rc) return -1;
    d->variance_pool = (double)(2 * radius + 1) * (2 * radius + 1);
    return 0;
}

/* ---- increments of a progressive series ---- */

/* The sums behind one member's increments variance: per value, each block's
 * size-weighted squared deviation of its mean from the member's mean X (R, G, B) and
 * the cross products of its colour deviations (RG, RB, GB), in double, six a pixel. A
 * block is the samples from one member to the next, or all of the first member's.
 * Blocks are added one at a time in the series' order, so that a series read member by
 * member holds these sums and two members instead of every member at once, and gets
 * the same bits as a series held whole. */
typedef struct increment_sums {
    const mcp_image *X;
    double *s;
    int blocks;
} increment_sums;

/* 1 when the member fits the increments: a scalar sample count above the one before
 * it (prev_spp; 0 for none) and the size of the member whose variance is sought. */
static int
increment_member_ok(const mcp_dump *d, double prev_spp, const mcp_dump *last)
{
    if (d->spp_map || !(d->spp > 0))
        return !mcp_error("%s: increments need one sample count per member (a scalar "
                          "spp)",
                          d->source);
    if (prev_spp > 0 && !(d->spp > prev_spp))
        return !mcp_error("%s: series members must have increasing sample counts (%g "
                          "after %g)",
                          d->source, d->spp, prev_spp);
    if (d->color->width != last->color->width || d->color->height != last->color->height)
        return !mcp_error("%s: not the size of %s", d->source, last->source);
    return 1;
}

/* Where the first block starts for a member of n samples: the least count it takes. */
static double
increments_first_spp(const mcp_increment_options *opt, double n)
{
    return opt->first_spp > 0 ? opt->first_spp : n / 64;
}

static int
increment_sums_begin(increment_sums *a, const mcp_image *X)
{
    a->X = X;
    a->blocks = 0;
    a->s = mcp_calloc((size_t)X->width * X->height * 6, sizeof *a->s);
    return a->s ? 0 : -1;
}

/* Adds the block of samples from prev's count to cur's (all of cur's when prev is
 * NULL); its mean from the two running means. */
static void
increment_sums_add(increment_sums *a, const mcp_dump *cur, const mcp_dump *prev)
{
    const mcp_image *X = a->X;
    const double nb = cur->spp, np = prev ? prev->spp : 0, size = nb - np;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < X->height; y++)
        for (int x = 0; x < X->width; x++) {
            const float *xm = mcp_image_px(X, x, y), *xb = mcp_image_px(cur->color, x, y);
            const float *xp = prev ? mcp_image_px(prev->color, x, y) : NULL;
            double dev[3];
            for (int c = 0; c < 3; c++)
                dev[c] = (xp ? (nb * xb[c] - np * xp[c]) / size : xb[c]) - xm[c];
            double *s = a->s + 6 * ((size_t)y * X->width + x);
            add_spread(size, dev, s, s + 3);
        }
    a->blocks++;
}

/* The member `last` with the variance of the sums' blocks, pooled per opt, into *out;
 * frees the sums. */
static int
increment_sums_finish(increment_sums *a, const mcp_dump *last,
                      const mcp_increment_options *opt, mcp_dump **out, double *ratio)
{
    const int blocks = a->blocks;
    const double n = last->spp;
    const mcp_image *X = last->color;
    mcp_image *shape = NULL;
    mcp_dump *d = NULL;
    if (blocks < 2) {
        mcp_error("%s: the variance from increments needs two blocks of samples "
                  "(members from %g spp on); this member is the first",
                  last->source, increments_first_spp(opt, n));
        goto fail;
    }
    /* the member itself, with the variance replaced */
    if (!(d = mcp_calloc(1, sizeof *d)) || mcp_image_copy(last->color, &d->color) ||
        (last->albedo && mcp_image_copy(last->albedo, &d->albedo)) ||
        (last->normal && mcp_image_copy(last->normal, &d->normal)) ||
        !(d->source = mcp_strdup(last->source)) ||
        mcp_attrs_copy(&last->attrs, &d->attrs) ||
        new3(X, "R", "G", "B", &d->var_of_mean) ||
        new3(X, "RG", "RB", "GB", &d->cov_of_mean))
        goto fail;
    d->spp = n;
    d->convention = last->convention;
    if (last->var_of_mean && mcp__variance_is_per_sample(last->variance_source) &&
        mcp_image_copy(last->var_of_mean, &shape))
        goto fail;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < X->height; y++)
        for (int x = 0; x < X->width; x++) {
            const double *s = a->s + 6 * ((size_t)y * X->width + x);
            float *v = mcp_image_px(d->var_of_mean, x, y),
                  *cv = mcp_image_px(d->cov_of_mean, x, y);
            for (int c = 0; c < 3; c++)
                v[c] = (float)(s[c] / ((blocks - 1) * n));
            for (int j = 0; j < 3; j++)
                cv[j] = (float)(s[3 + j] / ((blocks - 1) * n));
        }
    free(a->s);
    a->s = NULL;
    if (ratio && shape) {
        double sum_shape = 0, sum_incr = 0;
        for (int y = 0; y < X->height; y++)
            for (int x = 0; x < X->width; x++)
                for (int c = 0; c < 3; c++) {
                    sum_shape += mcp_image_px(shape, x, y)[c];
                    sum_incr += mcp_image_px(d->var_of_mean, x, y)[c];
                }
        *ratio = sum_incr > 0 ? sum_shape / sum_incr : 0;
    }
    d->variance_source = MCP_VARSRC_INCREMENTS;
    d->variance_dof = blocks - 1;
    d->replicates = blocks;
    d->variance_in_file = MCP_VAR_OF_MEAN;
    int radius = opt->pool_radius > 0    ? opt->pool_radius
                 : opt->pool_radius == 0 ? mcp_variance_pool_radius(blocks - 1, 100)
                                         : 0;
    if (mcp_dump_pool_variance(d, shape, radius)) goto fail;
    mcp_image_free(shape);
    *out = d;
    return 0;
fail:
    free(a->s);
    a->s = NULL;
    mcp_image_free(shape);
    mcp_dump_free(d);
    return -1;
}

int
mcp_dump_increment_variance(const mcp_dump *const *members, int count,
                            const mcp_increment_options *opt, mcp_dump **out,
                            double *ratio)
{
    mcp_increment_options defaults = mcp_increment_defaults();
    if (!opt) opt = &defaults;
    *out = NULL;
    if (ratio) *ratio = 0;
    if (count < 1) return mcp_error("increments: no members given");
    const mcp_dump *last = members[count - 1];
    for (int k = 0; k < count; k++)
        if (!increment_member_ok(members[k], k ? members[k - 1]->spp : 0, last))
            return -1;
    int i = count - 1, first = 0;
    const double first_spp = increments_first_spp(opt, last->spp);
    /* the first block ends at the first member with at least first_spp samples:
       smaller blocks sit where a stratified sampler's variance does not scale as 1/n */
    while (first < i && members[first]->spp < first_spp)
        first++;
    increment_sums a;
    if (increment_sums_begin(&a, last->color)) return -1;
    for (int b = first; b <= i; b++)
        increment_sums_add(&a, members[b], b == first ? NULL : members[b - 1]);
    return increment_sums_finish(&a, last, opt, out, ratio);
}

int
mcp_series_variance_ratio(const mcp_series *s, double *ratio)
{
    *ratio = 0;
    if (s->count < 2) return 0;
    mcp_series plain = *s;
    plain.variance_from =
        MCP_SERIES_VARIANCE_FILE; /* the files' own variance is the shape */
    mcp_increment_options io = s->increments;
    io.pool_radius = -1; /* the ratio is image-wide: no pooling needed */
    mcp_dump *incr = NULL, *last = NULL;
    if (mcp_series_increment_variance(&plain, s->count - 1, &io, &incr, ratio) == 0) {
        mcp_dump_free(incr);
        return 0;
    }
    /* nothing to measure, unless a member could not be read at all or memory ran out
       (which says nothing about the series; tests/common/test_alloc) */
    *ratio = 0;
    if (strstr(mcp_error_message(), "out of memory")) return -1;
    int unreadable = mcp__series_load_file(
        s, s->count - 1, MCP__DUMP_NO_ALBEDO | MCP__DUMP_NO_NORMAL, &last);
    mcp_dump_free(last);
    if (unreadable) return -1;
    mcp_error_clear();
    return 0;
}

int
mcp__series_increment_variance(const mcp_series *s, int i, unsigned without,
                               const mcp_increment_options *opt, mcp_dump **out,
                               double *ratio)
{
    *out = NULL;
    if (i < 0 || i >= s->count)
        return mcp_error("series: no member %d (it has %d)", i, s->count);
    mcp_dump *member = NULL;
    int rc = mcp__series_load_file(s, i, without, &member) ||
             mcp__series_increments_with(s, i, member, opt, out, ratio);
    mcp_dump_free(member);
    return rc ? -1 : 0;
}

int
mcp_series_increment_variance(const mcp_series *s, int i,
                              const mcp_increment_options *opt, mcp_dump **out,
                              double *ratio)
{
    return mcp__series_increment_variance(s, i, 0, opt, out, ratio);
}

int
mcp__series_increments_with(const mcp_series *s, int i, const mcp_dump *member,
                            const mcp_increment_options *opt, mcp_dump **out,
                            double *ratio)
{
    mcp_increment_options defaults = mcp_increment_defaults();
    if (!opt) opt = &defaults;
    *out = NULL;
    if (ratio) *ratio = 0;
    if (!increment_member_ok(member, 0, member)) return -1;
    /* the members before i one at a time, each block added as its member is read: the
       sums and two members' colours at once, whatever the length of the series, and
       the colours kept for the next member up to a budget (series_colours.c); members
       below the first block's count are not read where the series gives their counts,
       and nothing reads their albedo, normal or variance */
    const double first_spp = increments_first_spp(opt, member->spp);
    increment_sums a;
    if (increment_sums_begin(&a, member->color)) return -1;
    const mcp_dump *prev = NULL;
    double prev_spp = 0;
    int rc = 0;
    for (int k = 0; k < i && !rc; k++) {
        if (!prev && s->spp[k] > 0 && s->spp[k] < first_spp) {
            if (!(s->spp[k] > prev_spp))
                rc = mcp_error("%s: series members must have increasing sample counts "
                               "(%g after %g)",
                               s->paths[k], s->spp[k], prev_spp);
            prev_spp = s->spp[k];
            continue;
        }
        const mcp_dump *d = NULL;
        rc = mcp__series_colour(s, k, &d) || !increment_member_ok(d, prev_spp, member);
        if (!rc) prev_spp = d->spp;
        if (!rc && !prev && d->spp < first_spp) { /* before the first block */
            mcp__series_colour_release(s, d);
            continue;
        }
        if (!rc) increment_sums_add(&a, d, prev);
        mcp__series_colour_release(s, prev);
        prev = d;
    }
    rc = rc || !increment_member_ok(member, prev_spp, member);
    if (!rc) increment_sums_add(&a, member, prev);
    mcp__series_colour_release(s, prev);
    if (rc) {
        free(a.s);
        return -1;
    }
    return increment_sums_finish(&a, member, opt, out, ratio);
}
