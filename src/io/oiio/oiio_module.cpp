// OpenImageIO shim, built as a module that exrfog loads only when a run
// needs OIIO: Debian's OIIO pulls in ~260 libraries, which cost 0.2 s and
// 130 MB at start-up, more than fogging a 1080p frame.
#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <exception>

extern "C" __attribute__((visibility("default"))) int
ef_oiio_write_rgb8(const char *path, int w, int h, const unsigned char *rgb, char *err,
                   size_t errlen)
{
    try {
        auto out = OIIO::ImageOutput::create(path);
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

extern "C" __attribute__((visibility("default"))) const char *ef_oiio_version(void)
{
    return OIIO_VERSION_STRING;
}
