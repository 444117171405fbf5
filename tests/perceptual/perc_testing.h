/* perc_testing.h: inputs for the perceptual tests -- procedural-scene candidates with
 * their exact truth, the rendered fixtures (skipped when absent), a candidate check --
 * as static inline helpers (tests/CMakeLists.txt builds each test file alone). */
#ifndef PERC_TESTING_H
#define PERC_TESTING_H

#include "testing.h"

#include "procedural.h"

#include <mcpost/dump.h>
#include <mcpost/imageio.h>
#include <mcpost/metrics.h>
#include <mcpost/perceptual.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define PERC_MAX_M 16

/* m candidates of the procedural scene (size x size, spp samples each, one seed) and
 * the exact truth. */
typedef struct {
    int m;
    mcp_image *cand[PERC_MAX_M];
    mcp_image *truth;
    mcp_image *albedo, *normal; /* fixtures: the singles' mean features (else NULL) */
} perc_case;

static inline void
perc_case_free(perc_case *c)
{
    for (int j = 0; j < c->m; j++)
        mcp_image_free(c->cand[j]);
    mcp_image_free(c->truth);
    mcp_image_free(c->albedo);
    mcp_image_free(c->normal);
    memset(c, 0, sizeof *c);
}

static inline void
perc_procedural(int size, int m, int spp, uint64_t seed, int fireflies, perc_case *c)
{
    memset(c, 0, sizeof *c);
    mcp_proc_scene s = mcp_proc_scene_defaults();
    s.width = s.height = size;
    if (!fireflies) s.firefly_probability = 0.0;
    c->m = m;
    if (mcp_proc_render_samples(&s, m, spp, seed, NULL, c->cand) ||
        mcp_proc_truth(&s, &c->truth, NULL))
        fail_msg("procedural: %s", mcp_error_message());
}

static inline const mcp_image *const *
perc_cands(const perc_case *c)
{
    return (const mcp_image *const *)c->cand;
}

/* The fixture singles of `scene` grouped: candidate j is the mean of singles
 * [j*group, (j+1)*group). Returns 0, or 1 (with a message) when the fixture is not
 * there yet. */
static inline int
perc_fixture(const char *scene, int m, int group, perc_case *c)
{
    char path[4096];
    struct stat st;
    memset(c, 0, sizeof *c);
    snprintf(path, sizeof path, "%s/samples/fixtures/%s/%s_reference.exr",
             MCP_TEST_SOURCE_DIR, scene, scene);
    if (stat(path, &st) != 0) {
        print_message("fixture %s: %s is absent; skipped\n", scene, path);
        return 1;
    }
    for (int k = 0; k < m * group; k++) {
        snprintf(path, sizeof path, "%s/samples/fixtures/%s/singles/%s_single%02d.exr",
                 MCP_TEST_SOURCE_DIR, scene, scene, k);
        if (stat(path, &st) != 0) {
            print_message("fixture %s: %s is absent; skipped\n", scene, path);
            perc_case_free(c);
            return 1;
        }
    }
    snprintf(path, sizeof path, "%s/samples/fixtures/%s/%s_reference.exr",
             MCP_TEST_SOURCE_DIR, scene, scene);
    mcp_image *ref = NULL;
    if (mcp_image_read(path, NULL, &ref)) fail_msg("%s", mcp_error_message());
    c->m = m;
    mcp_image *albedo[PERC_MAX_M * PERC_MAX_M], *normal[PERC_MAX_M * PERC_MAX_M];
    for (int j = 0; j < m; j++) {
        mcp_image *group_imgs[PERC_MAX_M];
        for (int k = 0; k < group; k++) {
            mcp_dump *d = NULL;
            snprintf(path, sizeof path,
                     "%s/samples/fixtures/%s/singles/%s_single%02d.exr",
                     MCP_TEST_SOURCE_DIR, scene, scene, j * group + k);
            if (mcp_image_read(path, NULL, &group_imgs[k]) ||
                mcp_dump_from_image(group_imgs[k], NULL, &d) || !d->albedo ||
                !d->normal || mcp_image_copy(d->albedo, &albedo[j * group + k]) ||
                mcp_image_copy(d->normal, &normal[j * group + k]))
                fail_msg("%s: %s", path, mcp_error_message());
            mcp_dump_free(d);
        }
        if (mcp_perc_mean((const mcp_image *const *)group_imgs, group, &c->cand[j]))
            fail_msg("%s", mcp_error_message());
        for (int k = 0; k < group; k++)
            mcp_image_free(group_imgs[k]);
    }
    if (mcp_perc_mean((const mcp_image *const *)albedo, m * group, &c->albedo) ||
        mcp_perc_mean((const mcp_image *const *)normal, m * group, &c->normal))
        fail_msg("%s", mcp_error_message());
    for (int k = 0; k < m * group; k++) {
        mcp_image_free(albedo[k]);
        mcp_image_free(normal[k]);
    }
    int rgb[3];
    if (mcp_rgb_channels(ref, rgb) || mcp_image_copy_channels(ref, rgb, 3, &c->truth))
        fail_msg("%s", mcp_error_message());
    mcp_image_free(ref);
    return 0;
}

static inline double
perc_pmse(const mcp_image *img, const mcp_image *truth)
{
    double v;
    if (mcp_pmse(img, truth, NULL, &v)) fail_msg("pmse: %s", mcp_error_message());
    return v;
}

static inline double
perc_mean_pmse(const perc_case *c)
{
    mcp_image *mean = NULL;
    if (mcp_perc_mean(perc_cands(c), c->m, &mean)) fail_msg("%s", mcp_error_message());
    double v = perc_pmse(mean, c->truth);
    mcp_image_free(mean);
    return v;
}

/* Every pixel of img equals (bit for bit, RGB) candidate index(p) at p. */
static inline void
perc_assert_from_candidates(const mcp_image *img, const mcp_image *index,
                            const mcp_image *const *cands, int m)
{
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++) {
            float k = mcp_image_px(index, x, y)[0];
            assert_true(k >= 0.0f && k < (float)m && k == (float)(int)k);
            const float *o = mcp_image_px(img, x, y),
                        *q = mcp_image_px(cands[(int)k], x, y);
            int rgb[3];
            assert_int_equal(mcp_rgb_channels(cands[(int)k], rgb), 0);
            for (int c = 0; c < 3; c++)
                if (memcmp(&o[c], &q[rgb[c]], sizeof(float)) != 0)
                    fail_msg("pixel %d, %d channel %d: %g is not candidate %d's %g", x, y,
                             c, o[c], (int)k, q[rgb[c]]);
        }
}

#endif
