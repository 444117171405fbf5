/* mcpost_optdoc.c: the docs' option tables from the operation table (<mcpost/options.h>).
 *
 *   mcpost-optdoc NAME         prints the markdown table of operation NAME (or of the
 *                              settings of denoiser NAME)
 *   mcpost-optdoc --write DIR  writes DIR/NAME.md for every operation and denoiser
 *
 * The build writes them into build/docs/options/, and tests/docs/options.sh checks that
 * every docs page's table between `<!-- options: NAME -->` and `<!-- end options -->`
 * is the same text (docs/library.md, "Adding an option"). Not installed. */
#include <mcpost/denoiser.h>
#include <mcpost/options.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int
write_one(const mcp_operation *op, const char *dir)
{
    char *text = mcp_operation_markdown(op);
    if (!text) {
        fprintf(stderr, "mcpost-optdoc: %s: %s\n", op->name, mcp_error_message());
        return 1;
    }
    int rc = 0;
    if (!dir) {
        fputs(text, stdout);
    } else {
        char path[4096];
        snprintf(path, sizeof path, "%s/%s.md", dir, op->name);
        FILE *f = fopen(path, "w");
        rc = !f || fputs(text, f) < 0;
        if (f && fclose(f)) rc = 1;
        if (rc) fprintf(stderr, "mcpost-optdoc: cannot write %s\n", path);
    }
    free(text);
    return rc;
}

int
main(int argc, char **argv)
{
    if (argc == 3 && !strcmp(argv[1], "--write")) {
        int rc = 0;
        for (const mcp_operation *const *op = mcp_operations(); *op; op++)
            rc |= write_one(*op, argv[2]);
        for (const mcp_denoiser_kind *const *k = mcp_denoiser_kinds(); *k; k++)
            if ((*k)->options) rc |= write_one((*k)->options, argv[2]);
        return rc;
    }
    const mcp_operation *op = argc == 2 ? mcp_operation_find(argv[1]) : NULL;
    for (const mcp_denoiser_kind *const *k = mcp_denoiser_kinds(); !op && argc == 2 && *k;
         k++)
        if ((*k)->options && !strcmp((*k)->options->name, argv[1])) op = (*k)->options;
    if (!op) {
        fprintf(stderr, "usage: mcpost-optdoc NAME | --write DIR (NAME: ");
        for (const mcp_operation *const *o = mcp_operations(); *o; o++)
            fprintf(stderr, "%s%s", o == mcp_operations() ? "" : ", ", (*o)->name);
        fprintf(stderr, ")\n");
        return 2;
    }
    return write_one(op, NULL);
}
