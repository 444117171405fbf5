/* test_options.c: every operation's table (ops/, <mcpost/options.h>) through the
 * command line's and the job file's readers. For every option both take, a set of
 * values -- good ones (each bound, a value inside, every enum word in other case and
 * with '-' for '_', the default) and bad ones (outside the bounds, not a number, too
 * many list values, an unknown word) -- goes through mcp_cli_parse as argv and through
 * mcp__job_settings as a YAML map: both must accept it or both refuse it, refusing
 * with the same message (the label aside: "--tau" against "job.yaml:1: tau"), and when
 * they accept, give settings equal field by field for every option of the table.
 * Python's reader is held to the same in python/tests/test_options.py. Also: each
 * default as the docs say it reads back as the library's default; the job stages'
 * keys are the table's; no two flags of one command are spelt alike. */
#include "testing.h"

#include "../../cli/cli.h"

#include <mcpost/denoiser.h>
#include <mcpost/job.h>
#include <mcpost/options.h>
#include <mcpost/stages.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_VALUES 48

typedef struct {
    char v[MAX_VALUES][160];
    int n;
} values;

static void
add_value(values *vs, const char *fmt, double x)
{
    if (vs->n < MAX_VALUES) snprintf(vs->v[vs->n++], sizeof vs->v[0], fmt, x);
}

static void
add_text(values *vs, const char *t)
{
    if (vs->n < MAX_VALUES) snprintf(vs->v[vs->n++], sizeof vs->v[0], "%s", t);
}

/* Good and bad texts for o. */
static void
values_for(const mcp_option *o, values *vs)
{
    vs->n = 0;
    if (o->def) add_text(vs, o->def);
    int lo = (o->bounds & MCP_OPT_LO) != 0, hi = (o->bounds & MCP_OPT_HI) != 0;
    switch (o->type) {
    case MCP_OPT_NUMBER:
    case MCP_OPT_INT: {
        const char *f = o->type == MCP_OPT_INT ? "%.0f" : "%.17g";
        if (lo)
            add_value(vs, f, o->lo), add_value(vs, f, o->lo - 1),
                add_value(vs, f, o->lo + 3);
        if (hi)
            add_value(vs, f, o->hi), add_value(vs, f, o->hi + 1),
                add_value(vs, f, o->hi - 3);
        if (lo && hi) add_value(vs, f, floor((o->lo + o->hi) / 2) + 1);
        if (lo && hi && o->type == MCP_OPT_NUMBER)
            add_value(vs, "%.17g", (o->lo + o->hi) / 3);
        if (!lo && !hi) add_value(vs, f, 37), add_value(vs, f, -2);
        add_value(vs, "%g", o->type == MCP_OPT_INT ? 2.5 : 0.375);
        add_text(vs, "x");
        add_text(vs, "1e999");
        add_text(vs, "");
        if (o->auto_word) add_text(vs, o->auto_word);
        break;
    }
    case MCP_OPT_SEED:
        add_text(vs, "12345678901234567");
        add_text(vs, "-1");
        add_text(vs, "1.5");
        add_text(vs, "seed");
        break;
    case MCP_OPT_WHOLE:
        add_text(vs, "1048576");
        add_text(vs, "4503599627370497");
        add_text(vs, "1.5");
        add_text(vs, "-2");
        add_text(vs, "x");
        break;
    case MCP_OPT_FLAG:
        add_text(vs, "true");
        add_text(vs, "false");
        break;
    case MCP_OPT_ENUM:
        for (int i = 0; i < o->words->count; i++) {
            char w[64];
            snprintf(w, sizeof w, "%s", o->words->words[i]);
            add_text(vs, w);
            for (char *c = w; *c; c++)
                *c = *c == '_'                ? '-'
                     : *c == '-'              ? '_'
                     : *c >= 'a' && *c <= 'z' ? (char)(*c & ~0x20)
                                              : *c;
            add_text(vs, w);
        }
        add_text(vs, "nope");
        break;
    case MCP_OPT_WORDSET:
        for (int i = 0; i < o->words->count; i++) {
            char w[64];
            add_text(vs, o->words->words[i]);
            snprintf(w, sizeof w, "%s", o->words->words[i]);
            for (char *c = w; *c; c++)
                *c = (char)(*c & ~0x20);
            add_text(vs, w);
        }
        if (o->words->count > 1) {
            char w[160];
            snprintf(w, sizeof w, "%s,%s", o->words->words[1], o->words->words[0]);
            add_text(vs, w);
            snprintf(w, sizeof w, "none,%s", o->words->words[0]);
            add_text(vs, w);
        }
        add_text(vs, "none");
        add_text(vs, "nope");
        break;
    case MCP_OPT_TEXTS:
        add_text(vs, "flip_ldr.mean > 0.5");
        add_text(vs, "R");
        break;
    case MCP_OPT_LIST: {
        char many[160] = "";
        for (int i = 0; i <= o->max_count && strlen(many) + 6 < sizeof many; i++)
            strcat(many, i ? ",0.25" : "0.25");
        add_text(vs, many);
        add_text(vs, "0.25");
        add_text(vs, "0.75,0.25");
        add_text(vs, "0.25,x");
        if (hi) add_value(vs, "0.25,%.17g", o->hi + 1);
        if (lo) add_value(vs, "%.17g,0.25", o->lo - 1);
        break;
    }
    default:
        break;
    }
}

/* The settings' field of o in a and b are equal. */
static void
assert_field_equal(const mcp_option *o, const void *a, const void *b)
{
    const char *pa = (const char *)a + o->offset, *pb = (const char *)b + o->offset;
    switch (o->type) {
    case MCP_OPT_NUMBER:
        if (*(const double *)pa != *(const double *)pb &&
            !(isnan(*(const double *)pa) && isnan(*(const double *)pb)))
            fail_msg("%s: %.17g against %.17g", o->name, *(const double *)pa,
                     *(const double *)pb);
        break;
    case MCP_OPT_INT:
    case MCP_OPT_FLAG:
    case MCP_OPT_ENUM:
    case MCP_OPT_WORDSET:
        if (*(const int *)pa != *(const int *)pb)
            fail_msg("%s: %d against %d", o->name, *(const int *)pa, *(const int *)pb);
        break;
    case MCP_OPT_SEED:
    case MCP_OPT_WHOLE:
        if (memcmp(pa, pb, 8)) fail_msg("%s differs", o->name);
        break;
    case MCP_OPT_LIST: {
        int na = *(const int *)((const char *)a + o->count_offset);
        int nb = *(const int *)((const char *)b + o->count_offset);
        assert_int_equal(na, nb);
        if (memcmp(pa, pb, (size_t)na * sizeof(double))) fail_msg("%s differs", o->name);
        break;
    }
    case MCP_OPT_TEXTS: {
        int na = *(const int *)((const char *)a + o->count_offset);
        int nb = *(const int *)((const char *)b + o->count_offset);
        assert_int_equal(na, nb);
        for (int i = 0; i < na; i++)
            assert_string_equal(((const char *const *)pa)[i],
                                ((const char *const *)pb)[i]);
        break;
    }
    default:
        break; /* texts are the front ends' own strings; inputs and the denoiser */
    }
}

static void
assert_settings_equal(const mcp_operation *op, const void *a, const void *b)
{
    for (const mcp_option *o = op->options; o->name; o++)
        assert_field_equal(o, a, b);
}

/* What an operation needs besides the option under test for its finish (the library's
 * check) to pass: adaptive needs a stop rule, a budget or stop (a flag). */
static const char *
base_option(const mcp_operation *op, const mcp_option *o)
{
    if (strcmp(op->name, "adaptive")) return NULL;
    return strcmp(o->name, "budget") ? "budget" : "stop";
}

/* The CLI's reader on one option: -1 accepted, else the status. */
static int
cli_read(const mcp_operation *op, const mcp_option *o, const char *value, void *settings,
         char *msg, size_t cap)
{
    char flag[96], no[96];
    mcp_option_flag(o->name, flag, sizeof flag);
    snprintf(no, sizeof no, "--no-%s", flag + 2);
    char *argv[6] = {(char *)op->name, flag, (char *)value, NULL, NULL, NULL};
    int argc = 3;
    if (o->type == MCP_OPT_FLAG) {
        argv[1] = strcmp(value, "false") ? flag : no;
        argv[2] = NULL;
        argc = 2;
    }
    const char *base = base_option(op, o);
    if (base && !strcmp(base, "budget"))
        argv[argc++] = "--budget", argv[argc++] = "8";
    else if (base)
        argv[argc++] = "--stop";
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0;
    mcp_error_clear();
    int rc = mcp_cli_parse(op, "", "", argc, argv, settings, &sh, &df, &first);
    mcp_cli_denoiser_flags_free(&df);
    snprintf(msg, cap, "%s", mcp_error_message());
    return rc;
}

/* The job's reader on one option: 0 accepted, -1 refused (msg). */
static int
job_read(const mcp_operation *op, const mcp_option *o, const char *value, void *settings,
         char *msg, size_t cap)
{
    char yaml[512];
    if ((o->type == MCP_OPT_LIST || o->type == MCP_OPT_WORDSET) && strchr(value, ',')) {
        char items[400] = "";
        for (const char *p = value; *p; p++) {
            size_t n = strlen(items);
            if (n + 3 >= sizeof items) break;
            if (*p == ',')
                strcat(items, ", ");
            else
                items[n] = *p, items[n + 1] = '\0';
        }
        snprintf(yaml, sizeof yaml, "{%s: [%s]}", o->name, items);
    } else {
        snprintf(yaml, sizeof yaml, "{%s: %s}", o->name, *value ? value : "''");
    }
    const char *base = base_option(op, o);
    if (base) { /* ", budget: 8}" or ", stop: true}" */
        size_t n = strlen(yaml) - 1;
        snprintf(yaml + n, sizeof yaml - n, ", %s}",
                 strcmp(base, "budget") ? "stop: true" : "budget: 8");
    }
    /* the settings borrow the texts of the file: kept until the next read */
    static mcp_node *root = NULL;
    mcp_node_free(root);
    root = NULL;
    assert_int_equal(mcp_yaml_parse_string(yaml, "job.yaml", &root), 0);
    mcp_shared_settings sh;
    int rc = mcp__job_settings(op, root, &sh, settings);
    snprintf(msg, cap, "%s", mcp_error_message());
    return rc;
}

static void
test_cli_and_job_read_alike(void **state)
{
    (void)state;
    int compared = 0;
    for (const mcp_operation *const *op = mcp_operations(); *op; op++) {
        void *a = calloc(1, (*op)->size), *b = calloc(1, (*op)->size);
        assert_non_null(a);
        assert_non_null(b);
        for (const mcp_option *o = (*op)->options; o->name; o++) {
            if (!mcp_option_takes(o, MCP_OPT_CLI) || !mcp_option_takes(o, MCP_OPT_JOB) ||
                o->type == MCP_OPT_TEXT || o->type == MCP_OPT_INPUT ||
                o->type == MCP_OPT_DENOISER)
                continue;
            values vs;
            values_for(o, &vs);
            int accepted = 0, refused = 0;
            for (int i = 0; i < vs.n; i++) {
                char cli_msg[512], job_msg[512];
                int word = 0;
                /* blend's --weights is also the U-Net's weights shorthand: a value that
                   is none of its words is the denoiser's (test_blend_weights_and_the_
                   shorthand), not refused */
                if (o->type == MCP_OPT_ENUM && !strcmp(o->name, "weights") &&
                    mcp_wordlist_find(o->words, vs.v[i], &word))
                    continue;
                int cli = cli_read(*op, o, vs.v[i], a, cli_msg, sizeof cli_msg);
                int job = job_read(*op, o, vs.v[i], b, job_msg, sizeof job_msg);
                if ((cli == -1) != (job == 0))
                    fail_msg("%s %s '%s': the command line %s (%s), the job %s (%s)",
                             (*op)->name, o->name, vs.v[i],
                             cli == -1 ? "takes it" : "refuses it", cli_msg,
                             job ? "refuses it" : "takes it", job_msg);
                if (cli == -1) {
                    assert_settings_equal(*op, a, b);
                    accepted++;
                } else {
                    /* "--flag-name" in the CLI's message is "name" in the job's, after
                       "job.yaml:1: " */
                    char flag[96], want[600];
                    mcp_option_flag(o->name, flag, sizeof flag);
                    const char *at = strstr(cli_msg, flag);
                    if (at)
                        snprintf(want, sizeof want, "job.yaml:1: %.*s%s%s",
                                 (int)(at - cli_msg), cli_msg, o->name,
                                 at + strlen(flag));
                    else
                        snprintf(want, sizeof want, "job.yaml:1: %s", cli_msg);
                    if (strcmp(want, job_msg))
                        fail_msg("%s %s '%s': the messages differ:\n  %s\n  %s",
                                 (*op)->name, o->name, vs.v[i], want, job_msg);
                    refused++;
                }
                compared++;
            }
            if (!accepted) fail_msg("%s %s: no value was taken", (*op)->name, o->name);
            /* a repeatable text takes any text here (the gates' conditions are read by
               the front ends: test_gates_read_alike) */
            if (!refused && o->type != MCP_OPT_FLAG && o->type != MCP_OPT_TEXTS &&
                strcmp(o->name, "weights"))
                fail_msg("%s %s: no value was refused", (*op)->name, o->name);
        }
        free(a);
        free(b);
    }
    assert_true(compared > 100);
    printf("compared %d values\n", compared);
}

/* Each default, as the docs and --help say it, reads back as the library's default:
 * the operations' and the denoisers' settings. */
static void
defaults_read_back(const mcp_operation *const *op)
{
    {
        void *d = calloc(1, (*op)->size), *s = calloc(1, (*op)->size);
        mcp_operation_defaults(*op, d);
        for (const mcp_option *o = (*op)->options; o->name; o++) {
            if (!o->def || o->type == MCP_OPT_TEXT || o->type == MCP_OPT_INPUT ||
                o->type == MCP_OPT_DENOISER || o->type == MCP_OPT_TEXTS)
                continue;
            mcp_operation_defaults(*op, s);
            if (mcp_operation_set(*op, o, o->name, o->def, s))
                fail_msg("%s %s: the default '%s' does not read: %s", (*op)->name,
                         o->name, o->def, mcp_error_message());
            assert_field_equal(o, d, s);
            /* and the text written back is the text declared */
            char text[256];
            mcp_option_format(o, d, text, sizeof text);
            double x = 0, y = 0;
            if (o->type == MCP_OPT_NUMBER && !o->auto_word &&
                sscanf(text, "%lf", &x) == 1 && sscanf(o->def, "%lf", &y) == 1)
                assert_true(x == y);
            else
                assert_string_equal(text, o->def);
        }
        free(d);
        free(s);
    }
}

static void
test_defaults_read_back(void **state)
{
    (void)state;
    int n = 0;
    for (const mcp_operation *const *op = mcp_operations(); *op; op++, n++)
        defaults_read_back(op);
    for (const mcp_denoiser_kind *const *k = mcp_denoiser_kinds(); *k; k++)
        if ((*k)->options) {
            assert_string_equal((*k)->options->name, (*k)->name);
            assert_true((*k)->options->denoiser);
            defaults_read_back(&(*k)->options);
            /* the kind's keys are its table's */
            int i = 0;
            for (const mcp_option *o = (*k)->options->options; o->name; o++, i++)
                assert_string_equal((*k)->keys[i], o->name);
            assert_null((*k)->keys[i]);
            n++;
        }
    assert_int_equal(n, 15); /* estimate, blend, adaptive, info, merge, denoise, convert,
                                metrics, compare, perceptual; gauss, nlm, bilateral,
                                external, unet */
}

/* Every operation's stage takes exactly its table's job options, the shared output
 * when the operation has one, and title. */
static void
test_stage_keys_are_the_tables(void **state)
{
    (void)state;
    int stages = 0;
    for (const mcp_operation *const *op = mcp_operations(); *op; op++) {
        const mcp_stage *st = mcp_job_stage_find((*op)->name);
        if (!st) { /* merge, denoise, compare: the command line's alone */
            for (const mcp_option *o = (*op)->options; o->name; o++)
                assert_false(mcp_option_takes(o, MCP_OPT_JOB));
            continue;
        }
        stages++;
        int n = 0;
        for (const mcp_option *o = (*op)->options; o->name; o++) {
            if (!mcp_option_takes(o, MCP_OPT_JOB)) continue;
            assert_non_null(st->keys[n]);
            assert_string_equal(st->keys[n], o->name);
            n++;
        }
        if ((*op)->shared & MCP_SHARED_OUTPUT)
            assert_string_equal(st->keys[n++], "output");
        assert_string_equal(st->keys[n], "title");
        assert_null(st->keys[n + 1]);
    }
    assert_int_equal(stages, 7); /* estimate, blend, adaptive, info, convert, metrics,
                                    perceptual */
}

/* No two flags of one command are spelt alike (the table's, their --no- forms and
 * aliases, and the shared ones); the denoiser's shorthands may be, by design
 * (cli.h). */
static void
test_flags_are_spelt_once(void **state)
{
    (void)state;
    for (const mcp_operation *const *op = mcp_operations(); *op; op++) {
        const char *names[256];
        char store[256][80];
        int n = 0;
        const mcp_operation *tables[] = {*op, mcp_shared_operation()};
        for (int t = 0; t < 2; t++)
            for (const mcp_option *o = tables[t]->options; o->name; o++) {
                if (!mcp_option_takes(o, MCP_OPT_CLI) || o->type == MCP_OPT_DENOISER)
                    continue;
                const char *spell[3] = {o->name, o->alias, NULL};
                char no[80];
                if (o->type == MCP_OPT_FLAG)
                    snprintf(no, sizeof no, "no_%s", o->name), spell[1] = no;
                for (int k = 0; k < 2 && spell[k]; k++) {
                    mcp_option_flag(spell[k], store[n], sizeof store[n]);
                    for (int j = 0; j < n; j++)
                        if (!strcmp(store[j], store[n]))
                            fail_msg("%s: %s is spelt twice", (*op)->name, store[n]);
                    names[n] = store[n];
                    n++;
                }
            }
        assert_true(n > 5);
        (void)names;
    }
}

/* The drift that had crept in: blend's --weights takes the blend's words, and any other
 * value is still the U-Net's weights (the shorthand). */
static void
test_blend_weights_and_the_shorthand(void **state)
{
    (void)state;
    const mcp_operation *op = mcp_operation_blend();
    mcp_blend_settings s;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0;
    char *argv[] = {"blend", "--weights", "curves", "--weights", "w.tza", "x.exr", NULL};
    assert_int_equal(mcp_cli_parse(op, "", "", 6, argv, &s, &sh, &df, &first), -1);
    assert_int_equal(s.o.blend.weights, MCP_BLEND_WEIGHTS_CURVES);
    assert_int_equal(df.n_opts, 1);
    assert_string_equal(df.opts[0], "weights=w.tza");
    assert_int_equal(first, 5);
    mcp_cli_denoiser_flags_free(&df);
}

/* The reader of one front end on argv or a YAML map: 0 or -1 (msg). */
static int
cli_settings(const mcp_operation *op, int argc, char **argv, void *settings, char *msg,
             size_t cap)
{
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0;
    mcp_error_clear();
    int rc = mcp_cli_parse(op, "", "", argc, argv, settings, &sh, &df, &first);
    mcp_cli_denoiser_flags_free(&df);
    snprintf(msg, cap, "%s", mcp_error_message());
    return rc == -1 ? 0 : -1;
}

static mcp_node *
yaml(const char *text)
{
    mcp_node *root = NULL;
    assert_int_equal(mcp_yaml_parse_string(text, "job.yaml", &root), 0);
    return root;
}

/* The gates' conditions (repeatable texts the table takes as they are) read by the
 * command line and by a job alike: the same conditions taken, in the same order, asking
 * the metrics for the same shares of pixels; the same ones refused with the same
 * message ("--fail 'x': ..." against "fail: 'x': ..."). */
static void
test_gates_read_alike(void **state)
{
    (void)state;
    static const struct {
        const char *key, *text;
        int good;
    } cases[] = {{"fail", "flip_ldr.mean > 0.2", 1},
                 {"warn", "relmse >= 0.5", 1},
                 {"fail", "psnr<10", 1},
                 {"warn", "relse_percentiles.value.0 > 0.001", 1},
                 {"fail_percent", "flip_ldr 0.1 1%", 1},
                 {"warn_percent", "relse 0.3 5", 1},
                 {"fail", "flip.mean > 0.1", 0},
                 {"warn", "relmse = 0.1", 0},
                 {"fail", "psnr > lots", 0},
                 {"fail_percent", "flip 0.1 1%", 0},
                 {"warn_percent", "flip_ldr 0.1", 0},
                 {"fail_percent", "relse 0.1 120", 0}};
    const mcp_operation *op = mcp_operation_metrics();
    int n = (int)(sizeof cases / sizeof *cases);
    for (int i = 0; i < n; i++) {
        mcp_metrics_settings a, b;
        mcp_metrics_options oa, ob;
        mcp__gate ga, gb;
        const char *bad_key = NULL;
        int bad_index = -1;
        char flag[64], cli_msg[512] = "", job_msg[512] = "", text[512];
        mcp_option_flag(cases[i].key, flag, sizeof flag);
        /* fail: a good condition first, so that the one under test is the second */
        int two = !strcmp(cases[i].key, "fail");
        char *argv[] = {"metrics", flag, "mse > 1", flag, (char *)cases[i].text, NULL};
        char *one[] = {"metrics", flag, (char *)cases[i].text, NULL};
        int cli =
            cli_settings(op, two ? 5 : 3, two ? argv : one, &a, cli_msg, sizeof cli_msg);
        assert_int_equal(cli, 0);
        oa = a.o;
        cli = mcp__gate_from_settings(&a, &oa, &ga, &bad_key, &bad_index);
        if (cli) snprintf(cli_msg, sizeof cli_msg, "%s", mcp_error_message());
        /* the job: a list, the condition at its own line */
        if (two)
            snprintf(text, sizeof text, "%s:\n  - mse > 1\n  - '%s'\n", cases[i].key,
                     cases[i].text);
        else
            snprintf(text, sizeof text, "%s:\n  - '%s'\n", cases[i].key, cases[i].text);
        mcp_node *root = yaml(text);
        mcp_shared_settings sh;
        assert_int_equal(mcp__job_settings(op, root, &sh, &b), 0);
        ob = b.o;
        int job = mcp__gate_from_settings(&b, &ob, &gb, &bad_key, &bad_index);
        if (job) {
            /* as the stage puts it: at the condition's line, the key for the flag */
            const mcp_node *list = mcp_node_get(root, bad_key);
            const char *m = mcp_error_message();
            snprintf(job_msg, sizeof job_msg, "job.yaml:%d: %s: %s",
                     list->items[bad_index]->line, bad_key, strchr(m, ' ') + 1);
        }
        if (cases[i].good != !cli || cases[i].good != !job)
            fail_msg("%s '%s': the command line %s (%s), the job %s (%s)", cases[i].key,
                     cases[i].text, cli ? "refuses it" : "takes it", cli_msg,
                     job ? "refuses it" : "takes it", job_msg);
        if (cli) {
            char want[600];
            snprintf(want, sizeof want, "job.yaml:%d: %s: %s",
                     mcp_node_get(root, bad_key)->items[bad_index]->line, cases[i].key,
                     strchr(cli_msg, ' ') + 1);
            assert_string_equal(job_msg, want);
            assert_non_null(strstr(cli_msg, flag));
        } else {
            assert_int_equal(ga.n, gb.n);
            for (int k = 0; k < ga.n; k++)
                assert_string_equal(ga.c[k].text, gb.c[k].text);
            assert_int_equal(oa.n_above, ob.n_above);
            assert_memory_equal(oa.above, ob.above, sizeof oa.above);
        }
        mcp_node_free(root);
    }
}

/* A convert's channels and a perceptual kernel's taps: "A,B,C" on the command line is a
 * job's list [A, B, C]. */
static void
test_lists_as_texts_read_alike(void **state)
{
    (void)state;
    mcp_convert_settings ca, cb;
    char msg[512];
    char **na = NULL, **nb = NULL;
    int ka = 0, kb = 0;
    assert_int_equal(cli_settings(mcp_operation_convert(), 3,
                                  (char *[]){"convert", "--channels", "B,G,R", NULL}, &ca,
                                  msg, sizeof msg),
                     0);
    mcp_node *root = yaml("channels: [B, G, R]\n");
    assert_int_equal(mcp__job_settings(mcp_operation_convert(), root, NULL, &cb), 0);
    assert_int_equal(mcp__convert_channel_names(&ca, &na, &ka), 0);
    assert_int_equal(mcp__convert_channel_names(&cb, &nb, &kb), 0);
    assert_int_equal(ka, 3);
    assert_int_equal(kb, 3);
    for (int i = 0; i < 3; i++)
        assert_string_equal(na[i], nb[i]);
    assert_string_equal(na[0], "B");
    mcp__free_words(na, ka);
    mcp__free_words(nb, kb);
    mcp_node_free(root);

    mcp_perceptual_settings pa, pb;
    mcp__perc_args aa, ab;
    assert_int_equal(
        cli_settings(mcp_operation_perceptual(), 3,
                     (char *[]){"perceptual", "--kernel", "0.25,0.5,0.25", NULL}, &pa,
                     msg, sizeof msg),
        0);
    root = yaml("kernel: [0.25, 0.5, 0.25]\n");
    assert_int_equal(mcp__job_settings(mcp_operation_perceptual(), root, NULL, &pb), 0);
    assert_int_equal(mcp__perc_args_from_settings(&pa, &aa), 0);
    assert_int_equal(mcp__perc_args_from_settings(&pb, &ab), 0);
    assert_int_equal(aa.opt.model.user_kernel_width, 3);
    assert_int_equal(ab.opt.model.user_kernel_width, 3);
    /* the outer product of the taps: the centre 0.25, a corner 1/16 */
    assert_true(aa.kernel[4] == 0.25 && aa.kernel[0] == 0.0625);
    assert_memory_equal(aa.kernel, ab.kernel, 9 * sizeof(double));
    mcp__perc_args_free(&aa);
    mcp__perc_args_free(&ab);
    mcp_node_free(root);
    /* an even count fails alike */
    root = yaml("kernel: [0.5, 0.5]\n");
    assert_int_equal(mcp__job_settings(mcp_operation_perceptual(), root, NULL, &pb), 0);
    assert_int_equal(mcp__perc_args_from_settings(&pb, &ab), -1);
    snprintf(msg, sizeof msg, "%s", mcp_error_message());
    mcp__perc_args_free(&ab);
    mcp_node_free(root);
    assert_int_equal(cli_settings(mcp_operation_perceptual(), 3,
                                  (char *[]){"perceptual", "--kernel", "0.5,0.5", NULL},
                                  &pa, msg + 256, 256),
                     0);
    assert_int_equal(mcp__perc_args_from_settings(&pa, &aa), -1);
    assert_string_equal(msg, mcp_error_message());
    assert_string_equal(msg, "kernel: give an odd number of taps (got 2)");
    mcp__perc_args_free(&aa);
}

int
main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cli_and_job_read_alike),
        cmocka_unit_test(test_defaults_read_back),
        cmocka_unit_test(test_stage_keys_are_the_tables),
        cmocka_unit_test(test_flags_are_spelt_once),
        cmocka_unit_test(test_blend_weights_and_the_shorthand),
        cmocka_unit_test(test_gates_read_alike),
        cmocka_unit_test(test_lists_as_texts_read_alike),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
