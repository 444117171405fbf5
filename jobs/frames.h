/* frames.h: frame sets and frame tokens, for jobs over the frames of a shot
 * (docs/frames.md).
 *
 * A frame set is written as render farms write it: numbers, ranges and stepped ranges
 * separated by commas, "1-240", "1-240:2" (or "1-240x2": every second frame), "1,5,9-12".
 * Frames are 0 .. MCP_FRAME_MAX; a set is kept sorted, each frame once.
 *
 * A frame token in a path stands for the frame number:
 *   a run of '#'      padded to the number of '#' ("####": 0017; "#": 17); a frame
 *                     wider than the run is written in full (12345), never cut
 *   an integer        printf style, "%04d" (flags 0-+ #, width <= 16, d/i/u), as series
 *   conversion        patterns (mcp_series_from_pattern)
 * A series pattern also holds the spp token, always a printf conversion. So the frame
 * token of a path is, unambiguously:
 *   - its '#' run, when it has one (then its one printf conversion, if any, is the spp);
 *   - else, in a series pattern, the first of two printf conversions (frame, then spp);
 *     a series pattern with one conversion has no frame token (the spp is the only one);
 *   - else, in any other path, its one printf conversion.
 * More than one '#' run, a non-integer conversion, or more conversions than these
 * rules allow are errors. "%%" is a literal '%'. */
#ifndef MCP_FRAMES_H
#define MCP_FRAMES_H

#include <mcpost/error.h>

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The largest frame number, and the most frames one set may hold (over an hour of
 * film at 24 frames a second). */
#define MCP_FRAME_MAX 9999999
#define MCP_FRAMES_MAX_COUNT 100000

/* Parses a frame set into a sorted array of distinct frames (*frames malloc'd).
 * Errors name the text: "frames '1-x': ...". */
MCP_API int mcp_frames_parse(const char *text, int **frames, int *count);

/* Writes a sorted set compactly ("1-4,7,10-20:2") into buf; fails when it does not
 * fit. */
MCP_API int mcp_frames_format(const int *frames, int count, char *buf, size_t cap);

/* Whether frame is in the sorted set. */
MCP_API int mcp_frames_contains(const int *frames, int count, int frame);

/* The folder of a frame's results inside a job's output folder: "<dir>/0017". */
MCP_API int mcp_frame_dir(const char *output_dir, int frame, char *buf, size_t cap);

/* Whether a frame's results are complete: its report.json, written last and
 * atomically by the job, exists. */
MCP_API int mcp_frame_complete(const char *output_dir, int frame);

/* Removes, under dir (recursively), the temporary files that an atomic write left
 * behind when its process was killed (SIGKILL gives it no chance to clean up): names
 * with ".tmp-PID-" whose PID is no longer running. A live process's temporaries are
 * kept. Returns the number removed (0 when dir does not exist), or -1 with the error
 * set. */
MCP_API int mcp_frame_clear_temporaries(const char *dir);

#ifdef __cplusplus
}
#endif
#endif
