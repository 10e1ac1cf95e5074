/* Pipeline features of issue 9 through the exrfog binary: frame
 * sequences (patterns, --frames, per-frame cameras and time, missing and
 * failed frames, --keep-going, the progress bar under a pseudo-terminal,
 * the GNU parallel recipe) and multi-view files. Expected values come from
 * the pinhole model worked out here, not from exrfog's own code. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>

#include "frames.h"
#include "testutil.h"

#define W 8
#define H 6
#define HFOV 90.0

static char g_dir[1024];

/* A fresh scratch directory for one test; returns its path. */
static const char *fresh(const char *name)
{
    char *p = tu_path(name);
    snprintf(g_dir, sizeof g_dir, "%s", p);
    free(p);
    char cmd[2200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s' && mkdir -p '%s'", g_dir, g_dir);
    assert_int_equal(system(cmd), 0);
    return g_dir;
}

static float g_c[W * H], g_c2[W * H], g_a[W * H], g_z[W * H];

/* The planes of a frame: colour 0.5 (0.25 for a second view), alpha 1,
 * planar depth 5 with one sky pixel (depth 0) at pixel 0. */
static void planes_init(void)
{
    for (int i = 0; i < W * H; ++i) {
        g_c[i] = 0.5f;
        g_c2[i] = 0.25f;
        g_a[i] = 1.0f;
        g_z[i] = i == 0 ? 0.0f : 5.0f;
    }
}

/* Adds R, G, B, A, Z with the given prefix ("" or "left.") to p. */
static void add_rgbaz(tu_part *p, const char *prefix, const float *c)
{
    static char names[8][5][32];
    static int slot;
    char (*n)[32] = names[slot++ % 8];
    static const char *const ch[5] = { "R", "G", "B", "A", "Z" };
    for (int k = 0; k < 5; ++k) {
        snprintf(n[k], 32, "%s%s", prefix, ch[k]);
        tu_part_add(p, n[k], EXR_PIXEL_FLOAT, k < 3 ? c : k == 3 ? g_a : g_z);
    }
}

/* A camera at (cx, 0, 0) looking down +Z (worldToCamera is the
 * translation by -cx, row-vector layout), horizontal fov 90. */
static void set_camera(tu_part *p, double cx)
{
    static const float id[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    p->m44[0].name = "worldToCamera";
    memcpy(p->m44[0].m, id, sizeof id);
    p->m44[0].m[12] = (float) -cx;
    p->f[0].name = "CameraFov";
    p->f[0].v = (float) HFOV;
}

/* One frame with a camera at (cx, 0, 0). */
static void write_frame(const char *path, double cx)
{
    planes_init();
    tu_part p;
    tu_part_init(&p, W, H);
    add_rgbaz(&p, "", g_c);
    set_camera(&p, cx);
    assert_int_equal(tu_write_exr(path, &p, 1), 0);
}

static char *in_dir(const char *fmt, ...)
{
    char name[512], *out = malloc(2048);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(name, sizeof name, fmt, ap);
    va_end(ap);
    snprintf(out, 2048, "%s/%s", g_dir, name);
    return out;
}

/* Writes frames first..last of dir/shot.####.exr (4-digit), camera at x = 10 * frame. */
static void write_sequence(int first, int last)
{
    for (int f = first; f <= last; ++f) {
        char *p = in_dir("shot.%04d.exr", f);
        write_frame(p, 10.0 * f);
        free(p);
    }
}

/* fog_P of the output frame must be the frame's camera (10 f, 0, 0) plus
 * depth 5 along the pinhole ray of each pixel: ((u - 1/2)/a, -(v - 1/2)/b, 1)
 * with a = 1/2 / tan(45 deg), b = a W / H. */
static void check_positions_mirror(const char *out, int part, const char *view, double cx,
                                   double sx)
{
    tu_image img;
    char nx[64], ny[64], nz[64];
    snprintf(nx, sizeof nx, "fog_P.%s%sX", view, view[0] ? "." : "");
    snprintf(ny, sizeof ny, "fog_P.%s%sY", view, view[0] ? "." : "");
    snprintf(nz, sizeof nz, "fog_P.%s%sZ", view, view[0] ? "." : "");
    assert_int_equal(tu_read_image(out, part, &img), 0);
    const float *P[3] = { tu_image_f(&img, nx), tu_image_f(&img, ny), tu_image_f(&img, nz) };
    assert_non_null(P[0]);
    const double a = 0.5, b = a * W / H;
    long bad = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const int i = y * W + x;
            if (i == 0)
                continue;   /* sky */
            const double u = (x + 0.5) / W, v = (y + 0.5) / H;
            const double e[3] = { cx + sx * 5.0 * (u - 0.5) / a, 5.0 * -(v - 0.5) / b, 5.0 };
            for (int k = 0; k < 3; ++k)
                bad += fabs(P[k][i] - e[k]) > 1e-5 * (1 + fabs(e[k]));
        }
    tu_image_free(&img);
    assert_int_equal(bad, 0);
}

static void check_positions_in(const char *out, int part, const char *view, double cx)
{
    check_positions_mirror(out, part, view, cx, 1.0);
}

static void check_positions(const char *out, int frame)
{
    check_positions_in(out, 0, "", 10.0 * frame);
}

static void test_frame_patterns(void **state)
{
    (void) state;
    static const struct {
        const char *path;
        long frame;
        const char *want;
    } cases[] = {
        { "a/shot.#.exr", 7, "a/shot.0007.exr" },
        { "shot.##.exr", 7, "shot.00000007.exr" },
        { "shot.@@@.exr", 42, "shot.042.exr" },
        { "shot.@.exr", 1234, "shot.1234.exr" },
        { "shot.%04d.exr", -3, "shot.-003.exr" },
        { "shot.%d.exr", 12, "shot.12.exr" },
        { "take#2/shot.%03d.exr", 5, "take#2/shot.005.exr" },
        { "plain.exr", 5, "plain.exr" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
        ef_frame_pattern p;
        char out[256];
        ef_frame_pattern_find(cases[i].path, &p);
        assert_int_equal(ef_frame_path(cases[i].path, &p, cases[i].frame, out, sizeof out), 0);
        assert_string_equal(out, cases[i].want);
    }
    static const struct {
        const char *text;
        int n;
        long first, last;
    } lists[] = { { "1-100", 100, 1, 100 }, { "1-100x2", 50, 1, 99 }, { "1,5,10-20", 13, 1, 20 },
                  { "-5--1", 5, -5, -1 }, { "1001", 1, 1001, 1001 } };
    for (size_t i = 0; i < sizeof lists / sizeof lists[0]; ++i) {
        long *f;
        int n;
        ef_err err = { 0 };
        assert_int_equal(ef_frames_parse(lists[i].text, &f, &n, &err), 0);
        assert_int_equal(n, lists[i].n);
        assert_int_equal(f[0], lists[i].first);
        assert_int_equal(f[n - 1], lists[i].last);
        free(f);
    }
    static const char *const bad[] = { "", "1-", "a", "10-1", "1-10x0", "1,,2", "1-10y2", "1,", "5-3" };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        long *f;
        int n;
        ef_err err = { 0 };
        assert_int_equal(ef_frames_parse(bad[i], &f, &n, &err), -1);
        assert_non_null(strstr(err.msg, "--frames"));
    }
}

/* The frames on disk that match: exact padding, longer numbers without a
 * leading zero, negative frames; never look-alikes. */
static void test_frames_on_disk(void **state)
{
    (void) state;
    fresh("ondisk");
    static const char *const names[] = { "s.0001.exr", "s.0002.exr", "s.10000.exr", "s.-001.exr",
                                         "s.001.exr", "s.00002.exr", "s.0003.exr.bak",
                                         "t.0004.exr", "s.00a1.exr" };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; ++i) {
        char *p = in_dir("%s", names[i]);
        assert_int_equal(tu_write_bytes(p, "x", 1), 0);
        free(p);
    }
    char *pat = in_dir("s.#.exr");
    ef_frame_pattern p;
    ef_frame_pattern_find(pat, &p);
    long *f;
    int n;
    ef_err err = { 0 };
    assert_int_equal(ef_frames_on_disk(pat, &p, &f, &n, &err), 0);
    assert_int_equal(n, 4);
    assert_int_equal(f[0], -1);
    assert_int_equal(f[1], 1);
    assert_int_equal(f[2], 2);
    assert_int_equal(f[3], 10000);
    free(f);
    free(pat);
}

/* Each frame is fogged with its own header camera, into its own output. */
static void test_sequence_cameras(void **state)
{
    (void) state;
    fresh("seqcam");
    write_sequence(1, 3);
    assert_run(0, "'%s/shot.#.exr' -o '%s/out.#.exr' --fog exp:density=0.05 --aov P", g_dir, g_dir);
    for (int f = 1; f <= 3; ++f) {
        char *o = in_dir("out.%04d.exr", f);
        check_positions(o, f);
        free(o);
    }
    /* %04d and @@@@ name the same frames; --frames picks a subset */
    fresh("seqcam2");
    write_sequence(1, 3);
    assert_run(0, "'%s/shot.%%04d.exr' -o '%s/pct.@@@@.exr' --frames 1-3x2 --fog exp:density=0.05 "
                  "--aov P", g_dir, g_dir);
    char *o1 = in_dir("pct.0001.exr"), *o2 = in_dir("pct.0002.exr"), *o3 = in_dir("pct.0003.exr");
    check_positions(o1, 1);
    check_positions(o3, 3);
    assert_false(tu_exists(o2));
    free(o1);
    free(o2);
    free(o3);
}

/* --time defaults to frame / --fps: frame 2 of a sequence equals the
 * single file run with --time 2/24 (and 2/12 with --fps 12) bit for bit,
 * and an explicit --time overrides every frame. */
static void test_sequence_time(void **state)
{
    (void) state;
    fresh("seqtime");
    write_sequence(1, 2);
    static const char *const fog = "--fog noise:density=0.2:scale=2:velocity=3,0,0:method=exact";
    assert_run(0, "'%s/shot.#.exr' -o '%s/seq.#.exr' %s", g_dir, g_dir, fog);
    assert_run(0, "'%s/shot.0002.exr' -o '%s/single.exr' %s --time %.17g", g_dir, g_dir, fog,
               2.0 / 24.0);
    char *seq2 = in_dir("seq.0002.exr"), *seq1 = in_dir("seq.0001.exr"), *single = in_dir("single.exr");
    assert_int_equal(tu_compare_files(single, seq2, -1, NULL), 0);
    assert_run(0, "'%s/shot.#.exr' -o '%s/seq.#.exr' %s --fps 12", g_dir, g_dir, fog);
    assert_run(0, "'%s/shot.0002.exr' -o '%s/single.exr' %s --time %.17g", g_dir, g_dir, fog,
               2.0 / 12.0);
    assert_int_equal(tu_compare_files(single, seq2, -1, NULL), 0);
    /* the time really moves the fog: frame 1 and 2 at one time differ only by the camera */
    assert_run(0, "'%s/shot.#.exr' -o '%s/seq.#.exr' %s --time 0.5", g_dir, g_dir, fog);
    assert_run(0, "'%s/shot.0001.exr' -o '%s/single.exr' %s --time 0.5", g_dir, g_dir, fog);
    assert_int_equal(tu_compare_files(single, seq1, -1, NULL), 0);
    assert_run(0, "'%s/shot.0001.exr' -o '%s/single.exr' %s --time 0", g_dir, g_dir, fog);
    assert_true(tu_compare_files(single, seq1, -1, NULL) > 0);
    free(seq1);
    free(seq2);
    free(single);
}

/* Missing frames are named before any work; a failed frame stops the run
 * unless --keep-going, which fogs the others and names every failure. */
/* Sequences that would destroy data: an output pattern naming another
 * frame's input (s.%d.exr -o s.%d0.exr: frame 1's output is frame 10's
 * input) is refused before anything is written, and a frame --frames
 * lists twice (1,1 or overlapping ranges) is fogged once, with a note:
 * fogged in place twice, it would hold fog on fog. */
static void test_sequence_repeats_and_overwrites(void **state)
{
    (void) state;
    fresh("seqdanger");
    for (int f = 1; f <= 10; f += 9) {
        char *p = in_dir("s.%d.exr", f);
        write_frame(p, 10.0 * f);
        free(p);
    }
    char *s1 = in_dir("s.1.exr"), *s10 = in_dir("s.10.exr");
    size_t n10;
    unsigned char *before10 = NULL;
    {
        FILE *f = fopen(s10, "rb");
        assert_non_null(f);
        fseek(f, 0, SEEK_END);
        n10 = (size_t) ftell(f);
        fseek(f, 0, SEEK_SET);
        before10 = malloc(n10);
        assert_int_equal(fread(before10, 1, n10, f), n10);
        fclose(f);
    }
    assert_run(2, "'%s/s.%%d.exr' -o '%s/s.%%d0.exr' --frames 1,10 --fog exp:density=0.05", g_dir,
               g_dir);
    assert_non_null(strstr(tu_err, "names frame 10's input"));
    assert_non_null(strstr(tu_err, "nothing was written"));
    {
        FILE *f = fopen(s10, "rb");
        assert_non_null(f);
        unsigned char *now10 = malloc(n10 + 1);
        assert_int_equal(fread(now10, 1, n10 + 1, f), n10);
        fclose(f);
        assert_memory_equal(now10, before10, n10);
        free(now10);
    }
    char *o100 = in_dir("s.100.exr");
    assert_false(tu_exists(o100));
    /* in place, each frame onto itself, stays allowed */
    char *c1 = in_dir("c.1.exr"), *c10 = in_dir("c.10.exr");
    assert_int_equal(tu_copy(s1, c1), 0);
    assert_int_equal(tu_copy(s10, c10), 0);
    assert_run(0, "'%s/c.%%d.exr' -o '%s/c.%%d.exr' --frames 1,10 --fog exp:density=0.05", g_dir,
               g_dir);
    /* 1,1 and 1-10,10: each frame once; fogged once, in place, it equals
     * a single fog of the original */
    assert_int_equal(tu_copy(s1, c1), 0);
    assert_int_equal(tu_copy(s10, c10), 0);
    assert_run(0, "'%s/c.%%d.exr' -o '%s/c.%%d.exr' --frames 1,1,10,1,10 --fog exp:density=0.05",
               g_dir, g_dir);
    assert_non_null(strstr(tu_err, "note: --frames lists frames 1, 10 more than once; each frame "
                                   "is fogged once"));
    char *once = in_dir("once.exr");
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05", s1, once);
    assert_int_equal(tu_compare_files(c1, once, -1, NULL), 0);
    free(once);
    free(c1);
    free(c10);
    free(o100);
    free(before10);
    free(s1);
    free(s10);
}

static void test_sequence_failures(void **state)
{
    (void) state;
    fresh("seqfail");
    write_sequence(1, 3);
    char *o1 = in_dir("out.0001.exr"), *o2 = in_dir("out.0002.exr"), *o3 = in_dir("out.0003.exr");
    assert_run(1, "'%s/shot.#.exr' -o '%s/out.#.exr' --frames 1-5 --fog exp:density=0.05", g_dir,
               g_dir);
    assert_non_null(strstr(tu_err, "2 of 5 frames missing on disk"));
    assert_non_null(strstr(tu_err, ": 4, 5;"));
    assert_false(tu_exists(o1));
    /* no match at all, and the oiiotool padding hint */
    assert_run(1, "'%s/none.#.exr' -o '%s/out.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "no file on disk matches"));
    assert_run(1, "'%s/shot.####.exr' -o '%s/out.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "each # is four digits"));
    /* frame 2 corrupt: without --keep-going frame 1 is written, 3 is not */
    char *s2 = in_dir("shot.0002.exr");
    assert_int_equal(tu_write_bytes(s2, "v/1\001 not an exr", 16), 0);
    assert_run(1, "'%s/shot.#.exr' -o '%s/out.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "shot.0002.exr"));
    assert_non_null(strstr(tu_err, "stopped at frame 2"));
    assert_true(tu_exists(o1));
    assert_false(tu_exists(o2));
    assert_false(tu_exists(o3));
    unlink(o1);
    assert_run(1, "'%s/shot.#.exr' -o '%s/out.#.exr' --frames 1-4 --keep-going --fog "
                  "exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "2 of 4 frames failed: 2, 4"));
    assert_true(tu_exists(o1));
    assert_false(tu_exists(o2));
    assert_true(tu_exists(o3));
    /* usage errors */
    assert_run(2, "'%s/shot.#.exr' -o '%s/out.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "no frame pattern"));
    assert_run(2, "'%s/shot.0001.exr' -o '%s/out.exr' --frames 1-3 --fog exp:density=0.05", g_dir,
               g_dir);
    assert_run(2, "'%s/shot.#.exr' -o '%s/out.#.exr' --frames 3-1 --fog exp:density=0.05", g_dir,
               g_dir);
    assert_run(2, "'%s/shot.#.exr' -o '%s/out.#.exr' --fps 0 --fog exp:density=0.05", g_dir, g_dir);
    free(s2);
    free(o1);
    free(o2);
    free(o3);
}

/* The progress bar appears on a terminal (a pseudo-terminal made by
 * script(1)) and never in a pipe or with -q. */
static void test_progress_bar(void **state)
{
    (void) state;
    if (system("command -v script >/dev/null 2>&1"))
        skip();
    fresh("progress");
    write_sequence(1, 3);
    const char *bin = getenv("EXRFOG_BIN");
    char cmd[4096], out[8192] = "";
    snprintf(cmd, sizeof cmd,
             "script -qec \"'%s' '%s/shot.#.exr' -o '%s/out.#.exr' --fog exp:density=0.05\" "
             "/dev/null </dev/null",
             bin, g_dir, g_dir);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    const size_t n = fread(out, 1, sizeof out - 1, p);
    out[n] = '\0';
    assert_int_equal(pclose(p), 0);
    /* the last drawing shows the last frame, or the bar is cleared at the
     * end: at least the final clear sequence and no error */
    assert_non_null(strstr(out, "\033[K"));
    assert_null(strstr(out, "error"));
    /* a slow run draws: many frames of a heavier model */
    write_sequence(4, 12);
    snprintf(cmd, sizeof cmd,
             "script -qec \"'%s' '%s/shot.#.exr' -o '%s/out.#.exr' --fog "
             "noise:density=0.2:scale=0.01:octaves=8:method=exact --threads 1\" /dev/null "
             "</dev/null", bin, g_dir, g_dir);
    p = popen(cmd, "r");
    assert_non_null(p);
    const size_t m = fread(out, 1, sizeof out - 1, p);
    out[m] = '\0';
    assert_int_equal(pclose(p), 0);
    if (!strstr(out, "ETA") || !strstr(out, "elapsed") || !strstr(out, "/12)"))
        fail_msg("no progress bar on the terminal: '%s'", out);
    /* not a terminal, or -q: nothing at all */
    assert_run(0, "'%s/shot.#.exr' -o '%s/out.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_string_equal(tu_err, "");
    snprintf(cmd, sizeof cmd,
             "script -qec \"'%s' '%s/shot.#.exr' -o '%s/out.#.exr' --fog exp:density=0.05 -q\" "
             "/dev/null </dev/null", bin, g_dir, g_dir);
    p = popen(cmd, "r");
    const size_t q = fread(out, 1, sizeof out - 1, p);
    out[q] = '\0';
    assert_int_equal(pclose(p), 0);
    assert_string_equal(out, "");
}

/* Messages of the hostile campaign (issue 23): the #### padding hint names
 * the file looked for and the four-digit one found; limits are stated;
 * a single INPUT with a pattern in -o, a directory as -o and a file named
 * like an option are refused with what to write instead; --failed-list
 * holds every frame not written when the message must abbreviate. */
static void test_sequence_messages(void **state)
{
    (void) state;
    fresh("seqmsg");
    write_sequence(1, 3);
    assert_run(1, "'%s/shot.####.exr' -o '%s/o.#.exr' --frames 1-3 --fog exp:density=0.05", g_dir,
               g_dir);
    assert_non_null(strstr(tu_err, "looked for"));
    assert_non_null(strstr(tu_err, "shot.0000000000000001.exr, but"));
    assert_non_null(strstr(tu_err, "shot.0001.exr exists"));
    assert_non_null(strstr(tu_err, "shot.#.exr or"));
    assert_non_null(strstr(tu_err, "shot.%04d.exr)"));
    assert_run(1, "'%s/shot.%%08d.exr' -o '%s/o.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "names with 8 digits, but"));
    assert_run(2, "'%s/shot.#.exr' -o '%s/o.#.exr' --frames 1-1000000000 --fog exp:density=0.05",
               g_dir, g_dir);
    assert_non_null(strstr(tu_err, "frame numbers run from -999999999 to 999999999"));
    assert_run(2, "'%s/shot.%%0240d.exr' -o '%s/o.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "asks for 240 digits; at most 100"));
    assert_run(2, "'%s/shot.0001.exr' -o '%s/f.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "has a frame pattern but INPUT"));
    char *lit = in_dir("f.#.exr");
    assert_false(tu_exists(lit));
    free(lit);
    assert_run(2, "'%s/shot.0001.exr' -o '%s' --fog exp:density=0.05", g_dir, g_dir);
    assert_non_null(strstr(tu_err, "is a directory; give a file name"));
    assert_run(2, "-in.exr -o '%s/x.exr' --fog exp:density=0.05", g_dir);
    assert_non_null(strstr(tu_err, "unknown option '-i' in '-in.exr'"));
    assert_non_null(strstr(tu_err, "./-in.exr"));
    /* 197 of 200 frames missing: the message abbreviates, the list does not */
    assert_run(1, "'%s/shot.#.exr' -o '%s/o.#.exr' --frames 1-200 --keep-going --failed-list "
                  "'%s/failed.txt' --fog exp:density=0.05", g_dir, g_dir, g_dir);
    assert_non_null(strstr(tu_err, "197 of 200 frames missing on disk"));
    assert_non_null(strstr(tu_err, "(every one in --failed-list)"));
    char *fl = in_dir("failed.txt");
    FILE *f = fopen(fl, "r");
    assert_non_null(f);
    long v, want = 4;
    int count = 0;
    while (fscanf(f, "%ld", &v) == 1) {
        assert_int_equal(v, want);
        ++want;
        ++count;
    }
    fclose(f);
    assert_int_equal(count, 197);
    for (int k = 1; k <= 3; ++k) {
        char *o = in_dir("o.%04d.exr", k);
        assert_true(tu_exists(o));
        free(o);
    }
    /* every frame written: an empty list */
    assert_run(0, "'%s/shot.#.exr' -o '%s/o.#.exr' --frames 1-3 --failed-list '%s/failed.txt' "
                  "--fog exp:density=0.05", g_dir, g_dir, g_dir);
    struct stat st;
    assert_int_equal(stat(fl, &st), 0);
    assert_int_equal((int) st.st_size, 0);
    free(fl);
}

/* exrfog-farm --engine parallel (GNU parallel here): chunks of frames as
 * parallel tasks give the same pixels as one run; a damaged frame fails
 * its chunk, is named with its log and leaves the other frames written. */
static void test_parallel_recipe(void **state)
{
    (void) state;
    if (system("command -v parallel >/dev/null 2>&1 && command -v python3 >/dev/null 2>&1"))
        skip();
    fresh("farm");
    write_sequence(1, 5);
    const char *src = getenv("EXRFOG_SOURCE_DIR"), *bin = getenv("EXRFOG_BIN");
    char cmd[16384];
    snprintf(cmd, sizeof cmd,
             "cd '%s' && python3 '%s/src/farm/exrfog-farm' submit --engine parallel --jobs 2 "
             "--chunk 2 --exrfog '%s' --jobdir job1 -- '%s/shot.#.exr' -o '%s/par.#.exr' "
             "--frames 1-5 --fog exp:density=0.05 >'%s/log' 2>&1",
             g_dir, src, bin, g_dir, g_dir, g_dir);
    if (system(cmd)) {
        snprintf(cmd, sizeof cmd, "cat '%s/log' >&2", g_dir);
        (void) system(cmd);
        fail_msg("exrfog-farm --engine parallel failed");
    }
    assert_run(0, "'%s/shot.#.exr' -o '%s/one.#.exr' --fog exp:density=0.05", g_dir, g_dir);
    for (int f = 1; f <= 5; ++f) {
        char *a = in_dir("par.%04d.exr", f), *b = in_dir("one.%04d.exr", f);
        assert_int_equal(tu_compare_files(b, a, -1, NULL), 0);
        free(a);
        free(b);
    }
    /* a damaged frame fails its chunk (exit 1), named with its log */
    char *s3 = in_dir("shot.0003.exr");
    assert_int_equal(tu_write_bytes(s3, "junk", 4), 0);
    snprintf(cmd, sizeof cmd,
             "cd '%s' && python3 '%s/src/farm/exrfog-farm' submit --engine parallel --chunk 2 "
             "--exrfog '%s' --jobdir job2 -- '%s/shot.#.exr' -o '%s/par2.#.exr' --frames 1-5 "
             "--fog exp:density=0.05 >'%s/log' 2>&1; test $? = 1 && "
             "grep -q 'frames not written: 3; log %s/job2/logs/chunk-0001.log' '%s/log' && "
             "grep -q 'shot.0003.exr' '%s/job2/logs/chunk-0001.log' && test -e '%s/par2.0004.exr' "
             "&& test ! -e '%s/par2.0003.exr'",
             g_dir, src, bin, g_dir, g_dir, g_dir, g_dir, g_dir, g_dir, g_dir, g_dir);
    if (system(cmd)) {
        snprintf(cmd, sizeof cmd, "cat '%s/log' '%s/job2/logs/chunk-0001.log' >&2", g_dir, g_dir);
        (void) system(cmd);
        fail_msg("a damaged frame was not reported by exrfog-farm");
    }
    free(s3);
}

/* --camera-file: frames without a header camera take theirs from a JSON
 * file (camera at x = 10 f, OpenEXR convention) or a Nuke .chan (the same
 * positions, turned 180 degrees about y so that the -Z-looking Nuke camera
 * looks down world +Z with its x mirrored; the vertical fov 2 atan(3/4)
 * is the horizontal 90 of the 8x6 frame). */
static void test_camera_file(void **state)
{
    (void) state;
    fresh("camfile");
    planes_init();
    for (int f = 1; f <= 3; ++f) {
        tu_part p;
        tu_part_init(&p, W, H);
        add_rgbaz(&p, "", g_c);
        char *path = in_dir("shot.%04d.exr", f);
        assert_int_equal(tu_write_exr(path, &p, 1), 0);
        free(path);
    }
    char *json = in_dir("cams.json"), *chan = in_dir("cams.chan");
    FILE *j = fopen(json, "w");
    assert_non_null(j);
    fprintf(j, "{\"convention\": \"exr\", \"fov\": 90, \"frames\": {");
    for (int f = 1; f <= 3; ++f)
        fprintf(j, "%s\"%d\": {\"camera_to_world\": [1,0,0,0, 0,1,0,0, 0,0,1,0, %d,0,0,1]}",
                f > 1 ? ", " : "", f, 10 * f);
    fprintf(j, "}}\n");
    fclose(j);
    FILE *c = fopen(chan, "w");
    assert_non_null(c);
    fprintf(c, "# frame tx ty tz rx ry rz vfov\n");
    for (int f = 1; f <= 3; ++f)
        fprintf(c, "%d %d 0 0 0 180 0 %.17g\n", f, 10 * f, 2.0 * atan(0.75) * 180.0 / 3.14159265358979323846);
    fclose(c);
    assert_run(0, "'%s/shot.#.exr' -o '%s/j.#.exr' --camera-file '%s' --fog exp:density=0.05 "
                  "--aov P", g_dir, g_dir, json);
    assert_run(0, "'%s/shot.#.exr' -o '%s/c.#.exr' --camera-file '%s' --fog exp:density=0.05 "
                  "--aov P", g_dir, g_dir, chan);
    for (int f = 1; f <= 3; ++f) {
        char *a = in_dir("j.%04d.exr", f), *b = in_dir("c.%04d.exr", f);
        check_positions_mirror(a, 0, "", 10.0 * f, 1.0);
        check_positions_mirror(b, 0, "", 10.0 * f, -1.0);
        free(a);
        free(b);
    }
    /* a single frame takes its number from its name */
    char *one = in_dir("one.exr");
    assert_run(0, "'%s/shot.0002.exr' -o '%s' --camera-file '%s' --fog exp:density=0.05 --aov P",
               g_dir, one, json);
    check_positions_mirror(one, 0, "", 20.0, 1.0);
    /* --explain says where the camera came from */
    assert_run(0, "'%s/shot.0003.exr' --explain --camera-file '%s'", g_dir, chan);
    assert_non_null(strstr(tu_out, "frame 3"));
    assert_non_null(strstr(tu_out, "camera file"));
    /* and where its fov came from: the file, not "flag --fov" (it said so) */
    assert_null(strstr(tu_out, "flag --fov"));
    assert_non_null(strstr(tu_out, "deg horizontal  from camera file"));
    assert_run(0, "'%s/shot.0003.exr' --explain --camera-file '%s'", g_dir, json);
    assert_non_null(strstr(tu_out, "deg horizontal  from camera file"));
    assert_run(0, "'%s/shot.0003.exr' --explain --camera-file '%s' --fov 30", g_dir, json);
    assert_non_null(strstr(tu_out, "30 deg horizontal  from flag --fov"));
    /* near and far from the file say so too, and a flag over one of them
     * says it is the flag (issue 42: both said "from flag") */
    char *clip = in_dir("clip.json");
    FILE *cj = fopen(clip, "w");
    assert_non_null(cj);
    fprintf(cj, "{\"convention\": \"exr\", \"fov\": 90, \"near\": 0.25, \"far\": 500, "
                "\"frames\": {\"3\": {\"camera_to_world\": [1,0,0,0, 0,1,0,0, 0,0,1,0, 30,0,0,1]}}}\n");
    fclose(cj);
    assert_run(0, "'%s/shot.0003.exr' --explain --camera-file '%s'", g_dir, clip);
    assert_null(strstr(tu_out, "flag --near"));
    assert_null(strstr(tu_out, "flag --far"));
    assert_non_null(strstr(tu_out, "0.25  from camera file"));
    assert_non_null(strstr(tu_out, "500  from camera file"));
    assert_run(0, "'%s/shot.0003.exr' --explain --camera-file '%s' --far 900", g_dir, clip);
    assert_non_null(strstr(tu_out, "0.25  from camera file"));
    assert_non_null(strstr(tu_out, "900  from flag --far"));
    free(clip);
    /* a frame the file lacks is named */
    char *s4 = in_dir("shot.0004.exr");
    write_frame(s4, 0);
    assert_run(1, "'%s/shot.#.exr' -o '%s/j.#.exr' --camera-file '%s' --fog exp:density=0.05",
               g_dir, g_dir, json);
    assert_non_null(strstr(tu_err, "frame 4"));
    /* one pose source only */
    assert_run(2, "'%s/shot.#.exr' -o '%s/j.#.exr' --camera-file '%s' --camera-to-world "
                  "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fog exp:density=0.05", g_dir, g_dir, json);
    /* a singular matrix in the file is the file's error (exit 1), named by
     * its key and frame, not the flag's */
    FILE *bad = fopen(json, "w");
    assert_non_null(bad);
    fprintf(bad, "{\"fov\": 90, \"frames\": {\"1\": {\"camera_to_world\": "
                 "[1,0,0,0, 0,0,0,0, 0,0,1,0, 0,0,0,1]}}}\n");
    fclose(bad);
    assert_run(1, "'%s/shot.#.exr' -o '%s/j.#.exr' --frames 1 --camera-file '%s' "
                  "--fog exp:density=0.05", g_dir, g_dir, json);
    assert_non_null(strstr(tu_err, "camera_to_world of camera file"));
    assert_non_null(strstr(tu_err, "frame 1"));
    assert_non_null(strstr(tu_err, "is singular"));
    assert_null(strstr(tu_err, "--camera-to-world is"));
    free(s4);
    free(one);
    free(json);
    free(chan);
}

/* The channel `name` of part `part` is bit-identical in a and b. */
static void check_same_channel(const char *a, const char *b, int part, const char *name)
{
    tu_image ia, ib;
    assert_int_equal(tu_read_image(a, part, &ia), 0);
    assert_int_equal(tu_read_image(b, part, &ib), 0);
    assert_int_equal(tu_compare_channel(&ia, &ib, name, 0.0, 0), 0);
    tu_image_free(&ia);
    tu_image_free(&ib);
}

/* Whether channel `name` of part `part` differs between a and b. */
static int channel_differs(const char *a, const char *b, int part, const char *name)
{
    int wa, ha, wb, hb;
    float *x = tu_read_channel(a, part, name, &wa, &ha), *y = tu_read_channel(b, part, name, &wb, &hb);
    assert_non_null(x);
    assert_non_null(y);
    const int d = memcmp(x, y, sizeof(float) * (size_t) wa * (size_t) ha) != 0;
    free(x);
    free(y);
    return d;
}

/* Multi-part views: each part has its view and its own camera; both are
 * fogged by default, each from its own camera; --view picks one and the
 * other is copied bit for bit with a warning. */
static void test_views_multipart(void **state)
{
    (void) state;
    fresh("mpviews");
    planes_init();
    tu_part p[2];
    for (int k = 0; k < 2; ++k) {
        tu_part_init(&p[k], W, H);
        p[k].name = k ? "rgba.right" : "rgba.left";
        p[k].str_name = "view";
        p[k].str_value = k ? "right" : "left";
        add_rgbaz(&p[k], "", k ? g_c2 : g_c);
        set_camera(&p[k], k ? 1.0 : -1.0);
    }
    char *in = in_dir("stereo.exr"), *out = in_dir("out.exr");
    assert_int_equal(tu_write_exr(in, p, 2), 0);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov P", in, out);
    check_positions_in(out, 0, "", -1.0);
    check_positions_in(out, 1, "", 1.0);
    assert_true(channel_differs(in, out, 1, "R"));
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov P --view right", in, out);
    check_positions_in(out, 1, "", 1.0);
    assert_non_null(strstr(tu_err, "view 'left' is not fogged"));
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --view right", in, out);
    assert_int_equal(tu_compare_files(in, out, 1, NULL), 0);
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --view middle", in, out);
    assert_non_null(strstr(tu_err, "its views: left, right"));
    /* flags give one camera: with two views the user must say whose */
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --fov 40 --camera-to-world "
                  "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1", in, out);
    assert_non_null(strstr(tu_err, "--view"));
    /* the right eye loses its camera: never skipped silently */
    p[1].m44[0].name = NULL;
    p[1].f[0].name = NULL;
    assert_int_equal(tu_write_exr(in, p, 2), 0);
    unlink(out);
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.05", in, out);
    assert_non_null(strstr(tu_err, "right has no camera of its own"));
    assert_non_null(strstr(tu_err, "--view left"));
    assert_false(tu_exists(out));
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov P --view left", in, out);
    check_positions_in(out, 0, "", -1.0);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --view left", in, out);
    assert_int_equal(tu_compare_files(in, out, 0, NULL), 0);
    /* and with flags for the chosen eye */
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov P --view right --fov 90 "
                  "--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,-3,0,0,1", in, out);
    check_positions_in(out, 1, "", 3.0);
    /* Parts named as their views ("left"/"right") or as oiiotool names
     * them ("subimage00/01"), with a view attribute: both eyes, each with
     * its camera (the part name is not a layer of its channels). */
    /* ... and parts named anything, one per view ("beauty_L"/"beauty_R",
     * issue 47: 'no colour channels found') */
    static const char *const names[3][2] = { { "left", "right" }, { "subimage00", "subimage01" },
                                             { "beauty_L", "beauty_R" } };
    for (int n = 0; n < 3; ++n) {
        for (int k = 0; k < 2; ++k) {
            p[k].name = names[n][k];
            set_camera(&p[k], k ? 1.0 : -1.0);
        }
        assert_int_equal(tu_write_exr(in, p, 2), 0);
        assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov P", in, out);
        check_positions_in(out, 0, "", -1.0);
        check_positions_in(out, 1, "", 1.0);
        assert_true(channel_differs(in, out, 0, "R"));
        assert_true(channel_differs(in, out, 1, "R"));
    }
    /* One part whose header names its one view (Weta's left-eye
     * elements): --view of that view is the file (issue 47: 'INPUT has no
     * views'), the same pixels as without it; another view is refused. */
    char *one = in_dir("left_only.exr"), *o2 = in_dir("left_only_plain.exr");
    p[0].name = NULL;
    assert_int_equal(tu_write_exr(one, p, 1), 0);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --view left", one, out);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05", one, o2);
    assert_true(channel_differs(one, out, 0, "R"));
    float *a = tu_read_channel(out, 0, "R", &(int){ 0 }, &(int){ 0 });
    float *b = tu_read_channel(o2, 0, "R", &(int){ 0 }, &(int){ 0 });
    assert_true(a && b && !memcmp(a, b, (size_t) W * H * sizeof *a));
    free(a);
    free(b);
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.05 --view right", one, out);
    assert_non_null(strstr(tu_err, "holds the view 'left' alone"));
    free(one);
    free(o2);
    free(in);
    free(out);
}

/* Single-part multi-view (multiView = right, left): the default view's
 * channels are unprefixed and the header camera is its; left.* is the
 * other eye, whose AOVs are named fog_P.left.X as OpenEXR names views. */
/* A file with more views than a run fogs (8) is refused with the limit
 * named: the ninth and later were copied unfogged with exit 0. Eight are
 * fogged. */
static void test_views_over_limit(void **state)
{
    (void) state;
    fresh("nineviews");
    planes_init();
    tu_part p[9];
    static char names[9][2][16];
    for (int k = 0; k < 9; ++k) {
        tu_part_init(&p[k], W, H);
        snprintf(names[k][0], 16, "rgba.v%d", k);
        snprintf(names[k][1], 16, "v%d", k);
        p[k].name = names[k][0];
        p[k].str_name = "view";
        p[k].str_value = names[k][1];
        add_rgbaz(&p[k], "", g_c);
        set_camera(&p[k], (double) k);
    }
    char *in = in_dir("nine.exr"), *out = in_dir("out.exr");
    assert_int_equal(tu_write_exr(in, p, 9), 0);
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.05", in, out);
    assert_non_null(strstr(tu_err, "more than 8 views (v0, v1, ...)"));
    assert_false(tu_exists(out));
    assert_int_equal(tu_write_exr(in, p, 8), 0);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05", in, out);
    for (int k = 0; k < 8; ++k) {
        tu_image a, b;
        assert_int_equal(tu_read_image(in, k, &a), 0);
        assert_int_equal(tu_read_image(out, k, &b), 0);
        assert_true(tu_compare_channel(&a, &b, "R", 0, 0) > 0);   /* fogged */
        tu_image_free(&a);
        tu_image_free(&b);
    }
    free(in);
    free(out);
}

static void test_views_singlepart(void **state)
{
    (void) state;
    fresh("spviews");
    planes_init();
    tu_part p;
    tu_part_init(&p, W, H);
    add_rgbaz(&p, "", g_c);
    add_rgbaz(&p, "left.", g_c2);
    p.multiview[0] = "right";
    p.multiview[1] = "left";
    set_camera(&p, 1.0);
    char *in = in_dir("stereo.exr"), *out = in_dir("out.exr");
    assert_int_equal(tu_write_exr(in, &p, 1), 0);
    /* the left eye has no camera of its own */
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.05", in, out);
    assert_non_null(strstr(tu_err, "left has no camera of its own"));
    assert_non_null(strstr(tu_err, "--view right"));
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov P --view right", in, out);
    check_positions_in(out, 0, "", 1.0);
    check_same_channel(in, out, 0, "left.R");
    check_same_channel(in, out, 0, "left.Z");
    assert_true(channel_differs(in, out, 0, "R"));
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.05 --aov P --view left --fov 90 "
                  "--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,1,0,0,1", in, out);
    check_positions_in(out, 0, "left", -1.0);
    check_same_channel(in, out, 0, "R");
    assert_true(channel_differs(in, out, 0, "left.R"));
    assert_run(0, "'%s' --explain --fog exp:density=0.05 --view left --fov 90 "
                  "--world-to-camera 1,0,0,0,0,1,0,0,0,0,1,0,1,0,0,1", in);
    assert_non_null(strstr(tu_out, "colour: left.R, left.G, left.B, alpha left.A"));
    assert_non_null(strstr(tu_out, "depth: left.Z"));
    free(in);
    free(out);
}

/* The public Beachball multipart stereo frame: its left view (parts
 * rgba_left and depth_left) is selectable; with a camera given by flags
 * its fog follows depth_left's Z exactly, and the right eye's parts are
 * copied bit for bit. */
static void test_beachball_left(void **state)
{
    (void) state;
    const char *real = tu_real_exr_dir();
    if (!real)
        skip();
    fresh("beachball");
    char in[1024];
    snprintf(in, sizeof in, "%s/beachball-multipart.0001.exr", real);
    if (!tu_exists(in))
        skip();
    char *out = in_dir("left.exr");
    assert_run(0, "'%s' -o '%s' --view left --fov 40 --camera-to-world "
                  "1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1 --fog exp:density=0.1 --fog-color 0.25,0.5,0.75",
               in, out);
    assert_non_null(strstr(tu_err, "view 'right' is not fogged"));
    int rgba_left = -1, depth_left = -1;
    const int np = tu_nparts(in);
    for (int k = 0; k < np; ++k) {
        tu_image img;
        assert_int_equal(tu_read_image(in, k, &img), 0);
        if (!strcmp(img.name, "rgba_left"))
            rgba_left = k;
        if (!strcmp(img.name, "depth_left"))
            depth_left = k;
        tu_image_free(&img);
    }
    assert_true(rgba_left >= 0 && depth_left >= 0);
    assert_int_equal(tu_compare_files(in, out, rgba_left, NULL), 0);
    tu_pinhole pin;
    tu_image img;
    assert_int_equal(tu_read_image(in, rgba_left, &img), 0);
    tu_pinhole_fov(&pin, img.disp, 40.0);
    tu_image_free(&img);
    tu_fog_check fc;
    tu_fog_check_init(&fc, in, out, &pin, 0.1);
    fc.in_part = fc.out_part = rgba_left;
    fc.depth = in;
    fc.depth_part = depth_left;
    assert_int_equal(tu_check_fog(&fc), 0);
    assert_true(fc.fogged > 1000);
    free(out);
}

/* One frame of colour v, depth 5 (pixel 0 sky), camera at the origin,
 * with an optional string attribute (a colour space). */
static void write_colour_frame(const char *path, float v, const char *attr, const char *value)
{
    planes_init();
    static float c[W * H];
    for (int i = 0; i < W * H; ++i)
        c[i] = v;
    tu_part p;
    tu_part_init(&p, W, H);
    add_rgbaz(&p, "", c);
    set_camera(&p, 0.0);
    p.str_name = attr;
    p.str_value = value;
    assert_int_equal(tu_write_exr(path, &p, 1), 0);
}

/* Colours in any form land in the image's working space (issue 9):
 * #RRGGBB is sRGB-decoded ((128/255 + 0.055)/1.055)^2.4 = 0.2158605; a
 * colour named in the working space is taken as is; Rec.709 red in an
 * ACEScg image is the first column of the published Bradford Rec.709 ->
 * AP1 matrix (0.6130974, 0.0701937, 0.0206156); the header's colorSpace,
 * oiio:ColorSpace or arnold/color_space names the working space, and
 * --colorspace overrides it. Every output pixel is checked against the
 * exp fog with that colour. */
static void test_colour_spaces(void **state)
{
    (void) state;
    fresh("colour");
    tu_pinhole pin;
    const int disp[4] = { 0, 0, W - 1, H - 1 };
    tu_pinhole_fov(&pin, disp, HFOV);
    static const struct {
        const char *attr, *value, *flag, *arg, *extra;
        double F[3];
    } cases[] = {
        { NULL, NULL, "--fog-color", "#808080", "", { 0.2158605, 0.2158605, 0.2158605 } },
        { NULL, NULL, "--fog", "exp:density=0.2:color=#ff8000", "", { 1.0, 0.2158605, 0.0 } },
        { "colorSpace", "ACEScg", "--fog-color", "lin_srgb:1,0,0", "",
          { 0.6130974, 0.0701937, 0.0206156 } },
        { "oiio:ColorSpace", "acescg", "--fog", "exp:density=0.2:color=Linear Rec.709 (sRGB):1,0,0",
          "", { 0.6130974, 0.0701937, 0.0206156 } },
        { "arnold/color_space", "ACES - ACEScg", "--fog-color", "ACEScg:0.5,0.25,0.125", "",
          { 0.5, 0.25, 0.125 } },
        { "colorSpace", "ACEScg", "--fog-color", "0.3,0.2,0.1", "", { 0.3, 0.2, 0.1 } },
        { "colorSpace", "lin_srgb", "--fog-color", "lin_srgb:1,0,0", "--colorspace ACEScg",
          { 0.6130974, 0.0701937, 0.0206156 } },
    };
    char *in = in_dir("in.exr"), *out = in_dir("out.exr");
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
        write_colour_frame(in, 0.5f, cases[k].attr, cases[k].value);
        const int spec = !strcmp(cases[k].flag, "--fog");
        assert_run(0, "'%s' -o '%s' %s%s '%s' %s", in, out, spec ? "" : "--fog exp:density=0.2 ",
                   cases[k].flag, cases[k].arg, cases[k].extra);
        tu_fog_check fc;
        tu_fog_check_init(&fc, in, out, &pin, 0.2);
        memcpy(fc.F, cases[k].F, sizeof fc.F);
        fc.extra_rel = 2e-6;   /* the published matrix's 7 digits */
        if (tu_check_fog(&fc))
            fail_msg("case %zu (%s %s %s)", k, cases[k].flag, cases[k].arg, cases[k].extra);
    }
    /* --explain says which space and where it came from */
    write_colour_frame(in, 0.5f, "colorSpace", "ACEScg");
    assert_run(0, "'%s' --explain --fog exp:density=0.2", in);
    assert_non_null(strstr(tu_out, "working colour space: ACEScg  from header colorSpace 'ACEScg'"));
    write_colour_frame(in, 0.5f, NULL, NULL);
    assert_run(0, "'%s' --explain --fog exp:density=0.2", in);
    assert_non_null(strstr(tu_out, "working colour space: Linear Rec.709 (sRGB)  from the config's "
                                   "scene_linear role"));
    /* errors: an unknown space (usage), a header space the config lacks,
     * a colour outside the working gamut, a broken $OCIO */
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.2 --fog-color Bogus:1,0,0", in, out);
    assert_non_null(strstr(tu_err, "unknown colour space 'Bogus'"));
    assert_run(2, "'%s' -o '%s' --fog exp:density=0.2 --colorspace Bogus --preview '%s/p.png'", in,
               out, g_dir);
    write_colour_frame(in, 0.5f, "colorSpace", "Weird Space");
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.2 --fog-color '#ffffff'", in, out);
    assert_non_null(strstr(tu_err, "colorSpace 'Weird Space'"));
    write_colour_frame(in, 0.5f, NULL, NULL);
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.2 --fog-color ACEScg:1,0,0", in, out);
    assert_non_null(strstr(tu_err, "outside its gamut"));
    setenv("OCIO", "/nonexistent/config.ocio", 1);
    assert_run(1, "'%s' -o '%s' --fog exp:density=0.2 --fog-color '#ffffff'", in, out);
    assert_non_null(strstr(tu_err, "$OCIO"));
    /* plain colours need no config at all */
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.2 --fog-color 0.5,0.5,0.5", in, out);
    unsetenv("OCIO");
    free(in);
    free(out);
}

/* The mean of the preview's 8-bit pixels as oiiotool --stats reports
 * them (0..255), or -1. */
static double preview_mean(const char *png)
{
    char cmd[2048], line[512];
    snprintf(cmd, sizeof cmd, "oiiotool --stats '%s' 2>/dev/null", png);
    FILE *p = popen(cmd, "r");
    double m = -1;
    while (p && fgets(line, sizeof line, p))
        if (strstr(line, "Stats Avg:"))
            sscanf(strstr(line, "Stats Avg:") + 10, "%lf", &m);
    if (p)
        pclose(p);
    return m;
}

/* The preview goes through an OCIO display and view: mid grey 0.18 is
 * sRGB-encoded 0.46135 -> 118/255 by default (sRGB - Display,
 * Un-tone-mapped), 46/255 through the Raw view; an unknown view is a
 * usage error that lists the config's displays and views. */
static void test_preview_view(void **state)
{
    (void) state;
    if (system("command -v oiiotool >/dev/null 2>&1"))
        skip();
    fresh("pview");
    char *in = in_dir("in.exr"), *out = in_dir("out.exr"), *png = in_dir("p.png");
    write_colour_frame(in, 0.18f, NULL, NULL);
    /* a fog too thin to change a value in 8 bits, and a sky pixel kept */
    assert_run(0, "'%s' -o '%s' --fog exp:density=1e-9 --sky keep --preview '%s'", in, out, png);
    double m = preview_mean(png);
    if (fabs(m - 118.0) > 1e-9)
        fail_msg("default view: mean %g, expected 118", m);
    assert_run(0, "'%s' -o '%s' --fog exp:density=1e-9 --sky keep --preview '%s' --preview-view "
                  "'sRGB - Display, Raw'", in, out, png);
    m = preview_mean(png);
    if (fabs(m - 46.0) > 1e-9)
        fail_msg("Raw view: mean %g, expected 46", m);
    assert_run(2, "'%s' -o '%s' --fog exp:density=1e-9 --preview '%s' --preview-view "
                  "'sRGB - Display, Filmic'", in, out, png);
    assert_non_null(strstr(tu_err, "Un-tone-mapped"));
    free(in);
    free(out);
    free(png);
}

/* 4x4 inverse in long double (Gauss-Jordan, partial pivoting). */
static void inv4l(const long double *a, long double *out)
{
    long double m[4][8];
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 8; ++j)
            m[i][j] = j < 4 ? a[4 * i + j] : (long double) (j - 4 == i);
    for (int c = 0; c < 4; ++c) {
        int piv = c;
        for (int r = c + 1; r < 4; ++r)
            if (fabsl(m[r][c]) > fabsl(m[piv][c]))
                piv = r;
        for (int j = 0; j < 8; ++j) {
            const long double t = m[c][j];
            m[c][j] = m[piv][j];
            m[piv][j] = t;
        }
        const long double d = m[c][c];
        for (int j = 0; j < 8; ++j)
            m[c][j] /= d;
        for (int r = 0; r < 4; ++r)
            if (r != c) {
                const long double f = m[r][c];
                for (int j = 0; j < 8; ++j)
                    m[r][j] -= f * m[c][j];
            }
    }
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            out[4 * i + j] = m[i][j + 4];
}

/* Full precision from float32 headers (issue 9): a float64 camera far
 * from the origin (3000, 1.7, -2000), yawed 30 degrees and pitched 2
 * degrees down over the ground y = 0, is written as m44f worldToCamera and
 * worldToNDC (Arnold's screen-space layout) with float32 planar depth.
 * The best reconstruction those float32 numbers allow is computed here in
 * long double (exact inverse of the float32 pose, the float32
 * projection's linear part for the ray, the float32 depth); exrfog's
 * fog_P at grazing ground pixels (under 3 degrees of incidence) must be
 * within 1.5x of its error against the float64 truth (plus fog_P's own
 * float32 rounding). */
static void test_float32_header_precision(void **state)
{
    (void) state;
    fresh("f32prec");
    enum { PW = 96, PH = 48 };
    const double pi = 3.14159265358979323846, yaw = 30 * pi / 180, pitch = 2 * pi / 180;
    const double pos[3] = { 3000.0, 1.7, -2000.0 };
    /* camera-to-world rows: X, Y, Z axes and position (row vectors) */
    const double cy = cos(yaw), sy = sin(yaw), cp = cos(pitch), sp = sin(pitch);
    const double c2w[16] = { cy, 0, -sy, 0, sy * sp, cp, cy * sp, 0, sy * cp, -sp, cy * cp, 0,
                             pos[0], pos[1], pos[2], 1 };
    long double c2wl[16], w2cl[16];
    for (int k = 0; k < 16; ++k)
        c2wl[k] = c2w[k];
    inv4l(c2wl, w2cl);
    const double px = 1.0 / tan(25.0 * pi / 180), py = px * PW / PH;
    const double n = 0.1, fa = 1e5, A = fa / (fa - n), B = -n * fa / (fa - n);
    const double proj[16] = { px, 0, 0, 0, 0, py, 0, 0, 0, 0, A, 1, 0, 0, B, 0 };
    tu_part p;
    tu_part_init(&p, PW, PH);
    p.m44[0].name = "worldToCamera";
    p.m44[1].name = "worldToNDC";
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            long double v = 0;
            for (int k = 0; k < 4; ++k)
                v += w2cl[4 * i + k] * proj[4 * k + j];
            p.m44[0].m[4 * i + j] = (float) w2cl[4 * i + j];
            p.m44[1].m[4 * i + j] = (float) v;
        }
    /* the truth: each pixel's float64 ray to the ground */
    static float c[PW * PH], a[PW * PH], z[PW * PH];
    static double truth[PW * PH][3];
    static unsigned char grazing[PW * PH];
    int ngrazing = 0;
    for (int y = 0; y < PH; ++y)
        for (int x = 0; x < PW; ++x) {
            const int i = y * PW + x;
            const double sxs = 2.0 * (x + 0.5) / PW - 1.0, sys = 1.0 - 2.0 * (y + 0.5) / PH;
            const double d[3] = { sxs / px, sys / py, 1.0 };
            double wd[3];
            for (int k = 0; k < 3; ++k)
                wd[k] = d[0] * c2w[k] + d[1] * c2w[4 + k] + d[2] * c2w[8 + k];
            c[i] = 0.5f;
            a[i] = 1.0f;
            z[i] = 0.0f;   /* sky above the horizon */
            if (wd[1] >= 0)
                continue;
            const double t = -pos[1] / wd[1];
            z[i] = (float) t;
            for (int k = 0; k < 3; ++k)
                truth[i][k] = pos[k] + t * wd[k];
            const double len = sqrt(wd[0] * wd[0] + wd[1] * wd[1] + wd[2] * wd[2]);
            grazing[i] = -wd[1] / len < sin(3 * pi / 180) && t < 1e4;
            ngrazing += grazing[i];
        }
    assert_true(ngrazing > 100);
    tu_part_add(&p, "R", EXR_PIXEL_FLOAT, c);
    tu_part_add(&p, "G", EXR_PIXEL_FLOAT, c);
    tu_part_add(&p, "B", EXR_PIXEL_FLOAT, c);
    tu_part_add(&p, "A", EXR_PIXEL_FLOAT, a);
    tu_part_add(&p, "Z", EXR_PIXEL_FLOAT, z);
    char *in = in_dir("grazing.exr"), *out = in_dir("out.exr");
    assert_int_equal(tu_write_exr(in, &p, 1), 0);
    assert_run(0, "'%s' -o '%s' --fog exp:density=0.001 --aov P --aov-origin 3000,0,-2000", in, out);
    tu_image img;
    assert_int_equal(tu_read_image(out, 0, &img), 0);
    const float *P[3] = { tu_image_f(&img, "fog_P.X"), tu_image_f(&img, "fog_P.Y"),
                          tu_image_f(&img, "fog_P.Z") };
    assert_non_null(P[0]);
    /* the best reconstruction from the float32 header */
    long double Mf[16], Nf[16], c2wf[16], L[16];
    for (int k = 0; k < 16; ++k) {
        Mf[k] = p.m44[0].m[k];
        Nf[k] = p.m44[1].m[k];
    }
    inv4l(Mf, c2wf);
    for (int i = 0; i < 4; ++i)   /* camera -> screen: c2w . worldToNDC */
        for (int j = 0; j < 4; ++j) {
            long double v = 0;
            for (int k = 0; k < 4; ++k)
                v += c2wf[4 * i + k] * Nf[4 * k + j];
            L[4 * i + j] = v;
        }
    const long double origin[3] = { 3000, 0, -2000 };
    double worst_ratio = 0, err_ef_max = 0, err_best_max = 0;
    long bad = 0;
    for (int i = 0; i < PW * PH; ++i) {
        if (!grazing[i])
            continue;
        const int x = i % PW, y = i / PW;
        const long double sxs = 2.0L * (x + 0.5L) / PW - 1.0L, sys = 1.0L - 2.0L * (y + 0.5L) / PH;
        /* direction (dx, dy, 1) whose screen position is (sxs, sys), from
         * the linear part: (d . L[:,0]) / (d . L[:,3]) = sxs, likewise y */
        const long double a11 = L[0] - sxs * L[3], a12 = L[4] - sxs * L[7], b1 = -(L[8] - sxs * L[11]);
        const long double a21 = L[1] - sys * L[3], a22 = L[5] - sys * L[7], b2 = -(L[9] - sys * L[11]);
        const long double det = a11 * a22 - a12 * a21;
        const long double dx = (b1 * a22 - a12 * b2) / det, dy = (a11 * b2 - b1 * a21) / det;
        const long double q[3] = { dx * z[i], dy * z[i], z[i] };
        double eb = 0, ee = 0, floor2 = 0;
        for (int k = 0; k < 3; ++k) {
            const long double best = q[0] * c2wf[k] + q[1] * c2wf[4 + k] + q[2] * c2wf[8 + k] + c2wf[12 + k];
            const long double tr = truth[i][k];
            const double db = (double) (best - tr);
            const double de = (double) ((long double) P[k][i] + origin[k] - tr);
            const double ulp = nextafterf(fabsf(P[k][i]), INFINITY) - fabsf(P[k][i]);
            eb += db * db;
            ee += de * de;
            floor2 += 0.25 * ulp * ulp;
        }
        eb = sqrt(eb);
        ee = sqrt(ee);
        if (ee > err_ef_max)
            err_ef_max = ee;
        if (eb > err_best_max)
            err_best_max = eb;
        if (ee > 1.5 * eb + sqrt(floor2))
            ++bad;
        const double r = ee / (eb + sqrt(floor2));
        if (r > worst_ratio)
            worst_ratio = r;
    }
    tu_image_free(&img);
    print_message("  %d grazing pixels: max error exrfog %.3g m, best %.3g m; worst ratio %.3f\n",
                  ngrazing, err_ef_max, err_best_max, worst_ratio);
    assert_int_equal(bad, 0);
    free(in);
    free(out);
}

/* Depth from any file OpenImageIO reads (issue 9): a 32-bit float TIFF
 * holding the depth of the whole frame fogs the colour (here cropped to a
 * data window inside it) exactly as the same depth in an EXR does, and
 * the temporary EXR made from it is gone afterwards. */
static void test_depth_tiff(void **state)
{
    (void) state;
    if (system("command -v oiiotool >/dev/null 2>&1"))
        skip();
    fresh("depthtif");
    planes_init();
    static float zf[W * H], cc[W * H];
    for (int i = 0; i < W * H; ++i) {
        zf[i] = 2.0f + 0.37f * (float) i;
        cc[i] = 0.5f;
    }
    /* the colour: the 4x3 crop at (2,1) of the 8x6 frame, with the camera */
    tu_part cp;
    tu_part_init(&cp, 4, 3);
    cp.dw[0] = 2; cp.dw[1] = 1; cp.dw[2] = 5; cp.dw[3] = 3;
    cp.disp[0] = 0; cp.disp[1] = 0; cp.disp[2] = W - 1; cp.disp[3] = H - 1;
    tu_part_add(&cp, "R", EXR_PIXEL_FLOAT, cc);
    tu_part_add(&cp, "G", EXR_PIXEL_FLOAT, cc);
    tu_part_add(&cp, "B", EXR_PIXEL_FLOAT, cc);
    set_camera(&cp, 0.0);
    tu_part dp;
    tu_part_init(&dp, W, H);
    tu_part_add(&dp, "Z", EXR_PIXEL_FLOAT, zf);
    char *col = in_dir("colour.exr"), *dex = in_dir("depth.exr"), *dtif = in_dir("depth.tif"),
         *o1 = in_dir("o1.exr"), *o2 = in_dir("o2.exr");
    assert_int_equal(tu_write_exr(col, &cp, 1), 0);
    assert_int_equal(tu_write_exr(dex, &dp, 1), 0);
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "oiiotool '%s' -d float -o '%s'", dex, dtif);
    assert_int_equal(system(cmd), 0);
    setenv("TMPDIR", g_dir, 1);
    assert_run(0, "'%s' --depth '%s' -o '%s' --fog exp:density=0.05", col, dtif, o1);
    assert_run(0, "'%s' --depth '%s' -o '%s' --fog exp:density=0.05", col, dex, o2);
    assert_int_equal(tu_compare_files(o2, o1, -1, NULL), 0);
    assert_true(channel_differs(col, o1, 0, "R"));
    snprintf(cmd, sizeof cmd, "ls -a '%s' | grep -q exrfog-depth", g_dir);
    assert_true(system(cmd) != 0);
    /* a depth file nothing can read */
    assert_int_equal(tu_write_bytes(dtif, "not an image", 12), 0);
    assert_run(1, "'%s' --depth '%s' -o '%s' --fog exp:density=0.05", col, dtif, o1);
    assert_non_null(strstr(tu_err, "depth.tif"));
    assert_true(system(cmd) != 0);
    unsetenv("TMPDIR");
    free(col);
    free(dex);
    free(dtif);
    free(o1);
    free(o2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_frame_patterns),
        cmocka_unit_test(test_frames_on_disk),
        cmocka_unit_test(test_sequence_cameras),
        cmocka_unit_test(test_sequence_time),
        cmocka_unit_test(test_sequence_failures),
        cmocka_unit_test(test_sequence_repeats_and_overwrites),
        cmocka_unit_test(test_progress_bar),
        cmocka_unit_test(test_parallel_recipe),
        cmocka_unit_test(test_camera_file),
        cmocka_unit_test(test_depth_tiff),
        cmocka_unit_test(test_float32_header_precision),
        cmocka_unit_test(test_colour_spaces),
        cmocka_unit_test(test_preview_view),
        cmocka_unit_test(test_views_multipart),
        cmocka_unit_test(test_views_singlepart),
        cmocka_unit_test(test_views_over_limit),
        cmocka_unit_test(test_sequence_messages),
        cmocka_unit_test(test_beachball_left),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
