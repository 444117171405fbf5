/* denoise_unet.c: the `unet` denoiser -- OIDN's RT U-Net (unet.c) with weights from a
 * .tza file, and its exact forward-mode Jacobian-vector product through the same
 * network, several tangents batched with one primal pass (issue 6; Firmino et al. 2023
 * did this in PyTorch).
 *
 * Settings: weights (path to a .tza; default $MCPOST_OIDN_WEIGHTS), input_scale (auto
 * [default]: OIDN's autoexposure on the colour, or a number: the scale that maps the
 * colour to 1 = 100 cd/m^2), tile (0 [default]: the whole image where it fits in the
 * memory available, else the largest tiles that fit; or a multiple of 16: tiles of that
 * size; tiles give the same bits as the whole image), fixed_bits (false [default]:
 * Winograd convolutions; true: the direct loops, the same bits on every x86-64, as
 * MCPOST_UNET_FIXED=1 does for a whole process; the Winograd convolutions are F(4x4,
 * 3x3), unet_winograd4.c), exact_tangents (false [default]: the tangents'
 * convolutions as the primal's, JVP within 2e-6 of the double reference; true:
 * F(2x2, 3x3), 1.78 times more multiply-adds, 1e-6). The primal runs first and each
 * tangent after it alone (unet.c, the primal's trace). The autoexposure scale is computed
 * on the primal colour and held constant in the JVP (unet_internal.h). Weights for colour
 * + albedo + normal need both features; colour + albedo weights need the albedo.
 *
 * Loaded weights are shared within the process (shared_load below): reading and
 * checking a .tza costs more than everything else a job's check does, and a job
 * creates each stage's denoiser twice (to check it, then to run it), a Python
 * session once per call. */
#define _POSIX_C_SOURCE 200809L /* struct stat's st_mtim */
#include <mcpost/denoiser.h>

#include "internal.h"
#include "unet_internal.h"

#include <math.h>
#include <stddef.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define WEIGHTS_ENV "MCPOST_OIDN_WEIGHTS"
/* The weights mcpost ships (weights/, installed to share/mcpost/). */
#define SHIPPED_WEIGHTS "rt_hdr_alb_nrm.tza"

typedef struct {
    mcp__unet net;      /* borrows the shared network's tensors; own fixed_bits */
    mcp__unet *shared;  /* what shared_load gave, for shared_release */
    double input_scale; /* <= 0: autoexposure */
    int tile;           /* 0: as memory allows */
} unet_state;

/* ---- weights shared within the process ----
 * A network, once loaded, is never written again, so denoisers can share it. Each
 * file loaded stays in one of SHARED_SLOTS slots, keyed by what stat says of it
 * (device, inode, size, modification time): a file rewritten since is a new key and
 * is read again, and a slot no denoiser uses is reused for the next file. When every
 * slot is in use the network is the denoiser's own. */
#define SHARED_SLOTS 4

typedef struct {
    dev_t dev;
    ino_t ino;
    off_t size;
    struct timespec mtime;
    mcp__unet *net; /* NULL: a free slot */
    int users;
} shared_slot;

static shared_slot shared[SHARED_SLOTS];
static pthread_mutex_t shared_lock = PTHREAD_MUTEX_INITIALIZER;

static int
same_file(const shared_slot *s, const struct stat *st)
{
    return s->net && s->dev == st->st_dev && s->ino == st->st_ino &&
           s->size == st->st_size && s->mtime.tv_sec == st->st_mtim.tv_sec &&
           s->mtime.tv_nsec == st->st_mtim.tv_nsec;
}

/* mcp__unet_load through the slots; release with shared_release. */
static int
shared_load(const char *path, mcp__unet **out)
{
    struct stat st;
    if (stat(path, &st) != 0) /* let the loader say why */
        return mcp__unet_load(path, out);
    pthread_mutex_lock(&shared_lock);
    for (int i = 0; i < SHARED_SLOTS; i++)
        if (same_file(&shared[i], &st)) {
            shared[i].users++;
            *out = shared[i].net;
            pthread_mutex_unlock(&shared_lock);
            return 0;
        }
    pthread_mutex_unlock(&shared_lock);
    if (mcp__unet_load(path, out)) /* outside the lock: it is the slow part */
        return -1;
    pthread_mutex_lock(&shared_lock);
    shared_slot *slot = NULL;
    for (int i = 0; i < SHARED_SLOTS && !slot; i++)
        if (!shared[i].net) slot = &shared[i];
    for (int i = 0; i < SHARED_SLOTS && !slot; i++)
        if (!shared[i].users) {
            mcp__unet_free(shared[i].net);
            slot = &shared[i];
        }
    if (slot)
        *slot = (shared_slot){st.st_dev, st.st_ino, st.st_size, st.st_mtim, *out, 1};
    pthread_mutex_unlock(&shared_lock);
    return 0;
}

static void
shared_release(mcp__unet *net)
{
    pthread_mutex_lock(&shared_lock);
    int kept = 0;
    for (int i = 0; i < SHARED_SLOTS && !kept; i++)
        if (shared[i].net == net) {
            shared[i].users--;
            kept = 1;
        }
    pthread_mutex_unlock(&shared_lock);
    if (!kept) mcp__unet_free(net);
}

/* ---- settings: the table (<mcpost/options.h>; docs/denoisers.md) ---- */

typedef struct {
    const char *weights; /* a .tza; NULL: $MCPOST_OIDN_WEIGHTS, else the shipped ones */
    double input_scale;  /* 0: auto (OIDN's autoexposure) */
    int tile;            /* 0: as memory allows; else a multiple of 16 */
    int fixed_bits;
    int exact_tangents;
    int max_memory_mb; /* 0: the default */
} unet_settings;

static const mcp_option unet_options[] = {
    {.name = "weights",
     .type = MCP_OPT_TEXT,
     .offset = offsetof(unet_settings, weights),
     .meta = "PATH",
     .doc = "the .tza file (relative paths: to the job file's folder); --weights "
            "[$" WEIGHTS_ENV ", else the shipped share/mcpost/rt_hdr_alb_nrm.tza]"},
    {.name = "input_scale",
     .type = MCP_OPT_NUMBER,
     .offset = offsetof(unet_settings, input_scale),
     .def = "auto",
     .doc = "auto: OIDN's autoexposure; or the number that maps the colour to 1 = 100 "
            "cd/m^2; --input-scale",
     .bounds = MCP_OPT_LO_OPEN,
     .auto_word = "auto",
     .auto_value = 0},
    {.name = "tile",
     .type = MCP_OPT_INT,
     .offset = offsetof(unet_settings, tile),
     .def = "0",
     .doc = "0: the whole image when it fits in the memory available, else the largest "
            "tiles that fit; or a multiple of 16: tiles of that size"},
    {.name = "fixed_bits",
     .type = MCP_OPT_FLAG,
     .offset = offsetof(unet_settings, fixed_bits),
     .def = "false",
     .doc = "true: the direct-loop convolutions, the same bits on every x86-64 "
            "(MCPOST_UNET_FIXED=1 does it for the whole process); false: Winograd, 2-3x "
            "faster"},
    {.name = "exact_tangents",
     .type = MCP_OPT_FLAG,
     .offset = offsetof(unet_settings, exact_tangents),
     .def = "false",
     .doc = "true: the JVP's convolutions as Winograd F(2x2, 3x3), in float; false: as "
            "the primal's, Winograd F(4x4, 3x3), 1.78x fewer multiply-adds, in bfloat16 "
            "where the CPU has it (JVP within 2.3e-6 of the double reference in float "
            "against 1.0e-6; MCPOST_UNET_EXACT_TANGENTS=1 for a process)"},
    {.name = "max_memory_mb",
     .type = MCP_OPT_INT,
     .offset = offsetof(unet_settings, max_memory_mb),
     .def = "0",
     .meta = "MB",
     .doc =
         "the network's working memory at most: beyond it the image runs in tiles with "
         "the same bits (mcpost denoise: the whole process's, reading and writing a dump "
         "too large for it in bands of rows); 0: $MCPOST_UNET_MAX_MEMORY_MB, else 2048",
     .lo = 0,
     .bounds = MCP_OPT_LO},
    {0}};

const mcp_operation mcp__op_unet = {
    .name = "unet",
    .denoiser = 1,
    .summary = "OIDN's RT U-Net with .tza weights, exact JVP",
    .options = unet_options,
    .size = sizeof(unet_settings),
};

/* The keys, from the table (denoisers.c fills them in before the kinds are handed
 * out). */
const char *mcp__unet_keys[MCP__DENOISER_KEYS_MAX];

static int
unet_jvp(const mcp_denoiser *self, const mcp_denoise_input *at,
         const mcp_denoise_tangent *t, int n, mcp_image **primal, mcp_image **out)
{
    const unet_state *s = self->state;
    if (primal) *primal = NULL;
    for (int k = 0; k < n && out; k++)
        out[k] = NULL;
    /* the features these weights need, and the tangents, mcp__unet_run checks */
    if (mcp__denoise_check_input("unet", at)) return -1;
    if (n > 0 && !out) return mcp_error("unet: no room for %d tangent outputs", n);
    return mcp__unet_run_tiled(&s->net, at->color, at->albedo, at->normal, s->input_scale,
                               t, n, s->tile, primal, out);
}

static int
unet_apply(const mcp_denoiser *self, const mcp_denoise_input *in, mcp_image **out)
{
    *out = NULL;
    return unet_jvp(self, in, NULL, 0, out, NULL);
}

static void
unet_destroy(mcp_denoiser *self)
{
    unet_state *s = self->state;
    shared_release(s->shared);
    free(self);
}

static int
unet_create(const mcp_node *settings, const char *base_dir, mcp_denoiser **out)
{
    *out = NULL;
    unet_settings u;
    if (mcp__options_from_node(&mcp__op_unet, settings, NULL, &u)) return -1;
    const char *weights = u.weights;
    double scale = u.input_scale;
    int tile = u.tile, fixed_bits = u.fixed_bits;
    int exact_tangents = u.exact_tangents, max_memory_mb = u.max_memory_mb;
    if (tile < 0 || tile % 16)
        return mcp_node_error(
            mcp_node_get(settings, "tile"),
            "unet: tile must be 0 (as memory allows) or a multiple of 16 "
            "(got %d)",
            tile);
    char shipped[4096];
    if (!weights || !*weights) weights = getenv(WEIGHTS_ENV);
    if ((!weights || !*weights) &&
        mcp__find_data_file(SHIPPED_WEIGHTS, shipped, sizeof shipped) == 0)
        weights = shipped; /* OIDN 1.4's, shipped with mcpost (weights/README.md) */
    if (!weights || !*weights)
        return mcp_node_error(
            settings,
            "unet: no weights: give weights: PATH (--weights PATH), set " WEIGHTS_ENV
            " to an OIDN .tza file, or install mcpost's "
            "share/mcpost/" SHIPPED_WEIGHTS);
    char path[PATH_CAP];
    if (weights[0] != '/' && base_dir && *base_dir)
        snprintf(path, sizeof path, "%s/%s", base_dir, weights);
    else
        snprintf(path, sizeof path, "%s", weights);
    mcp__unet *net = NULL;
    if (shared_load(path, &net)) {
        const mcp_node *w = mcp_node_get(settings, "weights");
        return w ? mcp_error_prefix("%s:%d: ", w->file, w->line) : -1;
    }
    mcp_denoiser *d = mcp__denoiser_new("unet", sizeof(unet_state));
    if (!d) {
        shared_release(net);
        return -1;
    }
    unet_state *s = d->state;
    s->shared = net;
    s->net = *net;
    s->net.fixed_bits = fixed_bits;
    s->net.exact_tangents = exact_tangents;
    s->net.max_memory_mb = max_memory_mb;
    s->input_scale = scale;
    s->tile = tile;
    d->destroy = unet_destroy;
    d->uses_albedo = net->ic >= 6;
    d->uses_normal = net->ic >= 9;
    /* three probes agree with the truth as often as four with this network, a tangent
       costing 0.6-0.7 of an apply (docs/fidelity.md "The defaults") */
    d->estimate_probes = 3;
    d->estimate_probe_floor = 1;
    d->apply = unet_apply;
    d->jvp = unet_jvp;
    *out = d;
    return 0;
}

const mcp_denoiser_kind mcp__denoiser_unet = {
    "unet",
    "OIDN's RT U-Net with .tza weights (1.4 float32 or 2.x float16, base or small), "
    "exact JVP (weights [$" WEIGHTS_ENV "], input_scale [auto] or a number, tile [0: as "
    "memory allows] or a multiple of 16, fixed_bits [false]: the direct loops, the same "
    "bits on every x86-64, exact_tangents [false]: the JVP's convolutions on Winograd "
    "F(2x2,3x3) in float instead of the primal's F(4x4,3x3), max_memory_mb [2048]: the "
    "network's working memory at most, in tiles beyond)",
    mcp__unet_keys,
    unet_create,
    &mcp__op_unet,
};

const mcp__unet *
mcp__unet_of(const mcp_denoiser *d, double *input_scale, int *tile)
{
    if (!d || d->destroy != unet_destroy) return NULL;
    const unet_state *s = d->state;
    *input_scale = s->input_scale;
    *tile = s->tile;
    return &s->net;
}
