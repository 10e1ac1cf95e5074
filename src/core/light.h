/* Lit fog: single scattering of sun, point and spot lights in the scene's
 * own fog. For a view segment from the camera C along u over [0, D]:
 *
 *   S = sum_j int_0^D T(0,t) sum_c sigma_c(x) albedo_c p_c(l_j . u)
 *                    E_j(x) T_j(x) dt,            x = C + t u,
 *
 * T(0,t) the fog's transmittance along the view ray, T_j(x) from x towards
 * light j through the same fog, l_j the unit vector from x to the light and
 * p_c the component's phase function (phase=, g=). The pixel's composite
 * adds S to today's (ambient) term: out = T in + ambient + a S_surf +
 * (1 - a) S_far. Pure C, no I/O.
 *
 * Closed forms: the sun in one exponential height fog (Lengyel's and
 * Quilez's height fog lit with the sun's own attenuation), one half-space
 * (Lengyel's constant and linear, Walker's smooth) or one constant box or
 * convex volume; no light
 * at all from the sun in unbounded uniform fog (its light never arrives);
 * a point lamp of radius 0 in isotropic uniform fog (Sun et al. 2005, the
 * exponential integral of a complex argument in place of their table).
 * Other point and spot lamps in uniform (exp) fog: their equiangular
 * substitution, whose angular integral is evaluated directly by adaptive
 * Gauss-Kronrod, to 1e-13. Everything else: the same quadrature
 * of the formula above over the models' closed-form optical depths, split
 * at the densities' features and the spots' cone crossings, to 1e-10. */
#ifndef EF_LIGHT_H
#define EF_LIGHT_H

#include "fog.h"
#include "ms.h"
#include "shadow.h"

/* Chebyshev terms of a planet sun's table. */
#define EF_CH_TERMS 20
/* The most lights a scene holds. */
#define EF_MAX_LIGHTS 32

typedef enum ef_light_kind { EF_LIGHT_SUN = 0, EF_LIGHT_POINT, EF_LIGHT_SPOT, EF_LIGHT_NKIND } ef_light_kind;

/* A kind of light: what the parser, the default names and the
 * integrators know of it (the table in light.c). A new kind adds its row
 * there, its parsing of any key of its own, its branches where the lit
 * files ask at_position or cone, and its integrand in ref.c. */
typedef struct ef_light_kind_info {
    const char *name;                /* as written: --light NAME:... */
    const char *keys;                /* the keys it accepts, for messages */
    int at_position;                 /* a lamp at pos: E = I / (d^2 + radius^2), from all
                                      * around it; else a direction (the sun: dir, E) */
    int cone;                        /* lit only inside a cone around dir (aim=, cone=) */
    int shadow;                      /* takes a shadow= map (one view of its light) */
} ef_light_kind_info;

/* The table, one row per kind (light.c). */
extern const ef_light_kind_info ef_light_kinds[EF_LIGHT_NKIND];

/* A kind's name as a SPEC writes it ("sun", "point", "spot"): the one home
 * of those names (the parser and the default light names read it). */
const char *ef_light_kind_name(ef_light_kind k);

typedef struct ef_light {
    ef_light_kind kind;
    char name[64];                   /* name=, else sun1, point1, spot1... */
    double dir[3];                   /* sun: unit, towards the sun; spot: unit aim */
    double pos[3];                   /* point, spot: world position */
    /* sun: irradiance per channel on a surface facing it (color x
     * intensity); point, spot: intensity per channel, times U^2 so that
     * E = e / d^2 with d in scene units */
    double e[3];
    double radius;                   /* E = I / (d^2 + radius^2), scene units */
    double angle;                    /* sun: angular diameter, radians (kept: no penumbra yet) */
    double planet;                   /* sun: planet radius, scene units (0: flat; ef_chapman) */
    /* planet=: Ch(k (R + y), l . up) over heights y in [ch_y0, ch_y1] as a
     * Chebyshev series (ef_light_bind), verified off its nodes; ch_ok 0:
     * none (each point evaluates ef_chapman) */
    double ch_y0, ch_y1, ch_c[EF_CH_TERMS];
    int ch_ok;
    double cos_outer, smooth;        /* spot: cos(cone / 2), blend (1 - cos(cone / 2)) */
    int cosine;                      /* spot: cosine=1, Cycles' extra cos alpha */
    char aov[3][80];                 /* its AOV channels, fog_light.NAME.R/G/B */
    char lit_aov[80];                /* and fog_lit.NAME (with a shadow map) */
    /* shadow=: its light-view depth render (shared, counted: copies of the
     * scene ref it, ef_scene_free drops it), NULL without one; bias=,
     * slope= and outside= as given */
    struct ef_shadow *shadow;
    ef_shadow_opts shadow_opts;
    char shadow_path[256];
    char shadow_camera[256];  /* shadow-camera=: the map's camera file, "" for its header */
    /* sun, point: scattering=multiple adds the light scattered twice and more
     * (ms.h), over a black ground at height ground (has_ground) along the
     * fog's up; ms: its solve (shared, counted like the shadow map), built
     * by ef_scene_prepare_lights, NULL before or where it adds nothing */
    int multiple, has_ground;
    double ground;
    struct ef_ms *ms;
    ef_ms_view ms_view;              /* ms bound to the scene's camera (ef_scene_bind) */
    /* point lamp: scattering=multiple's solve in uniform fog (ms.h's
     * ef_lms; shared and counted as ms) */
    struct ef_lms *lms;
    struct ef_lms_view *lms_view;    /* lms bound to the scene's camera (ef_scene_bind) */
    char spec[512];                  /* as written, for messages */
} ef_light;

/* Parses one --light SPEC (sun:..., point:..., spot:...) with ctx's units;
 * the name stays empty unless name= gives it (the scene names it then).
 * A shadow= map is read through ctx->load_shadow and checked against the
 * light (a sun's map orthographic along its direction, a spot's a
 * perspective from its position); l then holds one reference to it.
 * Returns 0, or -1 with a message naming the spec and key (l holds
 * nothing then). */
int ef_light_parse(const char *spec, const ef_fog_context *ctx, ef_light *l, ef_err *err);

/* Whether l is a lamp at a position (point, spot), not a direction (sun). */
static inline int ef_light_at_position(const ef_light *l)
{
    return ef_light_kinds[l->kind].at_position;
}

/* Whether l shines inside a cone only (a spot). */
static inline int ef_light_coned(const ef_light *l)
{
    return ef_light_kinds[l->kind].cone;
}

/* Makes light l ready for fog c seen from a camera at height cam_y (up
 * the fog's up axis): a planet sun's Chebyshev table of Ch over the
 * heights its rays cross with any weight (from 200 / k below the lower of
 * the camera and the fog's base to 60 / k above the higher), kept only
 * where it matches ef_chapman to 1e-14 at 40 heights between its nodes.
 * Nothing for other lights. */
void ef_light_bind(ef_light *l, const ef_fog_component *c, double cam_y);
/* A spot's share of its intensity at cos alpha, alpha the angle from its
 * aim: 0 outside the cone, 1 inside the blend band, smoothstep across it
 * (x^2 (3 - 2x), x = (cos alpha - cos(cone/2)) / smooth; Blender's
 * spot_blend), times cos alpha with cosine=1 (Cycles 3.x's spot). */
double ef_spot_share(const ef_light *l, double cos_alpha);

/* Ch(k (R + y), mu) of planet sun l at height y: from its table (bound by
 * ef_light_bind) where that holds y, else ef_chapman (mu clamped to [-1, 1]). */
double ef_light_planet_ch(const ef_light *l, double k, double mu, double y);


/* The phase function of c at cos theta = l . u (l towards the light, u the
 * view direction away from the camera: g > 0 scatters forward). */
double ef_phase_eval(int phase, double g, double cos_theta);

#endif
