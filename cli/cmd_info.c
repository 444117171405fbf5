/* cmd_info.c: `mcpost info FILE` -- what a file holds: size, channels with statistics,
 * the render-dump convention and sample count (the channel and dump descriptions are
 * the library's, shared with the `info` job stage: jobs/stage_info.c). */
#include "cli.h"
#include "../common/core/internal.h" /* statistics a band at a time */
#include "../common/dump/internal.h" /* the dump a band at a time */
#include "../common/io/internal.h"   /* the file a band at a time */

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void
add_attrs(cJSON *o, const mcp_attrs *attrs)
{
    cJSON *a = cJSON_AddObjectToObject(o, "attributes");
    for (int i = 0; i < attrs->count; i++) {
        const mcp_attr *t = &attrs->items[i];
        if (t->type == MCP_ATTR_STRING)
            cJSON_AddStringToObject(a, t->name, t->s);
        else
            cJSON_AddNumberToObject(a, t->name,
                                    t->type == MCP_ATTR_INT ? (double)t->i : t->f);
    }
}

/* The description of a file: the raw channels, and what it means as a render dump
 * (or why it is none). */
static cJSON *
describe_file(const char *path, const mcp_image *img, const mcp_dump_spec *spec)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "file", path);
    cJSON_AddStringToObject(o, "format", mcp_format_name(mcp_format_from_path(path)));
    cJSON_AddNumberToObject(o, "width", img->width);
    cJSON_AddNumberToObject(o, "height", img->height);
    mcp_dump *d = NULL;
    if (mcp_dump_from_image(img, spec, &d) == 0) {
        mcp__info_add_dump(o, d);
        mcp_dump_free(d);
    } else {
        cJSON_AddStringToObject(o, "convention",
                                mcp_convention_name(mcp_dump_detect(img)));
        cJSON_AddStringToObject(o, "dump_error", mcp_error_message());
    }
    if (mcp__info_add_channels(cJSON_AddArrayToObject(o, "channels"), img, "")) {
        cJSON_Delete(o);
        return NULL;
    }
    add_attrs(o, &img->attrs);
    return o;
}

/* What a band of a streamed description needs: every channel's statistics so far, and
 * the dump's band reader until a band fails as a dump. */
typedef struct info_stream {
    mcp__exr_rows *exr;
    mcp__dump_bands *dump;
    mcp_dump *last;            /* the last band's dump: its metadata are the file's */
    char dump_error[1024];     /* why it is no dump, once a band says so */
    mcp_channel_stats *totals; /* each channel's, over the bands so far */
    mcp_channel_stats *rows;   /* a band's rows' */
    mcp_image *first;          /* the first band: the channels' names in a whole
                                  read's order, the attributes */
} info_stream;

static int
info_band(void *ctx, int y0, int y1)
{
    info_stream *st = ctx;
    mcp_image *img = NULL;
    if (mcp__exr_rows_read_image(st->exr, y0, y1, &img)) return -1;
    for (int c = 0; c < img->channels; c++) {
        mcp__channel_stats_rows(img, c, st->rows);
        mcp__channel_stats_add(&st->totals[c], st->rows, y1 - y0);
    }
    mcp_dump *d = NULL;
    if (!st->dump_error[0]) {
        if (mcp__dump_bands_from_rows(st->dump, img, y0, &d)) {
            snprintf(st->dump_error, sizeof st->dump_error, "%s", mcp_error_message());
            mcp_error_clear();
        } else {
            mcp_dump_free(st->last);
            st->last = d;
        }
    }
    if (!st->first)
        st->first = img;
    else
        mcp_image_free(img);
    return 0;
}

/* describe_file's object for an EXR read a band of rows at a time, so that a render of
 * any size is described within a band's memory (issue 31; docs/conventions.md,
 * "Files larger than memory"): the statistics of each row added in order, and the dump
 * built and checked band by band, give the whole read's figures and words. 0 and *o NULL
 * when the file is read whole instead (another format, MCPOST_BAND_ROWS=whole). */
static int
describe_streamed(const char *path, const mcp_dump_spec *given, cJSON **o)
{
    *o = NULL;
    const int band = mcp__stream_band_rows();
    if (!band || mcp_format_from_path(path) != MCP_FORMAT_EXR) return 0;
    info_stream st = {0};
    int w, h, rc = -1;
    mcp_dump_spec spec = *given;
    spec.path = path;
    char label[96];
    snprintf(label, sizeof label, "info %s", path);
    if (mcp__exr_rows_open(path, &st.exr)) return -1;
    const mcp_image *header = mcp__exr_rows_header(st.exr, &w, &h);
    if (!(st.totals = mcp_calloc((size_t)header->channels, sizeof *st.totals)) ||
        !(st.rows = mcp_calloc((size_t)band, sizeof *st.rows)) ||
        mcp__dump_bands_for_rows(&spec, h, &st.dump))
        goto done;
    for (int c = 0; c < header->channels; c++)
        mcp__channel_stats_start(&st.totals[c]);
    if (mcp__stream_bands(label, w, h, band, info_band, &st)) goto done;
    cJSON *d = cJSON_CreateObject();
    cJSON_AddStringToObject(d, "file", path);
    cJSON_AddStringToObject(d, "format", mcp_format_name(MCP_FORMAT_EXR));
    cJSON_AddNumberToObject(d, "width", w);
    cJSON_AddNumberToObject(d, "height", h);
    if (!st.dump_error[0]) {
        mcp__info_add_dump(d, st.last);
    } else {
        cJSON_AddStringToObject(d, "convention",
                                mcp_convention_name(mcp_dump_detect(st.first)));
        cJSON_AddStringToObject(d, "dump_error", st.dump_error);
    }
    cJSON *channels = cJSON_AddArrayToObject(d, "channels");
    for (int c = 0; c < st.first->channels; c++) {
        mcp__channel_stats_finish(&st.totals[c]);
        mcp__info_add_channel(channels, st.first->names[c], &st.totals[c]);
    }
    add_attrs(d, &st.first->attrs);
    *o = d;
    rc = 0;
done:
    mcp_image_free(st.first);
    mcp_dump_free(st.last);
    mcp__dump_bands_close(st.dump);
    free(st.rows);
    free(st.totals);
    mcp__exr_rows_close(st.exr);
    return rc;
}

/* What the variance rests on, in words: a per-sample variance is an assumption. */
static void
print_variance_source(const cJSON *o)
{
    const cJSON *src = cJSON_GetObjectItem(o, "variance_source");
    if (!cJSON_IsString(src) || strcmp(src->valuestring, "none") == 0) return;
    const cJSON *dof = cJSON_GetObjectItem(o, "variance_dof"),
                *k = cJSON_GetObjectItem(o, "replicates"),
                *pool = cJSON_GetObjectItem(o, "variance_pool");
    mcp_variance_source s;
    if (strcmp(src->valuestring, "per-sample") == 0 ||
        strcmp(src->valuestring, "of-mean") == 0 ||
        strcmp(src->valuestring, "xyz-moments") == 0)
        printf("  source:    %s\n",
               mcp_variance_source_from_name(src->valuestring, &s) == 0
                   ? mcp__variance_source_words(s)
                   : src->valuestring);
    else
        printf("  source:    %s: the spread of %d %s (%g degrees of freedom)\n",
               src->valuestring, k ? k->valueint : 0,
               strcmp(src->valuestring, "replicates") == 0 ? "renders" : "blocks",
               dof ? dof->valuedouble : 0);
    if (pool) printf("  pooled:    over %g pixels\n", pool->valuedouble);
}

static void
print_text(const cJSON *o)
{
    const cJSON *spp = cJSON_GetObjectItem(o, "spp");
    printf("file:        %s\n", cJSON_GetObjectItem(o, "file")->valuestring);
    printf("size:        %dx%d, %d channels (%s)\n",
           cJSON_GetObjectItem(o, "width")->valueint,
           cJSON_GetObjectItem(o, "height")->valueint,
           cJSON_GetArraySize(cJSON_GetObjectItem(o, "channels")),
           cJSON_GetObjectItem(o, "format")->valuestring);
    printf("convention:  %s\n", cJSON_GetObjectItem(o, "convention")->valuestring);
    if (cJSON_IsNumber(spp))
        printf("samples:     %g per pixel\n", spp->valuedouble);
    else if (cJSON_IsString(spp))
        printf("samples:     %s\n", spp->valuestring);
    else
        printf("samples:     unknown (give --spp)\n");
    const cJSON *var = cJSON_GetObjectItem(o, "variance");
    if (var) printf("variance:    %s\n", var->valuestring);
    print_variance_source(o);
    const cJSON *err = cJSON_GetObjectItem(o, "dump_error");
    if (err) printf("as a dump:   %s\n", err->valuestring);
    printf("\n%-28s %12s %12s %12s %8s %8s %8s\n", "channel", "min", "mean", "max", "NaN",
           "Inf", "negative");
    const cJSON *ch;
    cJSON_ArrayForEach(ch, cJSON_GetObjectItem(o, "channels"))
        printf("%-28s %12.6g %12.6g %12.6g %8.0f %8.0f %8.0f\n",
               cJSON_GetObjectItem(ch, "name")->valuestring,
               cJSON_GetObjectItem(ch, "min")->valuedouble,
               cJSON_GetObjectItem(ch, "mean")->valuedouble,
               cJSON_GetObjectItem(ch, "max")->valuedouble,
               cJSON_GetObjectItem(ch, "nan")->valuedouble,
               cJSON_GetObjectItem(ch, "inf")->valuedouble,
               cJSON_GetObjectItem(ch, "negative")->valuedouble);
    const cJSON *a = cJSON_GetObjectItem(o, "attributes");
    if (cJSON_GetArraySize(a)) printf("\nattributes:\n");
    cJSON_ArrayForEach(ch, a)
    {
        if (cJSON_IsString(ch))
            printf("  %-26s %s\n", ch->string, ch->valuestring);
        else
            printf("  %-26s %.10g\n", ch->string, ch->valuedouble);
    }
}

static const char head[] =
    "usage: mcpost info FILE... [--json] [--spp N] [--convention NAME] [--variance "
    "KIND]\n"
    "  Prints size, channels with min/mean/max and NaN/Inf/negative counts, the\n"
    "  render-dump convention (pbrt, mitsuba, blender, mcpost, plain) and the sample\n"
    "  count.\n";

static const char examples[] =
    "examples (from the source folder, on the sample renders):\n"
    "  mcpost info samples/fixtures/cornell/series/cornell_spp0016.exr\n"
    "  mcpost info --json samples/fixtures/cornell/cornell_reference.exr\n";

static int
cmd_info(int argc, char **argv)
{
    mcp_info_settings st;
    mcp_shared_settings sh;
    mcp_cli_denoiser_flags df = {0}; /* info takes no denoiser */
    int first = 0;
    int parsed = mcp_cli_parse(mcp_operation_info(), head, examples, argc, argv, &st, &sh,
                               &df, &first);
    mcp_cli_denoiser_flags_free(&df);
    if (parsed >= 0) return parsed;
    mcp_dump_spec spec = st.spec;
    int json = sh.json;
    if (first >= argc) return mcp_cli_usage("info", "no file given");
    int status = 0;
    cJSON *all = cJSON_CreateArray();
    for (int i = first; i < argc; i++) {
        cJSON *o = NULL;
        mcp_image *img = NULL;
        /* an EXR a band of rows at a time, the others whole */
        if (describe_streamed(argv[i], &spec, &o)) {
            status = mcp_cli_fail();
            continue;
        }
        if (!o) {
            if (mcp_image_read(argv[i], NULL, &img)) {
                status = mcp_cli_fail();
                continue;
            }
            o = describe_file(argv[i], img, &spec);
            mcp_image_free(img);
        }
        if (!o) {
            status = mcp_cli_fail();
            continue;
        }
        if (json) {
            cJSON_AddItemToArray(all, o);
        } else {
            if (i > first) printf("\n");
            print_text(o);
            cJSON_Delete(o);
        }
    }
    if (json && cJSON_GetArraySize(all) == 1 && argc - first == 1) {
        cJSON *one = cJSON_DetachItemFromArray(all, 0);
        cJSON_Delete(all);
        all = one;
    }
    if (json)
        mcp_cli_print_json(all);
    else
        cJSON_Delete(all);
    return status;
}

const mcp_command mcp_command_info = {"info", "describe images and render dumps",
                                      cmd_info, 1};
