/* Scene files: JSON (jansson) turned into the SPEC strings, colour, sky, up
 * axis and units the command line would give. The model keys are checked
 * for shape here (so a wrong type is reported at its path in the file); their
 * meaning is left to the models, which parse the SPEC as they parse --fog. */
#include "scene_file.h"
#include "json_util.h"

#include "aov.h"

#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Scene and profile files are a few kilobytes; anything this big is the
 * wrong file, and reading it whole would only waste memory. */
#define EF_TEXT_FILE_MAX ((size_t) 64 * 1024 * 1024)


static const char top_keys[] = "units, up, color, sky, time, aov, fog, lights, sky_light";

/* ------------------------------------------------------------ text files */

int ef_read_text_file(const char *path, char **text, ef_err *err)
{
    *text = NULL;
    ef_err_set_file(err, path);   /* path may belong to a fog component freed on failure */
    /* Opened without blocking: a named pipe nobody writes to would wait
     * for ever in open(). Reads block again (a shell's <(...) pipe has its
     * writer); a pipe with no writer reads as empty at once. */
    const int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0)
        return ef_fail(err, "cannot open: %s", strerror(errno));
    const int fl = fcntl(fd, F_GETFL);
    FILE *fp = fl < 0 || fcntl(fd, F_SETFL, fl & ~O_NONBLOCK) < 0 ? NULL : fdopen(fd, "rb");
    if (!fp) {
        const int e = errno;
        close(fd);
        return ef_fail(err, "cannot open: %s", strerror(e));
    }
    struct stat sb;
    int fifo = 0;
    if (fstat(fileno(fp), &sb) == 0) {
        fifo = S_ISFIFO(sb.st_mode);
        if (S_ISDIR(sb.st_mode))
            return fclose(fp), ef_fail(err, "is a directory, not a text file");
        /* A regular file announces its size: refuse before reading it. */
        if (S_ISREG(sb.st_mode) && (unsigned long long) sb.st_size > EF_TEXT_FILE_MAX)
            return fclose(fp), ef_fail(err, "is %llu bytes, larger than the 64 MB a text file "
                                            "may have here (is it the right file?)",
                                       (unsigned long long) sb.st_size);
    }
    /* Read to the end whatever fstat said: pipes have no size, and a file
     * may grow while we read it. */
    size_t cap = 1 << 16, len = 0;
    char *buf = malloc(cap + 1);
    if (!buf)
        return fclose(fp), ef_fail(err, "out of memory reading it");
    for (;;) {
        if (len == cap) {
            if (cap > EF_TEXT_FILE_MAX) {
                free(buf);
                fclose(fp);
                return ef_fail(err, "is larger than the 64 MB a text file may have here (is it "
                                    "the right file?)");
            }
            const size_t ncap = cap * 2 > EF_TEXT_FILE_MAX + 1 ? EF_TEXT_FILE_MAX + 1 : cap * 2;
            char *nb = realloc(buf, ncap + 1);
            if (!nb) {
                free(buf);
                fclose(fp);
                return ef_fail(err, "out of memory reading it");
            }
            buf = nb;
            cap = ncap;
        }
        const size_t got = fread(buf + len, 1, cap - len, fp);
        len += got;
        if (got == 0)
            break;
    }
    const int rd_err = ferror(fp);
    const int rd_errno = errno;
    fclose(fp);
    if (rd_err) {
        free(buf);
        return ef_fail(err, "cannot read: %s", strerror(rd_errno));
    }
    if (len > EF_TEXT_FILE_MAX) {
        free(buf);
        return ef_fail(err, "is larger than the 64 MB a text file may have here (is it the right "
                            "file?)");
    }
    if (fifo && len == 0) {
        free(buf);
        return ef_fail(err, "is a FIFO (named pipe) that nothing was written to; give a regular "
                            "file");
    }
    const char *nul = memchr(buf, '\0', len);
    if (nul) {
        const size_t at = (size_t) (nul - buf);
        free(buf);
        return ef_fail(err, "contains a NUL byte at offset %zu: not a text file", at);
    }
    buf[len] = '\0';
    *text = buf;
    return 0;
}

/* ------------------------------------------------------------ helpers */

const char *ef_json_type_name(const json_t *v)
{
    switch (json_typeof(v)) {
    case JSON_OBJECT: return "an object";
    case JSON_ARRAY: return "an array";
    case JSON_STRING: return "a string";
    case JSON_INTEGER:
    case JSON_REAL: return "a number";
    case JSON_TRUE: return "true";
    case JSON_FALSE: return "false";
    case JSON_NULL: return "null";
    }
    return "a value";
}

int ef_json_expected(ef_err *err, const char *path, const char *what, const json_t *v)
{
    if (json_is_array(v))
        return ef_fail(err, "%s: expected %s, got an array of %zu", path, what, json_array_size(v));
    return ef_fail(err, "%s: expected %s, got %s", path, what, ef_json_type_name(v));
}

/* The shortest decimal that reads back as v: lossless like %.17g, but 0.1
 * stays "0.1" in the SPEC that messages quote. */
static void fmt_num(double v, char out[32])
{
    for (int prec = 15; prec <= 17; ++prec) {
        snprintf(out, 32, "%.*g", prec, v);
        if (strtod(out, NULL) == v)
            return;
    }
}

/* A growing SPEC; overflow is remembered and reported once at the end. */
typedef struct spec_buf {
    char s[EF_SPEC_MAX + 64];
    size_t n;
    int overflow;
} spec_buf;

static void put(spec_buf *b, const char *text)
{
    const size_t len = strlen(text);
    if (b->overflow || b->n + len >= sizeof b->s) {
        b->overflow = 1;
        return;
    }
    memcpy(b->s + b->n, text, len + 1);
    b->n += len;
}

static void put_num(spec_buf *b, double v)
{
    char t[32];
    fmt_num(v, t);
    put(b, t);
}

/* Appends the n numbers of array a, joined by sep; every element must be a
 * number (n == 0: any length >= 1). */
static int put_numbers(spec_buf *b, const json_t *a, size_t n, char sep, const char *path,
                       const char *what, ef_err *err)
{
    const size_t len = json_array_size(a);
    if (!json_is_array(a) || (n ? len != n : len == 0))
        return ef_json_expected(err, path, what, a);
    for (size_t i = 0; i < len; ++i) {
        const json_t *e = json_array_get(a, i);
        if (!json_is_number(e))
            return ef_fail(err, "%s[%zu]: expected a number, got %s", path, i, ef_json_type_name(e));
        if (i) {
            const char s[2] = { sep, '\0' };
            put(b, s);
        }
        put_num(b, json_number_value(e));
    }
    return 0;
}

/* Refuses the SPEC grammar's separators inside a word. */
static int check_word(const char *path, const char *s, ef_err *err)
{
    if (!*s)
        return ef_fail(err, "%s: is empty", path);
    if (strpbrk(s, ":="))
        return ef_fail(err, "%s: '%s' cannot contain ':' or '=' (they separate a SPEC's keys "
                            "and values)", path, s);
    return 0;
}

/* A file= path as the models will open it: relative paths are taken from
 * the scene file's directory. ':' cannot go through the SPEC grammar. */
static int put_file(spec_buf *b, const char *scene_path, const char *file, const char *path,
                    ef_err *err)
{
    if (!*file)
        return ef_fail(err, "%s: is empty (give the profile's path)", path);
    if (strchr(file, ':'))
        return ef_fail(err, "%s: the path '%s' contains ':', which a fog SPEC cannot carry; "
                            "rename the file or move it to a path without ':'", path, file);
    const char *slash = strrchr(scene_path, '/');
    if (file[0] != '/' && slash) {
        const size_t dirlen = (size_t) (slash - scene_path) + 1;
        if (memchr(scene_path, ':', dirlen))
            return ef_fail(err, "%s: '%s' is relative to the scene file's directory, whose path "
                                "contains ':', which a fog SPEC cannot carry; give an absolute "
                                "path or move the scene file", path, file);
        char dir[1024];
        if (dirlen >= sizeof dir)
            return ef_fail(err, "%s: the scene file's directory is too long a path", path);
        memcpy(dir, scene_path, dirlen);
        dir[dirlen] = '\0';
        put(b, dir);
    }
    put(b, file);
    return 0;
}

/* ------------------------------------------------------------ components */

/* What a model key's value may look like. Keys not listed take a number,
 * a word or an array of numbers, and the model judges them. */
typedef enum key_shape {
    K_ANY, K_RGB, K_NUM, K_VEC3, K_PLANE, K_PLANES, K_LIST, K_DLIST, K_AXIS, K_WORD, K_FILE
} key_shape;

static const struct {
    const char *key;
    key_shape shape;
} key_shapes[] = {
    { "density", K_RGB },    { "visibility", K_RGB }, { "slope", K_RGB },
    { "sharpness", K_RGB },  { "falloff", K_RGB },    { "color", K_RGB },
    { "start", K_NUM },      { "end", K_NUM },        { "base", K_NUM },
    { "min", K_VEC3 },       { "max", K_VEC3 },       { "plane", K_PLANE },
    { "planes", K_PLANES },  { "heights", K_LIST },   { "densities", K_DLIST },
    { "up", K_AXIS },        { "distance", K_WORD },  { "file", K_FILE },
};

static key_shape shape_of(const char *key)
{
    for (size_t i = 0; i < sizeof key_shapes / sizeof key_shapes[0]; ++i)
        if (!strcmp(key_shapes[i].key, key))
            return key_shapes[i].shape;
    return K_ANY;
}

/* Appends one value of a model key in SPEC form. */
static int put_value(spec_buf *b, const char *scene_path, const char *key, const json_t *v,
                     const char *path, ef_err *err)
{
    switch (shape_of(key)) {
    case K_RGB:
        if (json_is_number(v))
            return put_num(b, json_number_value(v)), 0;
        if (!json_is_array(v))
            return ef_json_expected(err, path, "a number or [R,G,B]", v);
        return put_numbers(b, v, 3, ',', path, "a number or [R,G,B]", err);
    case K_NUM:
        if (!json_is_number(v))
            return ef_json_expected(err, path, "a number", v);
        return put_num(b, json_number_value(v)), 0;
    case K_VEC3:
        return put_numbers(b, v, 3, ',', path, "[X,Y,Z]", err);
    case K_PLANE:
        return put_numbers(b, v, 4, ',', path, "[A,B,C,D]", err);
    case K_LIST:
        return put_numbers(b, v, 0, ',', path, "an array of numbers", err);
    case K_PLANES:
    case K_DLIST: {
        /* Planes may be [[A,B,C,D],...] or flat; a layered density may be
         * [R,G,B], which the SPEC writes R/G/B. */
        const int planes = shape_of(key) == K_PLANES;
        const char *what = planes ? "[[A,B,C,D], ...] or a flat array of numbers"
                                  : "an array of numbers or [R,G,B]";
        if (!json_is_array(v) || json_array_size(v) == 0)
            return ef_json_expected(err, path, what, v);
        for (size_t i = 0; i < json_array_size(v); ++i) {
            const json_t *e = json_array_get(v, i);
            char sub[200];
            snprintf(sub, sizeof sub, "%s[%zu]", path, i);
            if (i)
                put(b, ",");
            if (json_is_number(e))
                put_num(b, json_number_value(e));
            else if (!json_is_array(e))
                return ef_json_expected(err, sub, planes ? "a number or [A,B,C,D]" : "a number or [R,G,B]",
                                e);
            else if (put_numbers(b, e, planes ? 4 : 3, planes ? ',' : '/', sub,
                                 planes ? "[A,B,C,D]" : "[R,G,B]", err))
                return -1;
        }
        return 0;
    }
    case K_AXIS:
        if (json_is_string(v))
            return check_word(path, json_string_value(v), err) ? -1
                                                              : (put(b, json_string_value(v)), 0);
        return put_numbers(b, v, 3, ',', path, "\"y\", \"z\", \"-y\", \"-z\" or [X,Y,Z]", err);
    case K_WORD:
        if (!json_is_string(v))
            return ef_json_expected(err, path, "a string", v);
        return check_word(path, json_string_value(v), err) ? -1
                                                          : (put(b, json_string_value(v)), 0);
    case K_FILE:
        if (!json_is_string(v))
            return ef_json_expected(err, path, "a file path (a string)", v);
        return put_file(b, scene_path, json_string_value(v), path, err);
    case K_ANY:
        if (json_is_number(v))
            return put_num(b, json_number_value(v)), 0;
        if (json_is_string(v))
            return check_word(path, json_string_value(v), err) ? -1
                                                              : (put(b, json_string_value(v)), 0);
        return put_numbers(b, v, 0, ',', path, "a number, a string or an array of numbers", err);
    }
    return ef_fail(err, "%s: internal error (unknown key shape)", path);
}

/* Copies b into a malloc'd SPEC, refusing what a component cannot hold. */
static int finish_spec(const spec_buf *b, const char *where, char **out, ef_err *err)
{
    if (b->overflow || b->n > EF_SPEC_MAX)
        return ef_fail(err, "%s: is too long as a fog SPEC (%s%zu characters, at most %zu); put "
                            "a long profile in a file (\"file\": PATH)",
                       where, b->overflow ? "over " : "", b->n, EF_SPEC_MAX);
    *out = strdup(b->s);
    if (!*out)
        return ef_fail(err, "%s: out of memory", where);
    return 0;
}

/* {"model": NAME, KEY: VALUE, ...} -> "NAME:KEY=VALUE:...". */
static int object_spec_as(const json_t *o, const char *head, const char *heads,
                          const char *scene_path, const char *where, char **out, ef_err *err)
{
    spec_buf b = { .n = 0 };
    const json_t *model = json_object_get(o, head);
    char path[160];
    if (!model)
        return ef_fail(err, "%s: missing \"%s\" (one of %s)", where, head, heads);
    snprintf(path, sizeof path, "%s.%s", where, head);
    if (!json_is_string(model))
        return ef_json_expected(err, path, "a name (a string)", model);
    if (check_word(path, json_string_value(model), err))
        return -1;
    put(&b, json_string_value(model));
    const char *key;
    json_t *v;
    json_object_foreach((json_t *) o, key, v) {
        if (!strcmp(key, head))
            continue;
        if (!*key || strpbrk(key, ":="))
            return ef_fail(err, "%s: key '%s' is not a key name (it cannot be empty or contain "
                                "':' or '=')", where, key);
        snprintf(path, sizeof path, "%s.%s", where, key);
        put(&b, ":");
        put(&b, key);
        put(&b, "=");
        if (put_value(&b, scene_path, key, v, path, err))
            return -1;
    }
    return finish_spec(&b, where, out, err);
}

static int object_spec(const json_t *o, const char *scene_path, const char *where, char **out,
                       ef_err *err)
{
    return object_spec_as(o, "model", "linear, exp, exp2, halfspace, halfspace-linear, "
                          "halfspace-smooth, height, layered, box, convex", scene_path, where,
                          out, err);
}

/* A SPEC string as written, except that a relative file= path is taken from
 * the scene file's directory, as in the object form. */
static int string_spec(const char *s, const char *scene_path, const char *where, char **out,
                       ef_err *err)
{
    spec_buf b = { .n = 0 };
    if (!*s)
        return ef_fail(err, "%s: is an empty SPEC (write MODEL[:KEY=VALUE]...)", where);
    const char *tok = s;
    for (int first = 1;; first = 0) {
        const char *colon = strchr(tok, ':');
        const size_t len = colon ? (size_t) (colon - tok) : strlen(tok);
        char t[EF_SPEC_MAX + 1];
        if (len >= sizeof t)
            return ef_fail(err, "%s: is too long as a fog SPEC", where);
        memcpy(t, tok, len);
        t[len] = '\0';
        if (!first)
            put(&b, ":");
        if (!first && !strncmp(t, "file=", 5)) {
            put(&b, "file=");
            if (put_file(&b, scene_path, t + 5, where, err))
                return -1;
        } else {
            put(&b, t);
        }
        if (!colon)
            break;
        tok = colon + 1;
    }
    return finish_spec(&b, where, out, err);
}

/* ------------------------------------------------------------ top level */

static int read_units(const json_t *v, ef_scene_file *out, ef_err *err)
{
    if (!json_is_number(v))
        return ef_json_expected(err, "units", "a number (units per metre)", v);
    const double u = json_number_value(v);
    if (!(u > 0)) {
        char t[32];
        fmt_num(u, t);
        return ef_fail(err, "units: must be > 0, got %s (scene units per metre: 100 for a scene "
                            "in centimetres)", t);
    }
    out->units = u;
    out->has_units = 1;
    return 0;
}

static int read_up(const json_t *v, ef_scene_file *out, ef_err *err)
{
    static const char what[] = "\"y\", \"z\", \"-y\", \"-z\" or [X,Y,Z]";
    spec_buf b = { .n = 0 };
    if (json_is_string(v)) {
        if (ef_parse_up(json_string_value(v), out->up))
            return ef_fail(err, "up: '%s' is not %s (non-zero)", json_string_value(v), what);
    } else {
        /* Through the same parser as --up-axis X,Y,Z, losslessly. */
        if (put_numbers(&b, v, 3, ',', "up", what, err))
            return -1;
        if (ef_parse_up(b.s, out->up))
            return ef_fail(err, "up: [%s] has zero length (give a non-zero direction)", b.s);
    }
    out->has_up = 1;
    return 0;
}

static int read_color(const json_t *v, ef_scene_file *out, ef_err *err)
{
    if (json_is_number(v)) {
        out->color[0] = out->color[1] = out->color[2] = json_number_value(v);
    } else {
        if (!json_is_array(v) || json_array_size(v) != 3)
            return ef_json_expected(err, "color", "[R,G,B]", v);
        for (size_t i = 0; i < 3; ++i) {
            const json_t *e = json_array_get(v, i);
            if (!json_is_number(e))
                return ef_fail(err, "color[%zu]: expected a number, got %s", i, ef_json_type_name(e));
            out->color[i] = json_number_value(e);
        }
    }
    for (int i = 0; i < 3; ++i)
        if (!(out->color[i] >= 0)) {
            char t[32];
            fmt_num(out->color[i], t);
            return ef_fail(err, "color: %s is negative (a scene-linear colour has R,G,B >= 0)", t);
        }
    out->has_color = 1;
    return 0;
}

static int read_sky(const json_t *v, ef_scene_file *out, ef_err *err)
{
    static const char what[] = "\"fog\", \"keep\" or {\"distance\": D}";
    if (json_is_string(v)) {
        const char *s = json_string_value(v);
        if (strcmp(s, "fog") && strcmp(s, "keep"))
            return ef_fail(err, "sky: '%s' is not %s", s, what);
        snprintf(out->sky, sizeof out->sky, "%s", s);
    } else if (json_is_object(v)) {
        const char *key;
        json_t *e;
        json_object_foreach((json_t *) v, key, e)
            if (strcmp(key, "distance"))
                return ef_fail(err, "sky: unknown key '%s' (keys: distance)", key);
        const json_t *d = json_object_get(v, "distance");
        if (!d)
            return ef_fail(err, "sky: missing \"distance\" (write {\"distance\": D})");
        if (!json_is_number(d))
            return ef_json_expected(err, "sky.distance", "a number", d);
        char t[32];
        fmt_num(json_number_value(d), t);
        if (!(json_number_value(d) > 0))
            return ef_fail(err, "sky.distance: must be > 0, got %s", t);
        snprintf(out->sky, sizeof out->sky, "distance=%s", t);
    } else {
        return ef_json_expected(err, "sky", what, v);
    }
    out->has_sky = 1;
    return 0;
}

static int read_time(const json_t *v, ef_scene_file *out, ef_err *err)
{
    if (!json_is_number(v))
        return ef_json_expected(err, "time", "a number (seconds)", v);
    out->time = json_number_value(v);
    out->has_time = 1;
    return 0;
}

/* "fog,T" or ["fog", "T"]. */
static int read_aov(const json_t *v, ef_scene_file *out, ef_err *err)
{
    static const char what[] = "a comma list or an array of AOV names (" EF_AOV_NAMES ")";
    if (json_is_string(v))
        return ef_aov_parse(json_string_value(v), &out->aov, "aov:", err);
    if (!json_is_array(v) || json_array_size(v) == 0)
        return ef_json_expected(err, "aov", what, v);
    for (size_t i = 0; i < json_array_size(v); ++i) {
        const json_t *e = json_array_get(v, i);
        char where[32];
        snprintf(where, sizeof where, "aov[%zu]:", i);
        if (!json_is_string(e))
            return ef_fail(err, "aov[%zu]: expected an AOV name (a string), got %s", i,
                           ef_json_type_name(e));
        if (ef_aov_parse(json_string_value(e), &out->aov, where, err))
            return -1;
    }
    return 0;
}

static int read_fog(const json_t *v, const char *path, ef_scene_file *out, ef_err *err)
{
    if (!json_is_array(v))
        return ef_json_expected(err, "fog", "an array of components", v);
    if (json_array_size(v) > EF_FOG_MAX_COMPONENTS)
        return ef_fail(err, "fog: has %zu components, at most %d are allowed",
                       json_array_size(v), EF_FOG_MAX_COMPONENTS);
    for (size_t i = 0; i < json_array_size(v); ++i) {
        const json_t *c = json_array_get(v, i);
        char *where = out->where[out->nspec];
        snprintf(where, sizeof out->where[0], "fog[%zu]", i);
        char **spec = &out->specs[out->nspec];
        if (json_is_object(c)) {
            if (object_spec(c, path, where, spec, err))
                return -1;
        } else if (json_is_string(c)) {
            if (string_spec(json_string_value(c), path, where, spec, err))
                return -1;
        } else {
            return ef_json_expected(err, where, "a component object or a SPEC string", c);
        }
        out->nspec++;
    }
    return 0;
}

/* "lights": [{"kind": "sun", "towards": [0, 1, 1], ...} or "sun:towards=..."]. */
static int read_lights(const json_t *v, const char *path, ef_scene_file *out, ef_err *err)
{
    if (!json_is_array(v))
        return ef_json_expected(err, "lights", "an array of lights", v);
    if (json_array_size(v) > EF_MAX_LIGHTS)
        return ef_fail(err, "lights: has %zu lights, at most %d are allowed", json_array_size(v),
                       EF_MAX_LIGHTS);
    for (size_t i = 0; i < json_array_size(v); ++i) {
        const json_t *c = json_array_get(v, i);
        char *where = out->lwhere[out->nlight];
        snprintf(where, sizeof out->lwhere[0], "lights[%zu]", i);
        char **spec = &out->lights[out->nlight];
        if (json_is_object(c)) {
            if (object_spec_as(c, "kind", "sun, point, spot", path, where, spec, err))
                return -1;
        } else if (json_is_string(c)) {
            if (string_spec(json_string_value(c), path, where, spec, err))
                return -1;
        } else {
            return ef_json_expected(err, where, "a light object or a --light SPEC string", c);
        }
        out->nlight++;
    }
    return 0;
}

static int read_root(const json_t *root, const char *path, ef_scene_file *out, ef_err *err)
{
    if (!json_is_object(root))
        return ef_fail(err, "expected a JSON object at the top level (keys: %s), got %s",
                       top_keys, ef_json_type_name(root));
    const char *key;
    json_t *v;
    json_object_foreach((json_t *) root, key, v) {
        int rc;
        if (!strcmp(key, "units"))
            rc = read_units(v, out, err);
        else if (!strcmp(key, "up"))
            rc = read_up(v, out, err);
        else if (!strcmp(key, "color"))
            rc = read_color(v, out, err);
        else if (!strcmp(key, "sky"))
            rc = read_sky(v, out, err);
        else if (!strcmp(key, "fog"))
            rc = read_fog(v, path, out, err);
        else if (!strcmp(key, "time"))
            rc = read_time(v, out, err);
        else if (!strcmp(key, "aov"))
            rc = read_aov(v, out, err);
        else if (!strcmp(key, "lights"))
            rc = read_lights(v, path, out, err);
        else if (!strcmp(key, "sky_light"))
            rc = !json_is_string(v)
                     ? ef_json_expected(err, "sky_light", "a --sky-light SPEC string "
                                        "(\"env.exr:rotate=90\")", v)
                     : (out->sky_light = strdup(json_string_value(v))) ? 0
                     : ef_fail(err, "out of memory");
        else
            rc = ef_fail(err, "unknown key '%s' (keys: %s)", key, top_keys);
        if (rc)
            return -1;
    }
    return 0;
}

int ef_scene_file_read(const char *path, ef_scene_file *out, ef_err *err)
{
    memset(out, 0, sizeof *out);
    char *text;
    if (ef_read_text_file(path, &text, err))
        return -1;
    if (err)
        err->file = path;
    /* A UTF-8 byte order mark is not JSON, but editors write one. */
    const size_t skip = !strncmp(text, "\xEF\xBB\xBF", 3) ? 3 : 0;
    json_error_t jerr;
    json_t *root = json_loadb(text + skip, strlen(text + skip),
                              JSON_REJECT_DUPLICATES | JSON_DECODE_INT_AS_REAL, &jerr);
    out->text = text;
    if (!root) {
        ef_scene_file_free(out);
        return ef_fail(err, "line %d, column %d: %s%s", jerr.line, jerr.column, jerr.text,
                       strstr(jerr.text, "near '/") ? " (JSON has no comments)" : "");
    }
    const int rc = read_root(root, path, out, err);
    json_decref(root);
    if (rc) {
        ef_scene_file_free(out);
        return -1;
    }
    return 0;
}

void ef_scene_file_free(ef_scene_file *f)
{
    for (int i = 0; i < EF_FOG_MAX_COMPONENTS; ++i) {
        free(f->specs[i]);
        f->specs[i] = NULL;
    }
    f->nspec = 0;
    for (int i = 0; i < EF_MAX_LIGHTS; ++i) {
        free(f->lights[i]);
        f->lights[i] = NULL;
    }
    f->nlight = 0;
    free(f->sky_light);
    f->sky_light = NULL;
    free(f->text);
    f->text = NULL;
}
