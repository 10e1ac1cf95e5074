/* The SPEC grammar under hostile input: seeded mutations of valid SPECs for
 * every model (bytes flipped, dropped, duplicated, numbers replaced by
 * extremes) must each parse or fail with a message, never crash, leak or
 * produce a component whose tau is NaN. Runs under ASan/UBSan with the suite. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "fog.h"

static const char *const seeds[] = {
    "exp:density=0.02,0.03,0.04:distance=planar",
    "exp2:density=0.03,0.02,0.01",
    "linear:start=1:end=50",
    "halfspace:plane=0,1,0,-1:density=0.15:color=1,0.5,0",
    "halfspace-linear:plane=0.3,1,0.2,-4:slope=0.01,0.02,0.03",
    "halfspace-smooth:plane=0,2,0,-3:density=0.2:sharpness=0.5",
    "height:density=0.08:falloff=0.3:base=2:up=z",
    "layered:heights=0,2,6:densities=0.2,0.05/0.06/0.07,0:up=0,0,1",
    "box:min=-3,0,-12:max=3,2.5,-4:visibility=20",
    "convex:planes=1,1,1,14,-1,1,1,24,1,-1,1,20,-1,-1,1,30:density=0.1",
};

static const char *const tokens[] = {
    "nan", "inf", "-inf", "1e308", "-1e308", "4.9e-324", "0", "-0", ",", ":", "=", "::", "/",
    "1e-320", "99999999999999999999999", "", "density=", "up=", "color=", "plane=0,0,0,0",
};

static uint64_t next(uint64_t *s)
{
    uint64_t z = (*s += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static void mutate(uint64_t *g, const char *in, char *out, size_t cap)
{
    snprintf(out, cap, "%s", in);
    const int edits = 1 + (int) (next(g) % 2);
    for (int e = 0; e < edits; ++e) {
        const size_t n = strlen(out);
        const size_t at = n ? next(g) % n : 0;
        char tmp[1024];
        switch (next(g) % 4) {
        case 0:  /* flip a byte (printable or not) */
            if (n)
                out[at] = (char) (1 + next(g) % 255);
            break;
        case 1: { /* drop a run of up to 3 bytes */
            const size_t k = n - at > 3 ? 3 : n - at;
            memmove(out + at, out + at + k, strlen(out + at) + 1 - k);
            break;
        }
        case 2:  /* insert a token */
            snprintf(tmp, sizeof tmp, "%.*s%s%s", (int) at, out,
                     tokens[next(g) % (sizeof tokens / sizeof tokens[0])], out + at);
            snprintf(out, cap, "%s", tmp);
            break;
        default: /* duplicate the tail */
            snprintf(tmp, sizeof tmp, "%s%s", out, out + at);
            snprintf(out, cap, "%s", tmp);
            break;
        }
    }
}

static void test_mutated_specs(void **state)
{
    (void) state;
    uint64_t g = 7;
    long ok = 0, refused = 0;
    for (int i = 0; i < 100000; ++i) {
        char spec[1024];
        mutate(&g, seeds[i % (sizeof seeds / sizeof seeds[0])], spec, sizeof spec);
        ef_fog_component c;
        ef_err err;
        err.msg[0] = '\0';
        if (ef_fog_parse(spec, NULL, &c, &err)) {
            refused++;
            if (!err.msg[0])
                fail_msg("'%s' refused without a message", spec);
            continue;
        }
        ok++;
        /* Whatever parsed must evaluate without NaN, sky included. */
        const double dirs[3][3] = { { 0, -1, 0 }, { 0.6, 0.8, 0 }, { 0, 0, 1 } };
        const double lens[3] = { 0, 7.5, INFINITY };
        for (int d = 0; d < 3; ++d)
            for (int l = 0; l < 3; ++l) {
                ef_ray r = { { dirs[d][0], dirs[d][1], dirs[d][2] }, lens[l], lens[l],
                             { 0.5, 1.5, -2 } };
                double t[3];
                c.model->tau(&c, &r, t);
                for (int k = 0; k < 3; ++k)
                    if (isnan(t[k]) || t[k] < 0)
                        fail_msg("'%s' gives tau %g", spec, t[k]);
            }
        ef_fog_free(&c);
    }
    printf("  %ld mutated specs parsed, %ld refused with a message\n", ok, refused);
    assert_true(ok > 100 && refused > 100);
}

/* The models mutated elsewhere, with where: the noise models' evaluation
 * is bounded per ray but far dearer than a closed form, so their hostile
 * values and scales are test_fog_noise's (test_bad_values,
 * test_hostile_scales) and the fuzzer's (fuzz/fuzz_cli.c). */
static const char *const elsewhere[] = { "noise", "noise-separable" };

/* Every registered model has a seed here or is named above: a new model
 * cannot be left out of the hostile SPECs unnoticed (issue 43). */
static void test_every_model_seeded(void **state)
{
    (void) state;
    for (int m = 0; m < ef_fog_model_count(); ++m) {
        const char *name = ef_fog_model_at(m)->name;
        const size_t n = strlen(name);
        int found = 0;
        for (size_t i = 0; i < sizeof seeds / sizeof seeds[0]; ++i)
            found |= !strncmp(seeds[i], name, n) && seeds[i][n] == ':';
        for (size_t i = 0; i < sizeof elsewhere / sizeof elsewhere[0]; ++i)
            found |= !strcmp(elsewhere[i], name);
        if (!found)
            fail_msg("model %s has no seed in test_spec_mutate (add one, or say where it is "
                     "mutated)", name);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_every_model_seeded),
        cmocka_unit_test(test_mutated_specs),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
