/* cmd_help.c: `mcpost help [TOPIC]` -- prints a docs page (docs/TOPIC.md, built into
 * the tool: help_pages.h) in the terminal, or lists the topics. */
#include "cli.h"
#include "help_pages.h"

#include <stdio.h>
#include <string.h>

static const char usage[] =
    "usage: mcpost help [TOPIC]\n"
    "  Prints the docs page on TOPIC (the Markdown of docs/TOPIC.md, built into the\n"
    "  tool); without TOPIC lists the topics. `mcpost SUBCOMMAND --help` gives a\n"
    "  subcommand's options and examples; `mcpost help SUBCOMMAND` does the same.\n"
    "\n"
    "examples:\n"
    "  mcpost help\n"
    "  mcpost help jobs\n"
    "  mcpost help conventions\n";

/* A page's title: its first line without the leading "# ". */
static void
print_title(const char *text)
{
    const char *end = strchr(text, '\n');
    int n = end ? (int)(end - text) : (int)strlen(text);
    if (n >= 2 && text[0] == '#' && text[1] == ' ') text += 2, n -= 2;
    printf("%.*s", n, text);
}

static void
list_topics(void)
{
    printf("mcpost help TOPIC prints a docs page in the terminal; the topics:\n\n");
    for (const mcp_help_page *p = mcp_help_pages; p->topic; p++) {
        printf("  %-12s ", p->topic);
        print_title(p->text);
        putchar('\n');
    }
    printf("\nEvery subcommand's options and examples: mcpost SUBCOMMAND --help.\n"
           "The other pages are in the docs/ folder of the source.\n");
}

static int
cmd_help(int argc, char **argv)
{
    if (argc == 1) {
        list_topics();
        return 0;
    }
    if (argc > 2) return mcp_cli_usage("help", "give one topic");
    const char *topic = argv[1];
    if (!strcmp(topic, "--help") || !strcmp(topic, "-h")) {
        fputs(usage, stdout);
        return 0;
    }
    for (const mcp_help_page *p = mcp_help_pages; p->topic; p++)
        if (!strcmp(p->topic, topic)) {
            fputs(p->text, stdout);
            return 0;
        }
    /* a subcommand's own help, for `mcpost help estimate` */
    for (const mcp_command *const *c = mcp_commands; *c; c++)
        if (!strcmp((*c)->name, topic) && strcmp(topic, "help")) {
            static char help_flag[] = "--help";
            char *args[] = {argv[1], help_flag, NULL};
            return (*c)->run(2, args);
        }
    char known[256] = "";
    size_t n = 0;
    for (const mcp_help_page *p = mcp_help_pages; p->topic && n < sizeof known; p++)
        n += (size_t)snprintf(known + n, sizeof known - n, "%s%s",
                              p == mcp_help_pages ? "" : ", ", p->topic);
    fprintf(stderr, "mcpost help: unknown topic '%s' (topics: %s; or a subcommand)\n",
            topic, known);
    return 2;
}

const mcp_command mcp_command_help = {"help",
                                      "print a docs page: render dumps, job files, "
                                      "denoisers (mcpost help lists them)",
                                      cmd_help, 0};
