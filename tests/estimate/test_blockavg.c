/* test_blockavg.c: estimate/blockavg.c (Firmino 2024 Alg. 1) on constructed cases and
 * against a naive recursion that sums every block directly in double (no tables).
 *
 * The constructed half-noisy case: the left half has variance 1 and a small SURE
 * (a strong denoiser's error), the right half no variance and a positive SURE. Eq. 13
 * then holds for the two halves of the whole image (2048 values a channel:
 * 2048/sqrt(2048) = 45.3 < 2048/40 = 51.2) but not for the quarters of the left half
 * (1024/32 = 32 > 25.6), while every right-half block keeps splitting (Σ̂ = 0 < SURE):
 * the left half must come out as one block ending exactly at the boundary and the
 * right half as single pixels. */
#include "testing.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include <mcpost/estimate.h>
#include "../../estimate/internal.h" /* mcp__block_average_quiet */

static const char *const RGB[] = {"R", "G", "B"};

static mcp_image *
new_rgb(int w, int h)
{
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_new(w, h, 3, RGB, &img), 0);
    return img;
}

static void
fill(mcp_image *img, int x0, int y0, int w, int h, float v)
{
    for (int y = y0; y < y0 + h; y++)
        for (int x = x0; x < x0 + w; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(img, x, y)[c] = v;
}

/* The block of pixel (x, y), through the label map (computed once per blocks). */
static const mcp_block *
block_at(const mcp_blocks *b, int x, int y)
{
    static const mcp_blocks *cached;
    static int32_t *label;
    if (b != cached) {
        free(label);
        assert_int_equal(mcp_blocks_label(b, &label), 0);
        cached = b;
    }
    return &b->items[label[(size_t)y * b->width + x]];
}

static void
test_half_noisy_splits_at_boundary(void **state)
{
    (void)state;
    mcp_image *sure = new_rgb(64, 64), *sigma = new_rgb(64, 64);
    fill(sigma, 0, 0, 32, 64, 1.0f);
    fill(sure, 0, 0, 32, 64, 1.0f / 40.0f);
    fill(sure, 32, 0, 32, 64, 0.5f);
    mcp_blocks *b = NULL;
    assert_int_equal(mcp_block_average(sure, sigma, NULL, &b), 0);
    const mcp_block *left = block_at(b, 0, 0);
    assert_int_equal(left->x, 0);
    assert_int_equal(left->y, 0);
    assert_int_equal(left->w, 32);
    assert_int_equal(left->h, 64);
    assert_close(left->sure_sum[1], 2048.0 * (float)(1.0 / 40.0), 1e-12, 0);
    for (int y = 0; y < 64; y++)
        for (int x = 32; x < 64; x++) {
            const mcp_block *k = block_at(b, x, y);
            assert_true(k->w == 1 && k->h == 1 && k->x == x && k->y == y);
        }
    assert_int_equal(b->count, 1 + 32 * 64);
    mcp_blocks_free(b);
    /* a little less SURE on the left and the root itself stays whole */
    fill(sure, 0, 0, 32, 64, 1.0f / 46.0f);
    assert_int_equal(mcp_block_average(sure, sigma, NULL, &b), 0);
    assert_int_equal(b->count, 1);
    mcp_blocks_free(b);
    mcp_image_free(sure);
    mcp_image_free(sigma);
}

/* The half-noisy case again, with the model's s² above 0 on the left half and in a
 * strip of the right half beside it (where a denoiser's footprint reaches the noisy
 * half), 0 on the rest. Quiet blocks stay whole; every other block is one of Alg. 1's,
 * with the same sums; each quiet block holds whole blocks of Alg. 1 with the same SURE
 * in all; and F(τ) and the percentiles are Alg. 1's, bit for bit, since every value of
 * a quiet block has s = 0. */
static void
test_quiet_blocks_stay_whole(void **state)
{
    (void)state;
    const int W = 64, H = 64, STRIP = 5;
    mcp_image *sure = new_rgb(W, H), *sigma = new_rgb(W, H), *s2 = new_rgb(W, H);
    fill(sigma, 0, 0, 32, H, 1.0f);
    fill(sure, 0, 0, 32, H, 1.0f / 40.0f);
    fill(sure, 32, 0, 32, H, 0.5f);
    for (int y = 0; y < H; y++) /* s² falling off from the noisy half */
        for (int x = 0; x < 32 + STRIP; x++)
            for (int c = 0; c < 3; c++)
                mcp_image_px(s2, x, y)[c] =
                    x < 32 ? 0.01f * (1 + c) : 0.002f / (float)(x - 31) * (1 + c);
    mcp_blocks *plain = NULL, *quiet = NULL;
    assert_int_equal(mcp_block_average(sure, sigma, NULL, &plain), 0);
    assert_int_equal(mcp__block_average_quiet(sure, sigma, s2, NULL, &quiet), 0);
    assert_int_equal(plain->count, 1 + 32 * 64);
    assert_true(quiet->count < 1 + STRIP * H + 64);
    int quiet_seen = 0;
    for (int i = 0; i < quiet->count; i++) {
        const mcp_block *q = &quiet->items[i];
        int is_loud = q->x < 32 + STRIP;
        double sum[3] = {0, 0, 0};
        int inside = 0;
        for (int j = 0; j < plain->count; j++) {
            const mcp_block *p = &plain->items[j];
            if (p->x < q->x || p->y < q->y || p->x + p->w > q->x + q->w ||
                p->y + p->h > q->y + q->h)
                continue;
            inside += p->w * p->h;
            for (int c = 0; c < 3; c++)
                sum[c] += p->sure_sum[c];
            if (is_loud) { /* the very same block */
                assert_true(p->x == q->x && p->y == q->y && p->w == q->w && p->h == q->h);
                for (int c = 0; c < 3; c++)
                    assert_true(p->sure_sum[c] == q->sure_sum[c]);
            }
        }
        assert_int_equal(inside, q->w * q->h); /* a union of Alg. 1's blocks */
        for (int c = 0; c < 3; c++)
            assert_close(sum[c], q->sure_sum[c], 1e-12, 0);
        if (!is_loud) {
            quiet_seen += q->w * q->h;
            for (int y = q->y; y < q->y + q->h; y++) /* quiet through and through */
                for (int x = q->x; x < q->x + q->w; x++)
                    for (int c = 0; c < 3; c++)
                        assert_true(mcp_image_px(s2, x, y)[c] == 0.0f &&
                                    mcp_image_px(sigma, x, y)[c] == 0.0f);
        }
    }
    assert_int_equal(quiet_seen, (32 - STRIP) * H);
    mcp_error_dist *dp = NULL, *dq = NULL;
    assert_int_equal(mcp_error_distribution(plain, s2, &dp), 0);
    assert_int_equal(mcp_error_distribution(quiet, s2, &dq), 0);
    /* down to τ far below any s²: a quiet block's λ is its SURE over 1e-6 (here 9e8),
       and its values must still count as below τ (stopping.c's fold_cdf) */
    for (double tau = 1e-35; tau < 10; tau *= 3.7)
        assert_true(mcp_error_cdf(dp, tau) == mcp_error_cdf(dq, tau));
    /* (the loud values' F_i there are 0 to float rounding: 1e-8 each either way) */
    assert_true(mcp_error_cdf(dq, 1e-35) >= (double)quiet_seen / (W * H) - 1e-6);
    const double ps[4] = {0.5, 0.9, 0.99, 0.999};
    double tp[4], tq[4];
    assert_int_equal(mcp_error_percentiles(dp, ps, 4, tp), 0);
    assert_int_equal(mcp_error_percentiles(dq, ps, 4, tq), 0);
    for (int k = 0; k < 4; k++)
        assert_true(tp[k] == tq[k]);
    print_message("quiet blocks: %d blocks against Alg. 1's %d; p99.9 %.6g\n",
                  quiet->count, plain->count, tq[3]);
    /* without an s² image every block is loud: Alg. 1 itself */
    mcp_blocks *again = NULL;
    assert_int_equal(mcp__block_average_quiet(sure, sigma, NULL, NULL, &again), 0);
    assert_int_equal(again->count, plain->count);
    mcp_blocks_free(again);
    mcp_error_dist_free(dp);
    mcp_error_dist_free(dq);
    mcp_blocks_free(plain);
    mcp_blocks_free(quiet);
    mcp_image_free(sure);
    mcp_image_free(sigma);
    mcp_image_free(s2);
}

/* ---- a naive Alg. 1: direct double sums over each candidate block ---- */

typedef struct naive {
    const mcp_image *sure, *sigma;
    mcp_block *items;
    int count;
} naive;

static void
naive_sums(const naive *n, int x0, int y0, int w, int h, double s[6])
{
    memset(s, 0, 6 * sizeof *s);
    for (int y = y0; y < y0 + h; y++)
        for (int x = x0; x < x0 + w; x++)
            for (int c = 0; c < 3; c++) {
                s[c] += mcp_image_px(n->sure, x, y)[c];
                s[3 + c] += mcp_image_px(n->sigma, x, y)[c];
            }
}

static int
naive_ok(const double s[6], int n)
{
    for (int c = 0; c < 3; c++)
        if (!(s[3 + c] / sqrt((double)n) < s[c])) return 0;
    return 1;
}

static void
naive_split(naive *n, int x, int y, int w, int h)
{
    if (w > 1 || h > 1) {
        int w1 = w >= h ? w / 2 : w, h1 = w >= h ? h : h / 2;
        int x2 = w >= h ? x + w1 : x, y2 = w >= h ? y : y + h1;
        int w2 = w >= h ? w - w1 : w, h2 = w >= h ? h : h - h1;
        double s1[6], s2[6];
        naive_sums(n, x, y, w1, h1, s1);
        naive_sums(n, x2, y2, w2, h2, s2);
        if (naive_ok(s1, w1 * h1) && naive_ok(s2, w2 * h2)) {
            naive_split(n, x, y, w1, h1);
            naive_split(n, x2, y2, w2, h2);
            return;
        }
    }
    mcp_block *k = &n->items[n->count++];
    k->x = x, k->y = y, k->w = w, k->h = h;
}

/* SURE^r = σ̂^r × (a smooth bias field + noise): splits at varied depths. */
static void
random_case(int w, int h, uint64_t seed, mcp_image **sure, mcp_image **sigma)
{
    *sure = new_rgb(w, h);
    *sigma = new_rgb(w, h);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) {
                double sg = 0.1 + mcp_test_rand_uniform(&seed);
                double bias = 0.02 * (1 + sin(0.2 * x + 0.1 * c) * cos(0.15 * y));
                mcp_image_px(*sigma, x, y)[c] = (float)sg;
                mcp_image_px(*sure, x, y)[c] =
                    (float)(bias * (x > w / 3 ? 30 : 1) +
                            0.3 * sg * mcp_test_rand_normal(&seed));
            }
}

static void
check_against_naive(int w, int h, int tile, uint64_t seed)
{
    mcp_image *sure, *sigma;
    random_case(w, h, seed, &sure, &sigma);
    naive n = {sure, sigma, calloc((size_t)w * h, sizeof(mcp_block)), 0};
    int t = tile > 0 ? tile : (w > h ? w : h);
    for (int ty = 0; ty < h; ty += t)
        for (int tx = 0; tx < w; tx += t)
            naive_split(&n, tx, ty, tx + t < w ? t : w - tx, ty + t < h ? t : h - ty);
    mcp_block_options o = mcp_block_defaults();
    o.tile_size = tile;
    mcp_blocks *b = NULL;
    assert_int_equal(mcp_block_average(sure, sigma, &o, &b), 0);
    print_message("%dx%d tile %d: %d blocks (naive %d)\n", w, h, tile, b->count, n.count);
    assert_int_equal(b->count, n.count);
    for (int i = 0; i < n.count; i++) {
        assert_int_equal(b->items[i].x, n.items[i].x);
        assert_int_equal(b->items[i].y, n.items[i].y);
        assert_int_equal(b->items[i].w, n.items[i].w);
        assert_int_equal(b->items[i].h, n.items[i].h);
        double s[6];
        naive_sums(&n, n.items[i].x, n.items[i].y, n.items[i].w, n.items[i].h, s);
        for (int c = 0; c < 3; c++)
            assert_close(b->items[i].sure_sum[c], s[c], 1e-9, 1e-9);
    }
    /* the label covers every pixel with its block */
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            const mcp_block *k = block_at(b, x, y);
            assert_true(x >= k->x && x < k->x + k->w && y >= k->y && y < k->y + k->h);
        }
    mcp_blocks_free(b);
    free(n.items);
    mcp_image_free(sure);
    mcp_image_free(sigma);
}

static void
test_matches_naive(void **state)
{
    (void)state;
    check_against_naive(64, 64, 0, 1);
    check_against_naive(37, 29, 0, 2);
    check_against_naive(130, 70, 0, 3);   /* spans two table bands of 64 rows */
    check_against_naive(200, 150, 48, 4); /* pre-split, with partial edge tiles */
    check_against_naive(1, 1, 0, 5);
    check_against_naive(97, 1, 0, 6);
}

static void
test_tiles_bound_blocks(void **state)
{
    (void)state;
    mcp_image *sure = new_rgb(100, 60), *sigma = new_rgb(100, 60);
    fill(sigma, 0, 0, 100, 60, 1.0f); /* SURE 0: nothing ever splits */
    mcp_block_options o = {32};
    mcp_blocks *b = NULL;
    assert_int_equal(mcp_block_average(sure, sigma, &o, &b), 0);
    assert_int_equal(b->count, 4 * 2); /* ceil(100/32) x ceil(60/32) */
    assert_int_equal(b->items[3].x, 96);
    assert_int_equal(b->items[3].w, 4);
    assert_int_equal(b->items[7].h, 28);
    mcp_blocks_free(b);
    mcp_image_free(sure);
    mcp_image_free(sigma);
}

static void
test_thread_count_independent(void **state)
{
    (void)state;
#ifdef _OPENMP
    mcp_image *sure, *sigma;
    random_case(150, 140, 9, &sure, &sigma);
    int saved = omp_get_max_threads();
    mcp_blocks *a = NULL, *b = NULL;
    omp_set_num_threads(1);
    assert_int_equal(mcp_block_average(sure, sigma, NULL, &a), 0);
    omp_set_num_threads(4);
    assert_int_equal(mcp_block_average(sure, sigma, NULL, &b), 0);
    omp_set_num_threads(saved);
    assert_int_equal(a->count, b->count);
    assert_memory_equal(a->items, b->items, (size_t)a->count * sizeof *a->items);
    mcp_blocks_free(a);
    mcp_blocks_free(b);
    mcp_image_free(sure);
    mcp_image_free(sigma);
#endif
}

static void
test_mean_image_and_picture(void **state)
{
    (void)state;
    mcp_image *sure = new_rgb(64, 64), *sigma = new_rgb(64, 64);
    fill(sigma, 0, 0, 32, 64, 1.0f);
    fill(sure, 0, 0, 32, 64, 1.0f / 40.0f);
    fill(sure, 32, 0, 32, 64, 0.5f);
    mcp_image_px(sure, 3, 5)[0] = 10.0f; /* one outlier inside the left block */
    mcp_blocks *b = NULL;
    assert_int_equal(mcp_block_average(sure, sigma, NULL, &b), 0);
    mcp_image *m = NULL;
    assert_int_equal(mcp_blocks_mean_image(b, sure, &m), 0);
    assert_close(mcp_image_px(m, 20, 40)[0], (2047 / 40.0 + 10.0) / 2048, 1e-6, 0);
    assert_close(mcp_image_px(m, 20, 40)[1], 1 / 40.0, 1e-6, 0);
    assert_close(mcp_image_px(m, 50, 40)[2], 0.5, 1e-6, 0);
    unsigned char *rgb = malloc(64 * 64 * 3);
    assert_int_equal(mcp_blocks_picture(b, rgb), 0);
    /* one colour over the left block; neighbouring pixel blocks mostly differ */
    assert_memory_equal(rgb, rgb + 3 * (63 * 64 + 31), 3);
    int differ = 0;
    for (int x = 32; x < 63; x++)
        differ += memcmp(rgb + 3 * (10 * 64 + x), rgb + 3 * (10 * 64 + x + 1), 3) != 0;
    assert_true(differ > 25);
    free(rgb);
    mcp_image_free(m);
    mcp_blocks_free(b);
    mcp_image_free(sure);
    mcp_image_free(sigma);
}

static void
test_errors(void **state)
{
    (void)state;
    mcp_image *a = new_rgb(8, 8), *b = new_rgb(8, 9), *one = NULL;
    mcp_blocks *out = NULL;
    assert_error_contains(mcp_block_average(a, b, NULL, &out),
                          "block averaging: SURE is 8x8 but the variance 8x9");
    assert_null(out);
    mcp_block_options o = {-1};
    assert_error_contains(mcp_block_average(a, a, &o, &out),
                          "block averaging: tile_size must be >= 0 (got -1)");
    mcp_image *clean = new_rgb(8, 8);
    mcp_image_px(a, 2, 2)[1] = NAN;
    mcp_image_px(a, 7, 7)[2] = INFINITY;
    assert_error_contains(mcp_block_average(a, clean, NULL, &out),
                          "block averaging: 2 values of SURE or variance are not finite");
    mcp_image_free(clean);
    assert_int_equal(mcp_image_new(8, 8, 1, NULL, &one), 0);
    assert_error_contains(mcp_block_average(one, one, NULL, &out),
                          "SURE and variance need 3 channels (got 1, 1)");
    mcp_image_free(one);
    mcp_image_free(a);
    mcp_image_free(b);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_half_noisy_splits_at_boundary),
        cmocka_unit_test(test_quiet_blocks_stay_whole),
        cmocka_unit_test(test_matches_naive),
        cmocka_unit_test(test_tiles_bound_blocks),
        cmocka_unit_test(test_thread_count_independent),
        cmocka_unit_test(test_mean_image_and_picture),
        cmocka_unit_test(test_errors),
    };
    return cmocka_run_group_tests_name("estimate/blockavg", tests, NULL, NULL);
}
