/* mcpost.h: the whole public API of libmcpost in one include (docs/library.md).
 *
 *     #include <mcpost/mcpost.h>
 *
 * Every installed header, and nothing else: the list is MCP_PUBLIC_HEADERS in
 * CMakeLists.txt, and tests/api/umbrella.sh checks that the two agree. */
#ifndef MCP_MCPOST_H
#define MCP_MCPOST_H

/* errors, words, images and their files */
#include <mcpost/error.h>
#include <mcpost/wordlist.h>
#include <mcpost/image.h>
#include <mcpost/imageio.h>
#include <mcpost/dump.h>
#include <mcpost/frames.h>

/* filters, tone maps, metrics, FLIP, spectra, statistics */
#include <mcpost/filter.h>
#include <mcpost/tonemap.h>
#include <mcpost/metrics.h>
#include <mcpost/flip.h>
#include <mcpost/spectra.h>
#include <mcpost/stats.h>

/* plots, reports, progress, job files (YAML node trees, jobs and stages) */
#include <mcpost/plot.h>
#include <mcpost/report.h>
#include <mcpost/progress.h>
#include <mcpost/yaml.h>
#include <mcpost/job.h>

/* the operations: estimate, blend, perceptual, their options and job stages */
#include <mcpost/denoiser.h>
#include <mcpost/estimate.h>
#include <mcpost/blend.h>
#include <mcpost/perceptual.h>
#include <mcpost/options.h>
#include <mcpost/operations.h>
#include <mcpost/stages.h>

#endif
