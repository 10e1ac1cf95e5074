/* Scene files (--scene FILE) and the scene flags of the command line
 * (--up-axis, --units-per-meter, visibility=, per-component color=).
 *
 *  - ef_scene_file_read on files written here: every key turned into the
 *    SPEC text or the value worked out by hand, numbers passed on without
 *    loss, relative profile paths taken from the scene file's directory,
 *    and every error naming the offending key by its path in the file;
 *  - ef_read_text_file: missing, directory, NUL byte, size limit;
 *  - the binary: --scene gives the pixels of the equivalent flags, flags
 *    override the file, bad files exit 1 with "exrfog: FILE: PATH: ..." and
 *    leave nothing behind, bad flag values exit 2 quoting the text, and
 *    units, visibility and per-component colours against values computed
 *    here from T = exp(-rho d) and the tau-weighted colour mean.
 *
 * Scratch files live in $EXRFOG_TMP_DIR/scene_file. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L
#endif

#include <dirent.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

#include <cmocka.h>

#include "fog.h"
#include "scene_file.h"
#include "tassert.h"
#include "testutil.h"

/* ------------------------------------------------------------ scratch files */

typedef struct path_t {
    char s[1024];
} path_t;

/* $EXRFOG_TMP_DIR/scene_file/<formatted> */
static path_t pth(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;
static path_t pth(const char *fmt, ...)
{
    static char root[512];
    if (!root[0]) {
        char *p = tu_path("scene_file");
        snprintf(root, sizeof root, "%s", p);
        free(p);
        mkdir(root, 0777);
    }
    path_t p;
    char rel[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(rel, sizeof rel, fmt, ap);
    va_end(ap);
    snprintf(p.s, sizeof p.s, "%s/%s", root, rel);
    return p;
}

static void spit(const char *path, const char *data, size_t len)
{
    assert_int_equal(tu_write_bytes(path, data, len), 0);
}

/* Writes text to scratch file name and returns its path. */
static path_t write_text(const char *name, const char *text)
{
    path_t p = pth("%s", name);
    spit(p.s, text, strlen(text));
    return p;
}

/* An empty scratch directory (files in it from an earlier run removed). */
static path_t fresh_dir(const char *name)
{
    path_t p = pth("%s", name);
    mkdir(p.s, 0777);
    DIR *d = opendir(p.s);
    assert_non_null(d);
    struct dirent *e;
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            char f[2048];
            snprintf(f, sizeof f, "%s/%s", p.s, e->d_name);
            unlink(f);
        }
    closedir(d);
    return p;
}

/* Number of entries of a directory besides . and .. (listed when verbose). */
static int dir_entries(const char *dir, int verbose)
{
    DIR *d = opendir(dir);
    assert_non_null(d);
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
            if (verbose)
                print_message("  left in %s: %s\n", dir, e->d_name);
            ++n;
        }
    closedir(d);
    return n;
}

/* ------------------------------------------------------------ reading */

static void read_ok(const char *json, ef_scene_file *sf, path_t *where)
{
    path_t p = write_text("ok.json", json);
    ef_err err = { .file = NULL };
    if (ef_scene_file_read(p.s, sf, &err)) {
        print_error("%s: %s\nfor:\n%s\n", p.s, err.msg, json);
        fail();
    }
    if (where)
        *where = p;
}

/* Reads json and expects a failure whose message starts with prefix and
 * contains needle (either may be NULL). Nothing may be left allocated. */
static void read_fails(const char *json, const char *prefix, const char *needle)
{
    path_t p = write_text("bad.json", json);
    ef_scene_file sf;
    ef_err err = { .file = NULL };
    if (ef_scene_file_read(p.s, &sf, &err) == 0) {
        print_error("accepted:\n%s\n", json);
        for (int i = 0; i < sf.nspec; ++i)
            print_error("  %s: %s\n", sf.where[i], sf.specs[i]);
        ef_scene_file_free(&sf);
        fail();
    }
    if ((prefix && strncmp(err.msg, prefix, strlen(prefix))) ||
        (needle && !strstr(err.msg, needle))) {
        print_error("for:\n%s\nmessage: %s\nwanted prefix '%s' and '%s'\n", json, err.msg,
                    prefix ? prefix : "", needle ? needle : "");
        fail();
    }
    assert_non_null(err.file);
    assert_string_equal(err.file, p.s);
    assert_int_equal(sf.nspec, 0);
    for (int i = 0; i < EF_FOG_MAX_COMPONENTS; ++i)
        assert_null(sf.specs[i]);
}

/* The brief's full example: every top-level key and every component form. */
static void test_full_example(void **state)
{
    (void) state;
    ef_scene_file sf;
    path_t p;
    read_ok("{\n"
            "  \"units\": 100,\n"
            "  \"up\": \"z\",\n"
            "  \"color\": [0.7, 0.75, 0.8],\n"
            "  \"sky\": {\"distance\": 1000},\n"
            "  \"fog\": [\n"
            "    {\"model\": \"halfspace\", \"plane\": [0,1,0,-1], \"density\": 0.15,\n"
            "     \"color\": [1,0.9,0.8]},\n"
            "    {\"model\": \"layered\", \"heights\": [0,10,50], \"densities\": [0.2,0.05,0]},\n"
            "    {\"model\": \"layered\", \"file\": \"profile.txt\"},\n"
            "    \"exp:density=0.02\"\n"
            "  ]\n"
            "}\n",
            &sf, &p);
    assert_int_equal(sf.has_units, 1);
    assert_true(sf.units == 100.0);
    assert_int_equal(sf.has_up, 1);
    assert_true(sf.up[0] == 0.0 && sf.up[1] == 0.0 && sf.up[2] == 1.0);
    assert_int_equal(sf.has_color, 1);
    assert_true(sf.color[0] == 0.7 && sf.color[1] == 0.75 && sf.color[2] == 0.8);
    assert_int_equal(sf.has_sky, 1);
    assert_string_equal(sf.sky, "distance=1000");
    assert_int_equal(sf.nspec, 4);
    assert_string_equal(sf.specs[0], "halfspace:plane=0,1,0,-1:density=0.15:color=1,0.9,0.8");
    assert_string_equal(sf.specs[1], "layered:heights=0,10,50:densities=0.2,0.05,0");
    char want[1200];
    snprintf(want, sizeof want, "layered:file=%.*s/profile.txt",
             (int) (strrchr(p.s, '/') - p.s), p.s);
    assert_string_equal(sf.specs[2], want);
    assert_string_equal(sf.specs[3], "exp:density=0.02");
    for (int i = 0; i < 4; ++i) {
        char w[16];
        snprintf(w, sizeof w, "fog[%d]", i);
        assert_string_equal(sf.where[i], w);
    }
    ef_scene_file_free(&sf);
    assert_int_equal(sf.nspec, 0);
    assert_null(sf.specs[0]);
}

/* An empty object sets nothing; keys not given stay unset. */
static void test_empty_and_partial(void **state)
{
    (void) state;
    ef_scene_file sf;
    read_ok("{}", &sf, NULL);
    assert_int_equal(sf.nspec + sf.has_color + sf.has_up + sf.has_units + sf.has_sky, 0);
    ef_scene_file_free(&sf);
    read_ok("{\"fog\": []}", &sf, NULL);
    assert_int_equal(sf.nspec, 0);
    ef_scene_file_free(&sf);
    /* One number is a grey colour; sky words pass as --sky takes them. */
    read_ok("{\"color\": 0.5, \"sky\": \"keep\"}", &sf, NULL);
    assert_true(sf.color[0] == 0.5 && sf.color[1] == 0.5 && sf.color[2] == 0.5);
    assert_string_equal(sf.sky, "keep");
    assert_int_equal(sf.has_up + sf.has_units, 0);
    ef_scene_file_free(&sf);
    read_ok("{\"sky\": \"fog\"}", &sf, NULL);
    assert_string_equal(sf.sky, "fog");
    ef_scene_file_free(&sf);
    /* Editors may write a UTF-8 byte order mark. */
    read_ok("\xEF\xBB\xBF{\"units\": 2.5}", &sf, NULL);
    assert_true(sf.units == 2.5);
    ef_scene_file_free(&sf);
}

/* Up axes: names, and vectors made unit length as --up-axis does. */
static void test_up_forms(void **state)
{
    (void) state;
    static const struct {
        const char *json;
        double up[3];
    } cases[] = {
        { "{\"up\": \"y\"}", { 0, 1, 0 } },
        { "{\"up\": \"-y\"}", { 0, -1, 0 } },
        { "{\"up\": \"-z\"}", { 0, 0, -1 } },
        { "{\"up\": [0, 0, 2]}", { 0, 0, 1 } },
        { "{\"up\": [0, -3, 0]}", { 0, -1, 0 } },
        { "{\"up\": [3, 0, 4]}", { 0.6, 0, 0.8 } },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        ef_scene_file sf;
        read_ok(cases[i].json, &sf, NULL);
        assert_int_equal(sf.has_up, 1);
        for (int k = 0; k < 3; ++k)
            assert_close(sf.up[k], cases[i].up[k], 1e-16);
        ef_scene_file_free(&sf);
    }
}

/* The value of key in spec (after "key="), up to the next ':'. */
static void spec_value(const char *spec, const char *key, char *out, size_t len)
{
    char pat[64];
    snprintf(pat, sizeof pat, ":%s=", key);
    const char *s = strstr(spec, pat);
    assert_non_null(s);
    s += strlen(pat);
    const size_t n = strcspn(s, ":");
    assert_true(n < len);
    memcpy(out, s, n);
    out[n] = '\0';
}

/* Numbers reach the SPEC without loss: each value written in the file reads
 * back from the SPEC as the double the C compiler makes of the same text. */
static void test_numbers_lossless(void **state)
{
    (void) state;
    static const struct {
        const char *text;
        double v;
    } nums[] = {
        { "0.1", 0.1 },
        { "0.30000000000000004", 0.30000000000000004 },
        { "0.3", 0.3 },
        { "1e-9", 1e-9 },
        { "1e6", 1e6 },
        { "5e-324", 5e-324 },
        { "2.2250738585072014e-308", 2.2250738585072014e-308 },
        { "1.7976931348623157e308", 1.7976931348623157e308 },
        { "123456789012345678", 123456789012345678.0 },
        { "9007199254740993", 9007199254740993.0 },
        { "3.14159265358979323846264338", 3.14159265358979323846264338 },
        { "0.1234567890123456789", 0.1234567890123456789 },
        { "-2.5e-7", -2.5e-7 },
        { "7", 7.0 },
    };
    for (size_t i = 0; i < sizeof nums / sizeof nums[0]; ++i) {
        char json[256], val[64];
        snprintf(json, sizeof json, "{\"fog\": [{\"model\": \"exp\", \"density\": %s}]}",
                 nums[i].text);
        ef_scene_file sf;
        read_ok(json, &sf, NULL);
        spec_value(sf.specs[0], "density", val, sizeof val);
        const double got = strtod(val, NULL);
        if (got != nums[i].v) {
            print_error("%s became '%s' = %.17g, expected %.17g\n", nums[i].text, val, got,
                        nums[i].v);
            fail();
        }
        ef_scene_file_free(&sf);
    }
    /* The shortest text that reads back: 0.1 is "0.1", not 0.10000000000000001. */
    ef_scene_file sf;
    read_ok("{\"fog\": [{\"model\": \"exp\", \"density\": 0.1}]}", &sf, NULL);
    assert_string_equal(sf.specs[0], "exp:density=0.1");
    ef_scene_file_free(&sf);
    /* -0 stays negative zero. */
    read_ok("{\"fog\": [{\"model\": \"linear\", \"start\": -0.0, \"end\": 5}]}", &sf, NULL);
    assert_string_equal(sf.specs[0], "linear:start=-0:end=5");
    ef_scene_file_free(&sf);
    /* The units and the sky distance are exact too. */
    read_ok("{\"units\": 0.30000000000000004, \"sky\": {\"distance\": 0.1}}", &sf, NULL);
    assert_true(sf.units == 0.30000000000000004);
    assert_string_equal(sf.sky, "distance=0.1");
    ef_scene_file_free(&sf);
}

/* Value shapes: R,G,B arrays, vectors, plane lists, per-channel profile
 * entries, words; keys keep the file's order, the model comes first. */
static void test_value_shapes(void **state)
{
    (void) state;
    static const struct {
        const char *comp, *spec;
    } cases[] = {
        { "{\"density\": 0.01, \"model\": \"exp\"}", "exp:density=0.01" },
        { "{\"model\": \"exp\", \"density\": [0.01, 0.02, 0.03], \"distance\": \"planar\"}",
          "exp:density=0.01,0.02,0.03:distance=planar" },
        { "{\"model\": \"exp\", \"visibility\": [100, 200, 300.5]}",
          "exp:visibility=100,200,300.5" },
        { "{\"model\": \"layered\", \"heights\": [0, 10, 50],"
          " \"densities\": [0.2, [0.05, 0.1, 0.2], 0], \"up\": [0, 0, 1]}",
          "layered:heights=0,10,50:densities=0.2,0.05/0.1/0.2,0:up=0,0,1" },
        { "{\"model\": \"layered\", \"heights\": [0, 1], \"densities\": [1, 2], \"up\": \"-z\"}",
          "layered:heights=0,1:densities=1,2:up=-z" },
        { "{\"model\": \"box\", \"min\": [-1, -2, -3], \"max\": [1, 2, 3], \"density\": 0.5}",
          "box:min=-1,-2,-3:max=1,2,3:density=0.5" },
        { "{\"model\": \"convex\", \"planes\": [[0, 1, 0, -1], [1, 0, 0, -5]], \"density\": 2}",
          "convex:planes=0,1,0,-1,1,0,0,-5:density=2" },
        { "{\"model\": \"convex\", \"planes\": [0, 1, 0, -1, 1, 0, 0, -5], \"density\": 2}",
          "convex:planes=0,1,0,-1,1,0,0,-5:density=2" },
        { "{\"model\": \"halfspace-smooth\", \"plane\": [0, 1, 0, 0], \"density\": 0.1,"
          " \"sharpness\": 3}",
          "halfspace-smooth:plane=0,1,0,0:density=0.1:sharpness=3" },
        { "{\"model\": \"halfspace-linear\", \"plane\": [0, 1, 0, 0], \"slope\": [1, 2, 3]}",
          "halfspace-linear:plane=0,1,0,0:slope=1,2,3" },
        { "{\"model\": \"height\", \"density\": 0.1, \"falloff\": 0.5, \"base\": -2}",
          "height:density=0.1:falloff=0.5:base=-2" },
        { "{\"model\": \"linear\", \"start\": 5, \"end\": 60, \"color\": 0.5}",
          "linear:start=5:end=60:color=0.5" },
        /* A key this reader does not know goes through for the model to judge. */
        { "{\"model\": \"exp\", \"future\": [1, 2], \"other\": \"word\", \"n\": 3}",
          "exp:future=1,2:other=word:n=3" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        char json[512];
        snprintf(json, sizeof json, "{\"fog\": [%s]}", cases[i].comp);
        ef_scene_file sf;
        read_ok(json, &sf, NULL);
        assert_int_equal(sf.nspec, 1);
        assert_string_equal(sf.specs[0], cases[i].spec);
        ef_scene_file_free(&sf);
    }
}

/* Relative profile paths are taken from the scene file's directory, in both
 * component forms; absolute ones are left alone. */
static void test_file_paths(void **state)
{
    (void) state;
    ef_scene_file sf;
    path_t p;
    read_ok("{\"fog\": [{\"model\": \"layered\", \"file\": \"sub/prof=1.txt\"},"
            " \"layered:file=prof.txt:up=z\","
            " {\"model\": \"layered\", \"file\": \"/abs/prof.txt\"},"
            " \"layered:up=z:file=/abs/p2.txt\"]}",
            &sf, &p);
    const int dl = (int) (strrchr(p.s, '/') - p.s);
    char want[1200];
    snprintf(want, sizeof want, "layered:file=%.*s/sub/prof=1.txt", dl, p.s);
    assert_string_equal(sf.specs[0], want);
    snprintf(want, sizeof want, "layered:file=%.*s/prof.txt:up=z", dl, p.s);
    assert_string_equal(sf.specs[1], want);
    assert_string_equal(sf.specs[2], "layered:file=/abs/prof.txt");
    assert_string_equal(sf.specs[3], "layered:up=z:file=/abs/p2.txt");
    ef_scene_file_free(&sf);

    /* A scene file named without a directory: paths stay relative to the
     * working directory, which is then the scene file's. */
    char cwd[1024];
    assert_non_null(getcwd(cwd, sizeof cwd));
    path_t dir = fresh_dir("cwd");
    write_text("cwd/s.json", "{\"fog\": [{\"model\": \"layered\", \"file\": \"prof.txt\"}]}");
    assert_int_equal(chdir(dir.s), 0);
    ef_err err = { .file = NULL };
    const int rc = ef_scene_file_read("s.json", &sf, &err);
    assert_int_equal(chdir(cwd), 0);
    assert_int_equal(rc, 0);
    assert_string_equal(sf.specs[0], "layered:file=prof.txt");
    ef_scene_file_free(&sf);

    /* A directory with ':' cannot prefix a relative path; an absolute one
     * still works from there. */
    path_t cd = pth("colon:dir");
    mkdir(cd.s, 0777);
    path_t s1 = write_text("colon:dir/s.json",
                           "{\"fog\": [{\"model\": \"layered\", \"file\": \"prof.txt\"}]}");
    err.msg[0] = '\0';
    assert_int_equal(ef_scene_file_read(s1.s, &sf, &err), -1);
    assert_string_equal(err.file, s1.s);
    assert_true(!strncmp(err.msg, "fog[0].file: ", 13));
    assert_contains(err.msg, "':'");
    assert_contains(err.msg, "absolute path");
    path_t s2 = write_text("colon:dir/s2.json", "{\"fog\": [\"layered:file=prof.txt\"]}");
    assert_int_equal(ef_scene_file_read(s2.s, &sf, &err), -1);
    assert_true(!strncmp(err.msg, "fog[0]: ", 8));
    assert_contains(err.msg, "':'");
    path_t s3 = write_text("colon:dir/s3.json",
                           "{\"fog\": [{\"model\": \"layered\", \"file\": \"/abs/prof.txt\"}]}");
    assert_int_equal(ef_scene_file_read(s3.s, &sf, &err), 0);
    assert_string_equal(sf.specs[0], "layered:file=/abs/prof.txt");
    ef_scene_file_free(&sf);
}

/* The messages the brief names, word for word. */
static void test_error_messages_exact(void **state)
{
    (void) state;
    path_t p = write_text("e.json", "{\"fog\": [{\"model\": \"exp\", \"density\": 0.1},\n"
                                    "          {\"model\": \"exp\", \"density\": \"0.1\"}]}");
    ef_scene_file sf;
    ef_err err;
    assert_int_equal(ef_scene_file_read(p.s, &sf, &err), -1);
    assert_string_equal(err.msg, "fog[1].density: expected a number or [R,G,B], got a string");

    p = write_text("e.json", "{\"units\": 1, \"colour\": [1, 1, 1]}");
    assert_int_equal(ef_scene_file_read(p.s, &sf, &err), -1);
    assert_string_equal(err.msg, "unknown key 'colour' (keys: units, up, color, sky, time, aov, fog, lights, sky_light)");

    p = write_text("e.json", "{\"units\": 0}");
    assert_int_equal(ef_scene_file_read(p.s, &sf, &err), -1);
    assert_true(!strncmp(err.msg, "units: must be > 0", 18));

    p = write_text("e.json", "{\"fog\": [{\"density\": 0.1}]}");
    assert_int_equal(ef_scene_file_read(p.s, &sf, &err), -1);
    assert_true(!strncmp(err.msg, "fog[0]: missing \"model\"", 23));
    /* The models that message lists are the registered ones. */
    const char *list = strchr(err.msg, '(');
    assert_non_null(list);
    char names[256];
    snprintf(names, sizeof names, "%s", list + strlen("(one of "));
    names[strcspn(names, ")")] = '\0';
    int n = 0;
    char *save = NULL;
    for (char *t = strtok_r(names, ", ", &save); t; t = strtok_r(NULL, ", ", &save), ++n)
        if (!ef_fog_model_find(t))
            fail_msg("'%s' listed but not a model", t);
    assert_int_equal(n, 10);

    /* JSON syntax: line and column of the ']' after a trailing comma, counted
     * by hand (line 3, column 13). */
    p = write_text("e.json", "{\n  \"units\": 100,\n  \"fog\": [1,]\n}\n");
    assert_int_equal(ef_scene_file_read(p.s, &sf, &err), -1);
    assert_true(!strncmp(err.msg, "line 3, column 13: ", 19));
}

/* Every error path: the message starts with the key's path in the file. */
static void test_errors_name_the_path(void **state)
{
    (void) state;
    static const struct {
        const char *json, *prefix, *needle;
    } cases[] = {
        /* top level */
        { "[1, 2]", "expected a JSON object at the top level", "got an array" },
        { "\"exp\"", "line 1", NULL },
        { "", "line 1, column 0", NULL },
        { "{\"units\": 1,}", "line 1", NULL },
        { "// comment\n{}", "line 1, column 1", "JSON has no comments" },
        { "{\"units\": 1, \"units\": 2}", "line 1", "duplicate object key" },
        { "{\"fog\": [{\"model\": \"exp\", \"density\": 1, \"density\": 2}]}", "line 1",
          "duplicate object key" },
        { "{\"units\": 1e999}", "line 1", NULL },
        { "{\"Units\": 1}", "unknown key 'Units'", NULL },
        { "{\"units\": -1}", "units: must be > 0", "got -1" },
        { "{\"units\": \"cm\"}", "units: expected a number", "got a string" },
        { "{\"units\": null}", "units: expected a number", "got null" },
        { "{\"up\": \"w\"}", "up: 'w' is not", "[X,Y,Z]" },
        { "{\"up\": [0, 0, 0]}", "up: ", "zero" },
        { "{\"up\": [0, 1]}", "up: expected", "got an array of 2" },
        { "{\"up\": [0, \"1\", 0]}", "up[1]: expected a number", "got a string" },
        { "{\"up\": true}", "up: expected", "got true" },
        { "{\"color\": \"grey\"}", "color: expected [R,G,B]", "got a string" },
        { "{\"color\": [1, 1]}", "color: expected [R,G,B]", "got an array of 2" },
        { "{\"color\": [1, false, 1]}", "color[1]: expected a number", "got false" },
        { "{\"color\": [1, -0.5, 1]}", "color: ", "-0.5" },
        { "{\"sky\": \"sometimes\"}", "sky: 'sometimes' is not", NULL },
        { "{\"sky\": 5}", "sky: expected", "got a number" },
        { "{\"sky\": {}}", "sky: missing \"distance\"", NULL },
        { "{\"sky\": {\"dist\": 5}}", "sky: unknown key 'dist'", "(keys: distance)" },
        { "{\"sky\": {\"distance\": 0}}", "sky.distance: must be > 0", NULL },
        { "{\"sky\": {\"distance\": -3}}", "sky.distance: must be > 0", "-3" },
        { "{\"sky\": {\"distance\": \"far\"}}", "sky.distance: expected a number", "got a string" },
        /* the component list */
        { "{\"fog\": {\"model\": \"exp\"}}", "fog: expected an array", "got an object" },
        { "{\"fog\": \"exp:density=1\"}", "fog: expected an array", "got a string" },
        { "{\"fog\": [\"exp:density=1\", 3]}", "fog[1]: expected", "got a number" },
        { "{\"fog\": [\"exp:density=1\", [1]]}", "fog[1]: expected", "got an array of 1" },
        { "{\"fog\": [\"\"]}", "fog[0]: ", "empty" },
        { "{\"fog\": [{}]}", "fog[0]: missing \"model\"", NULL },
        { "{\"fog\": [{\"model\": 3}]}", "fog[0].model: expected", "got a number" },
        { "{\"fog\": [{\"model\": \"\"}]}", "fog[0].model: ", "empty" },
        { "{\"fog\": [{\"model\": \"exp:density=1\"}]}", "fog[0].model: ", "':' or '='" },
        { "{\"fog\": [{\"model\": \"exp\", \"a:b\": 1}]}", "fog[0]: key 'a:b'", NULL },
        { "{\"fog\": [{\"model\": \"exp\", \"a=b\": 1}]}", "fog[0]: key 'a=b'", NULL },
        { "{\"fog\": [{\"model\": \"exp\", \"\": 1}]}", "fog[0]: key ''", NULL },
        /* component values */
        { "{\"fog\": [{\"model\": \"exp\", \"density\": [1, 2]}]}", "fog[0].density: expected",
          "got an array of 2" },
        { "{\"fog\": [{\"model\": \"exp\", \"density\": [1, \"2\", 3]}]}",
          "fog[0].density[1]: expected a number", "got a string" },
        { "{\"fog\": [{\"model\": \"exp\", \"density\": {\"r\": 1}}]}",
          "fog[0].density: expected a number or [R,G,B]", "got an object" },
        { "{\"fog\": [{\"model\": \"exp\", \"visibility\": null}]}", "fog[0].visibility: expected",
          "got null" },
        { "{\"fog\": [{\"model\": \"exp\", \"color\": \"red\"}]}",
          "fog[0].color: expected a number or [R,G,B]", "got a string" },
        { "{\"fog\": [{\"model\": \"linear\", \"end\": [60]}]}", "fog[0].end: expected a number",
          "got an array of 1" },
        { "{\"fog\": [{\"model\": \"halfspace\", \"plane\": [0, 1, 0]}]}",
          "fog[0].plane: expected [A,B,C,D]", "got an array of 3" },
        { "{\"fog\": [{\"model\": \"box\", \"min\": \"0,0,0\"}]}", "fog[0].min: expected [X,Y,Z]",
          "got a string" },
        { "{\"fog\": [{\"model\": \"convex\", \"planes\": [[0, 1, 0, 1], [1, 0, 0]]}]}",
          "fog[0].planes[1]: expected [A,B,C,D]", "got an array of 3" },
        { "{\"fog\": [{\"model\": \"convex\", \"planes\": [[1, 2, 3, 4], [1, \"x\", 3, 4]]}]}",
          "fog[0].planes[1][1]: expected a number", NULL },
        { "{\"fog\": [{\"model\": \"convex\", \"planes\": []}]}", "fog[0].planes: expected",
          "got an array of 0" },
        { "{\"fog\": [{\"model\": \"layered\", \"heights\": []}]}", "fog[0].heights: expected",
          "got an array of 0" },
        { "{\"fog\": [{\"model\": \"layered\", \"heights\": [0, \"10\"]}]}",
          "fog[0].heights[1]: expected a number", NULL },
        { "{\"fog\": [{\"model\": \"layered\", \"densities\": [0.1, [1, 2]]}]}",
          "fog[0].densities[1]: expected [R,G,B]", "got an array of 2" },
        { "{\"fog\": [{\"model\": \"layered\", \"densities\": [0.1, \"x\"]}]}",
          "fog[0].densities[1]: expected a number or [R,G,B]", "got a string" },
        { "{\"fog\": [{\"model\": \"layered\", \"densities\": 0.1}]}",
          "fog[0].densities: expected", "got a number" },
        { "{\"fog\": [{\"model\": \"layered\", \"up\": \"z:up\"}]}", "fog[0].up: ", "':' or '='" },
        { "{\"fog\": [{\"model\": \"layered\", \"up\": [0, 1]}]}", "fog[0].up: expected",
          "got an array of 2" },
        { "{\"fog\": [{\"model\": \"exp\", \"distance\": 1}]}",
          "fog[0].distance: expected a string", NULL },
        { "{\"fog\": [{\"model\": \"exp\", \"distance\": \"a=b\"}]}", "fog[0].distance: ",
          "':' or '='" },
        { "{\"fog\": [{\"model\": \"layered\", \"file\": 7}]}", "fog[0].file: expected a file path",
          NULL },
        { "{\"fog\": [{\"model\": \"layered\", \"file\": \"\"}]}", "fog[0].file: ", "empty" },
        { "{\"fog\": [{\"model\": \"layered\", \"file\": \"c:/prof.txt\"}]}", "fog[0].file: ",
          "contains ':'" },
        { "{\"fog\": [{\"model\": \"exp\", \"x\": null}]}", "fog[0].x: expected", "got null" },
        { "{\"fog\": [{\"model\": \"exp\", \"x\": \"a:b\"}]}", "fog[0].x: ", "':' or '='" },
        { "{\"fog\": [{\"model\": \"exp\", \"x\": [[1]]}]}", "fog[0].x[0]: expected a number",
          NULL },
        /* the error of the second component names it, not the first */
        { "{\"fog\": [{\"model\": \"exp\", \"density\": 1},"
          " {\"model\": \"exp\", \"density\": true}]}",
          "fog[1].density: ", "got true" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i)
        read_fails(cases[i].json, cases[i].prefix, cases[i].needle);
}

/* Limits: at most EF_FOG_MAX_COMPONENTS components, and a SPEC that fits
 * a component. */
static void test_limits(void **state)
{
    (void) state;
    static char json[32768];
    size_t n = (size_t) snprintf(json, sizeof json, "{\"fog\": [");
    for (int i = 0; i < EF_FOG_MAX_COMPONENTS; ++i)
        n += (size_t) snprintf(json + n, sizeof json - n, "%s\"exp:density=0.001\"", i ? "," : "");
    snprintf(json + n, sizeof json - n, "]}");
    ef_scene_file sf;
    read_ok(json, &sf, NULL);
    assert_int_equal(sf.nspec, EF_FOG_MAX_COMPONENTS);
    assert_string_equal(sf.where[EF_FOG_MAX_COMPONENTS - 1], "fog[31]");
    ef_scene_file_free(&sf);
    snprintf(json + n, sizeof json - n, ", \"exp:density=0.001\"]}");
    read_fails(json, "fog: has 33 components", "at most 32");

    /* The SPEC buffer's size fits; one more does not. "exp:density=" is 12
     * characters. */
    const size_t cap = EF_SPEC_MAX;
    static char digits[EF_SPEC_MAX + 17];
    memset(digits, '1', cap - 12);
    digits[cap - 12] = '\0';
    snprintf(json, sizeof json, "{\"fog\": [\"exp:density=%s\"]}", digits);
    read_ok(json, &sf, NULL);
    assert_int_equal(strlen(sf.specs[0]), cap);
    ef_scene_file_free(&sf);
    snprintf(json, sizeof json, "{\"fog\": [\"exp:density=%s1\"]}", digits);
    char most[64];
    snprintf(most, sizeof most, "at most %zu", cap);
    read_fails(json, "fog[0]: is too long", most);
    /* An inline profile that is too long says to use a file. */
    n = (size_t) snprintf(json, sizeof json, "{\"fog\": [{\"model\": \"layered\", \"heights\": [");
    for (int i = 0; i < 2000; ++i)
        n += (size_t) snprintf(json + n, sizeof json - n, "%s%d", i ? "," : "", i);
    snprintf(json + n, sizeof json - n, "]}]}");
    read_fails(json, "fog[0]: is too long", "file");
}

/* ef_read_text_file: contents, and every way a file can be wrong. */
static void test_read_text_file(void **state)
{
    (void) state;
    char *text = NULL;
    ef_err err = { .file = NULL };
    path_t p = write_text("t.txt", "0 1\n10 0.5\n");
    assert_int_equal(ef_read_text_file(p.s, &text, &err), 0);
    assert_string_equal(text, "0 1\n10 0.5\n");
    free(text);
    p = write_text("empty.txt", "");
    assert_int_equal(ef_read_text_file(p.s, &text, &err), 0);
    assert_string_equal(text, "");
    free(text);

    /* Larger than the first buffer. */
    const size_t big = 300000;
    char *data = malloc(big);
    for (size_t i = 0; i < big; ++i)
        data[i] = (char) ('a' + i % 26);
    p = pth("big.txt");
    spit(p.s, data, big);
    assert_int_equal(ef_read_text_file(p.s, &text, &err), 0);
    assert_int_equal(strlen(text), big);
    assert_memory_equal(text, data, big);
    free(text);
    free(data);

    path_t missing = pth("no-such-file.txt");
    unlink(missing.s);
    err.file = NULL;
    assert_int_equal(ef_read_text_file(missing.s, &text, &err), -1);
    assert_null(text);
    assert_string_equal(err.file, missing.s);
    assert_contains(err.msg, "cannot open");
    assert_contains(err.msg, "No such file");

    path_t dir = fresh_dir("adir");
    err.file = NULL;
    assert_int_equal(ef_read_text_file(dir.s, &text, &err), -1);
    assert_null(text);
    assert_string_equal(err.file, dir.s);
    assert_contains(err.msg, "directory");

    p = pth("nul.txt");
    spit(p.s, "abc\0def", 7);
    err.file = NULL;
    assert_int_equal(ef_read_text_file(p.s, &text, &err), -1);
    assert_null(text);
    assert_string_equal(err.file, p.s);
    assert_contains(err.msg, "NUL byte at offset 3");

    /* Just over 64 MB (sparse: no disk used) is refused by its size; exactly
     * 64 MB is read (and then refused for its NUL bytes, not its size). */
    p = pth("huge.txt");
    FILE *f = fopen(p.s, "wb");
    assert_non_null(f);
    assert_int_equal(ftruncate(fileno(f), (off_t) 64 * 1024 * 1024 + 1), 0);
    fclose(f);
    err.file = NULL;
    assert_int_equal(ef_read_text_file(p.s, &text, &err), -1);
    assert_null(text);
    assert_string_equal(err.file, p.s);
    assert_contains(err.msg, "64 MB");
    assert_int_equal(truncate(p.s, (off_t) 64 * 1024 * 1024), 0);
    assert_int_equal(ef_read_text_file(p.s, &text, &err), -1);
    assert_contains(err.msg, "NUL byte at offset 0");
    unlink(p.s);

    /* The scene reader reports the same errors, naming the scene file. */
    ef_scene_file sf;
    err.file = NULL;
    assert_int_equal(ef_scene_file_read(missing.s, &sf, &err), -1);
    assert_string_equal(err.file, missing.s);
    assert_contains(err.msg, "cannot open");
    p = pth("nul.json");
    spit(p.s, "{}\0", 3);
    assert_int_equal(ef_scene_file_read(p.s, &sf, &err), -1);
    assert_contains(err.msg, "NUL byte");
}

/* ------------------------------------------------------------ the binary */

#define W 32
#define H 24
#define FOV 60.0

static const float ID16[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };

/* A float R,G,B,A,Z frame, camera at the origin looking down +Z (identity
 * worldToCamera, CameraFov FOV). With sky, a few pixels have infinite depth
 * and some alpha below 1. Returns the path. */
static const char *frame(int sky)
{
    static path_t paths[2];
    path_t *p = &paths[sky != 0];
    if (p->s[0])
        return p->s;
    *p = pth("frame%d.exr", sky != 0);
    static float c[2][5][W * H];
    float(*ch)[W * H] = c[sky != 0];
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int i = y * W + x;
            ch[0][i] = 0.1f + 0.8f * (float) x / W;
            ch[1][i] = 0.2f + 0.5f * (float) y / H;
            ch[2][i] = 0.3f;
            ch[3][i] = 1.0f;
            ch[4][i] = 2.0f + (float) ((x * 7 + y * 13) % 50);
            if (sky && (x + y) % 11 == 0)
                ch[4][i] = INFINITY;
            if (sky && (x * y) % 7 == 3) {
                ch[3][i] = 0.5f;
                for (int k = 0; k < 3; ++k)
                    ch[k][i] *= 0.5f;
            }
        }
    static const char *const names[5] = { "R", "G", "B", "A", "Z" };
    tu_part part;
    tu_part_init(&part, W, H);
    for (int k = 0; k < 5; ++k)
        tu_part_add(&part, names[k], EXR_PIXEL_FLOAT, ch[k]);
    part.m44[0].name = "worldToCamera";
    memcpy(part.m44[0].m, ID16, sizeof ID16);
    part.f[0].name = "CameraFov";
    part.f[0].v = (float) FOV;
    assert_int_equal(tu_write_exr(p->s, &part, 1), 0);
    return p->s;
}

static void pinhole(tu_pinhole *pin)
{
    const int disp[4] = { 0, 0, W - 1, H - 1 };
    tu_pinhole_fov(pin, disp, FOV);
}

/* Runs exrfog on frame(sky) into dir/name with args; expects exit 0. */
static path_t run_ok(int sky, const char *dir, const char *name, const char *args)
{
    path_t out;
    /* The path is checked, not truncated: a short test directory is assumed. */
    if (snprintf(out.s, sizeof out.s, "%s/%s", dir, name) >= (int) sizeof out.s)
        fail_msg("path too long: %s/%s", dir, name);
    assert_run(0, "'%s' -o '%s' %s", frame(sky), out.s, args);
    return out;
}

/* Same pixels in every channel, bit for bit. */
static void assert_same_pixels(const char *a, const char *b)
{
    if (tu_compare_files(a, b, -1, NULL) != 0) {
        print_error("%s and %s differ\n", a, b);
        fail();
    }
}

/* Some pixel differs (the fog did something, or an option mattered). */
static void assert_differ(const char *a, const char *b)
{
    tu_image x, y;
    assert_int_equal(tu_read_image(a, 0, &x), 0);
    assert_int_equal(tu_read_image(b, 0, &y), 0);
    long diff = 0;
    for (int c = 0; c < 3; ++c) {
        const float *p = tu_image_f(&x, x.ch[c]), *q = tu_image_f(&y, x.ch[c]);
        assert_non_null(p);
        assert_non_null(q);
        for (int i = 0; i < x.w * x.h; ++i)
            diff += p[i] != q[i];
    }
    tu_image_free(&x);
    tu_image_free(&y);
    assert_true(diff > 0);
}

/* --scene gives the pixels of the equivalent --fog flags: exp with per
 * channel densities, linear, a SPEC string, the colour and the sky. */
static void test_cli_scene_equals_flags(void **state)
{
    (void) state;
    path_t dir = fresh_dir("cli_equal");
    path_t scene = write_text("cli_equal.json",
                              "{\"color\": [0.25, 0.5, 0.75],\n"
                              " \"sky\": {\"distance\": 40},\n"
                              " \"fog\": [{\"model\": \"exp\", \"density\": [0.01, 0.02, 0.03]},\n"
                              "         {\"model\": \"linear\", \"start\": 5, \"end\": 80,\n"
                              "          \"distance\": \"planar\"},\n"
                              "         \"exp2:density=0.004\"]}\n");
    char args[1200];
    snprintf(args, sizeof args, "--scene '%s'", scene.s);
    for (int sky = 0; sky < 2; ++sky) {
        path_t a = run_ok(sky, dir.s, "scene.exr", args);
        path_t b = run_ok(sky, dir.s, "flags.exr",
                          "--fog exp:density=0.01,0.02,0.03 "
                          "--fog linear:start=5:end=80:distance=planar --fog exp2:density=0.004 "
                          "--fog-color 0.25,0.5,0.75 --sky distance=40");
        assert_same_pixels(a.s, b.s);
        assert_differ(frame(sky), a.s);
    }
}

/* Flags override the file's colour, units, up axis and sky; --fog
 * components come after the file's. */
static void test_cli_flags_override_file(void **state)
{
    (void) state;
    path_t dir = fresh_dir("cli_override");
    path_t scene = write_text("cli_override.json",
                              "{\"color\": [1, 0, 0], \"units\": 100, \"up\": \"z\",\n"
                              " \"sky\": \"keep\",\n"
                              " \"fog\": [{\"model\": \"exp\", \"density\": 0.02}]}\n");
    char args[1200];
    snprintf(args, sizeof args,
             "--scene '%s' --fog-color 0.25,0.5,0.75 --units-per-meter 1 --up-axis y --sky fog "
             "--fog exp2:density=0.01", scene.s);
    path_t a = run_ok(1, dir.s, "override.exr", args);
    path_t b = run_ok(1, dir.s, "flags.exr",
                      "--fog exp:density=0.02 --fog exp2:density=0.01 --fog-color 0.25,0.5,0.75");
    assert_same_pixels(a.s, b.s);
    /* Only the colour overridden: the file's units (100) and sky (keep) hold. */
    snprintf(args, sizeof args, "--scene '%s' --fog-color 0.25,0.5,0.75", scene.s);
    a = run_ok(1, dir.s, "colour.exr", args);
    b = run_ok(1, dir.s, "flags2.exr",
               "--fog exp:density=0.0002 --fog-color 0.25,0.5,0.75 --sky keep");
    assert_same_pixels(a.s, b.s);
    /* And the file's own colour when no flag is given. */
    snprintf(args, sizeof args, "--scene '%s'", scene.s);
    path_t c = run_ok(1, dir.s, "filecolour.exr", args);
    b = run_ok(1, dir.s, "flags3.exr", "--fog exp:density=0.0002 --fog-color 1,0,0 --sky keep");
    assert_same_pixels(c.s, b.s);
    assert_differ(a.s, c.s);
}

/* A wrong scene file: exit 1, "exrfog: FILE: PATH: ...", and no output or
 * temporary file left. */
static void test_cli_bad_scene(void **state)
{
    (void) state;
    static const struct {
        const char *json, *msg;
    } cases[] = {
        { "{\"fog\": [{\"model\": \"exp\", \"density\": 0.1},\n"
          "         {\"model\": \"exp\", \"density\": \"thick\"}]}",
          "fog[1].density: expected a number or [R,G,B], got a string" },
        /* The model's own complaint, prefixed with the component's path. */
        { "{\"fog\": [{\"model\": \"exp\", \"density\": 0.1},\n"
          "         {\"model\": \"exp\", \"density\": -1}]}",
          "fog[1]: " },
        { "{\"fog\": [\"exp:density=0.1\", \"fogg:density=1\"]}", "fog[1]: " },
        { "{\"fog\": [{\"model\": \"exp\", \"density\": 0.1}],\n \"units\": 0}",
          "units: must be > 0" },
        { "{\"fog\": [{\"model\": \"exp\", \"density\": 0.1}], \"sky\": \"never\"}", "sky: " },
        { "{\"fog\": [{\"model\": \"exp\", \"density\": 0.1}], \"colour\": [1, 1, 1]}",
          "unknown key 'colour'" },
        { "{\"fog\": [{\"model\": \"exp\" \"density\": 0.1}]}", "line 1, column " },
    };
    path_t dir = fresh_dir("cli_bad");
    path_t scene = pth("cli_bad.json");
    char out[1100];
    snprintf(out, sizeof out, "%s/out.exr", dir.s);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        spit(scene.s, cases[i].json, strlen(cases[i].json));
        assert_run(1, "'%s' -o '%s' --scene '%s'", frame(0), out, scene.s);
        char want[1400];
        snprintf(want, sizeof want, "exrfog: %s: %s", scene.s, cases[i].msg);
        if (strncmp(tu_err, want, strlen(want))) {
            print_error("stderr:\n%s\nexpected to start with:\n%s\n", tu_err, want);
            fail();
        }
        assert_int_equal(dir_entries(dir.s, 1), 0);
    }
    /* The model's message quotes the offending text. */
    spit(scene.s, cases[1].json, strlen(cases[1].json));
    assert_run(1, "'%s' -o '%s' --scene '%s'", frame(0), out, scene.s);
    assert_contains(tu_err, "-1");
    /* A missing scene file. */
    path_t missing = pth("no-such-scene.json");
    unlink(missing.s);
    assert_run(1, "'%s' -o '%s' --scene '%s'", frame(0), out, missing.s);
    char want[1200];
    snprintf(want, sizeof want, "exrfog: %s: cannot open", missing.s);
    assert_contains(tu_err, want);
    assert_int_equal(dir_entries(dir.s, 1), 0);
    /* An existing output survives a bad scene file untouched. */
    path_t keep = run_ok(0, dir.s, "out.exr", "--fog exp:density=0.1");
    path_t ref = run_ok(0, dir.s, "ref.exr", "--fog exp:density=0.1");
    spit(scene.s, cases[0].json, strlen(cases[0].json));
    assert_run(1, "'%s' -o '%s' --scene '%s'", frame(0), keep.s, scene.s);
    assert_same_pixels(keep.s, ref.s);
    assert_int_equal(dir_entries(dir.s, 0), 2);
}

/* Bad --up-axis and --units-per-meter values: exit 2 quoting the text;
 * good ones are accepted. */
static void test_cli_bad_flag_values(void **state)
{
    (void) state;
    static const struct {
        const char *args, *needle;
    } cases[] = {
        { "--up-axis w", "--up-axis 'w'" },
        { "--up-axis 0,0,0", "'0,0,0'" },
        { "--up-axis 1,2", "'1,2'" },
        { "--up-axis ''", "''" },
        { "--units-per-meter 0", "--units-per-meter '0'" },
        { "--units-per-meter -100", "'-100'" },
        { "--units-per-meter cm", "'cm'" },
        { "--units-per-meter 1e999", "'1e999'" },
        { "--units-per-meter nan", "'nan'" },
        { "--fog exp:visibility=0", "visibility='0'" },
        { "--fog exp:visibility=-5", "'-5'" },
        { "--fog exp:density=0.1:visibility=10", "exp:density=0.1:visibility=10" },
        { "--fog exp:density=0.1:color=1,2", "color='1,2'" },
        { "--fog exp:density=0.1:color=-1,0,0", "'-1,0,0'" },
        { "--fog exp:density=0.1:color=1,1,1:color=1,1,1", "color" },
        { "--scene", "--scene" },
    };
    path_t dir = fresh_dir("cli_flags");
    char out[1100];
    snprintf(out, sizeof out, "%s/out.exr", dir.s);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        assert_run(2, "'%s' -o '%s' --fog exp:density=0.01 %s", frame(0), out, cases[i].args);
        if (!strstr(tu_err, cases[i].needle)) {
            print_error("`%s`: stderr does not quote \"%s\":\n%s", cases[i].args, cases[i].needle,
                        tu_err);
            fail();
        }
        assert_int_equal(dir_entries(dir.s, 1), 0);
    }
    /* Exp fog has no up: every valid axis leaves its pixels alone. */
    path_t ref = run_ok(0, dir.s, "ref.exr", "--fog exp:density=0.02");
    static const char *const axes[] = { "y", "z", "-y", "-z", "x", "0,0,2", "1,1,1" };
    for (size_t i = 0; i < sizeof axes / sizeof axes[0]; ++i) {
        char args[128];
        snprintf(args, sizeof args, "--fog exp:density=0.02 --up-axis %s", axes[i]);
        path_t o = run_ok(0, dir.s, "axis.exr", args);
        assert_same_pixels(ref.s, o.s);
    }
}

/* Densities are per metre: with U units per metre exp:density=D is
 * exp:density=D/U per unit (1.5/100 rounds to the double of 0.015, so the
 * pixels are bit-identical); linear's distances are scene units. */
static void test_cli_units(void **state)
{
    (void) state;
    path_t dir = fresh_dir("cli_units");
    path_t a = run_ok(1, dir.s, "u.exr", "--units-per-meter 100 --fog exp:density=1.5");
    path_t b = run_ok(1, dir.s, "d.exr", "--fog exp:density=0.015");
    assert_same_pixels(a.s, b.s);
    assert_differ(frame(1), a.s);
    a = run_ok(1, dir.s, "u.exr", "--units-per-meter 100 --fog exp:density=1.5,3,4.5");
    b = run_ok(1, dir.s, "d.exr", "--fog exp:density=0.015,0.03,0.045");
    assert_same_pixels(a.s, b.s);
    a = run_ok(1, dir.s, "u.exr", "--units-per-meter 0.5 --fog exp2:density=0.01");
    b = run_ok(1, dir.s, "d.exr", "--fog exp2:density=0.02");
    assert_same_pixels(a.s, b.s);
    /* The scene file's units do the same. */
    path_t scene = write_text("cli_units.json", "{\"units\": 100,"
                              " \"fog\": [{\"model\": \"exp\", \"density\": 1.5}]}");
    char args[1200];
    snprintf(args, sizeof args, "--scene '%s'", scene.s);
    a = run_ok(1, dir.s, "u.exr", args);
    b = run_ok(1, dir.s, "d.exr", "--fog exp:density=0.015");
    assert_same_pixels(a.s, b.s);
    /* linear:start/end are distances in the scene: units change nothing. */
    a = run_ok(1, dir.s, "u.exr", "--units-per-meter 100 --fog linear:start=5:end=40");
    b = run_ok(1, dir.s, "d.exr", "--fog linear:start=5:end=40");
    assert_same_pixels(a.s, b.s);
    /* And against T = exp(-rho d) worked out here, rho = 1.5/100 per unit. */
    a = run_ok(1, dir.s, "u.exr",
               "--units-per-meter 100 --fog exp:density=1.5 --fog-color 0.25,0.5,0.75");
    tu_pinhole pin;
    pinhole(&pin);
    tu_fog_check fc;
    tu_fog_check_init(&fc, frame(1), a.s, &pin, 0.015);
    assert_int_equal(tu_check_fog(&fc), 0);
    assert_true(fc.fogged > 0 && fc.sky > 0);
}

/* visibility=V is density=3.912/V, per channel too, and stays in metres
 * whatever the units. */
static void test_cli_visibility(void **state)
{
    (void) state;
    path_t dir = fresh_dir("cli_vis");
    tu_image x, y;
    /* 3.912/39.12 = 0.1 within an ulp or two: compare to float precision. */
    static const struct {
        const char *vis, *dens;
    } cases[] = {
        { "--fog exp:visibility=39.12", "--fog exp:density=0.1" },
        { "--fog exp:visibility=39.12,78.24,19.56", "--fog exp:density=0.1,0.05,0.2" },
        { "--units-per-meter 100 --fog exp:visibility=39.12", "--fog exp:density=0.001" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        path_t a = run_ok(1, dir.s, "v.exr", cases[i].vis);
        path_t b = run_ok(1, dir.s, "d.exr", cases[i].dens);
        assert_int_equal(tu_read_image(a.s, 0, &x), 0);
        assert_int_equal(tu_read_image(b.s, 0, &y), 0);
        for (int c = 0; c < 4; ++c)
            assert_int_equal(tu_compare_channel(&y, &x, x.ch[c], 1e-6, 0), 0);
        tu_image_free(&x);
        tu_image_free(&y);
        assert_differ(frame(1), a.s);
    }
    /* Against the formula directly, and from a scene file. */
    path_t scene = write_text("cli_vis.json",
                              "{\"color\": [0.25, 0.5, 0.75],"
                              " \"fog\": [{\"model\": \"exp\", \"visibility\": 39.12}]}");
    char args[1200];
    snprintf(args, sizeof args, "--scene '%s'", scene.s);
    path_t a = run_ok(1, dir.s, "s.exr", args);
    tu_pinhole pin;
    pinhole(&pin);
    tu_fog_check fc;
    tu_fog_check_init(&fc, frame(1), a.s, &pin, 3.912 / 39.12);
    assert_int_equal(tu_check_fog(&fc), 0);
    assert_true(fc.fogged > 0);
    /* At d = V the transmittance is 2% (3.912 = -ln 0.02 to four digits). */
    assert_close(exp(-3.912), 0.02, 1e-5);
}

/* Per-component colours: two exp components with colours c1, c2 and
 * densities r1, r2 scatter in (r1 c1 + r2 c2)/(r1 + r2), with T =
 * exp(-(r1 + r2) d). A component without color= uses the scene colour. */
static void test_cli_component_colours(void **state)
{
    (void) state;
    path_t dir = fresh_dir("cli_colour");
    const double r1 = 0.02, r2 = 0.05;
    const double c1[3] = { 1.0, 0.5, 0.0 }, c2[3] = { 0.0, 0.5, 1.0 };
    path_t a = run_ok(0, dir.s, "mix.exr",
                      "--fog exp:density=0.02:color=1,0.5,0 --fog exp:density=0.05:color=0,0.5,1 "
                      "--fog-color 0.9,0.9,0.9");
    /* One pixel by hand. */
    tu_pinhole pin;
    pinhole(&pin);
    const int px = 5, py = 7, i = py * W + px;
    tu_image in, out;
    assert_int_equal(tu_read_image(frame(0), 0, &in), 0);
    assert_int_equal(tu_read_image(a.s, 0, &out), 0);
    const double z = tu_image_f(&in, "Z")[i];
    assert_close(z, 2.0 + (px * 7 + py * 13) % 50, 0);
    const double d = z * tu_pinhole_ray_len(&pin, px, py);
    const double T = exp(-(r1 + r2) * d);
    assert_true(T > 0.05 && T < 0.95);
    static const char *const rgb[3] = { "R", "G", "B" };
    for (int k = 0; k < 3; ++k) {
        const double F = (r1 * c1[k] + r2 * c2[k]) / (r1 + r2);
        const double C = tu_image_f(&in, rgb[k])[i];
        const double want = T * C + (1.0 - T) * F;
        assert_close(tu_image_f(&out, rgb[k])[i], want, 1e-6 * (1.0 + fabs(want)));
    }
    tu_image_free(&in);
    tu_image_free(&out);
    /* Every pixel: grey fog of density r1 + r2 and colour the weighted mean. */
    tu_fog_check fc;
    tu_fog_check_init(&fc, frame(0), a.s, &pin, r1 + r2);
    for (int k = 0; k < 3; ++k)
        fc.F[k] = (r1 * c1[k] + r2 * c2[k]) / (r1 + r2);
    assert_int_equal(tu_check_fog(&fc), 0);
    assert_true(fc.fogged > 0);
    /* Without its own colour, the second component takes the scene's. */
    const double F0[3] = { 0.25, 0.5, 0.75 };
    path_t b = run_ok(0, dir.s, "half.exr",
                      "--fog exp:density=0.02:color=1,0.5,0 --fog exp:density=0.05 "
                      "--fog-color 0.25,0.5,0.75");
    tu_fog_check_init(&fc, frame(0), b.s, &pin, r1 + r2);
    for (int k = 0; k < 3; ++k)
        fc.F[k] = (r1 * c1[k] + r2 * F0[k]) / (r1 + r2);
    assert_int_equal(tu_check_fog(&fc), 0);
    /* The scene file's per-component colours do the same as the flags. */
    path_t scene = write_text("cli_colour.json",
                              "{\"color\": [0.9, 0.9, 0.9], \"fog\": [\n"
                              " {\"model\": \"exp\", \"density\": 0.02, \"color\": [1, 0.5, 0]},\n"
                              " {\"model\": \"exp\", \"density\": 0.05, \"color\": [0, 0.5, 1]}]}");
    char args[1200];
    snprintf(args, sizeof args, "--scene '%s'", scene.s);
    path_t s = run_ok(0, dir.s, "scene.exr", args);
    assert_same_pixels(a.s, s.s);
    /* Equal colours are the same as one scene colour. */
    path_t e1 = run_ok(1, dir.s, "eq1.exr",
                       "--fog exp:density=0.02:color=0.3,0.4,0.5 "
                       "--fog exp:density=0.05:color=0.3,0.4,0.5");
    path_t e2 = run_ok(1, dir.s, "eq2.exr",
                       "--fog exp:density=0.02 --fog exp:density=0.05 --fog-color 0.3,0.4,0.5");
    assert_int_equal(tu_read_image(e1.s, 0, &in), 0);
    assert_int_equal(tu_read_image(e2.s, 0, &out), 0);
    for (int k = 0; k < 4; ++k)
        assert_int_equal(tu_compare_channel(&out, &in, in.ch[k], 1e-6, 0), 0);
    tu_image_free(&in);
    tu_image_free(&out);
}

/* The analytic models through a scene file give the pixels of the same
 * --fog flags: vectors, nested planes, per-channel profile entries, a
 * profile file next to the scene, up and units. The models are written
 * alongside this reader; while one still refuses its SPEC this part is
 * skipped (their own tests cover them). */
static void test_cli_scene_analytic_models(void **state)
{
    (void) state;
    path_t dir = fresh_dir("cli_models");
    path_t prof = write_text("cli_models_profile.txt", "# height density\n0 0.05\n"
                                                       "500 0.01\n2000 0\n");
    path_t scene = write_text(
        "cli_models.json",
        "{\"units\": 100, \"up\": \"z\", \"color\": [0.6, 0.65, 0.7], \"fog\": [\n"
        " {\"model\": \"halfspace\", \"plane\": [0, 1, 0, -200], \"density\": 0.15,\n"
        "  \"color\": [1, 0.9, 0.8]},\n"
        " {\"model\": \"halfspace-smooth\", \"plane\": [0, 1, 0.5, -300], \"density\": 0.1,\n"
        "  \"sharpness\": 2},\n"
        " {\"model\": \"height\", \"density\": [0.02, 0.03, 0.04], \"falloff\": 0.5,\n"
        "  \"base\": 100},\n"
        " {\"model\": \"layered\", \"heights\": [0, 1000, 5000],\n"
        "  \"densities\": [[0.02, 0.025, 0.03], 0.005, 0]},\n"
        " {\"model\": \"layered\", \"file\": \"cli_models_profile.txt\", \"up\": [0, 1, 0]},\n"
        " {\"model\": \"box\", \"min\": [-500, -500, 1000], \"max\": [500, 500, 3000],\n"
        "  \"visibility\": 20},\n"
        " {\"model\": \"convex\", \"planes\": [[1, 0, 0, -300], [-1, 0, 0, -300],\n"
        "  [0, 0, 1, -4000], [0, 0, -1, 500]], \"density\": 0.3}]}\n");
    char fp[1200];
    snprintf(fp, sizeof fp, "layered:file=%s:up=0,1,0", prof.s);
    const char *const specs[] = {
        "halfspace:plane=0,1,0,-200:density=0.15:color=1,0.9,0.8",
        "halfspace-smooth:plane=0,1,0.5,-300:density=0.1:sharpness=2",
        "height:density=0.02,0.03,0.04:falloff=0.5:base=100",
        "layered:heights=0,1000,5000:densities=0.02/0.025/0.03,0.005,0",
        fp,
        "box:min=-500,-500,1000:max=500,500,3000:visibility=20",
        "convex:planes=1,0,0,-300,-1,0,0,-300,0,0,1,-4000,0,0,-1,500:density=0.3",
    };
    const int n = (int) (sizeof specs / sizeof specs[0]);
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.read_file = ef_read_text_file;
    for (int i = 0; i < n; ++i) {
        ef_fog_component c;
        ef_err err = { .file = NULL };
        if (ef_fog_parse(specs[i], &ctx, &c, &err)) {
            print_message("  skipped: '%s' is refused (%s); model not finished yet?\n", specs[i],
                          err.msg);
            return;
        }
        ef_fog_free(&c);
    }
    /* The reader's SPECs are the ones written here, path included. */
    ef_scene_file sf;
    ef_err err = { .file = NULL };
    assert_int_equal(ef_scene_file_read(scene.s, &sf, &err), 0);
    assert_int_equal(sf.nspec, n);
    for (int i = 0; i < n; ++i)
        assert_string_equal(sf.specs[i], specs[i]);
    ef_scene_file_free(&sf);
    char args[4096];
    snprintf(args, sizeof args, "--scene '%s'", scene.s);
    path_t a = run_ok(1, dir.s, "scene.exr", args);
    size_t len = (size_t) snprintf(args, sizeof args,
                                   "--units-per-meter 100 --up-axis z --fog-color 0.6,0.65,0.7");
    for (int i = 0; i < n; ++i)
        len += (size_t) snprintf(args + len, sizeof args - len, " --fog '%s'", specs[i]);
    path_t b = run_ok(1, dir.s, "flags.exr", args);
    assert_same_pixels(a.s, b.s);
    assert_differ(frame(1), a.s);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_full_example),
        cmocka_unit_test(test_empty_and_partial),
        cmocka_unit_test(test_up_forms),
        cmocka_unit_test(test_numbers_lossless),
        cmocka_unit_test(test_value_shapes),
        cmocka_unit_test(test_file_paths),
        cmocka_unit_test(test_error_messages_exact),
        cmocka_unit_test(test_errors_name_the_path),
        cmocka_unit_test(test_limits),
        cmocka_unit_test(test_read_text_file),
        cmocka_unit_test(test_cli_scene_equals_flags),
        cmocka_unit_test(test_cli_flags_override_file),
        cmocka_unit_test(test_cli_bad_scene),
        cmocka_unit_test(test_cli_bad_flag_values),
        cmocka_unit_test(test_cli_units),
        cmocka_unit_test(test_cli_visibility),
        cmocka_unit_test(test_cli_component_colours),
        cmocka_unit_test(test_cli_scene_analytic_models),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
