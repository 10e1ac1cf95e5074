/* Per-pixel outputs of the fog pass (AOVs), written as extra channels of
 * the colour part. Their names are a public interface:
 *   fog       fog.R, fog.G, fog.B, fog.A   the premultiplied fog alone:
 *                                          out.rgb - T in.rgb, out.a - in.a
 *   T         fog_T.R, fog_T.G, fog_T.B    transmittance to the surface
 *   error     fog_error.R, .G, .B          bound (or estimate) of |dT|
 *   P         fog_P.X, fog_P.Y, fog_P.Z    world position minus an origin
 *   distance  fog_distance.Z               true camera distance
 *   light     fog_ambient.R, .G, .B         the components' glow (the fog
 *                                          without lights, out.rgb - T in.rgb)
 *             fog_light.NAME.R, .G, .B     per --light, what it scatters in
 *                                          (alpha S + (1 - alpha) S_far)
 *             fog_light.sky.R, .G, .B      --sky-light's, likewise
 *   lit       fog_lit.NAME                 per --light with a shadow= map, the
 *                                          share of its light that passes the
 *                                          occluders: sum_k S_k / sum_k S_k
 *                                          unshadowed (1 where it adds none)
 * Pure C, no I/O. */
#ifndef EF_AOV_H
#define EF_AOV_H

#include "error.h"
#include "fog.h"
#include "scene.h"

enum {
    EF_AOV_FOG = 1u << 0,
    EF_AOV_T = 1u << 1,
    EF_AOV_ERROR = 1u << 2,
    EF_AOV_P = 1u << 3,
    EF_AOV_DISTANCE = 1u << 4,
    EF_AOV_LIGHT = 1u << 5,
    EF_AOV_LIT = 1u << 6,
};

/* Channels of every AOV together. */
#define EF_AOV_MAX_CHANNELS (14 + 3 + 4 * EF_MAX_LIGHTS + 3)

/* The AOV names as users write them, in table order, comma-separated. */
#define EF_AOV_NAMES "fog, T, error, P, distance, light, lit"

/* Adds the AOVs of a comma list ("fog,T") to *mask; duplicates merge, and
 * empty items are refused. On an unknown name returns -1 with a message
 * that lists the valid ones (what names where the value came from). */
int ef_aov_parse(const char *list, unsigned *mask, const char *what, ef_err *err);

/* The AOV bit of one name, or 0 when there is none. */
unsigned ef_aov_find(const char *name);

/* The channel names of mask, in table order (light's after the rest: the
 * ambient, then one layer per light of s, whose names they point into,
 * then lit's one channel per light of s with a shadow map; s may be NULL:
 * no light layers); returns how many (at most EF_AOV_MAX_CHANNELS). names
 * may be NULL to count. */
int ef_aov_channels(unsigned mask, const ef_fog_scene *s, const char **names);

/* Whether channel index of ef_aov_channels(mask, ...) holds data (a
 * position or a distance), which -d half must leave in float whatever
 * the channel is named (Blender's names differ). */
int ef_aov_channel_data(unsigned mask, int index);

/* The AOV names of mask as a comma list ("fog,T"), into buf. */
void ef_aov_list(unsigned mask, char *buf, size_t len);

/* Where the pass writes the AOVs of one block: planes of w x h floats, one
 * per channel; only those of the AOVs in mask are used. */
typedef struct ef_aov_out {
    unsigned mask;
    double origin[3];         /* subtracted from fog_P (in double) */
    float *fog[4], *T[3], *err[3], *P[3], *dist;
    float *ambient[3], *light[EF_MAX_LIGHTS][3];
    float *lit[EF_MAX_LIGHTS];  /* NULL for a light without a shadow map */
    float *sky[3];              /* fog_light.sky (--sky-light), or NULL */
} ef_aov_out;

/* Points out's planes at planes[i], i in the order ef_aov_channels gives
 * for s (NULL: a scene without lights). */
void ef_aov_bind(ef_aov_out *out, unsigned mask, const ef_fog_scene *s, float *const *planes);

/* Cost and error of the numerical components over many pixels (the
 * surface segment of each fogged pixel), for --stats. */
#define EF_STATS_BINS 256
typedef struct ef_tau_stats {
    double pixels;            /* pixels whose fog was evaluated */
    double evals, cells, dropped;   /* sums over those pixels */
    double evals_max;
    double err_max;           /* max over pixels and channels of info.err (tau) */
    double err_sum, err_sum_lo;     /* sum of the per-pixel max over channels, compensated */
    double over;              /* pixels where the work bound dropped octaves */
    double quad, stat;        /* pixels whose error is an estimate of a quadrature's, or
                               * a statistical one (the rest: bounds; ef_tau_info.kind) */
    double dT_max;            /* max over pixels and channels of T expm1(err), the error AOV */
    /* Log-binned counts (ef_stats_bin) of evaluations per pixel and, when
     * clock_ns is set, of the fog's time per pixel in ns (all components
     * of the pixel, kept in the first component's stats). */
    unsigned evals_hist[EF_STATS_BINS], time_hist[EF_STATS_BINS];
    double time_sum, time_max, timed;
    double time_max_clean;    /* the max over spans whose CPU time covers their wall time */
    double time_max_retimed;  /* the max of re-timed costliest pixels (ef_tau_stats_retimed) */
    /* The caller's monotonic clock and its thread's CPU clock, in ns, or
     * NULL: no timing (the core reads no clock of its own). A pixel's time
     * is its wall time, capped by the CPU time of its span of pixels (so
     * time the thread spent descheduled does not count). */
    double (*clock_ns)(void);
    double (*cpu_ns)(void);
} ef_tau_stats;

/* Adds one pixel's info to s; T is the pixel's transmittance per channel
 * (for the error AOV's |dT|; NULL: not counted). */
void ef_tau_stats_add(ef_tau_stats *s, const ef_tau_info *info, const double *T);
/* Adds one pixel's fog time (ns) to s; clean: its span was not
 * descheduled (its wall time is CPU time). */
void ef_tau_stats_time(ef_tau_stats *s, double ns, int clean);
/* Records the re-timed cost (ns, the least of several timings) of a
 * pixel that was the slowest of its span. */
void ef_tau_stats_retimed(ef_tau_stats *s, double ns);
/* Adds the totals of b to a. */
void ef_tau_stats_merge(ef_tau_stats *a, const ef_tau_stats *b);
/* The bin of value v >= 0: 8 per power of two of v + 1 (a value is within
 * 9 % of its bin's lower edge), the last bin open. */
int ef_stats_bin(double v);
/* The q-quantile (0..1) of a histogram of n values, as its bin's upper
 * edge (so it is never below the true quantile); 0 when n is 0. */
double ef_stats_quantile(const unsigned *hist, double n, double q);

#endif
