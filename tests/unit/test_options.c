/* Options: speed for size (--compression zip:LEVEL), and the parser run twice in one process. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <cmocka.h>

#include "tassert.h"
#include "args.h"
#include "colour.h"
#include "testutil.h"

static long file_size(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0 ? (long) sb.st_size : -1;
}

static char *sample(void)
{
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    size_t n = strlen(src ? src : ".") + 32;
    char *p = malloc(n);
    snprintf(p, n, "%s/samples/sample.exr", src ? src : ".");
    return p;
}

/* zlib levels change the size, never the pixels: level 1 is larger than
 * level 9 and both decode to the same values. */
static void test_zip_levels(void **state)
{
    (void) state;
    char *in = sample(), *fast = tu_path("opt_zip1.exr"), *small = tu_path("opt_zip9.exr");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.02 --compression zip:1", in, fast);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.02 --compression zip:9", in, small);
    assert_true(file_size(fast) > file_size(small));
    static const char *const ch[] = { "R", "G", "B", "A", "Z" };
    for (int k = 0; k < 5; ++k) {
        int w1, h1, w9, h9;
        float *a = tu_read_channel(fast, 0, ch[k], &w1, &h1);
        float *b = tu_read_channel(small, 0, ch[k], &w9, &h9);
        assert_non_null(a);
        assert_non_null(b);
        assert_true(w1 == w9 && h1 == h9);
        assert_memory_equal(a, b, sizeof(float) * (size_t) w1 * (size_t) h1);
        free(a);
        free(b);
    }
    free(in);
    free(fast);
    free(small);
}

static void test_zip_level_errors(void **state)
{
    (void) state;
    char *in = sample(), *out = tu_path("opt_bad.exr");
    static const char *const bad[] = { "zip:0", "zip:10", "zip:", "zip:x", "piz:3", "none:1" };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        assert_run(2, "'%s' -o '%s' --fog exp:density=0.02 --compression %s", in, out, bad[i]);
        assert_contains(tu_err, bad[i]);
        assert_false(tu_exists(out));
    }
    /* a level of zip out of range says so (it said zip takes no level) */
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.02 --compression zip:12", in, out);
    assert_contains(tu_err, "the zlib level 12 is out of range (1 fastest to 9 smallest");
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.02 --compression zips:x", in, out);
    assert_contains(tu_err, "not a whole number");
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.02 --compression piz:3", in, out);
    assert_contains(tu_err, "only zip and zips");
    free(in);
    free(out);
}

/* Found by fuzz/fuzz_cli: the parser reset getopt with optind = 1, so a
 * parse that stopped inside a cluster of short options ("-vZ") left glibc
 * pointing into that argv, and the next parse in the same process read it
 * after it was freed (ASan: heap-use-after-free). Two parses in a row, the
 * first argv freed in between, must each see only their own. */
static void test_parse_twice(void **state)
{
    (void) state;
    char *a1[] = { strdup("exrfog"), strdup("-vZq"), strdup("in.exr"), NULL };
    ef_options o;
    ef_err err = { 0 };
    ef_colour colour;
    memset(&colour, 0, sizeof colour);
    assert_int_equal(ef_options_parse(3, a1, &o, &colour, stdout, &err), EF_PARSE_USAGE);
    ef_options_free(&o);
    for (int i = 0; a1[i]; ++i)
        free(a1[i]);
    char *a2[] = { strdup("exrfog"), strdup("in.exr"), strdup("-o"), strdup("out.exr"),
                   strdup("--fog"), strdup("exp:density=0.1"), NULL };
    assert_int_equal(ef_options_parse(6, a2, &o, &colour, stdout, &err), EF_PARSE_RUN);
    assert_string_equal(o.output, "out.exr");
    assert_int_equal(o.scene.ncomp, 1);
    assert_int_equal(o.verbose, 0);
    ef_options_free(&o);
    ef_colour_close(&colour);
    for (int i = 0; a2[i]; ++i)
        free(a2[i]);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_zip_levels),
        cmocka_unit_test(test_zip_level_errors),
        cmocka_unit_test(test_parse_twice),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
