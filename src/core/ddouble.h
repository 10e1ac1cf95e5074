/* Double-double arithmetic (fma-based error-free transformations) and
 * the per-pixel dispatch macros: what exact.h's functionals and fog.c's
 * camera binding build on, with no fog type in it (so fog.c, which
 * implements fog.h, needs nothing that includes fog.h). */
#ifndef EF_DDOUBLE_H
#define EF_DDOUBLE_H

#include <math.h>

/* Marks a per-pixel function for runtime dispatch: GCC on x86-64 Linux
 * builds it twice, for the baseline ISA and for x86-64-v3 (AVX2, FMA), and
 * the loader picks one per CPU. The results are the same bits: fma() is
 * correctly rounded in libm and in hardware, and strict C11 contracts no
 * other a*b+c (no -ffp-contract=fast). What buys is fma() without a libm
 * call and wider vectors. */
/* (Not under ThreadSanitizer: its instrumented ifunc resolvers would run
 * before its runtime is up.) */
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && \
    !defined(__SANITIZE_THREAD__)
#define EF_MULTIVERSION __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define EF_MULTIVERSION
#endif

/* A helper of a per-pixel function, inlined into it (and so compiled for
 * each of its targets): a call from one multiversioned function to another
 * goes through the dispatcher and is never inlined. */
#if defined(__GNUC__)
#define EF_INLINE static inline __attribute__((always_inline))
#else
#define EF_INLINE static inline
#endif

/* fmax and fmin as glibc computes them on x86-64 (the first argument on a
 * tie, so -0 against +0 too; the other one where one is NaN), inline: the
 * library calls cost more than the per-pixel work around them. */
EF_INLINE double ef_fmax(double a, double b)
{
    return (a >= b || b != b) ? a : b;
}

EF_INLINE double ef_fmin(double a, double b)
{
    return (a <= b || b != b) ? a : b;
}

/* An unevaluated sum hi + lo, |lo| <= ulp(hi)/2. */
typedef struct ef_dd {
    double hi, lo;
} ef_dd;

static inline ef_dd ef_two_sum(double a, double b)
{
    const double s = a + b, bb = s - a;
    return (ef_dd) { s, (a - (s - bb)) + (b - bb) };
}

static inline ef_dd ef_two_prod(double a, double b)
{
    const double p = a * b;
    return (ef_dd) { p, fma(a, b, -p) };
}

static inline ef_dd ef_dd_add(ef_dd a, ef_dd b)
{
    ef_dd s = ef_two_sum(a.hi, b.hi);
    s.lo += a.lo + b.lo;
    return ef_two_sum(s.hi, s.lo);
}

/* a.b + d, accurate to about 2^-104 relative to the largest term. */
static inline ef_dd ef_dd_dot3(const double a[3], const double b[3], double d)
{
    ef_dd s = ef_dd_add(ef_two_prod(a[0], b[0]), ef_two_prod(a[1], b[1]));
    s = ef_dd_add(s, ef_two_prod(a[2], b[2]));
    return ef_dd_add(s, (ef_dd) { d, 0.0 });
}

/* h + s * t for a double-double h and s. */
static inline ef_dd ef_dd_affine(ef_dd h, ef_dd s, double t)
{
    ef_dd p = ef_two_prod(s.hi, t);
    p.lo += s.lo * t;
    return ef_dd_add(h, p);
}

#endif
