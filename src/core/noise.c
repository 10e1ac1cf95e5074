/* Perlin's Improved Noise and the fractal sum; see noise.h. Every
 * expression follows the reference's order of operations, and the build
 * turns off floating-point contraction for this file, so the bits match
 * the Java reference on every platform with binary64 arithmetic. */
#include "noise.h"

#include <math.h>

/* Perlin's permutation (noise.h). */
const unsigned char ef_noise_perm[256] = {
    151, 160, 137, 91, 90, 15, 131, 13, 201, 95, 96, 53, 194, 233, 7, 225, 140, 36, 103, 30,
    69, 142, 8, 99, 37, 240, 21, 10, 23, 190, 6, 148, 247, 120, 234, 75, 0, 26, 197, 62, 94,
    252, 219, 203, 117, 35, 11, 32, 57, 177, 33, 88, 237, 149, 56, 87, 174, 20, 125, 136, 171,
    168, 68, 175, 74, 165, 71, 134, 139, 48, 27, 166, 77, 146, 158, 231, 83, 111, 229, 122, 60,
    211, 133, 230, 220, 105, 92, 41, 55, 46, 245, 40, 244, 102, 143, 54, 65, 25, 63, 161, 1,
    216, 80, 73, 209, 76, 132, 187, 208, 89, 18, 169, 200, 196, 135, 130, 116, 188, 159, 86,
    164, 100, 109, 198, 173, 186, 3, 64, 52, 217, 226, 250, 124, 123, 5, 202, 38, 147, 118,
    126, 255, 82, 85, 212, 207, 206, 59, 227, 47, 16, 58, 17, 182, 189, 28, 42, 223, 183, 170,
    213, 119, 248, 152, 2, 44, 154, 163, 70, 221, 153, 101, 155, 167, 43, 172, 9, 129, 22, 39,
    253, 19, 98, 108, 110, 79, 113, 224, 232, 178, 185, 112, 104, 218, 246, 97, 228, 251, 34,
    242, 193, 238, 210, 144, 12, 191, 179, 162, 241, 81, 51, 145, 235, 249, 14, 239, 107, 49,
    192, 214, 31, 181, 199, 106, 157, 184, 84, 204, 176, 115, 121, 50, 45, 127, 4, 150, 254,
    138, 236, 205, 93, 222, 114, 67, 29, 24, 72, 243, 141, 128, 195, 78, 66, 215, 61, 156, 180
};

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
