/* A fog scene: the components, fog colour and sky policy, and the per-pixel
 * evaluation and premultiplied compositing they imply. */
#ifndef EF_SCENE_H
#define EF_SCENE_H

#include "fog.h"

typedef enum ef_sky_mode { EF_SKY_FOG = 0, EF_SKY_KEEP, EF_SKY_DISTANCE_MODE } ef_sky_mode;

typedef struct ef_fog_scene {
    ef_fog_component comp[EF_FOG_MAX_COMPONENTS];
    int ncomp;
    double color[3];                 /* scene-linear fog colour F */
    ef_sky_mode sky;
    double sky_distance;             /* EF_SKY_DISTANCE_MODE: background at this distance */
} ef_fog_scene;

/* The documented default fog colour. */
#define EF_DEFAULT_FOG_COLOR_R 0.7
#define EF_DEFAULT_FOG_COLOR_G 0.75
#define EF_DEFAULT_FOG_COLOR_B 0.8

/* An empty scene with the default colour and --sky fog. */
void ef_scene_init(ef_fog_scene *s);

/* Parses a --sky value (fog | keep | distance=D). Returns 0 or -1. */
int ef_scene_parse_sky(ef_fog_scene *s, const char *text, ef_err *err);

/* Transmittance per channel to the surface (T) and to infinity along the same
 * ray (Tinf), T = exp(-sum of the components' optical depths). For a sky
 * ray (r->dist infinite) T == Tinf. Tinf may be NULL when the caller has no
 * use for it (an opaque pixel), which saves evaluating every component. */
void ef_scene_transmittance(const ef_fog_scene *s, const ef_ray *r,
                            double T[3], double Tinf[3]);

/* Premultiplied compositing of one pixel in place:
 *   rgb   = T rgb + (1 - T) a F + (1 - a)(1 - Tinf) F
 *   alpha = a + (1 - a)(1 - Tinf)
 * fog_uncovered == 0 drops the last term and leaves alpha alone (--sky keep).
 * alpha may be NULL (a = 1). */
void ef_composite(const double T[3], const double Tinf[3], const double F[3],
                  int fog_uncovered, double rgb[3], double *alpha);

#endif
