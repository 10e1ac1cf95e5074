/* The foreign formats' face (foreign.h): loads the OpenImageIO module on
 * demand (see oiio/oiio_module.cpp) and calls through it. */
#include "foreign.h"

#include "module.h"

#include <dlfcn.h>
#include <stdio.h>

#define MODULE_NAME "libexrfog_oiio.so"

/* The module's function `name`, with the module handle to close after. */
static void *module_sym(const char *name, void **mod, char *err, size_t errlen)
{
    *mod = ef_module_open(MODULE_NAME, "the OpenImageIO module", err, errlen);
    if (!*mod)
        return NULL;
    void *f = dlsym(*mod, name);
    if (!f) {
        snprintf(err, errlen, "the OpenImageIO module lacks %s (reinstall exrfog)", name);
        dlclose(*mod);
        *mod = NULL;
    }
    return f;
}

int ef_preview_write(const char *path, const char *fmt, int w, int h, const unsigned char *rgb,
                     char *err, size_t errlen)
{
    void *mod;
    int (*fn)(const char *, const char *, int, int, const unsigned char *, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_write_rgb8", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(path, fmt, w, h, rgb, err, errlen);
    dlclose(mod);
    return rc;
}

int ef_preview_check(const char *path, char *err, size_t errlen)
{
    void *mod;
    int (*fn)(const char *, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_can_write", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(path, err, errlen);
    dlclose(mod);
    return rc;
}

int ef_oiio_convert_exr(const char *src, int part, const char *const *names, int n,
                        const char *dst, const char *dst_fmt, const ef_oiio_deliver *d,
                        char *err, size_t errlen)
{
    void *mod;
    int (*fn)(const char *, int, const char *const *, int, const char *, const char *,
              const ef_oiio_deliver *, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_convert", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(src, part, names, n, dst, dst_fmt, d, err, errlen);
    dlclose(mod);
    return rc;
}

int ef_oiio_output_probe(const char *ext, int dt, int nch, int *got, int *alpha, char *err,
                         size_t errlen)
{
    void *mod;
    int (*fn)(const char *, int, int, int *, int *, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_output_probe", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(ext, dt, nch, got, alpha, err, errlen);
    dlclose(mod);
    return rc;
}

int ef_oiio_image_to_exr(const char *src, int dst_fd, double max_pixels, char *err, size_t errlen)
{
    void *mod;
    int (*fn)(const char *, int, double, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_to_exr", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(src, dst_fd, max_pixels, err, errlen);
    dlclose(mod);
    return rc;
}
