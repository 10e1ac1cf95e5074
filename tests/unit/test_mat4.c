/* ef_mat4: inverses checked against matrices inverted by hand. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "mat4.h"

static ef_mat4 mk(const double v[16])
{
    ef_mat4 m;
    for (int i = 0; i < 16; ++i)
        m.m[i] = v[i];
    return m;
}

/* Every entry within tol * (1 + |expected|). */
static void assert_mat(const ef_mat4 *got, const double want[16], double tol)
{
    for (int i = 0; i < 16; ++i)
        if (!(fabs(got->m[i] - want[i]) <= tol * (1.0 + fabs(want[i])))) {
            print_error("entry %d: got %.17g, expected %.17g\n", i, got->m[i], want[i]);
            fail();
        }
}

static void test_invert_rigid(void **state)
{
    (void)state;
    /* 90 degrees about Z, then translate (3,4,5): inverse is [R^T; -t R^T]. */
    const double a[16] = {0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 3, 4, 5, 1};
    const double inv[16] = {0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1, 0, -4, 3, -5, 1};
    ef_mat4 m = mk(a), out;
    assert_int_equal(ef_mat4_invert(&m, &out), 0);
    assert_mat(&out, inv, 0.0);
}

static void test_invert_scale(void **state)
{
    (void)state;
    const double a[16] = {2, 0, 0, 0, 0, 4, 0, 0, 0, 0, 0.5, 0, 6, -8, 1, 1};
    const double inv[16] = {0.5, 0, 0, 0, 0, 0.25, 0, 0, 0, 0, 2, 0, -3, 2, -2, 1};
    ef_mat4 m = mk(a), out;
    assert_int_equal(ef_mat4_invert(&m, &out), 0);
    assert_mat(&out, inv, 1e-15);
}

static void test_invert_triangular(void **state)
{
    (void)state;
    /* I + N with N nilpotent: inverse I - N + N^2 - N^3. */
    const double a[16] = {1, 2, 0, 0, 0, 1, 3, 0, 0, 0, 1, 4, 0, 0, 0, 1};
    const double inv[16] = {1, -2, 6, -24, 0, 1, -3, 12, 0, 0, 1, -4, 0, 0, 0, 1};
    ef_mat4 m = mk(a), out;
    assert_int_equal(ef_mat4_invert(&m, &out), 0);
    assert_mat(&out, inv, 1e-15);
}

static void test_invert_needs_pivoting(void **state)
{
    (void)state;
    /* D3D-style perspective: a zero on the diagonal at [3][3]. */
    const double sx = 2.0, sy = 3.0, A = 1.25, B = -0.5;
    const double a[16] = {sx, 0, 0, 0, 0, sy, 0, 0, 0, 0, A, 1, 0, 0, B, 0};
    const double inv[16] = {1 / sx, 0, 0, 0, 0, 1 / sy, 0, 0,
                            0, 0, 0, 1 / B, 0, 0, 1, -A / B};
    ef_mat4 m = mk(a), out;
    assert_int_equal(ef_mat4_invert(&m, &out), 0);
    assert_mat(&out, inv, 1e-15);
}

static void test_invert_far_translation(void **state)
{
    (void)state;
    /* Camera 1e7+ units away: unit rotation next to a huge translation. */
    const double a[16] = {0, 0, 1, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1e7, -3e7, 2.5e7, 1};
    /* R^T = R^-1; -t R^T with R^T rows (0,0,-1), (0,1,0), (1,0,0). */
    const double inv[16] = {0, 0, -1, 0, 0, 1, 0, 0, 1, 0, 0, 0, -2.5e7, 3e7, 1e7, 1};
    ef_mat4 m = mk(a), out;
    assert_int_equal(ef_mat4_invert(&m, &out), 0);
    assert_mat(&out, inv, 1e-16);
    /* Far translation and tiny scale together must not look singular. */
    const double b[16] = {1e-3, 0, 0, 0, 0, 1e-3, 0, 0, 0, 0, 1e-3, 0, 1e9, 1e9, 1e9, 1};
    const double binv[16] = {1e3, 0, 0, 0, 0, 1e3, 0, 0, 0, 0, 1e3, 0, -1e12, -1e12, -1e12, 1};
    m = mk(b);
    assert_int_equal(ef_mat4_invert(&m, &out), 0);
    assert_mat(&out, binv, 1e-15);
}

static void test_invert_alias(void **state)
{
    (void)state;
    const double a[16] = {2, 0, 0, 0, 0, 4, 0, 0, 0, 0, 0.5, 0, 6, -8, 1, 1};
    const double inv[16] = {0.5, 0, 0, 0, 0, 0.25, 0, 0, 0, 0, 2, 0, -3, 2, -2, 1};
    ef_mat4 m = mk(a);
    assert_int_equal(ef_mat4_invert(&m, &m), 0);
    assert_mat(&m, inv, 1e-15);
}

static void test_singular(void **state)
{
    (void)state;
    ef_mat4 out;
    const double zero[16] = {0};
    ef_mat4 m = mk(zero);
    assert_int_equal(ef_mat4_invert(&m, &out), -1);
    /* A zero row. */
    const double zr[16] = {1, 2, 3, 0, 0, 0, 0, 0, 4, 5, 6, 0, 1, 1, 1, 1};
    m = mk(zr);
    assert_int_equal(ef_mat4_invert(&m, &out), -1);
    /* Row 2 = row 0 + row 1, with decimals that do not round exactly. */
    const double dep[16] = {0.1, 0.2, 0.3, 0, 0.7, 0.11, 0.13, 0,
                            0.1 + 0.7, 0.2 + 0.11, 0.3 + 0.13, 0, 1, 2, 3, 1};
    m = mk(dep);
    assert_int_equal(ef_mat4_invert(&m, &out), -1);
    /* Orthographic projection with a zero depth scale. */
    const double flat[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
    m = mk(flat);
    assert_int_equal(ef_mat4_invert(&m, &out), -1);
}

static void test_nonfinite(void **state)
{
    (void)state;
    ef_mat4 out;
    const double id[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    ef_mat4 m = mk(id);
    assert_int_equal(ef_mat4_finite(&m), 1);
    m.m[13] = NAN;
    assert_int_equal(ef_mat4_finite(&m), 0);
    assert_int_equal(ef_mat4_invert(&m, &out), -1);
    m.m[13] = INFINITY;
    assert_int_equal(ef_mat4_finite(&m), 0);
    assert_int_equal(ef_mat4_invert(&m, &out), -1);
    m.m[13] = -INFINITY;
    assert_int_equal(ef_mat4_invert(&m, &out), -1);
}

static void test_mul_apply(void **state)
{
    (void)state;
    /* a: scale x by 2 then translate (1,0,0); b: rotate 90 about Z (x -> y). */
    const double a[16] = {2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1};
    const double b[16] = {0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    /* Row-vector a.b: rows of a times b. */
    const double ab[16] = {0, 2, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 0, 1, 0, 1};
    ef_mat4 A = mk(a), B = mk(b), out;
    ef_mat4_mul(&A, &B, &out);
    assert_mat(&out, ab, 0.0);
    /* Aliasing the output with an input. */
    ef_mat4_mul(&A, &B, &A);
    assert_mat(&A, ab, 0.0);
    /* p = (3,4,5): a gives (7,4,5), then b gives (-4,7,5). */
    const double p[3] = {3, 4, 5};
    double q[4];
    ef_mat4_apply(&out, p, 1.0, q);
    assert_true(q[0] == -4 && q[1] == 7 && q[2] == 5 && q[3] == 1);
    /* w = 0: a direction ignores the translation. */
    ef_mat4_apply(&out, p, 0.0, q);
    assert_true(q[0] == -4 && q[1] == 6 && q[2] == 5 && q[3] == 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_invert_rigid),
        cmocka_unit_test(test_invert_scale),
        cmocka_unit_test(test_invert_triangular),
        cmocka_unit_test(test_invert_needs_pivoting),
        cmocka_unit_test(test_invert_far_translation),
        cmocka_unit_test(test_invert_alias),
        cmocka_unit_test(test_singular),
        cmocka_unit_test(test_nonfinite),
        cmocka_unit_test(test_mul_apply),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
