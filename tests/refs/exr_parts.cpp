// The OpenEXR C++ library as an independent writer and reader of multi-part
// files for deep_check.py (issue 24): OpenImageIO refuses to write deep and
// flat parts into one file, which OpenEXR 2 allows.
//
//   exr_parts mix OUT A.exr B.exr ...  a file whose parts are the first part
//                                      of each input, copied chunk for chunk
//                                      (flat or deep); the parts are named
//                                      after the inputs' order: part0, part1...
//   exr_parts read FILE                reads every part's pixels with the
//                                      library (deep: the sample counts, then
//                                      every sample) and prints per part
//                                      "name type samples checksum"
// Exit 0, or 1 with the library's message.
#include <ImfChannelList.h>
#include <ImfDeepFrameBuffer.h>
#include <ImfDeepScanLineInputPart.h>
#include <ImfDeepScanLineOutputPart.h>
#include <ImfDeepTiledInputPart.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputPart.h>
#include <ImfMultiPartInputFile.h>
#include <ImfMultiPartOutputFile.h>
#include <ImfOutputPart.h>
#include <ImfPartType.h>
#include <ImfTiledInputPart.h>

#include <cmath>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

using namespace OPENEXR_IMF_NAMESPACE;

static int mix(const char *out, int n, char **in)
{
    std::vector<MultiPartInputFile *> files;
    std::vector<Header> headers;
    for (int i = 0; i < n; ++i) {
        files.push_back(new MultiPartInputFile(in[i]));
        Header h = files.back()->header(0);
        h.setName("part" + std::to_string(i));
        headers.push_back(h);
    }
    MultiPartOutputFile o(out, headers.data(), n);
    for (int i = 0; i < n; ++i) {
        const std::string t = headers[i].type();
        if (t == DEEPSCANLINE) {
            DeepScanLineInputPart ip(*files[i], 0);
            DeepScanLineOutputPart op(o, i);
            op.copyPixels(ip);
        } else if (t == SCANLINEIMAGE) {
            InputPart ip(*files[i], 0);
            OutputPart op(o, i);
            op.copyPixels(ip);
        } else {
            std::fprintf(stderr, "exr_parts: %s: only scanline parts are mixed here\n", in[i]);
            return 1;
        }
    }
    for (auto f : files)
        delete f;
    return 0;
}

static int read_all(const char *path)
{
    MultiPartInputFile f(path);
    for (int p = 0; p < f.parts(); ++p) {
        const Header &h = f.header(p);
        const Imath::Box2i dw = h.dataWindow();
        const long w = dw.max.x - dw.min.x + 1, hh = dw.max.y - dw.min.y + 1;
        const std::string t = h.type();
        double sum = 0;
        unsigned long long samples = 0;
        if (t == DEEPSCANLINE || t == DEEPTILE) {
            std::vector<unsigned> counts((size_t) (w * hh));
            std::vector<std::vector<float *>> ptr;
            DeepFrameBuffer fb;
            fb.insertSampleCountSlice(Slice(UINT, (char *) (counts.data() - dw.min.x - dw.min.y * w),
                                            sizeof(unsigned), sizeof(unsigned) * w));
            std::vector<std::string> names;
            for (auto c = h.channels().begin(); c != h.channels().end(); ++c)
                names.push_back(c.name());
            ptr.resize(names.size(), std::vector<float *>((size_t) (w * hh)));
            for (size_t c = 0; c < names.size(); ++c)
                fb.insert(names[c], DeepSlice(FLOAT, (char *) (ptr[c].data() - dw.min.x - dw.min.y * w),
                                              sizeof(float *), sizeof(float *) * w, sizeof(float)));
            std::vector<float> store;
            if (t == DEEPSCANLINE) {
                DeepScanLineInputPart ip(f, p);
                ip.setFrameBuffer(fb);
                ip.readPixelSampleCounts(dw.min.y, dw.max.y);
                for (unsigned c : counts)
                    samples += c;
                store.resize((size_t) samples * names.size());
                size_t at = 0;
                for (size_t c = 0; c < names.size(); ++c)
                    for (size_t i = 0; i < counts.size(); ++i) {
                        ptr[c][i] = store.data() + at;
                        at += counts[i];
                    }
                ip.readPixels(dw.min.y, dw.max.y);
            } else {
                std::fprintf(stderr, "exr_parts: deep tiled parts are not read here\n");
                return 1;
            }
            for (float v : store)
                if (std::isfinite(v))
                    sum += v;
        } else {
            std::vector<float> px((size_t) (w * hh));
            int nch = 0;
            for (auto c = h.channels().begin(); c != h.channels().end(); ++c, ++nch) {
                FrameBuffer fb;
                fb.insert(c.name(), Slice(FLOAT, (char *) (px.data() - dw.min.x - dw.min.y * w),
                                          sizeof(float), sizeof(float) * w));
                if (t == TILEDIMAGE) {
                    TiledInputPart ip(f, p);
                    ip.setFrameBuffer(fb);
                    ip.readTiles(0, ip.numXTiles() - 1, 0, ip.numYTiles() - 1);
                } else {
                    InputPart ip(f, p);
                    ip.setFrameBuffer(fb);
                    ip.readPixels(dw.min.y, dw.max.y);
                }
                for (float v : px)
                    if (std::isfinite(v))
                        sum += v;
            }
            samples = (unsigned long long) (w * hh);
        }
        std::printf("%s %s %llu %.9g\n", h.hasName() ? h.name().c_str() : "-", t.c_str(), samples,
                    sum);
    }
    return 0;
}

int main(int argc, char **argv)
{
    try {
        if (argc >= 4 && std::string(argv[1]) == "mix")
            return mix(argv[2], argc - 3, argv + 3);
        if (argc == 3 && std::string(argv[1]) == "read")
            return read_all(argv[2]);
        std::fprintf(stderr, "usage: exr_parts mix OUT IN... | exr_parts read FILE\n");
        return 2;
    } catch (const std::exception &e) {
        std::fprintf(stderr, "exr_parts: %s\n", e.what());
        return 1;
    }
}
