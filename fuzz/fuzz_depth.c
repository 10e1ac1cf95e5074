/* libFuzzer target for --depth images read through OpenImageIO (a float
 * TIFF depth pass, a 16-bit PNG, DPX, HDR...): the first byte picks the
 * extension, the rest is the file, written to a private directory. The
 * reader must turn it into a float EXR or refuse it with a message (a
 * truncated or damaged file is refused, never half read); nothing may
 * crash or hang. */
#define _GNU_SOURCE 1
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "fuzz_file.h"

int ef_oiio_to_exr(const char *src, int dst_fd, double max_pixels, char *err, size_t errlen);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static const char *const ext[] = { "tif", "png", "dpx", "hdr", "jpg", "tga", "bmp", "pnm" };
    if (size < 1)
        return 0;
    char dir[] = "/tmp/fzdepthXXXXXX", path[128], name[32];
    snprintf(name, sizeof name, "depth.%s", ext[data[0] % 8]);
    if (fuzz_file_make(dir, name, data + 1, size - 1, path, sizeof path))
        return 0;
    int out = memfd_create("depth-exr", 0);
    char msg[1024] = "";
    if (out >= 0) {
        /* as for a 2048x1152 colour frame: four times its pixels at most */
        if (ef_oiio_to_exr(path, out, 4.0 * 2048 * 1152, msg, sizeof msg) && !msg[0])
            abort();   /* a refusal says why */
        close(out);
    }
    fuzz_file_drop(dir, path);
    return 0;
}
