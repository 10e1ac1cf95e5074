#include "apply.h"

#include <float.h>
#include <math.h>

/* double -> float without the undefined behaviour of an out-of-range cast. */
static float to_float(double v)
{
    if (v > FLT_MAX)
        return INFINITY;
    if (v < -FLT_MAX)
        return -INFINITY;
    return (float) v;
}

void ef_fog_block(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                  float *alpha, const float *depth)
{
    const ef_fog_scene *s = pass->scene;
    const int fog_uncovered = s->sky != EF_SKY_KEEP;
    for (int yy = 0; yy < h; ++yy) {
        const int y = y0 + yy;
        for (int xx = 0; xx < w; ++xx) {
            const int x = x0 + xx;
            const size_t i = (size_t) yy * (size_t) w + (size_t) xx;
            ef_ray r;
            const int sky = ef_reconstruct(pass->cam, pass->conv, x, y, depth[i], &r);
            if (sky && s->sky == EF_SKY_KEEP)
                continue;
            if (sky && s->sky == EF_SKY_DISTANCE_MODE)
                ef_ray_at_distance(pass->cam, x, y, s->sky_distance, &r);
            ef_fog_sample surf, inf;
            double c[3], a = alpha ? alpha[i] : 1.0;
            /* The fog behind only reaches the uncovered part (1 - a) of a pixel. */
            const int need_inf = fog_uncovered && !(a == 1.0 && isfinite(r.dist));
            ef_scene_eval(s, &r, &surf, need_inf ? &inf : NULL);
            if (!need_inf)
                inf = surf;
            for (int k = 0; k < 3; ++k)
                c[k] = rgb[k][i];
            ef_composite(&surf, &inf, fog_uncovered, c, alpha ? &a : NULL);
            for (int k = 0; k < 3; ++k)
                rgb[k][i] = to_float(c[k]);
            if (alpha)
                alpha[i] = to_float(a);
        }
    }
}
