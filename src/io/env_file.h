/* Lat-long environments from files: --sky-light's map read into the
 * core's ef_sky_light (the fog context's load_sky). */
#ifndef EF_ENV_FILE_H
#define EF_ENV_FILE_H

#include "error.h"

struct ef_sky_light;

/* Reads path (a flat EXR: the first part with R, G and B, or *.R, *.G,
 * *.B of one layer) and builds the sky light for the n phase functions.
 * Returns 0, or -1 with err->file set to path. */
int ef_sky_load(const char *path, double rotate_deg, double intensity, const int *phases,
                const double *g, int n, struct ef_sky_light **out, ef_err *err);

#endif
