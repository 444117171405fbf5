/* dump.h: render dumps -- what a Monte Carlo renderer knows about one image -- and
 * series of them (a progressive render).
 *
 * A dump holds, per pixel, the colour mean X (RGB), the variance of that mean
 * (per channel, and optionally the 3x3 colour covariance of the mean), the sample
 * count (scalar or per-pixel map), optional albedo and normal, and the header
 * attributes. Variance is ALWAYS stored as variance of the mean in memory; files that
 * store per-sample variance (pbrt-v4, Mitsuba's moments) are divided by the sample
 * count on load. docs/mathematics.md §1.
 *
 * Conventions recognised from channel names and attributes (docs/conventions.md):
 *   pbrt-v4 GBufferFilm: R,G,B; Variance.R/G/B (per-sample); Albedo.*; N.X/Y/Z;
 *                        int samplesPerPixel
 *   Mitsuba 3:           R,G,B (the film's main image); <aov>.R/G/B whose name
 *                        contains "albedo"; <aov>.X/Y/Z whose name contains "normal"
 *                        (or is "nn"); the moment integrator's <nested>.X/Y/Z (the
 *                        sample in CIE XYZ) with m2_<nested>.X/Y/Z (second moments,
 *                        no cross terms: variance source "xyz-moments"); mcpost's own
 *                        older m2_R/m2_G/m2_B; no sample count in the file
 *   Blender Cycles:      <layer>.Combined.R/G/B, <layer>.Denoising Albedo.*,
 *                        <layer>.Denoising Normal.*, string cycles.<layer>.samples;
 *                        <layer>.Variance.R/G/B when present (per-sample)
 *   mcpost:              as pbrt-v4, plus Covariance.RG/RB/GB (per-sample) and a
 *                        per-pixel sample-count channel "SampleCount"
 *   plain:               R,G,B only; everything else from separate files
 * An explicit mapping (mcp_dump_spec) overrides detection. */
#ifndef MCP_DUMP_H
#define MCP_DUMP_H

#include <mcpost/image.h>
#include <mcpost/wordlist.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    MCP_CONV_AUTO = 0, /* detect from the file */
    MCP_CONV_PBRT,
    MCP_CONV_MITSUBA,
    MCP_CONV_BLENDER,
    MCP_CONV_MCPOST,
    MCP_CONV_PLAIN
} mcp_convention;

MCP_API const char *mcp_convention_name(mcp_convention c);
/* The words of the dump enums (their from_name functions read them). */
MCP_API extern const mcp_wordlist mcp_convention_words, mcp_variance_kind_words,
    mcp_merge_variance_words;
MCP_API int mcp_convention_from_name(const char *name, mcp_convention *out);

typedef enum {
    MCP_VAR_DEFAULT = 0, /* what the convention says */
    MCP_VAR_PER_SAMPLE,  /* variance of one sample: divided by n on load */
    MCP_VAR_OF_MEAN      /* already the variance of the pixel mean */
} mcp_variance_kind;

MCP_API int mcp_variance_kind_from_name(const char *name, mcp_variance_kind *out);

typedef enum {
    MCP_BADVAL_FAIL = 0, /* NaN/Inf in colour or features, negative variance: error */
    MCP_BADVAL_ZERO      /* replace them by 0 and count them in the dump */
} mcp_badval_policy;

MCP_API int mcp_badval_policy_from_name(const char *name, mcp_badval_policy *out);

/* Where a dump's variance of the mean came from. It decides how far the estimates can
 * trust it (docs: "Variance sources"). A renderer's per-sample variance divided by n is
 * right only when the n samples are independent; stratified samplers (Cycles'
 * Sobol-Burley and PMJ, pbrt-v4's ZSobol) make it an overstatement. */
typedef enum {
    MCP_VARSRC_NONE = 0,   /* no variance */
    MCP_VARSRC_PER_SAMPLE, /* per-sample variance / n: assumes independent samples */
    MCP_VARSRC_OF_MEAN,    /* the file stored a variance of the mean, origin unknown */
    MCP_VARSRC_REPLICATES, /* the spread between K independent renders (mcp_dump_merge) */
    MCP_VARSRC_INCREMENTS, /* the spread between the increments of one progressive
                              render (mcp_series_increment_variance) */
    MCP_VARSRC_XYZ_MOMENTS /* Mitsuba 3's moment integrator: per-sample XYZ variances
                              without their covariances, turned into RGB as if X, Y, Z
                              were perfectly correlated, / n (docs/conventions.md) */
} mcp_variance_source;

/* "none", "per-sample", "of-mean", "replicates", "increments", "xyz-moments". */
MCP_API const char *mcp_variance_source_name(mcp_variance_source s);
MCP_API int mcp_variance_source_from_name(const char *name, mcp_variance_source *out);

/* How to load a dump. Zero-initialise (or use mcp_dump_spec_defaults()); set only what
 * detection should not decide. Paths in the *_path fields name separate files. */
typedef struct mcp_dump_spec {
    const char *path;             /* the main file (colour, and whatever else it holds) */
    mcp_convention convention;    /* [auto] */
    mcp_variance_kind variance;   /* [per convention] */
    mcp_badval_policy bad_values; /* [fail] */
    double spp;                   /* sample count when the file has none (0: from file) */
    /* explicit channel names in the main file (NULL: detect) */
    const char *color[3];
    const char *var[3];
    const char *albedo[3];
    const char *normal[3];
    /* separate files (NULL: none); they are read with the same channel rules */
    const char *variance_path;
    const char *albedo_path;
    const char *normal_path;
    const char *spp_map_path; /* one channel: per-pixel sample counts */
} mcp_dump_spec;

MCP_API mcp_dump_spec mcp_dump_spec_defaults(void);

typedef struct mcp_dump {
    mcp_image *color;       /* 3 channels R,G,B: the sample mean */
    mcp_image *var_of_mean; /* 3 channels R,G,B, or NULL when the file has none */
    mcp_image *cov_of_mean; /* 3 channels RG,RB,GB (off-diagonal), or NULL */
    mcp_image *albedo;      /* 3 channels R,G,B, or NULL */
    mcp_image *normal;      /* 3 channels X,Y,Z, or NULL */
    double spp;             /* scalar sample count; 0 when spp_map is used */
    mcp_image *spp_map;     /* 1 channel, or NULL */
    mcp_convention convention;
    mcp_variance_kind variance_in_file; /* how the file stored it */
    mcp_attrs attrs;                    /* the main file's header */
    char *source;                       /* the main file's path */
    long n_bad_values; /* NaN/Inf/negative-variance values replaced (policy zero) */
    /* What var_of_mean rests on. Files that mcpost wrote carry it in the header
     * (mcpost:varianceSource, mcpost:varianceDof, mcpost:replicates). */
    mcp_variance_source variance_source;
    double variance_dof;  /* degrees of freedom of each variance value before any
                             pooling: K - 1 for K replicates; 0 when unknown or large */
    int replicates;       /* K for MCP_VARSRC_REPLICATES / INCREMENTS (blocks), else 0 */
    double variance_pool; /* pixels pooled per value by mcp_dump_pool_variance, 0: none */
} mcp_dump;

/* Loads a dump by spec. Checks: colour present; every part the same size; sample
 * count present and > 0 wherever variance must be converted or is needed; no
 * NaN/Inf/negative variance (or replaced, per policy). */
MCP_API int mcp_dump_load(const mcp_dump_spec *spec, mcp_dump **out);

/* Shorthand: detect everything from one file. */
MCP_API int mcp_dump_read(const char *path, mcp_dump **out);

/* The bytes of one EXR or PFM file in memory (data[0 .. size)), read as
 * mcp_image_read_memory reads them; data NULL: not given. */
typedef struct mcp_dump_buffer {
    const void *data;
    size_t size;
} mcp_dump_buffer;

/* The files of a dump held in memory, one per part of mcp_dump_spec. */
typedef struct mcp_dump_buffers {
    mcp_dump_buffer main;     /* instead of spec->path */
    mcp_dump_buffer variance; /* instead of spec->variance_path */
    mcp_dump_buffer albedo;   /* instead of spec->albedo_path */
    mcp_dump_buffer normal;   /* instead of spec->normal_path */
    mcp_dump_buffer spp_map;  /* instead of spec->spp_map_path */
} mcp_dump_buffers;

/* Loads a dump as mcp_dump_load does, with any of its files in memory: a part whose
 * buffer has data is read from the buffer, and its path in spec, when set, only names
 * it (in messages, and as dump->source for the main part); without one it is named
 * "main (in memory)", "variance (in memory)", ... The parts without a buffer are read
 * from their paths as usual. spec may be NULL (defaults). The buffers are only read,
 * and may be freed once this returns. Gives exactly what mcp_dump_load gives on the
 * same bytes in files. */
MCP_API int mcp_dump_read_memory(const mcp_dump_spec *spec, const mcp_dump_buffers *parts,
                                 mcp_dump **out);

/* Builds a dump from an image already in memory (detection as for files). */
MCP_API int mcp_dump_from_image(const mcp_image *img, const mcp_dump_spec *spec,
                                mcp_dump **out);

MCP_API void mcp_dump_free(mcp_dump *dump);

/* Sample count at pixel (x, y). */
MCP_API double mcp_dump_spp_at(const mcp_dump *dump, int x, int y);

/* Writes the dump as one EXR in a convention (PBRT, MCPOST, MITSUBA or BLENDER), with
 * the variance stored as that convention stores it. opt may be NULL (float, ZIP). */
struct mcp_write_options;
MCP_API int mcp_dump_write(const mcp_dump *dump, const char *path, mcp_convention conv,
                           const struct mcp_write_options *opt);

/* Guesses the convention of an image's channels/attributes (never AUTO). */
MCP_API mcp_convention mcp_dump_detect(const mcp_image *img);

/* ---- series: a progressive render ---- */

typedef struct mcp_increment_options {
    double first_spp; /* members below this count are merged into the first block;
                         0: n / 64 of the member estimated [0] */
    int pool_radius;  /* 0: automatic (mcp_variance_pool_radius(dof, 100)), < 0: none
                         [0] */
} mcp_increment_options;

/* Where a series member's variance comes from (docs/variance-sources.md). */
typedef enum {
    /* The file's own, except that a member whose file holds a per-sample variance takes
     * the spread between the series' increments before it whenever Variance/n
     * overstates that spread (mcp_variance_ratio_off and > 1: a stratified sampler).
     * A member with fewer than two blocks keeps its own, and so does one whose
     * Variance/n is below the spread (correlated samples, or members that are not
     * checkpoints of one render). The default. */
    MCP_SERIES_VARIANCE_AUTO = 0,
    MCP_SERIES_VARIANCE_FILE,      /* the file's own, always */
    MCP_SERIES_VARIANCE_INCREMENTS /* the increments' (mcp_series_increment_variance),
                                      from the second block on */
} mcp_series_variance;

/* "auto", "file", "increments". */
MCP_API extern const mcp_wordlist mcp_series_variance_words;

/* Whether a ratio of Variance/n to the increments' spread (mcp_series_variance_ratio)
 * says Variance/n is off: outside [0.8, 1.25]. That band holds the independent
 * fixtures (0.99-1.04) and excludes the stratified ones (1.27-2.9); 0 (not measured)
 * is never off. */
MCP_API int mcp_variance_ratio_off(double ratio);

typedef struct mcp_series {
    int count;
    char **paths;       /* dump files, in increasing spp */
    double *spp;        /* their sample counts (0: read from the file) */
    mcp_dump_spec spec; /* applied to every member; .path and .spp are per member */
    /* Where mcp_series_load takes a member's variance from [auto] */
    mcp_series_variance variance_from;
    mcp_increment_options increments;
    /* private: the members' colours kept for the increments (series_colours.c); set
       paths and spec before reading any member */
    struct mcp__series_colours *colours;
} mcp_series;

/* A series from a printf-style pattern with one integer conversion (e.g.
 * "cornell_%04d.exr") and a list of spp values, or from an explicit list of paths
 * (spp from the files when spps is NULL). */
MCP_API int mcp_series_from_pattern(const char *pattern, const int *spps, int count,
                                    mcp_series **out);
MCP_API int mcp_series_from_paths(const char *const *paths, const double *spps, int count,
                                  mcp_series **out);
MCP_API int mcp_series_load(const mcp_series *s, int i, mcp_dump **out);
MCP_API void mcp_series_free(mcp_series *s);

/* ---- variance from replicates (replicates.c; docs "Variance sources") ---- */

typedef enum {
    MCP_MERGE_REPLICATES = 0, /* the parts are independent renders of the frame (other
                                 seeds): variance of the mean from their spread */
    MCP_MERGE_POOLED          /* the parts are passes of one render: their per-sample
                                 variances and means combined exactly (Chan et al.) */
} mcp_merge_variance;

MCP_API int mcp_merge_variance_from_name(const char *name, mcp_merge_variance *out);

typedef struct mcp_merge_options {
    mcp_merge_variance variance; /* [replicates] */
    int pool_radius;             /* > 0: mcp_dump_pool_variance with this radius [0] */
} mcp_merge_options;

MCP_API mcp_merge_options mcp_merge_defaults(void);

/* Combines count dumps of one frame into one. Per pixel and channel, with n_k the
 * part's sample count there (scalar or map) and N = Σ n_k:
 *   mean      X = Σ n_k X_k / N (albedo and normal the same way)
 *   replicates  var of mean = Σ n_k (X_k - X)² / ((K - 1) N), covariance alike;
 *             unbiased when Var X_k = σ²/n_k, with K - 1 degrees of freedom
 *   pooled    per-sample variance M2 / (N - 1), M2 = Σ (n_k - 1) s_k² + n_k (X_k - X)²,
 *             divided by N: what one render of all N samples would report
 * The result's spp is N (a map when any part has one), its source REPLICATES (dof
 * K - 1, replicates K) or the parts' own; its header is the first part's. Parts must
 * have one size; replicates need count >= 2, pooled needs every part's variance.
 * opt may be NULL. */
MCP_API int mcp_dump_merge(const mcp_dump *const *parts, int count,
                           const mcp_merge_options *opt, mcp_dump **out);

/* Pools a low-dof variance over a (2 radius + 1)² window (clipped at the borders), in
 * place: with shape (3 channels, e.g. the renderer's per-sample variance / n, whose
 * spatial pattern is right but whose level a stratified sampler biases) each value
 * becomes shape_i Σ_W V / Σ_W shape, a ratio estimate with about dof·|W| degrees of
 * freedom; without it (or where Σ_W shape is 0) the window mean of V. The covariance,
 * when present, becomes the window's pooled correlation Σ_W cov / sqrt(Σ_W V_a Σ_W V_b)
 * (within [-1, 1]) times the pooled standard deviations (without a shape: the window
 * mean). Sets
 * dump->variance_pool to the window's pixel count. */
MCP_API int mcp_dump_pool_variance(mcp_dump *dump, const mcp_image *shape, int radius);

/* The radius whose window gives a pooled variance at least min_dof degrees of freedom
 * from values of dof each (0 when dof alone is enough or unknown). */
MCP_API int mcp_variance_pool_radius(double dof, double min_dof);

MCP_API mcp_increment_options mcp_increment_defaults(void);

/* What the increments say about the variance of member i of a progressive series. The
 * samples between consecutive members are blocks (the first block: every sample up to
 * the first member >= first_spp) with means Y_b of sizes n_b; when the blocks behave
 * like independent renders (docs "Variance sources" measures where they do),
 * σ̂² = Σ n_b (Y_b - X)² / (B - 1) and the variance of the member's mean is σ̂² / n.
 * *out is member i with that variance (and covariance), pooled per opt; where the
 * member has its own per-sample variance, its pattern is the pooling's shape.
 * *ratio (may be NULL) receives Σ(the member's own variance) / Σ(the increments'),
 * over the image: how far the renderer's Variance/n overstates (> 1) or understates
 * the spread it shows; 0 when it has none. Needs B >= 2 blocks: fails otherwise.
 * opt may be NULL. */
MCP_API int mcp_series_increment_variance(const mcp_series *s, int i,
                                          const mcp_increment_options *opt,
                                          mcp_dump **out, double *ratio);

/* Σ(the last member's own variance) / Σ(the increments' spread before it) over the
 * image: how far the renderer's Variance/n overstates (> 1) or understates the variance
 * of the mean that the series itself shows (a stratified sampler overstates it). *ratio
 * is 0 where that cannot be measured (fewer than two blocks, no per-sample variance, or
 * no scalar sample counts); only a member that cannot be read fails. */
MCP_API int mcp_series_variance_ratio(const mcp_series *s, double *ratio);

/* The same from members already in memory: members[0..count) are the series up to
 * the member estimated, members[count - 1]. */
MCP_API int mcp_dump_increment_variance(const mcp_dump *const *members, int count,
                                        const mcp_increment_options *opt, mcp_dump **out,
                                        double *ratio);

#ifdef __cplusplus
}
#endif
#endif
