/* fuzz_job.c: the job-file path -- the YAML parser (common/yaml/yaml.c, on libyaml) and
 * the job's validation (mcp_job_check with the library's stage table, the one
 * `mcpost run` uses: inputs, stage names and keys, series patterns, replicate globs).
 * The input is the job file.
 *
 * mcp_job_check has no side effects, so a fuzzed `output:` makes no folder. The files
 * the seeds name (in.exr, x_0001.exr, ...) exist, empty, in the scratch folder: the
 * check looks for them but reads none, and with them the search gets past the
 * "input file ... not found" errors into the stages' settings. */
#include "fuzz.h"

#include <mcpost/job.h>
#include <mcpost/stages.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int ready;
    if (!ready) {
        static const char *const present[] = {"in.exr", "ref.exr", "r1.exr", "r2.exr"};
        for (int i = 0; i < 4; i++)
            mcp_fuzz_file(7, present[i], "", 0);
        /* a series x_%04d.exr of 1, 2, 4, ... 1024 samples, as the samples' jobs have */
        for (int spp = 1; spp <= 1024; spp *= 2) {
            char name[32];
            snprintf(name, sizeof name, "x_%04d.exr", spp);
            mcp_fuzz_file(7, name, "", 0);
        }
        ready = 1;
    }
    /* the parser on the text in memory */
    char *text = malloc(size + 1);
    if (!text) return 0;
    memcpy(text, data, size);
    text[size] = '\0';
    mcp_node *root = NULL;
    int rc = mcp_yaml_parse_string(text, "fuzz.yaml", &root);
    mcp_fuzz_check_error(rc, "yaml parse");
    mcp_node_free(root);
    free(text);
    /* the whole check, from a file as `mcpost run --check` reads it */
    const char *path = mcp_fuzz_file(0, "job.yaml", data, size);
    rc = mcp_job_check(path, mcp_job_stages());
    mcp_fuzz_check_error(rc, "job check");
    return 0;
}
