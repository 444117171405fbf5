/* renderer_rule.c: the adaptive stopping rule that renderers ship (Cycles' noise
 * threshold, Mitsuba 3's adaptive_sampling integrator), as a baseline for mcpost's
 * sampling maps (docs/adaptive.md, "The renderers' own rule").
 *
 * The rule keeps, beside the mean I of all of a pixel's samples, the mean A of half
 * of them (class A). I - A = (B - A) / 2 is a noise sample of size sigma / sqrt(n)
 * that costs nothing to keep; the rule stops a pixel when it is small against the
 * pixel's brightness, and keeps the pixels around an unstopped one sampling, so that
 * a noisy area's edge is not left behind. The renderer samples in lockstep: every
 * unstopped pixel gets `step` more samples between two checks. */
#include "estimate.h"
#include "internal.h"

#include <mcpost/metrics.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Cycles compares the error with 5x the threshold its UI shows ("an arbitrary factor
 * that makes the threshold more similar to what it was before"). */
#define CYCLES_THRESHOLD_SCALE 5.0
/* Cycles' guard against a black pixel's zero divisor. */
#define CYCLES_ERROR_EPS 1e-4

mcp_renderer_rule_options
mcp_renderer_rule_defaults(void)
{
    mcp_renderer_rule_options o;
    memset(&o, 0, sizeof o);
    o.threshold = 0.01; /* Blender's default noise threshold */
    o.min_samples = 0;
    o.step = 16;
    o.max_spp = 1024;
    o.dilate = 1;
    o.record_every = 0; /* = step */
    return o;
}

int
mcp_renderer_rule_check(const mcp_renderer_rule_options *o)
{
    if (!(o->threshold > 0.0) || !isfinite(o->threshold))
        return mcp_error("renderer rule: threshold must be > 0 (got %g)", o->threshold);
    if (o->min_samples < 0)
        return mcp_error("renderer rule: min_samples must be >= 0 (got %d)",
                         o->min_samples);
    if (o->step < 1 || o->step > 1 << 20)
        return mcp_error("renderer rule: step must be in [1, 2^20] (got %d)", o->step);
    if (o->max_spp < 1 || o->max_spp > 1 << 24)
        return mcp_error("renderer rule: max_spp must be in [1, 2^24] (got %d)",
                         o->max_spp);
    if (o->dilate < 0 || o->dilate > 64)
        return mcp_error("renderer rule: dilate must be in [0, 64] (got %d)", o->dilate);
    if (o->record_every < 0)
        return mcp_error("renderer rule: record_every must be >= 0 (got %d)",
                         o->record_every);
    return 0;
}

int
mcp_renderer_rule_min_samples(const mcp_renderer_rule_options *o)
{
    if (o->min_samples > 0) return o->min_samples < 4 ? 4 : o->min_samples;
    /* Cycles' guess: threshold 0.1 -> 32, 0.01 -> 64, 0.001 -> 128, at least 4 */
    int m = (int)ceil(16.0 / pow(o->threshold, 0.3));
    return m < 4 ? 4 : m;
}

double
mcp_renderer_rule_pixel_error(const float mean[3], const float half[3])
{
    double diff = 0.0, intensity = 0.0;
    for (int c = 0; c < 3; c++) {
        diff += fabs((double)mean[c] - (double)half[c]);
        intensity += mean[c];
    }
    /* below 1 the error is relative to sqrt(I), above to I: an overexposed pixel
       needs fewer samples, a dark one is not driven to zero noise */
    double norm = intensity < 1.0 ? sqrt(intensity > 0.0 ? intensity : 0.0) : intensity;
    return diff / (CYCLES_ERROR_EPS + norm);
}

long
mcp_renderer_rule_update(const mcp_image *mean, const mcp_image *half, double threshold,
                         int dilate, unsigned char *converged)
{
    if (!mean || !half || !converged)
        return mcp_error("renderer rule: missing the mean, the half buffer or the flags");
    if (mean->channels < 3 || half->channels < 3 || mean->width != half->width ||
        mean->height != half->height)
        return mcp_error("renderer rule: the mean (%dx%d, %d channels) and the half "
                         "buffer (%dx%d, %d channels) must be the same size with R, G, B",
                         mean->width, mean->height, mean->channels, half->width,
                         half->height, half->channels);
    const int w = mean->width, h = mean->height;
    const double limit = CYCLES_THRESHOLD_SCALE * threshold;
    /* a stopped pixel stays stopped unless a neighbour wakes it (Cycles only re-tests
       the pixels whose flag is clear) */
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            unsigned char *f = &converged[(size_t)y * w + x];
            if (*f) continue;
            float m[3], a[3];
            const float *pm = mcp_image_px(mean, x, y), *pa = mcp_image_px(half, x, y);
            for (int c = 0; c < 3; c++)
                m[c] = pm[c], a[c] = pa[c];
            *f = mcp_renderer_rule_pixel_error(m, a) < limit;
        }
    long active = 0;
    if (dilate == 0) {
        for (size_t i = 0; i < (size_t)w * h; i++)
            active += !converged[i];
        return active;
    }
    /* the unstopped set grown by a square of radius dilate: first along rows, then
       along columns (separable, as Cycles' two box passes) */
    unsigned char *row = mcp_malloc((size_t)w * h);
    if (!row) return -1;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int awake = 0;
            for (int dx = -dilate; dx <= dilate && !awake; dx++) {
                int xx = x + dx;
                awake = xx >= 0 && xx < w && !converged[(size_t)y * w + xx];
            }
            row[(size_t)y * w + x] = (unsigned char)awake;
        }
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            int awake = 0;
            for (int dy = -dilate; dy <= dilate && !awake; dy++) {
                int yy = y + dy;
                awake = yy >= 0 && yy < h && row[(size_t)yy * w + x];
            }
            converged[(size_t)y * w + x] = (unsigned char)!awake;
            active += awake;
        }
    free(row);
    return active;
}

void
mcp_renderer_rule_result_free(mcp_renderer_rule_result *r)
{
    if (!r) return;
    free(r->points);
    mcp_dump_free(r->accumulated);
    mcp_image_free(r->denoised);
    free(r);
}

/* The running sums of the half buffers: per pixel R, G, B and the count. */
static int
add_half(double *sums, const mcp_image *half, int pass, int w, int h)
{
    int ch = mcp_image_channel(half, "SampleCount");
    if (half->width != w || half->height != h || half->channels < 4 || ch < 3)
        return mcp_error("renderer rule: pass %d: the half buffer must be %dx%d with "
                         "R, G, B and SampleCount (got %dx%d, %d channels)",
                         pass, w, h, half->width, half->height, half->channels);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const float *p = mcp_image_px(half, x, y);
            double *s = sums + 4 * ((size_t)y * w + x);
            for (int c = 0; c < 3; c++)
                s[c] += (double)p[c] * p[ch];
            s[3] += p[ch];
        }
    return 0;
}

/* Denoises the accumulated dump and fills the point's errors. */
static int
record(const mcp_denoiser *den, const mcp_dump *acc, const mcp_image *reference,
       mcp_renderer_rule_point *pt, mcp_image **denoised)
{
    mcp_image_free(*denoised);
    *denoised = NULL;
    mcp_denoise_input in = mcp_denoise_input_of(acc);
    if (den->apply(den, &in, denoised)) return mcp_error_prefix("%s: ", den->name);
    pt->relmse = pt->relmse_noisy = NAN;
    if (reference && (mcp_relmse(*denoised, reference, MCP_EPS_REL, &pt->relmse) ||
                      mcp_relmse(acc->color, reference, MCP_EPS_REL, &pt->relmse_noisy)))
        return -1;
    return 0;
}

int
mcp_renderer_rule_run(int width, int height, const mcp_denoiser *den,
                      const mcp_renderer_rule_options *opt,
                      mcp_renderer_rule_render_fn render, void *render_ctx,
                      const mcp_image *reference, mcp_renderer_rule_result **out)
{
    static const char *const count_name[1] = {"SampleCount"};
    *out = NULL;
    mcp_renderer_rule_options o = opt ? *opt : mcp_renderer_rule_defaults();
    if (mcp_renderer_rule_check(&o)) return -1;
    if (width < 1 || height < 1 || width > MCP_MAX_DIM || height > MCP_MAX_DIM)
        return mcp_error("renderer rule: bad image size %dx%d", width, height);
    if (!den || !render) return mcp_error("renderer rule: missing denoiser or renderer");
    if (reference && (reference->width != width || reference->height != height))
        return mcp_error("renderer rule: the reference %s is %dx%d, the image %dx%d",
                         reference->source ? reference->source : "", reference->width,
                         reference->height, width, height);
    const size_t npix = (size_t)width * height;
    const int every = o.record_every > 0 ? o.record_every : o.step;
    const int min_samples = mcp_renderer_rule_min_samples(&o);
    /* at most one point per pass, and one at the end */
    const int max_points = (o.max_spp + o.step - 1) / o.step + 1;

    mcp_renderer_rule_result *r = mcp_calloc(1, sizeof *r);
    if (!r) return -1;
    r->min_samples = min_samples;
    r->points = mcp_calloc((size_t)max_points, sizeof *r->points);
    unsigned char *converged = mcp_calloc(npix, 1);
    double *sums = mcp_calloc(npix * 4, sizeof *sums);
    mcp_image *counts = NULL, *half = NULL, *half_mean = NULL;
    int rc = -1;
    if (!r->points || !converged || !sums ||
        mcp_image_new(width, height, 1, count_name, &counts) ||
        mcp__image_new(width, height, 3, NULL, "half buffer mean", &half_mean))
        goto done;
    int64_t total = 0;
    long active = (long)npix;
    for (int pass = 0, n = 0; n < o.max_spp && active > 0; pass++) {
        const int samples = o.max_spp - n < o.step ? o.max_spp - n : o.step;
        for (size_t i = 0; i < npix; i++)
            counts->data[i] = converged[i] ? 0.0f : (float)samples;
        mcp_dump *part = NULL;
        if (render(pass, counts, &part, &half, render_ctx)) {
            mcp_error_prefix("renderer rule: pass %d: ", pass);
            goto done;
        }
        if (!part || !part->color || !half) {
            mcp_dump_free(part);
            mcp_error("renderer rule: pass %d: the renderer gave no image or no half "
                      "buffer",
                      pass);
            goto done;
        }
        if (mcp__adaptive_check_pass(part, counts, pass) ||
            add_half(sums, half, pass, width, height)) {
            mcp_dump_free(part);
            goto done;
        }
        mcp_image_free(half);
        half = NULL;
        if (mcp__adaptive_accumulate(&r->accumulated, part)) {
            mcp_error_prefix("renderer rule: pass %d: ", pass);
            goto done;
        }
        total += (int64_t)samples * active;
        n += samples;
        /* Cycles checks after sample index n - 1 when it is past min_samples */
        if (n - 1 > min_samples) {
            for (size_t i = 0; i < npix; i++) {
                const double *s = sums + 4 * i;
                for (int c = 0; c < 3; c++)
                    half_mean->data[3 * i + c] = s[3] > 0 ? (float)(s[c] / s[3]) : 0.0f;
            }
            active = mcp_renderer_rule_update(r->accumulated->color, half_mean,
                                              o.threshold, o.dilate, converged);
            if (active < 0) goto done;
        }
        if (n % every == 0 || n >= o.max_spp || active == 0) {
            mcp_renderer_rule_point *pt = &r->points[r->count++];
            pt->max_spp = n;
            pt->mean_spp = (double)total / (double)npix;
            pt->active = active;
            if (record(den, r->accumulated, reference, pt, &r->denoised)) goto done;
        }
    }
    rc = 0;
done:
    free(converged);
    free(sums);
    mcp_image_free(counts);
    mcp_image_free(half);
    mcp_image_free(half_mean);
    if (rc)
        mcp_renderer_rule_result_free(r);
    else
        *out = r;
    return rc;
}
