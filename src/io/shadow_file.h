/* Shadow maps from files: a light-view depth render read into the core's
 * ef_shadow (the fog context's load_shadow). */
#ifndef EF_SHADOW_FILE_H
#define EF_SHADOW_FILE_H

#include "error.h"

struct ef_shadow;

/* Reads path (a flat EXR; the first part with a depth channel Z, depth.Z,
 * depth or *.Z, and the camera in that part's header) into *out with
 * the given bias and outside rule. Returns 0, or -1 with err->file set to
 * path and a message saying what is wrong and how to fix it. */
int ef_shadow_load(const char *path, double bias, int outside_lit, struct ef_shadow **out,
                   ef_err *err);

#endif
