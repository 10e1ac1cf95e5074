/* Ken Perlin's Improved Noise (SIGGRAPH 2002, with his 2003 gradient fix)
 * and the fractal sum exrfog builds its heterogeneous fog from. Both are a
 * public contract: an implementation in any language that follows the
 * reference (his permutation, fade 6t^5-15t^4+10t^3, gradients, lerp
 * a + t(b - a) in his nesting order, binary64 without fused multiply-adds)
 * reproduces these values bit for bit. noise.c is built with
 * -ffp-contract=off for that reason. */
#ifndef EF_NOISE_H
#define EF_NOISE_H

#include <stdint.h>

/* Perlin's noise at (x, y, z): 0 at every lattice point, period 256 in each
 * axis, |noise| <= EF_NOISE_BOUND. The cell index is floor(x) & 255, taken
 * exactly for every finite x (Java's int cast would saturate past 2^31). */
double ef_noise3(double x, double y, double z);

/* The eight corner hashes of one lattice cell (indices & 255). */
typedef struct ef_noise_cell {
    unsigned char h[8];    /* AA, BA, AB, BB, AA+1, BA+1, AB+1, BB+1 */
} ef_noise_cell;

/* Perlin's permutation (his reference replicates it to 512 entries so that
 * p[A + 1] needs no mask; indexing with & 255 reads the same values). */
extern const unsigned char ef_noise_perm[256];

/* The corners of the cell whose lower corner is (X, Y, Z) & 255. Inline:
 * the integrators hash every lattice cell they walk. */
static inline void ef_noise_cell_at(int64_t X, int64_t Y, int64_t Z, ef_noise_cell *c)
{
    const unsigned char *p = ef_noise_perm;
    const int x = (int) (X & 255), y = (int) (Y & 255), z = (int) (Z & 255);
    const int A = p[x] + y, AA = p[A & 255] + z, AB = p[(A + 1) & 255] + z;
    const int B = p[(x + 1) & 255] + y, BA = p[B & 255] + z, BB = p[(B + 1) & 255] + z;
    c->h[0] = p[AA & 255];
    c->h[1] = p[BA & 255];
    c->h[2] = p[AB & 255];
    c->h[3] = p[BB & 255];
    c->h[4] = p[(AA + 1) & 255];
    c->h[5] = p[(BA + 1) & 255];
    c->h[6] = p[(AB + 1) & 255];
    c->h[7] = p[(BB + 1) & 255];
}

/* Noise inside cell c at fractions (x, y, z) in [0, 1]: the same operations
 * as ef_noise3 after its floor, so ef_noise3 equals it bit for bit (in files
 * built with -ffp-contract=off). Inside a cell the noise is a polynomial
 * (degree 16 along any line). Inline: the integrators call it per node. */
static inline double ef_noise_fade_(double t)
{
    return t * t * t * (t * (t * 6 - 15) + 10);
}

static inline double ef_noise_lerp_(double t, double a, double b)
{
    return a + t * (b - a);
}

static inline double ef_noise_grad_(int hash, double x, double y, double z)
{
    const int h = hash & 15;
    const double u = h < 8 ? x : y;
    const double v = h < 4 ? y : (h == 12 || h == 14 ? x : z);
    return ((h & 1) == 0 ? u : -u) + ((h & 2) == 0 ? v : -v);
}

static inline double ef_noise_cell_eval(const ef_noise_cell *c, double x, double y, double z)
{
    const double u = ef_noise_fade_(x), v = ef_noise_fade_(y), w = ef_noise_fade_(z);
    const unsigned char *h = c->h;
    return ef_noise_lerp_(
        w,
        ef_noise_lerp_(v,
                       ef_noise_lerp_(u, ef_noise_grad_(h[0], x, y, z),
                                      ef_noise_grad_(h[1], x - 1, y, z)),
                       ef_noise_lerp_(u, ef_noise_grad_(h[2], x, y - 1, z),
                                      ef_noise_grad_(h[3], x - 1, y - 1, z))),
        ef_noise_lerp_(v,
                       ef_noise_lerp_(u, ef_noise_grad_(h[4], x, y, z - 1),
                                      ef_noise_grad_(h[5], x - 1, y, z - 1)),
                       ef_noise_lerp_(u, ef_noise_grad_(h[6], x, y - 1, z - 1),
                                      ef_noise_grad_(h[7], x - 1, y - 1, z - 1))));
}

/* The cell index (floor(v) & 255) and fraction v - floor(v), as ef_noise3
 * takes them. */
void ef_noise_split(double v, int64_t *cell, double *frac);

/* max |noise| over all gradient assignments (Perlin's 12 directions), the
 * bound every rigorous estimate here uses; its Lipschitz constant per
 * lattice unit; and max |d2 noise/ds2| along a unit direction. */
#define EF_NOISE_BOUND 1.0363538
#define EF_NOISE_LIPSCHITZ 3.75
#define EF_NOISE_CURVATURE 14.5

#define EF_FBM_MAX_OCTAVES 16

/* The fractal sum fbm(q) = sum_i g^i noise3(l^i q + i O) / sum_i g^i,
 * O = (31.416, 27.183, 14.142). freq[i] = l^i and weight[i] = g^i / sum g^j
 * are formed by repeated multiplication (freq[0] = 1, freq[i+1] = freq[i] l),
 * then the sum of g^i n_i is divided by the sum of g^i, in order i = 0.. */
typedef struct ef_fbm {
    int octaves;                         /* 1..EF_FBM_MAX_OCTAVES */
    double lacunarity, gain;
    double freq[EF_FBM_MAX_OCTAVES];     /* l^i */
    double amp[EF_FBM_MAX_OCTAVES];      /* g^i */
    double norm;                         /* sum g^i */
    double weight[EF_FBM_MAX_OCTAVES];   /* g^i / norm, for the integrators */
} ef_fbm;

/* The per-octave offset O. */
extern const double ef_fbm_offset[3];
/* The seed direction S of q = (p - offset - velocity t) / scale + seed S. */
extern const double ef_noise_seed_dir[3];

/* Fills f for octaves in 1..16, lacunarity > 1, gain > 0. */
void ef_fbm_init(ef_fbm *f, int octaves, double lacunarity, double gain);

/* fbm(q) as defined above; |fbm| <= EF_NOISE_BOUND. */
double ef_fbm_eval(const ef_fbm *f, const double q[3]);

/* Octave i's noise coordinates of q: l^i q + i O (the contract's order). */
void ef_fbm_octave_point(const ef_fbm *f, int i, const double q[3], double u[3]);

#endif
