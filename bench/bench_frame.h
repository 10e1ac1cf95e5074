/* A frame decoded whole into float planes, with its camera, for the
 * benchmarks that time ef_fog_block (model_bench, noise_bench). */
#ifndef EF_BENCH_FRAME_H
#define EF_BENCH_FRAME_H

#include "camera.h"
#include "depth.h"

typedef struct frame {
    int x0, y0, w, h;
    float *rgb[3], *alpha, *depth;
    ef_camera cam;
    ef_depth_conv conv;
} frame;

/* Reads path the way the CLI does (ef_exr_open, ef_find_channels, the
 * header camera, planar depth) and decodes its colour, alpha and depth
 * through the library's stream. Returns 0, or -1 with a message on stderr
 * prefixed by prog. */
int bench_load_frame(const char *prog, const char *path, frame *f);
void bench_free_frame(frame *f);

/* Monotonic seconds. */
double bench_now(void);
/* qsort comparator for doubles. */
int bench_cmp_double(const void *a, const void *b);

#endif
