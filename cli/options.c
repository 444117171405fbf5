/* options.c: a subcommand's flags read through its operation's table (<mcpost/options.h>)
 * -- the getopt_long entries, the --help option list and the parse into the settings
 * struct, so that a command holds no flag of its own (see cli.h). */
#include "cli.h"

#include <mcpost/progress.h>

#include <getopt.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* getopt_long values: option i of the table is OP_BASE + 2i (+1 for --no-NAME), row j
 * of the shared table SHARED_BASE + 2j; the denoiser flags keep their own (cli.h) */
#define OP_BASE 1000
#define SHARED_BASE 3000
#define MAX_LONGS 160
#define HELP_COLUMN 27
#define HELP_WIDTH 88

/* the denoiser shorthands' flags (cli.h): an option of the table spelt the same takes
 * a value of its own type, and the shorthand any other (blend's --weights curves, and
 * --weights PATH for the U-Net) */
static int
shorthand_code(const char *flag)
{
    if (!strcmp(flag, "weights")) return MCP_CLI_OPT_WEIGHTS;
    if (!strcmp(flag, "input-scale")) return MCP_CLI_OPT_INPUT_SCALE;
    if (!strcmp(flag, "denoiser-command")) return MCP_CLI_OPT_DENOISER_COMMAND;
    return 0;
}

static int
has_denoiser(const mcp_operation *op)
{
    for (const mcp_option *o = op->options; o->name; o++)
        if (o->type == MCP_OPT_DENOISER && mcp_option_takes(o, MCP_OPT_CLI)) return 1;
    return 0;
}

static int
shared_takes(const mcp_operation *op, const mcp_option *o)
{
    if (!mcp_option_takes(o, MCP_OPT_CLI)) return 0;
    for (unsigned bit = 1; bit <= MCP_SHARED_THREADS; bit <<= 1)
        if (mcp_shared_option(bit) == o) return (op->shared & bit) != 0;
    return 1; /* --print-settings: every command with a table */
}

/* flag names live as long as the process: getopt_long keeps pointers to them */
typedef struct {
    struct option longs[MAX_LONGS];
    char names[MAX_LONGS][64];
    int n;
} long_table;

static void
add_long(long_table *t, const char *name, int has_arg, int val)
{
    if (t->n >= MAX_LONGS - 1) return;
    snprintf(t->names[t->n], sizeof t->names[t->n], "%s", name);
    for (char *c = t->names[t->n]; *c; c++)
        if (*c == '_') *c = '-';
    t->longs[t->n] = (struct option){t->names[t->n], has_arg, 0, val};
    t->n++;
}

static void
add_rows(long_table *t, const mcp_operation *op, const mcp_operation *table, int base)
{
    int i = 0;
    for (const mcp_option *o = table->options; o->name; o++, i++) {
        if (table == op ? !mcp_option_takes(o, MCP_OPT_CLI) : !shared_takes(op, o))
            continue;
        if (o->type == MCP_OPT_DENOISER) continue;
        if (o->type == MCP_OPT_FLAG) {
            char no[80];
            snprintf(no, sizeof no, "no-%s", o->name);
            add_long(t, o->name, no_argument, base + 2 * i);
            add_long(t, no, no_argument, base + 2 * i + 1);
        } else {
            add_long(t, o->name, required_argument, base + 2 * i);
            if (o->alias) add_long(t, o->alias, required_argument, base + 2 * i);
        }
    }
}

static void
build_longs(const mcp_operation *op, long_table *t, char *shorts, size_t cap)
{
    t->n = 0;
    snprintf(shorts, cap, "h");
    add_rows(t, op, op, OP_BASE);
    add_rows(t, op, mcp_shared_operation(), SHARED_BASE);
    if (has_denoiser(op)) {
        static const struct option den[] = {MCP_CLI_DENOISER_LONGOPTS};
        for (size_t k = 0; k < sizeof den / sizeof *den; k++) {
            int taken = 0; /* an option of the table spelt the same comes first */
            for (int j = 0; j < t->n; j++)
                taken |= !strcmp(t->longs[j].name, den[k].name);
            if (!taken) add_long(t, den[k].name, den[k].has_arg, den[k].val);
        }
    }
    add_long(t, "help", no_argument, 'h');
    const mcp_operation *tables[2] = {op, mcp_shared_operation()};
    for (int k = 0; k < 2; k++)
        for (const mcp_option *o = tables[k]->options; o->name; o++)
            if (o->letter &&
                (k ? shared_takes(op, o) : mcp_option_takes(o, MCP_OPT_CLI))) {
                size_t n = strlen(shorts);
                if (n + 3 < cap)
                    snprintf(shorts + n, cap - n, "%c%s", o->letter,
                             o->type == MCP_OPT_FLAG ? "" : ":");
            }
    t->longs[t->n] = (struct option){0, 0, 0, 0};
}

/* ---- --help ---- */

/* text from column HELP_COLUMN, wrapped at HELP_WIDTH */
static void
print_wrapped(const char *head, const char *text)
{
    int col = printf("%s", head);
    if (col >= HELP_COLUMN) {
        printf("\n");
        col = 0;
    }
    printf("%*s", HELP_COLUMN - col, "");
    col = HELP_COLUMN;
    const char *p = text;
    while (*p) {
        const char *sp = strchr(p, ' ');
        int len = sp ? (int)(sp - p) : (int)strlen(p);
        if (col > HELP_COLUMN && col + 1 + len > HELP_WIDTH) {
            printf("\n%*s", HELP_COLUMN, "");
            col = HELP_COLUMN;
        } else if (col > HELP_COLUMN) {
            printf(" ");
            col++;
        }
        printf("%.*s", len, p);
        col += len;
        p += len;
        while (*p == ' ')
            p++;
    }
    printf("\n");
}

static void
print_option(const mcp_option *o, const char *doc, const char *def)
{
    char flag[80], head[160], text[1024];
    mcp_option_flag(o->name, flag, sizeof flag);
    int on = o->type == MCP_OPT_FLAG && def && !strcmp(def, "true");
    const char *letter = o->letter ? (char[]){'-', o->letter, ',', ' ', '\0'} : "";
    if (o->type == MCP_OPT_FLAG)
        snprintf(head, sizeof head, "  %s%s%s", letter, on ? "--no-" : flag,
                 on ? flag + 2 : "");
    else
        snprintf(head, sizeof head, "  %s%s%s%s %s", letter, flag, o->alias ? ", --" : "",
                 o->alias ? o->alias : "", o->meta ? o->meta : "X");
    if (o->type == MCP_OPT_FLAG)
        snprintf(text, sizeof text, on ? "turns off: %s" : "%s", doc);
    else
        snprintf(text, sizeof text, "%s", doc);
    size_t n = strlen(text);
    /* an enum's words, unless the line names them already */
    if (o->type == MCP_OPT_ENUM && !strstr(doc, o->words->words[0])) {
        char words[256];
        mcp_wordlist_join(o->words, ", ", words, sizeof words);
        n += (size_t)snprintf(text + n, sizeof text - n, " (%s)", words);
    }
    if (def && o->type != MCP_OPT_FLAG && n < sizeof text)
        snprintf(text + n, sizeof text - n, " [%s]", def);
    print_wrapped(head, text);
}

void
mcp_cli_print_help(const mcp_operation *op, const char *head, const char *examples)
{
    fputs(head, stdout);
    printf("\n");
    const char *group = NULL;
    for (const mcp_option *o = op->options; o->name; o++) {
        if (!mcp_option_takes(o, MCP_OPT_CLI)) continue;
        if (o->group && (!group || strcmp(group, o->group))) printf("  %s:\n", o->group);
        group = o->group;
        if (o->type == MCP_OPT_DENOISER) {
            print_wrapped("  --denoiser NAME",
                          "the denoiser (see 'mcpost denoise --list')");
            printf("%*s%s\n", HELP_COLUMN, "", MCP_CLI_DEFAULT_DENOISER);
            fputs(MCP_CLI_DENOISER_USAGE(" "), stdout);
            continue;
        }
        print_option(o, o->doc, o->def);
    }
    printf("  Every command:\n");
    const mcp_operation *sh = mcp_shared_operation();
    for (const mcp_option *o = sh->options; o->name; o++) {
        if (!shared_takes(op, o)) continue;
        int is_output = o == mcp_shared_option(MCP_SHARED_OUTPUT);
        print_option(o, is_output && op->output_doc ? op->output_doc : o->doc,
                     is_output ? op->output_def : o->def);
    }
    printf("\n");
    fputs(examples, stdout);
}

/* ---- the parse ---- */

static int
set_row(const mcp_operation *table, const mcp_option *o, int negated, const char *arg,
        void *dst)
{
    char label[96];
    mcp_option_flag(o->name, label, sizeof label);
    if (o->type == MCP_OPT_FLAG)
        return mcp_operation_set(table, o, label, negated ? "false" : "true", dst);
    return mcp_operation_set(table, o, label, arg, dst);
}

int
mcp_cli_parse(const mcp_operation *op, const char *head, const char *examples, int argc,
              char **argv, void *settings, mcp_shared_settings *sh,
              mcp_cli_denoiser_flags *df, int *first)
{
    static long_table t; /* one command runs per process */
    char shorts[32];
    build_longs(op, &t, shorts, sizeof shorts);
    mcp_operation_defaults(op, settings);
    mcp_operation_defaults(mcp_shared_operation(), sh);
    const mcp_operation *shared = mcp_shared_operation();
    int opt;
    optind = 1;
    while ((opt = getopt_long(argc, argv, shorts, t.longs, NULL)) != -1) {
        int rc = 0;
        if (opt == 'h') {
            mcp_cli_print_help(op, head, examples);
            return 0;
        }
        if (opt >= OP_BASE && opt < SHARED_BASE) {
            const mcp_option *o = &op->options[(opt - OP_BASE) / 2];
            char flag[80];
            mcp_option_flag(o->name, flag, sizeof flag);
            int code = o->type == MCP_OPT_ENUM ? shorthand_code(flag + 2) : 0, v;
            if (code && has_denoiser(op) && mcp_wordlist_find(o->words, optarg, &v)) {
                mcp_error_clear(); /* not one of its words: the denoiser's setting */
                rc = mcp_cli_denoiser_flag(df, code, optarg) < 0;
            } else {
                rc = set_row(op, o, (opt - OP_BASE) % 2, optarg, settings);
            }
        } else if (opt >= SHARED_BASE && opt < MCP_CLI_OPT_DENOISER) {
            rc = set_row(shared, &shared->options[(opt - SHARED_BASE) / 2],
                         (opt - SHARED_BASE) % 2, optarg, sh);
        } else if (opt < 256 && opt != '?') {
            for (const mcp_option *o = op->options; o->name; o++)
                if (o->letter == opt) rc = set_row(op, o, 0, optarg, settings);
            for (const mcp_option *o = shared->options; o->name; o++)
                if (o->letter == opt) rc = set_row(shared, o, 0, optarg, sh);
        } else {
            int taken = mcp_cli_denoiser_flag(df, opt, optarg);
            if (taken == 0) return mcp_cli_usage(op->name, "bad option");
            rc = taken < 0;
        }
        if (rc) return mcp_cli_fail();
    }
    if (mcp_operation_finish(op, settings)) return mcp_cli_fail();
    if (sh->quiet) mcp_progress_set_quiet(1);
    if (sh->threads > 0) omp_set_num_threads(sh->threads);
    if (sh->print_settings) {
        char *text = mcp_operation_dump(op, settings, MCP_OPT_CLI);
        if (!text) return mcp_cli_fail();
        fputs(text, stdout);
        free(text);
        return 0;
    }
    *first = optind;
    return -1;
}
