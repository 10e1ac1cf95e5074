/* Valid files that fuzzing found exrfog refusing or mishandling
 * (fuzz/regressions, made by this project). Each must now go through with
 * its header intact, and messages must not carry raw control bytes. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "tassert.h"
#include "testutil.h"

#define CAMERA_FLAGS "--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fov 40"

static char *regression(const char *name)
{
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    size_t n = strlen(src ? src : ".") + strlen(name) + 32;
    char *p = malloc(n);
    snprintf(p, n, "%s/fuzz/regressions/%s", src ? src : ".", name);
    return p;
}

/* Every attribute of part 0 of `in` appears in `out` with the same type name. */
static void assert_header_kept(const char *in, const char *out)
{
    exr_context_t a, b;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    int32_t n = 0;
    assert_int_equal(exr_start_read(&a, in, &init), EXR_ERR_SUCCESS);
    assert_int_equal(exr_start_read(&b, out, &init), EXR_ERR_SUCCESS);
    exr_get_attribute_count(a, 0, &n);
    for (int32_t i = 0; i < n; ++i) {
        const exr_attribute_t *x, *y;
        assert_int_equal(exr_get_attribute_by_index(a, 0, EXR_ATTR_LIST_FILE_ORDER, i, &x), 0);
        if (!strcmp(x->name, "chunkCount"))
            continue;
        if (exr_get_attribute_by_name(b, 0, x->name, &y) != EXR_ERR_SUCCESS)
            fail_msg("attribute '%s' was dropped", x->name);
        assert_string_equal(x->type_name, y->type_name);
    }
    exr_finish(&a);
    exr_finish(&b);
}

static void fog_through(const char *name)
{
    char *in = regression(name), *out = tu_path("regress.out.exr");
    assert_run(0, "'%s' -o '%s' " CAMERA_FLAGS " --fog exp:density=0.1", in, out);
    assert_header_kept(in, out);
    free(in);
    free(out);
}

/* Blender view layers make channel names longer than 31 bytes. */
static void test_long_channel_names(void **state)
{
    (void) state;
    fog_through("long_channel_names.exr");
    char *out = tu_path("regress.out.exr");
    int w, h;
    float *r = tu_read_channel(out, 0, "Forest_Night_ViewLayer.Combined.R", &w, &h);
    assert_non_null(r);
    free(r);
    free(out);
}

static void test_long_attribute_name(void **state)
{
    (void) state;
    fog_through("long_attribute_name.exr");
}

/* An attribute of a user-defined type ("myType") is copied as it is. */
static void test_opaque_attribute(void **state)
{
    (void) state;
    fog_through("opaque_attribute.exr");
}

/* A header attribute named ESC[2J ESC[H must not reach the terminal raw. */
static void test_escape_in_message(void **state)
{
    (void) state;
    char *in = regression("escape_in_attribute_name.exr"), *out = tu_path("regress.esc.exr");
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.1", in, out);
    assert_null(strchr(tu_err, 0x1b));
    assert_contains(tu_err, "\\x1b[2J");
    assert_false(tu_exists(out));
    free(in);
    free(out);
}

/* A required attribute repeated with the wrong type: Core reads the header
 * but complains; exrfog refuses it rather than copying a broken header. */
static void test_corrupt_required_attribute(void **state)
{
    (void) state;
    char *in = regression("wrong_type_required_attr.exr"), *out = tu_path("regress.type.exr");
    assert_run(1, "'%s' -o '%s' " CAMERA_FLAGS " --fog exp:density=0.1", in, out);
    assert_contains(tu_err, "header is corrupt");
    assert_contains(tu_err, "screenWindowWidth");
    assert_false(tu_exists(out));
    free(in);
    free(out);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_long_channel_names),
        cmocka_unit_test(test_long_attribute_name),
        cmocka_unit_test(test_opaque_attribute),
        cmocka_unit_test(test_escape_in_message),
        cmocka_unit_test(test_corrupt_required_attribute),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
