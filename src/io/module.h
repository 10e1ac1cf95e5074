/* exrfog's on-demand modules: the parts that link large C++ libraries
 * (OpenImageIO; OpenColorIO and OpenEXR's DWA codec) live in shared
 * modules loaded only when a run needs them, so that a plain run starts
 * as fast as a C program on OpenEXRCore. */
#ifndef EF_MODULE_H
#define EF_MODULE_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* dlopen()s module `name` (e.g. "libexrfog_oiio.so"): from
 * $EXRFOG_MODULE_DIR if set, else beside the library or program that holds
 * this code, in its exrfog/ subdirectory or ../lib/exrfog, else the
 * configured install and build directories. what names the module in the
 * message ("the OpenImageIO module"). Returns the handle, or NULL with a
 * message in err. */
void *ef_module_open(const char *name, const char *what, char *err, size_t errlen);

#ifdef __cplusplus
}
#endif

#endif
