/* Chapman's grazing-incidence function for a sun over a planet: the
 * optical depth of an exponential atmosphere (scale height H) along a
 * straight ray from radius r to infinity, relative to the vertical one,
 *
 *   Ch(X, mu) = int_0^inf exp(X - sqrt(X^2 + s^2 + 2 X s mu)) ds,
 *
 * X = r / H, mu the cosine of the ray's zenith angle at r, s in units of
 * H. Ch(X, 1) = 1; Ch(X, mu) -> 1 / mu as X -> inf (the flat model);
 * Ch(X, 0) ~ sqrt(pi X / 2). Pure C, no I/O. */
#ifndef EF_CHAPMAN_H
#define EF_CHAPMAN_H

/* Ch(X, mu) for X > 0 and mu in [-1, 1], to about 1e-14 relative; +inf
 * where it overflows (a ray far below the horizon). For mu < 0 the ray
 * passes its tangent point r sqrt(1 - mu^2) (whether the planet's surface
 * is there is the caller's question): Ch(X, mu) = 2 e^(X (1 - sin chi))
 * Ch(X sin chi, 0) - Ch(X, -mu). For mu >= 0 an adaptive Gauss-Kronrod
 * quadrature of int_0^inf 2 v e^(-v^2) g(v^2) dv, f = v^2 the exponent's
 * rise along the ray, g = ds/df = (X + f) / sqrt((X mu)^2 + f (2X + f))
 * (smooth in v, with a bend at v ~ mu sqrt(X / 2) that is a cut). */
double ef_chapman(double X, double mu);

#endif
