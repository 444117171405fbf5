/* cmd_run.c: `mcpost run JOB.yaml` -- runs a whole pipeline from one job file. */
#include "cli.h"
#include "shot.h"

#include <mcpost/progress.h>

#include <getopt.h>
#include <stdio.h>
#include <string.h>

static const char usage[] =
    "usage: mcpost run JOB.yaml [--output DIR] [--json] [--quiet] [--list] [--check]\n"
    "                  [--frames SET] [-j N] [--force]\n"
    "  Runs the stages of a job file in order and writes the results, report.json and\n"
    "  report.html into the job's output folder (output: in the file, relative to it;\n"
    "  --output overrides). --json prints the report on stdout. --list names the "
    "stages.\n"
    "  --check validates the job as run does before its first stage (every stage's "
    "keys,\n"
    "  values, inputs, results of earlier stages and files) and runs nothing.\n"
    "  A job with frames: runs every frame into its own folder, OUTPUT/0017/, skipping\n"
    "  frames that are complete (their report.json written): see docs/frames.md;\n"
    "  `mcpost collect OUTPUT` then gathers the whole shot into one report.\n"
    "  --frames SET      only these frames (17, 10-20, 1-240:2, 1,5,9)\n"
    "  -j, --jobs N      run N frames at once, in N processes [1]\n"
    "  Exit status: 0 done, 1 error, 2 usage error; a job whose metrics stage has a\n"
    "  gate (fail:, warn:) exits with its worst gate: 3 warning, 4 failure, after\n"
    "  writing every result and the report (docs/jobs.md).\n"
    "  --force           run complete frames again\n"
    "\n"
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost run --list\n"
    "  mcpost run --check samples/jobs/demo.yaml\n"
    "  mcpost run samples/jobs/metrics.yaml          # then open "
    "out/metrics/report.html\n";

static int
cmd_run(int argc, char **argv)
{
    static const struct option longs[] = {
        {"output", required_argument, 0, 'o'}, {"json", no_argument, 0, 'J'},
        {"frames", required_argument, 0, 'f'}, {"jobs", required_argument, 0, 'j'},
        {"force", no_argument, 0, 'F'},        {"quiet", no_argument, 0, 'q'},
        {"list", no_argument, 0, 'l'},         {"check", no_argument, 0, 'c'},
        {"help", no_argument, 0, 'h'},         {0, 0, 0, 0}};
    mcp_job_options jo = mcp_job_defaults();
    int opt, check = 0, jobs = 1, force = 0;
    const char *frames = NULL;
    optind = 1;
    while ((opt = getopt_long(argc, argv, "o:qhj:", longs, NULL)) != -1) {
        switch (opt) {
        case 'o':
            jo.output_dir = optarg;
            break;
        case 'J':
            jo.json_stdout = 1;
            break;
        case 'f':
            frames = optarg;
            break;
        case 'F':
            force = 1;
            break;
        case 'j':
            if (mcp__parse_int("--jobs", optarg, &jobs) || jobs < 1)
                return mcp_cli_usage("run", "-j/--jobs takes a count >= 1 (got '%s')",
                                     optarg);
            break;
        case 'q':
            jo.quiet = 1;
            break;
        case 'c':
            check = 1;
            break;
        case 'l':
            for (const mcp_stage *const *s = mcp_job_stages(); *s; s++)
                printf("%-12s %s\n", (*s)->name, (*s)->summary);
            return 0;
        case 'h':
            fputs(usage, stdout);
            return 0;
        default:
            return mcp_cli_usage("run", "bad option");
        }
    }
    if (argc - optind != 1) return mcp_cli_usage("run", "give one job file");
    if (check) {
        if (mcp_job_check(argv[optind], mcp_job_stages())) return mcp_cli_fail();
        printf("%s: valid\n", argv[optind]);
        return 0;
    }
    mcp_progress_set_quiet(jo.quiet);
    mcp__gate_reset();
    mcp_cli_shot shot;
    if (mcp_cli_shot_open(argv[optind], jo.output_dir, frames, &shot))
        return mcp_cli_fail();
    int rc;
    if (!shot.n_all) {
        mcp_cli_shot_free(&shot);
        if (jobs > 1 || force)
            return mcp_cli_usage("run", "-j and --force are for jobs with frames:");
        rc = mcp_job_run_file(argv[optind], mcp_job_stages(), &jo);
    } else {
        rc = mcp_cli_shot_write_manifest(&shot) ||
             mcp_cli_shot_run(&shot, &jo, jobs, force);
        mcp_cli_shot_free(&shot);
    }
    if (rc) return mcp_cli_fail();
    /* The job ran to its end; a gate that warned or failed decides the status, as
     * `mcpost metrics --fail` does, so a CI step can run a whole job as its check. */
    mcp__gate_verdict worst = mcp__gate_worst();
    if (worst != MCP__GATE_PASS && !jo.quiet)
        fprintf(stderr, "mcpost run: gate %s (see the metrics section of the report)\n",
                worst == MCP__GATE_FAILURE ? "FAILURE" : "WARNING");
    return mcp__gate_exit_code(worst);
}

const mcp_command mcp_command_run = {"run", "run a pipeline from a YAML job file",
                                     cmd_run, 1};
