/* fuzz_bands.c: an EXR read a band of rows at a time, as `mcpost merge`, `convert` and
 * `info` stream it (common/io's mcp__exr_rows_read_image; common/dump's
 * mcp__dump_bands, from the file and from rows), against the same file read whole
 * (mcp_image_read, mcp_dump_load, mcp_dump_from_image): both fail, or every band holds
 * the whole read's rows bit for bit, image and dump alike (docs/conventions.md, "Files
 * larger than memory").
 *
 * The first byte picks the bad-value policy (bit 0) and the band height (1 to 64 rows,
 * so that bands start inside chunks and tiles); the rest is the file, written to the
 * scratch folder. */
#include "fuzz.h"
#include "../../common/dump/internal.h"
#include "../../common/io/internal.h"

#include <mcpost/dump.h>
#include <mcpost/imageio.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void
finding(const char *what, int rc_whole, int rc_bands)
{
    fprintf(stderr, "fuzz: %s read whole and in bands differ (rc %d, %d)\n", what,
            rc_whole, rc_bands);
    abort();
}

/* part holds rows [y0, y0 + part->height) of whole: names and bits (NULL: both). */
static int
same_rows(const mcp_image *whole, const mcp_image *part, int y0)
{
    if (!whole || !part) return whole == part;
    if (whole->width != part->width || whole->channels != part->channels ||
        y0 + part->height > whole->height)
        return 0;
    for (int c = 0; c < whole->channels; c++)
        if (strcmp(whole->names[c], part->names[c]) != 0) return 0;
    for (int y = 0; y < part->height; y++)
        if (memcmp(mcp_image_px(whole, 0, y0 + y), mcp_image_px(part, 0, y),
                   (size_t)whole->width * whole->channels * sizeof(float)) != 0)
            return 0;
    return 1;
}

/* A band's dump holds the whole dump's rows and says what it says of itself. */
static int
same_dump_rows(const mcp_dump *whole, const mcp_dump *part, int y0)
{
    return same_rows(whole->color, part->color, y0) &&
           same_rows(whole->var_of_mean, part->var_of_mean, y0) &&
           same_rows(whole->cov_of_mean, part->cov_of_mean, y0) &&
           same_rows(whole->albedo, part->albedo, y0) &&
           same_rows(whole->normal, part->normal, y0) &&
           same_rows(whole->spp_map, part->spp_map, y0) &&
           memcmp(&whole->spp, &part->spp, sizeof whole->spp) == 0 &&
           whole->convention == part->convention &&
           whole->variance_in_file == part->variance_in_file &&
           whole->variance_source == part->variance_source;
}

/* The image in bands, and the dump `info` builds from each band's rows. */
static void
image_in_bands(const char *path, const mcp_dump_spec *spec, int rows)
{
    mcp_image *whole = NULL;
    mcp_dump *whole_dump = NULL;
    int rc_w = mcp_image_read(path, NULL, &whole);
    mcp_fuzz_check_error(rc_w, "whole read");
    int rc_wd = rc_w ? -1 : mcp_dump_from_image(whole, spec, &whole_dump);
    if (!rc_w) mcp_fuzz_check_error(rc_wd, "whole dump from the image");
    mcp__exr_rows *r = NULL;
    mcp__dump_bands *from_rows = NULL;
    int w = 0, h = 0, same = 1, rc_bd = 0;
    int rc_b = mcp__exr_rows_open(path, &r);
    if (!rc_b) {
        mcp__exr_rows_header(r, &w, &h);
        rc_b = mcp__dump_bands_for_rows(spec, h, &from_rows);
    }
    for (int y0 = 0; !rc_b && y0 < h; y0 += rows) {
        const int y1 = y0 + rows < h ? y0 + rows : h;
        mcp_image *band = NULL;
        mcp_dump *d = NULL;
        rc_b = mcp__exr_rows_read_image(r, y0, y1, &band);
        if (!rc_b && !rc_bd) {
            rc_bd = mcp__dump_bands_from_rows(from_rows, band, y0, &d);
            mcp_fuzz_check_error(rc_bd, "dump from a band's rows");
        }
        if (!rc_b && !rc_w) same = same && same_rows(whole, band, y0);
        if (d && whole_dump) same = same && same_dump_rows(whole_dump, d, y0);
        mcp_dump_free(d);
        mcp_image_free(band);
    }
    mcp_fuzz_check_error(rc_b, "read in bands");
    if (!rc_b && (rc_wd == 0) != (rc_bd == 0))
        finding("the dump from rows", rc_wd, rc_bd);
    mcp__dump_bands_close(from_rows);
    mcp__exr_rows_close(r);
    mcp_dump_free(whole_dump);
    mcp_image_free(whole);
    if ((rc_w == 0) != (rc_b == 0) || !same) finding("the image", rc_w, rc_b);
}

/* The dump in bands straight from the file, as merge and convert --dump read it. */
static void
dump_in_bands(const mcp_dump_spec *spec, int rows)
{
    mcp_dump *whole = NULL;
    int rc_w = mcp_dump_load(spec, &whole);
    mcp_fuzz_check_error(rc_w, "whole dump");
    mcp__dump_bands *b = NULL;
    int w = 0, h = 0, same = 1;
    int rc_b = mcp__dump_bands_open(spec, &b);
    mcp_fuzz_check_error(rc_b, "dump bands open");
    if (!rc_b && !b) { /* a dump that is read whole (two parts on one channel) */
        mcp_dump_free(whole);
        return;
    }
    if (!rc_b) mcp__dump_bands_size(b, &w, &h);
    for (int y0 = 0; !rc_b && y0 < h; y0 += rows) {
        const int y1 = y0 + rows < h ? y0 + rows : h;
        mcp_dump *d = NULL;
        rc_b = mcp__dump_bands_read(b, y0, y1, &d);
        if (!rc_b && !rc_w) same = same && same_dump_rows(whole, d, y0);
        mcp_dump_free(d);
    }
    mcp_fuzz_check_error(rc_b, "dump in bands");
    mcp__dump_bands_close(b);
    mcp_dump_free(whole);
    if ((rc_w == 0) != (rc_b == 0) || !same) finding("the dump", rc_w, rc_b);
}

int
LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 2) return 0;
    const int rows = 1 + (data[0] >> 1) % 64;
    const char *path = mcp_fuzz_file(0, "in.exr", data + 1, size - 1);
    mcp_dump_spec spec = mcp_dump_spec_defaults();
    spec.path = path;
    spec.bad_values = (mcp_badval_policy)(data[0] & 1);
    image_in_bands(path, &spec, rows);
    dump_in_bands(&spec, rows);
    return 0;
}
