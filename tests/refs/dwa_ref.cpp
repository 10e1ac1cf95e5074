// The OpenEXR C++ library as an independent reader for test_dwa: DWA files
// cannot be read by OpenEXRCore 3.1.5, so their pixels and headers are
// checked through the reference implementation, outside exr_dwa.cpp.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputPart.h>
#include <ImfMultiPartInputFile.h>
#include <ImfStandardAttributes.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>

#include "dwa_ref.h"

using namespace OPENEXR_IMF_NAMESPACE;

extern "C" int dwa_ref_header(const char *path, int part, dwa_ref_info *info)
{
    try {
        MultiPartInputFile f(path, 0);
        if (part >= f.parts())
            return -1;
        const Header &h = f.header(part);
        info->nparts = f.parts();
        info->compression = (int) h.compression();
        const FloatAttribute *la = h.findTypedAttribute<FloatAttribute>("dwaCompressionLevel");
        info->level = la ? la->value() : -1.0f;
        info->tiled = h.hasTileDescription();
        const IMATH_NAMESPACE::Box2i dw = h.dataWindow();
        info->dw[0] = dw.min.x;
        info->dw[1] = dw.min.y;
        info->dw[2] = dw.max.x;
        info->dw[3] = dw.max.y;
        info->nch = 0;
        for (ChannelList::ConstIterator i = h.channels().begin();
             i != h.channels().end() && info->nch < DWA_REF_MAX_CH; ++i, ++info->nch) {
            snprintf(info->ch[info->nch], sizeof info->ch[0], "%s", i.name());
            info->type[info->nch] = (int) i.channel().type;
        }
        return 0;
    } catch (const std::exception &e) {
        fprintf(stderr, "dwa_ref_header(%s): %s\n", path, e.what());
        return -1;
    }
}

extern "C" void *dwa_ref_read(const char *path, int part, const char *name, int *w, int *h)
{
    try {
        MultiPartInputFile f(path, 0);
        InputPart in(f, part);
        const IMATH_NAMESPACE::Box2i dw = in.header().dataWindow();
        const Channel *ch = in.header().channels().findChannel(name);
        if (!ch)
            return nullptr;
        *w = dw.max.x - dw.min.x + 1;
        *h = dw.max.y - dw.min.y + 1;
        uint32_t *buf = (uint32_t *) calloc((size_t) *w * (size_t) *h, 4);
        const PixelType t = ch->type == UINT ? UINT : FLOAT;
        char *base = (char *) buf - ((ptrdiff_t) dw.min.x + (ptrdiff_t) dw.min.y * *w) * 4;
        FrameBuffer fb;
        fb.insert(name, Slice(t, base, 4, (size_t) *w * 4));
        in.setFrameBuffer(fb);
        in.readPixels(dw.min.y, dw.max.y);
        return buf;
    } catch (const std::exception &e) {
        fprintf(stderr, "dwa_ref_read(%s, %s): %s\n", path, name, e.what());
        return nullptr;
    }
}
