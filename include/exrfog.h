/* libexrfog: physically correct fog for rendered images, as a C library.
 *
 * The style is OpenEXRCore's: opaque objects made and released by the
 * caller, every call returns an exrfog_result, memory the caller passes
 * stays the caller's, and the text of the last failure is kept per context
 * (exrfog_error). The library and the exrfog program are two clients of
 * one job layer; the library keeps nothing per process.
 *
 * Thread safety: every call is reentrant. A context is used by one thread
 * at a time (its error text is per context): make one per thread or per
 * job. Any number of exrfog_run, exrfog_explain and exrfog_fog_pixels calls
 * may run at once in one process, each with its own context, and each
 * gives the bytes it gives alone. Scenes and cameras are immutable once
 * made: any number of threads may pass the same ones at once.
 * exrfog_cancel is the one call that may be made on a context another
 * thread is using (and from a signal handler).
 *
 * The process is left alone: no signal handlers, no change to umask,
 * locale, cwd, environment, getopt's state or stdio, and nothing written
 * to stdout or stderr unless exrfog_set_print asked for it. A host that
 * wants temporary files removed when it dies by a signal handles that
 * signal itself and calls exrfog_cancel (the run removes them on the way
 * out).
 *
 * Every call that takes pointers returns EXRFOG_USAGE when a required one
 * is NULL (with a message in the context when there is one).
 *
 * ABI: the library's soname carries EXRFOG_VERSION_MAJOR; within a major
 * version functions are only added, structs passed by pointer only grow at
 * their end (their first member is their size), and enum values keep their
 * numbers. Before 1.0 (now) a minor version may break the ABI. */
#ifndef EXRFOG_H
#define EXRFOG_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define EXRFOG_VERSION_MAJOR 0
#define EXRFOG_VERSION_MINOR 1
#define EXRFOG_VERSION_PATCH 0
#define EXRFOG_VERSION "0.1.0"

#if defined(__GNUC__)
#define EXRFOG_API __attribute__((visibility("default")))
#else
#define EXRFOG_API
#endif

/* Results: the command line's exit statuses, plus cancellation. */
typedef enum exrfog_result {
    EXRFOG_OK = 0,
    EXRFOG_ERROR = 1,        /* bad input, I/O, no camera...: exrfog_error says what */
    EXRFOG_USAGE = 2,        /* a bad argument or option */
    EXRFOG_CANCELLED = 3     /* the progress callback asked to stop; nothing was written */
} exrfog_result;

/* The version of the library actually loaded ("0.1.0"). */
EXRFOG_API const char *exrfog_version(void);

typedef struct exrfog_context exrfog_context;

/* A new context, or NULL when out of memory. */
EXRFOG_API exrfog_context *exrfog_context_create(void);
/* Releases a context (NULL is fine). */
EXRFOG_API void exrfog_context_destroy(exrfog_context *ctx);
/* The last failure of a call made with ctx, as the command line prints it
 * without its "exrfog: " prefix ("FILE: what is wrong (how to fix it)");
 * "" after a success. Valid until the next call with ctx. */
EXRFOG_API const char *exrfog_error(const exrfog_context *ctx);

/* Progress of exrfog_run: called from worker threads, one call at a time,
 * after every chunk of pixels and every frame, with the fraction done
 * (0..1) of the whole run: monotonic, and exactly 1.0 once on success.
 * Returning non-zero cancels the run: it stops at the next chunk and
 * returns EXRFOG_CANCELLED with no output written. */
typedef int (*exrfog_progress_fn)(void *user, double fraction);
EXRFOG_API exrfog_result exrfog_set_progress(exrfog_context *ctx, exrfog_progress_fn fn,
                                             void *user);

/* Warnings of exrfog_run (a Nuke 1/z depth, a V-Ray Z-up camera, a view
 * left unfogged...): file is the file it is about, text what the command
 * line prints after "exrfog: FILE: warning: ". Called from the thread that
 * runs the job. */
typedef void (*exrfog_warning_fn)(void *user, const char *file, const char *text);
EXRFOG_API exrfog_result exrfog_set_warning(exrfog_context *ctx, exrfog_warning_fn fn,
                                            void *user);

/* Whether messages (errors, warnings) also go to stderr, and --help,
 * --version and --explain to stdout, as the command line prints them
 * (default 0: only exrfog_error keeps the failure). */
EXRFOG_API exrfog_result exrfog_set_print(exrfog_context *ctx, int print);

/* Asks the exrfog_run, exrfog_explain or exrfog_fog_pixels in progress with ctx (from
 * another thread or a signal handler) to stop: it stops at the next chunk
 * of decode, fog or encode work, removes its temporary files, writes
 * nothing and returns EXRFOG_CANCELLED. A later call on ctx starts afresh. */
EXRFOG_API void exrfog_cancel(exrfog_context *ctx);

/* ---------------------------------------------------------------- scenes */

typedef struct exrfog_scene exrfog_scene;

/* Parses a fog scene: the SPECs of --fog (MODEL[:KEY=VALUE]...) and/or a
 * scene file (JSON, as --scene; NULL for none), with the fog colour R,G,B
 * in the working space (NULL: the default 0.7,0.75,0.8). Nothing but the
 * scene file and the files it names (profiles, its lights' shadow maps,
 * its sky_light's environment) is read: this validates a scene with no
 * image at hand. Lights light exrfog_fog_pixels' fog, which writes their
 * AOV layers too (exrfog_image's light members). */
EXRFOG_API exrfog_result exrfog_scene_create(exrfog_context *ctx, const char *const *specs,
                                             int nspecs, const char *scene_file,
                                             const double *color, exrfog_scene **out);
EXRFOG_API void exrfog_scene_destroy(exrfog_scene *scene);
/* How many lights the scene has (--light SPECs and a scene file's
 * "lights", in that order), 0 for NULL. */
EXRFOG_API int exrfog_scene_light_count(const exrfog_scene *scene);
/* Light i's name (0 <= i < the count), as its AOV layer fog_light.NAME
 * has it, and into *shadowed (may be NULL) whether it has a shadow map
 * (then it has a fog_lit.NAME layer); NULL when i is out of range. The
 * string lives as long as the scene. */
EXRFOG_API const char *exrfog_scene_light_name(const exrfog_scene *scene, int i, int *shadowed);
/* Whether the scene has a sky light (--sky-light, a scene file's
 * "sky_light"): then exrfog_image's sky planes are written. */
EXRFOG_API int exrfog_scene_has_sky_light(const exrfog_scene *scene);

/* --------------------------------------------------------------- cameras */

typedef struct exrfog_camera exrfog_camera;

/* A pinhole camera from a 4x4 camera-to-world matrix (16 numbers, laid out
 * in `convention`: "exr", "blender", "nuke", "maya", "houdini" or "usd"; see
 * exrfog(1) CAMERAS), a horizontal field of view in degrees, and the image's
 * display window (xmin, ymin, xmax, ymax inclusive, square pixels). */
EXRFOG_API exrfog_result exrfog_camera_from_matrix(exrfog_context *ctx,
                                                   const double camera_to_world[16],
                                                   const char *convention, double hfov_deg,
                                                   const int display_window[4],
                                                   exrfog_camera **out);
/* The camera of an EXR file's header (colour part), as the command line
 * resolves it (worldToCamera with worldToNDC/worldToScreen or a fov,
 * V-Ray, Redshift). */
EXRFOG_API exrfog_result exrfog_camera_from_file(exrfog_context *ctx, const char *path,
                                                 exrfog_camera **out);
/* The camera's position in world space. */
EXRFOG_API exrfog_result exrfog_camera_position(const exrfog_camera *cam, double pos[3]);
EXRFOG_API void exrfog_camera_destroy(exrfog_camera *cam);

/* ---------------------------------------------------------------- pixels */

/* A rectangle of the caller's pixels, fogged in place: float planes whose
 * pixel (x0 + i, y0 + j) is at plane[j * stride + i] (stride in floats,
 * >= width). alpha may be NULL (alpha 1). depth is planar camera depth
 * unless depth_mode says otherwise (the names of --depth-mode). The
 * optional AOV planes (NULL: not wanted) get the transmittance fog_T, its
 * error bound fog_error and the world position fog_P, as the command line
 * writes them; a group may give some of its three planes only. With
 * lights, the layers of --aov light and lit may be asked for too (below).
 * The rectangle's pixel coordinates must stay within an int.
 *
 * The light layers (members added after P: a caller built against a
 * header without them passes the smaller size and gets none). Wanting any
 * of ambient, light or sky writes them all, as --aov light does (the
 * planes not given are computed and dropped); they need a scene with
 * lights or a sky light (EXRFOG_USAGE otherwise):
 *   ambient  fog_ambient.R/G/B, the fog's own colour (today's fog term)
 *   light    3 planes per light (R, G, B), light i's at light[3 i ..
 *            3 i + 2] in exrfog_scene_light_name's order:
 *            fog_light.NAME.R/G/B; NULL entries are not wanted
 *   sky      the sky light's layer (ignored without one)
 *   lit      1 plane per light, the lit fraction fog_lit.NAME of a light
 *            with a shadow map (entries of the others are ignored)
 * The fog's colour is their sum: ambient + the lights + sky. */
typedef struct exrfog_image {
    size_t size;                 /* sizeof(exrfog_image): the ABI check */
    int x0, y0, width, height;   /* absolute pixels, as in the display window */
    ptrdiff_t stride;
    float *rgb[3];
    float *alpha;
    const float *depth;
    const char *depth_mode;      /* NULL: "planar" */
    float *T[3];                 /* optional AOVs */
    float *error[3];
    float *P[3];
    float *ambient[3];           /* the light layers (above) */
    float *const *light;         /* 3 per light, or NULL */
    float *sky[3];
    float *const *lit;           /* 1 per light, or NULL */
} exrfog_image;

/* Fogs img in place with scene seen from cam. The scene is bound to the
 * camera on a private copy: nothing is parsed and no file is read. Safe to
 * call from several threads at once on disjoint rectangles (one context
 * each). exrfog_cancel(ctx) from another thread stops it between bands of
 * rows (about 16,384 pixels): it returns EXRFOG_CANCELLED, the rectangle
 * fogged in part. */
EXRFOG_API exrfog_result exrfog_fog_pixels(exrfog_context *ctx, const exrfog_scene *scene,
                                           const exrfog_camera *cam, exrfog_image *img);

/* -------------------------------------------------------- the whole run */

/* Runs exrfog on files with the command line's arguments (argv[0] is the
 * program name, then options and INPUT as exrfog(1) documents them):
 * sequences, views, colour management, every format. The progress
 * callback and cancellation apply. */
EXRFOG_API exrfog_result exrfog_run(exrfog_context *ctx, int argc, const char *const *argv);

/* What exrfog_run would read and do, without writing anything: the facts
 * of `exrfog --explain --json` (camera per view, channels, depth mode,
 * scene, working colour space) as a JSON object in *json, which the
 * caller releases with exrfog_free. argv as for exrfog_run (no -o needed). */
EXRFOG_API exrfog_result exrfog_explain(exrfog_context *ctx, int argc, const char *const *argv,
                                        char **json);

/* Releases memory the library returned. */
EXRFOG_API void exrfog_free(void *p);

#ifdef __cplusplus
}
#endif

#endif
