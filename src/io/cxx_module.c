/* OpenColorIO (ocio_shim.cpp) and OpenEXR's DWA codec (exr_dwa.cpp) live in
 * the module libexrfog_cxx.so, loaded on the first call that needs one of
 * them: a run with plain colours and no DWA never maps those libraries
 * (their loading and static initialisers cost about as much as OpenEXRCore
 * takes to start). These are the interfaces of ocio_shim.h and exr_dwa.h,
 * forwarded to the module. */
#define _GNU_SOURCE 1
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>

#include "exr_dwa.h"
#include "module.h"
#include "ocio_shim.h"

#define CXX_MODULE "libexrfog_cxx.so"

/* The module's entry points, resolved once for the process. */
static struct {
    const char *(*version)(void);
    ef_ocio *(*open)(const char *, char *, size_t, char *, size_t);
    void (*close)(ef_ocio *);
    int (*space_exists)(const ef_ocio *, const char *, char *, size_t);
    int (*role)(const ef_ocio *, const char *, char *, size_t);
    int (*from_chrom)(const ef_ocio *, const float[8], char *, size_t);
    int (*parse_color)(const ef_ocio *, const char *, const char *, double[3], char *, size_t);
    ef_ocio_display *(*display_open)(const ef_ocio *, const char *, const char *, char *, size_t,
                                     char *, size_t);
    ef_ocio_display *(*space_open)(const ef_ocio *, const char *, const char *, char *, size_t,
                                   char *, size_t);
    int (*display_apply)(const ef_ocio_display *, float *, long);
    void (*display_close)(ef_ocio_display *);
    int (*dwa_transcode)(const char *, int, const char *, int, int, float, int, char *, size_t);
    int ok;
    char err[1024];
} m;
static pthread_once_t once = PTHREAD_ONCE_INIT;

static void load(void)
{
    void *h = ef_module_open(CXX_MODULE, "the OpenColorIO and DWA module", m.err, sizeof m.err);
    if (!h)
        return;
    struct {
        void **fn;
        const char *name;
    } const syms[] = {
        { (void **) &m.version, "ef_ocio_version" },
        { (void **) &m.open, "ef_ocio_open" },
        { (void **) &m.close, "ef_ocio_close" },
        { (void **) &m.space_exists, "ef_ocio_space_exists" },
        { (void **) &m.role, "ef_ocio_role" },
        { (void **) &m.from_chrom, "ef_ocio_space_from_chromaticities" },
        { (void **) &m.parse_color, "ef_ocio_parse_color" },
        { (void **) &m.display_open, "ef_ocio_display_open" },
        { (void **) &m.space_open, "ef_ocio_space_open" },
        { (void **) &m.display_apply, "ef_ocio_display_apply" },
        { (void **) &m.display_close, "ef_ocio_display_close" },
        { (void **) &m.dwa_transcode, "ef_dwa_transcode" },
    };
    for (size_t i = 0; i < sizeof syms / sizeof syms[0]; ++i)
        if (!(*syms[i].fn = dlsym(h, syms[i].name))) {
            snprintf(m.err, sizeof m.err, "the module %s lacks %s (reinstall exrfog)", CXX_MODULE,
                     syms[i].name);
            return;   /* kept loaded: the process may hold its static objects */
        }
    m.ok = 1;
}

/* 1 once the module is loaded, else 0 with its message in m.err. */
static int have(void)
{
    pthread_once(&once, load);
    return m.ok;
}

/* Copies the load failure into a caller's message buffer. */
static void say(char *msg, size_t len)
{
    if (msg && len)
        snprintf(msg, len, "%s", m.err);
}

const char *ef_ocio_version(void)
{
    return have() ? m.version() : "unavailable (its module did not load)";
}

ef_ocio *ef_ocio_open(const char *path, char *where, size_t where_len, char *msg, size_t msg_len)
{
    if (!have()) {
        say(msg, msg_len);
        return NULL;
    }
    return m.open(path, where, where_len, msg, msg_len);
}

/* A handle exists only once the module is loaded: the rest need no check,
 * except the NULL-accepting frees. */
void ef_ocio_close(ef_ocio *o)
{
    if (o)
        m.close(o);
}

int ef_ocio_space_exists(const ef_ocio *o, const char *name, char *canonical, size_t len)
{
    return m.space_exists(o, name, canonical, len);
}

int ef_ocio_role(const ef_ocio *o, const char *role, char *out, size_t len)
{
    return m.role(o, role, out, len);
}

int ef_ocio_space_from_chromaticities(const ef_ocio *o, const float chrom[8], char *out,
                                      size_t len)
{
    return m.from_chrom(o, chrom, out, len);
}

int ef_ocio_parse_color(const ef_ocio *o, const char *text, const char *working, double rgb[3],
                        char *msg, size_t msg_len)
{
    return m.parse_color(o, text, working, rgb, msg, msg_len);
}

ef_ocio_display *ef_ocio_display_open(const ef_ocio *o, const char *working,
                                      const char *display_view, char *used, size_t used_len,
                                      char *msg, size_t msg_len)
{
    return m.display_open(o, working, display_view, used, used_len, msg, msg_len);
}

ef_ocio_display *ef_ocio_space_open(const ef_ocio *o, const char *working, const char *target,
                                    char *used, size_t used_len, char *msg, size_t msg_len)
{
    return m.space_open(o, working, target, used, used_len, msg, msg_len);
}

int ef_ocio_display_apply(const ef_ocio_display *d, float *rgb, long npixels)
{
    return m.display_apply(d, rgb, npixels);
}

void ef_ocio_display_close(ef_ocio_display *d)
{
    if (d)
        m.display_close(d);
}

int ef_dwa_transcode(const char *in_path, int out_fd, const char *out_name, int dwa_parts_to,
                     int all_parts_to, float dwa_level, int threads, char *msg, size_t msglen)
{
    if (!have()) {
        say(msg, msglen);
        return -1;
    }
    return m.dwa_transcode(in_path, out_fd, out_name, dwa_parts_to, all_parts_to, dwa_level,
                           threads, msg, msglen);
}
