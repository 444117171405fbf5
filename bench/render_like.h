/* render_like.h: the synthetic render-like input of the denoiser benchmarks
 * (bench_denoise.c, bench_unet.c; header-only: each bench is one executable built from
 * one file). */
#ifndef MCP_BENCH_RENDER_LIKE_H
#define MCP_BENCH_RENDER_LIKE_H

#include <mcpost/image.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

/* splitmix64 -> uniform in [0, 1) */
static inline double
bench_uniform(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return (double)((z ^ (z >> 31)) >> 11) / 9007199254740992.0;
}

/* A side x side R,G,B image; exits with a message on failure. */
static inline mcp_image *
bench_rgb(int side)
{
    static const char *const names[] = {"R", "G", "B"};
    mcp_image *img = NULL;
    if (mcp_image_new(side, side, 3, names, &img)) {
        fprintf(stderr, "bench: %s\n", mcp_error_message());
        exit(1);
    }
    return img;
}

/* Albedo cells of 16 px, a smooth light, noise of 20 % with its variance given, and
 * the normals of two planes. */
static inline void
bench_render_like(int side, mcp_image **color, mcp_image **albedo, mcp_image **normal,
                  mcp_image **variance)
{
    *color = bench_rgb(side), *albedo = bench_rgb(side), *normal = bench_rgb(side),
    *variance = bench_rgb(side);
    uint64_t st = 1;
    for (int y = 0; y < side; y++)
        for (int x = 0; x < side; x++) {
            size_t i = ((size_t)y * side + x) * 3;
            int cell = (x / 16 + y / 16) % 3;
            for (int c = 0; c < 3; c++) {
                double a = 0.2 + 0.3 * ((cell + c) % 3), t = a * (1 + 0.5 * sin(0.01 * x));
                double sd = 0.2 * t,
                       u = bench_uniform(&st) + bench_uniform(&st) + bench_uniform(&st) - 1.5;
                (*albedo)->data[i + c] = (float)a;
                (*normal)->data[i + c] = (float)(c == (y < side / 3 ? 2 : 1));
                (*variance)->data[i + c] = (float)(sd * sd);
                (*color)->data[i + c] = (float)(t + 2 * sd * u);
            }
        }
}

#endif
