/* main.c: mcpost-procedural, the command line of the procedural renderer: renders
 * realizations (pbrt-v4 dumps), one-or-few-sample images and the exact truth. */
#include "procedural.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mcpost/imageio.h>

static const char USAGE[] =
    "usage: mcpost-procedural [options] -o OUT_PREFIX\n"
    "  --width W, --height H      image size [64 x 64]\n"
    "  --spp N                    samples per pixel of each realization [16]\n"
    "  --seed S                   64-bit seed [1]\n"
    "  --realizations K           independent renders [1] (0: none), written as\n"
    "                             OUT_PREFIX_0000.exr ...; number 0 uses S itself\n"
    "  --permutation MAP.exr      re-render pixel p with the seed of pixel (X, Y)\n"
    "                             of the map (channels X, Y)\n"
    "  --singles M                also write M images of --single-spp samples\n"
    "                             each (samples k*n .. k*n+n-1 of seed S's\n"
    "                             streams) as OUT_PREFIX_single_0000.exr ...\n"
    "  --single-spp N             samples per single image [1]\n"
    "  --sampler NAME             footprint sampler: independent [default] or\n"
    "                             jittered (stratified; --spp and --single-spp\n"
    "                             must then be multiples of K*K)\n"
    "  --strata K                 cells per side of the jittered sampler [4]\n"
    "  --truth                    also write the exact expectation, per-sample\n"
    "                             variance and variance of the --spp-sample mean\n"
    "                             under the sampler: OUT_PREFIX_truth.exr,\n"
    "                             OUT_PREFIX_truth_variance.exr and\n"
    "                             OUT_PREFIX_truth_var_of_mean.exr\n"
    "  --truth-order N            quadrature points per triangle side [8]\n"
    "  --firefly-probability P    chance of a firefly per ground sample [1e-3]\n"
    "  --firefly-value V          a firefly's brightness [100]\n"
    "  --sample-counts MAP.exr    an adaptive pass instead: pixel p gets MAP(p)\n"
    "                             samples (channel SampleCount), and -o names the\n"
    "                             one dump written (mcpost convention, with the\n"
    "                             per-pixel SampleCount); the image size is MAP's\n"
    "  --pass P                   the pass number: pass P uses sample indices\n"
    "                             P*2^32 ... of every pixel's stream, so passes\n"
    "                             never share samples [0]\n"
    "example (an adaptive loop's render command):\n"
    "  mcpost adaptive --size 128x128 -o out \\\n"
    "    --render 'mcpost-procedural --sample-counts {counts} --pass {pass} \\\n"
    "              --seed {seed} -o {output}'\n";

static int
fail(const char *what)
{
    fprintf(stderr, "mcpost-procedural: %s\n", what);
    return 1;
}

static int
parse_int(const char *flag, const char *s, int lo, int *out)
{
    char *end;
    errno = 0;
    long v = s ? strtol(s, &end, 10) : 0;
    if (!s || !*s || *end || errno || v < lo || v > 1 << 30)
        return mcp_error("%s must be an integer >= %d (got '%s')", flag, lo, s ? s : "");
    *out = (int)v;
    return 0;
}

static int
parse_double(const char *flag, const char *s, double *out)
{
    char *end;
    errno = 0;
    double v = s ? strtod(s, &end) : 0;
    if (!s || !*s || *end || errno || !isfinite(v))
        return mcp_error("%s must be a number (got '%s')", flag, s ? s : "");
    *out = v;
    return 0;
}

static int
parse_u64(const char *flag, const char *s, uint64_t *out)
{
    char *end;
    errno = 0;
    unsigned long long v = s ? strtoull(s, &end, 10) : 0;
    if (!s || !*s || *s == '-' || *end || errno)
        return mcp_error("%s must be an unsigned 64-bit integer (got '%s')", flag,
                         s ? s : "");
    *out = v;
    return 0;
}

/* The sampler names of --sampler, in the order of mcp_proc_sampler. */
static const char *const SAMPLERS[] = {"independent", "jittered"};

static int
parse_sampler(const char *flag, const char *s, mcp_proc_sampler *out)
{
    for (size_t i = 0; s && i < sizeof SAMPLERS / sizeof *SAMPLERS; i++)
        if (!strcmp(s, SAMPLERS[i])) {
            *out = (mcp_proc_sampler)i;
            return 0;
        }
    return mcp_error("%s must be independent or jittered (got '%s')", flag, s ? s : "");
}

typedef struct {
    mcp_proc_scene scene;
    int spp, realizations, singles, single_spp, truth, pass;
    uint64_t seed;
    const char *permutation, *prefix, *sample_counts;
} options;

static int
parse(int argc, char **argv, options *o)
{
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        int rc = 0, takes = 1;
        if (!strcmp(a, "--width"))
            rc = parse_int(a, v, 1, &o->scene.width);
        else if (!strcmp(a, "--height"))
            rc = parse_int(a, v, 1, &o->scene.height);
        else if (!strcmp(a, "--spp"))
            rc = parse_int(a, v, 1, &o->spp);
        else if (!strcmp(a, "--seed"))
            rc = parse_u64(a, v, &o->seed);
        else if (!strcmp(a, "--realizations"))
            rc = parse_int(a, v, 0, &o->realizations);
        else if (!strcmp(a, "--singles"))
            rc = parse_int(a, v, 0, &o->singles);
        else if (!strcmp(a, "--single-spp"))
            rc = parse_int(a, v, 1, &o->single_spp);
        else if (!strcmp(a, "--truth-order"))
            rc = parse_int(a, v, 1, &o->scene.truth_order);
        else if (!strcmp(a, "--firefly-probability"))
            rc = parse_double(a, v, &o->scene.firefly_probability);
        else if (!strcmp(a, "--sampler"))
            rc = parse_sampler(a, v, &o->scene.sampler);
        else if (!strcmp(a, "--strata"))
            rc = parse_int(a, v, 1, &o->scene.strata);
        else if (!strcmp(a, "--firefly-value"))
            rc = parse_double(a, v, &o->scene.firefly_value);
        else if (!strcmp(a, "--pass"))
            rc = parse_int(a, v, 0, &o->pass);
        else if (!strcmp(a, "--sample-counts") && v)
            o->sample_counts = v;
        else if (!strcmp(a, "--permutation") && v)
            o->permutation = v;
        else if ((!strcmp(a, "-o") || !strcmp(a, "--output")) && v)
            o->prefix = v;
        else if (!strcmp(a, "--truth"))
            o->truth = 1, takes = 0;
        else
            return mcp_error("unknown or incomplete option '%s' (see --help)", a);
        if (rc) return -1;
        i += takes;
    }
    if (!o->prefix) return mcp_error("no output prefix (-o OUT_PREFIX)");
    if (mcp_proc_scene_check(&o->scene)) return -1;
    /* The library refuses partial passes too, but only once some files are written. */
    int pass = o->scene.strata * o->scene.strata;
    if (!o->sample_counts && o->scene.sampler == MCP_PROC_SAMPLER_JITTERED &&
        o->spp % pass)
        return mcp_error("--spp must be a multiple of --strata^2 = %d with the jittered "
                         "sampler (got %d)",
                         pass, o->spp);
    if (o->scene.sampler == MCP_PROC_SAMPLER_JITTERED && o->singles > 0 &&
        o->single_spp % pass)
        return mcp_error("--single-spp must be a multiple of --strata^2 = %d with the "
                         "jittered sampler (got %d)",
                         pass, o->single_spp);
    return 0;
}

static int
write_singles(const options *o, const mcp_image *perm)
{
    mcp_image **img = mcp_calloc((size_t)o->singles, sizeof *img);
    if (!img) return -1;
    int rc =
        mcp_proc_render_samples(&o->scene, o->singles, o->single_spp, o->seed, perm, img);
    for (int k = 0; k < o->singles && !rc; k++) {
        char path[4096];
        snprintf(path, sizeof path, "%s_single_%04d.exr", o->prefix, k);
        rc = mcp_image_write(img[k], path, NULL);
    }
    for (int k = 0; k < o->singles; k++)
        mcp_image_free(img[k]);
    free(img);
    return rc;
}

static int
write_truth(const options *o)
{
    mcp_image *mean = NULL, *var = NULL, *var_of_mean = NULL;
    char path[4096], vpath[4096], mpath[4096];
    snprintf(path, sizeof path, "%s_truth.exr", o->prefix);
    snprintf(vpath, sizeof vpath, "%s_truth_variance.exr", o->prefix);
    snprintf(mpath, sizeof mpath, "%s_truth_var_of_mean.exr", o->prefix);
    int rc = mcp_proc_truth(&o->scene, &mean, &var) ||
             mcp_image_write(mean, path, NULL) || mcp_image_write(var, vpath, NULL) ||
             mcp_proc_truth_var_of_mean(&o->scene, o->spp, &var_of_mean) ||
             mcp_image_write(var_of_mean, mpath, NULL);
    mcp_image_free(mean);
    mcp_image_free(var);
    mcp_image_free(var_of_mean);
    return rc ? -1 : 0;
}

/* An adaptive pass: one dump with the map's per-pixel counts, at the map's size. */
static int
run_counts(options *o)
{
    mcp_image *counts = NULL;
    mcp_dump *d = NULL;
    if (mcp_image_read(o->sample_counts, NULL, &counts)) return -1;
    o->scene.width = counts->width;
    o->scene.height = counts->height;
    int rc = mcp_proc_render_counts(&o->scene, counts, o->pass, o->seed, &d) ||
             mcp_dump_write(d, o->prefix, MCP_CONV_MCPOST, NULL);
    mcp_dump_free(d);
    mcp_image_free(counts);
    return rc ? -1 : 0;
}

static int
run(const options *o)
{
    mcp_image *perm = NULL;
    int rc = -1;
    if (o->permutation && mcp_image_read(o->permutation, NULL, &perm)) return -1;
    for (int r = 0; r < o->realizations; r++) {
        mcp_dump *d = NULL;
        char path[4096];
        snprintf(path, sizeof path, "%s_%04d.exr", o->prefix, r);
        uint64_t seed = mcp_proc_realization_seed(o->seed, r);
        int bad = mcp_proc_render(&o->scene, o->spp, seed, perm, &d) ||
                  mcp_dump_write(d, path, MCP_CONV_PBRT, NULL);
        mcp_dump_free(d);
        if (bad) goto done;
    }
    if (o->singles > 0 && write_singles(o, perm)) goto done;
    if (o->truth && write_truth(o)) goto done;
    rc = 0;
done:
    mcp_image_free(perm);
    return rc;
}

int
main(int argc, char **argv)
{
    options o = {.scene = mcp_proc_scene_defaults(),
                 .spp = 16,
                 .realizations = 1,
                 .single_spp = 1,
                 .seed = 1};
    for (int i = 1; i < argc; i++)
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            fputs(USAGE, stdout);
            return 0;
        }
    if (parse(argc, argv, &o)) return fail(mcp_error_message());
    if (o.sample_counts ? run_counts(&o) : run(&o)) return fail(mcp_error_message());
    return 0;
}
