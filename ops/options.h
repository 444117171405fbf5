/* options.h: the operation table -- each operation (estimate, blend, denoise, ...)
 * declares its options once, and the command line, job files, Python and the docs
 * read them from that declaration (docs/library.md, "Adding an option").
 *
 * An option is one row: its name (the job key and the Python keyword; the command
 * line's flag is the name with '-' for '_'), its type, where its value goes in the
 * operation's settings struct (offsetof), the default as text and one line of
 * documentation:
 *
 *   {.name = "tau", .type = MCP_OPT_NUMBER, .offset = offsetof(S, so.est.tau),
 *    .meta = "T", .def = "0.01", .doc = "error threshold", .bounds = MCP_OPT_LO_OPEN}
 *
 * Every front end turns a value into text and hands it to mcp_operation_set, which
 * parses it by type into the settings: `--tau 0.02`, `tau: 0.02` and `tau=0.02` give
 * the same bits, and the same bad values fail with the same message (the front end
 * puts its own label in it: "--tau", "job.yaml:7: tau", "tau"; a value out of range
 * names the operation too, as the library's checks do: "estimate: tau must be > 0"). */
#ifndef MCP_OPTIONS_H
#define MCP_OPTIONS_H

#include <mcpost/wordlist.h>

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* What a value is, and the C type of its field in the settings struct. */
typedef enum {
    MCP_OPT_NUMBER,   /* double; lo/hi per bounds; auto_word may stand for auto_value */
    MCP_OPT_INT,      /* int; lo/hi per bounds; auto_word may stand for auto_value */
    MCP_OPT_SEED,     /* uint64_t, a non-negative integer */
    MCP_OPT_WHOLE,    /* int64_t, a whole number >= 0 (up to 2^52: exact as a double) */
    MCP_OPT_FLAG,     /* int, 0 or 1: true/false, yes/no, on/off; the command line takes
                       * --NAME (1) and --no-NAME (0) */
    MCP_OPT_ENUM,     /* an enum (int-sized): one of words' words */
    MCP_OPT_LIST,     /* double[max_count] at offset, the count (int) at count_offset;
                       * comma-separated on the command line, a YAML list in a job */
    MCP_OPT_TEXT,     /* const char *, borrowed from the front end's text */
    MCP_OPT_INPUT,    /* const char *: a file on the command line, an input's name in a
                       * job, an array or a path in Python (each front end reads it) */
    MCP_OPT_DENOISER, /* the denoiser and its settings: each front end reads it
                       * (--denoiser and --denoiser-opt, a job's denoiser map, a
                       * Python name or dict); declared here for the docs and keys */
    MCP_OPT_TEXTS,    /* const char *[max_count] at offset, the count (int) at
                       * count_offset: each value given adds one (the command line
                       * repeats the flag, a job gives one or a YAML list, Python a str
                       * or a sequence of str); borrowed like MCP_OPT_TEXT */
    MCP_OPT_WORDSET   /* int: a set of words' words, bit i for words[i], given
                       * comma-separated ("ldr,hdr"; a YAML list in a job, a str or a
                       * sequence of str in Python); the word "none" is the empty set */
} mcp_opt_type;

/* Where an option is taken (the `where` bits; 0 means all three). */
enum { MCP_OPT_CLI = 1, MCP_OPT_JOB = 2, MCP_OPT_PY = 4, MCP_OPT_ALL = 7 };

/* Which of lo and hi bound a number (inclusive unless _OPEN). */
enum { MCP_OPT_LO = 1, MCP_OPT_HI = 2, MCP_OPT_LO_OPEN = 4 | 1, MCP_OPT_HI_OPEN = 8 | 2 };

typedef struct mcp_option {
    const char *name; /* job key and Python keyword; the flag is --name with '-' */
    mcp_opt_type type;
    unsigned where;            /* MCP_OPT_CLI | MCP_OPT_JOB | MCP_OPT_PY; 0: all */
    size_t offset;             /* offsetof the field in the operation's settings */
    const char *meta;          /* the value's name in --help: "T", "LIST", "NAME" */
    const char *def;           /* the default as the docs say it (NULL: none) */
    const char *doc;           /* one line */
    const mcp_wordlist *words; /* MCP_OPT_ENUM, MCP_OPT_WORDSET */
    double lo, hi;             /* MCP_OPT_NUMBER, MCP_OPT_INT: the range, per bounds */
    unsigned bounds;
    size_t count_offset; /* MCP_OPT_LIST, MCP_OPT_TEXTS: offsetof the count */
    int max_count;       /* MCP_OPT_LIST, MCP_OPT_TEXTS: at most this many values */
    /* MCP_OPT_INT, MCP_OPT_NUMBER: a word that stands for auto_value ("auto") */
    const char *auto_word;
    double auto_value;
    const char *alias; /* another command-line spelling ("ref" for reference) */
    char letter;       /* a one-letter flag ('o'), or 0 */
    const char *group; /* the --help heading it is listed under (NULL: the first) */
} mcp_option;

/* One operation: its options and its settings struct. */
typedef struct mcp_operation {
    const char *name;          /* "estimate" */
    const char *summary;       /* one line */
    const mcp_option *options; /* ended by a row with name NULL */
    size_t size;               /* sizeof the settings struct */
    void (*defaults)(void *settings);
    /* After every option is read: what follows from several of them (e.g. estimate's
     * taus from a single tau) and the library's own check. NULL: nothing. */
    int (*finish)(void *settings);
    size_t given_offset; /* offsetof a uint64_t: bit i set when options[i] was
                          * given (0: not kept) */
    unsigned shared;     /* the shared flags it takes (MCP_SHARED_*) */
    /* 1: a denoiser's settings (<mcpost/denoiser.h> mcp_denoiser_kind.options), which
     * every front end gives as a map: --denoiser-opt KEY=VALUE, a job's denoiser: map,
     * a Python dict */
    int denoiser;
    const char *output_doc; /* what -o / output is for this operation */
    const char *output_def; /* and its default as the docs say it (NULL: none) */
} mcp_operation;

/* ---- the flags every command shares ---- */

enum {
    MCP_SHARED_QUIET = 1,  /* --quiet: no progress on stderr */
    MCP_SHARED_JSON = 2,   /* --json: the result's JSON on stdout */
    MCP_SHARED_OUTPUT = 4, /* -o, --output (a job's output: key) */
    MCP_SHARED_THREADS = 8 /* --threads N: OpenMP threads */
};

typedef struct mcp_shared_settings {
    int quiet, json;
    const char *output;
    int threads;        /* 0: OpenMP's default */
    int print_settings; /* print the settings as read and stop (every command) */
} mcp_shared_settings;

/* The shared flags' table (settings: mcp_shared_settings). */
MCP_API const mcp_operation *mcp_shared_operation(void);
/* The row of the shared table that shared bit `bit` stands for. */
MCP_API const mcp_option *mcp_shared_option(unsigned bit);

/* ---- the operations ---- */

/* Every operation with a table, NULL-terminated, in `mcpost --help` order. */
MCP_API const mcp_operation *const *mcp_operations(void);
/* By name, or NULL (no error set). */
MCP_API const mcp_operation *mcp_operation_find(const char *name);
/* The option called name ('-' read as '_'), or NULL. */
MCP_API const mcp_option *mcp_operation_option(const mcp_operation *op, const char *name);

/* Fills settings with the operation's defaults (zeroed first). */
MCP_API void mcp_operation_defaults(const mcp_operation *op, void *settings);

/* Parses text by o's type into settings and records o as given. label names the
 * value in messages ("--tau", "tau"): "LABEL must be a number (got 'x')", "LABEL must
 * be in [0, 1] (got 2)", "unknown metric 'x' (known: ...)". MCP_OPT_DENOISER is not
 * read here (an error). */
MCP_API int mcp_operation_set(const mcp_operation *op, const mcp_option *o,
                              const char *label, const char *text, void *settings);

/* Whether o was given (set by mcp_operation_set since the defaults). */
MCP_API int mcp_operation_given(const mcp_operation *op, const mcp_option *o,
                                const void *settings);

/* After the options: op->finish (may fail, e.g. the library's check). */
MCP_API int mcp_operation_finish(const mcp_operation *op, void *settings);

/* The settings as "name: value" lines, one per option that front end `where` takes
 * (MCP_OPT_INPUT and MCP_OPT_DENOISER left out): what `--print-settings` prints and
 * Python's mcpost.settings returns, for comparing front ends. malloc'd. */
MCP_API char *mcp_operation_dump(const mcp_operation *op, const void *settings,
                                 unsigned where);

/* 1 when o is taken by front end `where` (one MCP_OPT_* bit). */
MCP_API int mcp_option_takes(const mcp_option *o, unsigned where);

/* The command-line spelling of a name: "--s2-pool" into buf. */
MCP_API void mcp_option_flag(const char *name, char *buf, size_t cap);

/* The markdown table of an operation's options (`| option | default | meaning |`),
 * as the docs pages hold it between `<!-- options: NAME -->` and `<!-- end -->`
 * (tests/docs/options.sh checks that they are up to date). malloc'd. */
MCP_API char *mcp_operation_markdown(const mcp_operation *op);

#ifdef __cplusplus
}
#endif
#endif
