/* Fog components, their registry and the SPEC grammar
 * (MODEL[:KEY=VALUE]...). Each model is one small unit in fog_*.c that knows
 * how to read its keys and the optical depth of a segment; adding a model
 * means one file plus one line in the registry (fog.c). */
#ifndef EF_FOG_H
#define EF_FOG_H

#include "error.h"
#include "recon.h"

#define EF_FOG_MAX_PARAMS 24
#define EF_FOG_MAX_COMPONENTS 32

/* Which distance a model measures: the true one, or OpenGL's eye depth. */
typedef enum ef_distance_kind { EF_DIST_RADIAL = 0, EF_DIST_PLANAR } ef_distance_kind;

struct ef_fog_model;

typedef struct ef_fog_component {
    const struct ef_fog_model *model;
    ef_distance_kind distance;
    double p[EF_FOG_MAX_PARAMS];     /* model parameters; layout is the model's */
    unsigned seen;                   /* bit i: key i of the model was given */
    char spec[256];                  /* the SPEC as written, for messages */
} ef_fog_component;

typedef struct ef_fog_model {
    const char *name;
    const char *const *keys;         /* NULL-terminated list of accepted keys */
    /* Parses value val of key index k into c. Returns 0 or -1 (usage error). */
    int (*set)(ef_fog_component *c, int k, const char *val, ef_err *err);
    /* Checks required keys and consistency once all keys are read. */
    int (*finish)(ef_fog_component *c, ef_err *err);
    /* Optical depth per channel along r (r->dist may be INFINITY; the
     * result is then the exact limit, possibly INFINITY). */
    void (*tau)(const ef_fog_component *c, const ef_ray *r, double tau[3]);
} ef_fog_model;

/* Parses one SPEC into c. On error, returns -1 with a message quoting the
 * offending text (unknown model or key, missing value, bad number...). */
int ef_fog_parse(const char *spec, ef_fog_component *c, ef_err *err);

/* The registered model with this name, or NULL. */
const ef_fog_model *ef_fog_model_find(const char *name);

/* Parses "a" or "a,b,c" into 1 or 3 finite numbers; a single value is
 * broadcast to all three. Returns 0 or -1. Shared by models for R,G,B keys. */
int ef_parse_rgb(const char *text, double out[3]);
/* Parses exactly n comma-separated finite numbers. Returns 0 or -1. */
int ef_parse_numbers(const char *text, double *out, int n);

/* The distance a component measures on r (radial or planar). */
static inline double ef_fog_distance(const ef_fog_component *c, const ef_ray *r)
{
    return c->distance == EF_DIST_PLANAR ? r->planar : r->dist;
}

/* Models, registered in fog.c. */
extern const ef_fog_model ef_fog_linear, ef_fog_exp, ef_fog_exp2;

#endif
