/* On-demand modules (module.h). */
#define _GNU_SOURCE 1
#include "module.h"

#include <dlfcn.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#ifndef EXRFOG_MODULE_INSTALL_DIR
#define EXRFOG_MODULE_INSTALL_DIR ""
#endif
#ifndef EXRFOG_MODULE_BUILD_DIR
#define EXRFOG_MODULE_BUILD_DIR ""
#endif

/* dlopen of dir rel/name, NULL when dir is empty, the path too long or
 * the file does not load. */
static void *open_in(const char *dir, const char *rel, const char *name)
{
    char path[PATH_MAX];
    const int n = snprintf(path, sizeof path, "%s%s/%s", dir, rel, name);
    if (!dir[0] || n < 0 || n >= (int) sizeof path)
        return NULL;
    return dlopen(path, RTLD_NOW | RTLD_LOCAL);
}

void *ef_module_open(const char *name, const char *what, char *err, size_t errlen)
{
    char dirs[2][PATH_MAX];
    int nd = 0;
    const char *env = getenv("EXRFOG_MODULE_DIR");
    void *h = env ? open_in(env, "", name) : NULL;
    Dl_info info;
    if (dladdr((void *) &ef_module_open, &info) && info.dli_fname)
        snprintf(dirs[nd++], PATH_MAX, "%s", info.dli_fname);
    const ssize_t n = readlink("/proc/self/exe", dirs[nd], PATH_MAX - 1);
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
        for (size_t i = 0; !h && i < sizeof rel / sizeof rel[0]; ++i)
            h = open_in(dirs[d], rel[i], name);
    }
    if (!h)
        h = open_in(EXRFOG_MODULE_INSTALL_DIR, "", name);
    if (!h)
        h = open_in(EXRFOG_MODULE_BUILD_DIR, "", name);
    if (!h) {
        const char *why = dlerror();
        snprintf(err, errlen, "cannot load %s %s (%s); reinstall exrfog or set EXRFOG_MODULE_DIR",
                 what, name, why ? why : "not found");
    }
    return h;
}
