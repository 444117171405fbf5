/* denoiser.h: the denoiser interface -- F(colour, albedo?, normal?) and its
 * Jacobian-vector products J·t, several tangents at once (docs/mathematics.md §2.1).
 *
 * Built-in denoisers compute J·t exactly by forward-mode differentiation (a tangent is
 * propagated through every operation). A black box (an external command, issue 6)
 * gives (F(x + δt) − F(x)) / δ and says so with exact = 0. A neural network fits the
 * same struct. Denoisers are created by name from a settings map, so the CLI
 * (`--denoiser NAME --denoiser-opt key=value`) and job files
 * (`denoiser: {name: NAME, key: value}`) share one path. */
#ifndef MCP_DENOISER_H
#define MCP_DENOISER_H

#include <mcpost/dump.h>
#include <mcpost/yaml.h>
#include <mcpost/options.h>

#ifdef __cplusplus
extern "C" {
#endif

/* What a denoiser reads: colour (3 channels), optional albedo, normal and colour
 * variance (3 each), all the same size. Zero-initialise it so that fields added later
 * stay NULL. */
typedef struct mcp_denoise_input {
    const mcp_image *color;
    const mcp_image *albedo; /* NULL: not given */
    const mcp_image *normal; /* NULL: not given */
    /* Variance of the colour mean, R,G,B (NULL: not given). Denoisers that weigh
     * colour differences by the noise level read it (nlm); it is a constant of F, not
     * an input that tangents move. */
    const mcp_image *variance;
} mcp_denoise_input;

/* A direction in input space. The colour part is required; feature parts may be NULL
 * (zero), and are used by joint SURE (Li 2017) when features are noisy. */
typedef struct mcp_denoise_tangent {
    const mcp_image *color;
    const mcp_image *albedo;
    const mcp_image *normal;
} mcp_denoise_tangent;

typedef struct mcp_denoiser mcp_denoiser;

struct mcp_denoiser {
    const char *name; /* "gauss", "bilateral", "unet", "external", ... */
    int exact;        /* 1: jvp is exact forward mode; 0: finite differences */
    int uses_albedo;  /* reads in->albedo when given */
    int uses_normal;  /* reads in->normal when given */
    /* Var[F] changes pixel by pixel (single-pixel colour weights: bilateral, nlm with
     * patch_radius 0): the estimate's automatic s² pooling stays off for it where the
     * variance has many degrees of freedom (docs/fidelity.md) */
    int sharp_variance;
    /* the estimate's automatic probe count (0: MCP_ESTIMATE_PROBES): each probe is one
     * more tangent, and a denoiser whose tangents cost nearly an apply picks fewer where
     * they agree as often (the U-Net: docs/fidelity.md "The defaults") */
    int estimate_probes;
    /* the estimate's automatic probe floor (probe_floor.c): the radius over whose
     * median the probes' variance is raised, for a denoiser that adapts to the noise
     * it sees (the U-Net: 1; docs/fidelity.md "The defaults"); 0: none */
    int estimate_probe_floor;
    /* how many rows above and below a pixel F and J read (its reach): a band of rows
       evaluated with this many rows around it gives the band's rows as the whole image
       does, so a large estimate goes in bands (estimate_bands.c); 0: unknown or
       unbounded, the estimate evaluates the image whole */
    int band_halo;
    /* F(in): a new 3-channel image "R,G,B". */
    int (*apply)(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out);
    /* J·t_k for k < n at the point `at`, in one primal pass: out[k] receives a new
     * 3-channel image; primal (may be NULL) receives F(at). On failure every out[k]
     * and *primal stay NULL. */
    int (*jvp)(const mcp_denoiser *self, const mcp_denoise_input *at,
               const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out);
    void (*destroy)(mcp_denoiser *self); /* frees state and self */
    /* A denoiser that hands each input to another (the `default` one) names the one
     * that runs on `in`, whose estimate_probes, estimate_probe_floor and sharp_variance
     * then apply; NULL for a denoiser that runs itself. */
    const mcp_denoiser *(*pick)(const mcp_denoiser *self, const mcp_denoise_input *in);
    void *state;
};

/* Creates a denoiser from a settings node: a scalar (its name) or a map with `name`
 * and that denoiser's own keys; unknown keys fail with the node's line. Relative paths
 * in settings (e.g. weights) resolve against base_dir (NULL: current folder). */
MCP_API int mcp_denoiser_create(const mcp_node *settings, const char *base_dir,
                                mcp_denoiser **out);

/* The same from command-line words: name and "key=value" options. `default` with
 * options is the U-Net with them (the options are the U-Net's). */
MCP_API int mcp_denoiser_create_from_args(const char *name, const char *const *opts,
                                          int n_opts, mcp_denoiser **out);

MCP_API void mcp_denoiser_free(mcp_denoiser *d);

/* The denoiser input of a dump: borrowed pointers to its colour, albedo, normal and
 * var_of_mean (each NULL where the dump has none). */
MCP_API mcp_denoise_input mcp_denoise_input_of(const mcp_dump *dump);

/* One entry per built-in kind, found by name (estimate/denoisers.c holds the table). */
typedef struct mcp_denoiser_kind {
    const char *name;
    const char *summary;
    const char *const *keys; /* settings keys besides `name`, NULL-terminated */
    int (*create)(const mcp_node *settings, const char *base_dir, mcp_denoiser **out);
    /* Its settings' table (<mcpost/options.h>: names, types, ranges, defaults, docs),
     * which create reads them through and keys come from; NULL: none (create reads
     * its keys itself) */
    const mcp_operation *options;
} mcp_denoiser_kind;

/* The table of kinds (NULL-terminated), for --help and `mcpost denoise --list`. */
MCP_API const mcp_denoiser_kind *const *mcp_denoiser_kinds(void);

#ifdef __cplusplus
}
#endif
#endif
