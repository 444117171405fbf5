/* test_unet_memory.c: the U-Net's memory plan (estimate/unet_memory.c). Random
 * sequences of takes and gives are recorded in a dry pass and replayed for real; the
 * check is independent of the placement: at every moment, no two live blocks share a
 * byte, the arena is at least the most that is ever alive at once (and at most all of
 * it), blocks that outlive the pass stay out of the arena, and a replay that departs
 * from the dry pass leaves the arena from there on. Then the network's own plan: apply
 * and JVP with the plan give the same bits as without it. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../../estimate/unet_internal.h"
#include "testing.h"

#define MB ((size_t)1 << 20)
#define MAX_BLOCKS 40

typedef struct event {
    int take;  /* 1: take block `block`; 0: give it */
    int block; /* index in the order of takes */
} event;

typedef struct sequence {
    int n_events, n_blocks;
    event ev[2 * MAX_BLOCKS];
    size_t bytes[MAX_BLOCKS];
} sequence;

static uint64_t
next_random(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return *s >> 33;
}

/* Up to MAX_BLOCKS takes of 1-8 MB, a give of a random live block between them; some
 * blocks are never given (they outlive the pass). */
static void
random_sequence(uint64_t seed, sequence *q)
{
    uint64_t s = seed;
    int live[MAX_BLOCKS], n_live = 0;
    memset(q, 0, sizeof *q);
    const int blocks = 5 + (int)(next_random(&s) % (MAX_BLOCKS - 5));
    while (q->n_blocks < blocks) {
        if (n_live > 0 && next_random(&s) % 2) {
            const int k = (int)(next_random(&s) % n_live);
            if (next_random(&s) % 8 == 0) { /* this one outlives the pass */
                live[k] = live[--n_live];
                continue;
            }
            q->ev[q->n_events++] = (event){0, live[k]};
            live[k] = live[--n_live];
        } else {
            const int b = q->n_blocks++;
            q->bytes[b] = (1 + next_random(&s) % 8) * MB - next_random(&s) % 4096;
            q->ev[q->n_events++] = (event){1, b};
            live[n_live++] = b;
        }
    }
}

/* Replays q with the plan's take and give; ptr[b] receives each block's address. */
static void
replay(const sequence *q, void **ptr, size_t *cap)
{
    for (int i = 0; i < q->n_events; i++) {
        const event *e = &q->ev[i];
        if (e->take)
            ptr[e->block] = mcp__unet_block_take(q->bytes[e->block], &cap[e->block]);
        else
            mcp__unet_block_give(ptr[e->block], cap[e->block]);
    }
}

/* The plan of q from a dry pass; returns the arena's size. */
static size_t
plan_of(const sequence *q, void **ptr, size_t *cap)
{
    size_t arena_bytes;
    mcp__unet_plan_record();
    assert_int_equal(mcp__unet_plan_dry(), 1);
    replay(q, ptr, cap);
    assert_int_equal(mcp__unet_plan_finish(), 0);
    assert_int_equal(mcp__unet_plan_dry(), 0);
    mcp__unet_plan_arena(&arena_bytes);
    return arena_bytes;
}

static int
in_arena(const void *p, const char *arena, size_t bytes)
{
    return (const char *)p >= arena && (const char *)p < arena + bytes;
}

/* At every take, the new block overlaps no live block, and every block is at least
 * its size; returns the most bytes alive at once among the blocks given back. */
static size_t
check_no_overlap(const sequence *q, void *const *ptr, const size_t *cap)
{
    int live[MAX_BLOCKS] = {0}, given[MAX_BLOCKS] = {0};
    size_t peak = 0;
    for (int i = 0; i < q->n_events; i++)
        if (!q->ev[i].take) given[q->ev[i].block] = 1;
    for (int i = 0; i < q->n_events; i++) {
        const event *e = &q->ev[i];
        if (!e->take) {
            live[e->block] = 0;
            continue;
        }
        const char *a = ptr[e->block];
        assert_non_null(a);
        assert_true(cap[e->block] >= q->bytes[e->block]);
        for (int b = 0; b < q->n_blocks; b++) {
            if (!live[b]) continue;
            const char *o = ptr[b];
            assert_false(a < o + q->bytes[b] && o < a + q->bytes[e->block]);
        }
        live[e->block] = 1;
        size_t sum = 0; /* the planned blocks alive now, at the plan's 2 MB grain */
        for (int b = 0; b < q->n_blocks; b++)
            if (live[b] && given[b])
                sum += (q->bytes[b] + 2 * MB - 1) / (2 * MB) * (2 * MB);
        if (sum > peak) peak = sum;
    }
    return peak;
}

static void
test_random_plans(void **state)
{
    (void)state;
    for (uint64_t seed = 1; seed <= 300; seed++) {
        sequence q;
        void *ptr[MAX_BLOCKS];
        size_t cap[MAX_BLOCKS], total = 0, arena_bytes;
        int given[MAX_BLOCKS] = {0};
        random_sequence(seed, &q);
        for (int i = 0; i < q.n_events; i++)
            if (!q.ev[i].take) {
                given[q.ev[i].block] = 1;
                total += (q.bytes[q.ev[i].block] + 2 * MB - 1) / (2 * MB) * (2 * MB);
            }
        plan_of(&q, ptr, cap);
        const char *arena = mcp__unet_plan_arena(&arena_bytes);
        for (int pass = 0; pass < 2; pass++) { /* as the primal's and a tangent's */
            mcp__unet_plan_pass();
            replay(&q, ptr, cap);
            const size_t peak = check_no_overlap(&q, ptr, cap);
            assert_true(arena_bytes >= peak);
            assert_true(arena_bytes <= total);
            /* the blocks given back came from the arena, the others did not */
            for (int b = 0; b < q.n_blocks; b++) {
                assert_int_equal(in_arena(ptr[b], arena, arena_bytes), given[b]);
                if (given[b])
                    assert_true((const char *)ptr[b] + q.bytes[b] <= arena + arena_bytes);
                else
                    mcp__unet_block_give(ptr[b], cap[b]);
            }
        }
        mcp__unet_plan_release();
        mcp__unet_blocks_drain();
    }
}

/* The U-Net's pattern: two full-resolution blocks early (in, out), then smaller
 * levels, then a 64-channel and a 32-channel one together at the end. The plan needs
 * the most alive at once (the last two), where the cache held more. */
static void
test_network_shape(void **state)
{
    (void)state;
    const size_t c1 = 4 * MB; /* a channel */
    sequence q = {0};
    const size_t sizes[] = {9 * c1,  32 * c1, 32 * c1, 8 * c1, 12 * c1,
                            16 * c1, 64 * c1, 32 * c1, 3 * c1};
    for (int b = 0; b < 9; b++)
        q.bytes[b] = sizes[b];
    q.n_blocks = 9;
    const event ev[] = {{1, 0}, {1, 1}, {1, 2}, {0, 1}, {1, 3}, {0, 2},
                        {1, 4}, {1, 5}, {0, 4}, {1, 6}, {0, 5}, {0, 0},
                        {0, 3}, {1, 7}, {0, 6}, {1, 8}, {0, 7}};
    q.n_events = (int)(sizeof ev / sizeof ev[0]);
    memcpy(q.ev, ev, sizeof ev);
    void *ptr[MAX_BLOCKS];
    size_t cap[MAX_BLOCKS];
    /* the most alive at once: 9 + 8 + 16 + 64 channels (blocks 0, 3, 5 and 6) */
    assert_int_equal(plan_of(&q, ptr, cap), 97 * c1);
    mcp__unet_plan_pass();
    replay(&q, ptr, cap);
    check_no_overlap(&q, ptr, cap);
    mcp__unet_block_give(ptr[8], cap[8]); /* the output outlives the pass */
    mcp__unet_plan_release();
    mcp__unet_blocks_drain();
}

/* A pass that gives a block back at another time than the dry one leaves the plan:
 * the later takes come from outside the arena and nothing live is shared. */
static void
test_diverging_pass(void **state)
{
    (void)state;
    sequence q = {0}, r;
    q.n_blocks = 3;
    q.bytes[0] = q.bytes[1] = q.bytes[2] = 4 * MB;
    const event ev[] = {{1, 0}, {1, 1}, {0, 0}, {1, 2}, {0, 1}, {0, 2}};
    memcpy(q.ev, ev, sizeof ev);
    q.n_events = 6;
    r = q; /* gives block 1 back where the dry pass gave block 0 */
    r.ev[2] = (event){0, 1};
    r.ev[4] = (event){0, 0};
    void *ptr[MAX_BLOCKS];
    size_t cap[MAX_BLOCKS];
    assert_int_equal(plan_of(&q, ptr, cap), 8 * MB); /* block 2 on block 0 */
    mcp__unet_plan_pass();
    replay(&r, ptr, cap);
    check_no_overlap(&r, ptr, cap);
    assert_ptr_not_equal(ptr[2], ptr[0]);
    mcp__unet_plan_release();
    mcp__unet_blocks_drain();
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_random_plans),
        cmocka_unit_test(test_network_shape),
        cmocka_unit_test(test_diverging_pass),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
