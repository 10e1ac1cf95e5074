/* libFuzzer target: one input = one EXR file, run through the same sequence
 * as a run (src/job/frame.c):
 *   ef_exr_open -> ef_find_channels -> ef_exr_read_cam_meta ->
 *   ef_camera_resolve -> ef_depth_conv_init -> ef_exr_stream -> ef_exr_close
 * with a callback that reads every colour/alpha/depth value, reconstructs
 * the pixel's ray and writes the colour back. Every failure must be a clean
 * error return; the sanitizers catch the rest.
 *
 * FUZZ_EXR_VERBOSE=1 in the environment prints each input's outcome;
 * FUZZ_EXR_EXPECT_OK=1 aborts when an input does not go all the way through
 * (for fuzz/regressions/: valid files exrfog must fog); FUZZ_EXR_PRINTABLE=1
 * aborts when an error message carries control bytes taken from the file
 * (terminal escapes reach the user's terminal). */
#define _GNU_SOURCE   /* memfd_create */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "apply.h"
#include "camera.h"
#include "depth.h"
#include "exr_io.h"
#include "recon.h"

/* Inputs whose parts' data windows add up to more pixels than this are
 * skipped after opening, to keep the fuzzer fast. */
#define FUZZ_MAX_PIXELS (2048LL * 2048LL)

/* Input and output are memfds named through /proc/self/fd, so nothing is
 * left behind when a run is killed (timeouts, -fork jobs) and parallel jobs
 * never share a file. The library opens them by path like any file. */
static int in_fd = -1, out_fd = -1;
static char in_path[64], out_path[64];

static int setup_files(void)
{
    if (in_fd >= 0)
        return 0;
    in_fd = memfd_create("exrfog-fuzz-in.exr", MFD_CLOEXEC);
    out_fd = memfd_create("exrfog-fuzz-out.exr", MFD_CLOEXEC);
    if (in_fd < 0 || out_fd < 0) {
        perror("fuzz_exr: memfd_create");
        abort();
    }
    snprintf(in_path, sizeof in_path, "/proc/self/fd/%d", in_fd);
    snprintf(out_path, sizeof out_path, "/proc/self/fd/%d", out_fd);
    return 0;
}

static int write_input(const uint8_t *data, size_t size)
{
    if (ftruncate(in_fd, 0) != 0 || ftruncate(out_fd, 0) != 0)
        return -1;
    size_t done = 0;
    while (done < size) {
        ssize_t n = pwrite(in_fd, data + done, size - done, (off_t) done);
        if (n <= 0)
            return -1;
        done += (size_t) n;
    }
    return 0;
}

/* The tool's own per-block pass (apply.h), so the fuzzer exercises what
 * users run: reconstruction, transmittance and compositing of every pixel. */
static void fog_chunk(void *user, const ef_chunk *ck)
{
    ef_fog_block(user, ck->x0, ck->y0, ck->w, ck->h, ck->rgb, ck->alpha, ck->depth);
}

static long long total_pixels(const ef_exr_file *f)
{
    long long total = 0;
    for (int p = 0; p < f->nparts; ++p) {
        exr_attr_box2i_t dw;
        if (exr_get_data_window(f->ctx, p, &dw) != EXR_ERR_SUCCESS)
            return -1;
        total += ((long long) dw.max.x - dw.min.x + 1) * ((long long) dw.max.y - dw.min.y + 1);
    }
    return total;
}

static int check_printable = -1;

/* The promise is a clear error, so a failure must come with a message. */
static int failed(int rc, const ef_err *err, const char *step)
{
    if (rc != 0 && (err->msg[0] == '\0' || memchr(err->msg, '\0', sizeof err->msg) == NULL)) {
        fprintf(stderr, "fuzz_exr: %s failed without an error message\n", step);
        abort();
    }
    if (rc != 0 && check_printable) {
        for (const unsigned char *c = (const unsigned char *) err->msg; *c; ++c)
            if (*c < 0x20 || *c == 0x7f) {
                fprintf(stderr, "fuzz_exr: %s: error message has control byte 0x%02x at %d\n", step,
                        *c, (int) (c - (const unsigned char *) err->msg));
                abort();
            }
    }
    return rc != 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    ef_exr_file in = { 0 };
    ef_channel_plan plan;
    ef_cam_meta meta;
    ef_camera cam;
    ef_depth_conv conv;
    ef_err err = { 0 };

    static int verbose = -1, expect_ok = 0;
    int ok = 0;
    if (verbose < 0) {
        verbose = getenv("FUZZ_EXR_VERBOSE") != NULL;
        expect_ok = getenv("FUZZ_EXR_EXPECT_OK") != NULL;
        check_printable = getenv("FUZZ_EXR_PRINTABLE") != NULL;
    }
    setup_files();
    if (write_input(data, size) != 0)
        return 0;
    if (failed(ef_exr_open(in_path, &in, &err), &err, "ef_exr_open"))
        goto done;
    long long px = total_pixels(&in);
    if (px < 0 || px > FUZZ_MAX_PIXELS)
        goto done;
    if (failed(ef_find_channels(&in, &in, NULL, NULL, &plan, &err), &err, "ef_find_channels"))
        goto done;
    if (failed(ef_exr_read_cam_meta(&in, plan.rgb[0].part, &meta, &err), &err,
               "ef_exr_read_cam_meta"))
        goto done;
    /* The header's own camera first (as the CLI without camera flags);
     * when it has none, the flags a user would pass so the stream runs. */
    ef_cam_flags flags;
    memset(&flags, 0, sizeof flags);
    if (failed(ef_camera_resolve(&meta, &flags, &cam, &err), &err, "ef_camera_resolve")) {
        flags.w2c.set = 1;
        for (int i = 0; i < 16; ++i)
            flags.w2c.v.m[i] = (i % 5 == 0) ? 1.0 : 0.0;
        flags.fov.set = 1;
        flags.fov.v = 40.0;
        err.msg[0] = '\0';
        if (failed(ef_camera_resolve(&meta, &flags, &cam, &err), &err, "ef_camera_resolve"))
            goto done;
    }
    if (failed(ef_depth_conv_init(&conv, EF_DEPTH_PLANAR, &cam, &err), &err, "ef_depth_conv_init"))
        goto done;
    for (int p = 0; p < in.nparts; ++p)
        (void) ef_exr_part_is_multilevel(&in, p);

    ef_fog_scene scene;
    ef_scene_init(&scene);
    if (ef_scene_add(&scene, "exp:density=0.01,0.02,0.03", &err))
        abort();
    ef_fog_pass pass = { &cam, &conv, &scene };
    ef_stream_opts so = { .threads = 1, .compression = -1, .zip_level = -1, .pixel_type = -1,
                          .param_attr = "fuzz" };
    ef_stream_stats st;
    struct stat sb;
    err.msg[0] = '\0';
    if (!failed(ef_exr_stream_file(&in, &in, &plan, out_path, &so, fog_chunk, &pass, &st, &err), &err,
                "ef_exr_stream") &&
        (fstat(out_fd, &sb) != 0 || sb.st_size < 8)) {
        fprintf(stderr, "fuzz_exr: ef_exr_stream succeeded but wrote no output\n");
        abort();
    }
    ok = err.msg[0] == '\0';

done:
    if (verbose || (expect_ok && !ok))
        fprintf(stderr, "fuzz_exr: %zu bytes: %s\n", size, ok ? "ok" : err.msg[0] ? err.msg : "skipped");
    if (expect_ok && !ok)
        abort();
    ef_exr_close(&in);
    return 0;
}
