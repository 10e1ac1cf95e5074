/* Deep pixels (OpenEXR's "Interpreting OpenEXR Deep Pixels"): tidying,
 * fog as volume samples, and flattening, one pixel at a time. Pure C; the
 * caller owns every buffer.
 *
 * A sample is nch doubles in the layout's channel order followed by two
 * more, its front and back depths as distances along the pixel's ray
 * (EF_DEEP_STRIDE). A sample whose back is not beyond its front is a point
 * sample; otherwise it is a homogeneous slab over [front, back) with
 * optical depth -log(1 - alpha) per alpha channel and colour c / alpha. */
#ifndef EF_DEEP_H
#define EF_DEEP_H

#include "recon.h"
#include "scene.h"

/* Channels a deep part may have (OpenEXR allows more; exrfog refuses). */
#define EF_DEEP_MAX_CH 64
/* Doubles per sample: the channels, then front and back distance. */
#define EF_DEEP_STRIDE(nch) ((nch) + 2)

enum {
    EF_DEEP_COLOR = 0,   /* premultiplied by its alpha channel (alpha[] names it) */
    EF_DEEP_ALPHA,       /* A, AR, AG, AB (and layer.A...) */
    EF_DEEP_Z,           /* Z: written from the front distance */
    EF_DEEP_ZBACK,       /* ZBack: written from the back distance */
    EF_DEEP_COPY         /* unsigned ints (ids): copied, never scaled */
};

typedef struct ef_deep_layout {
    int nch;
    unsigned char role[EF_DEEP_MAX_CH];
    signed char alpha[EF_DEEP_MAX_CH];  /* COLOR: its alpha channel (-1: none) */
    int rgb[3];               /* the colour the fog adds to (-1: absent) */
    int argb[3];              /* the alpha of each of rgb (AR/AG/AB, else A) */
    int a;                    /* A (-1: absent) */
} ef_deep_layout;

/* A growable array of samples (EF_DEEP_STRIDE(nch) doubles each). */
typedef struct ef_deep_buf {
    double *v;
    int n, cap, stride;
    /* scratch the calls that fill this buffer keep between pixels (owned):
     * depths, sort order, split pieces */
    double *bnd;
    int bcap;
    void *ord;
    int ocap;
    double *sv;
    int scap;
    /* the fog pass's: a component's features, and where they cut an interval */
    void *ft;
    int ftcap;
    double *cut;
    int ccap;
    /* with ef_deep_fog.per_light: each fog sample's in-scatter per light
     * (3 per light of the scene, then 3 for the sky light's share of its
     * colour when the scene has one: EF_DEEP_LV(scene) per sample, in
     * sample order, image units) */
    double *lv;
    int lvcap;
    /* lit fog samples: per light of the scene its dense in-scatter along
     * the pixel's ray (struct ef_lit_dense, lit.h), reused between pixels */
    struct ef_lit_dense *dense;
    int ndense;
    /* ef_deep_tidy's refusal: the pieces the split would have made */
    long long pieces;
} ef_deep_buf;

/* The values ef_deep_buf.lv keeps per sample for a scene. */
#define EF_DEEP_LV(scene) (3 * ((scene)->nlight + ((scene)->sky_light != NULL)))

void ef_deep_buf_init(ef_deep_buf *b, int nch);
void ef_deep_buf_free(ef_deep_buf *b);
/* A new sample at the end (zeroed); NULL when out of memory. */
double *ef_deep_buf_push(ef_deep_buf *b);
/* The same, uninitialised: for the caller that fills every value. */
double *ef_deep_buf_push_raw(ef_deep_buf *b);

/* What the fog pass needs per pixel. */
typedef struct ef_deep_fog {
    const ef_fog_scene *scene;
    /* --deep-tol: bound on |dT| when a fog sample is split later, and on
     * the lit colour's change relative to the pixel's light (estimated) */
    double tol;
    double tau_cap;           /* largest optical depth per fog sample (alpha precision) */
    int max_samples;          /* fog samples per pixel, at most */
    int chromatic;            /* write each channel's alpha (AR/AG/AB) */
    int want_err;             /* sum the models' tau error estimates (ef_deep_stats.pix_err) */
    int per_light;            /* keep each sample's light per light (ef_deep_buf.lv) */
} ef_deep_fog;

/* Counters a pixel adds to (the caller sums them). */
typedef struct ef_deep_stats {
    double fog_samples, pixels, capped;   /* capped: pixels that hit max_samples */
    double max_split_est;     /* the largest split-error estimate left in a fog sample */
    /* The last pixel's (reset by each ef_deep_fog_samples, filled when
     * want_err): the fog's tau error estimates summed over its samples. */
    double pix_err[3];
    /* and its lights' in-scatter error estimates, T(0, front) times each
     * sample's, summed (image units; always filled) */
    double pix_light_err[3];
} ef_deep_stats;

/* The split's memory for one pixel (per thread): nested volumes split at
 * each other's boundaries make O(n^2) pieces (6,000 nested samples: 36
 * million), so the pieces are counted before any is made. */
#define EF_DEEP_TIDY_BYTES ((long long) 256 << 20)

/* The most pieces ef_deep_tidy makes of one pixel of stride doubles per
 * sample. */
long long ef_deep_tidy_cap(int stride);

/* Tidies in (n samples, front/back set) into out: every volume split at
 * every other sample's front and back (Beer-Lambert within the slab),
 * coincident samples merged (optical depths add, sources weight by them),
 * sorted by front then back (points first). Returns 0, -1 when out of
 * memory, or -2 (nothing made) when the split would make more pieces than
 * ef_deep_tidy_cap allows: their count is then in out->pieces. out must
 * not be in. */
int ef_deep_tidy(const ef_deep_layout *L, const ef_deep_buf *in, ef_deep_buf *out);

/* The fog along ray r (the pixel's, dist ignored) as volume samples into
 * fog: between 0 and every boundary of the tidy samples in tidy, and
 * behind the last per the scene's sky policy, up to the first sample that
 * is opaque in every fog channel when stop_at_opaque. Each sample's alpha
 * and colour are the exact integrals over its interval (the scene's lights
 * and sky light included: the colour is the ambient and sky share of its
 * alpha plus the lights' in-scatter over it); boundaries are added where
 * an optical depth passes tau_cap, where a light's source jumps or turns
 * (ef_light_cuts), or where the estimated error of a later split passes
 * tol: |dT|, and the lit colour's change over the lights' in-scatter along
 * the pixel's visible ray. Returns 0, or -1 when out of memory. */
int ef_deep_fog_samples(const ef_deep_layout *L, const ef_deep_fog *F, const ef_ray *r,
                        const ef_deep_buf *tidy, int stop_at_opaque, ef_deep_buf *fog,
                        ef_deep_stats *st);

/* Flattens a tidy list front to back ("over" per alpha channel) into
 * out[nch]; Z gets the nearest front (INFINITY without samples), ZBack the
 * farthest back. */
void ef_deep_flatten(const ef_deep_layout *L, const ef_deep_buf *tidy, double *out);

/* ef_deep_flatten of the tidy union of two tidy lists a and b whose
 * samples either coincide (merged) or do not overlap, without building
 * it; Z and ZBack come from a's samples alone (a the input, b the fog:
 * the flattened depth is the render's nearest sample, not the fog's start
 * at the camera). Returns 0, or 1 (out undefined) when a sample of one
 * starts inside a volume of the other: tidy the union then. */
int ef_deep_flatten_pair(const ef_deep_layout *L, const ef_deep_buf *a, const ef_deep_buf *b,
                         double *out);

/* The split rule of one alpha at fraction x of a slab: 1 - (1 - a)^x, stably. */
double ef_deep_split_alpha(double a, double x);

#endif
