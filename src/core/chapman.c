/* Chapman's function by quadrature (chapman.h). */
#include "chapman.h"

#include "gk15.h"

#include <math.h>

/* The integrand 2 v e^(-v^2) g(v^2), g = ds/df, with v divided into the
 * root (no 0/0 at v = 0 when mu = 0). */
static double integrand(double X, double Xmu, double v)
{
    const double f = v * v;
    if (v == 0)
        return Xmu == 0 ? 2 * X / sqrt(2 * X) : 0;
    const double r = Xmu / v;
    return 2 * exp(-f) * (X + f) / sqrt(r * r + 2 * X + f);
}

/* One Kronrod rule over [a, b]: the result, and |Kronrod - Gauss| in *e. */
static double gk(double X, double Xmu, double a, double b, double *e)
{
    const double c = 0.5 * (a + b), h = 0.5 * (b - a);
    const double f0 = integrand(X, Xmu, c);
    double K = (double) ef_gk15_wk[7] * f0, G = (double) ef_gk15_wg[3] * f0;
    for (int j = 0; j < 7; ++j) {
        const double dx = h * (double) ef_gk15_x[j];
        const double s = integrand(X, Xmu, c - dx) + integrand(X, Xmu, c + dx);
        K += (double) ef_gk15_wk[j] * s;
        if (j & 1)
            G += (double) ef_gk15_wg[j / 2] * s;
    }
    *e = fabs((K - G) * h);
    return K * h;
}

/* int_a^b by bisection until each piece's |K - G| is at most tol, or at
 * the rounding of its own result (depth bounded too: the integrand is
 * smooth, and the pieces' cuts hold its bend; a Kronrod rule whose Gauss
 * rule agrees to tol is far more accurate than tol). */
static double adapt(double X, double Xmu, double a, double b, double tol, int depth)
{
    double e;
    const double r = gk(X, Xmu, a, b, &e);
    if (e <= tol || e <= 0x1p-50 * fabs(r) || depth >= 24)
        return r;
    const double m = 0.5 * (a + b);
    return adapt(X, Xmu, a, m, tol, depth + 1) + adapt(X, Xmu, m, b, tol, depth + 1);
}

/* Ch for mu >= 0. */
static double chapman_up(double X, double mu)
{
    if (mu >= 1)
        return 1;
    const double Xmu = X * mu;
    /* v beyond 6.5: e^-42 of the rest, below the 1e-16 asked for; the
     * bend at vc = mu sqrt(X / 2) and its neighbours are cuts */
    const double vc = mu * sqrt(0.5 * X), V = 6.5;
    double cut[12];
    int n = 0;
    cut[n++] = 0;
    for (double s = vc / 64; s > 0 && s < V && n < 6; s *= 4)
        cut[n++] = s;
    for (int i = 0; i < 4; ++i) {
        const double fixed[4] = { 0.5, 1.5, 3, 4.5 };
        if (fixed[i] > cut[n - 1])
            cut[n++] = fixed[i];
    }
    cut[n++] = V;
    /* a first pass for the scale, then the pieces to 1e-15 of it */
    double total = 0, e;
    for (int i = 0; i + 1 < n; ++i)
        total += gk(X, Xmu, cut[i], cut[i + 1], &e);
    double sum = 0;
    const double tol = 1e-15 * fabs(total) / 16;
    for (int i = 0; i + 1 < n; ++i)
        sum += adapt(X, Xmu, cut[i], cut[i + 1], tol, 0);
    return sum;
}

double ef_chapman(double X, double mu)
{
    if (!(X > 0) || !(mu >= -1) || !(mu <= 1))
        return NAN;
    if (mu >= 0)
        return chapman_up(X, mu);
    /* below the horizon: twice the tangent point's horizontal ray, as dense
     * as the tangent point is, less the part behind r */
    const double s = sqrt((1 - mu) * (1 + mu));
    const double rise = X * (mu * mu / (1 + s));   /* X (1 - sin chi), no cancellation */
    if (rise > 700)
        return INFINITY;
    return 2 * exp(rise) * chapman_up(X * s, 0) - chapman_up(X, -mu);
}
