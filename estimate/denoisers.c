/* denoisers.c: the table of denoiser kinds and creation by name (docs/mathematics.md
 * §2.1). A kind is one table entry: its name, a summary, its settings keys and a create
 * function; the external command and OIDN's U-Net join as more entries.
 *
 * Settings come from a job file (`denoiser: nlm` or `denoiser: {name: nlm, radius: 5}`)
 * or from command-line words (`--denoiser nlm --denoiser-opt radius=5`), which are
 * turned into the same YAML map, one option per line, so both report errors alike. */
#include <mcpost/denoiser.h>

#include "internal.h"
#include "../common/core/internal.h" /* growing strings (common/core/strbuf.c) */

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const mcp_denoiser_kind *const kinds[] = {
    &mcp__denoiser_gauss,
    &mcp__denoiser_nlm,
    &mcp__denoiser_bilateral,
    &mcp__denoiser_external,
    &mcp__denoiser_unet,
    &mcp__denoiser_james_stein, /* blend/denoise_james_stein.c: wraps any of the above */
    &mcp__denoiser_default,     /* unet, or nlm without features: when none is named */
    NULL,
};

/* Keys a settings map may hold at most (name + a kind's own keys). */
#define MAX_KEYS 64

/* The keys of the kinds with a settings table come from it, once, before a kind is
 * handed out (nlm and bilateral share theirs). The arrays are the kinds' files'
 * (internal.h), not const. */
static void
fill_keys(void)
{
    mcp__options_node_keys(&mcp__op_gauss, NULL, mcp__gauss_keys, MCP__DENOISER_KEYS_MAX);
    mcp__options_node_keys(&mcp__op_nlm, NULL, mcp__nlm_keys, MCP__DENOISER_KEYS_MAX);
    mcp__options_node_keys(&mcp__op_unet, NULL, mcp__unet_keys, MCP__DENOISER_KEYS_MAX);
    mcp__options_node_keys(&mcp__op_external, NULL, mcp__external_keys,
                           MCP__DENOISER_KEYS_MAX);
}

static void
keys_ready(void)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, fill_keys);
}

static const mcp_denoiser_kind *
find_kind(const char *name)
{
    keys_ready();
    for (int i = 0; kinds[i]; i++)
        if (strcmp(kinds[i]->name, name) == 0) return kinds[i];
    return NULL;
}

/* "gauss, nlm" into buf. */
static void
kind_names(char *buf, size_t cap)
{
    size_t n = 0;
    buf[0] = '\0';
    for (int i = 0; kinds[i] && n < cap; i++)
        n += (size_t)snprintf(buf + n, cap - n, "%s%s", i ? ", " : "", kinds[i]->name);
}

static int
check_image(const char *who, const char *part, const mcp_image *img,
            const mcp_image *color)
{
    if (img->channels != 3)
        return mcp_error("%s: %s must have 3 channels (got %d)", who, part,
                         img->channels);
    if (color && !mcp_image_same_size(img, color))
        return mcp_error_prefix("%s: %s: ", who, part);
    return 0;
}

/* A word that YAML reads back unchanged as a plain (unquoted) scalar in a flow map, so
 * that numbers stay numbers: letters, digits and . _ + - / only. */
static int
is_plain_word(const char *s)
{
    if (!*s || (s[0] == '-' && !s[1])) return 0;
    for (; *s; s++)
        if (!(('a' <= *s && *s <= 'z') || ('A' <= *s && *s <= 'Z') ||
              ('0' <= *s && *s <= '9') || strchr("._+-/", *s)))
            return 0;
    return 1;
}

static int
is_key(const char *s, size_t len)
{
    if (len == 0 || ('0' <= s[0] && s[0] <= '9')) return 0;
    for (size_t i = 0; i < len; i++)
        if (!(('a' <= s[i] && s[i] <= 'z') || ('A' <= s[i] && s[i] <= 'Z') ||
              ('0' <= s[i] && s[i] <= '9') || s[i] == '_'))
            return 0;
    return 1;
}

/* Appends s to b as a YAML double-quoted scalar. */
static int
append_quoted(mcp__strbuf *b, const char *s)
{
    char *p = mcp__strbuf_reserve(b, 2 * strlen(s) + 2);
    if (!p) return -1;
    *p++ = '"';
    for (; *s; s++) {
        if (*s == '"' || *s == '\\') *p++ = '\\';
        *p++ = *s;
    }
    *p++ = '"';
    *p = '\0';
    b->len = (size_t)(p - b->s);
    return 0;
}

/* The flow map "{name: "N", k1: v1,\n k2: v2}" with option i on line i + 1, so that
 * an error at "--denoiser-opt:LINE" names the LINE-th option. */
static int
args_to_yaml(const char *name, const char *const *opts, int n_opts, char **out)
{
    mcp__strbuf buf = {0};
    int rc = mcp__strbuf_str(&buf, "{name: ") || append_quoted(&buf, name);
    for (int i = 0; i < n_opts && !rc; i++) {
        const char *eq = strchr(opts[i], '=');
        if (!eq || !is_key(opts[i], (size_t)(eq - opts[i]))) {
            rc = mcp_error("--denoiser-opt: bad option '%s' (want key=value)", opts[i]);
            break;
        }
        size_t klen = (size_t)(eq - opts[i]);
        if (klen == 4 && strncmp(opts[i], "name", 4) == 0) {
            rc = mcp_error("--denoiser-opt: '%s': the name is given by --denoiser",
                           opts[i]);
            break;
        }
        for (int j = 0; j < i; j++)
            if (strncmp(opts[j], opts[i], klen + 1) == 0) {
                rc = mcp_error("--denoiser-opt: key '%.*s' given twice", (int)klen,
                               opts[i]);
                break;
            }
        if (rc) break;
        const char *value = eq + 1;
        rc = mcp__strbuf_str(&buf, i ? ",\n" : ", ") ||
             mcp__strbuf_put(&buf, opts[i], klen) || mcp__strbuf_str(&buf, ": ") ||
             (is_plain_word(value) ? mcp__strbuf_str(&buf, value)
                                   : append_quoted(&buf, value));
    }
    if (!rc) rc = mcp__strbuf_str(&buf, "}");
    if (rc) {
        mcp__strbuf_free(&buf);
        return -1;
    }
    *out = mcp__strbuf_take(&buf);
    return 0;
}

static void
destroy_plain(mcp_denoiser *self)
{
    free(self);
}

/* ---- helpers for the kinds (internal.h) ---- */

int
mcp__denoise_check_input(const char *who, const mcp_denoise_input *in)
{
    if (!in || !in->color) return mcp_error("%s: no colour given", who);
    if (check_image(who, "colour", in->color, NULL) ||
        (in->albedo && check_image(who, "albedo", in->albedo, in->color)) ||
        (in->normal && check_image(who, "normal", in->normal, in->color)) ||
        (in->variance && check_image(who, "variance", in->variance, in->color)))
        return -1;
    return 0;
}

int
mcp__denoise_check_tangents(const char *who, const mcp_denoise_input *at,
                            const mcp_denoise_tangent *t, int n)
{
    if (n < 0) return mcp_error("%s: number of tangents must be >= 0 (got %d)", who, n);
    if (n > 0 && !t) return mcp_error("%s: %d tangents announced, none given", who, n);
    for (int k = 0; k < n; k++) {
        char part[64];
        if (!t[k].color) return mcp_error("%s: tangent %d has no colour part", who, k);
        snprintf(part, sizeof part, "tangent %d colour", k);
        if (check_image(who, part, t[k].color, at->color)) return -1;
        snprintf(part, sizeof part, "tangent %d albedo", k);
        if (t[k].albedo && check_image(who, part, t[k].albedo, at->color)) return -1;
        snprintf(part, sizeof part, "tangent %d normal", k);
        if (t[k].normal && check_image(who, part, t[k].normal, at->color)) return -1;
    }
    return 0;
}

int
mcp__rgb_new(int width, int height, const char *source, mcp_image **out)
{
    static const char *const rgb[] = {"R", "G", "B"};
    mcp_image *img = NULL;
    if (mcp_image_new(width, height, 3, rgb, &img)) return -1;
    if (source && mcp_image_set_source(img, source)) {
        mcp_image_free(img);
        return -1;
    }
    *out = img;
    return 0;
}

mcp_denoiser *
mcp__denoiser_new(const char *name, size_t state_size)
{
    /* one block: the struct, then the state, aligned for any type */
    size_t head = (sizeof(mcp_denoiser) + 15) / 16 * 16;
    mcp_denoiser *d = mcp_calloc(1, head + state_size);
    if (!d) return NULL;
    d->name = name;
    d->exact = 1;
    d->destroy = destroy_plain;
    d->state = state_size ? (char *)d + head : NULL;
    return d;
}

/* ---- public ---- */

const mcp_denoiser_kind *const *
mcp_denoiser_kinds(void)
{
    keys_ready();
    return kinds;
}

int
mcp_denoiser_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    *out = NULL;
    if (!settings) return mcp_error("denoiser: no settings given");
    const mcp_node *name_node = settings;
    if (settings->kind == MCP_NODE_SEQ)
        return mcp_node_error(settings, "denoiser must be a name or a map with 'name', "
                                        "not a list");
    if (settings->kind == MCP_NODE_MAP &&
        mcp_node_require(settings, "name", "denoiser settings", &name_node))
        return -1;
    const char *name = NULL;
    if (mcp_node_string(name_node, "name", &name)) return -1;
    const mcp_denoiser_kind *kind = find_kind(name);
    if (!kind) {
        char known[256];
        kind_names(known, sizeof known);
        return mcp_node_error(name_node, "unknown denoiser '%s' (known: %s)", name,
                              known);
    }
    if (settings->kind == MCP_NODE_MAP) {
        const char *allowed[MAX_KEYS + 2] = {"name"};
        int n = 1;
        for (const char *const *k = kind->keys; k && *k && n <= MAX_KEYS; k++)
            allowed[n++] = *k;
        allowed[n] = NULL;
        char what[96];
        snprintf(what, sizeof what, "denoiser '%s'", kind->name);
        if (mcp_node_check_keys(settings, allowed, what)) return -1;
    }
    return kind->create(settings, base_dir, out);
}

int
mcp_denoiser_create_from_args(const char *name, const char *const *opts, int n_opts,
                              mcp_denoiser **out)
{
    *out = NULL;
    if (!name || !*name) return mcp_error("no denoiser named (give --denoiser NAME)");
    if (!find_kind(name)) {
        char known[256];
        kind_names(known, sizeof known);
        return mcp_error("unknown denoiser '%s' (known: %s)", name, known);
    }
    if (n_opts < 0 || (n_opts > 0 && !opts))
        return mcp_error("denoiser %s: bad option list", name);
    /* `default` has no settings of its own: settings with it are the U-Net's, which is
       what it stands for (the CLI, job files and Python take this one path) */
    if (!strcmp(name, "default") && n_opts > 0) name = "unet";
    char *text = NULL;
    mcp_node *root = NULL;
    if (args_to_yaml(name, opts, n_opts, &text)) return -1;
    int rc = mcp_yaml_parse_string(text, "--denoiser-opt", &root) ||
             mcp_denoiser_create(root, NULL, out);
    mcp_node_free(root);
    free(text);
    return rc ? -1 : 0;
}

void
mcp_denoiser_free(mcp_denoiser *d)
{
    if (!d) return;
    if (d->destroy)
        d->destroy(d);
    else
        free(d);
}

mcp_denoise_input
mcp_denoise_input_of(const mcp_dump *dump)
{
    mcp_denoise_input in = {0};
    if (dump) {
        in.color = dump->color;
        in.albedo = dump->albedo;
        in.normal = dump->normal;
        in.variance = dump->var_of_mean;
    }
    return in;
}
