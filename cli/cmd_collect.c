/* cmd_collect.c: `mcpost collect OUT_DIR` -- one report for the frames of a shot.
 *
 * Reads OUT_DIR/frames.json (the job's frames, written by run and submit) and every
 * frame folder OUT_DIR/NNNN/, takes each complete frame's figures from its report.json
 * (MSE, relMSE, FLIP, estimated error, stop spp of every metrics and estimate section),
 * and writes OUT_DIR/report.json and report.html: each figure plotted against the
 * frame number, a table with the worst frames first, a link to each frame's page, and
 * the frames that are missing, failed or unfinished, listed by name. Gates (--fail,
 * --warn, --fail-percent, --warn-percent; jobs/gate.c) judge each frame's metrics
 * sections as `mcpost metrics` judges a test. */
#include "cli.h"

#include <mcpost/frames.h>
#include <mcpost/imageio.h>
#include <mcpost/progress.h>
#include <mcpost/report.h>

#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char head[] =
    "usage: mcpost collect OUT_DIR [--json] [--quiet] [gates]\n"
    "  Gathers the frames of a frame job (OUT_DIR/0001/report.json, ...) into one\n"
    "  report, OUT_DIR/report.json and report.html: every figure (MSE, relMSE, FLIP,\n"
    "  estimated error, stop spp) against the frame number, the worst frames first\n"
    "  (by relMSE, else MSE, FLIP or estimated error), links to the frames' pages, and\n"
    "  the frames that are missing (never ran), failed (their error.txt) or unfinished.\n"
    "  The expected frames come from OUT_DIR/frames.json, which mcpost run and submit\n"
    "  write. Exits 1 when any frame is not complete (the report is written anyway).\n"
    "  --json prints the report on stdout.\n"
    "  Gates judge every frame's metrics sections (those with an input) as\n"
    "  `mcpost metrics` judges a test (docs/metrics.md, \"Gates\"): --fail 'EXPR',\n"
    "  --warn 'EXPR', --fail-percent 'MAP T P', --warn-percent 'MAP T P' (repeatable;\n"
    "  a share of pixels comes from the section's pixels_above or its map's EXR).\n"
    "  PASS, WARNING: ... or FAILURE: ... is the last line; exit 3 warning, 4 failure\n"
    "  (1 when a frame is not complete).\n";
static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost run samples/jobs/shot.yaml -j 2 && mcpost collect out/shot\n"
    "  mcpost collect out/shot --json > out/shot_figures.json\n"
    "  mcpost collect out/shot --quiet --warn 'relmse > 1' --fail-percent 'flip_ldr 0.9 "
    "1%'\n";

#define MAX_FIGURES 64

typedef enum {
    FRAME_COMPLETE,
    FRAME_FAILED,
    FRAME_UNFINISHED,
    FRAME_MISSING
} frame_status;
static const char *const status_names[] = {"complete", "failed", "unfinished", "missing"};

typedef struct frame_row {
    int frame;
    frame_status status;
    char message[1024];
    double values[MAX_FIGURES];
    /* with gates: the frame's worst verdict over its metrics sections, and what held
     * ("noisy: relmse > 1 (1.3); ...") */
    mcp__gate_verdict verdict;
    char gate_text[1024];
} frame_row;

typedef struct shot {
    const char *dir;
    char *job;   /* from the manifest (NULL when none) */
    char *title; /* the frames' title, without ", frame N" */
    frame_row *rows;
    int n_rows, cap;
    char *figures[MAX_FIGURES];
    int n_figures;
    const mcp__gate *gate; /* NULL: no gates */
    int gate_failed;       /* a frame could not be judged (an error, already said) */
} shot;

static char *
read_text(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    mcp__strbuf text = {0};
    mcp__strbuf_read_file(&text, f);
    fclose(f);
    return mcp__strbuf_take(&text);
}

static frame_row *
add_row(shot *s, int frame)
{
    for (int i = 0; i < s->n_rows; i++)
        if (s->rows[i].frame == frame) return &s->rows[i];
    if (s->n_rows == s->cap) {
        int cap = s->cap ? 2 * s->cap : 64;
        frame_row *grown = realloc(s->rows, (size_t)cap * sizeof *grown);
        if (!grown) {
            mcp_error("out of memory");
            return NULL;
        }
        s->rows = grown, s->cap = cap;
    }
    frame_row *r = &s->rows[s->n_rows++];
    memset(r, 0, sizeof *r);
    r->frame = frame;
    r->status = FRAME_MISSING;
    for (int k = 0; k < MAX_FIGURES; k++)
        r->values[k] = NAN;
    return r;
}

/* The frames the job has (frames.json) and those with a folder here. */
static int
find_frames(shot *s)
{
    char path[4200];
    snprintf(path, sizeof path, "%s/frames.json", s->dir);
    char *text = read_text(path);
    if (text) {
        cJSON *m = cJSON_Parse(text), *frames = cJSON_GetObjectItem(m, "frames");
        free(text);
        if (!cJSON_IsArray(frames)) {
            cJSON_Delete(m);
            return mcp_error("%s: not a frames manifest (no \"frames\" list)", path);
        }
        cJSON *f, *job = cJSON_GetObjectItem(m, "job");
        cJSON_ArrayForEach(f, frames) if (cJSON_IsNumber(f) && !add_row(s, f->valueint))
        {
            cJSON_Delete(m);
            return -1;
        }
        if (cJSON_IsString(job) && !(s->job = mcp_strdup(job->valuestring))) {
            cJSON_Delete(m);
            return -1;
        }
        cJSON_Delete(m);
    }
    DIR *d = opendir(s->dir);
    if (!d) return mcp_error("%s: cannot read the folder: %s", s->dir, strerror(errno));
    for (struct dirent *e; (e = readdir(d));) {
        const char *n = e->d_name;
        size_t len = strlen(n);
        if (len < 4 || len > 7 || strspn(n, "0123456789") != len) continue;
        struct stat st;
        snprintf(path, sizeof path, "%s/%s", s->dir, n);
        if (stat(path, &st) == 0 && S_ISDIR(st.st_mode) && !add_row(s, atoi(n))) {
            closedir(d);
            return -1;
        }
    }
    closedir(d);
    if (!s->n_rows)
        return mcp_error(
            "%s: no frames here (no frames.json and no frame folders such as "
            "0001/)",
            s->dir);
    return 0;
}

static int
figure_index(shot *s, const char *name)
{
    for (int k = 0; k < s->n_figures; k++)
        if (!strcmp(s->figures[k], name)) return k;
    if (s->n_figures == MAX_FIGURES || !(s->figures[s->n_figures] = mcp_strdup(name)))
        return -1;
    return s->n_figures++;
}

static void
put_figure(shot *s, frame_row *r, const char *section, const char *what, double v)
{
    char name[512];
    snprintf(name, sizeof name, "%s: %s", section, what);
    int k = figure_index(s, name);
    if (k >= 0) r->values[k] = v;
}

/* The figures of one section of a frame's report. */
static void
section_figures(shot *s, frame_row *r, const cJSON *sec)
{
    const cJSON *title = cJSON_GetObjectItem(sec, "title"),
                *stage = cJSON_GetObjectItem(sec, "stage");
    /* a section's title names its stage and input ("metrics: noisy against reference") */
    char name[256];
    snprintf(name, sizeof name, "%s",
             cJSON_IsString(title)   ? title->valuestring
             : cJSON_IsString(stage) ? stage->valuestring
                                     : "?");
    static const char *const keys[][2] = {{"mse", "MSE"},
                                          {"relmse", "relMSE"},
                                          {"flip_ldr", "FLIP LDR"},
                                          {"flip_hdr", "FLIP HDR"},
                                          {"expected_mean_error", "estimated error"}};
    for (size_t i = 0; i < sizeof keys / sizeof keys[0]; i++) {
        const cJSON *v = cJSON_GetObjectItem(sec, keys[i][0]);
        if (cJSON_IsObject(v)) /* flip_*: {"mean": ...} */
            v = cJSON_GetObjectItem(v, "mean");
        if (cJSON_IsNumber(v)) put_figure(s, r, name, keys[i][1], v->valuedouble);
    }
    /* estimate over a series: the first spp at which it would stop, per tau */
    const cJSON *table;
    cJSON_ArrayForEach(table, cJSON_GetObjectItem(sec, "tables"))
    {
        const cJSON *cols = cJSON_GetObjectItem(table, "columns"), *row;
        int col = -1, i = 0;
        const cJSON *c;
        cJSON_ArrayForEach(c, cols)
        {
            if (cJSON_IsString(c) && !strcmp(c->valuestring, "estimated first spp"))
                col = i;
            i++;
        }
        if (col < 1) continue;
        cJSON_ArrayForEach(row, cJSON_GetObjectItem(table, "rows"))
        {
            const cJSON *tau = cJSON_GetArrayItem(row, 0),
                        *spp = cJSON_GetArrayItem(row, col);
            char what[64];
            if (!cJSON_IsNumber(tau) || !cJSON_IsNumber(spp)) continue;
            snprintf(what, sizeof what, "stop spp (tau %g)", tau->valuedouble);
            put_figure(s, r, name, what, spp->valuedouble);
        }
    }
}

/* A percent condition's share for a section that did not measure it: counted over
 * the section's map as its job wrote it (<prefix>MAP.exr beside <prefix>MAP.png) and
 * added to its pixels_above, so that the gate reads it as the stage's own. */
static int
add_share_from_map(cJSON *sec, const char *frame_dir, const mcp__gate_cond *c)
{
    const cJSON *a;
    cJSON_ArrayForEach(a, cJSON_GetObjectItem(sec, "pixels_above"))
    {
        const cJSON *map = cJSON_GetObjectItem(a, "map"),
                    *t = cJSON_GetObjectItem(a, "threshold");
        if (cJSON_IsString(map) && !strcmp(map->valuestring, c->figure) &&
            cJSON_IsNumber(t) && t->valuedouble == c->threshold)
            return 0; /* measured by the stage */
    }
    char png[64], path[4400];
    snprintf(png, sizeof png, "%s.png", c->figure);
    const cJSON *img;
    cJSON_ArrayForEach(img, cJSON_GetObjectItem(sec, "images"))
    {
        const cJSON *p = cJSON_GetObjectItem(img, "path");
        size_t n = cJSON_IsString(p) ? strlen(p->valuestring) : 0;
        if (n < strlen(png) || strcmp(p->valuestring + n - strlen(png), png) ||
            (n > strlen(png) && p->valuestring[n - strlen(png) - 1] != '/' &&
             p->valuestring[n - strlen(png) - 1] != '.'))
            continue;
        snprintf(path, sizeof path, "%s/%.*s.exr", frame_dir, (int)(n - 4),
                 p->valuestring);
        mcp_image *map = NULL;
        double percent;
        if (mcp_image_read(path, NULL, &map) ||
            mcp_image_percent_above(map, c->threshold, &percent)) {
            mcp_image_free(map);
            return -1;
        }
        mcp_image_free(map);
        cJSON *list = cJSON_GetObjectItem(sec, "pixels_above");
        if (!list) list = cJSON_AddArrayToObject(sec, "pixels_above");
        cJSON *e = cJSON_CreateObject();
        if (!list || !e) return mcp_error("out of memory");
        cJSON_AddStringToObject(e, "map", c->figure);
        cJSON_AddNumberToObject(e, "threshold", c->threshold);
        cJSON_AddNumberToObject(e, "percent", percent);
        cJSON_AddItemToArray(list, e);
        return 0;
    }
    return 0; /* neither: the gate names what is missing */
}

/* Judges a complete frame's metrics sections (those that compared an input). */
static void
judge_frame(shot *s, frame_row *r, cJSON *rep, const char *frame_dir)
{
    cJSON *sec;
    int judged = 0;
    size_t len = 0;
    cJSON_ArrayForEach(sec, cJSON_GetObjectItem(rep, "sections"))
    {
        const cJSON *stage = cJSON_GetObjectItem(sec, "stage"),
                    *input = cJSON_GetObjectItem(sec, "input");
        if (!cJSON_IsString(stage) || strcmp(stage->valuestring, "metrics") ||
            !cJSON_IsString(input))
            continue;
        judged++;
        mcp__gate_verdict v;
        char line[2200];
        int failed = 0;
        for (int i = 0; i < s->gate->n && !failed; i++)
            if (s->gate->c[i].percent)
                failed = add_share_from_map(sec, frame_dir, &s->gate->c[i]);
        if (failed || mcp__gate_eval(s->gate, sec, &v, NULL, line, sizeof line)) {
            char why[1024]; /* copied: mcp_error rewrites the line it would read */
            snprintf(why, sizeof why, "%s", mcp_error_message());
            mcp_error("frame %d, metrics of %s: %s", r->frame, input->valuestring, why);
            s->gate_failed = 1;
            return;
        }
        if (v > r->verdict) {
            r->verdict = v;
            len = 0;
            r->gate_text[0] = '\0';
        }
        if (v == r->verdict && v != MCP__GATE_PASS && len < sizeof r->gate_text) {
            const char *why = strchr(line, ':');
            len +=
                (size_t)snprintf(r->gate_text + len, sizeof r->gate_text - len, "%s%s:%s",
                                 len ? "; " : "", input->valuestring, why ? why + 1 : "");
        }
    }
    if (!judged) {
        mcp_error("frame %d: no metrics section with an input to judge (%s/report.json)",
                  r->frame, frame_dir);
        s->gate_failed = 1;
    }
}

/* 1 when the shot's folder holds the frame's hidden folder in the making
 * (.0017.tmp-PID). */
static int
running_frame(const char *shot_dir, int frame)
{
    char prefix[32];
    int n = snprintf(prefix, sizeof prefix, ".%04d.tmp-", frame), found = 0;
    DIR *d = opendir(shot_dir);
    if (!d) return 0;
    struct dirent *e;
    while (!found && (e = readdir(d)))
        found = !strncmp(e->d_name, prefix, (size_t)n);
    closedir(d);
    return found;
}

/* One frame's state and figures. */
static void
read_frame(shot *s, frame_row *r)
{
    char dir[4096], path[4200];
    struct stat st;
    mcp_frame_dir(s->dir, r->frame, dir, sizeof dir);
    if (stat(dir, &st) != 0) {
        /* a frame's folder appears whole (common/io/outdir.c): until then it is hidden */
        int hidden = running_frame(s->dir, r->frame);
        r->status = hidden ? FRAME_UNFINISHED : FRAME_MISSING;
        if (hidden)
            snprintf(r->message, sizeof r->message,
                     "no folder %04d/ yet, only its hidden .%04d.tmp-PID: still running, "
                     "or killed",
                     r->frame, r->frame);
        else
            snprintf(r->message, sizeof r->message, "never ran (no folder %04d/)",
                     r->frame);
        return;
    }
    snprintf(path, sizeof path, "%s/report.json", dir);
    char *text = read_text(path);
    cJSON *rep = text ? cJSON_Parse(text) : NULL;
    free(text);
    if (rep) {
        r->status = FRAME_COMPLETE;
        const cJSON *sec, *title = cJSON_GetObjectItem(rep, "title");
        cJSON_ArrayForEach(sec, cJSON_GetObjectItem(rep, "sections"))
            section_figures(s, r, sec);
        if (s->gate && !s->gate_failed) judge_frame(s, r, rep, dir);
        if (!s->title && cJSON_IsString(title) &&
            (s->title = mcp_strdup(title->valuestring))) {
            char *cut = strstr(s->title, ", frame ");
            if (cut) *cut = '\0';
        }
        cJSON_Delete(rep);
        return;
    }
    snprintf(path, sizeof path, "%s/error.txt", dir);
    if ((text = read_text(path))) {
        r->status = FRAME_FAILED;
        text[strcspn(text, "\n")] = '\0';
        snprintf(r->message, sizeof r->message, "%s", text);
        free(text);
        return;
    }
    snprintf(path, sizeof path, "%s/report.json", dir);
    r->status = stat(path, &st) == 0 ? FRAME_FAILED : FRAME_UNFINISHED;
    snprintf(r->message, sizeof r->message, "%s",
             r->status == FRAME_FAILED ? "report.json is not JSON"
                                       : "no report.json: still running, or killed");
}

/* The figure that orders the frames: relMSE, else MSE, FLIP or estimated error. */
static int
rank_figure(const shot *s)
{
    static const char *const order[] = {": relMSE", ": MSE", ": FLIP LDR", ": FLIP HDR",
                                        ": estimated error"};
    for (size_t o = 0; o < sizeof order / sizeof order[0]; o++)
        for (int k = 0; k < s->n_figures; k++) {
            size_t n = strlen(s->figures[k]), m = strlen(order[o]);
            if (n >= m && !strcmp(s->figures[k] + n - m, order[o])) return k;
        }
    return -1;
}

static int rank_by; /* for qsort */
static int
worst_first(const void *a, const void *b)
{
    const frame_row *x = a, *y = b;
    if (x->status != y->status) /* complete frames first; the others have no figures */
        return (x->status > y->status) - (x->status < y->status);
    double u = rank_by >= 0 ? x->values[rank_by] : NAN,
           v = rank_by >= 0 ? y->values[rank_by] : NAN;
    if (isnan(u) != isnan(v)) return isnan(u) ? 1 : -1;
    if (!isnan(u) && u != v) return u < v ? 1 : -1;
    return (x->frame > y->frame) - (x->frame < y->frame);
}

static int
by_frame(const void *a, const void *b)
{
    const frame_row *x = a, *y = b;
    return (x->frame > y->frame) - (x->frame < y->frame);
}

static const char *
verdict_name(mcp__gate_verdict v)
{
    return v == MCP__GATE_FAILURE   ? "failure"
           : v == MCP__GATE_WARNING ? "warning"
                                    : "pass";
}

/* The gates' verdict over the complete frames, the worst, and its line: "PASS", or
 * "FAILURE: frame 3: noisy: relmse > 1 (1.3); frame 7: ..." naming each frame that has
 * the worst verdict. */
static mcp__gate_verdict
gate_line(const shot *s, char *line, size_t cap)
{
    mcp__gate_verdict worst = MCP__GATE_PASS;
    for (int i = 0; i < s->n_rows; i++)
        if (s->rows[i].status == FRAME_COMPLETE && s->rows[i].verdict > worst)
            worst = s->rows[i].verdict;
    size_t len = (size_t)snprintf(line, cap, "%s",
                                  worst == MCP__GATE_FAILURE   ? "FAILURE"
                                  : worst == MCP__GATE_WARNING ? "WARNING"
                                                               : "PASS");
    int shown = 0;
    for (int i = 0; worst != MCP__GATE_PASS && i < s->n_rows && len < cap; i++)
        if (s->rows[i].status == FRAME_COMPLETE && s->rows[i].verdict == worst)
            len += (size_t)snprintf(line + len, cap - len, "%s frame %d: %s",
                                    shown++ ? ";" : ":", s->rows[i].frame,
                                    s->rows[i].gate_text);
    return worst;
}

/* The shot's verdict: good when every frame is complete, bad otherwise (how many are
 * not, and that running the job again retries them); either way the worst complete
 * frame by the ranking figure. */
static int
shot_verdict(const shot *s, cJSON *sec, const int counts[4], int rank)
{
    const frame_row *worst = NULL;
    for (int i = 0; rank >= 0 && i < s->n_rows; i++)
        if (s->rows[i].status == FRAME_COMPLETE && !isnan(s->rows[i].values[rank]) &&
            (!worst || s->rows[i].values[rank] > worst->values[rank]))
            worst = &s->rows[i];
    char worst_text[600] = "";
    if (worst)
        snprintf(worst_text, sizeof worst_text, "; the worst by %s is frame %d (%.4g)",
                 s->figures[rank], worst->frame, worst->values[rank]);
    int complete = counts[FRAME_COMPLETE];
    if (s->gate && complete == s->n_rows) {
        /* the gate decides the colour, as on a metrics section: its line first */
        char line[3000];
        mcp__gate_verdict v = gate_line(s, line, sizeof line);
        return mcp_report_set_verdict(sec,
                                      v == MCP__GATE_FAILURE   ? MCP_VERDICT_BAD
                                      : v == MCP__GATE_WARNING ? MCP_VERDICT_INFO
                                                               : MCP_VERDICT_GOOD,
                                      "gate %s; all %d frames complete%s", line,
                                      s->n_rows, worst_text);
    }
    if (complete == s->n_rows)
        return mcp_report_set_verdict(sec, MCP_VERDICT_GOOD, "all %d frames complete%s",
                                      s->n_rows, worst_text);
    return mcp_report_set_verdict(
        sec, MCP_VERDICT_BAD,
        "%d of %d frames not complete (%d failed, %d unfinished, %d missing); running "
        "the job again retries them%s",
        s->n_rows - complete, s->n_rows, counts[FRAME_FAILED], counts[FRAME_UNFINISHED],
        counts[FRAME_MISSING], worst_text);
}

static int
build_report(shot *s, mcp_report *rep, int counts[4])
{
    cJSON *sec = mcp_report_section(rep, "collect", "the shot");
    if (!sec) return -1;
    cJSON_AddNumberToObject(sec, "frames", s->n_rows);
    for (int st = 0; st < 4; st++)
        cJSON_AddNumberToObject(sec, status_names[st], counts[st]);
    if (s->job) cJSON_AddStringToObject(sec, "job", s->job);
    int rank = rank_figure(s);
    if (rank >= 0) cJSON_AddStringToObject(sec, "worst_first_by", s->figures[rank]);

    /* every frame, machine-readable: its state, figures and page (report.json only:
       the page's tables show the same) */
    cJSON *list = cJSON_AddArrayToObject(sec, "frame_list");
    if (!list || mcp_report_json_only(sec, "frame_list")) return -1;
    for (int i = 0; list && i < s->n_rows; i++) {
        const frame_row *r = &s->rows[i];
        cJSON *o = cJSON_CreateObject(), *fig = cJSON_CreateObject();
        char page[64];
        snprintf(page, sizeof page, "%04d/report.html", r->frame);
        cJSON_AddItemToArray(list, o);
        cJSON_AddNumberToObject(o, "frame", r->frame);
        cJSON_AddStringToObject(o, "status", status_names[r->status]);
        if (r->status == FRAME_COMPLETE)
            cJSON_AddStringToObject(o, "page", page);
        else
            cJSON_AddStringToObject(o, "message", r->message);
        if (s->gate && r->status == FRAME_COMPLETE) {
            cJSON_AddStringToObject(o, "gate", verdict_name(r->verdict));
            if (r->verdict != MCP__GATE_PASS)
                cJSON_AddStringToObject(o, "gate_why", r->gate_text);
        }
        cJSON_AddItemToObject(o, "figures", fig);
        for (int k = 0; k < s->n_figures; k++)
            if (!isnan(r->values[k]))
                cJSON_AddNumberToObject(fig, s->figures[k], r->values[k]);
    }

    /* frames that are not complete: named, never dropped */
    if (counts[FRAME_COMPLETE] < s->n_rows) {
        static const char *const cols[] = {"frame", "status", "why"};
        cJSON *t = mcp_report_add_table(sec, "frames not complete", cols, 3);
        for (int i = 0; t && i < s->n_rows; i++)
            if (s->rows[i].status != FRAME_COMPLETE &&
                mcp_report_table_add_row(t, "iss", s->rows[i].frame,
                                         status_names[s->rows[i].status],
                                         s->rows[i].message))
                return -1;
    }

    /* each figure against the frame number */
    double *x = mcp_calloc((size_t)s->n_rows + 1, sizeof *x),
           *y = mcp_calloc((size_t)s->n_rows + 1, sizeof *y);
    if (!x || !y) {
        free(x), free(y);
        return -1;
    }
    for (int k = 0; k < s->n_figures; k++) {
        int shown = 0;
        for (int i = 0; i < s->n_rows; i++) {
            x[i] = s->rows[i].frame, y[i] = s->rows[i].values[k];
            shown += !isnan(y[i]);
        }
        if (!shown) continue;
        cJSON *plot = mcp_report_add_plot(sec, s->figures[k], "frame", MCP_AXIS_LINEAR,
                                          s->figures[k], MCP_AXIS_LINEAR);
        if (!plot || !mcp_report_plot_add_series(
                         plot, s->figures[k], MCP_SERIES_LINE_POINTS, x, y, s->n_rows)) {
            free(x), free(y);
            return -1;
        }
    }
    free(x), free(y);

    /* the complete frames, worst first */
    if (counts[FRAME_COMPLETE]) {
        const char *cols[MAX_FIGURES + 3];
        int n = 0;
        cols[n++] = "frame";
        for (int k = 0; k < s->n_figures; k++)
            cols[n++] = s->figures[k];
        if (s->gate) cols[n++] = "gate";
        cols[n++] = "page";
        rank_by = rank;
        frame_row *sorted = mcp_calloc((size_t)s->n_rows, sizeof *sorted);
        cJSON *t =
            sorted ? mcp_report_add_table(sec, "frames, worst first", cols, n) : NULL;
        if (!t) {
            free(sorted);
            return -1;
        }
        memcpy(sorted, s->rows, (size_t)s->n_rows * sizeof *sorted);
        qsort(sorted, (size_t)s->n_rows, sizeof *sorted, worst_first);
        /* rows of any width: one cJSON row per frame, as mcp_report_table_add_row
         * writes them (numbers, null for NaN, strings) */
        cJSON *rows = cJSON_GetObjectItem(t, "rows");
        for (int i = 0; i < counts[FRAME_COMPLETE]; i++) {
            cJSON *row = cJSON_CreateArray();
            char page[64];
            snprintf(page, sizeof page, "%04d/report.html", sorted[i].frame);
            cJSON_AddItemToArray(rows, row);
            cJSON_AddItemToArray(row, cJSON_CreateNumber(sorted[i].frame));
            for (int k = 0; k < s->n_figures; k++)
                cJSON_AddItemToArray(row, isnan(sorted[i].values[k])
                                              ? cJSON_CreateNull()
                                              : cJSON_CreateNumber(sorted[i].values[k]));
            if (s->gate)
                cJSON_AddItemToArray(row,
                                     cJSON_CreateString(verdict_name(sorted[i].verdict)));
            cJSON_AddItemToArray(row, cJSON_CreateString(page));
        }
        free(sorted);
    }
    return shot_verdict(s, sec, counts, rank);
}

/* Returns 0, -1 on an error (said), or a gate's exit status (3, 4). */
static int
collect(const char *dir, int json_stdout, const mcp__gate *gate)
{
    shot s = {.dir = dir, .gate = gate && gate->n ? gate : NULL};
    mcp_report *rep = NULL;
    int rc = -1, counts[4] = {0};
    char *json = NULL;
    if (find_frames(&s)) goto done;
    qsort(s.rows, (size_t)s.n_rows, sizeof *s.rows, by_frame);
    for (int i = 0; i < s.n_rows; i++) {
        read_frame(&s, &s.rows[i]);
        counts[s.rows[i].status]++;
    }
    if (s.gate_failed) goto done; /* a frame that cannot be judged: said, exit 1 */
    char title[600];
    snprintf(title, sizeof title, "%s: %d frames", s.title ? s.title : dir, s.n_rows);
    /* report.html links each frame's page from the table of frames (page column) */
    if (mcp_report_new(title, &rep) || build_report(&s, rep, counts) ||
        mcp_report_write(rep, dir))
        goto done;
    if (json_stdout) {
        if (!(json = cJSON_Print(mcp_report_json(rep)))) {
            mcp_error("out of memory");
            goto done;
        }
        puts(json);
    }
    mcp_note("%d frames: %d complete, %d failed, %d unfinished, %d missing; report in %s "
             "(report.html, report.json)",
             s.n_rows, counts[0], counts[1], counts[2], counts[3], dir);
    rc = 0;
    if (s.gate && counts[FRAME_COMPLETE] == s.n_rows) {
        char line[3000];
        mcp__gate_verdict v = gate_line(&s, line, sizeof line);
        /* idiff's convention: the verdict is the last line */
        if (!json_stdout) printf("%s\n", line);
        rc = mcp__gate_exit_code(v);
    }
    if (counts[FRAME_COMPLETE] < s.n_rows) {
        char list[256] = "";
        size_t len = 0;
        int shown = 0;
        for (int i = 0; i < s.n_rows && len < sizeof list - 32; i++)
            if (s.rows[i].status != FRAME_COMPLETE)
                len += (size_t)snprintf(list + len, sizeof list - len, "%s%d (%s)",
                                        shown++ ? ", " : "", s.rows[i].frame,
                                        status_names[s.rows[i].status]);
        rc = mcp_error("%s: %d of %d frames not complete: %s%s", dir,
                       s.n_rows - counts[FRAME_COMPLETE], s.n_rows, list,
                       shown < s.n_rows - counts[FRAME_COMPLETE] ? ", ..." : "");
    }
done:
    free(json);
    mcp_report_free(rep);
    for (int k = 0; k < s.n_figures; k++)
        free(s.figures[k]);
    free(s.rows);
    free(s.job);
    free(s.title);
    return rc;
}

static int
cmd_collect(int argc, char **argv)
{
    /* the gates through collect's table (ops/op_metrics.c), read as metrics reads them
       (jobs/gate.c) but without a figure check: the frames' sections were computed
       with their job's options, and each is judged by what it holds */
    mcp_metrics_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0;
    int parsed = mcp_cli_parse(&mcp__op_collect, head, examples, argc, argv, &st, &sh,
                               &df, &first);
    if (parsed >= 0) return parsed;
    mcp__gate gate;
    const char *bad_key;
    int bad_index;
    if (mcp__gate_from_settings(&st, NULL, &gate, &bad_key, &bad_index))
        return mcp_cli_usage("collect", "%s", mcp_error_message());
    if (argc - first != 1)
        return mcp_cli_usage("collect", "give one output folder (of a job with frames:)");
    int rc = collect(argv[first], sh.json, &gate);
    return rc < 0 ? mcp_cli_fail() : rc;
}

const mcp_command mcp_command_collect = {
    "collect", "gather a frame job's reports into one", cmd_collect, 1};
