/* void_cluster.c: blue-noise dither masks by the void-and-cluster method (Ulichney
 * 1993; docs/mathematics.md §4.8: [128x128, sigma = 1.5, toroidal]), generated
 * deterministically from a seed and cached on disk.
 *
 * Energy E(p) = sum over minority pixels q of exp(-|p - q|^2 / (2 sigma^2)), distances
 * on the torus. The Gaussian is cut at 6 sigma (weights below 2e-8 dropped), which
 * keeps every update local; ties go to the first pixel in row-major order.
 *  1. a random initial pattern of size^2 / 10 ones (from the seed);
 *  2. swap the tightest cluster (the one with the largest E) into the largest void
 *     (the zero with the smallest E) until that would put it back where it was;
 *  3. ranks of the initial ones: remove tightest clusters one by one, ranks counting
 *     down from ones - 1;
 *  4. ranks of the rest: fill the largest void, ranks counting up. (Ulichney's phase
 *     III, the tightest cluster of zeros, is the same pixel: the zeros' energy is the
 *     constant total minus the ones' energy.)
 * The cache holds the ranks as an EXR with one float channel "rank" (integers below
 * 2^24 are exact), named by size, sigma and seed; one that is missing, unreadable or
 * not a permutation is regenerated, and a folder that cannot be made means no cache. */
#define _POSIX_C_SOURCE 200809L /* mkdir, getenv in strict C11 */
#include "internal.h"

#include <mcpost/imageio.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

mcp_blue_noise_options
mcp_blue_noise_defaults(void)
{
    return (mcp_blue_noise_options){
        .size = 128, .sigma = 1.5, .seed = 1, .use_cache = 1, .cache_dir = NULL};
}

typedef struct {
    int size, radius;
    double *kernel; /* (2 radius + 1)^2 */
    double *energy; /* size^2 */
    unsigned char *bit;
} vc_state;

static void
splat(vc_state *v, int p, double sign)
{
    int s = v->size, r = v->radius, side = 2 * r + 1, px = p % s, py = p / s;
    for (int dy = -r; dy <= r; dy++) {
        int y = ((py + dy) % s + s) % s;
        for (int dx = -r; dx <= r; dx++) {
            int x = ((px + dx) % s + s) % s;
            v->energy[y * s + x] += sign * v->kernel[(dy + r) * side + dx + r];
        }
    }
    v->bit[p] = sign > 0;
}

/* The one with the largest energy (tightest cluster), or the zero with the smallest
 * (largest void). */
static int
tightest_cluster(const vc_state *v)
{
    int n = v->size * v->size, best = -1;
    double e = -INFINITY;
    for (int p = 0; p < n; p++)
        if (v->bit[p] && v->energy[p] > e) e = v->energy[p], best = p;
    return best;
}

static int
largest_void(const vc_state *v)
{
    int n = v->size * v->size, best = -1;
    double e = INFINITY;
    for (int p = 0; p < n; p++)
        if (!v->bit[p] && v->energy[p] < e) e = v->energy[p], best = p;
    return best;
}

int
mcp_void_and_cluster(int size, double sigma, uint64_t seed, int *rank)
{
    if (size < 4 || size > 1024)
        return mcp_error("blue noise: size must be in [4, 1024] (got %d)", size);
    if (!(sigma > 0.0 && sigma <= size / 4.0))
        return mcp_error("blue noise: sigma must be in (0, size/4] (got %g)", sigma);
    int n = size * size, rc = -1;
    vc_state v = {.size = size};
    v.radius = (int)ceil(6.0 * sigma);
    if (2 * v.radius + 1 > size)
        v.radius = (size - 1) / 2; /* the window must not wrap onto itself */
    int side = 2 * v.radius + 1, ones = n / 10 > 1 ? n / 10 : 1;
    unsigned char *proto = NULL;
    double *proto_energy = NULL;
    int *order = NULL;
    if (!(v.kernel = mcp_malloc((size_t)side * side * sizeof *v.kernel)) ||
        !(v.energy = mcp_calloc((size_t)n, sizeof *v.energy)) ||
        !(v.bit = mcp_calloc((size_t)n, 1)) || !(proto = mcp_malloc((size_t)n)) ||
        !(proto_energy = mcp_malloc((size_t)n * sizeof *proto_energy)) ||
        !(order = mcp_malloc((size_t)n * sizeof *order)))
        goto done;
    for (int dy = -v.radius; dy <= v.radius; dy++)
        for (int dx = -v.radius; dx <= v.radius; dx++)
            v.kernel[(dy + v.radius) * side + dx + v.radius] =
                exp(-(dx * dx + dy * dy) / (2.0 * sigma * sigma));
    /* 1. initial pattern: the first `ones` pixels of a seeded Fisher-Yates shuffle */
    for (int p = 0; p < n; p++)
        order[p] = p;
    for (int i = n - 1; i > 0; i--) {
        int j = (int)(mcp__hash64(seed, (uint64_t)i) % (uint64_t)(i + 1)), t = order[i];
        order[i] = order[j], order[j] = t;
    }
    for (int i = 0; i < ones; i++)
        splat(&v, order[i], 1.0);
    /* 2. rearrange into the prototype pattern; each swap lowers the clustering, and the
     * cap only guards against a float tie cycling */
    for (long it = 0; it < 64L * n; it++) {
        int t = tightest_cluster(&v);
        splat(&v, t, -1.0);
        int u = largest_void(&v);
        splat(&v, u, 1.0);
        if (u == t) break;
    }
    memcpy(proto, v.bit, (size_t)n);
    memcpy(proto_energy, v.energy, (size_t)n * sizeof *proto_energy);
    /* 3. the initial ones, tightest first, get the ranks below `ones` */
    for (int k = ones - 1; k >= 0; k--) {
        int t = tightest_cluster(&v);
        splat(&v, t, -1.0);
        rank[t] = k;
    }
    /* 4. the rest, largest void first */
    memcpy(v.bit, proto, (size_t)n);
    memcpy(v.energy, proto_energy, (size_t)n * sizeof *proto_energy);
    for (int k = ones; k < n; k++) {
        int u = largest_void(&v);
        splat(&v, u, 1.0);
        rank[u] = k;
    }
    rc = 0;
done:
    free(v.kernel), free(v.energy), free(v.bit), free(proto), free(proto_energy),
        free(order);
    return rc;
}

/* ---- the cache ---- */

static int
make_dirs(char *path)
{
    for (char *p = path + 1; *p; p++)
        if (*p == '/') {
            *p = '\0';
            int bad = mkdir(path, 0777) != 0 && errno != EEXIST;
            *p = '/';
            if (bad) return -1;
        }
    return mkdir(path, 0777) != 0 && errno != EEXIST ? -1 : 0;
}

/* The cache file's path in buf, its folder created; -1 when there is no usable one. */
static int
cache_path(const mcp_blue_noise_options *o, char *buf, size_t cap)
{
    char dir[4096];
    const char *xdg = getenv("XDG_CACHE_HOME"), *home = getenv("HOME");
    if (o->cache_dir && *o->cache_dir)
        snprintf(dir, sizeof dir, "%s", o->cache_dir);
    else if (xdg && *xdg)
        snprintf(dir, sizeof dir, "%s/mcpost", xdg);
    else if (home && *home)
        snprintf(dir, sizeof dir, "%s/.cache/mcpost", home);
    else
        return -1;
    if (make_dirs(dir)) return -1;
    int len = snprintf(buf, cap, "%s/void_cluster_%d_sigma%.6g_seed%llu.exr", dir,
                       o->size, o->sigma, (unsigned long long)o->seed);
    return len > 0 && (size_t)len < cap ? 0 : -1;
}

/* Reads cached ranks; -1 (no error kept) when absent or not a permutation. */
static int
cache_read(const char *path, int size, int *rank)
{
    mcp_image *img = NULL;
    int n = size * size, rc = -1;
    unsigned char *seen = NULL;
    if (mcp_image_read(path, NULL, &img) || img->width != size || img->height != size ||
        mcp_image_channel(img, "rank") < 0 || !(seen = mcp_calloc((size_t)n, 1)))
        goto done;
    int c = mcp_image_channel(img, "rank");
    for (int y = 0; y < size; y++)
        for (int x = 0; x < size; x++) {
            float v = mcp_image_px(img, x, y)[c];
            if (!(v >= 0.0f && v < (float)n) || v != floorf(v) || seen[(int)v]++)
                goto done;
            rank[y * size + x] = (int)v;
        }
    rc = 0;
done:
    free(seen);
    mcp_image_free(img);
    mcp_error_clear();
    return rc;
}

static void
cache_write(const char *path, int size, const int *rank)
{
    static const char *const names[] = {"rank"};
    mcp_image *img = NULL;
    if (mcp_image_new(size, size, 1, names, &img) == 0) {
        for (int p = 0; p < size * size; p++)
            img->data[p] = (float)rank[p];
        mcp_image_write(img, path, NULL); /* a cache that cannot be written is skipped */
    }
    mcp_image_free(img);
    mcp_error_clear();
}

/* Masks already made in this process (never freed: a handful of 64 KB images), so that
 * repeated calls -- a comparison, a benchmark -- neither regenerate nor reread them. */
#define MEMO_SLOTS 8
static struct {
    int size;
    double sigma;
    uint64_t seed;
    mcp_image *mask;
} memo[MEMO_SLOTS];

static const mcp_image *
memo_find(const mcp_blue_noise_options *o)
{
    const mcp_image *found = NULL;
#pragma omp critical(mcp_blue_noise_memo)
    for (int i = 0; i < MEMO_SLOTS && !found; i++)
        if (memo[i].mask && memo[i].size == o->size && memo[i].sigma == o->sigma &&
            memo[i].seed == o->seed)
            found = memo[i].mask;
    return found;
}

/* Keeps img (taking it) when a slot is free; returns the kept mask or NULL. */
static const mcp_image *
memo_keep(const mcp_blue_noise_options *o, mcp_image *img)
{
    const mcp_image *kept = NULL;
#pragma omp critical(mcp_blue_noise_memo)
    for (int i = 0; i < MEMO_SLOTS && !kept; i++)
        if (!memo[i].mask) {
            memo[i].size = o->size, memo[i].sigma = o->sigma, memo[i].seed = o->seed;
            kept = memo[i].mask = img;
        }
    return kept;
}

/* The mask made from ranks (a new image), or read/generated as the options say. */
static int
make_mask(const mcp_blue_noise_options *opt, mcp_image **out)
{
    static const char *const names[] = {"B"};
    int n = opt->size * opt->size;
    int *rank = mcp_malloc((size_t)n * sizeof *rank);
    if (!rank) return -1;
    char path[4096];
    int cached = opt->use_cache && cache_path(opt, path, sizeof path) == 0;
    if (!cached || cache_read(path, opt->size, rank)) {
        if (mcp_void_and_cluster(opt->size, opt->sigma, opt->seed, rank)) {
            free(rank);
            return -1;
        }
        if (cached) cache_write(path, opt->size, rank);
    }
    mcp_image *img = NULL;
    if (mcp_image_new(opt->size, opt->size, 1, names, &img)) {
        free(rank);
        return -1;
    }
    for (int p = 0; p < n; p++)
        img->data[p] = (float)((rank[p] + 0.5) / n);
    free(rank);
    if (mcp_image_set_source(img, "blue-noise mask")) {
        mcp_image_free(img);
        return -1;
    }
    *out = img;
    return 0;
}

/* The mask, from this process's memo when it was made before (borrowed), else made
 * and memoised (borrowed) or, with the memo full, returned in *owned. */
static int
shared_mask(const mcp_blue_noise_options *opt, const mcp_image **mask, mcp_image **owned)
{
    *owned = NULL;
    if (opt->size < 4 || opt->size > 1024)
        return mcp_error("blue noise: size must be in [4, 1024] (got %d)", opt->size);
    if ((*mask = memo_find(opt))) return 0;
    mcp_image *img = NULL;
    if (make_mask(opt, &img)) return -1;
    if (!(*mask = memo_keep(opt, img))) *mask = *owned = img;
    return 0;
}

int
mcp_blue_noise_mask(const mcp_blue_noise_options *opt, mcp_image **out)
{
    mcp_blue_noise_options d = mcp_blue_noise_defaults();
    if (!opt) opt = &d;
    *out = NULL;
    /* set: GCC -O3 cannot see that shared_mask() fills mask whenever it returns 0 */
    const mcp_image *mask = NULL;
    mcp_image *owned = NULL;
    if (shared_mask(opt, &mask, &owned)) return -1;
    if (owned) {
        *out = owned;
        return 0;
    }
    return mcp_image_copy(mask, out);
}

int
mcp__mask(const mcp_perc_options *opt, const mcp_image **mask, mcp_image **owned)
{
    *owned = NULL;
    *mask = NULL;
    if (!opt->mask_image) return shared_mask(&opt->mask, mask, owned);
    const mcp_image *m = opt->mask_image;
    const char *src = m->source ? m->source : "mask";
    if (m->width < 1 || m->height < 1 || m->channels < 1)
        return mcp_error("%s: a mask needs at least one channel and one pixel", src);
    for (int y = 0; y < m->height; y++)
        for (int x = 0; x < m->width; x++) {
            float v = mcp_image_px(m, x, y)[0];
            if (!(v >= 0.0f && v < 1.0f))
                return mcp_error(
                    "%s: mask values must be in [0, 1) (got %g at pixel %d, %d)", src, v,
                    x, y);
        }
    *mask = m;
    return 0;
}
