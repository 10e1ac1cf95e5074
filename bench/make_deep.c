/* make_deep.c - a deep benchmark frame: a flat frame's header (its camera)
 * and per pixel N volume samples, a synthetic stack of slabs between
 * Z = 4 and Z = 60 whose spacing, alpha and colour vary over the frame
 * (as a volume render's samples do), written deep scanline ZIPS.
 *
 *   make_deep FLAT.exr OUT.exr N [chain]
 *
 * chain: instead, N samples a pixel each 0.002 deep and starting 0.001
 * after the one before (every sample overlaps its neighbours: issue 42's
 * hostile "chain"), N up to 100,000.
 *
 * The header is copied from FLAT (make_sample's frame); the samples are
 * packed by exrfog's own deep writer (src/io/exr_deep.c) and read back by
 * oiiotool in bench/deep.sh, so a writer fault cannot pass unseen. */
#include "exr_deep.h"

#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int main(int argc, char **argv)
{
    if (argc != 4 && !(argc == 5 && !strcmp(argv[4], "chain"))) {
        fprintf(stderr, "usage: make_deep FLAT.exr OUT.exr N [chain]\n");
        return 2;
    }
    const int N = atoi(argv[3]), chain = argc == 5, Nmax = chain ? 100000 : 1000;
    ef_err err = { 0 };
    ef_exr_file in = { 0 };
    if (N < 1 || N > Nmax || ef_exr_open(argv[1], &in, &err)) {
        fprintf(stderr, "make_deep: %s\n", N < 1 || N > Nmax ? "N out of range" : err.msg);
        return 1;
    }
    exr_attr_box2i_t dw;
    exr_get_data_window(in.ctx, 0, &dw);
    const int W = dw.max.x - dw.min.x + 1, H = dw.max.y - dw.min.y + 1;
    const int fd = open(argv[2], O_RDWR | O_CREAT | O_TRUNC, 0644);
    static const char *const names[] = { "A", "B", "G", "R", "Z", "ZBack" };
    const exr_pixel_type_t types[] = { EXR_PIXEL_HALF, EXR_PIXEL_HALF, EXR_PIXEL_HALF,
                                       EXR_PIXEL_HALF, EXR_PIXEL_FLOAT, EXR_PIXEL_FLOAT };
    ef_deep_out out;
    if (fd < 0 || ef_deep_out_begin(&out, argv[2], fd, &in, 0, 1, 6, names, types, NULL, NULL,
                                    NULL, 0, &err)) {
        fprintf(stderr, "make_deep: %s\n", fd < 0 ? "cannot create the output" : err.msg);
        return 1;
    }
    uint32_t *counts = malloc((size_t) W * sizeof *counts);
    double *v = malloc((size_t) W * (size_t) N * 6 * sizeof *v);
    ef_deep_packed pk = { 0 };
    for (int y = 0; y < H && counts && v; ++y) {
        size_t s = 0;
        for (int x = 0; x < W; ++x) {
            counts[x] = (uint32_t) N;
            const double u = (double) x / W, t = (double) y / H;
            double z = 4 + 3 * u;
            for (int i = 0; i < N; ++i, ++s) {
                const double dz = (56.0 / N) * (0.6 + 0.8 * fabs(sin(7 * u + 3 * t + i)));
                const double a = 0.02 + 0.06 * (0.5 + 0.5 * sin(5 * t + i * 0.7));
                double *p = v + s * 6;
                if (chain) {
                    p[0] = p[1] = p[2] = p[3] = 0.0004;
                    p[4] = 4 + 0.001 * i;
                    p[5] = p[4] + 0.002;
                    continue;
                }
                p[0] = a;
                p[1] = a * (0.2 + 0.6 * t);
                p[2] = a * (0.3 + 0.4 * u);
                p[3] = a * 0.5;
                p[4] = z;
                p[5] = z + dz * 0.9;
                z += dz;
            }
        }
        pk.y = dw.min.y + y;
        if (ef_deep_pack_row(6, types, W, counts, v, -1, &pk) || ef_deep_out_write(&out, &pk, &err)) {
            fprintf(stderr, "make_deep: %s\n", err.msg[0] ? err.msg : "out of memory");
            return 1;
        }
    }
    ef_deep_packed_free(&pk);
    free(counts);
    free(v);
    const int rc = ef_deep_out_end(&out, &err);
    close(fd);
    ef_exr_close(&in);
    if (rc)
        fprintf(stderr, "make_deep: %s\n", err.msg);
    return rc ? 1 : 0;
}
