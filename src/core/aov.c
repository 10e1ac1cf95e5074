#include "aov.h"
#include "sky_light.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* data: positions and distances, which half precision would destroy */
static const struct {
    const char *name;
    unsigned bit;
    int n, data;
    const char *ch[4];
} aovs[] = {
    { "fog", EF_AOV_FOG, 4, 0, { "fog.R", "fog.G", "fog.B", "fog.A" } },
    { "T", EF_AOV_T, 3, 0, { "fog_T.R", "fog_T.G", "fog_T.B" } },
    { "error", EF_AOV_ERROR, 3, 0, { "fog_error.R", "fog_error.G", "fog_error.B" } },
    { "P", EF_AOV_P, 3, 1, { "fog_P.X", "fog_P.Y", "fog_P.Z" } },
    { "distance", EF_AOV_DISTANCE, 1, 1, { "fog_distance.Z" } },
    { "light", EF_AOV_LIGHT, 3, 0, { "fog_ambient.R", "fog_ambient.G", "fog_ambient.B" } },
    { "lit", EF_AOV_LIT, 0, 0, { NULL } },   /* per shadowed light only */
};
#define NAOV ((int) (sizeof aovs / sizeof aovs[0]))

unsigned ef_aov_find(const char *name)
{
    for (int i = 0; i < NAOV; ++i)
        if (!strcmp(aovs[i].name, name))
            return aovs[i].bit;
    return 0;
}

int ef_aov_parse(const char *list, unsigned *mask, const char *what, ef_err *err)
{
    const char *s = list;
    for (;;) {
        const char *comma = strchr(s, ',');
        const size_t len = comma ? (size_t) (comma - s) : strlen(s);
        char name[32];
        if (len == 0)
            return ef_fail(err, "%s '%s' has an empty name (a comma list of %s)", what, list,
                           EF_AOV_NAMES);
        if (len >= sizeof name)
            return ef_fail(err, "%s '%s': '%.*s' is not an AOV (valid: %s)", what, list,
                           (int) (len > 40 ? 40 : len), s, EF_AOV_NAMES);
        memcpy(name, s, len);
        name[len] = '\0';
        const unsigned bit = ef_aov_find(name);
        if (!bit)
            return ef_fail(err, "%s '%s': '%s' is not an AOV (valid: %s)", what, list, name,
                           EF_AOV_NAMES);
        *mask |= bit;
        if (!comma)
            return 0;
        s = comma + 1;
    }
}

int ef_aov_channels(unsigned mask, const ef_fog_scene *s, const char **names)
{
    int n = 0;
    for (int i = 0; i < NAOV; ++i)
        if (mask & aovs[i].bit)
            for (int k = 0; k < aovs[i].n; ++k, ++n)
                if (names)
                    names[n] = aovs[i].ch[k];
    if ((mask & EF_AOV_LIGHT) && s)
        for (int j = 0; j < s->nlight; ++j)
            for (int k = 0; k < 3; ++k, ++n)
                if (names)
                    names[n] = s->light[j].aov[k];
    if ((mask & EF_AOV_LIGHT) && s && s->sky_light)
        for (int k = 0; k < 3; ++k, ++n)
            if (names)
                names[n] = s->sky_light->aov[k];
    if ((mask & EF_AOV_LIT) && s)
        for (int j = 0; j < s->nlight; ++j)
            if (s->light[j].shadow) {
                if (names)
                    names[n] = s->light[j].lit_aov;
                ++n;
            }
    return n;
}

int ef_aov_channel_data(unsigned mask, int index)
{
    int n = 0;
    for (int i = 0; i < NAOV; ++i)
        if (mask & aovs[i].bit) {
            if (index < n + aovs[i].n)
                return aovs[i].data;
            n += aovs[i].n;
        }
    return 0;   /* the light layers */
}

void ef_aov_list(unsigned mask, char *buf, size_t len)
{
    size_t at = 0;
    if (len)
        buf[0] = '\0';
    for (int i = 0; i < NAOV; ++i)
        if (mask & aovs[i].bit) {
            int n = snprintf(buf + at, len - at, "%s%s", at ? "," : "", aovs[i].name);
            if (n < 0 || (size_t) n >= len - at)
                return;
            at += (size_t) n;
        }
}

void ef_aov_bind(ef_aov_out *out, unsigned mask, const ef_fog_scene *s, float *const *planes)
{
    const int nlight = s ? s->nlight : 0;
    float **slot[NAOV][4] = {
        { &out->fog[0], &out->fog[1], &out->fog[2], &out->fog[3] },
        { &out->T[0], &out->T[1], &out->T[2], NULL },
        { &out->err[0], &out->err[1], &out->err[2], NULL },
        { &out->P[0], &out->P[1], &out->P[2], NULL },
        { &out->dist, NULL, NULL, NULL },
        { &out->ambient[0], &out->ambient[1], &out->ambient[2], NULL },
    };
    int n = 0;
    out->mask = mask;
    for (int i = 0; i < NAOV; ++i)
        for (int k = 0; k < aovs[i].n; ++k)
            *slot[i][k] = mask & aovs[i].bit ? planes[n++] : NULL;
    for (int j = 0; j < EF_MAX_LIGHTS; ++j)
        for (int k = 0; k < 3; ++k)
            out->light[j][k] = (mask & EF_AOV_LIGHT) && j < nlight ? planes[n++] : NULL;
    for (int k = 0; k < 3; ++k)
        out->sky[k] = (mask & EF_AOV_LIGHT) && s && s->sky_light ? planes[n++] : NULL;
    for (int j = 0; j < EF_MAX_LIGHTS; ++j)
        out->lit[j] = (mask & EF_AOV_LIT) && j < nlight && s->light[j].shadow ? planes[n++] : NULL;
}

/* s += v, keeping the rounding error in *lo (Neumaier), so the total does
 * not depend on the order partial sums are merged in, to double rounding. */
static void add_comp(double *s, double *lo, double v)
{
    const double t = *s + v;
    if (!isfinite(t)) {
        *s = t;
        return;
    }
    if (fabs(*s) >= fabs(v))
        *lo += (*s - t) + v;
    else
        *lo += (v - t) + *s;
    *s = t;
}

int ef_stats_bin(double v)
{
    if (!(v > 0))
        return 0;
    const double b = floor(8 * log2(v + 1));
    return b >= EF_STATS_BINS - 1 ? EF_STATS_BINS - 1 : (int) b;
}

double ef_stats_quantile(const unsigned *hist, double n, double q)
{
    if (!(n > 0))
        return 0;
    double seen = 0;
    for (int b = 0; b < EF_STATS_BINS; ++b) {
        seen += hist[b];
        if (seen >= q * n)
            return exp2((b + 1) / 8.0) - 1;
    }
    return INFINITY;
}

void ef_tau_stats_add(ef_tau_stats *s, const ef_tau_info *info, const double *T)
{
    const double e = fmax(info->err[0], fmax(info->err[1], info->err[2]));
    s->pixels += 1.0;
    s->evals += info->evals;
    s->cells += info->cells;
    s->dropped += info->dropped;
    s->over += info->over;
    s->quad += info->kind == EF_ERR_QUAD;
    s->stat += info->kind == EF_ERR_STAT;
    s->evals_hist[ef_stats_bin(info->evals)]++;
    if (info->evals > s->evals_max)
        s->evals_max = info->evals;
    if (e > s->err_max)
        s->err_max = e;
    for (int k = 0; T && k < 3; ++k) {
        const double d = info->err[k] > 0 ? fmin(1.0, T[k] * expm1(info->err[k])) : 0;
        if (d > s->dT_max)
            s->dT_max = d;
    }
    add_comp(&s->err_sum, &s->err_sum_lo, e);
}

void ef_tau_stats_time(ef_tau_stats *s, double ns, int clean)
{
    s->timed += 1.0;
    s->time_sum += ns;
    if (ns > s->time_max)
        s->time_max = ns;
    if (clean && ns > s->time_max_clean)
        s->time_max_clean = ns;
    s->time_hist[ef_stats_bin(ns)]++;
}

void ef_tau_stats_retimed(ef_tau_stats *s, double ns)
{
    if (ns > s->time_max_retimed)
        s->time_max_retimed = ns;
}

void ef_tau_stats_merge(ef_tau_stats *a, const ef_tau_stats *b)
{
    a->pixels += b->pixels;
    a->evals += b->evals;
    a->cells += b->cells;
    a->dropped += b->dropped;
    a->over += b->over;
    a->quad += b->quad;
    a->stat += b->stat;
    a->evals_max = fmax(a->evals_max, b->evals_max);
    a->err_max = fmax(a->err_max, b->err_max);
    a->dT_max = fmax(a->dT_max, b->dT_max);
    a->timed += b->timed;
    a->time_sum += b->time_sum;
    a->time_max = fmax(a->time_max, b->time_max);
    a->time_max_clean = fmax(a->time_max_clean, b->time_max_clean);
    a->time_max_retimed = fmax(a->time_max_retimed, b->time_max_retimed);
    for (int i = 0; i < EF_STATS_BINS; ++i) {
        a->evals_hist[i] += b->evals_hist[i];
        a->time_hist[i] += b->time_hist[i];
    }
    add_comp(&a->err_sum, &a->err_sum_lo, b->err_sum);
    add_comp(&a->err_sum, &a->err_sum_lo, b->err_sum_lo);
}
