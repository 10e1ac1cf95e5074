/* Fog components, their registry and the SPEC grammar
 * (MODEL[:KEY=VALUE]...). Each model is one small unit in fog_*.c that knows
 * how to read its keys, its density, and the closed-form optical depth of a
 * segment; adding a model means one file plus one line in the registry
 * (fog.c). */
#ifndef EF_FOG_H
#define EF_FOG_H

#include <float.h>
#include <math.h>
#include <stdatomic.h>

#include "error.h"
#include "recon.h"

#define EF_FOG_MAX_PARAMS 32
#define EF_FOG_MAX_COMPONENTS 32

/* Which distance a model measures: the true one, or OpenGL's eye depth. */
typedef enum ef_distance_kind { EF_DIST_RADIAL = 0, EF_DIST_PLANAR } ef_distance_kind;

/* Scene-wide settings a component is finished against: the up axis of the
 * height models and the scene's units per metre (densities are read per
 * metre and converted to per scene unit). */
struct ef_shadow;
struct ef_shadow_opts;
struct ef_sky_light;

typedef struct ef_fog_context {
    double up[3];                    /* unit length */
    double units_per_meter;          /* > 0 */
    double time;                     /* --time T: the time every velocity= key is read at */
    /* Reads a whole text file (file= keys) into a malloc'd, NUL-terminated
     * buffer; NULL means files cannot be read here. The core does no I/O. */
    int (*read_file)(const char *path, char **text, ef_err *err);
    /* Turns a color= value into the working space's R,G,B (colour
     * management lives outside the core); NULL: plain numbers only
     * (ef_parse_color). Returns 0, or -1 with err set. */
    int (*parse_color)(void *user, const char *text, double out[3], ef_err *err);
    void *color_user;
    /* Reads a light-view depth render (a light's shadow= key) into a
     * shadow map (shadow.h) read as o says; NULL means maps cannot be read
     * here. Returns 0, or -1 with err set. */
    int (*load_shadow)(const char *path, const struct ef_shadow_opts *o, struct ef_shadow **out,
                       ef_err *err);
    /* Reads a lat-long environment (--sky-light) and convolves it with the
     * n phase functions (phases[i], g[i]) into a sky light (sky_light.h);
     * NULL means environments cannot be read here. Returns 0, or -1 with
     * err set. */
    int (*load_sky)(const char *path, double rotate_deg, double intensity, const int *phases,
                    const double *g, int n, struct ef_sky_light **out, ef_err *err);
} ef_fog_context;

struct ef_fog_model;

typedef struct ef_fog_component {
    const struct ef_fog_model *model;
    ef_distance_kind distance;
    double p[EF_FOG_MAX_PARAMS];     /* model parameters; layout is the model's */
    double *arr;                     /* variable-size data (planes, profiles), owned */
    int narr;                        /* number of doubles in arr */
    char *path;                      /* a file= key's path, owned */
    unsigned seen;                   /* bit i: key i of the model was given */
    int has_color, has_up;
    double color[3];                 /* color=R,G,B: this component's in-scattered colour */
    double up[3];                    /* unit up (height models): up= key, else the context's */
    /* Single scattering under lights (light.h): albedo=, phase=, g=. Read
     * only when the scene has lights; albedo is 1 unless has_albedo. */
    int has_albedo, phase, has_g;
    double albedo[3], g;
    /* The camera bound by ef_fog_bind: n.org of the first functional, as a
     * double-double, so per-pixel work skips a per-frame constant. */
    int bound;
    double bound_org[3], bound_dot[2];
    /* The bound camera's pixel footprint per unit of distance (radians: a
     * pixel at distance s covers about s spread), set by ef_scene_bind_camera
     * before ef_fog_bind; 0 when no camera is known. Models whose density
     * is filtered to the pixel (noise's lod=pixel) read it in bind. */
    double spread;
    /* When not NULL and *cancel becomes non-zero, models whose optical
     * depth may take long (noise) return 0 at once: the host is stopping
     * and throws the result away. Never read otherwise. */
    const _Atomic int *cancel;
    /* the SPEC as written, for messages: owned (malloc'd), or ef_spec_none
     * in a copy made only for evaluation (ef_scene_copy without specs) */
    char *spec;
} ef_fog_component;

/* The empty SPEC of a component copied without its text (never freed). */
extern const char ef_spec_none[];

/* The longest SPEC accepted (a usage error beyond). */
#define EF_SPEC_MAX ((size_t) 8191)

/* The phase functions of phase= (normalised over the sphere). */
enum { EF_PHASE_ISO = 0, EF_PHASE_RAYLEIGH, EF_PHASE_HG, EF_PHASE_CS };

/* A linear functional of world position, value(x) = n.x + d. Models that
 * have a density describe it through such functionals (planes, heights). */
typedef struct ef_fog_functional {
    double n[3], d;
} ef_fog_functional;

/* Where a density changes: functional f crosses value, and the density
 * varies over about scale (in the functional's units) around it; scale 0
 * marks a jump or kink only. The reference integrator splits there. */
typedef struct ef_fog_feature {
    int f;
    double value, scale;
} ef_fog_feature;

/* Where a density repeats a non-smooth seam: functional f crosses
 * phase + k * period for every integer k (a noise lattice's planes). The
 * reference integrator splits at every such crossing on a segment. */
typedef struct ef_fog_lattice {
    int f;
    double phase, period;
} ef_fog_lattice;

/* What one optical-depth evaluation cost and how far it may be off. Closed
 * forms leave it zero. */
typedef struct ef_tau_info {
    double err[3];      /* bound (or stated estimate) of |tau - exact tau| per channel */
    double evals;       /* noise evaluations (one octave at one point each) */
    double cells;       /* lattice cells walked, over all octaves */
    double dropped;     /* octaves left out by the tolerance rule */
    int over;           /* the work bound dropped octaves beyond the tolerance */
    int kind;           /* what err is: EF_ERR_BOUND, _QUAD or _STAT */
} ef_tau_info;

/* What an optical depth's error (ef_tau_info.err) is: a bound (closed
 * forms, method=exact, steps, preintegrated, the separable walk where it
 * dropped nothing), an estimate of a quadrature's error with every octave
 * integrated (the default method's node plans), or a statistical estimate
 * (octaves dropped by the tolerance rule or the work bound, the clamp's
 * share, a ttol stop's lower value). */
enum { EF_ERR_BOUND = 0, EF_ERR_QUAD, EF_ERR_STAT };

/* A sun as a model's closed form sees it (the sun hook): towards the sun
 * (unit), and per channel the weight albedo p(theta) E, formed by lit fog
 * in that order (theta between the sun and the view ray), and whether the
 * channel has light at all (E and the albedo non-zero). */
typedef struct ef_sun_light {
    double dir[3];
    double w[3];
    int live[3];
} ef_sun_light;

/* tau phi(tau q), phi(x) = -expm1(-x) / x: the integral of e^(linear) over
 * a segment of optical depth tau whose exponent changes by tau q, relative
 * to its larger end (the sun closed forms' kernel). tau phi(x) while x <= 1
 * (x -> 0 tends to tau exactly), -expm1(-x) / q beyond (tau = inf gives
 * 1 / q). */
static inline double ef_tau_phi(double tau, double q)
{
    const double x = tau * q;
    if (x == 0)
        return tau;
    if (x <= 1)
        return tau * (-expm1(-x) / x);
    return -expm1(-x) / q;
}

typedef struct ef_fog_model {
    const char *name;
    const char *const *keys;         /* NULL-terminated list of accepted keys */
    /* Parses value val of key index k into c. Returns 0 or -1 (usage error). */
    int (*set)(ef_fog_component *c, int k, const char *val, ef_err *err);
    /* Checks required keys and consistency once all keys are read, and
     * converts to scene units with ctx. */
    int (*finish)(ef_fog_component *c, const ef_fog_context *ctx, ef_err *err);
    /* Closed-form optical depth per channel along r, from r->org over
     * [0, r->dist] along r->dir (r->dist may be INFINITY; the result is then
     * the exact limit, possibly INFINITY). */
    void (*tau)(const ef_fog_component *c, const ef_ray *r, double tau[3]);
    /* For the reference integrator (NULL for models with no density of
     * position, such as OpenGL's linear and exp2). functionals() fills up to
     * cap entries and returns how many there are; features() likewise (with
     * cap 0, out may be NULL: the count alone). */
    int (*functionals)(const ef_fog_component *c, ef_fog_functional *out, int cap);
    int (*features)(const ef_fog_component *c, ef_fog_feature *out, int cap);
    /* Density per channel at a point given by its functional values v
     * (any may be +-INFINITY: the density's limit there). */
    void (*density)(const ef_fog_component *c, const long double *v, long double out[3]);
    /* Models whose tau is not a closed form (noise) also report its error
     * and cost; NULL for the exact ones. tau must give the same values. */
    void (*tau_info)(const ef_fog_component *c, const ef_ray *r, double tau[3],
                     ef_tau_info *info);
    /* Optional, models whose tau is not a closed form: the relative
     * accuracy lit fog aims at through this component (lit_noise.c). */
    double (*lit_tol)(const ef_fog_component *c);
    /* Optional, the same models: tau_info at an absolute tolerance tol on
     * tau where the method has one (others ignore tol). */
    void (*tau_tol)(const ef_fog_component *c, const ef_ray *r, double tol, double tau[3],
                    ef_tau_info *info);
    /* Periodic seams for the reference integrator (NULL: none), like
     * functionals(): fills up to cap, returns how many there are. */
    int (*lattices)(const ef_fog_component *c, ef_fog_lattice *out, int cap);
    /* Optional: adds tau along r[j] to acc[j] for j < n, the same bits as
     * tau() added per ray (NULL: ef_fog_tau_add loops over tau()). */
    void (*tau_add)(const ef_fog_component *c, const ef_ray *r, int n, double (*acc)[3]);
    /* Optional: caches what every ray from the camera at org repeats
     * (ef_fog_bind calls it); tau must give the same bits with or without. */
    void (*bind)(ef_fog_component *c, const double org[3]);
    /* Optional, depth-only models: adds tau in channel k to tau[k][j], j < n
     * (to 0 when first: the planes are then only written), for the ray of
     * planar distance planar[j] and distance dist[j], the same bits as
     * tau() of such a ray added. The fog pass then builds no rays. dist is
     * only read for distance=radial. */
    void (*tau_dist)(const ef_fog_component *c, const double *planar, const double *dist, int n,
                     int first, double *const tau[3]);
    /* Optional: the noise evaluations tau is predicted to make along r
     * when that work is not bounded per ray (method=exact), else 0: an
     * estimate, not a bound (the job times a sample of pixels for its
     * cost warning and reads this only to say method=exact is why). */
    double (*work)(const ef_fog_component *c, const ef_ray *r);
    /* Optional: a bound on |d sigma/dt| (the largest channel's) along r over
     * [0, r->dist], for the deep split rule h^2/8 max|sigma'|. Models
     * without it promise a density monotone along any segment between the
     * crossings of their features of scale 0 (jumps and kinks), where the
     * rule takes twice the midpoint's deviation instead (deep.c). */
    double (*dsigma_max)(const ef_fog_component *c, const ef_ray *r);
    /* Optional, for the reference integrator: where the density has kinks
     * inside its lattice pieces (the noise's clamp max(0, x)), a function
     * of the functional values v, continuous there, whose sign changes are
     * the kinks (1 + c fbm). Returns 0 when the component has none (the
     * clamp cannot bind: *g is not set), else 1 with *g. */
    int (*kink)(const ef_fog_component *c, const long double *v, long double *g);
    /* Optional, for lit fog: 1 when the density is the same at every point
     * of space (it fills all space: exp along the true distance), with
     * that extinction per channel into sigma; else 0. */
    int (*uniform)(const ef_fog_component *c, double sigma[3]);
    /* Optional, for lit fog's planet sun: 1 when the density is
     * rho e^(-k (up.x - base)) with k > 0 (exponential strata along the
     * component's up), with rho per channel, k and base; else 0. */
    int (*strata)(const ef_fog_component *c, double rho[3], double *k, double *base);
    /* Optional, for lit fog: 1 when the density is rho per channel inside
     * a convex volume and 0 outside, with the volume's *n planes (A, B, C,
     * D each, a unit normal, fog where A x + B y + C z + D < 0) at *planes
     * (the component's own array); else 0. */
    int (*convex)(const ef_fog_component *c, double rho[3], const double **planes, int *n);
    /* Optional, for lit fog: a sun's single scattering along r when this
     * component is the scene's only one, in closed form: S[ch] = sl->w[ch]
     * times the model's own factors (the view ray's optical depth, the
     * sun's from its ends, the geometry), 0 where !sl->live[ch]. tv: the
     * view ray's optical depth per channel as tau() gives it, or NULL (the
     * model computes it). Returns 1, or 0 when the component has no closed
     * form (S untouched; lit fog integrates instead). */
    int (*sun)(const ef_fog_component *c, const struct ef_sun_light *sl, const ef_ray *r,
               const double *tv, double S[3]);
    int depth_only;                  /* tau reads r->dist or r->planar only, never dir or org */
    int uses_distance;               /* accepts distance=radial|planar */
    int uses_up;                     /* accepts up=AXIS (else ctx->up applies) */
} ef_fog_model;

/* The default context: up = +y, 1 unit per metre. */
void ef_fog_context_init(ef_fog_context *ctx);

/* Length-dimensioned conversions with ctx: a per-metre coefficient to per
 * scene unit (x / U), and a per-metre-squared one (x / U^2). */
double ef_fog_per_unit(const ef_fog_context *ctx, double per_meter);
double ef_fog_per_unit2(const ef_fog_context *ctx, double per_meter2);

/* Parses and finishes one SPEC into c (ctx may be NULL: the default). On
 * error, returns -1 with a message quoting the offending text (unknown model
 * or key, missing value, bad number...). Release c with ef_fog_free. */
int ef_fog_parse(const char *spec, const ef_fog_context *ctx, ef_fog_component *c, ef_err *err);

/* The token of a SPEC (or --light SPEC) after tok, strtok_r's at ':' with
 * save, once a color=SPACE:R,G,B split at its ':' is joined back into tok. */
char *ef_spec_next(const char *tok, char **save);

/* Precomputes the camera-dependent part of c's first functional for rays
 * starting at org (the camera). Rays from elsewhere are still exact. Call
 * before any thread evaluates c. */
void ef_fog_bind(ef_fog_component *c, const double org[3]);

/* Copies src into dst, duplicating owned data. Returns 0 or -1 (memory). */
int ef_fog_copy(ef_fog_component *dst, const ef_fog_component *src);

/* Releases what c owns; c may then be reused. */
void ef_fog_free(ef_fog_component *c);

/* c's optical depth along r, and into info (which may be NULL) its error
 * and cost: zero for the closed forms. */
void ef_fog_tau(const ef_fog_component *c, const ef_ray *r, double tau[3], ef_tau_info *info);

/* acc[j][k] += c's tau along r[j] in channel k, for j < n: one dispatch
 * for n rays, the same sums as adding ef_fog_tau's per ray. */
void ef_fog_tau_add(const ef_fog_component *c, const ef_ray *r, int n, double (*acc)[3]);

/* The registered model with this name, or NULL. */
const ef_fog_model *ef_fog_model_find(const char *name);

/* The registry in order: how many models, and model i (NULL past the
 * end). Tests that sweep the models iterate it, so a new model cannot be
 * left out unnoticed. */
int ef_fog_model_count(void);
const ef_fog_model *ef_fog_model_at(int i);

/* Parses "a" or "a,b,c" into 1 or 3 finite numbers; a single value is
 * broadcast to all three. Returns 0 or -1. Shared by models for R,G,B keys. */
int ef_parse_rgb(const char *text, double out[3]);
/* The largest magnitude a SPEC or option number may have: every finite
 * double (the models are exact at the extremes; a key whose use would
 * overflow has its own range). */
#define EF_NUM_MAX DBL_MAX
/* The largest colour component: the largest half, so that fogged pixels
 * stay finite in half channels. */
#define EF_COLOR_MAX 65504.0
/* One number at s (strtod's syntax); *end past it. Returns 0, -1 when it
 * is not a number (NaN included), -2 when out of range: overflow, infinity,
 * underflow to 0 or a subnormal, or (unless wide) above EF_NUM_MAX. */
int ef_parse_real(const char *s, char **end, double *out, int wide);
/* Whether text (a value, or a list separated by , / : or spaces) holds a
 * number that is out of range in ef_parse_real's sense: for messages that
 * say "out of range" rather than "not a number". */
int ef_out_of_range(const char *text, int wide);
/* Parses exactly n comma-separated numbers in range. Returns 0, -1 or -2
 * as ef_parse_real. */
int ef_parse_numbers_ex(const char *text, double *out, int n, int wide);
/* ef_parse_numbers_ex, not wide. */
int ef_parse_numbers(const char *text, double *out, int n);
/* ef_parse_rgb with every component from 0 to EF_COLOR_MAX. */
int ef_parse_color(const char *text, double out[3]);
/* Parses 1..cap comma-separated finite numbers; returns the count or -1. */
int ef_parse_list(const char *text, double *out, int cap);
/* Parses an up axis: y, z, -y, -z (also x, -x) or X,Y,Z (non-zero, made
 * unit). Returns 0 or -1. */
int ef_parse_up(const char *text, double up[3]);

/* Shared key parsers for models; each fails with a message naming the spec
 * and key. density: R,G,B >= 0. visibility: R,G,B > 0, stored as the
 * density 3.912/V. plane: A,B,C,D with (A,B,C) != 0, stored normalised. */
int ef_fog_set_density(ef_fog_component *c, const char *key, const char *val, double out[3],
                       ef_err *err);
int ef_fog_set_visibility(ef_fog_component *c, const char *key, const char *val, double out[3],
                          ef_err *err);
int ef_fog_set_plane(ef_fog_component *c, const char *key, const char *val, double out[4],
                     ef_err *err);

/* The contrast threshold of visibility=V: density = EF_VISIBILITY_K / V. */
#define EF_VISIBILITY_K 3.912

/* The distance a component measures on r (radial or planar). */
static inline double ef_fog_distance(const ef_fog_component *c, const ef_ray *r)
{
    return c->distance == EF_DIST_PLANAR ? r->planar : r->dist;
}

/* Models, registered in fog.c. */
extern const ef_fog_model ef_fog_linear, ef_fog_exp, ef_fog_exp2;
extern const ef_fog_model ef_fog_halfspace, ef_fog_halfspace_linear, ef_fog_halfspace_smooth;
extern const ef_fog_model ef_fog_height, ef_fog_layered, ef_fog_box, ef_fog_convex;
extern const ef_fog_model ef_fog_noise, ef_fog_noise_separable;

/* The noise models' default tolerance, 2^-12: |dT| per channel under the
 * default ttol (and tol='s default), which keeps |dT| below half an ulp of
 * a half float for every T; lit fog aims at it where no component states
 * its own. The one home of that number. */
#define EF_NOISE_DEFAULT_TOL 0x1p-12

#endif
