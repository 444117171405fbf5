/* gate.c: pass / warning / failure conditions on the figures of `mcpost metrics` and
 * of the metrics stage (docs/metrics.md, "Gates"). CI jobs gate image comparisons on
 * a threshold, as idiff's -fail / -warn and flip's --exit-on-test do; here a condition
 * names any figure of the metrics JSON, so one syntax covers FLIP, relMSE, PSNR, ...
 * A percent condition bounds the share of pixels above a per-pixel threshold, as
 * idiff's -failpercent does, read from the metrics' pixels_above. */
#include "internal.h"

#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *
op_text(int op)
{
    return op == '>' ? ">" : op == 'G' ? ">=" : op == '<' ? "<" : "<=";
}

int
mcp__gate_add(mcp__gate *g, const char *expr, int is_fail)
{
    const char *what = is_fail ? "--fail" : "--warn";
    if (g->n >= MCP__GATE_MAX)
        return mcp_error("%s: at most %d conditions in all", what, MCP__GATE_MAX);
    mcp__gate_cond *c = &g->c[g->n];
    memset(c, 0, sizeof *c);
    const char *p = expr;
    while (isspace((unsigned char)*p))
        p++;
    size_t len = 0;
    while (isalnum((unsigned char)p[len]) || p[len] == '_' || p[len] == '.')
        len++;
    if (len == 0 || len >= sizeof c->figure) goto bad;
    memcpy(c->figure, p, len);
    p += len;
    while (isspace((unsigned char)*p))
        p++;
    if (*p == '>' || *p == '<') {
        c->op = p[1] == '=' ? (*p == '>' ? 'G' : 'L') : *p;
        p += p[1] == '=' ? 2 : 1;
    } else
        goto bad;
    char *end = NULL;
    c->value = strtod(p, &end);
    if (end == p || !isfinite(c->value)) goto bad;
    while (isspace((unsigned char)*end))
        end++;
    if (*end) goto bad;
    c->is_fail = is_fail;
    char text[sizeof c->text]; /* built aside: c->figure may not be both source and
                                  destination of one snprintf (restrict) */
    snprintf(text, sizeof text, "%s %s %g", c->figure, op_text(c->op), c->value);
    memcpy(c->text, text, sizeof text);
    g->n++;
    return 0;
bad:
    return mcp_error("%s '%s': want FIGURE OP NUMBER, OP one of > >= < <= "
                     "(e.g. 'flip_ldr.mean > 0.05')",
                     what, expr);
}

static const char *
flag_of(const mcp__gate_cond *c)
{
    return c->percent ? (c->is_fail ? "--fail-percent" : "--warn-percent")
                      : (c->is_fail ? "--fail" : "--warn");
}

int
mcp__gate_add_percent(mcp__gate *g, const char *expr, int is_fail)
{
    const char *what = is_fail ? "--fail-percent" : "--warn-percent";
    if (g->n >= MCP__GATE_MAX)
        return mcp_error("%s: at most %d conditions in all", what, MCP__GATE_MAX);
    mcp__gate_cond *c = &g->c[g->n];
    memset(c, 0, sizeof *c);
    char map[32];
    int used = 0;
    mcp_above_map m;
    /* MAP THRESHOLD PERCENT[%], as idiff's -fail T -failpercent P in one argument */
    if (sscanf(expr, " %31s %lf %lf%n", map, &c->threshold, &c->value, &used) != 3)
        goto bad;
    const char *rest = expr + used;
    if (*rest == '%') rest++;
    while (isspace((unsigned char)*rest))
        rest++;
    if (*rest || !isfinite(c->threshold) || !(c->value >= 0.0 && c->value <= 100.0))
        goto bad;
    if (mcp_above_map_from_name(map, &m))
        return mcp_error("%s '%s': unknown map '%s' (use flip_ldr, flip_hdr or relse)",
                         what, expr, map);
    snprintf(c->figure, sizeof c->figure, "%s", map);
    c->percent = 1;
    c->op = '>';
    c->is_fail = is_fail;
    snprintf(c->text, sizeof c->text, "%s > %g on more than %g%% of the pixels", map,
             c->threshold, c->value);
    g->n++;
    return 0;
bad:
    return mcp_error("%s '%s': want MAP THRESHOLD PERCENT, MAP one of flip_ldr, "
                     "flip_hdr, relse, PERCENT in [0, 100] (e.g. 'flip_ldr 0.1 1%%')",
                     what, expr);
}

int
mcp__gate_request(const mcp__gate *g, mcp_metrics_options *o)
{
    for (int i = 0; i < g->n; i++) {
        const mcp__gate_cond *c = &g->c[i];
        mcp_above_map m;
        if (!c->percent) continue;
        if (mcp_above_map_from_name(c->figure, &m) ||
            mcp_metrics_add_above(o, m, c->threshold)) {
            char why[512]; /* copied: mcp_error rewrites the line it would read */
            snprintf(why, sizeof why, "%s", mcp_error_message());
            return mcp_error("%s '%s': %s", flag_of(c), c->text, why);
        }
    }
    return 0;
}

cJSON *
mcp__gate_metrics_names(const mcp_metrics_options *o)
{
    /* The same function fills the real JSON, so the names cannot drift apart. */
    mcp_metrics m;
    memset(&m, 0, sizeof m);
    m.n_percentiles = o->n_percentiles;
    for (int k = 0; k < o->n_percentiles; k++)
        m.percentiles[k] = o->percentiles[k];
    m.has_flip_ldr = o->flip_ldr;
    m.has_flip_hdr = o->flip_hdr;
    m.has_spectra = o->spectra;
    /* shares of pixels only of the maps these options compute: a percent condition
     * on a FLIP that is off is then named as unknown, before anything runs */
    for (int k = 0; k < o->n_above; k++)
        if ((o->above[k].map != MCP_ABOVE_FLIP_LDR || o->flip_ldr) &&
            (o->above[k].map != MCP_ABOVE_FLIP_HDR || o->flip_hdr))
            m.above[m.n_above++] = o->above[k];
    cJSON *doc = cJSON_CreateObject();
    if (!doc) return NULL;
    cJSON_AddNumberToObject(doc, "width", 0);
    cJSON_AddNumberToObject(doc, "height", 0);
    if (mcp_metrics_json(&m, o, doc)) {
        cJSON_Delete(doc);
        return NULL;
    }
    return doc;
}

/* The item at a dotted path; a numeric part indexes an array
 * (relse_percentiles.value.2). */
static const cJSON *
lookup(const cJSON *root, const char *path)
{
    const cJSON *at = root;
    for (const char *p = path; at && *p;) {
        char part[128];
        size_t len = strcspn(p, ".");
        if (len == 0 || len >= sizeof part) return NULL;
        memcpy(part, p, len);
        part[len] = 0;
        p += len + (p[len] == '.');
        if (cJSON_IsArray(at)) {
            char *e = NULL;
            long i = strtol(part, &e, 10);
            at = *e || i < 0 ? NULL : cJSON_GetArrayItem(at, (int)i);
        } else
            at = cJSON_IsObject(at) ? cJSON_GetObjectItemCaseSensitive(at, part) : NULL;
    }
    return at;
}

/* The numbers of figures by name ("mse, relmse, flip_ldr.mean, ..."), a few. */
static void
known_names(const cJSON *obj, const char *prefix, char *buf, size_t cap, int *count)
{
    for (const cJSON *it = obj ? obj->child : NULL; it && *count < 12; it = it->next) {
        char name[160];
        snprintf(name, sizeof name, "%s%s", prefix, it->string ? it->string : "");
        if (cJSON_IsNumber(it)) {
            size_t len = strlen(buf);
            snprintf(buf + len, cap - len, "%s%s", *count ? ", " : "", name);
            ++*count;
        } else if (cJSON_IsObject(it)) {
            char sub[170];
            snprintf(sub, sizeof sub, "%s.", name);
            known_names(it, sub, buf, cap, count);
        }
    }
}

/* The share of pixels above a percent condition's threshold, from pixels_above. */
static const cJSON *
share_of(const cJSON *figures, const mcp__gate_cond *c)
{
    const cJSON *a;
    cJSON_ArrayForEach(a, cJSON_GetObjectItemCaseSensitive(figures, "pixels_above"))
    {
        const cJSON *map = cJSON_GetObjectItemCaseSensitive(a, "map"),
                    *t = cJSON_GetObjectItemCaseSensitive(a, "threshold");
        if (cJSON_IsString(map) && !strcmp(map->valuestring, c->figure) &&
            cJSON_IsNumber(t) && t->valuedouble == c->threshold)
            return cJSON_GetObjectItemCaseSensitive(a, "percent");
    }
    return NULL;
}

static const cJSON *
value_of(const cJSON *figures, const mcp__gate_cond *c)
{
    return c->percent ? share_of(figures, c) : lookup(figures, c->figure);
}

int
mcp__gate_check(const mcp__gate *g, const cJSON *figures, int *bad)
{
    for (int i = 0; i < g->n; i++) {
        if (cJSON_IsNumber(value_of(figures, &g->c[i]))) continue;
        if (bad) *bad = i;
        if (g->c[i].percent)
            return mcp_error(
                "%s '%s': the metrics have no share of pixels above %g in "
                "%s%s",
                flag_of(&g->c[i]), g->c[i].text, g->c[i].threshold, g->c[i].figure,
                strcmp(g->c[i].figure, "relse") ? " (is that FLIP computed?)" : "");
        char names[600] = "";
        int count = 0;
        known_names(figures, "", names, sizeof names, &count);
        return mcp_error("%s '%s': no figure '%s' in the metrics (known: %s%s)",
                         flag_of(&g->c[i]), g->c[i].text, g->c[i].figure, names,
                         count >= 12 ? ", ..." : "");
    }
    return 0;
}

static int
holds(const mcp__gate_cond *c, double v)
{
    /* A figure that is not a number (NaN: e.g. a broken image) cannot show that it is
     * within bounds, so it counts as holding: a gate errs on the side of failing. */
    if (isnan(v)) return 1;
    switch (c->op) {
    case '>':
        return v > c->value;
    case 'G':
        return v >= c->value;
    case '<':
        return v < c->value;
    default:
        return v <= c->value;
    }
}

int
mcp__gate_eval(const mcp__gate *g, const cJSON *figures, mcp__gate_verdict *verdict,
               cJSON **gate_json, char *line, size_t cap)
{
    if (mcp__gate_check(g, figures, NULL)) return -1;
    char failed[1024] = "", warned[1024] = "";
    int n_failed = 0, n_warned = 0;
    cJSON *j = gate_json ? cJSON_CreateObject() : NULL;
    cJSON *jv = j ? cJSON_AddStringToObject(j, "verdict", "pass") : NULL;
    cJSON *jf = j ? cJSON_AddArrayToObject(j, "failed") : NULL;
    cJSON *jw = j ? cJSON_AddArrayToObject(j, "warned") : NULL;
    for (int i = 0; i < g->n; i++) {
        const mcp__gate_cond *c = &g->c[i];
        double v = value_of(figures, c)->valuedouble;
        if (!holds(c, v)) continue;
        char *buf = c->is_fail ? failed : warned;
        int *n = c->is_fail ? &n_failed : &n_warned;
        size_t len = strlen(buf);
        /* the figure's value beside the condition: what the CI log reader wants next */
        snprintf(buf + len, sizeof failed - len, "%s%s (%.6g%s)", *n ? "; " : "", c->text,
                 v, c->percent ? "%" : "");
        ++*n;
        if (j) cJSON_AddItemToArray(c->is_fail ? jf : jw, cJSON_CreateString(c->text));
    }
    mcp__gate_verdict v = n_failed   ? MCP__GATE_FAILURE
                          : n_warned ? MCP__GATE_WARNING
                                     : MCP__GATE_PASS;
    if (v == MCP__GATE_FAILURE)
        snprintf(line, cap, "FAILURE: %s", failed);
    else if (v == MCP__GATE_WARNING)
        snprintf(line, cap, "WARNING: %s", warned);
    else
        snprintf(line, cap, "PASS");
    if (j) {
        /* verdict first in the object, for people reading the JSON */
        cJSON_SetValuestring(jv, v == MCP__GATE_FAILURE   ? "failure"
                                 : v == MCP__GATE_WARNING ? "warning"
                                                          : "pass");
        *gate_json = j;
    }
    *verdict = v;
    return 0;
}

int
mcp__gate_exit_code(mcp__gate_verdict v)
{
    return v == MCP__GATE_FAILURE   ? MCP__GATE_EXIT_FAILURE
           : v == MCP__GATE_WARNING ? MCP__GATE_EXIT_WARNING
                                    : 0;
}

/* One process runs one job (or, with -j 1, the frames of one shot in turn), so a
 * process-wide worst verdict is what `mcpost run` needs without widening the job API. */
static mcp__gate_verdict worst = MCP__GATE_PASS;

void
mcp__gate_record(mcp__gate_verdict v)
{
    if (v > worst) worst = v;
}

mcp__gate_verdict
mcp__gate_worst(void)
{
    return worst;
}

void
mcp__gate_reset(void)
{
    worst = MCP__GATE_PASS;
}

int
mcp__gate_from_settings(const mcp_metrics_settings *s, mcp_metrics_options *o,
                        mcp__gate *g, const char **bad_key, int *bad_index)
{
    /* the four kinds in the table's order, each condition added, its percent share
       requested and its figure checked before the next, so the first bad one is named */
    const struct {
        const char *key;
        const char *const *texts;
        int n, is_fail, percent;
    } kinds[] = {{"fail", s->fail, s->n_fail, 1, 0},
                 {"warn", s->warn, s->n_warn, 0, 0},
                 {"fail_percent", s->fail_percent, s->n_fail_percent, 1, 1},
                 {"warn_percent", s->warn_percent, s->n_warn_percent, 0, 1}};
    memset(g, 0, sizeof *g);
    for (int k = 0; k < 4; k++)
        for (int i = 0; i < kinds[k].n; i++) {
            *bad_key = kinds[k].key;
            *bad_index = i;
            const char *t = kinds[k].texts[i];
            if (kinds[k].percent ? mcp__gate_add_percent(g, t, kinds[k].is_fail)
                                 : mcp__gate_add(g, t, kinds[k].is_fail))
                return -1;
            if (!o) continue; /* collect: each section's own figures judge it */
            mcp__gate one = {.n = 1};
            one.c[0] = g->c[g->n - 1];
            if (mcp__gate_request(&one, o)) return -1;
            cJSON *names = mcp__gate_metrics_names(o);
            int bad = !names || mcp__gate_check(&one, names, NULL);
            cJSON_Delete(names);
            if (bad) return -1;
        }
    *bad_key = NULL;
    *bad_index = -1;
    return 0;
}
