/* make_sample.c - render a small synthetic scene by analytic ray casting and
 * write it as an OpenEXR file that exrfog can fog.
 *
 *   make_sample OUT.exr [--size WxH] [--compression none|rle|zips|zip|piz|pxr24|b44|b44a]
 *                       [--tiled N] [--seed S] [--check]
 *                       [--sun-view X,Y,Z [--sun-width W] [--sun-centre X,Y,Z]]
 *
 * --sun-view renders the same scene from the sun instead (towards X,Y,Z):
 * an orthographic camera looking along the sunlight, W units wide (default
 * 240) around the centre (default 0,0,-90), Z its planar depth: a shadow
 * map for exrfog --light sun:...:shadow=OUT.exr, whose worldToNDC is
 * orthographic (w column 0 0 0 1).
 *
 * Output: one part, channels R,G,B,A (half) and Z (float, planar camera-space
 * depth = distance along the view axis; sky = 1e10 with A = 0, like Cycles).
 * Header: worldToCamera and worldToNDC (M44f, OpenEXR conventions, see below),
 * CameraFov (float, horizontal degrees), comments (string).
 *
 * Conventions (OpenEXR / RenderMan, Imath row vectors p' = p . M, translation in m[12..14]):
 *   world      right-handed, Y up, ground plane y = 0.
 *   camera     left-handed, +X right, +Y up, +Z = viewing direction.  A right-handed
 *              world therefore bakes a Z flip into worldToCamera: det(3x3) = -1.
 *   NDC        x right, y DOWN, (0,0) = top-left corner of the displayWindow,
 *              (1,1) = bottom-right corner; w = z_cam, p_ndc = (p . worldToNDC).xy / w.
 *              NDC z is D3D-style [0,1] between near 0.1 and far 1e5 (informative only).
 *   pixels     pixel (x, y) has its centre at NDC ((x + 0.5) / W, (y + 0.5) / H).
 *
 * The image is streamed chunk by chunk (scanline block or tile); no buffer
 * larger than one chunk is allocated.  The camera is checked for every pixel:
 * the centre-ray hit point projected with the stored (float) worldToNDC must land
 * on the pixel centre within 1e-5, and its camera z (stored worldToCamera) must
 * equal the stored Z.  --check also prints the statistics and reads the file back,
 * comparing every decoded chunk with a re-render.
 *
 * Build: cc -std=c11 -Wall -Wextra -O2 make_sample.c -o make_sample \
 *            $(pkg-config --cflags --libs OpenEXR) -lm
 */
#include <openexr.h>

#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PROG "make_sample"
#define PI 3.14159265358979323846
#define SKY_Z 1e10f
#define NEAR_CLIP 0.1
#define FAR_CLIP 1e5
#define HFOV_DEG 60.0
#define CHECK_TOL 1e-5
#define MAX_DIM 65536
#define MAX_TILE 4096

/* ------------------------------------------------------------------ vectors */

typedef struct { double x, y, z; } v3;

static v3 V(double x, double y, double z) { v3 r = { x, y, z }; return r; }
static v3 add(v3 a, v3 b) { return V(a.x + b.x, a.y + b.y, a.z + b.z); }
static v3 sub(v3 a, v3 b) { return V(a.x - b.x, a.y - b.y, a.z - b.z); }
static v3 scl(v3 a, double s) { return V(a.x * s, a.y * s, a.z * s); }
static v3 mulv(v3 a, v3 b) { return V(a.x * b.x, a.y * b.y, a.z * b.z); }
static double dot(v3 a, v3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static double len(v3 a) { return sqrt(dot(a, a)); }
static v3 norm(v3 a) { return scl(a, 1.0 / len(a)); }
static v3 cross(v3 a, v3 b)
{
    return V(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
static v3 lerp(v3 a, v3 b, double t) { return add(scl(a, 1.0 - t), scl(b, t)); }
static double clampd(double v, double lo, double hi) { return v < lo ? lo : v > hi ? hi : v; }

/* ------------------------------------------------------------------ random */

static uint64_t splitmix64(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}
static double rnd01(uint64_t *s) { return (double) (splitmix64(s) >> 11) * (1.0 / 9007199254740992.0); }

static double hash01(uint32_t x, uint32_t y, uint32_t k, uint64_t seed)
{
    uint64_t s = seed ^ ((uint64_t) x * 0x8da6b343u) ^ ((uint64_t) y * 0xd8163841u << 20)
               ^ ((uint64_t) k * 0xcb1ab31fu << 40);
    return rnd01(&s);
}

/* ------------------------------------------------------------------ scene */

typedef struct { v3 c; double r; v3 alb; } sphere_t;
typedef struct { v3 lo, hi; v3 alb; } box_t;

enum { MAX_SPHERES = 48, MAX_BOXES = 8, N_RANDOM_SPHERES = 10 };

typedef struct {
    sphere_t sph[MAX_SPHERES]; int nsph;
    box_t box[MAX_BOXES]; int nbox;
    v3 sun_dir, sun_col, amb_sky, amb_ground;
} scene_t;

typedef struct {
    int W, H;
    v3 eye, r, u, f;        /* world position; right, up, forward (unit) */
    double sx, sy;          /* NDC scale: u = 0.5 + sx * x/z, v = 0.5 - sy * y/z
                             * (orthographic: x and y, not x/z and y/z) */
    int ortho;
    double hfov;            /* CameraFov, degrees */
    float w2c[16], w2n[16]; /* exactly what goes into the header */
} camera_t;

typedef struct {
    double t;   /* ray parameter; for camera rays (dir.z_cam = 1) = planar depth */
    v3 n, alb;
    int kind;   /* 0 none, 1 ground, 2 object */
} hit_t;

static void add_sphere(scene_t *s, double x, double y, double z, double r, v3 alb)
{
    if (s->nsph < MAX_SPHERES) {
        s->sph[s->nsph].c = V(x, y, z); s->sph[s->nsph].r = r; s->sph[s->nsph].alb = alb;
        s->nsph++;
    }
}

static void add_box(scene_t *s, v3 lo, v3 hi, v3 alb)
{
    if (s->nbox < MAX_BOXES) {
        s->box[s->nbox].lo = lo; s->box[s->nbox].hi = hi; s->box[s->nbox].alb = alb;
        s->nbox++;
    }
}

/* Horizontal (xz) clearance between a candidate sphere and everything placed so far. */
static int overlaps(const scene_t *s, v3 c, double r)
{
    for (int i = 0; i < s->nsph; ++i) {
        double dx = c.x - s->sph[i].c.x, dz = c.z - s->sph[i].c.z;
        if (sqrt(dx * dx + dz * dz) < r + s->sph[i].r + 0.3) return 1;
    }
    for (int i = 0; i < s->nbox; ++i) {
        const box_t *b = &s->box[i];
        if (c.x + r + 0.3 > b->lo.x && c.x - r - 0.3 < b->hi.x &&
            c.z + r + 0.3 > b->lo.z && c.z - r - 0.3 < b->hi.z) return 1;
    }
    return 0;
}

static void build_scene(scene_t *s, const camera_t *cam, uint64_t seed)
{
    memset(s, 0, sizeof *s);
    /* Hero objects at roughly 5, 9, 15, 20, 40, 90, 120, 180 units. */
    add_sphere(s, -1.3, 0.6, -5.0, 0.6, V(0.70, 0.08, 0.06));     /* red */
    add_sphere(s, 1.6, 1.0, -9.0, 1.0, V(0.10, 0.22, 0.65));      /* blue */
    add_sphere(s, -4.5, 2.0, -20.0, 2.0, V(0.12, 0.50, 0.14));    /* green */
    add_sphere(s, 9.0, 3.0, -42.0, 3.0, V(0.80, 0.55, 0.08));     /* yellow */
    add_sphere(s, -16.0, 6.0, -88.0, 6.0, V(0.75, 0.75, 0.75));   /* white */
    add_sphere(s, 26.0, 10.0, -178.0, 10.0, V(0.60, 0.20, 0.45)); /* purple */
    add_box(s, V(2.6, 0.0, -15.8), V(4.4, 1.8, -14.0), V(0.55, 0.35, 0.18));       /* crate */
    add_box(s, V(-9.0, 0.0, -33.0), V(-7.0, 9.0, -31.0), V(0.45, 0.45, 0.48));     /* pillar */
    add_box(s, V(-34.0, 0.0, -128.0), V(-22.0, 26.0, -116.0), V(0.50, 0.42, 0.36)); /* tower */
    add_box(s, V(40.0, 0.0, -215.0), V(70.0, 18.0, -195.0), V(0.40, 0.45, 0.50));  /* hall */

    /* Seeded extra spheres, log-uniform in distance 5..200, inside the view. */
    static const double pal[8][3] = {
        { 0.75, 0.30, 0.10 }, { 0.20, 0.55, 0.55 }, { 0.70, 0.70, 0.20 }, { 0.35, 0.20, 0.60 },
        { 0.80, 0.80, 0.80 }, { 0.15, 0.40, 0.15 }, { 0.65, 0.15, 0.30 }, { 0.30, 0.30, 0.32 },
    };
    uint64_t rs = seed * 0x2545f4914f6cdd1dull + 12345u;
    double yaw0 = atan2(cam->f.x, -cam->f.z);
    double half = atan(0.5 / cam->sx) * 0.92;
    int placed = 0;
    for (int tries = 0; placed < N_RANDOM_SPHERES && tries < 2000; ++tries) {
        double d = 5.0 * pow(40.0, rnd01(&rs));
        double a = yaw0 + (2.0 * rnd01(&rs) - 1.0) * half;
        double r = d * (0.010 + 0.025 * rnd01(&rs));
        const double *p = pal[splitmix64(&rs) & 7];
        v3 c = V(cam->eye.x + d * sin(a), r, cam->eye.z - d * cos(a));
        if (overlaps(s, c, r)) continue;
        add_sphere(s, c.x, c.y, c.z, r, V(p[0], p[1], p[2]));
        placed++;
    }
    s->sun_dir = norm(V(0.55, 0.70, 0.30));          /* towards the sun */
    s->sun_col = V(2.6, 2.45, 2.2);
    s->amb_sky = V(0.30, 0.38, 0.52);
    s->amb_ground = V(0.10, 0.09, 0.08);
}

static int hit_sphere(const sphere_t *sp, v3 o, v3 d, double tmin, double *t)
{
    v3 oc = sub(o, sp->c);
    double a = dot(d, d), b = dot(oc, d), c = dot(oc, oc) - sp->r * sp->r;
    double disc = b * b - a * c;
    if (disc < 0) return 0;
    double q = sqrt(disc);
    double t0 = (-b - q) / a, t1 = (-b + q) / a;
    if (t0 > tmin) { *t = t0; return 1; }
    if (t1 > tmin) { *t = t1; return 1; }
    return 0;
}

static int hit_box(const box_t *bx, v3 o, v3 d, double tmin, double *t, v3 *n)
{
    double lo[3] = { bx->lo.x, bx->lo.y, bx->lo.z }, hi[3] = { bx->hi.x, bx->hi.y, bx->hi.z };
    double oo[3] = { o.x, o.y, o.z }, dd[3] = { d.x, d.y, d.z };
    double tn = -INFINITY, tf = INFINITY;
    int an = 0, af = 0; double sn = 1, sf = 1;
    for (int k = 0; k < 3; ++k) {
        if (dd[k] == 0.0) {
            if (oo[k] < lo[k] || oo[k] > hi[k]) return 0;
            continue;
        }
        double inv = 1.0 / dd[k];
        double ta = (lo[k] - oo[k]) * inv, tb = (hi[k] - oo[k]) * inv;
        double s = -1.0;                 /* entering through the lo face */
        if (ta > tb) { double tmp = ta; ta = tb; tb = tmp; s = 1.0; }
        if (ta > tn) { tn = ta; an = k; sn = s; }
        if (tb < tf) { tf = tb; af = k; sf = -s; }
    }
    if (tn > tf) return 0;
    double tt; int ax; double sg;
    if (tn > tmin) { tt = tn; ax = an; sg = sn; }
    else if (tf > tmin) { tt = tf; ax = af; sg = sf; }
    else return 0;
    *t = tt;
    *n = V(ax == 0 ? sg : 0, ax == 1 ? sg : 0, ax == 2 ? sg : 0);
    return 1;
}

/* Closest hit along o + t d, t > tmin (d need not be unit length). */
static hit_t trace(const scene_t *s, v3 o, v3 d, double tmin)
{
    hit_t h = { INFINITY, { 0, 1, 0 }, { 0, 0, 0 }, 0 };
    if (d.y < 0 && o.y > 0) {
        double t = -o.y / d.y;
        if (t > tmin) { h.t = t; h.kind = 1; h.n = V(0, 1, 0); }
    }
    for (int i = 0; i < s->nsph; ++i) {
        double t;
        if (hit_sphere(&s->sph[i], o, d, tmin, &t) && t < h.t) {
            h.t = t; h.kind = 2; h.alb = s->sph[i].alb;
            h.n = scl(sub(add(o, scl(d, t)), s->sph[i].c), 1.0 / s->sph[i].r);
        }
    }
    for (int i = 0; i < s->nbox; ++i) {
        double t; v3 n;
        if (hit_box(&s->box[i], o, d, tmin, &t, &n) && t < h.t) {
            h.t = t; h.kind = 2; h.alb = s->box[i].alb; h.n = n;
        }
    }
    return h;
}

static int occluded(const scene_t *s, v3 o, v3 d)
{
    double t; v3 n;
    for (int i = 0; i < s->nsph; ++i)
        if (hit_sphere(&s->sph[i], o, d, 0.0, &t)) return 1;
    for (int i = 0; i < s->nbox; ++i)
        if (hit_box(&s->box[i], o, d, 0.0, &t, &n)) return 1;
    return 0;
}

/* Cheap analytic ambient occlusion from the spheres (and the boxes, treated as spheres). */
static double ambient_occlusion(const scene_t *s, v3 p, v3 n)
{
    double occ = 0;
    for (int i = 0; i < s->nsph + s->nbox; ++i) {
        v3 c; double r;
        if (i < s->nsph) { c = s->sph[i].c; r = s->sph[i].r; }
        else {
            const box_t *b = &s->box[i - s->nsph];
            c = scl(add(b->lo, b->hi), 0.5);
            r = 0.5 * fmin(b->hi.x - b->lo.x, fmin(b->hi.y - b->lo.y, b->hi.z - b->lo.z));
        }
        v3 dv = sub(c, p);
        double l2 = dot(dv, dv), l = sqrt(l2);
        if (l <= r * 1.0001) continue;       /* p on (or in) this object */
        double cosv = dot(n, dv) / l;
        if (cosv > 0) occ += cosv * r * r / l2;
    }
    return exp(-1.2 * occ);   /* soft: a contact point stays dim, not black */
}

static double fract(double x) { return x - floor(x); }

/* Box-filtered checker (0/1), footprint w in checker units per axis. */
static double checker_filtered(double px, double pz, double wx, double wz)
{
    wx += 1e-3; wz += 1e-3;
    double ix = 2.0 * (fabs(fract((px - 0.5 * wx) * 0.5) - 0.5) - fabs(fract((px + 0.5 * wx) * 0.5) - 0.5)) / wx;
    double iz = 2.0 * (fabs(fract((pz - 0.5 * wz) * 0.5) - 0.5) - fabs(fract((pz + 0.5 * wz) * 0.5) - 0.5)) / wz;
    return 0.5 - 0.5 * ix * iz;
}

static v3 sky_colour(v3 d)
{
    v3 dn = norm(d);
    double t = sqrt(clampd(dn.y, 0.0, 1.0));
    return lerp(V(0.85, 0.92, 1.05), V(0.18, 0.36, 0.85), t);
}

/* ------------------------------------------------------------------ camera */

/* World-space ray direction for NDC (u, v), scaled so that its camera z is 1. */
static v3 cam_dir(const camera_t *c, double u, double v)
{
    double xc = (u - 0.5) / c->sx, yc = -(v - 0.5) / c->sy;
    if (c->ortho)
        return c->f;
    return add(add(scl(c->r, xc), scl(c->u, yc)), c->f);
}

/* Where the ray for NDC (u, v) starts: the eye, or for an orthographic
 * camera the point of its image plane. */
static v3 cam_org(const camera_t *c, double u, double v)
{
    if (!c->ortho)
        return c->eye;
    double xc = (u - 0.5) / c->sx, yc = -(v - 0.5) / c->sy;
    return add(c->eye, add(scl(c->r, xc), scl(c->u, yc)));
}

/* worldToCamera from the camera's axes and eye, and worldToNDC as it times
 * the camera-to-NDC matrix p, both as floats exactly as the header holds
 * them. */
static void store_matrices(camera_t *c, const double p[16])
{
    /* worldToCamera (row vectors): columns = camera axes (right, up, forward) in world. */
    double m[16] = { 0 };
    v3 ax[3] = { c->r, c->u, c->f };
    for (int j = 0; j < 3; ++j) {
        m[0 * 4 + j] = ax[j].x; m[1 * 4 + j] = ax[j].y; m[2 * 4 + j] = ax[j].z;
        m[3 * 4 + j] = -dot(c->eye, ax[j]);
    }
    m[15] = 1.0;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            double acc = 0;
            for (int k = 0; k < 4; ++k) acc += m[i * 4 + k] * p[k * 4 + j];
            c->w2n[i * 4 + j] = (float) (acc + 0.0);          /* + 0.0: no "-0" */
            c->w2c[i * 4 + j] = (float) (m[i * 4 + j] + 0.0);
        }
}

/* The default view: eye 1.7 up, 4 degrees down, HFOV_DEG wide; view[]
 * (height, pitch, fov in degrees) replaces it. */
static void setup_camera(camera_t *c, int W, int H, const double view[3])
{
    const double yaw = 6.0 * PI / 180.0;     /* turned slightly right */
    const double pitch = view[1] * PI / 180.0;
    c->W = W; c->H = H;
    c->ortho = 0;
    c->eye = V(0.0, view[0], 0.0);
    c->f = V(sin(yaw) * cos(pitch), sin(pitch), -cos(yaw) * cos(pitch));
    c->r = norm(cross(c->f, V(0, 1, 0)));
    c->u = cross(c->r, c->f);
    c->hfov = view[2];
    double tan_h = tan(0.5 * view[2] * PI / 180.0);
    double tan_v = tan_h * (double) H / (double) W;  /* pixelAspectRatio 1 */
    c->sx = 0.5 / tan_h;
    c->sy = 0.5 / tan_v;

    /* camera -> NDC: (x, y, z, 1) -> (sx x + 0.5 z, -sy y + 0.5 z, A z + B, z). */
    double A = FAR_CLIP / (FAR_CLIP - NEAR_CLIP), B = -NEAR_CLIP * FAR_CLIP / (FAR_CLIP - NEAR_CLIP);
    const double p[16] = { c->sx, 0, 0, 0,
                           0, -c->sy, 0, 0,
                           0.5, 0.5, A, 1,
                           0, 0, B, 0 };
    store_matrices(c, p);
}

/* The sun's orthographic view of the scene: looking along -towards from
 * 1000 units towards the sun over a width x width * H / W window around
 * centre. */
static void setup_sun_camera(camera_t *c, int W, int H, v3 towards, v3 centre, double width)
{
    c->W = W; c->H = H;
    c->ortho = 1;
    c->hfov = HFOV_DEG;
    c->f = scl(norm(towards), -1.0);
    v3 up = fabs(c->f.y) > 0.99 ? V(0, 0, -1) : V(0, 1, 0);
    c->r = norm(cross(c->f, up));
    c->u = cross(c->r, c->f);
    c->eye = add(centre, scl(norm(towards), 1000.0));
    c->sx = 1.0 / width;
    c->sy = 1.0 / (width * (double) H / (double) W);
    /* camera -> NDC: (x, y, z, 1) -> (sx x + 0.5, -sy y + 0.5, z / 1e4, 1) */
    const double p[16] = { c->sx, 0, 0, 0,
                           0, -c->sy, 0, 0,
                           0, 0, 1e-4, 0,
                           0.5, 0.5, 0, 1 };
    store_matrices(c, p);
}

static void xform(const float *m, v3 p, double out[4])
{
    for (int j = 0; j < 4; ++j)
        out[j] = p.x * m[j] + p.y * m[4 + j] + p.z * m[8 + j] + m[12 + j];
}

/* ------------------------------------------------------------------ render */

typedef struct {
    const scene_t *s;
    const camera_t *c;
    uint64_t seed;
    /* camera self-check statistics */
    double max_ndc_err, max_z_err;
    long long nchecked, nsky;
} render_t;

static v3 shade_ground(const render_t *R, v3 p, double fx, double fy)
{
    /* Ray differentials: where do the neighbouring pixels' rays hit the ground? */
    const camera_t *c = R->c;
    v3 dx = cam_dir(c, (fx + 1.0) / c->W, fy / c->H), dy = cam_dir(c, fx / c->W, (fy + 1.0) / c->H);
    double wx = 1e3, wz = 1e3;
    if (c->ortho) {
        wx = wz = 1.0 / (c->sx * c->W);
    } else if (dx.y < 0 && dy.y < 0) {
        v3 px = add(c->eye, scl(dx, -c->eye.y / dx.y)), py = add(c->eye, scl(dy, -c->eye.y / dy.y));
        wx = fmax(fabs(px.x - p.x), fabs(py.x - p.x));
        wz = fmax(fabs(px.z - p.z), fabs(py.z - p.z));
    }
    const double sq = 2.0;  /* checker square size */
    double k = checker_filtered(p.x / sq, p.z / sq, 0.5 * wx / sq, 0.5 * wz / sq);
    return lerp(V(0.08, 0.085, 0.09), V(0.42, 0.40, 0.36), k);
}

/* Colour of one camera sample at continuous pixel position (fx, fy); sets *covered. */
static v3 sample(const render_t *R, double fx, double fy, int *covered)
{
    const camera_t *c = R->c; const scene_t *s = R->s;
    v3 d = cam_dir(c, fx / c->W, fy / c->H), o0 = cam_org(c, fx / c->W, fy / c->H);
    hit_t h = trace(s, o0, d, 1e-6);
    if (!h.kind) { *covered = 0; return sky_colour(d); }
    *covered = 1;
    v3 p = add(o0, scl(d, h.t));
    v3 alb = h.kind == 1 ? shade_ground(R, p, fx, fy) : h.alb;
    double ndl = dot(h.n, s->sun_dir);
    double sun = 0;
    if (ndl > 0) {
        v3 o = add(p, scl(h.n, 1e-5 * fmax(1.0, h.t)));
        sun = occluded(s, o, s->sun_dir) ? 0.0 : ndl;
    }
    v3 amb = lerp(s->amb_ground, s->amb_sky, 0.5 + 0.5 * h.n.y);
    double ao = ambient_occlusion(s, p, h.n);
    return mulv(alb, add(scl(s->sun_col, sun), scl(amb, ao)));
}

/* Render the w x h region at (x0, y0) into planes R,G,B,A,Z with line stride w. */
static int render_region(render_t *R, int x0, int y0, int w, int h, float *pl[5])
{
    const camera_t *c = R->c;
    int ok = 1;
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i) {
            int x = x0 + i, y = y0 + j;
            size_t o = (size_t) j * w + i;
            v3 acc = V(0, 0, 0); int cov = 0;
            for (int k = 0; k < 4; ++k) {   /* 2x2 jittered supersampling for colour */
                double jx = ((k & 1) + hash01((uint32_t) x, (uint32_t) y, 2u * k, R->seed)) * 0.5;
                double jy = ((k >> 1) + hash01((uint32_t) x, (uint32_t) y, 2u * k + 1, R->seed)) * 0.5;
                int cv; acc = add(acc, sample(R, x + jx, y + jy, &cv)); cov += cv;
            }
            pl[0][o] = (float) (acc.x * 0.25); pl[1][o] = (float) (acc.y * 0.25);
            pl[2][o] = (float) (acc.z * 0.25); pl[3][o] = (float) (cov * 0.25);

            /* Depth from the pixel-centre ray: planar camera-space z (ray has z_cam = 1). */
            double u = (x + 0.5) / c->W, v = (y + 0.5) / c->H;
            v3 d = cam_dir(c, u, v), o0 = cam_org(c, u, v);
            hit_t hc = trace(R->s, o0, d, 1e-6);
            pl[4][o] = hc.kind ? (float) hc.t : SKY_Z;

            /* Self-check with the float matrices exactly as stored in the header. */
            v3 p = add(o0, scl(d, hc.kind ? hc.t : 1000.0));
            double q[4], qc[4];
            xform(c->w2n, p, q);
            xform(c->w2c, p, qc);
            double e = fmax(fabs(q[0] / q[3] - u), fabs(q[1] / q[3] - v));
            double ze = hc.kind ? fabs(qc[2] - pl[4][o]) / fmax(1.0, fabs(pl[4][o])) : 0.0;
            if (e > R->max_ndc_err) R->max_ndc_err = e;
            if (ze > R->max_z_err) R->max_z_err = ze;
            R->nchecked++; R->nsky += !hc.kind;
            if (!(e <= CHECK_TOL) || !(ze <= CHECK_TOL)) ok = 0;
        }
    return ok;
}

/* ------------------------------------------------------------------ EXR I/O */

static const char *const CHAN[5] = { "R", "G", "B", "A", "Z" };

static int chan_index(const char *n)
{
    for (int i = 0; i < 5; ++i) if (!strcmp(n, CHAN[i])) return i;
    return -1;
}

static void err_handler(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
    (void) ctxt;
    fprintf(stderr, PROG ": OpenEXR: %s (%s)\n", msg ? msg : "", exr_get_error_code_as_string(code));
}

#define CHK(call) do { exr_result_t rv_ = (call); if (rv_ != EXR_ERR_SUCCESS) { \
    fprintf(stderr, PROG ": %s failed: %s\n", #call, exr_get_error_code_as_string(rv_)); \
    goto fail; } } while (0)

typedef struct {
    const char *out;
    int W, H, tile;
    exr_compression_t comp;
    uint64_t seed;
    int check;
    int sun_view;
    double sun[3], sun_centre[3], sun_width;
    double view[3];   /* --view HEIGHT,PITCH,FOV: eye height, pitch and horizontal fov (degrees) */
} opts_t;

static void comments_string(const opts_t *o, char *buf, size_t n)
{
    snprintf(buf, n, "Synthetic test scene made by make_sample (exrfog samples/make_sample.c): "
             "%dx%d, seed %llu. Y-up right-handed world, ground plane y=0; "
             "Z = planar camera-space depth (sky: Z=1e10, A=0); scene-linear RGB; "
             "worldToNDC is true OpenEXR NDC (y down, w = camera z).",
             o->W, o->H, (unsigned long long) o->seed);
}

static int write_image(const opts_t *o, render_t *R)
{
    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    float *buf = NULL, *pl[5];
    int part, started = 0, failed_check = 0;
    char comments[512];
    const camera_t *c = R->c;
    exr_attr_m44f_t w2c, w2n;

    init.error_handler_fn = err_handler;
    memcpy(w2c.m, c->w2c, sizeof w2c.m);
    memcpy(w2n.m, c->w2n, sizeof w2n.m);
    comments_string(o, comments, sizeof comments);

    CHK(exr_start_write(&f, o->out, EXR_WRITE_FILE_DIRECTLY, &init));
    CHK(exr_add_part(f, NULL, o->tile ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE, &part));
    CHK(exr_initialize_required_attr_simple(f, part, o->W, o->H, o->comp));
    if (o->tile)
        CHK(exr_set_tile_descriptor(f, part, (uint32_t) o->tile, (uint32_t) o->tile,
                                    EXR_TILE_ONE_LEVEL, EXR_TILE_ROUND_DOWN));
    for (int k = 0; k < 5; ++k)
        CHK(exr_add_channel(f, part, CHAN[k], k < 4 ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT,
                            k < 3 ? EXR_PERCEPTUALLY_LOGARITHMIC : EXR_PERCEPTUALLY_LINEAR, 1, 1));
    CHK(exr_attr_set_m44f(f, part, "worldToCamera", &w2c));
    CHK(exr_attr_set_m44f(f, part, "worldToNDC", &w2n));
    CHK(exr_attr_set_float(f, part, "CameraFov", (float) R->c->hfov));
    CHK(exr_attr_set_string(f, part, "comments", comments));
    CHK(exr_write_header(f));

    int cw, ch;   /* chunk buffer size */
    int32_t lpc = 0;
    if (o->tile) {
        cw = o->tile < o->W ? o->tile : o->W;
        ch = o->tile < o->H ? o->tile : o->H;
    } else {
        CHK(exr_get_scanlines_per_chunk(f, part, &lpc));
        cw = o->W;
        ch = lpc < o->H ? lpc : o->H;
    }
    buf = malloc(sizeof(float) * 5 * (size_t) cw * (size_t) ch);
    if (!buf) { fprintf(stderr, PROG ": out of memory\n"); goto fail; }
    for (int k = 0; k < 5; ++k) pl[k] = buf + (size_t) k * cw * ch;

    int ntx = o->tile ? (o->W + o->tile - 1) / o->tile : 1;
    int nty = o->tile ? (o->H + o->tile - 1) / o->tile : (o->H + lpc - 1) / lpc;
    for (int ty = 0; ty < nty; ++ty)
        for (int tx = 0; tx < ntx; ++tx) {
            exr_chunk_info_t ci;
            int x0, y0;
            if (o->tile) {
                CHK(exr_write_tile_chunk_info(f, part, tx, ty, 0, 0, &ci));
                x0 = tx * o->tile; y0 = ty * o->tile;
            } else {
                CHK(exr_write_scanline_chunk_info(f, part, ty * lpc, &ci));
                x0 = 0; y0 = ty * lpc;
            }
            int w = ci.width, h = ci.height;
            if (w > cw || h > ch) { fprintf(stderr, PROG ": unexpected chunk size\n"); goto fail; }
            if (!render_region(R, x0, y0, w, h, pl)) failed_check = 1;
            if (!started) CHK(exr_encoding_initialize(f, part, &ci, &enc));
            else          CHK(exr_encoding_update(f, part, &ci, &enc));
            for (int k = 0; k < enc.channel_count; ++k) {
                exr_coding_channel_info_t *cc = &enc.channels[k];
                int idx = chan_index(cc->channel_name);
                if (idx < 0) { fprintf(stderr, PROG ": unexpected channel\n"); goto fail; }
                cc->encode_from_ptr = (const uint8_t *) pl[idx];
                cc->user_data_type = EXR_PIXEL_FLOAT;
                cc->user_bytes_per_element = 4;
                cc->user_pixel_stride = 4;
                cc->user_line_stride = 4 * w;
            }
            if (!started) CHK(exr_encoding_choose_default_routines(f, part, &enc));
            started = 1;
            CHK(exr_encoding_run(f, part, &enc));
        }
    CHK(exr_encoding_destroy(f, &enc));
    started = 0;
    CHK(exr_finish(&f));
    free(buf);
    if (failed_check) {
        fprintf(stderr, PROG ": camera self-check FAILED: max NDC error %.3g, max relative Z error %.3g "
                "(tolerance %g)\n", R->max_ndc_err, R->max_z_err, CHECK_TOL);
        return 1;
    }
    return 0;
fail:
    if (started) exr_encoding_destroy(f, &enc);
    if (f) exr_finish(&f);
    free(buf);
    remove(o->out);
    return 1;
}

/* Read the file back and compare every chunk with a re-render (--check). */
static int verify_file(const opts_t *o, render_t *R)
{
    exr_context_t f = NULL;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    float *buf = NULL, *pl[5], *ref[5];
    int started = 0, bad = 0;
    const camera_t *c = R->c;
    int lossy = o->comp == EXR_COMPRESSION_PXR24 || o->comp == EXR_COMPRESSION_B44 ||
                o->comp == EXR_COMPRESSION_B44A;
    double maxerr[5] = { 0 };

    init.error_handler_fn = err_handler;
    CHK(exr_start_read(&f, o->out, &init));

    exr_attr_m44f_t m; float fov; int32_t slen; const char *str;
    exr_attr_box2i_t dw, disp;
    exr_storage_t st;
    CHK(exr_attr_get_m44f(f, 0, "worldToCamera", &m));
    if (memcmp(m.m, c->w2c, sizeof m.m)) { fprintf(stderr, PROG ": check: worldToCamera differs\n"); bad = 1; }
    CHK(exr_attr_get_m44f(f, 0, "worldToNDC", &m));
    if (memcmp(m.m, c->w2n, sizeof m.m)) { fprintf(stderr, PROG ": check: worldToNDC differs\n"); bad = 1; }
    CHK(exr_attr_get_float(f, 0, "CameraFov", &fov));
    if (fov != (float) R->c->hfov) { fprintf(stderr, PROG ": check: CameraFov differs\n"); bad = 1; }
    CHK(exr_attr_get_string(f, 0, "comments", &slen, &str));
    CHK(exr_get_data_window(f, 0, &dw));
    CHK(exr_get_display_window(f, 0, &disp));
    CHK(exr_get_storage(f, 0, &st));
    if (dw.min.x != 0 || dw.min.y != 0 || dw.max.x != o->W - 1 || dw.max.y != o->H - 1 ||
        memcmp(&dw, &disp, sizeof dw)) {
        fprintf(stderr, PROG ": check: unexpected data/display window\n"); bad = 1;
        goto done;
    }
    if (st != (o->tile ? EXR_STORAGE_TILED : EXR_STORAGE_SCANLINE)) {
        fprintf(stderr, PROG ": check: unexpected storage type\n"); bad = 1;
        goto done;
    }

    int32_t tw, th;
    if (o->tile) CHK(exr_get_tile_sizes(f, 0, 0, 0, &tw, &th));
    else { tw = o->W; CHK(exr_get_scanlines_per_chunk(f, 0, &th)); }
    int cw = tw < o->W ? tw : o->W, ch = th < o->H ? th : o->H;
    buf = malloc(sizeof(float) * 10 * (size_t) cw * (size_t) ch);
    if (!buf) { fprintf(stderr, PROG ": out of memory\n"); goto fail; }
    for (int k = 0; k < 5; ++k) {
        pl[k] = buf + (size_t) k * cw * ch;
        ref[k] = buf + (size_t) (5 + k) * cw * ch;
    }
    render_t R2 = *R;
    for (int ty = 0; ty * th < o->H; ++ty)
        for (int tx = 0; tx * tw < o->W; ++tx) {
            exr_chunk_info_t ci;
            if (o->tile) CHK(exr_read_tile_chunk_info(f, 0, tx, ty, 0, 0, &ci));
            else         CHK(exr_read_scanline_chunk_info(f, 0, ty * th, &ci));
            int w = ci.width, h = ci.height;
            if (!started) CHK(exr_decoding_initialize(f, 0, &ci, &dec));
            else          CHK(exr_decoding_update(f, 0, &ci, &dec));
            for (int k = 0; k < dec.channel_count; ++k) {
                exr_coding_channel_info_t *cc = &dec.channels[k];
                int idx = chan_index(cc->channel_name);
                cc->decode_to_ptr = idx < 0 ? NULL : (uint8_t *) pl[idx];
                cc->user_data_type = EXR_PIXEL_FLOAT;
                cc->user_bytes_per_element = 4;
                cc->user_pixel_stride = 4;
                cc->user_line_stride = 4 * w;
            }
            if (!started) CHK(exr_decoding_choose_default_routines(f, 0, &dec));
            started = 1;
            CHK(exr_decoding_run(f, 0, &dec));
            render_region(&R2, tx * tw, ty * th, w, h, ref);
            for (int k = 0; k < 5; ++k)
                for (size_t i = 0; i < (size_t) w * h; ++i) {
                    double e = fabs((double) pl[k][i] - ref[k][i]) / fmax(1.0, fabs(ref[k][i]));
                    if (!(e <= maxerr[k])) maxerr[k] = e;   /* also catches NaN */
                }
        }
    printf("read-back max relative error: R %.2g G %.2g B %.2g A %.2g Z %.2g%s\n",
           maxerr[0], maxerr[1], maxerr[2], maxerr[3], maxerr[4],
           lossy ? " (lossy compression: informative)" : "");
    if (!lossy) {
        for (int k = 0; k < 4; ++k)
            if (!(maxerr[k] <= 1e-3)) bad = 1;   /* half rounding: <= 2^-11 relative */
        if (!(maxerr[4] == 0.0)) bad = 1;        /* float Z is stored exactly */
        if (bad) fprintf(stderr, PROG ": check: decoded pixels differ from the render\n");
    }
done:
    if (started) CHK(exr_decoding_destroy(f, &dec));
    started = 0;
    CHK(exr_finish(&f));
    free(buf);
    return bad;
fail:
    if (started) exr_decoding_destroy(f, &dec);
    if (f) exr_finish(&f);
    free(buf);
    return 1;
}

/* ------------------------------------------------------------------ main */

static void usage(FILE *to)
{
    fprintf(to,
        "usage: " PROG " OUT.exr [--size WxH] [--compression none|rle|zips|zip|piz|pxr24|b44|b44a]\n"
        "                   [--tiled N] [--seed S] [--check]\n"
        "Renders a synthetic fog test scene: R,G,B,A half + Z float (planar depth, sky 1e10),\n"
        "worldToCamera/worldToNDC (OpenEXR conventions), CameraFov (horizontal degrees).\n"
        "  --size WxH          image size (default 640x360)\n"
        "  --compression C     default zip\n"
        "  --tiled N           write a tiled ONE_LEVEL file with NxN tiles (default scanline)\n"
        "  --seed S            layout of the extra spheres and sample jitter (default 1)\n"
        "  --check             print the camera self-check and verify the written file\n"
        "  --sun-view X,Y,Z    render the scene's depth from the sun (towards X,Y,Z) with an\n"
        "                      orthographic camera: a shadow map for exrfog's shadow=\n"
        "  --sun-width W       its width in scene units (default 240)\n"
        "  --sun-centre X,Y,Z  what it looks at (default 0,0,-90)\n"
        "  --view H,P,F        the camera: eye H units above the ground, pitch P degrees\n"
        "                      (negative: down), horizontal fov F degrees (default 1.7,-4,60)\n");
}

static int parse_int(const char *s, long lo, long hi, long *out)
{
    char *end; errno = 0;
    long v = strtol(s, &end, 10);
    if (errno || end == s || *end || v < lo || v > hi) return 0;
    *out = v; return 1;
}

static int parse_args(int argc, char **argv, opts_t *o)
{
    static const struct { const char *name; exr_compression_t c; } comps[] = {
        { "none", EXR_COMPRESSION_NONE }, { "rle", EXR_COMPRESSION_RLE },
        { "zips", EXR_COMPRESSION_ZIPS }, { "zip", EXR_COMPRESSION_ZIP },
        { "piz", EXR_COMPRESSION_PIZ },   { "pxr24", EXR_COMPRESSION_PXR24 },
        { "b44", EXR_COMPRESSION_B44 },   { "b44a", EXR_COMPRESSION_B44A },
    };
    memset(o, 0, sizeof *o);
    o->W = 640; o->H = 360; o->comp = EXR_COMPRESSION_ZIP; o->seed = 1;
    o->sun_width = 240; o->sun_centre[2] = -90;
    o->view[0] = 1.7; o->view[1] = -4; o->view[2] = HFOV_DEG;
    for (int i = 1; i < argc; ++i) {
        const char *a = argv[i];
        const char *val = (i + 1 < argc) ? argv[i + 1] : NULL;
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) { usage(stdout); exit(0); }
        else if (!strcmp(a, "--check")) o->check = 1;
        else if (!strcmp(a, "--view")) {
            char tail;
            if (!val || sscanf(val, "%lf,%lf,%lf%c", &o->view[0], &o->view[1], &o->view[2], &tail) != 3 ||
                !(o->view[0] > 0) || !(fabs(o->view[1]) < 89) || !(o->view[2] > 1 && o->view[2] < 170)) {
                fprintf(stderr, PROG ": bad --view '%s' (want HEIGHT>0,PITCH,FOV)\n", val ? val : ""); return 0;
            }
            ++i;
        }
        else if (!strcmp(a, "--sun-view") || !strcmp(a, "--sun-centre") || !strcmp(a, "--sun-width")) {
            double *dst = !strcmp(a, "--sun-view") ? o->sun : !strcmp(a, "--sun-centre") ? o->sun_centre
                                                                                     : &o->sun_width;
            const int n = !strcmp(a, "--sun-width") ? 1 : 3;
            char tail;
            int got = !val ? 0 : n == 1 ? sscanf(val, "%lf%c", dst, &tail)
                                        : sscanf(val, "%lf,%lf,%lf%c", dst, dst + 1, dst + 2, &tail);
            if (got != n || (n == 1 && !(dst[0] > 0))) {
                fprintf(stderr, PROG ": bad %s '%s'\n", a, val ? val : ""); return 0;
            }
            o->sun_view |= !strcmp(a, "--sun-view");
            ++i;
        }
        else if (!strcmp(a, "--size") || !strcmp(a, "--compression") || !strcmp(a, "--tiled") ||
                 !strcmp(a, "--seed")) {
            if (!val) { fprintf(stderr, PROG ": %s needs a value\n", a); return 0; }
            ++i;
            if (!strcmp(a, "--size")) {
                char *end; long w, h; errno = 0;
                w = strtol(val, &end, 10);
                if (errno || end == val || (*end != 'x' && *end != 'X') || !parse_int(end + 1, 1, MAX_DIM, &h) ||
                    w < 1 || w > MAX_DIM) {
                    fprintf(stderr, PROG ": bad --size '%s' (want WxH, 1..%d)\n", val, MAX_DIM); return 0;
                }
                o->W = (int) w; o->H = (int) h;
            } else if (!strcmp(a, "--compression")) {
                size_t k, n = sizeof comps / sizeof comps[0];
                for (k = 0; k < n && strcmp(val, comps[k].name); ++k) {}
                if (k == n) { fprintf(stderr, PROG ": unknown compression '%s'\n", val); return 0; }
                o->comp = comps[k].c;
            } else if (!strcmp(a, "--tiled")) {
                long n;
                if (!parse_int(val, 1, MAX_TILE, &n)) {
                    fprintf(stderr, PROG ": bad --tiled '%s' (want 1..%d)\n", val, MAX_TILE); return 0;
                }
                o->tile = (int) n;
            } else {
                char *end; errno = 0;
                unsigned long long s = strtoull(val, &end, 10);
                if (errno || end == val || *end || val[0] == '-') {
                    fprintf(stderr, PROG ": bad --seed '%s'\n", val); return 0;
                }
                o->seed = s;
            }
        } else if (a[0] == '-' && a[1]) {
            fprintf(stderr, PROG ": unknown option '%s'\n", a); return 0;
        } else if (o->out) {
            fprintf(stderr, PROG ": more than one output file given\n"); return 0;
        } else o->out = a;
    }
    if (!o->out) { fprintf(stderr, PROG ": no output file given\n"); return 0; }
    return 1;
}

int main(int argc, char **argv)
{
    opts_t o;
    if (!parse_args(argc, argv, &o)) {
        fprintf(stderr, "usage: " PROG " OUT.exr [OPTIONS]  (see --help)\n");
        return 1;
    }

    camera_t cam;
    setup_camera(&cam, o.W, o.H, o.view);
    static scene_t scene;
    build_scene(&scene, &cam, o.seed);   /* the frame's camera places the spheres */
    if (o.sun_view) {
        v3 t = V(o.sun[0], o.sun[1], o.sun[2]);
        if (!(len(t) > 0)) { fprintf(stderr, PROG ": --sun-view needs a non-zero direction\n"); return 1; }
        setup_sun_camera(&cam, o.W, o.H, t,
                         V(o.sun_centre[0], o.sun_centre[1], o.sun_centre[2]), o.sun_width);
    }
    render_t R = { &scene, &cam, o.seed, 0, 0, 0, 0 };

    if (write_image(&o, &R)) return 1;
    if (o.check) {
        printf("camera self-check: %lld pixels (%lld sky), max NDC error %.3g, max relative Z error %.3g "
               "(tolerance %g): OK\n", R.nchecked, R.nsky, R.max_ndc_err, R.max_z_err, CHECK_TOL);
        if (verify_file(&o, &R)) { fprintf(stderr, PROG ": check FAILED\n"); return 1; }
        printf("check OK: %s\n", o.out);
    }
    return 0;
}
