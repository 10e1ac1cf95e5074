/* ocio_shim: exrfog's OCIO config and the C interface over OpenColorIO,
 * checked against published matrices and transfer functions worked out
 * here (never against the shim's or the config's own numbers).
 *
 * Published values used:
 *  - Rec.709 -> ACEScg and ACEScg -> Rec.709 with Bradford adaptation
 *    (colour-science 0.4 `RGB_to_RGB(..., chromatic_adaptation_transform=
 *    "Bradford")`; the same ACEScg -> Rec.709 matrix is OCIO's builtin
 *    "UTILITY - ACES-AP1_to_LINEAR-REC709_BFD"), 8 decimals.
 *  - AP0 -> AP1 from Academy S-2014-004 (ACEScg), section 4.3.
 *  - sRGB (IEC 61966-2-1) decoding/encoding, ACEScct (S-2016-001) encoding
 *    and the BT.1886 2.4 power: evaluated here with pow/log2. */
#include <math.h>
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>
#include <sys/stat.h>

#include "ocio_shim.h"
#include "tassert.h"

static const double REC709_TO_ACESCG[3][3] = {{0.61309740, 0.33952315, 0.04737945},
                                              {0.07019372, 0.91635388, 0.01345240},
                                              {0.02061559, 0.10956977, 0.86981463}};
static const double ACESCG_TO_REC709[3][3] = {{1.70505099, -0.62179212, -0.08325887},
                                              {-0.13025642, 1.14080474, -0.01054832},
                                              {-0.02400336, -0.12896898, 1.15297233}};
static const double AP0_TO_AP1[3][3] = {{1.4514393161, -0.2365107469, -0.2149285693},
                                        {-0.0765537734, 1.1762296998, -0.0996759264},
                                        {0.0083161484, -0.0060324498, 0.9977163014}};

#define LIN709 "Linear Rec.709 (sRGB)"

static char g_config[1024];   /* the shipped config in the source tree */
static char g_dir[64];        /* scratch directory */
static char g_odd[1100];      /* a config with ':' and ',' in its names */
static ef_ocio *g_ocio;       /* g_config, opened once */

static double srgb_decode(double v)
{
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

static double srgb_encode(double v)
{
    return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

static void write_file(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fputs(text, f);
    fclose(f);
}

static int setup(void **state)
{
    (void)state;
    const char *src = getenv("EXRFOG_SOURCE_DIR");
    if (!src) {
        fprintf(stderr, "EXRFOG_SOURCE_DIR is not set (run through ctest)\n");
        return -1;
    }
    snprintf(g_config, sizeof g_config, "%s/share/ocio/exrfog-config.ocio", src);
    strcpy(g_dir, "/tmp/ef_ocio_XXXXXX");
    if (!mkdtemp(g_dir))
        return -1;
    snprintf(g_odd, sizeof g_odd, "%s/odd.ocio", g_dir);
    FILE *f = fopen(g_odd, "w");
    if (!f)
        return -1;
    fputs("ocio_profile_version: 2.1\n"
          "search_path: \"\"\n"
          "roles:\n"
          "  default: \"Cam:Linear\"\n"
          "  scene_linear: \"Cam:Linear\"\n"
          "  data: Raw\n"
          "file_rules:\n"
          "  - !<Rule> {name: Default, colorspace: default}\n"
          "displays:\n"
          "  \"Monitor, left\":\n"
          "    - !<View> {name: \"Half, bright\", colorspace: Half}\n"
          "    - !<View> {name: Raw, colorspace: Raw}\n"
          "colorspaces:\n"
          "  - !<ColorSpace>\n"
          "    name: \"Cam:Linear\"\n"
          "    isdata: false\n"
          "  - !<ColorSpace>\n"
          "    name: Half\n"
          "    isdata: false\n"
          "    from_scene_reference: !<MatrixTransform> {matrix: [0.5, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 1]}\n"
          "  - !<ColorSpace>\n"
          "    name: Raw\n"
          "    isdata: true\n",
          f);
    fclose(f);
    char where[1200], msg[2048];
    g_ocio = ef_ocio_open(g_config, where, sizeof where, msg, sizeof msg);
    if (!g_ocio) {
        fprintf(stderr, "%s\n", msg);
        return -1;
    }
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    ef_ocio_close(g_ocio);
    char path[1200];
    snprintf(path, sizeof path, "%s/odd.ocio", g_dir);
    remove(path);
    snprintf(path, sizeof path, "%s/bad.ocio", g_dir);
    remove(path);
    rmdir(g_dir);
    return 0;
}

static void parse_ok(const char *text, const char *working, const double want[3], double tol)
{
    double rgb[3];
    char msg[1024] = "";
    if (ef_ocio_parse_color(g_ocio, text, working, rgb, msg, sizeof msg) != 0) {
        print_error("'%s' -> %s: %s\n", text, working ? working : "(scene_linear)", msg);
        fail();
    }
    for (int i = 0; i < 3; ++i)
        assert_close(rgb[i], want[i], tol);
}

static void parse_fails(const char *text, const char *working, const char *needle)
{
    double rgb[3];
    char msg[1024] = "";
    assert_int_equal(ef_ocio_parse_color(g_ocio, text, working, rgb, msg, sizeof msg), -1);
    assert_contains(msg, needle);
}

/* --- opening ----------------------------------------------------------- */

static void test_open_explicit_and_errors(void **state)
{
    (void)state;
    char where[1200], msg[2048], want[1200];
    ef_ocio *o = ef_ocio_open(g_config, where, sizeof where, msg, sizeof msg);
    assert_non_null(o);
    snprintf(want, sizeof want, "--colorconfig %s", g_config);
    assert_string_equal(where, want);
    ef_ocio_close(o);

    char missing[1200];
    snprintf(missing, sizeof missing, "%s/no-such.ocio", g_dir);
    assert_null(ef_ocio_open(missing, where, sizeof where, msg, sizeof msg));
    assert_contains(msg, missing);
    assert_contains(msg, "does not exist");
    assert_contains(msg, "--colorconfig");

    char bad[1200];
    snprintf(bad, sizeof bad, "%s/bad.ocio", g_dir);
    write_file(bad, "this is: [not an OCIO config\n");
    assert_null(ef_ocio_open(bad, where, sizeof where, msg, sizeof msg));
    assert_contains(msg, "not a usable OpenColorIO config");
    assert_contains(msg, bad);

    /* A directory is not a config either. */
    assert_null(ef_ocio_open(g_dir, where, sizeof where, msg, sizeof msg));
    assert_contains(msg, "not a file");
}

/* A config whose FileTransform names /dev/zero (OCIO would read it without
 * end), a FIFO (it would block for ever) or a directory is refused when
 * opened, naming the file; a real LUT file in a group is fine. (The
 * hostile campaign: 4 GB in 10 s, and a hang.) */
static void test_lut_files_checked(void **state)
{
    (void)state;
    char where[1200], msg[2048], cfg[1200], lut[1200], fifo[1200];
    snprintf(cfg, sizeof cfg, "%s/lut.ocio", g_dir);
    snprintf(lut, sizeof lut, "%s/gain.spi1d", g_dir);
    snprintf(fifo, sizeof fifo, "%s/pipe.spi1d", g_dir);
    write_file(lut, "Version 1\nFrom 0.0 1.0\nLength 2\nComponents 1\n{\n0.0\n2.0\n}\n");
    assert_int_equal(mkfifo(fifo, 0600), 0);
    static const char *const head =
        "ocio_profile_version: 2.1\n"
        "search_path: \".\"\n"
        "roles:\n  default: lin\n  scene_linear: lin\n  data: Raw\n"
        "file_rules:\n  - !<Rule> {name: Default, colorspace: default}\n"
        "displays:\n  sRGB:\n    - !<View> {name: Raw, colorspace: Raw}\n"
        "colorspaces:\n  - !<ColorSpace>\n    name: lin\n    isdata: false\n"
        "  - !<ColorSpace>\n    name: Raw\n    isdata: true\n"
        "  - !<ColorSpace>\n    name: lut\n    isdata: false\n"
        "    from_scene_reference: !<GroupTransform> {children: [!<FileTransform> {src: \"%s\"}]}\n";
    const char *const srcs[] = { lut, "/dev/zero", fifo, g_dir };
    const char *const says[] = { NULL, "a character device", "a FIFO", "a directory" };
    for (int k = 0; k < 4; ++k) {
        char text[4096];
        snprintf(text, sizeof text, head, srcs[k]);
        write_file(cfg, text);
        ef_ocio *o = ef_ocio_open(cfg, where, sizeof where, msg, sizeof msg);
        if (!says[k]) {
            if (!o)
                print_error("%s\n", msg);
            assert_non_null(o);
            ef_ocio_close(o);
            continue;
        }
        assert_null(o);
        assert_contains(msg, srcs[k]);
        assert_contains(msg, says[k]);
        assert_contains(msg, "a LUT must be a file");
    }
    remove(cfg);
    remove(lut);
    remove(fifo);
}

static void test_env_and_precedence(void **state)
{
    (void)state;
    char where[1200], msg[2048], want[1200], name[256];
    const char *old = getenv("OCIO");
    char *saved = old ? strdup(old) : NULL;

    /* $OCIO is used when --colorconfig is absent. */
    setenv("OCIO", g_odd, 1);
    ef_ocio *o = ef_ocio_open(NULL, where, sizeof where, msg, sizeof msg);
    assert_non_null(o);
    snprintf(want, sizeof want, "$OCIO=%s", g_odd);
    assert_string_equal(where, want);
    assert_true(ef_ocio_space_exists(o, "cam:linear", name, sizeof name));
    assert_string_equal(name, "Cam:Linear");
    assert_false(ef_ocio_space_exists(o, "ACEScg", NULL, 0));
    ef_ocio_close(o);

    /* --colorconfig wins over $OCIO. */
    o = ef_ocio_open(g_config, where, sizeof where, msg, sizeof msg);
    assert_non_null(o);
    assert_contains(where, "--colorconfig");
    assert_true(ef_ocio_space_exists(o, "ACEScg", NULL, 0));
    ef_ocio_close(o);

    /* A broken $OCIO is reported as such. */
    setenv("OCIO", "/nonexistent/config.ocio", 1);
    assert_null(ef_ocio_open(NULL, where, sizeof where, msg, sizeof msg));
    assert_contains(msg, "$OCIO=/nonexistent/config.ocio");
    assert_contains(msg, "does not exist");

    /* Empty or unset: exrfog's own config. */
    setenv("OCIO", "", 1);
    o = ef_ocio_open(NULL, where, sizeof where, msg, sizeof msg);
    assert_non_null(o);
    assert_contains(where, "exrfog's config ");
    assert_contains(where, "exrfog-config.ocio");
    assert_true(ef_ocio_space_exists(o, "ACEScg", NULL, 0));
    ef_ocio_close(o);
    unsetenv("OCIO");
    o = ef_ocio_open(NULL, where, sizeof where, msg, sizeof msg);
    assert_non_null(o);
    assert_contains(where, "exrfog's config ");
    ef_ocio_close(o);

    if (saved) {
        setenv("OCIO", saved, 1);
        free(saved);
    }
}

/* --- names ------------------------------------------------------------- */

static void test_names_aliases_roles(void **state)
{
    (void)state;
    static const char *const pairs[][2] = {
        {"ACEScg", "ACEScg"},
        {"acescg", "ACEScg"},
        {"ACESCG", "ACEScg"},
        {"lin_ap1", "ACEScg"},
        {"aces2065-1", "ACES2065-1"},
        {"lin_ap0", "ACES2065-1"},
        {"lin_srgb", LIN709},
        {"lin_rec709", LIN709},
        {"linear", LIN709},
        {"Utility - Linear - sRGB", LIN709},
        {LIN709, LIN709},
        {"srgb_texture", "sRGB - Texture"},
        {"sRGB", "sRGB - Texture"},
        {"Utility - sRGB - Texture", "sRGB - Texture"},
        {"Non-Color", "Raw"},
        {"lin_rec2020", "Linear Rec.2020"},
        {"scene_linear", "Linear Rec.709 (sRGB)"},
        {"srgb_display", "sRGB - Display"},
    };
    char name[256];
    for (size_t i = 0; i < sizeof pairs / sizeof pairs[0]; ++i) {
        name[0] = 0;
        if (!ef_ocio_space_exists(g_ocio, pairs[i][0], name, sizeof name)) {
            print_error("'%s' not found\n", pairs[i][0]);
            fail();
        }
        assert_string_equal(name, pairs[i][1]);
    }
    assert_false(ef_ocio_space_exists(g_ocio, "no such space", name, sizeof name));
    assert_false(ef_ocio_space_exists(g_ocio, "", name, sizeof name));
    /* Too small a buffer is a failure, not a silent truncation. */
    assert_false(ef_ocio_space_exists(g_ocio, "lin_srgb", name, 5));

    assert_int_equal(ef_ocio_role(g_ocio, "scene_linear", name, sizeof name), 0);
    assert_string_equal(name, "Linear Rec.709 (sRGB)");
    assert_int_equal(ef_ocio_role(g_ocio, "data", name, sizeof name), 0);
    assert_string_equal(name, "Raw");
    assert_int_equal(ef_ocio_role(g_ocio, "color_picking", name, sizeof name), 0);
    assert_string_equal(name, "sRGB - Texture");
    assert_int_equal(ef_ocio_role(g_ocio, "aces_interchange", name, sizeof name), 0);
    assert_string_equal(name, "ACES2065-1");
    assert_int_equal(ef_ocio_role(g_ocio, "no_such_role", name, sizeof name), -1);
}

static void chrom_is(const float c[8], const char *want)
{
    char name[256] = "";
    int rc = ef_ocio_space_from_chromaticities(g_ocio, c, name, sizeof name);
    if (!want) {
        if (rc != -1) {
            print_error("expected no match, got '%s'\n", name);
            fail();
        }
        return;
    }
    if (rc != 0) {
        print_error("no match, expected '%s'\n", want);
        fail();
    }
    assert_string_equal(name, want);
}

static void test_chromaticities(void **state)
{
    (void)state;
    /* BT.709 / sRGB, D65 (as OpenEXR's default chromaticities). */
    const float rec709[8] = {0.64f, 0.33f, 0.30f, 0.60f, 0.15f, 0.06f, 0.3127f, 0.3290f};
    /* AP1 / AP0 with the ACES white (S-2014-004, ST 2065-1). */
    const float ap1[8] = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.32168f, 0.33767f};
    const float ap0[8] = {0.7347f, 0.2653f, 0.0f, 1.0f, 0.0001f, -0.0770f, 0.32168f, 0.33767f};
    /* BT.2020, D65. */
    const float rec2020[8] = {0.708f, 0.292f, 0.170f, 0.797f, 0.131f, 0.046f, 0.3127f, 0.3290f};
    chrom_is(rec709, LIN709);
    chrom_is(ap1, "ACEScg");
    chrom_is(ap0, "ACES2065-1");
    chrom_is(rec2020, "Linear Rec.2020");
    /* Within the tolerance: rounded to 3 decimals. */
    const float ap1r[8] = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.322f, 0.338f};
    chrom_is(ap1r, "ACEScg");
    /* Misses: odd primaries; Rec.709 primaries with the ACES white; AP1
     * primaries with D65; garbage. */
    const float odd[8] = {0.60f, 0.35f, 0.30f, 0.60f, 0.15f, 0.06f, 0.3127f, 0.3290f};
    const float r709_d60[8] = {0.64f, 0.33f, 0.30f, 0.60f, 0.15f, 0.06f, 0.32168f, 0.33767f};
    const float ap1_d65[8] = {0.713f, 0.293f, 0.165f, 0.830f, 0.128f, 0.044f, 0.3127f, 0.3290f};
    const float zero[8] = {0};
    chrom_is(odd, NULL);
    chrom_is(r709_d60, NULL);
    chrom_is(ap1_d65, NULL);
    chrom_is(zero, NULL);
}

/* --- colours ----------------------------------------------------------- */

static void test_parse_plain_and_hex(void **state)
{
    (void)state;
    parse_ok("0.1,0.2,0.3", "ACEScg", (double[3]){0.1, 0.2, 0.3}, 0);
    parse_ok(" 1e-3 , -2 ,  4.5 ", NULL, (double[3]){1e-3, -2, 4.5}, 0);

    /* #808080 decoded by the sRGB curve: ((128/255 + 0.055)/1.055)^2.4. */
    const double g = pow((128.0 / 255.0 + 0.055) / 1.055, 2.4);
    assert_close(g, 0.21586050011389923, 1e-12);
    parse_ok("#808080", LIN709, (double[3]){g, g, g}, 2e-6);
    parse_ok("#808080", "sRGB - Texture", (double[3]){128 / 255.0, 128 / 255.0, 128 / 255.0}, 2e-6);
    /* #FF0000 in ACEScg: the first column of Rec.709 -> ACEScg. */
    parse_ok("#FF0000", "ACEScg",
             (double[3]){REC709_TO_ACESCG[0][0], REC709_TO_ACESCG[1][0], REC709_TO_ACESCG[2][0]}, 2e-6);
    parse_ok("#ff0000", "acescg",
             (double[3]){REC709_TO_ACESCG[0][0], REC709_TO_ACESCG[1][0], REC709_TO_ACESCG[2][0]}, 2e-6);
    /* A dark value on the linear segment of the curve: 0x05 = 5/255. */
    const double d = srgb_decode(5.0 / 255.0), c = srgb_decode(0x40 / 255.0);
    parse_ok("#054005", LIN709, (double[3]){d, c, d}, 1e-6);
}

static void test_parse_spaces(void **state)
{
    (void)state;
    /* ACEScg red in Rec.709: first column of ACEScg -> Rec.709. */
    parse_ok("ACEScg:1,0,0", LIN709,
             (double[3]){ACESCG_TO_REC709[0][0], ACESCG_TO_REC709[1][0], ACESCG_TO_REC709[2][0]}, 2e-6);
    /* The full matrix on a general colour, through an alias. */
    const double v[3] = {0.25, 0.5, 0.125};
    double w[3];
    for (int i = 0; i < 3; ++i)
        w[i] = ACESCG_TO_REC709[i][0] * v[0] + ACESCG_TO_REC709[i][1] * v[1] + ACESCG_TO_REC709[i][2] * v[2];
    parse_ok("lin_ap1:0.25,0.5,0.125", "lin_srgb", w, 2e-6);
    /* A name with spaces and parentheses. */
    parse_ok(LIN709 ":0,1,0", "ACEScg",
             (double[3]){REC709_TO_ACESCG[0][1], REC709_TO_ACESCG[1][1], REC709_TO_ACESCG[2][1]}, 2e-6);
    parse_ok("  Linear Rec.709 (sRGB) : 0,1,0 ", "ACEScg",
             (double[3]){REC709_TO_ACESCG[0][1], REC709_TO_ACESCG[1][1], REC709_TO_ACESCG[2][1]}, 2e-6);
    /* AP0 -> AP1 (S-2014-004). */
    parse_ok("ACES2065-1:1,0,0", "ACEScg",
             (double[3]){AP0_TO_AP1[0][0], AP0_TO_AP1[1][0], AP0_TO_AP1[2][0]}, 2e-6);
    parse_ok("ACES2065-1:1,1,1", "ACEScg", (double[3]){1, 1, 1}, 2e-6);
    /* sRGB texture values given as numbers. */
    parse_ok("srgb_texture:0.5,0.5,0.5", LIN709,
             (double[3]){srgb_decode(0.5), srgb_decode(0.5), srgb_decode(0.5)}, 2e-6);
    /* ACEScct code value of 0.18: (log2(0.18) + 9.72) / 17.52. */
    const double cct = (log2(0.18) + 9.72) / 17.52;
    char text[128];
    snprintf(text, sizeof text, "ACEScct:%.9f,%.9f,%.9f", cct, cct, cct);
    parse_ok(text, "ACEScg", (double[3]){0.18, 0.18, 0.18}, 1e-5);
    /* A role works as a space name; data is never converted. */
    parse_ok("scene_linear:0.5,0.25,1", "Linear Rec.709 (sRGB)", (double[3]){0.5, 0.25, 1}, 0);
    parse_ok("Raw:0.5,0.25,1", "ACEScg", (double[3]){0.5, 0.25, 1}, 0);
}

static void test_parse_errors(void **state)
{
    (void)state;
    parse_fails("Nope:1,2,3", "ACEScg", "unknown colour space 'Nope'");
    parse_fails("Nope:1,2,3", "ACEScg", "'ACEScg'");
    parse_fails("1,2", "ACEScg", "expected R,G,B");
    parse_fails("1,2,3,4", "ACEScg", "expected R,G,B");
    parse_fails("1,,3", "ACEScg", "expected R,G,B");
    parse_fails("ACEScg:1,2,x", "ACEScg", "expected R,G,B");
    parse_fails("ACEScg:", "ACEScg", "expected R,G,B");
    parse_fails("", "ACEScg", "expected R,G,B");
    parse_fails("nan,1,1", "ACEScg", "expected R,G,B");
    parse_fails("1,1,inf", "ACEScg", "expected R,G,B");
    parse_fails("#12345", "ACEScg", "#RRGGBB");
    parse_fails("#1234567", "ACEScg", "#RRGGBB");
    parse_fails("#GG0000", "ACEScg", "#RRGGBB");
    parse_fails("1,1,1", "no-such-working", "unknown working colour space 'no-such-working'");
}

static void test_odd_names(void **state)
{
    (void)state;
    char where[1200], msg[2048], used[256];
    ef_ocio *o = ef_ocio_open(g_odd, where, sizeof where, msg, sizeof msg);
    assert_non_null(o);
    ef_ocio *keep = g_ocio;
    g_ocio = o;
    /* A space whose name holds ':' splits at the last ':'. */
    parse_ok("Cam:Linear:0.5,1,2", "Half", (double[3]){0.25, 0.5, 1}, 1e-7);
    parse_ok("0.5,1,2", NULL, (double[3]){0.5, 1, 2}, 0);
    /* No sRGB texture space in this config. */
    parse_fails("#808080", NULL, "no sRGB texture space");
    g_ocio = keep;

    /* A display and a view whose names hold ", ". */
    ef_ocio_display *d = ef_ocio_display_open(o, NULL, "Monitor, left, Half, bright", used, sizeof used,
                                              msg, sizeof msg);
    if (!d)
        print_error("%s\n", msg);
    assert_non_null(d);
    assert_string_equal(used, "Monitor, left, Half, bright");
    float px[3] = {1, 2, 4};
    assert_int_equal(ef_ocio_display_apply(d, px, 1), 0);
    assert_close(px[0], 0.5, 1e-7);
    assert_close(px[2], 2.0, 1e-7);
    ef_ocio_display_close(d);
    d = ef_ocio_display_open(o, NULL, "Monitor, left", used, sizeof used, msg, sizeof msg);
    assert_non_null(d);
    assert_string_equal(used, "Monitor, left, Half, bright");
    ef_ocio_display_close(d);
    ef_ocio_close(o);
}

/* --- displays ---------------------------------------------------------- */

static void display_grey(const char *working, const char *dv, const char *want_used, double in,
                         double want, double tol)
{
    char used[256] = "", msg[2048] = "";
    ef_ocio_display *d = ef_ocio_display_open(g_ocio, working, dv, used, sizeof used, msg, sizeof msg);
    if (!d) {
        print_error("%s\n", msg);
        fail();
    }
    assert_string_equal(used, want_used);
    float px[6] = {(float) in, (float) in, (float) in, 0, 0, 0};
    assert_int_equal(ef_ocio_display_apply(d, px, 2), 0);
    for (int i = 0; i < 3; ++i) {
        assert_close(px[i], want, tol);
        assert_close(px[3 + i], 0.0, 1e-6);
    }
    ef_ocio_display_close(d);
}

static void test_display_views(void **state)
{
    (void)state;
    /* sRGB encoding of 0.18: 1.055 * 0.18^(1/2.4) - 0.055 = 0.46135... */
    const double s = srgb_encode(0.18);
    assert_close(s, 0.461356129, 1e-8);
    display_grey(NULL, NULL, "sRGB - Display, Un-tone-mapped", 0.18, s, 2e-6);
    display_grey("ACEScg", "sRGB - Display, Un-tone-mapped", "sRGB - Display, Un-tone-mapped", 0.18, s, 2e-6);
    display_grey(LIN709, "srgb - display,un-tone-mapped", "sRGB - Display, Un-tone-mapped", 0.18, s, 2e-6);
    display_grey("ACEScg", "sRGB - Display", "sRGB - Display, Un-tone-mapped", 1.0, 1.0, 2e-6);
    /* BT.1886 with a zero black level: 0.18^(1/2.4). */
    display_grey("ACEScg", "Rec.1886 Rec.709 - Display, Un-tone-mapped",
                 "Rec.1886 Rec.709 - Display, Un-tone-mapped", 0.18, pow(0.18, 1 / 2.4), 2e-6);
    display_grey("ACEScg", "sRGB - Display, Raw", "sRGB - Display, Raw", 0.18, 0.18, 1e-7);
    /* OCIO's built-in ACES 1.0 SDR video output: only a sanity range here
     * (mid grey lands near 10 nits of 100, i.e. ~0.35 in sRGB code). */
    display_grey("ACEScg", "sRGB - Display, ACES 1.0 - SDR Video", "sRGB - Display, ACES 1.0 - SDR Video",
                 0.18, 0.35, 0.03);

    /* Rec.709 primaries pass through the XYZ round trip: red stays red,
     * ACEScg red becomes the Rec.709 column, sRGB-encoded. */
    char used[256], msg[2048];
    ef_ocio_display *d = ef_ocio_display_open(g_ocio, LIN709, NULL, used, sizeof used, msg, sizeof msg);
    assert_non_null(d);
    float red[3] = {1, 0, 0};
    assert_int_equal(ef_ocio_display_apply(d, red, 1), 0);
    assert_close(red[0], 1.0, 2e-6);
    assert_close(red[1], 0.0, 2e-6);
    assert_close(red[2], 0.0, 2e-6);
    ef_ocio_display_close(d);
    d = ef_ocio_display_open(g_ocio, "ACEScg", NULL, used, sizeof used, msg, sizeof msg);
    assert_non_null(d);
    float half[3] = {0.5f, 0.5f, 0.25f};
    double lin[3];
    for (int i = 0; i < 3; ++i)
        lin[i] = ACESCG_TO_REC709[i][0] * 0.5 + ACESCG_TO_REC709[i][1] * 0.5 + ACESCG_TO_REC709[i][2] * 0.25;
    assert_int_equal(ef_ocio_display_apply(d, half, 1), 0);
    for (int i = 0; i < 3; ++i)
        assert_close(half[i], srgb_encode(lin[i]), 5e-6);
    ef_ocio_display_close(d);
}

static void test_display_errors(void **state)
{
    (void)state;
    char used[256], msg[2048];
    assert_null(ef_ocio_display_open(g_ocio, "ACEScg", "Cinema, Fancy", used, sizeof used, msg, sizeof msg));
    assert_contains(msg, "'Cinema, Fancy'");
    assert_contains(msg, "'sRGB - Display': 'Un-tone-mapped'");
    assert_contains(msg, "'Rec.1886 Rec.709 - Display'");
    assert_null(ef_ocio_display_open(g_ocio, "ACEScg", "sRGB - Display, Filmic", used, sizeof used, msg,
                                     sizeof msg));
    assert_contains(msg, "'Raw'");
    assert_null(ef_ocio_display_open(g_ocio, "nope", NULL, used, sizeof used, msg, sizeof msg));
    assert_contains(msg, "unknown working colour space 'nope'");
}

/* Several threads share one display processor. */
struct job {
    const ef_ocio_display *d;
    float px[3 * 4096];
    int rc;
};

static void *run_job(void *arg)
{
    struct job *j = arg;
    for (int k = 0; k < 8 && j->rc == 0; ++k) {
        for (int i = 0; i < 3 * 4096; ++i)
            j->px[i] = 0.18f;
        j->rc = ef_ocio_display_apply(j->d, j->px, 4096);
    }
    return NULL;
}

static void test_display_threads(void **state)
{
    (void)state;
    char used[256], msg[2048];
    ef_ocio_display *d = ef_ocio_display_open(g_ocio, NULL, NULL, used, sizeof used, msg, sizeof msg);
    assert_non_null(d);
    static struct job jobs[4];
    pthread_t t[4];
    for (int i = 0; i < 4; ++i) {
        jobs[i].d = d;
        jobs[i].rc = 0;
        assert_int_equal(pthread_create(&t[i], NULL, run_job, &jobs[i]), 0);
    }
    for (int i = 0; i < 4; ++i) {
        pthread_join(t[i], NULL);
        assert_int_equal(jobs[i].rc, 0);
        assert_close(jobs[i].px[3 * 4095 + 1], srgb_encode(0.18), 2e-6);
    }
    ef_ocio_display_close(d);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_open_explicit_and_errors),
        cmocka_unit_test(test_lut_files_checked),
        cmocka_unit_test(test_env_and_precedence),
        cmocka_unit_test(test_names_aliases_roles),
        cmocka_unit_test(test_chromaticities),
        cmocka_unit_test(test_parse_plain_and_hex),
        cmocka_unit_test(test_parse_spaces),
        cmocka_unit_test(test_parse_errors),
        cmocka_unit_test(test_odd_names),
        cmocka_unit_test(test_display_views),
        cmocka_unit_test(test_display_errors),
        cmocka_unit_test(test_display_threads),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
