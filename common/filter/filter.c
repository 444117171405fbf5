/* filter.c: separable and 2D filters, Gaussian kernels and blur, and tile power spectra
 * (mathematics.md §4.1, §4.11: kernel g, blue-noise analysis; §3.2: Gaussian blur of v
 * and SURE; FLIP's filters). The arithmetic is OpenCV's, behind cv_shim.cpp.
 *
 * Borders are replicate (clamp to edge, BORDER_REPLICATE) everywhere, as
 * docs/mathematics.md asks.
 * Filters are correlations, sum_i k[i] * img[x + i - r] (filter.h), always computed
 * directly: cv_shim.cpp keeps OpenCV off its DFT method, so an Inf or NaN pixel (common
 * in renders) only reaches the outputs whose kernel footprint covers it.
 *
 * Images reach OpenCV as interleaved planes of at most MCP__CV_MAX_CHANNELS channels.
 * A view whose pixels are packed within rows is wrapped as it is (any row stride);
 * anything else (pixel_stride != channels, or more channels than a group) is copied
 * channel group by channel group into a packed scratch buffer first.
 *
 * Parallelism: OpenCV 4.6 runs these filters single-threaded for CV_32F
 * (docs/libraries.md §4), so rows are cut into fixed strips of STRIP_ROWS and the
 * strips run under OpenMP. Each strip is a row range of a Mat over the whole image, so
 * OpenCV reads the real neighbouring rows and the result equals the whole-image call
 * bit for bit. The split depends only on the image height, never on the thread count,
 * so results are reproducible for any thread count. */
#include <mcpost/filter.h>

#include "cv_shim.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* Measured with bench/bench_filter.c on 1024x1024x3 Gaussians (2 cores, quiet): strips
 * of 64-128 rows ran fastest, 5x5 in 1.0 ms and 11x11 in 2.1-2.3 ms on 2 threads
 * against 1.8 and 3.9 ms for one whole-image call; 16-32 rows recompute too many
 * overlapping rows, 256 leave threads idle. 64 keeps 16 strips for bigger teams. */
#define STRIP_ROWS 64

/* Images this small (in floats) are not worth an OpenMP team. */
#define PARALLEL_MIN_FLOATS (1 << 16)

/* Kernels longer than this cannot be meant (an image side is at most MCP_MAX_DIM, and
 * beyond 2 * MCP_MAX_DIM + 1 taps every pixel sees only replicated edges). */
#define KERNEL_MAX (2 * MCP_MAX_DIM + 1)

#define ERR_CAP 256

typedef struct {
    int is_2d;
    const float *kx, *ky; /* separable: row and column kernels */
    int kx_len, ky_len;
    const float *k2; /* 2D: row-major kx_len x ky_len */
} filter_spec;

static int
min_int(int a, int b)
{
    return a < b ? a : b;
}

/* Runs the filter over every strip of src -> dst; reports the first failure after
 * the parallel loop (workers must not set the error line). */
static int
run_strips(const mcp__cv_plane *src, const mcp__cv_plane *dst, const filter_spec *f,
           const char *source)
{
    int h = src->height, n_strips = (h + STRIP_ROWS - 1) / STRIP_ROWS, failed = 0;
    size_t floats = (size_t)src->width * (size_t)h * (size_t)src->channels;
    char first_err[ERR_CAP] = "";
#pragma omp parallel for schedule(dynamic) if (n_strips > 1 &&                           \
                                               floats >= PARALLEL_MIN_FLOATS)
    for (int s = 0; s < n_strips; s++) {
        char err[ERR_CAP];
        int y0 = s * STRIP_ROWS, y1 = min_int(h, y0 + STRIP_ROWS);
        int rc = f->is_2d ? mcp__cv_filter2d_rows(src, dst, y0, y1, f->k2, f->kx_len,
                                                  f->ky_len, err, sizeof err)
                          : mcp__cv_sep_filter_rows(src, dst, y0, y1, f->kx, f->kx_len,
                                                    f->ky, f->ky_len, err, sizeof err);
        if (rc) {
#pragma omp critical(mcp_filter_error)
            if (!failed++) memcpy(first_err, err, sizeof err);
        }
    }
    if (failed) return mcp_error("%s: %s", source, first_err);
    return 0;
}

/* Copies channels [c0, c0 + n) of img into the packed n-channel buffer buf. */
static void
gather(const mcp_image *img, int c0, int n, float *buf)
{
    int w = img->width, h = img->height;
#pragma omp parallel for if ((size_t)w * h * n >= PARALLEL_MIN_FLOATS)
    for (int y = 0; y < h; y++) {
        float *d = buf + (size_t)y * w * n;
        for (int x = 0; x < w; x++) {
            const float *s = mcp_image_px(img, x, y) + c0;
            for (int i = 0; i < n; i++)
                d[(size_t)x * n + i] = s[i];
        }
    }
}

/* Copies the packed n-channel buffer buf into channels [c0, c0 + n) of out. */
static void
scatter(const float *buf, int c0, int n, mcp_image *out)
{
    int w = out->width, h = out->height;
#pragma omp parallel for if ((size_t)w * h * n >= PARALLEL_MIN_FLOATS)
    for (int y = 0; y < h; y++) {
        const float *s = buf + (size_t)y * w * n;
        for (int x = 0; x < w; x++) {
            float *d = mcp_image_px(out, x, y) + c0;
            for (int i = 0; i < n; i++)
                d[i] = s[(size_t)x * n + i];
        }
    }
}

static mcp__cv_plane
packed_plane(float *data, int w, int h, int channels)
{
    return (mcp__cv_plane){data, w, h, channels, (size_t)w * channels};
}

/* A new packed image shaped like img, with its names and attributes, and the source
 * "<img source> (<what>)". */
static int
result_new(const mcp_image *img, const char *what, mcp_image **out)
{
    mcp_image *res = NULL;
    if (mcp_image_new(img->width, img->height, img->channels,
                      (const char *const *)img->names, &res))
        return mcp_error_prefix("%s: ", img->source);
    size_t n = strlen(img->source) + strlen(what) + 4;
    char *source = mcp_malloc(n);
    if (!source || mcp_attrs_copy(&img->attrs, &res->attrs)) {
        free(source);
        mcp_image_free(res);
        return -1;
    }
    snprintf(source, n, "%s (%s)", img->source, what);
    int rc = mcp_image_set_source(res, source);
    free(source);
    if (rc) {
        mcp_image_free(res);
        return -1;
    }
    *out = res;
    return 0;
}

/* Filters every channel of img with f into a new packed image. */
static int
filter_image(const mcp_image *img, const filter_spec *f, const char *what,
             mcp_image **out)
{
    int w = img->width, h = img->height, c = img->channels, rc = -1;
    mcp_image *res = NULL;
    float *in_buf = NULL, *out_buf = NULL;
    if (result_new(img, what, &res)) return -1;
    int group = min_int(c, MCP__CV_MAX_CHANNELS);
    /* A view with pixels packed within rows goes to OpenCV as it is. */
    int wrap_input = c <= MCP__CV_MAX_CHANNELS && img->pixel_stride == c &&
                     img->row_stride >= (ptrdiff_t)w * c;
    size_t n_scratch = (size_t)w * (size_t)h * (size_t)group;
    if (!wrap_input && !(in_buf = mcp_malloc(n_scratch * sizeof(float)))) goto done;
    if (c > MCP__CV_MAX_CHANNELS && !(out_buf = mcp_malloc(n_scratch * sizeof(float))))
        goto done;
    for (int c0 = 0; c0 < c; c0 += group) {
        int n = min_int(group, c - c0);
        mcp__cv_plane src, dst;
        if (wrap_input) {
            src = (mcp__cv_plane){img->data, w, h, c, (size_t)img->row_stride};
        } else {
            gather(img, c0, n, in_buf);
            src = packed_plane(in_buf, w, h, n);
        }
        dst = packed_plane(out_buf ? out_buf : res->data, w, h, n);
        if (run_strips(&src, &dst, f, img->source)) goto done;
        if (out_buf) scatter(out_buf, c0, n, res);
    }
    *out = res;
    res = NULL;
    rc = 0;
done:
    free(in_buf);
    free(out_buf);
    mcp_image_free(res);
    return rc;
}

/* Checks an odd kernel length; `what` names it in the message. */
static int
check_kernel_len(const mcp_image *img, const char *op, const char *what, int len)
{
    if (len < 1 || len % 2 == 0 || len > KERNEL_MAX)
        return mcp_error("%s: %s: %s must be odd and between 1 and %d (got %d)",
                         img->source, op, what, KERNEL_MAX, len);
    return 0;
}

/* The zero-frequency-centred position of DFT index k in an n-point transform: like
 * numpy's fftshift, DC lands at n / 2 (rounded down). */
static int
shifted(int k, int n)
{
    return (k + n / 2) % n;
}

int
mcp_filter_separable(const mcp_image *img, const float *kx, int kx_len, const float *ky,
                     int ky_len, mcp_image **out)
{
    const char *op = "separable filter";
    *out = NULL;
    if (!kx || !ky) return mcp_error("%s: %s: no kernel given", img->source, op);
    if (check_kernel_len(img, op, "kx length", kx_len) ||
        check_kernel_len(img, op, "ky length", ky_len))
        return -1;
    filter_spec f = {.kx = kx, .kx_len = kx_len, .ky = ky, .ky_len = ky_len};
    return filter_image(img, &f, "filtered", out);
}

int
mcp_filter_2d(const mcp_image *img, const float *kernel, int kw, int kh, mcp_image **out)
{
    const char *op = "2d filter";
    *out = NULL;
    if (!kernel) return mcp_error("%s: %s: no kernel given", img->source, op);
    if (check_kernel_len(img, op, "kernel width", kw) ||
        check_kernel_len(img, op, "kernel height", kh))
        return -1;
    filter_spec f = {.is_2d = 1, .k2 = kernel, .kx_len = kw, .ky_len = kh};
    return filter_image(img, &f, "filtered", out);
}

int
mcp_gaussian_kernel(double sigma_px, int radius, float *k)
{
    if (!isfinite(sigma_px) || sigma_px < 0)
        return mcp_error("gaussian kernel: sigma must be finite and >= 0 (got %g)",
                         sigma_px);
    if (radius < 0 || radius > MCP_MAX_DIM)
        return mcp_error("gaussian kernel: radius must be between 0 and %d (got %d)",
                         MCP_MAX_DIM, radius);
    /* sigma 0 is the limit of ever narrower Gaussians: the identity. */
    if (sigma_px == 0) {
        for (int i = -radius; i <= radius; i++)
            k[i + radius] = i == 0 ? 1.0f : 0.0f;
        return 0;
    }
    double sum = 0, inv_2var = 1.0 / (2.0 * sigma_px * sigma_px);
    for (int i = -radius; i <= radius; i++)
        sum += exp(-(double)i * i * inv_2var);
    for (int i = -radius; i <= radius; i++)
        k[i + radius] = (float)(exp(-(double)i * i * inv_2var) / sum);
    return 0;
}

int
mcp_gaussian_blur(const mcp_image *img, int window, double sigma_px, mcp_image **out)
{
    *out = NULL;
    if (window < 1 || window % 2 == 0)
        return mcp_error("%s: gaussian blur: window must be odd and >= 1 (got %d)",
                         img->source, window);
    if (window > KERNEL_MAX)
        return mcp_error("%s: gaussian blur: window must be at most %d (got %d)",
                         img->source, KERNEL_MAX, window);
    if (!isfinite(sigma_px) || sigma_px < 0)
        return mcp_error("%s: gaussian blur: sigma must be finite and >= 0 (got %g)",
                         img->source, sigma_px);
    float *k = mcp_malloc((size_t)window * sizeof *k);
    if (!k) return -1;
    int rc = mcp_gaussian_kernel(sigma_px, window / 2, k);
    if (rc == 0) {
        filter_spec f = {.kx = k, .kx_len = window, .ky = k, .ky_len = window};
        rc = filter_image(img, &f, "blurred", out);
    }
    free(k);
    return rc;
}

int
mcp_tile_power_spectra(const mcp_image *img, int channel, int tile_size, mcp_image **out)
{
    const char *op = "tile power spectra";
    int t = tile_size, failed = 0, rc = -1;
    char first_err[ERR_CAP] = "";
    *out = NULL;
    if (channel < 0 || channel >= img->channels)
        return mcp_error("%s: %s: channel %d outside its %d channels", img->source, op,
                         channel, img->channels);
    if (t < 1)
        return mcp_error("%s: %s: tile size must be >= 1 (got %d)", img->source, op, t);
    if (t > img->width || t > img->height)
        return mcp_error("%s: %s: tile size %d larger than the %dx%d image", img->source,
                         op, t, img->width, img->height);
    int tiles_x = img->width / t, tiles_y = img->height / t;
    long long n_tiles = (long long)tiles_x * tiles_y; /* 65536^2 one-pixel tiles fit */
    int n_threads = 1;
#ifdef _OPENMP
    n_threads = omp_get_max_threads();
#endif
    mcp_image *res = NULL;
    double *scratch = NULL;
    size_t tile_floats = (size_t)t * t;
    if (mcp_image_new(tiles_x * t, tiles_y * t, 1, (const char *[]){"power"}, &res))
        goto done;
    if (!(scratch = mcp_malloc((size_t)n_threads * 2 * tile_floats * sizeof *scratch)))
        goto done;
    size_t out_w = (size_t)res->width;
#pragma omp parallel for schedule(static)                                                \
    num_threads(n_threads) if ((size_t)n_tiles * tile_floats >= PARALLEL_MIN_FLOATS)
    for (long long i = 0; i < n_tiles; i++) {
        int thread = 0;
#ifdef _OPENMP
        thread = omp_get_thread_num();
#endif
        double *tile = scratch + (size_t)thread * 2 * tile_floats;
        double *power = tile + tile_floats;
        int x0 = (int)(i % tiles_x) * t, y0 = (int)(i / tiles_x) * t;
        for (int y = 0; y < t; y++)
            for (int x = 0; x < t; x++)
                tile[(size_t)y * t + x] = mcp_image_px(img, x0 + x, y0 + y)[channel];
        char err[ERR_CAP];
        if (mcp__cv_dft_power(tile, t, power, err, sizeof err)) {
#pragma omp critical(mcp_filter_error)
            if (!failed++) memcpy(first_err, err, sizeof err);
            continue;
        }
        for (int v = 0; v < t; v++) {
            float *row = res->data + (size_t)(y0 + shifted(v, t)) * out_w + x0;
            for (int u = 0; u < t; u++)
                row[shifted(u, t)] = (float)power[(size_t)v * t + u];
        }
    }
    if (failed) {
        mcp_error("%s: %s", img->source, first_err);
        goto done;
    }
    size_t n = strlen(img->source) + 32;
    char *source = mcp_malloc(n);
    if (!source) goto done;
    snprintf(source, n, "%s (power spectra)", img->source);
    rc = mcp_image_set_source(res, source);
    free(source);
    if (rc) goto done;
    *out = res;
    res = NULL;
done:
    free(scratch);
    mcp_image_free(res);
    return rc;
}
