/* A deep input's pass (--deep samples | fog | flatten): rows of 16 read,
 * fogged per pixel (src/core/deep.c) and packed on the worker threads,
 * written in order by the calling thread, so memory stays bounded by the
 * rows in flight. */
#define _GNU_SOURCE 1
#include <math.h>
#include <time.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "aov.h"
#include "deep.h"
#include "deep_pass.h"
#include "exr_deep.h"
#include "recon.h"

/* Rows per unit: 16 (a ZIP chunk of the flat output, 16 ZIPS rows of the
 * deep one), or a deep tiled input's tile height when it is a multiple of
 * 16 up to UNIT_MAX, so that no tile is decoded twice. */
#define UNIT_ROWS 16
#define UNIT_MAX 256

/* The output channels and how each comes from an input channel. */
typedef struct plan {
    ef_deep_layout L;         /* in the output's channel order */
    const char *name[EF_DEEP_MAX_CH];
    exr_pixel_type_t type[EF_DEEP_MAX_CH];
    int from[EF_DEEP_MAX_CH]; /* input channel, or -1 (filled below) */
    int from_alpha[EF_DEEP_MAX_CH];   /* -1, or the output alpha copied in (AR from A) */
    int z, zb;                /* output Z / ZBack (-1: none) */
    int in_z, in_zb;          /* input Z / ZBack (-1: none) */
    char *own[3];             /* names made here (AR/AG/AB) */
} plan;

/* The last component of a channel name, and its layer's length. */
static const char *base_of(const char *name, size_t *layer_len)
{
    const char *dot = strrchr(name, '.');
    *layer_len = dot ? (size_t) (dot - name) : 0;
    return dot ? dot + 1 : name;
}

static int find_name(const plan *P, const char *name)
{
    for (int c = 0; c < P->L.nch; ++c)
        if (!strcmp(P->name[c], name))
            return c;
    return -1;
}

/* The alpha channel of colour channel c (same layer: R -> AR else A, and
 * so on; else the base layer's), or -1. */
static int alpha_for(const plan *P, int c)
{
    size_t ll;
    const char *b = base_of(P->name[c], &ll);
    const char *want = !strcmp(b, "R") ? "AR" : !strcmp(b, "G") ? "AG" : !strcmp(b, "B") ? "AB" : NULL;
    char buf[300];
    for (int pass = 0; pass < 2; ++pass) {
        const size_t l = pass == 0 ? ll : 0;
        if (pass == 1 && ll == 0)
            break;
        if (want) {
            snprintf(buf, sizeof buf, "%.*s%s%s", (int) l, P->name[c], l ? "." : "", want);
            const int i = find_name(P, buf);
            if (i >= 0)
                return i;
        }
        snprintf(buf, sizeof buf, "%.*s%sA", (int) l, P->name[c], l ? "." : "");
        const int i = find_name(P, buf);
        if (i >= 0)
            return i;
    }
    return -1;
}

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(const char *const *) a, *(const char *const *) b);
}

/* Adds output channel name (a static or the input's string). */
static void add_channel(plan *P, const char *name, exr_pixel_type_t t, int from)
{
    const int c = P->L.nch++;
    P->name[c] = name;
    P->type[c] = t;
    P->from[c] = from;
    P->from_alpha[c] = -1;
}

/* Sorts the output channels by name (the file's order) and fills the
 * layout's roles from the names. */
static int finish_plan(plan *P, const ef_channel_plan *cp, ef_err *err)
{
    /* sort (name, type, from) together through an index */
    const int n = P->L.nch;
    const char *names[EF_DEEP_MAX_CH];
    memcpy(names, P->name, sizeof names);
    qsort(names, (size_t) n, sizeof *names, cmp_str);
    plan Q = *P;   /* own[] travels with the copy */
    for (int i = 0; i < n; ++i) {
        int j = 0;
        while (strcmp(P->name[j], names[i]))
            ++j;
        Q.name[i] = P->name[j];
        Q.type[i] = P->type[j];
        Q.from[i] = P->from[j];
    }
    *P = Q;
    ef_deep_layout *L = &P->L;
    P->z = P->zb = -1;
    for (int c = 0; c < n; ++c) {
        size_t ll;
        const char *b = base_of(P->name[c], &ll);
        L->alpha[c] = -1;
        if (ll == 0 && !strcmp(b, "Z"))
            L->role[c] = EF_DEEP_Z, P->z = c;
        else if (ll == 0 && !strcmp(b, "ZBack"))
            L->role[c] = EF_DEEP_ZBACK, P->zb = c;
        else if (!strcmp(b, "A") || !strcmp(b, "AR") || !strcmp(b, "AG") || !strcmp(b, "AB"))
            L->role[c] = EF_DEEP_ALPHA;
        else if (P->type[c] == EXR_PIXEL_UINT)
            L->role[c] = EF_DEEP_COPY;
        else
            L->role[c] = EF_DEEP_COLOR;
    }
    for (int c = 0; c < n; ++c)
        if (L->role[c] == EF_DEEP_COLOR)
            L->alpha[c] = (signed char) alpha_for(P, c);
    for (int k = 0; k < 3; ++k) {
        /* the colour by its index in the part (the plan's names carry a
         * multi-part file's part name as their layer) */
        L->rgb[k] = -1;
        for (int c = 0; cp && c < n; ++c)
            if (P->from[c] == cp->rgb[k].index)
                L->rgb[k] = c;
        if (!cp)
            L->rgb[k] = find_name(P, (const char *[]){ "R", "G", "B" }[k]);
        L->argb[k] = L->rgb[k] >= 0 ? L->alpha[L->rgb[k]] : -1;
    }
    {
        char buf[300];
        size_t ll = 0;
        if (L->rgb[0] >= 0)
            base_of(P->name[L->rgb[0]], &ll);
        snprintf(buf, sizeof buf, "%.*s%sA", (int) ll, L->rgb[0] >= 0 ? P->name[L->rgb[0]] : "",
                 ll ? "." : "");
        L->a = find_name(P, buf);
    }
    if (L->a < 0 || L->rgb[0] < 0 || L->rgb[1] < 0 || L->rgb[2] < 0)
        return ef_fail(err, "the deep part has no colour with alpha (R, G, B and A of one layer): "
                            "exrfog fogs deep samples through their alpha");
    /* AR/AG/AB the fog adds to a file with A only: from A */
    for (int c = 0; c < n; ++c)
        if (P->from[c] < 0 && L->role[c] == EF_DEEP_ALPHA)
            P->from_alpha[c] = L->a;
    return 0;
}

/* Whether the scene's optical depth differs between channels: probed on
 * rays from the camera in 26 directions to 4 lengths (a component's own
 * colour changes what the fog adds, not its alpha). A chromatic fog the
 * probes miss still gets its colour right per channel; only its alpha is
 * then A alone, the mean (as for consumers that read A only). */
static int scene_chromatic(const ef_fog_scene *s, const double org[3])
{
    static const double len[4] = { 1, 30, 1000, INFINITY };
    for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dz = -1; dz <= 1; ++dz) {
                if (!dx && !dy && !dz)
                    continue;
                const double n = sqrt((double) (dx * dx + dy * dy + dz * dz));
                for (int l = 0; l < 4; ++l) {
                    ef_ray r = { { dx / n, dy / n, dz / n }, len[l], len[l],
                                 { org[0], org[1], org[2] } };
                    for (int i = 0; i < s->ncomp; ++i) {
                        double t[3];
                        s->comp[i].model->tau(&s->comp[i], &r, t);
                        if (t[0] != t[1] || t[1] != t[2])
                            return 1;
                    }
                }
            }
    return 0;
}

typedef struct unit {
    int y, n;
    ef_deep_packed pk[UNIT_MAX];
    int npk;
    int failed;
    ef_err err;
} unit;

/* The flat output's channels (--deep flatten): the plan's and the AOVs',
 * sorted by name together. src >= 0: plan channel; else AOV -1 - src (in
 * ef_aov_channels order). */
typedef struct flat_out {
    int n;
    const char *name[EF_DEEP_IO_MAX_CH];
    exr_pixel_type_t type[EF_DEEP_IO_MAX_CH];
    int src[EF_DEEP_IO_MAX_CH];
} flat_out;

typedef struct shared {
    const ef_deep_req *q;
    const ef_deep_in *d;
    const plan *P;
    flat_out FO;
    unsigned aov;             /* AOVs of the flat output (0: none) */
    ef_deep_fog fog;
    ef_deep_fog bare;         /* --aov lit: the fog with every shadow map left out */
    unit *units;
    int nunits;
    _Atomic int next;
    pthread_mutex_t lock;
    ef_deep_stats st;
    double samples_in;
    double max_in;
} shared;

typedef struct worker {
    shared *S;
    ef_deep_rows rows;
    ef_deep_buf in, tidy, fog, all, out;
    ef_deep_buf ta, tb;       /* --aov: the input's and the fog's samples, recoloured */
    ef_deep_buf bare;         /* --aov lit: the fog samples without shadow maps */
    double *flat;
    size_t flatcap;           /* bytes */
    uint32_t *counts;
    double *ov;
    size_t ovcap;             /* bytes */
    ef_deep_stats st;
    double samples_in, max_in;
} worker;


/* One pixel: its input samples into w->in (output layout, distances);
 * returns 0, or -1 with a message. */
static int load_pixel(worker *w, const ef_deep_rows *R, size_t pi, double k, int x, int y,
                      ef_err *err)
{
    const shared *S = w->S;
    const plan *P = S->P;
    const int nin = S->d->nch, nch = P->L.nch;
    w->in.n = 0;
    const uint64_t s0 = R->start[pi], s1 = R->start[pi + 1];
    for (uint64_t s = s0; s < s1; ++s) {
        const double *iv = R->v + (size_t) s * (size_t) nin;
        double *o = ef_deep_buf_push(&w->in);
        if (!o)
            return ef_fail(err, "out of memory");
        for (int c = 0; c < nch; ++c)
            if (P->from[c] >= 0)
                o[c] = iv[P->from[c]];
        for (int c = 0; c < nch; ++c)
            if (P->from_alpha[c] >= 0)
                o[c] = o[P->from_alpha[c]];
        const double z = P->in_z >= 0 ? iv[P->in_z] : NAN;
        double zb = P->in_zb >= 0 ? iv[P->in_zb] : z;
        if (!(z >= 0) || !(z < INFINITY))
            return ef_fail(err, "pixel (%d, %d) has a sample at Z = %g; deep depths must be "
                                "finite and not negative (the file is corrupt, or its Z is not "
                                "a distance)", x, y, z);
        if (zb != zb)
            return ef_fail(err, "pixel (%d, %d) has a sample at Z = %g whose ZBack is %g; "
                                "deep depths must be numbers (the file is corrupt)", x, y, z, zb);
        /* an infinite alpha makes every rule's arithmetic NaN (inf - inf) */
        for (int c = 0; c < nch; ++c)
            if (P->L.role[c] == EF_DEEP_ALPHA && !isfinite(o[c]))
                return ef_fail(err, "pixel (%d, %d) has a sample at Z = %g whose %s is %g; "
                                    "deep alphas must be finite, 0 to 1 (the file is corrupt)",
                               x, y, z, P->name[c], o[c]);
        if (!(zb < INFINITY))
            zb = z;
        o[nch] = z * k;
        o[nch + 1] = zb > z ? zb * k : z * k;
    }
    if (s1 - s0 > w->max_in)
        w->max_in = (double) (s1 - s0);
    w->samples_in += (double) (s1 - s0);
    return 0;
}

/* The samples of b into the row's output values (Z and ZBack back to the
 * file's depth: distance / k). */
static int append_out(worker *w, const ef_deep_buf *b, double k, size_t *nv)
{
    const plan *P = w->S->P;
    const int nch = P->L.nch;
    if (ef_deep_grow((void **) &w->ov, &w->ovcap,
                     (*nv + (size_t) b->n) * (size_t) nch * sizeof *w->ov))
        return -1;
    for (int i = 0; i < b->n; ++i) {
        const double *s = b->v + (size_t) i * (size_t) b->stride;
        double *o = w->ov + (*nv + (size_t) i) * (size_t) nch;
        memcpy(o, s, (size_t) nch * sizeof *o);
        if (P->z >= 0)
            o[P->z] = s[nch] / k;
        if (P->zb >= 0)
            o[P->zb] = s[nch + 1] / k;
    }
    *nv += (size_t) b->n;
    return 0;
}

/* The tidy union of the tidy lists a and b into w->out, when b's samples
 * hold every boundary of a's (the fog's do): b is split nowhere, a's
 * volumes are split at b's boundaries and merged with what they share. */
static int union_tidy(worker *w, const ef_deep_buf *a, const ef_deep_buf *b, ef_err *err)
{
    const ef_deep_layout *L = &w->S->P->L;
    w->all.n = 0;
    const int nch = L->nch, SS = a->stride;
    for (int i = 0, j = 0; i < a->n || j < b->n;) {
        /* merged by (front, back), so that the tidy below finds them in
         * order and sorts nothing */
        const double *p = i < a->n ? a->v + (size_t) i * (size_t) SS : NULL;
        const double *q = j < b->n ? b->v + (size_t) j * (size_t) SS : NULL;
        const int take_p =
            p && (!q || p[nch] < q[nch] || (p[nch] == q[nch] && p[nch + 1] <= q[nch + 1]));
        double *d = ef_deep_buf_push_raw(&w->all);
        if (!d)
            return ef_fail(err, "out of memory");
        memcpy(d, take_p ? p : q, (size_t) SS * sizeof *d);
        if (take_p)
            ++i;
        else
            ++j;
    }
    const int rc = ef_deep_tidy(L, &w->all, &w->out);
    if (rc == -2)
        return ef_fail(err, "the fog's samples and the input's overlap into %lld pieces (at most "
                            "%lld)", w->out.pieces, ef_deep_tidy_cap(w->out.stride));
    if (rc)
        return ef_fail(err, "out of memory");
    return 0;
}

/* The flatten of the union of a and b (union_tidy's lists) into out, its
 * Z and ZBack a's alone (ef_deep_flatten_pair: the input's nearest
 * sample, not the fog's start at the camera). */
static int flatten_union(worker *w, const ef_deep_buf *a, const ef_deep_buf *b, double *out,
                         ef_err *err)
{
    const ef_deep_layout *L = &w->S->P->L;
    if (!ef_deep_flatten_pair(L, a, b, out))
        return 0;
    if (union_tidy(w, a, b, err))
        return -1;
    ef_deep_flatten(L, &w->out, out);
    double own[EF_DEEP_MAX_CH];
    ef_deep_flatten(L, a, own);
    for (int c = 0; c < L->nch; ++c)
        if (L->role[c] == EF_DEEP_Z || L->role[c] == EF_DEEP_ZBACK)
            out[c] = own[c];
    return 0;
}

/* The fog of pixel (x, y) into w->out (samples, fog) or flat (nch
 * values). */
static int fog_pixel(worker *w, const ef_ray *r, int x, int y, int mode, double *flat,
                     ef_err *err)
{
    const shared *S = w->S;
    const ef_deep_layout *L = &S->P->L;
    const int rc = ef_deep_tidy(L, &w->in, &w->tidy);
    if (rc == -2)
        return ef_fail(err,
                       "pixel (%d, %d): its %d deep samples overlap so much that splitting "
                       "them at each other's fronts and backs (the OpenEXR tidy rule) would "
                       "make %lld pieces, past the %lld one pixel may hold (%lld MiB a "
                       "thread); render volumes as samples that do not overlap, or merge "
                       "the overlapping ones before exrfog",
                       x, y, w->in.n, w->tidy.pieces, ef_deep_tidy_cap(w->tidy.stride),
                       EF_DEEP_TIDY_BYTES >> 20);
    if (rc ||
        ef_deep_fog_samples(L, &S->fog, r, &w->tidy, mode != EF_DEEP_MODE_FOG, &w->fog, &w->st))
        return ef_fail(err, "out of memory");
    if (mode == EF_DEEP_MODE_FOG)
        return 0;
    /* flatten: the fog has no boundary the input lacks, so the union
     * needs no split, and is composited as it is walked */
    if (mode == EF_DEEP_MODE_FLATTEN)
        return flatten_union(w, &w->tidy, &w->fog, flat, err);
    return union_tidy(w, &w->tidy, &w->fog, err);
}

/* --deep-grey-alpha: the tidy list b (front to back) made exact for
 * readers of A alone. Each sample's alphas become their least, and its
 * colour is scaled by e^-R_k, R_k the optical depth channel k has in front
 * beyond the least (summed over the samples in front), so that "over" with
 * one alpha gives every channel what per-channel alphas give:
 * c_k T_k(front) = (c_k e^-R_k) T_least(front). A later holdout or merge
 * with another element sees the least alpha only. */
static void grey_alpha(const ef_deep_layout *L, ef_deep_buf *b)
{
    double R[3] = { 0, 0, 0 };
    for (int i = 0; i < b->n; ++i) {
        double *s = b->v + (size_t) i * (size_t) b->stride;
        double tau[3], lo = INFINITY;
        for (int k = 0; k < 3; ++k) {
            const int ai = L->argb[k] >= 0 ? L->argb[k] : L->a;
            const double a = ai >= 0 ? s[ai] : 0;
            tau[k] = a >= 1 ? INFINITY : -log1p(-(a > 0 ? a : 0));
            lo = fmin(lo, tau[k]);
        }
        for (int k = 0; k < 3; ++k)
            if (L->rgb[k] >= 0)
                s[L->rgb[k]] *= isfinite(R[k]) ? exp(-R[k]) : 0;
        const double A = isinf(lo) ? 1 : -expm1(-lo);
        for (int k = 0; k < 3; ++k) {
            if (L->argb[k] >= 0)
                s[L->argb[k]] = A;
            R[k] += isinf(lo) ? 0 : tau[k] - lo;
        }
        if (L->a >= 0)
            s[L->a] = A;
    }
}

/* Copies src into dst. */
static int copy_buf(ef_deep_buf *dst, const ef_deep_buf *src)
{
    dst->n = 0;
    for (int i = 0; i < src->n; ++i) {
        double *d = ef_deep_buf_push_raw(dst);
        if (!d)
            return -1;
        memcpy(d, src->v + (size_t) i * (size_t) src->stride, (size_t) src->stride * sizeof *d);
    }
    return 0;
}

/* Light j's layer of one pixel: the flatten of w->ta (the input, its
 * colour zeroed) with the fog samples of fog carrying light j's
 * in-scatter (fog->lv) as their colour; j = nlight: the sky light's. */
static int light_layer(worker *w, const ef_deep_buf *fog, int j, double out[3], ef_err *err)
{
    const ef_deep_layout *L = &w->S->P->L;
    const int nv = EF_DEEP_LV(w->S->q->scene);
    double o[EF_DEEP_MAX_CH];
    if (copy_buf(&w->tb, fog))
        return ef_fail(err, "out of memory");
    for (int i = 0; i < w->tb.n; ++i)
        for (int k = 0; k < 3; ++k)
            w->tb.v[(size_t) i * (size_t) w->tb.stride + (size_t) L->rgb[k]] =
                fog->lv[(size_t) i * (size_t) nv + 3 * (size_t) j + (size_t) k];
    if (flatten_union(w, &w->ta, &w->tb, o, err))
        return -1;
    for (int k = 0; k < 3; ++k)
        out[k] = o[L->rgb[k]];
    return 0;
}

/* The AOVs of one flattened pixel (--deep flatten --aov), in
 * ef_aov_channels order, from its tidy input, its fog samples and its
 * flatten (distances, before Z goes back to the file's depth):
 *   fog       the flatten less the input's light as the fog attenuates it
 *             (the flatten with the fog's colour zeroed); A: the flatten's
 *             alpha less the input's own
 *   T         the fog's transmittance to the input, weighted by coverage:
 *             the input's alpha attenuated by the fog (each sample's alpha
 *             as its colour, the fog's zeroed) over the input's own alpha;
 *             where the input covers nothing, the fog's own transmittance
 *             (1 without fog behind, as a sky pixel under --sky keep)
 *   error     T expm1(e), e the models' tau error estimates summed along
 *             the pixel's fog samples (at most 1), plus the lights'
 *             in-scatter error estimates (each sample's times T to it)
 *   P, distance  the nearest sample's front (inf where there is none),
 *             as the flattened Z
 * For a pixel of one opaque point sample these are the flat image's AOVs. */
static int pixel_aovs(worker *w, const ef_ray *r, const double *flat, double *aov, ef_err *err)
{
    const shared *S = w->S;
    const ef_deep_layout *L = &S->P->L;
    const int nch = L->nch;
    double in[EF_DEEP_MAX_CH], att[EF_DEEP_MAX_CH], cov[EF_DEEP_MAX_CH], fog[EF_DEEP_MAX_CH];
    ef_deep_flatten(L, &w->tidy, in);
    if (copy_buf(&w->ta, &w->tidy) || copy_buf(&w->tb, &w->fog))
        return ef_fail(err, "out of memory");
    for (int i = 0; i < w->tb.n; ++i)
        for (int k = 0; k < 3; ++k)
            w->tb.v[(size_t) i * (size_t) w->tb.stride + (size_t) L->rgb[k]] = 0;
    if (flatten_union(w, &w->ta, &w->tb, att, err))
        return -1;
    for (int i = 0; i < w->ta.n; ++i) {
        double *s = w->ta.v + (size_t) i * (size_t) w->ta.stride;
        for (int k = 0; k < 3; ++k)
            s[L->rgb[k]] = s[L->argb[k] >= 0 ? L->argb[k] : L->a];
    }
    if (flatten_union(w, &w->ta, &w->tb, cov, err))
        return -1;
    ef_deep_flatten(L, &w->fog, fog);
    double T[3];
    for (int k = 0; k < 3; ++k) {
        const int ai = L->argb[k] >= 0 ? L->argb[k] : L->a;
        const double c = in[ai];
        const double t = c > 0 ? cov[L->rgb[k]] / c : 1 - fog[ai];
        T[k] = t > 1 ? 1 : t > 0 ? t : 0;
    }
    const double front = w->tidy.n > 0 ? w->tidy.v[nch] : INFINITY;
    int n = 0;
    if (S->aov & EF_AOV_FOG) {
        for (int k = 0; k < 3; ++k)
            aov[n++] = flat[L->rgb[k]] - att[L->rgb[k]];
        aov[n++] = flat[L->a] - in[L->a];
    }
    for (int k = 0; k < 3 && (S->aov & EF_AOV_T); ++k)
        aov[n++] = T[k];
    for (int k = 0; k < 3 && (S->aov & EF_AOV_ERROR); ++k) {
        const double e = w->st.pix_err[k], b = e > 0 ? T[k] * expm1(e) : 0;
        aov[n++] = (b < 1 ? b : 1) + w->st.pix_light_err[k];
    }
    for (int k = 0; k < 3 && (S->aov & EF_AOV_P); ++k)
        aov[n++] = isfinite(front) ? (r->org[k] - S->q->aov_origin[k]) + r->dir[k] * front
                   : r->dir[k] == 0 ? 0 : r->dir[k] > 0 ? INFINITY : -INFINITY;
    if (S->aov & EF_AOV_DISTANCE)
        aov[n++] = front;
    if (!(S->aov & (EF_AOV_LIGHT | EF_AOV_LIT)))
        return 0;
    /* each light's layer: the flatten of the input with its colour zeroed
     * and the fog samples with that light's in-scatter as theirs; the
     * ambient what the fog adds beyond them */
    const int nl = S->q->scene->nlight;
    /* the lights' layers, then the sky light's (its share of the samples'
     * colour) */
    const int sky = (S->aov & EF_AOV_LIGHT) && S->q->scene->sky_light;
    double lay[EF_MAX_LIGHTS + 1][3];
    if (copy_buf(&w->ta, &w->tidy))
        return ef_fail(err, "out of memory");
    for (int i = 0; i < w->ta.n; ++i)
        for (int k = 0; k < 3; ++k)
            w->ta.v[(size_t) i * (size_t) w->ta.stride + (size_t) L->rgb[k]] = 0;
    for (int j = 0; j < nl + sky; ++j)
        if (light_layer(w, &w->fog, j, lay[j], err))
            return -1;
    if (S->aov & EF_AOV_LIGHT) {
        for (int k = 0; k < 3; ++k) {
            double amb = flat[L->rgb[k]] - att[L->rgb[k]];
            for (int j = 0; j < nl + sky; ++j)
                amb -= lay[j][k];
            aov[n++] = amb;
        }
        for (int j = 0; j < nl + sky; ++j)
            for (int k = 0; k < 3; ++k)
                aov[n++] = lay[j][k];
    }
    if (S->aov & EF_AOV_LIT) {
        /* a shadowed light's share past its occluders: its layer's
         * channel sum over the same from the fog without the maps (the
         * flat path's definition) */
        if (ef_deep_fog_samples(L, &S->bare, r, &w->tidy, 1, &w->bare, NULL))
            return ef_fail(err, "out of memory");
        for (int j = 0; j < nl; ++j) {
            if (!S->q->scene->light[j].shadow)
                continue;
            double u[3];
            if (light_layer(w, &w->bare, j, u, err))
                return -1;
            const double num = lay[j][0] + lay[j][1] + lay[j][2], den = u[0] + u[1] + u[2];
            aov[n++] = den > 0 && isfinite(den) ? num / den : 1.0;
        }
    }
    return 0;
}

/* Pixel (x, y), index pi of the rows read, through the whole per-pixel
 * fog: its ray r, its samples in, the fog samples and their union (or,
 * flattening, o: the flat pixel, and av: its AOVs). Returns 0, or -1 with
 * a message. */
static int fog_one(worker *w, size_t pi, int x, int y, ef_ray *r, double *o, double *av,
                   ef_err *err)
{
    const shared *S = w->S;
    ef_reconstruct(S->q->cam, S->q->conv, x, y, 1.0, r);
    return load_pixel(w, &w->rows, pi, r->dist, x, y, err) ||
                   fog_pixel(w, r, x, y, S->q->mode, o, err) ||
                   (o && S->aov && pixel_aovs(w, r, o, av, err))
               ? -1 : 0;
}

/* Samples times channels a unit decodes at once when it can read fewer
 * rows (128 MiB of doubles a thread): past it, chunk by chunk. */
#define BATCH_VALUES (1ull << 24)

/* Rows from y (at most n, whole chunks) into r: all n where they hold at
 * most BATCH_VALUES values or a chunk holds all n, else the first chunk's
 * rows alone (up to the reader's hard cap, refused with the figure past
 * it). *chunkwise (set here once the rows of a unit pass the budget) goes
 * straight to a chunk at a time for the rest of the unit, not reading
 * what it would drop. A chain of 20,000 overlapping samples a pixel in
 * ZIPS then takes one row at a time, not a unit's 16. */
static int read_batch(const ef_deep_in *d, int y, int n, ef_deep_rows *r, int *chunkwise,
                      ef_err *err)
{
    const int chunk = d->tiled ? n : d->lines - (y - d->y0) % d->lines;
    int rc = -2;
    if (!*chunkwise || chunk >= n) {
        r->cap = chunk < n ? BATCH_VALUES : 0;
        rc = ef_deep_read_rows(d, y, n, r, err);
    }
    if (rc == -2 && chunk < n) {
        *chunkwise = 1;
        r->cap = 0;
        rc = ef_deep_read_rows(d, y, chunk, r, err);
    }
    return rc ? -1 : 0;
}

static void do_unit(worker *w, unit *u)
{
    shared *S = w->S;
    const ef_deep_req *q = S->q;
    const ef_deep_in *d = S->d;
    const plan *P = S->P;
    const int nch = P->L.nch, W = d->w, mode = q->mode;
    int chunkwise = 0;
    if (read_batch(d, u->y, u->n, &w->rows, &chunkwise, &u->err)) {
        u->failed = 1;
        return;
    }
    const int nfo = S->FO.n;
    if (mode == EF_DEEP_MODE_FLATTEN &&
        ef_deep_grow((void **) &w->flat, &w->flatcap,
                     (size_t) W * (size_t) u->n * (size_t) nfo * sizeof *w->flat)) {
        ef_fail(&u->err, "out of memory");
        u->failed = 1;
        return;
    }
    if (!w->counts && !(w->counts = malloc((size_t) W * sizeof *w->counts))) {
        ef_fail(&u->err, "out of memory");
        u->failed = 1;
        return;
    }
    u->npk = 0;
    for (int j = 0; j < u->n; ++j) {
        const int y = u->y + j;
        if (y >= w->rows.y + w->rows.n &&
            read_batch(d, y, u->y + u->n - y, &w->rows, &chunkwise, &u->err)) {
            u->failed = 1;
            return;
        }
        const size_t row0 = (size_t) (y - w->rows.y) * (size_t) W;
        size_t nv = 0;
        for (int i = 0; i < W; ++i) {
            if (q->cancel && atomic_load_explicit(q->cancel, memory_order_relaxed)) {
                ef_fail(&u->err, "cancelled");
                u->failed = 1;
                return;
            }
            ef_ray r;
            double px[EF_DEEP_MAX_CH], av[EF_AOV_MAX_CHANNELS];
            double *o = mode == EF_DEEP_MODE_FLATTEN ? px : NULL;
            if (fog_one(w, row0 + (size_t) i, d->x0 + i, y, &r, o, av, &u->err)) {
                u->failed = 1;
                return;
            }
            const double k = r.dist;
            if (o) {
                if (P->z >= 0)
                    o[P->z] = isfinite(o[P->z]) ? o[P->z] / k : INFINITY;
                if (P->zb >= 0)
                    o[P->zb] = isfinite(o[P->zb]) ? o[P->zb] / k : INFINITY;
                double *f = w->flat + ((size_t) j * (size_t) W + (size_t) i) * (size_t) nfo;
                for (int c = 0; c < nfo; ++c)
                    f[c] = S->FO.src[c] >= 0 ? o[S->FO.src[c]] : av[-1 - S->FO.src[c]];
                continue;
            }
            ef_deep_buf *b = mode == EF_DEEP_MODE_FOG ? &w->fog : &w->out;
            if (q->grey && S->fog.chromatic)
                grey_alpha(&P->L, b);
            w->counts[i] = (uint32_t) b->n;
            if (append_out(w, b, k, &nv)) {
                ef_fail(&u->err, "out of memory");
                u->failed = 1;
                return;
            }
        }
        if (mode != EF_DEEP_MODE_FLATTEN) {
            ef_deep_packed *pk = &u->pk[u->npk++];
            pk->y = y;
            if (ef_deep_pack_row(nch, P->type, W, w->counts, w->ov, q->zip_level, pk)) {
                ef_fail(&u->err, "out of memory packing row %d", y);
                u->failed = 1;
                return;
            }
        }
    }
    for (int j = 0; mode == EF_DEEP_MODE_FLATTEN && j < u->n; j += UNIT_ROWS) {
        /* one ZIP chunk per 16 rows */
        const int n = u->n - j < UNIT_ROWS ? u->n - j : UNIT_ROWS;
        ef_deep_packed *pk = &u->pk[u->npk++];
        pk->y = u->y + j;
        if (ef_flat_pack_rows(nfo, S->FO.type, W, n,
                              w->flat + (size_t) j * (size_t) W * (size_t) nfo, q->zip_level, pk)) {
            ef_fail(&u->err, "out of memory packing rows %d-%d", pk->y, pk->y + n - 1);
            u->failed = 1;
            return;
        }
    }
}

/* A clock's time in ns (the thread's CPU time, or the wall's). */
static double clock_ns(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (double) ts.tv_sec * 1e9 + (double) ts.tv_nsec;
}

/* The fog's thread time per pixel, from up to 64 pixels of each of up to
 * 16 rows spread over the image (bit-reversed, so a probe stopped early
 * has still seen its height), until half a second of wall time has
 * passed (checked between pixels). Only the fog is timed (the pixels' samples in, the fog
 * samples, their union or flattening and the AOVs), not the decoding of
 * the rows. The worker's statistics are left as they were. Returns 0 when
 * nothing could be timed (the pass then reports what failed). */
static double probe_deep(worker *w, int *npx)
{
    shared *S = w->S;
    const ef_deep_in *d = S->d;
    const int W = d->w, step = W > 64 ? W / 64 : 1;
    const ef_deep_stats st = w->st;
    const double sin = w->samples_in, mxin = w->max_in, w0 = clock_ns(CLOCK_MONOTONIC);
    double ns = 0;
    int n = 0;
    ef_err err;
    for (int k = 0; k < 16; ++k) {
        const int rk = (k & 1) << 3 | (k & 2) << 1 | (k & 4) >> 1 | (k & 8) >> 3;
        const int y = d->y0 + (int) ((2 * (long) rk + 1) * d->h / 32);
        if (y >= d->y0 + d->h || ef_deep_read_rows(d, y, 1, &w->rows, &err))
            break;
        for (int i = 0; i < W; i += step) {
            if (clock_ns(CLOCK_MONOTONIC) - w0 > 0.5e9 ||
                (S->q->cancel && atomic_load_explicit(S->q->cancel, memory_order_relaxed)))
                goto done;
            const double t = clock_ns(CLOCK_THREAD_CPUTIME_ID);
            ef_ray r;
            double px[EF_DEEP_MAX_CH], av[EF_AOV_MAX_CHANNELS];
            if (fog_one(w, (size_t) i, d->x0 + i, y, &r,
                        S->q->mode == EF_DEEP_MODE_FLATTEN ? px : NULL, av, &err))
                goto done;
            ns += clock_ns(CLOCK_THREAD_CPUTIME_ID) - t;
            ++n;
        }
    }
done:
    w->st = st;
    w->samples_in = sin;
    w->max_in = mxin;
    *npx = n;
    return n > 0 ? ns * 1e-9 / n : 0;
}

static void *work(void *arg)
{
    worker *w = arg;
    shared *S = w->S;
    for (;;) {
        const int i = atomic_fetch_add(&S->next, 1);
        if (i >= S->nunits)
            break;
        do_unit(w, &S->units[i]);
        if (S->units[i].failed)
            break;
    }
    return NULL;
}

static void worker_free(worker *w)
{
    ef_deep_rows_free(&w->rows);
    ef_deep_buf_free(&w->in);
    ef_deep_buf_free(&w->tidy);
    ef_deep_buf_free(&w->fog);
    ef_deep_buf_free(&w->all);
    ef_deep_buf_free(&w->out);
    ef_deep_buf_free(&w->ta);
    ef_deep_buf_free(&w->tb);
    ef_deep_buf_free(&w->bare);
    free(w->flat);
    free(w->counts);
    free(w->ov);
}

/* Builds the output plan for the mode. */
static int make_plan(const ef_deep_req *q, const ef_deep_in *d, int chromatic, plan *P, ef_err *err)
{
    memset(P, 0, sizeof *P);
    P->in_z = P->in_zb = -1;
    for (int c = 0; c < d->nch; ++c) {
        if (!strcmp(d->name[c], "Z"))
            P->in_z = c;
        else if (!strcmp(d->name[c], "ZBack"))
            P->in_zb = c;
    }
    if (P->in_z < 0)
        return ef_fail(err, "the deep part has no Z channel: every deep sample needs its depth");
    const ef_channel_plan *cp = q->cplan;
    if (q->mode == EF_DEEP_MODE_FOG) {
        /* a fog-only element: colour and alpha in half (tau is capped at 2
         * per sample for half alpha), depths in float */
        static const char *const rgba[] = { "R", "G", "B", "A", "AR", "AG", "AB" };
        for (int i = 0; i < (chromatic ? 7 : 4); ++i)
            add_channel(P, rgba[i], EXR_PIXEL_HALF, -1);
        add_channel(P, "Z", EXR_PIXEL_FLOAT, -1);
        add_channel(P, "ZBack", EXR_PIXEL_FLOAT, -1);
        return finish_plan(P, NULL, err);
    }
    for (int c = 0; c < d->nch; ++c) {
        if (q->mode == EF_DEEP_MODE_FLATTEN && c == P->in_zb)
            continue;
        add_channel(P, d->name[c], d->type[c], c);
    }
    if (q->mode == EF_DEEP_MODE_SAMPLES && P->in_zb < 0)
        add_channel(P, "ZBack", EXR_PIXEL_FLOAT, -1);
    if (chromatic) {
        /* AR/AG/AB beside the colour's A, when the file has only A */
        static const char *const ab[] = { "AR", "AG", "AB" };
        size_t ll;
        const char *r0 = d->name[cp->rgb[0].index];   /* as the part names it */
        base_of(r0, &ll);
        for (int k = 0; k < 3; ++k) {
            char buf[300];
            snprintf(buf, sizeof buf, "%.*s%s%s", (int) ll, r0, ll ? "." : "", ab[k]);
            int have = 0;
            for (int c = 0; c < P->L.nch; ++c)
                have |= !strcmp(P->name[c], buf);
            if (have)
                continue;
            char *s = strdup(buf);
            if (!s)
                return ef_fail(err, "out of memory");
            P->own[k] = s;
            add_channel(P, s, EXR_PIXEL_HALF, -1);
        }
    }
    return finish_plan(P, cp, err);
}

/* -d on the output's channels, as the flat stream applies it: TYPE for
 * half and float channels (half never demotes Z, ZBack or other data),
 * then NAME=TYPE overrides; uint stays. */
static void apply_types(plan *P, const ef_deep_req *q)
{
    for (int c = 0; c < P->L.nch; ++c) {
        int t = P->type[c];
        if (q->pixel_type >= 0 && t != EXR_PIXEL_UINT &&
            !(q->pixel_type == EXR_PIXEL_HALF && ef_data_channel(P->name[c])))
            t = q->pixel_type;
        P->type[c] = (exr_pixel_type_t) ef_exr_named_type(q->chan_type_name, q->chan_type,
                                                          q->nchan_type, P->name[c], t);
    }
}

/* The flat output's channels: the plan's, and under --aov the AOVs'
 * (FLOAT, then -d as for every channel: half does not demote data
 * channels such as fog_P and fog_distance), sorted by name together. */
static int make_flat_out(const ef_deep_req *q, const plan *P, flat_out *FO, ef_err *err)
{
    const int naov = q->mode == EF_DEEP_MODE_FLATTEN ? q->naov : 0;
    if (P->L.nch + naov > EF_DEEP_IO_MAX_CH)
        return ef_fail(err, "too many channels with the AOVs (%d, at most %d)", P->L.nch + naov,
                       EF_DEEP_IO_MAX_CH);
    const char *nm[EF_DEEP_IO_MAX_CH];
    int src[EF_DEEP_IO_MAX_CH];
    exr_pixel_type_t ty[EF_DEEP_IO_MAX_CH];
    int n = 0;
    for (int c = 0; c < P->L.nch; ++c, ++n) {
        nm[n] = P->name[c];
        ty[n] = P->type[c];
        src[n] = c;
    }
    for (int a = 0; a < naov; ++a, ++n) {
        nm[n] = q->aov_names[a];
        int t = EXR_PIXEL_FLOAT;
        if (q->pixel_type >= 0 &&
            !(q->pixel_type == EXR_PIXEL_HALF && ef_aov_channel_data(q->aov, a)))
            t = q->pixel_type;
        ty[n] = (exr_pixel_type_t) ef_exr_named_type(q->chan_type_name, q->chan_type,
                                                     q->nchan_type, nm[n], t);
        src[n] = -1 - a;
    }
    /* insertion sort by name: a few dozen channels */
    for (int i = 1; i < n; ++i)
        for (int j = i; j > 0 && strcmp(nm[j - 1], nm[j]) > 0; --j) {
            const char *tn = nm[j];
            nm[j] = nm[j - 1];
            nm[j - 1] = tn;
            const exr_pixel_type_t tt = ty[j];
            ty[j] = ty[j - 1];
            ty[j - 1] = tt;
            const int ts = src[j];
            src[j] = src[j - 1];
            src[j - 1] = ts;
        }
    for (int i = 1; i < n; ++i)
        if (!strcmp(nm[i - 1], nm[i]))
            return ef_fail(err, "the AOV channel %s is already in the deep part (choose other "
                                "AOVs, or rename the channel)", nm[i]);
    FO->n = n;
    memcpy(FO->name, nm, sizeof nm);
    memcpy(FO->type, ty, sizeof ty);
    memcpy(FO->src, src, sizeof src);
    return 0;
}

int ef_deep_run(const ef_deep_req *q, ef_deep_result *res, ef_err *err)
{
    memset(res, 0, sizeof *res);
    if (q->naov && (q->aov & (EF_AOV_LIGHT | EF_AOV_LIT)) &&   /* (the CLI refuses these first) */
        (q->mode != EF_DEEP_MODE_FLATTEN ||
         (q->scene->nlight == 0 && ((q->aov & EF_AOV_LIT) || !q->scene->sky_light))))
        return ef_fail(err, "--aov light and lit on deep input take --deep flatten and --light "
                            "(light: or --sky-light)");
    ef_deep_in d;
    if (ef_deep_in_open(q->in, q->part, &d, err))
        return -1;
    const int chromatic = scene_chromatic(q->scene, q->cam->pos);
    plan *P = calloc(1, sizeof *P);
    if (!P)
        return ef_fail(err, "out of memory");
    int rc = make_plan(q, &d, chromatic, P, err);
    if (!rc)
        apply_types(P, q);
    /* Z must be a distance along the ray (affine): planar or radial */
    if (!rc) {
        ef_ray r1, r2;
        const int cx = d.x0 + d.w / 2, cy = d.y0 + d.h / 2;
        ef_reconstruct(q->cam, q->conv, cx, cy, 1.0, &r1);
        ef_reconstruct(q->cam, q->conv, cx, cy, 2.0, &r2);
        if (!(fabs(r2.dist - 2 * r1.dist) <= 1e-9 * r2.dist) || !(r1.dist > 0))
            rc = ef_fail(err, "deep Z is a distance along each pixel's ray (the OpenEXR deep "
                              "rules); --depth-mode must be planar (the default) or radial");
    }
    shared S;
    memset(&S, 0, sizeof S);
    S.q = q;
    S.d = &d;
    S.P = P;
    S.fog.scene = q->scene;
    S.fog.tol = q->tol;
    S.fog.tau_cap = P->type[P->L.a] == EXR_PIXEL_HALF ? 2.0 : 10.0;
    S.fog.max_samples = 4096;
    if (q->mode == EF_DEEP_MODE_FLATTEN) {
        /* a flat result is exact whatever the fog's sample count: no
         * boundaries beyond the input's (nothing splits them later) */
        S.fog.tau_cap = INFINITY;
        S.fog.tol = 1;
    }
    S.fog.chromatic = chromatic;
    S.aov = q->mode == EF_DEEP_MODE_FLATTEN && q->naov ? q->aov : 0;
    S.fog.want_err = (S.aov & EF_AOV_ERROR) != 0;
    S.fog.per_light = (S.aov & (EF_AOV_LIGHT | EF_AOV_LIT)) != 0;
    ef_fog_scene *bare = NULL;
    if (!rc && (S.aov & EF_AOV_LIT)) {
        /* the same scene without its shadow maps (a shallow copy: the
         * components and maps stay the scene's, read only) */
        if (!(bare = malloc(sizeof *bare))) {
            rc = ef_fail(err, "out of memory");
        } else {
            memcpy(bare, q->scene, sizeof *bare);
            for (int j = 0; j < bare->nlight; ++j)
                bare->light[j].shadow = NULL;
            S.bare = S.fog;
            S.bare.scene = bare;
        }
    }
    if (!rc)
        rc = make_flat_out(q, P, &S.FO, err);
    res->tau_cap = S.fog.tau_cap;
    res->chromatic = chromatic;
    const char *names[EF_DEEP_MAX_CH];
    for (int c = 0; c < P->L.nch; ++c)
        names[c] = P->name[c];
    ef_deep_out out;
    memset(&out, 0, sizeof out);
    int began = 0;
    if (!rc) {
        const int flat = q->mode == EF_DEEP_MODE_FLATTEN;
        /* samples and flatten keep the input's other parts beside the
         * fogged one (not in a foreign deliverable's intermediate); a fog
         * element is its one part */
        const int others = q->mode != EF_DEEP_MODE_FOG && q->keep_parts;
        rc = ef_deep_out_begin(&out, q->out_path, q->out_fd, q->in, q->part, !flat,
                               flat ? S.FO.n : P->L.nch, flat ? S.FO.name : names,
                               flat ? S.FO.type : P->type, q->history, q->params,
                               S.aov && q->has_aov_origin ? q->aov_origin : NULL, others, err);
        began = 1;
    }
    const int nthreads = q->threads > 0 ? q->threads : 1;
    const int batch = 2 * nthreads;
    S.units = calloc((size_t) batch, sizeof *S.units);
    worker *W = calloc((size_t) nthreads, sizeof *W);
    if (!rc && (!S.units || !W))
        rc = ef_fail(err, "out of memory");
    for (int t = 0; t < nthreads && W; ++t) {
        W[t].S = &S;
        ef_deep_buf_init(&W[t].in, P->L.nch);
        ef_deep_buf_init(&W[t].tidy, P->L.nch);
        ef_deep_buf_init(&W[t].fog, P->L.nch);
        ef_deep_buf_init(&W[t].all, P->L.nch);
        ef_deep_buf_init(&W[t].out, P->L.nch);
        ef_deep_buf_init(&W[t].ta, P->L.nch);
        ef_deep_buf_init(&W[t].tb, P->L.nch);
        ef_deep_buf_init(&W[t].bare, P->L.nch);
    }
    if (!rc && q->predicted) {
        int n = 0;
        const double per_px = probe_deep(&W[0], &n);
        if (n > 0)
            q->predicted(q->progress_user, per_px * (double) d.w * (double) d.h, n);
    }
    const int urows = d.tiled && d.th % UNIT_ROWS == 0 && d.th <= UNIT_MAX ? d.th : UNIT_ROWS;
    for (int y0 = d.y0; !rc && y0 < d.y0 + d.h;) {
        /* one batch of units, fogged on the threads, written in order */
        S.nunits = 0;
        for (int i = 0; i < batch && y0 < d.y0 + d.h; ++i) {
            unit *u = &S.units[S.nunits++];
            u->y = y0;
            u->n = d.y0 + d.h - y0 < urows ? d.y0 + d.h - y0 : urows;
            u->failed = 0;
            u->npk = 0;
            y0 += u->n;
        }
        atomic_store(&S.next, 0);
        pthread_t th[64];
        int started = 0;
        for (int t = 1; t < nthreads && t < 64; ++t)
            if (pthread_create(&th[t], NULL, work, &W[t]) == 0)
                started = t;
            else
                break;
        work(&W[0]);
        for (int t = 1; t <= started; ++t)
            pthread_join(th[t], NULL);
        for (int i = 0; i < S.nunits && !rc; ++i) {
            unit *u = &S.units[i];
            if (u->failed) {
                *err = u->err;
                rc = -1;
                break;
            }
            for (int k = 0; k < u->npk && !rc; ++k)
                rc = ef_deep_out_write(&out, &u->pk[k], err);
            if (!rc && q->progress)
                q->progress(q->progress_user, (long) u->n * d.w);
        }
        if (!rc && q->cancel && atomic_load(q->cancel))
            rc = ef_fail(err, "cancelled");
    }
    for (int i = 0; S.units && i < batch; ++i)
        for (int k = 0; k < UNIT_MAX; ++k)
            ef_deep_packed_free(&S.units[i].pk[k]);
    free(S.units);
    for (int t = 0; t < nthreads && W; ++t) {
        res->fog_samples += W[t].st.fog_samples;
        res->pixels += W[t].st.pixels;
        res->capped += W[t].st.capped;
        res->samples_in += W[t].samples_in;
        if (W[t].max_in > res->max_in)
            res->max_in = W[t].max_in;
        if (W[t].st.max_split_est > res->max_split_est)
            res->max_split_est = W[t].st.max_split_est;
        worker_free(&W[t]);
    }
    free(W);
    if (!rc)
        rc = ef_deep_out_end(&out, err);
    else if (began)
        ef_deep_out_abort(&out);
    res->max_out = out.max_count;
    for (int k = 0; k < 3; ++k)
        free(P->own[k]);
    free(P);
    free(bare);
    return rc;
}

int ef_deep_census(const ef_exr_file *f, int part, double *pixels, double *samples,
                   double *max_px, ef_err *err)
{
    ef_deep_in d;
    ef_deep_rows r;
    memset(&r, 0, sizeof r);
    *pixels = *samples = *max_px = 0;
    if (ef_deep_in_open(f, part, &d, err))
        return -1;
    int rc = 0, chunkwise = 0;
    for (int y = d.y0; y < d.y0 + d.h && !rc; y += r.n) {
        const int n = d.y0 + d.h - y < UNIT_ROWS ? d.y0 + d.h - y : UNIT_ROWS;
        rc = read_batch(&d, y, n, &r, &chunkwise, err);
        for (size_t i = 0; !rc && i < (size_t) r.n * (size_t) d.w; ++i)
            if (r.count[i] > *max_px)
                *max_px = r.count[i];
        if (!rc)
            *samples += (double) r.total;
    }
    *pixels = (double) d.w * d.h;
    ef_deep_rows_free(&r);
    return rc;
}
