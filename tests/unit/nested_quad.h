/* Nested adaptive quadrature for the tests' independent references
 * (test_ms, test_lms): Gauss-Kronrod 7/15 bisected to an absolute
 * tolerance, or to one relative to a first rule's size, and the exact
 * Henyey-Greenstein phase. Deliberately not the library's integrators. */
#ifndef EF_TEST_NESTED_QUAD_H
#define EF_TEST_NESTED_QUAD_H

#include <math.h>

#include "gk15.h"

#ifndef PI
#define PI 3.14159265358979323846
#endif

static inline double hg(double g, double c)
{
    const double q = 1 + g * g - 2 * g * c;
    return (1 - g * g) / (4 * PI * q * sqrt(q));
}

typedef double (*fn1)(void *, double);

static inline double gk15(fn1 f, void *u, double a, double b, double *err)
{
    const double c = 0.5 * (a + b), h = 0.5 * (b - a), fc = f(u, c);
    double rk = fc * (double) ef_gk15_wk[7], rg = fc * (double) ef_gk15_wg[3];
    for (int j = 0; j < 7; ++j) {
        const double x = h * (double) ef_gk15_x[j], f1 = f(u, c - x), f2 = f(u, c + x);
        rk += (f1 + f2) * (double) ef_gk15_wk[j];
        if (j & 1)
            rg += (f1 + f2) * (double) ef_gk15_wg[j / 2];
    }
    *err = fabs((rk - rg) * h);
    return rk * h;
}

/* int_a^b f, bisected until each piece's estimate is within its share of
 * tol (or maxdepth levels deep). */
static inline double adapt_to(fn1 f, void *u, double a, double b, double tol, int depth,
                              int maxdepth)
{
    double e;
    const double r = gk15(f, u, a, b, &e);
    if (e <= tol || depth > maxdepth || !(e == e))
        return r;
    const double m = 0.5 * (a + b);
    return adapt_to(f, u, a, m, tol / 2, depth + 1, maxdepth) +
           adapt_to(f, u, m, b, tol / 2, depth + 1, maxdepth);
}

/* adapt_to, 30 levels at most. */
static inline double adapt(fn1 f, void *u, double a, double b, double tol, int depth)
{
    return adapt_to(f, u, a, b, tol, depth, 30);
}

/* int_a^b f to about rel of itself (the tolerance from a first rule's
 * size: integrands that span many orders of magnitude), 24 levels at most
 * (the lamp's integrands, nested three deep, would otherwise spend minutes
 * under the sanitizers where a piece cannot meet its share). */
static inline double adapt_rel(fn1 f, void *u, double a, double b, double rel)
{
    double e;
    const double r = gk15(f, u, a, b, &e);
    return adapt_to(f, u, a, b, rel * fabs(r) + 1e-300, 0, 24);
}

#endif
