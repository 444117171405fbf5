/* diffusion.c: error diffusion in the vertical search space (docs/mathematics.md §4.7;
 * Chizhov et al. 2022 Alg. 1 lines 8-15; Floyd & Steinberg 1976).
 *
 * O := I' (the surrogate); serpentine scan; each pixel takes the candidate nearest
 * (squared RGB distance) to its current value, and the difference is pushed to the
 * unvisited neighbours with weights 7/16 (ahead), 3/16 (below behind), 5/16 (below)
 * and 1/16 (below ahead), mirrored on rows scanned right to left. Weights that fall
 * outside the image are dropped, not renormalised. Values live in display space T,
 * the space of the error model (with T = none this is plain linear RGB).
 *
 * The scan is one serial chain through the image (serpentine rows cannot overlap), so
 * its time is the latency of one pixel's step. The step keeps only what depends on
 * the chain: q = (error from the row above) + (7/16 of the pixel before's), the
 * distances |q - w_j|^2 with w_j = T(Q_j) - T(I'), the selection and 7/16 of the
 * chosen difference. The selection runs in pairs of candidates (each pair's nearer
 * one found in parallel, then one running comparison per pair), with masks and
 * min, not branches: the choice is data-dependent, and the comparison's result must
 * not wait for the blend. With two threads a second one tone-maps rows ahead of the
 * scan into a ring (two counters hand rows over) and writes out the finished rows;
 * with one they alternate. bench_perceptual: 4.7 ms at 512^2, M = 4, 2 cores, from
 * 12 ms for a single-threaded scan with one comparison after another. */
#include "internal.h"

#include <math.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#define RING 8 /* prepared rows the scan may run behind */

typedef struct {
    const mcp_image *const *cands;
    const mcp_image *surrogate;
    const int *rgb, *srgb;
    int w, h, m;
    mcp_tonemap tm;
    float *ring;   /* RING slots of ring_row */
    double *below; /* the scan's: error pushed down to this row */
    double *e;     /* the row's errors, a zero pixel at each end */
    int *choice;   /* RING rows of the scan's choices, [RING][w] */
    mcp_image *image, *index;
    long n_bad;
    atomic_int prepared, scanned; /* rows done by each side */
} diffusion_run;

#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
#include <emmintrin.h>

/* two floats (any alignment) as doubles */
static inline __m128d
load2(const float *p)
{
    return _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)p)));
}

static inline __m128d
load1(const float *p)
{
    return _mm_cvtss_sd(_mm_setzero_pd(), _mm_load_ss(p));
}

/* mask ? a : b */
static inline __m128d
mask_select(__m128d mask, __m128d a, __m128d b)
{
    return _mm_or_pd(_mm_and_pd(mask, a), _mm_andnot_pd(mask, b));
}

/* |q - (T(Q_j) - T(I'))|^2 for the candidate at t, and its differences */
static inline __m128d
distance(__m128d q01, __m128d q2, __m128d s01, __m128d s2, const float *t, __m128d *d01,
         __m128d *d2)
{
    *d01 = _mm_sub_pd(q01, _mm_sub_pd(load2(t), s01));
    *d2 = _mm_sub_sd(q2, _mm_sub_sd(load1(t + 2), s2));
    /* the sum in both lanes, so that comparisons give whole masks */
    __m128d sq = _mm_mul_pd(*d01, *d01), sq2 = _mm_mul_sd(*d2, *d2);
    return _mm_add_pd(_mm_add_pd(sq, _mm_shuffle_pd(sq, sq, 1)),
                      _mm_unpacklo_pd(sq2, sq2));
}

/* The nearer of the candidates at t and t + stride (only the first when !two, and
 * the first on a tie): its index in the pair (0, 1), distance and differences. */
static inline int
nearer_of_pair(__m128d q01, __m128d q2, __m128d s01, __m128d s2, const float *t,
               size_t stride, int two, __m128d *d, __m128d *d01, __m128d *d2)
{
    *d = distance(q01, q2, s01, s2, t, d01, d2);
    if (!two) return 0;
    __m128d od01, od2, od = distance(q01, q2, s01, s2, t + stride, &od01, &od2);
    __m128d lt = _mm_cmplt_pd(od, *d);
    *d = _mm_min_pd(od, *d); /* = lt ? od : *d, without waiting for the mask */
    *d01 = mask_select(lt, od01, *d01), *d2 = mask_select(lt, od2, *d2);
    return _mm_movemask_pd(lt) & 1;
}
#endif

/* Row y's slot of the ring: T(Q_j) rows [m][w][3], then T(I') [w][3]. */
static float *
ring_row(const diffusion_run *r, int y)
{
    return r->ring + (size_t)(y % RING) * (r->m + 1) * r->w * 3;
}

static void
prepare_row(diffusion_run *r, int y)
{
    size_t row3 = (size_t)r->w * 3;
    float *slot = ring_row(r, y);
    for (int j = 0; j < r->m; j++)
        r->n_bad += mcp__tone_row(r->cands[j], r->rgb + 3 * j, y, r->tm, slot + j * row3);
    r->n_bad += mcp__tone_row(r->surrogate, r->srgb, y, r->tm, slot + r->m * row3);
}

/* The serial scan of row y from its ring slot; inlined for the common candidate
 * counts, so that the loop over candidates unrolls. */
static inline __attribute__((always_inline)) void
scan_row_m(diffusion_run *r, int y, int m)
{
    int w = r->w;
    size_t row3 = (size_t)w * 3;
    const float *slot = ring_row(r, y), *ts = slot + m * row3;
    int *choice = r->choice + (size_t)(y % RING) * w;
    double *below = r->below, *e = r->e + 3; /* e[-1] and e[w] stay zero */
    int x0 = y % 2 ? w - 1 : 0, dx = y % 2 ? -1 : 1;
#if defined(__SSE2__) && !defined(MCP_NO_SIMD)
    /* SSE2 (every x86-64): channels 0-1 in one register, 2 in another; the selects
     * are masks, which the compiler would otherwise turn back into branches */
    const __m128d k716 = _mm_set1_pd(7.0 / 16.0);
    __m128d a01 = _mm_setzero_pd(), a2 = _mm_setzero_pd();
    for (int i = 0, x = x0; i < w; i++, x += dx) {
        __m128d q01 = _mm_add_pd(_mm_loadu_pd(below + 3 * x), a01);
        __m128d q2 = _mm_add_sd(_mm_load_sd(below + 3 * x + 2), a2);
        __m128d s01 = load2(ts + 3 * x), s2 = load1(ts + 3 * x + 2);
        /* candidates in pairs: each pair's nearer one is found off the chain, and the
         * first pair starts the running best, so that the chain of comparisons is
         * half as long */
        const float *t = slot + 3 * (size_t)x;
        __m128d e01, e2, best_d;
        int best = nearer_of_pair(q01, q2, s01, s2, t, row3, m > 1, &best_d, &e01, &e2);
        for (int j = 2; j < m; j += 2) {
            __m128d pd01, pd2, pd;
            int pj = j + nearer_of_pair(q01, q2, s01, s2, t + j * row3, row3, j + 1 < m,
                                        &pd, &pd01, &pd2);
            __m128d lt = _mm_cmplt_pd(pd, best_d);
            best_d = _mm_min_pd(pd, best_d);
            e01 = mask_select(lt, pd01, e01), e2 = mask_select(lt, pd2, e2);
            best += (pj - best) & -(_mm_movemask_pd(lt) & 1);
        }
        a01 = _mm_mul_pd(e01, k716), a2 = _mm_mul_sd(e2, k716);
        _mm_storeu_pd(e + 3 * x, e01), _mm_store_sd(e + 3 * x + 2, e2);
        choice[x] = best;
    }
#else
    /* the 7/16 share carried to the pixel ahead: scalars, kept in registers */
    double a0 = 0.0, a1 = 0.0, a2 = 0.0;
    for (int i = 0, x = x0; i < w; i++, x += dx) {
        double q0 = below[3 * x] + a0, q1 = below[3 * x + 1] + a1,
               q2 = below[3 * x + 2] + a2;
        double s0 = ts[3 * x], s1 = ts[3 * x + 1], s2 = ts[3 * x + 2];
        int best = 0;
        double best_d = INFINITY, e0 = 0.0, e1 = 0.0, e2 = 0.0;
        const float *t = slot + 3 * (size_t)x;
        for (int j = 0; j < m; j++, t += row3) {
            double d0 = q0 - ((double)t[0] - s0), d1 = q1 - ((double)t[1] - s1),
                   d2 = q2 - ((double)t[2] - s2);
            double d = d0 * d0 + d1 * d1 + d2 * d2;
            int lt = d < best_d;
            best = lt ? j : best;
            best_d = lt ? d : best_d;
            e0 = lt ? d0 : e0, e1 = lt ? d1 : e1, e2 = lt ? d2 : e2;
        }
        a0 = e0 * (7.0 / 16.0), a1 = e1 * (7.0 / 16.0), a2 = e2 * (7.0 / 16.0);
        e[3 * x] = e0, e[3 * x + 1] = e1, e[3 * x + 2] = e2;
        choice[x] = best;
    }
#endif
    /* what the next row receives: 1/16 from the pixel behind, 5/16 from the one above
     * and 3/16 from the one ahead (the zero pixels at each end of e drop the shares
     * that fall beyond the image) */
    const double *eb = e - 3 * dx, *ea = e + 3 * dx;
#pragma omp simd
    for (size_t i = 0; i < row3; i++)
        below[i] = eb[i] * (1.0 / 16.0) + e[i] * (5.0 / 16.0) + ea[i] * (3.0 / 16.0);
}

static void
scan_row(diffusion_run *r, int y)
{
    switch (r->m) {
    case 2:
        scan_row_m(r, y, 2);
        break;
    case 3:
        scan_row_m(r, y, 3);
        break;
    case 4:
        scan_row_m(r, y, 4);
        break;
    default:
        scan_row_m(r, y, r->m);
        break;
    }
}

/* The chosen candidates' linear values and indices of row y. */
static void
write_row(diffusion_run *r, int y)
{
    int w = r->w;
    const int *choice = r->choice + (size_t)(y % RING) * w;
    float *img = r->image->data + (size_t)y * w * 3,
          *idx = r->index->data + (size_t)y * w;
    for (int x = 0; x < w; x++) {
        int j = choice[x];
        const float *p = mcp_image_px(r->cands[j], x, y);
        const int *k = r->rgb + 3 * j;
        img[3 * x] = p[k[0]], img[3 * x + 1] = p[k[1]], img[3 * x + 2] = p[k[2]];
        idx[x] = (float)j;
    }
}

/* Waits until *counter >= target, yielding the core now and then (the other side may
 * share it). */
static void
wait_for(atomic_int *counter, int target)
{
    for (int spins = 0; atomic_load_explicit(counter, memory_order_acquire) < target;)
        if (++spins == 256) {
            sched_yield();
            spins = 0;
        }
}

/* The second thread: prepares rows up to RING ahead of the scan and writes out the
 * rows it has finished. */
static void
run_preparer(diffusion_run *r)
{
    int written = 0;
    for (int y = 0; y < r->h; y++) {
        /* slot y % RING is free once the scan has finished row y - RING and that row
         * is written out (the scan reuses its choices' slot for row y) */
        while (written < y - RING + 1) {
            wait_for(&r->scanned, written + 1);
            write_row(r, written++);
        }
        /* meanwhile, what the scan has finished */
        while (written < atomic_load_explicit(&r->scanned, memory_order_acquire))
            write_row(r, written++);
        prepare_row(r, y);
        atomic_store_explicit(&r->prepared, y + 1, memory_order_release);
    }
    while (written < r->h) {
        wait_for(&r->scanned, written + 1);
        write_row(r, written++);
    }
}

static void
run_scanner(diffusion_run *r)
{
    for (int y = 0; y < r->h; y++) {
        wait_for(&r->prepared, y + 1);
        scan_row(r, y);
        atomic_store_explicit(&r->scanned, y + 1, memory_order_release);
    }
}

static void
run_alone(diffusion_run *r)
{
    for (int y = 0; y < r->h; y++) {
        prepare_row(r, y);
        scan_row(r, y);
        write_row(r, y);
    }
}

int
mcp_perc_error_diffusion(const mcp_image *const *cands, int m, const mcp_image *surrogate,
                         const mcp_perc_options *opt, mcp_perc_result *out)
{
    static const char *const rgb_names[] = {"R", "G", "B"}, *const idx_names[] = {
                                                                "index"};
    mcp_perc_options d = mcp_perc_defaults();
    if (!opt) opt = &d;
    memset(out, 0, sizeof *out);
    if (!surrogate) return mcp_error("error-diffusion: needs a surrogate");
    if (mcp__check_run(opt, cands, m, surrogate)) return -1;
    double t0 = mcp__seconds();
    int w = cands[0]->width, h = cands[0]->height, rc = -1, srgb[3];
    size_t row3 = (size_t)w * 3;
    diffusion_run r = {.cands = cands,
                       .surrogate = surrogate,
                       .srgb = srgb,
                       .w = w,
                       .h = h,
                       .m = m,
                       .tm = opt->model.tone_map};
    atomic_init(&r.prepared, 0);
    atomic_init(&r.scanned, 0);
    int *rgb = mcp_malloc((size_t)m * 3 * sizeof *rgb);
    r.rgb = rgb;
    r.ring = mcp_malloc((size_t)RING * (m + 1) * row3 * sizeof *r.ring);
    r.below = mcp_calloc(row3, sizeof *r.below);
    r.e = mcp_calloc(row3 + 6, sizeof *r.e);
    r.choice = mcp_malloc((size_t)RING * w * sizeof *r.choice);
    mcp_perc_result res = {0};
    if (!rgb || !r.ring || !r.below || !r.e || !r.choice ||
        mcp__check_candidates(cands, m, NULL, rgb) || mcp_rgb_channels(surrogate, srgb) ||
        mcp_image_new(w, h, 3, rgb_names, &res.image) ||
        mcp_image_new(w, h, 1, idx_names, &res.index))
        goto done;
    r.image = res.image, r.index = res.index;
    int pipelined = 0;
#ifdef _OPENMP
    /* two threads pay off once a row's preparation outweighs the hand-over */
    pipelined = omp_get_max_threads() >= 2 && (size_t)w * m >= 256 && h > 1;
#endif
    if (pipelined) {
#pragma omp parallel num_threads(2)
        {
#ifdef _OPENMP
            if (omp_get_num_threads() < 2)
                run_alone(&r);
            else if (omp_get_thread_num() == 1)
                run_preparer(&r);
            else
                run_scanner(&r);
#endif
        }
    } else {
        run_alone(&r);
    }
    if (r.n_bad) {
        mcp_error("error-diffusion: the inputs hold %ld non-finite values", r.n_bad);
        goto done;
    }
    res.passes = 1;
    res.energy_initial = res.energy_final = NAN; /* mcp_perc_energy computes it */
    res.seconds = mcp__seconds() - t0;
    *out = res;
    memset(&res, 0, sizeof res);
    rc = 0;
done:
    mcp_perc_result_free(&res);
    free(rgb), free(r.ring), free(r.below), free(r.e), free(r.choice);
    return rc;
}
