/* internal.h: functions of common/dump/ that other library files and the tests call
 * but that libmcpost.so does not export (hidden visibility; not installed). */
#ifndef MCP_DUMP_INTERNAL_H
#define MCP_DUMP_INTERNAL_H

#include <mcpost/dump.h>
#include <mcpost/wordlist.h>

/* ---- dump.c: the words of two dump enums, and the series' variance source ---- */

extern const mcp_wordlist mcp_variance_source_words, mcp_badval_policy_words;
const char *mcp_series_variance_name(mcp_series_variance v);
int mcp_series_variance_from_name(const char *name, mcp_series_variance *out);

/* ---- dump.c, replicates.c ---- */

/* Whether a dump's variance is a renderer's per-sample one divided by n (Mitsuba's XYZ
 * moments are too): what a stratified sampler makes an overstatement. */
static inline int
mcp__variance_is_per_sample(mcp_variance_source s)
{
    return s == MCP_VARSRC_PER_SAMPLE || s == MCP_VARSRC_XYZ_MOMENTS;
}

/* A series member as its file holds it, whatever the series' variance_from (dump.c). */
int mcp__series_load_file(const mcp_series *s, int i, mcp_dump **out);
/* mcp_series_increment_variance of member i with that member already read (borrowed),
 * the members before it read from their files (replicates.c). */
int mcp__series_increments_with(const mcp_series *s, int i, const mcp_dump *member,
                                const mcp_increment_options *opt, mcp_dump **out,
                                double *ratio);
/* What to do about a dump without variance, for the end of its one-line error: the
 * recipe for a Cycles render (convention blender), else `otherwise` (dump.c). */
const char *mcp__no_variance_hint(const mcp_dump *d, const char *otherwise);

#endif
