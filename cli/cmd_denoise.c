/* cmd_denoise.c: `mcpost denoise` -- runs one denoiser alone on a render dump or on
 * separate colour/albedo/normal files, and with --tangent also writes its
 * Jacobian-vector product J·T: the way to check a denoiser and its derivative from
 * outside (docs/mathematics.md §2.1). The flags are the denoise table's
 * (ops/op_denoise.c), read by cli/options.c. */
#include "cli.h"

#include <mcpost/denoiser.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PATH_CAP 4096

static const char head[] =
    "usage: mcpost denoise DUMP [--denoiser NAME] [options]\n"
    "       mcpost denoise --color FILE [--albedo FILE] [--normal FILE]\n"
    "                      [--variance-of-mean FILE] [--denoiser NAME] [options]\n"
    "       mcpost denoise --list\n"
    "  Runs one denoiser on a render dump (colour, and the albedo, normal and variance\n"
    "  it holds) or on separate files, and writes the denoised colour as R,G,B.\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost denoise samples/fixtures/cornell/series/cornell_spp0064.exr --denoiser nlm "
    "-o /tmp/cornell_nlm.exr\n"
    "  mcpost denoise samples/fixtures/cornell/series/cornell_spp0016.exr -o "
    "/tmp/cornell_unet.exr   # the U-Net\n"
    "  mcpost denoise --list\n";

static void
print_kinds(void)
{
    for (const mcp_denoiser_kind *const *k = mcp_denoiser_kinds(); *k; k++) {
        printf("%-10s %s\n", (*k)->name, (*k)->summary);
        printf("%-10s settings:", "");
        for (const char *const *key = (*k)->keys; key && *key; key++)
            printf(" %s", *key);
        printf("\n");
    }
}

/* The 3 channels of an image file: the first of the name triples it has, or all of
 * them when it has exactly 3. */
static int
read_rgb(const char *path, const char *what, mcp_image **out)
{
    static const char *const triples[][3] = {{"R", "G", "B"}, {"X", "Y", "Z"}};
    mcp_image *img = NULL;
    *out = NULL;
    if (mcp_image_read(path, NULL, &img)) return -1;
    int idx[3], rc = -1;
    if (mcp_image_find_triple(img, triples, 2, idx))
        mcp_error("%s: the %s needs channels R,G,B or X,Y,Z, or exactly 3 channels "
                  "(it has %d)",
                  path, what, img->channels);
    else
        rc = mcp_image_copy_channels(img, idx, 3, out);
    mcp_image_free(img);
    return rc;
}

/* path without its extension (and, when strip_dir, without its folder) into buf. */
static void
stem_of(const char *path, int strip_dir, char *buf, size_t cap)
{
    const char *base = path, *slash = strrchr(path, '/');
    if (strip_dir && slash) base = slash + 1;
    snprintf(buf, cap, "%s", base);
    char *dot = strrchr(buf, '.'), *sep = strrchr(buf, '/');
    if (dot && dot != buf && (!sep || dot > sep + 1)) *dot = '\0';
}

typedef struct {
    const char *dump, *color, *albedo, *normal, *variance;
    const char *spp, *convention, *variance_kind;
    int no_albedo, no_normal, no_variance;
} inputs;

/* Loads the input (a dump, or separate files) into *dump. */
static int
load_input(const inputs *in, mcp_dump **out)
{
    *out = NULL;
    if (in->dump)
        return mcp_cli_read_dump(in->dump, in->spp, in->convention, in->variance_kind,
                                 out);
    mcp_dump *d = mcp_calloc(1, sizeof *d);
    if (!d) return -1;
    int rc = read_rgb(in->color, "colour", &d->color) ||
             (in->albedo && read_rgb(in->albedo, "albedo", &d->albedo)) ||
             (in->normal && read_rgb(in->normal, "normal", &d->normal)) ||
             (in->variance && read_rgb(in->variance, "variance", &d->var_of_mean));
    const mcp_image *parts[] = {d->albedo, d->normal, d->var_of_mean};
    for (int i = 0; i < 3 && !rc; i++)
        if (parts[i] && !mcp_image_same_size(parts[i], d->color)) rc = -1;
    if (!rc && !(d->source = mcp_strdup(in->color))) rc = -1;
    if (rc) {
        mcp_dump_free(d);
        return -1;
    }
    *out = d;
    return 0;
}

/* Denoises (and differentiates) and writes the outputs. */
static int
run(const mcp_denoiser *den, const mcp_dump *dump, const inputs *ins, const char *out,
    const char *tangent_path, const char *tangent_out)
{
    mcp_denoise_input in = mcp_denoise_input_of(dump);
    if (ins->no_albedo) in.albedo = NULL;
    if (ins->no_normal) in.normal = NULL;
    if (ins->no_variance) in.variance = NULL;
    mcp_image *t = NULL, *den_img = NULL, *jt = NULL;
    int rc = -1;
    if (tangent_path) {
        if (read_rgb(tangent_path, "tangent", &t)) goto done;
        if (!mcp_image_same_size(t, in.color)) goto done;
        mcp_denoise_tangent tan = {t, NULL, NULL};
        if (den->jvp(den, &in, &tan, 1, &den_img, &jt)) goto done;
    } else if (den->apply(den, &in, &den_img)) {
        goto done;
    }
    /* the input's header travels with the result (renderer, camera, sample count...) */
    if (mcp_attrs_copy(&dump->attrs, &den_img->attrs) ||
        mcp_attrs_set_string(&den_img->attrs, "mcpost.denoiser", den->name) ||
        mcp_image_write(den_img, out, NULL))
        goto done;
    if (jt && (mcp_attrs_set_string(&jt->attrs, "mcpost.denoiser", den->name) ||
               mcp_attrs_set_string(&jt->attrs, "mcpost.jvp_tangent", tangent_path) ||
               mcp_image_write(jt, tangent_out, NULL)))
        goto done;
    rc = 0;
done:
    mcp_image_free(jt);
    mcp_image_free(den_img);
    mcp_image_free(t);
    return rc;
}

/* A dump too large to hold whole beside the U-Net is denoised in bands of rows, read
 * and written as they go (docs/denoisers.md, "Images larger than memory"): *status 0
 * when it was; else it stays and the whole run follows. */
static int
streamed(const mcp_denoiser *den, const inputs *in, const char *tangent, const char *out,
         int *status)
{
    mcp_dump_spec spec;
    int done = 0;
    if (!in->dump || tangent || in->no_albedo || in->no_normal) return 0;
    if (mcp_cli_dump_spec(in->dump, in->spp, in->convention, in->variance_kind, &spec) ||
        mcp__denoise_dump_streamed(den, &spec, out, &done))
        return -1;
    if (done) *status = 0;
    return 0;
}

static int
cmd_denoise(int argc, char **argv)
{
    mcp_denoise_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0;
    int parsed = mcp_cli_parse(mcp_operation_denoise(), head, examples, argc, argv, &st,
                               &sh, &df, &first);
    if (parsed >= 0) {
        mcp_cli_denoiser_flags_free(&df);
        return parsed;
    }
    inputs in = {.color = st.color,
                 .albedo = st.albedo,
                 .normal = st.normal,
                 .variance = st.variance_of_mean,
                 .spp = st.spp,
                 .convention = st.convention,
                 .variance_kind = st.variance,
                 .no_albedo = st.no_albedo,
                 .no_normal = st.no_normal,
                 .no_variance = st.no_variance};
    const char *out = sh.output, *tangent = st.tangent, *tangent_out = st.tangent_out;
    int list = st.list;
    int status = 2;
    if (list) {
        print_kinds();
        mcp_cli_denoiser_flags_free(&df);
        return 0;
    }
    if (argc - first > 1)
        mcp_cli_usage("denoise", "give one DUMP (got %d inputs)", argc - first);
    else if (argc - first == 1 && in.color)
        mcp_cli_usage("denoise", "give either DUMP or --color, not both");
    else if (argc - first == 0 && !in.color)
        mcp_cli_usage("denoise", "no input: give DUMP or --color FILE");
    else if (!in.color && (in.albedo || in.normal || in.variance))
        mcp_cli_usage("denoise", "--albedo, --normal and --variance-of-mean go with "
                                 "--color; a DUMP carries its own");
    else if (in.color && (in.spp || in.convention || in.variance_kind))
        mcp_cli_usage("denoise", "--spp, --convention and --variance go with DUMP");
    else if (tangent_out && !tangent)
        mcp_cli_usage("denoise", "--tangent-out needs --tangent");
    else
        status = 1;
    if (status == 2) {
        mcp_cli_denoiser_flags_free(&df);
        return 2;
    }
    if (argc - first == 1) in.dump = argv[first];
    char out_buf[PATH_CAP], jvp_buf[PATH_CAP], stem[PATH_CAP];
    if (!out) {
        stem_of(in.dump ? in.dump : in.color, 1, stem, sizeof stem);
        snprintf(out_buf, sizeof out_buf, "%s_%s.exr", stem,
                 df.name     ? df.name
                 : df.n_opts ? "unet"
                             : "default");
        out = out_buf;
    }
    if (tangent && !tangent_out) {
        stem_of(out, 0, stem, sizeof stem);
        snprintf(jvp_buf, sizeof jvp_buf, "%s_jvp.exr", stem);
        tangent_out = jvp_buf;
    }
    mcp_denoiser *den = NULL;
    mcp_dump *dump = NULL;
    const char *inputs[6] = {in.dump,   in.color,    in.albedo,
                             in.normal, in.variance, tangent};
    if (mcp_cli_output_is_not_input("denoise", out, inputs, 6) ||
        mcp_cli_output_is_not_input("denoise", tangent_out, inputs, 6)) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_fail();
    }
    if (!mcp_cli_denoiser_create(&df, &den) &&
        !streamed(den, &in, tangent, out, &status) &&
        (status == 0 ||
         (!load_input(&in, &dump) && !run(den, dump, &in, out, tangent, tangent_out))))
        status = 0;
    else
        mcp_cli_fail();
    mcp_dump_free(dump);
    mcp_denoiser_free(den);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_denoise = {"denoise",
                                         "run one denoiser (and its "
                                         "Jacobian-vector product) alone",
                                         cmd_denoise, 1};
