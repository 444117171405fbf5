/* sure.c: Stein's unbiased risk estimate of a denoised render
 * (docs/mathematics.md §2.2-§2.4; Firmino 2024 Alg. 2 and Eqs. 6-12, Li 2017,
 * Ramani 2008 for MC-SURE).
 *
 * Per value i, with K probes ε_k ~ N(0, Σ̂):
 *   SURE_i   = (F_i - X_i)² + mean_k ε_k,i (2 (Jε_k)_i - ε_k,i)
 *   SURE_M,i = (M(F - X))_i² + mean_k (Mε_k)_i (M(2Jε_k - ε_k))_i
 * Joint SURE draws (ε_x, ε_y) from the colour-feature covariance and uses
 * J_x ε_x + J_y ε_y in place of Jε (the last term stays ε_x,i²). MC-SURE replaces Jε by
 * (F(X + δε) - F(X)) / δ. The same evaluation gives Var[F_i] ≈ mean_k (Jε_k)_i²
 * (Firmino 2024 Alg. 2 line 5) and the scaled Σ̂_ii for block splitting. M is FLIP's
 * CSF operator (common/metrics/flip_csf.c). */
#define _POSIX_C_SOURCE 200809L /* clock_gettime, strcasecmp */
#include "estimate.h"
#include "internal.h"

#include <mcpost/flip.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

static const char *const metric_names[] = {"relse", "relse-perceptual", "se"};
const mcp_wordlist mcp_error_metric_words = {"metric", metric_names, 3};

int
mcp_error_metric_from_name(const char *name, mcp_error_metric *out)
{
    return mcp_wordlist_find(&mcp_error_metric_words, name, (int *)out);
}

const char *
mcp_error_metric_name(mcp_error_metric metric)
{
    return (unsigned)metric < 3 ? metric_names[metric] : "unknown";
}

mcp_sure_options
mcp_sure_defaults(void)
{
    mcp_sure_options o;
    memset(&o, 0, sizeof o);
    o.metric = MCP_METRIC_RELSE;
    o.n_probes = 1;
    o.seed = 0;
    o.ppd = 0.0;
    o.mc_sure = 0;
    o.fd_delta = 0.1;
    o.features = NULL;
    return o;
}

static int
check_options(const mcp_sure_options *o)
{
    if ((unsigned)o->metric > MCP_METRIC_SE)
        return mcp_error("sure: metric must be relse, relse-perceptual or se (got %d)",
                         (int)o->metric);
    if (o->n_probes < 1 || o->n_probes > 1024)
        return mcp_error("sure: n_probes must be in [1, 1024] (got %d)", o->n_probes);
    if (!(o->fd_delta > 0.0) || !isfinite(o->fd_delta))
        return mcp_error("sure: fd_delta must be > 0 (got %g)", o->fd_delta);
    if (!(o->ppd >= 0.0) || !isfinite(o->ppd))
        return mcp_error("sure: ppd must be >= 0 (got %g)", o->ppd);
    return 0;
}

/* ---- helpers shared inside estimate/ ---- */

double
mcp__now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

int
mcp__image_new(int width, int height, int n, const char *const *names, const char *source,
               mcp_image **out)
{
    static const char *const rgb[3] = {"R", "G", "B"};
    if (!names && n == 3) names = rgb;
    if (mcp_image_new(width, height, n, names, out)) return -1;
    if (source && mcp_image_set_source(*out, source)) {
        mcp_image_free(*out);
        *out = NULL;
        return -1;
    }
    return 0;
}

/* A new packed image a + delta t (a and t any strides, same shape). */
static int
axpy(const mcp_image *a, const mcp_image *t, double delta, mcp_image **out)
{
    if (mcp_image_copy(a, out)) return -1;
    if (!t) return 0;
    mcp_image *o = *out;
    int n = a->channels < t->channels ? a->channels : t->channels;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < a->height; y++)
        for (int x = 0; x < a->width; x++) {
            float *po = mcp_image_px(o, x, y);
            const float *pt = mcp_image_px(t, x, y);
            for (int c = 0; c < n; c++)
                po[c] = (float)(po[c] + delta * pt[c]);
        }
    return 0;
}

/* Puts "NAME: " before the current error unless it already starts so (the external
 * command's messages do). */
static int
name_denoiser(const mcp_denoiser *den)
{
    const char *msg = mcp_error_message();
    size_t n = strlen(den->name);
    if (strncmp(msg, den->name, n) == 0 && msg[n] == ':') return -1;
    return mcp_error_prefix("%s: ", den->name);
}

int
mcp_jvp_finite_difference(const mcp_denoiser *den, const mcp_denoise_input *at,
                          const mcp_denoise_tangent *t, int n, double delta,
                          mcp_image **primal, mcp_image **out)
{
    if (primal) *primal = NULL;
    for (int k = 0; k < n; k++)
        out[k] = NULL;
    if (!den || !den->apply) return mcp_error("jvp: missing denoiser");
    if (!(delta > 0.0) || !isfinite(delta))
        return mcp_error("jvp: delta must be > 0 (got %g)", delta);
    for (int k = 0; k < n; k++)
        if (!t[k].color || t[k].color->width != at->color->width ||
            t[k].color->height != at->color->height || t[k].color->channels != 3)
            return mcp_error(
                "jvp: tangent %d must be a 3-channel image of the input's size", k);
    mcp_image *f0 = NULL;
    if (den->apply(den, at, &f0)) return name_denoiser(den);
    for (int k = 0; k < n; k++) {
        mcp_denoise_input moved = *at;
        mcp_image *c = NULL, *a = NULL, *nn = NULL, *f1 = NULL;
        int rc = axpy(at->color, t[k].color, delta, &c);
        if (!rc && at->albedo && t[k].albedo)
            rc = axpy(at->albedo, t[k].albedo, delta, &a);
        if (!rc && at->normal && t[k].normal)
            rc = axpy(at->normal, t[k].normal, delta, &nn);
        moved.color = c;
        if (a) moved.albedo = a;
        if (nn) moved.normal = nn;
        if (!rc && den->apply(den, &moved, &f1)) rc = name_denoiser(den);
        mcp_image_free(c);
        mcp_image_free(a);
        mcp_image_free(nn);
        if (rc) {
            mcp_image_free(f0);
            for (int j = 0; j < k; j++) {
                mcp_image_free(out[j]);
                out[j] = NULL;
            }
            return -1;
        }
        /* f1 becomes (f1 - f0) / delta in place */
#pragma omp parallel for schedule(static)
        for (int y = 0; y < f1->height; y++)
            for (int x = 0; x < f1->width; x++) {
                float *p1 = mcp_image_px(f1, x, y);
                const float *p0 = mcp_image_px(f0, x, y);
                for (int c = 0; c < 3; c++)
                    p1[c] = (float)(((double)p1[c] - p0[c]) / delta);
            }
        out[k] = f1;
    }
    if (primal)
        *primal = f0;
    else
        mcp_image_free(f0);
    return 0;
}

int
mcp__jvp(const mcp_denoiser *den, const mcp_denoise_input *at,
         const mcp_denoise_tangent *t, int n, int fd, double delta, mcp_image **primal,
         mcp_image **out)
{
    if (fd || !den->jvp)
        return mcp_jvp_finite_difference(den, at, t, n, delta, primal, out);
    if (den->jvp(den, at, t, n, primal, out)) return mcp_error_prefix("%s: ", den->name);
    for (int k = 0; k < n; k++)
        if (!out[k] || out[k]->channels != 3 || out[k]->width != at->color->width ||
            out[k]->height != at->color->height) {
            for (int j = 0; j < n; j++) {
                mcp_image_free(out[j]);
                out[j] = NULL;
            }
            if (primal) {
                mcp_image_free(*primal);
                *primal = NULL;
            }
            return mcp_error("%s: jvp returned no 3-channel image of the input's size",
                             den->name);
        }
    return 0;
}

/* ---- the maps ---- */

void
mcp_error_maps_free(mcp_error_maps *m)
{
    if (!m) return;
    mcp_image *imgs[] = {m->denoised, m->sure,      m->sure_rel,   m->var,
                         m->var_rel,  m->sigma_rel, m->denominator};
    for (size_t i = 0; i < sizeof imgs / sizeof *imgs; i++)
        mcp_image_free(imgs[i]);
    memset(m, 0, sizeof *m);
}

/* 1 when img is a packed w x h image of channels R, G, B that owns its pixels: what
 * mcp__image_new makes for a map. */
static int
is_packed_rgb(const mcp_image *img, int w, int h)
{
    static const char *const rgb[3] = {"R", "G", "B"};
    if (!img || !img->owns_data || img->width != w || img->height != h ||
        img->channels != 3 || img->pixel_stride != 3 ||
        img->row_stride != (ptrdiff_t)3 * w)
        return 0;
    for (int c = 0; c < 3; c++)
        if (!img->names || !img->names[c] || strcmp(img->names[c], rgb[c]) != 0) return 0;
    return 1;
}

/* A map's image: one of spare[0..n) that is usable and is_packed_rgb (taken: its slot
 * is set to NULL, its attributes cleared, its source set), else a new one. plain_maps
 * writes every value of every map, so a reused image's old values never show. */
static int
map_image(mcp_image **spare, const unsigned char *usable, int n, int w, int h,
          const char *source, mcp_image **out)
{
    for (int i = 0; i < n; i++)
        if (usable[i] && is_packed_rgb(spare[i], w, h)) {
            mcp_image *img = spare[i];
            mcp_attrs_clear(&img->attrs);
            if (mcp_image_set_source(img, source)) return -1;
            spare[i] = NULL;
            *out = img;
            return 0;
        }
    return mcp__image_new(w, h, 3, NULL, source, out);
}

static int
maps_alloc(int w, int h, mcp_image **spare, const unsigned char *usable, int n,
           mcp_error_maps *m)
{
    static const char *const den_name[1] = {"denominator"};
    return map_image(spare, usable, n, w, h, "SURE", &m->sure) ||
           map_image(spare, usable, n, w, h, "relative SURE", &m->sure_rel) ||
           map_image(spare, usable, n, w, h, "variance of the denoised image", &m->var) ||
           map_image(spare, usable, n, w, h, "relative variance", &m->var_rel) ||
           map_image(spare, usable, n, w, h, "relative input variance", &m->sigma_rel) ||
           mcp__image_new(w, h, 1, den_name, "denominator", &m->denominator);
}

static double
maxc(const float *p)
{
    double m = p[0];
    if (p[1] > m) m = p[1];
    if (p[2] > m) m = p[2];
    return m;
}

/* Plain and relative SURE, all in one pass over the pixels. The maps may be the probes'
 * or the JVPs' own images (mcp__error_maps_from_own_probes): each value of a map is
 * written after every value of the same pixel and channel has been read. */
static void
plain_maps(const mcp_dump *d, const mcp_image *f, const mcp_image *const *eps,
           const mcp_image *const *jeps, int k, int relative, const mcp_image *probe_var,
           mcp_error_maps *m)
{
    int w = f->width, h = f->height;
    double inv_k = 1.0 / k;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++) {
        for (int x = 0; x < w; x++) {
            const float *pf = mcp_image_px(f, x, y), *px = mcp_image_px(d->color, x, y),
                        *pv = mcp_image_px(d->var_of_mean, x, y);
            double mc = maxc(pf), den = relative ? mc * mc + MCP_EPS_REL : 1.0;
            double inv = 1.0 / den;
            float *s = mcp_image_px(m->sure, x, y), *sr = mcp_image_px(m->sure_rel, x, y),
                  *v = mcp_image_px(m->var, x, y), *vr = mcp_image_px(m->var_rel, x, y),
                  *sg = mcp_image_px(m->sigma_rel, x, y);
            const float *pq = probe_var ? mcp_image_px(probe_var, x, y) : NULL;
            for (int c = 0; c < 3; c++) {
                double diff = (double)pf[c] - px[c], probe = 0.0, var = 0.0;
                for (int j = 0; j < k; j++) {
                    double e = mcp_image_px(eps[j], x, y)[c];
                    double je = mcp_image_px(jeps[j], x, y)[c];
                    probe += e * (2.0 * je - e);
                    var += je * je;
                }
                /* probes drawn from another variance q: E[e(2Je - e)] = q(2J - 1), so
                   pv / q of it is the dump's own pv(2J - 1) */
                if (pq && pq[c] > 0.0f) probe *= (double)pv[c] / pq[c];
                double sure = diff * diff + probe * inv_k;
                var *= inv_k;
                s[c] = (float)sure;
                sr[c] = (float)(sure * inv);
                v[c] = (float)var;
                vr[c] = (float)(var * inv);
                sg[c] = (float)(pv[c] * inv);
            }
            mcp_image_px(m->denominator, x, y)[0] = (float)den;
        }
    }
}

int
mcp__error_maps_begin(int w, int h, mcp_error_metric metric, mcp_error_maps *m)
{
    memset(m, 0, sizeof *m);
    m->metric = metric;
    if (maps_alloc(w, h, NULL, NULL, 0, m)) {
        mcp_error_maps_free(m);
        return -1;
    }
    return 0;
}

int
mcp__rows_view(const mcp_image *img, int y0, int y1, mcp_image **out)
{
    *out = NULL;
    return img ? mcp_image_crop_view(img, 0, y0, img->width, y1 - y0, out) : 0;
}

int
mcp__error_maps_rows(const mcp_dump *rows, const mcp_image *f,
                     const mcp_image *const *eps, const mcp_image *const *jeps, int k,
                     int y0, mcp_error_maps *m)
{
    const int y1 = y0 + rows->color->height;
    mcp_error_maps v = {.metric = m->metric};
    int rc = mcp__rows_view(m->sure, y0, y1, &v.sure) ||
             mcp__rows_view(m->sure_rel, y0, y1, &v.sure_rel) ||
             mcp__rows_view(m->var, y0, y1, &v.var) ||
             mcp__rows_view(m->var_rel, y0, y1, &v.var_rel) ||
             mcp__rows_view(m->sigma_rel, y0, y1, &v.sigma_rel) ||
             mcp__rows_view(m->denominator, y0, y1, &v.denominator);
    if (!rc) plain_maps(rows, f, eps, jeps, k, m->metric == MCP_METRIC_RELSE, NULL, &v);
    mcp_error_maps_free(&v);
    return rc ? -1 : 0;
}

/* a op b into a new packed image: out = sa * a + sb * b. */
static int
combine(const mcp_image *a, double sa, const mcp_image *b, double sb, mcp_image **out)
{
    if (mcp__image_new(a->width, a->height, 3, NULL, "combination", out)) return -1;
    mcp_image *o = *out;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < a->height; y++)
        for (int x = 0; x < a->width; x++) {
            const float *pa = mcp_image_px(a, x, y), *pb = mcp_image_px(b, x, y);
            float *po = mcp_image_px(o, x, y);
            for (int c = 0; c < 3; c++)
                po[c] = (float)(sa * pa[c] + sb * pb[c]);
        }
    return 0;
}

/* M applied to sa * a + sb * b. */
static int
csf_of(const mcp_image *a, double sa, const mcp_image *b, double sb, double ppd,
       mcp_image **out)
{
    mcp_image *t = NULL;
    int rc = combine(a, sa, b, sb, &t) || mcp_flip_csf_apply(t, ppd, out);
    mcp_image_free(t);
    return rc ? -1 : 0;
}

/* SURE_M (Firmino 2024 Eqs. 8, 10, 12): everything through M before squaring. */
static int
perceptual_maps(const mcp_dump *d, const mcp_image *f, const mcp_image *const *eps,
                const mcp_image *const *jeps, int k, double ppd, mcp_error_maps *m)
{
    int w = f->width, h = f->height, rc = -1;
    size_t plane = (size_t)w * h * 3;
    mcp_image *md = NULL, *mf = NULL;
    double *probe = NULL, *var = NULL, *sig = NULL;
    if (csf_of(f, 1.0, d->color, -1.0, ppd, &md) || mcp_flip_csf_apply(f, ppd, &mf))
        goto done;
    probe = mcp_calloc(plane, sizeof *probe);
    var = mcp_calloc(plane, sizeof *var);
    sig = mcp_calloc(plane, sizeof *sig);
    if (!probe || !var || !sig) goto done;
    for (int j = 0; j < k; j++) {
        mcp_image *me = NULL, *mt = NULL, *mje = NULL;
        if (mcp_flip_csf_apply(eps[j], ppd, &me) ||
            csf_of(jeps[j], 2.0, eps[j], -1.0, ppd, &mt) ||
            mcp_flip_csf_apply(jeps[j], ppd, &mje)) {
            mcp_image_free(me);
            mcp_image_free(mt);
            goto done;
        }
        /* CSF outputs are packed: index them directly */
#pragma omp parallel for schedule(static)
        for (size_t i = 0; i < plane; i++) {
            probe[i] += (double)me->data[i] * mt->data[i];
            var[i] += (double)mje->data[i] * mje->data[i];
            sig[i] += (double)me->data[i] * me->data[i];
        }
        mcp_image_free(me);
        mcp_image_free(mt);
        mcp_image_free(mje);
    }
    double inv_k = 1.0 / k;
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = ((size_t)y * w + x) * 3;
            double mc = maxc(mf->data + i), den = mc * mc + MCP_EPS_REL, inv = 1.0 / den;
            float *s = mcp_image_px(m->sure, x, y), *sr = mcp_image_px(m->sure_rel, x, y),
                  *v = mcp_image_px(m->var, x, y), *vr = mcp_image_px(m->var_rel, x, y),
                  *sg = mcp_image_px(m->sigma_rel, x, y);
            for (int c = 0; c < 3; c++) {
                double e = md->data[i + c];
                double sure = e * e + probe[i + c] * inv_k, vv = var[i + c] * inv_k;
                s[c] = (float)sure;
                sr[c] = (float)(sure * inv);
                v[c] = (float)vv;
                vr[c] = (float)(vv * inv);
                sg[c] = (float)(sig[i + c] * inv_k * inv);
            }
            mcp_image_px(m->denominator, x, y)[0] = (float)den;
        }
    rc = 0;
done:
    mcp_image_free(md);
    mcp_image_free(mf);
    free(probe);
    free(var);
    free(sig);
    return rc;
}

/* What the maps did not take goes back to the caller's slots (own_probes[j] and
 * own_jvps[j] were spare[2j + 1] and spare[2j]). */
static void
give_back(mcp_image **spare, int own, int k, mcp_image **own_probes, mcp_image **own_jvps)
{
    for (int j = 0; own && j < k && 2 * j + 1 < 2 * MCP_SURE_MAX_OWN; j++) {
        own_jvps[j] = spare[2 * j];
        own_probes[j] = spare[2 * j + 1];
    }
}

/* The maps from F(X), the probes and their JVPs. With `own` (and a metric other than
 * relse-perceptual, whose maps read the probes more than once), *own_denoised becomes
 * the maps' denoised image instead of a copy, and the probes' and JVPs' images in
 * own_probes and own_jvps hold five of the maps instead of new images (their slots
 * set to NULL): at 1080p with four probes the estimate's peak falls by 150 MB, and no
 * value changes. */
static int
maps_from_probes(const mcp_dump *dump, const mcp_image *denoised,
                 const mcp_image *const *probes, const mcp_image *const *jvps, int k,
                 const mcp_sure_options *opt, const mcp_image *probe_var, int own,
                 mcp_image **own_denoised, mcp_image **own_probes, mcp_image **own_jvps,
                 mcp_error_maps *out)
{
    memset(out, 0, sizeof *out);
    mcp_sure_options o = opt ? *opt : mcp_sure_defaults();
    if (check_options(&o) || mcp__check_dump("sure", dump)) return -1;
    if (k < 1) return mcp_error("sure: needs at least one probe (got %d)", k);
    const mcp_image *c = dump->color;
    if (!denoised || denoised->channels != 3 || denoised->width != c->width ||
        denoised->height != c->height)
        return mcp_error(
            "sure: the denoised image must have 3 channels and %s's size %dx%d",
            dump->source ? dump->source : "the dump", c->width, c->height);
    for (int j = 0; j < k; j++)
        for (int which = 0; which < 2; which++) {
            const mcp_image *p = which ? jvps[j] : probes[j];
            if (!p || p->channels != 3 || p->width != c->width || p->height != c->height)
                return mcp_error("sure: %s %d must have 3 channels and the dump's size",
                                 which ? "jvp" : "probe", j);
        }
    out->metric = o.metric;
    own = own && o.metric != MCP_METRIC_RELSE_PERCEPTUAL;
    mcp_image *spare[2 * MCP_SURE_MAX_OWN] = {0};
    unsigned char usable[2 * MCP_SURE_MAX_OWN];
    memset(usable, 1, sizeof usable);
    int n_spare = 0;
    for (int j = 0; own && j < k && n_spare + 2 <= 2 * MCP_SURE_MAX_OWN; j++) {
        spare[n_spare++] = own_jvps[j];
        spare[n_spare++] = own_probes[j];
    }
    for (int i = 0; i < n_spare; i++) /* an image offered twice is not spare */
        for (int j = 0; j < i; j++)
            if (spare[i] && spare[i] == spare[j]) usable[i] = usable[j] = 0;
    int copied = 0;
    if (own && denoised->pixel_stride == 3 &&
        denoised->row_stride == (ptrdiff_t)3 * c->width && denoised->owns_data) {
        out->denoised = *own_denoised;
        *own_denoised = NULL;
    } else {
        copied = 1;
    }
    if ((copied && mcp_image_copy(denoised, &out->denoised)) ||
        maps_alloc(c->width, c->height, spare, usable, n_spare, out) ||
        (o.metric == MCP_METRIC_RELSE_PERCEPTUAL
             ? perceptual_maps(dump, out->denoised, probes, jvps, k, o.ppd, out)
             : (plain_maps(dump, out->denoised, probes, jvps, k,
                           o.metric == MCP_METRIC_RELSE, probe_var, out),
                0))) {
        give_back(spare, own, k, own_probes, own_jvps);
        mcp_error_maps_free(out);
        return -1;
    }
    give_back(spare, own, k, own_probes, own_jvps);
    return 0;
}

int
mcp_error_maps_from_probes(const mcp_dump *dump, const mcp_image *denoised,
                           const mcp_image *const *probes, const mcp_image *const *jvps,
                           int k, const mcp_sure_options *opt, mcp_error_maps *out)
{
    return maps_from_probes(dump, denoised, probes, jvps, k, opt, NULL, 0, NULL, NULL,
                            NULL, out);
}

int
mcp__error_maps_from_own_probes(const mcp_dump *dump, mcp_image **denoised,
                                mcp_image **probes, mcp_image **jvps, int k,
                                const mcp_sure_options *opt, const mcp_image *probe_var,
                                mcp_error_maps *out)
{
    /* the images are read through copies of the pointers: the maps may take them */
    const mcp_image *eps[MCP_SURE_MAX_OWN], *jeps[MCP_SURE_MAX_OWN];
    if (k < 1 || k > MCP_SURE_MAX_OWN)
        return maps_from_probes(dump, *denoised, (const mcp_image *const *)probes,
                                (const mcp_image *const *)jvps, k, opt, probe_var, 0,
                                NULL, NULL, NULL, out);
    for (int j = 0; j < k; j++) {
        eps[j] = probes[j];
        jeps[j] = jvps[j];
    }
    return maps_from_probes(dump, *denoised, eps, jeps, k, opt, probe_var, 1, denoised,
                            probes, jvps, out);
}

int
mcp_error_maps_compute(const mcp_dump *dump, const mcp_denoiser *den,
                       const mcp_sure_options *opt, mcp_error_maps *out)
{
    memset(out, 0, sizeof *out);
    mcp_sure_options o = opt ? *opt : mcp_sure_defaults();
    if (check_options(&o) || mcp__check_dump("sure", dump)) return -1;
    if (!den) return mcp_error("sure: missing denoiser");
    int k = o.n_probes, rc = -1;
    mcp_probe *probes = mcp_calloc((size_t)k, sizeof *probes);
    mcp_denoise_tangent *t = mcp_calloc((size_t)k, sizeof *t);
    mcp_image **jv = mcp_calloc((size_t)k, sizeof *jv), *f = NULL;
    if (!probes || !t || !jv) goto done;
    for (int j = 0; j < k; j++) {
        if (mcp_probe_gaussian(dump, o.features, o.seed, j, &probes[j])) goto done;
        t[j].color = probes[j].color;
        t[j].albedo = probes[j].albedo;
        t[j].normal = probes[j].normal;
    }
    mcp_denoise_input in = mcp_denoise_input_of(dump);
    if (mcp__jvp(den, &in, t, k, o.mc_sure, o.fd_delta, &f, jv)) goto done;
    if (!f && den->apply(den, &in, &f)) { /* a jvp that gave no primal */
        mcp_error_prefix("%s: ", den->name);
        goto done;
    }
    {
        mcp_image **eps = mcp_calloc((size_t)k, sizeof *eps);
        if (!eps) goto done;
        for (int j = 0; j < k; j++)
            eps[j] = probes[j].color;
        rc = mcp__error_maps_from_own_probes(dump, &f, eps, jv, k, &o, NULL, out);
        for (int j = 0; j < k; j++) /* what the maps took is NULL now */
            probes[j].color = eps[j];
        free(eps);
    }
done:
    if (probes)
        for (int j = 0; j < k; j++)
            mcp_probe_clear(&probes[j]);
    if (jv)
        for (int j = 0; j < k; j++)
            mcp_image_free(jv[j]);
    free(probes);
    free(t);
    free(jv);
    mcp_image_free(f);
    return rc;
}

int
mcp_sure(const mcp_dump *dump, const mcp_denoiser *den, const mcp_sure_options *opt,
         mcp_image **out)
{
    *out = NULL;
    mcp_error_maps m;
    if (mcp_error_maps_compute(dump, den, opt, &m)) return -1;
    *out = m.metric == MCP_METRIC_SE ? m.sure : m.sure_rel;
    if (m.metric == MCP_METRIC_SE)
        m.sure = NULL;
    else
        m.sure_rel = NULL;
    mcp_error_maps_free(&m);
    return 0;
}
