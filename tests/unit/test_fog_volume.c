/* Box and convex fog volumes (seed 002, done analytically): tau = rho times
 * the length of the segment inside the volume. Every expected length below
 * is worked out by hand from where the ray crosses each face, in the ray's
 * own parameter t (org + t dir), so decimal directions such as (0.6, 0.8, 0)
 * are divided by exactly as the inputs are rounded. */
#include <float.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "tassert.h"

#include "fog.h"

static const double REL = 1e-14;

static void parse_ctx(const char *spec, const ef_fog_context *ctx, ef_fog_component *c)
{
    ef_err err = { .file = NULL };
    if (ef_fog_parse(spec, ctx, c, &err))
        fail_msg("'%s' failed: %s", spec, err.msg);
}

static void parse(const char *spec, ef_fog_component *c)
{
    parse_ctx(spec, NULL, c);
}

/* tau of one ray, twice: as given, and from a copy bound to the ray's
 * origin (a frame's camera: the box's slab clipper and the cached plane
 * values), which must agree to the bit. */
static void tau_of(const ef_fog_component *c, double ox, double oy, double oz, double dx,
                   double dy, double dz, double len, double tau[3])
{
    const ef_ray r = { { dx, dy, dz }, len, len, { ox, oy, oz } };
    c->model->tau(c, &r, tau);
    ef_fog_component b;
    assert_int_equal(ef_fog_copy(&b, c), 0);
    ef_fog_bind(&b, r.org);
    double tb[3];
    b.model->tau(&b, &r, tb);
    ef_fog_free(&b);
    for (int k = 0; k < 3; ++k)
        if (memcmp(&tau[k], &tb[k], sizeof tb[k]))
            fail_msg("tau from (%.17g,%.17g,%.17g) along (%g,%g,%g) over %g: %.17g unbound, "
                     "%.17g from the bound camera", ox, oy, oz, dx, dy, dz, len, tau[k], tb[k]);
}

/* Channel 0 of tau equals want: exactly for 0 and INFINITY, else to rel. */
static void expect_rel(const ef_fog_component *c, double ox, double oy, double oz, double dx,
                       double dy, double dz, double len, double want, double rel)
{
    double t[3];
    tau_of(c, ox, oy, oz, dx, dy, dz, len, t);
    if (want == 0.0 || isinf(want)) {
        if (!(t[0] == want))
            fail_msg("tau from (%g,%g,%g) along (%g,%g,%g) over %g = %.17g, expected %.17g", ox,
                     oy, oz, dx, dy, dz, len, t[0], want);
        return;
    }
    if (!(fabs(t[0] - want) <= rel * fabs(want)))
        fail_msg("tau from (%.17g,%.17g,%.17g) along (%g,%g,%g) over %g = %.17g, expected %.17g "
                 "(rel %g)", ox, oy, oz, dx, dy, dz, len, t[0], want, rel);
}

static void expect(const ef_fog_component *c, double ox, double oy, double oz, double dx,
                   double dy, double dz, double len, double want)
{
    expect_rel(c, ox, oy, oz, dx, dy, dz, len, want, REL);
}

/* Unit box, camera outside on the x axis through the middle: enters x = 0
 * at t = 1, leaves x = 1 at t = 2. Pixel before, inside, on either face. */
static void test_box_through_middle(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=1", &c);
    double t[3];
    tau_of(&c, -1, 0.5, 0.5, 1, 0, 0, INFINITY, t);
    assert_true(t[0] == 1.0 && t[1] == 1.0 && t[2] == 1.0);
    expect(&c, -1, 0.5, 0.5, 1, 0, 0, 10, 1.0);
    expect(&c, -1, 0.5, 0.5, 1, 0, 0, 2, 1.0);     /* pixel on the exit face */
    expect(&c, -1, 0.5, 0.5, 1, 0, 0, 1.5, 0.5);   /* pixel inside */
    expect(&c, -1, 0.5, 0.5, 1, 0, 0, 1, 0.0);     /* pixel on the entry face */
    expect(&c, -1, 0.5, 0.5, 1, 0, 0, 0.5, 0.0);   /* pixel before the box */
    expect(&c, -1, 0.5, 0.5, -1, 0, 0, INFINITY, 0.0);  /* looking away */
    /* The same segment from the other side: symmetric. */
    expect(&c, 2, 0.5, 0.5, -1, 0, 0, 3, 1.0);
    ef_fog_free(&c);
}

/* Oblique rays with hand lengths. */
static void test_box_diagonals(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=2", &c);
    /* In the plane z = 0.5, dir (0.6, 0.8): enters x = 0 at t = 0.3/0.6 = 0.5
     * (y = 0.4), leaves y = 1 at t = 1/0.8 = 1.25 (x = 0.45): 0.75. The camera
     * lies on the plane y = 0 (outside in x). */
    expect(&c, -0.3, 0, 0.5, 0.6, 0.8, 0, INFINITY, 2 * 0.75);
    expect(&c, -0.3, 0, 0.5, 0.6, 0.8, 0, 1.25, 2 * 0.75);      /* pixel on the exit face */
    expect(&c, -0.3, 0, 0.5, 0.6, 0.8, 0, 1.0, 2 * 0.5);        /* pixel inside */
    expect(&c, -0.3, 0, 0.5, 0.6, 0.8, 0, 0.5, 0.0);            /* pixel on the entry face */
    /* dir (12, 15, 16)/25 from (-0.96, -0.5, -0.64): planes x=0,y=0,z=0 are
     * crossed at t = 2, 5/6, 1 (entry 2); x=1,y=1,z=1 at t = 49/12, 2.5, 2.5625
     * (exit 2.5): length 0.5. */
    expect(&c, -0.96, -0.5, -0.64, 0.48, 0.6, 0.64, INFINITY, 2 * 0.5);
    /* Missing: leaves y = 1 (t = 0.625) before entering x = 0 (t = 5/3). */
    expect(&c, -1, 0.5, 0.5, 0.6, 0.8, 0, INFINITY, 0.0);
    ef_fog_free(&c);
}

static void test_box_camera_inside(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=1", &c);
    expect(&c, 0.5, 0.5, 0.5, 0, 0, 1, INFINITY, 0.5);
    expect(&c, 0.5, 0.5, 0.5, 0, 0, -1, INFINITY, 0.5);
    expect(&c, 0.5, 0.5, 0.5, 1, 0, 0, 0.25, 0.25);
    /* Leaves z = 1 at t = 0.5/0.8 = 0.625 before x = 0 at t = 0.5/0.6. */
    expect(&c, 0.5, 0.5, 0.5, -0.6, 0, 0.8, INFINITY, 0.625);
    expect(&c, 0.5, 0.5, 0.5, -0.6, 0, 0.8, 0.625, 0.625);      /* pixel on that face */
    expect(&c, 0.5, 0.5, 0.5, -0.6, 0, 0.8, 0.5, 0.5);
    ef_fog_free(&c);
}

/* Camera exactly on a face: looking in, out and along it. The density is 0
 * on the faces (fog is strictly inside), so a ray in a face sees none. */
static void test_box_camera_on_face(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=1", &c);
    expect(&c, 0, 0.5, 0.5, 1, 0, 0, INFINITY, 1.0);
    expect(&c, 0, 0.5, 0.5, 1, 0, 0, 0.75, 0.75);
    expect(&c, 0, 0.5, 0.5, -1, 0, 0, INFINITY, 0.0);
    expect(&c, 0, 0.5, 0.5, 0, 1, 0, INFINITY, 0.0);           /* in the face */
    expect(&c, 0, 0.5, 0.5, 0.6, 0.8, 0, INFINITY, 0.625);     /* y = 1 at t = 0.5/0.8 */
    expect(&c, 1, 0.5, 0.5, -1, 0, 0, INFINITY, 1.0);          /* on the max face */
    ef_fog_free(&c);
}

/* Edges and corners: rays that only touch the box, and a sliver near an
 * edge whose length is e / d. */
static void test_box_grazing(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=1", &c);
    const double d = sqrt(0.5), d3 = 1 / sqrt(3.0), e = ldexp(1, -30);
    expect(&c, -1, 0, 0, 1, 0, 0, INFINITY, 0.0);               /* along an edge */
    expect(&c, -1, 0, 0.5, 1, 0, 0, INFINITY, 0.0);             /* along a face */
    expect(&c, -1, 1, 0.5, d, -d, 0, INFINITY, 0.0);            /* touches the edge x=y=0 */
    expect(&c, -1, 1, 1, d3, -d3, -d3, INFINITY, 0.0);          /* touches the corner 0 */
    /* x = 0 at t = 1/d, y = 0 at t = (1 + e)/d: inside for e/d. */
    expect(&c, -1, 1 + e, 0.5, d, -d, 0, INFINITY, e / d);
    expect(&c, -1, 1 + e, 0.5, d, -d, 0, 10, e / d);
    /* Pixel exactly on the corner edge the sliver leaves through. */
    expect(&c, -1, 1 + e, 0.5, d, -d, 0, (1 + e) / d, e / d);
    ef_fog_free(&c);
}

/* Rays parallel to faces, inside and outside their slabs. */
static void test_box_parallel(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=1", &c);
    expect(&c, -1, 2, 0.5, 1, 0, 0, INFINITY, 0.0);             /* above y = 1 */
    expect(&c, -1, -1e-300, 0.5, 1, 0, 0, INFINITY, 0.0);       /* just below y = 0 */
    expect(&c, -1, 1e-300, 0.5, 1, 0, 0, INFINITY, 1.0);        /* just above y = 0 */
    expect(&c, 0.5, 0.5, 0.5, 1, 0, 0, INFINITY, 0.5);          /* sky, inside the slab */
    expect(&c, 0.25, 0.5, 0.5, 0, 0, 1, 1e300, 0.5);
    ef_fog_free(&c);
}

/* A box and a camera 1e7 from the origin: lengths stay exact. */
static void test_box_far(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=1", &c);
    expect(&c, -1e7, 0.5, 0.5, 1, 0, 0, INFINITY, 1.0);
    expect(&c, 0.5, 0.5, 1e7, 0, 0, -1, INFINITY, 1.0);
    expect(&c, 0.5, 0.5, 1e7, 0, 0, -1, 1e7 - 0.25, 0.75);
    ef_fog_free(&c);

    /* A slab 2^-20 thick at x = 1e7, crossed obliquely by a camera 2e7 away:
     * the crossings are at t ~ 3.3e7 yet differ by 2^-20/0.6. */
    parse("box:min=1e7,-1,-1e8:max=10000000.00000095367431640625,1,1e8:density=1e6", &c);
    const double w = ldexp(1, -20);
    expect_rel(&c, -1e7, 0, 0, 0.6, 0, 0.8, INFINITY, 1e6 * w / 0.6, 1e-13);
    expect_rel(&c, 1e7 - 3, 0, 0, 0.6, 0, 0.8, INFINITY, 1e6 * w / 0.6, 1e-13);
    /* Pixel inside the slab, about half way: it is 0.6 L - 3 past the face
     * (one rounding with fma), at rate 0.6. */
    const double L = (3 + w / 2) / 0.6;
    expect_rel(&c, 1e7 - 3, 0, 0, 0.6, 0, 0.8, L, 1e6 * (fma(L, 0.6, -3) / 0.6), 1e-13);
    ef_fog_free(&c);

    /* A sliver at a corner 1e7 away, entered and left through two different
     * faces: x = 1e7 at t = (1+K)/d, y = 1e7 at t = (1+K+e)/d, length e/d
     * while t ~ 1.5e6 (a double quotient alone would be off by ~1e-10). */
    parse("box:min=1e7,1e7,0:max=10000001,10000001,1:density=1", &c);
    const double d = sqrt(0.5), K = ldexp(1, 20), e = ldexp(1, -20);
    expect_rel(&c, 1e7 - 1 - K, 1e7 + 1 + e + K, 0.5, d, -d, 0, INFINITY, e / d, 1e-12);
    ef_fog_free(&c);
}

/* Two faces crossed within a rounding of each other, 1.2e7-1.5e7 away: a
 * double quotient cannot tell which binds (here both round to the same t,
 * and the binding one comes second), and picking the wrong one is off by
 * e / d, e = 2^-29. Entries alone: x = 0 at t = H/d, y = 0 at (H + e)/d
 * (binding); x = 1 left at (H + 1)/d (binding), y = 1.5 at (H + 1.5 + e)/d.
 * Then exits alone: y = 0 entered at (G - 0.5)/d, x = 0 at G/d (binding),
 * x = 1 + e left at (G + 1 + e)/d, y = 1.5 at (G + 1)/d (binding). */
static void test_box_near_ties(void **state)
{
    (void) state;
    ef_fog_component c;
    const double d = sqrt(0.5), e = ldexp(1, -29), H = 1.5e7, G = 1.2e7;
    /* dz = 0 and a z crossing far beyond (the bound camera's slab clipper
     * hands a zero rate to the general one). */
    for (int k = 0; k < 2; ++k) {
        const double dz = k ? 1e-9 : 0.0;
        parse("box:min=0,0,0:max=1,1.5,1:density=1", &c);
        expect(&c, -H, -(H + e), 0.5, d, d, dz, INFINITY, (1 - e) / d);
        expect(&c, -H, -(H + e), 0.5, d, d, dz, 1e8, (1 - e) / d);
        /* A pixel one ulp before x = 0 (t = H/d = 21213203.435596424...,
         * between the doubles 0x1.43b0136f833f4p+24 and ...f5p+24): no fog,
         * though the rounded crossing is that pixel's distance. */
        expect(&c, -H, 0.5, 0.5, d, dz, dz, 0x1.43b0136f833f4p+24, 0.0);
        expect(&c, H + 1, H + 1.5 + e, 0.5, -d, -d, dz, INFINITY, (1 - e) / d);
        ef_fog_free(&c);
        parse("box:min=0,0,0:max=1.0000000018626451,1.5,1:density=1", &c);
        expect(&c, -G, -G + 0.5, 0.5, d, d, dz, INFINITY, 1 / d);
        expect(&c, -G, -G + 0.5, 0.5, d, d, dz, 1e8, 1 / d);
        ef_fog_free(&c);
    }
}

/* One plane: a half-space. y < 2 (normal (0,2,0) not unit). */
static void test_convex_halfspace(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("convex:planes=0,2,0,-4:density=0.5", &c);
    /* From y = 5 along (0,-0.6,0.8): enters y = 2 at t = 3/0.6 = 5. */
    expect(&c, 0, 5, 0, 0, -0.6, 0.8, 10, 0.5 * 5);
    expect(&c, 0, 5, 0, 0, -0.6, 0.8, INFINITY, INFINITY);
    expect(&c, 0, 5, 0, 0, -0.6, 0.8, 5, 0.0);                   /* pixel on the plane */
    /* From y = 0 up along (0,0.6,0.8): leaves at t = 2/0.6. */
    expect(&c, 0, 0, 0, 0, 0.6, 0.8, INFINITY, 0.5 * (2 / 0.6));
    expect(&c, 0, 0, 0, 1, 0, 0, INFINITY, INFINITY);            /* horizontal, inside */
    expect(&c, 0, 2, 0, 1, 0, 0, INFINITY, 0.0);                 /* horizontal, in the plane */
    expect(&c, 1e7, 1, -1e7, 0, 1, 0, INFINITY, 0.5);
    /* The longest finite segment: DBL_MAX - 3 inside, rounded, no overflow. */
    expect(&c, 0, 5, 0, 0, -1, 0, DBL_MAX, 0.5 * DBL_MAX);
    ef_fog_free(&c);
}

/* Tetrahedron x, y, z > 0, x + y + z < 1. */
static void test_convex_tetrahedron(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("convex:planes=-1,0,0,0,0,-1,0,0,0,0,-1,0,1,1,1,-1:density=1", &c);
    /* y = z = 0.25: inside for 0 < x < 0.5. */
    expect(&c, -1, 0.25, 0.25, 1, 0, 0, INFINITY, 0.5);
    /* x = 0.1, y = 0.2, down z: inside for 0 < z < 0.7. */
    expect(&c, 0.1, 0.2, 2, 0, 0, -1, 10, 0.7);
    expect(&c, 0.1, 0.1, 0.1, 0, 0, 1, INFINITY, 0.7);           /* camera inside */
    expect(&c, 0.1, 0.1, 0.1, 0, 0, 1, 0.3, 0.3);
    /* Along the slanted face's normal through (0.25,0.25,0.25) from
     * (0,0,0) (a vertex): leaves at t = sqrt(3)/3 where x+y+z = 1. */
    const double d3 = 1 / sqrt(3.0);
    expect(&c, 0, 0, 0, d3, d3, d3, INFINITY, 1 / (3 * d3));
    /* Parallel to the slanted face (x+y+z stays 0.95): leaves z = 0 at
     * t = 0.2/d. Outside it (1.05) and exactly on it (1): nothing. */
    const double d = sqrt(0.5);
    expect(&c, 0.5, 0.25, 0.2, 0, d, -d, INFINITY, 0.2 / d);
    expect(&c, 0.5, 0.25, 0.3, 0, d, -d, INFINITY, 0.0);
    expect(&c, 0.5, 0.25, 0.25, 0, d, -d, INFINITY, 0.0);
    ef_fog_free(&c);
}

/* Octahedron |x| + |y| + |z| < 1: eight planes. */
static void test_convex_octahedron(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("convex:planes=1,1,1,-1,1,1,-1,-1,1,-1,1,-1,1,-1,-1,-1,-1,1,1,-1,-1,1,-1,-1,"
          "-1,-1,1,-1,-1,-1,-1,-1:density=1", &c);
    expect(&c, -2, 0, 0, 1, 0, 0, INFINITY, 2.0);
    expect(&c, -2, 0.25, 0.25, 1, 0, 0, INFINITY, 1.0);
    /* Along (d, d, 0) from (-1,-1,0): inside for |x| < 0.5, t in (0.5/d, 1.5/d). */
    const double d = sqrt(0.5);
    expect(&c, -1, -1, 0, d, d, 0, INFINITY, 1 / d);
    expect(&c, 0, 0, 0, 0, 0, 1, INFINITY, 1.0);
    expect(&c, 0, 0, 0, 0, 0, 1, 0.3, 0.3);
    expect(&c, -2, 1, 0, 1, 0, 0, INFINITY, 0.0);                /* touches the vertex (0,1,0) */
    ef_fog_free(&c);
}

/* Unbounded: the quarter-space x < 0, y < 0, and the slab |y| < 1. */
static void test_convex_unbounded(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("convex:planes=1,0,0,0,0,1,0,0:density=1,0,2", &c);
    double t[3];
    tau_of(&c, -1, -1, 0, 0, 0, 1, INFINITY, t);
    assert_true(isinf(t[0]) && t[1] == 0.0 && isinf(t[2]));       /* no 0 * inf */
    tau_of(&c, 1, -1, 0, -1, 0, 0, INFINITY, t);                  /* enters and stays */
    assert_true(isinf(t[0]) && t[1] == 0.0 && isinf(t[2]));
    /* Leaves y = 0 at t = 1.25 (before x = 0 at t = 1/0.6). */
    tau_of(&c, -1, -1, 0, 0.6, 0.8, 0, INFINITY, t);
    assert_close(t[0], 1.25, 1e-15);
    assert_true(t[1] == 0.0);
    assert_close(t[2], 2.5, 1e-15);
    ef_fog_free(&c);

    parse("convex:planes=0,1,0,-1,0,-1,0,-1:density=0.25", &c);
    expect(&c, 0, 0, 0, 1, 0, 0, INFINITY, INFINITY);
    expect(&c, 0, 0, 0, 0, 0.6, 0.8, INFINITY, 0.25 / 0.6);
    expect(&c, 0, 5, 0, 0, -0.6, 0.8, INFINITY, 0.25 * 2 / 0.6);
    expect(&c, 0, 5, 0, 0, -0.6, 0.8, 5 / 0.6, 0.25 * 1 / 0.6);  /* pixel at y = 0 */
    ef_fog_free(&c);

    parse("convex:planes=0,1,0,-1:density=0", &c);               /* zero density: no NaN */
    tau_of(&c, 0, 0, 0, 1, 0, 0, INFINITY, t);
    assert_true(t[0] == 0.0 && t[1] == 0.0 && t[2] == 0.0);
    ef_fog_free(&c);
}

/* Contradictory planes x < 0 and x > 1: empty, whatever the ray. */
static void test_convex_empty(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("convex:planes=1,0,0,0,-1,0,0,1:density=1", &c);
    expect(&c, -5, 0, 0, 1, 0, 0, INFINITY, 0.0);
    expect(&c, -5, 0, 0, 1, 0, 0, 10, 0.0);
    expect(&c, 5, 0, 0, -1, 0, 0, INFINITY, 0.0);
    expect(&c, 0.5, 0, 0, 0, 1, 0, INFINITY, 0.0);
    expect(&c, -1, 0, 0, 0, 1, 0, INFINITY, 0.0);
    expect(&c, -5, 0, 0, 0.6, 0.8, 0, INFINITY, 0.0);
    ef_fog_free(&c);
    /* Three planes with an empty intersection that no single pair rules out
     * along this ray: x < 0, y < 0, x + y > 1. */
    parse("convex:planes=1,0,0,0,0,1,0,0,-1,-1,0,1:density=1", &c);
    expect(&c, -5, -5, 0, 0.6, 0.8, 0, INFINITY, 0.0);
    expect(&c, -5, -5, 0, 0, 0, 1, INFINITY, 0.0);
    ef_fog_free(&c);
}

static void test_per_channel_units_visibility(void **state)
{
    (void) state;
    ef_fog_component c;
    double t[3];
    parse("box:min=0,0,0:max=1,1,1:density=1,2,3", &c);
    tau_of(&c, -1, 0.5, 0.5, 1, 0, 0, INFINITY, t);
    assert_true(t[0] == 1.0 && t[1] == 2.0 && t[2] == 3.0);
    ef_fog_free(&c);

    parse("box:min=0,0,0:max=1,1,1:visibility=3.912", &c);       /* 3.912/V = 1 */
    tau_of(&c, -1, 0.5, 0.5, 1, 0, 0, INFINITY, t);
    assert_close(t[0], 1.0, 1e-15);
    ef_fog_free(&c);
    parse("box:min=0,0,0:max=1,1,1:visibility=1,2,4", &c);
    tau_of(&c, -1, 0.5, 0.5, 1, 0, 0, 1.5, t);
    assert_close(t[0], 3.912 * 0.5, 1e-15);
    assert_close(t[1], 1.956 * 0.5, 1e-15);
    assert_close(t[2], 0.978 * 0.5, 1e-15);
    ef_fog_free(&c);

    /* A scene in centimetres: a 1 m box is 100 units across, density 1/m. */
    ef_fog_context ctx;
    ef_fog_context_init(&ctx);
    ctx.units_per_meter = 100;
    parse_ctx("box:min=0,0,0:max=100,100,100:density=1", &ctx, &c);
    tau_of(&c, -100, 50, 50, 1, 0, 0, INFINITY, t);
    assert_close(t[0], 1.0, 1e-15);
    ef_fog_free(&c);
    parse_ctx("convex:planes=0,1,0,-100:visibility=3.912", &ctx, &c);
    tau_of(&c, 0, 0, 0, 0, 1, 0, INFINITY, t);                    /* 100 units = 1 m */
    assert_close(t[0], 1.0, 1e-15);
    ef_fog_free(&c);
}

static void test_zero_length(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,1,1:density=1", &c);
    expect(&c, 0.5, 0.5, 0.5, 1, 0, 0, 0, 0.0);
    expect(&c, 0, 0.5, 0.5, 1, 0, 0, 0, 0.0);
    expect(&c, -1, 0.5, 0.5, 1, 0, 0, 0, 0.0);
    ef_fog_free(&c);
}

/* density() straight from the definition, at points whose functional
 * values are evaluated here from functionals(); features: each plane at 0. */
static void test_density_functionals_features(void **state)
{
    (void) state;
    ef_fog_component c;
    parse("box:min=0,0,0:max=1,2,3:density=1,2,3", &c);
    ef_fog_functional f[64];
    ef_fog_feature ft[64];
    assert_int_equal(c.model->functionals(&c, f, 64), 6);
    assert_int_equal(c.model->features(&c, ft, 64), 6);
    for (int i = 0; i < 6; ++i) {
        assert_int_equal(ft[i].f, i);
        assert_true(ft[i].value == 0.0 && ft[i].scale == 0.0);
        assert_close(f[i].n[0] * f[i].n[0] + f[i].n[1] * f[i].n[1] + f[i].n[2] * f[i].n[2],
                     1.0, 1e-15);
    }
    const double pts[][4] = {
        /* x, y, z, inside? */
        { 0.5, 1, 1.5, 1 }, { 0.999, 1.999, 2.999, 1 }, { 1.5, 1, 1, 0 }, { 0.5, -0.1, 1, 0 },
        { 0.5, 1, 3, 0 },   /* on the face z = 3 */
        { 0, 0, 0, 0 },     /* a corner */
    };
    for (size_t p = 0; p < sizeof pts / sizeof pts[0]; ++p) {
        long double v[6], out[3];
        for (int i = 0; i < 6; ++i)
            v[i] = (long double) f[i].n[0] * pts[p][0] + (long double) f[i].n[1] * pts[p][1] +
                   (long double) f[i].n[2] * pts[p][2] + f[i].d;
        c.model->density(&c, v, out);
        for (int k = 0; k < 3; ++k)
            assert_true(out[k] == (pts[p][3] != 0 ? k + 1.0L : 0.0L));
    }
    long double v[6], out[3];
    for (int i = 0; i < 6; ++i)
        v[i] = -INFINITY;
    c.model->density(&c, v, out);
    assert_true(out[0] == 1.0L && out[2] == 3.0L);
    v[3] = INFINITY;
    c.model->density(&c, v, out);
    assert_true(out[0] == 0.0L && out[1] == 0.0L);
    ef_fog_free(&c);

    /* Convex planes come back normalised: (0,2,0,-4) is y - 2. */
    parse("convex:planes=0,2,0,-4,3,0,4,5:density=1", &c);
    assert_int_equal(c.model->functionals(&c, f, 1), 2);          /* count beyond cap */
    assert_int_equal(c.model->functionals(&c, f, 64), 2);
    assert_true(f[0].n[0] == 0 && f[0].n[1] == 1 && f[0].n[2] == 0 && f[0].d == -2);
    assert_close(f[1].n[0], 0.6, 1e-16);
    assert_close(f[1].n[2], 0.8, 1e-16);
    assert_close(f[1].d, 1.0, 1e-16);
    ef_fog_free(&c);
}

static void expect_error(const char *spec, const char *quote)
{
    ef_fog_component c;
    ef_err err = { .file = NULL };
    if (ef_fog_parse(spec, NULL, &c, &err) == 0) {
        ef_fog_free(&c);
        fail_msg("'%s' was accepted", spec);
    }
    if (!strstr(err.msg, quote))
        fail_msg("error for '%s' does not quote '%s': %s", spec, quote, err.msg);
    if (!strstr(err.msg, spec))
        fail_msg("error for '%s' does not name the spec: %s", spec, err.msg);
}

static void test_spec_errors_box(void **state)
{
    (void) state;
    expect_error("box:min=0,1,0:max=1,1,1:density=1", "min y = 1 is not less than max y = 1");
    expect_error("box:min=0,0,2:max=1,1,1:density=1", "min z = 2 is not less than max z = 1");
    expect_error("box:min=0,0,1.0000000000000002:max=1,1,1:density=1",
                 "min z = 1.0000000000000002 is not less than max z = 1");
    expect_error("box:min=0,0:max=1,1,1:density=1", "min='0,0' is not X,Y,Z");
    expect_error("box:min=0,0,0:max=a,1,1:density=1", "max='a,1,1'");
    expect_error("box:max=1,1,1:density=1", "missing min");
    expect_error("box:min=0,0,0:density=1", "missing max");
    expect_error("box:min=0,0,0:max=1,1,1", "missing density");
    expect_error("box:min=0,0,0:max=1,1,1:density=1:visibility=2", "not both");
    expect_error("box:min=0,0,0:max=1,1,1:density=-1", "density='-1' is negative");
    expect_error("box:min=0,0,0:max=1,1,1:visibility=0", "visibility='0' must be > 0");
    expect_error("box:min=0,0,0:max=1,1,1:density=1:up=z", "unknown key 'up'");
}

static void test_spec_errors_convex(void **state)
{
    (void) state;
    expect_error("convex:planes=1,0,0,0,1:density=1", "has 5 numbers, not a multiple of 4");
    expect_error("convex:planes=1,0,0:density=1", "has 3 numbers");
    expect_error("convex:planes=1,0,0,0,0,0,0,1:density=1", "plane 2 (0,0,0,1) has a zero normal");
    expect_error("convex:planes=1,0,x,0:density=1", "number 3 ('x')");
    expect_error("convex:planes=1,0,0,0,:density=1", "number 5 ('')");
    expect_error("convex:planes=1,0,0,1e999:density=1", "number 4 ('1e999')");
    expect_error("convex:density=1", "missing planes");
    expect_error("convex:planes=1,0,0,0", "missing density");
}

/* 64 planes are accepted, 65 are not. Plane k: z < k + 1 (all but the
 * first redundant), the last one x < 0. */
static void test_plane_count_limit(void **state)
{
    (void) state;
    static char spec[2048];
    for (int n = 64; n <= 65; ++n) {
        snprintf(spec, sizeof spec, "convex:density=1:planes=");
        for (int k = 0; k < n - 1; ++k) {
            char one[32];
            snprintf(one, sizeof one, "0,0,1,%d,", -(k + 1));
            strcat(spec, one);
        }
        strcat(spec, "1,0,0,0");
        if (n == 65) {
            expect_error(spec, "has 260 numbers");
            expect_error(spec, "at most 64 planes");
            expect_error(spec, "planes='0,0,1,-1,0,0,1,-2");
        } else {
            ef_fog_component c;
            parse(spec, &c);
            assert_int_equal(c.narr, 256);
            /* z < 1 and x < 0: from (-1, 0, 0) up z leaves at t = 1. */
            expect(&c, -1, 0, 0, 0, 0, 1, INFINITY, 1.0);
            expect(&c, 1, 0, 0, 0, 0, 1, INFINITY, 0.0);
            ef_fog_component d;
            assert_int_equal(ef_fog_copy(&d, &c), 0);
            ef_fog_free(&c);
            expect(&d, -1, 0, 0, 0, 0, 1, 0.5, 0.5);               /* the copy owns its planes */
            ef_fog_free(&d);
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_box_through_middle),
        cmocka_unit_test(test_box_diagonals),
        cmocka_unit_test(test_box_near_ties),
        cmocka_unit_test(test_box_camera_inside),
        cmocka_unit_test(test_box_camera_on_face),
        cmocka_unit_test(test_box_grazing),
        cmocka_unit_test(test_box_parallel),
        cmocka_unit_test(test_box_far),
        cmocka_unit_test(test_convex_halfspace),
        cmocka_unit_test(test_convex_tetrahedron),
        cmocka_unit_test(test_convex_octahedron),
        cmocka_unit_test(test_convex_unbounded),
        cmocka_unit_test(test_convex_empty),
        cmocka_unit_test(test_per_channel_units_visibility),
        cmocka_unit_test(test_zero_length),
        cmocka_unit_test(test_density_functionals_features),
        cmocka_unit_test(test_spec_errors_box),
        cmocka_unit_test(test_spec_errors_convex),
        cmocka_unit_test(test_plane_count_limit),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
