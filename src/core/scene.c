#include "scene.h"

#include <math.h>
#include <string.h>

void ef_scene_init(ef_fog_scene *s)
{
    memset(s, 0, sizeof *s);
    s->color[0] = EF_DEFAULT_FOG_COLOR_R;
    s->color[1] = EF_DEFAULT_FOG_COLOR_G;
    s->color[2] = EF_DEFAULT_FOG_COLOR_B;
    s->sky = EF_SKY_FOG;
    s->sky_distance = INFINITY;
}

int ef_scene_parse_sky(ef_fog_scene *s, const char *text, ef_err *err)
{
    if (!strcmp(text, "fog")) {
        s->sky = EF_SKY_FOG;
        return 0;
    }
    if (!strcmp(text, "keep")) {
        s->sky = EF_SKY_KEEP;
        return 0;
    }
    if (!strncmp(text, "distance=", 9)) {
        double d;
        if (ef_parse_numbers(text + 9, &d, 1) || !(d > 0))
            return ef_fail(err, "--sky '%s': the distance must be a positive number", text);
        s->sky = EF_SKY_DISTANCE_MODE;
        s->sky_distance = d;
        return 0;
    }
    return ef_fail(err, "--sky '%s' is not fog, keep or distance=D", text);
}

static void sum_tau(const ef_fog_scene *s, const ef_ray *r, double acc[3])
{
    acc[0] = acc[1] = acc[2] = 0.0;
    for (int i = 0; i < s->ncomp; ++i) {
        double t[3];
        s->comp[i].model->tau(&s->comp[i], r, t);
        for (int k = 0; k < 3; ++k)
            acc[k] += t[k];
    }
}

/* exp(-tau) per channel; grey fog (equal taus) needs one exp, not three. */
static void transmit(const double tau[3], double T[3])
{
    T[0] = exp(-tau[0]);
    T[1] = tau[1] == tau[0] ? T[0] : exp(-tau[1]);
    T[2] = tau[2] == tau[0] ? T[0] : tau[2] == tau[1] ? T[1] : exp(-tau[2]);
}

void ef_scene_transmittance(const ef_fog_scene *s, const ef_ray *r, double T[3], double Tinf[3])
{
    double tau[3];
    if (!Tinf) {
        sum_tau(s, r, tau);
        transmit(tau, T);
        return;
    }
    ef_ray far = *r;
    if (s->sky == EF_SKY_DISTANCE_MODE && isfinite(r->dist) && r->dist > 0) {
        /* The background is a shell at sky_distance: "infinity" ends there. */
        const double d = fmax(s->sky_distance, r->dist);
        far.planar = r->planar * (d / r->dist);
        far.dist = d;
    } else {
        far.dist = far.planar = INFINITY;
    }
    sum_tau(s, &far, tau);
    transmit(tau, Tinf);
    if (far.dist == r->dist) {
        memcpy(T, Tinf, 3 * sizeof *T);
        return;
    }
    sum_tau(s, r, tau);
    transmit(tau, T);
}

void ef_composite(const double T[3], const double Tinf[3], const double F[3], int fog_uncovered,
                  double rgb[3], double *alpha)
{
    const double a = alpha ? *alpha : 1.0;
    double cover = 0.0;
    for (int k = 0; k < 3; ++k) {
        /* T = 0 hides the surface entirely, even an infinite or NaN one. */
        rgb[k] = (T[k] > 0.0 ? T[k] * rgb[k] : 0.0) + (1.0 - T[k]) * a * F[k];
        if (fog_uncovered)
            rgb[k] += (1.0 - a) * (1.0 - Tinf[k]) * F[k];
    }
    if (alpha && fog_uncovered) {
        /* One alpha for three channels: the mean coverage of the fog behind. */
        cover = (3.0 - Tinf[0] - Tinf[1] - Tinf[2]) / 3.0;
        *alpha = a + (1.0 - a) * cover;
    }
}
