/* yaml.c: job files as a tree of nodes that remember their line (see yaml.h).
 *
 * libyaml's event API builds the tree; JSON is YAML, so it parses too. Anchors and
 * aliases are refused (a job file has no use for them and they make line numbers
 * ambiguous). */
#define _POSIX_C_SOURCE 200809L
#include <mcpost/yaml.h>

#include <yaml.h>

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* Deeper nesting than this is refused: parse_node() recurses once per level (libyaml
 * itself has no limit), and a job file needs about five levels, so a few thousand
 * brackets would otherwise overflow the stack. */
#define YAML_MAX_DEPTH 64

typedef struct builder {
    yaml_parser_t parser;
    const char *file; /* shared by every node; owned by the root's `file` copy */
} builder;

static mcp_node *
node_new(mcp_node_kind kind, const yaml_mark_t *mark, const char *file)
{
    mcp_node *n = mcp_calloc(1, sizeof *n);
    if (n) {
        n->kind = kind;
        n->line = (int)mark->line + 1;
        n->column = (int)mark->column + 1;
        n->file = file;
    }
    return n;
}

static void
node_free(mcp_node *n)
{
    if (!n) return;
    for (int i = 0; i < n->count; i++) {
        node_free(n->items[i]);
        if (n->keys) node_free(n->keys[i]);
    }
    free(n->items);
    free(n->keys);
    free(n->value);
    free(n);
}

static int
append(mcp_node *parent, mcp_node *key, mcp_node *value)
{
    size_t n = (size_t)parent->count + 1;
    mcp_node **items = mcp_realloc(parent->items, n * sizeof *items);
    if (!items) return mcp_error("out of memory reading %s", parent->file);
    parent->items = items;
    if (parent->kind == MCP_NODE_MAP) {
        mcp_node **keys = mcp_realloc(parent->keys, n * sizeof *keys);
        if (!keys) return mcp_error("out of memory reading %s", parent->file);
        parent->keys = keys;
        keys[parent->count] = key;
    }
    items[parent->count++] = value;
    return 0;
}

static int
parse_error(builder *b)
{
    const yaml_parser_t *p = &b->parser;
    return mcp_error("%s:%d: %s%s%s", b->file, (int)p->problem_mark.line + 1,
                     p->problem ? p->problem : "bad YAML", p->context ? " " : "",
                     p->context ? p->context : "");
}

/* Parses one node whose first event is *ev (consumed) at nesting level `depth` (the
 * document's root is 0); recursion follows nesting. */
static int
parse_node(builder *b, yaml_event_t *ev, int depth, mcp_node **out)
{
    *out = NULL;
    switch (ev->type) {
    case YAML_SCALAR_EVENT: {
        mcp_node *n = node_new(MCP_NODE_SCALAR, &ev->start_mark, b->file);
        if (!n || !(n->value = mcp_strdup((const char *)ev->data.scalar.value))) {
            node_free(n);
            return -1;
        }
        n->quoted = ev->data.scalar.style == YAML_SINGLE_QUOTED_SCALAR_STYLE ||
                    ev->data.scalar.style == YAML_DOUBLE_QUOTED_SCALAR_STYLE;
        *out = n;
        return 0;
    }
    case YAML_ALIAS_EVENT:
        return mcp_error("%s:%d: aliases are not supported in job files", b->file,
                         (int)ev->start_mark.line + 1);
    case YAML_SEQUENCE_START_EVENT:
    case YAML_MAPPING_START_EVENT: {
        int is_map = ev->type == YAML_MAPPING_START_EVENT;
        if (depth >= YAML_MAX_DEPTH)
            return mcp_error("%s:%d: lists and maps nested deeper than %d levels",
                             b->file, (int)ev->start_mark.line + 1, YAML_MAX_DEPTH);
        mcp_node *n =
            node_new(is_map ? MCP_NODE_MAP : MCP_NODE_SEQ, &ev->start_mark, b->file);
        if (!n) return -1;
        for (;;) {
            yaml_event_t e;
            if (!yaml_parser_parse(&b->parser, &e)) {
                node_free(n);
                return parse_error(b);
            }
            if (e.type == YAML_SEQUENCE_END_EVENT || e.type == YAML_MAPPING_END_EVENT) {
                yaml_event_delete(&e);
                break;
            }
            mcp_node *key = NULL, *value = NULL;
            int rc = parse_node(b, &e, depth + 1, is_map ? &key : &value);
            yaml_event_delete(&e);
            if (!rc && is_map) {
                if (key->kind != MCP_NODE_SCALAR)
                    rc = mcp_error("%s:%d: keys must be plain words", b->file, key->line);
                for (int i = 0; !rc && i < n->count; i++)
                    if (strcmp(n->keys[i]->value, key->value) == 0)
                        rc = mcp_error("%s:%d: key '%s' appears twice (first at line %d)",
                                       b->file, key->line, key->value, n->keys[i]->line);
                if (!rc) {
                    yaml_event_t v;
                    if (!yaml_parser_parse(&b->parser, &v))
                        rc = parse_error(b);
                    else {
                        rc = parse_node(b, &v, depth + 1, &value);
                        yaml_event_delete(&v);
                    }
                }
            }
            if (rc || append(n, key, value)) {
                node_free(key);
                node_free(value);
                node_free(n);
                return -1;
            }
        }
        *out = n;
        return 0;
    }
    default:
        return mcp_error("%s:%d: unexpected YAML structure", b->file,
                         (int)ev->start_mark.line + 1);
    }
}

static int
parse(yaml_parser_t *parser, const char *label, mcp_node **out)
{
    builder b = {.file = label};
    b.parser = *parser;
    int rc = -1;
    mcp_node *doc = NULL;
    yaml_event_t ev;
    int depth = 0;
    for (;;) {
        if (!yaml_parser_parse(&b.parser, &ev)) {
            parse_error(&b);
            break;
        }
        if (ev.type == YAML_STREAM_START_EVENT || ev.type == YAML_DOCUMENT_START_EVENT) {
            depth += ev.type == YAML_DOCUMENT_START_EVENT;
            yaml_event_delete(&ev);
            if (depth > 1) {
                mcp_error("%s: more than one YAML document", label);
                break;
            }
            continue;
        }
        if (ev.type == YAML_DOCUMENT_END_EVENT) {
            yaml_event_delete(&ev);
            continue;
        }
        if (ev.type == YAML_STREAM_END_EVENT) {
            yaml_event_delete(&ev);
            if (!doc)
                mcp_error("%s: empty job file", label);
            else
                rc = 0;
            break;
        }
        if (doc) {
            mcp_error("%s:%d: more than one YAML document", label,
                      (int)ev.start_mark.line + 1);
            yaml_event_delete(&ev);
            break;
        }
        int r = parse_node(&b, &ev, 0, &doc);
        yaml_event_delete(&ev);
        if (r) break;
    }
    *parser = b.parser;
    if (rc) {
        node_free(doc);
        return -1;
    }
    *out = doc;
    return 0;
}

/* Every node points at one copy of the label; the copy is kept just before the root
 * in one allocation so that mcp_node_free() can release it. */
typedef struct labelled_root {
    mcp_node root;
    char label[];
} labelled_root;

static void
relabel(mcp_node *n, const char *label)
{
    n->file = label;
    for (int i = 0; i < n->count; i++) {
        relabel(n->items[i], label);
        if (n->keys) relabel(n->keys[i], label);
    }
}

/* Moves the parsed root into a labelled_root that owns the label text. */
static int
adopt(mcp_node *doc, const char *label, mcp_node **out)
{
    labelled_root *r = mcp_malloc(sizeof *r + strlen(label) + 1);
    if (!r) {
        node_free(doc);
        return -1;
    }
    strcpy(r->label, label);
    r->root = *doc;
    free(doc);
    relabel(&r->root, r->label);
    *out = &r->root;
    return 0;
}

int
mcp_yaml_parse_string(const char *text, const char *label, mcp_node **out)
{
    yaml_parser_t parser;
    *out = NULL;
    if (!yaml_parser_initialize(&parser))
        return mcp_error("%s: cannot start the YAML parser", label);
    yaml_parser_set_input_string(&parser, (const unsigned char *)text, strlen(text));
    mcp_node *doc = NULL;
    int rc = parse(&parser, label, &doc);
    yaml_parser_delete(&parser);
    return rc ? -1 : adopt(doc, label, out);
}

int
mcp_yaml_parse_file(const char *path, mcp_node **out)
{
    *out = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) return mcp_error("%s: cannot open: %s", path, strerror(errno));
    yaml_parser_t parser;
    if (!yaml_parser_initialize(&parser)) {
        fclose(f);
        return mcp_error("%s: cannot start the YAML parser", path);
    }
    yaml_parser_set_input_file(&parser, f);
    mcp_node *doc = NULL;
    int rc = parse(&parser, path, &doc);
    yaml_parser_delete(&parser);
    fclose(f);
    return rc ? -1 : adopt(doc, path, out);
}

void
mcp_node_free(mcp_node *root)
{
    if (!root) return;
    /* the root sits at the start of a labelled_root allocation */
    for (int i = 0; i < root->count; i++) {
        node_free(root->items[i]);
        if (root->keys) node_free(root->keys[i]);
    }
    free(root->items);
    free(root->keys);
    free(root->value);
    free((labelled_root *)root);
}

/* ---- typed access ---- */

int
mcp_node_error(const mcp_node *n, const char *fmt, ...)
{
    char msg[768];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return mcp_error("%s:%d: %s", n->file, n->line, msg);
}

const mcp_node *
mcp_node_get(const mcp_node *map, const char *key)
{
    if (!map || map->kind != MCP_NODE_MAP) return NULL;
    for (int i = 0; i < map->count; i++)
        if (strcmp(map->keys[i]->value, key) == 0) return map->items[i];
    return NULL;
}

int
mcp_node_check_keys(const mcp_node *map, const char *const *allowed, const char *what)
{
    if (!map || map->kind != MCP_NODE_MAP)
        return map ? mcp_node_error(map, "%s must be a map of settings", what)
                   : mcp_error("%s: no settings", what);
    for (int i = 0; i < map->count; i++) {
        int ok = 0;
        for (const char *const *a = allowed; a && *a && !ok; a++)
            ok = strcmp(*a, map->keys[i]->value) == 0;
        if (ok) continue;
        char known[512] = "";
        size_t n = 0;
        for (const char *const *a = allowed; a && *a; a++)
            n += (size_t)snprintf(known + n, n < sizeof known ? sizeof known - n : 0,
                                  "%s%s", a == allowed ? "" : ", ", *a);
        return mcp_node_error(map->keys[i], "unknown key '%s' in %s (known: %s)",
                              map->keys[i]->value, what, known[0] ? known : "none");
    }
    return 0;
}

static int
want_scalar(const mcp_node *n, const char *key, const char *type)
{
    if (n->kind == MCP_NODE_SCALAR) return 0;
    return mcp_node_error(n, "%s must be %s, not a %s", key, type,
                          n->kind == MCP_NODE_MAP ? "map" : "list");
}

int
mcp_node_int(const mcp_node *n, const char *key, int *out)
{
    if (want_scalar(n, key, "an integer")) return -1;
    char *end;
    errno = 0;
    long v = strtol(n->value, &end, 10);
    if (n->quoted || end == n->value || *end || errno || v < -2147483647L - 1 ||
        v > 2147483647L)
        return mcp_node_error(n, "%s must be an integer (got '%s')", key, n->value);
    *out = (int)v;
    return 0;
}

int
mcp_node_double(const mcp_node *n, const char *key, double *out)
{
    if (want_scalar(n, key, "a number")) return -1;
    char *end;
    errno = 0;
    double v = strtod(n->value, &end);
    if (n->quoted || end == n->value || *end || errno || !isfinite(v))
        return mcp_node_error(n, "%s must be a number (got '%s')", key, n->value);
    *out = v;
    return 0;
}

int
mcp_node_bool(const mcp_node *n, const char *key, int *out)
{
    if (want_scalar(n, key, "true or false")) return -1;
    static const char *yes[] = {"true", "yes", "on"}, *no[] = {"false", "no", "off"};
    for (int i = 0; i < 3 && !n->quoted; i++) {
        if (strcasecmp(n->value, yes[i]) == 0) return *out = 1, 0;
        if (strcasecmp(n->value, no[i]) == 0) return *out = 0, 0;
    }
    return mcp_node_error(n, "%s must be true or false (got '%s')", key, n->value);
}

int
mcp_node_string(const mcp_node *n, const char *key, const char **out)
{
    if (want_scalar(n, key, "a string")) return -1;
    *out = n->value;
    return 0;
}

int
mcp_node_opt_int(const mcp_node *map, const char *key, int *out)
{
    const mcp_node *n = mcp_node_get(map, key);
    return n ? mcp_node_int(n, key, out) : 0;
}

int
mcp_node_opt_double(const mcp_node *map, const char *key, double *out)
{
    const mcp_node *n = mcp_node_get(map, key);
    return n ? mcp_node_double(n, key, out) : 0;
}

int
mcp_node_opt_bool(const mcp_node *map, const char *key, int *out)
{
    const mcp_node *n = mcp_node_get(map, key);
    return n ? mcp_node_bool(n, key, out) : 0;
}

int
mcp_node_opt_string(const mcp_node *map, const char *key, const char **out)
{
    const mcp_node *n = mcp_node_get(map, key);
    return n ? mcp_node_string(n, key, out) : 0;
}

int
mcp_node_opt_doubles(const mcp_node *map, const char *key, double **out, int *count)
{
    const mcp_node *n = mcp_node_get(map, key);
    if (!n) return 0;
    int m = n->kind == MCP_NODE_SEQ ? n->count : 1;
    if (n->kind == MCP_NODE_MAP)
        return mcp_node_error(n, "%s must be a number or a list of numbers", key);
    double *v = mcp_calloc((size_t)m, sizeof *v);
    if (!v) return -1;
    for (int i = 0; i < m; i++)
        if (mcp_node_double(n->kind == MCP_NODE_SEQ ? n->items[i] : n, key, &v[i])) {
            free(v);
            return -1;
        }
    free(*out);
    *out = v;
    *count = m;
    return 0;
}

int
mcp_node_require(const mcp_node *map, const char *key, const char *what,
                 const mcp_node **out)
{
    *out = mcp_node_get(map, key);
    if (!*out) return mcp_node_error(map, "missing key '%s' in %s", key, what);
    return 0;
}
