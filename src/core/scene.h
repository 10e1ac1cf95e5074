/* A fog scene: the components, fog colour and sky policy, and the per-pixel
 * evaluation and premultiplied compositing they imply. */
#ifndef EF_SCENE_H
#define EF_SCENE_H

#include "fog.h"
#include "light.h"

#include <math.h>

typedef enum ef_sky_mode { EF_SKY_FOG = 0, EF_SKY_KEEP, EF_SKY_DISTANCE_MODE } ef_sky_mode;

typedef struct ef_fog_scene {
    ef_fog_component comp[EF_FOG_MAX_COMPONENTS];
    int ncomp;
    int any_color;                   /* some component carries its own color= */
    double color[3];                 /* scene-linear fog colour F */
    ef_fog_context ctx;              /* up axis and units the components were finished with */
    ef_sky_mode sky;
    double sky_distance;             /* EF_SKY_DISTANCE_MODE: background at this distance */
    ef_light light[EF_MAX_LIGHTS];   /* --light, in order (lit.h) */
    int nlight;
    /* --sky-light (sky_light.h; shared, counted like the shadow maps), or
     * NULL, and its SPEC */
    struct ef_sky_light *sky_light;
    char sky_light_spec[512];
    /* --sky-light ...:scattering=multiple[:ground=H]: the sky's light
     * carried through the fog, every order (ms.h), in place of its
     * unattenuated single scattering; sky_ms its solve (shared, counted),
     * built by ef_scene_prepare_lights, and bound to the camera */
    int sky_multiple, sky_has_ground;
    double sky_ground;
    struct ef_ms *sky_ms;
    ef_ms_view sky_ms_view;
} ef_fog_scene;

/* The documented default fog colour. */
#define EF_DEFAULT_FOG_COLOR_R 0.7
#define EF_DEFAULT_FOG_COLOR_G 0.75
#define EF_DEFAULT_FOG_COLOR_B 0.8

/* An empty scene with the default colour, --sky fog, up +y, 1 unit/metre. */
void ef_scene_init(ef_fog_scene *s);

/* Parses SPEC with the scene's context and appends it. Returns 0 or -1. */
int ef_scene_add(ef_fog_scene *s, const char *spec, ef_err *err);

/* Parses a --light SPEC with the scene's context and appends it (the
 * components are checked for a density in space when the frame starts:
 * ef_lights_check). Returns 0 or -1. */
int ef_scene_add_light(ef_fog_scene *s, const char *spec, ef_err *err);

/* Reads --sky-light FILE.exr[:rotate=DEG][:intensity=K] through the
 * context's load_sky, convolved with the phase functions of the
 * components already added (add the components first). Returns 0, or -1
 * with a message (err->file naming the map when it is at fault). */
int ef_scene_set_sky_light(ef_fog_scene *s, const char *spec, ef_err *err);

/* Solves what the lights need from the whole scene once its components
 * are final: the multiple scattering of each scattering=multiple sun and
 * of a scattering=multiple sky light (ms.h). Call again after the
 * components change. Returns 0, or -1 with a message (a component the
 * solve does not take). */
int ef_scene_prepare_lights(ef_fog_scene *s, ef_err *err);

/* Whether the scene has any light (--light or --sky-light). */
static inline int ef_scene_lit(const ef_fog_scene *s)
{
    return s->nlight > 0 || s->sky_light != NULL;
}

/* Binds every component to the camera at org (ef_fog_bind): once per
 * frame, before the threads start. */
void ef_scene_bind(ef_fog_scene *s, const double org[3]);

struct ef_camera;
/* ef_scene_bind at the camera's position, with its pixel footprint
 * (ef_camera_pixel_spread) given to every component first. */
void ef_scene_bind_camera(ef_fog_scene *s, const struct ef_camera *cam);

/* Copies src's settings and components into dst without parsing or reading
 * anything (component data is duplicated); with_spec 0 leaves the SPEC
 * texts empty, for a copy that is only evaluated. Returns 0, or -1 when out
 * of memory (dst is then empty). */
int ef_scene_copy(ef_fog_scene *dst, const ef_fog_scene *src, int with_spec);

/* Points every component at the host's stop flag (ef_fog_component.cancel;
 * NULL: none). */
void ef_scene_set_cancel(ef_fog_scene *s, const _Atomic int *cancel);

/* Releases the components' data; the scene is empty afterwards. */
void ef_scene_free(ef_fog_scene *s);

/* What the fog does to one segment: transmittance per channel and the
 * colour it scatters in. F is the scene colour, or, when components carry
 * their own, the optical-depth-weighted mean of their colours (exact when
 * the components' densities are proportional along the segment). */
typedef struct ef_fog_sample {
    double T[3], F[3];
} ef_fog_sample;

/* Parses a --sky value (fog | keep | distance=D). Returns 0 or -1. */
int ef_scene_parse_sky(ef_fog_scene *s, const char *text, ef_err *err);

/* The fog to the surface (surf) and to infinity along the same ray (inf),
 * T = exp(-sum of the components' optical depths). For a sky ray
 * (r->dist infinite) both are equal. inf may be NULL when the caller has no
 * use for it (an opaque pixel), which saves evaluating every component. */
void ef_scene_eval(const ef_fog_scene *s, const ef_ray *r, ef_fog_sample *surf,
                   ef_fog_sample *inf);

/* ef_scene_eval that also reports, in info[i] for each component i (info
 * may be NULL), the error and cost of its optical depth on the surface
 * segment (ef_fog_tau; zero for the closed forms). The far segment's
 * evaluation is not reported unless it is the surface segment (sky). */
void ef_scene_eval_info(const ef_fog_scene *s, const ef_ray *r, ef_fog_sample *surf,
                        ef_fog_sample *inf, ef_tau_info *info);

/* The far segment of r's pixel: to infinity, or with --sky distance=D to
 * D (or r's own end when farther). Returns 1 when it is r itself. */
int ef_scene_far_ray(const ef_fog_scene *s, const ef_ray *r, ef_ray *far);

/* out[j] = the fog along r[j] for j < n, the same bits as ef_scene_eval
 * gives for one segment (inf NULL), evaluated component by component over
 * all n rays. */
void ef_scene_eval_rays(const ef_fog_scene *s, const ef_ray *r, int n, ef_fog_sample *out);

/* Premultiplied compositing of one pixel in place:
 *   rgb   = T rgb + (1 - T) a F + (1 - a)(1 - Tinf) Finf
 *   alpha = a + (1 - a)(1 - Tinf)
 * fog_uncovered == 0 drops the last term and leaves alpha alone (--sky keep).
 * alpha may be NULL (a = 1). */
static inline void ef_composite(const ef_fog_sample *surf, const ef_fog_sample *inf, int fog_uncovered,
                                double rgb[3], double *alpha)
{
    const double a = alpha ? *alpha : 1.0;
    const double *T = surf->T, *Tinf = inf->T;
    for (int k = 0; k < 3; ++k) {
        /* T = 0 hides the surface entirely, even an infinite or NaN one. */
        rgb[k] = (T[k] > 0.0 ? T[k] * rgb[k] : 0.0) + (1.0 - T[k]) * a * surf->F[k];
        if (fog_uncovered)
            rgb[k] += (1.0 - a) * (1.0 - Tinf[k]) * inf->F[k];
    }
    if (alpha && fog_uncovered) {
        /* One alpha for three channels: the mean coverage of the fog behind. */
        const double cover = (3.0 - Tinf[0] - Tinf[1] - Tinf[2]) / 3.0;
        *alpha = a + (1.0 - a) * cover;
    }
}

#endif
