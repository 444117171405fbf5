/* imageio.c: format dispatch, the lazily loaded OpenImageIO plug-in, sRGB coding,
 * and atomic output files (see imageio.h). */
#define _GNU_SOURCE /* dladdr */
#include "oiio_internal.h"
#include "internal.h"
#include "../core/internal.h"

#include <dlfcn.h>
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* ---- formats ---- */

static const struct {
    const char *ext;
    mcp_format format;
} extensions[] = {
    {"exr", MCP_FORMAT_EXR},  {"pfm", MCP_FORMAT_PFM},   {"png", MCP_FORMAT_PNG},
    {"jpg", MCP_FORMAT_JPEG}, {"jpeg", MCP_FORMAT_JPEG}, {"hdr", MCP_FORMAT_HDR},
    {"tif", MCP_FORMAT_TIFF}, {"tiff", MCP_FORMAT_TIFF},
};

mcp_format
mcp_format_from_path(const char *path)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    if (!dot || (slash && dot < slash)) return MCP_FORMAT_UNKNOWN;
    for (size_t i = 0; i < sizeof extensions / sizeof *extensions; i++)
        if (strcasecmp(dot + 1, extensions[i].ext) == 0) return extensions[i].format;
    return MCP_FORMAT_UNKNOWN;
}

const char *
mcp_format_name(mcp_format format)
{
    static const char *names[] = {"unknown", "exr", "pfm", "png", "jpeg", "hdr", "tiff"};
    return (unsigned)format < sizeof names / sizeof *names ? names[format] : "unknown";
}

mcp_read_options
mcp_read_defaults(void)
{
    return (mcp_read_options){.srgb_decode = 1};
}

mcp_write_options
mcp_write_defaults(void)
{
    return (mcp_write_options){.exr_pixel = MCP_EXR_FLOAT,
                               .compression = MCP_EXR_ZIP,
                               .exr_tiled = 0,
                               .exr_tile_size = 64,
                               .srgb_encode = 1};
}

static const char *const exr_compression_names[] = {
    "none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a", "dwaa", "dwab"};
const mcp_wordlist mcp_exr_compression_words = {"EXR compression", exr_compression_names,
                                                10};

static const char *const exr_pixel_names[] = {"float", "half"};
const mcp_wordlist mcp_exr_pixel_words = {"pixel type", exr_pixel_names, 2};

int
mcp_exr_compression_from_name(const char *name, mcp_exr_compression *out)
{
    return mcp_wordlist_find(&mcp_exr_compression_words, name, (int *)out);
}

float
mcp_srgb_to_linear(float c)
{
    return c <= 0.04045f ? c / 12.92f : powf((c + 0.055f) / 1.055f, 2.4f);
}

float
mcp_linear_to_srgb(float l)
{
    return l <= 0.0031308f ? 12.92f * l : 1.055f * powf(l, 1.0f / 2.4f) - 0.055f;
}

/* ---- the OpenImageIO plug-in ---- */

static struct {
    pthread_once_t once;
    void *handle;
    mcp__oiio_read_fn read;
    mcp__oiio_write_fn write;
    char error[1024];
} oiio = {PTHREAD_ONCE_INIT, NULL, NULL, NULL, ""};

/* Loads the plug-in (mcp__plugin_open says where from) and its two functions. */
static void
oiio_load(void)
{
    void *h = mcp__plugin_open("mcpost_oiio.so", oiio.error, sizeof oiio.error);
    if (!h) return;
    oiio.read = (mcp__oiio_read_fn)(uintptr_t)dlsym(h, MCP__OIIO_READ);
    oiio.write = (mcp__oiio_write_fn)(uintptr_t)dlsym(h, MCP__OIIO_WRITE);
    if (oiio.read && oiio.write) {
        oiio.handle = h;
        return;
    }
    snprintf(oiio.error, sizeof oiio.error, "mcpost_oiio.so lacks its functions");
    dlclose(h);
}

static int
oiio_ready(const char *path)
{
    pthread_once(&oiio.once, oiio_load);
    if (!oiio.handle)
        return mcp_error("%s: this format needs the OpenImageIO plug-in: %s", path,
                         oiio.error);
    return 0;
}

int
mcp_oiio_loaded(void)
{
    return oiio.handle != NULL;
}

static int
oiio_read(const char *path, const mcp_read_options *opt, mcp_image **out)
{
    int w, h, c, bits;
    float *data = NULL;
    char **names = NULL, err[1024] = "";
    if (oiio_ready(path)) return -1;
    if (oiio.read(path, &w, &h, &c, &data, &names, &bits, err, sizeof err))
        return mcp_error("%s", err);
    mcp_image *img = NULL;
    int rc = -1;
    if (w > MCP_MAX_DIM || h > MCP_MAX_DIM)
        mcp_error("%s: image too large (%dx%d)", path, w, h);
    else if (!mcp_image_new(w, h, c, (const char *const *)names, &img) &&
             !mcp_image_set_source(img, path)) {
        memcpy(img->data, data, (size_t)w * h * c * sizeof(float));
        /* integer files hold sRGB-encoded values; alpha stays linear */
        if (bits && opt->srgb_decode)
            for (size_t i = 0; i < (size_t)w * h; i++)
                for (int k = 0; k < c; k++)
                    if (strcmp(img->names[k], "A") != 0)
                        img->data[i * c + k] = mcp_srgb_to_linear(img->data[i * c + k]);
        /* a TIFF may name its channels in any order: colour first, as every reader
           gives it (docs/conventions.md, "Channel order") */
        if (!mcp_image_colour_first(img)) {
            *out = img;
            img = NULL;
            rc = 0;
        }
    }
    for (int k = 0; k < c; k++)
        free(names[k]);
    free(names);
    free(data);
    mcp_image_free(img);
    return rc;
}

static int
oiio_write(const mcp_image *img, const char *path, mcp_format format,
           const mcp_write_options *opt)
{
    int c = img->channels;
    int ldr = format == MCP_FORMAT_PNG || format == MCP_FORMAT_JPEG;
    if (ldr && c != 1 && c != 3 && c != 4)
        return mcp_error("%s: %s takes 1, 3 or 4 channels, not %d (pick channels first)",
                         path, mcp_format_name(format), c);
    if (format == MCP_FORMAT_HDR && c != 3)
        return mcp_error("%s: hdr takes 3 channels, not %d", path, c);
    if (oiio_ready(path)) return -1;
    size_t n = (size_t)img->width * img->height * c;
    float *buf = mcp_malloc(n * sizeof(float));
    if (!buf) return -1;
    for (int y = 0; y < img->height; y++)
        for (int x = 0; x < img->width; x++)
            for (int k = 0; k < c; k++) {
                float v = mcp_image_px(img, x, y)[k];
                if (ldr && opt->srgb_encode && !(c == 4 && k == 3))
                    v = mcp_linear_to_srgb(v < 0 ? 0 : v > 1 ? 1 : v);
                buf[((size_t)y * img->width + x) * c + k] = v;
            }
    char err[1024] = "";
    int rc =
        oiio.write(path, img->width, img->height, c, buf, ldr ? 8 : 0, err, sizeof err);
    free(buf);
    return rc ? mcp_error("%s", err) : 0;
}

/* ---- atomic output files ---- */

/* Temporary files in flight, removed if the process is interrupted. Only async-signal-
 * safe calls (unlink, signal, raise) run in the handler. */
#define MAX_IN_FLIGHT 32
static char *volatile in_flight[MAX_IN_FLIGHT];
static pthread_mutex_t in_flight_lock = PTHREAD_MUTEX_INITIALIZER;
/* then the output folder in flight (outdir.c) */
static void (*volatile cleanup_hook)(void);

static void
on_fatal_signal(int sig)
{
    for (int i = 0; i < MAX_IN_FLIGHT; i++)
        if (in_flight[i]) unlink(in_flight[i]);
    if (cleanup_hook) cleanup_hook();
    signal(sig, SIG_DFL);
    raise(sig);
}

static void
install_handlers(void)
{
    int sigs[] = {SIGINT, SIGTERM, SIGHUP};
    for (size_t i = 0; i < sizeof sigs / sizeof *sigs; i++) {
        struct sigaction sa, old;
        memset(&sa, 0, sizeof sa);
        sa.sa_handler = on_fatal_signal;
        /* leave handlers that the embedding program installed alone */
        if (sigaction(sigs[i], NULL, &old) == 0 && old.sa_handler == SIG_DFL)
            sigaction(sigs[i], &sa, NULL);
    }
}

static void
install_signal_cleanup(void)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, install_handlers);
}

void
mcp__signal_cleanup_hook(void (*hook)(void))
{
    cleanup_hook = hook;
    install_signal_cleanup();
}

static void
track(char *tmp, int add)
{
    pthread_mutex_lock(&in_flight_lock);
    for (int i = 0; i < MAX_IN_FLIGHT; i++)
        if (add ? !in_flight[i] : in_flight[i] == tmp) {
            in_flight[i] = add ? tmp : NULL;
            break;
        }
    pthread_mutex_unlock(&in_flight_lock);
}

int
mcp_atomic_begin(mcp_atomic_file *f, const char *path)
{
    static _Atomic unsigned counter;
    memset(f, 0, sizeof *f);
    /* keep the extension last: format libraries choose the format from it */
    const char *slash = strrchr(path, '/'), *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash)) dot = path + strlen(path);
    size_t n = strlen(path) + 64;
    f->final_path = mcp_strdup(path);
    f->tmp_path = mcp_malloc(n);
    if (!f->final_path || !f->tmp_path) {
        mcp_atomic_abort(f);
        return -1;
    }
    snprintf(f->tmp_path, n, "%.*s.tmp-%d-%u%s", (int)(dot - path), path, (int)getpid(),
             counter++, dot);
    FILE *probe = fopen(f->tmp_path, "wb");
    if (!probe) {
        int e = errno;
        mcp_atomic_abort(f);
        return mcp_error("%s: cannot write: %s", path, strerror(e));
    }
    fclose(probe);
    install_signal_cleanup();
    track(f->tmp_path, 1);
    return 0;
}

int
mcp_atomic_commit(mcp_atomic_file *f)
{
    if (rename(f->tmp_path, f->final_path) != 0) {
        int e = errno;
        mcp_error("%s: cannot rename the finished file into place: %s", f->final_path,
                  strerror(e));
        mcp_atomic_abort(f);
        return -1;
    }
    track(f->tmp_path, 0);
    free(f->tmp_path);
    free(f->final_path);
    memset(f, 0, sizeof *f);
    return 0;
}

void
mcp_atomic_abort(mcp_atomic_file *f)
{
    if (f->tmp_path) {
        unlink(f->tmp_path);
        track(f->tmp_path, 0);
    }
    free(f->tmp_path);
    free(f->final_path);
    memset(f, 0, sizeof *f);
}

int
mcp_make_dirs(const char *path)
{
    char buf[4096];
    size_t n = strlen(path);
    if (n == 0) return mcp_error("no folder name given");
    if (n >= sizeof buf) return mcp_error("path too long: %s", path);
    memcpy(buf, path, n + 1);
    for (size_t i = 1; i <= n; i++)
        if (buf[i] == '/' || buf[i] == '\0') {
            char c = buf[i];
            buf[i] = '\0';
            if (mkdir(buf, 0777) != 0 && errno != EEXIST)
                return mcp_error("%s: cannot create folder: %s", buf, strerror(errno));
            buf[i] = c;
        }
    return 0;
}

int
mcp_write_file_atomic(const char *path, const void *data, size_t size)
{
    mcp_atomic_file af;
    if (mcp_atomic_begin(&af, path)) return -1;
    FILE *f = fopen(af.tmp_path, "wb");
    int ok = f && fwrite(data, 1, size, f) == size;
    if (f && fclose(f) != 0) ok = 0;
    if (!ok) {
        mcp_atomic_abort(&af);
        return mcp_error("%s: write failed (disk full?)", path);
    }
    return mcp_atomic_commit(&af);
}

/* ---- public read/write ---- */

int
mcp__check_readable(const char *path)
{
    struct stat st;
    if (stat(path, &st) != 0)
        return mcp_error("%s: cannot open: %s", path, strerror(errno));
    if (S_ISDIR(st.st_mode)) return mcp_error("%s: is a directory, not an image", path);
    return 0;
}

int
mcp_image_read(const char *path, const mcp_read_options *opt, mcp_image **out)
{
    mcp_read_options defaults = mcp_read_defaults();
    *out = NULL;
    if (!opt) opt = &defaults;
    if (mcp__check_readable(path)) return -1;
    switch (mcp_format_from_path(path)) {
    case MCP_FORMAT_EXR:
        return mcp__exr_read(path, out);
    case MCP_FORMAT_PFM:
        return mcp__pfm_read(path, out);
    case MCP_FORMAT_PNG:
        return mcp__png_read(path, opt, out);
    case MCP_FORMAT_UNKNOWN: {
        /* no known extension: sniff the EXR and PNG magic numbers before trying OIIO */
        unsigned char magic[8] = {0};
        static const unsigned char png[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
        FILE *f = fopen(path, "rb");
        if (f) {
            size_t got = fread(magic, 1, 8, f);
            fclose(f);
            if (mcp__exr_magic(magic, got)) return mcp__exr_read(path, out);
            if (got == 8 && memcmp(magic, png, 8) == 0)
                return mcp__png_read(path, opt, out);
        }
        return oiio_read(path, opt, out);
    }
    default:
        return oiio_read(path, opt, out);
    }
}

void
mcp__name_output_in_error(const char *tmp_path, const char *path)
{
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", mcp_error_message());
    char *at = strstr(msg, tmp_path);
    if (at) mcp_error("%.*s%s%s", (int)(at - msg), msg, path, at + strlen(tmp_path));
}

int
mcp_image_read_memory(const void *data, size_t size, const char *name, mcp_image **out)
{
    const unsigned char *b = data;
    *out = NULL;
    if (!name) name = "(memory)";
    if (!data && size) return mcp_error("%s: no data (%zu bytes at NULL)", name, size);
    if (mcp__exr_magic(data, size)) return mcp__exr_read_memory(data, size, name, out);
    if (size >= 2 && b[0] == 'P' && (b[1] == 'F' || b[1] == 'f'))
        return mcp__pfm_read_memory(data, size, name, out);
    /* OpenImageIO's plug-in reads only files: other formats go through a file */
    return mcp_error("%s: not an EXR or PFM image (%zu bytes); only those two are read "
                     "from memory",
                     name, size);
}

int
mcp_image_write(const mcp_image *img, const char *path, const mcp_write_options *opt)
{
    mcp_write_options defaults = mcp_write_defaults();
    if (!opt) opt = &defaults;
    mcp_format format = mcp_format_from_path(path);
    if (format == MCP_FORMAT_UNKNOWN)
        return mcp_error("%s: unknown output format (use .exr, .pfm, .png, .jpg, .hdr or "
                         ".tif)",
                         path);
    /* Formats without channel names store colour by place: R, G, B go first, taken by
       name wherever they stand, the other channels (alpha) after them in their order
       (docs/conventions.md, "Channel order"). EXR keeps the names: the image as it is. */
    mcp_image *ordered = NULL;
    if (format != MCP_FORMAT_EXR) {
        int *order = mcp_calloc((size_t)img->channels, sizeof *order);
        int moved = order ? mcp_image_colour_order(img, order) : -1;
        if (moved > 0 && !mcp_image_copy_channels(img, order, img->channels, &ordered))
            img = ordered;
        free(order);
        if (moved < 0 || (moved > 0 && !ordered)) return -1;
    }
    mcp_atomic_file af;
    if (mcp_atomic_begin(&af, path)) {
        mcp_image_free(ordered);
        return -1;
    }
    int rc;
    switch (format) {
    case MCP_FORMAT_EXR:
        rc = mcp__exr_write(img, af.tmp_path, opt);
        break;
    case MCP_FORMAT_PFM:
        rc = mcp__pfm_write(img, af.tmp_path);
        break;
    case MCP_FORMAT_PNG:
        rc = mcp__png_write(img, af.tmp_path, opt);
        break;
    default:
        rc = oiio_write(img, af.tmp_path, format, opt);
        break;
    }
    mcp_image_free(ordered);
    if (rc) {
        mcp__name_output_in_error(af.tmp_path, path);
        mcp_atomic_abort(&af);
        return -1;
    }
    return mcp_atomic_commit(&af);
}

int
mcp_write_rgb8(const unsigned char *rgb8, int width, int height, const char *path)
{
    if (mcp_format_from_path(path) == MCP_FORMAT_PNG) { /* the bytes as they are */
        mcp_atomic_file af;
        if (mcp_atomic_begin(&af, path)) return -1;
        if (mcp__png_write_bytes(rgb8, width, height, 3, af.tmp_path)) {
            mcp__name_output_in_error(af.tmp_path, path);
            mcp_atomic_abort(&af);
            return -1;
        }
        return mcp_atomic_commit(&af);
    }
    mcp_image *img;
    if (mcp_image_new(width, height, 3, (const char *[]){"R", "G", "B"}, &img)) return -1;
    for (size_t i = 0; i < (size_t)width * height * 3; i++)
        img->data[i] = rgb8[i] / 255.0f;
    mcp_write_options opt = mcp_write_defaults();
    opt.srgb_encode = 0; /* already display-encoded bytes */
    int rc = mcp_image_write(img, path, &opt);
    mcp_image_free(img);
    return rc;
}

int
mcp_write_files(const mcp_file_write *files, int n)
{
    if (n <= 0) return 0;
    /* a failed file's error line, kept from its worker thread (error lines are
       thread-local; error.c's are 1024 bytes too) */
    char(*message)[1024] = mcp_calloc((size_t)n, sizeof *message);
    if (!message) return -1;
    int failed = 0, written = 0;
    /* a bar on a terminal, a step per file, when the files hold a megapixel each (an
       estimate's 13 files of 4K take 5 to 8 s); the thread that owns it draws it */
    const mcp_file_write *first = &files[0];
    int w0 = first->image ? first->image->width : first->width,
        h0 = first->image ? first->image->height : first->height;
    mcp_progress bar;
    int shown = (double)w0 * h0 >= 1048576.0 && n > 1 && !mcp_progress_quiet();
    if (shown) {
        char label[96];
        snprintf(label, sizeof label, "writing %d files", n);
        mcp_progress_begin(&bar, label, n);
    }
#pragma omp parallel for schedule(dynamic, 1) if (n > 1) reduction(+ : failed)
    for (int i = 0; i < n; i++) {
        const mcp_file_write *w = &files[i];
        int rc = w->image ? mcp_image_write(w->image, w->path, w->opt)
                          : mcp_write_rgb8(w->rgb8, w->width, w->height, w->path);
        if (rc) {
            snprintf(message[i], sizeof *message, "%s", mcp_error_message());
            failed++;
        }
        int done;
#pragma omp atomic capture
        done = ++written;
        int owner = 1;
#ifdef _OPENMP
        owner = omp_get_thread_num() == 0;
#endif
        if (shown && owner) mcp_progress_update(&bar, done);
    }
    if (shown) {
        if (failed)
            mcp__progress_stop(&bar);
        else
            mcp_progress_end(&bar);
    }
    int rc = 0;
    for (int i = 0; failed && i < n; i++)
        if (message[i][0]) {
            rc = mcp_error("%s", message[i]);
            break;
        }
    free(message);
    return rc;
}
