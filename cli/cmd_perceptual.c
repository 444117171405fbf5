/* cmd_perceptual.c: `mcpost perceptual` and the `perceptual` job stage -- perceptual
 * error optimisation of M candidate renders (SPEC "perceptual"; perceptual.h). Writes
 * the optimised image (for horizontal methods the prediction and the permutation map,
 * and the re-rendered image when a re-render command is given), the surrogate, the
 * scores against a reference (pMSE, MSE, the blue-noise spectrum), and with --compare
 * the table of every method on the same input (Chizhov et al. 2022 Table 1).
 * Flags and job keys are the same words ('-' in flags, '_' in keys). */
#include "cli.h"

#include <mcpost/filter.h>
#include <mcpost/perceptual.h>
#include <mcpost/progress.h>

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

/* ---- settings shared by the flags and the job keys ---- */

typedef struct {
    mcp_perc_options opt;
    double *kernel;          /* user kernel taps, owned (separable list or 2D file) */
    const char *kernel_file; /* a 2D kernel image, loaded before the run */
    const char *surrogate;   /* "denoise" [default], "reference", or a file/input name */
    const char *confidence;  /* a file/input name for a map, or NULL (the number) */
    int group;               /* files averaged into one candidate [1] */
    int compare;             /* the comparison table [0] */
    const char *rerender;    /* command with {permutation} {output} {method} [NULL] */
    int spectra_tile;        /* [32] */
} perc_args;

static void
args_init(perc_args *a)
{
    memset(a, 0, sizeof *a);
    a->opt = mcp_perc_defaults();
    a->surrogate = "denoise";
    a->group = 1;
    a->spectra_tile = 32;
}

static void
args_free(perc_args *a)
{
    free(a->kernel);
    a->kernel = NULL;
}

static int
parse_bool(const char *key, const char *v, int *out)
{
    if (!strcasecmp(v, "true") || !strcasecmp(v, "yes") || !strcmp(v, "1"))
        *out = 1;
    else if (!strcasecmp(v, "false") || !strcasecmp(v, "no") || !strcmp(v, "0"))
        *out = 0;
    else
        return mcp_error("%s must be true or false (got '%s')", key, v);
    return 0;
}

static int
parse_u64(const char *key, const char *v, uint64_t *out)
{
    char *end;
    errno = 0;
    unsigned long long u = strtoull(v, &end, 10);
    if (!*v || *v == '-' || *end || errno)
        return mcp_error("%s must be an unsigned integer (got '%s')", key, v);
    *out = u;
    return 0;
}

/* Separable taps "a,b,c" (odd count): the kernel is their outer product. */
static int
parse_taps(perc_args *a, const double *t, int n)
{
    if (n < 1 || n % 2 == 0)
        return mcp_error("kernel: give an odd number of taps (got %d)", n);
    double *k = mcp_malloc((size_t)n * n * sizeof *k);
    if (!k) return -1;
    for (int y = 0; y < n; y++)
        for (int x = 0; x < n; x++)
            k[y * n + x] = t[y] * t[x];
    free(a->kernel);
    a->kernel = k;
    a->opt.model.user_kernel = k;
    a->opt.model.user_kernel_width = a->opt.model.user_kernel_height = n;
    a->kernel_file = NULL;
    return 0;
}

static int
set_kernel(perc_args *a, const char *v)
{
    if (!mcp_pkernel_kind_from_name(v, &a->opt.model.kernel.kind)) {
        a->opt.model.user_kernel = NULL;
        a->kernel_file = NULL;
        return 0;
    }
    mcp_error_clear();
    if (strchr(v, ',') || strspn(v, "0123456789.+-eE") == strlen(v)) {
        char **words = NULL;
        int n = 0, rc = mcp_cli_split(v, &words, &n);
        double *t = rc ? NULL : mcp_malloc((size_t)(n ? n : 1) * sizeof *t);
        for (int i = 0; !rc && t && i < n; i++)
            rc = mcp_cli_double("kernel", words[i], &t[i]);
        rc = rc || !t || parse_taps(a, t, n);
        mcp_cli_free_words(words, n);
        free(t);
        return rc ? -1 : 0;
    }
    a->kernel_file = v; /* a 2D kernel image */
    return 0;
}

/* One setting by its key (flag name with '_' for '-') and text value. */
static int
set_word(perc_args *a, const char *key, const char *v)
{
    mcp_perc_options *o = &a->opt;
    int rc = 0;
    double d = 0.0;
    if (!strcmp(key, "method"))
        rc = mcp_perc_method_from_name(v, &o->method);
    else if (!strcmp(key, "surrogate"))
        a->surrogate = v;
    else if (!strcmp(key, "confidence")) {
        if (mcp_cli_double("confidence", v, &d) == 0) {
            o->model.confidence = d;
            a->confidence = NULL;
        } else {
            mcp_error_clear();
            a->confidence = v; /* a per-pixel map */
        }
    } else if (!strcmp(key, "group")) {
        rc = mcp_cli_int("group", v, &a->group);
        if (!rc && a->group < 1) rc = mcp_error("group must be >= 1 (got %d)", a->group);
    } else if (!strcmp(key, "tone_map"))
        rc = mcp_tonemap_from_name(v, &o->model.tone_map);
    else if (!strcmp(key, "kernel"))
        rc = set_kernel(a, v);
    else if (!strcmp(key, "dpi"))
        rc = mcp_cli_double("dpi", v, &o->model.kernel.dpi);
    else if (!strcmp(key, "distance"))
        rc = mcp_cli_double("distance", v, &o->model.kernel.distance_in);
    else if (!strcmp(key, "filter_surrogate"))
        rc = parse_bool(key, v, &o->model.filter_surrogate);
    else if (!strcmp(key, "passes"))
        rc = mcp_cli_int("passes", v, &o->passes);
    else if (!strcmp(key, "init"))
        rc = mcp_perc_init_from_name(v, &o->init);
    else if (!strcmp(key, "seed"))
        rc = parse_u64("seed", v, &o->seed);
    else if (!strcmp(key, "max_subsets"))
        rc = mcp_cli_int("max_subsets", v, &o->max_subsets);
    else if (!strcmp(key, "radius"))
        rc = mcp_cli_int("radius", v, &o->radius);
    else if (!strcmp(key, "travel"))
        rc = mcp_cli_int("travel", v, &o->travel);
    else if (!strcmp(key, "tile"))
        rc = mcp_cli_int("tile", v, &o->tile);
    else if (!strcmp(key, "mask_size"))
        rc = mcp_cli_int("mask_size", v, &o->mask.size);
    else if (!strcmp(key, "mask_sigma"))
        rc = mcp_cli_double("mask_sigma", v, &o->mask.sigma);
    else if (!strcmp(key, "mask_seed"))
        rc = parse_u64("mask_seed", v, &o->mask.seed);
    else if (!strcmp(key, "cache"))
        rc = parse_bool(key, v, &o->mask.use_cache);
    else if (!strcmp(key, "compare"))
        rc = parse_bool(key, v, &a->compare);
    else if (!strcmp(key, "rerender"))
        a->rerender = v;
    else if (!strcmp(key, "spectra_tile")) {
        rc = mcp_cli_int("spectra_tile", v, &a->spectra_tile);
        if (!rc && a->spectra_tile < 4)
            rc = mcp_error("spectra_tile must be >= 4 (got %d)", a->spectra_tile);
    } else
        rc = mcp_error("unknown setting '%s'", key);
    return rc;
}

/* ---- the run, shared by the subcommand and the stage ---- */

typedef struct {
    mcp_image **files;   /* colour (R, G, B) of every candidate file, owned */
    mcp_image **albedos; /* each file's albedo and normal, or NULL; owned */
    mcp_image **normals;
    int n_files;
    mcp_image *albedo; /* mean albedo of the files, or NULL; owned */
    mcp_image *normal; /* mean normal, or NULL; owned */
    const mcp_image *reference, *surrogate_img, *confidence_map, *kernel_img;
    mcp_denoiser *den;  /* for surrogate: denoise */
    char out_dir[4096]; /* where the files go */
    char rel[256];      /* their path relative to the report's folder: rel + name */
    cJSON *section;     /* the report section to fill */
} perc_run;

static void
run_free(perc_run *r)
{
    for (int i = 0; i < r->n_files; i++) {
        mcp_image_free(r->files[i]);
        mcp_image_free(r->albedos[i]);
        mcp_image_free(r->normals[i]);
    }
    free(r->files), free(r->albedos), free(r->normals);
    mcp_image_free(r->albedo);
    mcp_image_free(r->normal);
    mcp_denoiser_free(r->den);
    memset(r, 0, sizeof *r);
}

/* Adds one file's colour (by its render-dump convention when it has one) and its
 * features (NULL where it has none) to the run. */
static int
add_file(perc_run *r, const mcp_image *img)
{
    mcp_dump *d = NULL;
    mcp_image *rgb = NULL;
    size_t n = (size_t)r->n_files + 1;
    mcp_image **files = realloc(r->files, n * sizeof *files);
    if (files) r->files = files;
    mcp_image **albedo = files ? realloc(r->albedos, n * sizeof *albedo) : NULL;
    if (albedo) r->albedos = albedo;
    mcp_image **normal = albedo ? realloc(r->normals, n * sizeof *normal) : NULL;
    if (!normal) return mcp_error("out of memory");
    r->normals = normal;
    if (mcp_dump_from_image(img, NULL, &d) == 0) {
        if (mcp_image_copy(d->color, &rgb)) {
            mcp_dump_free(d);
            return -1;
        }
    } else if (strstr(mcp_error_message(), "out of memory")) {
        /* a failed allocation is no sign that the file is a plain image: reading it as
           one would drop its albedo and normal without a word (tests/common/test_alloc) */
        return -1;
    } else {
        mcp_error_clear();
        int idx[3];
        if (mcp_rgb_channels(img, idx) || mcp_image_copy_channels(img, idx, 3, &rgb))
            return -1;
    }
    if (mcp_image_set_source(rgb, img->source ? img->source : "candidate")) {
        mcp_image_free(rgb);
        mcp_dump_free(d);
        return -1;
    }
    r->albedos[r->n_files] = r->normals[r->n_files] = NULL;
    r->files[r->n_files++] = rgb;
    int rc = (d && d->albedo && mcp_image_copy(d->albedo, &r->albedos[r->n_files - 1])) ||
             (d && d->normal && mcp_image_copy(d->normal, &r->normals[r->n_files - 1]));
    mcp_dump_free(d);
    return rc ? -1 : 0;
}

/* The mean albedo and normal of the files, when every file has them (for the
 * denoiser). */
static int
finish_features(perc_run *r)
{
    mcp_image **lists[2] = {r->albedos, r->normals},
              **means[2] = {&r->albedo, &r->normal};
    for (int k = 0; k < 2; k++) {
        int all = r->n_files > 0;
        for (int i = 0; i < r->n_files; i++)
            all = all && lists[k][i];
        if (all &&
            mcp_perc_mean((const mcp_image *const *)lists[k], r->n_files, means[k]))
            return -1;
    }
    return 0;
}

static int
write_image(const perc_run *r, const mcp_image *img, const char *name, cJSON *outputs)
{
    char path[4400];
    snprintf(path, sizeof path, "%s/%s", r->out_dir, name);
    if (mcp_image_write(img, path, NULL)) return -1;
    cJSON_AddItemToArray(outputs, cJSON_CreateString(path));
    return 0;
}

/* The spectrum picture as a PNG, into the report. */
static int
write_spectrum(const perc_run *r, const mcp_image *pic, const char *name,
               const char *caption, cJSON *outputs)
{
    char path[4400], rel[600];
    unsigned char *rgb8 = mcp_malloc((size_t)pic->width * pic->height * 3);
    if (!rgb8) return -1;
    snprintf(path, sizeof path, "%s/%s", r->out_dir, name);
    snprintf(rel, sizeof rel, "%s%s", r->rel, name);
    int rc = mcp_colormap_apply(pic, 0, 0.0, 1.0, MCP_COLORMAP_INFERNO, rgb8) ||
             mcp_write_rgb8(rgb8, pic->width, pic->height, path) ||
             !mcp_report_add_map(r->section, rel, caption, MCP_COLORMAP_INFERNO, 0.0, 1.0,
                                 MCP_AXIS_LINEAR,
                                 "c ln(1 + power), scaled to 0..1 per picture: blue noise "
                                 "is dark at the centre of each tile");
    free(rgb8);
    if (!rc) cJSON_AddItemToArray(outputs, cJSON_CreateString(path));
    return rc ? -1 : 0;
}

/* Runs the re-render command for a permutation; *out the re-rendered colour. */
typedef struct {
    const perc_args *a;
    const perc_run *r;
} rerender_ctx;

static int
substitute(const char *tmpl, const char *perm, const char *out, const char *method,
           char *buf, size_t cap)
{
    size_t n = 0;
    for (const char *p = tmpl; *p; p++) {
        const char *v = NULL;
        size_t skip = 0;
        if (!strncmp(p, "{permutation}", 13))
            v = perm, skip = 13;
        else if (!strncmp(p, "{output}", 8))
            v = out, skip = 8;
        else if (!strncmp(p, "{method}", 8))
            v = method, skip = 8;
        if (v) {
            n += (size_t)snprintf(buf + n, n < cap ? cap - n : 0, "%s", v);
            p += skip - 1;
        } else if (n + 1 < cap) {
            buf[n++] = *p;
            buf[n] = '\0';
        } else {
            n++;
        }
        if (n >= cap) return mcp_error("rerender: the command is too long");
    }
    buf[n < cap ? n : cap - 1] = '\0';
    return 0;
}

static int
rerender(void *ctx, mcp_perc_method method, const mcp_image *perm, mcp_image **out)
{
    const rerender_ctx *c = ctx;
    const char *name = mcp_perc_method_name(method);
    char perm_path[4400], out_path[4400], cmd[16384];
    *out = NULL;
    snprintf(perm_path, sizeof perm_path, "%s/%s_permutation.exr", c->r->out_dir, name);
    snprintf(out_path, sizeof out_path, "%s/%s_rerendered.exr", c->r->out_dir, name);
    if (mcp_image_write(perm, perm_path, NULL) ||
        substitute(c->a->rerender, perm_path, out_path, name, cmd, sizeof cmd))
        return -1;
    remove(out_path);
    fflush(NULL);
    int status = system(cmd);
    if (status != 0) return mcp_error("rerender: '%s' failed (status %d)", cmd, status);
    mcp_image *img = NULL;
    if (mcp_image_read(out_path, NULL, &img))
        return mcp_error_prefix("rerender: '%s' wrote no image: ", cmd);
    perc_run tmp = {0};
    int rc = add_file(&tmp, img); /* its colour, by convention */
    mcp_image_free(img);
    if (!rc) {
        *out = tmp.files[0];
        tmp.files[0] = NULL;
    }
    run_free(&tmp);
    return rc;
}

typedef struct {
    const perc_run *r;
    mcp_perc_method primary;
    cJSON *outputs;
} keep_ctx;

/* The comparison's images: every method's result beside the primary one's. */
static int
keep_result(void *ctx, mcp_perc_method method, const mcp_perc_result *res,
            const mcp_image *again)
{
    const keep_ctx *k = ctx;
    char name[128];
    const mcp_image *img = again ? again : res->image;
    if (method == k->primary) return 0;
    snprintf(name, sizeof name, "%s.exr", mcp_perc_method_name(method));
    return write_image(k->r, img, name, k->outputs);
}

static void
add_number(cJSON *o, const char *key, double v)
{
    if (isfinite(v))
        cJSON_AddNumberToObject(o, key, v);
    else
        cJSON_AddNullToObject(o, key);
}

static void
add_scores(cJSON *o, const char *prefix, const mcp_perc_scores *s, int with_ref)
{
    char key[128];
    snprintf(key, sizeof key, "%senergy", prefix);
    add_number(o, key, s->energy);
    if (!with_ref) return;
    snprintf(key, sizeof key, "%spmse", prefix);
    add_number(o, key, s->pmse);
    snprintf(key, sizeof key, "%smse", prefix);
    add_number(o, key, s->mse);
    snprintf(key, sizeof key, "%slow_freq_fraction", prefix);
    add_number(o, key, s->low_freq_fraction);
}

/* The comparison as a report table. */
static int
add_table(cJSON *section, const cJSON *rows, double mean_pmse)
{
    static const char *const cols[] = {
        "method", "pMSE",    "pMSE / mean", "MSE", "low-frequency fraction",
        "energy", "seconds", "passes"};
    cJSON *t = mcp_report_add_table(section,
                                    "all methods on this input (Chizhov et al. "
                                    "2022 Table 1)",
                                    cols, 8);
    if (!t) return -1;
    const cJSON *row;
    cJSON_ArrayForEach(row, rows)
    {
        const cJSON *p = cJSON_GetObjectItem(row, "pmse");
        double pm = cJSON_IsNumber(p) ? p->valuedouble : NAN;
#define NUM(k)                                                                           \
    (cJSON_IsNumber(cJSON_GetObjectItem(row, k))                                         \
         ? cJSON_GetObjectItem(row, k)->valuedouble                                      \
         : NAN)
        /* a horizontal method's row measures its prediction unless it was re-rendered:
         * say so, since the prediction flatters it (the seeds were not re-rendered) */
        const cJSON *again = cJSON_GetObjectItem(row, "rerendered");
        char method[64];
        snprintf(method, sizeof method, "%s%s", cJSON_GetObjectItem(row, "method")->valuestring,
                 !again ? "" : cJSON_IsTrue(again) ? " (re-rendered)" : " (prediction)");
        if (mcp_report_table_add_row(t, "sddddddd", method, pm,
                                     pm / mean_pmse, NUM("mse"), NUM("low_freq_fraction"),
                                     NUM("energy"), NUM("seconds"), NUM("passes")))
            return -1;
#undef NUM
    }
    return 0;
}

/* Everything after the inputs are loaded. *summary receives the figures, *result (may
 * be NULL) a copy of the image measured (the re-rendered one when there is one). */
static int
run(perc_args *a, perc_run *r, cJSON **summary, mcp_image **result)
{
    int rc = -1, m = 0;
    mcp_image **cands = NULL, *mean = NULL, *surr_own = NULL, *again = NULL, *spec = NULL;
    mcp_image *mean_spec = NULL;
    mcp_perc_result res = {0};
    cJSON *s = cJSON_CreateObject(), *outputs = NULL, *table = NULL;
    *summary = NULL;
    if (result) *result = NULL;
    if (!s) return mcp_error("out of memory");
    outputs = cJSON_AddArrayToObject(s, "outputs");
    /* candidates: the files averaged in groups */
    if (r->n_files < 1 || r->n_files % a->group) {
        mcp_error("perceptual: %d candidate files do not split into groups of %d",
                  r->n_files, a->group);
        goto done;
    }
    m = r->n_files / a->group;
    if (!(cands = mcp_calloc((size_t)m, sizeof *cands))) goto done;
    for (int j = 0; j < m; j++)
        if (a->group == 1
                ? mcp_image_copy(r->files[j], &cands[j])
                : mcp_perc_mean((const mcp_image *const *)r->files + j * a->group,
                                a->group, &cands[j]))
            goto done;
    const mcp_image *const *cc = (const mcp_image *const *)cands;
    if (mcp_perc_mean(cc, m, &mean)) goto done;
    /* the model's borrowed inputs */
    a->opt.model.confidence_map = r->confidence_map;
    if (r->kernel_img) {
        int kw = r->kernel_img->width, kh = r->kernel_img->height;
        double *k = mcp_malloc((size_t)kw * kh * sizeof *k);
        if (!k) goto done;
        for (int y = 0; y < kh; y++)
            for (int x = 0; x < kw; x++)
                k[y * kw + x] = mcp_image_px(r->kernel_img, x, y)[0];
        free(a->kernel);
        a->kernel = k;
        a->opt.model.user_kernel = k;
        a->opt.model.user_kernel_width = kw, a->opt.model.user_kernel_height = kh;
    }
    /* the surrogate */
    const mcp_image *surr = NULL;
    char surr_desc[256];
    if (!strcmp(a->surrogate, "reference")) {
        if (!r->reference) {
            mcp_error("perceptual: surrogate 'reference' needs a reference (--ref)");
            goto done;
        }
        surr = r->reference;
        snprintf(surr_desc, sizeof surr_desc, "reference");
    } else if (!strcmp(a->surrogate, "denoise")) {
        mcp_note("perceptual: denoising the mean of %d candidates with '%s'", m,
                 r->den->name ? r->den->name : "?");
        if (mcp_perc_surrogate_denoise(cc, m, r->albedo, r->normal, r->den, &surr_own))
            goto done;
        surr = surr_own;
        snprintf(surr_desc, sizeof surr_desc, "denoise (%s)",
                 r->den->name ? r->den->name : "?");
    } else {
        surr = r->surrogate_img;
        snprintf(surr_desc, sizeof surr_desc, "%s", a->surrogate);
    }
    if (surr_own && write_image(r, surr_own, "surrogate.exr", outputs))
        goto done; /* (a given surrogate is not copied) */
    /* the method */
    const char *name = mcp_perc_method_name(a->opt.method);
    mcp_note("perceptual: %s on %d candidates of %dx%d", name, m, cands[0]->width,
             cands[0]->height);
    if (mcp_perc_optimize(cc, m, surr, &a->opt, &res)) goto done;
    char file[160];
    snprintf(file, sizeof file, "%s.exr", name);
    if (write_image(r, res.image, file, outputs)) goto done;
    if (res.index) {
        snprintf(file, sizeof file, "%s_index.exr", name);
        if (write_image(r, res.index, file, outputs)) goto done;
    }
    rerender_ctx rc_ctx = {a, r};
    if (res.permutation) {
        if (a->rerender) {
            if (rerender(&rc_ctx, a->opt.method, res.permutation, &again)) goto done;
            char p[4400];
            snprintf(p, sizeof p, "%s/%s_permutation.exr", r->out_dir, name);
            cJSON_AddItemToArray(outputs, cJSON_CreateString(p));
            snprintf(p, sizeof p, "%s/%s_rerendered.exr", r->out_dir, name);
            cJSON_AddItemToArray(outputs, cJSON_CreateString(p));
        } else {
            snprintf(file, sizeof file, "%s_permutation.exr", name);
            if (write_image(r, res.permutation, file, outputs)) goto done;
        }
    }
    /* figures */
    cJSON_AddStringToObject(s, "method", name);
    cJSON_AddNumberToObject(s, "candidates", m);
    cJSON_AddNumberToObject(s, "width", cands[0]->width);
    cJSON_AddNumberToObject(s, "height", cands[0]->height);
    cJSON_AddStringToObject(s, "surrogate", surr_desc);
    cJSON_AddStringToObject(s, "tone_map", mcp_tonemap_name(a->opt.model.tone_map));
    add_number(s, "confidence", r->confidence_map ? NAN : a->opt.model.confidence);
    cJSON_AddNumberToObject(s, "passes", res.passes);
    cJSON_AddNumberToObject(s, "changes", (double)res.changes);
    add_number(s, "seconds", res.seconds);
    add_number(s, "energy_initial", res.energy_initial);
    add_number(s, "energy_final", res.energy_final);
    mcp_perc_scores sc, sm;
    const mcp_image *measured = again ? again : res.image;
    if (mcp_perc_score(measured, surr, mean, r->reference, &a->opt.model, a->spectra_tile,
                       &sc, &spec) ||
        mcp_perc_score(mean, surr, mean, r->reference, &a->opt.model, a->spectra_tile,
                       &sm, &mean_spec))
        goto done;
    if (res.permutation) /* else the prediction is what is measured */
        cJSON_AddBoolToObject(s, "rerendered", again != NULL);
    if (again) {
        mcp_perc_scores sp;
        if (mcp_perc_score(res.image, surr, mean, r->reference, &a->opt.model,
                           a->spectra_tile, &sp, NULL))
            goto done;
        add_scores(s, "prediction_", &sp, r->reference != NULL);
    }
    add_scores(s, "", &sc, r->reference != NULL);
    add_scores(s, "mean_", &sm, r->reference != NULL);
    if (r->reference) {
        add_number(s, "pmse_ratio", sc.pmse / sm.pmse);
        add_number(s, "white_fraction", sc.white_fraction);
    }
    if (spec) {
        char caption[160];
        snprintf(file, sizeof file, "%s_spectrum.png", name);
        snprintf(caption, sizeof caption, "%s: error power spectrum per %dx%d tile", name,
                 a->spectra_tile, a->spectra_tile);
        if (write_spectrum(r, spec, file, caption, outputs) ||
            write_spectrum(r, mean_spec, "mean_spectrum.png",
                           "the candidates' mean: error power spectrum (white noise)",
                           outputs))
            goto done;
    }
    /* the comparison */
    if (a->compare) {
        mcp_note("perceptual: comparing every method");
        mcp_perc_compare_options co = mcp_perc_compare_defaults();
        keep_ctx kc = {r, a->opt.method, outputs};
        co.base = a->opt;
        co.reference = r->reference;
        co.spectra_tile = a->spectra_tile;
        co.on_result = keep_result;
        co.on_result_ctx = &kc;
        if (a->rerender) {
            co.rerender = rerender;
            co.rerender_ctx = &rc_ctx;
        }
        if (mcp_perc_compare(cc, m, surr, &co, &table)) goto done;
        if (r->section && add_table(r->section, table, sm.pmse)) goto done;
        cJSON_AddItemToObject(s, "comparison", table);
        table = NULL;
    }
    if (result && mcp_image_copy(again ? again : res.image, result)) goto done;
    *summary = s;
    s = NULL;
    rc = 0;
done:
    if (cands)
        for (int j = 0; j < m; j++)
            mcp_image_free(cands[j]);
    free(cands);
    mcp_image_free(mean), mcp_image_free(surr_own), mcp_image_free(again);
    mcp_image_free(spec), mcp_image_free(mean_spec);
    mcp_perc_result_free(&res);
    cJSON_Delete(s);
    cJSON_Delete(table);
    return rc;
}

static double
summary_number(const cJSON *s, const char *key)
{
    const cJSON *v = cJSON_GetObjectItem(s, key);
    return cJSON_IsNumber(v) ? v->valuedouble : NAN;
}

/* The section's verdict from the summary: with a reference, pMSE against the
 * candidates' mean (below 1: the method lowered the perceived error) and how much of
 * the error's power is at low frequencies (blue noise: less than the mean's white
 * noise); without one, what the optimisation did to its own energy. */
static void
perceptual_verdict(cJSON *section, const cJSON *summary)
{
    const cJSON *mj = cJSON_GetObjectItem(summary, "method");
    const char *method = cJSON_IsString(mj) ? mj->valuestring : "the method";
    double ratio = summary_number(summary, "pmse_ratio"),
           low = summary_number(summary, "low_freq_fraction"),
           mean_low = summary_number(summary, "mean_low_freq_fraction");
    int rc;
    if (!isnan(ratio))
        rc = mcp_report_set_verdict(
            section, ratio < 1 ? MCP_VERDICT_GOOD : MCP_VERDICT_BAD,
            "%s: pMSE %.3g\u00d7 the candidates' mean (%.2g%% %s perceived error); "
            "low-frequency share of the error %.3g against the mean's %.3g: %s",
            method, ratio, 100 * fabs(1 - ratio), ratio < 1 ? "less" : "more: no gain",
            low, mean_low,
            low < mean_low ? "bluer noise" : "no bluer than the mean's white noise");
    else
        rc = mcp_report_set_verdict(
            section, MCP_VERDICT_INFO,
            "%s: energy %.4g to %.4g in %.0f passes (the model's own error; give a "
            "reference for the true pMSE)",
            method, summary_number(summary, "energy_initial"),
            summary_number(summary, "energy_final"), summary_number(summary, "passes"));
    if (rc) mcp_error_clear(); /* the figures are in; the page shows no verdict */
}

/* Copies the summary's members into the report section, with a verdict. */
static void
fill_section(cJSON *section, const cJSON *summary)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, summary)
    {
        if (!strcmp(it->string, "comparison")) continue; /* in the section's table */
        cJSON_AddItemToObject(section, it->string, cJSON_Duplicate(it, 1));
    }
    perceptual_verdict(section, summary);
}

static void
print_summary(const cJSON *s)
{
    const cJSON *pm = cJSON_GetObjectItem(s, "pmse");
#define STR(k) cJSON_GetObjectItem(s, k)->valuestring
#define NUM(k) cJSON_GetObjectItem(s, k)->valuedouble
    printf("method:      %s on %d candidates of %dx%d\n", STR("method"),
           (int)NUM("candidates"), (int)NUM("width"), (int)NUM("height"));
    printf("surrogate:   %s\n", STR("surrogate"));
    printf("passes:      %d (%.0f changes, %.3f s)\n", (int)NUM("passes"), NUM("changes"),
           cJSON_IsNumber(cJSON_GetObjectItem(s, "seconds")) ? NUM("seconds") : 0.0);
    if (cJSON_IsNumber(pm)) {
        printf("pMSE:        %.6g (candidates' mean %.6g; ratio %.3f)%s\n", NUM("pmse"),
               NUM("mean_pmse"), NUM("pmse_ratio"),
               !cJSON_GetObjectItem(s, "rerendered")                ? ""
               : cJSON_IsTrue(cJSON_GetObjectItem(s, "rerendered")) ? ", re-rendered"
                                                                    : ", the prediction");
        printf("MSE:         %.6g (mean %.6g)\n", NUM("mse"), NUM("mean_mse"));
        if (cJSON_IsNumber(cJSON_GetObjectItem(s, "low_freq_fraction")))
            printf(
                "low-freq:    %.4f of the error spectrum (mean %.4f, white noise %.4f)\n",
                NUM("low_freq_fraction"), NUM("mean_low_freq_fraction"),
                NUM("white_fraction"));
    }
    const cJSON *t = cJSON_GetObjectItem(s, "comparison"), *row;
    if (t) {
        printf("\n%-20s %12s %12s %12s %10s %9s\n", "method", "pMSE", "MSE", "energy",
               "low-freq", "seconds");
        cJSON_ArrayForEach(row, t)
        {
#define RN(k)                                                                            \
    (cJSON_IsNumber(cJSON_GetObjectItem(row, k))                                         \
         ? cJSON_GetObjectItem(row, k)->valuedouble                                      \
         : NAN)
            const cJSON *again = cJSON_GetObjectItem(row, "rerendered");
            char secs[32] = "-";
            if (isfinite(RN("seconds")))
                snprintf(secs, sizeof secs, "%.4f", RN("seconds"));
            printf("%-20s %12.6g %12.6g %12.6g %10.4f %9s%s\n",
                   cJSON_GetObjectItem(row, "method")->valuestring, RN("pmse"), RN("mse"),
                   RN("energy"), RN("low_freq_fraction"), secs,
                   !again                ? ""
                   : cJSON_IsTrue(again) ? "  (re-rendered)"
                                         : "  (prediction)");
#undef RN
        }
    }
    const cJSON *o;
    printf("\nwrote:\n");
    cJSON_ArrayForEach(o, cJSON_GetObjectItem(s, "outputs"))
        printf("  %s\n", o->valuestring);
#undef STR
#undef NUM
}

/* ---- the subcommand ---- */

static const char usage[] =
    "usage: mcpost perceptual [options] CANDIDATES...\n"
    "  Perceptual error optimisation (Chizhov et al. 2022): picks, per pixel, one of "
    "the\n"
    "  candidate renders (vertical methods) or permutes pixels' seeds (horizontal) so\n"
    "  that the error is least visible. Candidates are images or render dumps of few\n"
    "  samples each, e.g. 4 single-sample renders.\n"
    "  --method M          vertical-iterative [default], power-set, error-diffusion,\n"
    "                      dither, horizontal, histogram, permutation\n"
    "  --surrogate S       denoise [default: the denoiser on the candidates' mean],\n"
    "                      reference (the ground truth: best case), or an image FILE\n"
    "  --denoiser NAME     the surrogate's denoiser [default: unet with the shipped\n"
    "                      weights; nlm when the candidates have no albedo and normal];\n"
    "                      its settings:\n"
    MCP_CLI_DENOISER_USAGE("")
    "  --ref FILE          ground truth: pMSE, MSE and the error spectrum\n"
    "  --confidence C      trust in the surrogate, in [0, 1] [1], or a per-pixel FILE\n"
    "  --group N           average N consecutive files into one candidate [1]\n"
    "  --compare           also run every method on the input: the comparison table\n"
    "  --rerender CMD      for horizontal methods: a shell command that re-renders with\n"
    "                      the permutation map {permutation} into the image {output}\n"
    "                      ({method} names the method); the result is then measured\n"
    "  -o, --output DIR    output folder [perceptual]\n"
    "  --json              print the figures as JSON\n"
    "  model: --tone-map clamp|aces|none [clamp]; --kernel tap3|gaussian|a,b,c "
    "(separable\n"
    "         taps)|FILE (a 2D kernel image) [tap3]; --dpi R [300], --distance INCHES "
    "[16]\n"
    "         (gaussian); --filter-surrogate (h = g instead of delta)\n"
    "  search: --passes T [100 vertical, 10 horizontal]; --init random|mean [random];\n"
    "         --seed S [1]; --max-subsets N [64]; --radius R [1]; --travel r [1];\n"
    "         --tile N [8] (permutation baseline)\n"
    "  mask:  --mask-size N [128]; --mask-sigma S [1.5]; --mask-seed S [1]; --no-cache\n"
    "         (the mask is cached in $XDG_CACHE_HOME/mcpost or ~/.cache/mcpost)\n"
    "  --spectra-tile N    tiles of the error spectrum [32]\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost perceptual samples/fixtures/cornell/singles/cornell_single0[0-3].exr \\\n"
    "                    --ref samples/fixtures/cornell/cornell_reference.exr -o out/perceptual\n"
    "  mcpost perceptual --compare --surrogate reference --ref samples/fixtures/cornell/cornell_reference.exr \\\n"
    "                    samples/fixtures/cornell/singles/cornell_single0[0-3].exr -o out/compare\n"
    "  mcpost perceptual --group 4 --method error-diffusion \\\n"
    "                    samples/fixtures/texture/singles/texture_single*.exr -o out/perceptual_texture\n";

static int
read_rgb(const char *path, mcp_image **out)
{
    mcp_image *img = NULL;
    perc_run tmp = {0};
    *out = NULL;
    if (mcp_image_read(path, NULL, &img)) return -1;
    int rc = add_file(&tmp, img);
    mcp_image_free(img);
    if (!rc) {
        *out = tmp.files[0];
        tmp.files[0] = NULL;
    }
    run_free(&tmp);
    return rc;
}

static int
cmd_perceptual(int argc, char **argv)
{
    enum { O_JSON = 1000, O_FILTER, O_NOCACHE, O_COMPARE };
    static const struct option longs[] = {
        {"method", required_argument, 0, 'm'},
        {"surrogate", required_argument, 0, 's'},
        {"ref", required_argument, 0, 'r'},
        {"reference", required_argument, 0, 'r'},
        {"output", required_argument, 0, 'o'},
        {"json", no_argument, 0, O_JSON},
        MCP_CLI_DENOISER_LONGOPTS,
        {"filter-surrogate", no_argument, 0, O_FILTER},
        {"no-cache", no_argument, 0, O_NOCACHE},
        {"compare", no_argument, 0, O_COMPARE},
        {"confidence", required_argument, 0, 'W'},
        {"group", required_argument, 0, 'W'},
        {"tone-map", required_argument, 0, 'W'},
        {"kernel", required_argument, 0, 'W'},
        {"dpi", required_argument, 0, 'W'},
        {"distance", required_argument, 0, 'W'},
        {"passes", required_argument, 0, 'W'},
        {"init", required_argument, 0, 'W'},
        {"seed", required_argument, 0, 'W'},
        {"max-subsets", required_argument, 0, 'W'},
        {"radius", required_argument, 0, 'W'},
        {"travel", required_argument, 0, 'W'},
        {"tile", required_argument, 0, 'W'},
        {"mask-size", required_argument, 0, 'W'},
        {"mask-sigma", required_argument, 0, 'W'},
        {"mask-seed", required_argument, 0, 'W'},
        {"rerender", required_argument, 0, 'W'},
        {"spectra-tile", required_argument, 0, 'W'},
        {"help", no_argument, 0, 'h'},
        {0, 0, 0, 0}};
    perc_args a;
    perc_run r;
    args_init(&a);
    memset(&r, 0, sizeof r);
    const char *out_dir = "perceptual", *ref_path = NULL;
    mcp_cli_denoiser_flags df = {0}; /* no --denoiser: the default */
    int json = 0, opt, idx = 0, status = 1;
    mcp_image *ref = NULL, *surr = NULL, *conf = NULL, *kern = NULL;
    mcp_report *report = NULL;
    cJSON *summary = NULL;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "m:s:r:o:h", longs, &idx)) != -1) {
        int rc = mcp_cli_denoiser_flag(&df, opt, optarg);
        if (rc < 0) goto fail;
        if (rc) continue;
        switch (opt) {
        case 'm':
            rc = set_word(&a, "method", optarg);
            break;
        case 's':
            rc = set_word(&a, "surrogate", optarg);
            break;
        case 'r':
            ref_path = optarg;
            break;
        case 'o':
            out_dir = optarg;
            break;
        case O_JSON:
            json = 1;
            break;
        case O_FILTER:
            a.opt.model.filter_surrogate = 1;
            break;
        case O_NOCACHE:
            a.opt.mask.use_cache = 0;
            break;
        case O_COMPARE:
            a.compare = 1;
            break;
        case 'W': {
            char key[64];
            snprintf(key, sizeof key, "%s", longs[idx].name);
            for (char *p = key; *p; p++)
                *p = *p == '-' ? '_' : *p;
            rc = set_word(&a, key, optarg);
            break;
        }
        case 'h':
            fputs(usage, stdout);
            status = 0;
            goto done;
        default:
            status = mcp_cli_usage("perceptual", "bad option");
            goto done;
        }
        if (rc) {
            status = mcp_cli_fail();
            goto done;
        }
    }
    if (optind >= argc) {
        status = mcp_cli_usage("perceptual", "no candidate files given");
        goto done;
    }
    for (int i = optind; i < argc; i++) {
        mcp_image *img = NULL;
        if (mcp_image_read(argv[i], NULL, &img) || add_file(&r, img)) {
            mcp_image_free(img);
            goto fail;
        }
        mcp_image_free(img);
    }
    if (finish_features(&r)) goto fail;
    if (ref_path && read_rgb(ref_path, &ref)) goto fail;
    r.reference = ref;
    if (strcmp(a.surrogate, "denoise") && strcmp(a.surrogate, "reference")) {
        if (read_rgb(a.surrogate, &surr)) goto fail;
        r.surrogate_img = surr;
    }
    if (a.confidence) {
        if (mcp_image_read(a.confidence, NULL, &conf)) goto fail;
        r.confidence_map = conf;
    }
    if (a.kernel_file) {
        if (mcp_image_read(a.kernel_file, NULL, &kern)) goto fail;
        r.kernel_img = kern;
    }
    if (!strcmp(a.surrogate, "denoise") &&
        mcp_cli_denoiser_create(&df, &r.den))
        goto fail;
    if (mcp_make_dirs(out_dir) || mcp_report_new("mcpost perceptual", &report)) goto fail;
    snprintf(r.out_dir, sizeof r.out_dir, "%s", out_dir);
    if (!(r.section = mcp_report_section(report, "perceptual",
                                         mcp_perc_method_name(a.opt.method))))
        goto fail;
    if (run(&a, &r, &summary, NULL)) goto fail;
    fill_section(r.section, summary);
    if (mcp_report_write(report, out_dir)) goto fail;
    if (json)
        mcp_cli_print_json(summary);
    else {
        print_summary(summary);
        cJSON_Delete(summary);
    }
    summary = NULL;
    status = 0;
    goto done;
fail:
    status = mcp_cli_fail();
done:
    cJSON_Delete(summary);
    mcp_report_free(report);
    mcp_image_free(ref), mcp_image_free(surr), mcp_image_free(conf), mcp_image_free(kern);
    run_free(&r);
    args_free(&a);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_perceptual = {
    "perceptual", "perceptual error optimisation of few-sample renders (Chizhov 2022)",
    cmd_perceptual};

/* ---- the job stage ---- */

static const char *const perceptual_keys[] = {"name",
                                              "candidates",
                                              "method",
                                              "surrogate",
                                              "denoiser",
                                              "reference",
                                              "confidence",
                                              "group",
                                              "tone_map",
                                              "kernel",
                                              "dpi",
                                              "distance",
                                              "filter_surrogate",
                                              "passes",
                                              "init",
                                              "seed",
                                              "max_subsets",
                                              "radius",
                                              "travel",
                                              "tile",
                                              "mask_size",
                                              "mask_sigma",
                                              "mask_seed",
                                              "cache",
                                              "compare",
                                              "rerender",
                                              "spectra_tile",
                                              NULL};

/* Loads the candidates: a series input (every member a dump or image) or a list of
 * input names (images or dumps; their colour only). */
static int
stage_candidates(mcp_job *job, const mcp_node *settings, perc_run *r)
{
    const mcp_node *n = NULL;
    if (mcp_node_require(settings, "candidates", "stage 'perceptual'", &n)) return -1;
    if (n->kind == MCP_NODE_SCALAR) {
        const mcp_series *s = NULL;
        if (mcp_job_series(job, settings, "candidates", &s)) return -1;
        for (int i = 0; i < s->count; i++) {
            mcp_image *img = NULL;
            if (mcp_image_read(s->paths[i], NULL, &img) || add_file(r, img)) {
                mcp_image_free(img);
                return mcp_node_error(n, "%s", mcp_error_message());
            }
            mcp_image_free(img);
        }
    } else if (n->kind == MCP_NODE_SEQ) {
        for (int i = 0; i < n->count; i++) {
            const char *name;
            if (mcp_node_string(n->items[i], "candidates", &name)) return -1;
            const mcp_image *img = mcp_job_find_image(job, name);
            if (!img)
                return mcp_node_error(
                    n->items[i], "no image input or result called '%s'%s%s", name,
                    *mcp_error_message() ? ": " : "", mcp_error_message());
            if (add_file(r, img))
                return mcp_node_error(n->items[i], "%s", mcp_error_message());
        }
    } else {
        return mcp_node_error(n,
                              "candidates must name a series input or list image inputs");
    }
    return finish_features(r);
}

/* The stage's settings, read before anything is loaded (by the run, and by the job's
 * check before any stage runs): every word into `a` (as the flags), the result's
 * name, the inputs it names (candidates, reference, surrogate, confidence: checked
 * against the job's inputs and earlier results), the kernel file, and the surrogate's
 * denoiser (*den, the caller's to free). Declares the result for later stages. */
static int
parse_perceptual(mcp_job *job, const mcp_node *settings, perc_args *a, const char **name,
                 mcp_denoiser **den)
{
    *name = "perceptual";
    *den = NULL;
    for (int i = 0; i < settings->count; i++) {
        const char *key = settings->keys[i]->value;
        const mcp_node *v = settings->items[i];
        if (!strcmp(key, "candidates") || !strcmp(key, "denoiser") ||
            !strcmp(key, "reference") || !strcmp(key, "name"))
            continue;
        if (!strcmp(key, "kernel") && v->kind == MCP_NODE_SEQ) {
            double *t = NULL;
            int n = 0;
            if (mcp_node_opt_doubles(settings, "kernel", &t, &n)) return -1;
            int bad = parse_taps(a, t, n);
            free(t);
            if (bad) return mcp_node_error(v, "%s", mcp_error_message());
            continue;
        }
        if (v->kind != MCP_NODE_SCALAR)
            return mcp_node_error(v, "%s must be a single value", key);
        if (set_word(a, key, v->value)) return mcp_node_error(v, "%s", mcp_error_message());
    }
    const mcp_node *n = NULL;
    if (mcp_node_opt_string(settings, "name", name) ||
        mcp_node_require(settings, "candidates", "stage 'perceptual'", &n))
        return -1;
    if (n->kind == MCP_NODE_SCALAR) {
        if (mcp_job_check_name(job, n, MCP_JOB_SERIES)) return -1;
    } else if (n->kind == MCP_NODE_SEQ) {
        for (int i = 0; i < n->count; i++)
            if (mcp_job_check_name(job, n->items[i], MCP_JOB_IMAGE)) return -1;
    } else {
        return mcp_node_error(n,
                              "candidates must name a series input or list image inputs");
    }
    if ((mcp_node_get(settings, "reference") &&
         mcp_job_check_input(job, settings, "reference", MCP_JOB_IMAGE)) ||
        (strcmp(a->surrogate, "denoise") && strcmp(a->surrogate, "reference") &&
         mcp_job_check_input(job, settings, "surrogate", MCP_JOB_IMAGE)) ||
        (a->confidence && mcp_job_check_input(job, settings, "confidence", MCP_JOB_IMAGE)) ||
        (a->kernel_file && mcp_job_check_file(job, mcp_node_get(settings, "kernel"), "kernel")))
        return -1;
    if (!strcmp(a->surrogate, "denoise") && mcp_cli_stage_denoiser(job, settings, den))
        return -1;
    return mcp_job_declare(job, *name, MCP_JOB_IMAGE);
}

static int
check_perceptual(mcp_job *job, const mcp_node *settings)
{
    perc_args a;
    args_init(&a);
    const char *name;
    mcp_denoiser *den = NULL;
    int rc = parse_perceptual(job, settings, &a, &name, &den);
    mcp_denoiser_free(den);
    args_free(&a);
    return rc;
}

static int
stage_perceptual(mcp_job *job, const mcp_node *settings)
{
    perc_args a;
    perc_run r;
    args_init(&a);
    memset(&r, 0, sizeof r);
    int rc = -1;
    const char *name = "perceptual";
    cJSON *summary = NULL;
    mcp_image *kern = NULL, *img = NULL;
    if (parse_perceptual(job, settings, &a, &name, &r.den) ||
        stage_candidates(job, settings, &r))
        goto done;
    if (mcp_node_get(settings, "reference") &&
        mcp_job_image(job, settings, "reference", &r.reference))
        goto done;
    if (strcmp(a.surrogate, "denoise") && strcmp(a.surrogate, "reference") &&
        mcp_job_image(job, settings, "surrogate", &r.surrogate_img))
        goto done;
    if (a.confidence && mcp_job_image(job, settings, "confidence", &r.confidence_map))
        goto done;
    if (a.kernel_file) {
        char path[4096];
        if (mcp_job_resolve(job, a.kernel_file, path, sizeof path) ||
            mcp_image_read(path, NULL, &kern)) {
            mcp_node_error(mcp_node_get(settings, "kernel"), "%s", mcp_error_message());
            goto done;
        }
        r.kernel_img = kern;
    }
    /* outputs in <output>/<name>/, images relative to the report */
    char probe[4600];
    snprintf(r.rel, sizeof r.rel, "%s/", name);
    snprintf(probe, sizeof probe, "%s/x", name);
    char path[4096];
    if (mcp_job_output_path(job, probe, path, sizeof path)) goto done;
    snprintf(r.out_dir, sizeof r.out_dir, "%s/%s", mcp_job_output_dir(job), name);
    char title[300];
    snprintf(title, sizeof title, "%s: %s", name, mcp_perc_method_name(a.opt.method));
    if (!(r.section = mcp_report_section(mcp_job_report(job), "perceptual", title)) ||
        run(&a, &r, &summary, &img))
        goto done;
    fill_section(r.section, summary);
    /* the result, for later stages: NAME (the job takes it) */
    const char *m = mcp_perc_method_name(a.opt.method);
    if (mcp_image_set_source(img, name) || mcp_job_put_image(job, name, img)) {
        img = NULL;
        goto done;
    }
    img = NULL;
    const cJSON *pm = cJSON_GetObjectItem(summary, "pmse");
    const cJSON *again = cJSON_GetObjectItem(summary, "rerendered");
    if (cJSON_IsNumber(pm))
        mcp_note("%s: %s %spMSE %.4g (%.3f of the mean's)", name, m,
                 again && !cJSON_IsTrue(again) ? "prediction " : "", pm->valuedouble,
                 cJSON_GetObjectItem(summary, "pmse_ratio")->valuedouble);
    else
        mcp_note("%s: %s done", name, m);
    rc = 0;
done:
    mcp_image_free(img);
    cJSON_Delete(summary);
    mcp_image_free(kern);
    run_free(&r);
    args_free(&a);
    return rc;
}

const mcp_stage mcp_stage_perceptual = {
    "perceptual",
    "perceptual error optimisation of few-sample renders, with scores and the comparison "
    "of every method",
    perceptual_keys, stage_perceptual, check_perceptual};
