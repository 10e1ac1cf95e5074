/* libFuzzer target for camera files (--camera-file): the first byte picks
 * the format (even: JSON, odd: Nuke .chan) and the rest is the file, held
 * in a memfd. Every file the reader accepts is asked for a few frames, and
 * each camera it gives is resolved on a 64x48 frame; a refusal must carry
 * a message, and nothing may crash, leak or hang. */
#define _GNU_SOURCE 1
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "camera.h"
#include "camera_file.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1)
        return 0;
    const int chan = data[0] & 1;
    int fd = memfd_create("camfile", 0);
    if (fd < 0)
        return 0;
    if (size > 1 && write(fd, data + 1, size - 1) != (ssize_t) (size - 1)) {
        close(fd);
        return 0;
    }
    /* the reader decides the format by the name's extension */
    char dir[] = "/tmp/fzcamXXXXXX", path[128], proc[64];
    if (!mkdtemp(dir)) {
        close(fd);
        return 0;
    }
    snprintf(path, sizeof path, "%s/c.%s", dir, chan ? "chan" : "json");
    snprintf(proc, sizeof proc, "/proc/self/fd/%d", fd);
    if (symlink(proc, path)) {
        close(fd);
        rmdir(dir);
        return 0;
    }
    ef_camera_file *cf = NULL;
    ef_err err = { 0 };
    if (ef_camera_file_read(path, EF_CONV_BLENDER, &cf, &err)) {
        if (!err.msg[0])
            abort();   /* a refusal says why */
    } else {
        double first = 0, last = 0;
        int count = 0;
        ef_camera_file_frames(cf, &first, &last, &count);
        (void) ef_camera_file_describe(cf);
        const double frames[] = { first, last, (first + last) / 2, first - 1, 1001 };
        for (size_t i = 0; i < sizeof frames / sizeof frames[0]; ++i) {
            ef_cam_flags flags;
            memset(&flags, 0, sizeof flags);
            ef_err e2 = { 0 };
            if (ef_camera_file_frame(cf, frames[i], &flags, &e2)) {
                if (!e2.msg[0])
                    abort();
                continue;
            }
            ef_cam_meta meta;
            ef_camera cam;
            ef_cam_meta_init(&meta, 0, 0, 63, 47);
            if (!flags.fov.set && !flags.vfov.set) {
                flags.fov.set = 1;
                flags.fov.v = 40;
            }
            ef_err e3 = { 0 };
            if (ef_camera_resolve(&meta, &flags, &cam, &e3) && !e3.msg[0])
                abort();
        }
        ef_camera_file_free(cf);
    }
    unlink(path);
    rmdir(dir);
    close(fd);
    return 0;
}
