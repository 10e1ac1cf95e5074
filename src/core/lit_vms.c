/* A sun's multiple scattering in one uniform convex volume (box, convex):
 * the volume's density changes across the ground, so the plane-parallel
 * solve of lit_ms.c does not hold, and the light that enters through the
 * volume's sides and leaks out through them needs a solve in three
 * dimensions. This one is Monte Carlo, once per scene and sun, on a grid
 * over the volume (ms.h's ef_vms_*). Pure C, no I/O.
 *
 * What is solved: photons of the sun's beam, aimed at the volume over a
 * disc that covers it, each forced to scatter once inside (weight: the
 * chance that it does, times the albedo), then followed scattering after
 * scattering (the phase sampled exactly, the albedo a weight per channel,
 * Russian roulette below a hundredth) until they leave the volume or fall
 * below a black ground. Every flight after the first scattering adds its
 * length to the voxels it crosses, times the real spherical harmonics of
 * its direction to degree VMS_L - 1 (the track-length estimator of the
 * once-and-more-scattered radiance's moments Phi_lm). The source of orders
 * two and up towards the camera, per unit length, is then
 *
 *   J(x, u) = sigma albedo sum_lm b_l Y_lm(u) Phi_lm(x),
 *
 * b_l the phase's Legendre coefficients (the addition theorem), u the
 * propagation direction towards the camera; a view segment gathers int
 * e^-sigma s J ds along its stretch inside the volume.
 *
 * Its estimate (per pixel, in the error output), each an estimate, not a
 * bound:
 *   - the Monte Carlo noise: three standard errors of each voxel's Phi_00
 *     from VMS_BATCHES independent batches, as a share of the voxel's J,
 *     summed along the ray as if fully correlated;
 *   - the grid: each voxel's second differences along the three axes over
 *     8 (trilinear interpolation's error for a field with that curvature);
 *   - the harmonics left out: the last band's term times |g| / (1 - |g|)
 *     (the bands fall as b_l times the radiance's own, about g^l each).
 * Beyond |g| VMS_GMAX_SH the harmonics do not hold the forward peak: each
 * camera bind then traces the photons again, every flight scoring the
 * exact phase towards the camera from its voxel's centre (ef_vms_bind).
 * Scattered light is not shadowed (as in lit_ms.c). */
#include "ms.h"

#include <math.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "lit_int.h"

#define VMS_L 4                        /* bands 0..3 */
#define VMS_NC (VMS_L * VMS_L)         /* harmonics kept */
#define VMS_NMAX 16                    /* voxels along every side */
#define VMS_PHOTONS (1 << 21)          /* photons of the beam */
#define VMS_BATCHES 16                 /* batches for the noise's estimate */
#define VMS_WMIN 0.01                  /* Russian roulette below this weight */
#define VMS_MAXP 70                    /* planes: a convex volume's 64 and the ground */
/* The largest |g| the harmonics serve alone: against Cycles
 * (bench/ms_sun_box.md) the multiple part is within 1.2 % at g 0.6 and the
 * error output covers every block; at 0.7 4.8 % high, 95 % covered; at
 * 0.85 31 % high, 82 % covered (the forward peak needs harmonics far
 * beyond degree 3). Beyond it each camera bind traces the photons again,
 * scoring the phase itself towards the camera (ef_vms_bind); up to
 * VMS_GMAX. */
#define VMS_GMAX_SH 0.6
#define VMS_GMAX 0.9

struct ef_vms {
    int n[3];                   /* voxels per axis */
    double lo[3], h[3];         /* the grid: voxel (i, j, k) spans lo + [i, i+1) h */
    int np;
    double pl[VMS_MAXP * 4];    /* the volume's planes (inside: n.x + d < 0), the ground's */
    double sig;                 /* extinction (every channel) */
    double E[3];                /* the sun's irradiance */
    double alb[3];              /* albedo per channel */
    double b[VMS_L];            /* the phase's Legendre coefficients */
    double trunc;               /* |g| / (1 - |g|): the harmonics left out */
    double *phi;                /* [voxel][channel][VMS_NC] */
    double *est;                /* [voxel][channel]: noise and grid, as a share of Phi_00 */
    double *frac;               /* [voxel]: its share inside the volume (0: none of it) */
    int phase;                  /* the phase function and its g */
    double g;
    int exact;                  /* |g| beyond VMS_GMAX_SH: each camera bind scores the phase */
    int nch;                    /* channels traced: 1 where the albedo is grey, else 3 */
    double sd[3];               /* towards the sun */
    ef_ms_info info;
};

/* ---------------------------------------------------------------- pieces */

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* xoshiro256** (Blackman and Vigna), seeded by splitmix64: a fixed
 * sequence, so a scene's solve is the same every run and every frame. */
typedef struct vrng {
    uint64_t s[4];
} vrng;

static uint64_t rotl(uint64_t x, int k)
{
    return (x << k) | (x >> (64 - k));
}

static void rng_seed(vrng *r, uint64_t seed)
{
    for (int i = 0; i < 4; ++i) {
        seed += 0x9e3779b97f4a7c15ULL;
        uint64_t z = seed;
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
        r->s[i] = z ^ (z >> 31);
    }
}

/* uniform in (0, 1) */
static double rng_u(vrng *r)
{
    const uint64_t res = rotl(r->s[1] * 5, 7) * 9, t = r->s[1] << 17;
    r->s[2] ^= r->s[0];
    r->s[3] ^= r->s[1];
    r->s[1] ^= r->s[2];
    r->s[0] ^= r->s[3];
    r->s[2] ^= t;
    r->s[3] = rotl(r->s[3], 45);
    return ((double) (res >> 11) + 0.5) * 0x1p-53;
}

void ef_vms_harmonics(const double d[3], double Y[16])
{
    const double x = d[0], y = d[1], z = d[2];
    Y[0] = 0.28209479177387814;
    Y[1] = 0.4886025119029199 * y;
    Y[2] = 0.4886025119029199 * z;
    Y[3] = 0.4886025119029199 * x;
    Y[4] = 1.0925484305920792 * x * y;
    Y[5] = 1.0925484305920792 * y * z;
    Y[6] = 0.31539156525252005 * (3 * z * z - 1);
    Y[7] = 1.0925484305920792 * x * z;
    Y[8] = 0.5462742152960396 * (x * x - y * y);
    Y[9] = 0.5900435899266435 * y * (3 * x * x - y * y);
    Y[10] = 2.890611442640554 * x * y * z;
    Y[11] = 0.4570457994644658 * y * (5 * z * z - 1);
    Y[12] = 0.3731763325901154 * z * (5 * z * z - 3);
    Y[13] = 0.4570457994644658 * x * (5 * z * z - 1);
    Y[14] = 1.445305721320277 * z * (x * x - y * y);
    Y[15] = 0.5900435899266435 * x * (x * x - 3 * y * y);
}

/* Two unit vectors e1, e2 across unit d, (e1, e2, d) right-handed. */
static void across(const double d[3], double e1[3], double e2[3])
{
    double a[3] = { 1, 0, 0 };
    if (fabs(d[0]) > 0.9)
        a[0] = 0, a[1] = 1;
    e1[0] = d[1] * a[2] - d[2] * a[1];
    e1[1] = d[2] * a[0] - d[0] * a[2];
    e1[2] = d[0] * a[1] - d[1] * a[0];
    const double n1 = sqrt(dot3(e1, e1));
    for (int q = 0; q < 3; ++q)
        e1[q] /= n1;
    e2[0] = d[1] * e1[2] - d[2] * e1[1];
    e2[1] = d[2] * e1[0] - d[0] * e1[2];
    e2[2] = d[0] * e1[1] - d[1] * e1[0];
}

/* A unit vector at cosine mu from unit d, azimuth 2 pi v about it. */
static void turn(const double d[3], double mu, double v, double out[3])
{
    double e1[3], e2[3];
    across(d, e1, e2);
    const double st = sqrt(fmax(0, 1 - mu * mu)), ph = 2 * PI * v, c = cos(ph), s = sin(ph);
    for (int q = 0; q < 3; ++q)
        out[q] = mu * d[q] + st * (c * e1[q] + s * e2[q]);
    const double nn = sqrt(dot3(out, out));
    for (int q = 0; q < 3; ++q)
        out[q] /= nn;
}

/* The cosine of a scattering by the phase (iso, Rayleigh, HG or CS):
 * HG by its inverse, the others by rejection under their largest value. */
static double phase_mu(int phase, double g, vrng *r)
{
    if (phase == EF_PHASE_ISO || (phase == EF_PHASE_HG && fabs(g) < 1e-6))
        return 2 * rng_u(r) - 1;
    if (phase == EF_PHASE_HG) {
        const double s = (1 - g * g) / (1 - g + 2 * g * rng_u(r));
        return fmax(-1, fmin(1, (1 + g * g - s * s) / (2 * g)));
    }
    const double pmax = fmax(ef_phase_eval(phase, g, 1), ef_phase_eval(phase, g, -1));
    for (;;) {
        const double mu = 2 * rng_u(r) - 1;
        if (rng_u(r) * pmax <= ef_phase_eval(phase, g, mu))
            return mu;
    }
}

/* The stretch [t0, t1] of the line o + t d inside the volume (empty: t0 >
 * t1). */
static void clip(const ef_vms *v, const double o[3], const double d[3], double *t0, double *t1)
{
    double a = -INFINITY, b = INFINITY;
    for (int i = 0; i < v->np && a <= b; ++i) {
        const double *p = v->pl + 4 * i, nd = dot3(p, d), s = dot3(p, o) + p[3];
        if (nd == 0) {
            if (s >= 0)
                a = INFINITY;
        } else if (nd > 0) {
            b = fmin(b, -s / nd);
        } else {
            a = fmax(a, -s / nd);
        }
    }
    *t0 = a;
    *t1 = b;
}

/* The voxel index along axis q of coordinate c, clamped to the grid. */
static int vox(const ef_vms *v, int q, double c)
{
    const double f = (c - v->lo[q]) / v->h[q];
    int i = (int) floor(f);
    return i < 0 ? 0 : i >= v->n[q] ? v->n[q] - 1 : i;
}

static size_t vidx(const ef_vms *v, int i, int j, int k)
{
    return ((size_t) k * (size_t) v->n[1] + (size_t) j) * (size_t) v->n[0] + (size_t) i;
}

/* Where a solve's flights go: the harmonics' moments phi ([voxel][nch]
 * [VMS_NC]), or, bound to a camera, jc ([voxel][nch]): each flight's
 * length times the phase towards the camera from the voxel's centre
 * (ucam, [voxel][3]); bat the batch's channel 0 (for the noise), bs and
 * bq the batches' sums and squares. */
typedef struct tally {
    int nch;
    double *phi, *jc;
    const double *ucam;
    double *bat, *bs, *bq;
} tally;

/* Adds the flight x + t d, t in [0, len], of weights w to the voxels it
 * crosses (Amanatides and Woo's walk): w[ch] len Y into phi, or w[ch]
 * len p(d . ucam) into jc. */
static void deposit(const ef_vms *v, tally *ty, const double x[3], const double d[3],
                    double len, const double *w, const double Y[VMS_NC])
{
    const int nch = ty->nch;
    int c[3], st[3];
    double tm[3], td[3];
    for (int q = 0; q < 3; ++q) {
        c[q] = vox(v, q, x[q]);
        if (d[q] > 0) {
            st[q] = 1;
            td[q] = v->h[q] / d[q];
            tm[q] = (v->lo[q] + (c[q] + 1) * v->h[q] - x[q]) / d[q];
        } else if (d[q] < 0) {
            st[q] = -1;
            td[q] = -v->h[q] / d[q];
            tm[q] = (v->lo[q] + c[q] * v->h[q] - x[q]) / d[q];
        } else {
            st[q] = 0;
            td[q] = tm[q] = INFINITY;
        }
        if (tm[q] < 0)
            tm[q] = 0;
    }
    double t = 0;
    while (t < len) {
        const int q = tm[0] <= tm[1] && tm[0] <= tm[2] ? 0 : tm[1] <= tm[2] ? 1 : 2;
        const double tn = fmin(tm[q], len), l = tn - t;
        if (l > 0) {
            const size_t a = vidx(v, c[0], c[1], c[2]);
            if (ty->jc) {
                const double p = l * ef_phase_eval(v->phase, v->g, dot3(d, ty->ucam + 3 * a));
                for (int ch = 0; ch < nch; ++ch)
                    ty->jc[a * (size_t) nch + ch] += w[ch] * p;
                ty->bat[a] += w[0] * p;
            } else {
                double *ph = ty->phi + a * (size_t) nch * VMS_NC;
                for (int ch = 0; ch < nch; ++ch) {
                    const double wl = w[ch] * l;
                    for (int m = 0; m < VMS_NC; ++m)
                        ph[ch * VMS_NC + m] += wl * Y[m];
                }
                ty->bat[a] += w[0] * l;
            }
        }
        t = tn;
        if (t >= len)
            break;
        c[q] += st[q];
        if (c[q] < 0 || c[q] >= v->n[q])
            break;   /* (rounding at the volume's face) */
        tm[q] += td[q];
    }
}

/* The beam's disc: its centre (the grid's) and radius R (the grid's half
 * diagonal), which covers the volume. */
static void beam_disc(const ef_vms *v, double ctr[3], double *R)
{
    double r2 = 0;
    for (int q = 0; q < 3; ++q) {
        ctr[q] = v->lo[q] + 0.5 * v->n[q] * v->h[q];
        r2 += 0.25 * (v->n[q] * v->h[q]) * (v->n[q] * v->h[q]);
    }
    *R = sqrt(r2) * 1.001;
}

/* The photons of the sun's beam through v into ty (module comment), in
 * VMS_BATCHES batches of fixed seeds. */
static void trace(const ef_vms *v, tally *ty)
{
    const size_t nv = (size_t) v->n[0] * v->n[1] * v->n[2];
    const double *sd = v->sd;
    double ctr[3], R;
    beam_disc(v, ctr, &R);
    const double back[3] = { -sd[0], -sd[1], -sd[2] };
    double e1[3], e2[3];
    across(sd, e1, e2);
    const int per = VMS_PHOTONS / VMS_BATCHES;
    double wmax = 1;
    for (int k = 0; k < 3; ++k)
        wmax = fmax(wmax, v->alb[k]);
    for (int bt = 0; bt < VMS_BATCHES; ++bt) {
        vrng rg;
        rng_seed(&rg, 0x65786672666f67ULL + (uint64_t) bt);
        for (int p = 0; p < per; ++p) {
            const double rr = R * sqrt(rng_u(&rg)), ph = 2 * PI * rng_u(&rg);
            double x[3], d[3] = { back[0], back[1], back[2] };
            for (int q = 0; q < 3; ++q)
                x[q] = ctr[q] + 2 * R * sd[q] + rr * (cos(ph) * e1[q] + sin(ph) * e2[q]);
            double ta, tb;
            clip(v, x, d, &ta, &tb);
            if (!(tb > ta) || !(tb > 0))
                continue;
            ta = fmax(ta, 0);
            /* the first scattering, forced inside */
            const double pc = -expm1(-v->sig * (tb - ta));
            const double t1 = ta - log1p(-rng_u(&rg) * pc) / v->sig;
            for (int q = 0; q < 3; ++q)
                x[q] += fmin(t1, tb) * d[q];
            double w[3];
            for (int k = 0; k < 3; ++k)
                w[k] = pc * v->alb[k];
            for (int it = 0; it < 100000; ++it) {
                double nd[3];
                turn(d, phase_mu(v->phase, v->g, &rg), rng_u(&rg), nd);
                memcpy(d, nd, sizeof d);
                double t0, te;   /* where the flight leaves the volume (x is inside) */
                clip(v, x, d, &t0, &te);
                te = fmax(te, 0);
                const double f = -log(rng_u(&rg)) / v->sig;
                const double len = fmin(f, te);
                double Y[VMS_NC];
                if (!ty->jc)
                    ef_vms_harmonics(d, Y);
                deposit(v, ty, x, d, len, w, Y);
                if (!(f < te))
                    break;
                for (int q = 0; q < 3; ++q)
                    x[q] += f * d[q];
                double wm = 0;
                for (int k = 0; k < 3; ++k) {
                    w[k] *= v->alb[k];
                    wm = fmax(wm, w[k]);
                }
                if (wm < VMS_WMIN * wmax) {
                    if (rng_u(&rg) < 0.5)
                        break;
                    for (int k = 0; k < 3; ++k)
                        w[k] *= 2;
                }
            }
        }
        for (size_t a = 0; a < nv; ++a) {
            ty->bs[a] += ty->bat[a];
            ty->bq[a] += ty->bat[a] * ty->bat[a];
            ty->bat[a] = 0;
        }
    }
}

/* A photon's track length in voxel a to its Phi: the beam's power per
 * photon (unit irradiance over the disc) over the voxel's volume inside. */
static double photon_scale(const ef_vms *v, size_t a)
{
    double ctr[3], R;
    beam_disc(v, ctr, &R);
    const double vol = v->h[0] * v->h[1] * v->h[2];
    return v->frac[a] > 0 ? PI * R * R / (VMS_PHOTONS * vol * v->frac[a]) : 0;
}

/* Three standard errors of the batches' mean as a share of it, per voxel. */
static double noise_share(const tally *ty, size_t a)
{
    if (!(ty->bs[a] > 0))
        return 0;
    const double mb = ty->bs[a] / VMS_BATCHES;
    const double var = fmax(0, ty->bq[a] / VMS_BATCHES - mb * mb) / (VMS_BATCHES - 1);
    return 3 * sqrt(var) / mb;
}

static double curvature(const ef_vms *v, const double *f, size_t st, int i, int j, int k);

/* The estimate's share per voxel and channel into out ([voxel][3]): the
 * batches' noise (ty) plus the grid's second differences of a field whose
 * channel ch at voxel a is f[ch * cst + a * vst], over its value. */
static void shares(const ef_vms *v, const tally *ty, const double *f, size_t cst, size_t vst,
                   double *out)
{
    for (int k = 0; k < v->n[2]; ++k)
        for (int j = 0; j < v->n[1]; ++j)
            for (int i = 0; i < v->n[0]; ++i) {
                const size_t a = vidx(v, i, j, k);
                const double share = noise_share(ty, a);
                for (int ch = 0; ch < 3; ++ch) {
                    const double f0 = f[ch * cst + a * vst];
                    const double curv = curvature(v, f + ch * cst, vst, i, j, k);
                    out[a * 3 + ch] = share + (f0 > 0 ? curv / f0 : 0);
                }
            }
}

/* The grid's estimate at voxel (i, j, k) of a field f (stride st between
 * voxels, channel's offset applied by the caller): its second differences
 * along the axes over 8, where both neighbours hold volume. */
static double curvature(const ef_vms *v, const double *f, size_t st, int i, int j, int k)
{
    const int ix[3] = { i, j, k };
    const double f0 = f[vidx(v, i, j, k) * st];
    double curv = 0;
    for (int q = 0; q < 3; ++q) {
        if (ix[q] == 0 || ix[q] == v->n[q] - 1)
            continue;
        int lo3[3] = { i, j, k }, hi3[3] = { i, j, k };
        lo3[q]--, hi3[q]++;
        const size_t al = vidx(v, lo3[0], lo3[1], lo3[2]);
        const size_t ah = vidx(v, hi3[0], hi3[1], hi3[2]);
        if (!(v->frac[al] > 0) || !(v->frac[ah] > 0))
            continue;
        curv += fabs(f[al * st] - 2 * f0 + f[ah * st]) / 8;
    }
    return curv;
}

/* ---------------------------------------------------------------- build */

/* The volume's corners: every triple of planes that meets at a point
 * inside all of them. Returns their count into lo and hi (the box they
 * span): 0 when the planes hold nothing, -1 when they leave it open. */
static int corners(const double *pl, int np, double lo[3], double hi[3])
{
    /* open: some direction d with n.d <= 0 for every plane (a polyhedral
     * cone's extreme rays are -n_i or the crossings n_i x n_j) */
    for (int i = 0; i < np; ++i)
        for (int j = i; j < np; ++j)
            for (int sg = -1; sg <= 1; sg += 2) {
                const double *a = pl + 4 * i, *b = pl + 4 * j;
                double d[3];
                if (i == j) {
                    if (sg > 0)
                        continue;
                    d[0] = -a[0], d[1] = -a[1], d[2] = -a[2];
                } else {
                    d[0] = sg * (a[1] * b[2] - a[2] * b[1]);
                    d[1] = sg * (a[2] * b[0] - a[0] * b[2]);
                    d[2] = sg * (a[0] * b[1] - a[1] * b[0]);
                }
                const double dn = sqrt(dot3(d, d));
                if (!(dn > 1e-9))
                    continue;
                int open = 1;
                for (int k = 0; k < np && open; ++k)
                    open = dot3(pl + 4 * k, d) <= 1e-12 * dn;
                if (open)
                    return -1;
            }
    int nc = 0;
    for (int q = 0; q < 3; ++q)
        lo[q] = INFINITY, hi[q] = -INFINITY;
    for (int i = 0; i < np; ++i)
        for (int j = i + 1; j < np; ++j)
            for (int k = j + 1; k < np; ++k) {
                const double *a = pl + 4 * i, *b = pl + 4 * j, *c = pl + 4 * k;
                const double bc[3] = { b[1] * c[2] - b[2] * c[1], b[2] * c[0] - b[0] * c[2],
                                       b[0] * c[1] - b[1] * c[0] };
                const double det = dot3(a, bc);
                if (!(fabs(det) > 1e-12))
                    continue;
                const double ca[3] = { c[1] * a[2] - c[2] * a[1], c[2] * a[0] - c[0] * a[2],
                                       c[0] * a[1] - c[1] * a[0] };
                const double ab[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                                       a[0] * b[1] - a[1] * b[0] };
                double x[3];
                for (int q = 0; q < 3; ++q)
                    x[q] = -(a[3] * bc[q] + b[3] * ca[q] + c[3] * ab[q]) / det;
                double sc = 1;
                for (int q = 0; q < 3; ++q)
                    sc = fmax(sc, fabs(x[q]));
                int inside = 1;
                for (int m = 0; m < np && inside; ++m)
                    inside = dot3(pl + 4 * m, x) + pl[4 * m + 3] <= 1e-9 * sc;
                if (!inside)
                    continue;
                for (int q = 0; q < 3; ++q) {
                    lo[q] = fmin(lo[q], x[q]);
                    hi[q] = fmax(hi[q], x[q]);
                }
                ++nc;
            }
    return nc;
}

void ef_vms_free(ef_vms *v)
{
    if (!v)
        return;
    free(v->phi);
    free(v->est);
    free(v->frac);
    free(v);
}

int ef_vms_build(const ef_fog_scene *s, const ef_light *l, ef_vms **out, ef_err *err)
{
    *out = NULL;
    const ef_fog_component *c = &s->comp[0];
    double rho[3];
    const double *planes;
    int np;
    if (s->ncomp != 1 || !c->model->convex || !c->model->convex(c, rho, &planes, &np))
        return ef_fail(err, "light '%s': multiple scattering in a volume is solved for one box "
                       "or convex volume alone", l->name);
    if (rho[0] != rho[1] || rho[0] != rho[2])
        return ef_fail(err, "light '%s': multiple scattering in a box or convex volume is solved "
                       "for a density the same in every channel (give the colour by albedo=)",
                       l->name);
    if (np + 1 > VMS_MAXP)
        return ef_fail(err, "light '%s': multiple scattering in a convex volume takes up to %d "
                       "planes", l->name, VMS_MAXP - 1);
    if (l->planet > 0)
        return ef_fail(err, "light '%s': scattering=multiple is solved over flat ground (no "
                       "planet=)", l->name);
    if ((c->phase == EF_PHASE_HG || c->phase == EF_PHASE_CS) && fabs(c->g) > VMS_GMAX)
        return ef_fail(err, "light '%s': multiple scattering in a box or convex volume is "
                       "solved for |g| up to %g (the phase's peak beyond it leaves the Monte "
                       "Carlo solve's noise unbounded); this fog has g %g", l->name, VMS_GMAX,
                       c->g);
    struct timespec t0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    ef_vms *v = calloc(1, sizeof *v);
    if (!v)
        return ef_fail(err, "out of memory for light '%s''s multiple scattering", l->name);
    memcpy(v->pl, planes, (size_t) np * 4 * sizeof *planes);
    v->np = np;
    if (l->has_ground) {   /* -(up . x) + ground < 0: above the black ground */
        double *p = v->pl + 4 * v->np++;
        for (int q = 0; q < 3; ++q)
            p[q] = -s->ctx.up[q];
        p[3] = l->ground;
    }
    double lo[3], hi[3];
    const int nc = corners(v->pl, v->np, lo, hi);
    if (nc < 0) {
        ef_vms_free(v);
        return ef_fail(err, "light '%s': multiple scattering in a convex volume is solved where "
                       "its planes close it (these leave it open; a half-space is "
                       "halfspace:, solved along the ground, or give ground=)", l->name);
    }
    if (!(rho[0] > 0) || nc == 0) {
        ef_vms_free(v);
        return 0;   /* no fog, or none above the ground: nothing scatters */
    }
    v->sig = rho[0];
    memcpy(v->E, l->e, sizeof v->E);
    for (int k = 0; k < 3; ++k)
        v->alb[k] = c->has_albedo ? c->albedo[k] : 1;
    ef_ms_phase_legendre(c->phase, c->g, VMS_L, v->b);
    v->phase = c->phase;
    v->g = c->phase == EF_PHASE_HG || c->phase == EF_PHASE_CS ? c->g : 0;
    v->exact = fabs(v->g) > VMS_GMAX_SH;
    v->trunc = fabs(v->g) / (1 - fabs(v->g));   /* (0 for iso and Rayleigh: degree 2 holds them) */
    /* the grid: VMS_NMAX voxels along every side (a thin slab's depth
     * needs its own resolution as much as its width) */
    double side = 0;
    for (int q = 0; q < 3; ++q)
        side = fmax(side, hi[q] - lo[q]);
    for (int q = 0; q < 3; ++q) {
        const double w = fmax(hi[q] - lo[q], 1e-9 * side);
        v->n[q] = VMS_NMAX;
        v->lo[q] = lo[q];
        v->h[q] = w / v->n[q];
    }
    const size_t nv = (size_t) v->n[0] * v->n[1] * v->n[2];
    const int nch = v->nch = v->alb[0] == v->alb[1] && v->alb[0] == v->alb[2] ? 1 : 3;
    v->phi = calloc(nv * 3 * VMS_NC, sizeof *v->phi);
    v->est = calloc(nv * 3, sizeof *v->est);
    v->frac = calloc(nv, sizeof *v->frac);
    double *bat = calloc(nv, sizeof *bat), *bs = calloc(nv, sizeof *bs),
           *bq = calloc(nv, sizeof *bq);
    if (!v->phi || !v->est || !v->frac || !bat || !bs || !bq) {
        free(bat), free(bs), free(bq);
        ef_vms_free(v);
        return ef_fail(err, "out of memory for light '%s''s multiple scattering", l->name);
    }
    /* each voxel's share inside the volume (4^3 points), which its
     * track lengths are divided by */
    for (int k = 0; k < v->n[2]; ++k)
        for (int j = 0; j < v->n[1]; ++j)
            for (int i = 0; i < v->n[0]; ++i) {
                int cnt = 0;
                for (int p = 0; p < 64; ++p) {
                    const double x[3] = { v->lo[0] + (i + ((p & 3) + 0.5) / 4) * v->h[0],
                                          v->lo[1] + (j + (((p >> 2) & 3) + 0.5) / 4) * v->h[1],
                                          v->lo[2] + (k + ((p >> 4) + 0.5) / 4) * v->h[2] };
                    int inside = 1;
                    for (int m = 0; m < v->np && inside; ++m)
                        inside = dot3(v->pl + 4 * m, x) + v->pl[4 * m + 3] < 0;
                    cnt += inside;
                }
                v->frac[vidx(v, i, j, k)] = cnt / 64.0;
            }
    memcpy(v->sd, l->dir, sizeof v->sd);
    tally ty = { .nch = nch, .phi = v->phi, .bat = bat, .bs = bs, .bq = bq };
    trace(v, &ty);
    /* to Phi: power per photon over the voxel's volume inside; a grey
     * solve's one channel spread to three (from the last voxel down, so
     * none is overwritten before it is read) */
    for (size_t a = nv; a-- > 0;) {
        const double sc = photon_scale(v, a);
        for (int m = 0; m < VMS_NC; ++m) {
            if (nch == 3) {
                for (int ch = 0; ch < 3; ++ch)
                    v->phi[(a * 3 + ch) * VMS_NC + m] *= sc;
                continue;
            }
            const double val = v->phi[a * VMS_NC + m] * sc;
            for (int ch = 0; ch < 3; ++ch)
                v->phi[(a * 3 + ch) * VMS_NC + m] = val;
        }
    }
    /* the noise and the grid, as a share of Phi_00 */
    shares(v, &ty, v->phi, VMS_NC, 3 * VMS_NC, v->est);
    free(bat), free(bs), free(bq);
    struct timespec t1;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    v->info.seconds = (double) (t1.tv_sec - t0.tv_sec) + 1e-9 * (double) (t1.tv_nsec - t0.tv_nsec);
    v->info.nodes = (int) nv;
    v->info.kept = VMS_NMAX;
    v->info.volume = 1;
    v->info.photons = VMS_PHOTONS;
    *out = v;
    return 0;
}

/* --------------------------------------------------------------- gather */

struct ef_vms_cam {
    _Atomic int refs;
    double org[3];
    double *j;                  /* [voxel][channel]: J towards org from the voxel's centre */
    double *e;                  /* exact: [voxel][channel] its estimate's share; else NULL */
};

void ef_vms_cam_ref(ef_vms_cam *c)
{
    if (c)
        atomic_fetch_add(&c->refs, 1);
}

void ef_vms_cam_unref(ef_vms_cam *c)
{
    if (!c || atomic_fetch_sub(&c->refs, 1) != 1)
        return;
    free(c->j);
    free(c->e);
    free(c);
}

/* The harmonics' weights towards propagation direction u: b_l Y_lm(u). */
static void weights(const ef_vms *v, const double u[3], double cw[VMS_NC])
{
    double Y[VMS_NC];
    ef_vms_harmonics(u, Y);
    for (int l = 0; l < VMS_L; ++l)
        for (int m = l * l; m < (l + 1) * (l + 1); ++m)
            cw[m] = v->b[l] * Y[m];
}

/* The unit vector from voxel (i, j, k)'s centre towards org into u. */
static void towards(const ef_vms *v, const double org[3], int i, int j, int k, double u[3])
{
    u[0] = org[0] - (v->lo[0] + (i + 0.5) * v->h[0]);
    u[1] = org[1] - (v->lo[1] + (j + 0.5) * v->h[1]);
    u[2] = org[2] - (v->lo[2] + (k + 0.5) * v->h[2]);
    const double un = sqrt(dot3(u, u));
    for (int q = 0; q < 3; ++q)
        u[q] = un > 0 ? u[q] / un : q == 2;
}

/* ef_vms_bind where the phase is too peaked for the harmonics: the
 * photons again, each flight scoring the phase towards org from the
 * voxel's centre, and the estimate's share per voxel (the noise over the
 * batches, the grid's second differences). Returns 0, or -1 out of
 * memory. */
static int bind_exact(const ef_vms *v, const double org[3], ef_vms_cam *c)
{
    const size_t nv = (size_t) v->n[0] * v->n[1] * v->n[2];
    const int nch = v->nch;
    double *u = malloc(nv * 3 * sizeof *u), *jc = calloc(nv * 3, sizeof *jc);
    double *bat = calloc(nv, sizeof *bat), *bs = calloc(nv, sizeof *bs),
           *bq = calloc(nv, sizeof *bq);
    c->e = malloc(nv * 3 * sizeof *c->e);
    if (!u || !jc || !bat || !bs || !bq || !c->e) {
        free(u), free(jc), free(bat), free(bs), free(bq);
        return -1;
    }
    for (int k = 0; k < v->n[2]; ++k)
        for (int j = 0; j < v->n[1]; ++j)
            for (int i = 0; i < v->n[0]; ++i)
                towards(v, org, i, j, k, u + 3 * vidx(v, i, j, k));
    tally ty = { .nch = nch, .jc = jc, .ucam = u, .bat = bat, .bs = bs, .bq = bq };
    trace(v, &ty);
    for (size_t a = 0; a < nv; ++a) {
        const double sc = photon_scale(v, a);
        for (int ch = 0; ch < 3; ++ch)
            c->j[a * 3 + ch] = v->sig * v->alb[ch] * sc * jc[a * (size_t) nch + (nch == 3 ? ch : 0)];
    }
    shares(v, &ty, c->j, 1, 3, c->e);
    free(u), free(jc), free(bat), free(bs), free(bq);
    return 0;
}

ef_vms_cam *ef_vms_bind(const ef_vms *v, const double org[3])
{
    ef_vms_cam *c = calloc(1, sizeof *c);
    const size_t nv = (size_t) v->n[0] * v->n[1] * v->n[2];
    if (!c || !(c->j = malloc(nv * 3 * sizeof *c->j))) {
        free(c);
        return NULL;
    }
    atomic_init(&c->refs, 1);
    memcpy(c->org, org, sizeof c->org);
    if (v->exact) {
        if (bind_exact(v, org, c)) {
            ef_vms_cam_unref(c);
            return NULL;
        }
        return c;
    }
    for (int k = 0; k < v->n[2]; ++k)
        for (int jj = 0; jj < v->n[1]; ++jj)
            for (int i = 0; i < v->n[0]; ++i) {
                const size_t a = vidx(v, i, jj, k);
                double u[3];
                towards(v, org, i, jj, k, u);
                double cw[VMS_NC];
                weights(v, u, cw);
                for (int ch = 0; ch < 3; ++ch) {
                    const double *p = v->phi + (a * 3 + (size_t) ch) * VMS_NC;
                    double jv = 0;
                    for (int m = 0; m < VMS_NC; ++m)
                        jv += cw[m] * p[m];
                    c->j[a * 3 + (size_t) ch] = v->sig * v->alb[ch] * jv;
                }
            }
    return c;
}

/* The trilinear weights and corners about x between voxel centres, over
 * the voxels that hold some volume (renormalised); returns how many. */
static int stencil(const ef_vms *v, const double x[3], size_t id[8], double w[8])
{
    int i0[3];
    double f[3];
    for (int q = 0; q < 3; ++q) {
        double u = (x[q] - v->lo[q]) / v->h[q] - 0.5;
        u = u < 0 ? 0 : u > v->n[q] - 1 ? v->n[q] - 1 : u;
        i0[q] = (int) u;
        if (i0[q] > v->n[q] - 2)
            i0[q] = v->n[q] - 2;
        f[q] = u - i0[q];
    }
    int n = 0;
    double ws = 0;
    for (int cn = 0; cn < 8; ++cn) {
        const int a = cn & 1, b = (cn >> 1) & 1, cc = cn >> 2;
        const size_t k = vidx(v, i0[0] + a, i0[1] + b, i0[2] + cc);
        if (!(v->frac[k] > 0))
            continue;
        w[n] = (a ? f[0] : 1 - f[0]) * (b ? f[1] : 1 - f[1]) * (cc ? f[2] : 1 - f[2]);
        ws += w[n];
        id[n++] = k;
    }
    for (int i = 0; i < n && ws > 0; ++i)
        w[i] /= ws;
    return ws > 0 ? n : 0;
}

void ef_vms_gather(const ef_vms *v, const ef_vms_cam *c, const ef_ray *r, double S[3],
                   double E[3])
{
    S[0] = S[1] = S[2] = 0;
    if (E)
        E[0] = E[1] = E[2] = 0;
    if (!v || !(r->dist > 0))
        return;
    double ta, tb;
    clip(v, r->org, r->dir, &ta, &tb);
    ta = fmax(ta, 0);
    tb = fmin(tb, r->dist);
    if (!(tb > ta))
        return;
    /* per channel the harmonics' weights towards the camera: b_l
     * Y_lm(-dir) (sigma albedo apart); the last band's for the truncation
     * estimate */
    const double u[3] = { -r->dir[0], -r->dir[1], -r->dir[2] };
    double cw[VMS_NC];
    weights(v, u, cw);
    /* pieces: one per voxel the ray crosses along each axis; each takes J
     * at its middle times its exact share of e^-sigma s (s from where the
     * ray enters, the only fog there is): the midpoint's error, dl^2 J'' /
     * 24, is the trilinear interpolation's own order */
    double cross = 0, hmax = 0;
    for (int q = 0; q < 3; ++q) {
        cross += (tb - ta) * fabs(r->dir[q]) / v->h[q];
        hmax = fmax(hmax, v->h[q]);
    }
    int n = (int) ceil(cross) + 1;
    n = n > 2048 ? 2048 : n;
    /* where the camera's table serves: beyond eight voxels from it (the
     * direction from a voxel's centre then within 7 degrees of the node's);
     * a table that scores the phase itself (c->e), whose harmonics would
     * be worse, beyond half a voxel diagonal (its stencil's spread joins
     * the estimate; with the camera inside a box at g 0.85, against
     * Cycles, two diagonals gave 31 % and 92 % of blocks covered, half a
     * diagonal 11 % and 100 %, none at all missed test_ms's slab rays) */
    const double diag = sqrt(v->h[0] * v->h[0] + v->h[1] * v->h[1] + v->h[2] * v->h[2]);
    const double tcam = !c ? INFINITY : c->e ? 0.5 * diag : 8 * hmax;
    const double dl = (tb - ta) / n, ratio = exp(-v->sig * dl);
    const int nch = v->nch;
    double acc[3] = { 0, 0, 0 }, err[3] = { 0, 0, 0 };
    double T = -expm1(-v->sig * dl) / v->sig;
    for (int i = 0; i < n; ++i, T *= ratio) {
        const double t = ta + (i + 0.5) * dl;
        const double x[3] = { r->org[0] + t * r->dir[0], r->org[1] + t * r->dir[1],
                              r->org[2] + t * r->dir[2] };
        size_t id[8];
        double w[8];
        const int ns = stencil(v, x, id, w);
        for (int ch = 0; ch < nch; ++ch) {
            double jj = 0, j0 = 0, jl = 0, es = 0;
            if (t > tcam) {
                for (int k = 0; k < ns; ++k)
                    jj += w[k] * c->j[id[k] * 3 + (size_t) ch];
                if (c->e) {
                    /* the exact table's estimate: its noise and grid, and
                     * the stencil's spread (the direction to the camera
                     * turns across it) */
                    for (int k = 0; E && k < ns; ++k) {
                        const double jk = c->j[id[k] * 3 + (size_t) ch];
                        err[ch] += T * w[k] *
                                   (fabs(jk) * c->e[id[k] * 3 + (size_t) ch] + fabs(jk - jj));
                    }
                    acc[ch] += T * (jj > 0 ? jj : 0);
                    continue;
                }
            } else {
                for (int k = 0; k < ns; ++k) {
                    const double *p = v->phi + (id[k] * 3 + (size_t) ch) * VMS_NC;
                    double s0 = 0;
                    for (int m = 0; m < VMS_NC; ++m)
                        s0 += cw[m] * p[m];
                    jj += w[k] * s0;
                }
                jj *= v->sig * v->alb[ch];
            }
            acc[ch] += T * (jj > 0 ? jj : 0);
            if (!E)
                continue;
            /* the estimate: the noise's and the grid's share of the
             * voxel's isotropic part, and the harmonics left out */
            for (int k = 0; k < ns; ++k) {
                const double *p = v->phi + (id[k] * 3 + (size_t) ch) * VMS_NC;
                double sl = 0;
                for (int m = (VMS_L - 1) * (VMS_L - 1); m < VMS_NC; ++m)
                    sl += cw[m] * p[m];
                j0 += w[k] * p[0];
                jl += w[k] * sl;
                es += w[k] * v->est[id[k] * 3 + (size_t) ch];
            }
            err[ch] += T * v->sig * v->alb[ch] * (fabs(cw[0] * j0) * es + fabs(jl) * v->trunc);
        }
    }
    for (int k = 0; k < 3; ++k) {
        S[k] = v->E[k] * (nch == 1 ? acc[0] : acc[k]);
        if (E)
            E[k] = v->E[k] * (nch == 1 ? err[0] : err[k]);
    }
}

void ef_vms_get_info(const ef_vms *v, ef_ms_info *info)
{
    if (v)
        *info = v->info;
}
