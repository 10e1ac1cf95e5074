// OpenImageIO shim, built as a module that exrfog loads only when a run
// needs OIIO: Debian's OIIO pulls in ~260 libraries, which cost 0.2 s and
// 130 MB at start-up, more than fogging a 1080p frame.
#include <OpenImageIO/imageio.h>

#include "../foreign.h"

#include <stdlib.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <vector>

// path may be a descriptor's /proc/self/fd/N name (the caller's own file,
// whatever its directory entry has become since); fmt, a name whose
// extension gives the format (NULL: path's own).
extern "C" __attribute__((visibility("default"))) int
ef_oiio_write_rgb8(const char *path, const char *fmt, int w, int h, const unsigned char *rgb,
                   char *err, size_t errlen)
{
    try {
        auto out = OIIO::ImageOutput::create(fmt ? fmt : path);
        if (!out) {
            std::snprintf(err, errlen, "cannot write a preview in this format: %s",
                          OIIO::geterror().c_str());
            return -1;
        }
        OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
        spec.attribute("oiio:ColorSpace", "sRGB");
        if (!out->open(path, spec) || !out->write_image(OIIO::TypeDesc::UINT8, rgb) ||
            !out->close()) {
            std::snprintf(err, errlen, "cannot write the preview: %s", out->geterror().c_str());
            return -1;
        }
        return 0;
    } catch (const std::exception &e) {
        std::snprintf(err, errlen, "cannot write the preview: %s", e.what());
        return -1;
    }
}

// Whether OIIO has a writer for this name's extension (nothing is written).
extern "C" __attribute__((visibility("default"))) int
ef_oiio_can_write(const char *path, char *err, size_t errlen)
{
    try {
        auto out = OIIO::ImageOutput::create(path);
        if (!out) {
            std::snprintf(err, errlen, "OpenImageIO cannot write this format (%s); use a name "
                          "ending in .png, .jpg or .tif", OIIO::geterror().c_str());
            return -1;
        }
        return 0;
    } catch (const std::exception &e) {
        std::snprintf(err, errlen, "OpenImageIO cannot write this format: %s", e.what());
        return -1;
    }
}

// The data window's origin and the full (display) window of `from`.
static void copy_window(OIIO::ImageSpec &to, const OIIO::ImageSpec &from)
{
    to.x = from.x;
    to.y = from.y;
    to.full_x = from.full_x;
    to.full_y = from.full_y;
    to.full_width = from.full_width;
    to.full_height = from.full_height;
}

extern "C" __attribute__((visibility("default"))) const char *ef_oiio_version(void)
{
    return OIIO_VERSION_STRING;
}

namespace {

// The OIIO type and bits per sample of an EF_DT_ code (0: float).
OIIO::TypeDesc dt_type(int dt, int *bits)
{
    switch (dt) {
    case EF_DT_UINT8: *bits = 8; return OIIO::TypeDesc::UINT8;
    case EF_DT_UINT10: *bits = 10; return OIIO::TypeDesc::UINT16;
    case EF_DT_UINT12: *bits = 12; return OIIO::TypeDesc::UINT16;
    case EF_DT_UINT16: *bits = 16; return OIIO::TypeDesc::UINT16;
    case EF_DT_HALF: *bits = 16; return OIIO::TypeDesc::HALF;
    default: *bits = 32; return OIIO::TypeDesc::FLOAT;
    }
}

// The EF_DT_ code of a writer's chosen type and bits per sample (0: none).
int dt_of(const OIIO::ImageSpec &s)
{
    const int bits = s.get_int_attribute("oiio:BitsPerSample", 0);
    if (s.format == OIIO::TypeDesc::UINT8)
        return EF_DT_UINT8;
    if (s.format == OIIO::TypeDesc::UINT16)
        return bits == 10 ? EF_DT_UINT10 : bits == 12 ? EF_DT_UINT12 : EF_DT_UINT16;
    if (s.format == OIIO::TypeDesc::HALF)
        return EF_DT_HALF;
    if (s.format == OIIO::TypeDesc::FLOAT)
        return EF_DT_FLOAT;
    return 0;
}

// Asks for type dt in s (0: float, the writer's choice): the bits per
// sample, and 16-bit float TIFF, which OIIO writes only when asked.
void set_type(OIIO::ImageSpec &s, int dt, int bits)
{
    if (dt)
        s.attribute("oiio:BitsPerSample", bits);
    if (dt == EF_DT_HALF)
        s.attribute("tiff:half", 1);
}

} // namespace

// Opens a 1x1 image of nch channels of type dt (0: float, the writer's
// choice) with the writer of ext's format, in a private directory
// (mkdtemp, 0700, so nobody can race its name), and removes it: what the
// writer accepts, before any pixel is read. *got: the EF_DT_ code the
// writer settled on; *alpha: whether the format holds alpha.
extern "C" __attribute__((visibility("default"))) int
ef_oiio_output_probe(const char *ext, int dt, int nch, int *got, int *alpha, char *err,
                     size_t errlen)
{
    char dir[4096];
    const char *tmp = getenv("TMPDIR");
    std::snprintf(dir, sizeof dir, "%s/exrfog-probe-XXXXXX", tmp && *tmp ? tmp : "/tmp");
    try {
        auto out = OIIO::ImageOutput::create(std::string("probe") + ext);
        if (!out) {
            std::snprintf(err, errlen, "OpenImageIO has no writer for it (%s)",
                          OIIO::geterror().c_str());
            return -1;
        }
        *alpha = out->supports("alpha") ? 1 : 0;
        if (!mkdtemp(dir)) {
            std::snprintf(err, errlen, "cannot make a private directory under %s to check the "
                          "format (set TMPDIR)", tmp && *tmp ? tmp : "/tmp");
            return -1;
        }
        std::string path = std::string(dir) + "/probe" + ext;
        int bits;
        OIIO::ImageSpec spec(1, 1, nch, dt_type(dt, &bits));
        set_type(spec, dt, bits);
        spec.alpha_channel = nch == 4 ? 3 : -1;
        bool ok = out->open(path, spec);
        std::string why = ok ? "" : out->geterror();
        if (ok) {
            std::vector<float> px((size_t) nch, 0.0f);
            ok = out->write_image(OIIO::TypeDesc::FLOAT, px.data()) && out->close();
            why = ok ? "" : out->geterror();
        }
        out.reset();
        if (ok) {
            // What the file holds, read back: a writer may keep a request
            // in its spec (PNG and 10 bits) and still write another depth.
            auto in = OIIO::ImageInput::open(path);
            *got = in ? dt_of(in->spec()) : 0;
            if (in)
                in->close();
        }
        unlink(path.c_str());
        rmdir(dir);
        if (!ok) {
            std::snprintf(err, errlen, "%s", why.empty() ? "the writer refused it" : why.c_str());
            return -1;
        }
        return 0;
    } catch (const std::exception &e) {
        std::snprintf(err, errlen, "OpenImageIO: %s", e.what());
        return -1;
    }
}

// Writes channels names[0..n) of subimage `part` of the EXR src to dst,
// in the format dst_fmt's extension names (colour and alpha of a fogged
// frame: --output with a non-EXR name), as d says: its type, the display
// window or the data window, colour encoded by d->encode (alpha
// unassociated first where d->unassociate), and labels.
// src and dst may be /proc/self/fd/N names (the caller's own files): src
// is read as EXR, dst written in dst_fmt's format (NULL: dst's extension).
extern "C" __attribute__((visibility("default"))) int
ef_oiio_convert(const char *src, int part, const char *const *names, int n, const char *dst,
                const char *dst_fmt, const ef_oiio_deliver *d, char *err, size_t errlen)
{
    try {
        auto in = OIIO::ImageInput::create("exr");
        OIIO::ImageSpec none;
        if (in && !in->open(src, none))
            in.reset();
        if (!in || !in->seek_subimage(part, 0)) {
            std::snprintf(err, errlen, "cannot read the fogged frame back: %s",
                          in ? in->geterror().c_str() : OIIO::geterror().c_str());
            return -1;
        }
        const OIIO::ImageSpec is = in->spec();
        std::vector<int> idx;
        for (int k = 0; k < n; ++k) {
            int at = -1;
            for (int c = 0; c < is.nchannels; ++c)
                if (is.channelnames[c] == names[k])
                    at = c;
            if (at < 0) {
                std::snprintf(err, errlen, "the fogged frame has no channel %s", names[k]);
                return -1;
            }
            idx.push_back(at);
        }
        const size_t npx = (size_t) is.width * (size_t) is.height;
        std::vector<float> all(npx * (size_t) is.nchannels);
        if (!in->read_image(part, 0, 0, is.nchannels, OIIO::TypeDesc::FLOAT, all.data())) {
            std::snprintf(err, errlen, "cannot read the fogged frame back: %s",
                          in->geterror().c_str());
            return -1;
        }
        // The output grid: the display window (pixels outside the data
        // window stay 0, as oiiotool writes them), or the data window.
        const int ox = d->full_window ? is.full_x : is.x, oy = d->full_window ? is.full_y : is.y;
        const int ow = d->full_window ? is.full_width : is.width,
                  oh = d->full_window ? is.full_height : is.height;
        std::vector<float> sel((size_t) ow * (size_t) oh * (size_t) n, 0.0f);
        for (int y = 0; y < is.height; ++y) {
            const int yy = is.y + y - oy;
            if (yy < 0 || yy >= oh)
                continue;
            for (int x = 0; x < is.width; ++x) {
                const int xx = is.x + x - ox;
                if (xx < 0 || xx >= ow)
                    continue;
                const float *p = &all[((size_t) y * (size_t) is.width + (size_t) x) *
                                      (size_t) is.nchannels];
                float *q = &sel[((size_t) yy * (size_t) ow + (size_t) xx) * (size_t) n];
                for (int k = 0; k < n; ++k)
                    q[k] = p[idx[(size_t) k]];
            }
        }
        std::vector<float>().swap(all);
        const size_t opx = (size_t) ow * (size_t) oh;
        if (d->encode) {
            // Colour to the output space, in rows of RGB triples; with
            // alpha unassociated first (a display-referred file's alpha
            // is straight: encoding premultiplied colour is wrong).
            std::vector<float> rgb(3 * 4096);
            for (size_t at = 0; at < opx; at += 4096) {
                const size_t m = opx - at < 4096 ? opx - at : 4096;
                for (size_t i = 0; i < m; ++i) {
                    const float *q = &sel[(at + i) * (size_t) n];
                    const float a = n == 4 ? q[3] : 1.0f;
                    const float u = d->unassociate && n == 4 && a > 0 && a < 1 ? 1.0f / a : 1.0f;
                    for (int k = 0; k < 3; ++k)
                        rgb[3 * i + (size_t) k] = q[k] * u;
                }
                if (d->encode(d->encode_user, rgb.data(), (long) m)) {
                    std::snprintf(err, errlen, "OpenColorIO failed to encode the colour");
                    return -1;
                }
                for (size_t i = 0; i < m; ++i)
                    for (int k = 0; k < 3; ++k)
                        sel[(at + i) * (size_t) n + (size_t) k] = rgb[3 * i + (size_t) k];
            }
        }
        auto out = OIIO::ImageOutput::create(dst_fmt ? dst_fmt : dst);
        if (!out) {
            std::snprintf(err, errlen, "no writer for this format: %s", OIIO::geterror().c_str());
            return -1;
        }
        int bits;
        OIIO::ImageSpec os(ow, oh, n, dt_type(d->type, &bits));
        set_type(os, d->type, bits);
        static const char *const rgba[4] = { "R", "G", "B", "A" };
        os.channelnames.clear();
        for (int k = 0; k < n; ++k)
            os.channelnames.push_back(rgba[k < 4 ? k : 3]);
        os.alpha_channel = n == 4 ? 3 : -1;
        if (n == 4 && d->unassociate)
            os.attribute("oiio:UnassociatedAlpha", 1);
        if (d->colorspace)
            os.attribute("oiio:ColorSpace", d->colorspace);
        if (d->dpx_transfer)
            os.attribute("dpx:Transfer", d->dpx_transfer);
        if (d->dpx_colorimetric)
            os.attribute("dpx:Colorimetric", d->dpx_colorimetric);
        if (!d->full_window && out->supports("origin")) {
            os.x = is.x;
            os.y = is.y;
        }
        if (!d->full_window && out->supports("displaywindow")) {
            os.full_x = is.full_x;
            os.full_y = is.full_y;
            os.full_width = is.full_width;
            os.full_height = is.full_height;
        }
        if (!out->open(dst, os) || !out->write_image(OIIO::TypeDesc::FLOAT, sel.data()) ||
            !out->close()) {
            std::snprintf(err, errlen, "cannot write it: %s", out->geterror().c_str());
            return -1;
        }
        return 0;
    } catch (const std::exception &e) {
        std::snprintf(err, errlen, "cannot write it: %s", e.what());
        return -1;
    }
}

// Reads the first image of src as float and writes it as a float EXR to
// the open descriptor dst_fd (--depth from a TIFF or any other format):
// channel names kept (one channel is Z), origin and full window kept.
extern "C" __attribute__((visibility("default"))) int
ef_oiio_to_exr(const char *src, int dst_fd, double max_pixels, char *err, size_t errlen)
{
    try {
        // The reader of the file's extension only: when it fails, OIIO's
        // open() tries every other reader on the bytes, and one of them
        // took 1.9 GB and 6 s on a damaged PNG (fuzz_depth).
        auto in = OIIO::ImageInput::create(src, false);
        OIIO::ImageSpec opened;
        if (!in || !in->open(src, opened)) {
            std::string why = in ? in->geterror() : OIIO::geterror();
            const size_t nl = why.find('\n');
            if (nl != std::string::npos)
                why.resize(nl);
            std::snprintf(err, errlen, "cannot read the depth image: %s",
                          why.empty() ? "no reader for this file" : why.c_str());
            return -1;
        }
        const OIIO::ImageSpec is = in->spec();
        if (is.deep || is.width < 1 || is.height < 1 || is.nchannels < 1) {
            std::snprintf(err, errlen, "the depth image is empty or deep");
            return -1;
        }
        // A header may claim any size (a 372-byte BMP claimed 13 million
        // pixels a row): more pixels than max_pixels, or past 2^28 values
        // (1 GiB of float), is not a depth pass of this frame, and is
        // refused unread.
        if (max_pixels > 0 && (double) is.width * (double) is.height > max_pixels) {
            std::snprintf(err, errlen, "the depth image claims %d x %d pixels, far more than the "
                          "colour image has (a depth pass matches its render)", is.width,
                          is.height);
            return -1;
        }
        if ((double) is.width * (double) is.height * (double) is.nchannels > (double) (1u << 28)) {
            std::snprintf(err, errlen, "the depth image claims %d x %d pixels of %d channels, "
                          "more than exrfog reads (2^28 values)", is.width, is.height,
                          is.nchannels);
            return -1;
        }
        std::vector<float> px((size_t) is.width * (size_t) is.height * (size_t) is.nchannels);
        // A truncated or damaged file may read "successfully" with its
        // errors left pending (TIFF strips past the end): any error fails.
        const bool ok = in->read_image(0, 0, 0, is.nchannels, OIIO::TypeDesc::FLOAT, px.data());
        std::string why = in->has_error() ? in->geterror() : "";
        if (why.empty() && OIIO::has_error())
            why = OIIO::geterror();
        const size_t nl = why.find('\n');
        if (nl != std::string::npos)
            why.resize(nl);   // the first of the reader's lines says it
        if (!ok || !why.empty()) {
            std::snprintf(err, errlen, "cannot read the depth image (truncated or damaged?): %s",
                          why.empty() ? "the reader failed" : why.c_str());
            return -1;
        }
        OIIO::ImageSpec os(is.width, is.height, is.nchannels, OIIO::TypeDesc::FLOAT);
        copy_window(os, is);
        os.channelnames = is.channelnames;
        if (is.nchannels == 1)
            os.channelnames[0] = "Z";
        os.alpha_channel = -1;
        os.attribute("compression", "zip");
        // OIIO writes by name: the descriptor is reached through /proc.
        char path[64];
        std::snprintf(path, sizeof path, "/proc/self/fd/%d", dst_fd);
        auto out = OIIO::ImageOutput::create("exr");
        if (!out || !out->open(path, os) || !out->write_image(OIIO::TypeDesc::FLOAT, px.data()) ||
            !out->close()) {
            std::snprintf(err, errlen, "cannot convert the depth image: %s",
                          out ? out->geterror().c_str() : OIIO::geterror().c_str());
            return -1;
        }
        return 0;
    } catch (const std::exception &e) {
        std::snprintf(err, errlen, "cannot convert the depth image: %s", e.what());
        return -1;
    }
}
