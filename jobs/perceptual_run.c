/* perceptual_run.c: perceptual error optimisation of M candidate renders, for `mcpost
 * perceptual` and the `perceptual` job stage alike (docs/mathematics.md §4;
 * perceptual.h): the run's settings from the perceptual table's (ops/op_perceptual.c),
 * the candidates and their features, the run with its files (the optimised
 * image, for horizontal methods the prediction and the permutation map, the re-rendered
 * image when a re-render command is given, the surrogate, the scores against a reference
 * and the error spectra), the comparison of every method (Chizhov et al. 2022 Table 1)
 * and the report section. */
#define _POSIX_C_SOURCE 200809L /* WEXITSTATUS */

#include "internal.h"
#include "../common/report/internal.h" /* maps of one value */

#include <mcpost/filter.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* ---- settings shared by the flags and the job keys ---- */

void
mcp__perc_args_init(mcp__perc_args *a)
{
    memset(a, 0, sizeof *a);
    a->opt = mcp_perc_defaults();
    a->surrogate = "denoise";
    a->group = 1;
    a->spectra_tile = 32;
}

void
mcp__perc_args_free(mcp__perc_args *a)
{
    free(a->kernel);
    a->kernel = NULL;
}

/* Separable taps "a,b,c" (odd count): the kernel is their outer product. */
int
mcp__perc_set_taps(mcp__perc_args *a, const double *t, int n)
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
set_kernel(mcp__perc_args *a, const char *v)
{
    if (!mcp_pkernel_kind_from_name(v, &a->opt.model.kernel.kind)) {
        a->opt.model.user_kernel = NULL;
        a->kernel_file = NULL;
        return 0;
    }
    mcp_error_clear();
    if (strchr(v, ',') || strspn(v, "0123456789.+-eE") == strlen(v)) {
        char **words = NULL;
        int n = 0, rc = mcp__split_words(v, &words, &n);
        double *t = rc ? NULL : mcp_malloc((size_t)(n ? n : 1) * sizeof *t);
        for (int i = 0; !rc && t && i < n; i++)
            rc = mcp__parse_double("kernel", words[i], &t[i]);
        rc = rc || !t || mcp__perc_set_taps(a, t, n);
        mcp__free_words(words, n);
        free(t);
        return rc ? -1 : 0;
    }
    a->kernel_file = v; /* a 2D kernel image */
    return 0;
}

/* A kernel's taps, one number an item (a job's list) */
static int
set_kernel_items(mcp__perc_args *a, const char *const *items, int n)
{
    double *t = mcp_malloc((size_t)n * sizeof *t);
    int rc = !t;
    for (int i = 0; !rc && i < n; i++)
        rc = mcp__parse_double("kernel", items[i], &t[i]);
    rc = rc || mcp__perc_set_taps(a, t, n);
    free(t);
    return rc ? -1 : 0;
}

int
mcp__perc_args_from_settings(const mcp_perceptual_settings *s, mcp__perc_args *a)
{
    mcp__perc_args_init(a);
    a->opt = s->opt;
    a->surrogate = s->surrogate;
    a->group = s->group;
    a->compare = s->compare;
    a->rerender = s->rerender;
    a->spectra_tile = s->spectra_tile;
    double c = 0.0;
    if (mcp__parse_double("confidence", s->confidence, &c) == 0) {
        a->opt.model.confidence = c;
    } else {
        mcp_error_clear();
        a->confidence = s->confidence; /* a per-pixel map */
    }
    if ((s->n_kernel == 1 && set_kernel(a, s->kernel[0])) ||
        (s->n_kernel > 1 && set_kernel_items(a, s->kernel, s->n_kernel)))
        return -1;
    return mcp_perc_check(&a->opt);
}

/* ---- the run, shared by the subcommand and the stage ---- */

void
mcp__perc_run_free(mcp__perc_run *r)
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
int
mcp__perc_add_file(mcp__perc_run *r, const mcp_image *img)
{
    mcp_dump *d = NULL;
    mcp_image *rgb = NULL;
    size_t n = (size_t)r->n_files + 1;
    mcp_image **files = mcp_realloc(r->files, n * sizeof *files);
    if (files) r->files = files;
    mcp_image **albedo = files ? mcp_realloc(r->albedos, n * sizeof *albedo) : NULL;
    if (albedo) r->albedos = albedo;
    mcp_image **normal = albedo ? mcp_realloc(r->normals, n * sizeof *normal) : NULL;
    if (!normal) return -1;
    r->normals = normal;
    if (mcp_dump_from_image(img, NULL, &d) ==
        0) { /* the dump's parts are the run's now */
        rgb = d->color;
        d->color = NULL;
    } else if (strstr(mcp_error_message(), "out of memory")) {
        /* a failed allocation is no sign that the file is a plain image: reading it as
           one would drop its albedo and normal without a word (tests/common/test_alloc)
         */
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
    r->albedos[r->n_files] = d ? d->albedo : NULL;
    r->normals[r->n_files] = d ? d->normal : NULL;
    r->files[r->n_files++] = rgb;
    if (d) d->albedo = d->normal = NULL;
    mcp_dump_free(d);
    return 0;
}

/* The mean albedo and normal of the files, when every file has them (for the
 * denoiser). */
int
mcp__perc_finish_features(mcp__perc_run *r)
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
write_image(const mcp__perc_run *r, const mcp_image *img, const char *name,
            cJSON *outputs)
{
    char path[4400];
    snprintf(path, sizeof path, "%s/%s", r->out_dir, name);
    if (mcp_image_write(img, path, NULL)) return -1;
    cJSON_AddItemToArray(outputs, cJSON_CreateString(path));
    return 0;
}

/* The spectrum picture as a PNG, into the report. */
static int
write_spectrum(const mcp__perc_run *r, const mcp_image *pic, const char *name,
               const char *caption, cJSON *outputs)
{
    char path[4400], rel[600];
    unsigned char *rgb8 = mcp_malloc((size_t)pic->width * pic->height * 3);
    if (!rgb8) return -1;
    snprintf(path, sizeof path, "%s/%s", r->out_dir, name);
    snprintf(rel, sizeof rel, "%s%s", r->rel, name);
    cJSON *map = NULL;
    int rc =
        mcp_colormap_apply(pic, 0, 0.0, 1.0, MCP_COLORMAP_INFERNO, rgb8) ||
        mcp_write_rgb8(rgb8, pic->width, pic->height, path) ||
        !(map = mcp_report_add_map(r->section, rel, caption, MCP_COLORMAP_INFERNO, 0.0,
                                   1.0, MCP_AXIS_LINEAR,
                                   "c ln(1 + power), scaled to 0..1 per picture: "
                                   "blue noise is dark at the centre of each tile")) ||
        mcp__report_map_one_value(map, pic, 0, 0, 1.0);
    free(rgb8);
    if (!rc) cJSON_AddItemToArray(outputs, cJSON_CreateString(path));
    return rc ? -1 : 0;
}

/* A render's picture for the report: NAME.png as a screen shows it (clamped, sRGB),
 * with NAME<exr_suffix>.exr (written already) as the linear values the page
 * re-exposes; exr_suffix NULL: NAME.exr. The caption starts with NAME. */
static int
write_render(const mcp__perc_run *r, const mcp_image *img, const char *exr_suffix,
             const char *name, const char *what, cJSON *outputs)
{
    char file[200], rel_png[800], rel_exr[800], caption[400];
    mcp_image *shown = NULL;
    snprintf(file, sizeof file, "%s.png", name);
    snprintf(rel_png, sizeof rel_png, "%s%s.png", r->rel, name);
    snprintf(rel_exr, sizeof rel_exr, "%s%s%s.exr", r->rel, name,
             exr_suffix ? exr_suffix : "");
    snprintf(caption, sizeof caption, "%s: %s", name, what);
    int rc = mcp_tonemap_apply(img, MCP_TONEMAP_CLAMP, &shown) ||
             write_image(r, shown, file, outputs) ||
             !mcp_report_add_hdr_image(r->section, rel_png, rel_exr, caption);
    mcp_image_free(shown);
    return rc ? -1 : 0;
}

/* Runs the re-render command for a permutation; *out the re-rendered colour. */
typedef struct {
    const mcp__perc_args *a;
    const mcp__perc_run *r;
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
    mcp__perc_run tmp = {0};
    int rc = mcp__perc_add_file(&tmp, img); /* its colour, by convention */
    mcp_image_free(img);
    if (!rc) {
        *out = tmp.files[0];
        tmp.files[0] = NULL;
    }
    mcp__perc_run_free(&tmp);
    return rc;
}

typedef struct {
    const mcp__perc_run *r;
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
add_scores(cJSON *o, const char *prefix, const mcp_perc_scores *s, int with_ref)
{
    char key[128];
    snprintf(key, sizeof key, "%senergy", prefix);
    mcp_report_add_number(o, key, s->energy);
    if (!with_ref) return;
    snprintf(key, sizeof key, "%spmse", prefix);
    mcp_report_add_number(o, key, s->pmse);
    snprintf(key, sizeof key, "%smse", prefix);
    mcp_report_add_number(o, key, s->mse);
    snprintf(key, sizeof key, "%slow_freq_fraction", prefix);
    mcp_report_add_number(o, key, s->low_freq_fraction);
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
        snprintf(method, sizeof method, "%s%s",
                 cJSON_GetObjectItem(row, "method")->valuestring,
                 !again                ? ""
                 : cJSON_IsTrue(again) ? " (re-rendered)"
                                       : " (prediction)");
        if (mcp_report_table_add_row(t, "sddddddd", method, pm, pm / mean_pmse,
                                     NUM("mse"), NUM("low_freq_fraction"), NUM("energy"),
                                     NUM("seconds"), NUM("passes")))
            return -1;
#undef NUM
    }
    return 0;
}

/* Everything after the inputs are loaded. *summary receives the figures, *result (may
 * be NULL) a copy of the image measured (the re-rendered one when there is one). */
int
mcp__perceptual_run(mcp__perc_args *a, mcp__perc_run *r, cJSON **summary,
                    mcp_image **result)
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
    mcp_report_add_number(s, "confidence",
                          r->confidence_map ? NAN : a->opt.model.confidence);
    cJSON_AddNumberToObject(s, "passes", res.passes);
    cJSON_AddNumberToObject(s, "changes", (double)res.changes);
    mcp_report_add_number(s, "seconds", res.seconds);
    mcp_report_add_number(s, "energy_initial", res.energy_initial);
    mcp_report_add_number(s, "energy_final", res.energy_final);
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
        mcp_report_add_number(s, "pmse_ratio", sc.pmse / sm.pmse);
        mcp_report_add_number(s, "white_fraction", sc.white_fraction);
    }
    /* the pictures: the result beside the candidates' mean, for the wipe */
    if (r->section &&
        (write_render(r, measured, again ? "_rerendered" : "", name,
                      "the optimised image", outputs) ||
         write_image(r, mean, "mean.exr", outputs) ||
         write_render(r, mean, NULL, "mean",
                      "the candidates' mean (what averaging gives)", outputs)))
        goto done;
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

/* With the comparison table: "; X does better here (...)" when a method other than
 * the one run has a lower pMSE on this input, and why it is not the result: a
 * horizontal method's figure without a re-render is its prediction (it moves samples
 * between pixels, so only a re-render of the scene realises it). */
static void
best_other(const cJSON *summary, const char *method, double ratio, char *buf, size_t cap)
{
    const cJSON *row, *best = NULL;
    double mean = summary_number(summary, "mean_pmse"), best_ratio = ratio;
    cJSON_ArrayForEach(row, cJSON_GetObjectItem(summary, "comparison"))
    {
        const cJSON *mj = cJSON_GetObjectItem(row, "method");
        if (!cJSON_IsString(mj) || !strcmp(mj->valuestring, method) ||
            !strcmp(mj->valuestring, "mean") || !strcmp(mj->valuestring, "surrogate"))
            continue; /* the mean and the surrogate are no methods */
        double r = summary_number(row, "pmse") / mean;
        if (r < best_ratio) best_ratio = r, best = row;
    }
    if (!best) return;
    const char *name = cJSON_GetObjectItem(best, "method")->valuestring;
    const cJSON *again = cJSON_GetObjectItem(best, "rerendered");
    if (again && !cJSON_IsTrue(again))
        snprintf(buf, cap,
                 "; %s predicts %.3g\u00d7, but it moves samples between pixels: only a "
                 "re-render (rerender:) realises that",
                 name, best_ratio);
    else
        snprintf(buf, cap,
                 "; %s does better on this input (%.3g\u00d7; method: %s to use it)",
                 name, best_ratio, name);
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
    char other[400] = "";
    if (!isnan(ratio)) best_other(summary, method, ratio, other, sizeof other);
    if (!isnan(ratio))
        rc = mcp_report_set_verdict(
            section, ratio < 1 ? MCP_VERDICT_GOOD : MCP_VERDICT_BAD,
            "%s: pMSE %.3g\u00d7 the candidates' mean (%.2g%% %s perceived error); "
            "low-frequency share of the error %.3g against the mean's %.3g: %s%s",
            method, ratio, 100 * fabs(1 - ratio), ratio < 1 ? "less" : "more: no gain",
            low, mean_low,
            low < mean_low ? "bluer noise" : "no bluer than the mean's white noise",
            other);
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
void
mcp__perc_fill_section(cJSON *section, const cJSON *summary)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, summary)
    {
        if (!strcmp(it->string, "comparison")) continue; /* in the section's table */
        cJSON_AddItemToObject(section, it->string, cJSON_Duplicate(it, 1));
    }
    perceptual_verdict(section, summary);
}
