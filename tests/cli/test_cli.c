/* test_cli.c: the mcpost executable -- info on pbrt-v4, Mitsuba 3 and Blender files,
 * convert, run, the one-line error with a non-zero exit for every bad-input class, and
 * the denoiser flags every denoising subcommand shares. */
#include "testing.h"

#include <cjson/cJSON.h>
#include <mcpost/denoiser.h>
#include <mcpost/dump.h>
#include <mcpost/flip.h>
#include <mcpost/imageio.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static char out[1 << 16], err[1 << 16];

#define run(...) mcp_test_run_mcpostf(out, sizeof out, err, sizeof err, __VA_ARGS__)

/* The failure contract: non-zero exit, exactly one stderr line "mcpost: ...needle...". */
static void
assert_one_line_error(int status, const char *needle)
{
    if (status == 0 || strncmp(err, "mcpost: ", 8) != 0 || !strstr(err, needle) ||
        strchr(err, '\n') != err + strlen(err) - 1)
        fail_msg("status %d, stderr \"%s\", wanted one line with \"%s\"", status, err,
                 needle);
}

static mcp_dump *
sample_dump(void)
{
    mcp_dump *d = calloc(1, sizeof *d);
    d->color = mcp_test_random(16, 8, 3, 0.0f, 2.0f, 1, (const char *[]){"R", "G", "B"});
    d->var_of_mean =
        mcp_test_random(16, 8, 3, 0.0f, 0.1f, 2, (const char *[]){"R", "G", "B"});
    d->albedo = mcp_test_random(16, 8, 3, 0.0f, 1.0f, 3, (const char *[]){"R", "G", "B"});
    d->normal =
        mcp_test_random(16, 8, 3, -1.0f, 1.0f, 4, (const char *[]){"X", "Y", "Z"});
    d->spp = 128;
    d->source = strdup("sample");
    return d;
}

static void
test_info_describes_each_renderer(void **state)
{
    (void)state;
    mcp_dump *d = sample_dump();
    struct {
        mcp_convention conv;
        const char *file, *convention, *samples, *channel;
    } cases[] = {
        {MCP_CONV_PBRT, "pbrt.exr", "convention:  pbrt", "samples:     128 per pixel",
         "Variance.R"},
        {MCP_CONV_MITSUBA, "mitsuba.exr", "convention:  mitsuba", "samples:     unknown",
         "m2_R"},
        {MCP_CONV_BLENDER, "blender.exr", "convention:  blender",
         "samples:     128 per pixel", "ViewLayer.Denoising Albedo.G"},
    };
    for (int i = 0; i < 3; i++) {
        const char *path = mcp_test_path(cases[i].file);
        assert_int_equal(mcp_dump_write(d, path, cases[i].conv, NULL), 0);
        assert_int_equal(run("info '%s'", path), 0);
        assert_non_null(strstr(out, cases[i].convention));
        assert_non_null(strstr(out, cases[i].samples));
        assert_non_null(strstr(out, cases[i].channel));
        assert_non_null(strstr(out, "size:        16x8"));
    }
    /* Mitsuba 3's moment integrator layout: the convention and the variance source */
    {
        const char *names[] = {"R",           "G",           "B",           "A",
                               "m2_nested.X", "m2_nested.Y", "m2_nested.Z", "nested.X",
                               "nested.Y",    "nested.Z"};
        mcp_image *img = NULL;
        assert_int_equal(mcp_image_new(4, 2, 10, names, &img), 0);
        for (int i = 0; i < 4 * 2 * 10; i++)
            img->data[i] = i % 10 >= 4 && i % 10 < 7 ? 1.0f : 0.5f;
        const char *path = mcp_test_path("mitsuba3.exr");
        assert_int_equal(mcp_image_write(img, path, NULL), 0);
        mcp_image_free(img);
        assert_int_equal(run("info --spp 16 '%s'", path), 0);
        assert_non_null(strstr(out, "convention:  mitsuba"));
        assert_non_null(strstr(out, "Mitsuba's XYZ moments"));
        assert_int_equal(run("info --json --spp 16 '%s'", path), 0);
        assert_non_null(strstr(out, "\"xyz-moments\""));
        assert_int_equal(run("info --json '%s'", path), 0); /* no count: says why */
        assert_non_null(strstr(out, "Mitsuba writes no sample count"));
    }
    /* Mitsuba has no count in the file: --spp gives it */
    assert_int_equal(run("info --spp 128 '%s'", mcp_test_path("mitsuba.exr")), 0);
    assert_non_null(strstr(out, "samples:     128 per pixel"));
    /* JSON: the statistics are exact */
    assert_int_equal(run("info --json '%s'", mcp_test_path("pbrt.exr")), 0);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    assert_true(cJSON_GetObjectItem(j, "spp")->valuedouble == 128);
    double mean = 0;
    for (int i = 0; i < 16 * 8; i++)
        mean += d->color->data[i * 3];
    const cJSON *ch;
    cJSON_ArrayForEach(ch, cJSON_GetObjectItem(j, "channels"))
    {
        if (!strcmp(cJSON_GetObjectItem(ch, "name")->valuestring, "R"))
            assert_close(cJSON_GetObjectItem(ch, "mean")->valuedouble, mean / 128, 1e-12,
                         0);
    }
    cJSON_Delete(j);
    mcp_dump_free(d);
}

static void
test_info_counts_bad_values(void **state)
{
    (void)state;
    mcp_image *img = mcp_test_constant(4, 4, 3, 1, (const char *[]){"R", "G", "B"});
    img->data[0] = NAN;
    img->data[3] = INFINITY;
    img->data[6] = -2;
    assert_int_equal(mcp_image_write(img, mcp_test_path("nan.exr"), NULL), 0);
    assert_int_equal(run("info --json '%s'", mcp_test_path("nan.exr")), 0);
    cJSON *j = cJSON_Parse(out);
    /* the file lists B, G, R; read back, colour comes first (docs/conventions.md) */
    const cJSON *r = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "channels"), 0);
    assert_string_equal(cJSON_GetObjectItem(r, "name")->valuestring, "R");
    assert_true(cJSON_GetObjectItem(r, "nan")->valuedouble == 1);
    assert_true(cJSON_GetObjectItem(r, "inf")->valuedouble == 1);
    assert_true(cJSON_GetObjectItem(r, "negative")->valuedouble == 1);
    cJSON_Delete(j);
    mcp_image_free(img);
}

static void
test_convert(void **state)
{
    (void)state;
    mcp_dump *d = sample_dump();
    assert_int_equal(mcp_dump_write(d, mcp_test_path("c.exr"), MCP_CONV_PBRT, NULL), 0);
    assert_int_equal(run("convert '%s' '%s' --channels B,R --half --compression piz",
                         mcp_test_path("c.exr"), mcp_test_path("br.exr")),
                     0);
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_read(mcp_test_path("br.exr"), NULL, &img), 0);
    assert_int_equal(img->channels, 2);
    mcp_image_free(img);
    /* a dump rewritten in Blender's convention keeps its meaning */
    assert_int_equal(run("convert --dump blender '%s' '%s'", mcp_test_path("c.exr"),
                         mcp_test_path("b.exr")),
                     0);
    mcp_dump *back = NULL;
    assert_int_equal(mcp_dump_read(mcp_test_path("b.exr"), &back), 0);
    assert_int_equal(back->convention, MCP_CONV_BLENDER);
    assert_close(back->var_of_mean->data[7], d->var_of_mean->data[7], 1e-6, 0);
    mcp_dump_free(back);
    mcp_dump_free(d);
}

static void
test_every_bad_input_class(void **state)
{
    (void)state;
    mcp_dump *d = sample_dump();
    char good[4096]; /* mcp_test_path's buffers rotate: keep a copy */
    snprintf(good, sizeof good, "%s", mcp_test_path("good.exr"));
    assert_int_equal(mcp_dump_write(d, good, MCP_CONV_PBRT, NULL), 0);
    /* missing or misnamed channel */
    assert_one_line_error(
        run("convert '%s' '%s' --channels R,Q", good, mcp_test_path("q.exr")),
        "good.exr: no channel 'Q'");
    /* unreadable, corrupt, truncated */
    assert_one_line_error(run("info '%s'", mcp_test_path("nothing.exr")),
                          "nothing.exr: cannot open");
    mcp_test_write_text(mcp_test_path("junk.exr"), "not an exr");
    assert_one_line_error(run("info '%s'", mcp_test_path("junk.exr")), "junk.exr");
    char *bytes = mcp_test_read_text(good);
    FILE *f = fopen(mcp_test_path("cut.exr"), "wb");
    fwrite(bytes, 1, 600, f);
    fclose(f);
    free(bytes);
    assert_one_line_error(run("info '%s'", mcp_test_path("cut.exr")), "cut.exr");
    /* NaN in colour, negative variance */
    mcp_image *img = NULL;
    if (mcp_image_read(good, NULL, &img)) fail_msg("%s", mcp_error_message());
    int r = mcp_image_channel(img, "R"), vg = mcp_image_channel(img, "Variance.G");
    mcp_image_px(img, 3, 2)[r] = NAN;
    assert_int_equal(mcp_image_write(img, mcp_test_path("nan.exr"), NULL), 0);
    assert_one_line_error(
        run("convert --dump pbrt '%s' '%s'", mcp_test_path("nan.exr"),
            mcp_test_path("o.exr")),
        "nan.exr: colour channel 'R' has 1 NaN/Inf value (first nan at pixel 3,2");
    mcp_image_px(img, 3, 2)[r] = 1;
    mcp_image_px(img, 5, 1)[vg] = -1;
    assert_int_equal(mcp_image_write(img, mcp_test_path("neg.exr"), NULL), 0);
    assert_one_line_error(run("convert --dump pbrt '%s' '%s'", mcp_test_path("neg.exr"),
                              mcp_test_path("o.exr")),
                          "neg.exr: variance channel 'G' has 1 negative value");
    /* zero sample count */
    mcp_image_px(img, 5, 1)[vg] = 1;
    mcp_attrs_set_int(&img->attrs, "samplesPerPixel", 0);
    assert_int_equal(mcp_image_write(img, mcp_test_path("zero.exr"), NULL), 0);
    assert_one_line_error(run("convert --dump mcpost '%s' '%s'",
                              mcp_test_path("zero.exr"), mcp_test_path("o.exr")),
                          "zero.exr: no sample count");
    assert_int_equal(access(mcp_test_path("o.exr"), F_OK), -1);
    mcp_image_free(img);
    /* mismatched sizes between dump parts (job file: a separate albedo) */
    mcp_image *small = mcp_test_constant(5, 5, 3, 1, (const char *[]){"R", "G", "B"});
    assert_int_equal(mcp_image_write(small, mcp_test_path("small.exr"), NULL), 0);
    mcp_image_free(small);
    mcp_test_write_text(mcp_test_path("size.yaml"),
                        "inputs:\n  d: {dump: good.exr, albedo_file: small.exr}\n"
                        "stages:\n  - info: {input: d}\n");
    assert_one_line_error(run("run -q '%s'", mcp_test_path("size.yaml")),
                          "small.exr: size 5x5 does not match");
    /* unwritable output */
    assert_one_line_error(run("convert '%s' /nonexistent-dir/o.exr", good),
                          "/nonexistent-dir/o.exr: cannot write");
    /* an output that is an input is refused, however it is spelled, and the input
       stays as it was (a dump denoised onto itself lost its 12 channels) */
    {
        mcp_image *before = NULL, *after = NULL;
        assert_int_equal(mcp_image_read(good, NULL, &before), 0);
        char same[4200];
        snprintf(same, sizeof same, "%s/good.exr",
                 mcp_test_path(".")); /* dir/./good.exr */
        assert_one_line_error(run("denoise '%s' --denoiser gauss -o '%s'", good, same),
                              "denoise: the output");
        assert_one_line_error(run("convert '%s' '%s'", good, good), "is the input");
        assert_one_line_error(run("merge '%s' '%s' -o '%s'", good, good, good),
                              "merge: the output");
        assert_int_equal(mcp_image_read(good, NULL, &after), 0);
        assert_int_equal(after->channels, before->channels);
        assert_true(mcp_test_max_abs_diff(after, before) == 0);
        /* denoise keeps the input's header attributes beside its own */
        mcp_image *den = NULL;
        assert_int_equal(run("denoise '%s' --denoiser gauss -o '%s'", good,
                             mcp_test_path("den_attrs.exr")),
                         0);
        assert_int_equal(mcp_image_read(mcp_test_path("den_attrs.exr"), NULL, &den), 0);
        assert_non_null(mcp_attrs_find(&den->attrs, "mcpost.denoiser"));
        for (int a = 0; a < before->attrs.count; a++)
            if (strcmp(before->attrs.items[a].name, "channels") != 0)
                assert_non_null(mcp_attrs_find(&den->attrs, before->attrs.items[a].name));
        mcp_image_free(den);
        /* so does convert, as an image and as a dump in another convention: a
           renderer's string, a camera's double and the sample count, value for value */
        mcp_image *tagged = NULL;
        assert_int_equal(mcp_image_read(good, NULL, &tagged), 0);
        assert_int_equal(mcp_attrs_set_string(&tagged->attrs, "renderer", "Cycles 3.4"),
                         0);
        assert_int_equal(mcp_attrs_set_double(&tagged->attrs, "camera.fov", 39.6), 0);
        char tagged_path[4200];
        snprintf(tagged_path, sizeof tagged_path, "%s", mcp_test_path("tagged.exr"));
        assert_int_equal(mcp_image_write(tagged, tagged_path, NULL), 0);
        mcp_image_free(tagged);
        const char *how[2] = {"", " --dump mcpost"};
        for (int k = 0; k < 2; k++) {
            mcp_image *conv = NULL;
            assert_int_equal(run("convert '%s' '%s'%s", tagged_path,
                                 mcp_test_path("conv_attrs.exr"), how[k]),
                             0);
            assert_int_equal(mcp_image_read(mcp_test_path("conv_attrs.exr"), NULL, &conv),
                             0);
            const mcp_attr *r = mcp_attrs_find(&conv->attrs, "renderer"),
                           *fov = mcp_attrs_find(&conv->attrs, "camera.fov"),
                           *spp = mcp_attrs_find(&conv->attrs, "samplesPerPixel");
            assert_non_null(r), assert_non_null(fov), assert_non_null(spp);
            assert_string_equal(r->s, "Cycles 3.4");
            assert_float_equal(fov->f, 39.6, 0);
            assert_int_equal(spp->i,
                             mcp_attrs_find(&before->attrs, "samplesPerPixel")->i);
            mcp_image_free(conv);
        }
        mcp_image_free(before);
        mcp_image_free(after);
    }
    /* unknown job key, with its line */
    mcp_test_write_text(mcp_test_path("key.yaml"),
                        "inputs:\n  d: {dump: good.exr}\nstages:\n  - info: {input: d}\n"
                        "  - convert: {input: d, output: x.exr, chanels: [R]}\n");
    assert_one_line_error(run("run -q '%s'", mcp_test_path("key.yaml")),
                          "key.yaml:5: unknown key 'chanels' in stage 'convert'");
    /* usage errors exit 2 */
    assert_int_equal(run("frobnicate"), 2);
    assert_int_equal(run("info"), 2);
    mcp_dump_free(d);
}

static void
test_run_job_with_info_and_convert(void **state)
{
    (void)state;
    mcp_dump *d = sample_dump();
    assert_int_equal(mcp_dump_write(d, mcp_test_path("job_in.exr"), MCP_CONV_PBRT, NULL),
                     0);
    mcp_test_write_text(mcp_test_path("job.yaml"),
                        "title: test job\n"
                        "inputs:\n  noisy: {dump: job_in.exr}\n"
                        "output: results\n"
                        "stages:\n"
                        "  - info: {input: noisy}\n"
                        "  - convert: {input: noisy, output: noisy.png}\n"
                        "  - convert: {input: noisy, output: maps/noisy.exr, channels: "
                        "[G], pixel: half}\n");
    assert_int_equal(run("run --json '%s'", mcp_test_path("job.yaml")), 0);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    assert_string_equal(cJSON_GetObjectItem(j, "title")->valuestring, "test job");
    const cJSON *info = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0);
    assert_true(cJSON_GetObjectItem(info, "spp")->valuedouble == 128);
    cJSON_Delete(j);
    mcp_image *img = NULL;
    assert_int_equal(mcp_image_read(mcp_test_path("results/maps/noisy.exr"), NULL, &img),
                     0);
    assert_string_equal(img->names[0], "G");
    mcp_image_free(img);
    assert_int_equal(access(mcp_test_path("results/noisy.png"), R_OK), 0);
    assert_int_equal(access(mcp_test_path("results/report.html"), R_OK), 0);
    assert_non_null(strstr(err, "results in"));
    mcp_dump_free(d);
}

/* An image file's R, G, B channels in that order (EXR keeps channels sorted: B, G, R). */
static mcp_image *
rgb_of(const char *path)
{
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *img = NULL, *out = NULL;
    int idx[3];
    if (mcp_image_read(path, NULL, &img)) fail_msg("%s", mcp_error_message());
    for (int c = 0; c < 3; c++)
        assert_true((idx[c] = mcp_image_channel(img, rgb[c])) >= 0);
    assert_int_equal(mcp_image_copy_channels(img, idx, 3, &out), 0);
    mcp_image_free(img);
    return out;
}

/* --denoiser, --denoiser-opt and the shorthands (--weights, --input-scale,
 * --denoiser-command) are one parser (cli/denoiser_flags.c): a shorthand is exactly
 * --denoiser-opt KEY=VALUE, so a key the denoiser lacks and a key given twice fail alike
 * in every command. Only built-in kinds here (gauss): unet's weights are not needed. */
static void
test_denoiser_flags(void **state)
{
    (void)state;
    mcp_dump *d = sample_dump();
    char color[4096], dump[4096], w[4096];
    snprintf(color, sizeof color, "%s", mcp_test_path("dn_color.exr"));
    snprintf(dump, sizeof dump, "%s", mcp_test_path("dn_dump.exr"));
    snprintf(w, sizeof w, "%s", mcp_test_path("w.tza"));
    assert_int_equal(mcp_image_write(d->color, color, NULL), 0);
    assert_int_equal(mcp_dump_write(d, dump, MCP_CONV_PBRT, NULL), 0);
    mcp_test_write_text(w, "not read: gauss refuses the key first");

    /* a shorthand's key, unknown to gauss, is named like --denoiser-opt's */
    int st = run("denoise --color '%s' --denoiser gauss --weights '%s' -o '%s'", color, w,
                 mcp_test_path("dn_w.exr"));
    assert_int_equal(st, 1);
    assert_one_line_error(st, "unknown key 'weights' in denoiser 'gauss'");
    assert_int_equal(access(mcp_test_path("dn_w.exr"), F_OK), -1);
    st = run("denoise --color '%s' --denoiser gauss --denoiser-opt weights='%s'", color,
             w);
    assert_int_equal(st, 1);
    assert_one_line_error(st, "unknown key 'weights' in denoiser 'gauss'");
    assert_one_line_error(
        run("denoise --color '%s' --denoiser gauss --input-scale auto", color),
        "unknown key 'input_scale' in denoiser 'gauss'");
    assert_one_line_error(
        run("denoise --color '%s' --denoiser gauss --denoiser-command 'cp "
            "{color} {output}'",
            color),
        "unknown key 'command' in denoiser 'gauss'");

    /* a shorthand and --denoiser-opt naming one key, in either order, or twice */
    const char *twice[][2] = {
        {"--weights a.tza --denoiser-opt weights=b.tza", "key 'weights' given twice"},
        {"--denoiser-opt weights=b.tza --weights a.tza", "key 'weights' given twice"},
        {"--weights a.tza --weights b.tza", "key 'weights' given twice"},
        {"--input-scale 2 --denoiser-opt input_scale=auto",
         "key 'input_scale' given twice"},
        {"--denoiser-command true --denoiser-opt command=false",
         "key 'command' given twice"},
    };
    for (size_t i = 0; i < sizeof twice / sizeof twice[0]; i++)
        assert_one_line_error(
            run("denoise --color '%s' --denoiser gauss %s", color, twice[i][0]),
            twice[i][1]);

    /* --denoiser-opt still sets the denoiser: the output is the library's gauss with
     * sigma 3 (not its default 2) */
    assert_int_equal(
        run("denoise --color '%s' --denoiser gauss --denoiser-opt sigma=3 -o '%s'", color,
            mcp_test_path("dn_s3.exr")),
        0);
    mcp_image *in = rgb_of(color), *got = rgb_of(mcp_test_path("dn_s3.exr")),
              *want = NULL;
    mcp_denoiser *den = NULL;
    const char *sigma[] = {"sigma=3"};
    assert_int_equal(mcp_denoiser_create_from_args("gauss", sigma, 1, &den), 0);
    mcp_denoise_input din = {.color = in};
    assert_int_equal(den->apply(den, &din, &want), 0);
    assert_close(mcp_test_max_abs_diff(got, want), 0, 0, 1e-6);
    mcp_image_free(got), mcp_image_free(want), mcp_image_free(in);
    mcp_denoiser_free(den);

    /* the same flags in the other commands */
    assert_int_equal(
        run("estimate '%s' --denoiser gauss --denoiser-opt sigma=2 --json", dump), 0);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    assert_string_equal(cJSON_GetObjectItem(j, "denoiser")->valuestring, "gauss");
    cJSON_Delete(j);
    assert_one_line_error(run("estimate '%s' --denoiser gauss --weights '%s'", dump, w),
                          "unknown key 'weights' in denoiser 'gauss'");
    assert_one_line_error(run("estimate '%s' --denoiser gauss --denoiser-opt sigma=2 "
                              "--denoiser-opt sigma=3",
                              dump),
                          "key 'sigma' given twice");
    assert_one_line_error(
        run("blend --quiet '%s' -o '%s' --denoiser gauss --weights '%s'", dump,
            mcp_test_path("dn_blend"), w),
        "unknown key 'weights' in denoiser 'gauss'");
    assert_one_line_error(
        run("perceptual '%s' '%s' -o '%s' --denoiser gauss --weights '%s'", color, color,
            mcp_test_path("dn_perc"), w),
        "unknown key 'weights' in denoiser 'gauss'");
    assert_one_line_error(
        run("perceptual '%s' '%s' -o '%s' --weights a --denoiser-opt weights=b", color,
            color, mcp_test_path("dn_perc")),
        "key 'weights' given twice");

    /* every one of them lists the shorthands */
    const char *cmds[] = {"denoise", "estimate", "blend", "perceptual"};
    for (int i = 0; i < 4; i++) {
        assert_int_equal(run("%s --help", cmds[i]), 0);
        assert_non_null(strstr(out, "--denoiser-opt KEY=VAL"));
        assert_non_null(strstr(out, "--weights PATH"));
        assert_non_null(strstr(out, "--input-scale auto|N"));
        assert_non_null(strstr(out, "--denoiser-command CMD"));
    }
    mcp_dump_free(d);
}

/* mcpost merge and the job input replicates: give the same dump as mcp_dump_merge;
 * info and estimate name the variance source; a series with variance_from:
 * increments is estimated from its increments; bad merges fail in one line. */
static void
test_merge_and_variance_sources(void **state)
{
    (void)state;
    const char *names[4] = {"rep0.exr", "rep1.exr", "rep2.exr", "rep3.exr"};
    mcp_dump *parts[4];
    for (int k = 0; k < 4; k++) {
        parts[k] = sample_dump();
        for (int i = 0; i < 16 * 8 * 3; i++)
            parts[k]->color->data[i] += 0.1f * (float)((k * 7 + i) % 5);
        assert_int_equal(
            mcp_dump_write(parts[k], mcp_test_path(names[k]), MCP_CONV_PBRT, NULL), 0);
    }
    mcp_dump *want = NULL, *got = NULL;
    assert_int_equal(mcp_dump_merge((const mcp_dump *const *)parts, 4, NULL, &want), 0);
    assert_int_equal(run("merge '%s' '%s' '%s' '%s' -o '%s'", mcp_test_path(names[0]),
                         mcp_test_path(names[1]), mcp_test_path(names[2]),
                         mcp_test_path(names[3]), mcp_test_path("merged.exr")),
                     0);
    assert_non_null(
        strstr(out, "512 spp; variance of the mean from their spread (3 degrees"));
    assert_int_equal(mcp_dump_read(mcp_test_path("merged.exr"), &got), 0);
    assert_int_equal(got->variance_source, MCP_VARSRC_REPLICATES);
    assert_true(mcp_test_max_abs_diff(got->color, want->color) == 0);
    for (int i = 0; i < 16 * 8 * 3; i++)
        assert_close(got->var_of_mean->data[i], want->var_of_mean->data[i], 1e-6, 1e-12);
    assert_int_equal(run("info '%s'", mcp_test_path("merged.exr")), 0);
    assert_non_null(
        strstr(out, "replicates: the spread of 4 renders (3 degrees of freedom)"));
    assert_int_equal(run("info '%s'", mcp_test_path(names[0])), 0);
    assert_non_null(strstr(out, "per-sample / n (assumes independent samples"));
    /* estimate says what the variance rests on */
    assert_int_equal(
        run("estimate '%s' --denoiser gauss --json", mcp_test_path("merged.exr")), 0);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    assert_string_equal(cJSON_GetObjectItem(j, "variance_source")->valuestring,
                        "replicates");
    assert_true(cJSON_GetObjectItem(j, "variance_dof")->valuedouble == 3);
    cJSON_Delete(j);
    assert_int_equal(
        run("estimate '%s' --denoiser gauss --json", mcp_test_path(names[0])), 0);
    j = cJSON_Parse(out);
    assert_string_equal(cJSON_GetObjectItem(j, "variance_source")->valuestring,
                        "per-sample");
    assert_non_null(cJSON_GetObjectItem(j, "variance_note"));
    cJSON_Delete(j);
    /* the job input: a glob, merged once, the same dump */
    mcp_test_write_text(
        mcp_test_path("merge.yaml"),
        "inputs:\n  frame: {replicates: rep*.exr}\n"
        "  progress: {series: [rep0.exr, merged.exr], variance_from: increments}\n"
        "output: merge_out\n"
        "stages:\n  - info: {input: frame}\n"
        "  - estimate: {input: progress, denoiser: gauss, taus: [0.5]}\n"
        "  - estimate: {input: frame, output: default}\n");
    assert_int_equal(run("run --json '%s'", mcp_test_path("merge.yaml")), 0);
    j = cJSON_Parse(out);
    assert_non_null(j);
    const cJSON *info = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0);
    assert_string_equal(cJSON_GetObjectItem(info, "variance_source")->valuestring,
                        "replicates");
    assert_true(cJSON_GetObjectItem(info, "spp")->valuedouble == 512);
    /* a stage without denoiser: the default, the U-Net (the dumps have features) */
    const cJSON *est = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 2);
    assert_string_equal(cJSON_GetObjectItem(est, "denoiser")->valuestring,
                        "default (unet)");
    cJSON_Delete(j);
    /* blend on the stratified texture series: the source, the measured ratio and the
       line in blend.json. By default (auto) its increments, which show Variance/n 2x
       too large, are used and said to be (variance_choice, no warning); with
       --variance-from file the per-sample variance stays and the line is a warning. */
    const char *sources[3] = {"", " --variance-from increments", " --variance-from file"},
               *want_src[3] = {"increments", "increments", "per-sample"};
    for (int k = 0; k < 3; k++) {
        assert_int_equal(run("blend '%s/samples/fixtures/strat/texture/series/"
                             "texture_spp%%04d.exr' --spp 32,64,128 --denoiser gauss "
                             "--no-flip --quiet -o '%s'%s",
                             MCP_TEST_SOURCE_DIR, mcp_test_path("strat_blend"),
                             sources[k]),
                         0);
        char *text = mcp_test_read_text(mcp_test_path("strat_blend/blend.json"));
        cJSON *b = cJSON_Parse(text);
        free(text);
        assert_non_null(b);
        assert_string_equal(cJSON_GetObjectItem(b, "variance_source")->valuestring,
                            want_src[k]);
        double ratio = cJSON_GetObjectItem(b, "variance_ratio")->valuedouble;
        assert_true(ratio > 1.6 && ratio < 2.4);
        int used = k < 2;
        const cJSON *line =
            cJSON_GetObjectItem(b, used ? "variance_choice" : "variance_warning");
        assert_non_null(line);
        assert_null(
            cJSON_GetObjectItem(b, used ? "variance_warning" : "variance_choice"));
        assert_non_null(
            strstr(line->valuestring, used ? "the estimates use the increments"
                                           : "use --variance-from increments"));
        /* stderr says it when the choice was automatic, or warns when Variance/n is
           kept; asked for (--variance-from increments), it is no news */
        if (k == 1)
            assert_null(strstr(err, "Variance/n is"));
        else
            assert_non_null(strstr(err, used ? "mcpost: Variance/n is"
                                             : "mcpost: warning: Variance/n is"));
        cJSON_Delete(b);
    }
    /* errors: one render; a pattern that matches nothing; a bad variance_from */
    assert_one_line_error(
        run("merge '%s' -o '%s'", mcp_test_path(names[0]), mcp_test_path("m1.exr")),
        "at least 2");
    assert_int_equal(access(mcp_test_path("m1.exr"), F_OK), -1);
    mcp_test_write_text(mcp_test_path("merge_bad.yaml"),
                        "inputs:\n  frame: {replicates: none*.exr}\n"
                        "stages:\n  - info: {input: frame}\n");
    assert_one_line_error(run("run '%s'", mcp_test_path("merge_bad.yaml")),
                          "merge_bad.yaml:2: replicates: no file matches");
    mcp_test_write_text(
        mcp_test_path("merge_bad2.yaml"),
        "inputs:\n  p: {series: [rep0.exr, merged.exr], variance_from: spread}\n"
        "stages:\n  - info: {input: p}\n");
    assert_one_line_error(run("run '%s'", mcp_test_path("merge_bad2.yaml")),
                          "variance_from must be auto, file or increments");
    mcp_dump_free(want);
    mcp_dump_free(got);
    for (int k = 0; k < 4; k++)
        mcp_dump_free(parts[k]);
}

static void
test_help_and_version(void **state)
{
    (void)state;
    assert_int_equal(run("--version"), 0);
    assert_non_null(strstr(out, "mcpost 0."));
    assert_int_equal(run("--help"), 0);
    assert_non_null(strstr(out, "info"));
    assert_non_null(strstr(out, "run"));
    assert_int_equal(run("run --list"), 0);
    assert_non_null(strstr(out, "convert"));
    /* every subcommand accepts --quiet (main takes it for those that do not parse it),
       and a "--quiet" after "--" is left for the subcommand */
    static const char *const subs[] = {"info",       "convert",  "merge",   "run",
                                       "submit",     "collect",  "metrics", "denoise",
                                       "perceptual", "estimate", "blend",   "adaptive"};
    for (size_t i = 0; i < sizeof subs / sizeof *subs; i++) {
        int rc = run("%s --quiet --help", subs[i]);
        if (rc != 0) fail_msg("mcpost %s --quiet --help: %d: %s", subs[i], rc, err);
        assert_non_null(strstr(out, "usage"));
    }
    assert_int_equal(
        run("estimate '%s/samples/fixtures/cornell/series/cornell_spp0016.exr' "
            "--denoiser gauss --probes 1 --quiet --json",
            MCP_TEST_SOURCE_DIR),
        0);
    assert_int_equal(run("info --quiet -- --quiet"), 1);
    assert_non_null(strstr(err, "--quiet"));
}

/* A usage error: status 2 and one stderr line "mcpost metrics: ...needle...". */
static void
assert_usage_error(int status, const char *needle)
{
    if (status != 2 || strncmp(err, "mcpost metrics: ", 16) != 0 ||
        !strstr(err, needle) || strchr(err, '\n') != err + strlen(err) - 1)
        fail_msg("status %d, stderr \"%s\", wanted a usage error with \"%s\"", status,
                 err, needle);
}

/* The last line of out (without its newline). */
static const char *
last_line(void)
{
    size_t n = strlen(out);
    while (n && out[n - 1] == '\n')
        out[--n] = 0;
    const char *nl = strrchr(out, '\n');
    return nl ? nl + 1 : out;
}

#define CORNELL_PAIR                                                                     \
    "'" MCP_TEST_SOURCE_DIR                                                              \
    "/samples/fixtures/cornell/series/cornell_spp0016.exr' '" MCP_TEST_SOURCE_DIR        \
    "/samples/fixtures/cornell/cornell_reference.exr' --no-spectra "                     \
    "--flip ldr"

/* Gates on the 16-spp Cornell box (LDR-FLIP about 0.135, relMSE about 0.40): the
 * thresholds sit on both sides of each figure, so holding and not holding are both
 * seen. Exit statuses: 0 pass, 3 warning, 4 failure (docs/metrics.md, "Gates"). */
static void
test_metrics_gates(void **state)
{
    (void)state;
    assert_int_equal(run("metrics " CORNELL_PAIR " --fail 'flip_ldr.mean > 0.15' "
                         "--warn 'relmse >= 0.5'"),
                     0);
    assert_string_equal(last_line(), "PASS");
    assert_int_equal(run("metrics " CORNELL_PAIR " --fail 'flip_ldr.mean > 0.15' "
                         "--warn 'relmse >= 0.3' --warn 'psnr<10'"),
                     3);
    assert_true(!strncmp(last_line(), "WARNING: relmse >= 0.3 (0.39",
                         strlen("WARNING: relmse >= 0.3 (0.39")));
    assert_null(strstr(last_line(), "psnr"));
    assert_int_equal(run("metrics " CORNELL_PAIR " --fail 'flip_ldr.mean > 0.12' "
                         "--warn 'relmse >= 0.3'"),
                     4);
    assert_true(!strncmp(last_line(), "FAILURE: flip_ldr.mean > 0.12 (0.13",
                         strlen("FAILURE: flip_ldr.mean > 0.12 (0.13")));
    /* --json: the gate object, and still the gate's status */
    assert_int_equal(run("metrics --json " CORNELL_PAIR " --fail 'flip_ldr.mean<=0.12' "
                         "--warn 'relse_percentiles.value.0 > 0.001' --warn 'mse > 1'"),
                     3);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    const cJSON *g = cJSON_GetObjectItem(j, "gate");
    assert_string_equal(cJSON_GetObjectItem(g, "verdict")->valuestring, "warning");
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(g, "failed")), 0);
    const cJSON *warned = cJSON_GetObjectItem(g, "warned");
    assert_int_equal(cJSON_GetArraySize(warned), 1);
    assert_string_equal(cJSON_GetArrayItem(warned, 0)->valuestring,
                        "relse_percentiles.value.0 > 0.001");
    cJSON_Delete(j);
    /* usage errors, before anything is computed: an unknown figure (named, with known
       ones), a malformed expression, and a figure these options do not compute */
    assert_usage_error(run("metrics " CORNELL_PAIR " --fail 'flip.mean > 0.1'"),
                       "no figure 'flip.mean' in the metrics (known: width, height, mse");
    assert_usage_error(run("metrics " CORNELL_PAIR " --warn 'relmse = 0.1'"),
                       "--warn 'relmse = 0.1': want FIGURE OP NUMBER");
    assert_usage_error(run("metrics " CORNELL_PAIR " --fail 'psnr > lots'"),
                       "want FIGURE OP NUMBER");
    assert_usage_error(run("metrics " CORNELL_PAIR " --fail 'flip_hdr.mean > 0.1'"),
                       "no figure 'flip_hdr.mean'");
    assert_int_equal(run("metrics --help"), 0);
    assert_non_null(strstr(out, "--fail 'EXPR'"));
}

/* Percent gates with a closed-form truth: against a reference of ones, a test of ones
 * with 7 of its 100 pixels at 2 has RelSE (2 - 1)^2 / (2^2 + 0.01) = 0.249 there and
 * 0 elsewhere, so exactly 7% of the pixels are above 0.1 (and none above 0.3). idiff's
 * rule is strict: more than P% fails, so 7% fails at 5% and passes at 7%. */
static void
test_metrics_percent_gates(void **state)
{
    (void)state;
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *ref = mcp_test_constant(10, 10, 3, 1.0f, rgb),
              *test = mcp_test_constant(10, 10, 3, 1.0f, rgb);
    for (int i = 0; i < 7; i++) /* spread over rows and columns */
        mcp_image_px(test, (3 * i) % 10, (7 * i + 1) % 10)[i % 3] = 2.0f;
    char t_path[4200], r_path[4200];
    snprintf(t_path, sizeof t_path, "%s", mcp_test_path("pct_test.exr"));
    snprintf(r_path, sizeof r_path, "%s", mcp_test_path("pct_ref.exr"));
    assert_int_equal(mcp_image_write(test, t_path, NULL), 0);
    assert_int_equal(mcp_image_write(ref, r_path, NULL), 0);
    mcp_image_free(test);
    mcp_image_free(ref);
#define PCT_PAIR "'%s' '%s' --no-spectra --flip ldr"
    assert_int_equal(
        run("metrics " PCT_PAIR " --fail-percent 'relse 0.1 5%%'", t_path, r_path), 4);
    assert_string_equal(last_line(),
                        "FAILURE: relse > 0.1 on more than 5% of the pixels (7%)");
    assert_int_equal(run("metrics " PCT_PAIR " --fail-percent 'relse 0.1 7' "
                         "--warn-percent 'relse 0.3 0%%'",
                         t_path, r_path),
                     0);
    assert_string_equal(last_line(), "PASS");
    assert_int_equal(run("metrics " PCT_PAIR " --fail-percent 'relse 0.3 0' "
                         "--warn-percent 'relse 0.2 6.5%%'",
                         t_path, r_path),
                     3);
    assert_string_equal(last_line(),
                        "WARNING: relse > 0.2 on more than 6.5% of the pixels (7%)");
    /* --json: the measured shares beside the figures */
    assert_int_equal(run("metrics --json " PCT_PAIR " --warn-percent 'relse 0.1 50' "
                         "--warn-percent 'relse 0.3 50'",
                         t_path, r_path),
                     0);
    cJSON *j = cJSON_Parse(out);
    const cJSON *above = cJSON_GetObjectItem(j, "pixels_above");
    assert_int_equal(cJSON_GetArraySize(above), 2);
    assert_string_equal(
        cJSON_GetObjectItem(cJSON_GetArrayItem(above, 0), "map")->valuestring, "relse");
    assert_true(
        cJSON_GetObjectItem(cJSON_GetArrayItem(above, 0), "percent")->valuedouble == 7.0);
    assert_true(
        cJSON_GetObjectItem(cJSON_GetArrayItem(above, 1), "percent")->valuedouble == 0.0);
    cJSON_Delete(j);

    /* FLIP: the share agrees with a count over the FLIP map written by -o */
    const char *dir = mcp_test_path("pct_maps");
    assert_int_equal(run("metrics --json " CORNELL_PAIR " -o '%s' "
                         "--warn-percent 'flip_ldr 0.2 100'",
                         dir),
                     0);
    j = cJSON_Parse(out);
    double share =
        cJSON_GetObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItem(j, "pixels_above"), 0),
                            "percent")
            ->valuedouble;
    char path[4300];
    snprintf(path, sizeof path, "%s/flip_ldr.exr", dir);
    mcp_image *map = NULL;
    assert_int_equal(mcp_image_read(path, NULL, &map), 0);
    long above_n = 0, n = (long)map->width * map->height;
    for (long i = 0; i < n; i++)
        above_n += map->data[i] > 0.2f;
    assert_true(share == 100.0 * above_n / n);
    assert_true(above_n > 0 && above_n < n); /* a threshold inside the map's range */
    /* and the statistics in the JSON are those of that map */
    mcp_flip_stats st;
    assert_int_equal(mcp_flip_statistics(map->data, (size_t)n, &st), 0);
    const cJSON *fl = cJSON_GetObjectItem(j, "flip_ldr");
    assert_true(cJSON_GetObjectItem(fl, "weighted_median")->valuedouble ==
                st.weighted_median);
    assert_true(cJSON_GetObjectItem(fl, "max")->valuedouble == st.max);
    const cJSON *counts =
        cJSON_GetObjectItem(cJSON_GetObjectItem(j, "flip_histogram"), "flip_ldr");
    assert_int_equal(cJSON_GetArraySize(counts), MCP_FLIP_HISTOGRAM_BUCKETS);
    for (int i = 0; i < MCP_FLIP_HISTOGRAM_BUCKETS; i++)
        assert_true(cJSON_GetArrayItem(counts, i)->valuedouble ==
                    (double)st.histogram[i]);
    mcp_image_free(map);
    cJSON_Delete(j);

    /* usage errors before anything is computed */
    assert_usage_error(run("metrics " CORNELL_PAIR " --fail-percent 'flip 0.1 1%%'"),
                       "--fail-percent 'flip 0.1 1%': unknown map 'flip'");
    assert_usage_error(run("metrics " CORNELL_PAIR " --warn-percent 'flip_ldr 0.1'"),
                       "want MAP THRESHOLD PERCENT");
    assert_usage_error(run("metrics " CORNELL_PAIR " --fail-percent 'relse 0.1 120'"),
                       "PERCENT in [0, 100]");
    assert_usage_error(
        run("metrics " CORNELL_PAIR " --fail-percent 'flip_hdr 0.1 1'"),
        "no share of pixels above 0.1 in flip_hdr (is that FLIP computed?)");
#undef PCT_PAIR
}

/* Several tests against one reference: a row each in the text, the CSV and the JSON;
 * the verdict is the worst (16 spp fails LDR-FLIP > 0.13, 64 spp at 0.117 passes), the
 * last line names the failing test, and each row carries its own verdict. The CSV's
 * numbers are the JSON's (printed to 9 digits). */
static void
test_metrics_several_tests(void **state)
{
    (void)state;
    const char *csv = mcp_test_path("several.csv"), *dir = mcp_test_path("several");
#define SERIES MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell/series/"
#define THREE                                                                            \
    "'" SERIES "cornell_spp0016.exr' '" SERIES "cornell_spp0064.exr' '" SERIES           \
    "cornell_spp0256.exr' '" MCP_TEST_SOURCE_DIR                                         \
    "/samples/fixtures/cornell/cornell_reference.exr' --no-spectra --flip ldr"
    assert_int_equal(run("metrics " THREE
                         " --fail 'flip_ldr.mean > 0.13' --csv '%s' -o '%s'",
                         csv, dir),
                     4);
    assert_string_equal(last_line(), "FAILURE: " SERIES "cornell_spp0016.exr: "
                                     "flip_ldr.mean > 0.13 (0.135066)");
    /* the text: a header and a row per test, each with its verdict */
    assert_non_null(strstr(out, "LDR-FLIP median"));
    const char *row16 = strstr(out, "cornell_spp0016.exr "),
               *row64 = strstr(out, "cornell_spp0064.exr ");
    assert_non_null(row16);
    assert_non_null(row64);
    assert_non_null(strstr(row16, "FAILURE\n"));
    assert_true(strstr(row64, "PASS\n") < strstr(row64, "\n") + 1);
    /* the CSV: header + 3 rows, the gate column last */
    char *text = mcp_test_read_text(csv);
    int lines = 0;
    for (char *c = text; *c; c++)
        lines += *c == '\n';
    assert_int_equal(lines, 4);
    assert_true(!strncmp(text, "test,reference,mse,rmse,relmse,psnr,pmse,", 41));
    assert_non_null(strstr(text, ",flip_ldr_mean,flip_ldr_weighted_median,"
                                 "flip_ldr_weighted_q1,flip_ldr_weighted_q3,flip_ldr_min,"
                                 "flip_ldr_max,gate\n"));
    /* the JSON: tests[] with the same numbers, and the worst verdict */
    assert_int_equal(run("metrics --json " THREE " --fail 'flip_ldr.mean > 0.13'"), 4);
    cJSON *j = cJSON_Parse(out);
    const cJSON *tests = cJSON_GetObjectItem(j, "tests");
    assert_int_equal(cJSON_GetArraySize(tests), 3);
    const cJSON *g = cJSON_GetObjectItem(j, "gate");
    assert_string_equal(cJSON_GetObjectItem(g, "verdict")->valuestring, "failure");
    assert_int_equal(cJSON_GetArraySize(cJSON_GetObjectItem(g, "failed_tests")), 1);
    char *row = strchr(text, '\n') + 1; /* the CSV's first test */
    for (int t = 0; t < 3; t++) {
        const cJSON *one = cJSON_GetArrayItem(tests, t);
        const cJSON *fl = cJSON_GetObjectItem(one, "flip_ldr");
        char want[200];
        snprintf(want, sizeof want, ",%.9g,%.9g,",
                 cJSON_GetObjectItem(fl, "mean")->valuedouble,
                 cJSON_GetObjectItem(fl, "weighted_median")->valuedouble);
        char *end = strchr(row, '\n');
        *end = '\0';
        assert_non_null(strstr(row, want));
        assert_non_null(strstr(row, t == 0 ? ",FAILURE" : ",PASS"));
        row = end + 1;
        assert_string_equal(
            cJSON_GetObjectItem(cJSON_GetObjectItem(one, "gate"), "verdict")->valuestring,
            t == 0 ? "failure" : "pass");
    }
    free(text);
    cJSON_Delete(j);
    /* -o: each test's maps under its name, and the overlapped histogram */
    char path[4300];
    snprintf(path, sizeof path, "%s/cornell_spp0064.flip_ldr.exr", dir);
    assert_int_equal(access(path, R_OK), 0);
    snprintf(path, sizeof path, "%s/flip_ldr_histogram.svg", dir);
    text = mcp_test_read_text(path);
    assert_non_null(strstr(text, "cornell_spp0016.exr"));
    assert_non_null(strstr(text, "cornell_spp0256.exr"));
    assert_non_null(strstr(text, "fill-opacity=\"0.45\""));
    free(text);
    assert_usage_error(run("metrics '" SERIES "cornell_spp0016.exr'"),
                       "give TEST... and REF");
#undef THREE
#undef SERIES
}

/* The stage's fail: / warn: keys: a bad figure at its job-file line before anything
 * runs, and `mcpost run` exiting with the worst gate after writing the report. */
/* The stage's fail_percent: / warn_percent: and compare:. A bad map is named at its
 * job-file line before anything runs; the shares, the compared test's FLIP and the
 * histograms are those `mcpost metrics` gives for the same images. */
static void
test_metrics_percent_job(void **state)
{
    (void)state;
    static const char job[] =
        "inputs:\n"
        "  noisy: {image: '%s/samples/fixtures/cornell/series/cornell_spp0016.exr'}\n"
        "  better: {image: '%s/samples/fixtures/cornell/series/cornell_spp0256.exr'}\n"
        "  ref: {image: '%s/samples/fixtures/cornell/cornell_reference.exr'}\n"
        "output: percent_out\n"
        "stages:\n"
        "  - metrics:\n"
        "      input: noisy\n"
        "      reference: ref\n"
        "      compare: better\n"
        "      maps: false\n"
        "      spectra: false\n"
        "      flip: ldr\n"
        "      fail_percent: ['%s']\n";
    char text[2048], path[1024];
    snprintf(path, sizeof path, "%s", mcp_test_path("percent.yaml"));
    snprintf(text, sizeof text, job, MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR,
             MCP_TEST_SOURCE_DIR, "flip_hdr 0.3 1%");
    mcp_test_write_text(path, text);
    assert_one_line_error(
        run("run --check '%s'", path),
        "percent.yaml:14: fail_percent: 'flip_hdr > 0.3 on more than 1% of "
        "the pixels': the metrics have no share of pixels above 0.3 in "
        "flip_hdr");
    snprintf(text, sizeof text, job, MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR,
             MCP_TEST_SOURCE_DIR, "flip_ldr 0.3 1%");
    mcp_test_write_text(path, text);
    assert_int_equal(run("run -q --json '%s'", path), 4);
    cJSON *j = cJSON_Parse(out);
    const cJSON *sec = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0);
    assert_string_equal(
        cJSON_GetArrayItem(
            cJSON_GetObjectItem(cJSON_GetObjectItem(sec, "gate"), "failed"), 0)
            ->valuestring,
        "flip_ldr > 0.3 on more than 1% of the pixels");
    double share =
        cJSON_GetObjectItem(
            cJSON_GetArrayItem(cJSON_GetObjectItem(sec, "pixels_above"), 0), "percent")
            ->valuedouble;
    double cmp_median =
        cJSON_GetObjectItem(
            cJSON_GetObjectItem(cJSON_GetObjectItem(sec, "compare"), "flip_ldr"),
            "weighted_median")
            ->valuedouble;
    /* the LDR-FLIP histogram's bars: input and compare overlapped */
    const cJSON *plot = NULL, *p;
    cJSON_ArrayForEach(
        p, cJSON_GetObjectItem(
               sec, "plots")) if (!strcmp(cJSON_GetObjectItem(p, "title")->valuestring,
                                          "weighted LDR-FLIP histogram")) plot = p;
    assert_non_null(plot);
    const cJSON *series = cJSON_GetObjectItem(plot, "series");
    assert_int_equal(cJSON_GetArraySize(series), 2);
    assert_string_equal(
        cJSON_GetObjectItem(cJSON_GetArrayItem(series, 1), "name")->valuestring,
        "better");
    assert_string_equal(
        cJSON_GetObjectItem(cJSON_GetArrayItem(series, 0), "style")->valuestring, "bars");
    assert_string_equal(
        cJSON_GetArrayItem(cJSON_GetObjectItem(sec, "json_only"), 0)->valuestring,
        "flip_histogram");
    cJSON_Delete(j);
    /* the same numbers from the command */
    assert_int_equal(run("metrics --json --no-spectra --flip ldr "
                         "'%s/samples/fixtures/cornell/series/cornell_spp0016.exr' "
                         "'%s/samples/fixtures/cornell/series/cornell_spp0256.exr' "
                         "'%s/samples/fixtures/cornell/cornell_reference.exr' "
                         "--fail-percent 'flip_ldr 0.3 1'",
                         MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR),
                     4);
    j = cJSON_Parse(out);
    const cJSON *tests = cJSON_GetObjectItem(j, "tests");
    assert_true(
        cJSON_GetObjectItem(
            cJSON_GetArrayItem(
                cJSON_GetObjectItem(cJSON_GetArrayItem(tests, 0), "pixels_above"), 0),
            "percent")
            ->valuedouble == share);
    assert_true(
        cJSON_GetObjectItem(cJSON_GetObjectItem(cJSON_GetArrayItem(tests, 1), "flip_ldr"),
                            "weighted_median")
            ->valuedouble == cmp_median);
    cJSON_Delete(j);
}

static void
test_metrics_gate_job(void **state)
{
    (void)state;
    static const char job[] =
        "inputs:\n"
        "  noisy: {image: '%s/samples/fixtures/cornell/series/cornell_spp0016.exr'}\n"
        "  ref: {image: '%s/samples/fixtures/cornell/cornell_reference.exr'}\n"
        "output: gate_out\n"
        "stages:\n"
        "  - metrics:\n"
        "      input: noisy\n"
        "      reference: ref\n"
        "      maps: false\n"
        "      spectra: false\n"
        "      fail: ['%s']\n"
        "      warn: relmse > 0.3\n";
    char text[2048], path[1024];
    /* copied: mcp_test_path's buffer is reused by later calls */
    snprintf(path, sizeof path, "%s", mcp_test_path("gate.yaml"));
    snprintf(text, sizeof text, job, MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR,
             "flip_ldr.men > 0.1");
    mcp_test_write_text(path, text);
    assert_one_line_error(
        run("run --check '%s'", path),
        "gate.yaml:11: fail: 'flip_ldr.men > 0.1': no figure 'flip_ldr.men'");
    assert_int_equal(run("run -q '%s'", path), 1);
    snprintf(text, sizeof text, job, MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR,
             "flip_ldr.mean > 0.12");
    mcp_test_write_text(path, text);
    assert_int_equal(run("run -q --json '%s'", path), 4);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    const cJSON *sec = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0);
    const cJSON *g = cJSON_GetObjectItem(sec, "gate");
    assert_string_equal(cJSON_GetObjectItem(g, "verdict")->valuestring, "failure");
    assert_string_equal(
        cJSON_GetArrayItem(cJSON_GetObjectItem(g, "failed"), 0)->valuestring,
        "flip_ldr.mean > 0.12");
    assert_string_equal(
        cJSON_GetObjectItem(cJSON_GetObjectItem(sec, "verdict"), "level")->valuestring,
        "bad");
    cJSON_Delete(j);
    /* only the warning holding: status 3, an info verdict; none: 0, good */
    snprintf(text, sizeof text, job, MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR,
             "flip_ldr.mean > 0.15");
    mcp_test_write_text(path, text);
    assert_int_equal(run("run -q '%s'", path), 3);
    snprintf(text, sizeof text, job, MCP_TEST_SOURCE_DIR, MCP_TEST_SOURCE_DIR,
             "flip_ldr.mean > 0.15");
    char *w = strstr(text, "relmse > 0.3");
    memcpy(w, "relmse > 0.5", 12);
    mcp_test_write_text(path, text);
    assert_int_equal(run("run -q --json '%s'", path), 0);
    j = cJSON_Parse(out);
    sec = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0);
    assert_string_equal(
        cJSON_GetObjectItem(cJSON_GetObjectItem(sec, "verdict"), "level")->valuestring,
        "good");
    cJSON_Delete(j);
}

/* A series estimate measures SURE on each member's own checkpoints from the third
 * member on, says so (the last line, "sure" in the JSON, each member's sure_groups),
 * and --sure-groups 0 (or the job key) keeps the probes' divergence. */
static void
test_estimate_series_sure_groups(void **state)
{
    (void)state;
    const char *words[2] = {"from groups of each member's own checkpoints",
                            "the probes' divergence"};
    for (int off = 0; off < 2; off++) {
        assert_int_equal(run("estimate --series '%s/samples/fixtures/cornell/series/"
                             "cornell_spp%%04d.exr' --spp 16,32,64 --denoiser gauss%s",
                             MCP_TEST_SOURCE_DIR, off ? " --sure-groups 0" : ""),
                         0);
        assert_non_null(strstr(out, words[off]));
        assert_int_equal(run("estimate --series '%s/samples/fixtures/cornell/series/"
                             "cornell_spp%%04d.exr' --spp 16,32,64 --denoiser gauss "
                             "--json%s",
                             MCP_TEST_SOURCE_DIR, off ? " --sure-groups 0" : ""),
                         0);
        cJSON *j = cJSON_Parse(out);
        assert_non_null(j);
        assert_non_null(strstr(cJSON_GetObjectItem(j, "sure")->valuestring, words[off]));
        const cJSON *members = cJSON_GetObjectItem(j, "members");
        for (int i = 0; i < 3; i++) /* 16 and 32 spp: too few groups; then 3 */
            assert_true(cJSON_GetObjectItem(cJSON_GetArrayItem(members, i), "sure_groups")
                            ->valuedouble == (off || i < 2 ? 0 : 3));
        cJSON_Delete(j);
        /* a tau every member reaches: the first two are held (F >= p, no stop, an h in
           the table) with the groups, and the first stops without them */
        assert_int_equal(run("estimate --series '%s/samples/fixtures/cornell/series/"
                             "cornell_spp%%04d.exr' --spp 16,32,64 --denoiser gauss "
                             "--tau 100 --json%s",
                             MCP_TEST_SOURCE_DIR, off ? " --sure-groups 0" : ""),
                         0);
        j = cJSON_Parse(out);
        assert_non_null(j);
        members = cJSON_GetObjectItem(j, "members");
        for (int i = 0; i < 3; i++) {
            const cJSON *m = cJSON_GetArrayItem(members, i);
            assert_int_equal(cJSON_IsTrue(cJSON_GetObjectItem(m, "held")), !off && i < 2);
            /* the fixture's per-sample variance is not off: the probes keep it */
            assert_true(cJSON_IsFalse(cJSON_GetObjectItem(m, "probes_from_groups")));
            assert_int_equal(
                cJSON_IsTrue(cJSON_GetArrayItem(cJSON_GetObjectItem(m, "stop"), 0)),
                off || i == 2);
        }
        cJSON_Delete(j);
        assert_int_equal(run("estimate --series '%s/samples/fixtures/cornell/series/"
                             "cornell_spp%%04d.exr' --spp 16,32,64 --denoiser gauss "
                             "--tau 100%s",
                             MCP_TEST_SOURCE_DIR, off ? " --sure-groups 0" : ""),
                         0);
        assert_int_equal(strstr(out, "h: F(tau) >= p, held") != NULL, !off);
    }
    assert_int_not_equal(run("estimate --series '%s/samples/fixtures/cornell/series/"
                             "cornell_spp%%04d.exr' --spp 16,32 --sure-groups 1",
                             MCP_TEST_SOURCE_DIR),
                         0);
    assert_non_null(strstr(err, "sure_groups must be"));
    mcp_test_write_text(mcp_test_path("groups.yaml"),
                        "inputs:\n  progress: {series: "
                        "['" MCP_TEST_SOURCE_DIR "/samples/fixtures/cornell/series/"
                        "cornell_spp0016.exr', '" MCP_TEST_SOURCE_DIR
                        "/samples/fixtures/cornell/series/cornell_spp0032.exr']}\n"
                        "output: groups_out\n"
                        "stages:\n  - estimate: {input: progress, denoiser: gauss, "
                        "sure_groups: 0}\n");
    assert_int_equal(run("run --json '%s'", mcp_test_path("groups.yaml")), 0);
    cJSON *j = cJSON_Parse(out);
    assert_non_null(j);
    const cJSON *est = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "sections"), 0);
    assert_non_null(strstr(cJSON_GetObjectItem(est, "sure")->valuestring, words[1]));
    cJSON_Delete(j);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_info_describes_each_renderer),
        cmocka_unit_test(test_info_counts_bad_values),
        cmocka_unit_test(test_convert),
        cmocka_unit_test(test_every_bad_input_class),
        cmocka_unit_test(test_run_job_with_info_and_convert),
        cmocka_unit_test(test_denoiser_flags),
        cmocka_unit_test(test_merge_and_variance_sources),
        cmocka_unit_test(test_help_and_version),
        cmocka_unit_test(test_metrics_gates),
        cmocka_unit_test(test_metrics_percent_gates),
        cmocka_unit_test(test_metrics_several_tests),
        cmocka_unit_test(test_metrics_gate_job),
        cmocka_unit_test(test_metrics_percent_job),
        cmocka_unit_test(test_estimate_series_sure_groups),
    };
    return cmocka_run_group_tests_name("cli", tests, NULL, NULL);
}
