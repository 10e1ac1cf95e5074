// OpenImageIO shim, built as a module that exrfog loads only when a run
// needs OIIO: Debian's OIIO pulls in ~260 libraries, which cost 0.2 s and
// 130 MB at start-up, more than fogging a 1080p frame.
#include <OpenImageIO/imageio.h>

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

// Writes channels names[0..n) of subimage `part` of the EXR src to dst,
// in the format dst's extension names (colour and alpha of a fogged frame:
// --output with a non-EXR name). Values go as float; the writer converts
// to what its format holds.
// src and dst may be /proc/self/fd/N names (the caller's own files): src
// is read as EXR, dst written in dst_fmt's format (NULL: dst's extension).
extern "C" __attribute__((visibility("default"))) int
ef_oiio_convert(const char *src, int part, const char *const *names, int n, const char *dst,
                const char *dst_fmt, char *err, size_t errlen)
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
        std::vector<float> all(npx * (size_t) is.nchannels), sel(npx * (size_t) n);
        if (!in->read_image(part, 0, 0, is.nchannels, OIIO::TypeDesc::FLOAT, all.data())) {
            std::snprintf(err, errlen, "cannot read the fogged frame back: %s",
                          in->geterror().c_str());
            return -1;
        }
        for (size_t i = 0; i < npx; ++i)
            for (int k = 0; k < n; ++k)
                sel[i * (size_t) n + (size_t) k] = all[i * (size_t) is.nchannels + (size_t) idx[(size_t) k]];
        auto out = OIIO::ImageOutput::create(dst_fmt ? dst_fmt : dst);
        if (!out) {
            std::snprintf(err, errlen, "no writer for this format: %s", OIIO::geterror().c_str());
            return -1;
        }
        OIIO::ImageSpec os(is.width, is.height, n, OIIO::TypeDesc::FLOAT);
        static const char *const rgba[4] = { "R", "G", "B", "A" };
        os.channelnames.clear();
        for (int k = 0; k < n; ++k)
            os.channelnames.push_back(rgba[k < 4 ? k : 3]);
        os.alpha_channel = n == 4 ? 3 : -1;
        if (out->supports("origin"))
            copy_window(os, is);
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
ef_oiio_to_exr(const char *src, int dst_fd, char *err, size_t errlen)
{
    try {
        auto in = OIIO::ImageInput::open(src);
        if (!in) {
            std::snprintf(err, errlen, "cannot read the depth image: %s", OIIO::geterror().c_str());
            return -1;
        }
        const OIIO::ImageSpec is = in->spec();
        if (is.deep || is.width < 1 || is.height < 1 || is.nchannels < 1) {
            std::snprintf(err, errlen, "the depth image is empty or deep");
            return -1;
        }
        std::vector<float> px((size_t) is.width * (size_t) is.height * (size_t) is.nchannels);
        if (!in->read_image(0, 0, 0, is.nchannels, OIIO::TypeDesc::FLOAT, px.data())) {
            std::snprintf(err, errlen, "cannot read the depth image: %s", in->geterror().c_str());
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
