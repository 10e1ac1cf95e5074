/* libFuzzer target for OpenColorIO configs (--colorconfig, $OCIO): the input
 * is a config file, written to a private directory (so its relative search
 * paths and FileTransforms resolve there). Every config the shim accepts
 * is asked what exrfog asks of one: names, roles, colours in every form
 * (#RRGGBB, SPACE:R,G,B), the default display and a file space, applied to
 * a few pixels. A refusal must carry a message; nothing may crash, hang
 * (a FileTransform naming a FIFO or /dev/zero) or grow without bound. */
#define _GNU_SOURCE 1
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fuzz_file.h"
#include "ocio_shim.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char dir[] = "/tmp/fzocioXXXXXX", path[128];
    if (fuzz_file_make(dir, "config.ocio", data, size, path, sizeof path))
        return 0;
    char where[1200], msg[2048] = "";
    ef_ocio *o = ef_ocio_open(path, where, sizeof where, msg, sizeof msg);
    if (!o) {
        if (!msg[0])
            abort();   /* a refusal says why */
    } else {
        char name[256], used[600];
        (void) ef_ocio_space_exists(o, "ACEScg", name, sizeof name);
        (void) ef_ocio_role(o, "scene_linear", name, sizeof name);
        static const char *const colours[] = { "0.5,0.5,0.5", "#80a0c0", "ACEScg:0.1,0.2,0.3",
                                               "scene_linear:1,1,1", "sRGB - Texture:0.5,0.5,0.5" };
        for (size_t k = 0; k < sizeof colours / sizeof colours[0]; ++k) {
            double rgb[3];
            msg[0] = '\0';
            if (ef_ocio_parse_color(o, colours[k], NULL, rgb, msg, sizeof msg) && !msg[0])
                abort();
        }
        float px[12] = { 0, 0, 0, 0.18f, 0.18f, 0.18f, 1, 1, 1, 4, 0.5f, -1 };
        msg[0] = '\0';
        ef_ocio_display *d = ef_ocio_display_open(o, NULL, NULL, used, sizeof used, msg, sizeof msg);
        if (!d && !msg[0])
            abort();
        if (d) {
            (void) ef_ocio_display_apply(d, px, 4);
            ef_ocio_display_close(d);
        }
        msg[0] = '\0';
        d = ef_ocio_space_open(o, NULL, NULL, used, sizeof used, msg, sizeof msg);
        if (!d && !msg[0])
            abort();
        if (d) {
            (void) ef_ocio_display_apply(d, px, 4);
            ef_ocio_display_close(d);
        }
        ef_ocio_close(o);
    }
    fuzz_file_drop(dir, path);
    return 0;
}
