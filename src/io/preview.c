/* Loads the OpenImageIO module on demand (see oiio/oiio_module.cpp). */
#define _GNU_SOURCE 1
#include "preview.h"

#include <dlfcn.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MODULE_NAME "libexrfog_oiio.so"

/* The module sits beside the library that holds this code or in its
 * exrfog/ subdirectory (installed: LIBDIR/exrfog), beside the executable
 * (build tree) or in ../lib/exrfog; $EXRFOG_MODULE_DIR overrides all. */
static void *load_module(char *err, size_t errlen)
{
    char dirs[3][PATH_MAX], path[PATH_MAX + 64];
    int nd = 0;
    const char *env = getenv("EXRFOG_MODULE_DIR");
    void *h = NULL;
    if (env) {
        snprintf(path, sizeof path, "%s/%s", env, MODULE_NAME);
        h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    }
    Dl_info info;
    if (dladdr((void *) &load_module, &info) && info.dli_fname)
        snprintf(dirs[nd++], PATH_MAX, "%s", info.dli_fname);
    ssize_t n = readlink("/proc/self/exe", dirs[nd], PATH_MAX - 1);
    if (n > 0) {
        dirs[nd][n] = '\0';
        ++nd;
    }
    for (int d = 0; !h && d < nd; ++d) {
        char *slash = strrchr(dirs[d], '/');
        if (!slash)
            continue;
        *slash = '\0';
        static const char *const rel[] = { "", "/exrfog", "/../lib/exrfog" };
        for (size_t i = 0; !h && i < sizeof rel / sizeof rel[0]; ++i) {
            snprintf(path, sizeof path, "%s%s/%s", dirs[d], rel[i], MODULE_NAME);
            h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
        }
    }
    if (!h)
        snprintf(err, errlen, "cannot load the OpenImageIO module %s (%s); reinstall exrfog or set "
                              "EXRFOG_MODULE_DIR", MODULE_NAME, dlerror());
    return h;
}

/* The module's function `name`, with the module handle to close after. */
static void *module_sym(const char *name, void **mod, char *err, size_t errlen)
{
    *mod = load_module(err, errlen);
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

int ef_preview_write(const char *path, int w, int h, const unsigned char *rgb, char *err,
                     size_t errlen)
{
    void *mod;
    int (*fn)(const char *, int, int, const unsigned char *, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_write_rgb8", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(path, w, h, rgb, err, errlen);
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
                        const char *dst, char *err, size_t errlen)
{
    void *mod;
    int (*fn)(const char *, int, const char *const *, int, const char *, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_convert", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(src, part, names, n, dst, err, errlen);
    dlclose(mod);
    return rc;
}

int ef_oiio_image_to_exr(const char *src, int dst_fd, char *err, size_t errlen)
{
    void *mod;
    int (*fn)(const char *, int, char *, size_t);
    *(void **) &fn = module_sym("ef_oiio_to_exr", &mod, err, errlen);
    if (!fn)
        return -1;
    const int rc = fn(src, dst_fd, err, errlen);
    dlclose(mod);
    return rc;
}
