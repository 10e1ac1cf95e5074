/* Shadow maps: building one from a light-view depth render, and the lit
 * intervals of a view segment (shadow.h). */
#include "shadow.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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
                        a = fminf(a, m->zmin[l][i]);
                        b = fmaxf(b, m->zmax[l][i]);
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

