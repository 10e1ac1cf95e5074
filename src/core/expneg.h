/* e^-x for the transmittance T = e^-tau, written out so that a loop over
 * pixels vectorises (glibc's exp is a call per pixel, a quarter of the
 * exp model's fog pass). Within 1 ulp of e^-x (the tests compare it with
 * expl on 10^6 values); the same operations wherever it is compiled
 * (no FMA: the files that use it are built without contraction, -std=c11),
 * so the per-pixel and the span-wise paths give the same bits. */
#ifndef EF_EXPNEG_H
#define EF_EXPNEG_H

#include <stdint.h>
#include <string.h>

/* e^-x: 1 at 0, 0 from x >= 746 and at +inf, NaN for NaN; every x
 * (negative too, up to e^709). Branch-free. */
static inline double ef_exp_neg(double x)
{
    /* Cody and Waite: y = k ln2 + r, |r| <= ln2 / 2, ln2 in two parts whose
     * first has trailing zeros so that k ln2_hi is exact. */
    const double ln2_hi = 0x1.62e42fee00000p-1, ln2_lo = 0x1.a39ef35793c76p-33;
    const double inv_ln2 = 0x1.71547652b82fep0, shifter = 0x1.8p52;
    double y = -x;
    y = y < -746.0 ? -746.0 : y;   /* NaN passes both */
    y = y > 709.0 ? 709.0 : y;
    const double t = y * inv_ln2 + shifter;   /* k in the low bits */
    const double kd = t - shifter;
    const double hi = y - kd * ln2_hi, lo = kd * ln2_lo, r = hi - lo;
    /* fdlibm's rational form: e^r = 1 + 2r / (R(r^2) - r) written as
     * 1 - ((lo - r c / (2 - c)) - hi), c = r - r^2 P(r^2), P its Remez
     * polynomial (error below 2^-59 on |r| <= 0.3466) */
    const double P1 = 1.66666666666666019037e-01, P2 = -2.77777777770155933842e-03,
                 P3 = 6.61375632143793436117e-05, P4 = -1.65339022054652515390e-06,
                 P5 = 4.13813679705723846039e-08;
    const double t2 = r * r;
    const double c = r - t2 * (P1 + t2 * (P2 + t2 * (P3 + t2 * (P4 + t2 * P5))));
    const double p = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi);
    /* times 2^k in two exact halves, so that a subnormal result rounds once */
    uint64_t bits;
    memcpy(&bits, &t, sizeof bits);
    const int64_t k = (int64_t) (int32_t) (uint32_t) bits;
    const int64_t k1 = k >> 1, k2 = k - k1;
    const uint64_t b1 = (uint64_t) (k1 + 1023) << 52, b2 = (uint64_t) (k2 + 1023) << 52;
    double s1, s2;
    memcpy(&s1, &b1, sizeof s1);
    memcpy(&s2, &b2, sizeof s2);
    return p * s1 * s2;
}

#endif
