/* Shadow maps from files: a light-view depth render read into the core's
 * ef_shadow (the fog context's load_shadow). */
#ifndef EF_SHADOW_FILE_H
#define EF_SHADOW_FILE_H

#include "error.h"

struct ef_shadow;
struct ef_shadow_opts;

/* Reads path (a flat EXR; the first part with a depth channel Z, depth.Z,
 * depth or *.Z, and the camera in that part's header) into *out with
 * o's biases and outside rule. Returns 0, or -1 with err->file set to
 * path and a message saying what is wrong and how to fix it. */
int ef_shadow_load(const char *path, const struct ef_shadow_opts *o, struct ef_shadow **out,
                   ef_err *err);

#endif
