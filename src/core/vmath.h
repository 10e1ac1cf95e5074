/* exp, expm1, log, log1p, atan2, sincos and tan on four lanes at once, in plain IEEE
 * arithmetic (no fma, no table beyond nine constants, no libm call), for
 * the lamp's closed form across a span of rays. Plain arithmetic because
 * strict C11 contracts nothing: each lane's value is the same bits in the
 * baseline clone (two SSE2 halves), the x86-64-v3 clone (one AVX2 vector)
 * and on any other CPU, whatever its neighbours hold. Accurate to a few
 * ulp (tests/unit/test_vmath.c measures each against libm); every function
 * states the inputs it takes, and its callers keep to them (a lane outside
 * goes to libm's scalar functions instead).
 *
 * Pointers in and out, never vectors by value: a 32-byte vector argument
 * changes the ABI where AVX is off, and these are inlined anyway. */
#ifndef EF_VMATH_H
#define EF_VMATH_H

#include <math.h>
#include <string.h>

#include "span.h"

typedef long long v4di __attribute__((vector_size(32)));
/* unsigned lanes for the bit arithmetic, which wraps where a lane not
 * taken holds garbage */
typedef unsigned long long v4u __attribute__((vector_size(32)));

/* m ? a : b per lane (m all ones or all zeros, as comparisons give) */
EF_INLINE void v_sel(v4d *o, const v4di *m, const v4d *a, const v4d *b)
{
    *o = (v4d) (((v4di) *a & *m) | ((v4di) *b & ~*m));
}

/* whether any lane of m is set */
EF_INLINE int v_any(const v4di *m)
{
    return ((*m)[0] | (*m)[1] | (*m)[2] | (*m)[3]) != 0;
}

/* |x| per lane (the sign bit cleared) */
EF_INLINE void v_abs(const v4d *x, v4d *o)
{
    *o = (v4d) ((v4di) *x & 0x7fffffffffffffffLL);
}

/* sqrt per lane, correctly rounded as sqrt() is. Through an array: GCC
 * vectorises the loop there (one vsqrtpd in the x86-64-v3 clone, two
 * sqrtpd in the baseline), not on a vector's lanes. */
EF_INLINE void v_sqrt(const v4d *x, v4d *o)
{
    double t[4];
    memcpy(t, x, sizeof t);
    for (int i = 0; i < 4; ++i)
        t[i] = sqrt(t[i]);
    memcpy(o, t, sizeof t);
}

/* 2^52 + 2^51: adding it rounds a double below 2^51 in magnitude to an
 * integer, which then sits in the low bits of the sum's representation. */
#define EF_V_MAGIC 0x1.8p52

/* e^x for |x| <= 708 (normal results): x = k ln 2 + r, |r| <= ln 2 / 2,
 * ln 2 in two parts (the high one of 32 bits, so k ln2_hi is exact), e^r
 * = 1 + (r + r^2 q(r)), q by its Taylor series to r^11 (e^r's to r^13, the
 * next term below 4.2e-18) in Estrin's scheme: five dependent steps rather
 * than thirteen, so a caller's exponentials overlap; q's rounding is
 * scaled by r^2 <= 0.12. Times 2^k built in the exponent field. */
EF_INLINE void v_exp(const v4d *x, v4d *o)
{
    const v4d magic = { EF_V_MAGIC, EF_V_MAGIC, EF_V_MAGIC, EF_V_MAGIC };
    const v4d t = *x * 1.4426950408889634 + magic;
    const v4d k = t - magic;
    const v4d r = (*x - k * 0.6931471803691238) - k * 1.9082149292705877e-10;
    const v4d r2 = r * r, r4 = r2 * r2, r8 = r4 * r4;
    const v4d q0 = (0.5 + r * 0.16666666666666666) + r2 * (0.041666666666666664 + r * 0.008333333333333333);
    const v4d q1 = (0.001388888888888889 + r * 0.0001984126984126984) +
                   r2 * (2.48015873015873e-05 + r * 2.7557319223985893e-06);
    const v4d q2 = (2.755731922398589e-07 + r * 2.505210838544172e-08) +
                   r2 * (2.08767569878681e-09 + r * 1.6059043836821613e-10);
    const v4d q = (q0 + r4 * q1) + r8 * q2;
    const v4d p = 1.0 + (r + r2 * q);
    const v4u ki = (v4u) t - (v4u) magic;
    *o = p * (v4d) ((ki + 1023) << 52);
}

/* e^x - 1 for x <= 700 (-1 below -708): below 1/2 in magnitude x + x^2
 * q(x), q by e^x's Taylor series from x^2 / 2! to x^17 / 17! (the next
 * term below 1.6e-17 of x^2 at 1/2) in Estrin's scheme, so small x keep
 * every digit; beyond, v_exp less 1 (|e^x - 1| >= 0.39 there, so the
 * subtraction costs at most 3 ulp). */
EF_INLINE void v_expm1(const v4d *x, v4d *o)
{
    const v4d x1 = *x, x2 = x1 * x1, x4 = x2 * x2, x8 = x4 * x4;
    const v4d p0 = (0.5 + x1 * 0.16666666666666666) +
                   (0.041666666666666664 + x1 * 0.008333333333333333) * x2;
    const v4d p1 = (0.001388888888888889 + x1 * 0.0001984126984126984) +
                   (2.48015873015873e-05 + x1 * 2.7557319223985893e-06) * x2;
    const v4d p2 = (2.755731922398589e-07 + x1 * 2.505210838544172e-08) +
                   (2.08767569878681e-09 + x1 * 1.6059043836821613e-10) * x2;
    const v4d p3 = (1.1470745597729725e-11 + x1 * 7.647163731819816e-13) +
                   (4.779477332387385e-14 + x1 * 2.8114572543455206e-15) * x2;
    const v4d q = (p0 + p1 * x4) + (p2 + p3 * x4) * x8;
    const v4d small = x1 + x2 * q;
    v4d xc = x1;
    const v4di lo = xc < -708.0;
    const v4d m708 = { -708.0, -708.0, -708.0, -708.0 };
    v_sel(&xc, &lo, &m708, &xc);
    v4d e;
    v_exp(&xc, &e);
    const v4d big = e - 1.0;
    v4d ax;
    v_abs(&x1, &ax);
    const v4di near = ax < 0.5;
    v_sel(o, &near, &small, &big);
}

/* log x for x normal, positive and finite: x = 2^e m, m in [sqrt(1/2),
 * sqrt(2)), log m = 2 atanh(s) = 2 (s + s^3 / 3 + ...), s = (m - 1) /
 * (m + 1), |s| <= 0.1716, to s^23 (the next term below 1.3e-19 of it),
 * e ln 2 in two parts. */
EF_INLINE void v_log(const v4d *x, v4d *o)
{
    const v4d magic = { EF_V_MAGIC, EF_V_MAGIC, EF_V_MAGIC, EF_V_MAGIC };
    const v4di bits = (v4di) *x;
    v4di e = (bits >> 52) - 1023;
    v4d m = (v4d) ((bits & 0x000fffffffffffffLL) | 0x3ff0000000000000LL);
    const v4di big = m > 1.4142135623730951;
    const v4d half = m * 0.5;
    v_sel(&m, &big, &half, &m);
    e -= big;   /* big is -1 where true */
    const v4d ed = (v4d) ((v4di) magic + e) - magic;
    const v4d s = (m - 1.0) / (m + 1.0), s2 = s * s, s4 = s2 * s2, s8 = s4 * s4;
    /* sum_j s2^j / (2j + 3), j = 0..10, by Estrin's scheme (four levels
     * rather than ten dependent steps; it is scaled by s2 <= 0.03 below,
     * so its rounding stays far under the leading terms') */
    const v4d p0 = (1.0 / 3 + s2 * (1.0 / 5)) + s4 * (1.0 / 7 + s2 * (1.0 / 9));
    const v4d p1 = (1.0 / 11 + s2 * (1.0 / 13)) + s4 * (1.0 / 15 + s2 * (1.0 / 17));
    const v4d p2 = (1.0 / 19 + s2 * (1.0 / 21)) + s4 * (1.0 / 23);
    const v4d p = (p0 + s8 * p1) + (s8 * s8) * p2;
    const v4d s_2 = s + s;
    *o = ed * 0.6931471803691238 + (s_2 + (s_2 * s2 * p + ed * 1.9082149292705877e-10));
}

/* log(1 + x) for x > -1 with 1 + x normal and finite: log(u) x / (u - 1),
 * u = 1 + x rounded (Goldberg's correction: the rounding of u cancels to
 * first order), and x itself where u rounds to 1. */
EF_INLINE void v_log1p(const v4d *x, v4d *o)
{
    const v4d u = *x + 1.0;
    v4d l;
    v_log(&u, &l);
    const v4d c = l * (*x / (u - 1.0));
    const v4di one = u == 1.0;
    v_sel(o, &one, x, &c);
}

/* atan2(y, x) for finite x and y, not both zero and neither -0: the
 * ratio t of the smaller magnitude to the larger, in [0, 1], against its
 * nearest eighth c, atan t = atan c + atan((t - c) / (1 + t c)), the
 * second by its series to s^13 (|s| <= 1/16: the next term below 1.5e-17
 * of it), then the octant and the signs; pi / 2 and pi in two parts. */
EF_INLINE void v_atan2(const v4d *y, const v4d *x, v4d *o)
{
    static const double tab[9] = {
        0.0, 0.12435499454676144, 0.24497866312686414, 0.35877067027057225,
        0.4636476090008061, 0.5585993153435624, 0.6435011087932844, 0.7188299996216245,
        0.7853981633974483,
    };
    const v4d magic = { EF_V_MAGIC, EF_V_MAGIC, EF_V_MAGIC, EF_V_MAGIC };
    v4d ax, ay;
    v_abs(x, &ax);
    v_abs(y, &ay);
    const v4di swap = ay > ax;
    v4d num, den;
    v_sel(&num, &swap, &ax, &ay);
    v_sel(&den, &swap, &ay, &ax);
    const v4d t = num / den;
    const v4d kt = t * 8.0 + magic;
    const v4d c = (kt - magic) * 0.125;
    const v4u k = (v4u) kt - (v4u) magic;
    const v4d s = (t - c) / (1.0 + t * c), s2 = s * s;
    v4d p = s2 * (-1.0 / 13) + 1.0 / 11;
    p = p * s2 - 1.0 / 9;
    p = p * s2 + 1.0 / 7;
    p = p * s2 - 1.0 / 5;
    p = p * s2 + 1.0 / 3;
    const v4d base = { tab[k[0] <= 8 ? k[0] : 0], tab[k[1] <= 8 ? k[1] : 0],
                       tab[k[2] <= 8 ? k[2] : 0], tab[k[3] <= 8 ? k[3] : 0] };
    v4d a = base + (s - s * s2 * p);
    const v4d comp = (1.5707963267948966 - a) + 6.123233995736766e-17;
    v_sel(&a, &swap, &comp, &a);
    const v4d back = (3.141592653589793 - a) + 1.2246467991473532e-16;
    const v4di xneg = *x < 0.0;
    v_sel(&a, &xneg, &back, &a);
    const v4d neg = -a;
    const v4di yneg = *y < 0.0;
    v_sel(o, &yneg, &neg, &a);
}

/* sin x and cos x for |x| <= 1.6, by their Taylor series to x^23 and x^22
 * (the next terms below 1.1e-18 and 1.5e-17 at 1.6). */
EF_INLINE void v_sincos(const v4d *x, v4d *sn, v4d *cs)
{
    const v4d x2 = *x * *x;
    v4d s = x2 * -3.868170170630684e-23 + 1.9572941063391263e-20;
    s = s * x2 - 8.22063524662433e-18;
    s = s * x2 + 2.8114572543455206e-15;
    s = s * x2 - 7.647163731819816e-13;
    s = s * x2 + 1.6059043836821613e-10;
    s = s * x2 - 2.505210838544172e-08;
    s = s * x2 + 2.7557319223985893e-06;
    s = s * x2 - 0.0001984126984126984;
    s = s * x2 + 0.008333333333333333;
    s = s * x2 - 0.16666666666666666;
    *sn = *x + *x * x2 * s;
    v4d c = x2 * 8.896791392450574e-22 - 4.110317623312165e-19;
    c = c * x2 + 1.5619206968586225e-16;
    c = c * x2 - 4.779477332387385e-14;
    c = c * x2 + 1.1470745597729725e-11;
    c = c * x2 - 2.08767569878681e-09;
    c = c * x2 + 2.755731922398589e-07;
    c = c * x2 - 2.48015873015873e-05;
    c = c * x2 + 0.001388888888888889;
    c = c * x2 - 0.041666666666666664;
    c = c * x2 + 0.5;
    *cs = 1.0 - x2 * c;
}

/* tan x for |x| <= pi/2 (the double nearest it included): sin x / cos x
 * up to pi/4, beyond cos w / sin w with w = pi/2 - |x| (exact by
 * Sterbenz's lemma from pi/2's double, its low part added), so the large
 * values near pi/2 keep their relative accuracy; a few ulp. */
EF_INLINE void v_tan(const v4d *x, v4d *o)
{
    v4d ax;
    v_abs(x, &ax);
    const v4di big = ax > 0.7853981633974483;
    const v4d w = (1.5707963267948966 - ax) + 6.123233995736766e-17;
    v4d a;
    v_sel(&a, &big, &w, &ax);
    v4d sn, cs;
    v_sincos(&a, &sn, &cs);
    const v4d tn = sn / cs, ct = cs / sn;
    v4d r;
    v_sel(&r, &big, &ct, &tn);
    const v4d neg = -r;
    const v4di xn = *x < 0.0;
    v_sel(o, &xn, &neg, &r);
}

#endif
