/* Shadow maps: building one from a light-view depth render, and the lit
 * intervals of a view segment (shadow.h). */
#include "shadow.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The lesser and greater of two depths (never NaN here: a map holds finite
 * depths or inf), inline where libm's fminf and fmaxf are calls. */
static inline float lessf(float a, float b)
{
    return b < a ? b : a;
}

static inline float greaterf(float a, float b)
{
    return b > a ? b : a;
}

/* Whether an entry of the camera-to-clip matrix is rounding only: small
 * against the largest rounding any entry could carry (|C2W| . |M|, whose
 * float32 headers leave ~1e-7 of it where the projection has zeros). */
static int near_zero(double v, const double *tol)
{
    double big = 0;
    for (int i = 0; i < 16; ++i)
        big = fmax(big, tol[i]);
    return fabs(v) <= 1e-5 * big;
}

/* Builds the mip levels above level 0 (its zmin is the map itself, its
 * zmax the same array). Returns 0, or -1 out of memory. */
static int build_mip(ef_shadow *m)
{
    m->zmax[0] = m->zmin[0];
    int l = 0;
    while (m->lw[l] > 1 || m->lh[l] > 1) {
        if (l + 1 >= 24)
            return -1;
        const int w = (m->lw[l] + 1) / 2, h = (m->lh[l] + 1) / 2;
        float *mn = malloc((size_t) w * (size_t) h * sizeof *mn);
        float *mx = malloc((size_t) w * (size_t) h * sizeof *mx);
        m->zmin[l + 1] = mn;
        m->zmax[l + 1] = mx;
        m->lw[l + 1] = w;
        m->lh[l + 1] = h;
        m->nlev = l + 2;
        if (!mn || !mx)
            return -1;
        const int pw = m->lw[l], ph = m->lh[l];
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                float a = INFINITY, b = -INFINITY;
                for (int dy = 0; dy < 2; ++dy)
                    for (int dx = 0; dx < 2; ++dx) {
                        const int cx = 2 * x + dx, cy = 2 * y + dy;
                        if (cx >= pw || cy >= ph)
                            continue;
                        const size_t i = (size_t) cy * (size_t) pw + (size_t) cx;
                        a = lessf(a, m->zmin[l][i]);
                        b = greaterf(b, m->zmax[l][i]);
                    }
                mn[(size_t) y * (size_t) w + (size_t) x] = a;
                mx[(size_t) y * (size_t) w + (size_t) x] = b;
            }
        ++l;
    }
    m->nlev = l + 1;
    return 0;
}

/* The smaller one-sided depth difference at v between its neighbours a
 * and b (either may be missing: inf), 0 where neither is finite. */
static double one_sided(float a, float v, float b)
{
    const double da = isfinite(a) ? fabs((double) v - a) : INFINITY;
    const double db = isfinite(b) ? fabs((double) b - v) : INFINITY;
    const double d = da < db ? da : db;
    return isfinite(d) ? d : 0;
}

/* The greatest lit depth of every texel of z (w x h, inf: nothing) into
 * out: z plus the constant bias plus the slope bias (shadow.h). */
static void biased(const float *z, int w, int h, const ef_shadow_opts *o, float *out)
{
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            const size_t i = (size_t) y * (size_t) w + (size_t) x;
            const float v = z[i];
            if (!isfinite(v)) {
                out[i] = INFINITY;
                continue;
            }
            double s = 0;
            if (o->slope > 0) {
                const float l = x > 0 ? z[i - 1] : INFINITY, r = x + 1 < w ? z[i + 1] : INFINITY;
                const float u = y > 0 ? z[i - (size_t) w] : INFINITY,
                            d = y + 1 < h ? z[i + (size_t) w] : INFINITY;
                s = o->slope * 0.5 * (one_sided(l, v, r) + one_sided(u, v, d));
            }
            out[i] = (float) (v + o->bias + s);
        }
}

ef_shadow *ef_shadow_build(const ef_shadow_src *src, const ef_shadow_opts *o, ef_err *err)
{
    const char *path = src->path ? src->path : "the shadow map";
    if (!src->has_w2c || !src->has_proj) {
        ef_fail(err, "a shadow map needs the light camera in its header: worldToCamera and "
                "worldToNDC (or worldToScreen); render it from a camera at the light and write "
                "the camera matrices (the Blender add-on, Arnold and RenderMan do)");
        return NULL;
    }
    if (!ef_mat4_finite(&src->w2c) || !ef_mat4_finite(&src->proj)) {
        ef_fail(err, "the shadow map's camera matrices are not finite");
        return NULL;
    }
    ef_mat4 c2w, pc, absc, absm, pabs;
    if (ef_mat4_invert(&src->w2c, &c2w)) {
        ef_fail(err, "the shadow map's worldToCamera is singular");
        return NULL;
    }
    ef_mat4_mul(&c2w, &src->proj, &pc);
    for (int i = 0; i < 16; ++i) {
        absc.m[i] = fabs(c2w.m[i]);
        absm.m[i] = fabs(src->proj.m[i]);
    }
    ef_mat4_mul(&absc, &absm, &pabs);
    const double *p = pc.m, *tol = pabs.m;
    int ortho;
    if (near_zero(p[3], tol) && near_zero(p[7], tol) && near_zero(p[11], tol) &&
        !near_zero(p[15], tol))
        ortho = 1;
    else if (near_zero(p[3], tol) && near_zero(p[7], tol) && p[11] > 0 &&
             !near_zero(p[11], tol) && near_zero(p[15], tol))
        ortho = 0;
    else {
        ef_fail(err, "the shadow map's %s is neither an orthographic projection (w column "
                "0 0 0 1) nor a perspective one looking down +Z of its worldToCamera",
                src->proj_name ? src->proj_name : "projection");
        return NULL;
    }
    ef_shadow *m = calloc(1, sizeof *m);
    if (!m) {
        ef_fail(err, "out of memory for the shadow map");
        return NULL;
    }
    atomic_init(&m->refs, 1);
    snprintf(m->path, sizeof m->path, "%s", path);
    m->ortho = ortho;
    m->opts = *o;
    m->outside_lit = o->outside_lit;
    m->w = src->width;
    m->h = src->height;
    double an = 0;
    for (int a = 0; a < 3; ++a) {
        m->org[a] = c2w.m[12 + a];
        m->axis[a] = c2w.m[8 + a];
        an += m->axis[a] * m->axis[a];
    }
    an = sqrt(an);
    for (int a = 0; a < 3; ++a)
        m->axis[a] /= an;
    /* where the axis lands: (0, 0) with y up is screen space (Arnold's),
     * (0.5, 0.5) with y down NDC (OpenEXR's, RenderMan's, Blender's) */
    double q[3], c[4];
    for (int a = 0; a < 3; ++a)
        q[a] = m->org[a] + m->axis[a];
    ef_mat4_apply(&src->proj, q, 1.0, c);
    const double cx = c[0] / c[3], cy = c[1] / c[3];
    int ndc;
    const double wc = ortho ? p[15] : p[11];   /* w of camera-space points ahead */
    if (fabs(cx) < 0.25 && fabs(cy) < 0.25 && p[5] / wc > 0)
        ndc = 0;
    else if (fabs(cx - 0.5) < 0.25 && fabs(cy - 0.5) < 0.25)
        ndc = 1;
    else {
        ef_fail(err, "the shadow map's %s is neither screen space (centre 0,0) nor NDC "
                "(centre 0.5,0.5): its centre is %g,%g",
                src->proj_name ? src->proj_name : "projection", cx, cy);
        free(m);
        return NULL;
    }
    const double Wd = src->disp[2] - src->disp[0] + 1.0, Hd = src->disp[3] - src->disp[1] + 1.0;
    double ax, bx, ay, by;   /* px = ax s_x + bx, py = ay s_y + by, texels of the data window */
    if (ndc) {
        ax = Wd;
        bx = src->disp[0] - src->dw[0];
        ay = Hd;
        by = src->disp[1] - src->dw[1];
    } else {
        ax = Wd / 2;
        bx = Wd / 2 + src->disp[0] - src->dw[0];
        ay = -Hd / 2;
        by = Hd / 2 + src->disp[1] - src->dw[1];
    }
    const double *M = src->proj.m;
    /* an orthographic w of either sign, made positive */
    const double ws = ortho && c[3] < 0 ? -1 : 1;
    for (int i = 0; i < 4; ++i) {
        m->T[i][0] = ws * (ax * M[4 * i + 0] + bx * M[4 * i + 3]);
        m->T[i][1] = ws * (ay * M[4 * i + 1] + by * M[4 * i + 3]);
        m->T[i][2] = ws * M[4 * i + 3];
    }
    const size_t n = (size_t) m->w * (size_t) m->h;
    m->lw[0] = m->w;
    m->lh[0] = m->h;
    m->nlev = 1;
    if (!(m->zmin[0] = malloc(n * sizeof(float)))) {
        ef_shadow_unref(m);
        ef_fail(err, "out of memory for the shadow map (%d x %d)", src->width, src->height);
        return NULL;
    }
    /* nothing there (sky, no sample, nonsense): nothing to cast a shadow */
    float *z = malloc(n * sizeof *z);
    if (!z) {
        ef_shadow_unref(m);
        ef_fail(err, "out of memory for the shadow map (%d x %d)", src->width, src->height);
        return NULL;
    }
    for (size_t i = 0; i < n; ++i) {
        const float v = src->depth[i];
        z[i] = v > 0 && v < 1e9f ? v : INFINITY;
    }
    biased(z, m->w, m->h, o, m->zmin[0]);
    free(z);
    if (build_mip(m)) {
        ef_shadow_unref(m);
        ef_fail(err, "out of memory for the shadow map's mip levels");
        return NULL;
    }
    return m;
}

void ef_shadow_ref(ef_shadow *m)
{
    if (m)
        atomic_fetch_add(&m->refs, 1);
}

void ef_shadow_unref(ef_shadow *m)
{
    if (!m || atomic_fetch_sub(&m->refs, 1) != 1)
        return;
    for (int k = 0; k < m->ntilt; ++k)
        ef_shadow_unref(m->tilt[k]);
    free(m->tilt);
    ef_shadow_unref(m->env);
    for (int l = 0; l < 24; ++l) {
        if (m->zmax[l] != m->zmin[l])
            free(m->zmax[l]);
        free(m->zmin[l]);
    }
    free(m);
}

/* ------------------------------------------------------------ the walk */

/* One view segment in the map's terms: X, Y, W and the planar depth d,
 * each affine in t. */
typedef struct sh_q {
    const ef_shadow *m;
    double X0, Xu, Y0, Yu, W0, Wu, d0, du;
    int sx, sy;               /* the directions px and py move in (0: fixed) */
    double (*iv)[2];
    int n, cap, over;
} sh_q;

/* Appends the lit interval [a, b] (merged with the last when they touch;
 * past cap the last absorbs it, flagged in q->over). */
static void emit(sh_q *q, double a, double b)
{
    if (!(b > a))
        return;
    if (q->n > 0 && q->iv[q->n - 1][1] >= a) {
        if (b > q->iv[q->n - 1][1])
            q->iv[q->n - 1][1] = b;
        return;
    }
    if (q->n < q->cap) {
        q->iv[q->n][0] = a;
        q->iv[q->n][1] = b;
        q->n++;
        return;
    }
    q->over = 1;   /* the last piece absorbs the rest */
    q->iv[q->n - 1][1] = b;
}

/* The planar depth at t, its limit at t = inf. */
static double depth_at(const sh_q *q, double t)
{
    if (isinf(t))
        return q->du > 0 ? INFINITY : q->du < 0 ? -INFINITY : q->d0;
    return q->d0 + t * q->du;
}

/* Where (X0 + t Xu) / (W0 + t Wu) = k ahead of the light's camera; INFINITY
 * where the line meets k only on the branch behind it (W < 0: a
 * perspective segment's texel coordinate tends to Xu / Wu and may never
 * reach k). */
static double crossing(double X0, double Xu, double W0, double Wu, double k)
{
    const double den = Xu - k * Wu;
    if (den == 0)
        return INFINITY;
    const double t = (k * W0 - X0) / den;
    return W0 + t * Wu > 0 ? t : INFINITY;
}

static void walk(sh_q *q, int lev, double ta, double tb, int x0, int x1, int y0, int y1);

/* Cell (ix, iy) of level lev over [t0, t1]: lit, shadowed, solved (level
 * 0) or walked one level down. */
static void cell(sh_q *q, int lev, int ix, int iy, double t0, double t1)
{
    const ef_shadow *m = q->m;
    const size_t i = (size_t) iy * (size_t) m->lw[lev] + (size_t) ix;
    const double zn = m->zmin[lev][i], zx = m->zmax[lev][i];
    const double da = depth_at(q, t0), db = depth_at(q, t1);
    const double lo = da < db ? da : db, hi = da < db ? db : da;
    if (hi <= zn) {
        emit(q, t0, t1);
    } else if (lo > zx) {
        return;
    } else if (lev == 0) {
        /* d0 + t du <= zn: one interval */
        if (q->du == 0) {
            if (q->d0 <= zn)
                emit(q, t0, t1);
            return;
        }
        const double ts = (zn - q->d0) / q->du;
        if (q->du > 0)
            emit(q, t0, ts < t1 ? ts : t1);
        else
            emit(q, ts > t0 ? ts : t0, t1);
    } else {
        const int w = m->lw[lev - 1], h = m->lh[lev - 1];
        walk(q, lev - 1, t0, t1, 2 * ix, 2 * ix + 1 < w ? 2 * ix + 1 : w - 1, 2 * iy,
             2 * iy + 1 < h ? 2 * iy + 1 : h - 1);
    }
}

/* The cells of level lev (within x0..x1, y0..y1) the segment crosses over
 * [ta, tb], in order of t: the crossings come from the closed forms, the
 * cells from integer steps, so rounding can shift a boundary by an ulp
 * but never loop or skip a cell. */
static void walk(sh_q *q, int lev, double ta, double tb, int x0, int x1, int y0, int y1)
{
    const double s = (double) (1L << lev);   /* texels per cell (lev < 24) */
    const double W = q->W0 + ta * q->Wu;
    const double px = (q->X0 + ta * q->Xu) / W / s, py = (q->Y0 + ta * q->Yu) / W / s;
    int ix = q->sx < 0 ? (int) ceil(px) - 1 : (int) floor(px);
    int iy = q->sy < 0 ? (int) ceil(py) - 1 : (int) floor(py);
    if (!(px > x0))
        ix = x0;
    if (!(px < x1 + 1))
        ix = x1;
    if (!(py > y0))
        iy = y0;
    if (!(py < y1 + 1))
        iy = y1;
    ix = ix < x0 ? x0 : ix > x1 ? x1 : ix;
    iy = iy < y0 ? y0 : iy > y1 ? y1 : iy;
    double t = ta;
    for (;;) {
        double tx = INFINITY, ty = INFINITY;
        if (q->sx)
            tx = crossing(q->X0, q->Xu, q->W0, q->Wu, (q->sx > 0 ? ix + 1 : ix) * s);
        if (q->sy)
            ty = crossing(q->Y0, q->Yu, q->W0, q->Wu, (q->sy > 0 ? iy + 1 : iy) * s);
        if (!(tx == tx))
            tx = INFINITY;
        if (!(ty == ty))
            ty = INFINITY;
        double tn = tx < ty ? tx : ty;
        if (tn > tb)
            tn = tb;
        if (tn < t)
            tn = t;
        const int nx = tx <= ty && tx < tb ? ix + q->sx : ix;
        const int ny = ty <= tx && ty < tb ? iy + q->sy : iy;
        if (tn >= tb || nx < x0 || nx > x1 || ny < y0 || ny > y1) {
            /* the last cell takes the rest (its exit lies within rounding
             * of tb) */
            cell(q, lev, ix, iy, t, tb);
            return;
        }
        if (tn > t)
            cell(q, lev, ix, iy, t, tn);
        ix = nx;
        iy = ny;
        t = tn;
    }
}

/* Narrows [*lo, *hi] to where c0 + t c1 >= 0. */
static void keep(double c0, double c1, double *lo, double *hi)
{
    if (c1 == 0) {
        if (!(c0 >= 0))
            *hi = -INFINITY;
        return;
    }
    const double r = -c0 / c1;
    if (c1 > 0) {
        if (r > *lo)
            *lo = r;
    } else if (r < *hi) {
        *hi = r;
    }
}

int ef_shadow_lit(const ef_shadow *m, const double org[3], const double dir[3], double a,
                  double b, double (*iv)[2], int cap)
{
    sh_q q;
    memset(&q, 0, sizeof q);
    q.m = m;
    q.iv = iv;
    q.cap = cap;
    double e[3][2];
    for (int j = 0; j < 3; ++j) {
        e[j][0] = m->T[3][j];
        e[j][1] = 0;
        for (int k = 0; k < 3; ++k) {
            e[j][0] += org[k] * m->T[k][j];
            e[j][1] += dir[k] * m->T[k][j];
        }
    }
    q.X0 = e[0][0];
    q.Xu = e[0][1];
    q.Y0 = e[1][0];
    q.Yu = e[1][1];
    q.W0 = e[2][0];
    q.Wu = e[2][1];
    for (int k = 0; k < 3; ++k) {
        q.d0 += (org[k] - m->org[k]) * m->axis[k];
        q.du += dir[k] * m->axis[k];
    }
    /* d(px)/dt has the sign of Xu W0 - X0 Wu all along (W > 0) */
    const double gx = q.Xu * q.W0 - q.X0 * q.Wu, gy = q.Yu * q.W0 - q.Y0 * q.Wu;
    q.sx = gx > 0 ? 1 : gx < 0 ? -1 : 0;
    q.sy = gy > 0 ? 1 : gy < 0 ? -1 : 0;
    /* the part in front of the light's camera and inside the map */
    double lo = a, hi = b;
    if (!m->ortho) {
        keep(q.W0, q.Wu, &lo, &hi);
        if (q.Wu == 0 && !(q.W0 > 0))
            hi = -INFINITY;
    }
    keep(q.X0, q.Xu, &lo, &hi);
    keep(m->w * q.W0 - q.X0, m->w * q.Wu - q.Xu, &lo, &hi);
    keep(q.Y0, q.Yu, &lo, &hi);
    keep(m->h * q.W0 - q.Y0, m->h * q.Wu - q.Yu, &lo, &hi);
    if (!(lo < hi)) {
        if (m->outside_lit)
            emit(&q, a, b);
        return q.n;
    }
    /* at lo on a perspective map's w = 0 plane nothing is defined: start
     * an ulp inside */
    if (!m->ortho && q.W0 + lo * q.Wu <= 0)
        lo = nextafter(lo, hi);
    if (m->outside_lit && lo > a)
        emit(&q, a, lo);
    if (lo < hi && isfinite(lo))
        walk(&q, m->nlev - 1, lo, hi, 0, 0, 0, 0);
    if (m->outside_lit && hi < b)
        emit(&q, hi, b);
    return q.over ? -1 - q.n : q.n;
}

int ef_shadow_point_lit(const ef_shadow *m, const double x[3])
{
    double e[3], d = 0;
    for (int j = 0; j < 3; ++j) {
        e[j] = m->T[3][j];
        for (int k = 0; k < 3; ++k)
            e[j] += x[k] * m->T[k][j];
    }
    for (int k = 0; k < 3; ++k)
        d += (x[k] - m->org[k]) * m->axis[k];
    if (!(e[2] > 0))
        return m->outside_lit;
    const double px = e[0] / e[2], py = e[1] / e[2];
    if (!(px >= 0 && px < m->w && py >= 0 && py < m->h))
        return m->outside_lit;
    const size_t i = (size_t) py * (size_t) m->w + (size_t) px;
    return d <= m->zmin[0][i];
}

/* ------------------------------------------------------------ penumbra */

/* A map with m's camera and outside rule whose level 0 is z (taken over,
 * w x h of m), its mip built; NULL out of memory (z freed). */
static ef_shadow *sibling(const ef_shadow *m, float *z)
{
    ef_shadow *t = calloc(1, sizeof *t);
    if (!t) {
        free(z);
        return NULL;
    }
    atomic_init(&t->refs, 1);
    t->w = m->w;
    t->h = m->h;
    t->ortho = m->ortho;
    t->opts = m->opts;
    t->outside_lit = m->outside_lit;
    memcpy(t->T, m->T, sizeof t->T);
    memcpy(t->org, m->org, sizeof t->org);
    memcpy(t->axis, m->axis, sizeof t->axis);
    snprintf(t->path, sizeof t->path, "%s", m->path);
    t->zmin[0] = z;
    t->lw[0] = m->w;
    t->lh[0] = m->h;
    t->nlev = 1;
    if (build_mip(t)) {
        ef_shadow_unref(t);
        return NULL;
    }
    return t;
}

/* a[i * stride] for i < n replaced by the least of it within r places
 * either side, in O(n) (van Herk / Gil-Werman: running minima within
 * blocks of 2r + 1 from both ends, over the row padded by r infinities
 * each side); f and g: n + 2r floats each. */
static void slide(float *a, size_t stride, int n, int r, float *f, float *g)
{
    const int k = 2 * r + 1, m = n + 2 * r;
#define AT(i) ((i) < r || (i) >= n + r ? INFINITY : a[(size_t) ((i) - r) * stride])
    for (int i = 0; i < m; ++i)
        f[i] = i % k == 0 ? AT(i) : lessf(f[i - 1], AT(i));
    for (int i = m - 1; i >= 0; --i)
        g[i] = i % k == k - 1 || i == m - 1 ? AT(i) : lessf(g[i + 1], AT(i));
#undef AT
    /* padded index i + r holds a[i]: its window is [i, i + 2r] */
    for (int i = 0; i < n; ++i)
        a[(size_t) i * stride] = lessf(g[i], f[i + 2 * r]);
}

/* z (w x h) replaced by its least over the square of radius r about each
 * texel. Returns 0, or -1 out of memory. */
static int square_min(float *z, int w, int h, int r)
{
    const size_t n = (size_t) (w > h ? w : h) + 2 * (size_t) r;
    float *f = malloc(2 * n * sizeof *f);
    if (!f)
        return -1;
    for (int y = 0; y < h; ++y)
        slide(z + (size_t) y * (size_t) w, 1, w, r, f, f + n);
    for (int x = 0; x < w; ++x)
        slide(z + x, (size_t) w, h, r, f, f + n);
    free(f);
    return 0;
}

/* ceil(v) for v within (-1, n + 1], clamped to [-1, n + 1] beyond (the
 * callers clamp to the map; libm's ceil is a call on the baseline ISA). */
static int ceil_in(double v, int n)
{
    if (!(v > -1))
        return -1;
    if (v > n + 1)
        return n + 1;
    const int i = (int) v;   /* truncation: v > -1 */
    return i + (v > i);
}

/* The copy of m (level 0: z, biased depths) seen along the direction that
 * moves a point cx, cy texels per unit of depth: the texel coordinates of
 * x become those of x's projection along it onto the plane of depth zref
 * (the middle of the map's depths, so that little leaves the map), for
 * points (T, through the shear) and plates alike. NULL out of memory. */
/* Per texel of a map, what every tilted copy needs of its neighbours:
 * which of them (left, right, up, down: bits 1, 2, 4, 8) lie on the same
 * surface (within 16 texel widths in depth) and the surface's slope per
 * texel in x and y from them (0 without). */
typedef struct sh_nb {
    unsigned char *same;
    float *sx, *sy;
} sh_nb;

/* Fills nb for m; 0, or -1 out of memory (nb empty). */
static int neighbours(const ef_shadow *m, sh_nb *nb)
{
    const int w = m->w, h = m->h;
    const size_t n = (size_t) w * (size_t) h;
    const double W = m->T[3][2];
    const double cont_x = 16 * fabs(W) / hypot(hypot(m->T[0][0], m->T[1][0]), m->T[2][0]),
                 cont_y = 16 * fabs(W) / hypot(hypot(m->T[0][1], m->T[1][1]), m->T[2][1]);
    nb->same = malloc(n);
    nb->sx = malloc(n * sizeof *nb->sx);
    nb->sy = malloc(n * sizeof *nb->sy);
    if (!nb->same || !nb->sx || !nb->sy) {
        free(nb->same);
        free(nb->sx);
        free(nb->sy);
        memset(nb, 0, sizeof *nb);
        return -1;
    }
    const float *z = m->zmin[0];
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i) {
            const size_t at = (size_t) j * (size_t) w + (size_t) i;
            const double d = z[at];
            const int l = i > 0 && fabs(z[at - 1] - d) <= cont_x,
                      r = i + 1 < w && fabs(z[at + 1] - d) <= cont_x,
                      u = j > 0 && fabs(z[at - (size_t) w] - d) <= cont_y,
                      b = j + 1 < h && fabs(z[at + (size_t) w] - d) <= cont_y;
            nb->same[at] = (unsigned char) (l | r << 1 | u << 2 | b << 3);
            nb->sx[at] = (float) (l && r ? 0.5 * (z[at + 1] - z[at - 1]) : l ? d - z[at - 1]
                                  : r ? z[at + 1] - d : 0);
            nb->sy[at] = (float) (u && b ? 0.5 * (z[at + (size_t) w] - z[at - (size_t) w])
                                  : u ? d - z[at - (size_t) w] : b ? z[at + (size_t) w] - d : 0);
        }
    return 0;
}

static ef_shadow *tilted(const ef_shadow *m, const sh_nb *nb, double cx, double cy, double zref)
{
    const int w = m->w, h = m->h;
    const size_t n = (size_t) w * (size_t) h;
    float *out = malloc(n * sizeof *out);
    if (!out)
        return NULL;
    for (size_t i = 0; i < n; ++i)
        out[i] = INFINITY;
    const double W = m->T[3][2];
    const float *z = m->zmin[0];
    for (int j = 0; j < h; ++j)
        for (int i = 0; i < w; ++i) {
            const size_t at = (size_t) j * (size_t) w + (size_t) i;
            const double d = z[at];
            if (!isfinite(d))
                continue;
            double x0 = i + cx * (d - zref), x1 = x0 + 1, y0 = j + cy * (d - zref), y1 = y0 + 1;
            const double px = x0 + 0.5, py = y0 + 0.5;
            /* a centre the plate covers off its own takes the plane's
             * depth there (no acne from the resampling); a gap to a
             * neighbour of the same surface is closed */
            const double sx = nb->sx[at], sy = nb->sy[at];
            const unsigned same = nb->same[at];
            const double gl = same & 1 ? cx * (d - z[at - 1]) : 0,
                         gr = same & 2 ? cx * (z[at + 1] - d) : 0,
                         gu = same & 4 ? cy * (d - z[at - (size_t) w]) : 0,
                         gb = same & 8 ? cy * (z[at + (size_t) w] - d) : 0;
            x0 -= gl > 0 ? gl : 0;
            x1 += gr > 0 ? gr : 0;
            y0 -= gu > 0 ? gu : 0;
            y1 += gb > 0 ? gb : 0;
            /* the texel centres c + 0.5 in [x0, x1) x [y0, y1) */
            if (!(x1 > 0.5 && x0 < w - 0.5 && y1 > 0.5 && y0 < h - 0.5))
                continue;   /* (also what a NaN would give) */
            const int ca = ceil_in(x0 - 0.5, w), cb = ceil_in(x1 - 0.5, w) - 1;
            const int ra = ceil_in(y0 - 0.5, h), rb = ceil_in(y1 - 0.5, h) - 1;
            const int xa = ca < 0 ? 0 : ca, xb = cb > w - 1 ? w - 1 : cb;
            const int ya = ra < 0 ? 0 : ra, yb = rb > h - 1 ? h - 1 : rb;
            for (int y = ya; y <= yb; ++y)
                for (int x = xa; x <= xb; ++x) {
                    const float v = (float) (d + sx * (x + 0.5 - px) + sy * (y + 0.5 - py));
                    float *o = &out[(size_t) y * (size_t) w + (size_t) x];
                    if (v < *o)
                        *o = v;
                }
        }
    ef_shadow *t = sibling(m, out);
    if (!t)
        return NULL;
    double oa = zref;
    for (int i = 0; i < 3; ++i)
        oa += m->org[i] * m->axis[i];
    for (int i = 0; i < 4; ++i) {
        const double ax = i < 3 ? m->axis[i] : -oa;
        t->T[i][0] = m->T[i][0] + cx * W * ax;
        t->T[i][1] = m->T[i][1] + cy * W * ax;
    }
    return t;
}

int ef_shadow_soften(ef_shadow *m, double angle, int n, ef_err *err)
{
    if (!m->ortho)
        return ef_fail(err, "a penumbra needs an orthographic (sun's) shadow map");
    if (!(angle > 0) || !(angle < 3.14159265358979) || n < 1 || n > EF_PENUMBRA_MAX)
        return ef_fail(err, "a penumbra needs an angle in (0, 180) degrees and 1 to %d "
                       "directions", EF_PENUMBRA_MAX);
    const int w = m->w, h = m->h;
    const size_t npx = (size_t) w * (size_t) h;
    const float *z = m->zmin[0];
    double zlo = INFINITY, zhi = -INFINITY;
    for (size_t i = 0; i < npx; ++i)
        if (isfinite(z[i])) {
            zlo = fmin(zlo, z[i]);
            zhi = fmax(zhi, z[i]);
        }
    if (!isfinite(zlo))
        zlo = zhi = 0;   /* nothing casts a shadow: every copy is empty */
    const double zref = 0.5 * (zlo + zhi);
    /* the map's x axis and, across it, its y axis, as world unit vectors
     * (the tilts); their texel rates give the shear per unit of depth */
    const double W = m->T[3][2];
    double gx[3], gy[3], ex[3], ey[3], nx = 0;
    for (int i = 0; i < 3; ++i) {
        gx[i] = m->T[i][0] / W;
        gy[i] = m->T[i][1] / W;
        nx += gx[i] * gx[i];
    }
    nx = sqrt(nx);
    for (int i = 0; i < 3; ++i)
        ex[i] = gx[i] / nx;
    ey[0] = m->axis[1] * ex[2] - m->axis[2] * ex[1];
    ey[1] = m->axis[2] * ex[0] - m->axis[0] * ex[2];
    ey[2] = m->axis[0] * ex[1] - m->axis[1] * ex[0];
    ef_shadow **tilt = calloc((size_t) n, sizeof *tilt);
    if (!tilt)
        return ef_fail(err, "out of memory for the shadow map's penumbra");
    double rmax = 0;   /* the largest shear, texels per unit of depth */
    int k = 0;
    sh_nb nb;
    if (neighbours(m, &nb))
        k = -1;   /* out of memory: below */
    for (; k >= 0 && k < n; ++k) {
        /* equal areas of the disc: radius sqrt((k + 1/2) / n), golden angle */
        const double r = tan(0.5 * angle * sqrt((k + 0.5) / n)), phi = 2.39996322972865332 * k;
        double v[3], cx = 0, cy = 0;
        for (int i = 0; i < 3; ++i) {
            v[i] = r * (cos(phi) * ex[i] + sin(phi) * ey[i]);
            cx += v[i] * gx[i];
            cy += v[i] * gy[i];
        }
        rmax = fmax(rmax, hypot(cx, cy));
        if (!(tilt[k] = tilted(m, &nb, cx, cy, zref)))
            break;
    }
    if (k < 0)
        k = 0;
    /* Where the copies can differ from the map: a copy shears a plate at
     * depth z_q by at most rmax (d - z_q) texels against a point of depth
     * d, and only a plate next to a depth jump (or the sky, or the border)
     * leaves a penumbra where it moves; elsewhere the copies show the same
     * surfaces as the map, at most resampled. So a point at texel p is in
     * no penumbra where d < z_e + max(0, |p - e| - c) / rmax for every
     * edge texel e (chessboard distance; c: a plate's width and a half,
     * the texel's rounding, and what closing a gap adds; z_e lowered by
     * the plate's slope over as far): env is that cone-shaped lower
     * envelope (a square minimum of radius c, then a chamfer pass of slope
     * 1 / rmax per texel), and below it the map decides alone. */
    const double twx = 1 / nx, twy = 1 / sqrt(gy[0] * gy[0] + gy[1] * gy[1] + gy[2] * gy[2]);
    const double ext = rmax * 16 * fmax(twx, twy);   /* a closed gap, texels */
    const int c = (int) ceil(1.5 + ext);
    float *e = k == n ? malloc(npx * sizeof *e) : NULL;
    int ok = e != NULL;
    if (ok) {
        for (int j = 0; j < h; ++j)
            for (int i = 0; i < w; ++i) {
                const size_t at = (size_t) j * (size_t) w + (size_t) i;
                const float d = z[at];
                /* a texel with a neighbour off its surface (a depth jump,
                 * the sky) or on the border */
                const int edge = isfinite(d) && nb.same[at] != 15;
                /* (a copy takes the plate's plane up to 1 + ext texels
                 * off its centre: as low as that) */
                e[at] = edge ? (float) (d - (fabs(nb.sx[at]) + fabs(nb.sy[at])) * (1 + ext))
                             : INFINITY;
            }
        ok = square_min(e, w, h, c) == 0;
    }
    if (ok) {
        /* the chamfer cone: two passes over the 8 neighbours */
        const float st = rmax > 0 ? (float) (1 / rmax) : INFINITY;
        for (int j = 0; j < h; ++j)
            for (int i = 0; i < w; ++i) {
                float *v = &e[(size_t) j * (size_t) w + (size_t) i];
                if (i > 0)
                    *v = lessf(*v, v[-1] + st);
                if (j > 0) {
                    const float *u = v - w;
                    *v = lessf(*v, u[0] + st);
                    if (i > 0)
                        *v = lessf(*v, u[-1] + st);
                    if (i + 1 < w)
                        *v = lessf(*v, u[1] + st);
                }
            }
        for (int j = h - 1; j >= 0; --j)
            for (int i = w - 1; i >= 0; --i) {
                float *v = &e[(size_t) j * (size_t) w + (size_t) i];
                if (i + 1 < w)
                    *v = lessf(*v, v[1] + st);
                if (j + 1 < h) {
                    const float *u = v + w;
                    *v = lessf(*v, u[0] + st);
                    if (i > 0)
                        *v = lessf(*v, u[-1] + st);
                    if (i + 1 < w)
                        *v = lessf(*v, u[1] + st);
                }
            }
        /* below it strictly, whatever the sums' rounding */
        for (size_t i = 0; i < npx; ++i)
            e[i] = nextafterf(nextafterf(e[i], -INFINITY), -INFINITY);
    }
    free(nb.same);
    free(nb.sx);
    free(nb.sy);
    ef_shadow *env = ok ? sibling(m, e) : (free(e), NULL);
    if (!env) {
        for (int j = 0; j < k; ++j)
            ef_shadow_unref(tilt[j]);
        free(tilt);
        return ef_fail(err, "out of memory for the shadow map's penumbra (%d copies of "
                       "%d x %d)", n, w, h);
    }
    /* outside the map the copies decide (a point may shear into it) */
    env->outside_lit = 0;
    m->tilt = tilt;
    m->ntilt = n;
    m->angle = angle;
    m->env = env;
    return 0;
}

double ef_shadow_point_vis(const ef_shadow *m, const double x[3])
{
    if (!m->ntilt)
        return ef_shadow_point_lit(m, x);
    int lit = 0;
    for (int k = 0; k < m->ntilt; ++k)
        lit += ef_shadow_point_lit(m->tilt[k], x);
    return (double) lit / m->ntilt;
}

/* One end of a copy's lit interval: where the count of copies lighting
 * the ray steps up (+1) or down (-1). */
typedef struct sh_ev {
    double t;
    int step;
} sh_ev;

static int cmp_ev(const void *a, const void *b)
{
    const sh_ev *x = a, *y = b;
    return (x->t > y->t) - (x->t < y->t);
}

/* Lit intervals a copy keeps on the stack per call; more go to the heap. */
#define PIECE_STACK 256

/* m's lit intervals into *lit (lcap of them, the stack's at first); past
 * that, once into a heap buffer of cap (*lit then points to it, owned by
 * the caller). Returns ef_shadow_lit's count (negative: still over). */
static int copy_lit(const ef_shadow *m, const double org[3], const double dir[3], double a,
                    double b, double (**lit)[2], int *lcap, int cap)
{
    int k = ef_shadow_lit(m, org, dir, a, b, *lit, *lcap);
    if (k >= 0 || *lcap >= cap)
        return k;
    double (*heap)[2] = malloc((size_t) cap * sizeof *heap);
    if (!heap)
        return k;
    *lit = heap;
    *lcap = cap;
    return ef_shadow_lit(m, org, dir, a, b, *lit, *lcap);
}

int ef_shadow_pieces(const ef_shadow *m, const double org[3], const double dir[3], double a,
                     double b, double (*iv)[3], int cap)
{
    double stack[PIECE_STACK][2], (*lit)[2] = stack;
    int lcap = PIECE_STACK, over = 0, n = 0;
    if (!m->ntilt) {
        int k = copy_lit(m, org, dir, a, b, &lit, &lcap, cap);
        if (k < 0) {
            over = 1;
            k = -1 - k;
        }
        for (int i = 0; i < k && n < cap; ++i) {
            iv[n][0] = lit[i][0];
            iv[n][1] = lit[i][1];
            iv[n][2] = 1;
            ++n;
        }
        over |= k > cap;
        if (lit != stack)
            free(lit);
        return over ? -1 - n : n;
    }
    /* Below env (Q) the map decides alone: its lit runs there count all
     * ntilt copies (events +-ntilt); the rest of [a, b] is walked copy by
     * copy (events +-1). */
    double hst[PIECE_STACK][2], (*H)[2] = hst, qst[PIECE_STACK][2], (*Q)[2] = qst;
    int hc = PIECE_STACK, qc = PIECE_STACK;
    int nh = copy_lit(m, org, dir, a, b, &H, &hc, cap);
    int nq = copy_lit(m->env, org, dir, a, b, &Q, &qc, cap);
    if (nh < 0 || nq < 0)
        over = 1;
    nh = nh < 0 ? -1 - nh : nh;
    nq = nq < 0 ? -1 - nq : nq;
    sh_ev evs[2 * PIECE_STACK], *ev = evs;
    int nev = 0, evcap = 2 * PIECE_STACK;
    if (2 * (nh + nq) > evcap) {
        if (!(ev = malloc(2 * (size_t) (nh + nq) * sizeof *ev))) {
            ev = evs;
            over = 1;
            goto swept;
        }
        evcap = 2 * (nh + nq);
    }
    /* H within Q */
    for (int i = 0, j = 0; i < nh && j < nq;) {
        const double lo = fmax(H[i][0], Q[j][0]), hi = fmin(H[i][1], Q[j][1]);
        if (lo < hi) {
            ev[nev++] = (sh_ev) { lo, m->ntilt };
            ev[nev++] = (sh_ev) { hi, -m->ntilt };
        }
        if (H[i][1] < Q[j][1])
            ++i;
        else
            ++j;
    }
    /* the gaps of Q in [a, b], copy by copy */
    for (int j = 0; j <= nq; ++j) {
        const double u0 = j == 0 ? a : Q[j - 1][1], u1 = j == nq ? b : Q[j][0];
        if (!(u1 > u0))
            continue;
        for (int c = 0; c < m->ntilt; ++c) {
            int k = copy_lit(m->tilt[c], org, dir, u0, u1, &lit, &lcap, cap);
            if (k < 0) {
                over = 1;
                k = -1 - k;
            }
            if (nev + 2 * k > evcap) {
                int ncap = evcap;
                while (nev + 2 * k > ncap)
                    ncap *= 2;
                sh_ev *g = ev == evs ? malloc((size_t) ncap * sizeof *ev)
                                     : realloc(ev, (size_t) ncap * sizeof *ev);
                if (!g) {   /* no memory: what fitted, flagged */
                    over = 1;
                    goto swept;
                }
                if (ev == evs)
                    memcpy(g, evs, (size_t) nev * sizeof *ev);
                ev = g;
                evcap = ncap;
            }
            for (int e = 0; e < k; ++e) {
                ev[nev++] = (sh_ev) { lit[e][0], 1 };
                ev[nev++] = (sh_ev) { lit[e][1], -1 };
            }
        }
    }
swept:
    qsort(ev, (size_t) nev, sizeof *ev, cmp_ev);
    int count = 0;
    for (int i = 0; i < nev;) {
        const double t = ev[i].t;
        for (; i < nev && ev[i].t == t; ++i)
            count += ev[i].step;
        if (i == nev || count <= 0)
            continue;
        const double t1 = ev[i].t, v = fmin(1.0, (double) count / m->ntilt);
        if (n > 0 && iv[n - 1][1] == t && iv[n - 1][2] == v) {
            iv[n - 1][1] = t1;
        } else if (n < cap) {
            iv[n][0] = t;
            iv[n][1] = t1;
            iv[n][2] = v;
            ++n;
        } else {   /* the last absorbs the rest */
            over = 1;
            iv[n - 1][1] = t1;
        }
    }
    if (ev != evs)
        free(ev);
    if (lit != stack)
        free(lit);
    if (H != hst)
        free(H);
    if (Q != qst)
        free(Q);
    return over ? -1 - n : n;
}

