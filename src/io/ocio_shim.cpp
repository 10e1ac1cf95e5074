#include "ocio_shim.h"

// Thin OpenColorIO shim (C in, C out): config loading, name resolution,
// colour parsing and display/view processors. No exception leaves a
// function of this file.
#include <OpenColorIO/OpenColorIO.h>

#include <dlfcn.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <sys/stat.h>

namespace OCIO = OCIO_NAMESPACE;

#ifndef EXRFOG_OCIO_CONFIG_INSTALL
#define EXRFOG_OCIO_CONFIG_INSTALL ""
#endif
#ifndef EXRFOG_OCIO_CONFIG_BUILD
#define EXRFOG_OCIO_CONFIG_BUILD ""
#endif

#ifndef EXRFOG_OCIO_CONFIG_RELATIVE
#define EXRFOG_OCIO_CONFIG_RELATIVE ""
#endif

struct ef_ocio {
    OCIO::ConstConfigRcPtr cfg;
    std::string where;
};

struct ef_ocio_display {
    OCIO::ConstCPUProcessorRcPtr cpu;
};

namespace {

// Copies s to out; -1 (with a truncated copy) if it does not fit.
int put(char *out, size_t len, const std::string &s)
{
    if (!out || len == 0)
        return out ? -1 : 0;
    std::snprintf(out, len, "%s", s.c_str());
    return s.size() < len ? 0 : -1;
}

void say(char *msg, size_t len, const std::string &s)
{
    if (msg && len)
        std::snprintf(msg, len, "%s", s.c_str());
}

std::string trim(const std::string &s)
{
    size_t a = 0, b = s.size();
    while (a < b && std::isspace((unsigned char) s[a]))
        ++a;
    while (b > a && std::isspace((unsigned char) s[b - 1]))
        --b;
    return s.substr(a, b - a);
}

bool same_nocase(const std::string &a, const char *b)
{
    if (!b || a.size() != std::strlen(b))
        return false;
    for (size_t i = 0; i < a.size(); ++i)
        if (std::tolower((unsigned char) a[i]) != std::tolower((unsigned char) b[i]))
            return false;
    return true;
}

bool is_file(const char *path)
{
    struct stat st;
    return path && *path && stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

// Canonical name of a space, alias or role; "" if unknown.
std::string resolve(const OCIO::ConstConfigRcPtr &cfg, const char *name)
{
    if (!name || !*name)
        return "";
    OCIO::ConstColorSpaceRcPtr cs = cfg->getColorSpace(name);
    return cs ? cs->getName() : "";
}

// The config's sRGB texture space (piecewise sRGB encoding, Rec.709
// primaries) under the names configs give it, or "".
std::string srgb_texture(const OCIO::ConstConfigRcPtr &cfg)
{
    static const char *const srgb[] = {"sRGB - Texture", "srgb_texture", "srgb_tx",
                                       "Utility - sRGB - Texture", "sRGB Encoded Rec.709 (sRGB)",
                                       "sRGB"};
    for (const char *s : srgb) {
        std::string n = resolve(cfg, s);
        if (!n.empty())
            return n;
    }
    return "";
}

// The working space: name, or the scene_linear role when name is NULL.
bool working_space(const ef_ocio *o, const char *working, std::string &out, std::string &err)
{
    if (!working) {
        out = resolve(o->cfg, OCIO::ROLE_SCENE_LINEAR);
        if (out.empty()) {
            err = "the colour config (" + o->where +
                  ") has no scene_linear role; name the working space (--colorspace)";
            return false;
        }
        return true;
    }
    out = resolve(o->cfg, working);
    if (out.empty()) {
        err = std::string("unknown working colour space '") + working + "'";
        return false;
    }
    return true;
}

// "A, B, C, ..." of the config's colour spaces (scene ones first), at most n.
std::string some_spaces(const OCIO::ConstConfigRcPtr &cfg, int n)
{
    std::string s;
    int shown = 0, total = 0;
    const OCIO::SearchReferenceSpaceType kinds[2] = {OCIO::SEARCH_REFERENCE_SPACE_SCENE,
                                                     OCIO::SEARCH_REFERENCE_SPACE_DISPLAY};
    for (OCIO::SearchReferenceSpaceType k : kinds) {
        int count = cfg->getNumColorSpaces(k, OCIO::COLORSPACE_ACTIVE);
        for (int i = 0; i < count; ++i, ++total)
            if (shown < n) {
                s += (shown++ ? ", " : "");
                s += std::string("'") + cfg->getColorSpaceNameByIndex(k, OCIO::COLORSPACE_ACTIVE, i) + "'";
            }
    }
    if (total > shown)
        s += ", ... (" + std::to_string(total) + " in all; ociocheck --iconfig lists them)";
    return s;
}

// Exactly three comma-separated finite numbers.
bool parse3(const std::string &text, double v[3])
{
    const char *p = text.c_str();
    for (int i = 0; i < 3; ++i) {
        char *end;
        errno = 0;
        double x = std::strtod(p, &end);
        if (end == p || errno == ERANGE || !std::isfinite(x))
            return false;
        v[i] = x;
        p = end;
        while (std::isspace((unsigned char) *p))
            ++p;
        if (i < 2) {
            if (*p != ',')
                return false;
            ++p;
        }
    }
    return *p == '\0';
}

int hexval(char c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    c = (char) std::tolower((unsigned char) c);
    return (c >= 'a' && c <= 'f') ? c - 'a' + 10 : -1;
}

// Converts one RGB triple between two config spaces (canonical names).
void convert(const OCIO::ConstConfigRcPtr &cfg, const std::string &src, const std::string &dst,
             const double in[3], double out[3])
{
    float p[3] = {(float) in[0], (float) in[1], (float) in[2]};
    if (src != dst) {
        OCIO::ConstProcessorRcPtr proc = cfg->getProcessor(src.c_str(), dst.c_str());
        proc->getDefaultCPUProcessor()->applyRGB(p);
    }
    for (int i = 0; i < 3; ++i)
        out[i] = p[i];
}

// 3x3 helpers for the chromaticity match (row-major).
typedef double M3[3][3];

void mul3(const M3 a, const M3 b, M3 r)
{
    M3 t;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            t[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
    std::memcpy(r, t, sizeof t);
}

bool inv3(const M3 m, M3 r)
{
    double c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    double c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    double c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    double det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    if (!(std::fabs(det) > 1e-300))
        return false;
    r[0][0] = c00 / det;
    r[1][0] = c01 / det;
    r[2][0] = c02 / det;
    r[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det;
    r[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det;
    r[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det;
    r[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det;
    r[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det;
    r[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det;
    return true;
}

void xy_to_xyz(double x, double y, double v[3])
{
    v[0] = x / y;
    v[1] = 1.0;
    v[2] = (1.0 - x - y) / y;
}

// RGB -> XYZ of primaries p = {rx ry gx gy bx by} and white (wx, wy).
bool npm(const double p[6], double wx, double wy, M3 out)
{
    M3 m, mi;
    for (int c = 0; c < 3; ++c) {
        double v[3];
        xy_to_xyz(p[2 * c], p[2 * c + 1], v);
        for (int r = 0; r < 3; ++r)
            m[r][c] = v[r];
    }
    double w[3];
    xy_to_xyz(wx, wy, w);
    if (!inv3(m, mi))
        return false;
    for (int c = 0; c < 3; ++c) {
        double s = mi[c][0] * w[0] + mi[c][1] * w[1] + mi[c][2] * w[2];
        for (int r = 0; r < 3; ++r)
            out[r][c] = m[r][c] * s;
    }
    return true;
}

// Bradford von Kries adaptation XYZ(white a) -> XYZ(white b).
void bradford(double ax, double ay, double bx, double by, M3 out)
{
    static const M3 B = {{0.8951, 0.2664, -0.1614}, {-0.7502, 1.7135, 0.0367}, {0.0389, -0.0685, 1.0296}};
    M3 Bi, D = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
    inv3(B, Bi);
    double a[3], b[3];
    xy_to_xyz(ax, ay, a);
    xy_to_xyz(bx, by, b);
    for (int i = 0; i < 3; ++i) {
        double ca = B[i][0] * a[0] + B[i][1] * a[1] + B[i][2] * a[2];
        double cb = B[i][0] * b[0] + B[i][1] * b[1] + B[i][2] * b[2];
        D[i][i] = cb / ca;
    }
    mul3(D, B, out);
    mul3(Bi, out, out);
}

// Candidate RGB -> reference RGB as a matrix, if the transform is linear.
bool linear_matrix(const OCIO::ConstCPUProcessorRcPtr &cpu, M3 m)
{
    for (int c = 0; c < 3; ++c) {
        float p[3] = {0, 0, 0};
        p[c] = 1.0f;
        cpu->applyRGB(p);
        for (int r = 0; r < 3; ++r)
            m[r][c] = p[r];
    }
    static const float probes[3][3] = {{0, 0, 0}, {0.3f, 0.6f, 0.1f}, {4.0f, 2.0f, 8.0f}};
    for (const float *q : probes) {
        float p[3] = {q[0], q[1], q[2]};
        cpu->applyRGB(p);
        for (int r = 0; r < 3; ++r) {
            double want = m[r][0] * q[0] + m[r][1] * q[1] + m[r][2] * q[2];
            if (!(std::fabs(p[r] - want) <= 1e-4 * (1.0 + std::fabs(want))))
                return false;
        }
    }
    return true;
}

// "DISPLAY: view, view; DISPLAY: ..." for error messages.
std::string displays_and_views(const OCIO::ConstConfigRcPtr &cfg)
{
    std::string s;
    for (int i = 0; i < cfg->getNumDisplays(); ++i) {
        const char *d = cfg->getDisplay(i);
        s += (i ? "; '" : "'") + std::string(d) + "': ";
        for (int j = 0; j < cfg->getNumViews(d); ++j)
            s += (j ? ", '" : "'") + std::string(cfg->getView(d, j)) + "'";
    }
    return s.empty() ? "(the config has no displays)" : s;
}

const char *find_display(const OCIO::ConstConfigRcPtr &cfg, const std::string &name)
{
    for (int i = 0; i < cfg->getNumDisplays(); ++i)
        if (same_nocase(name, cfg->getDisplay(i)))
            return cfg->getDisplay(i);
    return nullptr;
}

const char *find_view(const OCIO::ConstConfigRcPtr &cfg, const char *display, const std::string &name)
{
    for (int i = 0; i < cfg->getNumViews(display); ++i)
        if (same_nocase(name, cfg->getView(display, i)))
            return cfg->getView(display, i);
    return nullptr;
}

} // namespace

extern "C" const char *ef_ocio_version(void)
{
    return OCIO::GetVersion();
}

namespace {

// The largest LUT file a config may reference: a 65^3 cube as text is
// about 20 MB; anything past this is not a LUT (or /dev/zero's cousin).
const off_t LUT_MAX_BYTES = (off_t) 1 << 30;

// Checks the file t references (recursing into groups): OCIO reads LUTs
// whole, so a device (/dev/zero grows without bound), a FIFO (blocks for
// ever) or a huge file is refused before it ever opens one. Files it
// cannot find are left to OCIO's own message.
bool check_transform(const OCIO::ConstConfigRcPtr &cfg, const OCIO::ConstTransformRcPtr &t,
                     std::string &bad)
{
    if (!t)
        return true;
    if (auto g = OCIO::DynamicPtrCast<const OCIO::GroupTransform>(t)) {
        for (int i = 0; i < g->getNumTransforms(); ++i)
            if (!check_transform(cfg, g->getTransform(i), bad))
                return false;
        return true;
    }
    auto f = OCIO::DynamicPtrCast<const OCIO::FileTransform>(t);
    if (!f || !f->getSrc() || !*f->getSrc())
        return true;
    std::string path;
    try {
        path = cfg->getCurrentContext()->resolveFileLocation(f->getSrc());
    } catch (...) {
        return true;
    }
    struct stat st;
    if (stat(path.c_str(), &st) != 0)
        return true;
    if (!S_ISREG(st.st_mode)) {
        bad = "its FileTransform '" + path + "' is not a regular file (" +
              (S_ISFIFO(st.st_mode) ? "a FIFO" : S_ISCHR(st.st_mode) ? "a character device"
               : S_ISDIR(st.st_mode) ? "a directory" : "a device or socket") +
              "); a LUT must be a file";
        return false;
    }
    if (st.st_size > LUT_MAX_BYTES) {
        bad = "its FileTransform '" + path + "' is " + std::to_string((long long) st.st_size) +
              " bytes, more than any LUT (1 GiB at most)";
        return false;
    }
    return true;
}

// Every file the config's transforms reference: colour spaces (both
// directions), looks, view transforms and named transforms.
bool check_files(const OCIO::ConstConfigRcPtr &cfg, std::string &bad)
{
    for (int i = 0; i < cfg->getNumColorSpaces(OCIO::SEARCH_REFERENCE_SPACE_ALL, OCIO::COLORSPACE_ALL); ++i) {
        auto cs = cfg->getColorSpace(
            cfg->getColorSpaceNameByIndex(OCIO::SEARCH_REFERENCE_SPACE_ALL, OCIO::COLORSPACE_ALL, i));
        if (cs && (!check_transform(cfg, cs->getTransform(OCIO::COLORSPACE_DIR_TO_REFERENCE), bad) ||
                   !check_transform(cfg, cs->getTransform(OCIO::COLORSPACE_DIR_FROM_REFERENCE), bad)))
            return false;
    }
    for (int i = 0; i < cfg->getNumLooks(); ++i) {
        auto lk = cfg->getLook(cfg->getLookNameByIndex(i));
        if (lk && (!check_transform(cfg, lk->getTransform(), bad) ||
                   !check_transform(cfg, lk->getInverseTransform(), bad)))
            return false;
    }
    for (int i = 0; i < cfg->getNumViewTransforms(); ++i) {
        auto vt = cfg->getViewTransform(cfg->getViewTransformNameByIndex(i));
        if (vt && (!check_transform(cfg, vt->getTransform(OCIO::VIEWTRANSFORM_DIR_TO_REFERENCE), bad) ||
                   !check_transform(cfg, vt->getTransform(OCIO::VIEWTRANSFORM_DIR_FROM_REFERENCE), bad)))
            return false;
    }
    for (int i = 0; i < cfg->getNumNamedTransforms(OCIO::NAMEDTRANSFORM_ALL); ++i) {
        auto nt = cfg->getNamedTransform(cfg->getNamedTransformNameByIndex(OCIO::NAMEDTRANSFORM_ALL, i));
        if (nt && (!check_transform(cfg, nt->getTransform(OCIO::TRANSFORM_DIR_FORWARD), bad) ||
                   !check_transform(cfg, nt->getTransform(OCIO::TRANSFORM_DIR_INVERSE), bad)))
            return false;
    }
    return true;
}

} // namespace

extern "C" ef_ocio *ef_ocio_open(const char *path, char *where, size_t where_len, char *msg,
                                 size_t msg_len)
{
    std::string file, desc, fix;
    const char *env = std::getenv("OCIO");
    if (path) {
        file = path;
        desc = "--colorconfig " + file;
        fix = "check the --colorconfig path, or leave --colorconfig out to use $OCIO or exrfog's config";
    } else if (env && *env) {
        file = env;
        desc = "$OCIO=" + file;
        fix = "fix or unset $OCIO, or pass --colorconfig FILE";
    } else {
        /* Beside the installed library or program first (a package
         * installs under another prefix than the build was configured
         * with), then the configured prefix, then the source tree. */
        Dl_info info;
        std::string beside;
        if (dladdr(reinterpret_cast<void *>(&ef_ocio_version), &info) && info.dli_fname &&
            *EXRFOG_OCIO_CONFIG_RELATIVE) {
            std::string lib = info.dli_fname;
            const size_t slash = lib.rfind('/');
            if (slash != std::string::npos)
                beside = lib.substr(0, slash + 1) + EXRFOG_OCIO_CONFIG_RELATIVE;
        }
        file = !beside.empty() && is_file(beside.c_str())  ? beside
               : is_file(EXRFOG_OCIO_CONFIG_INSTALL)        ? std::string(EXRFOG_OCIO_CONFIG_INSTALL)
                                                            : std::string(EXRFOG_OCIO_CONFIG_BUILD);
        desc = "exrfog's config " + file;
        fix = "reinstall exrfog, or pass --colorconfig FILE or set $OCIO";
    }
    put(where, where_len, desc);
    if (file.compare(0, 7, "ocio://") == 0) {
        say(msg, msg_len, "colour config " + desc + ": built-in 'ocio://' configs need OpenColorIO 2.2 or "
                              "newer (this is " + OCIO::GetVersion() + "); " + fix);
        return nullptr;
    }
    if (!is_file(file.c_str())) {
        std::string what = file.empty() ? "no path" : "'" + file + "' does not exist or is not a file";
        if (!path && !(env && *env))
            what = std::string("not found (looked for '") + EXRFOG_OCIO_CONFIG_INSTALL + "' and '" +
                   EXRFOG_OCIO_CONFIG_BUILD + "')";
        say(msg, msg_len, "colour config (" + desc + "): " + what + "; " + fix);
        return nullptr;
    }
    try {
        OCIO::ConstConfigRcPtr cfg = OCIO::Config::CreateFromFile(file.c_str());
        cfg->validate();
        std::string bad;
        if (!check_files(cfg, bad)) {
            say(msg, msg_len, "colour config (" + desc + "): " + bad + "; " + fix);
            return nullptr;
        }
        ef_ocio *o = new ef_ocio;
        o->cfg = cfg;
        o->where = desc;
        return o;
    } catch (const std::exception &e) {
        say(msg, msg_len, "colour config (" + desc + ") is not a usable OpenColorIO config: " + e.what() +
                              " (check it with 'ociocheck --iconfig " + file + "'; " + fix + ")");
    } catch (...) {
        say(msg, msg_len, "colour config (" + desc + "): unknown OpenColorIO failure; " + fix);
    }
    return nullptr;
}

extern "C" void ef_ocio_close(ef_ocio *o)
{
    delete o;
}

extern "C" int ef_ocio_space_exists(const ef_ocio *o, const char *name, char *canonical, size_t len)
{
    try {
        std::string c = resolve(o->cfg, name);
        return !c.empty() && put(canonical, len, c) == 0;
    } catch (...) {
        return 0;
    }
}

extern "C" int ef_ocio_role(const ef_ocio *o, const char *role, char *out, size_t len)
{
    try {
        if (!role || !o->cfg->hasRole(role))
            return -1;
        std::string c = resolve(o->cfg, role);
        return c.empty() ? -1 : put(out, len, c);
    } catch (...) {
        return -1;
    }
}

extern "C" int ef_ocio_space_from_chromaticities(const ef_ocio *o, const float chrom[8], char *out,
                                                 size_t len)
{
    // ACES2065-1 (SMPTE ST 2065-1): AP0 primaries, ACES white.
    static const double ap0[6] = {0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.0770};
    static const double aces_w[2] = {0.32168, 0.33767};
    try {
        const OCIO::ConstConfigRcPtr &cfg = o->cfg;
        for (int i = 0; i < 8; ++i)
            if (!std::isfinite(chrom[i]))
                return -1;
        if (!(chrom[7] > 0) || !cfg->hasRole(OCIO::ROLE_INTERCHANGE_SCENE))
            return -1;
        std::string ref = resolve(cfg, OCIO::ROLE_INTERCHANGE_SCENE);
        if (ref.empty())
            return -1;
        M3 ap0_xyz, to_w, base;
        if (!npm(ap0, aces_w[0], aces_w[1], ap0_xyz))
            return -1;
        bradford(aces_w[0], aces_w[1], chrom[6], chrom[7], to_w);
        mul3(to_w, ap0_xyz, base); // ACES2065-1 RGB -> XYZ adapted to chrom's white

        std::string best;
        double best_err = 1e-3;
        const OCIO::SearchReferenceSpaceType scene = OCIO::SEARCH_REFERENCE_SPACE_SCENE;
        int n = cfg->getNumColorSpaces(scene, OCIO::COLORSPACE_ACTIVE);
        for (int i = 0; i < n; ++i) {
            const char *name = cfg->getColorSpaceNameByIndex(scene, OCIO::COLORSPACE_ACTIVE, i);
            OCIO::ConstColorSpaceRcPtr cs = cfg->getColorSpace(name);
            if (!cs || cs->isData())
                continue;
            M3 m, x;
            if (!linear_matrix(cfg->getProcessor(name, ref.c_str())->getDefaultCPUProcessor(), m))
                continue;
            mul3(base, m, x); // candidate RGB -> XYZ (chrom's white)
            double got[8] = { 0 }, err = 0;
            for (int c = 0; c < 4; ++c) {
                double X, Y, Z;
                if (c < 3) {
                    X = x[0][c], Y = x[1][c], Z = x[2][c];
                } else {
                    X = x[0][0] + x[0][1] + x[0][2];
                    Y = x[1][0] + x[1][1] + x[1][2];
                    Z = x[2][0] + x[2][1] + x[2][2];
                }
                double s = X + Y + Z;
                if (!(std::fabs(s) > 1e-12))
                    err = 1e9;
                else
                    got[2 * c] = X / s, got[2 * c + 1] = Y / s;
            }
            for (int k = 0; k < 8 && err < 1e9; ++k)
                err = std::fmax(err, std::fabs(got[k] - chrom[k]));
            if (err <= best_err) {
                best_err = err;
                best = cs->getName();
            }
        }
        return best.empty() ? -1 : put(out, len, best);
    } catch (...) {
        return -1;
    }
}

extern "C" int ef_ocio_parse_color(const ef_ocio *o, const char *text, const char *working,
                                   double rgb[3], char *msg, size_t msg_len)
{
    try {
        const OCIO::ConstConfigRcPtr &cfg = o->cfg;
        std::string t = trim(text ? text : ""), work, err;
        const std::string quoted = "colour '" + t + "'";
        if (!working_space(o, working, work, err)) {
            say(msg, msg_len, quoted + ": " + err + "; known spaces: " + some_spaces(cfg, 8));
            return -1;
        }
        if (!t.empty() && t[0] == '#') {
            double v[3];
            bool ok = t.size() == 7;
            for (int i = 0; ok && i < 3; ++i) {
                int hi = hexval(t[1 + 2 * i]), lo = hexval(t[2 + 2 * i]);
                ok = hi >= 0 && lo >= 0;
                v[i] = (hi * 16 + lo) / 255.0;
            }
            if (!ok) {
                say(msg, msg_len, quoted + ": expected #RRGGBB with six hexadecimal digits");
                return -1;
            }
            std::string src = srgb_texture(cfg);
            if (src.empty()) {
                say(msg, msg_len, quoted + ": the colour config (" + o->where +
                                      ") has no sRGB texture space (looked for 'sRGB - Texture', "
                                      "'srgb_texture', 'srgb_tx', 'sRGB'); write it as SPACE:R,G,B");
                return -1;
            }
            convert(cfg, src, work, v, rgb);
            return 0;
        }
        size_t colon = t.rfind(':');
        std::string nums = colon == std::string::npos ? t : t.substr(colon + 1);
        double v[3];
        if (!parse3(nums, v)) {
            say(msg, msg_len, quoted + ": expected R,G,B (three numbers), #RRGGBB or SPACE:R,G,B");
            return -1;
        }
        if (colon == std::string::npos) {
            for (int i = 0; i < 3; ++i)
                rgb[i] = v[i];
            return 0;
        }
        std::string space = trim(t.substr(0, colon));
        std::string src = resolve(cfg, space.c_str());
        if (src.empty()) {
            say(msg, msg_len, quoted + ": unknown colour space '" + space + "' in the colour config (" +
                                  o->where + "); known spaces: " + some_spaces(cfg, 8));
            return -1;
        }
        convert(cfg, src, work, v, rgb);
        return 0;
    } catch (const std::exception &e) {
        say(msg, msg_len, std::string("colour '") + (text ? text : "") + "': OpenColorIO: " + e.what());
    } catch (...) {
        say(msg, msg_len, std::string("colour '") + (text ? text : "") + "': OpenColorIO failed");
    }
    return -1;
}

namespace {

// A float CPU processor for proc, its name (display and view, or a space)
// written to used; NULL with msg when the name does not fit.
ef_ocio_display *make_display(const OCIO::ConstProcessorRcPtr &proc, const std::string &name,
                              char *used, size_t used_len, char *msg, size_t msg_len)
{
    ef_ocio_display *d = new ef_ocio_display;
    d->cpu = proc->getOptimizedCPUProcessor(OCIO::BIT_DEPTH_F32, OCIO::BIT_DEPTH_F32,
                                            OCIO::OPTIMIZATION_DEFAULT);
    if (put(used, used_len, name) != 0 && used) {
        delete d;
        say(msg, msg_len, "the name '" + name.substr(0, 60) + "...' is too long");
        return nullptr;
    }
    return d;
}

} // namespace

extern "C" ef_ocio_display *ef_ocio_display_open(const ef_ocio *o, const char *working,
                                                 const char *display_view, char *used, size_t used_len,
                                                 char *msg, size_t msg_len)
{
    try {
        const OCIO::ConstConfigRcPtr &cfg = o->cfg;
        std::string work, err;
        if (!working_space(o, working, work, err)) {
            say(msg, msg_len, "preview: " + err + "; known spaces: " + some_spaces(cfg, 8));
            return nullptr;
        }
        std::string s = trim(display_view ? display_view : "");
        const char *display = nullptr, *view = nullptr;
        if (s.empty()) {
            display = cfg->getDefaultDisplay();
            if (display && *display)
                view = cfg->getDefaultView(display);
        } else if ((display = find_display(cfg, s)) != nullptr) {
            view = cfg->getDefaultView(display);
        } else {
            for (size_t i = s.find(','); i != std::string::npos && !view; i = s.find(',', i + 1)) {
                display = find_display(cfg, trim(s.substr(0, i)));
                if (display)
                    view = find_view(cfg, display, trim(s.substr(i + 1)));
            }
        }
        if (!display || !*display || !view || !*view) {
            say(msg, msg_len, "preview: no display/view '" + s + "' in the colour config (" + o->where +
                                  "); give \"DISPLAY, VIEW\" from: " + displays_and_views(cfg));
            return nullptr;
        }
        OCIO::DisplayViewTransformRcPtr dvt = OCIO::DisplayViewTransform::Create();
        dvt->setSrc(work.c_str());
        dvt->setDisplay(display);
        dvt->setView(view);
        return make_display(cfg->getProcessor(dvt), std::string(display) + ", " + view, used,
                            used_len, msg, msg_len);
    } catch (const std::exception &e) {
        say(msg, msg_len, std::string("preview: OpenColorIO: ") + e.what());
    } catch (...) {
        say(msg, msg_len, "preview: OpenColorIO failed");
    }
    return nullptr;
}

extern "C" ef_ocio_display *ef_ocio_space_open(const ef_ocio *o, const char *working,
                                               const char *target, char *used, size_t used_len,
                                               char *msg, size_t msg_len)
{
    try {
        const OCIO::ConstConfigRcPtr &cfg = o->cfg;
        std::string work, err;
        if (!working_space(o, working, work, err)) {
            say(msg, msg_len, err + "; known spaces: " + some_spaces(cfg, 8));
            return nullptr;
        }
        std::string dst = target ? resolve(cfg, target) : srgb_texture(cfg);
        if (dst.empty()) {
            say(msg, msg_len, target ? "--output-colorspace '" + std::string(target) +
                                           "' is not a colour space of the config (" + o->where +
                                           "); known spaces: " + some_spaces(cfg, 8)
                                     : "the colour config (" + o->where +
                                           ") has no sRGB texture space (looked for 'sRGB - "
                                           "Texture', 'srgb_texture', 'srgb_tx', 'sRGB'); name "
                                           "the output's with --output-colorspace");
            return nullptr;
        }
        return make_display(cfg->getProcessor(work.c_str(), dst.c_str()), dst, used, used_len,
                            msg, msg_len);
    } catch (const std::exception &e) {
        say(msg, msg_len, std::string("OpenColorIO: ") + e.what());
    } catch (...) {
        say(msg, msg_len, "OpenColorIO failed");
    }
    return nullptr;
}

extern "C" int ef_ocio_display_apply(const ef_ocio_display *d, float *rgb, long npixels)
{
    // Rows of at most 64 Ki pixels: OCIO's image descriptors take long
    // widths, but its inner loops are happiest with modest ones.
    const long row = 65536;
    try {
        for (long done = 0; done < npixels; done += row) {
            long n = npixels - done < row ? npixels - done : row;
            OCIO::PackedImageDesc img(rgb + 3 * done, n, 1, 3);
            d->cpu->apply(img);
        }
        return 0;
    } catch (...) {
        return -1;
    }
}

extern "C" void ef_ocio_display_close(ef_ocio_display *d)
{
    delete d;
}
