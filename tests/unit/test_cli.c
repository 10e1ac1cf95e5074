/* The command line as a user meets it: the exrfog binary is run on real
 * files and its exit status, messages and files are checked against the
 * contract of man/exrfog.1.
 *
 *  - bad files (missing, truncated, corrupt, not EXR, empty, absurd sizes,
 *    colour/depth mismatch, NaN/Inf depth and camera, no camera, no output
 *    directory): exit 1, "exrfog: FILE: what is wrong", no output and no
 *    temporary file left, input bytes unchanged;
 *  - usage errors: exit 2, quoting the offending text;
 *  - safety: OUTPUT == INPUT, an existing OUTPUT survives failures and
 *    killed runs;
 *  - thread determinism;
 *  - end to end on samples/sample.exr, every pixel checked against a
 *    per-pixel computation done here from the header matrices (own 4x4
 *    inverse, world-space rays), never by calling the code under test.
 *
 * Scratch files live in $EXRFOG_TMP_DIR/cli; each case writes its outputs
 * in its own directory so leftovers can be detected. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L
#endif

#include <dirent.h>
#include <fcntl.h>
#include <errno.h>
#include <math.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

#include "testutil.h"
#include "version.h"

/* ------------------------------------------------------------ paths */

typedef struct path_t { char s[2048]; } path_t;

static char g_root[1024];

static const char *root(void)
{
    if (!g_root[0]) {
        char *p = tu_path("cli");
        snprintf(g_root, sizeof g_root, "%s", p);
        free(p);
        mkdir(g_root, 0777);
    }
    return g_root;
}

/* root/<formatted> */
static path_t pth(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;
static path_t pth(const char *fmt, ...)
{
    path_t p;
    char rel[900];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(rel, sizeof rel, fmt, ap);
    va_end(ap);
    snprintf(p.s, sizeof p.s, "%s/%s", root(), rel);
    return p;
}

static void rm_rf(const char *path)
{
    struct stat sb;
    if (lstat(path, &sb) != 0)
        return;
    if (S_ISDIR(sb.st_mode)) {
        DIR *d = opendir(path);
        struct dirent *e;
        while (d && (e = readdir(d)) != NULL) {
            if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, ".."))
                continue;
            char sub[4096];
            snprintf(sub, sizeof sub, "%s/%s", path, e->d_name);
            rm_rf(sub);
        }
        if (d)
            closedir(d);
        rmdir(path);
    } else {
        unlink(path);
    }
}

/* An empty directory root/name. */
static path_t fresh_dir(const char *name)
{
    path_t p = pth("%s", name);
    rm_rf(p.s);
    assert_int_equal(mkdir(p.s, 0777), 0);
    return p;
}

/* ------------------------------------------------------------ files */

static unsigned char *slurp(const char *path, size_t *len)
{
    *len = 0;
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *d = malloc(n > 0 ? (size_t) n : 1);
    size_t got = n > 0 ? fread(d, 1, (size_t) n, f) : 0;
    fclose(f);
    *len = got;
    return d;
}

static void spit(const char *path, const void *data, size_t len)
{
    assert_int_equal(tu_write_bytes(path, data, len), 0);
}

static int same_bytes(const char *path, const unsigned char *data, size_t len)
{
    size_t n;
    unsigned char *d = slurp(path, &n);
    int same = d && n == len && memcmp(d, data, len) == 0;
    free(d);
    return same;
}

/* Every file of a directory (one level) with its bytes. */
typedef struct snap_t {
    int n;
    char name[32][256];
    unsigned char *data[32];
    size_t len[32];
} snap_t;

static void snap_take(const char *dir, snap_t *s)
{
    memset(s, 0, sizeof *s);
    DIR *d = opendir(dir);
    assert_non_null(d);
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, ".."))
            continue;
        assert_true(s->n < 32);
        char p[4096];
        snprintf(p, sizeof p, "%s/%s", dir, e->d_name);
        snprintf(s->name[s->n], sizeof s->name[0], "%s", e->d_name);
        struct stat sb;
        if (stat(p, &sb) == 0 && S_ISREG(sb.st_mode))
            s->data[s->n] = slurp(p, &s->len[s->n]);
        s->n++;
    }
    closedir(d);
}

static void snap_free(snap_t *s)
{
    for (int i = 0; i < s->n; ++i)
        free(s->data[i]);
    s->n = 0;
}

/* The directory holds exactly the files of s, with the same bytes. */
static void snap_check(const char *dir, const snap_t *s)
{
    snap_t now;
    snap_take(dir, &now);
    for (int i = 0; i < now.n; ++i) {
        int k = 0;
        while (k < s->n && strcmp(s->name[k], now.name[i]))
            ++k;
        if (k == s->n)
            fail_msg("leftover file '%s' in %s", now.name[i], dir);
        if (s->data[k] && !(now.data[i] && now.len[i] == s->len[k] &&
                            memcmp(now.data[i], s->data[k], s->len[k]) == 0))
            fail_msg("file '%s' in %s was modified", now.name[i], dir);
    }
    for (int k = 0; k < s->n; ++k) {
        int i = 0;
        while (i < now.n && strcmp(s->name[k], now.name[i]))
            ++i;
        if (i == now.n)
            fail_msg("file '%s' in %s disappeared", s->name[k], dir);
    }
    snap_free(&now);
}

static int dir_count(const char *dir)
{
    snap_t s;
    snap_take(dir, &s);
    int n = s.n;
    snap_free(&s);
    return n;
}

/* ------------------------------------------------------------ running */

static char g_out[1 << 16], g_err[1 << 15];

static const char *bin(void)
{
    const char *b = getenv("EXRFOG_BIN");
    return b ? b : "exrfog";
}

static void slurp_text(const char *path, char *buf, size_t cap)
{
    size_t n = 0;
    unsigned char *d = slurp(path, &n);
    if (n >= cap)
        n = cap - 1;
    if (d)
        memcpy(buf, d, n);
    buf[n] = '\0';
    free(d);
    unlink(path);
}

/* Runs "BIN ARGS" through sh (in dir when not NULL); stdout and stderr go to
 * g_out and g_err. Returns the exit status (128 + signal when killed). */
static int run_in(const char *dir, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static int run_in(const char *dir, const char *fmt, ...)
{
    char args[8192], cmd[16384];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(args, sizeof args, fmt, ap);
    va_end(ap);
    path_t o = pth("run.stdout"), e = pth("run.stderr");
    char cd[2200] = "";
    if (dir)
        snprintf(cd, sizeof cd, "cd '%s' && ", dir);
    snprintf(cmd, sizeof cmd, "%s'%s' %s >'%s' 2>'%s'", cd, bin(), args, o.s, e.s);
    int st = system(cmd);
    slurp_text(o.s, g_out, sizeof g_out);
    slurp_text(e.s, g_err, sizeof g_err);
    if (st == -1)
        fail_msg("system() failed: %s", strerror(errno));
    if (!WIFEXITED(st))
        return 128 + (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
    char why[4200];
    if (WEXITSTATUS(st) == 0 && !dir && tu_check_readback(args, why, sizeof why))
        fail_msg("`exrfog %s`: %s", args, why);
    return WEXITSTATUS(st);
}

#define run(...) run_in(NULL, __VA_ARGS__)

/* No sanitizer report on stderr (they also change the exit code, see main). */
static void assert_no_crash(void)
{
    if (strstr(g_err, "Sanitizer") || strstr(g_err, "runtime error") || strstr(g_err, "AddressSanitizer"))
        fail_msg("sanitizer report:\n%s", g_err);
}

static void assert_err_has(const char *needle)
{
    if (!strstr(g_err, needle))
        fail_msg("stderr lacks \"%s\"; it was:\n%s", needle, g_err);
}

static void assert_status(int got, int want)
{
    if (got != want)
        fail_msg("exit status %d, expected %d; stderr:\n%s", got, want, g_err);
}

/* stderr is one or more lines, the first "exrfog: FILE: message" (FILE may
 * be NULL: any non-empty name followed by ": "). */
static void assert_error_line(const char *file)
{
    assert_no_crash();
    if (strncmp(g_err, "exrfog: ", 8) != 0)
        fail_msg("stderr does not start with \"exrfog: \":\n%s", g_err);
    const char *rest = g_err + 8;
    if (file) {
        size_t n = strlen(file);
        if (strncmp(rest, file, n) != 0 || strncmp(rest + n, ": ", 2) != 0)
            fail_msg("stderr does not name %s as \"exrfog: %s: ...\":\n%s", file, file, g_err);
        rest += n + 2;
    } else {
        const char *colon = strstr(rest, ": ");
        const char *nl = strchr(rest, '\n');
        if (!colon || colon == rest || (nl && nl < colon))
            fail_msg("stderr is not \"exrfog: FILE: message\":\n%s", g_err);
        rest = colon + 2;
    }
    if (rest[0] == '\0' || rest[0] == '\n')
        fail_msg("empty error message:\n%s", g_err);
    if (g_err[strlen(g_err) - 1] != '\n')
        fail_msg("error message does not end with a newline:\n%s", g_err);
}

/* Runs a command that must fail with exit status want. Checks the input's
 * bytes are unchanged, that outdir holds exactly what it held before (no
 * output, no temporary file, existing files untouched), that nothing went
 * to stdout, and that stderr starts with "exrfog: ". */
static int check_failure(int want, const char *input, const char *outdir, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;
static int check_failure(int want, const char *input, const char *outdir, const char *fmt, ...)
{
    char args[8192];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(args, sizeof args, fmt, ap);
    va_end(ap);
    size_t inlen = 0;
    unsigned char *inb = input ? slurp(input, &inlen) : NULL;
    snap_t before;
    snap_take(outdir, &before);
    int st = run("%s", args);
    assert_no_crash();
    if (st != want)
        fail_msg("`exrfog %s`: exit status %d, expected %d; stderr:\n%s", args, st, want, g_err);
    snap_check(outdir, &before);
    snap_free(&before);
    if (inb) {
        if (!same_bytes(input, inb, inlen))
            fail_msg("the input %s was modified", input);
        free(inb);
    }
    if (g_out[0])
        fail_msg("unexpected stdout on failure:\n%s", g_out);
    if (strncmp(g_err, "exrfog: ", 8) != 0)
        fail_msg("stderr does not start with \"exrfog: \":\n%s", g_err);
    return st;
}

/* ------------------------------------------------------------ inputs */

static const char *source_dir(void)
{
    const char *s = getenv("EXRFOG_SOURCE_DIR");
    return s ? s : "..";
}

/* A private copy of samples/sample.exr (the original is never touched). */
static const char *sample(void)
{
    static path_t p;
    if (!p.s[0]) {
        char src[1200];
        snprintf(src, sizeof src, "%s/samples/sample.exr", source_dir());
        mkdir(pth("in").s, 0777);
        p = pth("in/sample.exr");
        assert_int_equal(tu_copy(src, p.s), 0);
    }
    return p.s;
}

static unsigned char *sample_bytes(size_t *len)
{
    unsigned char *d = slurp(sample(), len);
    assert_non_null(d);
    return d;
}

static uint32_t rd32(const unsigned char *p)
{
    return (uint32_t) p[0] | (uint32_t) p[1] << 8 | (uint32_t) p[2] << 16 | (uint32_t) p[3] << 24;
}

static uint64_t rd64(const unsigned char *p)
{
    return (uint64_t) rd32(p) | (uint64_t) rd32(p + 4) << 32;
}

static void wr32(unsigned char *p, uint32_t v)
{
    for (int i = 0; i < 4; ++i)
        p[i] = (unsigned char) (v >> (8 * i));
}

/* Byte layout of a single-part scanline file: end of the header (start of
 * the offset table), chunk count and offsets. */
typedef struct layout_t {
    size_t header_end;
    int nchunks;
    uint64_t off[1024];
} layout_t;

static void exr_layout(const unsigned char *d, size_t n, layout_t *L)
{
    size_t p = 8;
    memset(L, 0, sizeof *L);
    assert_true(n > 8 && rd32(d) == 20000630u);
    for (;;) {
        assert_true(p < n);
        if (d[p] == 0) {
            ++p;
            break;
        }
        size_t name = strlen((const char *) d + p);
        size_t type = strlen((const char *) d + p + name + 1);
        uint32_t sz = rd32(d + p + name + 1 + type + 1);
        p += name + 1 + type + 1 + 4 + sz;
    }
    L->header_end = p;
    uint64_t first = rd64(d + p);
    L->nchunks = (int) ((first - p) / 8);
    assert_true(L->nchunks > 0 && L->nchunks <= 1024);
    for (int i = 0; i < L->nchunks; ++i)
        L->off[i] = rd64(d + p + 8 * (size_t) i);
}

/* Offset of the value of attribute name/type in a header, or 0. */
static size_t find_attr(const unsigned char *d, size_t n, const char *name, const char *type,
                        uint32_t *size)
{
    char pat[256];
    size_t ln = strlen(name), lt = strlen(type), lp = ln + 1 + lt + 1;
    memcpy(pat, name, ln + 1);
    memcpy(pat + ln + 1, type, lt + 1);
    for (size_t i = 8; i + lp + 4 <= n; ++i)
        if (memcmp(d + i, pat, lp) == 0) {
            if (size)
                *size = rd32(d + i + lp);
            return i + lp + 4;
        }
    return 0;
}

static const float ID16[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };

/* A synthetic frame: float R,G,B,A (and Z unless z is NULL) of w x h. */
typedef struct frame_t {
    int w, h;
    float *c[5];
} frame_t;

static void frame_alloc(frame_t *f, int w, int h)
{
    f->w = w;
    f->h = h;
    for (int k = 0; k < 5; ++k)
        f->c[k] = calloc((size_t) w * (size_t) h, sizeof(float));
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            size_t i = (size_t) y * (size_t) w + (size_t) x;
            f->c[0][i] = 0.1f + 0.8f * (float) x / (float) w;
            f->c[1][i] = 0.2f + 0.5f * (float) y / (float) h;
            f->c[2][i] = 0.3f;
            f->c[3][i] = 1.0f;
            f->c[4][i] = 2.0f + (float) ((x * 7 + y * 13) % 50);
        }
}

static void frame_free(frame_t *f)
{
    for (int k = 0; k < 5; ++k)
        free(f->c[k]);
}

/* A part over f with the given channel set: bit k of mask adds R,G,B,A,Z. */
static void frame_part(tu_part *p, const frame_t *f, unsigned mask, exr_pixel_type_t rgba_type)
{
    static const char *const names[5] = { "R", "G", "B", "A", "Z" };
    tu_part_init(p, f->w, f->h);
    for (int k = 0; k < 5; ++k)
        if (mask & (1u << k))
            tu_part_add(p, names[k], k == 4 ? EXR_PIXEL_FLOAT : rgba_type, f->c[k]);
}

/* Identity worldToCamera (camera at the origin looking down +Z) and a
 * horizontal field of view. */
static void add_camera(tu_part *p, float fov)
{
    p->m44[0].name = "worldToCamera";
    memcpy(p->m44[0].m, ID16, sizeof ID16);
    p->f[0].name = "CameraFov";
    p->f[0].v = fov;
}

static void write_part(const char *path, const tu_part *p)
{
    int rv = tu_write_exr(path, p, 1);
    if (rv)
        fail_msg("tu_write_exr(%s) failed: %d", path, rv);
}

/* ------------------------------------------------------------ the reference model */

/* 4x4 inverse, Gauss-Jordan with partial pivoting. Returns 0 or -1. */
static int inv4(const double *a, double *out)
{
    double m[4][8];
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 8; ++j)
            m[i][j] = j < 4 ? a[4 * i + j] : (j - 4 == i);
    for (int c = 0; c < 4; ++c) {
        int piv = c;
        for (int r = c + 1; r < 4; ++r)
            if (fabs(m[r][c]) > fabs(m[piv][c]))
                piv = r;
        if (fabs(m[piv][c]) < 1e-300)
            return -1;
        for (int j = 0; j < 8; ++j) {
            double t = m[c][j];
            m[c][j] = m[piv][j];
            m[piv][j] = t;
        }
        double s = 1.0 / m[c][c];
        for (int j = 0; j < 8; ++j)
            m[c][j] *= s;
        for (int r = 0; r < 4; ++r)
            if (r != c) {
                double f = m[r][c];
                for (int j = 0; j < 8; ++j)
                    m[r][j] -= f * m[c][j];
            }
    }
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            out[4 * i + j] = m[i][j + 4];
    return 0;
}

/* Row vector (x y z w) times M. */
static void xform4(const double v[4], const double *M, double out[4])
{
    for (int j = 0; j < 4; ++j)
        out[j] = v[0] * M[j] + v[1] * M[4 + j] + v[2] * M[8 + j] + v[3] * M[12 + j];
}

/* Per pixel: the world distance to the surface (d), the planar depth
 * (z), radial length per unit of planar depth (k) and whether it is sky. */
typedef struct geom_t {
    int w, h;
    double *d, *z, *k;
    unsigned char *sky;
    double eye[3];
} geom_t;

static void geom_free(geom_t *g)
{
    free(g->d);
    free(g->z);
    free(g->k);
    free(g->sky);
}

static void geom_alloc(geom_t *g, int w, int h)
{
    size_t n = (size_t) w * (size_t) h;
    g->w = w;
    g->h = h;
    g->d = calloc(n, sizeof *g->d);
    g->z = calloc(n, sizeof *g->z);
    g->k = calloc(n, sizeof *g->k);
    g->sky = calloc(n, 1);
}

static int is_sky(double Z)
{
    return !isfinite(Z) || Z <= 0 || Z >= 1e9;
}

/* The sample's geometry, in world space: for pixel (x, y) the point
 * (u, v) = ((x+.5)/W, (y+.5)/H) of true NDC is taken back to the world with
 * the inverse of worldToNDC, giving a world point p1 on the pixel's ray from
 * the eye (the origin of camera space taken to the world with the inverse of
 * worldToCamera). The surface is where the camera-space z along that ray
 * equals the stored planar Z. */
static void geom_from_header(const char *path, const float *Z, geom_t *g)
{
    exr_context_t f;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    assert_int_equal(exr_start_read(&f, path, &init), 0);
    exr_attr_m44f_t wc, wn;
    exr_attr_box2i_t disp, dw;
    assert_int_equal(exr_attr_get_m44f(f, 0, "worldToCamera", &wc), 0);
    assert_int_equal(exr_attr_get_m44f(f, 0, "worldToNDC", &wn), 0);
    assert_int_equal(exr_get_display_window(f, 0, &disp), 0);
    assert_int_equal(exr_get_data_window(f, 0, &dw), 0);
    exr_finish(&f);
    double W2C[16], W2N[16], C2W[16], N2W[16];
    for (int i = 0; i < 16; ++i) {
        W2C[i] = wc.m[i];
        W2N[i] = wn.m[i];
    }
    assert_int_equal(inv4(W2C, C2W), 0);
    assert_int_equal(inv4(W2N, N2W), 0);
    const double o[4] = { 0, 0, 0, 1 };
    double e[4];
    xform4(o, C2W, e);
    const double W = disp.max.x - disp.min.x + 1.0, H = disp.max.y - disp.min.y + 1.0;
    const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    geom_alloc(g, w, h);
    for (int j = 0; j < 3; ++j)
        g->eye[j] = e[j] / e[3];
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const size_t i = (size_t) y * (size_t) w + (size_t) x;
            const int px = dw.min.x + x, py = dw.min.y + y;
            const double ndc[4] = { (px - disp.min.x + 0.5) / W, (py - disp.min.y + 0.5) / H, 0.5, 1 };
            double p1[4], pc[4];
            xform4(ndc, N2W, p1);
            for (int j = 0; j < 3; ++j)
                p1[j] /= p1[3];
            p1[3] = 1;
            /* Sanity: p1 projects back onto the pixel centre. */
            double back[4];
            xform4(p1, W2N, back);
            assert_true(fabs(back[0] / back[3] - ndc[0]) < 1e-6);
            assert_true(fabs(back[1] / back[3] - ndc[1]) < 1e-6);
            xform4(p1, W2C, pc);
            const double zc = pc[2] / pc[3];
            assert_true(zc > 0);
            double len = 0;
            for (int j = 0; j < 3; ++j)
                len += (p1[j] - g->eye[j]) * (p1[j] - g->eye[j]);
            len = sqrt(len);
            /* The eye has camera z 0, so z is linear in t along eye + t (p1 - eye). */
            g->k[i] = len / zc;
            g->sky[i] = (unsigned char) is_sky(Z[i]);
            g->z[i] = g->sky[i] ? INFINITY : Z[i];
            g->d[i] = g->sky[i] ? INFINITY : Z[i] * g->k[i];
        }
}

/* Geometry of a synthetic frame: identity worldToCamera, horizontal fov,
 * square pixels, display window = data window at the origin. The ray of
 * pixel (x, y) is (t (2u - 1), t (1 - 2v) H/W, 1) with t = tan(fov/2). */
static void geom_from_fov(int w, int h, double fov_deg, const float *Z, geom_t *g)
{
    const double t = tan(fov_deg * 3.14159265358979323846 / 360.0);
    geom_alloc(g, w, h);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const size_t i = (size_t) y * (size_t) w + (size_t) x;
            const double dx = t * (2.0 * (x + 0.5) / w - 1.0);
            const double dy = t * (1.0 - 2.0 * (y + 0.5) / h) * h / w;
            g->k[i] = sqrt(dx * dx + dy * dy + 1.0);
            g->sky[i] = (unsigned char) is_sky(Z[i]);
            g->z[i] = g->sky[i] ? INFINITY : Z[i];
            g->d[i] = g->sky[i] ? INFINITY : Z[i] * g->k[i];
        }
}

enum { M_EXP, M_EXP2, M_LINEAR };
enum { SKY_FOG, SKY_KEEP, SKY_DIST };

typedef struct comp_t {
    int model;
    double rho[3];
    double start, end;
    int planar;
} comp_t;

typedef struct fog_t {
    int n;
    comp_t c[4];
    double F[3];
    int sky;
    double sky_d;
} fog_t;

/* Optical depth of the components for a surface at distance d (planar z);
 * d and z may be infinite. glFog: exp f = e^(-D z), exp2 f = e^(-(D z)^2),
 * linear f = (end - z)/(end - start) clamped; tau = -ln f. */
static void tau_of(const fog_t *f, double d, double z, double tau[3])
{
    tau[0] = tau[1] = tau[2] = 0;
    for (int i = 0; i < f->n; ++i) {
        const comp_t *c = &f->c[i];
        const double s = c->planar ? z : d;
        for (int k = 0; k < 3; ++k) {
            double t;
            if (c->model == M_LINEAR) {
                double lin = (c->end - s) / (c->end - c->start);
                t = s <= c->start ? 0 : s >= c->end ? INFINITY : -log(lin);
            } else {
                double x = c->rho[k] == 0 ? 0 : c->rho[k] * s;
                t = c->model == M_EXP ? x : x * x;
            }
            tau[k] += t;
        }
    }
}

/* The composite of the contract for one pixel:
 *   out.rgb   = T in + (1 - T) a F + (1 - a)(1 - Tinf) F
 *   out.alpha = a + (1 - a)(1 - Tinf)
 * with --sky keep leaving sky pixels alone and dropping the last term. */
static void expect_pixel(const fog_t *f, const geom_t *g, size_t i, const float in[4], double out[4])
{
    double T[3], Tinf[3], tau[3];
    const double a = in[3];
    if (g->sky[i]) {
        if (f->sky == SKY_KEEP) {
            for (int k = 0; k < 4; ++k)
                out[k] = in[k];
            return;
        }
        if (f->sky == SKY_DIST)
            tau_of(f, f->sky_d, f->sky_d / g->k[i], tau);
        else
            tau_of(f, INFINITY, INFINITY, tau);
        for (int k = 0; k < 3; ++k)
            T[k] = Tinf[k] = exp(-tau[k]);
    } else {
        tau_of(f, g->d[i], g->z[i], tau);
        for (int k = 0; k < 3; ++k)
            T[k] = exp(-tau[k]);
        if (f->sky == SKY_DIST) {
            /* The background is a surface at sky_d along each ray. */
            double dd = fmax(f->sky_d, g->d[i]);
            tau_of(f, dd, dd / g->k[i], tau);
        } else {
            tau_of(f, INFINITY, INFINITY, tau);
        }
        for (int k = 0; k < 3; ++k)
            Tinf[k] = exp(-tau[k]);
    }
    double cover = 0;
    for (int k = 0; k < 3; ++k) {
        out[k] = T[k] * in[k] + (1 - T[k]) * a * f->F[k];
        if (f->sky != SKY_KEEP)
            out[k] += (1 - a) * (1 - Tinf[k]) * f->F[k];
        cover += (1 - Tinf[k]) / 3;
    }
    out[3] = f->sky == SKY_KEEP ? a : a + (1 - a) * cover;
}

typedef struct img_t {
    int w, h;
    float *c[5]; /* R G B A Z */
} img_t;

static void img_read(const char *path, img_t *im, int with_z)
{
    static const char *const names[5] = { "R", "G", "B", "A", "Z" };
    memset(im, 0, sizeof *im);
    for (int k = 0; k < (with_z ? 5 : 4); ++k) {
        int w, h;
        im->c[k] = tu_read_channel(path, 0, names[k], &w, &h);
        if (!im->c[k])
            fail_msg("cannot read channel %s of %s", names[k], path);
        im->w = w;
        im->h = h;
    }
}

static void img_free(img_t *im)
{
    for (int k = 0; k < 5; ++k)
        free(im->c[k]);
}

/* Every pixel of out against the reference. Returns the number of
 * channel values out of tolerance (rel * |expected| + abs). */
static long compare_all(const fog_t *f, const geom_t *g, const img_t *in, const img_t *out,
                        double rel, double abs_tol)
{
    long bad = 0;
    assert_int_equal(in->w, out->w);
    assert_int_equal(in->h, out->h);
    for (int y = 0; y < in->h; ++y)
        for (int x = 0; x < in->w; ++x) {
            const size_t i = (size_t) y * (size_t) in->w + (size_t) x;
            float px[4];
            double e[4];
            for (int k = 0; k < 4; ++k)
                px[k] = in->c[k][i];
            expect_pixel(f, g, i, px, e);
            for (int k = 0; k < 4; ++k) {
                double o = out->c[k][i];
                if (!(fabs(o - e[k]) <= rel * fabs(e[k]) + abs_tol)) {
                    if (bad < 8)
                        print_message("pixel (%d,%d) ch %d: got %.9g expected %.9g (in %.9g a %.9g "
                                      "Z %.9g d %.9g sky %d)\n",
                                      x, y, k, o, e[k], (double) px[k], (double) px[3],
                                      in->c[4] ? (double) in->c[4][i] : 0.0, g->d[i], g->sky[i]);
                    ++bad;
                }
            }
        }
    return bad;
}

/* Fogs the sample with args and checks every pixel (half tolerance). */
static void e2e(const char *args, const fog_t *f, int check_sky_unchanged)
{
    path_t dir = fresh_dir("e2e");
    path_t out = pth("e2e/out.exr");
    size_t inlen;
    unsigned char *inb = sample_bytes(&inlen);
    int st = run("--threads 2 %s '%s' -o '%s'", args, sample(), out.s);
    assert_no_crash();
    assert_status(st, 0);
    assert_true(same_bytes(sample(), inb, inlen));
    free(inb);
    assert_int_equal(dir_count(dir.s), 1);

    img_t in, o;
    geom_t g;
    img_read(sample(), &in, 1);
    img_read(out.s, &o, 1);
    geom_from_header(sample(), in.c[4], &g);
    assert_int_equal(g.w, in.w);
    long nsky = 0;
    for (size_t i = 0; i < (size_t) in.w * (size_t) in.h; ++i)
        nsky += g.sky[i];
    /* The sample has both sky and geometry. */
    assert_true(nsky > 1000 && nsky < (long) in.w * in.h - 1000);
    long bad = compare_all(f, &g, &in, &o, 2e-3, 1e-5);
    if (bad) {
        geom_free(&g);
        img_free(&in);
        img_free(&o);
        fail_msg("%ld channel values differ from the reference (%s)", bad, args);
    }
    /* Depth passes through untouched. */
    assert_memory_equal(in.c[4], o.c[4], sizeof(float) * (size_t) in.w * (size_t) in.h);
    if (check_sky_unchanged)
        for (size_t i = 0; i < (size_t) in.w * (size_t) in.h; ++i) {
            if (g.sky[i])
                for (int k = 0; k < 3; ++k)
                    assert_true(o.c[k][i] == in.c[k][i]);
            assert_true(o.c[3][i] == in.c[3][i]);
        }
    geom_free(&g);
    img_free(&in);
    img_free(&o);
}

/* ============================================================ bad files */

static void test_missing_input(void **state)
{
    (void) state;
    path_t dir = fresh_dir("missing");
    path_t in = pth("missing/no-such-file.exr"), out = pth("missing/out.exr");
    check_failure(1, NULL, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    /* A missing --depth file is named too. */
    check_failure(1, sample(), dir.s, "'%s' --depth '%s' -o '%s' --fog exp:density=0.1", sample(),
                  in.s, out.s);
    assert_error_line(in.s);
    /* A directory is not an image. */
    check_failure(1, NULL, dir.s, "'%s' -o '%s' --fog exp:density=0.1", dir.s, out.s);
    assert_error_line(dir.s);
}

/* Cuts a copy of the sample to n bytes and runs it with one thread. */
static int run_truncated(size_t n, const char *name)
{
    size_t len;
    unsigned char *d = sample_bytes(&len);
    path_t dir = fresh_dir("trunc");
    path_t in = pth("trunc-%s.exr", name), out = pth("trunc/out.exr");
    assert_true(n < len);
    spit(in.s, d, n);
    free(d);
    int st = check_failure(1, in.s, dir.s, "--threads 1 '%s' -o '%s' --fog exp:density=0.1", in.s,
                           out.s);
    assert_error_line(NULL);
    unlink(in.s);
    return st;
}

static void test_truncated_in_header(void **state)
{
    (void) state;
    size_t len;
    layout_t L;
    unsigned char *d = sample_bytes(&len);
    exr_layout(d, len, &L);
    free(d);
    const size_t cuts[] = { 3, 8, 10, 100, L.header_end / 2, L.header_end - 1 };
    for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; ++i) {
        char name[32];
        snprintf(name, sizeof name, "h%zu", cuts[i]);
        run_truncated(cuts[i], name);
        /* The header is read before anything else: the input is named. */
        path_t in = pth("trunc-%s.exr", name);
        assert_error_line(in.s);
    }
}

static void test_truncated_in_offset_table(void **state)
{
    (void) state;
    size_t len;
    layout_t L;
    unsigned char *d = sample_bytes(&len);
    exr_layout(d, len, &L);
    free(d);
    const size_t cuts[] = { L.header_end, L.header_end + 1, L.header_end + 8 * (size_t) (L.nchunks / 2) + 3,
                            L.header_end + 8 * (size_t) L.nchunks - 1 };
    for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; ++i) {
        char name[32];
        snprintf(name, sizeof name, "t%zu", cuts[i]);
        run_truncated(cuts[i], name);
        assert_err_has("truncated or corrupt");
    }
}

static void test_truncated_in_pixel_data(void **state)
{
    (void) state;
    size_t len;
    layout_t L;
    unsigned char *d = sample_bytes(&len);
    exr_layout(d, len, &L);
    const int k = L.nchunks / 2, last = L.nchunks - 1;
    const int yk = (int) rd32(d + L.off[k]), ylast = (int) rd32(d + L.off[last]);
    const uint32_t szk = rd32(d + L.off[k] + 4);
    free(d);
    struct { size_t cut; int y; } cases[] = {
        { (size_t) L.off[0] + 2, 0 },                 /* inside the first chunk's leader */
        { (size_t) L.off[k] + 6, yk },                /* inside chunk k's leader */
        { (size_t) L.off[k] + 8 + szk / 2, yk },      /* in the middle of chunk k's data */
        { len - 10, ylast },                          /* in the last chunk */
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        char name[32], where[64];
        snprintf(name, sizeof name, "p%zu", cases[i].cut);
        run_truncated(cases[i].cut, name);
        /* It fails at the chunk that is cut, not before, not with a crash. */
        snprintf(where, sizeof where, "scanline %d", cases[i].y);
        assert_err_has(where);
    }
}

/* An uncompressed copy of the sample (written by exrfog, no fog), one
 * scanline per chunk. */
static const char *sample_none(void)
{
    static path_t p;
    if (!p.s[0]) {
        p = pth("in/sample-none.exr");
        assert_status(run("'%s' -o '%s' --compression none --fog exp:density=0", sample(), p.s), 0);
    }
    return p.s;
}

/* Writes a corrupted copy of src (the sample when NULL): fn edits the bytes. */
static void corrupt_case_in(const char *src, const char *name,
                            void (*fn)(unsigned char *, size_t, const layout_t *, int *),
                            int threads)
{
    size_t len;
    layout_t L;
    unsigned char *d = src ? slurp(src, &len) : sample_bytes(&len);
    assert_non_null(d);
    exr_layout(d, len, &L);
    int y = -1;
    fn(d, len, &L, &y);
    path_t dir = fresh_dir("corrupt");
    path_t in = pth("corrupt-%s.exr", name), out = pth("corrupt/out.exr");
    spit(in.s, d, len);
    free(d);
    check_failure(1, in.s, dir.s, "--threads %d '%s' -o '%s' --fog exp:density=0.1", threads, in.s,
                  out.s);
    assert_error_line(NULL);
    if (threads == 1 && y >= 0) {
        char where[64];
        snprintf(where, sizeof where, "scanline %d", y);
        assert_err_has(where);
    }
    unlink(in.s);
}

static void corrupt_case(const char *name, void (*fn)(unsigned char *, size_t, const layout_t *, int *),
                         int threads)
{
    corrupt_case_in(NULL, name, fn, threads);
}

static void garbage_in_chunk(unsigned char *d, size_t len, const layout_t *L, int *y)
{
    const int k = L->nchunks / 2;
    const size_t o = (size_t) L->off[k];
    const uint32_t sz = rd32(d + o + 4);
    uint32_t s = 12345;
    assert_true(o + 8 + sz <= len && sz > 200);
    for (size_t i = 0; i < 64; ++i) {
        s = s * 1103515245u + 12345u;
        d[o + 8 + sz / 2 + i] = (unsigned char) (s >> 16);
    }
    *y = (int) rd32(d + o);
}

static void huge_chunk_size(unsigned char *d, size_t len, const layout_t *L, int *y)
{
    (void) len;
    const size_t o = (size_t) L->off[L->nchunks / 2];
    wr32(d + o + 4, 0x7fffffffu);
    *y = (int) rd32(d + o);
}

static void negative_chunk_size(unsigned char *d, size_t len, const layout_t *L, int *y)
{
    (void) len;
    const size_t o = (size_t) L->off[L->nchunks / 2];
    wr32(d + o + 4, (uint32_t) -5);
    *y = (int) rd32(d + o);
}

static void short_chunk_size(unsigned char *d, size_t len, const layout_t *L, int *y)
{
    (void) len;
    const size_t o = (size_t) L->off[L->nchunks / 2];
    wr32(d + o + 4, 100);
    *y = (int) rd32(d + o);
}

static void wrong_chunk_y(unsigned char *d, size_t len, const layout_t *L, int *y)
{
    (void) len;
    const size_t o = (size_t) L->off[L->nchunks / 2];
    *y = (int) rd32(d + o);
    wr32(d + o, 1000);
}

static void long_chunk_size(unsigned char *d, size_t len, const layout_t *L, int *y)
{
    (void) len;
    const size_t o = (size_t) L->off[L->nchunks / 2];
    wr32(d + o + 4, rd32(d + o + 4) + 8);
    *y = (int) rd32(d + o);
}

/* The same damage to an uncompressed file, whose chunks exrfog reads whole:
 * a stored size other than the chunk's pixels is a corrupt chunk, at its
 * scanline (OpenEXRCore's own per-channel reads went by the geometry and
 * took the neighbouring chunk's bytes as pixels). */
static void test_corrupt_uncompressed_chunk(void **state)
{
    (void) state;
    corrupt_case_in(sample_none(), "none-hugesize", huge_chunk_size, 1);
    corrupt_case_in(sample_none(), "none-negsize", negative_chunk_size, 1);
    corrupt_case_in(sample_none(), "none-shortsize", short_chunk_size, 1);
    corrupt_case_in(sample_none(), "none-longsize", long_chunk_size, 1);
    corrupt_case_in(sample_none(), "none-longsize2", long_chunk_size, 2);
    corrupt_case_in(sample_none(), "none-wrongy", wrong_chunk_y, 1);
    /* And through OpenEXRCore's own unpacking (no F16C path). */
    assert_int_equal(setenv("EXRFOG_F16C", "0", 1), 0);
    corrupt_case_in(sample_none(), "none-shortsize-core", short_chunk_size, 1);
    unsetenv("EXRFOG_F16C");
}

static void test_corrupt_chunk(void **state)
{
    (void) state;
    /* ZIP data with garbage in the middle: zlib must reject it. */
    corrupt_case("garbage", garbage_in_chunk, 1);
    corrupt_case("garbage2", garbage_in_chunk, 2);
    /* The chunk's size and scanline fields. */
    corrupt_case("hugesize", huge_chunk_size, 1);
    corrupt_case("negsize", negative_chunk_size, 1);
    corrupt_case("shortsize", short_chunk_size, 1);
    corrupt_case("wrongy", wrong_chunk_y, 1);
}

/* An offset-table entry pointing past the end: OpenEXRCore may rebuild the
 * table from the chunk leaders. Either way: a clean success with the right
 * pixels, or a clean failure. */
static void test_corrupt_offset_table(void **state)
{
    (void) state;
    size_t len;
    layout_t L;
    unsigned char *d = sample_bytes(&len);
    exr_layout(d, len, &L);
    const size_t e = L.header_end + 8 * (size_t) (L.nchunks / 2);
    wr32(d + e, 0xd4a51000u);
    wr32(d + e + 4, 0xe8u); /* 1e12 */
    path_t dir = fresh_dir("offtab");
    path_t in = pth("offtab.exr"), out = pth("offtab/out.exr"), ref = pth("offtab-ref.exr");
    spit(in.s, d, len);
    int st = run("--threads 2 '%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_no_crash();
    assert_true(same_bytes(in.s, d, len));
    free(d);
    if (st == 0) {
        assert_status(run("--threads 2 '%s' -o '%s' --fog exp:density=0.1", sample(), ref.s), 0);
        img_t a, b;
        img_read(out.s, &a, 1);
        img_read(ref.s, &b, 1);
        for (int k = 0; k < 5; ++k)
            assert_memory_equal(a.c[k], b.c[k], sizeof(float) * (size_t) a.w * (size_t) a.h);
        img_free(&a);
        img_free(&b);
        unlink(ref.s);
    } else {
        assert_status(st, 1);
        assert_error_line(NULL);
        assert_int_equal(dir_count(dir.s), 0);
    }
    unlink(in.s);
}

static void test_not_exr(void **state)
{
    (void) state;
    path_t dir = fresh_dir("notexr");
    path_t out = pth("notexr/out.exr");
    static const char text[] = "This is a text file, not an image.\n";
    static const unsigned char png[] = { 0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0, 13,
                                         'I', 'H', 'D', 'R', 0, 0, 2, 0x80, 0, 0, 1, 0x68, 8, 2, 0, 0, 0 };
    static const unsigned char shorty[] = { 0x76, 0x2f, 0x31 };
    /* The right magic number followed by rubbish. */
    unsigned char fake[256];
    for (size_t i = 0; i < sizeof fake; ++i)
        fake[i] = (unsigned char) (i * 37 + 11);
    fake[0] = 0x76, fake[1] = 0x2f, fake[2] = 0x31, fake[3] = 0x01;
    struct { const char *name; const void *data; size_t len; } cases[] = {
        { "text.exr", text, sizeof text - 1 },
        { "png.exr", png, sizeof png },
        { "short.exr", shorty, sizeof shorty },
        { "fake.exr", fake, sizeof fake },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        path_t in = pth("%s", cases[i].name);
        spit(in.s, cases[i].data, cases[i].len);
        check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
        assert_error_line(in.s);
        assert_err_has("EXR");
        unlink(in.s);
    }
}

static void test_zero_size(void **state)
{
    (void) state;
    path_t dir = fresh_dir("empty");
    path_t in = pth("empty.exr"), out = pth("empty/out.exr");
    spit(in.s, "", 0);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("empty");
    /* As a --depth file too. */
    check_failure(1, sample(), dir.s, "'%s' --depth '%s' -o '%s' --fog exp:density=0.1", sample(),
                  in.s, out.s);
    assert_error_line(in.s);
    unlink(in.s);
}

/* A small valid file whose dataWindow box2i is patched to (x0,y0)-(x1,y1). */
static void write_patched_window(const char *path, int x0, int y0, int x1, int y1)
{
    frame_t f;
    tu_part p;
    frame_alloc(&f, 8, 4);
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    add_camera(&p, 60);
    write_part(path, &p);
    frame_free(&f);
    size_t len;
    uint32_t sz = 0;
    unsigned char *d = slurp(path, &len);
    size_t v = find_attr(d, len, "dataWindow", "box2i", &sz);
    assert_true(v > 0);
    assert_int_equal(sz, 16);
    wr32(d + v, (uint32_t) x0);
    wr32(d + v + 4, (uint32_t) y0);
    wr32(d + v + 8, (uint32_t) x1);
    wr32(d + v + 12, (uint32_t) y1);
    spit(path, d, len);
    free(d);
}

static void test_absurd_dimensions(void **state)
{
    (void) state;
    path_t dir = fresh_dir("absurd");
    path_t in = pth("absurd.exr"), out = pth("absurd/out.exr");
    /* 300001 x 10: above exrfog's cap (262144), below OpenEXRCore's own limit. */
    write_patched_window(in.s, 0, 0, 300000, 9);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("262144");
    write_patched_window(in.s, 0, 0, 9, 300000);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("262144");
    unlink(in.s);
}

/* A dataWindow of (0,0)-(2000000000,10) is refused by OpenEXRCore itself
 * inside exr_start_read; the message must still state exrfog's cap. */
static void test_absurd_dimensions_huge(void **state)
{
    (void) state;
    path_t dir = fresh_dir("absurd2");
    path_t in = pth("absurd2.exr"), out = pth("absurd2/out.exr");
    write_patched_window(in.s, 0, 0, 2000000000, 10);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("262144");
    unlink(in.s);
}

/* Colour in one file, depth in another with a different data window. */
static void test_depth_window_mismatch(void **state)
{
    (void) state;
    path_t dir = fresh_dir("mismatch");
    path_t col = pth("mm-colour.exr"), dep = pth("mm-depth.exr"), dep2 = pth("mm-depth2.exr"),
           ok = pth("mm-depth-ok.exr"), out = pth("mismatch/out.exr");
    frame_t f;
    tu_part p;
    frame_alloc(&f, 16, 8);
    frame_part(&p, &f, 0x0f, EXR_PIXEL_FLOAT);
    add_camera(&p, 90);
    write_part(col.s, &p);
    /* 16 x 4 depth. */
    frame_t fd;
    frame_alloc(&fd, 16, 4);
    frame_part(&p, &fd, 0x10, EXR_PIXEL_FLOAT);
    write_part(dep.s, &p);
    size_t dlen;
    unsigned char *db = slurp(dep.s, &dlen);
    check_failure(1, col.s, dir.s, "'%s' --depth '%s' -o '%s' --fog exp:density=0.1", col.s, dep.s,
                  out.s);
    assert_error_line(NULL);
    assert_err_has("(0,0)-(15,3)");
    assert_err_has("(0,0)-(15,7)");
    assert_true(same_bytes(dep.s, db, dlen));
    free(db);
    /* Same size, shifted: (2,0)-(17,7). */
    frame_part(&p, &f, 0x10, EXR_PIXEL_FLOAT);
    p.dw[0] = 2;
    p.dw[2] = 17;
    write_part(dep2.s, &p);
    check_failure(1, col.s, dir.s, "'%s' --depth '%s' -o '%s' --fog exp:density=0.1", col.s, dep2.s,
                  out.s);
    assert_error_line(NULL);
    assert_err_has("(2,0)-(17,7)");
    assert_err_has("(0,0)-(15,7)");
    /* Control: a matching depth file works and is used. */
    frame_part(&p, &f, 0x10, EXR_PIXEL_FLOAT);
    write_part(ok.s, &p);
    assert_status(run("'%s' --depth '%s' -o '%s' --fog exp:density=0.1 --fog-color 0.5,0.6,0.7",
                      col.s, ok.s, out.s),
                  0);
    img_t in, o;
    geom_t g;
    img_read(col.s, &in, 0);
    img_read(out.s, &o, 0);
    geom_from_fov(16, 8, 90, f.c[4], &g);
    fog_t fog = { 1, { { M_EXP, { 0.1, 0.1, 0.1 }, 0, 0, 0 } }, { 0.5, 0.6, 0.7 }, SKY_FOG, 0 };
    assert_int_equal(compare_all(&fog, &g, &in, &o, 1e-5, 1e-6), 0);
    geom_free(&g);
    img_free(&in);
    img_free(&o);
    frame_free(&f);
    frame_free(&fd);
    unlink(col.s);
    unlink(dep.s);
    unlink(dep2.s);
    unlink(ok.s);
}

/* A --depth file cut in its pixel data: a clean failure at that chunk. */
static void test_truncated_depth_file(void **state)
{
    (void) state;
    path_t dir = fresh_dir("cutdepth");
    path_t col = pth("cd-colour.exr"), dep = pth("cd-depth.exr"), out = pth("cutdepth/out.exr");
    frame_t f;
    tu_part p;
    frame_alloc(&f, 16, 64);
    for (int i = 0; i < 16 * 64; ++i)
        f.c[4][i] = 1.0f + (float) ((i * 7919) % 1000) * 0.37f;
    frame_part(&p, &f, 0x0f, EXR_PIXEL_FLOAT);
    add_camera(&p, 90);
    write_part(col.s, &p);
    frame_part(&p, &f, 0x10, EXR_PIXEL_FLOAT);
    write_part(dep.s, &p);
    frame_free(&f);
    size_t len;
    layout_t L;
    unsigned char *d = slurp(dep.s, &len);
    exr_layout(d, len, &L);
    assert_true(L.nchunks >= 3);
    const int y = (int) rd32(d + L.off[2]);
    spit(dep.s, d, (size_t) L.off[2] + 8 + rd32(d + L.off[2] + 4) / 2);
    check_failure(1, col.s, dir.s, "--threads 1 '%s' --depth '%s' -o '%s' --fog exp:density=0.1",
                  col.s, dep.s, out.s);
    assert_error_line(NULL);
    assert_err_has("depth");
    char where[64];
    snprintf(where, sizeof where, "scanline %d", y);
    assert_err_has(where);
    /* The depth file is not modified either. */
    assert_true(same_bytes(dep.s, d, (size_t) L.off[2] + 8 + rd32(d + L.off[2] + 4) / 2));
    free(d);
    unlink(col.s);
    unlink(dep.s);
}

/* Non-finite and non-positive depth is sky: fogged to infinity. For exp
 * fog on an opaque pixel that is exactly the fog colour. */
static void test_nan_inf_depth(void **state)
{
    (void) state;
    path_t dir = fresh_dir("nandepth");
    path_t in = pth("nandepth.exr"), out = pth("nandepth/out.exr");
    frame_t f;
    tu_part p;
    frame_alloc(&f, 12, 6);
    const float bad[] = { NAN, INFINITY, -INFINITY, 0.0f, -3.0f, 2e9f, -NAN };
    size_t nb = sizeof bad / sizeof bad[0];
    for (size_t i = 0; i < nb; ++i) {
        f.c[4][3 * i] = bad[i];
        f.c[4][3 * i + 40] = bad[i];
    }
    frame_part(&p, &f, 0x1f, EXR_PIXEL_FLOAT);
    add_camera(&p, 75);
    write_part(in.s, &p);
    size_t len;
    unsigned char *ib = slurp(in.s, &len);
    assert_status(run("--threads 2 '%s' -o '%s' --fog exp:density=0.3 --fog-color 0.5,0.6,0.7", in.s,
                      out.s),
                  0);
    assert_no_crash();
    assert_true(same_bytes(in.s, ib, len));
    free(ib);
    assert_int_equal(dir_count(dir.s), 1);
    img_t a, o;
    geom_t g;
    img_read(in.s, &a, 1);
    img_read(out.s, &o, 1);
    geom_from_fov(12, 6, 75, a.c[4], &g);
    const float F[3] = { 0.5f, 0.6f, 0.7f };
    for (size_t i = 0; i < nb; ++i)
        for (size_t j = 0; j < 2; ++j) {
            size_t px = 3 * i + 40 * j;
            assert_true(g.sky[px]);
            for (int k = 0; k < 3; ++k)
                if (o.c[k][px] != F[k])
                    fail_msg("sky pixel %zu (Z=%g) channel %d is %.9g, not the fog colour %.9g", px,
                             (double) a.c[4][px], k, (double) o.c[k][px], (double) F[k]);
            assert_true(o.c[3][px] == 1.0f);
        }
    fog_t fog = { 1, { { M_EXP, { 0.3, 0.3, 0.3 }, 0, 0, 0 } }, { 0.5, 0.6, 0.7 }, SKY_FOG, 0 };
    assert_int_equal(compare_all(&fog, &g, &a, &o, 1e-5, 1e-6), 0);
    /* Depth passes through, NaN and all (compare bits). */
    assert_memory_equal(a.c[4], o.c[4], sizeof(float) * 72);
    geom_free(&g);
    img_free(&a);
    img_free(&o);
    frame_free(&f);
    unlink(in.s);
}

static void test_nan_in_camera(void **state)
{
    (void) state;
    path_t dir = fresh_dir("nancam");
    path_t in = pth("nancam.exr"), out = pth("nancam/out.exr");
    frame_t f;
    tu_part p;
    frame_alloc(&f, 8, 4);
    /* worldToCamera with a NaN. */
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    add_camera(&p, 60);
    p.m44[0].m[5] = NAN;
    write_part(in.s, &p);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("worldToCamera");
    /* ... and an infinite translation. */
    p.m44[0].m[5] = 1;
    p.m44[0].m[13] = INFINITY;
    write_part(in.s, &p);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("worldToCamera");
    /* A valid worldToCamera with a worldToNDC holding Inf. */
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    add_camera(&p, 60);
    p.m44[1].name = "worldToNDC";
    memcpy(p.m44[1].m, ID16, sizeof ID16);
    p.m44[1].m[0] = INFINITY;
    write_part(in.s, &p);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("worldToNDC");
    /* CameraFov NaN. */
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    add_camera(&p, NAN);
    write_part(in.s, &p);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("CameraFov");
    frame_free(&f);
    unlink(in.s);
}

static void test_no_camera(void **state)
{
    (void) state;
    path_t dir = fresh_dir("nocam");
    path_t in = pth("nocam.exr"), in2 = pth("nocam2.exr"), out = pth("nocam/out.exr");
    frame_t f;
    tu_part p;
    frame_alloc(&f, 8, 4);
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    write_part(in.s, &p);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("--world-to-camera");
    assert_err_has("--camera-to-world");
    assert_err_has("--fov");
    assert_err_has("none");
    /* A header with a lens but no pose: the message lists what it has. */
    p.f[0].name = "CameraFov";
    p.f[0].v = 50;
    p.m44[0].name = "worldToNDC";
    memcpy(p.m44[0].m, ID16, sizeof ID16);
    write_part(in2.s, &p);
    check_failure(1, in2.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in2.s, out.s);
    assert_error_line(in2.s);
    assert_err_has("CameraFov");
    assert_err_has("worldToNDC");
    assert_err_has("--world-to-camera");
    assert_err_has("--camera-to-world");
    assert_err_has("--fov");
    /* --fov alone is no pose. */
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1 --fov 60", in.s, out.s);
    assert_error_line(in.s);
    /* A pose alone is no lens. */
    check_failure(1, in.s, dir.s,
                  "'%s' -o '%s' --fog exp:density=0.1 --camera-to-world 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1",
                  in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("--fov");
    /* The flags the message names fix it. */
    assert_status(run("'%s' -o '%s' --fog exp:density=0.1 --camera-to-world "
                      "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 90",
                      in.s, out.s),
                  0);
    assert_true(tu_exists(out.s));
    frame_free(&f);
    unlink(in.s);
    unlink(in2.s);
}

static void test_output_dir_missing(void **state)
{
    (void) state;
    path_t dir = fresh_dir("nodir");
    path_t out = pth("nodir/not/there/out.exr");
    check_failure(1, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.1", sample(), out.s);
    assert_error_line(out.s);
    assert_false(tu_exists(out.s));
    /* An OUTPUT that is a directory: refused as a usage error, the
     * directory is untouched. */
    path_t sub = pth("nodir/sub");
    assert_int_equal(mkdir(sub.s, 0777), 0);
    check_failure(2, sample(), dir.s, "--threads 2 '%s' -o '%s' --fog exp:density=0.1", sample(),
                  sub.s);
    assert_error_line(sub.s);
    assert_int_equal(dir_count(sub.s), 0);
}

/* Errors found while streaming (a corrupt or truncated chunk of INPUT, a
 * --depth file whose data window differs) name the file that is wrong,
 * never the OUTPUT that was not written. */
static void test_stream_errors_name_the_bad_file(void **state)
{
    (void) state;
    size_t len;
    layout_t L;
    unsigned char *d = sample_bytes(&len);
    exr_layout(d, len, &L);
    path_t dir = fresh_dir("naming");
    path_t in = pth("naming-cut.exr"), out = pth("naming/out.exr");
    /* Cut in the middle of the pixel data. */
    spit(in.s, d, (size_t) L.off[L.nchunks / 2] + 100);
    free(d);
    check_failure(1, in.s, dir.s, "--threads 1 '%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    unlink(in.s);

    /* A --depth file with another data window: the depth file is at fault. */
    path_t col = pth("naming-col.exr"), dep = pth("naming-dep.exr");
    frame_t f, fd;
    tu_part p;
    frame_alloc(&f, 16, 8);
    frame_alloc(&fd, 16, 4);
    frame_part(&p, &f, 0x0f, EXR_PIXEL_FLOAT);
    add_camera(&p, 90);
    write_part(col.s, &p);
    frame_part(&p, &fd, 0x10, EXR_PIXEL_FLOAT);
    write_part(dep.s, &p);
    check_failure(1, col.s, dir.s, "'%s' --depth '%s' -o '%s' --fog exp:density=0.1", col.s, dep.s,
                  out.s);
    assert_error_line(dep.s);
    frame_free(&f);
    frame_free(&fd);
    unlink(col.s);
    unlink(dep.s);
}

/* ============================================================ usage errors */

static void test_usage_errors(void **state)
{
    (void) state;
    path_t dir = fresh_dir("usage");
    path_t out = pth("usage/out.exr");
    const char *in = sample();
    /* Each: extra arguments after "IN -o OUT", and text stderr must quote. */
    static const struct { const char *args, *needle; } cases[] = {
        { "--fog fogg:density=1", "'fogg'" },
        { "--fog exp:dens=1", "'dens'" },
        { "--fog exp:density", "density" },
        { "--fog exp:density=", "density" },
        { "--fog exp", "density" },
        { "--fog exp:density=-1", "-1" },
        { "--fog exp:density=0.1,-0.2,0.1", "-0.2" },
        { "--fog exp:density=abc", "abc" },
        { "--fog exp2:density=-0.5", "-0.5" },
        { "--fog linear:start=10:end=5", "linear:start=10:end=5" },
        { "--fog linear:start=10", "end" },
        { "--fog exp:density=0.1:distance=sideways", "sideways" },
        { "--fog exp:density=0.1 --bogus", "--bogus" },
        { "--fog exp:density=0.1 -x", "-x" },
        { "", "--fog" },
        { "--fog exp:density=0.1 --depth-mode banana", "'banana'" },
        { "--fog exp:density=0.1 --compression lzw", "'lzw'" },
        { "--fog exp:density=0.1 --compression dwaa:0", "dwaa:0" },
        { "--fog exp:density=0.1 --compression dwab:x", "dwab:x" },
        { "--fog exp:density=0.1 --threads many", "'many'" },
        { "--fog exp:density=0.1 --threads -1", "'-1'" },
        { "--fog exp:density=0.1 --threads 3x", "'3x'" },
        { "--fog exp:density=0.1 --fov wide", "'wide'" },
        { "--fog exp:density=0.1 --fov 0", "'0'" },
        { "--fog exp:density=0.1 --fov 180", "'180'" },
        { "--fog exp:density=0.1 --fov -30", "'-30'" },
        { "--fog exp:density=0.1 --sky sometimes", "'sometimes'" },
        { "--fog exp:density=0.1 --sky distance=-3", "distance=-3" },
        { "--fog exp:density=0.1 --sky distance=", "distance=" },
        { "--fog exp:density=0.1 --world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0",
          "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0" },
        { "--fog exp:density=0.1 --camera-to-world 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0",
          "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0" },
        { "--fog exp:density=0.1 --world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1,7",
          "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1,7" },
        { "--fog exp:density=0.1 --world-to-camera 1,0,0,0,0,nan,0,0,0,0,1,0,0,0,0,1", "nan" },
        { "--fog exp:density=0.1 --fog-color 1,2", "'1,2'" },
        { "--fog exp:density=0.1 -d int", "'int'" },
        { "--fog exp:density=0.1 --near -1", "'-1'" },
        { "--fog exp:density=0.1 --near 5 --far 2", "--far" },
        { "--fog exp:density=0.1 extra.exr", "'extra.exr'" },
        { "--fog exp:density=0.1 --fog", "--fog" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        check_failure(2, in, dir.s, "'%s' -o '%s' %s", in, out.s, cases[i].args);
        if (!strstr(g_err, cases[i].needle))
            fail_msg("`%s`: stderr does not quote \"%s\":\n%s", cases[i].args, cases[i].needle, g_err);
    }
    /* No -o. */
    /* A name longer than any (--layer, --view, --preview-view, --colorspace,
     * --depth-channel) is refused abbreviated, its reason kept: 100 kB
     * filled the message and cut the reason off. */
    {
        static char big[2001];
        memset(big, 'x', sizeof big - 1);
        static const char *const opts[] = { "--layer", "--view", "--preview-view", "--colorspace",
                                            "--depth-channel" };
        for (size_t k = 0; k < sizeof opts / sizeof opts[0]; ++k) {
            check_failure(2, in, dir.s, "'%s' -o '%s' --fog exp:density=0.1 %s %s", in, out.s,
                          opts[k], big);
            assert_err_has("...(2000 bytes)' is longer than any name exrfog reads");
            assert_true(strlen(g_err) < 400);
        }
    }
    check_failure(2, in, dir.s, "'%s' --fog exp:density=0.1", in);
    assert_err_has("-o");
    /* -o without its value. */
    check_failure(2, in, dir.s, "'%s' --fog exp:density=0.1 -o", in);
    assert_err_has("-o");
    /* No INPUT. */
    check_failure(2, in, dir.s, "-o '%s' --fog exp:density=0.1", out.s);
    assert_err_has("INPUT");
    /* A usage error wins even with a bad input file: nothing is opened. */
    check_failure(2, NULL, dir.s, "'%s/none.exr' -o '%s' --fog fogg", dir.s, out.s);
    assert_err_has("'fogg'");
}

static void test_help_and_version(void **state)
{
    (void) state;
    assert_status(run("--help"), 0);
    assert_no_crash();
    assert_true(strncmp(g_out, "usage: exrfog", 13) == 0);
    assert_non_null(strstr(g_out, "--fog"));
    assert_non_null(strstr(g_out, "--explain"));
    assert_string_equal(g_err, "");
    assert_status(run("-h"), 0);
    assert_true(strncmp(g_out, "usage: exrfog", 13) == 0);
    assert_string_equal(g_err, "");
    /* --help wins over everything else and writes nothing. */
    path_t dir = fresh_dir("help");
    path_t out = pth("help/out.exr");
    assert_status(run("'%s' -o '%s' --fog exp:density=0.1 --help", sample(), out.s), 0);
    assert_int_equal(dir_count(dir.s), 0);
    assert_status(run("--version"), 0);
    assert_string_equal(g_err, "");
    int maj = -1, min = -1;
    assert_int_equal(sscanf(g_out, "exrfog %d.%d", &maj, &min), 2);
    assert_true(maj >= 0 && min >= 0);
    assert_non_null(strchr(g_out, '\n'));
}

/* ============================================================ safety */

static void test_output_is_input(void **state)
{
    (void) state;
    path_t dir = fresh_dir("inplace");
    path_t x = pth("inplace/x.exr"), ref = pth("inplace-ref.exr");
    assert_int_equal(tu_copy(sample(), x.s), 0);
    size_t len;
    unsigned char *orig = sample_bytes(&len);
    assert_status(run("--threads 2 '%s' -o '%s' --fog exp:density=0.02", x.s, x.s), 0);
    assert_no_crash();
    assert_false(same_bytes(x.s, orig, len));
    assert_int_equal(dir_count(dir.s), 1);
    assert_status(run("--threads 2 '%s' -o '%s' --fog exp:density=0.02", sample(), ref.s), 0);
    img_t a, b;
    img_read(x.s, &a, 1);
    img_read(ref.s, &b, 1);
    for (int k = 0; k < 5; ++k)
        assert_memory_equal(a.c[k], b.c[k], sizeof(float) * (size_t) a.w * (size_t) a.h);
    img_free(&a);
    /* A bare file name in the current directory (no '/' in OUTPUT). */
    assert_int_equal(tu_copy(sample(), x.s), 0);
    assert_status(run_in(dir.s, "--threads 2 x.exr -o x.exr --fog exp:density=0.02"), 0);
    assert_no_crash();
    assert_int_equal(dir_count(dir.s), 1);
    img_read(x.s, &a, 1);
    for (int k = 0; k < 5; ++k)
        assert_memory_equal(a.c[k], b.c[k], sizeof(float) * (size_t) a.w * (size_t) a.h);
    img_free(&a);
    img_free(&b);
    free(orig);
    unlink(ref.s);
}

/* An existing OUTPUT survives every kind of failed run. */
static void test_existing_output_untouched(void **state)
{
    (void) state;
    path_t dir = fresh_dir("keep");
    path_t out = pth("keep/out.exr"), txt = pth("keep-text.exr"), cut = pth("keep-cut.exr"),
           col = pth("keep-col.exr"), dep = pth("keep-dep.exr");
    assert_int_equal(tu_copy(sample(), out.s), 0);
    spit(txt.s, "not an exr\n", 11);
    size_t len;
    layout_t L;
    unsigned char *d = sample_bytes(&len);
    exr_layout(d, len, &L);
    spit(cut.s, d, (size_t) L.off[L.nchunks - 2] + 50);
    free(d);
    frame_t f, fd;
    tu_part p;
    frame_alloc(&f, 16, 8);
    frame_alloc(&fd, 16, 4);
    frame_part(&p, &f, 0x0f, EXR_PIXEL_FLOAT);
    add_camera(&p, 90);
    write_part(col.s, &p);
    frame_part(&p, &fd, 0x10, EXR_PIXEL_FLOAT);
    write_part(dep.s, &p);
    frame_free(&f);
    frame_free(&fd);

    /* check_failure verifies out.exr keeps its bytes and nothing is added. */
    check_failure(1, sample(), dir.s, "'%s' --depth '%s' -o '%s' --fog exp:density=0.1", sample(),
                  txt.s, out.s);
    check_failure(1, cut.s, dir.s, "--threads 2 '%s' -o '%s' --fog exp:density=0.1", cut.s, out.s);
    check_failure(1, col.s, dir.s, "'%s' --depth '%s' -o '%s' --fog exp:density=0.1", col.s, dep.s,
                  out.s);
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=-1", sample(), out.s);
    /* OUTPUT == INPUT and the input is bad. */
    path_t self = pth("keep/self.exr");
    assert_int_equal(tu_copy(cut.s, self.s), 0);
    check_failure(1, self.s, dir.s, "--threads 2 '%s' -o '%s' --fog exp:density=0.1", self.s, self.s);
    unlink(txt.s);
    unlink(cut.s);
    unlink(col.s);
    unlink(dep.s);
}

/* A frame big enough to be killed mid-run (written here: make_sample takes
 * tens of seconds under the sanitizers). */
static const char *big_frame(void)
{
    static path_t p;
    if (!p.s[0]) {
        const int w = 2048, h = 1152;
        frame_t f;
        tu_part part;
        frame_alloc(&f, w, h);
        /* Noise, so compression has real work to do. */
        uint32_t s = 1;
        for (size_t i = 0; i < (size_t) w * (size_t) h; ++i)
            for (int k = 0; k < 3; ++k) {
                s = s * 1664525u + 1013904223u;
                f.c[k][i] += (float) (s >> 8) * (1.0f / 16777216.0f) * 0.25f;
            }
        frame_part(&part, &f, 0x1f, EXR_PIXEL_HALF);
        add_camera(&part, 60);
        mkdir(pth("in").s, 0777);
        p = pth("in/big.exr");
        write_part(p.s, &part);
        frame_free(&f);
    }
    return p.s;
}

static void sleep_ms(long ms)
{
    struct timespec ts = { ms / 1000, (ms % 1000) * 1000000L };
    nanosleep(&ts, NULL);
}

/* Finds exrfog's temporary file for OUTPUT name in dir, written by pid:
 * .NAME.exrfog-PID-TAG.tmp with TAG 10 letters or digits (documented, so
 * that a stale one is recognisable). Returns 1 and its path. */
static int find_tmp(const char *dir, const char *name, long pid, char *buf, size_t cap)
{
    char head[600];
    snprintf(head, sizeof head, ".%s.exrfog-%ld-", name, pid);
    DIR *d = opendir(dir);
    struct dirent *e;
    int found = 0;
    while (d && !found && (e = readdir(d)) != NULL) {
        const size_t hn = strlen(head), n = strlen(e->d_name);
        if (n != hn + 14 || strncmp(e->d_name, head, hn) || strcmp(e->d_name + hn + 10, ".tmp"))
            continue;
        found = 1;
        for (size_t k = hn; k < hn + 10; ++k)
            found &= (e->d_name[k] >= 'a' && e->d_name[k] <= 'z') ||
                     (e->d_name[k] >= '0' && e->d_name[k] <= '9');
        if (found)
            snprintf(buf, cap, "%s/%s", dir, e->d_name);
    }
    if (d)
        closedir(d);
    return found;
}

/* Waits up to ms milliseconds for exrfog (pid) to create its temporary
 * file for name in dir (its path into tmp); fails the test when exrfog
 * ends first. Returns whether it appeared. */
static int await_tmp(const char *dir, const char *name, pid_t pid, int ms, char *tmp, size_t cap)
{
    int status = 0;
    for (int i = 0; i < ms; ++i) {
        if (find_tmp(dir, name, pid, tmp, cap))
            return 1;
        sleep_ms(1);
        if (waitpid(pid, &status, WNOHANG) == pid)
            fail_msg("exrfog finished (status %d) before it could be stopped", status);
    }
    return 0;
}

/* Starts exrfog on the big frame, waits for its temporary file to appear,
 * then sends sig. Checks OUTPUT is absent (or unchanged when preexisting),
 * and for catchable signals that no temporary file is left. */
static void kill_case(int sig, int preexisting)
{
    path_t dir = fresh_dir("kill");
    path_t out = pth("kill/out.exr");
    const char *in = big_frame();
    static const char keep[] = "precious earlier output\n";
    if (preexisting)
        spit(out.s, keep, sizeof keep - 1);
    size_t inlen;
    unsigned char *inb = slurp(in, &inlen);
    snap_t before;
    snap_take(dir.s, &before);

    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        execl(bin(), bin(), "--threads", "1", "--compression", "piz", in, "-o", out.s, "--fog",
              "exp:density=0.02", (char *) NULL);
        _exit(127);
    }
    char tmp[2200] = "";
    int status = 0;
    const int seen = await_tmp(dir.s, "out.exr", pid, 20000, tmp, sizeof tmp);
    if (!seen) {
        kill(pid, SIGKILL);
        waitpid(pid, &status, 0);
        fail_msg("the temporary file .out.exr.exrfog-%ld-*.tmp never appeared in %s", (long) pid, dir.s);
    }
    sleep_ms(20);
    if (waitpid(pid, &status, WNOHANG) == pid)
        fail_msg("exrfog finished (status %d) before it could be killed", status);
    assert_int_equal(kill(pid, sig), 0);
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFSIGNALED(status));
    assert_int_equal(WTERMSIG(status), sig);

    if (preexisting)
        assert_true(same_bytes(out.s, (const unsigned char *) keep, sizeof keep - 1));
    else
        assert_false(tu_exists(out.s));
    if (sig == SIGKILL)
        unlink(tmp); /* nothing can clean up after SIGKILL */
    snap_check(dir.s, &before);
    snap_free(&before);
    assert_true(same_bytes(in, inb, inlen));
    free(inb);
}

/* SIGINT during frame 3 of a sequence names frame 3's output (it named
 * frame 1's, the first output the run ever made); frames 1 and 2 stay
 * written, frame 3 is not. */
static void test_killed_sequence_names_frame(void **state)
{
    (void) state;
    path_t dir = fresh_dir("killseq");
    for (int f = 1; f <= 3; ++f) {
        path_t in = pth("killseq/in.%04d.exr", f);
        assert_int_equal(tu_copy(big_frame(), in.s), 0);
    }
    path_t in = pth("killseq/in.#.exr"), out = pth("killseq/out.#.exr");
    path_t err = pth("killseq.stderr");
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        const int fd = open(err.s, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fd < 0 || dup2(fd, 2) < 0)
            _exit(126);
        execl(bin(), bin(), "--threads", "1", "--compression", "piz", in.s, "-o", out.s, "--fog",
              "exp:density=0.02", (char *) NULL);
        _exit(127);
    }
    char tmp[2200] = "";
    int status = 0;
    assert_true(await_tmp(dir.s, "out.0003.exr", pid, 60000, tmp, sizeof tmp));
    sleep_ms(20);
    assert_int_equal(kill(pid, SIGINT), 0);
    assert_int_equal(waitpid(pid, &status, 0), pid);
    assert_true(WIFSIGNALED(status) && WTERMSIG(status) == SIGINT);
    size_t n;
    unsigned char *e = slurp(err.s, &n);
    assert_non_null(e);
    char text[4096];
    snprintf(text, sizeof text, "%.*s", (int) (n < sizeof text ? n : sizeof text - 1), e);
    free(e);
    assert_non_null(strstr(text, "out.0003.exr: stopped by SIGINT"));
    assert_null(strstr(text, "out.0001.exr"));
    assert_true(tu_exists(pth("killseq/out.0001.exr").s));
    assert_true(tu_exists(pth("killseq/out.0002.exr").s));
    assert_false(tu_exists(pth("killseq/out.0003.exr").s));
    assert_false(find_tmp(dir.s, "out.0003.exr", pid, tmp, sizeof tmp));
}

static void test_killed_run_sigterm(void **state)
{
    (void) state;
    kill_case(SIGTERM, 0);
    kill_case(SIGTERM, 1);
}

static void test_killed_run_sigint(void **state)
{
    (void) state;
    kill_case(SIGINT, 1);
}

static void test_killed_run_sigkill(void **state)
{
    (void) state;
    kill_case(SIGKILL, 0);
    kill_case(SIGKILL, 1);
}

/* ============================================================ threads */

static const int g_threads[] = { 1, 2, 3, 7, 0 };
#define NTHREADS ((int) (sizeof g_threads / sizeof g_threads[0]))

/* The sample fogged with each thread count, to the same OUTPUT path (so the
 * recorded parameters differ only in the digit), then renamed. */
static void thread_outputs(path_t outs[NTHREADS])
{
    static int done;
    fresh_dir("threads");
    path_t out = pth("threads/out.exr");
    for (int i = 0; i < NTHREADS; ++i)
        outs[i] = pth("threads-%d.exr", g_threads[i]);
    if (done)
        return;
    for (int i = 0; i < NTHREADS; ++i) {
        assert_status(run("--threads %d '%s' -o '%s' --fog exp:density=0.01,0.02,0.03 --fog "
                          "linear:start=3:end=400 --fog-color 0.5,0.6,0.7",
                          g_threads[i], sample(), out.s),
                      0);
        assert_no_crash();
        assert_int_equal(rename(out.s, outs[i].s), 0);
    }
    done = 1;
}

static void test_threads_deterministic(void **state)
{
    (void) state;
    path_t outs[NTHREADS];
    thread_outputs(outs);
    size_t l0;
    unsigned char *d0 = slurp(outs[0].s, &l0);
    assert_non_null(d0);
    uint32_t s0 = 0;
    size_t v0 = find_attr(d0, l0, "exrfog/parameters", "string", &s0);
    assert_true(v0 > 0);
    for (int i = 1; i < NTHREADS; ++i) {
        size_t li;
        uint32_t si = 0;
        unsigned char *di = slurp(outs[i].s, &li);
        assert_non_null(di);
        if (li != l0)
            fail_msg("--threads %d gives %zu bytes, --threads 1 gives %zu", g_threads[i], li, l0);
        size_t vi = find_attr(di, li, "exrfog/parameters", "string", &si);
        assert_int_equal(vi, v0);
        assert_int_equal(si, s0);
        /* The recorded parameters may differ only in the thread count. */
        for (uint32_t j = 0; j < s0; ++j)
            if (d0[v0 + j] != di[v0 + j] && !(d0[v0 + j] == '1' && di[v0 + j] == '0' + g_threads[i]))
                fail_msg("exrfog/parameters differ beyond --threads");
        memset(di + vi, 0, si);
        unsigned char *m0 = malloc(l0);
        memcpy(m0, d0, l0);
        memset(m0 + v0, 0, s0);
        if (memcmp(m0, di, l0) != 0) {
            size_t k = 0;
            while (m0[k] == di[k])
                ++k;
            fail_msg("--threads %d differs from --threads 1 at byte %zu (pixel data or header)",
                     g_threads[i], k);
        }
        free(m0);
        free(di);
    }
    free(d0);
}

/* The man page promises a bit-identical output for any N: the header too,
 * so exrfog/parameters must not record --threads. */
static void test_threads_bit_identical_files(void **state)
{
    (void) state;
    path_t outs[NTHREADS];
    thread_outputs(outs);
    size_t l0;
    unsigned char *d0 = slurp(outs[0].s, &l0);
    assert_non_null(d0);
    int differs = -1;
    for (int i = 1; i < NTHREADS && differs < 0; ++i) {
        size_t li;
        unsigned char *di = slurp(outs[i].s, &li);
        if (!di || li != l0 || memcmp(d0, di, l0) != 0)
            differs = i;
        free(di);
    }
    free(d0);
    if (differs >= 0)
        fail_msg("the file written with --threads %d is not byte-identical to --threads 1",
                 g_threads[differs]);
}

/* Whether two files hold the same bytes. */
static int same_files(const char *a, const char *b)
{
    size_t la, lb;
    unsigned char *da = slurp(a, &la), *db = slurp(b, &lb);
    const int same = da && db && la == lb && !memcmp(da, db, la);
    free(da);
    free(db);
    return same;
}

/* Every option of the one output-neutral list (args.c's
 * ef_option_neutral, read by exrfog/parameters and exrfog/history alike)
 * leaves the output file byte-identical, spelled in full, by a unique
 * prefix, with = or as a short cluster (issue 43: --preview-view was in
 * the parameters' list only, so it changed the history and the file). */
static void test_neutral_options_same_bytes(void **state)
{
    (void) state;
    mkdir(pth("neutral").s, 0777);
    path_t base = pth("neutral/base.exr"), out = pth("neutral/out.exr"), pv = pth("neutral/p.png");
    path_t fl = pth("neutral/failed.txt");
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02", sample(), base.s), 0);
    static const char *const single[] = {
        "--threads 1", "--thr 1", "--threads=1", "--stats", "-v", "-q", "-vq", "--verbose",
        "--quiet", "--preview '%s'", "--preview '%s' --preview-view 'sRGB - Display, Raw'",
        "--preview '%s' --preview-v 'sRGB - Display, Raw'",
    };
    for (size_t k = 0; k < sizeof single / sizeof single[0]; ++k) {
        char extra[3000];
        snprintf(extra, sizeof extra, single[k], pv.s);
        assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 %s", sample(), out.s, extra), 0);
        if (!same_files(base.s, out.s))
            fail_msg("%s changed the output file's bytes", single[k]);
        /* in front of INPUT too */
        assert_int_equal(tu_runf("%s '%s' --output='%s' --fog exp:density=0.02", extra, sample(),
                                 out.s), 0);
        if (!same_files(base.s, out.s))
            fail_msg("%s (before INPUT, --output=) changed the output file's bytes", single[k]);
    }
    /* the sequence's: --frames, --keep-going, --failed-list */
    path_t s1 = pth("neutral/s.0001.exr"), s2 = pth("neutral/s.0002.exr");
    assert_int_equal(tu_copy(sample(), s1.s), 0);
    assert_int_equal(tu_copy(sample(), s2.s), 0);
    path_t pat = pth("neutral/s.#.exr"), a = pth("neutral/a.#.exr"), b = pth("neutral/b.#.exr");
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02", pat.s, a.s), 0);
    assert_int_equal(tu_runf("'%s' -o '%s' --fog exp:density=0.02 --frames 1-2 --keep-going "
                             "--failed-list '%s'", pat.s, b.s, fl.s), 0);
    path_t a1 = pth("neutral/a.0001.exr"), b1 = pth("neutral/b.0001.exr");
    assert_true(same_files(a1.s, b1.s));
}

/* ============================================================ end to end */

static void test_e2e_exp_chromatic(void **state)
{
    (void) state;
    fog_t f = { 1, { { M_EXP, { 0.01, 0.02, 0.03 }, 0, 0, 0 } }, { 0.5, 0.6, 0.7 }, SKY_FOG, 0 };
    e2e("--fog exp:density=0.01,0.02,0.03 --fog-color 0.5,0.6,0.7", &f, 0);
    /* The header is carried over and the parameters recorded. */
    path_t out = pth("e2e/out.exr");
    exr_context_t a, b;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    assert_int_equal(exr_start_read(&a, sample(), &init), 0);
    assert_int_equal(exr_start_read(&b, out.s, &init), 0);
    static const char *const mats[] = { "worldToCamera", "worldToNDC" };
    for (int i = 0; i < 2; ++i) {
        exr_attr_m44f_t ma, mb;
        assert_int_equal(exr_attr_get_m44f(a, 0, mats[i], &ma), 0);
        assert_int_equal(exr_attr_get_m44f(b, 0, mats[i], &mb), 0);
        assert_memory_equal(ma.m, mb.m, sizeof ma.m);
    }
    float fa = 0, fb = 0;
    assert_int_equal(exr_attr_get_float(a, 0, "CameraFov", &fa), 0);
    assert_int_equal(exr_attr_get_float(b, 0, "CameraFov", &fb), 0);
    assert_true(fa == fb);
    int32_t n = 0;
    const char *s = NULL;
    assert_int_equal(exr_attr_get_string(b, 0, "exrfog/parameters", &n, &s), 0);
    assert_non_null(s);
    char par[512];
    snprintf(par, sizeof par, "%.*s", (int) n, s);
    assert_non_null(strstr(par, "exp:density=0.01,0.02,0.03"));
    exr_finish(&a);
    exr_finish(&b);
}

static void test_e2e_default_colour_exp2(void **state)
{
    (void) state;
    fog_t f = { 1, { { M_EXP2, { 0.015, 0.015, 0.015 }, 0, 0, 0 } }, { 0.7, 0.75, 0.8 }, SKY_FOG, 0 };
    e2e("--fog exp2:density=0.015", &f, 0);
}

static void test_e2e_linear(void **state)
{
    (void) state;
    fog_t f = { 1, { { M_LINEAR, { 0, 0, 0 }, 5, 60, 0 } }, { 0.4, 0.45, 0.5 }, SKY_FOG, 0 };
    e2e("--fog linear:start=5:end=60 --fog-color 0.4,0.45,0.5", &f, 0);
}

static void test_e2e_two_components(void **state)
{
    (void) state;
    fog_t f = { 2,
                { { M_EXP, { 0.01, 0.01, 0.01 }, 0, 0, 0 }, { M_EXP2, { 0.02, 0.01, 0.005 }, 0, 0, 0 } },
                { 0.5, 0.6, 0.7 },
                SKY_FOG,
                0 };
    e2e("--fog exp:density=0.01 --fog exp2:density=0.02,0.01,0.005 --fog-color 0.5,0.6,0.7", &f, 0);
}

static void test_e2e_planar_distance(void **state)
{
    (void) state;
    fog_t f = { 1, { { M_EXP, { 0.03, 0.03, 0.03 }, 0, 0, 1 } }, { 0.5, 0.6, 0.7 }, SKY_FOG, 0 };
    e2e("--fog exp:density=0.03:distance=planar --fog-color 0.5,0.6,0.7", &f, 0);
}

static void test_e2e_sky_keep(void **state)
{
    (void) state;
    fog_t f = { 1, { { M_EXP, { 0.02, 0.02, 0.02 }, 0, 0, 0 } }, { 0.5, 0.6, 0.7 }, SKY_KEEP, 0 };
    e2e("--fog exp:density=0.02 --fog-color 0.5,0.6,0.7 --sky keep", &f, 1);
}

static void test_e2e_sky_distance(void **state)
{
    (void) state;
    fog_t f = { 1, { { M_EXP, { 0.02, 0.02, 0.02 }, 0, 0, 0 } }, { 0.5, 0.6, 0.7 }, SKY_DIST, 50 };
    e2e("--fog exp:density=0.02 --fog-color 0.5,0.6,0.7 --sky distance=50", &f, 0);
}

static void test_explain(void **state)
{
    (void) state;
    path_t dir = fresh_dir("explain");
    path_t out = pth("explain/out.exr");
    size_t len;
    unsigned char *inb = sample_bytes(&len);
    int st = run("--explain '%s'", sample());
    assert_no_crash();
    assert_status(st, 0);
    /* Camera position: the eye from the inverse of worldToCamera, computed here. */
    img_t in;
    geom_t g;
    img_read(sample(), &in, 1);
    geom_from_header(sample(), in.c[4], &g);
    const char *pos = strstr(g_out, "position");
    assert_non_null(pos);
    double p[3];
    assert_int_equal(sscanf(pos, "position (%lf, %lf, %lf)", &p[0], &p[1], &p[2]), 3);
    for (int i = 0; i < 3; ++i)
        assert_true(fabs(p[i] - g.eye[i]) < 1e-5);
    assert_true(fabs(p[0]) < 1e-3 && fabs(p[1] - 1.7) < 1e-3 && fabs(p[2]) < 1e-3);
    const char *fov = strstr(g_out, "fov");
    assert_non_null(fov);
    double deg = 0;
    assert_int_equal(sscanf(fov, "fov %lf", &deg), 1);
    assert_true(fabs(deg - 60.0) < 0.01);
    geom_free(&g);
    img_free(&in);
    /* With -o and a fog: still nothing written. */
    st = run("--explain '%s' -o '%s' --fog exp:density=0.1", sample(), out.s);
    assert_status(st, 0);
    assert_non_null(strstr(g_out, "position"));
    assert_int_equal(dir_count(dir.s), 0);
    assert_true(same_bytes(sample(), inb, len));
    free(inb);
    /* The scene-wide settings the height models are read with. */
    st = run("--explain --up-axis -z --units-per-meter 100 '%s' --fog height:density=1:falloff=1",
             sample());
    assert_status(st, 0);
    assert_non_null(strstr(g_out, "up axis: -0, -0, -1; 100 scene units per metre") ?
                    g_out : strstr(g_out, "up axis: 0, 0, -1; 100 scene units per metre"));
}

static void test_preview(void **state)
{
    (void) state;
    path_t dir = fresh_dir("preview");
    path_t out = pth("preview/out.exr"), png = pth("preview/p.png");
    int st = run("--threads 2 '%s' -o '%s' --fog exp:density=0.02 --preview '%s'", sample(), out.s,
                 png.s);
    assert_no_crash();
    assert_status(st, 0);
    assert_true(tu_exists(out.s));
    size_t len;
    unsigned char *d = slurp(png.s, &len);
    assert_non_null(d);
    static const unsigned char sig[8] = { 0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n' };
    assert_true(len > 33);
    assert_memory_equal(d, sig, 8);
    assert_memory_equal(d + 12, "IHDR", 4);
    const uint32_t w = (uint32_t) d[16] << 24 | (uint32_t) d[17] << 16 | (uint32_t) d[18] << 8 | d[19];
    const uint32_t h = (uint32_t) d[20] << 24 | (uint32_t) d[21] << 16 | (uint32_t) d[22] << 8 | d[23];
    assert_int_equal(w, 640);
    assert_int_equal(h, 360);
    free(d);
    assert_int_equal(dir_count(dir.s), 2);
}

/* ------------------------------------------------------------ output safety (issue 8) */

/* OUTPUT that is not a regular file is refused (exit 2) and left as it was. */
static void test_output_not_regular(void **state)
{
    (void) state;
    path_t dir = fresh_dir("notreg");
    path_t fifo = pth("notreg/fifo"), sub = pth("notreg/sub"), sock = pth("notreg/sock");
    assert_int_equal(mkfifo(fifo.s, 0644), 0);
    assert_int_equal(mkdir(sub.s, 0755), 0);
    const int fd = socket(AF_UNIX, SOCK_STREAM, 0);
    struct sockaddr_un sa;
    memset(&sa, 0, sizeof sa);
    sa.sun_family = AF_UNIX;
    const int sock_ok = strlen(sock.s) < sizeof sa.sun_path;
    if (sock_ok) {
        memcpy(sa.sun_path, sock.s, strlen(sock.s) + 1);
        assert_int_equal(bind(fd, (struct sockaddr *) &sa, sizeof sa), 0);
    }
    static const struct {
        const char *name, *kind;
    } cases[] = { { "fifo", "FIFO" }, { "sub", "directory" }, { "sock", "socket" } };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        if (!sock_ok && !strcmp(cases[i].name, "sock"))
            continue;
        path_t t = pth("notreg/%s", cases[i].name);
        check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.02", sample(), t.s);
        assert_error_line(t.s);
        assert_err_has(cases[i].kind);
    }
    close(fd);
    /* A device: refused before anything is opened, and still a device. */
    struct stat before, after;
    assert_int_equal(stat("/dev/null", &before), 0);
    assert_status(run("'%s' -o /dev/null --fog exp:density=0.02", sample()), 2);
    assert_error_line("/dev/null");
    assert_err_has("character device");
    assert_int_equal(stat("/dev/null", &after), 0);
    assert_true(S_ISCHR(after.st_mode));
    assert_true(after.st_rdev == before.st_rdev);
    /* Empty names are usage errors. */
    check_failure(2, sample(), dir.s, "'%s' -o '' --fog exp:density=0.02", sample());
    assert_err_has("empty");
    path_t out = pth("notreg/o.exr");
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --preview '' --fog exp:density=0.02", sample(),
                  out.s);
    /* A missing directory: nothing read, nothing written. */
    path_t nodir = pth("notreg/none/o.exr");
    check_failure(1, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.02", sample(), nodir.s);
    assert_error_line(nodir.s);
    assert_err_has("does not exist");
}

/* A symlink OUTPUT is written through to its target (the link stays); a
 * dangling one is refused, as cp does. */
static void test_output_symlink(void **state)
{
    (void) state;
    path_t dir = fresh_dir("symlink");
    path_t target = pth("symlink/target.exr"), link = pth("symlink/link.exr");
    static const char old[] = "old target\n";
    spit(target.s, old, sizeof old - 1);
    assert_int_equal(symlink("target.exr", link.s), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.02", sample(), link.s), 0);
    struct stat st;
    assert_int_equal(lstat(link.s, &st), 0);
    assert_true(S_ISLNK(st.st_mode));
    assert_int_equal(tu_nparts(target.s), 1);   /* the target is now the fogged EXR */
    assert_int_equal(dir_count(dir.s), 2);
    path_t dang = pth("symlink/dangling.exr");
    assert_int_equal(symlink("missing.exr", dang.s), 0);
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.02", sample(), dang.s);
    assert_error_line(dang.s);
    assert_err_has("missing file");
}

/* A replaced OUTPUT keeps its permission bits and (as root) its owner. */
static void test_output_keeps_mode(void **state)
{
    (void) state;
    fresh_dir("mode");
    path_t out = pth("mode/out.exr");
    spit(out.s, "x", 1);
    assert_int_equal(chmod(out.s, 0640), 0);
    const int root_user = geteuid() == 0;
    if (root_user)
        assert_int_equal(chown(out.s, 65534, 65534), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.02", sample(), out.s), 0);
    struct stat st;
    assert_int_equal(stat(out.s, &st), 0);
    assert_int_equal(st.st_mode & 07777, 0640);
    if (root_user) {
        assert_int_equal(st.st_uid, 65534);
        assert_int_equal(st.st_gid, 65534);
    }
    assert_int_equal(tu_nparts(out.s), 1);
    /* A new file gets 0666 minus the umask, like any program's. */
    path_t fresh = pth("mode/new.exr");
    const mode_t um = umask(022);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.02", sample(), fresh.s), 0);
    umask(um);
    assert_int_equal(stat(fresh.s, &st), 0);
    assert_int_equal(st.st_mode & 07777, 0644);
}

/* A 240-byte name (legal up to NAME_MAX) works: the temporary name is shortened. */
static void test_output_long_name(void **state)
{
    (void) state;
    path_t dir = fresh_dir("longname");
    char name[256];
    memset(name, 'n', 236);
    memcpy(name + 236, ".exr", 5);
    path_t out = pth("longname/%s", name);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.02", sample(), out.s), 0);
    assert_int_equal(tu_nparts(out.s), 1);
    assert_int_equal(dir_count(dir.s), 1);
}

/* The temporary file is created exclusively: a symlink planted under the
 * old predictable name (or any name) is never followed. */
static void test_output_planted_symlink(void **state)
{
    (void) state;
    path_t dir = fresh_dir("planted");
    path_t victim = pth("planted/victim.txt"), out = pth("planted/out.exr");
    static const char keep[] = "not yours\n";
    spit(victim.s, keep, sizeof keep - 1);
    /* The names older versions used, for the next few process ids. */
    const long me = (long) getpid();
    for (long p = me; p < me + 16; ++p) {
        path_t plant = pth("planted/.out.exr.exrfog-%ld.tmp", p);
        assert_int_equal(symlink(victim.s, plant.s), 0);
    }
    assert_status(run("'%s' -o '%s' --fog exp:density=0.02", sample(), out.s), 0);
    assert_true(same_bytes(victim.s, (const unsigned char *) keep, sizeof keep - 1));
    assert_int_equal(tu_nparts(out.s), 1);
    assert_int_equal(dir_count(dir.s), 16 + 2);
}

/* -o equal to INPUT with a preview that cannot be written: the input is
 * left as it was (everything is checked before a pixel is read). */
static void test_output_preview_checked_first(void **state)
{
    (void) state;
    path_t dir = fresh_dir("pvfirst");
    path_t in = pth("pvfirst/in.exr"), bad = pth("pvfirst/none/p.png"), fmt = pth("pvfirst/p.nosuchformat");
    assert_int_equal(tu_copy(sample(), in.s), 0);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --preview '%s' --fog exp:density=0.02", in.s, in.s,
                  bad.s);
    assert_error_line(bad.s);
    check_failure(2, in.s, dir.s, "'%s' -o '%s' --preview '%s' --fog exp:density=0.02", in.s, in.s,
                  fmt.s);
    assert_error_line(fmt.s);
    check_failure(2, in.s, dir.s, "'%s' -o '%s' --preview '%s' --fog exp:density=0.02", in.s, in.s,
                  in.s);
    assert_error_line(in.s);
}

/* Runs exrfog on the sample under a file size limit (with SIGXFSZ caught,
 * or ignored so the write fails with EFBIG); returns the wait status. */
static int run_fsize_limited(const char *out, int ignore_xfsz)
{
    path_t e = pth("fsize.stderr");
    pid_t pid = fork();
    assert_true(pid >= 0);
    if (pid == 0) {
        struct rlimit rl = { 20000, 20000 }, core = { 0, 0 };
        setrlimit(RLIMIT_FSIZE, &rl);
        setrlimit(RLIMIT_CORE, &core);   /* SIGXFSZ dumps core by default */
        if (ignore_xfsz)
            signal(SIGXFSZ, SIG_IGN);
        const int fd = open(e.s, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(fd, 2);
        execl(bin(), bin(), sample(), "-o", out, "--fog", "exp:density=0.02", (char *) NULL);
        _exit(127);
    }
    int status = 0;
    assert_int_equal(waitpid(pid, &status, 0), pid);
    slurp_text(e.s, g_err, sizeof g_err);
    return status;
}

/* ulimit -f: SIGXFSZ removes the temporary file and says so; ignored, the
 * write error names OUTPUT (not an empty name) and exits 1. */
static void test_output_file_size_limit(void **state)
{
    (void) state;
    path_t dir = fresh_dir("fsize");
    path_t out = pth("fsize/out.exr");
    int st = run_fsize_limited(out.s, 0);
    assert_true(WIFSIGNALED(st));
    assert_int_equal(WTERMSIG(st), SIGXFSZ);
    assert_error_line(out.s);
    assert_err_has("SIGXFSZ");
    assert_int_equal(dir_count(dir.s), 0);
    st = run_fsize_limited(out.s, 1);
    assert_true(WIFEXITED(st));
    assert_int_equal(WEXITSTATUS(st), 1);
    assert_error_line(out.s);
    assert_err_has("File too large");
    assert_int_equal(dir_count(dir.s), 0);
}

static void test_killed_run_other_signals(void **state)
{
    (void) state;
    kill_case(SIGHUP, 1);
    kill_case(SIGPIPE, 0);
    kill_case(SIGALRM, 0);
    kill_case(SIGUSR1, 1);
}

/* A tile that would need more than the per-worker limit (1 GiB) is refused
 * as a corrupt header before anything is allocated: a 64x64 tiled frame
 * whose header claims one 262144x262144 tile. */
static void test_huge_tile_refused(void **state)
{
    (void) state;
    path_t dir = fresh_dir("hugetile");
    path_t in = pth("hugetile/in.exr"), out = pth("hugetile/out.exr");
    frame_t f;
    frame_alloc(&f, 64, 64);
    tu_part p;
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    p.tile = 16;
    write_part(in.s, &p);
    frame_free(&f);
    size_t n;
    unsigned char *d = slurp(in.s, &n);
    const size_t t = find_attr(d, n, "tiles", "tiledesc", NULL);
    const size_t w = find_attr(d, n, "dataWindow", "box2i", NULL);
    assert_true(t > 0 && w > 0);
    wr32(d + t, 262144);
    wr32(d + t + 4, 262144);
    wr32(d + w + 8, 262143);
    wr32(d + w + 12, 262143);
    spit(in.s, d, n);
    free(d);
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1 --fov 40", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("per worker");
}

/* Messages (issue 8): a long value is shortened so the reason still fits;
 * luminance-only and colourless images say so (not --layer); a subsampled
 * channel says what to do; a FIFO input says what it is; bytes that are
 * not UTF-8 are escaped. */
static void test_messages(void **state)
{
    (void) state;
    path_t dir = fresh_dir("msgs");
    path_t out = pth("msgs/out.exr");
    char longv[2101];
    memset(longv, 'z', 2100);
    longv[2100] = '\0';
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.1 --compression %s",
                  sample(), out.s, longv);
    assert_err_has("(2100 bytes)");
    assert_err_has("is not one of");
    /* Y + Z and foo.A + Z images (written here with OpenEXRCore). */
    frame_t f;
    frame_alloc(&f, 16, 8);
    tu_part p;
    tu_part_init(&p, 16, 8);
    tu_part_add(&p, "Y", EXR_PIXEL_HALF, f.c[0]);
    tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, f.c[4]);
    add_camera(&p, 40);
    path_t lum = pth("msgs/lum.exr"), noc = pth("msgs/noc.exr");
    write_part(lum.s, &p);
    tu_part_init(&p, 16, 8);
    tu_part_add(&p, "foo.A", EXR_PIXEL_HALF, f.c[0]);
    tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, f.c[4]);
    add_camera(&p, 40);
    write_part(noc.s, &p);
    frame_free(&f);
    check_failure(1, lum.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", lum.s, out.s);
    assert_err_has("luminance-only");
    if (strstr(g_err, "--layer"))
        fail_msg("the luminance message points at --layer:\n%s", g_err);
    /* Its hint names only channels the file has (Y and Z, no A), and works
     * as written: the converted file fogs. */
    assert_err_has("--ch R=Y,G=Y,B=Y,Z -o RGB.exr");
    if (system("command -v oiiotool >/dev/null 2>&1") == 0) {
        path_t rgb = pth("msgs/rgb.exr");
        char cmd[4200];
        snprintf(cmd, sizeof cmd, "oiiotool '%s' --ch R=Y,G=Y,B=Y,Z -o '%s'", lum.s, rgb.s);
        assert_int_equal(system(cmd), 0);
        assert_status(run("'%s' -o '%s' --fog exp:density=0.1", rgb.s, out.s), 0);
        unlink(rgb.s);
        unlink(out.s);
    }
    check_failure(1, noc.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", noc.s, out.s);
    assert_err_has("no R,G,B colour");
    assert_err_has("foo.A");
    /* A 2x2-subsampled channel, patched into the sample's channel list. */
    size_t n;
    unsigned char *d = slurp(sample(), &n);
    uint32_t sz;
    const size_t at = find_attr(d, n, "channels", "chlist", &sz);
    assert_true(at > 0);
    const size_t pt = at + strlen((const char *) d + at) + 1;   /* after the first name */
    wr32(d + pt + 8, 2);
    wr32(d + pt + 12, 2);
    path_t sub = pth("msgs/sub.exr");
    spit(sub.s, d, n);
    free(d);
    check_failure(1, sub.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", sub.s, out.s);
    assert_err_has("subsampled");
    assert_err_has("render without subsampling");
    /* A FIFO as INPUT: said to be one (not an empty file), nothing read. */
    path_t fifo = pth("msgs/fifo.exr");
    assert_int_equal(mkfifo(fifo.s, 0644), 0);
    check_failure(1, NULL, dir.s, "'%s' -o '%s' --fog exp:density=0.1", fifo.s, out.s);
    assert_err_has("FIFO");
    /* A FIFO as a camera file, scene file or profile: refused at once (open
     * blocked for ever), while a shell's <(...) pipe still reads. */
    check_failure(1, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.1 --camera-file '%s'",
                  sample(), out.s, fifo.s);
    assert_err_has("is a FIFO (named pipe) that nothing was written to");
    check_failure(1, sample(), dir.s, "'%s' -o '%s' --scene '%s'", sample(), out.s, fifo.s);
    assert_err_has("FIFO");
    check_failure(1, sample(), dir.s, "'%s' -o '%s' --fog 'layered:file=%s'", sample(), out.s,
                  fifo.s);
    assert_err_has("FIFO");
    unlink(fifo.s);
    /* Invalid UTF-8 is escaped; valid UTF-8 passes. */
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog 'exp:density=0.1:k\xff\xc3\xa9=1'",
                  sample(), out.s);
    assert_err_has("k\\xff\xc3\xa9");
    assert_null(strchr(g_err, '\xff'));
}

/* A multi-part file whose parts disagree on the display window (OpenEXR's
 * "non-conforming shared attributes", which the C++ library refuses) is
 * refused, so exrfog never writes such a file. */
static void test_nonconforming_multipart(void **state)
{
    (void) state;
    path_t dir = fresh_dir("nonconf");
    path_t in = pth("nonconf/in.exr"), out = pth("nonconf/out.exr");
    frame_t f;
    frame_alloc(&f, 16, 8);
    tu_part p[2];
    frame_part(&p[0], &f, 0x1f, EXR_PIXEL_HALF);
    add_camera(&p[0], 40);
    p[0].name = "beauty";
    frame_part(&p[1], &f, 0x1, EXR_PIXEL_HALF);
    p[1].name = "other";
    p[1].disp[2] = 31;   /* a wider display window than part 0's */
    const int rc = tu_write_exr(in.s, p, 2);
    frame_free(&f);
    if (rc) {
        print_message("OpenEXRCore would not write the test file (%d); skipped\n", rc);
        return;
    }
    check_failure(1, in.s, dir.s, "'%s' -o '%s' --fog exp:density=0.1", in.s, out.s);
    assert_error_line(in.s);
    assert_err_has("non-conforming shared attributes");
}

/* A NaN or infinite alpha (damaged data) is fogged as an opaque pixel and
 * written back as it was: RGB equal the run where that alpha is 1, and no
 * NaN or inf appears that the input did not have. */
static void test_nonfinite_alpha(void **state)
{
    (void) state;
    fresh_dir("badalpha");
    path_t bad = pth("badalpha/bad.exr"), ok = pth("badalpha/ok.exr");
    path_t bad_o = pth("badalpha/bad_o.exr"), ok_o = pth("badalpha/ok_o.exr");
    frame_t f;
    frame_alloc(&f, 16, 8);
    tu_part p;
    frame_part(&p, &f, 0x1f, EXR_PIXEL_FLOAT);
    add_camera(&p, 40);
    write_part(ok.s, &p);
    for (size_t i = 0; i < 16 * 8; i += 3)
        f.c[3][i] = (i / 3) % 2 ? NAN : INFINITY;
    write_part(bad.s, &p);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05", bad.s, bad_o.s), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05", ok.s, ok_o.s), 0);
    tu_image a, b;
    assert_int_equal(tu_read_image(bad_o.s, 0, &a), 0);
    assert_int_equal(tu_read_image(ok_o.s, 0, &b), 0);
    const char *rgb[3] = { "R", "G", "B" };
    for (size_t i = 0; i < 16 * 8; ++i) {
        for (int k = 0; k < 3; ++k) {
            const float va = tu_image_f(&a, rgb[k])[i], vb = tu_image_f(&b, rgb[k])[i];
            if (!isfinite(va) || memcmp(&va, &vb, sizeof va))
                fail_msg("pixel %zu %s: %g with a bad alpha, %g opaque", i, rgb[k], va, vb);
        }
        const float al = tu_image_f(&a, "A")[i];
        if (i % 3 == 0)
            assert_true((i / 3) % 2 ? isnan(al) : (isinf(al) && al > 0));
        else
            assert_true(al == 1.0f);
    }
    tu_image_free(&a);
    tu_image_free(&b);
    frame_free(&f);
}

/* Provenance (issue 9): exrfog/history holds, per pass, the version, the
 * command line shell-quoted less what cannot change the output (threads,
 * messages, preview, output name) and the scene file's contents; a second
 * pass appends its line to the first's. */
static void test_history(void **state)
{
    (void) state;
    fresh_dir("history");
    path_t scene = pth("history/scene.json"), o1 = pth("history/one.exr"),
           o2 = pth("history/two.exr"), o3 = pth("history/three.exr");
    static const char json[] = "{\"fog\": [\"exp:density=0.01\"],\n \"color\": [0.5, 0.6, 0.7]}\n";
    spit(scene.s, json, sizeof json - 1);
    assert_status(run("--threads 2 -v '%s' -o '%s' --scene '%s' --fog 'height:density=0.1:falloff=0.5' "
                      "--fog-color \"0.5,0.5,0.5\"", sample(), o1.s, scene.s), 0);
    assert_status(run("'%s' -o '%s' --fog 'exp:density=0.02:color=1,1,1' --aov T", o1.s, o2.s), 0);
    exr_context_t c;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    assert_int_equal(exr_start_read(&c, o2.s, &init), 0);
    int32_t n = 0;
    const char *h = NULL;
    assert_int_equal(exr_attr_get_string(c, 0, "exrfog/history", &n, &h), 0);
    static char want[16384];
    snprintf(want, sizeof want,
             "exrfog " EXRFOG_VERSION ": exrfog %s --scene %s --fog height:density=0.1:falloff=0.5 "
             "--fog-color 0.5,0.5,0.5\n"
             "  scene %s:\n"
             "    {\"fog\": [\"exp:density=0.01\"],\n"
             "     \"color\": [0.5, 0.6, 0.7]}\n"
             "exrfog " EXRFOG_VERSION ": exrfog %s --fog exp:density=0.02:color=1,1,1 --aov T",
             sample(), scene.s, scene.s, o1.s);
    if (strcmp(h, want))
        fail_msg("exrfog/history is\n%s\nexpected\n%s", h, want);
    exr_finish(&c);
    /* Quoting: a path with a space and a quote, as a POSIX shell reads it back. */
    path_t odd = pth("history/it's a scene.json");
    spit(odd.s, json, sizeof json - 1);
    assert_status(run("'%s' -o '%s' --scene \"%s\"", sample(), o3.s, odd.s), 0);
    assert_int_equal(exr_start_read(&c, o3.s, &init), 0);
    assert_int_equal(exr_attr_get_string(c, 0, "exrfog/history", &n, &h), 0);
    static char q[4096];
    snprintf(q, sizeof q, " --scene '%.*s'\\''s a scene.json'\n", (int) (strstr(odd.s, "it's") - odd.s + 2), odd.s);
    if (!strstr(h, q))
        fail_msg("exrfog/history lacks %s:\n%s", q, h);
    exr_finish(&c);
}

/* Silent traps warned (issue 9): a Nuke render's depth.Z read as planar,
 * and a V-Ray (Z-up) camera with height fog on the default y axis. Each
 * warning goes away with the flag it suggests, and with -q. */
static void test_trap_warnings(void **state)
{
    (void) state;
    fresh_dir("traps");
    path_t nk = pth("traps/nuke.exr"), vr = pth("traps/vray.exr"), out = pth("traps/out.exr");
    frame_t f;
    frame_alloc(&f, 16, 8);
    tu_part p;
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    add_camera(&p, 40);
    p.str_name = "nuke/version";
    p.str_value = "13.1v2";
    write_part(nk.s, &p);
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    p.m44[0].name = "cameraTransform";
    memcpy(p.m44[0].m, ID16, sizeof ID16);
    p.f[0].name = "cameraFov";
    p.f[0].v = 40;
    write_part(vr.s, &p);
    frame_free(&f);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.1", nk.s, out.s), 0);
    assert_err_has("--depth-mode inverse");
    assert_status(run("'%s' -o '%s' --fog exp:density=0.1 --depth-mode planar", nk.s, out.s), 0);
    assert_null(strstr(g_err, "warning"));
    assert_status(run("'%s' -o '%s' --fog exp:density=0.1 -q", nk.s, out.s), 0);
    assert_null(strstr(g_err, "warning"));
    assert_status(run("'%s' -o '%s' --fog height:density=0.1:falloff=0.2", vr.s, out.s), 0);
    assert_err_has("--up-axis z");
    assert_status(run("'%s' -o '%s' --fog height:density=0.1:falloff=0.2 --up-axis z", vr.s, out.s), 0);
    assert_null(strstr(g_err, "warning"));
    assert_status(run("'%s' -o '%s' --fog height:density=0.1:falloff=0.2:up=z", vr.s, out.s), 0);
    assert_null(strstr(g_err, "warning"));
    assert_status(run("'%s' -o '%s' --fog exp:density=0.1", vr.s, out.s), 0);
    assert_null(strstr(g_err, "warning"));
    /* A Blender-convention camera is Z-up too: the same warning, and
     * --up-axis auto says what it chose. */
    static const char blender_cam[] = "--camera-convention blender --fov 50 --camera-to-world "
                                      "1,0,0,0,0,0,-1,-10,0,1,0,2,0,0,0,1";
    assert_status(run("'%s' -o '%s' %s --fog height:density=0.1:falloff=0.2", vr.s, out.s,
                      blender_cam), 0);
    assert_err_has("in Blender's convention, whose world is Z-up");
    assert_err_has("--up-axis auto");
    assert_status(run("'%s' -o '%s' %s --fog height:density=0.1:falloff=0.2 --up-axis auto", vr.s,
                      out.s, blender_cam), 0);
    assert_null(strstr(g_err, "warning"));
    assert_err_has("note: --up-axis auto: z, since the camera is in Blender's convention");
}

/* OUTPUT's extension chooses the format (issue 9): .tif/.png through
 * OpenImageIO with the fogged colour and alpha (a -d half TIFF's values equal
 * the EXR run's R,G,B,A, compared by oiiotool --diff); an extension no
 * writer knows, or AOVs with a colour-only format, is a usage error before
 * any work, and never an EXR under another name. */
static void test_output_formats(void **state)
{
    (void) state;
    path_t dir = fresh_dir("formats");
    path_t exr = pth("formats/out.exr"), tif = pth("formats/out.tif"), png = pth("formats/out.png"),
           foo = pth("formats/out.foo");
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05", sample(), exr.s), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05 -d half", sample(), tif.s), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05", sample(), png.s), 0);
    size_t n;
    unsigned char *d = slurp(png.s, &n);
    static const unsigned char sig[8] = { 0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n' };
    assert_true(d && n > 8 && !memcmp(d, sig, 8));
    free(d);
    if (system("command -v oiiotool >/dev/null 2>&1") == 0) {
        char cmd[5000];
        snprintf(cmd, sizeof cmd, "oiiotool '%s' --ch R,G,B,A '%s' --diff --fail 0 >/dev/null 2>&1",
                 exr.s, tif.s);
        assert_int_equal(system(cmd), 0);
    }
    assert_int_equal(dir_count(dir.s), 3);
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.05", sample(), foo.s);
    assert_err_has("has no writer");
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.05 --aov T", sample(), png.s);
    assert_err_has("--aov needs an EXR");
}

/* Runs ARGS (after INPUT -o OUT) in the background until its stderr has a
 * prediction (10 s at most), then stops it; g_err gets that stderr. Nothing
 * may be left in dir (SIGTERM removes the temporary output). */
static void run_until_predicted(const char *dir, const char *name, const char *args)
{
    char cmd[16384], o[1100], e[1100];
    snprintf(o, sizeof o, "%s/%s.exr", dir, name);
    snprintf(e, sizeof e, "%s.%s.err", dir, name);
    snprintf(cmd, sizeof cmd, "'%s' '%s' -o '%s' %s --threads 2 2>'%s' & p=$!; for i in "
             "$(seq 100); do grep -q predicted '%s' 2>/dev/null && break; sleep 0.1; done; "
             "kill $p; wait $p", bin(), sample(), o, args, e, e);
    (void) system(cmd);
    slurp_text(e, g_err, sizeof g_err);
    assert_int_equal(dir_count(dir), 0);
}

/* A costly frame is warned about before the work, from the fog of a sample
 * of its pixels timed (issue 47): method=exact with the hostile campaign's
 * 0.1 scale, 16 octaves and falloff 1e-6 (147 s on a 64x64 frame), and lit
 * noise fog (noise-separable past a point lamp, the campaign's "cheap
 * unlit SPEC past 60 s once lit", which no evaluation count predicted).
 * The runs are stopped once the warning is out. A cheap frame is not
 * warned about. */
static void test_cost_warning(void **state)
{
    (void) state;
    path_t dir = fresh_dir("exactcost");
    run_until_predicted(dir.s, "exact",
                        "--fog noise:density=0.001:scale=0.1:octaves=16:falloff=1e-6:method=exact");
    assert_non_null(strstr(g_err, "warning: this frame is predicted to take about"));
    assert_non_null(strstr(g_err, "drop method=exact"));
    run_until_predicted(dir.s, "lit", "--fog noise-separable:density=0.02:scale=10:octaves=3 "
                                      "--light point:position=0,3,-20:intensity=50");
    assert_non_null(strstr(g_err, "warning: this frame is predicted to take about"));
    assert_non_null(strstr(g_err, "lit fog integrates every light"));
    path_t out = pth("exactcost/out.exr");
    assert_status(run("'%s' -o '%s' --fog noise:density=0.02:scale=10:octaves=2:method=exact",
                      sample(), out.s), 0);
    assert_null(strstr(g_err, "predicted"));
}

/* The prediction --stats gives (fog thread time, from timed sampled
 * pixels) against the run's own CPU time (getrusage of the child: the
 * pass's "fog" figure is wall time per thread, which a loaded machine
 * inflates): within a factor of 3 on patchy noise fog and on a lamp in
 * height fog, one thread (1.04 and 1.02 of the fog time in Release on an
 * idle machine). */
static void test_cost_prediction(void **state)
{
    (void) state;
    path_t dir = fresh_dir("predict"), out = pth("predict/out.exr");
    (void) dir;
    static const char *const scenes[] = {
        "--fog noise:density=0.05:scale=10:octaves=5:falloff=0.1:base=0:contrast=1.5",
        "--fog height:density=0.05:falloff=0.3 --light point:position=0,3,-20:intensity=50",
    };
    for (int i = 0; i < 2; ++i) {
        struct rusage r0, r1;
        getrusage(RUSAGE_CHILDREN, &r0);
        assert_status(run("'%s' -o '%s' %s --stats --threads 1", sample(), out.s, scenes[i]), 0);
        getrusage(RUSAGE_CHILDREN, &r1);
        const double cpu = (double) (r1.ru_utime.tv_sec - r0.ru_utime.tv_sec) +
                           1e-6 * (double) (r1.ru_utime.tv_usec - r0.ru_utime.tv_usec) +
                           (double) (r1.ru_stime.tv_sec - r0.ru_stime.tv_sec) +
                           1e-6 * (double) (r1.ru_stime.tv_usec - r0.ru_stime.tv_usec);
        const char *p = strstr(g_err, "predicted before the pass at ");
        assert_non_null(p);
        const double pred = strtod(p + 29, NULL);
        printf("%s: CPU %.3f s, predicted %.3f s\n", scenes[i], cpu, pred);
        assert_true(cpu > 0.05 && pred > cpu / 3 && pred < cpu * 3);
    }
}

/* --sky-light's rotate= is a turn modulo 360 (issue 47: 1e308 degrees
 * overflowed in radians and made every pixel NaN): 450 gives 90's bytes,
 * and a huge angle a finite image (through a Henyey-Greenstein phase, whose
 * convolution the overflow reached). The environment varies with longitude,
 * so the turn shows. */
static void test_sky_rotate_huge(void **state)
{
    (void) state;
    fresh_dir("skyrot");
    path_t env = pth("skyrot/env.exr"), a = pth("skyrot/a.exr"), b = pth("skyrot/b.exr"),
           c = pth("skyrot/c.exr");
    enum { W = 32, H = 16 };
    static float R[W * H], G[W * H], B[W * H];
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            R[y * W + x] = (float) x / W;
            G[y * W + x] = 0.5f;
            B[y * W + x] = 1.0f - (float) x / W;
        }
    tu_part p;
    tu_part_init(&p, W, H);
    tu_part_add(&p, "R", EXR_PIXEL_FLOAT, R);
    tu_part_add(&p, "G", EXR_PIXEL_FLOAT, G);
    tu_part_add(&p, "B", EXR_PIXEL_FLOAT, B);
    assert_int_equal(tu_write_exr(env.s, &p, 1), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05:phase=hg:g=0.6 --sky-light '%s:rotate=90' -d float",
                      sample(), a.s, env.s), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05:phase=hg:g=0.6 --sky-light '%s:rotate=450' -d float",
                      sample(), b.s, env.s), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05:phase=hg:g=0.6 --sky-light '%s:rotate=1e308' -d float",
                      sample(), c.s, env.s), 0);
    tu_image x, y, z;
    assert_int_equal(tu_read_image(a.s, 0, &x), 0);
    assert_int_equal(tu_read_image(b.s, 0, &y), 0);
    assert_int_equal(tu_read_image(c.s, 0, &z), 0);
    for (int ch = 0; ch < x.nch; ++ch) {
        assert_memory_equal(x.plane[ch], y.plane[ch], sizeof(float) * (size_t) x.w * (size_t) x.h);
        const float *v = z.plane[ch];
        for (size_t k = 0; k < (size_t) z.w * (size_t) z.h; ++k)
            assert_false(isnan(v[k]));
    }
    tu_image_free(&x);
    tu_image_free(&y);
    tu_image_free(&z);
}

/* A shadow map's memory is bounded before it is read (issue 47: a
 * penumbra of 64 on a small map took 7.1 GB): 2048^2 texels with 64
 * penumbra copies is past the limit of 2^27 texels (exit 1, the limit
 * named, nothing written); with 8 copies the same map runs. */
static void test_shadow_map_bound(void **state)
{
    (void) state;
    fresh_dir("mapbound");
    path_t map = pth("mapbound/sun.exr"), out = pth("mapbound/out.exr");
    const char *mk = getenv("EXRFOG_MAKE_SAMPLE");
    assert_non_null(mk);
    char cmd[8192];
    snprintf(cmd, sizeof cmd, "'%s' '%s' --sun-view 0.3,1,0.2 --size 2048x2048 >/dev/null", mk,
             map.s);
    assert_int_equal(system(cmd), 0);
    assert_status(run("'%s' -o '%s' --fog height:density=0.05:falloff=0.3 --light "
                      "sun:towards=0.3,1,0.2:intensity=3:angle=0.53:penumbra=64:shadow='%s'",
                      sample(), out.s, map.s), 1);
    assert_non_null(strstr(g_err, "past the limit of 134217728"));
    assert_non_null(strstr(g_err, "penumbra="));
    assert_false(tu_exists(out.s));
}

/* Largest |a - b| over R, G and B of two same-sized outputs (finite
 * values; the sky's 1e10 depth makes no colour). */
static double rgb_max_diff(const char *a, const char *b)
{
    tu_image x, y;
    assert_int_equal(tu_read_image(a, 0, &x), 0);
    assert_int_equal(tu_read_image(b, 0, &y), 0);
    assert_int_equal(x.w * x.h, y.w * y.h);
    double m = 0;
    for (int k = 0; k < 3; ++k) {
        const char *n = (const char *[]) { "R", "G", "B" }[k];
        const float *p = x.plane[tu_image_find(&x, n)], *q = y.plane[tu_image_find(&y, n)];
        for (size_t i = 0; i < (size_t) x.w * (size_t) x.h; ++i)
            if (isfinite(p[i]) && isfinite(q[i]) && fabs((double) p[i] - q[i]) > m)
                m = fabs((double) p[i] - q[i]);
    }
    tu_image_free(&x);
    tu_image_free(&y);
    return m;
}

/* The worldToCamera oiiotool prints for map (16 numbers, comma
 * separated, 6 digits) into w2c, after erasing the map's camera
 * attributes into bare (a map as a DCC writes it). */
static void map_w2c(const char *map, const char *bare, char *w2c, size_t cap)
{
    char cmd[16384], txt[2200];
    snprintf(txt, sizeof txt, "%s.w2c", bare);
    snprintf(cmd, sizeof cmd, "oiiotool '%s' --eraseattrib worldToCamera --eraseattrib worldToNDC "
             "--eraseattrib CameraFov -o '%s' && oiiotool --info -v '%s' | sed -n "
             "'s/.*worldToCamera: //p' > '%s'", map, bare, map, txt);
    assert_int_equal(system(cmd), 0);
    slurp_text(txt, w2c, cap);
    w2c[strcspn(w2c, "\n")] = 0;
}

/* LIGHT (a --fog and --light prefix) with the header's map, with the bare
 * map and the camera file cam, and with no map, into a, b, c: b must be
 * a's within a half step (the 6 digits of the file) while c differs
 * (the map matters). */
static void map_camera_same(const char *what, const char *light, const char *map,
                            const char *bare, const char *cam, const char *a, const char *b,
                            const char *c)
{
    assert_status(run("'%s' -o '%s' %s:shadow='%s'", sample(), a, light, map), 0);
    assert_status(run("'%s' -o '%s' %s:shadow='%s':shadow-camera='%s'", sample(), b, light, bare,
                      cam), 0);
    assert_status(run("'%s' -o '%s' %s", sample(), c, light), 0);
    const double same = rgb_max_diff(a, b), differ = rgb_max_diff(a, c);
    printf("%s shadow-camera=: %.3g from the header's map; the map itself changes up to %.3g\n",
           what, same, differ);
    assert_true(same <= 2e-3 && differ > 0.02);
}

/* A shadow map's camera from a camera file (issue 42 item 4: shadow-
 * camera=, for maps whose header has none, as a DCC writes them): make_
 * sample's sun map with its header's matrices erased and the same camera
 * in a JSON camera file (world_to_camera as oiiotool prints it, 6 digits,
 * and ortho_width, the map's 240 units) shades as the header's map does,
 * within a half float's step at the brightest fog (the digits), while the
 * map changes the image by far more. A spot map likewise (make_sample's
 * perspective view, fov from its header). The mistakes are refused with
 * the file named: two frames, no lens, ortho_width with a fov, ortho_width
 * for the image's own camera, shadow-camera= without shadow=. */
static void test_shadow_camera_file(void **state)
{
    (void) state;
    fresh_dir("mapcam");
    path_t map = pth("mapcam/sun.exr"), bare = pth("mapcam/bare.exr"), cj = pth("mapcam/sun.json");
    path_t a = pth("mapcam/a.exr"), b = pth("mapcam/b.exr"), c = pth("mapcam/c.exr");
    const char *mk = getenv("EXRFOG_MAKE_SAMPLE");
    assert_non_null(mk);
    char cmd[16384], w2c[600];
    snprintf(cmd, sizeof cmd, "'%s' '%s' --sun-view 0.2,0.3,-1 --size 256x256 >/dev/null", mk,
             map.s);
    assert_int_equal(system(cmd), 0);
    map_w2c(map.s, bare.s, w2c, sizeof w2c);
    FILE *f = fopen(cj.s, "w");
    assert_non_null(f);
    fprintf(f, "{\"convention\": \"exr\", \"ortho_width\": 240,\n \"frames\": {\"7\": "
               "{\"world_to_camera\": [%s]}}}\n", w2c);
    fclose(f);
    const char *fog = "--fog height:density=0.05:falloff=0.2 --light sun:towards=0.2,0.3,-1:intensity=3";
    map_camera_same("sun", fog, map.s, bare.s, cj.s, a.s, b.s, c.s);
    /* --explain says where the map's camera came from */
    assert_status(run("'%s' --explain %s:shadow='%s':shadow-camera='%s'", sample(), fog, bare.s,
                      cj.s), 0);
    assert_non_null(strstr(g_out, "orthographic, camera from "));
    assert_non_null(strstr(g_out, "sun.json"));
    /* without the camera file the bare map is refused, naming what it lacks */
    assert_status(run("'%s' -o '%s' %s:shadow='%s'", sample(), b.s, fog, bare.s), 1);
    assert_non_null(strstr(g_err, "light camera in its header"));

    /* a spot's perspective map: make_sample's own view from the spot */
    path_t spot = pth("mapcam/spot.exr"), sbare = pth("mapcam/sbare.exr"), sj = pth("mapcam/spot.json");
    snprintf(cmd, sizeof cmd, "'%s' '%s' --view 6,-30,70 --size 256x256 >/dev/null", mk, spot.s);
    assert_int_equal(system(cmd), 0);
    map_w2c(spot.s, sbare.s, w2c, sizeof w2c);
    /* the spot at the view's camera, aimed along its axis: from the matrix's
     * inverse (row vectors: position -t R^T, axis the third row of R^T) */
    double m[16];
    assert_int_equal(sscanf(w2c, "%lf, %lf, %lf, %lf, %lf, %lf, %lf, %lf, %lf, %lf, %lf, %lf, "
                            "%lf, %lf, %lf, %lf", &m[0], &m[1], &m[2], &m[3], &m[4], &m[5],
                            &m[6], &m[7], &m[8], &m[9], &m[10], &m[11], &m[12], &m[13],
                            &m[14], &m[15]), 16);
    double pos[3], aim[3];
    for (int j = 0; j < 3; ++j) {
        pos[j] = -(m[12] * m[4 * j] + m[13] * m[4 * j + 1] + m[14] * m[4 * j + 2]);
        aim[j] = m[4 * j + 2];
    }
    f = fopen(sj.s, "w");
    assert_non_null(f);
    fprintf(f, "[{\"frame\": 1, \"world_to_camera\": [%s], \"fov\": 70}]\n", w2c);
    fclose(f);
    char lspot[600];
    snprintf(lspot, sizeof lspot, "--fog exp:density=0.04 --light spot:position=%.9g,%.9g,%.9g:"
             "aim=%.9g,%.9g,%.9g:cone=60:intensity=1500", pos[0], pos[1], pos[2], aim[0], aim[1],
             aim[2]);
    map_camera_same("spot", lspot, spot.s, sbare.s, sj.s, a.s, b.s, c.s);

    /* what is refused */
    static const struct { const char *json, *want; } bad[] = {
        { "{\"ortho_width\": 240, \"frames\": {\"1\": {\"world_to_camera\": [%s]}, \"2\": "
          "{\"world_to_camera\": [%s]}}}", "holds 2 frames" },
        { "{\"frames\": {\"1\": {\"world_to_camera\": [%s]}}}%s", "gives no lens" },
        { "{\"frames\": {\"1\": {\"world_to_camera\": [%s], \"fov\": 30, \"ortho_width\": 9}}}%s",
          "gives ortho_width" },
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        f = fopen(cj.s, "w");
        assert_non_null(f);
        fprintf(f, bad[i].json, w2c, i == 0 ? w2c : "");
        fclose(f);
        assert_status(run("'%s' -o '%s' %s:shadow='%s':shadow-camera='%s'", sample(), b.s, fog,
                          bare.s, cj.s), 1);
        assert_non_null(strstr(g_err, bad[i].want));
        assert_non_null(strstr(g_err, "sun.json"));
    }
    f = fopen(cj.s, "w");
    assert_non_null(f);
    fprintf(f, "{\"frames\": {\"1\": {\"world_to_camera\": [%s], \"ortho_width\": 9}}}", w2c);
    fclose(f);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.02 --camera-file '%s'",
                      sbare.s, b.s, cj.s), 1);
    assert_non_null(strstr(g_err, "shadow map's camera"));
    assert_status(run("'%s' -o '%s' %s:shadow-camera='%s'", sample(), b.s, fog, cj.s), 2);
    assert_non_null(strstr(g_err, "need shadow=FILE.exr"));
}

/* A light's AOV channel past 31 bytes (issue 47: names of 20 to 63
 * characters failed at the write with "Channel name must shorter than
 * length allowed by file"): the output takes the long-names flag and
 * holds the channels. */
static void test_long_light_name_aov(void **state)
{
    (void) state;
    fresh_dir("longname");
    path_t out = pth("longname/out.exr");
    const char *name = "a_lamp_with_a_name_of_sixty_three_characters_for_its_aov_layer_";
    assert_int_equal(strlen(name), 63);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.02 --light "
                      "point:position=1,2,-5:intensity=10:name=%s --aov light",
                      sample(), out.s, name), 0);
    tu_image img;
    assert_int_equal(tu_read_image(out.s, 0, &img), 0);
    char want[128];
    for (int k = 0; k < 3; ++k) {
        snprintf(want, sizeof want, "fog_light.%s.%c", name, "RGB"[k]);
        assert_true(tu_image_find(&img, want) >= 0);
    }
    tu_image_free(&img);
}

/* A light key's number that overflows or underflows is called out of
 * range, as in a SPEC (issue 47: it was reported with the key's own rule);
 * a name that merely holds digits is no number. */
static void test_light_key_range(void **state)
{
    (void) state;
    fresh_dir("lightrange");
    path_t out = pth("lightrange/out.exr");
    /* numbers past double's range, and (issue 47: +inf pixels with exit
     * 0) a light past half's, refused as a fog colour past 65504 is:
     * colour times intensity, a lamp's before its units' scale. Nothing
     * is written. */
    static const struct {
        const char *spec, *want;
    } bad[] = { { "point:position=1,2,3:intensity=1e999", "is out of range" },
                { "point:position=1e-400,2,3:intensity=1", "is out of range" },
                { "sun:towards=0,1,0:intensity=3:angle=1e999", "is out of range" },
                { "sun:towards=0,1,0:intensity=1e6", "past 65504" },
                { "point:position=1,2,3:intensity=40000:color=2,1,1", "past 65504" },
                { "spot:position=1,2,3:aim=0,-1,0:cone=30:intensity=1e5", "past 65504" } };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; ++k) {
        assert_status(run("'%s' -o '%s' --fog exp:density=0.05 --light '%s'", sample(), out.s,
                          bad[k].spec), 2);
        assert_non_null(strstr(g_err, bad[k].want));
        assert_false(tu_exists(out.s));
    }
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05 --light "
                      "'point:position=1,2,3:intensity=1:name=lamp1e999'", sample(), out.s), 0);
    path_t hot = pth("lightrange/hot.exr");
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05 --units-per-meter 100 --light "
                      "'point:position=1,2,3:intensity=65504'", sample(), hot.s), 0);
}

/* lod=pixel reads the frame's camera (ef_scene_bind_camera): on a fine
 * noise seen far off, octaves below the pixel fade out, so the run costs
 * fewer noise evaluations than lod=point and the picture changes within
 * what fine detail held. */
static double stats_evals(void)
{
    const char *p = strstr(g_err, "noise evaluations mean ");
    return p ? atof(p + strlen("noise evaluations mean ")) : -1;
}

static void test_lod_pixel_camera(void **state)
{
    (void) state;
    fresh_dir("lodpixel");
    path_t a = pth("lodpixel/point.exr"), b = pth("lodpixel/pixel.exr");
    assert_status(run("'%s' -o '%s' --fog noise:density=0.05:scale=0.5:octaves=6 --stats",
                      sample(), a.s), 0);
    const double ea = stats_evals();
    assert_status(run("'%s' -o '%s' --fog noise:density=0.05:scale=0.5:octaves=6:lod=pixel "
                      "--stats", sample(), b.s), 0);
    const double eb = stats_evals();
    printf("  noise evaluations per pixel: lod=point %.1f, lod=pixel %.1f\n", ea, eb);
    assert_true(ea > 0 && eb > 0 && eb < 0.8 * ea);
    tu_image x, y;
    assert_int_equal(tu_read_image(a.s, 0, &x), 0);
    assert_int_equal(tu_read_image(b.s, 0, &y), 0);
    const int r = tu_image_find(&x, "R");
    assert_true(r >= 0 && tu_image_find(&y, "R") == r);
    double most = 0;
    const float *px = x.plane[r], *py = y.plane[r];   /* read as float */
    for (size_t k = 0; k < (size_t) x.w * (size_t) x.h; ++k)
        most = fmax(most, fabs((double) px[k] - (double) py[k]));
    assert_true(most > 0 && most < 0.05);
    tu_image_free(&x);
    tu_image_free(&y);
}

/* -d CHANNEL=TYPE as oiiotool (issue 9): per-channel types over -d TYPE,
 * the last one naming a channel winning; a name-less override is a usage
 * error. */
static void test_data_type_per_channel(void **state)
{
    (void) state;
    path_t dir = fresh_dir("dtype");
    path_t out = pth("dtype/out.exr");
    assert_status(run("'%s' -o '%s' --fog exp:density=0.05 -d half -d Z=half -d A=half -d A=float",
                      sample(), out.s), 0);
    tu_image b;
    assert_int_equal(tu_read_image(out.s, 0, &b), 0);
    static const struct { const char *ch; exr_pixel_type_t t; } want[] = {
        { "R", EXR_PIXEL_HALF }, { "G", EXR_PIXEL_HALF }, { "B", EXR_PIXEL_HALF },
        { "A", EXR_PIXEL_FLOAT }, { "Z", EXR_PIXEL_HALF },
    };
    for (size_t k = 0; k < sizeof want / sizeof want[0]; ++k) {
        const int at = tu_image_find(&b, want[k].ch);
        if (at < 0 || b.type[at] != want[k].t)
            fail_msg("channel %s: type %d, want %d", want[k].ch, at < 0 ? -1 : (int) b.type[at],
                     (int) want[k].t);
    }
    tu_image_free(&b);
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.05 -d =half", sample(),
                  out.s);
    check_failure(2, sample(), dir.s, "'%s' -o '%s' --fog exp:density=0.05 -d Z=double", sample(),
                  out.s);
}

/* --focal-length with --aperture (issue 9): the field of view is
 * 2 atan(36 / 70) = 54.4322 degrees for a 35 mm lens on a 36 mm back
 * (by hand); one without the other, or with --fov, is a usage error. */
static void test_focal_length(void **state)
{
    (void) state;
    assert_status(run("'%s' --explain --focal-length 35 --aperture 36", sample()), 0);
    if (!strstr(g_out, "54.4322"))
        fail_msg("--explain does not show a 54.4322 degree field of view:\n%s", g_out);
    assert_status(run("'%s' --explain --focal-length 35", sample()), 2);
    assert_err_has("--aperture");
    assert_status(run("'%s' --explain --focal-length 35 --aperture 36 --fov 40", sample()), 2);
}

/* --explain reports what it found before the first thing it could not
 * find (issue 9): a frame without a camera still shows its channels and
 * the scene, then the error; a frame without colour shows the scene. */
static void test_explain_partial(void **state)
{
    (void) state;
    fresh_dir("explainp");
    path_t nocam = pth("explainp/nocam.exr"), nocol = pth("explainp/nocol.exr");
    frame_t f;
    frame_alloc(&f, 16, 8);
    tu_part p;
    frame_part(&p, &f, 0x1f, EXR_PIXEL_HALF);
    write_part(nocam.s, &p);
    frame_part(&p, &f, 0x10, EXR_PIXEL_HALF);   /* Z only */
    write_part(nocol.s, &p);
    frame_free(&f);
    assert_status(run("'%s' --explain --fog exp:density=0.02", nocam.s), 1);
    if (!strstr(g_out, "camera: not resolved") || !strstr(g_out, "colour: R, G, B, alpha A") ||
        !strstr(g_out, "depth: Z") || !strstr(g_out, "fog: exp:density=0.02"))
        fail_msg("--explain without a camera printed:\n%s", g_out);
    assert_err_has("no camera pose");
    assert_status(run("'%s' --explain --fog exp:density=0.02", nocol.s), 1);
    if (!strstr(g_out, "colour, depth and views: not resolved") ||
        !strstr(g_out, "fog: exp:density=0.02"))
        fail_msg("--explain without colour printed:\n%s", g_out);
}

/* A depth covering the whole frame beside a cropped colour render is
 * cropped to match (issue 9): the output equals the run with a depth file
 * cropped by hand to the colour's data window. */
static void test_depth_covers_crop(void **state)
{
    (void) state;
    fresh_dir("depthcrop");
    path_t col = pth("depthcrop/colour.exr"), full = pth("depthcrop/full.exr"),
           cut = pth("depthcrop/cut.exr"), o1 = pth("depthcrop/o1.exr"), o2 = pth("depthcrop/o2.exr");
    frame_t f, c, z;
    frame_alloc(&f, 16, 8);    /* the full frame's depth */
    frame_alloc(&c, 8, 4);     /* colour of (4,2)-(11,5) */
    frame_alloc(&z, 8, 4);     /* the same window of f's depth, by hand */
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 8; ++x)
            z.c[4][y * 8 + x] = f.c[4][(y + 2) * 16 + (x + 4)];
    tu_part p;
    frame_part(&p, &c, 0x0f, EXR_PIXEL_FLOAT);
    add_camera(&p, 60);
    p.dw[0] = 4; p.dw[1] = 2; p.dw[2] = 11; p.dw[3] = 5;
    p.disp[0] = 0; p.disp[1] = 0; p.disp[2] = 15; p.disp[3] = 7;
    write_part(col.s, &p);
    frame_part(&p, &f, 0x10, EXR_PIXEL_FLOAT);
    write_part(full.s, &p);
    frame_part(&p, &z, 0x10, EXR_PIXEL_FLOAT);
    p.dw[0] = 4; p.dw[1] = 2; p.dw[2] = 11; p.dw[3] = 5;
    p.disp[0] = 0; p.disp[1] = 0; p.disp[2] = 15; p.disp[3] = 7;
    write_part(cut.s, &p);
    frame_free(&f);
    frame_free(&c);
    frame_free(&z);
    assert_status(run("'%s' --depth '%s' -o '%s' --fog exp:density=0.1", col.s, full.s, o1.s), 0);
    assert_status(run("'%s' --depth '%s' -o '%s' --fog exp:density=0.1", col.s, cut.s, o2.s), 0);
    tu_image a, b;
    assert_int_equal(tu_read_image(o1.s, 0, &a), 0);
    assert_int_equal(tu_read_image(o2.s, 0, &b), 0);
    for (int k = 0; k < 4; ++k) {
        static const char *const ch[4] = { "R", "G", "B", "A" };
        assert_int_equal(tu_compare_channel(&b, &a, ch[k], 0.0, 0), 0);
    }
    tu_image_free(&a);
    tu_image_free(&b);
}

/* --camera-convention (issue 9): a matrix pasted from a DCC works as
 * pasted. By hand: Blender's matrix_world (column vectors) and Maya's
 * (row vectors) of a camera at (0,0,10) with no rotation look down world
 * -Z; Nuke's (column vectors) turned -90 degrees about Y looks down +X;
 * Blender's world-to-camera (the inverse) gives the same camera. */
static void test_camera_convention(void **state)
{
    (void) state;
    static const struct {
        const char *conv, *flag, *m, *fwd;
    } cases[] = {
        { "exr", "--camera-to-world", "1,0,0,0,0,1,0,0,0,0,1,0,0,0,10,1", "(0, 0, 1)" },
        { "blender", "--camera-to-world", "1,0,0,0,0,1,0,0,0,0,1,10,0,0,0,1", "(0, 0, -1)" },
        { "maya", "--camera-to-world", "1,0,0,0,0,1,0,0,0,0,1,0,0,0,10,1", "(0, 0, -1)" },
        { "houdini", "--camera-to-world", "1,0,0,0,0,1,0,0,0,0,1,0,0,0,10,1", "(0, 0, -1)" },
        { "usd", "--camera-to-world", "1,0,0,0,0,1,0,0,0,0,1,0,0,0,10,1", "(0, 0, -1)" },
        { "nuke", "--camera-to-world", "0,0,-1,0,0,1,0,0,1,0,0,10,0,0,0,1", "(1, 0, 0)" },
        { "blender", "--world-to-camera", "1,0,0,0,0,1,0,0,0,0,1,-10,0,0,0,1", "(0, 0, -1)" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        assert_status(run("'%s' --explain --fov 40 --camera-convention %s %s %s", sample(),
                          cases[i].conv, cases[i].flag, cases[i].m), 0);
        char fwd[64];
        snprintf(fwd, sizeof fwd, "forward     %s", cases[i].fwd);
        if (!strstr(g_out, "position    (0, 0, 10)") || !strstr(g_out, fwd) ||
            !strstr(g_out, "up          (0, 1, 0)"))
            fail_msg("%s %s: --explain printed\n%s", cases[i].conv, cases[i].flag, g_out);
    }
    assert_status(run("'%s' --explain --fov 40 --camera-convention max", sample()), 2);
}

/* --up-axis auto (issue 9): z under a V-Ray camera (cameraTransform), y
 * under an OpenEXR worldToCamera: the outputs equal those of --up-axis z
 * and --up-axis y bit for bit. */
static void test_up_axis_auto(void **state)
{
    (void) state;
    fresh_dir("upauto");
    path_t vr = pth("upauto/vray.exr"), ex = pth("upauto/exr.exr"), a = pth("upauto/a.exr"),
           b = pth("upauto/b.exr");
    frame_t f;
    frame_alloc(&f, 16, 8);
    tu_part p;
    frame_part(&p, &f, 0x1f, EXR_PIXEL_FLOAT);
    p.m44[0].name = "cameraTransform";
    static const float c2w[16] = { 1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 0, 1.7f, 1 };
    memcpy(p.m44[0].m, c2w, sizeof c2w);
    p.f[0].name = "cameraFov";
    p.f[0].v = 50;
    write_part(vr.s, &p);
    frame_part(&p, &f, 0x1f, EXR_PIXEL_FLOAT);
    add_camera(&p, 50);
    write_part(ex.s, &p);
    frame_free(&f);
    static const char *const fog = "--fog height:density=0.2:falloff=0.3:base=0.5";
    const char *const files[2] = { vr.s, ex.s }, *const axes[2] = { "z", "y" };
    for (int i = 0; i < 2; ++i) {
        assert_status(run("'%s' -o '%s' %s --up-axis auto", files[i], a.s, fog), 0);
        assert_status(run("'%s' -o '%s' %s --up-axis %s", files[i], b.s, fog, axes[i]), 0);
        tu_image ia, ib;
        assert_int_equal(tu_read_image(a.s, 0, &ia), 0);
        assert_int_equal(tu_read_image(b.s, 0, &ib), 0);
        for (int k = 0; k < 3; ++k) {
            static const char *const ch[3] = { "R", "G", "B" };
            assert_int_equal(tu_compare_channel(&ib, &ia, ch[k], 0.0, 0), 0);
        }
        tu_image_free(&ia);
        tu_image_free(&ib);
    }
    /* and on the V-Ray frame z really differs from y */
    assert_status(run("'%s' -o '%s' %s --up-axis auto", vr.s, a.s, fog), 0);
    assert_status(run("'%s' -o '%s' %s --up-axis y", vr.s, b.s, fog), 0);
    tu_image ia, ib;
    assert_int_equal(tu_read_image(a.s, 0, &ia), 0);
    assert_int_equal(tu_read_image(b.s, 0, &ib), 0);
    assert_true(tu_compare_channel(&ib, &ia, "R", 0.0, 0) > 0);
    tu_image_free(&ia);
    tu_image_free(&ib);
}

/* Rays come from the projection's linear part (issue 9): a far camera's
 * worldToNDC whose translation row carries float32-sized noise (a few
 * ulps of its 1e5-sized entries) gives bit-identical positions (fog_P),
 * so that noise cannot tilt a ray. The camera sits 1e5 from the origin,
 * looking down -Z with a screen-space projection (Arnold's layout). */
static void test_projection_translation_noise(void **state)
{
    (void) state;
    fresh_dir("projnoise");
    path_t a = pth("projnoise/a.exr"), b = pth("projnoise/b.exr"), oa = pth("projnoise/oa.exr"),
           ob = pth("projnoise/ob.exr");
    const int W = 16, H = 8;
    /* worldToCamera: camera at (1e5, 2, 1e5) looking down world -Z (Z flip baked in) */
    const double w2c[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, -1, 0, -1e5, -2, 1e5, 1 };
    const double sx = 1.0 / tan(50.0 * 3.14159265358979323846 / 360.0), sy = sx * W / H;
    const double n = 0.1, fa = 1e5, A = fa / (fa - n), B = -n * fa / (fa - n);
    const double proj[16] = { sx, 0, 0, 0, 0, sy, 0, 0, 0, 0, A, 1, 0, 0, B, 0 };
    double w2ndc[16];
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double v = 0;
            for (int k = 0; k < 4; ++k)
                v += w2c[4 * i + k] * proj[4 * k + j];
            w2ndc[4 * i + j] = v;
        }
    frame_t f;
    frame_alloc(&f, W, H);
    for (int v = 0; v < 2; ++v) {
        tu_part p;
        frame_part(&p, &f, 0x1f, EXR_PIXEL_FLOAT);
        p.m44[0].name = "worldToCamera";
        p.m44[1].name = "worldToNDC";
        for (int k = 0; k < 16; ++k) {
            p.m44[0].m[k] = (float) w2c[k];
            p.m44[1].m[k] = (float) w2ndc[k];
        }
        if (v) /* the translation row, a few float32 ulps off */
            for (int k = 12; k < 16; ++k)
                p.m44[1].m[k] = nextafterf(nextafterf(p.m44[1].m[k], INFINITY), INFINITY);
        write_part(v ? b.s : a.s, &p);
    }
    frame_free(&f);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.01 --aov P", a.s, oa.s), 0);
    assert_status(run("'%s' -o '%s' --fog exp:density=0.01 --aov P", b.s, ob.s), 0);
    tu_image ia, ib;
    assert_int_equal(tu_read_image(oa.s, 0, &ia), 0);
    assert_int_equal(tu_read_image(ob.s, 0, &ib), 0);
    static const char *const ch[4] = { "fog_P.X", "fog_P.Y", "fog_P.Z", "R" };
    for (int k = 0; k < 4; ++k)
        assert_int_equal(tu_compare_channel(&ia, &ib, ch[k], 0.0, 0), 0);
    tu_image_free(&ia);
    tu_image_free(&ib);
}

int main(void)
{
    /* Sanitizer reports in the child must not pass for "exit 1". */
    char buf[1024];
    const char *a = getenv("ASAN_OPTIONS"), *u = getenv("UBSAN_OPTIONS");
    snprintf(buf, sizeof buf, "%s%sexitcode=86", a ? a : "", a && *a ? ":" : "");
    setenv("ASAN_OPTIONS", buf, 1);
    snprintf(buf, sizeof buf, "%s%sexitcode=87", u ? u : "", u && *u ? ":" : "");
    setenv("UBSAN_OPTIONS", buf, 1);

    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_missing_input),
        cmocka_unit_test(test_truncated_in_header),
        cmocka_unit_test(test_truncated_in_offset_table),
        cmocka_unit_test(test_truncated_in_pixel_data),
        cmocka_unit_test(test_corrupt_chunk),
        cmocka_unit_test(test_corrupt_uncompressed_chunk),
        cmocka_unit_test(test_corrupt_offset_table),
        cmocka_unit_test(test_not_exr),
        cmocka_unit_test(test_zero_size),
        cmocka_unit_test(test_absurd_dimensions),
        cmocka_unit_test(test_absurd_dimensions_huge),
        cmocka_unit_test(test_depth_window_mismatch),
        cmocka_unit_test(test_truncated_depth_file),
        cmocka_unit_test(test_nan_inf_depth),
        cmocka_unit_test(test_nan_in_camera),
        cmocka_unit_test(test_no_camera),
        cmocka_unit_test(test_output_dir_missing),
        cmocka_unit_test(test_stream_errors_name_the_bad_file),
        cmocka_unit_test(test_usage_errors),
        cmocka_unit_test(test_help_and_version),
        cmocka_unit_test(test_output_is_input),
        cmocka_unit_test(test_existing_output_untouched),
        cmocka_unit_test(test_killed_run_sigterm),
        cmocka_unit_test(test_killed_sequence_names_frame),
        cmocka_unit_test(test_killed_run_sigint),
        cmocka_unit_test(test_killed_run_sigkill),
        cmocka_unit_test(test_threads_deterministic),
        cmocka_unit_test(test_threads_bit_identical_files),
        cmocka_unit_test(test_neutral_options_same_bytes),
        cmocka_unit_test(test_e2e_exp_chromatic),
        cmocka_unit_test(test_e2e_default_colour_exp2),
        cmocka_unit_test(test_e2e_linear),
        cmocka_unit_test(test_e2e_two_components),
        cmocka_unit_test(test_e2e_planar_distance),
        cmocka_unit_test(test_e2e_sky_keep),
        cmocka_unit_test(test_e2e_sky_distance),
        cmocka_unit_test(test_explain),
        cmocka_unit_test(test_preview),
        cmocka_unit_test(test_output_not_regular),
        cmocka_unit_test(test_output_symlink),
        cmocka_unit_test(test_output_keeps_mode),
        cmocka_unit_test(test_output_long_name),
        cmocka_unit_test(test_output_planted_symlink),
        cmocka_unit_test(test_output_preview_checked_first),
        cmocka_unit_test(test_output_file_size_limit),
        cmocka_unit_test(test_killed_run_other_signals),
        cmocka_unit_test(test_huge_tile_refused),
        cmocka_unit_test(test_messages),
        cmocka_unit_test(test_nonconforming_multipart),
        cmocka_unit_test(test_nonfinite_alpha),
        cmocka_unit_test(test_history),
        cmocka_unit_test(test_trap_warnings),
        cmocka_unit_test(test_output_formats),
        cmocka_unit_test(test_cost_warning),
        cmocka_unit_test(test_cost_prediction),
        cmocka_unit_test(test_data_type_per_channel),
        cmocka_unit_test(test_focal_length),
        cmocka_unit_test(test_explain_partial),
        cmocka_unit_test(test_depth_covers_crop),
        cmocka_unit_test(test_camera_convention),
        cmocka_unit_test(test_up_axis_auto),
        cmocka_unit_test(test_projection_translation_noise),
        cmocka_unit_test(test_lod_pixel_camera),
        cmocka_unit_test(test_sky_rotate_huge),
        cmocka_unit_test(test_shadow_map_bound),
        cmocka_unit_test(test_shadow_camera_file),
        cmocka_unit_test(test_long_light_name_aov),
        cmocka_unit_test(test_light_key_range),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
