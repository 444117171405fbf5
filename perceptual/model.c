/* model.c: the perceptual error model and its incremental form (docs/mathematics.md
 * §4.3-§4.4, Chizhov et al. 2022 Eqs. 15, 16, 21).
 *
 *   E_C(O) = sum_p (1 - C_p) |g|_1^2 |T(O_p) - T(Q_init,p)|^2
 *          + sum_q C_q |(g * T(O))_q - (h * T(I'))_q|^2
 *
 * Borders replicate (clamp to edge), as §4.3 asks. §4.4 writes the confidence term as
 * |O - Q_init|^2; we take it in display space, T(O) - T(Q_init), like the rest of the
 * energy (with T = none the two agree), so that one firefly cannot outweigh the whole
 * perceptual term.
 *
 * The residual r = g * T(O) - h * T(I') is kept in double and updated per change
 * (direct binary search). It is computed here by direct convolution in double rather
 * than through filter.h: the OpenCV filters work in float, and the incremental energy
 * must agree with a recomputation to ~1e-12, not 1e-7. */
#include "internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Footprint tables grow as side^4; 33x33 kernels (sigma up to ~5 px) are plenty for a
 * viewing-distance model. */
#define MAX_KERNEL_RADIUS 16

mcp_perc_model
mcp_perc_model_defaults(void)
{
    mcp_perc_model m;
    memset(&m, 0, sizeof m);
    m.kernel = mcp_pkernel_defaults();
    m.tone_map = MCP_TONEMAP_CLAMP;
    m.confidence = 1.0;
    return m;
}

/* ---- the kernel ---- */

int
mcp__pkern_build(const mcp_perc_model *model, mcp__pkern *out)
{
    memset(out, 0, sizeof *out);
    if (model->user_kernel) {
        int kw = model->user_kernel_width, kh = model->user_kernel_height;
        if (kw < 1 || kh < 1 || kw % 2 == 0 || kh % 2 == 0)
            return mcp_error("perceptual: kernel must be odd-sized (got %dx%d)", kw, kh);
        int r = (kw > kh ? kw : kh) / 2;
        if (r > MAX_KERNEL_RADIUS)
            return mcp_error(
                "perceptual: kernel %dx%d is too wide (at most %d taps a side)", kw, kh,
                2 * MAX_KERNEL_RADIUS + 1);
        int side = 2 * r + 1;
        double *t = mcp_calloc((size_t)side * side, sizeof *t);
        if (!t) return -1;
        /* centre a narrower side in the square array */
        int ox = r - kw / 2, oy = r - kh / 2;
        for (int y = 0; y < kh; y++)
            for (int x = 0; x < kw; x++) {
                double v = model->user_kernel[y * kw + x];
                if (!isfinite(v)) {
                    free(t);
                    return mcp_error("perceptual: kernel tap (%d, %d) is not finite", x,
                                     y);
                }
                t[(y + oy) * side + x + ox] = v;
            }
        out->r = r, out->side = side, out->taps = t;
    } else {
        double *t1 = NULL;
        int r;
        if (mcp_pkernel_taps(&model->kernel, &t1, &r))
            return mcp_error_prefix("perceptual: ");
        if (r > MAX_KERNEL_RADIUS) {
            free(t1);
            return mcp_error("perceptual: kernel radius %d is too wide (at most %d; "
                             "check dpi and distance_in)",
                             r, MAX_KERNEL_RADIUS);
        }
        int side = 2 * r + 1;
        double *t = mcp_malloc((size_t)side * side * sizeof *t);
        if (!t) {
            free(t1);
            return -1;
        }
        for (int y = 0; y < side; y++) /* separable: the outer product */
            for (int x = 0; x < side; x++)
                t[y * side + x] = t1[y] * t1[x];
        free(t1);
        out->r = r, out->side = side, out->taps = t;
    }
    for (int i = 0; i < out->side * out->side; i++)
        out->l1 += fabs(out->taps[i]);
    return 0;
}

void
mcp__pkern_free(mcp__pkern *k)
{
    free(k->taps);
    k->taps = NULL;
}

/* ---- footprints ---- */

/* Classes along one axis of length n: the class of coordinate p is given by its
 * distances to both ends capped at r. Fills cls[n], rep[] (a coordinate of each class)
 * and the interior class (-1 when none). */
static int
axis_classes(int n, int r, int *cls, int *rep, int *count, int *interior)
{
    int codes = (r + 1) * (r + 1);
    int *index = mcp_malloc((size_t)codes * sizeof *index);
    if (!index) return -1;
    for (int i = 0; i < codes; i++)
        index[i] = -1;
    *count = 0;
    *interior = -1;
    for (int p = 0; p < n; p++) {
        int lo = p < r ? p : r, hi = n - 1 - p < r ? n - 1 - p : r;
        int code = lo * (r + 1) + hi;
        if (index[code] < 0) {
            index[code] = (*count)++;
            rep[index[code]] = p;
            if (lo == r && hi == r) *interior = index[code];
        }
        cls[p] = index[code];
    }
    free(index);
    return 0;
}

static int
clampi(int v, int lo, int hi)
{
    return v < lo ? lo : v > hi ? hi : v;
}

/* hit[(d + r) * side + k + r] = 1 when clamp(p + d - k) == p with p + d inside. */
static void
axis_hits(int p, int n, int r, unsigned char *hit)
{
    int side = 2 * r + 1;
    for (int d = -r; d <= r; d++)
        for (int k = -r; k <= r; k++) {
            int q = p + d;
            hit[(d + r) * side + k + r] = q >= 0 && q < n && clampi(q - k, 0, n - 1) == p;
        }
}

int
mcp__footprints_build(const mcp__pkern *g, int w, int h, mcp__footprints *f)
{
    memset(f, 0, sizeof *f);
    int r = g->r, side = g->side, n_cls = side; /* at most 2r+1 classes per axis */
    int *repx = NULL, *repy = NULL;
    unsigned char *hx = NULL, *hy = NULL;
    f->w = w, f->h = h, f->r = r, f->side = side;
    if (!(f->cx = mcp_malloc((size_t)w * sizeof *f->cx)) ||
        !(f->cy = mcp_malloc((size_t)h * sizeof *f->cy)) ||
        !(repx = mcp_malloc((size_t)n_cls * sizeof *repx)) ||
        !(repy = mcp_malloc((size_t)n_cls * sizeof *repy)) ||
        !(hx = mcp_malloc((size_t)side * side)) ||
        !(hy = mcp_malloc((size_t)side * side)) ||
        axis_classes(w, r, f->cx, repx, &f->nx, &f->ix) ||
        axis_classes(h, r, f->cy, repy, &f->ny, &f->iy) ||
        !(f->fp = mcp_calloc((size_t)f->nx * f->ny * side * side, sizeof *f->fp)) ||
        !(f->norm2 = mcp_calloc((size_t)f->nx * f->ny, sizeof *f->norm2))) {
        free(repx), free(repy), free(hx), free(hy);
        mcp__footprints_free(f);
        return -1;
    }
    /* a_p(p + d) = sum_{ky, kx} g(kx, ky) [hit_y(dy, ky)] [hit_x(dx, kx)] */
    for (int cy = 0; cy < f->ny; cy++) {
        axis_hits(repy[cy], h, r, hy);
        for (int cx = 0; cx < f->nx; cx++) {
            axis_hits(repx[cx], w, r, hx);
            double *a = f->fp + ((size_t)cy * f->nx + cx) * side * side, n2 = 0.0;
            for (int dy = 0; dy < side; dy++)
                for (int dx = 0; dx < side; dx++) {
                    double s = 0.0;
                    for (int ky = 0; ky < side; ky++) {
                        if (!hy[dy * side + ky]) continue;
                        for (int kx = 0; kx < side; kx++)
                            if (hx[dx * side + kx]) s += g->taps[ky * side + kx];
                    }
                    a[dy * side + dx] = s;
                    n2 += s * s;
                }
            f->norm2[(size_t)cy * f->nx + cx] = n2;
        }
    }
    free(repx), free(repy), free(hx), free(hy);
    return 0;
}

void
mcp__footprints_free(mcp__footprints *f)
{
    free(f->cx), free(f->cy), free(f->fp), free(f->norm2);
    memset(f, 0, sizeof *f);
}

/* ---- direct convolution and the full energy ---- */

/* dst[q] = (g * src)(q) = sum_k g(k) src(clamp(q - k)), [n][3], in double. */
static void
convolve(const mcp__pkern *g, int w, int h, const double *src, double *dst)
{
    int r = g->r, side = g->side;
#pragma omp parallel for if ((size_t)w * h >= 16384)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double s[3] = {0.0, 0.0, 0.0};
            for (int ky = -r; ky <= r; ky++) {
                int sy = clampi(y - ky, 0, h - 1);
                for (int kx = -r; kx <= r; kx++) {
                    double k = g->taps[(ky + r) * side + kx + r];
                    const double *p =
                        src + ((size_t)sy * w + clampi(x - kx, 0, w - 1)) * 3;
                    s[0] += k * p[0], s[1] += k * p[1], s[2] += k * p[2];
                }
            }
            double *d = dst + ((size_t)y * w + x) * 3;
            d[0] = s[0], d[1] = s[1], d[2] = s[2];
        }
}

double
mcp__state_energy_full(const mcp__perc_state *s)
{
    int w = s->w, h = s->h, r = s->g.r, side = s->g.side;
    double *rows = mcp_malloc((size_t)h * sizeof *rows), e = 0.0;
    if (!rows) return NAN;
#pragma omp parallel for if ((size_t)w * h >= 16384)
    for (int y = 0; y < h; y++) {
        double row = 0.0;
        for (int x = 0; x < w; x++) {
            size_t q = (size_t)y * w + x;
            double c = s->cmap ? s->cmap[q] : s->c, conv[3] = {0.0, 0.0, 0.0};
            for (int ky = -r; ky <= r; ky++) {
                int sy = clampi(y - ky, 0, h - 1);
                for (int kx = -r; kx <= r; kx++) {
                    double k = s->g.taps[(ky + r) * side + kx + r];
                    const double *p =
                        s->o + ((size_t)sy * w + clampi(x - kx, 0, w - 1)) * 3;
                    conv[0] += k * p[0], conv[1] += k * p[1], conv[2] += k * p[2];
                }
            }
            for (int ch = 0; ch < 3; ch++) {
                double d = conv[ch] - s->target[q * 3 + ch];
                row += c * d * d;
            }
            double u = mcp__state_unary(s, q);
            if (u != 0.0)
                for (int ch = 0; ch < 3; ch++) {
                    double d = s->o[q * 3 + ch] - s->qinit[q * 3 + ch];
                    row += u * d * d;
                }
        }
        rows[y] = row;
    }
    for (int y = 0; y < h; y++)
        e += rows[y];
    free(rows);
    return e;
}

/* ---- the incremental state ---- */

int
mcp__state_init(mcp__perc_state *s, const mcp_perc_model *model, int w, int h,
                const float *t_surr, const float *t_qinit, const double *o_init)
{
    memset(s, 0, sizeof *s);
    size_t n = (size_t)w * h, n3 = n * 3;
    s->w = w, s->h = h, s->c = model->confidence;
    if (mcp__pkern_build(model, &s->g)) return -1;
    s->unary = s->g.l1 * s->g.l1;
    if (mcp__footprints_build(&s->g, w, h, &s->fp) ||
        mcp__confidence_map(model, w, h, &s->cmap) ||
        !(s->target = mcp_malloc(n3 * sizeof *s->target)) ||
        !(s->resid = mcp_malloc(n3 * sizeof *s->resid)) ||
        !(s->o = mcp_malloc(n3 * sizeof *s->o)))
        goto fail;
    int need_qinit = !s->cmap ? s->c < 1.0 : 0;
    for (size_t p = 0; s->cmap && p < n && !need_qinit; p++)
        need_qinit = s->cmap[p] < 1.0f;
    if (need_qinit) {
        if (!t_qinit) {
            mcp_error("perceptual: confidence below 1 needs the initial estimate");
            goto fail;
        }
        if (!(s->qinit = mcp_malloc(n3 * sizeof *s->qinit))) goto fail;
        memcpy(s->qinit, t_qinit, n3 * sizeof *s->qinit);
    }
    memcpy(s->o, o_init, n3 * sizeof *s->o);
    for (size_t i = 0; i < n3; i++) /* the surrogate in double, staged in resid */
        s->resid[i] = t_surr[i];
    if (model->filter_surrogate)
        convolve(&s->g, w, h, s->resid, s->target); /* h = g */
    else
        memcpy(s->target, s->resid, n3 * sizeof *s->target); /* h = delta */
    convolve(&s->g, w, h, s->o, s->resid);
    for (size_t i = 0; i < n3; i++)
        s->resid[i] -= s->target[i];
    s->energy = mcp__state_energy_full(s);
    if (isnan(s->energy)) {
        mcp_error("out of memory");
        goto fail;
    }
    return 0;
fail:
    mcp__state_free(s);
    return -1;
}

void
mcp__state_free(mcp__perc_state *s)
{
    mcp__pkern_free(&s->g);
    mcp__footprints_free(&s->fp);
    free(s->target), free(s->resid), free(s->o), free(s->qinit), free(s->cmap);
    memset(s, 0, sizeof *s);
}

void
mcp__state_corr(const mcp__perc_state *s, int x, int y, double corr[3], double *n2)
{
    int r = s->g.r, side = s->g.side, w = s->w, h = s->h;
    const double *a = mcp__footprint(&s->fp, x, y);
    double c0 = 0.0, c1 = 0.0, c2 = 0.0, nn = 0.0;
    int inside = mcp__footprint_interior(&s->fp, x, y);
    for (int dy = -r; dy <= r; dy++) {
        int qy = y + dy;
        if (!inside && (qy < 0 || qy >= h)) continue;
        for (int dx = -r; dx <= r; dx++) {
            int qx = x + dx;
            if (!inside && (qx < 0 || qx >= w)) continue;
            size_t q = (size_t)qy * w + qx;
            double k = a[(dy + r) * side + dx + r];
            if (s->cmap) {
                nn += k * k * s->cmap[q];
                k *= s->cmap[q];
            }
            const double *rq = s->resid + q * 3;
            c0 += k * rq[0], c1 += k * rq[1], c2 += k * rq[2];
        }
    }
    if (s->cmap) {
        corr[0] = c0, corr[1] = c1, corr[2] = c2;
        *n2 = nn;
    } else {
        corr[0] = s->c * c0, corr[1] = s->c * c1, corr[2] = s->c * c2;
        *n2 = s->c * s->fp.norm2[(size_t)s->fp.cy[y] * s->fp.nx + s->fp.cx[x]];
    }
}

double
mcp__state_delta(const mcp__perc_state *s, int x, int y, const double o_new[3])
{
    size_t p = (size_t)y * s->w + x;
    double corr[3], n2, de = 0.0;
    mcp__state_corr(s, x, y, corr, &n2);
    const double *o = s->o + p * 3;
    for (int c = 0; c < 3; c++) {
        double d = o_new[c] - o[c];
        de += d * (2.0 * corr[c] + d * n2);
    }
    double u = mcp__state_unary(s, p);
    if (u != 0.0)
        for (int c = 0; c < 3; c++) {
            double a = o_new[c] - s->qinit[p * 3 + c], b = o[c] - s->qinit[p * 3 + c];
            de += u * (a * a - b * b);
        }
    return de;
}

void
mcp__state_set(mcp__perc_state *s, int x, int y, const double o_new[3], double de)
{
    int r = s->g.r, side = s->g.side, w = s->w, h = s->h;
    size_t p = (size_t)y * w + x;
    double *o = s->o + p * 3, d[3] = {o_new[0] - o[0], o_new[1] - o[1], o_new[2] - o[2]};
    const double *a = mcp__footprint(&s->fp, x, y);
    int inside = mcp__footprint_interior(&s->fp, x, y);
    for (int dy = -r; dy <= r; dy++) {
        int qy = y + dy;
        if (!inside && (qy < 0 || qy >= h)) continue;
        for (int dx = -r; dx <= r; dx++) {
            int qx = x + dx;
            if (!inside && (qx < 0 || qx >= w)) continue;
            double k = a[(dy + r) * side + dx + r];
            double *rq = s->resid + ((size_t)qy * w + qx) * 3;
            rq[0] += k * d[0], rq[1] += k * d[1], rq[2] += k * d[2];
        }
    }
    o[0] = o_new[0], o[1] = o_new[1], o[2] = o_new[2];
    s->energy += de;
}

double
mcp__state_cross(const mcp__perc_state *s, int xi, int yi, int xj, int yj)
{
    int r = s->g.r, side = s->g.side, w = s->w, h = s->h;
    const double *ai = mcp__footprint(&s->fp, xi, yi),
                 *aj = mcp__footprint(&s->fp, xj, yj);
    /* the overlap of the two (2r+1)^2 windows, inside the image */
    int x0 = (xi > xj ? xi : xj) - r, x1 = (xi < xj ? xi : xj) + r;
    int y0 = (yi > yj ? yi : yj) - r, y1 = (yi < yj ? yi : yj) + r;
    x0 = x0 < 0 ? 0 : x0, y0 = y0 < 0 ? 0 : y0;
    x1 = x1 >= w ? w - 1 : x1, y1 = y1 >= h ? h - 1 : y1;
    double sum = 0.0;
    for (int qy = y0; qy <= y1; qy++)
        for (int qx = x0; qx <= x1; qx++) {
            double k = ai[(qy - yi + r) * side + qx - xi + r] *
                       aj[(qy - yj + r) * side + qx - xj + r];
            sum += k * (s->cmap ? s->cmap[(size_t)qy * w + qx] : 1.0);
        }
    return s->cmap ? sum : s->c * sum;
}

double
mcp__state_swap_delta(const mcp__perc_state *s, int xi, int yi, int xj, int yj)
{
    size_t i = (size_t)yi * s->w + xi, j = (size_t)yj * s->w + xj;
    double ci[3], cj[3], ni, nj;
    mcp__state_corr(s, xi, yi, ci, &ni);
    mcp__state_corr(s, xj, yj, cj, &nj);
    double curv = ni + nj - 2.0 * mcp__state_cross(s, xi, yi, xj, yj), de = 0.0;
    const double *oi = s->o + i * 3, *oj = s->o + j * 3;
    for (int c = 0; c < 3; c++) {
        double d = oj[c] - oi[c]; /* pixel i takes j's value, j takes i's */
        de += d * (2.0 * (ci[c] - cj[c]) + d * curv);
    }
    double ui = mcp__state_unary(s, i), uj = mcp__state_unary(s, j);
    if (ui != 0.0 || uj != 0.0)
        for (int c = 0; c < 3; c++) {
            double qi = s->qinit[i * 3 + c], qj = s->qinit[j * 3 + c];
            de += ui * ((oj[c] - qi) * (oj[c] - qi) - (oi[c] - qi) * (oi[c] - qi));
            de += uj * ((oi[c] - qj) * (oi[c] - qj) - (oj[c] - qj) * (oj[c] - qj));
        }
    return de;
}

/* ---- public ---- */

int
mcp_perc_energy(const mcp_image *img, const mcp_image *surrogate, const mcp_image *qinit,
                const mcp_perc_model *model, double *energy)
{
    mcp_perc_model d = mcp_perc_model_defaults();
    if (!model) model = &d;
    const mcp_image *imgs[1] = {img};
    if (!img || !surrogate)
        return mcp_error("perceptual: energy needs an image and a surrogate");
    if (mcp__check_candidates(imgs, 1, surrogate, NULL) ||
        (qinit && mcp__check_candidates(imgs, 1, qinit, NULL)))
        return -1;
    int w = img->width, h = img->height, rc = -1;
    size_t n3 = (size_t)w * h * 3;
    float *t_img = NULL, *t_surr = NULL, *t_qinit = NULL;
    double *o = NULL;
    mcp__perc_state s;
    if (mcp__rgb_tone(img, model->tone_map, &t_img) ||
        mcp__rgb_tone(surrogate, model->tone_map, &t_surr) ||
        (qinit && mcp__rgb_tone(qinit, model->tone_map, &t_qinit)) ||
        !(o = mcp_malloc(n3 * sizeof *o)))
        goto done;
    for (size_t i = 0; i < n3; i++)
        o[i] = t_img[i];
    if (mcp__state_init(&s, model, w, h, t_surr, t_qinit, o)) goto done;
    *energy = s.energy;
    mcp__state_free(&s);
    rc = 0;
done:
    free(t_img), free(t_surr), free(t_qinit), free(o);
    return rc;
}
