/* fastpow.h: x^y for x >= 0 in plain, branch-free float arithmetic, so that loops
 * calling it vectorise (libm's powf is a call per value: it was 30% of an HDR-FLIP
 * run). mcp__powf_pos(x, y) = 2^(y log2 x):
 *
 *   log2 x: x = 2^e m with m in [sqrt(1/2), sqrt(2)); log m = 2 atanh(f) with
 *           f = (m - 1) / (m + 1), |f| <= 0.1716, summed to f^9 (the next term is
 *           below 1e-9 of the result);
 *   2^z:    z = n + r with n = rint(z), |r| <= 1/2; 2^r = e^(r ln 2) by its Taylor
 *           series to degree 7 (remainder below 6e-9), and n added to the exponent.
 *
 * The relative error is below (1 + |y log2 x|) * 1.5e-7, a few float roundings
 * (tests/common/test_fastpow.c checks it against double pow over 2^-60 .. 2^60).
 * Edges as powf has them for x >= 0: 0^y is 0 for y > 0, 1 for y = 0 and +Inf for
 * y < 0; results below about 2^-125 are flushed to 0 and above about 2^127.5 are
 * +Inf. x must not
 * be negative or NaN (the callers' values are sums of squares and clamped colours). */
#ifndef MCP_FASTPOW_H
#define MCP_FASTPOW_H

#include <math.h>
#include <stdint.h>
#include <string.h>

/* inlined even into the AVX2 clones of their callers, so that their loops vectorise */
#define MCP_ALWAYS_INLINE __attribute__((always_inline))

static inline MCP_ALWAYS_INLINE float
mcp__log2_pos(float x)
{
    /* a denormal x is scaled by 2^24 into the normal range first */
    int32_t denormal = x < 1.17549435e-38f;
    x = denormal ? x * 16777216.0f : x;
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    /* exponent and mantissa, the mantissa moved into [sqrt(1/2), sqrt(2)) */
    int32_t e = (int32_t)(u >> 23) - 127 - (denormal ? 24 : 0);
    uint32_t mu = (u & 0x007fffffu) | 0x3f800000u;
    float m;
    memcpy(&m, &mu, sizeof m);
    int32_t big = m > 1.41421356f;
    m = big ? 0.5f * m : m;
    e += big;
    float f = (m - 1.0f) / (m + 1.0f), f2 = f * f;
    float s = 1.0f / 9.0f;
    s = s * f2 + 1.0f / 7.0f;
    s = s * f2 + 1.0f / 5.0f;
    s = s * f2 + 1.0f / 3.0f;
    s = s * f2 + 1.0f;
    /* log2 m = 2 f s / ln 2 */
    return (float)e + f * s * 2.88539008f;
}

static inline MCP_ALWAYS_INLINE float
mcp__exp2_clamped(float z)
{
    z = z < -126.0f ? -127.0f : z; /* -127 marks "flush to 0" below */
    z = z > 128.0f ? 128.0f : z;
    /* round to nearest by adding and taking away 1.5 * 2^23 (|z| <= 128), which
       vectorises without SSE4.1's round instruction */
    float n = (z + 12582912.0f) - 12582912.0f, r = (z - n) * 0.693147181f;
    float p = 1.0f / 5040.0f;
    p = p * r + 1.0f / 720.0f;
    p = p * r + 1.0f / 120.0f;
    p = p * r + 1.0f / 24.0f;
    p = p * r + 1.0f / 6.0f;
    p = p * r + 0.5f;
    p = p * r + 1.0f;
    p = p * r + 1.0f;
    /* p in [0.70, 1.42]: 2^n p, n in [-125, 127] added to the exponent field (2^n p
       stays normal); n = 128 comes out as +Inf, smaller n as 0 */
    int32_t ni = (int32_t)n;
    int32_t in_range = (ni > -126) & (ni < 128); /* & not &&: no branch */
    uint32_t pu;
    memcpy(&pu, &p, sizeof pu);
    pu += (uint32_t)(in_range ? ni : 0) << 23;
    float scaled;
    memcpy(&scaled, &pu, sizeof scaled);
    return in_range ? scaled : ni >= 128 ? INFINITY : 0.0f;
}

static inline MCP_ALWAYS_INLINE float
mcp__powf_pos(float x, float y)
{
    float v = mcp__exp2_clamped(y * mcp__log2_pos(x > 0.0f ? x : 1.0f));
    float at_zero = y > 0.0f ? 0.0f : y == 0.0f ? 1.0f : INFINITY;
    return x > 0.0f ? v : at_zero;
}

#endif
