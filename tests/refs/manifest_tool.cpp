// The OpenEXR C++ library's side of the idManifest test (issue 8):
//   manifest_tool write FILE   a small RGB + Z frame with a camera and an
//                              idManifest (channel "id": 1 sphere, 2 ground)
//   manifest_tool check FILE   reads FILE whole with the C++ library and
//                              exits 0 only if its idManifest decodes to
//                              exactly those entries
// so that exrfog's copy of the attribute (made by OpenEXRCore) is judged
// by the other implementation.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIDManifest.h>
#include <ImfIDManifestAttribute.h>
#include <ImfInputFile.h>
#include <ImfMatrixAttribute.h>
#include <ImfOutputFile.h>
#include <ImfStandardAttributes.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <vector>

using namespace Imf;

static int write_file(const char *path)
{
    const int w = 16, h = 8;
    Header hdr(w, h);
    for (const char *n : { "R", "G", "B", "Z" })
        hdr.channels().insert(n, Channel(FLOAT));
    IDManifest m;
    IDManifest::ChannelGroupManifest &g = m.add("id");
    g.setComponent("name");
    g.insert(1, "sphere");
    g.insert(2, "ground");
    addIDManifest(hdr, CompressedIDManifest(m));
    Imath::M44f w2c;
    w2c.makeIdentity();
    hdr.insert("worldToCamera", M44fAttribute(w2c));
    hdr.insert("CameraFov", FloatAttribute(40.f));
    std::vector<float> c(w * h, 0.5f), z(w * h, 10.f);
    FrameBuffer fb;
    for (const char *n : { "R", "G", "B" })
        fb.insert(n, Slice(FLOAT, (char *) c.data(), 4, 4 * w));
    fb.insert("Z", Slice(FLOAT, (char *) z.data(), 4, 4 * w));
    OutputFile f(path, hdr);
    f.setFrameBuffer(fb);
    f.writePixels(h);
    return 0;
}

static int check_file(const char *path)
{
    InputFile f(path);
    const Header &hdr = f.header();
    if (!hasIDManifest(hdr)) {
        std::fprintf(stderr, "manifest_tool: %s has no idManifest\n", path);
        return 1;
    }
    IDManifest m(idManifest(hdr));
    if (m.size() != 1 || m[0].size() != 2 || m[0].find(1) == m[0].end() ||
        m[0].find(2) == m[0].end() || m[0][1][0] != "sphere" || m[0][2][0] != "ground") {
        std::fprintf(stderr, "manifest_tool: %s: the idManifest lost its entries\n", path);
        return 1;
    }
    const Imath::Box2i dw = hdr.dataWindow();
    const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    std::vector<float> c((size_t) w * h);
    FrameBuffer fb;
    fb.insert("R", Slice(FLOAT, (char *) (c.data() - dw.min.x - (size_t) dw.min.y * w), 4, 4 * w));
    f.setFrameBuffer(fb);
    f.readPixels(dw.min.y, dw.max.y);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 3)
        return 2;
    try {
        return !std::strcmp(argv[1], "write") ? write_file(argv[2]) : check_file(argv[2]);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "manifest_tool: %s: %s\n", argv[2], e.what());
        return 1;
    }
}
