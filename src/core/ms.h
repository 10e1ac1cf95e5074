/* Multiple scattering of a sun (and of a sky light: ef_ms_build_sky) in
 * fog that is the same along the ground (its density a function of height
 * alone: exp, height, layered, a horizontal half-space): the
 * plane-parallel problem in vertical optical depth, solved once per scene
 * and light, independent of the pixels.
 *
 * The sun's beam propagates down; fog at vertical optical depth tau (from
 * the top of the fog) scatters it once (exrfog's single scattering, exact
 * elsewhere), and the diffuse light that results scatters again and again.
 * What the view ray gathers of the second and later orders is
 *
 *   S_ms = int_0^{s_D} e^{-s} J(tau_c - mu_u s, -u) ds,
 *
 * s the view's own optical depth (in a plane-parallel medium the vertical
 * depth changes by -mu_u per unit of it, mu_u the view direction's up
 * component), J(tau, w) the source of orders 2 and up per unit extinction
 * at depth tau in propagation direction w. J comes from the diffuse
 * radiance of every order (discrete ordinates: double-Gauss directions,
 * azimuthal Fourier modes of the phase functions' Legendre series, a
 * piecewise-linear source between depth nodes integrated exactly along
 * each direction), each mode by a direct banded solve or, where its
 * scattering operator's norm is below MS_ITER_KAPPA, order by order with
 * the bound of the orders left out. J is tabulated against depth and
 * direction; the view gathers it exactly for a source linear between
 * nodes. Pure C, no I/O.
 *
 * Errors, per pixel through ef_ms_gather's estimate:
 *   - bound: the orders an iterated mode leaves out (sup norm of its last
 *     order times kappa / (1 - kappa));
 *   - estimate: the discretisation, as the difference from a second solve
 *     at about half the resolution in depth and direction, plus the
 *     bilinear interpolation of the direction table from its second
 *     differences.
 * Scattered light is not shadowed: a shadow map blocks single scattering
 * only. The ground is black (ground=) or absent (the fog's own depth, to
 * tau 10^4, takes the light). */
#ifndef EF_MS_H
#define EF_MS_H

#include "error.h"

struct ef_fog_scene;
struct ef_light;
struct ef_ray;

typedef struct ef_ms ef_ms;

/* One channel's problem, for the solver alone (tests, bench): nodes in
 * vertical optical depth tau[0] = 0 < ... < tau[n-1] (the bottom, black
 * below), and per node the albedo times the phase function's Legendre
 * coefficients a[i * nl + l] = omega b_l (b_0 = 1; p(x) = sum_l (2l + 1)
 * b_l P_l(x) / 4 pi); a sun of irradiance E whose beam falls at cosine
 * mu_s > 0 from the vertical. */
typedef struct ef_ms_slab {
    int n;
    const double *tau;
    const double *a;
    int nl;
    double mu_s, E;
    /* A sky (NULL: none): the radiance entering at the top per azimuthal
     * mode m and parity cs (0: cos m phi, 1: sin m phi) for the downward
     * direction of cosine -x_i (x_i the i-th Gauss node on [0, 1]):
     * top[(m * 2 + cs) * nh + i], m < 2 nh. The solve then keeps sin modes
     * too, and J holds the sky's orders 1 and up. */
    const double *top;
} ef_ms_slab;

/* Resolution of a solve: directions per hemisphere (nh, 4..64) and the
 * depth grid's growth (a solve of ef_ms_build picks them; tests set
 * them). max_order > 0 keeps orders 2..max_order only (every mode
 * iterated), for tests against nested quadrature. */
typedef struct ef_ms_res {
    int nh;
    int max_order;
} ef_ms_res;

/* The diffuse radiance's fluxes of a solve, for the energy check: up out
 * of the top, down out of the bottom (diffuse only), per unit area. */
typedef struct ef_ms_flux {
    double up_top, down_bottom;
} ef_ms_flux;

/* The solve's directions per hemisphere: the n Gauss-Legendre nodes on
 * [0, 1] (cosines from up) and weights (summing to 1), as ef_ms_slab's
 * top indexes them. */
void ef_ms_directions(int n, double *x, double *w);

/* Solves one slab: J of orders 2 and up at depth node k, propagation
 * direction of up component mu (any in [-1, 1]) and azimuth dphi from the
 * beam's, through ef_ms_slab_eval. Returns an opaque solve or NULL (out of
 * memory). */
typedef struct ef_ms_solve ef_ms_solve;
ef_ms_solve *ef_ms_slab_solve(const ef_ms_slab *sl, const ef_ms_res *res, ef_ms_flux *flux);
double ef_ms_slab_eval(const ef_ms_solve *so, int k, double mu, double dphi);
/* The bound of the orders a solve left out, the largest over nodes and
 * directions (0 where every mode was solved directly). */
double ef_ms_slab_tail(const ef_ms_solve *so);
void ef_ms_solve_free(ef_ms_solve *so);

/* Builds the multiple scattering of sun l in scene s (l a sun; its
 * ground= and the components' albedo and phases read), or *out = NULL
 * when it adds nothing (the sun below the horizon, no fog above the
 * ground). Returns 0, or -1 with a message: a component whose density is
 * not a function of height along a common up (noise, a box, a tilted
 * half-space), a planet sun, out of memory. */
int ef_ms_build(const struct ef_fog_scene *s, const struct ef_light *l, ef_ms **out, ef_err *err);

/* Builds the sky light's transport through the fog (s->sky_light with
 * scattering=multiple; s->sky_ground when s->sky_has_ground): the
 * plane-parallel solve with the environment entering at the top, every
 * order (its single scattering, attenuated, included); *out = NULL when
 * there is no fog above the ground. Returns 0, or -1 with a message (as
 * ef_ms_build, or fog whose up is not the scene's). */
int ef_ms_build_sky(const struct ef_fog_scene *s, ef_ms **out, ef_err *err);

/* S_ms per channel along r (org anywhere, dir unit, r->dist possibly
 * INFINITY), seen from r->org, and into E (may be NULL) its error
 * estimate (the bound and estimates above); 0 where m is NULL. tv: r's
 * optical depth per channel when the caller has it, tauc: r->org's
 * vertical depth as ef_ms_bind keeps it (both NULL: computed here; the
 * same bits either way). */
void ef_ms_gather(const ef_ms *m, const struct ef_fog_scene *s, const struct ef_ray *r,
                  const double *tv, const double *tauc, double S[3], double E[3]);
/* A solve bound to a camera: the camera's vertical optical depth per
 * channel, which every ray from it would otherwise compute again. */
typedef struct ef_vms_cam ef_vms_cam;
typedef struct ef_ms_view {
    int bound;
    double org[3], tauc[3];
    /* a volume's solve (lit_vms.c): its source towards the camera at each
     * voxel, shared by copies of the scene (ef_vms_cam_ref), or NULL */
    ef_vms_cam *cam;
} ef_ms_view;

/* Binds m (may be NULL: nothing bound) to the camera at org of scene s. */
void ef_ms_bind(const ef_ms *m, const struct ef_fog_scene *s, const double org[3],
                ef_ms_view *v);

/* ef_ms_gather with v's depth where r starts at v's camera: the same bits. */
void ef_ms_gather_view(const ef_ms *m, const ef_ms_view *v, const struct ef_fog_scene *s,
                       const struct ef_ray *r, const double *tv, double S[3], double E[3]);

/* What the build chose and measured, for --explain and the bench: depth
 * nodes (and those the table keeps), directions per hemisphere, modes
 * solved directly and iterated,
 * the largest tail bound and the largest discretisation estimate relative
 * to the largest J, and the solve's time in seconds. */
typedef struct ef_ms_info {
    int nodes, kept, nh, direct, iterated;
    double tail_rel, disc_rel, seconds;
    /* a box or convex volume's solve (lit_vms.c): 1, its photons, and
     * nodes the voxels, kept the voxels along each side */
    int volume, photons;
} ef_ms_info;
void ef_ms_get_info(const ef_ms *m, ef_ms_info *info);

/* Shared, immutable once built: copies of a scene take references. */
void ef_ms_ref(ef_ms *m);
void ef_ms_unref(ef_ms *m);

/* A sun's multiple scattering in one uniform box or convex volume
 * (lit_vms.c: a Monte Carlo solve on a grid over the volume, once per
 * scene and sun). ef_ms_build makes one where the scene is such a volume
 * alone; its gather then takes the view's segment through it. */
typedef struct ef_vms ef_vms;
int ef_vms_build(const struct ef_fog_scene *s, const struct ef_light *l, ef_vms **out,
                 ef_err *err);
void ef_vms_free(ef_vms *v);
void ef_vms_gather(const ef_vms *v, const ef_vms_cam *c, const struct ef_ray *r, double S[3],
                   double E[3]);
/* v's source towards a camera at org at every voxel (the harmonics summed
 * for the direction from the voxel's centre to it), which ef_vms_gather
 * reads beyond eight voxels from c's camera for rays that start there;
 * NULL out of memory (the gather then sums the harmonics itself). */
ef_vms_cam *ef_vms_bind(const ef_vms *v, const double org[3]);
void ef_vms_cam_ref(ef_vms_cam *c);
void ef_vms_cam_unref(ef_vms_cam *c);
/* Releases what ef_ms_bind holds in v and clears it. */
void ef_ms_view_clear(ef_ms_view *v);
void ef_vms_get_info(const ef_vms *v, ef_ms_info *info);
/* The real spherical harmonics Y_lm of unit d to degree 3, in the order
 * (0,0), (1,-1), (1,0), (1,1), (2,-2) .. (3,3). */
void ef_vms_harmonics(const double d[3], double Y[16]);

/* Legendre polynomials P_0..P_{L-1} at x into P. */
void ef_ms_legendre(int L, double x, double *P);

/* The phase's Legendre coefficients b_0..b_{L-1} (b_0 = 1; p(x) = sum_l
 * (2l + 1) b_l P_l(x) / 4 pi), L <= 128. */
void ef_ms_phase_legendre(int phase, double g, int L, double *b);

/* ---- a point lamp in uniform fog (lit_lamp_ms.c) ----
 *
 * The light of a point lamp scattered twice and more in fog of uniform
 * extinction (one exp component): the problem is symmetric about the
 * lamp, so it is solved once per albedo and phase in optical units, as a
 * table of the source Q(r, nu) of orders 2 and up against the distance
 * from the lamp and the direction from the outward radial, and gathered
 * along each view ray by adaptive quadrature about the ray's closest
 * approach to the lamp. Errors, through ef_lms_gather's estimate: the
 * difference from a second solve at about 2/3 the resolution and 0.8 of
 * the domain (an estimate), GMRES's residual through the series (a bound
 * for the linear solve) and the gather's quadrature (an estimate).
 * Scattered light is not shadowed. */
typedef struct ef_lms ef_lms;

/* Builds point lamp l's multiple scattering in scene s (uniform fog, or
 * any fog but noise whose components share albedo and phase: the local
 * mode below; albedo and phase read). Returns 0, or -1 with a message
 * (noise fog, components that scatter differently, a shadow map in fog
 * that is not uniform, |g| > 0.9, out of memory). */
int ef_lms_build(const struct ef_fog_scene *s, const struct ef_light *l, ef_lms **out,
                 ef_err *err);
/* The light of orders 2 and up scattered towards r->org along [a, b) of r
 * (seen from r->org: attenuated from there), per channel, and into E
 * (may be NULL) its estimate. */
void ef_lms_gather(const ef_lms *m, const struct ef_ray *r, double a, double b, double S[3],
                   double E[3]);
/* A lamp's solve bound to a camera at org: the gather of every ray from
 * there tabulated against the ray's angle from the lamp and its depth
 * (ef_lms_gather_view reads it; rays from elsewhere integrate). *v is
 * replaced (the old one unreffed; NULL when m is). Returns 0, or -1 out
 * of memory (*v NULL: every ray integrates). */
typedef struct ef_lms_view ef_lms_view;
int ef_lms_bind(const ef_lms *m, const double org[3], ef_lms_view **v);
void ef_lms_view_ref(ef_lms_view *v);
void ef_lms_view_unref(ef_lms_view *v);
/* ef_lms_gather through v where r starts at v's camera and a is 0 (the
 * table: cubic in depth, linear in angle, its interpolation in the
 * estimate), else ef_lms_gather. */
void ef_lms_gather_view(const ef_lms *m, const ef_lms_view *v, const struct ef_ray *r, double a,
                        double b, double S[3], double E[3]);
void ef_lms_ref(ef_lms *m);
void ef_lms_unref(ef_lms *m);
void ef_lms_get_info(const ef_lms *m, ef_ms_info *info);

/* For tests: the solve alone in optical units (a lamp of intensity 1,
 * extinction 1) for albedo omega (max_order 2: order 2 alone), its r Q at
 * (r, nu) through ef_lms_eval, and with phi0/phi1 ([nr] each) the scalar
 * flux of orders 2 and up and of order 1 at the radial nodes
 * ef_lms_rho(nr, lg, i). */
int ef_lms_build_albedo(double omega, int phase, double g, int max_order, ef_lms **out,
                        double *phi0, double *phi1, int *nr, double *lg);
double ef_lms_eval(const ef_lms *m, double r, double nu, double *err);

/* Fog that is not uniform (ef_lms_build's local mode; the gathers then
 * add nothing and the lit quadrature reads the table at its nodes).
 * Uniform fog's field about the lamp, Q = sigma^3 Q1(sigma r, nu) in
 * optical units, scaled to the medium the lamp's light crossed: at a node
 * of extinction sg in channel k, distance d from the lamp and optical
 * distance tl from it along the straight line, Q = sg (tl / d)^2 Q1(tl,
 * nu), the mean extinction of the line setting the field's scale (exact
 * in uniform fog). Returns d^2 Q (the quadrature's weights carry 1 /
 * d^2 and the lamp's intensity), and into *est the spread from the same
 * field scaled by the node's own extinction (sg^3 Q1(sg d, nu)) plus the
 * table's estimate, plus the light the unbounded fog's field counts that
 * would scatter back from where this fog drops or thins (a box's or convex
 * volume's faces, a half-space's plane; height fog one e-fold up; layered
 * fog wherever its profile falls, each fall as a plane's drop): the
 * value times LEAK_C sqrt(0.1 / (1 - albedo)) times the exposure of the
 * node and of the lamp to them (the share of the extinction that drops
 * times E_2 of the optical depth to the drop, over 2; at most 1). An
 * estimate, calibrated against nested quadrature of the second order and
 * against Cycles (bench/ms_lamp.md, bench/ms_lamp_box.md,
 * bench/ms_lamp_height.md, bench/ms_lamp_layered.md). ca: the cosine of
 * the node's direction from the lamp against a spot's aim (ef_lms_spot;
 * else unused); expo: the
 * node's exposure, ef_lms_leak_exposure (a point near it serves: it is
 * smooth, and read once per four nodes of a quadrature rule). x: the
 * node; where the fog holding the lamp ends at planes the value is less the field of the
 * lamp's images across them (lit_lamp_ms.c's lamp_images; x NULL: none).
 * est NULL: the value alone, the same bits, without the estimate's reads
 * (expo unused). */
int ef_lms_is_local(const ef_lms *m);
/* Whether m is a spot's (ef_lms_spot), and whether its fog is not
 * uniform (the field scaled as above); either makes it local. */
int ef_lms_is_spot(const ef_lms *m);
int ef_lms_is_scaled(const ef_lms *m);
/* ef_lms_local_node's value (est NULL) at four nodes at once, into f:
 * the table's places on vectors (vmath.h's log1p, log, atan2 and sqrt, a
 * few ulp from libm's), the reads per node. x: the four nodes (NULL as
 * there). A node with sg, tl or d not above 0 gets 0. */
void ef_lms_local_node4(const ef_lms *m, int k, const double tl[4], const double sg[4],
                        const double d[4], const double nu[4], const double ca[4],
                        const double (*x)[3], double f[4]);
/* Whether channels j and k read the same table (one albedo). */
int ef_lms_same_table(const ef_lms *m, int j, int k);
double ef_lms_local_node(const ef_lms *m, int k, double tl, double sg, double d, double nu,
                         double ca, const double x[3], double expo, double *est);
/* The exposure in channel k of a point x of extinction sg to where the fog
 * drops or thins (the leak term's; 0 in fog that does neither). */
double ef_lms_leak_exposure(const ef_lms *m, const double x[3], int k, double sg);
/* Makes m a spot's (l's cone and aim; local mode from then on): at a node
 * whose direction from the lamp has cosine ca from the aim, the table's
 * value is taken times the cone's share averaged over where the light
 * reaching the node first scattered (exact with isotropic phase; with
 * another, the spread of eight weightings and the view's dependence join
 * the estimate; lit_lamp_ms.c). Returns 0, or -1 out of memory. */
int ef_lms_spot(ef_lms *m, const struct ef_light *l);
double ef_lms_rho(int nr, double lg, int i);

#endif
