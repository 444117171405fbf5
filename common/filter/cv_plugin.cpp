// cv_plugin.cpp: the OpenCV plug-in (mcpost_cv.so): the C ABI over OpenCV core +
// imgproc that filter.c and colormap.c use (the perceptual, blend and FLIP filters;
// docs/libraries.md §4), through cv.c, which loads it on first use (OpenCV and what it
// links cost every process ~10 ms of relocations at start, most of `mcpost --version`).
// C++17 stays in this file. Caller buffers are wrapped as cv::Mat without copies
// (const_cast for inputs; OpenCV never writes through src). Every entry point catches
// every exception: none may cross extern "C". Borders are BORDER_REPLICATE (clamp to
// edge) everywhere, as docs/mathematics.md §4.3 and docs/flip.md §3 ask; filters are
// correlations with the anchor at the centre.
#include "cv_shim.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <exception>
#include <string>

static_assert(cv::COLORMAP_MAGMA == MCP__CV_COLORMAP_MAGMA, "colormap id");
static_assert(cv::COLORMAP_INFERNO == MCP__CV_COLORMAP_INFERNO, "colormap id");
static_assert(cv::COLORMAP_VIRIDIS == MCP__CV_COLORMAP_VIRIDIS, "colormap id");
static_assert(cv::COLORMAP_TURBO == MCP__CV_COLORMAP_TURBO, "colormap id");
static_assert(MCP__CV_MAX_CHANNELS <= CV_CN_MAX, "channel groups");

// Writes msg to err as one line (OpenCV messages can hold newlines).
static int
fail(char *err, size_t cap, const std::string &msg)
{
    std::string line = msg;
    for (char &ch : line)
        if (ch == '\n' || ch == '\r') ch = ' ';
    while (!line.empty() && line.back() == ' ')
        line.pop_back();
    if (err && cap) std::snprintf(err, cap, "%s", line.c_str());
    return -1;
}

// The message of whatever was thrown. cv::Exception::err is the bare reason (e.g.
// "ksize.width > 0 && ksize.width % 2 == 1"), what() adds file and line.
static int
fail_current(char *err, size_t cap, const char *op)
{
    try {
        throw;
    } catch (const cv::Exception &e) {
        return fail(err, cap, std::string(op) + ": opencv: " + e.err);
    } catch (const std::exception &e) {
        return fail(err, cap, std::string(op) + ": " + e.what());
    } catch (...) {
        return fail(err, cap, std::string(op) + ": unknown exception");
    }
}

// A Mat header over a caller plane, no copy. AUTO_STEP is an enum, hence the cast.
static cv::Mat
wrap(const mcp__cv_plane *p)
{
    size_t step = p->row_step ? p->row_step * sizeof(float) : (size_t)cv::Mat::AUTO_STEP;
    return cv::Mat(p->height, p->width, CV_32FC(p->channels), p->data, step);
}

// Checks the arguments every strip filter shares; returns 0 or fails into err.
static int
check_strip(const mcp__cv_plane *src, const mcp__cv_plane *dst, int y0, int y1, char *err,
            size_t cap, const char *op)
{
    if (src->channels < 1 || src->channels > MCP__CV_MAX_CHANNELS ||
        src->width != dst->width || src->height != dst->height ||
        src->channels != dst->channels || y0 < 0 || y1 > src->height || y0 >= y1)
        return fail(err, cap, std::string(op) + ": bad plane or strip arguments");
    return 0;
}

static int
sep_filter_rows(const mcp__cv_plane *src, const mcp__cv_plane *dst, int y0, int y1,
                const float *kx, int kx_len, const float *ky, int ky_len, char *err,
                size_t err_cap)
{
    const char *op = "separable filter";
    try {
        if (check_strip(src, dst, y0, y1, err, err_cap, op)) return -1;
        cv::Mat s = wrap(src), d = wrap(dst);
        // Row ranges of Mats that span the whole buffers: OpenCV locates the ROI in its
        // parent and reads the rows above and below it; only the parent's edges are
        // replicated.
        cv::Mat sr = s.rowRange(y0, y1), dr = d.rowRange(y0, y1);
        const uchar *before = dr.data;
        cv::Mat mx(1, kx_len, CV_32F, const_cast<float *>(kx));
        cv::Mat my(ky_len, 1, CV_32F, const_cast<float *>(ky));
        cv::sepFilter2D(sr, dr, CV_32F, mx, my, cv::Point(-1, -1), 0.0,
                        cv::BORDER_REPLICATE);
        if (dr.data != before)
            return fail(err, err_cap,
                        std::string(op) + ": opencv reallocated the output");
        return 0;
    } catch (...) {
        return fail_current(err, err_cap, op);
    }
}

// Correlates the ROI (rows, cols) of s into the same ROI of d; false if OpenCV
// reallocated the output.
static bool
filter2d_roi(const cv::Mat &s, const cv::Mat &d, cv::Range rows, cv::Range cols,
             const cv::Mat &k)
{
    cv::Mat sr = s(rows, cols), dr = d(rows, cols);
    const uchar *before = dr.data;
    // filter2D correlates (no kernel flip), as filter.h specifies.
    cv::filter2D(sr, dr, CV_32F, k, cv::Point(-1, -1), 0.0, cv::BORDER_REPLICATE);
    return dr.data == before;
}

static int
filter2d_rows(const mcp__cv_plane *src, const mcp__cv_plane *dst, int y0, int y1,
              const float *kernel, int kw, int kh, char *err, size_t err_cap)
{
    const char *op = "2d filter";
    try {
        if (check_strip(src, dst, y0, y1, err, err_cap, op)) return -1;
        cv::Mat s = wrap(src), d = wrap(dst);
        cv::Mat k(kh, kw, CV_32F, const_cast<float *>(kernel));
        cv::Range all = cv::Range::all(), rows(y0, y1);
        bool ok;
        // OpenCV 4.6 correlates a whole image (never a proper ROI) with a kernel of 130+
        // taps through a DFT, which turns a single Inf or NaN pixel into NaN everywhere
        // and rounds differently. So a whole image is filtered as two ROIs.
        if (y0 > 0 || y1 < s.rows) {
            ok = filter2d_roi(s, d, rows, all, k);
        } else if (s.rows >= 2) {
            int m = s.rows / 2;
            ok = filter2d_roi(s, d, cv::Range(0, m), all, k) &&
                 filter2d_roi(s, d, cv::Range(m, s.rows), all, k);
        } else if (s.cols >= 2) {
            int m = s.cols / 2;
            ok = filter2d_roi(s, d, all, cv::Range(0, m), k) &&
                 filter2d_roi(s, d, all, cv::Range(m, s.cols), k);
        } else {
            // One pixel: with replicate borders every tap reads it.
            const float *in = reinterpret_cast<const float *>(s.data);
            float *out = reinterpret_cast<float *>(d.data);
            for (int c = 0; c < s.channels(); c++) {
                double sum = 0;
                for (size_t i = 0; i < (size_t)kw * (size_t)kh; i++)
                    sum += (double)kernel[i] * in[c];
                out[c] = (float)sum;
            }
            ok = true;
        }
        if (!ok)
            return fail(err, err_cap,
                        std::string(op) + ": opencv reallocated the output");
        return 0;
    } catch (...) {
        return fail_current(err, err_cap, op);
    }
}

static int
dft_power(const double *tile, int n, double *power, char *err, size_t err_cap)
{
    const char *op = "tile dft";
    try {
        if (n < 1) return fail(err, err_cap, std::string(op) + ": bad tile size");
        cv::Mat in(n, n, CV_64F, const_cast<double *>(tile));
        cv::Mat spec; // n x n CV_64FC2, allocated by OpenCV (a scratch, not the output)
        cv::dft(in, spec, cv::DFT_COMPLEX_OUTPUT);
        for (int v = 0; v < n; v++) {
            const cv::Vec2d *row = spec.ptr<cv::Vec2d>(v);
            double *out = power + (size_t)v * n;
            for (int u = 0; u < n; u++)
                out[u] = row[u][0] * row[u][0] + row[u][1] * row[u][1];
        }
        return 0;
    } catch (...) {
        return fail_current(err, err_cap, op);
    }
}

static int
colormap_lut(int cv_map, unsigned char *rgb, char *err, size_t err_cap)
{
    const char *op = "colormap";
    try {
        // applyColorMap is a per-grey-level table lookup, so mapping the 256 levels
        // once gives exactly what it would give on a whole 8-bit image.
        cv::Mat levels(1, 256, CV_8UC1), bgr;
        for (int i = 0; i < 256; i++)
            levels.at<uchar>(0, i) = (uchar)i;
        cv::applyColorMap(levels, bgr, cv_map);
        if (bgr.type() != CV_8UC3 || bgr.total() != 256)
            return fail(err, err_cap, std::string(op) + ": unexpected opencv output");
        for (int i = 0; i < 256; i++) {
            const cv::Vec3b &c = bgr.at<cv::Vec3b>(0, i);
            rgb[3 * i + 0] = c[2];
            rgb[3 * i + 1] = c[1];
            rgb[3 * i + 2] = c[0];
        }
        return 0;
    } catch (...) {
        return fail_current(err, err_cap, op);
    }
}

// The plug-in's one entry point (cv.c looks it up with dlsym).
extern "C" __attribute__((visibility("default"))) const mcp__cv_table *
mcp_cv_plugin_table(void)
{
    static const mcp__cv_table table = {MCP__CV_ABI, sep_filter_rows, filter2d_rows,
                                        dft_power, colormap_lut};
    return &table;
}
