// Thin OpenImageIO shim: C in, C out, no exceptions across the boundary.
#include "preview.h"

#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <string>

extern "C" int ef_preview_write(const char *path, int w, int h, const unsigned char *rgb,
                                char *err, size_t errlen)
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
