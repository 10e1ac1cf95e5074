/* Shared by the JSON readers (scene files, camera files): how a value is
 * named in messages. */
#ifndef EF_JSON_UTIL_H
#define EF_JSON_UTIL_H

#include <jansson.h>

#include "error.h"

/* "an object", "a number", ... for messages. */
const char *ef_json_type_name(const json_t *v);

/* Fails with "PATH: expected WHAT, got TYPE" (arrays with their size). */
int ef_json_expected(ef_err *err, const char *path, const char *what, const json_t *v);

#endif
