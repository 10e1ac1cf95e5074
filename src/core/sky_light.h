/* Sky light for lit fog (--sky-light ENV.exr): a lat-long environment's
 * single scattering in the fog, added per view direction, unshadowed.
 *
 * For a component c the light it scatters towards the camera from the
 * environment L is
 *   S_c = albedo_c C_c(u) int_0^D T(0,t) sigma_c(x) dt,
 *   C_c(u) = int_sphere p_c(l . u) L(l) dl,
 * the environment convolved with the component's phase function, seen in
 * the view direction u. The environment's light is taken to reach every
 * point of the fog unattenuated (the sky dome over a layer of fog, as the
 * issue defines it: no shadows, no extinction on the way in), so the
 * integral along the view ray is the component's share of 1 - T: exactly
 * 1 - T for one component, the optical-depth-weighted share for several
 * (exact when their densities are proportional along the ray, as the
 * ambient colours are mixed).
 *
 * Orientation: pixel (x, y) of a W x H map (rows top-down) is the
 * direction of polar angle theta = pi (y + 0.5) / H from the scene's up
 * axis and azimuth phi = pi - 2 pi (x + 0.5) / W + rotate, d = sin(theta)
 * (cos(phi) e1 + sin(phi) e2) + cos(theta) up, with e1 the world axis most
 * across up (x for a y- or z-up scene) and e2 = up x e1. For a z-up scene
 * this is Cycles' equirectangular environment (the image centre looks
 * along +X, up at the top); for a y-up scene the same picture with
 * Blender's -Y as +Z.
 *
 * The convolution runs on a grid of the map averaged down to 2N x N texels
 * (N from the phase's sharpness: 3 pi / N at most 1.35 (1 - |g|), from 64
 * to 256; 1 x 1 for iso, the mean): for each pair of rows the
 * phase depends on the azimuth difference only, so each output row is a
 * sum of circular convolutions, done by FFT. Lookups are bilinear. Pure
 * C, no I/O. */
#ifndef EF_SKY_LIGHT_H
#define EF_SKY_LIGHT_H

#include "error.h"

#include <stdatomic.h>

/* The most distinct (phase, g) pairs a scene's components may have. */
#define EF_SKY_MAX_PHASES 32   /* as many as a scene has components */

/* An environment as read: W x H RGB, rows top-down, scene-linear. */
typedef struct ef_env_src {
    const char *path;
    int w, h;
    const float *rgb[3];      /* the whole map's planes, or NULL: */
    /* row y (0 = top) of each channel into out[c][0..w), front to back
     * once each (a reader that streams the file); returns 0 or -1 */
    int (*row)(void *user, int y, float *const out[3]);
    void *user;
} ef_env_src;

/* One phase function's convolved environment. */
typedef struct ef_sky_conv {
    int phase;
    double g;
    int w, h;                 /* grid: 2N x N (1 x 1 for iso) */
    float *c[3];              /* C per channel, rows top-down */
} ef_sky_conv;

typedef struct ef_sky_light {
    _Atomic int refs;
    char path[256];
    double rotate;            /* radians, about up */
    double intensity;
    int src_w, src_h;
    int nconv;
    ef_sky_conv conv[EF_SKY_MAX_PHASES];
    /* the environment itself averaged to EF_SKY_ENV_W x EF_SKY_ENV_H texels
     * per channel (rows top-down, as the map), for multiple scattering's
     * solve (ms.h) */
    float *env[3];
    char aov[3][80];          /* fog_light.sky.R/G/B */
} ef_sky_light;

#define EF_SKY_ENV_W 256
#define EF_SKY_ENV_H 128

/* The environment's frame about up: e1 the world axis most across up,
 * e2 = up x e1 (the orientation above). */
void ef_sky_frame(const double up[3], double e1[3], double e2[3]);

/* The environment's radiance per channel towards direction d (unit; the
 * light arrives from d), times the intensity: bilinear in the averaged
 * grid. */
void ef_sky_light_env(const ef_sky_light *k, const double up[3], const double d[3],
                      double out[3]);

/* Builds the sky light from src for the phase functions phases[i], g[i]
 * (n of them, at most EF_SKY_MAX_PHASES). Returns it (one reference), or
 * NULL with a message. */
ef_sky_light *ef_sky_light_build(const ef_env_src *src, double rotate_deg, double intensity,
                                 const int *phases, const double *g, int n, ef_err *err);

void ef_sky_light_ref(ef_sky_light *k);
void ef_sky_light_unref(ef_sky_light *k);

/* C(u) (intensity included) for the phase (phase, g) in the view
 * direction u (unit, world), with up the scene's up axis (unit). Returns 0
 * and zeros when that phase was not built. */
int ef_sky_light_eval(const ef_sky_light *k, int phase, double g, const double up[3],
                      const double u[3], double out[3]);

/* The direction of grid point (x + 0.5, y + 0.5) of a w x h lat-long map
 * (the orientation above). */
void ef_sky_light_dir(const ef_sky_light *k, const double up[3], double x, double y, int w, int h,
                      double d[3]);

#endif
