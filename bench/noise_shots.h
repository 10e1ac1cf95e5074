/* noise_shots.h - the shots of the noise sweep (issue 41), shared by
 * bench/noise_sweep.c and the suite's reduced sweep (tests/unit/test_noise_sweep.c):
 * the list, and a pinhole over the ground plane y = 0 as make_sample --view
 * renders it. Header-only (static functions). */
#ifndef EF_BENCH_NOISE_SHOTS_H
#define EF_BENCH_NOISE_SHOTS_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon.h"
#include "splitmix.h"

#define NS_PI 3.14159265358979323846
#define YAW_DEG 6.0
#define MAX_SHOTS 64

typedef struct shot {
    char name[48];
    double height, pitch, fov;
    char spec[512];
} shot;

static inline int add_fixed(shot *s, int n, const char *name, double h, double p, double f,
                     const char *spec)
{
    snprintf(s[n].name, sizeof s[n].name, "%s", name);
    s[n].height = h;
    s[n].pitch = p;
    s[n].fov = f;
    snprintf(s[n].spec, sizeof s[n].spec, "%s", spec);
    return n + 1;
}

static inline double uni(uint64_t *g, double a, double b)
{
    return a + (b - a) * splitmix_uni(g);
}

static inline double logu(uint64_t *g, double a, double b)
{
    return exp(uni(g, log(a), log(b)));
}

/* The shot list: the fixed ones, then count drawn from seed 41. */
static inline int make_shots(shot *s, int count)
{
    int n = 0;
    n = add_fixed(s, n, "bench-noise", 1.7, -4, 60, "noise:density=0.02:scale=10:octaves=4");
    n = add_fixed(s, n, "bench-horizon", 1.7, -4, 60,
                  "noise:density=0.05:scale=10:octaves=4:falloff=0.1:base=0");
    n = add_fixed(s, n, "issue-patchy-30up", 30, -8, 60,
                  "noise:density=0.02:scale=25:octaves=5:falloff=0.05:contrast=1.2");
    n = add_fixed(s, n, "issue-patchy-sky", 12, 2, 60,
                  "noise:density=0.02:scale=25:octaves=6:falloff=0.05:contrast=1.6");
    n = add_fixed(s, n, "issue-patchy-120up", 120, -20, 60,
                  "noise:density=0.02:scale=25:octaves=5:falloff=0.05:contrast=2");
    n = add_fixed(s, n, "corner-high-gentle", 300, -10, 60,
                  "noise:density=0.01:scale=50:octaves=6:falloff=0.002:base=0:contrast=0.9");
    n = add_fixed(s, n, "corner-c4-8oct", 10, -5, 60,
                  "noise:density=0.03:scale=20:octaves=8:falloff=0.05:base=0:contrast=4");
    uint64_t g = 41;
    for (int i = 0; i < count && n < MAX_SHOTS; ++i, ++n) {
        shot *t = &s[n];
        snprintf(t->name, sizeof t->name, "sweep-%02d", i + 1);
        t->height = logu(&g, 1.5, 300);
        t->pitch = uni(&g, -30, 10);
        t->fov = uni(&g, 30, 90);
        double c = uni(&g, 0, 1);
        if (i % 3 == 0)
            c = uni(&g, 1, 4);
        else if (i % 6 == 1)
            c = -uni(&g, 0.2, 2);
        const int oct = 1 + (int) (splitmix_uni(&g) * 8);
        const double scale = logu(&g, 1, 100);
        const double rho = logu(&g, 0.002, 0.1);
        const int sep = i % 6 == 5;
        double k = i % 5 == 0 ? 0 : logu(&g, 0.002, 1);
        /* base above or below the camera, the envelope there at most e^8 */
        const double span = k > 0 ? fmin(8 / k, 3 * t->height) : 0;
        const double base = i % 2 ? t->height - uni(&g, 0.2, 1) * span
                                  : t->height + uni(&g, 0.1, 1) * span;
        int len = snprintf(t->spec, sizeof t->spec,
                           "%s:density=%.4g:scale=%.4g:octaves=%d:contrast=%.3g",
                           sep ? "noise-separable" : "noise", rho, scale, oct, c);
        if (k > 0)
            len += snprintf(t->spec + len, sizeof t->spec - (size_t) len, ":falloff=%.4g:base=%.4g",
                            k, base);
        if (i % 4 == 3)
            len += snprintf(t->spec + len, sizeof t->spec - (size_t) len,
                            ":min=-300,0,-600:max=300,%.4g,-10", 2 * t->height + 20);
        if (sep)
            snprintf(t->spec + len, sizeof t->spec - (size_t) len, ":axes=xz");
    }
    return n;
}

/* The pinhole: ray through pixel (x, y) of a W x H frame. */
typedef struct view {
    double eye[3], r[3], u[3], f[3], tx, ty;
    int W, H;
} view;

/* The shot's pinhole turned yaw_deg right (a pan moves it). */
static inline void view_init_yaw(view *v, const shot *s, int W, int H, double yaw_deg)
{
    const double yaw = yaw_deg * NS_PI / 180, pitch = s->pitch * NS_PI / 180;
    v->W = W;
    v->H = H;
    v->eye[0] = 0;
    v->eye[1] = s->height;
    v->eye[2] = 0;
    v->f[0] = sin(yaw) * cos(pitch);
    v->f[1] = sin(pitch);
    v->f[2] = -cos(yaw) * cos(pitch);
    /* r = f x (0,1,0) normalised; u = r x f */
    double r[3] = { -v->f[2], 0, v->f[0] };
    const double rn = hypot(r[0], r[2]);
    for (int a = 0; a < 3; ++a)
        v->r[a] = r[a] / rn;
    v->u[0] = v->r[1] * v->f[2] - v->r[2] * v->f[1];
    v->u[1] = v->r[2] * v->f[0] - v->r[0] * v->f[2];
    v->u[2] = v->r[0] * v->f[1] - v->r[1] * v->f[0];
    v->tx = tan(0.5 * s->fov * NS_PI / 180);
    v->ty = v->tx * H / W;
}

/* The shot's pinhole, turned YAW_DEG right. */
static inline void view_init(view *v, const shot *s, int W, int H)
{
    view_init_yaw(v, s, W, H, YAW_DEG);
}

/* The pinhole's pixel angle on its axis (what ef_camera_pixel_spread gives
 * for the camera make_sample --view writes). */
static inline double view_spread(const view *v)
{
    return 2 * v->tx / v->W;
}

static inline void view_ray(const view *v, double px, double py, ef_ray *r)
{
    const double sx = (2 * px / v->W - 1) * v->tx, sy = (1 - 2 * py / v->H) * v->ty;
    double d[3], n = 0;
    for (int a = 0; a < 3; ++a) {
        d[a] = v->f[a] + sx * v->r[a] + sy * v->u[a];
        n += d[a] * d[a];
    }
    n = sqrt(n);
    for (int a = 0; a < 3; ++a) {
        r->dir[a] = d[a] / n;
        r->org[a] = v->eye[a];
    }
    r->dist = r->dir[1] < 0 ? v->eye[1] / -r->dir[1] : INFINITY;
    r->planar = r->dist * (r->dir[0] * v->f[0] + r->dir[1] * v->f[1] + r->dir[2] * v->f[2]);
}

/* The row (fractional) where the horizon is, or NAN when out of frame. */
static inline double horizon_row(const view *v)
{
    /* direction with dir.y = 0 at the centre column: f + sy u, f.y + sy u.y = 0 */
    if (v->u[1] == 0)
        return NAN;
    const double sy = -v->f[1] / v->u[1];
    const double py = (1 - sy / v->ty) * v->H / 2;
    return py >= 0 && py < v->H ? py : NAN;
}

/* A number after key in spec, or 0. */
static inline double spec_num(const char *spec, const char *key)
{
    const char *p = strstr(spec, key);
    return p ? atof(p + strlen(key)) : 0;
}

/* How far the reference must integrate along r for shot spec: r's
 * distance, clipped to the box where there is one; on a sky ray, to where
 * the box is left or the envelope's tail (the most tau it can still add)
 * is below tail; 0 when fog fills the whole infinite ray (T = 0). */
static inline double shot_ref_len(const char *spec, const ef_ray *r, double tail)
{
    double len = r->dist;
    const char *mn = strstr(spec, "min="), *mx = strstr(spec, "max=");
    if (mn && mx) {
        double lo[3], hi[3], t1 = INFINITY;
        if (sscanf(mn + 4, "%lf,%lf,%lf", &lo[0], &lo[1], &lo[2]) == 3 &&
            sscanf(mx + 4, "%lf,%lf,%lf", &hi[0], &hi[1], &hi[2]) == 3)
            for (int a = 0; a < 3; ++a)
                if (r->dir[a] != 0)
                    t1 = fmin(t1, fmax((lo[a] - r->org[a]) / r->dir[a],
                                       (hi[a] - r->org[a]) / r->dir[a]));
        /* a little past the exit: the density is 0 there by definition */
        if (t1 < len)
            len = t1 > 0 ? t1 * (1 + 1e-12) + 1e-9 : 0;
    }
    if (isfinite(len))
        return len;
    const double k = spec_num(spec, "falloff="), rho = spec_num(spec, "density="),
                 base = spec_num(spec, "base=");
    const double a = k * r->dir[1];
    if (!(a > 0))
        return INFINITY;
    /* tail from t: rho B e^-(k (y0 + dy t - base)) / (k dy) < tail */
    const double need = log(rho * 5 / (a * tail)) + k * (base - r->org[1]);
    return need > 0 ? need / a + 1 : 1;
}

/* n pixels (x, y) of v's frame from seed: 60 % uniform, 20 % within 2 %
 * of the frame's height of the horizon (long ground and sky rays), 20 % in
 * the sky or, when the horizon is out of frame, in the frame's top fifth
 * (the farthest ground) when the camera looks down. */
static inline void shot_pixels(const view *v, uint64_t seed, int n, double (*pix)[2])
{
    uint64_t g = seed;
    const double hr = horizon_row(v);
    const int W = v->W, H = v->H;
    for (int j = 0; j < n; ++j) {
        const double u = splitmix_uni(&g);
        double x = uni(&g, 0, W), y;
        if (u < 0.6 || (u < 0.8 && isnan(hr)))
            y = uni(&g, 0, H);
        else if (u < 0.8)
            y = fmin(H - 1e-9, fmax(0, hr + uni(&g, -0.02, 0.02) * H));
        else if (!isnan(hr))
            y = uni(&g, 0, hr);   /* the sky above the horizon */
        else
            y = v->f[1] + v->ty * v->u[1] < 0 ? uni(&g, 0, 0.2 * H) : uni(&g, 0, H);
        pix[j][0] = x;
        pix[j][1] = y;
    }
}

#endif
