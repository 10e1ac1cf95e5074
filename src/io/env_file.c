/* Lat-long environments from files (env_file.h). */
#include "env_file.h"

#include "exr_io.h"
#include "sky_light.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The R, G and B channels of part p: plain, else the first layer's
 * LAYER.R, .G, .B. Returns 0 with idx set, or -1. */
static int rgb_channels(const ef_exr_file *f, int p, int idx[3])
{
    const exr_attr_chlist_t *cl;
    if (exr_get_channels(f->ctx, p, &cl))
        return -1;
    static const char *const suffix[3] = { "R", "G", "B" };
    for (int pass = 0; pass < 2; ++pass) {
        for (int i = 0; i < cl->num_channels; ++i) {
            const char *n = cl->entries[i].name.str;
            const char *dot = strrchr(n, '.');
            const size_t stem = pass == 0 ? 0 : dot ? (size_t) (dot - n + 1) : 0;
            if (pass == 1 && !dot)
                continue;
            int found = 0;
            for (int c = 0; c < 3; ++c) {
                char want[300];
                snprintf(want, sizeof want, "%.*s%s", (int) stem, n, suffix[c]);
                idx[c] = -1;
                for (int j = 0; j < cl->num_channels; ++j)
                    if (!strcmp(cl->entries[j].name.str, want))
                        idx[c] = j;
                found += idx[c] >= 0;
            }
            if (found == 3)
                return 0;
            if (pass == 0)
                break;
        }
    }
    return -1;
}

/* ef_env_src's row reader over an ef_exr_rows. */
static int env_row(void *user, int y, float *const out[3])
{
    return ef_exr_rows_read(user, y, out);
}

int ef_sky_load(const char *path, double rotate_deg, double intensity, const int *phases,
                const double *g, int n, struct ef_sky_light **out, ef_err *err)
{
    ef_exr_file f;
    *out = NULL;
    if (ef_exr_open(path, &f, err)) {
        ef_err_set_file(err, path);
        return -1;
    }
    int part = -1, idx[3];
    for (int p = 0; p < f.nparts && part < 0; ++p)
        if (rgb_channels(&f, p, idx) == 0)
            part = p;
    int rc = -1;
    if (part < 0) {
        ef_fail(err, "no R, G, B channels in the sky light's environment (a lat-long "
                "RGB EXR, as the lighter's HDRI)");
    } else {
        /* streamed: each row is reduced as it is read (no whole planes) */
        int w = 0, h = 0;
        ef_exr_rows *R = ef_exr_rows_open(&f, part, idx, 3, &w, &h);
        if (!R) {
            ef_fail(err, "cannot read the environment's colour (damaged or out of memory)");
        } else {
            ef_env_src src = { path, w, h, { NULL, NULL, NULL }, env_row, R };
            *out = ef_sky_light_build(&src, rotate_deg, intensity, phases, g, n, err);
            rc = *out ? 0 : -1;
            ef_exr_rows_close(R);
        }
    }
    ef_exr_close(&f);
    if (rc)
        ef_err_set_file(err, path);
    return rc;
}
