/* The clamp's statistics for the noise model's fast path: for the fractal
 * sum's octaves j..N-1 (the ones too fine to resolve on a stretch of ray),
 * X_j = sum_{i >= j} w_i noise_i, the stop-loss transforms
 *
 *   m_j(y) = E[max(0, X_j - y)],  v_j(y) = E[max(0, X_j - y)^2],
 *
 * which give the expected clamp max(0, -(1 + c fbm)) where the coarse
 * octaves are known and the fine ones are not. The octaves are taken as
 * independent (different frequencies and offsets: the sampled correlation
 * between neighbouring octaves' values is below 0.01), each with the
 * distribution of Perlin's noise itself, sampled once at 2^16 fixed
 * points (each value also taken with its sign turned: the distribution is
 * symmetric but for sampling noise), and convolved on a grid of 2^-10 of
 * the noise bound. Plain
 * doubles, so the component's arr holds them. Pure: no I/O, no globals. */
#ifndef EF_NOISE_CLAMP_H
#define EF_NOISE_CLAMP_H

#include <stddef.h>

#include "noise.h"

/* Points per table (the y grid over [0, ymax_j]). */
#define EF_CLAMP_POINTS 256

/* The doubles the tables of an fbm with this many octaves take. */
size_t ef_clamp_tables_size(int octaves);

/* Fills tab (ef_clamp_tables_size(f->octaves) doubles) for f. Returns 0,
 * or -1 when memory for the work arrays runs out. */
int ef_clamp_tables_build(const ef_fbm *f, double *tab);

/* m_j(y) and v_j(y) (into *v) from the tables, for any real y (the
 * symmetry of X_j gives y < 0); j == octaves: X is 0 (every octave
 * resolved), m = max(0, -y). */
double ef_clamp_m(const double *tab, int octaves, int j, double y, double *v);

/* The largest value X_j takes in the tables (0 for j == octaves). */
double ef_clamp_ymax(const double *tab, int octaves, int j);

/* Var X_j (0 for j == octaves). */
double ef_clamp_var(const double *tab, int octaves, int j);

#endif
