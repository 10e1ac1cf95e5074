/* The per-block fog pass: stored depth -> ray -> transmittance -> composite,
 * in place on float planes. This is the whole per-pixel data flow; the I/O
 * layer only feeds it decoded blocks. */
#ifndef EF_APPLY_H
#define EF_APPLY_H

#include "aov.h"
#include "camera.h"
#include "depth.h"
#include "scene.h"

typedef struct ef_fog_pass {
    const ef_camera *cam;
    const ef_depth_conv *conv;
    const ef_fog_scene *scene;
} ef_fog_pass;

/* Fogs a w x h block whose top-left pixel is absolute (x0, y0); rows are w
 * values long. alpha may be NULL (alpha = 1). Sky pixels follow the scene's
 * sky policy. Results beyond the float range saturate to +-inf. */
void ef_fog_block(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                  float *alpha, const float *depth);

/* ef_fog_block that also writes the AOVs of aov->mask into aov's planes
 * (w x h each; aov may be NULL) and, when stats is not NULL, adds to
 * stats[i] the cost and error of component i's surface segment for every
 * component whose model reports them (model->tau_info). The fogged colour
 * is bit-identical to ef_fog_block's. Per pixel:
 *   fog.RGB  = out.rgb - T in.rgb (0 where T = 0 hides the surface's term)
 *   fog.A    = out.a - in.a (0 without alpha)
 *   fog_T    = T to the surface (to infinity, or to D with --sky
 *              distance=D, on sky pixels; 1 on sky pixels with --sky keep)
 *   fog_error = min(1, T expm1(sum over components of info.err))
 *   fog_P    = (camera + dir dist) - origin in double; on sky pixels
 *              dir * inf per axis (0 where dir is 0)
 *   fog_distance = dist (inf on sky pixels, whatever the sky policy). */
void ef_fog_block_aov(const ef_fog_pass *pass, int x0, int y0, int w, int h, float *const rgb[3],
                      float *alpha, const float *depth, const ef_aov_out *aov,
                      ef_tau_stats *stats);

#endif
