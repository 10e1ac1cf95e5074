/* Sky light: a lat-long environment convolved with the phase functions
 * (sky_light.h). */
#include "sky_light.h"
#include "light.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

/* e1, the world axis most across up made perpendicular to it, and
 * e2 = up x e1. */
static void frame_of(const double up[3], double e1[3], double e2[3]);

void ef_sky_frame(const double up[3], double e1[3], double e2[3])
{
    frame_of(up, e1, e2);
}

static void frame_of(const double up[3], double e1[3], double e2[3])
{
    int a = 0;
    for (int i = 1; i < 3; ++i)
        if (fabs(up[i]) < fabs(up[a]) - 1e-12)
            a = i;
    double n = 0;
    for (int i = 0; i < 3; ++i) {
        e1[i] = (i == a) - up[a] * up[i];
        n += e1[i] * e1[i];
    }
    n = sqrt(n);
    for (int i = 0; i < 3; ++i)
        e1[i] /= n;
    e2[0] = up[1] * e1[2] - up[2] * e1[1];
    e2[1] = up[2] * e1[0] - up[0] * e1[2];
    e2[2] = up[0] * e1[1] - up[1] * e1[0];
}

void ef_sky_light_dir(const ef_sky_light *k, const double up[3], double x, double y, int w, int h,
                      double d[3])
{
    double e1[3], e2[3];
    frame_of(up, e1, e2);
    const double th = PI * y / h, ph = PI - 2 * PI * x / w + k->rotate;
    const double st = sin(th), ct = cos(th), sp = sin(ph), cp = cos(ph);
    for (int i = 0; i < 3; ++i)
        d[i] = st * (cp * e1[i] + sp * e2[i]) + ct * up[i];
}

/* ------------------------------------------------------------ averaging */

/* Source texel i's overlap with [a, b), over b - a. */
static double overlap(int i, double a, double b)
{
    const double lo = i > a ? i : a, hi = i + 1 < b ? i + 1 : b;
    return hi > lo ? (hi - lo) / (b - a) : 0;
}

/* One source row (src_w texels per channel) reduced to w columns by box
 * overlap, into rows[c * src_h + y][0..w) (non-light values count 0). */
static void horiz_row(const float *const row[3], int src_w, int src_h, int y, int w,
                      double *rows)
{
    const double sx = (double) src_w / w;
    for (int X = 0; X < w; ++X) {
        const double a = X * sx, b = (X + 1) * sx;
        double acc[3] = { 0, 0, 0 };
        for (int i = (int) floor(a); i < (int) ceil(b) && i < src_w; ++i) {
            const double wt = overlap(i, a, b);
            for (int c = 0; c < 3; ++c) {
                const float v = row[c][i];
                acc[c] += wt * (isfinite(v) && v > 0 ? v : 0);   /* not light: 0 */
            }
        }
        for (int c = 0; c < 3; ++c)
            rows[((size_t) c * (size_t) src_h + (size_t) y) * (size_t) w + (size_t) X] = acc[c];
    }
}

/* The reduced rows (horiz_row's, src_h of them) averaged to h rows,
 * weighted by their solid angle (sin theta at the source row's centre):
 * out[3][w * h]. */
static void vert_rows(const double *rows, int src_h, int w, int h, float *out[3])
{
    const double sy = (double) src_h / h;
    for (int Y = 0; Y < h; ++Y) {
        const double a = Y * sy, b = (Y + 1) * sy;
        for (int X = 0; X < w; ++X) {
            double acc[3] = { 0, 0, 0 }, ws = 0;
            for (int i = (int) floor(a); i < (int) ceil(b) && i < src_h; ++i) {
                const double wt = overlap(i, a, b) * sin(PI * (i + 0.5) / src_h);
                ws += wt;
                for (int c = 0; c < 3; ++c)
                    acc[c] += wt * rows[((size_t) c * (size_t) src_h + (size_t) i) * (size_t) w +
                                        (size_t) X];
            }
            for (int c = 0; c < 3; ++c)
                out[c][(size_t) Y * (size_t) w + (size_t) X] = (float) (ws > 0 ? acc[c] / ws : 0);
        }
    }
}

/* ------------------------------------------------------------------ FFT */

/* In place, n a power of two, with tw[k] = e^(-2 pi i k / n) for k < n / 2
 * (twr, twi); inverse: the conjugate transform (no 1/n). */
static void fft(double *re, double *im, int n, const double *twr, const double *twi, int inverse)
{
    for (int i = 1, j = 0; i < n; ++i) {
        int bit = n >> 1;
        for (; j & bit; bit >>= 1)
            j ^= bit;
        j ^= bit;
        if (i < j) {
            double t = re[i];
            re[i] = re[j];
            re[j] = t;
            t = im[i];
            im[i] = im[j];
            im[j] = t;
        }
    }
    for (int len = 2; len <= n; len <<= 1) {
        const int step = n / len;
        for (int k = 0; k < len / 2; ++k) {
            const double wr = twr[k * step], wi = inverse ? -twi[k * step] : twi[k * step];
            for (int i = k; i < n; i += len) {
                const int j = i + len / 2;
                const double xr = re[j] * wr - im[j] * wi, xi = re[j] * wi + im[j] * wr;
                re[j] = re[i] - xr;
                im[j] = im[i] - xi;
                re[i] += xr;
                im[i] += xi;
            }
        }
    }
}

/* The grid size a phase needs: 3 pi / N at most 1.35 times its lobe's
 * width 1 - |g| (Rayleigh's 1), a power of two from 64 to 256; 1 for
 * iso. Measured against known transforms and a texel-by-texel sum
 * (tests/unit/test_sky_light.c): a few 1e-4 relative, up to 3e-3 near a sharp
 * lobe. */
static int grid_for(int phase, double g)
{
    if (phase == EF_PHASE_ISO)
        return 1;
    const double lobe = phase == EF_PHASE_RAYLEIGH ? 1 : 1 - fabs(g);
    int n = 64;
    while (n < 256 && 3 * PI / n > 1.35 * lobe)
        n *= 2;
    return n;
}

/* C for one phase on an N x 2N grid of the map (avg: the map averaged to
 * that grid). */
static int convolve(ef_sky_conv *cv, float *const avg[3], int w, int h)
{
    const size_t n = (size_t) w * (size_t) h;
    double *Lr = malloc(3 * n * sizeof *Lr), *Li = malloc(3 * n * sizeof *Li);
    double *Ar = calloc(3 * n, sizeof *Ar), *Ai = calloc(3 * n, sizeof *Ai);
    double *kr = malloc((size_t) w * sizeof *kr), *ki = malloc((size_t) w * sizeof *ki);
    double *st = malloc((size_t) h * sizeof *st), *ct = malloc((size_t) h * sizeof *ct);
    double *dom = malloc((size_t) h * sizeof *dom);
    double *twr = malloc((size_t) w / 2 * sizeof *twr), *twi = malloc((size_t) w / 2 * sizeof *twi);
    double *cosx = malloc((size_t) w * sizeof *cosx);
    int ok = Lr && Li && Ar && Ai && kr && ki && st && ct && dom && twr && twi && cosx;
    for (int c = 0; ok && c < 3; ++c)
        ok = (cv->c[c] = malloc(n * sizeof(float))) != NULL;
    if (ok) {
        for (int k = 0; k < w / 2; ++k) {
            twr[k] = cos(2 * PI * k / w);
            twi[k] = -sin(2 * PI * k / w);
        }
        for (int x = 0; x < w; ++x)
            cosx[x] = cos(2 * PI * x / w);
        for (int y = 0; y < h; ++y) {
            st[y] = sin(PI * (y + 0.5) / h);
            ct[y] = cos(PI * (y + 0.5) / h);
            dom[y] = (cos(PI * y / h) - cos(PI * (y + 1) / h)) * 2 * PI / w;
        }
        /* every row's spectrum per channel */
        for (int c = 0; c < 3; ++c)
            for (int y = 0; y < h; ++y) {
                double *r = Lr + ((size_t) c * h + (size_t) y) * (size_t) w,
                       *i = Li + ((size_t) c * h + (size_t) y) * (size_t) w;
                for (int x = 0; x < w; ++x) {
                    r[x] = avg[c][(size_t) y * (size_t) w + (size_t) x];
                    i[x] = 0;
                }
                fft(r, i, w, twr, twi, 0);
            }
        /* the phase between rows a and b depends on the azimuth difference
         * only, and is symmetric in a and b: one real spectrum per pair */
        for (int a = 0; a < h; ++a)
            for (int b = a; b < h; ++b) {
                for (int x = 0; x < w; ++x) {
                    const double cg = st[a] * st[b] * cosx[x] + ct[a] * ct[b];
                    kr[x] = ef_phase_eval(cv->phase, cv->g, cg > 1 ? 1 : cg < -1 ? -1 : cg);
                    ki[x] = 0;
                }
                fft(kr, ki, w, twr, twi, 0);
                for (int pass = 0; pass < 1 + (b != a); ++pass) {
                    const int o = pass ? b : a, s = pass ? a : b;   /* output row, source row */
                    for (int c = 0; c < 3; ++c) {
                        double *ar = Ar + ((size_t) c * h + (size_t) o) * (size_t) w,
                               *ai = Ai + ((size_t) c * h + (size_t) o) * (size_t) w;
                        const double *lr = Lr + ((size_t) c * h + (size_t) s) * (size_t) w,
                                     *li = Li + ((size_t) c * h + (size_t) s) * (size_t) w;
                        for (int f = 0; f < w; ++f) {
                            ar[f] += dom[s] * kr[f] * lr[f];
                            ai[f] += dom[s] * kr[f] * li[f];
                        }
                    }
                }
            }
        for (int c = 0; c < 3; ++c)
            for (int y = 0; y < h; ++y) {
                double *r = Ar + ((size_t) c * h + (size_t) y) * (size_t) w,
                       *i = Ai + ((size_t) c * h + (size_t) y) * (size_t) w;
                fft(r, i, w, twr, twi, 1);
                for (int x = 0; x < w; ++x)
                    cv->c[c][(size_t) y * (size_t) w + (size_t) x] = (float) fmax(r[x] / w, 0);
            }
    }
    free(Lr);
    free(Li);
    free(Ar);
    free(Ai);
    free(kr);
    free(ki);
    free(st);
    free(ct);
    free(dom);
    free(twr);
    free(twi);
    free(cosx);
    return ok ? 0 : -1;
}

ef_sky_light *ef_sky_light_build(const ef_env_src *src, double rotate_deg, double intensity,
                                 const int *phases, const double *g, int n, ef_err *err)
{
    if (!(src->w >= 2 && src->h >= 1)) {
        ef_fail(err, "the sky light's map is %d x %d: too small for a lat-long environment",
                src->w, src->h);
        return NULL;
    }
    ef_sky_light *k = calloc(1, sizeof *k);
    if (!k) {
        ef_fail(err, "out of memory for the sky light");
        return NULL;
    }
    atomic_init(&k->refs, 1);
    snprintf(k->path, sizeof k->path, "%s", src->path ? src->path : "");
    k->rotate = rotate_deg * PI / 180;
    k->intensity = intensity;
    k->src_w = src->w;
    k->src_h = src->h;
    for (int c = 0; c < 3; ++c)
        snprintf(k->aov[c], sizeof k->aov[c], "fog_light.sky.%c", "RGB"[c]);
    /* the distinct phases, and each one's grid */
    for (int i = 0; i < n && k->nconv < EF_SKY_MAX_PHASES; ++i) {
        int seen = 0;
        for (int j = 0; j < k->nconv; ++j)
            seen |= k->conv[j].phase == phases[i] && k->conv[j].g == g[i];
        if (seen)
            continue;
        ef_sky_conv *cv = &k->conv[k->nconv++];
        cv->phase = phases[i];
        cv->g = g[i];
        const int N = grid_for(phases[i], g[i]);
        cv->h = N;
        cv->w = N == 1 ? 1 : 2 * N;
    }
    /* One pass over the source's rows (a file streams them): each row
     * reduced to every grid's columns, then each grid's rows averaged. */
    double *rows[EF_SKY_MAX_PHASES] = { NULL }, *erows = NULL;
    float *line = NULL;
    int bad = 0, failed_row = 0;
    for (int j = 0; j < k->nconv; ++j)
        bad |= !(rows[j] = malloc((size_t) k->conv[j].w * (size_t) src->h * 3 * sizeof **rows));
    bad |= !(erows = malloc((size_t) EF_SKY_ENV_W * (size_t) src->h * 3 * sizeof *erows));
    if (!src->rgb[0])
        bad |= !(line = malloc((size_t) src->w * 3 * sizeof *line));
    for (int y = 0; !bad && y < src->h; ++y) {
        const float *row[3];
        if (src->rgb[0]) {
            for (int c = 0; c < 3; ++c)
                row[c] = src->rgb[c] + (size_t) y * (size_t) src->w;
        } else {
            float *const out[3] = { line, line + src->w, line + 2 * (size_t) src->w };
            if (src->row(src->user, y, out)) {
                bad = failed_row = 1;
                break;
            }
            for (int c = 0; c < 3; ++c)
                row[c] = out[c];
        }
        for (int j = 0; j < k->nconv; ++j)
            horiz_row(row, src->w, src->h, y, k->conv[j].w, rows[j]);
        horiz_row(row, src->w, src->h, y, EF_SKY_ENV_W, erows);
    }
    free(line);
    for (int c = 0; !bad && c < 3; ++c)
        bad |= !(k->env[c] = malloc((size_t) EF_SKY_ENV_W * EF_SKY_ENV_H * sizeof(float)));
    if (!bad)
        vert_rows(erows, src->h, EF_SKY_ENV_W, EF_SKY_ENV_H, k->env);
    free(erows);
    for (int j = 0; !bad && j < k->nconv; ++j) {
        ef_sky_conv *cv = &k->conv[j];
        float *avg[3] = { NULL, NULL, NULL };
        for (int c = 0; c < 3; ++c)
            bad |= !(avg[c] = malloc((size_t) cv->w * (size_t) cv->h * sizeof(float)));
        if (!bad)
            vert_rows(rows[j], src->h, cv->w, cv->h, avg);
        if (!bad && cv->h == 1) {
            /* iso: 1 / (4 pi) times the integral, which the average
             * weighted by solid angle is over 4 pi */
            for (int c = 0; c < 3; ++c) {
                cv->c[c] = malloc(sizeof(float));
                bad |= !cv->c[c];
                if (cv->c[c])
                    cv->c[c][0] = avg[c][0];
            }
        } else if (!bad) {
            bad = convolve(cv, avg, cv->w, cv->h);
        }
        for (int c = 0; c < 3; ++c)
            free(avg[c]);
    }
    for (int j = 0; j < k->nconv; ++j)
        free(rows[j]);
    if (bad) {
        ef_sky_light_unref(k);
        if (failed_row)
            ef_fail(err, "cannot read the environment's colour (damaged or out of memory)");
        else
            ef_fail(err, "out of memory for the sky light's convolution");
        return NULL;
    }
    return k;
}

void ef_sky_light_ref(ef_sky_light *k)
{
    if (k)
        atomic_fetch_add(&k->refs, 1);
}

void ef_sky_light_unref(ef_sky_light *k)
{
    if (!k || atomic_fetch_sub(&k->refs, 1) != 1)
        return;
    for (int i = 0; i < k->nconv; ++i)
        for (int c = 0; c < 3; ++c)
            free(k->conv[i].c[c]);
    for (int c = 0; c < 3; ++c)
        free(k->env[c]);
    free(k);
}

/* A lat-long grid of w x h texels per channel (rows top-down, k's
 * orientation) bilinear at direction u, times k's intensity, into out. */
static void grid_at(const ef_sky_light *k, float *const c3[3], int w, int h, const double up[3],
                    const double u[3], double out[3])
{
    double e1[3], e2[3];
    frame_of(up, e1, e2);
    const double cu = u[0] * up[0] + u[1] * up[1] + u[2] * up[2];
    const double a = u[0] * e1[0] + u[1] * e1[1] + u[2] * e1[2];
    const double b = u[0] * e2[0] + u[1] * e2[1] + u[2] * e2[2];
    const double th = acos(cu > 1 ? 1 : cu < -1 ? -1 : cu), ph = atan2(b, a) - k->rotate;
    double fx = (PI - ph) / (2 * PI);
    fx -= floor(fx);
    const double x = fx * w - 0.5, y = th / PI * h - 0.5;
    const int x0 = (int) floor(x), y0 = (int) floor(y);
    const double tx = x - x0, ty = y - y0;
    for (int c = 0; c < 3; ++c) {
        double v = 0;
        for (int dy = 0; dy < 2; ++dy) {
            int yy = y0 + dy;
            yy = yy < 0 ? 0 : yy >= h ? h - 1 : yy;
            for (int dx = 0; dx < 2; ++dx) {
                const int xx = ((x0 + dx) % w + w) % w;
                v += (dx ? tx : 1 - tx) * (dy ? ty : 1 - ty) *
                     c3[c][(size_t) yy * (size_t) w + (size_t) xx];
            }
        }
        out[c] = k->intensity * v;
    }
}

void ef_sky_light_env(const ef_sky_light *k, const double up[3], const double d[3],
                      double out[3])
{
    grid_at(k, (float *const *) k->env, EF_SKY_ENV_W, EF_SKY_ENV_H, up, d, out);
}

int ef_sky_light_eval(const ef_sky_light *k, int phase, double g, const double up[3],
                      const double u[3], double out[3])
{
    out[0] = out[1] = out[2] = 0;
    const ef_sky_conv *cv = NULL;
    for (int i = 0; i < k->nconv && !cv; ++i)
        if (k->conv[i].phase == phase && k->conv[i].g == g)
            cv = &k->conv[i];
    if (!cv)
        return 0;
    if (cv->w == 1) {
        for (int c = 0; c < 3; ++c)
            out[c] = k->intensity * cv->c[c][0];
        return 0;
    }
    grid_at(k, cv->c, cv->w, cv->h, up, u, out);
    return 0;
}
