/* The frame loader and timing helpers the fog-pass benchmarks share. */
#include "bench_frame.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "exr_io.h"

/* Copies one decoded unit's colour, alpha and depth into the frame. */
static void copy_chunk(void *user, const ef_chunk *ch)
{
    frame *f = user;
    for (int yy = 0; yy < ch->h; ++yy) {
        const size_t dst = (size_t) (ch->y0 - f->y0 + yy) * (size_t) f->w +
                           (size_t) (ch->x0 - f->x0);
        const size_t src = (size_t) yy * (size_t) ch->w;
        const size_t n = (size_t) ch->w * sizeof(float);
        for (int k = 0; k < 3; ++k)
            memcpy(f->rgb[k] + dst, ch->rgb[k] + src, n);
        if (ch->alpha)
            memcpy(f->alpha + dst, ch->alpha + src, n);
        memcpy(f->depth + dst, ch->depth + src, n);
    }
}

int bench_load_frame(const char *prog, const char *path, frame *f)
{
    ef_exr_file in = { 0 };
    ef_err err;
    ef_channel_plan plan;
    ef_cam_meta meta;
    ef_cam_flags flags;
    memset(&flags, 0, sizeof flags);
    memset(f, 0, sizeof *f);
    if (ef_exr_open(path, &in, &err) || ef_find_channels(&in, &in, NULL, NULL, &plan, &err) ||
        ef_exr_read_cam_meta(&in, plan.rgb[0].part, &meta, &err) ||
        ef_camera_resolve(&meta, &flags, &f->cam, &err) ||
        ef_depth_conv_init(&f->conv, EF_DEPTH_PLANAR, &f->cam, &err)) {
        fprintf(stderr, "%s: %s: %s\n", prog, path, err.msg);
        ef_exr_close(&in);
        return -1;
    }
    exr_attr_box2i_t dw;
    if (exr_get_data_window(in.ctx, plan.rgb[0].part, &dw) != EXR_ERR_SUCCESS) {
        fprintf(stderr, "%s: %s: cannot read the data window\n", prog, path);
        ef_exr_close(&in);
        return -1;
    }
    f->x0 = dw.min.x;
    f->y0 = dw.min.y;
    f->w = dw.max.x - dw.min.x + 1;
    f->h = dw.max.y - dw.min.y + 1;
    const size_t n = (size_t) f->w * (size_t) f->h;
    for (int k = 0; k < 3; ++k)
        f->rgb[k] = calloc(n, sizeof(float));
    f->alpha = plan.alpha.part >= 0 ? calloc(n, sizeof(float)) : NULL;
    f->depth = calloc(n, sizeof(float));
    if (!f->rgb[0] || !f->rgb[1] || !f->rgb[2] || !f->depth ||
        (plan.alpha.part >= 0 && !f->alpha)) {
        fprintf(stderr, "%s: out of memory\n", prog);
        ef_exr_close(&in);
        return -1;
    }

    /* Decode through the library's stream; what it encodes goes nowhere. */
    const int fd = open("/dev/null", O_WRONLY | O_CLOEXEC);
    if (fd < 0) {
        fprintf(stderr, "%s: /dev/null: %s\n", prog, strerror(errno));
        ef_exr_close(&in);
        return -1;
    }
    ef_stream_opts so = { .threads = 1, .compression = EXR_COMPRESSION_NONE, .zip_level = -1,
                          .pixel_type = -1, .param_attr = prog };
    ef_stream_stats st;
    const int rc = ef_exr_stream(&in, &in, &plan, "/dev/null", fd, &so, copy_chunk, f, &st, &err);
    close(fd);
    ef_exr_close(&in);
    if (rc) {
        fprintf(stderr, "%s: %s: %s\n", prog, path, err.msg);
        return -1;
    }
    return 0;
}

void bench_free_frame(frame *f)
{
    for (int k = 0; k < 3; ++k)
        free(f->rgb[k]);
    free(f->alpha);
    free(f->depth);
}

double bench_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double) ts.tv_sec + 1e-9 * (double) ts.tv_nsec;
}

int bench_cmp_double(const void *a, const void *b)
{
    const double x = *(const double *) a, y = *(const double *) b;
    return (x > y) - (x < y);
}

