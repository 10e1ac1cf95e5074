/* The per-block fog pass: stored depth -> ray -> transmittance -> composite,
 * in place on float planes. This is the whole per-pixel data flow; the I/O
 * layer only feeds it decoded blocks. */
#ifndef EF_APPLY_H
#define EF_APPLY_H

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

#endif
