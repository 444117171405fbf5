/* series_colours.c: the colours of a series' members, kept for the increments.
 *
 * The variance from increments of member i adds the blocks of every member before it
 * (replicates.c), so a blend or series estimate of N checkpoints whose blocks all count
 * read about N²/2 dumps, and decoding them was half of its time (docs/benchmarks.md,
 * "Series members read once"). The increments read only a member's colour and sample
 * count, so those are kept here, up to a budget (SERIES_COLOURS_MB), and members are
 * read from their files once while they fit. The kept dump is the one the file gives
 * (without albedo, normal and variance), so the sums are the same bits.
 *
 * A member in use is counted (refs) and never dropped; past the budget a member of a
 * lower index not in use makes room for a higher one (make_room). The entries are keyed
 * by the member's index: a series whose paths or spec change after members were read must
 * not be used for the increments again (no caller does that). */
#include "internal.h"

#include <pthread.h>
#include <stdlib.h>

/* at 4K (3840x2160) 5 members' colours, at 1080p 20 */
#define SERIES_COLOURS_MB 512

typedef struct kept {
    mcp_dump *d; /* NULL: not kept */
    int refs;
    size_t bytes;
} kept;

struct mcp__series_colours {
    pthread_mutex_t lock;
    int count;
    kept *k; /* count */
    size_t bytes, budget;
};

int
mcp__series_colours_new(int count, mcp__series_colours **out)
{
    *out = NULL;
    mcp__series_colours *c = mcp_calloc(1, sizeof *c);
    if (!c) return -1;
    if (!(c->k = mcp_calloc((size_t)count, sizeof *c->k))) {
        free(c);
        return -1;
    }
    pthread_mutex_init(&c->lock, NULL);
    c->count = count;
    c->budget = (size_t)SERIES_COLOURS_MB << 20;
    *out = c;
    return 0;
}

void
mcp__series_colours_free(mcp__series_colours *c)
{
    if (!c) return;
    for (int i = 0; i < c->count; i++)
        mcp_dump_free(c->k[i].d);
    pthread_mutex_destroy(&c->lock);
    free(c->k);
    free(c);
}

void
mcp__series_colours_budget(const mcp_series *s, size_t bytes)
{
    if (s->colours) s->colours->budget = bytes;
}

/* Drops members below `index` not in use, lowest first, until `bytes` more fit; 0
 * when they do. A member is never dropped for a lower one: member i needs the members
 * from its first block's on, so the higher ones are needed longest, and a series
 * scanned from its start again (the next member's increments) would otherwise drop
 * each kept member before reaching it. Under the lock. */
static int
make_room(mcp__series_colours *c, int index, size_t bytes)
{
    for (int i = 0; i < index && c->bytes + bytes > c->budget; i++)
        if (c->k[i].d && c->k[i].refs == 0) {
            mcp_dump_free(c->k[i].d);
            c->k[i].d = NULL;
            c->bytes -= c->k[i].bytes;
        }
    return c->bytes + bytes <= c->budget ? 0 : -1;
}

int
mcp__series_colour(const mcp_series *s, int i, const mcp_dump **out)
{
    *out = NULL;
    mcp__series_colours *c = s->colours;
    if (c && i >= 0 && i < c->count) {
        pthread_mutex_lock(&c->lock);
        kept *k = &c->k[i];
        if (k->d) {
            k->refs++;
            *out = k->d;
        }
        pthread_mutex_unlock(&c->lock);
        if (*out) return 0;
    }
    mcp_dump *d = NULL;
    if (mcp__series_load_file(s, i, MCP__DUMP_NO_ALBEDO | MCP__DUMP_NO_NORMAL, &d))
        return -1;
    /* what the increments do not read */
    mcp_image_free(d->var_of_mean);
    mcp_image_free(d->cov_of_mean);
    d->var_of_mean = d->cov_of_mean = NULL;
    *out = d;
    if (!c || i < 0 || i >= c->count) return 0;
    const size_t bytes = (size_t)d->color->width * d->color->height *
                         (d->color->channels + (d->spp_map ? 1 : 0)) * sizeof(float);
    pthread_mutex_lock(&c->lock);
    kept *k = &c->k[i];
    if (!k->d && make_room(c, i, bytes) == 0) { /* else: another thread kept it first */
        k->d = d;
        k->refs = 1;
        k->bytes = bytes;
        c->bytes += bytes;
    }
    pthread_mutex_unlock(&c->lock);
    return 0;
}

void
mcp__series_colour_release(const mcp_series *s, const mcp_dump *d)
{
    if (!d) return;
    mcp__series_colours *c = s->colours;
    if (c) {
        pthread_mutex_lock(&c->lock);
        for (int i = 0; i < c->count; i++)
            if (c->k[i].d == d) {
                c->k[i].refs--;
                pthread_mutex_unlock(&c->lock);
                return;
            }
        pthread_mutex_unlock(&c->lock);
    }
    mcp_dump_free((mcp_dump *)d);
}
