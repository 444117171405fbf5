/* cmd_run.c: `mcpost run JOB.yaml` -- runs a whole pipeline from one job file. */
#include "cli.h"

#include <mcpost/progress.h>

#include <getopt.h>
#include <stdio.h>
#include <string.h>

static const char usage[] =
    "usage: mcpost run JOB.yaml [--output DIR] [--json] [--quiet] [--list] [--check]\n"
    "  Runs the stages of a job file in order and writes the results, report.json and\n"
    "  report.html into the job's output folder (output: in the file, relative to it;\n"
    "  --output overrides). --json prints the report on stdout. --list names the stages.\n"
    "  --check validates the job as run does before its first stage (every stage's keys,\n"
    "  values, inputs, results of earlier stages and files) and runs nothing.\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost run --list\n"
    "  mcpost run --check samples/jobs/demo.yaml\n"
    "  mcpost run samples/jobs/metrics.yaml          # then open out/metrics/report.html\n";

static int
cmd_run(int argc, char **argv)
{
    static const struct option longs[] = {{"output", required_argument, 0, 'o'},
                                          {"json", no_argument, 0, 'j'},
                                          {"quiet", no_argument, 0, 'q'},
                                          {"list", no_argument, 0, 'l'},
                                          {"check", no_argument, 0, 'c'},
                                          {"help", no_argument, 0, 'h'},
                                          {0, 0, 0, 0}};
    mcp_job_options jo = mcp_job_defaults();
    int opt, check = 0;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "o:qh", longs, NULL)) != -1) {
        switch (opt) {
        case 'o': jo.output_dir = optarg; break;
        case 'j': jo.json_stdout = 1; break;
        case 'q': jo.quiet = 1; break;
        case 'c': check = 1; break;
        case 'l':
            for (const mcp_stage *const *s = mcp_stages; *s; s++)
                printf("%-12s %s\n", (*s)->name, (*s)->summary);
            return 0;
        case 'h': fputs(usage, stdout); return 0;
        default: return mcp_cli_usage("run", "bad option");
        }
    }
    if (argc - optind != 1)
        return mcp_cli_usage("run", "give one job file");
    if (check) {
        if (mcp_job_check(argv[optind], mcp_stages))
            return mcp_cli_fail();
        printf("%s: valid\n", argv[optind]);
        return 0;
    }
    mcp_progress_set_quiet(jo.quiet);
    return mcp_job_run_file(argv[optind], mcp_stages, &jo) ? mcp_cli_fail() : 0;
}

const mcp_command mcp_command_run = {"run", "run a pipeline from a YAML job file", cmd_run};
