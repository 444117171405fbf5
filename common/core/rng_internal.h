/* rng_internal.h: splitmix64 (Steele, Lea, Flood 2014), the one 64-bit mixer and
 * sequential generator behind every seeded stream in mcpost: estimate's probes, the
 * perceptual optimiser's per-pixel hashes, the procedural renderer, the tests' and
 * benchmarks' data (not installed). Header-only so that each caller inlines it in its
 * inner loops; changing a constant here changes every pinned random stream. */
#ifndef MCP_RNG_INTERNAL_H
#define MCP_RNG_INTERNAL_H

#include <stdint.h>

/* The Weyl increment: 2^64 over the golden ratio, odd. */
#define MCP__SPLITMIX64_GAMMA 0x9e3779b97f4a7c15ULL

/* splitmix64's finaliser: a bijection of 64-bit words with full avalanche, so hashes
 * of counters serve as independent random words. */
static inline uint64_t
mcp__mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

/* The next word of the sequential generator whose state is *state. */
static inline uint64_t
mcp__splitmix64_next(uint64_t *state)
{
    *state += MCP__SPLITMIX64_GAMMA;
    return mcp__mix64(*state);
}

#endif
