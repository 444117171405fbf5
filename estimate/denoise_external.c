/* denoise_external.c: the `external` denoiser -- any command that reads image files and
 * writes one, e.g. Open Image Denoise's oidnDenoise (docs/mathematics.md §2.1;
 * docs/oidn-network.md §5). It is a black box, so its Jacobian-vector product is the
 * finite difference (F(X + delta t) - F(X)) / delta, where t already carries the noise
 * scale and delta is unitless (exact = 0).
 *
 * Settings: command (required; a /bin/sh template with {color}, {albedo}, {normal} and
 * {output}, each replaced by a single-quoted path), format [pfm] (pfm or exr: the files
 * written and read), delta [0.1] (> 0), workdir [$TMPDIR or /tmp] (where the private
 * temporary folder of each run goes). Every run writes its inputs into a fresh
 * mkdtemp() folder, runs the command, reads {output} and removes the folder. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L /* mkdtemp */
#endif
#include <mcpost/denoiser.h>

#include "internal.h"

#include <mcpost/imageio.h>

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct {
    char *command;   /* the template */
    const char *ext; /* "pfm" or "exr" */
    double delta;    /* unitless finite-difference step */
    char *workdir;   /* NULL: $TMPDIR or /tmp */
    int needs_albedo, needs_normal;
} external_state;

/* ---- settings: the table (<mcpost/options.h>; docs/denoisers.md) ---- */

typedef struct {
    const char *command, *format, *workdir;
    double delta;
} external_settings;

static const mcp_option external_options[] = {
    {.name = "command",
     .type = MCP_OPT_TEXT,
     .offset = offsetof(external_settings, command),
     .meta = "CMD",
     .doc = "a /bin/sh command with {color} {albedo} {normal} {output} for its files "
            "(required); --denoiser-command"},
    {.name = "format",
     .type = MCP_OPT_TEXT,
     .offset = offsetof(external_settings, format),
     .def = "pfm",
     .doc = "the files' format: pfm or exr"},
    {.name = "delta",
     .type = MCP_OPT_NUMBER,
     .offset = offsetof(external_settings, delta),
     .def = "0.1",
     .doc = "finite-difference step of the JVP, in units of the tangent",
     .bounds = MCP_OPT_LO_OPEN},
    {.name = "workdir",
     .type = MCP_OPT_TEXT,
     .offset = offsetof(external_settings, workdir),
     .doc = "where the private folders go (relative to the job file) [$TMPDIR or /tmp]"},
    {0}};

static void
external_defaults(void *p)
{
    external_settings *e = p;
    e->format = "pfm";
    e->delta = 0.1;
}

const mcp_operation mcp__op_external = {
    .name = "external",
    .denoiser = 1,
    .summary = "any command that reads and writes image files; finite-difference JVP",
    .options = external_options,
    .size = sizeof(external_settings),
    .defaults = external_defaults,
};

/* The keys, from the table (denoisers.c fills them in before the kinds are handed
 * out). */
const char *mcp__external_keys[MCP__DENOISER_KEYS_MAX];

/* ---- running the command ---- */

/* The command line: the template with each {color}, {albedo}, {normal}, {output}
 * replaced by the quoted path (paths[i], in that order); other text is kept. */
static int
substitute(const char *tmpl, const char *const paths[4], char **out)
{
    static const char *const names[4] = {"{color}", "{albedo}", "{normal}", "{output}"};
    return mcp__shell_fill(tmpl, 4, names, paths, 0xF, out);
}

/* The 3 channels of the command's output: R,G,B, or all of them when exactly 3. */
static int
read_output(const external_state *s, const char *path, const mcp_image *color,
            mcp_image **out)
{
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *img = NULL, *o = NULL;
    if (mcp_image_read(path, NULL, &img))
        return mcp_error_prefix("external: command '%s': output: ", s->command);
    int idx[3], rc = -1;
    if (mcp_image_find_triple(img, &rgb, 1, idx))
        mcp_error("external: command '%s': output needs channels R,G,B or exactly 3 "
                  "channels (it has %d)",
                  s->command, img->channels);
    else if (img->width != color->width || img->height != color->height)
        mcp_error("external: command '%s': output is %dx%d, the input %dx%d", s->command,
                  img->width, img->height, color->width, color->height);
    else if (!mcp_image_copy_channels(img, idx, 3, &o)) {
        rc = 0;
        for (int c = 0; c < 3 && !rc; c++)
            rc = mcp_image_set_channel_name(o, c, rgb[c]);
        mcp_attrs_clear(&o->attrs);
        if (!rc) rc = mcp_image_set_source(o, "external");
    }
    mcp_image_free(img);
    if (rc) {
        mcp_image_free(o);
        return -1;
    }
    *out = o;
    return 0;
}

/* F(in): writes the inputs, runs the command, reads the output, cleans up. */
static int
run_external(const external_state *s, const mcp_denoise_input *in, mcp_image **out)
{
    *out = NULL;
    if (s->needs_albedo && !in->albedo)
        return mcp_error("external: command '%s' needs {albedo}, but the input has no "
                         "albedo",
                         s->command);
    if (s->needs_normal && !in->normal)
        return mcp_error("external: command '%s' needs {normal}, but the input has no "
                         "normal",
                         s->command);
    const char *base = s->workdir;
    if (!base || !*base) base = getenv("TMPDIR");
    if (!base || !*base) base = "/tmp";
    char dir[PATH_CAP - 32];
    if (mcp__scratch_dir_begin(base, "mcpost-external-", dir, sizeof dir))
        return mcp_error_prefix("external: workdir: ");
    static const char *const stems[4] = {"color", "albedo", "normal", "output"};
    char paths[4][PATH_CAP];
    for (int i = 0; i < 4; i++)
        snprintf(paths[i], sizeof paths[i], "%s/%s.%s", dir, stems[i], s->ext);
    const char *const path_ptrs[4] = {paths[0], paths[1], paths[2], paths[3]};
    char *line = NULL;
    int rc = -1;
    if (mcp_image_write(in->color, paths[0], NULL) ||
        (s->needs_albedo && mcp_image_write(in->albedo, paths[1], NULL)) ||
        (s->needs_normal && mcp_image_write(in->normal, paths[2], NULL))) {
        mcp_error_prefix("external: ");
        goto done;
    }
    if (substitute(s->command, path_ptrs, &line)) goto done;
    if (mcp__shell_check(mcp__shell(line), "external: command", s->command)) goto done;
    if (access(paths[3], F_OK) != 0) {
        mcp_error("external: command '%s' wrote no {output} file", s->command);
        goto done;
    }
    rc = read_output(s, paths[3], in->color, out);
done:
    free(line);
    mcp__scratch_dir_end(dir);
    return rc;
}

/* ---- the denoiser ---- */

static int
external_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    *out = NULL;
    if (mcp__denoise_check_input("external", in)) return -1;
    return run_external(self->state, in, out);
}

/* A black box: (F(X + delta t) - F(X)) / delta, one more run of the command per
 * tangent (estimate.h's finite-difference JVP over external_apply). */
static int
external_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
             const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const external_state *s = self->state;
    if (primal) *primal = NULL;
    for (int k = 0; k < n && out; k++)
        out[k] = NULL;
    if (mcp__denoise_check_input("external", at) ||
        mcp__denoise_check_tangents("external", at, t, n))
        return -1;
    if (n > 0 && !out) return mcp_error("external: no room for %d tangent outputs", n);
    return mcp_jvp_finite_difference(self, at, t, n, s->delta, primal, out);
}

static void
external_destroy(mcp_denoiser *self)
{
    external_state *s = self->state;
    free(s->command);
    free(s->workdir);
    free(self);
}

static int
external_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    *out = NULL;
    const mcp_node *cmd_node = NULL;
    external_settings e;
    if (settings->kind != MCP_NODE_MAP)
        return mcp_node_error(settings, "external: needs settings: a map with 'command' "
                                        "(e.g. --denoiser-opt 'command=...')");
    if (mcp_node_require(settings, "command", "denoiser 'external'", &cmd_node) ||
        mcp__options_from_node(&mcp__op_external, settings, NULL, &e))
        return -1;
    const char *command = e.command, *format = e.format, *workdir = e.workdir;
    double delta = e.delta;
    if (!strstr(command, "{color}") || !strstr(command, "{output}"))
        return mcp_node_error(
            cmd_node, "external: command '%s' must name {color} and {output}", command);
    const char *ext = NULL;
    if (strcmp(format, "pfm") == 0)
        ext = "pfm";
    else if (strcmp(format, "exr") == 0)
        ext = "exr";
    else
        return mcp_node_error(mcp_node_get(settings, "format"),
                              "external: format must be pfm or exr (got '%s')", format);
    if (!(delta > 0) || !isfinite(delta))
        return mcp_node_error(mcp_node_get(settings, "delta"),
                              "external: delta must be > 0 (got %g)", delta);
    mcp_denoiser *d = mcp__denoiser_new("external", sizeof(external_state));
    if (!d) return -1;
    external_state *s = d->state;
    d->destroy = external_destroy;
    d->exact = 0;
    s->ext = ext;
    s->delta = delta;
    s->needs_albedo = strstr(command, "{albedo}") != NULL;
    s->needs_normal = strstr(command, "{normal}") != NULL;
    d->uses_albedo = s->needs_albedo;
    d->uses_normal = s->needs_normal;
    s->command = mcp_strdup(command);
    if (!s->command) {
        mcp_denoiser_free(d);
        return -1;
    }
    if (workdir && *workdir) {
        char buf[PATH_CAP];
        if (workdir[0] != '/' && base_dir && *base_dir)
            snprintf(buf, sizeof buf, "%s/%s", base_dir, workdir);
        else
            snprintf(buf, sizeof buf, "%s", workdir);
        if (!(s->workdir = mcp_strdup(buf))) {
            mcp_denoiser_free(d);
            return -1;
        }
    }
    d->apply = external_apply;
    d->jvp = external_jvp;
    *out = d;
    return 0;
}

const mcp_denoiser_kind mcp__denoiser_external = {
    "external",
    "any command that reads and writes image files, e.g. oidnDenoise; "
    "finite-difference JVP (command with {color} {albedo} {normal} {output}, "
    "format [pfm], delta [0.1], workdir [$TMPDIR])",
    mcp__external_keys,
    external_create,
    &mcp__op_external,
};
