/* unet_memory.c: the memory of the U-Net's activations (unet.c): huge-page blocks, the
 * cache of freed blocks, and the memory plan of a pass.
 *
 * Every layer writes a fresh output, and the kernel clears each fresh page on its first
 * touch: on the 2-core VM that clearing runs at about 1 GB/s and took 16% of a 1080p
 * apply's CPU (`perf record`: clear_page_erms). What a pass asks for is known before
 * it runs: the same requests, of the same sizes, in the same order, for the primal and
 * for every tangent (they run one at a time). So a run first walks the network without
 * computing anything (a dry pass: every request gets a placeholder address and is
 * recorded with its lifetime), places the requests in one arena so that no two that are
 * alive at once overlap (largest first, each at the lowest offset free for its
 * lifetime), and then every pass takes its blocks from the arena. The arena is the
 * largest sum of blocks alive at once, rounded to huge pages: at 1080p 0.80 GB (one
 * full-resolution 64-channel output beside a 32-channel one), where the cache below
 * held 1.16 GB at the peak of an apply with tangents and had touched 1.17 GB fresh. A
 * request the plan does not cover (one that outlives its pass, as the network's
 * output, or a pass that differs from the plan) goes to the cache. */
#define _DEFAULT_SOURCE /* madvise, MADV_HUGEPAGE */
#include "unet_internal.h"

#include <mcpost/error.h>

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

/* ---- huge-page blocks ----
 * Large blocks are aligned to 2 MB and marked for transparent huge pages where the
 * system offers them on request: the first touch of a fresh block then faults once per
 * 2 MB instead of once per 4 kB page, which otherwise costs as much as the convolutions
 * on some virtual machines. */
#define HUGE_PAGE ((size_t)2 << 20)

static size_t
block_bytes(size_t bytes)
{
    return bytes < 2 * HUGE_PAGE ? bytes
                                 : (bytes + HUGE_PAGE - 1) / HUGE_PAGE * HUGE_PAGE;
}

void *
mcp__unet_alloc(size_t bytes)
{
    if (bytes < 2 * HUGE_PAGE) return mcp_malloc(bytes);
    void *p = NULL;
    const size_t rounded = block_bytes(bytes);
    if (!(p = aligned_alloc(HUGE_PAGE, rounded))) {
        mcp_error("out of memory (%zu bytes)", bytes);
        return NULL;
    }
#ifdef MADV_HUGEPAGE
    (void)madvise(p, rounded, MADV_HUGEPAGE); /* a hint: without it, 4 kB pages */
#endif
    return p;
}

/* ---- the cache of freed blocks ----
 * Blocks freed during one run of the network, kept for its next requests that the
 * plan does not serve (the fixed-bit mode's passes, whose direct loops are not planned,
 * and the outputs). The cache belongs to the calling thread (the network's layers are
 * called from one thread; OpenMP's workers never allocate batches), and it is emptied
 * when the run ends, so nothing is held between calls. A request takes the smallest
 * cached block that holds it; a full cache frees its smallest block. When none holds
 * it, a plain apply empties the cache first (its blocks would only raise the peak),
 * while a run with tangents keeps them: each tangent's pass repeats the primal's
 * requests, so they all find their blocks. */
#define CACHE_SLOTS 6

typedef struct cached_block {
    void *p;
    size_t cap;
} cached_block;

static _Thread_local cached_block block_cache[CACHE_SLOTS];
static _Thread_local int block_cache_keeps; /* 1: tangents follow the primal */

void
mcp__unet_blocks_keep(int keep)
{
    block_cache_keeps = keep;
}

void
mcp__unet_blocks_drain(void)
{
    for (int i = 0; i < CACHE_SLOTS; i++) {
        free(block_cache[i].p);
        block_cache[i] = (cached_block){0};
    }
}

static void *
cache_take(size_t bytes, size_t *cap)
{
    int best = -1;
    for (int i = 0; i < CACHE_SLOTS; i++)
        if (block_cache[i].p && block_cache[i].cap >= bytes &&
            (best < 0 || block_cache[i].cap < block_cache[best].cap))
            best = i;
    if (best >= 0) {
        void *p = block_cache[best].p;
        *cap = block_cache[best].cap;
        block_cache[best] = (cached_block){0};
        return p;
    }
    /* none holds it: in a plain apply, the cached blocks would only raise the peak */
    if (!block_cache_keeps) mcp__unet_blocks_drain();
    *cap = block_bytes(bytes);
    return mcp__unet_alloc(bytes);
}

static void
cache_give(void *p, size_t cap)
{
    int slot = -1;
    for (int i = 0; i < CACHE_SLOTS && slot < 0; i++)
        if (!block_cache[i].p) slot = i;
    if (slot < 0) { /* full: the smallest of the cache's blocks and this one goes */
        slot = 0;
        for (int i = 1; i < CACHE_SLOTS; i++)
            if (block_cache[i].cap < block_cache[slot].cap) slot = i;
        if (block_cache[slot].cap >= cap) {
            free(p);
            return;
        }
        free(block_cache[slot].p);
    }
    block_cache[slot] = (cached_block){p, cap};
}

/* ---- the plan ----
 * Request i of a pass: its size, when it is taken and given back (in the order of the
 * pass's takes and gives; a request never given back outlives the pass), and its
 * offset in the arena (NOT_PLANNED for one that outlives the pass). A dry pass hands
 * out placeholder addresses, (i + 1) * PLACEHOLDER, which nothing may read or write:
 * the layers skip their work in a dry pass (mcp__unet_plan_dry). */
#define PLAN_MAX 64
#define NOT_PLANNED SIZE_MAX
#define PLACEHOLDER ((uintptr_t)4096)

typedef struct plan_request {
    size_t bytes, offset;
    int taken, given; /* event times; given -1: never */
} plan_request;

typedef struct plan_state {
    int recording; /* a dry pass */
    int count;     /* requests recorded (or planned) */
    int next;      /* the next request of the pass that runs */
    int clock;     /* takes and gives so far in this pass */
    int diverged;  /* this pass left the plan: the rest goes to the cache */
    int failed;    /* the dry pass asked for more than PLAN_MAX */
    char *arena;   /* NULL: no plan */
    size_t arena_bytes;
    plan_request req[PLAN_MAX];
    signed char given_at[2 * PLAN_MAX]; /* event time -> the request given then, or -1 */
} plan_state;

static _Thread_local plan_state plan;

int
mcp__unet_plan_dry(void)
{
    return plan.recording;
}

void
mcp__unet_plan_record(void)
{
    mcp__unet_plan_release();
    memset(plan.given_at, -1, sizeof plan.given_at);
    plan.recording = 1;
}

/* Lifetimes [taken, given) overlap; one never given lasts to the end. */
static int
alive_together(const plan_request *a, const plan_request *b)
{
    const int a_end = a->given < 0 ? INT32_MAX : a->given,
              b_end = b->given < 0 ? INT32_MAX : b->given;
    return a->taken < b_end && b->taken < a_end;
}

/* Places the requests that end within the pass, largest first, each at the lowest
 * offset where it overlaps no placed request alive at the same time. */
static size_t
place(plan_request *req, int count)
{
    int order[PLAN_MAX], placed = 0;
    size_t top = 0;
    for (int i = 0; i < count; i++)
        order[i] = i;
    for (int i = 1; i < count; i++) /* by size, descending; ties by time */
        for (int j = i; j > 0 && req[order[j]].bytes > req[order[j - 1]].bytes; j--) {
            const int t = order[j];
            order[j] = order[j - 1], order[j - 1] = t;
        }
    for (int k = 0; k < count; k++) {
        plan_request *r = &req[order[k]];
        r->offset = NOT_PLANNED;
        if (r->given < 0) continue;
        const size_t need = r->bytes;
        size_t at = 0;
        for (int moved = 1; moved;) { /* past every conflict, until none is left */
            moved = 0;
            for (int j = 0; j < placed; j++) {
                const plan_request *o = &req[order[j]];
                if (o->offset == NOT_PLANNED || !alive_together(r, o)) continue;
                const size_t o_end = o->offset + o->bytes;
                if (at < o_end && o->offset < at + need) at = o_end, moved = 1;
            }
        }
        r->offset = at;
        if (at + need > top) top = at + need;
        placed = k + 1;
    }
    return top;
}

int
mcp__unet_plan_finish(void)
{
    plan.recording = 0;
    mcp__unet_plan_pass();
    if (plan.failed || plan.count == 0) { /* unplanned: the cache serves */
        plan.count = 0;
        return 0;
    }
    /* whole huge pages: the offsets stay multiples of 2 MB */
    for (int i = 0; i < plan.count; i++)
        if (plan.req[i].given >= 0)
            plan.req[i].bytes =
                (plan.req[i].bytes + HUGE_PAGE - 1) / HUGE_PAGE * HUGE_PAGE;
    plan.arena_bytes = place(plan.req, plan.count);
    if (plan.arena_bytes == 0) {
        plan.count = 0;
        return 0;
    }
    if (!(plan.arena = mcp__unet_alloc(plan.arena_bytes))) {
        plan.count = 0;
        return -1;
    }
    return 0;
}

void
mcp__unet_plan_pass(void)
{
    plan.next = plan.clock = plan.diverged = 0;
}

void
mcp__unet_plan_release(void)
{
    free(plan.arena);
    memset(&plan, 0, sizeof plan);
}

const void *
mcp__unet_plan_arena(size_t *bytes)
{
    *bytes = plan.arena ? plan.arena_bytes : 0;
    return plan.arena;
}

static int
in_arena(const void *p)
{
    return plan.arena && (const char *)p >= plan.arena &&
           (const char *)p < plan.arena + plan.arena_bytes;
}

/* ---- taking and giving blocks ---- */

void *
mcp__unet_block_take(size_t bytes, size_t *cap)
{
    if (plan.recording) {
        if (plan.count >= PLAN_MAX || plan.clock >= 2 * PLAN_MAX) {
            plan.failed = 1;
            *cap = bytes;
            return (void *)(PLACEHOLDER * (PLAN_MAX + 1));
        }
        const int i = plan.count++;
        plan.req[i] = (plan_request){bytes, NOT_PLANNED, plan.clock++, -1};
        *cap = bytes;
        return (void *)(PLACEHOLDER * (uintptr_t)(i + 1));
    }
    if (plan.arena && !plan.diverged && plan.next < plan.count) {
        /* the pass must be the dry pass again, event for event: a take or give that
         * came at another time would let two live blocks share memory */
        const plan_request *r = &plan.req[plan.next++];
        if (r->taken == plan.clock++ && bytes <= r->bytes) {
            if (r->offset == NOT_PLANNED) return cache_take(bytes, cap);
            *cap = r->bytes;
            return plan.arena + r->offset;
        }
        plan.diverged = 1;
    }
    return cache_take(bytes, cap);
}

void
mcp__unet_block_give(void *p, size_t cap)
{
    if (!p) return;
    if (plan.recording) {
        const uintptr_t i = (uintptr_t)p / PLACEHOLDER - 1;
        if (i < (uintptr_t)plan.count && plan.clock < 2 * PLAN_MAX) {
            plan.given_at[plan.clock] = (signed char)i;
            plan.req[i].given = plan.clock++;
        } else {
            plan.failed = 1;
        }
        return;
    }
    if (plan.arena && !plan.diverged) {
        /* the block the dry pass gave back at this time, or the pass has left it */
        const int t = plan.clock++, i = t < 2 * PLAN_MAX ? plan.given_at[t] : -1;
        const plan_request *r = i >= 0 ? &plan.req[i] : NULL;
        const int expected =
            r && (r->offset == NOT_PLANNED ? !in_arena(p)
                                           : (const char *)p == plan.arena + r->offset);
        if (!expected) plan.diverged = 1;
    }
    if (in_arena(p)) return; /* its place is the plan's */
    cache_give(p, cap);
}
