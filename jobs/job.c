/* job.c: running a job file -- inputs, output folder, stages from a registry, the
 * report (see job.h). Everything is checked before the first stage runs, so a typo
 * on the last line fails in a second, not after an hour of work. */
#define _XOPEN_SOURCE 700 /* realpath */
#include <mcpost/job.h>
#include <mcpost/frames.h>
#include <mcpost/imageio.h>
#include <mcpost/progress.h>
#include <mcpost/stages.h> /* the built-in table, for stages == NULL (jobs/) */

#include "internal.h"
#include "../common/dump/internal.h"
#include "../common/report/internal.h"

#include <errno.h>
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <glob.h>
#include <unistd.h>

typedef enum { ENTRY_DUMP, ENTRY_IMAGE, ENTRY_SERIES } entry_kind;

typedef struct entry {
    char *name;
    entry_kind kind;
    const mcp_node *def; /* the input's definition (NULL for results of stages) */
    mcp_dump *dump;
    mcp_image *image;
    mcp_series *series;
    unsigned declared; /* MCP_JOB_* a stage's check said its result will provide */
} entry;

struct mcp_job {
    char *path, *dir, *output_dir;
    int output_made;
    mcp_node *root;
    entry *entries;
    int n_entries;
    mcp_report *report;
    mcp_job_options opt;
    int checking;          /* the stages' checks are running (job_validate) */
    int frame_paths;       /* an input path has changed with the frame (resolve_input) */
    int skip_input_files;  /* mcp_job_check_settings: inputs' files not looked for */
    int *frames, n_frames; /* the job's frames: (none: n_frames 0) */
    const mcp__outdir *whole; /* the output folder being written: no input inside it */
};

static const char *const root_keys[] = {"title",  "inputs", "output",
                                        "frames", "stages", NULL};
/* keys shared by dump and series inputs: how to read a render dump */
#define DUMP_KEYS                                                                        \
    "convention", "variance", "spp", "bad_values", "variance_file", "albedo_file",       \
        "normal_file", "spp_map_file", "channels"
static const char *const dump_keys[] = {"dump", DUMP_KEYS, NULL};
static const char *const series_keys[] = {"series", "variance_from", DUMP_KEYS, NULL};
static const char *const replicates_keys[] = {"replicates", "merge", "pool", DUMP_KEYS,
                                              NULL};
static const char *const image_keys[] = {"image", NULL};
static const char *const channel_keys[] = {"color", "variance", "albedo", "normal", NULL};

mcp_job_options
mcp_job_defaults(void)
{
    return (mcp_job_options){
        .output_dir = NULL, .json_stdout = 0, .quiet = 0, .frame = -1};
}

/* ---- paths ---- */

int
mcp_job_resolve(const mcp_job *job, const char *rel, char *buf, size_t cap)
{
    int n = rel[0] == '/' ? snprintf(buf, cap, "%s", rel)
                          : snprintf(buf, cap, "%s/%s", job->dir, rel);
    if (n < 0 || (size_t)n >= cap)
        return mcp_error("%s: path too long: %s", job->path, rel);
    return 0;
}

/* Resolves an input's path, with the frame token replaced by the frame of a frame
 * run (frames.h; a series pattern keeps its spp conversion). Errors name the line. */
static int
resolve_input(mcp_job *job, const mcp_node *at, const char *rel, int series, char *buf,
              size_t cap)
{
    char expanded[4096];
    if (job->opt.frame >= 0) {
        if (mcp_frame_expand(rel, series, job->opt.frame, expanded, sizeof expanded))
            return mcp_node_error(at, "%s", mcp_error_message());
        job->frame_paths |= strcmp(expanded, rel) != 0;
        rel = expanded;
    }
    if (mcp_job_resolve(job, rel, buf, cap)) return -1;
    /* a rerun replaces the old output folder whole: an input inside it would go too */
    if (job->whole && mcp__outdir_check_input(job->whole, buf))
        return mcp_node_error(at, "%s", mcp_error_message());
    return 0;
}

const char *
mcp_job_path(const mcp_job *job)
{
    return job->path;
}

/* Creates the output folder once, and from then on names it by its real path (no
 * "jobs/../../out" in messages). */
static int
make_output_dir(mcp_job *job)
{
    if (job->output_made) return 0;
    if (mcp_make_dirs(job->output_dir)) return -1;
    char *real = realpath(job->output_dir, NULL);
    if (real) {
        free(job->output_dir);
        job->output_dir = real;
    }
    job->output_made = 1;
    return 0;
}

const char *
mcp_job_output_dir(mcp_job *job)
{
    make_output_dir(job);
    return job->output_dir;
}

/* <output>/name into buf, the output folder made. */
static int
output_join(mcp_job *job, const char *name, char *buf, size_t cap)
{
    if (make_output_dir(job)) return -1;
    int n = snprintf(buf, cap, "%s/%s", job->output_dir, name);
    if (n < 0 || (size_t)n >= cap)
        return mcp_error("%s: output path too long: %s", job->path, name);
    return 0;
}

int
mcp_job_output_path(mcp_job *job, const char *name, char *buf, size_t cap)
{
    if (output_join(job, name, buf, cap)) return -1;
    /* names may hold sub-folders ("maps/flip.png") */
    char *slash = strrchr(buf, '/');
    if (slash && slash > buf + strlen(job->output_dir)) {
        *slash = '\0';
        int rc = mcp_make_dirs(buf);
        *slash = '/';
        return rc;
    }
    return 0;
}

int
mcp_job_output_subdir(mcp_job *job, const char *sub, char *buf, size_t cap)
{
    return output_join(job, sub, buf, cap) || mcp_make_dirs(buf) ? -1 : 0;
}

mcp_report *
mcp_job_report(mcp_job *job)
{
    return job->report;
}

int
mcp_job_quiet(const mcp_job *job)
{
    return job->opt.quiet;
}

/* ---- inputs ---- */

static int
file_exists(const mcp_job *job, const mcp_node *at, const char *path)
{
    struct stat st;
    if (job->skip_input_files) return 0;
    if (stat(path, &st) != 0)
        return mcp_node_error(at, "input file %s: %s", path, strerror(errno));
    return 0;
}

/* Fills a dump spec from an input definition; strings point into the node tree or
 * into `store` (resolved paths), which must outlive the spec. */
static int
dump_spec_from(mcp_job *job, const mcp_node *def, mcp_dump_spec *spec,
               char store[6][4096])
{
    *spec = mcp_dump_spec_defaults();
    const char *s = NULL;
    /* a wrong type already names the line (mcp_node_opt_string); only a bad name,
     * reported without a location, gets the key's line added */
    if (mcp_node_opt_string(def, "convention", &s)) return -1;
    if (s && mcp_convention_from_name(s, &spec->convention))
        return mcp_node_error(mcp_node_get(def, "convention"), "%s", mcp_error_message());
    s = NULL;
    if (mcp_node_opt_string(def, "variance", &s)) return -1;
    if (s && mcp_variance_kind_from_name(s, &spec->variance))
        return mcp_node_error(mcp_node_get(def, "variance"), "%s", mcp_error_message());
    s = NULL;
    if (mcp_node_opt_string(def, "bad_values", &s)) return -1;
    if (s && mcp_badval_policy_from_name(s, &spec->bad_values))
        return mcp_node_error(mcp_node_get(def, "bad_values"), "%s", mcp_error_message());
    /* a series' spp list belongs to series_from(), which checks it; anywhere else spp
     * must be one number (mcp_node_double names the line of a list or map) */
    const mcp_node *spp = mcp_node_get(def, "spp");
    if (spp && (spp->kind == MCP_NODE_SCALAR || !mcp_node_get(def, "series"))) {
        if (mcp_node_double(spp, "spp", &spec->spp)) return -1;
        if (spec->spp <= 0)
            return mcp_node_error(spp, "spp must be > 0 (got %g)", spec->spp);
    }
    static const char *file_keys[] = {"variance_file", "albedo_file", "normal_file",
                                      "spp_map_file"};
    const char **targets[] = {&spec->variance_path, &spec->albedo_path,
                              &spec->normal_path, &spec->spp_map_path};
    for (int i = 0; i < 4; i++) {
        const mcp_node *n = mcp_node_get(def, file_keys[i]);
        if (!n) continue;
        if (mcp_node_string(n, file_keys[i], &s) ||
            resolve_input(job, n, s, 0, store[i], 4096) || file_exists(job, n, store[i]))
            return -1;
        *targets[i] = store[i];
    }
    const mcp_node *ch = mcp_node_get(def, "channels");
    if (ch) {
        if (mcp_node_check_keys(ch, channel_keys, "channels")) return -1;
        const char **dst[] = {spec->color, spec->var, spec->albedo, spec->normal};
        for (int k = 0; k < 4; k++) {
            const mcp_node *list = mcp_node_get(ch, channel_keys[k]);
            if (!list) continue;
            if (list->kind != MCP_NODE_SEQ || list->count != 3)
                return mcp_node_error(list, "channels.%s must list 3 channel names",
                                      channel_keys[k]);
            for (int i = 0; i < 3; i++)
                if (mcp_node_string(list->items[i], channel_keys[k], &dst[k][i]))
                    return -1;
        }
    }
    return 0;
}

static entry *
find_entry(mcp_job *job, const char *name)
{
    for (int i = 0; i < job->n_entries; i++)
        if (strcmp(job->entries[i].name, name) == 0) return &job->entries[i];
    return NULL;
}

static entry *
add_entry(mcp_job *job, const char *name)
{
    entry *e = find_entry(job, name);
    if (e) {
        mcp_dump_free(e->dump);
        mcp_image_free(e->image);
        mcp_series_free(e->series);
        e->dump = NULL, e->image = NULL, e->series = NULL;
        return e;
    }
    entry *grown =
        mcp_realloc(job->entries, (size_t)(job->n_entries + 1) * sizeof *grown);
    if (!grown) return NULL;
    job->entries = grown;
    e = &grown[job->n_entries];
    memset(e, 0, sizeof *e);
    if (!(e->name = mcp_strdup(name))) return NULL;
    job->n_entries++;
    return e;
}

/* Builds the series of an input definition (not its dumps). */
static int
series_from(mcp_job *job, const mcp_node *def, mcp_series **out)
{
    const mcp_node *src = mcp_node_get(def, "series"), *spp = mcp_node_get(def, "spp");
    char path[4096];
    int rc;
    if (src->kind == MCP_NODE_SCALAR) {
        if (!spp || spp->kind != MCP_NODE_SEQ)
            return mcp_node_error(src, "a series pattern needs 'spp: [list of sample "
                                       "counts]'");
        int *counts = mcp_calloc((size_t)spp->count, sizeof *counts);
        if (!counts) return -1;
        rc = 0;
        for (int i = 0; i < spp->count && !rc; i++)
            rc = mcp_node_int(spp->items[i], "spp", &counts[i]);
        if (!rc && resolve_input(job, src, src->value, 1, path, sizeof path))
            rc = -1;
        else if (!rc && mcp_series_from_pattern(path, counts, spp->count, out))
            rc = mcp_node_error(src, "%s", mcp_error_message());
        free(counts);
        if (rc) return -1;
    } else if (src->kind == MCP_NODE_SEQ) {
        char **paths = mcp_calloc((size_t)src->count, sizeof *paths);
        double *counts = NULL;
        if (!paths) return -1;
        rc = 0;
        for (int i = 0; i < src->count && !rc; i++) {
            const char *s;
            rc = mcp_node_string(src->items[i], "series", &s) ||
                 resolve_input(job, src->items[i], s, 0, path, sizeof path) ||
                 !(paths[i] = mcp_strdup(path));
        }
        if (!rc && spp) {
            int n = 0;
            rc = mcp_node_opt_doubles(def, "spp", &counts, &n);
            if (!rc && n != src->count)
                rc = mcp_node_error(spp, "spp lists %d counts for %d files", n,
                                    src->count);
        }
        rc = rc ||
             mcp_series_from_paths((const char *const *)paths, counts, src->count, out);
        for (int i = 0; i < src->count; i++)
            free(paths[i]);
        free(paths);
        free(counts);
    } else {
        return mcp_node_error(src, "series must be a file pattern or a list of files");
    }
    if (rc) return -1;
    const char *from = NULL;
    if (mcp_node_opt_string(def, "variance_from", &from))
        rc = -1;
    else if (from && mcp_series_variance_from_name(from, &(*out)->variance_from))
        rc =
            mcp_node_error(mcp_node_get(def, "variance_from"), "%s", mcp_error_message());
    if (rc) {
        mcp_series_free(*out);
        *out = NULL;
        return -1;
    }
    for (int i = 0; i < (*out)->count; i++)
        if (file_exists(job, src, (*out)->paths[i])) {
            mcp_series_free(*out);
            *out = NULL;
            return -1;
        }
    return 0;
}

/* The files of a replicates input: a list, or a glob pattern (sorted matches). */
static int
replicate_paths(mcp_job *job, const mcp_node *def, char ***out, int *count)
{
    const mcp_node *src = mcp_node_get(def, "replicates");
    char path[4096];
    *out = NULL, *count = 0;
    char **paths = NULL;
    int n = 0, rc = 0;
    if (src->kind == MCP_NODE_SCALAR) {
        glob_t g;
        if (resolve_input(job, src, src->value, 0, path, sizeof path)) return -1;
        if (job->skip_input_files) /* which files match is for each frame to say */
            return 0;
        int grc = glob(path, 0, NULL, &g);
        if (grc == GLOB_NOMATCH)
            return mcp_node_error(src, "replicates: no file matches %s", path);
        if (grc != 0) return mcp_node_error(src, "replicates: cannot expand %s", path);
        n = (int)g.gl_pathc;
        if (!(paths = mcp_calloc((size_t)n, sizeof *paths))) rc = -1;
        for (int i = 0; i < n && !rc; i++)
            rc = !(paths[i] = mcp_strdup(g.gl_pathv[i]));
        globfree(&g);
    } else if (src->kind == MCP_NODE_SEQ) {
        n = src->count;
        if (!(paths = mcp_calloc((size_t)n + 1, sizeof *paths))) return -1;
        for (int i = 0; i < n && !rc; i++) {
            const char *f;
            rc = mcp_node_string(src->items[i], "replicates", &f) ||
                 resolve_input(job, src->items[i], f, 0, path, sizeof path) ||
                 !(paths[i] = mcp_strdup(path)) || file_exists(job, src->items[i], path);
        }
    } else {
        return mcp_node_error(src, "replicates must be a list of files or a pattern");
    }
    if (!rc && n < 2)
        rc = mcp_node_error(src, "replicates: %d file%s; the spread needs at least 2", n,
                            n == 1 ? "" : "s");
    if (rc) {
        for (int i = 0; i < n && paths; i++)
            free(paths[i]);
        free(paths);
        return -1;
    }
    *out = paths, *count = n;
    return 0;
}

static void
free_paths(char **paths, int n)
{
    for (int i = 0; i < n; i++)
        free(paths[i]);
    free(paths);
}

/* The merge settings of a replicates input (merge: replicates|pooled, pool: R). */
static int
merge_options_from(const mcp_node *def, mcp_merge_options *opt)
{
    *opt = mcp_merge_defaults();
    const char *kind = NULL;
    if (mcp_node_opt_string(def, "merge", &kind) ||
        mcp_node_opt_int(def, "pool", &opt->pool_radius))
        return -1;
    if (kind && mcp_merge_variance_from_name(kind, &opt->variance))
        return mcp_node_error(mcp_node_get(def, "merge"), "%s", mcp_error_message());
    if (opt->pool_radius < 0)
        return mcp_node_error(mcp_node_get(def, "pool"), "pool must be >= 0 (got %d)",
                              opt->pool_radius);
    return 0;
}

/* Loads every replicate with the input's dump settings and merges them. */
static int
load_replicates(mcp_job *job, const mcp_node *def, mcp_dump **out)
{
    char **paths = NULL, store[6][4096];
    int n = 0, rc = -1;
    mcp_dump_spec spec;
    mcp_merge_options mo;
    if (merge_options_from(def, &mo) || replicate_paths(job, def, &paths, &n) ||
        dump_spec_from(job, def, &spec, store))
        return -1;
    mcp_dump **parts = mcp_calloc((size_t)n, sizeof *parts);
    if (!parts) goto done;
    for (int i = 0; i < n; i++) {
        spec.path = paths[i];
        if (mcp_dump_load(&spec, &parts[i])) goto done;
    }
    rc = mcp_dump_merge((const mcp_dump *const *)parts, n, &mo, out);
done:
    for (int i = 0; parts && i < n; i++)
        mcp_dump_free(parts[i]);
    free(parts);
    free_paths(paths, n);
    return rc;
}

/* Checks every input definition (keys, types, files present) without loading. */
static int
check_inputs(mcp_job *job)
{
    const mcp_node *inputs = mcp_node_get(job->root, "inputs");
    if (!inputs) return 0;
    if (inputs->kind != MCP_NODE_MAP)
        return mcp_node_error(inputs, "inputs must map names to inputs");
    for (int i = 0; i < inputs->count; i++) {
        const mcp_node *def = inputs->items[i];
        const char *name = inputs->keys[i]->value;
        char what[256];
        snprintf(what, sizeof what, "input '%s'", name);
        if (def->kind != MCP_NODE_MAP)
            return mcp_node_error(def,
                                  "input '%s' must be a map (dump:, image:, series: or "
                                  "replicates:)",
                                  name);
        entry *e = add_entry(job, name);
        if (!e) return -1;
        e->def = def;
        char path[4096], store[6][4096];
        const char *file;
        mcp_dump_spec spec;
        if (mcp_node_get(def, "dump")) {
            e->kind = ENTRY_DUMP;
            if (mcp_node_check_keys(def, dump_keys, what) ||
                mcp_node_string(mcp_node_get(def, "dump"), "dump", &file) ||
                resolve_input(job, mcp_node_get(def, "dump"), file, 0, path,
                              sizeof path) ||
                file_exists(job, mcp_node_get(def, "dump"), path) ||
                dump_spec_from(job, def, &spec, store))
                return -1;
        } else if (mcp_node_get(def, "replicates")) {
            /* K renders of the frame with other seeds, merged into one dump */
            e->kind = ENTRY_DUMP;
            char **paths = NULL;
            int n = 0;
            mcp_merge_options mo;
            if (mcp_node_check_keys(def, replicates_keys, what) ||
                merge_options_from(def, &mo) || replicate_paths(job, def, &paths, &n) ||
                dump_spec_from(job, def, &spec, store))
                return -1;
            free_paths(paths, n);
        } else if (mcp_node_get(def, "image")) {
            e->kind = ENTRY_IMAGE;
            if (mcp_node_check_keys(def, image_keys, what) ||
                mcp_node_string(mcp_node_get(def, "image"), "image", &file) ||
                resolve_input(job, mcp_node_get(def, "image"), file, 0, path,
                              sizeof path) ||
                file_exists(job, mcp_node_get(def, "image"), path))
                return -1;
        } else if (mcp_node_get(def, "series")) {
            e->kind = ENTRY_SERIES;
            mcp_series *s = NULL;
            if (mcp_node_check_keys(def, series_keys, what) ||
                series_from(job, def, &s) || dump_spec_from(job, def, &spec, store)) {
                mcp_series_free(s);
                return -1;
            }
            mcp_series_free(s);
        } else {
            return mcp_node_error(def,
                                  "input '%s' needs one of dump:, image:, series: or "
                                  "replicates:",
                                  name);
        }
    }
    return 0;
}

static int
load_entry(mcp_job *job, entry *e)
{
    char path[4096], store[6][4096];
    const char *file = NULL;
    mcp_dump_spec spec;
    switch (e->kind) {
    case ENTRY_DUMP:
        if (e->dump) return 0;
        if (mcp_node_get(e->def, "replicates"))
            return load_replicates(job, e->def, &e->dump);
        mcp_node_string(mcp_node_get(e->def, "dump"), "dump", &file);
        if (resolve_input(job, e->def, file, 0, path, sizeof path) ||
            dump_spec_from(job, e->def, &spec, store))
            return -1;
        spec.path = path;
        return mcp_dump_load(&spec, &e->dump);
    case ENTRY_IMAGE:
        if (e->image) return 0;
        mcp_node_string(mcp_node_get(e->def, "image"), "image", &file);
        if (resolve_input(job, e->def, file, 0, path, sizeof path)) return -1;
        return mcp_image_read(path, NULL, &e->image);
    case ENTRY_SERIES:
        if (e->series) return 0;
        if (series_from(job, e->def, &e->series) ||
            dump_spec_from(job, e->def, &e->series->spec, store))
            return -1;
        /* the spec's extra file paths point into `store`: series members share the
         * main settings only */
        e->series->spec.variance_path = e->series->spec.albedo_path = NULL;
        e->series->spec.normal_path = e->series->spec.spp_map_path = NULL;
        e->series->spec.spp = 0;
        return 0;
    }
    return -1;
}

static int
lookup(mcp_job *job, const mcp_node *settings, const char *key, entry **out)
{
    const mcp_node *n = mcp_node_get(settings, key);
    const char *name;
    if (!n)
        return mcp_node_error(settings, "missing key '%s' (the name of an input)", key);
    if (mcp_node_string(n, key, &name)) return -1;
    entry *e = find_entry(job, name);
    if (!e) return mcp_node_error(n, "no input or result called '%s'", name);
    if (e->def && load_entry(job, e)) return mcp_node_error(n, "%s", mcp_error_message());
    *out = e;
    return 0;
}

int
mcp_job_dump(mcp_job *job, const mcp_node *settings, const char *key,
             const mcp_dump **out)
{
    entry *e;
    if (lookup(job, settings, key, &e)) return -1;
    if (!e->dump)
        return mcp_node_error(mcp_node_get(settings, key), "'%s' is not a render dump",
                              e->name);
    *out = e->dump;
    return 0;
}

int
mcp_job_image(mcp_job *job, const mcp_node *settings, const char *key,
              const mcp_image **out)
{
    entry *e;
    if (lookup(job, settings, key, &e)) return -1;
    if (!e->image && !e->dump)
        return mcp_node_error(mcp_node_get(settings, key), "'%s' is not an image",
                              e->name);
    *out = e->image ? e->image : e->dump->color;
    return 0;
}

int
mcp_job_series(mcp_job *job, const mcp_node *settings, const char *key,
               const mcp_series **out)
{
    entry *e;
    if (lookup(job, settings, key, &e)) return -1;
    if (!e->series)
        return mcp_node_error(mcp_node_get(settings, key), "'%s' is not a series",
                              e->name);
    *out = e->series;
    return 0;
}

const mcp_image *
mcp_job_find_image(mcp_job *job, const char *name)
{
    entry *e = find_entry(job, name);
    if (!e || (e->def && load_entry(job, e))) return NULL;
    return e->image ? e->image : e->dump ? e->dump->color : NULL;
}

/* ---- checks before anything runs ---- */

static unsigned
entry_kinds(const entry *e)
{
    unsigned k = e->declared;
    if (e->def)
        k |= e->kind == ENTRY_DUMP    ? MCP_JOB_DUMP | MCP_JOB_IMAGE
             : e->kind == ENTRY_IMAGE ? MCP_JOB_IMAGE
                                      : MCP_JOB_SERIES;
    if (e->dump) k |= MCP_JOB_DUMP | MCP_JOB_IMAGE;
    if (e->image) k |= MCP_JOB_IMAGE;
    if (e->series) k |= MCP_JOB_SERIES;
    return k;
}

unsigned
mcp_job_kinds(mcp_job *job, const char *name)
{
    entry *e = find_entry(job, name);
    return e ? entry_kinds(e) : 0;
}

int
mcp_job_check_name(mcp_job *job, const mcp_node *name_node, unsigned kinds)
{
    const char *name;
    if (mcp_node_string(name_node, "the name of an input", &name)) return -1;
    entry *e = find_entry(job, name);
    if (!e || !entry_kinds(e))
        return mcp_node_error(name_node, "no input or result called '%s'", name);
    if (!(entry_kinds(e) & kinds)) {
        /* an image is anything with colour, a dump included: name the widest */
        int image = (kinds & MCP_JOB_IMAGE) != 0, series = (kinds & MCP_JOB_SERIES) != 0,
            dump = !image && (kinds & MCP_JOB_DUMP);
        return mcp_node_error(name_node, "'%s' is not %s%s%s%s", name,
                              series ? "a series" : "",
                              series && (image || dump) ? " or " : "",
                              image ? "an image" : "", dump ? "a render dump" : "");
    }
    return 0;
}

int
mcp_job_check_input(mcp_job *job, const mcp_node *settings, const char *key,
                    unsigned kinds)
{
    const mcp_node *n = mcp_node_get(settings, key);
    if (!n)
        return mcp_node_error(settings, "missing key '%s' (the name of an input)", key);
    return mcp_job_check_name(job, n, kinds);
}

int
mcp_job_declare(mcp_job *job, const char *name, unsigned kind)
{
    if (!job->checking) return 0;
    entry *e = find_entry(job, name);
    if (!e && !(e = add_entry(job, name))) return -1;
    e->declared |= kind & MCP_JOB_DUMP ? MCP_JOB_DUMP | MCP_JOB_IMAGE : kind;
    return 0;
}

int
mcp_job_check_file(const mcp_job *job, const mcp_node *path_node, const char *key)
{
    const char *rel;
    char path[4096];
    struct stat st;
    if (mcp_node_string(path_node, key, &rel) ||
        mcp_job_resolve(job, rel, path, sizeof path))
        return -1;
    if (stat(path, &st) != 0 || !S_ISREG(st.st_mode))
        return mcp_node_error(path_node, "%s: no such file: %s", key, path);
    return 0;
}

int
mcp_job_put_image(mcp_job *job, const char *name, mcp_image *img)
{
    entry *e = add_entry(job, name);
    if (!e) {
        mcp_image_free(img);
        return -1;
    }
    e->def = NULL;
    e->kind = ENTRY_IMAGE;
    e->image = img;
    return 0;
}

int
mcp_job_put_dump(mcp_job *job, const char *name, mcp_dump *dump)
{
    entry *e = add_entry(job, name);
    if (!e) {
        mcp_dump_free(dump);
        return -1;
    }
    e->def = NULL;
    e->kind = ENTRY_DUMP;
    e->dump = dump;
    return 0;
}

/* ---- stages ---- */

static const mcp_stage *
find_stage(const mcp_stage *const *stages, const char *name)
{
    for (; *stages; stages++)
        if (strcmp((*stages)->name, name) == 0) return *stages;
    return NULL;
}

/* An empty settings map, for "- info:" with nothing after it. */
static mcp_node *
empty_map_at(const mcp_node *at)
{
    mcp_node *n = mcp_calloc(1, sizeof *n);
    if (n) {
        n->kind = MCP_NODE_MAP;
        n->line = at->line;
        n->column = at->column;
        n->file = at->file;
    }
    return n;
}

/* Resolves stage i of the list to its definition and settings (checked). */
static int
stage_at(const mcp_node *item, const mcp_stage *const *stages, const mcp_stage **stage,
         const mcp_node **settings)
{
    if (item->kind != MCP_NODE_MAP || item->count != 1)
        return mcp_node_error(item, "each stage must be one 'name: {settings}' entry");
    const char *name = item->keys[0]->value;
    *stage = find_stage(stages, name);
    if (!*stage) {
        char known[512] = "";
        size_t n = 0;
        for (const mcp_stage *const *s = stages; *s; s++)
            n += (size_t)snprintf(known + n, n < sizeof known ? sizeof known - n : 0,
                                  "%s%s", s == stages ? "" : ", ", (*s)->name);
        return mcp_node_error(item->keys[0], "unknown stage '%s' (known: %s)", name,
                              known);
    }
    *settings = item->items[0];
    if ((*settings)->kind == MCP_NODE_SCALAR && (*settings)->value[0] == '\0')
        *settings = NULL; /* no settings given */
    char what[128];
    snprintf(what, sizeof what, "stage '%s'", name);
    return *settings ? mcp_node_check_keys(*settings, (*stage)->keys, what) : 0;
}

static void
job_free(mcp_job *job)
{
    if (!job) return;
    for (int i = 0; i < job->n_entries; i++) {
        free(job->entries[i].name);
        mcp_dump_free(job->entries[i].dump);
        mcp_image_free(job->entries[i].image);
        mcp_series_free(job->entries[i].series);
    }
    free(job->entries);
    mcp_node_free(job->root);
    mcp_report_free(job->report);
    free(job->path);
    free(job->dir);
    free(job->output_dir);
    free(job->frames);
    free(job);
}

/* The job's `frames:` (a set as text, "1-240:2", or a list of numbers and sets). */
static int
frames_from(mcp_job *job)
{
    const mcp_node *n = mcp_node_get(job->root, "frames");
    if (!n) return 0;
    char text[4096] = "";
    size_t len = 0;
    int items = n->kind == MCP_NODE_SEQ ? n->count : 1;
    if (n->kind == MCP_NODE_MAP || items == 0)
        return mcp_node_error(n,
                              "frames must be a set such as 1-240, 1-240:2 or 1,5,9-12, "
                              "or a list of them");
    for (int i = 0; i < items; i++) {
        const mcp_node *item = n->kind == MCP_NODE_SEQ ? n->items[i] : n;
        const char *s;
        if (mcp_node_string(item, "frames", &s)) return -1;
        int w = snprintf(text + len, sizeof text - len, "%s%s", i ? "," : "", s);
        if (w < 0 || (size_t)w >= sizeof text - len)
            return mcp_node_error(n,
                                  "frames: the list is too long; write ranges (1-240)");
        len += (size_t)w;
    }
    if (mcp_frames_parse(text, &job->frames, &job->n_frames))
        return mcp_node_error(n, "%s", mcp_error_message());
    return 0;
}

/* A frame run (opt.frame >= 0) writes into the frame's own folder of the job's output
 * folder, "<output>/0017", so that frames run in any order, anywhere, apart. */
static int
frame_open(mcp_job *job)
{
    int f = job->opt.frame;
    if (f < 0) return 0;
    if (!job->n_frames)
        return mcp_error("%s: frame %d asked for, but the job has no frames:", job->path,
                         f);
    if (!mcp_frames_contains(job->frames, job->n_frames, f)) {
        char set[256];
        if (mcp_frames_format(job->frames, job->n_frames, set, sizeof set))
            snprintf(set, sizeof set, "%d-%d, %d frames", job->frames[0],
                     job->frames[job->n_frames - 1], job->n_frames);
        return mcp_node_error(mcp_node_get(job->root, "frames"),
                              "frame %d is not among the job's frames (%s)", f, set);
    }
    char dir[4096];
    if (mcp_frame_dir(job->output_dir, f, dir, sizeof dir)) return -1;
    free(job->output_dir);
    return (job->output_dir = mcp_strdup(dir)) ? 0 : -1;
}

static int
job_open(const char *path, const mcp_job_options *opt, mcp_job **out)
{
    mcp_job *job = mcp_calloc(1, sizeof *job);
    if (!job) return -1;
    job->opt = opt ? *opt : mcp_job_defaults();
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s", path);
    const char *title = NULL, *output = NULL;
    if (!(job->path = mcp_strdup(path)) || !(job->dir = mcp_strdup(dirname(tmp))) ||
        mcp_yaml_parse_file(path, &job->root))
        goto fail;
    if (job->root->kind != MCP_NODE_MAP) {
        mcp_node_error(job->root,
                       "a job file is a map with inputs:, output: and stages:");
        goto fail;
    }
    if (mcp_node_check_keys(job->root, root_keys, "the job file") ||
        mcp_node_opt_string(job->root, "title", &title) ||
        mcp_node_opt_string(job->root, "output", &output))
        goto fail;
    if (job->opt.output_dir) {
        job->output_dir = mcp_strdup(job->opt.output_dir);
    } else {
        char name[512], resolved[4096];
        snprintf(tmp, sizeof tmp, "%s", path);
        snprintf(name, sizeof name, "out/%s", basename(tmp));
        char *dot = strrchr(name, '.');
        if (dot && dot > name + 4) *dot = '\0';
        if (mcp_job_resolve(job, output ? output : name, resolved, sizeof resolved))
            goto fail;
        job->output_dir = mcp_strdup(resolved);
    }
    char frame_title[4096];
    if (job->opt.frame >= 0)
        snprintf(frame_title, sizeof frame_title, "%s, frame %d",
                 title ? title : job->path, job->opt.frame);
    if (!job->output_dir || frames_from(job) || frame_open(job) ||
        mcp_report_new(job->opt.frame >= 0 ? frame_title
                       : title             ? title
                                           : job->path,
                       &job->report))
        goto fail;
    if (job->opt.frame >= 0 &&
        !cJSON_AddNumberToObject(mcp_report_json(job->report), "frame", job->opt.frame)) {
        mcp_error("out of memory");
        goto fail;
    }
    *out = job;
    return 0;
fail:
    job_free(job);
    return -1;
}

/* Puts the stage's place in front of the current error unless it names one. */
static void
stage_error_place(const mcp_job *job, const mcp_node *item, const mcp_stage *stage)
{
    if (!strstr(mcp_error_message(), job->path))
        mcp_error_prefix("%s:%d: stage '%s': ", job->path, item->line, stage->name);
}

/* Everything that can be checked without running a stage: the list of stages, every
 * input (keys, types, files present), every stage known, its keys allowed, and its
 * settings as its check reads them (values, the inputs and results it names, its
 * files), in order, so that a stage may name the results of the stages before it.
 * *list receives the stages' list. No side effects: nothing is loaded or written. */
static int
job_validate(mcp_job *job, const mcp_stage *const *stages, const mcp_node **list)
{
    *list = mcp_node_get(job->root, "stages");
    if (!*list || (*list)->kind != MCP_NODE_SEQ || (*list)->count == 0)
        return mcp_node_error(*list ? *list : job->root,
                              "the job needs a list of stages");
    if (check_inputs(job)) return -1;
    int rc = 0;
    job->checking = 1;
    for (int i = 0; i < (*list)->count && rc == 0; i++) {
        const mcp_stage *stage;
        const mcp_node *settings;
        if (stage_at((*list)->items[i], stages, &stage, &settings)) {
            rc = -1;
            break;
        }
        /* title: is the runner's (the heading of the stage's sections), for every
           stage that lists it */
        const char *title;
        if (settings && mcp_node_opt_string(settings, "title", &title)) {
            rc = -1;
            break;
        }
        if (!stage->check) continue;
        mcp_node *empty = settings ? NULL : empty_map_at((*list)->items[i]);
        if (!settings && !empty) {
            rc = -1;
            break;
        }
        if (stage->check(job, settings ? settings : empty)) {
            stage_error_place(job, (*list)->items[i], stage);
            rc = -1;
        }
        free(empty);
    }
    job->checking = 0;
    return rc;
}

/* A frame job is checked frame by frame: every frame's inputs must be there. Only
 * the input paths depend on the frame (stage checks resolve their files without it),
 * so the first frame gets the whole check and the others only their inputs' -- and
 * not even those when no input path names the frame: a job of 10,000 frames is then
 * checked once, not 10,000 times. */
static int
check_frames(mcp_job *job, const mcp_stage *const *stages)
{
    job->frame_paths = 0;
    for (int i = 0; i < job->n_frames; i++) {
        const mcp_node *list = NULL;
        job->opt.frame = job->frames[i];
        if (i > 0 && !job->frame_paths) break;
        if (i == 0 ? job_validate(job, stages, &list) : check_inputs(job))
            return mcp_error_prefix("frame %d: ", job->frames[i]);
    }
    job->opt.frame = -1;
    return 0;
}

/* mcp_job_check, and with settings_only mcp_job_check_settings: the inputs' files not
 * looked for, the paths those of the first frame (a frame token that does not parse
 * is still found). */
static int
check_job_file(const char *path, const mcp_stage *const *stages, int settings_only)
{
    mcp_job *job = NULL;
    if (!stages) stages = mcp_job_stages();
    if (job_open(path, NULL, &job)) return -1;
    const mcp_node *list = NULL;
    int rc;
    if (settings_only) {
        job->skip_input_files = 1;
        job->opt.frame = job->n_frames ? job->frames[0] : -1;
        rc = job_validate(job, stages, &list);
    } else {
        rc = job->n_frames ? check_frames(job, stages) : job_validate(job, stages, &list);
    }
    job_free(job);
    return rc;
}

int
mcp_job_check(const char *path, const mcp_stage *const *stages)
{
    return check_job_file(path, stages, 0);
}

int
mcp_job_check_settings(const char *path, const mcp_stage *const *stages)
{
    return check_job_file(path, stages, 1);
}

int
mcp_job_frames(const char *path, const mcp_job_options *opt, int **frames, int *count,
               char **output_dir)
{
    *frames = NULL, *count = 0;
    if (output_dir) *output_dir = NULL;
    mcp_job_options base = opt ? *opt : mcp_job_defaults();
    base.frame = -1;
    mcp_job *job = NULL;
    if (job_open(path, &base, &job)) return -1;
    int rc = 0;
    if (output_dir && !(*output_dir = mcp_strdup(job->output_dir))) rc = -1;
    if (!rc) {
        *frames = job->frames, *count = job->n_frames;
        job->frames = NULL, job->n_frames = 0;
    }
    job_free(job);
    return rc;
}

/* report.html first and report.json last, each atomically, into the hidden folder that
 * becomes the output folder once they are written (begin_whole_output). */
static int
write_report(mcp_job *job)
{
    char *html = NULL, *json = cJSON_Print(mcp_report_json(job->report)), path[4096];
    int rc = -1;
    if (!json)
        mcp_error("out of memory");
    else if (!mcp_report_html(job->report, job->output_dir, &html) &&
             !mcp_job_output_path(job, "report.html", path, sizeof path) &&
             !mcp_write_file_atomic(path, html, strlen(html)) &&
             !mcp_job_output_path(job, "report.json", path, sizeof path) &&
             !mcp_write_file_atomic(path, json, strlen(json)))
        rc = 0;
    free(json);
    free(html);
    return rc;
}

/* The output folder appears whole (common/io/outdir.c; docs/conventions.md, "Output
 * folders"): the stages write into a hidden folder beside it, named by its real path
 * (no "jobs/../../out" in messages and reports), which becomes job->output_dir. A
 * frame's folder in a shot's output (beside frames.json) is mcpost's by its place:
 * replaced whatever it holds (a frame run again after its report.json was removed). */
static int
begin_whole_output(mcp_job *job, mcp__outdir *o)
{
    char dir[4096], parent[4096], real_dir[8200];
    snprintf(dir, sizeof dir, "%s", job->output_dir);
    size_t n = strlen(dir);
    while (n > 1 && dir[n - 1] == '/')
        dir[--n] = '\0';
    char *slash = strrchr(dir, '/');
    const char *base = slash ? slash + 1 : dir, *path = dir;
    snprintf(parent, sizeof parent, "%.*s",
             slash ? (int)(slash - dir) + (slash == dir) : 1, slash ? dir : ".");
    char *real = NULL;
    /* ".", ".." and "/" are refused by mcp__outdir_begin, by the name given */
    if (*base && strcmp(base, ".") && strcmp(base, "..")) {
        if (mcp_make_dirs(parent)) return -1;
        if ((real = realpath(parent, NULL))) {
            snprintf(real_dir, sizeof real_dir, "%s/%s", strcmp(real, "/") ? real : "",
                     base);
            path = real_dir;
        }
    }
    char manifest[8300];
    struct stat st;
    snprintf(manifest, sizeof manifest, "%s/frames.json", real ? real : parent);
    free(real);
    int owned = job->opt.frame >= 0 && stat(manifest, &st) == 0;
    if (owned ? mcp__outdir_begin_owned(o, path) : mcp__outdir_begin(o, path)) return -1;
    char *tmp = mcp_strdup(o->tmp);
    if (!tmp) {
        mcp__outdir_abort(o);
        return -1;
    }
    free(job->output_dir);
    job->output_dir = tmp;
    job->output_made = 1;
    return 0;
}

int
mcp_job_run_file(const char *path, const mcp_stage *const *stages,
                 const mcp_job_options *opt)
{
    mcp_job *job = NULL;
    if (!stages) stages = mcp_job_stages();
    if (job_open(path, opt, &job)) return -1;
    int rc = -1;
    const mcp_node *list = NULL;
    mcp__outdir whole = {0};
    /* quiet covers the job's own notes and all that its stages print through mcp_note
     * and mcp_progress, which read the process-wide switch: it is set for the run and
     * put back as the caller had it */
    int was_quiet = mcp_progress_quiet();
    if (job->opt.quiet) mcp_progress_set_quiet(1);
    if (job->n_frames && job->opt.frame < 0) {
        char set[256];
        if (mcp_frames_format(job->frames, job->n_frames, set, sizeof set))
            snprintf(set, sizeof set, "%d frames", job->n_frames);
        mcp_error("%s: the job has frames: (%s); run them with mcpost run, or name one",
                  job->path, set);
        goto done;
    }
    /* check everything before running anything */
    if (job_validate(job, stages, &list)) goto done;
    /* a frame run again (--force) stays complete, the old run's, until the new one
       is renamed into place */
    if (begin_whole_output(job, &whole)) {
        mcp_error_prefix("%s: output: ", job->path);
        goto done;
    }
    /* the inputs once more, now that the folder the run replaces is known */
    job->whole = &whole;
    if (check_inputs(job)) goto done;
    for (int i = 0; i < list->count; i++) {
        const mcp_stage *stage;
        const mcp_node *settings;
        stage_at(list->items[i], stages, &stage, &settings);
        mcp_node *empty = settings ? NULL : empty_map_at(list->items[i]);
        if (!settings && !empty) goto done;
        mcp_note("[%d/%d] %s", i + 1, list->count, stage->name);
        /* the stage's title: heads the sections it makes (its type checked before) */
        const char *title = NULL;
        if (settings) mcp_node_opt_string(settings, "title", &title);
        mcp__report_set_heading(job->report, title);
        int failed = stage->run(job, settings ? settings : empty);
        mcp__report_set_heading(job->report, NULL);
        free(empty);
        if (failed) {
            stage_error_place(job, list->items[i], stage);
            goto done;
        }
    }
    /* the report names the folder where it will be */
    if (mcp__outdir_fix_paths(&whole, mcp_report_json(job->report)) ||
        write_report(job) || mcp__outdir_commit(&whole))
        goto done;
    if (job->opt.json_stdout) {
        char *json = cJSON_Print(mcp_report_json(job->report));
        if (json) puts(json);
        free(json);
    }
    mcp_note("results in %s (report.html, report.json)", whole.final);
    rc = 0;
done:
    mcp__outdir_abort(&whole);
    mcp_progress_set_quiet(was_quiet);
    job_free(job);
    return rc;
}
