/* Lit fog over a scene: the in-scattered light of every light along a view
 * segment (light.h gives the model and the methods). */
#ifndef EF_LIT_H
#define EF_LIT_H

#include "scene.h"

/* Whether every component of s has a density in space, so that light can
 * be carried through it: not linear or exp2, nor exp with
 * distance=planar (functions of the camera's distance); a planet sun takes
 * one exponential height fog. Returns 0, or -1 with a message naming the
 * component. */
int ef_lights_check(const ef_fog_scene *s, ef_err *err);

/* Whether light l of s cannot light the fog at all: a sun (without
 * planet=) over a component that fills all space uniformly with density in
 * every channel (exp): its light crosses infinite fog on the way in, so S
 * is 0 everywhere. */
int ef_light_dark(const ef_fog_scene *s, const ef_light *l);

/* S per channel along r (its org is the camera; r->dist may be INFINITY)
 * from light l of s, and into *err (may be NULL) an estimate of its
 * absolute error per channel (the quadrature's Kronrod-Gauss differences,
 * with noise fog the steps' Richardson differences and the noise calls'
 * estimates; 0 for closed forms). +inf where a lamp of radius 0 lies on the
 * segment itself. */
void ef_light_inscatter(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, double S[3],
                        double err[3]);

/* ef_light_inscatter for each of the n rays r[j]: S[k][j] and, where E is
 * not NULL, the estimate E[k][j], the same bits. A point lamp in uniform
 * isotropic fog takes its closed form four rays at a time (on vectors). */
void ef_light_rays(const ef_fog_scene *s, const ef_light *l, const ef_ray *r, int n,
                   double *const S[3], double *const E[3]);

/* Where along r (org the camera, dir unit), strictly inside (a, b), light
 * l's in-scatter per unit optical depth jumps or turns fast: a lamp's
 * closest approach and points 4^j times its distance from the line either
 * side of it, a spot's cone crossings, a shadow map's lit-interval ends (the
 * first 64 intervals). Sorted and distinct into cut (at most cap); returns
 * how many. Deep fog samples are cut there, so that the split rule's
 * colour error can be estimated from one midpoint per sample. */
int ef_light_cuts(const ef_light *l, const ef_ray *r, double a, double b, double *cut, int cap);
/* Whether l's light in scene s is the closed form of the sun in one
 * exponential height fog, without a shadow map: what the span path of
 * apply.c computes from the optical depths it already has. */
int ef_light_sun_span(const ef_fog_scene *s, const ef_light *l);
/* That light along r (ef_light_inscatter's S for such a sun), given the
 * segment's optical depth tv per channel as the model computes it. */
void ef_light_sun_span_eval(const ef_fog_scene *s, const ef_light *l, const ef_ray *r,
                            const double tv[3], double S[3]);

#endif
