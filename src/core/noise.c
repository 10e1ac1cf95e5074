/* Perlin's Improved Noise and the fractal sum; see noise.h. Every
 * expression follows the reference's order of operations, and the build
 * turns off floating-point contraction for this file, so the bits match
 * the Java reference on every platform with binary64 arithmetic. */
#include "noise.h"

#include <math.h>

/* Perlin's permutation (noise.h). */
#define EF_NOISE_ID(v) v,
const unsigned char ef_noise_perm[256] = { EF_NOISE_PERM(EF_NOISE_ID) };
#undef EF_NOISE_ID

const double ef_fbm_offset[3] = { 31.416, 27.183, 14.142 };
const double ef_noise_seed_dir[3] = { 12.9898, 78.233, 37.719 };

void ef_noise_split(double v, int64_t *cell, double *frac)
{
    const double f = floor(v);
    *frac = v - f;
    /* floor(v) & 255 for every finite v: exact below 2^62, and past it
     * every double is a multiple of 256. */
    if (fabs(f) < 0x1p62)
        *cell = (int64_t) f & 255;
    else
        *cell = 0;
}

double ef_noise3(double x, double y, double z)
{
    int64_t X, Y, Z;
    double fx, fy, fz;
    ef_noise_split(x, &X, &fx);
    ef_noise_split(y, &Y, &fy);
    ef_noise_split(z, &Z, &fz);
    ef_noise_cell c;
    ef_noise_cell_at(X, Y, Z, &c);
    return ef_noise_cell_eval(&c, fx, fy, fz);
}

void ef_fbm_init(ef_fbm *f, int octaves, double lacunarity, double gain)
{
    f->octaves = octaves < 1 ? 1 : octaves > EF_FBM_MAX_OCTAVES ? EF_FBM_MAX_OCTAVES : octaves;
    f->lacunarity = lacunarity;
    f->gain = gain;
    double fr = 1, a = 1, norm = 0;
    for (int i = 0; i < f->octaves; ++i) {
        f->freq[i] = fr;
        f->amp[i] = a;
        norm += a;
        fr *= lacunarity;
        a *= gain;
    }
    f->norm = norm;
    for (int i = 0; i < f->octaves; ++i)
        f->weight[i] = f->amp[i] / norm;
}

void ef_fbm_octave_point(const ef_fbm *f, int i, const double q[3], double u[3])
{
    for (int k = 0; k < 3; ++k)
        u[k] = f->freq[i] * q[k] + (double) i * ef_fbm_offset[k];
}

double ef_fbm_eval(const ef_fbm *f, const double q[3])
{
    double sum = 0;
    for (int i = 0; i < f->octaves; ++i) {
        double u[3];
        ef_fbm_octave_point(f, i, q, u);
        sum += f->amp[i] * ef_noise3(u[0], u[1], u[2]);
    }
    return sum / f->norm;
}
