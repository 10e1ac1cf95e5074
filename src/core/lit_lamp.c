/* A point lamp in uniform isotropic fog (lit_int.h): the closed form of
 * its in-scatter along a segment (the exponential integral through
 * continued fractions and series), four rays at a time in vector lanes,
 * and a span of rays beside the lamp. */
#include "lit_int.h"
#include "span.h"
#include "vmath.h"

#include <complex.h>
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------ a point lamp in uniform fog */

/* |z|^2, without hypot's care for overflow (the arguments here are far
 * from it) */
static double norm2(double complex z)
{
    return creal(z) * creal(z) + cimag(z) * cimag(z);
}

/* w_k = (-1)^k / (k k!), k = 0..21 (w_0 = 0): sum_k w_k z^k is the sum
 * (-z)^k / (k k!) in E1(z) = -gamma - ln z - sum. */
static const double lamp_w[22] = {
    0, -1, 0.25, -0.055555555555555552, 0.010416666666666666, -0.0016666666666666668,
    0.00023148148148148149, -2.834467120181406e-05, 3.1001984126984127e-06,
    -3.0619243582206544e-07, 2.7557319223985891e-08, -2.27746439867652e-09,
    1.7397297489890083e-10, -1.2353110643708935e-11, 8.1933897126640886e-13,
    -5.0981091545465446e-14, 2.9871733327421158e-15, -1.6537983849091297e-16,
    8.6773372047701253e-18, -4.326650129802279e-19, 2.0551588116560825e-20,
    -9.3204481254244102e-22,
};

/* The terms of lamp_w that reach 1e-17 of the series for |z|^2 <= r2
 * <= 2.25: r^n / (n + 1)! below it. */
static int lamp_terms(double r2)
{
    return r2 <= 0.0625 ? 12 : r2 <= 0.25 ? 15 : r2 <= 0.5625 ? 17 : r2 <= 1 ? 18
           : r2 <= 1.5625 ? 20 : 21;
}

/* g_e1's continued fraction for the lanes of live (|z| >= 1.5), each
 * lane stopping at its own convergence (its value is the same whatever
 * its neighbours): G into (Gr, Gi), and in conv whether it converged
 * within 2000 terms. F = b_0 + a_1 / (b_1 + a_2 / (b_2 + ...)), b_j =
 * z + 2j + 1, a_j = -j^2, G = 1 / F, by the forward recurrences of F's
 * numerators and denominators (Wallis): no division per term, so one
 * term is a few multiplications deep rather than the modified Lentz
 * method's three divisions. Both grow; every fourth term they are scaled
 * back by a power of two of the lane's own (exact: no rounding), and the
 * test for convergence uses |F_j - F_(j-1)| = (j!)^2 / |B_j B_(j-1)| (the
 * product of the a's, not a difference that would cancel), tracked in
 * the same scale as q2 = (j!)^4. */
EF_INLINE void lamp_cf4(const v4d *zr, const v4d *zi, const v4di *live_in, v4d *Gr, v4d *Gi,
                        v4di *conv)
{
    const v4d zero = { 0, 0, 0, 0 };
    /* A_(j-1), A_j, B_(j-1), B_j; j = 0 */
    v4d pAr = zero + 1.0, pAi = zero, Ar = *zr + 1.0, Ai = *zi, pBr = zero, pBi = zero,
        Br = zero + 1.0, Bi = zero, q2 = zero + 1.0;
    v4d fAr = Ar, fAi = Ai, fBr = Br, fBi = Bi;   /* each lane's at its convergence */
    v4di live = *live_in;
    *conv = live & 0;
    for (int j = 1; j < 2000 && v_any(&live); ++j) {
        const v4d br = *zr + (2.0 * j + 1);
        const double a = -(double) j * j;
        const v4d nAr = (br * Ar - *zi * Ai) + a * pAr, nAi = (br * Ai + *zi * Ar) + a * pAi;
        const v4d nBr = (br * Br - *zi * Bi) + a * pBr, nBi = (br * Bi + *zi * Br) + a * pBi;
        pAr = Ar;
        pAi = Ai;
        pBr = Br;
        pBi = Bi;
        Ar = nAr;
        Ai = nAi;
        Br = nBr;
        Bi = nBi;
        q2 = q2 * (a * a);
        /* |F_j - F_(j-1)| < 1e-16 |F_j|: (j!)^2 < 1e-16 |A_j| |B_(j-1)| */
        const v4di done =
            live & (q2 < 1e-32 * ((Ar * Ar + Ai * Ai) * (pBr * pBr + pBi * pBi)));
        v_sel(&fAr, &done, &Ar, &fAr);
        v_sel(&fAi, &done, &Ai, &fAi);
        v_sel(&fBr, &done, &Br, &fBr);
        v_sel(&fBi, &done, &Bi, &fBi);
        *conv |= done;
        live &= ~done;
        if (j % 4 == 0) {
            /* by 2^-e, 2^e <= |Br| + |Bi| < 2^(e+1) (lanes not live may
             * hold anything: their scale is never used) */
            v4d m, t;
            v_abs(&Br, &m);
            v_abs(&Bi, &t);
            m = m + t;
            const v4u eb = ((v4u) m >> 52) & 2047;
            const v4d sc = (v4d) ((2046 - eb) << 52), sc2 = sc * sc;
            pAr = pAr * sc;
            pAi = pAi * sc;
            Ar = Ar * sc;
            Ai = Ai * sc;
            pBr = pBr * sc;
            pBi = pBi * sc;
            Br = Br * sc;
            Bi = Bi * sc;
            q2 = q2 * (sc2 * sc2);
        }
    }
    /* G = B / A */
    const v4d an = fAr * fAr + fAi * fAi;
    *Gr = (fBr * fAr + fBi * fAi) / an;
    *Gi = (fBi * fAr - fBr * fAi) / an;
}

/* G(z) = e^z E1(z) for Re z >= 0, z != 0, to about 1e-16 of |G|: the
 * series -gamma - ln z - sum (-z)^k / (k k!) (times e^z) for |z| < 1.5,
 * else the continued fraction 1/(z + 1 - 1/(z + 3 - 4/(z + 5 - ...)))
 * by the modified Lentz method. Returns 0, or -1 when it did not converge
 * (the caller integrates instead). */
static int g_e1(double complex z, double complex *out)
{
    const double zr = creal(z), zi = cimag(z), r2 = zr * zr + zi * zi;
    if (r2 < 1.5 * 1.5) {
        /* Horner: sum_k w_k z^k = z (w_1 + z (w_2 + ...)) */
        const int n = lamp_terms(r2);
        double sr = lamp_w[n], si = 0;
        for (int k = n - 1; k >= 1; --k) {
            const double tr = lamp_w[k] + zr * sr - zi * si;
            si = zr * si + zi * sr;
            sr = tr;
        }
        const double complex sum = (zr * sr - zi * si) + I * (zr * si + zi * sr);
        *out = cexp(z) * (-0.57721566490153286061 - clog(z) - sum);
        return 0;
    }
    /* the continued fraction: lamp_cf4's, one lane used */
    const v4d vr = { zr, zr, zr, zr }, vi = { zi, zi, zi, zi };
    const v4di live = { -1, -1, -1, -1 };
    v4d Gr, Gi;
    v4di conv;
    lamp_cf4(&vr, &vi, &live, &Gr, &Gi, &conv);
    if (!conv[0])
        return -1;
    *out = Gr[0] + I * Gi[0];
    return 0;
}

double ef_lit_e2(double x)
{
    if (!(x > 0))
        return 1;
    if (x > 700)
        return 0;
    /* E_2 = e^-x - x E_1 = e^-x (1 - x G), G = e^x E_1 */
    double complex G;
    if (g_e1(x, &G))
        return exp(-x);
    return fmax(0, exp(-x) * (1 - x * creal(G)));
}

/* Sun, Ramamoorthi, Narasimhan and Nayar's closed form for a point lamp
 * of radius 0 in uniform fog with the isotropic phase, over [a, D]:
 *   int e^-(sigma (t + d)) / d^2 dt = (2 / h) Im[F(w_a) - F(w_D)],
 *   F(w) = e^-(sigma (t + d)) G(sigma (t - ts + d) - i sigma h),
 * with w = tan(xi) + sec(xi) = (t - ts + d) / h (the equiangular xi in
 * the half angle: 2 int e^-(A w) / (1 + w^2) dw, A = sigma h) and the
 * exponential integral of the complex argument in place of their table.
 * t - ts + d is formed as h^2 / (d - (t - ts)) behind the lamp (no
 * cancellation). Adds to S per channel scat[k] e[k] times it, and to E
 * the rounding of the two ends (2e-15 of their magnitudes); returns 0,
 * or -1 (nothing added) where G does not converge or the two ends cancel
 * to more than a tenth of the result's digits at 1e-13 (short segments,
 * a lamp far off the segment's end): the caller integrates then. */
/* (2 / h) Im[F(w_a) - F(w_D)] for two finite ends whose z = sig (p - i h)
 * (p = t - ts + d) both lie inside the series' circle |z| < 1.5, into *r,
 * and its rounding into *err; returns 0, or -1 when they do not. There
 * x e^z = e^-(sig ts) at both ends, so
 *   F(w_a) - F(w_D) = e^-(sig ts) e^-(i sig h) (log(z_D / z_a) + sum_k
 *                     (-1)^k (z_D^k - z_a^k) / (k k!)),
 * with no cexp or clog per end, and no difference of the ends' values:
 * z_D - z_a = sig dp is real (dp = p_D - p_a as the caller forms it),
 * |z_D|^2 - |z_a|^2 = sig dp (Re z_a + Re z_D), arg(z_D / z_a) from
 * z_D conj(z_a), and z_D^k - z_a^k = z_D P_(k-1) + (z_D - z_a) z_a^(k-1).
 * Near ends (a short segment far from the lamp) keep their digits. */
static int lamp_series_pair(double sg, double ts, double h, double pa, double pD, double dp,
                            double *r, double *err)
{
    const double ar = sg * pa, dr = sg * pD, zi = -sg * h, dz = sg * dp;
    const double na = ar * ar + zi * zi, nd = dr * dr + zi * zi;
    if (!(na < 2.25 && nd < 2.25) || !(na > 0) || !(sg * ts > -700))
        return -1;
    const double lr = 0.5 * log1p(dz * (ar + dr) / na);
    const double li = atan2(-zi * dz, ar * dr + zi * zi);
    /* Horner at z_D with the divided difference (p(z_D) - p(z_a)) / dz
     * alongside: q <- b + z_a q, b <- w_k + z_D b */
    const int n = lamp_terms(na > nd ? na : nd);
    double br = lamp_w[n], bi = 0, qr = 0, qi = 0;
    for (int k = n - 1; k >= 0; --k) {
        const double nqr = br + ar * qr - zi * qi, nqi = bi + ar * qi + zi * qr;
        const double nbr = lamp_w[k] + dr * br - zi * bi, nbi = dr * bi + zi * br;
        qr = nqr;
        qi = nqi;
        br = nbr;
        bi = nbi;
    }
    const double complex V = (lr + dz * qr) + I * (li + dz * qi);
    const double c = cos(sg * h), sn = sin(sg * h), f = 2 / h * exp(-sg * ts);
    *r = f * (c * cimag(V) - sn * creal(V));
    *err = f * sqrt(norm2(V)) * 1e-15;
    return isfinite(*r) ? 0 : -1;
}

/* One channel of lamp_closed for one segment: the integral per unit of
 * scat e over [a, D] into *r and its rounding into *re, by the series pair
 * where both ends lie in its circle and its rounding allows, else from
 * the two ends' G (series or continued fraction). Returns 0, or -1 where
 * G does not converge or the ends cancel (the caller integrates). The
 * scalar form, for the segments lamp_kernel leaves. */
static int lamp_unit1(double sg, double ts, double h, double a, double D, double *r, double *re)
{
    if (isfinite(D)) {
        /* both ends near the lamp's scale: the series pair */
        const double ua = a - ts, uD = D - ts, da = ef_lit_len2(ua, h), dD = ef_lit_len2(uD, h);
        const double pa = ua >= 0 ? ua + da : h * h / (da - ua);
        const double pD = uD >= 0 ? uD + dD : h * h / (dD - uD);
        if (lamp_series_pair(sg, ts, h, pa, pD, (D - a) * (pa + pD) / (da + dD), r, re) == 0 &&
            *re <= 1e-13 * fabs(*r))
            return 0;
    }
    double v[2] = { 0, 0 }, mag = 0;
    const double ends[2] = { a, D };
    for (int i = 0; i < 2; ++i) {
        const double t = ends[i];
        if (!isfinite(t))
            continue;   /* F(inf) = 0 */
        const double u = t - ts, d = ef_lit_len2(u, h);
        const double w = u >= 0 ? u + d : h * h / (d - u);   /* h w, really */
        double complex G;
        if (g_e1(sg * w - I * (sg * h), &G))
            return -1;
        const double x = exp(-sg * (t + d));
        v[i] = x == 0 ? 0 : x * cimag(G);
        mag += x == 0 ? 0 : x * sqrt(norm2(G));
    }
    *r = 2 / h * (v[0] - v[1]);
    *re = 2 / h * mag * 2e-15;   /* the ends' rounding */
    return *re <= 1e-13 * fabs(*r) && isfinite(*r) ? 0 : -1;
}

/* Four segments of one lamp at once: their ts, h (> 0) and ends a < D
 * (D may be infinite), one sigma. */
typedef struct lamp4 {
    double ts[4], h[4], a[4], D[4];
} lamp4;

/* (or, oi) = (ar, ai) (br, bi), complex, per lane */
EF_INLINE void cmul4(const v4d *ar, const v4d *ai, const v4d *br, const v4d *bi, v4d *or,
                     v4d *oi)
{
    const v4d r = *ar * *br - *ai * *bi, i = *ar * *bi + *ai * *br;
    *or = r;
    *oi = i;
}

/* One of lamp_poly4's chains: X(v) = sum_n lamp_w[i0 + 4 n] v^n, n =
 * 0..top, by Horner at v into b, and with pair its divided difference
 * [X](v, va) into q (q <- b + va q beside b <- w + v b). */
EF_INLINE void lamp_chain4(int i0, int top, const v4d *vr, const v4d *vi, const v4d *var,
                           const v4d *vai, int pair, v4d b[2], v4d q[2])
{
    const v4d zero = { 0, 0, 0, 0 };
    v4d br = zero + lamp_w[i0 + 4 * top], bi = zero, qr = zero, qi = zero;
    for (int n = top - 1; n >= 0; --n) {
        if (pair) {
            const v4d nqr = br + (*var * qr - *vai * qi), nqi = bi + (*var * qi + *vai * qr);
            qr = nqr;
            qi = nqi;
        }
        const v4d nbr = lamp_w[i0 + 4 * n] + (*vr * br - *vi * bi), nbi = *vr * bi + *vi * br;
        br = nbr;
        bi = nbi;
    }
    b[0] = br;
    b[1] = bi;
    q[0] = qr;
    q[1] = qi;
}

/* o = (a + u b) t + c, complex (index 0 real, 1 imaginary), per lane:
 * one step of [A(u) + u B(u)](u, ua) = ([A] + ua [B]) (u + ua) + B(u) */
EF_INLINE void lamp_dd4(const v4d u[2], const v4d a[2], const v4d b[2], const v4d t[2],
                        const v4d c[2], v4d o[2])
{
    v4d x0, x1, y0, y1;
    cmul4(&u[0], &u[1], &b[0], &b[1], &x0, &x1);
    x0 = a[0] + x0;
    x1 = a[1] + x1;
    cmul4(&x0, &x1, &t[0], &t[1], &y0, &y1);
    o[0] = y0 + c[0];
    o[1] = y1 + c[1];
}

/* P(z) = sum_k w_k z^k over all of lamp_w (21 terms: 1e-17 at |z| = 1.5,
 * more than needed nearer 0, but the same steps for every lane, so that a
 * lane's value never depends on its neighbours; per-lane counts measured
 * no faster) into P, or with pair the divided difference [P](z, za) =
 * (P(z) - P(za)) / (z - za) without that difference's cancellation. The
 * weights split four ways, P(z) = EE(v) + u EO(v) + z (OE(v) + u OO(v)),
 * u = z^2, v = u^2: four independent chains of five steps (rather than
 * one Horner's twenty dependent ones), and [P] from the
 * chains' divided differences by [A(u) + u B(u)](uD, ua) = [A] (uD + ua)
 * ... applied twice: [E](u, ua) = [EE](v, va) t + EO(v) + ua [EO](v, va) t,
 * t = u + ua, and [P] = [E] s + O(u) + za [O] s, s = z + za. */
EF_INLINE void lamp_poly4(const v4d *zr, const v4d *zi, const v4d *zar, const v4d *zai,
                          int pair, v4d *Pr, v4d *Pi)
{
    v4d ur, ui, vr, vi, uar = *zr, uai = *zi, var = *zr, vai = *zi;
    cmul4(zr, zi, zr, zi, &ur, &ui);
    cmul4(&ur, &ui, &ur, &ui, &vr, &vi);
    if (pair) {
        cmul4(zar, zai, zar, zai, &uar, &uai);
        cmul4(&uar, &uai, &uar, &uai, &var, &vai);
    }
    v4d ee[2], eo[2], oe[2], oo[2], qee[2], qeo[2], qoe[2], qoo[2];
    lamp_chain4(0, 5, &vr, &vi, &var, &vai, pair, ee, qee);
    lamp_chain4(2, 4, &vr, &vi, &var, &vai, pair, eo, qeo);
    lamp_chain4(1, 5, &vr, &vi, &var, &vai, pair, oe, qoe);
    lamp_chain4(3, 4, &vr, &vi, &var, &vai, pair, oo, qoo);
    v4d t0, t1;
    cmul4(&ur, &ui, &oo[0], &oo[1], &t0, &t1);
    const v4d Or = oe[0] + t0, Oi = oe[1] + t1;   /* O(u) */
    if (!pair) {
        v4d x0, x1;
        cmul4(&ur, &ui, &eo[0], &eo[1], &t0, &t1);
        cmul4(zr, zi, &Or, &Oi, &x0, &x1);
        *Pr = (ee[0] + t0) + x0;
        *Pi = (ee[1] + t1) + x1;
        return;
    }
    const v4d t[2] = { ur + uar, ui + uai }, sz[2] = { *zr + *zar, *zi + *zai },
              ua[2] = { uar, uai }, za[2] = { *zar, *zai }, O[2] = { Or, Oi };
    /* [E] and [O] over (u, ua), then [P] = ([E] + za [O]) s + O(u) */
    v4d dE[2], dO[2], P[2];
    lamp_dd4(ua, qee, qeo, t, eo, dE);
    lamp_dd4(ua, qoe, qoo, t, oo, dO);
    lamp_dd4(za, dE, dO, sz, O, P);
    *Pr = P[0];
    *Pi = P[1];
}

/* sqrt(x^2 + y^2) per lane, and in ok whether len2 takes that form (its
 * magnitudes within 1e-150 .. 1e150), so that the value is len2's. */
EF_INLINE void len2_4(const v4d *x, const v4d *y, v4d *o, v4di *ok)
{
    v4d ax, ay;
    v_abs(x, &ax);
    v_abs(y, &ay);
    const v4di xbig = ax > ay;
    v4d m;
    v_sel(&m, &xbig, &ax, &ay);   /* NaN: ay, which fails below as len2's does */
    const v4d s = *x * *x + *y * *y;
    v_sqrt(&s, o);
    *ok = (m < 1e150) & (m > 1e-150);
}

/* lamp_unit1 for four lanes on vectors: the series pair as
 * lamp_series_pair computes it; where that is not taken, the two ends'
 * F = e^-(sg ts) e^-(i sg h) E1(z) (x e^z = e^-(sg ts) at every end: one
 * exp and one sincos per segment, E1 = -gamma - log z - series), each end
 * inside the series' circle. st[i]: 1 done (r, re), -1 the ends cancel
 * (the caller integrates), 0 left to lamp_unit1 (an end outside the
 * circle, or a value beyond vmath.h's ranges). */
EF_INLINE void lamp_kernel(double sg, const lamp4 *in, v4d *r, v4d *re, v4di *st)
{
    v4d ts, h, a, D;
    memcpy(&ts, in->ts, sizeof ts);
    memcpy(&h, in->h, sizeof h);
    memcpy(&a, in->a, sizeof a);
    memcpy(&D, in->D, sizeof D);
    const v4di finD = D < INFINITY;
    const v4d zero = { 0, 0, 0, 0 }, ua = a - ts, uD0 = D - ts;
    v4d uD;
    v_sel(&uD, &finD, &uD0, &zero);   /* no inf - inf below */
    v4d da, dD;
    v4di okA, okD;
    len2_4(&ua, &h, &da, &okA);
    len2_4(&uD, &h, &dD, &okD);
    const v4d h2 = h * h, paf = ua + da, pab = h2 / (da - ua), pDf = uD + dD,
              pDb = h2 / (dD - uD);
    v4d pa, pD;
    const v4di fa = ua >= 0.0, fD = uD >= 0.0;
    v_sel(&pa, &fa, &paf, &pab);
    v_sel(&pD, &fD, &pDf, &pDb);
    const v4d dp = (D - a) * (pa + pD) / (da + dD);
    const v4d ar = sg * pa, dr = sg * pD, zi = -sg * h, dz = sg * dp;
    const v4d na = ar * ar + zi * zi, nd = dr * dr + zi * zi, sts = sg * ts;
    /* the vector functions' ranges: exp's argument, log's normal inputs;
     * each end by the series inside its circle, else by the continued
     * fraction with e^-(sg (t + d)) */
    const v4di sts_ok = (sts > -700.0) & (sts < 700.0);
    const v4di ser_a = (na > 1e-200) & (na < 2.25), ser_D = (nd > 1e-200) & (nd < 2.25);
    const v4d xa_arg = sg * (a + da), xD_arg = sg * (D + dD);
    const v4di cf_a = (na >= 2.25) & (na < 1e300) & (xa_arg < 700.0);
    const v4di cf_D = (nd >= 2.25) & (nd < 1e300) & (xD_arg < 700.0);
    const v4di pair = okA & okD & finD & sts_ok & ser_a & ser_D;
    const v4di ends = okA & ((ser_a & sts_ok) | cf_a) &
                      (~finD | (okD & ((ser_D & sts_ok) | cf_D)));
    const v4d msts = -sts, sgh = sg * h;
    v4d E, sn, cs;
    v_exp(&msts, &E);
    v_sincos(&sgh, &sn, &cs);
    const v4d h2h = 2.0 / h, f = h2h * E;
    v4d rp = zero, rpe = zero;
    v4di done = { 0, 0, 0, 0 };
    if (v_any(&pair)) {
        const v4d x1 = dz * (ar + dr) / na, y = -zi * dz, x = ar * dr + zi * zi;
        v4d lr, li;
        v_log1p(&x1, &lr);
        lr = lr * 0.5;
        v_atan2(&y, &x, &li);
        v4d qr, qi;   /* [P](z_D, z_a) */
        lamp_poly4(&dr, &zi, &ar, &zi, 1, &qr, &qi);
        const v4d Vr = lr + dz * qr, Vi = li + dz * qi;
        rp = f * (cs * Vi - sn * Vr);
        v4d m2 = Vr * Vr + Vi * Vi;
        v_sqrt(&m2, &m2);
        rpe = f * m2 * 1e-15;
        v4d arp;
        v_abs(&rp, &arp);
        done = pair & (arp < INFINITY) & (rpe <= 1e-13 * arp);
    }
    v4d re2 = zero, ree = zero;
    const v4di need = ends & ~done;
    v4di bad = { 0, 0, 0, 0 };   /* a continued fraction that did not converge */
    if (v_any(&need)) {
        /* Im F and |F| at each end (D's where finite), then their
         * difference and sum */
        v4d V = zero, mag = zero;
        for (int e = 0; e < 2; ++e) {
            const v4d zr = e ? dr : ar, r2 = e ? nd : na, xarg = e ? xD_arg : xa_arg;
            /* (the far end only where it is finite) */
            const v4di ser = (e ? ser_D & finD : ser_a) & need,
                       cf = (e ? cf_D & finD : cf_a) & need;
            v4d vi = zero, m = zero;
            if (v_any(&ser)) {
                v4d lg, th;
                v_log(&r2, &lg);
                v_atan2(&zi, &zr, &th);
                v4d sumr, sumi;
                lamp_poly4(&zr, &zi, &zr, &zi, 0, &sumr, &sumi);
                const v4d Er = (-0.57721566490153286061 - 0.5 * lg) - sumr, Ei = -th - sumi;
                v4d m2 = Er * Er + Ei * Ei;
                v_sqrt(&m2, &m2);
                const v4d svi = E * (cs * Ei - sn * Er), sm = E * m2;
                v_sel(&vi, &ser, &svi, &vi);
                v_sel(&m, &ser, &sm, &m);
            }
            if (v_any(&cf)) {
                v4d Gr, Gi, x;
                v4di conv;
                lamp_cf4(&zr, &zi, &cf, &Gr, &Gi, &conv);
                bad |= cf & ~conv;
                const v4d mx = -xarg;
                v_exp(&mx, &x);
                v4d m2 = Gr * Gr + Gi * Gi;
                v_sqrt(&m2, &m2);
                const v4d cvi = x * Gi, cm = x * m2;
                v_sel(&vi, &cf, &cvi, &vi);
                v_sel(&m, &cf, &cm, &m);
            }
            if (e == 0) {
                V = vi;
                mag = m;
            } else {
                const v4d dV = V - vi, dm = mag + m;
                v_sel(&V, &finD, &dV, &V);
                v_sel(&mag, &finD, &dm, &mag);
            }
        }
        re2 = h2h * V;
        ree = h2h * mag * 2e-15;
    }
    /* as vectors: their lanes are read as vectors next */
    v4d are2;
    v_abs(&re2, &are2);
    const v4di one = { 1, 1, 1, 1 }, ok = ~bad & (ree <= 1e-13 * are2) & (are2 < INFINITY);
    v_sel(r, &done, &rp, &re2);
    v_sel(re, &done, &rpe, &ree);
    *st = (done & one) | (need & ~done & ((ok & one) | (~ok & -one)));
}

/* lamp_closed for four segments of one medium (sig, scat) and lamp (e),
 * lamp_kernel's lanes with lamp_unit1 for those it leaves: for each lane
 * i < m whose every channel holds (st[i] 0), S[k][idx[i]] and (E not
 * NULL) E[k][idx[i]] set to the sums from 0 that ef_light_inscatter forms;
 * st[i] -1 and nothing written where a channel's closed form does not
 * hold (the caller integrates). */
EF_INLINE void lamp_rays4_in(const double sig[3], const double scat[3], const double e[3],
                             const lamp4 *in, int m, const int *idx, double *const S[3],
                             double *const E[3], int st[4])
{
    const v4d zero = { 0, 0, 0, 0 };
    v4d out[3], err[3];
    /* the integral per unit of scat e, and its rounding, at sig[have]:
     * channels of the same sigma take it (grey fog, coloured lamps) */
    v4d unit = zero, unit_e = zero;
    v4di stv = { 0, 0, 0, 0 };
    int have = -1;
    for (int k = 0; k < 3; ++k) {
        if (!(sig[k] > 0) || scat[k] == 0 || e[k] == 0) {
            out[k] = err[k] = zero;
            continue;
        }
        if (have < 0 || sig[k] != sig[have]) {
            v4di ust;
            lamp_kernel(sig[k], in, &unit, &unit_e, &ust);
            stv |= ust == -1;
            const v4di left = ust == 0;
            if (v_any(&left)) {   /* rare: lamp_unit1 for those lanes */
                double u[4], ue[4];
                memcpy(u, &unit, sizeof u);
                memcpy(ue, &unit_e, sizeof ue);
                for (int i = 0; i < 4; ++i)
                    if (left[i] && lamp_unit1(sig[k], in->ts[i], in->h[i], in->a[i], in->D[i],
                                              &u[i], &ue[i]))
                        stv[i] = -1;
                memcpy(&unit, u, sizeof u);
                memcpy(&unit_e, ue, sizeof ue);
            }
            have = k;
        }
        out[k] = unit * scat[k] * e[k];
        err[k] = E ? unit_e * scat[k] * e[k] : zero;
    }
    for (int i = 0; i < 4; ++i)
        st[i] = (int) stv[i];
    /* 0.0 + x: a -0 sum from 0, as ef_light_inscatter's */
    if (m == 4 && idx[3] == idx[0] + 3 && !v_any(&stv)) {
        for (int k = 0; k < 3; ++k) {
            const v4d o = 0.0 + out[k];
            memcpy(S[k] + idx[0], &o, sizeof o);
            if (E) {
                const v4d oe = 0.0 + err[k];
                memcpy(E[k] + idx[0], &oe, sizeof oe);
            }
        }
        return;
    }
    for (int i = 0; i < m; ++i)
        if (st[i] == 0)
            for (int k = 0; k < 3; ++k) {
                S[k][idx[i]] = 0.0 + out[k][i];
                if (E)
                    E[k][idx[i]] = 0.0 + err[k][i];
            }
}

/* lamp_rays4_in, dispatched (one segment at a time: lamp_closed) */
EF_MULTIVERSION static void lamp_rays4(const double sig[3], const double scat[3],
                                       const double e[3], const lamp4 *in, int m,
                                       const int *idx, double *const S[3], double *const E[3],
                                       int st[4])
{
    lamp_rays4_in(sig, scat, e, in, m, idx, S, E, st);
}

/* lamp_rays4 for one segment (its lanes all alike): the same bits as the
 * segment in any lane of a span's batch, added to S and E (0 here: a
 * point lamp's one lit range). Returns 0, or -1 with nothing added. */
int ef_lit_lamp_closed(const double sig[3], const double scat[3], const double e[3], double ts,
                       double h, double a, double D, double S[3], double E[3])
{
    const lamp4 in = { { ts, ts, ts, ts }, { h, h, h, h }, { a, a, a, a }, { D, D, D, D } };
    double Sv[3], Ev[3];
    double *const Sk[3] = { &Sv[0], &Sv[1], &Sv[2] }, *const Ek[3] = { &Ev[0], &Ev[1], &Ev[2] };
    const int idx = 0;
    int st[4];
    lamp_rays4(sig, scat, e, &in, 1, &idx, Sk, Ek, st);
    if (st[0])
        return -1;
    for (int k = 0; k < 3; ++k) {
        S[k] += Sv[k];
        E[k] += Ev[k];
    }
    return 0;
}

/* Whether lamp_span's batches take a ray of length D whose closest
 * approach to the lamp is h at ts (h as lamp_line gives it): a segment,
 * beside the lamp, in magnitudes the kernel handles. No short circuit, so
 * a loop over a span vectorises. */
EF_INLINE int lamp_takes(double D, double h, double ts)
{
    return (D > 0) & (h > 0) & (h <= DBL_MAX / 64) & (fabs(ts) < INFINITY);
}

/* The n <= EF_SPAN rays r[j] of one span beside point lamp l (radius 0)
 * in the medium (sig, scat), four at a time by lamp_rays4_in: S[k][j]
 * and (E not NULL) E[k][j] set, except for the rays whose indices go to
 * left (their count returned), which the caller evaluates one by one (at
 * or through the lamp, a length of 0, magnitudes out of range, a closed
 * form that does not hold). ts and h as lamp_line forms them, in a loop
 * the compiler vectorises (len3's plain form; lamp_line where a ray
 * leaves it): the same bits. */
EF_MULTIVERSION int ef_lit_lamp_span(const ef_light *l, const double sig[3],
                                     const double scat[3], const ef_ray *r, int n,
                                     double *const S[3], double *const E[3], int *left)
{
    double F[8][EF_SPAN], tsv[EF_SPAN], hv[EF_SPAN];
    rays_soa(r, n, F);
    const double px = l->pos[0], py = l->pos[1], pz = l->pos[2];
    for (int j = 0; j < n; ++j) {
        const double dx = F[EF_F_DIR][j], dy = F[EF_F_DIR + 1][j], dz = F[EF_F_DIR + 2][j];
        const double wx = px - F[EF_F_ORG][j], wy = py - F[EF_F_ORG + 1][j],
                     wz = pz - F[EF_F_ORG + 2][j];
        tsv[j] = wx * dx + wy * dy + wz * dz;
        const double cx = wy * dz - wz * dy, cy = wz * dx - wx * dz, cz = wx * dy - wy * dx;
        const double ax = fabs(cx), ay = fabs(cy), az = fabs(cz);
        const double mxy = ax > ay ? ax : ay, m = mxy > az ? mxy : az;
        const double v = sqrt(cx * cx + cy * cy + cz * cz);
        hv[j] = m < 1e150 && m > 1e-150 ? v : -1.0;
    }
    /* the common span: every ray beside the lamp in plain magnitudes, its
     * batches the arrays' slices (copied as vectors) */
    int all = n % 4 == 0;
    for (int j = 0; j < n; ++j)
        all &= lamp_takes(F[EF_F_DIST][j], hv[j], tsv[j]);
    lamp4 in[EF_SPAN / 4];
    int idx[EF_SPAN], m = 0, nl = 0;
    if (all) {
        const double zero[4] = { 0, 0, 0, 0 };
        for (int b = 0; b < n / 4; ++b) {
            memcpy(in[b].ts, tsv + 4 * b, sizeof in[b].ts);
            memcpy(in[b].h, hv + 4 * b, sizeof in[b].h);
            memcpy(in[b].a, zero, sizeof in[b].a);
            memcpy(in[b].D, F[EF_F_DIST] + 4 * b, sizeof in[b].D);
        }
        for (int j = 0; j < n; ++j)
            idx[j] = j;
        m = n;
    }
    /* else every ray's batch first, then the batches: a batch's four lanes
     * are read as vectors long after their scalar stores (not through a
     * stalled store-to-load forward) */
    for (int j = 0; !all && j < n; ++j) {
        double w[3], ts = tsv[j], h = hv[j];
        const int beside = r[j].dist > 0;
        if (beside && !(h >= 0))
            ef_lit_lamp_line(l, &r[j], w, &ts, &h);
        if (!lamp_takes(r[j].dist, h, ts)) {
            left[nl++] = j;
            continue;
        }
        lamp4 *const b = &in[m / 4];
        b->ts[m % 4] = ts;
        b->h[m % 4] = h;
        b->a[m % 4] = 0;
        b->D[m % 4] = r[j].dist;
        idx[m++] = j;
    }
    for (int i = m; i % 4; ++i) {   /* the last batch: its last ray again */
        lamp4 *const b = &in[i / 4];
        const lamp4 *const lb = &in[(m - 1) / 4];
        b->ts[i % 4] = lb->ts[(m - 1) % 4];
        b->h[i % 4] = lb->h[(m - 1) % 4];
        b->a[i % 4] = lb->a[(m - 1) % 4];
        b->D[i % 4] = lb->D[(m - 1) % 4];
    }
    for (int i0 = 0; i0 < m; i0 += 4) {
        int st[4];
        const int mb = m - i0 < 4 ? m - i0 : 4;
        lamp_rays4_in(sig, scat, l->e, &in[i0 / 4], mb, idx + i0, S, E, st);
        for (int i = 0; i < mb; ++i)
            if (st[i])   /* the ends cancel: ef_light_inscatter integrates */
                left[nl++] = idx[i0 + i];
    }
    return nl;
}
