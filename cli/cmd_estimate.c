/* cmd_estimate.c: `mcpost estimate` -- how wrong a denoised render is and whether to
 * stop (estimate/estimate.h; docs/mathematics.md §2). The flags are the estimate's
 * table (ops/op_estimate.c), read by cli/options.c; the outputs
 * (images, estimate.json, the report section) are the library's, shared with the
 * `estimate` job stage (jobs/estimate_output.c, jobs/stage_estimate.c).
 *
 * One dump: the denoised image, SURE, variance, sampling map and counts, the blocks,
 * the error distribution, and the decision F(τ) >= p with the estimated percentiles,
 * written to a folder with estimate.json and a report. A series (several dumps, or a
 * pattern with --spp): the first spp at which each τ is reached and, with a reference,
 * the true one beside it (Firmino 2024 Table 1) with the estimated and true percentile
 * curves. Flags, job keys and Python keywords are the table's words (--denoiser-opt is
 * the denoiser map in a job). */
#include "cli.h"
#include "../common/dump/internal.h" /* a dump without the parts nothing reads */
#include "../estimate/internal.h"    /* which parts those are */

#include <mcpost/estimate.h>

#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EXIT_CONTINUE 10 /* --exit-status: keep rendering */

/* ---- flag values ---- */

static int
parse_int_list(const char *flag, const char *text, int **out, int *n)
{
    char **words = NULL;
    int count = 0, rc = 0;
    if (mcp__split_words(text, &words, &count)) return -1;
    int *v = mcp_calloc((size_t)(count ? count : 1), sizeof *v);
    rc = v ? 0 : -1;
    for (int i = 0; i < count && !rc; i++) {
        rc = mcp__parse_int(flag, words[i], &v[i]);
        if (!rc && v[i] < 1)
            rc = mcp_error("%s: sample counts must be >= 1 (got %d)", flag, v[i]);
    }
    mcp__free_words(words, count);
    if (rc) {
        free(v);
        return -1;
    }
    *out = v;
    *n = count;
    return 0;
}
static void
print_single(const mcp_estimate *e, const char *input, const char *denoiser,
             const mcp_estimate_options *o)
{
    printf("input:       %s\n", input);
    printf("denoiser:    %s\n", denoiser);
    printf("metric:      %s, tau %g, p %g\n", mcp_error_metric_name(o->sure.metric),
           e->tau, e->p);
    printf("F(tau):      %.6f -> %s%s\n", e->cdf_at_tau, e->stop ? "stop" : "continue",
           e->no_variance ? " (the dump has no variance: no estimate)" : "");
    printf("blocks:      %d\n", e->blocks->count);
    printf("variance:    %s\n", mcp__variance_source_words(e->variance_source));
    printf("estimated error at percentile:\n");
    for (int k = 0; k < e->n_percentiles; k++)
        printf("  %-10g %.6g\n", e->percentiles[k], e->percentile_tau[k]);
    printf(
        "time (ms):   denoise+jvp %.1f, SURE+variance %.1f, blocks %.1f, stopping %.1f, "
        "percentiles %.1f, sampling map %.1f\n",
        e->ms_denoise, e->ms_error_terms, e->ms_blocks, e->ms_stopping, e->ms_percentiles,
        e->ms_sampling);
}

static void
print_series(const mcp_series_estimate *s)
{
    printf("%-10s", "spp");
    for (int j = 0; j < s->n_taus; j++)
        printf("  F(%-8g)%s", s->taus[j], s->has_reference ? "  true     " : "");
    printf("\n");
    for (int i = 0; i < s->count; i++) {
        const mcp_series_point *pt = &s->points[i];
        printf("%-10g", pt->spp);
        for (int j = 0; j < s->n_taus; j++) {
            printf("  %.6f%s", pt->cdf[j],
                   pt->stop[j]                      ? "*"
                   : pt->held && pt->cdf[j] >= s->p ? "h"
                                                    : " ");
            if (s->has_reference)
                printf("  %.6f%s", pt->true_cdf[j], pt->true_stop[j] ? "*" : " ");
        }
        printf("\n");
    }
    printf("\n%-10s  %-12s%s\n", "tau", "stop at spp",
           s->has_reference ? "  true spp      agree" : "");
    int agree = 0, held = 0;
    for (int i = 0; i < s->count; i++)
        held = held || s->points[i].held;
    for (int j = 0; j < s->n_taus; j++) {
        printf("%-10g  %-12g", s->taus[j], s->first_spp[j]);
        if (s->has_reference)
            printf("  %-12g  %s", s->true_first_spp[j], s->agree[j] ? "yes" : "no");
        printf("\n");
        agree += s->agree[j];
    }
    if (s->has_reference) printf("agreement: %d of %d\n", agree, s->n_taus);
    printf("(0: not reached within the series; * F(tau) >= p%s)\n",
           held ? "; h: F(tau) >= p, held: no stop before the third checkpoint, whose "
                  "SURE rests on the render's own groups"
                : "");
    printf("variance: %s\n", mcp__variance_source_words(s->variance_source));
    printf("SURE: %s\n", mcp__sure_source_words(s));
}

/* ---- the subcommand ---- */

static const char head[] =
    "usage: mcpost estimate DUMP... [--denoiser NAME] [options]\n"
    "  Estimates the error of the denoised DUMP (SURE, Firmino et al. 2024) and decides\n"
    "  whether rendering can stop: F(tau) >= p, F the estimated CDF of the per-value\n"
    "  error. Several DUMPs, or --series, make a progressive series: then it reports\n"
    "  the first spp at which each tau is reached (and the true one with --ref).\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost estimate samples/fixtures/cornell/series/cornell_spp0064.exr --denoiser "
    "nlm -o out/estimate\n"
    "  mcpost estimate --series 'samples/fixtures/cornell/series/cornell_spp%04d.exr' "
    "--spp 16,32,64,128 \\\n"
    "                  --denoiser bilateral --ref "
    "samples/fixtures/cornell/cornell_reference.exr\n";

static int
cmd_estimate(int argc, char **argv)
{
    mcp_estimate_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0};
    int first = 0;
    int parsed = mcp_cli_parse(mcp_operation_estimate(), head, examples, argc, argv, &st,
                               &sh, &df, &first);
    if (parsed >= 0) {
        mcp_cli_denoiser_flags_free(&df);
        return parsed;
    }
    mcp_series_estimate_options so = st.so;
    mcp_estimate_options *eo = &so.est;
    const char *outdir = sh.output, *pattern = st.series, *spp_text = st.spp,
               *ref_path = st.reference;
    int json = sh.json, exit_status = st.exit_status;
    mcp_series_variance variance_from = st.variance_from;
    optind = first;
    int n_files = argc - optind;
    if (!n_files && !pattern) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("estimate", "no dump given");
    }
    if (pattern && (n_files || !spp_text)) {
        mcp_cli_denoiser_flags_free(&df);
        return mcp_cli_usage("estimate", "--series needs --spp and no other dumps");
    }
    int status = 1, is_series = pattern || n_files > 1;
    mcp_denoiser *den = NULL;
    mcp_dump *dump = NULL;
    mcp_series *series = NULL;
    mcp_image *ref = NULL;
    mcp_estimate *e = NULL;
    mcp_series_estimate *s = NULL;
    mcp_report *report = NULL;
    cJSON *summary = NULL, *section = NULL;
    mcp__estimate_dir od;
    mcp__outdir whole = {0}; /* -o DIR appears whole, or not at all */
    mcp__estimate_files files = {0};
    memset(&od, 0, sizeof od);
    if (mcp_estimate_check(eo) || mcp_cli_denoiser_create(&df, &den) ||
        (ref_path && mcp_image_read(ref_path, NULL, &ref)))
        goto done;
    if (outdir) { /* after the cheap checks, before any work */
        const char *named[] = {ref_path, pattern};
        if (mcp__outdir_begin(&whole, outdir) ||
            mcp__outdir_check_inputs(&whole, named, 2) ||
            mcp__outdir_check_inputs(&whole, (const char *const *)argv + optind, n_files))
            goto done;
        snprintf(od.dir, sizeof od.dir, "%s", whole.tmp);
    }
    if (outdir && (mcp_report_new("mcpost estimate", &report) ||
                   !(section = mcp_report_section(
                         report, "estimate",
                         is_series ? "error estimate over a series" : "error estimate"))))
        goto done;
    if (is_series) {
        if (pattern) {
            int *spps = NULL, n = 0;
            int rc = parse_int_list("--spp", spp_text, &spps, &n) ||
                     mcp_series_from_pattern(pattern, spps, n, &series);
            free(spps);
            if (rc) goto done;
        } else if (mcp_series_from_paths((const char *const *)argv + optind, NULL,
                                         n_files, &series)) {
            goto done;
        }
        series->spec.convention = st.convention;
        series->spec.variance = st.variance;
        series->variance_from = variance_from;
        if (mcp__estimate_run_series(series, den, &so, ref, outdir ? &od : NULL, section,
                                     &summary, &s))
            goto done;
        if (!json) print_series(s);
        status = 0;
        if (exit_status) {
            const mcp_series_point *last = &s->points[s->count - 1];
            for (int j = 0; j < s->n_taus; j++)
                if (!last->stop[j]) status = EXIT_CONTINUE;
        }
    } else {
        const char *path = argv[optind];
        mcp_dump_spec spec = mcp_dump_spec_defaults();
        spec.path = path;
        spec.convention = st.convention;
        spec.variance = st.variance;
        /* the features only when something reads them: the denoiser, or joint SURE */
        const unsigned without = mcp__dump_parts_unread(den, eo->sure.features != NULL);
        /* a large dump, read and estimated a band at a time, F(X), SURE and Var[F]
           written as their bands are made (jobs/estimate_stream.c); not with a
           reference, whose truth reads F(X) whole */
        int streamed = 0;
        if (!ref) {
            files.dir = outdir ? &od : NULL;
            files.want_picture = section != NULL;
            const mcp__estimate_sink sink = {mcp__estimate_files_rows, &files};
            int bad = mcp__estimate_streamed(&spec, without, den, eo,
                                             outdir ? &sink : NULL, &e, &streamed);
            if (mcp__estimate_files_end(&files, bad) || bad) goto done;
        }
        if (!streamed && (mcp__dump_load_without(&spec, without, &dump) ||
                          mcp_estimate_compute(dump, den, eo, &e)))
            goto done;
        /* nothing after the estimate reads the dump, nor Σ̂^r, which only cut the
           blocks: their memory goes to the pictures and files */
        mcp_dump_free(dump);
        dump = NULL;
        mcp_image_free(e->maps.sigma_rel);
        e->maps.sigma_rel = NULL;
        summary = mcp__estimate_json(e, path, den->name, eo);
        if (ref && mcp__estimate_add_truth(e, ref, eo, summary)) /* the truth beside it */
            goto done;
        if (outdir) {
            char path_json[4352];
            char *text = cJSON_Print(summary);
            int rc =
                !text ||
                mcp__estimate_write_single(e, &od, section, summary,
                                           files.denoised_rgb) ||
                mcp__estimate_path(&od, "estimate.json", path_json, sizeof path_json) ||
                mcp_write_file_atomic(path_json, text, strlen(text)) ||
                mcp__estimate_report_single(section, summary, e);
            free(text);
            if (rc) goto done;
        }
        if (!json) print_single(e, path, den->name, eo);
        status = exit_status && !e->stop ? EXIT_CONTINUE : 0;
    }
    if ((report && mcp__outdir_fix_paths(&whole, mcp_report_json(report))) ||
        mcp__outdir_fix_paths(&whole, summary) ||
        (report && (mcp_report_write(report, od.dir) || mcp__outdir_commit(&whole)))) {
        status = 1;
        goto done;
    }
    if (json) {
        mcp_cli_print_json(summary);
        summary = NULL;
    }
done:
    mcp__estimate_files_free(&files);
    mcp__outdir_abort(&whole);
    if (status == 1) mcp_cli_fail();
    cJSON_Delete(summary);
    mcp_report_free(report);
    mcp_series_estimate_free(s);
    mcp_estimate_free(e);
    mcp_image_free(ref);
    mcp_series_free(series);
    mcp_dump_free(dump);
    mcp_denoiser_free(den);
    mcp_cli_denoiser_flags_free(&df);
    return status;
}

const mcp_command mcp_command_estimate = {
    "estimate", "estimate the error of a denoised render and decide when to stop",
    cmd_estimate, 1};
