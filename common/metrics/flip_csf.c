/* flip_csf.c: FLIP's contrast-sensitivity filter as a linear operator M on linear RGB,
 * and its exact adjoint (docs/mathematics.md §2.3; docs/flip.md §4).
 *
 *   M = T^-1 blkdiag(K_Y, K_Cx, K_Cz) T,   M^T = T^T blkdiag(K_Y^T, K_Cx^T, K_Cz^T) T^-T
 *
 * T = A diag(1/white) M_xyz maps linear RGB to YCxCz without FLIP's -16 offset (the
 * filters have unit DC gain, so the offset passes through and dropping it keeps M
 * exactly linear); T^-1 is its exact inverse (FLIP's rounded inverse matrix agrees to
 * ~1e-9). K_Y and K_Cx are separable Gaussians; K_Cz is g1 x g1 + g2 x g2 (FLIP's
 * GaussianSqrt split). Borders replicate (clamp to edge), as in FLIP, so K is not
 * symmetric near borders: its adjoint adds the taps that the clamp folds onto the edge
 * rows and columns (scatter-add, written here as a gather so rows can run in
 * parallel). Colour matrices are applied in double, filters in float. */
#include <mcpost/flip.h>

#include <stdlib.h>
#include <string.h>
#include "internal.h"

#define PARALLEL_MIN_FLOATS 65536

/* T in double from FLIP's constants (FLIP.h LinearRGBToXYZ, INV_DEFAULT_ILLUMINANT,
 * XYZToYCxCz without the offset). */
static void
matrix_t(double t[9])
{
    const double m[9] = {
        10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0,
        2613072.0 / 12288897.0,  8788810.0 / 12288897.0, 887015.0 / 12288897.0,
        1425312.0 / 73733382.0,  8788810.0 / 73733382.0, 70074185.0 / 73733382.0};
    const double inv_white[3] = {1.052156925, 1.0, 0.918357670};
    double s[9]; /* diag(inv_white) M_xyz */
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            s[3 * i + j] = inv_white[i] * m[3 * i + j];
    for (int j = 0; j < 3; j++) {
        t[0 + j] = 116.0 * s[3 + j];
        t[3 + j] = 500.0 * (s[0 + j] - s[3 + j]);
        t[6 + j] = 200.0 * (s[3 + j] - s[6 + j]);
    }
}

static void
invert3(const double a[9], double inv[9])
{
    double c00 = a[4] * a[8] - a[5] * a[7], c01 = a[5] * a[6] - a[3] * a[8],
           c02 = a[3] * a[7] - a[4] * a[6];
    double det = a[0] * c00 + a[1] * c01 + a[2] * c02;
    inv[0] = c00 / det;
    inv[1] = (a[2] * a[7] - a[1] * a[8]) / det;
    inv[2] = (a[1] * a[5] - a[2] * a[4]) / det;
    inv[3] = c01 / det;
    inv[4] = (a[0] * a[8] - a[2] * a[6]) / det;
    inv[5] = (a[2] * a[3] - a[0] * a[5]) / det;
    inv[6] = c02 / det;
    inv[7] = (a[1] * a[6] - a[0] * a[7]) / det;
    inv[8] = (a[0] * a[4] - a[1] * a[3]) / det;
}

static void
transpose3(const double a[9], double t[9])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            t[3 * j + i] = a[3 * i + j];
}

/* One pass along columns over an m-wide, n-high plane. Forward:
 *   dst[j] = sum_t w[t + r] src[clamp(j + t)]
 * Adjoint (the transpose of that n x n matrix): row j gathers every src row x with
 * clamp(x + t) == j, i.e. x = j - t inside the plane, plus, for the edge rows, the rows
 * whose taps fell off the edge and were folded onto it. */
static void
pass_rows(const float *src, float *dst, int m, int n, const float *w, int r, int adjoint)
{
#pragma omp parallel for if ((size_t)m * n >= PARALLEL_MIN_FLOATS)
    for (int j = 0; j < n; j++) {
        float *d = dst + (size_t)j * m;
        memset(d, 0, (size_t)m * sizeof *d);
        for (int t = -r; t <= r; t++) {
            int x = adjoint ? j - t : j + t;
            if (adjoint && (x < 0 || x >= n)) continue;
            x = x < 0 ? 0 : x > n - 1 ? n - 1 : x;
            const float wt = w[t + r], *s = src + (size_t)x * m;
            for (int i = 0; i < m; i++)
                d[i] += wt * s[i];
        }
        if (!adjoint || (j != 0 && j != n - 1)) continue;
        for (int x = 0; x < n; x++) {
            float fold = 0.0f; /* weight of the taps of row x clamped onto row j */
            for (int t = -r; t <= r; t++)
                if ((j == 0 && x + t < 0) || (j == n - 1 && x + t > n - 1))
                    fold += w[t + r];
            if (fold == 0.0f) continue;
            const float *s = src + (size_t)x * m;
            for (int i = 0; i < m; i++)
                d[i] += fold * s[i];
        }
    }
}

static void
transpose_plane(const float *src, float *dst, int w, int h)
{
#pragma omp parallel for if ((size_t)w * h >= PARALLEL_MIN_FLOATS)
    for (int x = 0; x < w; x++)
        for (int y = 0; y < h; y++)
            dst[(size_t)x * h + y] = src[(size_t)y * w + x];
}

/* dst = K src for one separable kernel (taps w along x, then along y), or K^T src.
 * a and b are w*h scratch planes. */
static void
separable(const float *src, float *dst, int w, int h, const float *taps, int r,
          int adjoint, float *a, float *b)
{
    transpose_plane(src, a, w, h);             /* h-wide, w-high: x runs down */
    pass_rows(a, b, h, w, taps, r, adjoint);   /* along x */
    transpose_plane(b, a, h, w);               /* back to w-wide */
    pass_rows(a, dst, w, h, taps, r, adjoint); /* along y */
}

static int
csf_run(const mcp_image *rgb, double ppd, int adjoint, mcp_image **out)
{
    *out = NULL;
    int idx[3], rc = -1;
    if (!rgb) return mcp_error("flip csf: missing image");
    if (mcp_rgb_channels(rgb, idx)) return -1;
    float ppd_f;
    if (ppd > 0.0) {
        mcp_flip_options o = mcp_flip_defaults();
        o.ppd = ppd;
        if (mcp_flip_ppd(&o, &ppd_f)) return -1;
    } else if (mcp_flip_ppd(NULL, &ppd_f)) {
        return -1;
    }
    int w = rgb->width, h = rgb->height;
    size_t n;
    if (w < 1 || h < 1 || mcp_size_mul3((size_t)w, (size_t)h, 7, &n))
        return mcp_error("flip csf: bad size %dx%d", w, h);
    mcp_flip_filters *f = NULL;
    float *block = NULL;
    mcp_image *o = NULL;
    if (mcp_flip_filters_new(ppd_f, &f) || !(block = mcp_malloc(n * sizeof(float))) ||
        mcp_image_new(w, h, 3, (const char *const[]){"R", "G", "B"}, &o))
        goto done;
    size_t np = (size_t)w * h;
    float *c[3] = {block, block + np, block + 2 * np};
    float *k[3] = {block + 3 * np, block + 4 * np, block + 5 * np};
    float *a = block + 6 * np, *b = NULL;

    double t[9], ti[9], into[9], back[9];
    matrix_t(t);
    invert3(t, ti);
    if (adjoint) {
        transpose3(ti, into); /* T^-T */
        transpose3(t, back);  /* T^T */
    } else {
        memcpy(into, t, sizeof t);
        memcpy(back, ti, sizeof ti);
    }
#pragma omp parallel for if (np * 3 >= PARALLEL_MIN_FLOATS)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *p = mcp_image_px(rgb, x, y);
            double v[3] = {p[idx[0]], p[idx[1]], p[idx[2]]};
            size_t i = (size_t)y * w + x;
            for (int q = 0; q < 3; q++)
                c[q][i] = (float)(into[3 * q] * v[0] + into[3 * q + 1] * v[1] +
                                  into[3 * q + 2] * v[2]);
        }
    /* Filter each opponent channel; Cz is the sum of its two separable halves. The
     * scratch for the second Cz half is the output image's pixels (3 planes). */
    b = o->data;
    separable(c[0], k[0], w, h, f->y, f->spatial_radius, adjoint, a, b);
    separable(c[1], k[1], w, h, f->cx, f->spatial_radius, adjoint, a, b);
    separable(c[2], k[2], w, h, f->cz1, f->spatial_radius, adjoint, a, b);
    separable(c[2], c[0], w, h, f->cz2, f->spatial_radius, adjoint, a, b);
    for (size_t i = 0; i < np; i++)
        k[2][i] += c[0][i];
#pragma omp parallel for if (np * 3 >= PARALLEL_MIN_FLOATS)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            double v[3] = {k[0][i], k[1][i], k[2][i]};
            for (int q = 0; q < 3; q++)
                o->data[3 * i + q] = (float)(back[3 * q] * v[0] + back[3 * q + 1] * v[1] +
                                             back[3 * q + 2] * v[2]);
        }
    if (rgb->source && mcp_image_set_source(o, rgb->source)) goto done;
    *out = o;
    o = NULL;
    rc = 0;
done:
    mcp_image_free(o);
    free(block);
    mcp_flip_filters_free(f);
    return rc;
}

int
mcp_flip_csf_apply(const mcp_image *rgb, double ppd, mcp_image **out)
{
    return csf_run(rgb, ppd, 0, out);
}

int
mcp_flip_csf_apply_transpose(const mcp_image *rgb, double ppd, mcp_image **out)
{
    return csf_run(rgb, ppd, 1, out);
}
