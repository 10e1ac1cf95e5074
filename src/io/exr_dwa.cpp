// DWAA/DWAB transcoding through the OpenEXR C++ library (see exr_dwa.h).
// No exception crosses into C: every entry point catches and reports.
#include "exr_dwa.h"

#include <Iex.h>
#include <ImfChannelList.h>
#include <ImfCompression.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfIO.h>
#include <ImfInputPart.h>
#include <ImfLineOrder.h>
#include <ImfMultiPartInputFile.h>
#include <ImfMultiPartOutputFile.h>
#include <ImfOutputPart.h>
#include <ImfPartType.h>
#include <ImfStandardAttributes.h>
#include <ImfAttribute.h>
#include <ImfThreading.h>
#include <ImfTileDescription.h>
#include <ImfTiledInputPart.h>
#include <ImfTiledOutputPart.h>

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

namespace {

using namespace OPENEXR_IMF_NAMESPACE;
using IMATH_NAMESPACE::Box2i;

// Same caps as exr_io.h (EF_MAX_DIMENSION, EF_WORKER_BYTES): a block that
// would need more than this is a corrupt header, refused before allocating.
const int64_t kMaxDimension = 262144;
const uint64_t kMaxBlockBytes = 1ull << 30;
// What the library's buffers may take together: it keeps two line buffers
// (or tiles) per thread in each file, each with its (de)compressor's work
// space, about 8 chunk sizes per thread in all (measured: 26 MB for a 4K
// DWAA frame of 12 bytes a pixel at 2 threads). Fewer threads run when the
// chunks are large: a 4K DWAB part (256-line chunks) runs on one.
const uint64_t kThreadBudget = 128ull << 20;

const char *const kCompNames[] = { "none", "rle", "zips", "zip", "piz",
                                   "pxr24", "b44", "b44a", "dwaa", "dwab" };

const char *comp_name(int c)
{
    return c >= 0 && c < NUM_COMPRESSION_METHODS ? kCompNames[c] : "unknown";
}

bool is_dwa(int c)
{
    return c == DWAA_COMPRESSION || c == DWAB_COMPRESSION;
}

// Scanlines per chunk of each compression (OpenEXR file format).
int lines_per_chunk(Compression c)
{
    switch (c) {
    case ZIP_COMPRESSION:
    case PXR24_COMPRESSION:
        return 16;
    case PIZ_COMPRESSION:
    case B44_COMPRESSION:
    case B44A_COMPRESSION:
    case DWAA_COMPRESSION:
        return 32;
    case DWAB_COMPRESSION:
        return 256;
    default:
        return 1;
    }
}

struct Failure {
    std::string msg;
};

[[noreturn]] void fail(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void fail(const char *fmt, ...)
{
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    throw Failure{ buf };
}

// Imf's output stream over the caller's descriptor. Errors are remembered
// as well as thrown: the library writes the chunk offset tables from its
// destructors, which swallow exceptions.
class FdOStream : public OStream {
  public:
    FdOStream(int fd, const char *name) : OStream(name), fd_(fd), name_(name) {}

    void write(const char c[], int n) override
    {
        while (n > 0) {
            ssize_t k = pwrite(fd_, c, (size_t) n, (off_t) pos_);
            if (k < 0 && errno == EINTR)
                continue;
            if (k <= 0) {
                if (error_.empty())
                    error_ = "cannot write " + name_ + ": " +
                             (k < 0 ? std::strerror(errno) : "nothing written") +
                             " (free some space or write elsewhere)";
                throw IEX_NAMESPACE::IoExc(error_);
            }
            pos_ += (uint64_t) k;
            c += k;
            n -= (int) k;
        }
        end_ = std::max(end_, pos_);
    }
    uint64_t tellp() override { return pos_; }
    void seekp(uint64_t pos) override { pos_ = pos; }

    const std::string &error() const { return error_; }
    uint64_t end() const { return end_; }

  private:
    int fd_;
    std::string name_;
    uint64_t pos_ = 0, end_ = 0;
    std::string error_;
};

// The library's global thread pool, restored when the transcode ends.
class ThreadCountGuard {
  public:
    explicit ThreadCountGuard(int n) : old_(globalThreadCount())
    {
        if (n != old_)
            setGlobalThreadCount(n);
    }
    ~ThreadCountGuard()
    {
        try {
            if (globalThreadCount() != old_)
                setGlobalThreadCount(old_);
        } catch (...) {
        }
    }

  private:
    int old_;
};

struct Plane {
    std::string name;
    PixelType type;
    size_t bytes;     // per sample
    size_t offset;    // of its plane in the block buffer
};

// Planar block buffer: each channel a plane of w x rows samples of its own
// type, slices addressed with absolute pixel coordinates.
struct Block {
    std::vector<Plane> planes;
    std::vector<char> buf;
    int64_t w = 0, rows = 0;

    void layout(const ChannelList &cl, int64_t width, int64_t nrows, int part)
    {
        w = width;
        rows = nrows;
        planes.clear();
        uint64_t off = 0;
        for (ChannelList::ConstIterator i = cl.begin(); i != cl.end(); ++i) {
            const Channel &ch = i.channel();
            if (ch.xSampling != 1 || ch.ySampling != 1)
                fail("part %d: channel '%s' is subsampled (%dx%d), which exrfog does not "
                     "support; render or convert without subsampling",
                     part, i.name(), ch.xSampling, ch.ySampling);
            size_t b = ch.type == HALF ? 2 : 4;
            planes.push_back(Plane{ i.name(), ch.type, b, (size_t) off });
            off += ((uint64_t) w * (uint64_t) rows * b + 7) & ~(uint64_t) 7;
            if (off > kMaxBlockBytes)
                fail("part %d needs over %.0f GiB for one block of %lld x %lld pixels: the "
                     "header is probably corrupt",
                     part, (double) kMaxBlockBytes / (1u << 30), (long long) w,
                     (long long) rows);
        }
        buf.assign((size_t) off, 0);
    }

    // A frame buffer whose pixel (x0, y0) is the first sample of each plane.
    FrameBuffer frame(int x0, int y0)
    {
        FrameBuffer fb;
        for (const Plane &p : planes) {
            const intptr_t xs = (intptr_t) p.bytes, ys = (intptr_t) (p.bytes * (size_t) w);
            char *base = (char *) ((intptr_t) (buf.data() + p.offset) - (intptr_t) x0 * xs -
                                   (intptr_t) y0 * ys);
            fb.insert(p.name, Slice(p.type, base, (size_t) xs, (size_t) ys));
        }
        return fb;
    }
};

void copy_scanline_part(MultiPartInputFile &mi, MultiPartOutputFile &mo, int p, bool raw,
                        int threads)
{
    InputPart in(mi, p);
    OutputPart out(mo, p);
    if (raw) {
        out.copyPixels(in);
        return;
    }
    const Header &ih = in.header();
    const Box2i dw = ih.dataWindow();
    const int64_t w = (int64_t) dw.max.x - dw.min.x + 1, h = (int64_t) dw.max.y - dw.min.y + 1;
    if (w < 1 || h < 1 || w > kMaxDimension || h > kMaxDimension)
        fail("part %d has an absurd data window (%d,%d)-(%d,%d): the header is corrupt", p,
             dw.min.x, dw.min.y, dw.max.x, dw.max.y);
    // Whole chunks of both compressions, a few at a time so the library's
    // threads have several line buffers to work on.
    int64_t lines = std::max(lines_per_chunk(ih.compression()),
                             lines_per_chunk(out.header().compression())) *
                    (int64_t) std::max(1, threads);
    lines = std::min(lines, h);
    Block b;
    b.layout(ih.channels(), w, lines, p);
    const int64_t nblocks = (h + lines - 1) / lines;
    const bool down = ih.lineOrder() == DECREASING_Y;
    for (int64_t k = 0; k < nblocks; ++k) {
        const int64_t kb = down ? nblocks - 1 - k : k;
        const int y0 = (int) (dw.min.y + kb * lines);
        const int y1 = (int) std::min<int64_t>(y0 + lines - 1, dw.max.y);
        FrameBuffer fb = b.frame(dw.min.x, y0);
        in.setFrameBuffer(fb);
        in.readPixels(y0, y1);
        out.setFrameBuffer(fb);
        out.writePixels(y1 - y0 + 1);
    }
}

void copy_tiled_part(MultiPartInputFile &mi, MultiPartOutputFile &mo, int p, bool raw)
{
    TiledInputPart in(mi, p);
    TiledOutputPart out(mo, p);
    if (raw) {
        out.copyPixels(in);
        return;
    }
    const Header &ih = in.header();
    const TileDescription td = ih.tileDescription();
    const bool down = ih.lineOrder() == DECREASING_Y;
    // Levels in the order the library lays them out in the file (ly outer,
    // lx inner; mip levels diagonal), so nothing waits in its buffers.
    std::vector<std::pair<int, int>> levels;
    if (td.mode == ONE_LEVEL)
        levels.emplace_back(0, 0);
    else if (td.mode == MIPMAP_LEVELS)
        for (int l = 0; l < in.numLevels(); ++l)
            levels.emplace_back(l, l);
    else
        for (int ly = 0; ly < in.numYLevels(); ++ly)
            for (int lx = 0; lx < in.numXLevels(); ++lx)
                levels.emplace_back(lx, ly);
    Block b;
    for (const auto &lv : levels) {
        const int lx = lv.first, ly = lv.second;
        const Box2i dw = in.dataWindowForLevel(lx, ly);
        const int64_t w = (int64_t) dw.max.x - dw.min.x + 1, h = (int64_t) dw.max.y - dw.min.y + 1;
        if (w < 1 || h < 1 || w > kMaxDimension || h > kMaxDimension || td.ySize < 1 ||
            td.ySize > (unsigned) kMaxDimension)
            fail("part %d has an absurd data window or tile size: the header is corrupt", p);
        const int64_t rows = std::min<int64_t>(td.ySize, h);
        if (b.w != w || b.rows != rows)
            b.layout(ih.channels(), w, rows, p);
        const int nx = in.numXTiles(lx), ny = in.numYTiles(ly);
        for (int k = 0; k < ny; ++k) {
            const int ty = down ? ny - 1 - k : k;
            FrameBuffer fb = b.frame(dw.min.x, (int) (dw.min.y + (int64_t) ty * td.ySize));
            in.setFrameBuffer(fb);
            in.readTiles(0, nx - 1, ty, ty, lx, ly);
            out.setFrameBuffer(fb);
            out.writeTiles(0, nx - 1, ty, ty, lx, ly);
        }
    }
}

bool part_is_tiled(const Header &h)
{
    return h.hasType() ? h.type() == TILEDIMAGE : h.hasTileDescription();
}

void transcode(const char *in_path, int out_fd, const char *out_name, int dwa_parts_to,
               int all_parts_to, float dwa_level, int threads)
{
    if (dwa_parts_to < -1 || dwa_parts_to >= NUM_COMPRESSION_METHODS || all_parts_to < -1 ||
        all_parts_to >= NUM_COMPRESSION_METHODS)
        fail("internal error: compression %d/%d is not an OpenEXR compression", dwa_parts_to,
             all_parts_to);
    // Headers first (a first, thread-less open), to size the thread count.
    std::unique_ptr<MultiPartInputFile> in(new MultiPartInputFile(in_path, 0));
    const int nparts = in->parts();
    std::vector<Header> headers;
    std::vector<int> in_comp;
    std::vector<char> raw((size_t) nparts, 0);
    for (int p = 0; p < nparts; ++p) {
        Header h = in->header(p);
        if (h.hasType() && isDeepData(h.type()))
            fail("%s: part %d holds deep data, which exrfog does not handle (flatten it first, "
                 "e.g. oiiotool IN --flatten -o FLAT.exr)",
                 in_path, p);
        const int ic = h.compression();
        in_comp.push_back(ic);
        int oc = is_dwa(ic) && dwa_parts_to >= 0 ? dwa_parts_to : ic;
        if (all_parts_to >= 0)
            oc = all_parts_to;
        const FloatAttribute *la = h.findTypedAttribute<FloatAttribute>("dwaCompressionLevel");
        const float in_level = la ? la->value() : EF_DWA_DEFAULT_LEVEL;
        const float level = dwa_level >= 0 ? dwa_level : in_level;
        raw[(size_t) p] = oc == ic && (!is_dwa(oc) || level == in_level);
        if (!h.hasType())
            h.setType(part_is_tiled(h) ? TILEDIMAGE : SCANLINEIMAGE);
        if (!raw[(size_t) p]) {
            h.compression() = (Compression) oc;
            if (is_dwa(oc)) {
                h.dwaCompressionLevel() = level;
                h.insert("dwaCompressionLevel", FloatAttribute(level));
            } else if (la) {
                // The level would describe a compression no longer used.
                // Header::erase leaks the attribute in OpenEXR 3.1.5, so
                // the header is rebuilt without it.
                Header stripped;
                for (Header::ConstIterator i = h.begin(); i != h.end(); ++i)
                    if (strcmp(i.name(), "dwaCompressionLevel"))
                        stripped.insert(i.name(), i.attribute());
                h = stripped;
            }
        }
        headers.push_back(h);
    }
    // The largest chunk (or tile) of either file, uncompressed.
    uint64_t chunk = 0;
    for (int p = 0; p < nparts; ++p) {
        const Header &h = headers[(size_t) p];
        uint64_t px = 0;
        for (ChannelList::ConstIterator i = h.channels().begin(); i != h.channels().end(); ++i)
            px += i.channel().type == HALF ? 2 : 4;
        const Box2i dw = h.dataWindow();
        const uint64_t w = (uint64_t) ((int64_t) dw.max.x - dw.min.x + 1);
        uint64_t cw = w, ch;
        if (part_is_tiled(h)) {
            cw = std::min<uint64_t>(h.tileDescription().xSize, w);
            ch = h.tileDescription().ySize;
        } else {
            ch = (uint64_t) std::max(lines_per_chunk(h.compression()),
                                     lines_per_chunk((Compression) in_comp[(size_t) p]));
        }
        chunk = std::max(chunk, cw * ch * px);
    }
    int nthreads = std::max(threads, 1);
    while (nthreads > 1 && 8 * (uint64_t) nthreads * chunk > kThreadBudget)
        --nthreads;
    if (nthreads < 2)
        nthreads = 0;   // no pool: everything on the calling thread
    in.reset();
    ThreadCountGuard guard(nthreads);
    MultiPartInputFile inr(in_path, nthreads);
    FdOStream os(out_fd, out_name);
    {
        MultiPartOutputFile out(os, headers.data(), nparts, false, nthreads);
        for (int p = 0; p < nparts; ++p) {
            try {
                if (part_is_tiled(headers[(size_t) p]))
                    copy_tiled_part(inr, out, p, raw[(size_t) p]);
                else
                    copy_scanline_part(inr, out, p, raw[(size_t) p], nthreads);
            } catch (const Failure &) {
                throw;
            } catch (const std::exception &e) {
                if (!os.error().empty())
                    throw;
                fail("cannot convert part %d of %s from %s to %s: %s (the file is damaged or "
                     "truncated)",
                     p, in_path, comp_name(in_comp[(size_t) p]),
                     comp_name(headers[(size_t) p].compression()), e.what());
            }
        }
    }
    if (!os.error().empty())
        fail("%s", os.error().c_str());
    struct stat st;
    if (fstat(out_fd, &st) == 0 && S_ISREG(st.st_mode) && (uint64_t) st.st_size > os.end() &&
        ftruncate(out_fd, (off_t) os.end()) != 0)
        fail("cannot truncate %s: %s", out_name, std::strerror(errno));
}

} // namespace

extern "C" int ef_dwa_transcode(const char *in_path, int out_fd, const char *out_name,
                                int dwa_parts_to, int all_parts_to, float dwa_level, int threads,
                                char *msg, size_t msglen)
{
    std::string m;
    try {
        transcode(in_path, out_fd, out_name, dwa_parts_to, all_parts_to, dwa_level, threads);
        return 0;
    } catch (const Failure &f) {
        m = f.msg;
    } catch (const std::bad_alloc &) {
        m = std::string("out of memory converting ") + in_path;
    } catch (const std::exception &e) {
        m = e.what();
    } catch (...) {
        m = std::string("unknown error converting ") + in_path;
    }
    if (msg && msglen)
        snprintf(msg, msglen, "%s", m.c_str());
    return -1;
}
