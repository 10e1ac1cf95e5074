#include <stdio.h>

#include "args.h"

#include <float.h>
#include <math.h>
#include <openexr.h>
#include <stdlib.h>
#include <string.h>

#include "aov.h"
#include "argscan.h"
#include "foreign.h"
#include "exr_deflate.h"
#include "exr_io.h"
#include "colour.h"
#include "ocio_shim.h"
#include "scene_build.h"
#include "scene_file.h"
#include "version.h"

enum {
    OPT_DEPTH = 256, OPT_LAYER, OPT_DEPTH_CHANNEL, OPT_DEPTH_MODE, OPT_SKY, OPT_FOG, OPT_LIGHT, OPT_SKY_LIGHT,
    OPT_FOG_COLOR, OPT_W2C, OPT_C2W, OPT_FOV, OPT_NEAR, OPT_FAR, OPT_COMPRESSION,
    OPT_THREADS, OPT_PREVIEW, OPT_EXPLAIN, OPT_STATS, OPT_VERSION, OPT_SCENE, OPT_UP_AXIS,
    OPT_UNITS, OPT_TIME, OPT_AOV, OPT_AOV_ORIGIN, OPT_FOCAL, OPT_APERTURE, OPT_CONVENTION,
    OPT_FRAMES, OPT_FPS, OPT_KEEP_GOING, OPT_FAILED_LIST, OPT_VIEW, OPT_CAMERA_FILE,
    OPT_COLORCONFIG, OPT_COLORSPACE, OPT_PREVIEW_VIEW, OPT_JSON, OPT_CODEC, OPT_DEEP,
    OPT_DEEP_TOL, OPT_OUTPUT_COLORSPACE, OPT_CROP, OPT_DEEP_GREY, OPT_OUTPUT_DISPLAY, OPT_EDGES
};

static const struct option long_opts[] = {
    { "output", required_argument, NULL, 'o' },
    { "depth", required_argument, NULL, OPT_DEPTH },
    { "layer", required_argument, NULL, OPT_LAYER },
    { "depth-channel", required_argument, NULL, OPT_DEPTH_CHANNEL },
    { "depth-mode", required_argument, NULL, OPT_DEPTH_MODE },
    { "sky", required_argument, NULL, OPT_SKY },
    { "deep", required_argument, NULL, OPT_DEEP },
    { "deep-tol", required_argument, NULL, OPT_DEEP_TOL },
    { "deep-grey-alpha", no_argument, NULL, OPT_DEEP_GREY },
    { "edges", required_argument, NULL, OPT_EDGES },
    { "fog", required_argument, NULL, OPT_FOG },
    { "light", required_argument, NULL, OPT_LIGHT },
    { "sky-light", required_argument, NULL, OPT_SKY_LIGHT },
    { "fog-color", required_argument, NULL, OPT_FOG_COLOR },
    { "scene", required_argument, NULL, OPT_SCENE },
    { "up-axis", required_argument, NULL, OPT_UP_AXIS },
    { "units-per-meter", required_argument, NULL, OPT_UNITS },
    { "time", required_argument, NULL, OPT_TIME },
    { "frames", required_argument, NULL, OPT_FRAMES },
    { "fps", required_argument, NULL, OPT_FPS },
    { "keep-going", no_argument, NULL, OPT_KEEP_GOING },
    { "failed-list", required_argument, NULL, OPT_FAILED_LIST },
    { "view", required_argument, NULL, OPT_VIEW },
    { "camera-file", required_argument, NULL, OPT_CAMERA_FILE },
    { "colorconfig", required_argument, NULL, OPT_COLORCONFIG },
    { "colorspace", required_argument, NULL, OPT_COLORSPACE },
    { "preview-view", required_argument, NULL, OPT_PREVIEW_VIEW },
    { "output-colorspace", required_argument, NULL, OPT_OUTPUT_COLORSPACE },
    { "output-display", required_argument, NULL, OPT_OUTPUT_DISPLAY },
    { "crop", required_argument, NULL, OPT_CROP },
    { "aov", required_argument, NULL, OPT_AOV },
    { "aov-origin", required_argument, NULL, OPT_AOV_ORIGIN },
    { "world-to-camera", required_argument, NULL, OPT_W2C },
    { "camera-to-world", required_argument, NULL, OPT_C2W },
    { "fov", required_argument, NULL, OPT_FOV },
    { "focal-length", required_argument, NULL, OPT_FOCAL },
    { "aperture", required_argument, NULL, OPT_APERTURE },
    { "camera-convention", required_argument, NULL, OPT_CONVENTION },
    { "near", required_argument, NULL, OPT_NEAR },
    { "far", required_argument, NULL, OPT_FAR },
    { "compression", required_argument, NULL, OPT_COMPRESSION },
    { "codec", required_argument, NULL, OPT_CODEC },
    { "data-type", required_argument, NULL, 'd' },
    { "threads", required_argument, NULL, OPT_THREADS },
    { "preview", required_argument, NULL, OPT_PREVIEW },
    { "explain", no_argument, NULL, OPT_EXPLAIN },
    { "json", no_argument, NULL, OPT_JSON },
    { "stats", no_argument, NULL, OPT_STATS },
    { "verbose", no_argument, NULL, 'v' },
    { "quiet", no_argument, NULL, 'q' },
    { "help", no_argument, NULL, 'h' },
    { "version", no_argument, NULL, OPT_VERSION },
    { NULL, 0, NULL, 0 },
};

void ef_options_usage(FILE *out)
{
    fprintf(out,
            "usage: exrfog [OPTIONS] INPUT -o OUTPUT\n"
            "       exrfog [OPTIONS] shot.#.exr -o fog.#.exr [--frames 1-100]\n"
            "Puts physically correct fog into a rendered EXR, using its depth and camera.\n"
            "\n"
            "  -o, --output FILE        output image (may equal INPUT; written atomically):\n"
            "                           .exr, or .tif, .png, .jpg, .dpx... through OpenImageIO\n"
            "      --fog SPEC           fog component, repeatable: MODEL[:KEY=VALUE]...\n"
            "                           linear:start=S:end=E  exp:density=D  exp2:density=D\n"
            "                           halfspace, halfspace-linear, halfspace-smooth,\n"
            "                           height, layered, box, convex,\n"
            "                           noise, noise-separable (see exrfog(1))\n"
            "                           density may be R,G,B or visibility=V (metres);\n"
            "                           color=R,G,B: the component's own colour;\n"
            "                           distance=radial|planar (linear, exp, exp2)\n"
            "      --fog-color COLOR    fog colour (default %g,%g,%g): R,G,B in the working\n"
            "                           space, #RRGGBB (sRGB) or SPACE:R,G,B (any OCIO space);\n"
            "                           color= in a SPEC takes the same forms\n"
            "      --colorconfig FILE   OpenColorIO config (default $OCIO, else exrfog's own)\n"
            "      --colorspace NAME    the image's working space (default: from the header,\n"
            "                           else the config's scene_linear)\n"
            "      --sky fog|keep|distance=D  background pixels (default fog)\n"
            "      --light SPEC         light the fog (single scattering), repeatable:\n"
            "                           sun:towards=X,Y,Z:intensity=E, point:position=X,Y,Z:\n"
            "                           intensity=I[:radius=R], spot:position=..:aim=..:cone=DEG;\n"
            "                           color=R,G,B, name=NAME; sun and spot: shadow=MAP.exr\n"
            "                           (a depth render from the light), bias=, slope=,\n"
            "                           outside=lit|shadow; sun: angle=DEG (its disc) with a\n"
            "                           map: soft shadows, penumbra=N directions (16; 0 hard)\n"
            "                           ; albedo=, phase=iso|rayleigh|\n"
            "                           hg|cs and g= in a fog SPEC (see exrfog(1) LIGHTS)\n"
            "      --sky-light ENV.exr[:rotate=DEG][:intensity=K][:scattering=multiple[:ground=H]]\n"
            "                           light the fog with a lat-long environment (its\n"
            "                           phase-convolved light; multiple: carried through the\n"
            "                           fog, every order)\n"
            "      --deep MODE          deep input: samples (default: the input's samples\n"
            "                           and the fog as volume samples), fog (a fog-only\n"
            "                           deep element) or flatten (a flat image)\n"
            "      --deep-tol E         deep fog: |dT| bound when a fog sample is split\n"
            "                           later (default 1e-3; lit: colour over the pixel's\n"
            "                           light, estimated)\n"
            "      --deep-grey-alpha    deep output of chromatic fog for readers of A only:\n"
            "                           every alpha the least, the rest folded into colour\n"
            "      --edges unmix|off    flat input: fog each anti-aliased edge pixel as the\n"
            "                           mix of the near and far surfaces its neighbours\n"
            "                           show, each at its own depth (default off)\n"
            "      --scene FILE         JSON scene: fog, lights, color, sky, up, units, time,\n"
            "                           aov; the flags given here override it\n"
            "      --up-axis y|z|-y|-z|auto|X,Y,Z  up for the height models (default y;\n"
            "                           Blender and V-Ray scenes are z-up)\n"
            "      --units-per-meter U  scene units per metre (default 1, 100 for cm);\n"
            "                           densities are per metre\n"
            "      --time T             time in seconds for velocity= keys (default: the\n"
            "                           frame / --fps in a sequence, else 0)\n"
            "                           Frame patterns: # is four digits (#### sixteen, as\n"
            "                           in oiiotool; Nuke/Houdini/Blender's #### is # here),\n"
            "                           @ one digit, %%04d four\n"
            "      --frames LIST        frames of a sequence: 1-100, 1-100x2, 1,5,10-20\n"
            "                           (default: every frame on disk matching INPUT)\n"
            "      --fps N              frames per second for the default time (default 24)\n"
            "      --keep-going         a failed frame does not stop the sequence\n"
            "      --failed-list FILE   write the frames that failed (or were missing), one\n"
            "                           per line, to FILE (empty when none failed)\n"
            "      --view NAME          fog this view of a stereo/multi-view file, repeatable\n"
            "                           (default: every view with a camera)\n"
            "      --aov LIST           extra output channels, repeatable: a comma list of\n"
            "                           fog (fog.R,G,B,A), T (fog_T.R,G,B), error\n"
            "                           (fog_error.R,G,B), P (fog_P.X,Y,Z), distance\n"
            "                           (fog_distance.Z), light (fog_ambient.R,G,B and\n"
            "                           fog_light.NAME.R,G,B per --light), lit (fog_lit.NAME\n"
            "                           per light with a shadow map: its share past them)\n"
            "      --aov-origin X,Y,Z   subtracted from fog_P (default 0,0,0)\n"
            "      --depth FILE         take depth from a second EXR\n"
            "      --layer NAME         colour layer (e.g. ViewLayer.Combined)\n"
            "      --depth-channel NAME depth channel (e.g. depth.Z)\n"
            "      --depth-mode MODE    planar (default), radial, inverse, normalized, gl-ndc,\n"
            "                           gl-window, zero-one, reversed, reversed-infinite\n"
            "      --world-to-camera M  16 numbers, row-vector layout as in the file\n"
            "      --camera-to-world M  its inverse\n"
            "      --fov DEG            horizontal field of view\n"
            "      --camera-file FILE   per-frame cameras: JSON or Nuke .chan (see exrfog(1))\n"
            "      --camera-convention C  exr (default), blender, nuke, maya, houdini, usd:\n"
            "                           the layout of --world-to-camera/--camera-to-world\n"
            "      --focal-length MM --aperture MM  the same from a lens and the film's\n"
            "                           horizontal aperture (both needed)\n"
            "      --near N, --far F    clip planes for the buffer depth modes\n"
            "      --compression C      none|rle|zips|zip|piz|pxr24|b44|b44a|dwaa|dwab (default:\n"
            "                           the input's); zip:LEVEL, zips:LEVEL with zlib level\n"
            "                           1-9; dwaa:LEVEL, dwab:LEVEL (default 45)\n"
            "      --codec C            libdeflate (default) or zlib: the DEFLATE of zip/zips\n"
            "  -d, --data-type T        half|float output for half/float channels (depth,\n"
            "                           P and ids stay float), or CHANNEL=half|float; for\n"
            "                           .png/.tif/.dpx/.jpg...: uint8|uint10|uint12|uint16|\n"
            "                           half|float (default: DPX uint10 RGB, TIFF uint16,\n"
            "                           PNG and JPEG uint8)\n"
            "      --output-colorspace NAME  an integer (display-referred) non-EXR output's\n"
            "                           colour space (default: the config's sRGB texture)\n"
            "      --output-display \"DISPLAY, VIEW\"  a non-EXR output through an OCIO\n"
            "                           display and view instead (what oiiotool's\n"
            "                           ociodisplay does), at any -d\n"
            "      --crop display|data  a non-EXR output covers the display window (default)\n"
            "                           or only the data window\n"
            "      --threads N          worker threads, 0 = all cores (default)\n"
            "      --preview FILE       also write a preview (PNG, JPEG, ...) through an OCIO view\n"
            "      --preview-view \"DISPLAY, VIEW\"  its display and view (default: the config's)\n"
            "      --explain            print the resolved camera and conventions, write nothing\n"
            "      --json               with --explain: the same facts as one JSON object\n"
            "      --stats              print per-stage timings and peak memory, and the cost\n"
            "                           and error of each noise component\n"
            "  -v, --verbose  -q, --quiet  -h, --help  --version\n"
            "\n"
            "Exit status: 0 success, 1 runtime error, 2 usage error. See exrfog(1).\n",
            EF_DEFAULT_FOG_COLOR_R, EF_DEFAULT_FOG_COLOR_G, EF_DEFAULT_FOG_COLOR_B);
}

/* 16 numbers separated by commas and/or spaces. */
static int parse_matrix(const char *text, ef_opt_mat *m)
{
    char buf[1024];
    size_t n = 0;
    int sep = 1;
    for (const char *s = text; *s && n + 1 < sizeof buf; ++s) {
        if (*s == ',' || *s == ' ' || *s == '\t') {
            if (!sep)
                buf[n++] = ',';
            sep = 1;
        } else {
            buf[n++] = *s;
            sep = 0;
        }
    }
    if (n && buf[n - 1] == ',')
        --n;
    buf[n] = '\0';
    if (ef_parse_numbers_ex(buf, m->v.m, 16, 1))
        return -1;
    m->set = 1;
    return 0;
}

static int parse_num(const char *text, ef_opt_num *n)
{
    if (ef_parse_numbers(text, &n->v, 1))
        return -1;
    n->set = 1;
    return 0;
}

static void record(ef_options *o, const char *a)
{
    size_t len = strlen(o->params);
    snprintf(o->params + len, sizeof o->params - len, "%s%s", len ? " " : "", a);
}

int ef_option_neutral(int c)
{
    return c == OPT_THREADS || c == OPT_STATS || c == OPT_KEEP_GOING || c == OPT_FRAMES ||
           c == OPT_FAILED_LIST || c == OPT_PREVIEW || c == OPT_PREVIEW_VIEW || c == 'v' ||
           c == 'q' || c == 'o';
}

/* The long option a names (--name or --name=VALUE; a unique prefix, as
 * getopt_long takes it, an exact name first), or NULL. */
static const struct option *long_option_of(const char *a)
{
    if (a[0] != '-' || a[1] != '-' || !a[2])
        return NULL;
    const char *name = a + 2, *eq = strchr(name, '=');
    const size_t n = eq ? (size_t) (eq - name) : strlen(name);
    const struct option *found = NULL;
    int matches = 0;
    for (const struct option *lo = long_opts; lo->name; ++lo)
        if (!strncmp(lo->name, name, n)) {
            if (strlen(lo->name) == n)
                return lo;
            found = lo;
            ++matches;
        }
    return matches == 1 ? found : NULL;
}

int ef_option_neutral_span(char **argv, int argc, int i)
{
    const char *a = argv[i];
    if (a[0] == '-' && a[1] == '-') {
        const struct option *lo = long_option_of(a);
        if (!lo || !ef_option_neutral(lo->val))
            return 0;
        const int takes = lo->has_arg == required_argument && !strchr(a, '=');
        return takes && i + 1 < argc ? 2 : 1;
    }
    if (a[0] != '-' || !a[1])
        return 0;
    /* a cluster of short options (:o:d:vqh): every one neutral; o takes
     * the rest of the cluster, or the next argument */
    for (const char *c = a + 1; *c; ++c) {
        if (!ef_option_neutral((unsigned char) *c))
            return 0;
        if (*c == 'o')
            return c[1] ? 1 : i + 1 < argc ? 2 : 1;
    }
    return 1;
}

/* Records an option in canonical form, unless it cannot change the output
 * file (ef_option_neutral): equal outputs get equal headers.
 * --deep and --deep-tol are the deep pass's to record (frame.c: the mode
 * and tolerance that ran, defaults too), so that they stand there once. */
static void record_option(ef_options *o, int c, const char *arg)
{
    if (ef_option_neutral(c) || c == OPT_DEEP || c == OPT_DEEP_TOL)
        return;
    for (const struct option *lo = long_opts; lo->name; ++lo)
        if (lo->val == c) {
            char buf[64];
            snprintf(buf, sizeof buf, "--%s", lo->name);
            record(o, buf);
            if (arg)
                record(o, arg);
            return;
        }
}

void ef_options_free(ef_options *o)
{
    ef_scene_free(&o->scene);
    free(o->scene_text);
    o->scene_text = NULL;
}

static ef_parse_result parse_options(int argc, char **argv, ef_options *o, ef_colour *colour,
                                     FILE *out, ef_err *err, int *cur_opt, const char **cur_arg);

/* The numeric options, for the "out of range" message (wide: matrices). */
static const struct {
    int opt, wide;
} numeric_opts[] = { { OPT_FOG_COLOR, 0 }, { OPT_UP_AXIS, 0 }, { OPT_UNITS, 0 }, { OPT_TIME, 0 }, { OPT_FPS, 0 },
                     { OPT_AOV_ORIGIN, 0 }, { OPT_FOV, 0 }, { OPT_FOCAL, 0 }, { OPT_APERTURE, 0 }, { OPT_NEAR, 0 }, { OPT_FAR, 0 },
                     { OPT_W2C, 1 }, { OPT_C2W, 1 } };

ef_parse_result ef_options_parse(int argc, char **argv, ef_options *o, ef_colour *colour, FILE *out,
                                 ef_err *err)
{
    int opt = 0;
    const char *arg = NULL;
    const ef_parse_result r = parse_options(argc, argv, o, colour, out, err, &opt, &arg);
    if (r != EF_PARSE_USAGE || !arg)
        return r;
    /* A number that underflows or overflows is out of range, not "not a number". */
    for (size_t i = 0; i < sizeof numeric_opts / sizeof numeric_opts[0]; ++i) {
        if (numeric_opts[i].opt != opt || !ef_out_of_range(arg, numeric_opts[i].wide))
            continue;
        const char *name = "?";
        for (const struct option *lo = long_opts; lo->name; ++lo)
            if (lo->val == opt)
                name = lo->name;
        if (numeric_opts[i].wide)
            ef_fail(err, "--%s '%s' is out of range (a number overflows, or underflows below "
                         "2.2e-308)", name, arg);
        else
            ef_fail(err, "--%s '%s' is out of range (numbers are 0 or between 2.2e-308 and "
                         "1.8e308 in magnitude%s)", name, arg,
                    opt == OPT_FOG_COLOR ? "; colours at most 65504" : "");
    }
    return r;
}

static ef_parse_result parse_options(int argc, char **argv, ef_options *o, ef_colour *colour,
                                     FILE *out, ef_err *err, int *cur_opt, const char **cur_arg)
{
    ef_scene_desc f;
    memset(&f, 0, sizeof f);
    memset(o, 0, sizeof *o);
    ef_scene_init(&o->scene);
    o->depth_mode = EF_DEPTH_PLANAR;
    o->compression = -1;
    o->zip_level = -1;
    o->dwa_level = -1;
    o->pixel_type = -1;
    o->fps = 24;
    o->deep_tol = EF_DEEP_DEFAULT_TOL;
    /* The scanner's state is this parse's own: runs parse at once, and the
     * host's getopt state is never touched. */
    ef_argscan scan;
    ef_argscan_init(&scan);
    int c;
    double focal = 0, aperture = 0;
    while ((c = ef_argscan_next(&scan, argc, argv, ":o:d:vqh", long_opts)) != -1) {
        const char *a = scan.optarg;
        *cur_opt = c;
        *cur_arg = a;
        record_option(o, c, a);
        switch (c) {
        case 'o': o->output = a; break;
        case OPT_DEPTH: o->depth_file = a; break;
        case OPT_LAYER: o->layer = a; break;
        case OPT_DEPTH_CHANNEL: o->depth_channel = a; break;
        case OPT_PREVIEW: o->preview = a; break;
        case OPT_DEPTH_MODE:
            o->depth_mode_set = 1;
            if (ef_depth_mode_parse(a, &o->depth_mode))
                return ef_fail(err, "--depth-mode '%s' is not one of planar, radial, inverse, "
                                    "normalized, gl-ndc, gl-window, zero-one, reversed, "
                                    "reversed-infinite", a), EF_PARSE_USAGE;
            break;
        case OPT_DEEP:
            if (!strcmp(a, "samples"))
                o->deep_mode = EF_DEEP_MODE_SAMPLES;
            else if (!strcmp(a, "fog"))
                o->deep_mode = EF_DEEP_MODE_FOG;
            else if (!strcmp(a, "flatten"))
                o->deep_mode = EF_DEEP_MODE_FLATTEN;
            else
                return ef_fail(err, "--deep '%s' is not samples, fog or flatten", a),
                       EF_PARSE_USAGE;
            o->deep_set = 1;
            break;
        case OPT_DEEP_GREY:
            o->deep_grey = 1;
            break;
        case OPT_EDGES:
            if (!strcmp(a, "unmix"))
                o->edges = 1;
            else if (!strcmp(a, "off"))
                o->edges = 0;
            else
                return ef_fail(err, "--edges '%s' is not unmix or off", a), EF_PARSE_USAGE;
            break;
        case OPT_DEEP_TOL:
            if (ef_parse_numbers(a, &o->deep_tol, 1) || !(o->deep_tol > 0) || !(o->deep_tol < 1))
                return ef_fail(err, "--deep-tol '%s' must be a number between 0 and 1 (e.g. "
                                    "1e-3)", a), EF_PARSE_USAGE;
            if (o->deep_tol < EF_DEEP_TOL_FLOOR)
                return ef_fail(err, "--deep-tol '%s' is below %g, finer than double precision "
                                    "computes a fog sample's transmittance (and than a float "
                                    "channel stores, 6e-8): give %g or more", a,
                               EF_DEEP_TOL_FLOOR, EF_DEEP_TOL_FLOOR), EF_PARSE_USAGE;
            break;
        case OPT_SKY:
            f.has_sky = 1;
            f.sky = a;
            break;
        case OPT_FOG:
            if (f.nspec >= EF_FOG_MAX_COMPONENTS)
                return ef_fail(err, "too many --fog components (at most %d)", EF_FOG_MAX_COMPONENTS),
                       EF_PARSE_USAGE;
            f.specs[f.nspec++] = a;
            break;
        case OPT_LIGHT:
            if (f.nlight >= EF_MAX_LIGHTS)
                return ef_fail(err, "too many --light (at most %d)", EF_MAX_LIGHTS),
                       EF_PARSE_USAGE;
            f.lights[f.nlight++] = a;
            break;
        case OPT_SKY_LIGHT:
            if (f.sky_light)
                return ef_fail(err, "--sky-light is given twice (one environment lights the "
                                    "fog)"), EF_PARSE_USAGE;
            f.sky_light = a;
            break;
        case OPT_FOG_COLOR:
            /* read once every option is known (--colorconfig) */
            f.color_text = o->fog_color = a;
            f.has_color = 1;
            break;
        case OPT_COLORCONFIG:
            if (!a[0])
                return ef_fail(err, "--colorconfig: the file name is empty"), EF_PARSE_USAGE;
            o->colorconfig = a;
            break;
        case OPT_COLORSPACE:
            if (!a[0])
                return ef_fail(err, "--colorspace: the name is empty (e.g. ACEScg)"), EF_PARSE_USAGE;
            o->colorspace = a;
            break;
        case OPT_PREVIEW_VIEW: o->preview_view = a; break;
        case OPT_OUTPUT_COLORSPACE: o->output_colorspace = a; break;
        case OPT_OUTPUT_DISPLAY: o->output_display = a; break;
        case OPT_CROP:
            if (strcmp(a, "display") && strcmp(a, "data"))
                return ef_fail(err, "--crop '%s' is not display or data", a), EF_PARSE_USAGE;
            o->crop_data = !strcmp(a, "data");
            break;
        case OPT_SCENE: o->scene_file = a; break;
        case OPT_UP_AXIS:
            if (!strcmp(a, "auto")) {
                /* y until the camera is known (run.c re-reads the SPECs) */
                o->up_auto = 1;
                f.up[0] = f.up[2] = 0;
                f.up[1] = 1;
                f.has_up = 1;
                break;
            }
            o->up_auto = 0;
            if (ef_parse_up(a, f.up))
                return ef_fail(err, "--up-axis '%s' is not y, z, -y, -z, auto or X,Y,Z (non-zero)", a),
                       EF_PARSE_USAGE;
            f.has_up = 1;
            break;
        case OPT_UNITS:
            if (ef_parse_numbers(a, &f.units, 1) || !(f.units > 0))
                return ef_fail(err, "--units-per-meter '%s' is not a positive number (100 for a "
                                    "scene in centimetres)", a), EF_PARSE_USAGE;
            f.has_units = 1;
            break;
        case OPT_TIME:
            if (ef_parse_numbers(a, &f.time, 1))
                return ef_fail(err, "--time '%s' is not a finite number (seconds)", a),
                       EF_PARSE_USAGE;
            f.has_time = 1;
            break;
        case OPT_FRAMES: o->frames = a; break;
        case OPT_FPS:
            if (ef_parse_numbers(a, &o->fps, 1) || !(o->fps > 0))
                return ef_fail(err, "--fps '%s' is not a positive number of frames per second", a),
                       EF_PARSE_USAGE;
            break;
        case OPT_KEEP_GOING: o->keep_going = 1; break;
        case OPT_FAILED_LIST: o->failed_list = a; break;
        case OPT_CAMERA_FILE:
            if (!a[0])
                return ef_fail(err, "--camera-file: the file name is empty"), EF_PARSE_USAGE;
            o->camera_file = a;
            break;
        case OPT_VIEW:
            if (!a[0])
                return ef_fail(err, "--view: the view name is empty (e.g. --view left)"), EF_PARSE_USAGE;
            if (o->nviews >= (int) (sizeof o->views / sizeof o->views[0]))
                return ef_fail(err, "too many --view (at most %d)",
                               (int) (sizeof o->views / sizeof o->views[0])), EF_PARSE_USAGE;
            o->views[o->nviews++] = a;
            break;
        case OPT_AOV:
            if (ef_aov_parse(a, &o->aov, "--aov", err))
                return EF_PARSE_USAGE;
            break;
        case OPT_AOV_ORIGIN:
            if (ef_parse_numbers(a, o->aov_origin, 3))
                return ef_fail(err, "--aov-origin '%s' is not X,Y,Z (three finite numbers)", a),
                       EF_PARSE_USAGE;
            /* beyond any scene exrfog takes (LIMITS): fog_P - origin would
             * overflow the float channels to infinity */
            if (fabs(o->aov_origin[0]) > 1e30 || fabs(o->aov_origin[1]) > 1e30 ||
                fabs(o->aov_origin[2]) > 1e30)
                return ef_fail(err, "--aov-origin '%s' is more than 1e30 from the world's origin "
                                    "(fog_P minus it would overflow float; give a point of the "
                                    "scene, e.g. the camera's position)", a), EF_PARSE_USAGE;
            o->has_aov_origin = 1;
            break;
        case OPT_CONVENTION:
            if (ef_cam_convention_parse(a, &o->cam.convention))
                return ef_fail(err, "--camera-convention '%s' is not one of exr, blender, nuke, "
                                    "maya, houdini, usd", a), EF_PARSE_USAGE;
            break;
        case OPT_W2C:
            if (parse_matrix(a, &o->cam.w2c))
                return ef_fail(err, "--world-to-camera '%s' is not 16 finite numbers", a), EF_PARSE_USAGE;
            break;
        case OPT_C2W:
            if (parse_matrix(a, &o->cam.c2w))
                return ef_fail(err, "--camera-to-world '%s' is not 16 finite numbers", a), EF_PARSE_USAGE;
            break;
        case OPT_FOCAL:
        case OPT_APERTURE: {
            double v;
            if (ef_parse_numbers(a, &v, 1) || !(v > 0))
                return ef_fail(err, "--%s '%s' is not a positive length in millimetres",
                               c == OPT_FOCAL ? "focal-length" : "aperture", a), EF_PARSE_USAGE;
            *(c == OPT_FOCAL ? &focal : &aperture) = v;
            break;
        }
        case OPT_FOV:
            if (parse_num(a, &o->cam.fov) || !(o->cam.fov.v > 0 && o->cam.fov.v < 180))
                return ef_fail(err, "--fov '%s' is not an angle between 0 and 180 degrees", a),
                       EF_PARSE_USAGE;
            break;
        case OPT_NEAR:
            if (parse_num(a, &o->cam.near_) || !(o->cam.near_.v > 0))
                return ef_fail(err, "--near '%s' is not a positive number", a), EF_PARSE_USAGE;
            break;
        case OPT_FAR:
            if (parse_num(a, &o->cam.far_) || !(o->cam.far_.v > 0))
                return ef_fail(err, "--far '%s' is not a positive number", a), EF_PARSE_USAGE;
            break;
        case OPT_COMPRESSION:
            if (ef_compression_parse(a, &o->compression, &o->zip_level, &o->dwa_level, err))
                return EF_PARSE_USAGE;
            break;
        case OPT_CODEC:
            if (strcmp(a, "libdeflate") && strcmp(a, "zlib"))
                return ef_fail(err, "--codec '%s' is not libdeflate or zlib", a), EF_PARSE_USAGE;
            o->codec = strcmp(a, "zlib") ? EF_CODEC_LIBDEFLATE : EF_CODEC_ZLIB;
            break;
        case 'd': {
            /* TYPE for every half/float channel, or CHANNEL=TYPE for one */
            const char *eq = strrchr(a, '='), *ty = eq ? eq + 1 : a;
            int t;
            static const char *const uints[] = { "uint8", "uint10", "uint12", "uint16" };
            int dt = 0;
            for (int k = 0; k < 4; ++k)
                if (!strcmp(ty, uints[k]))
                    dt = EF_DT_UINT8 + k;
            if (dt && !eq) {
                o->out_dt = dt;
                break;
            }
            if (dt)
                return ef_fail(err, "--data-type '%s': integer types apply to a whole non-EXR "
                                    "output (write -d %s)", a, ty), EF_PARSE_USAGE;
            if (!strcmp(ty, "half"))
                t = EXR_PIXEL_HALF;
            else if (!strcmp(ty, "float"))
                t = EXR_PIXEL_FLOAT;
            else
                return ef_fail(err, "--data-type '%s' is not uint8, uint10, uint12, uint16, half, "
                                    "float or CHANNEL=half|float", a), EF_PARSE_USAGE;
            if (!eq) {
                o->pixel_type = t;
                o->out_dt = t == EXR_PIXEL_HALF ? EF_DT_HALF : EF_DT_FLOAT;
            } else if (eq == a) {
                return ef_fail(err, "--data-type '%s' names no channel (write CHANNEL=%s)", a, ty),
                       EF_PARSE_USAGE;
            } else {
                if (o->nchan_type >= EF_MAX_CHAN_TYPES)
                    return ef_fail(err, "too many --data-type CHANNEL=TYPE (at most %d)",
                                   EF_MAX_CHAN_TYPES), EF_PARSE_USAGE;
                o->chan_type_name[o->nchan_type] = a;   /* "NAME=TYPE": compared up to '=' */
                o->chan_type[o->nchan_type++] = t;
            }
            break;
        }
        case OPT_THREADS: {
            char *end;
            long n = strtol(a, &end, 10);
            if (*a == '\0' || *end || n < 0 || n > 1024)
                return ef_fail(err, "--threads '%s' is not a count from 0 to 1024", a), EF_PARSE_USAGE;
            o->threads = (int) n;
            break;
        }
        case OPT_EXPLAIN: o->explain = 1; break;
        case OPT_JSON: o->json = 1; break;
        case OPT_STATS: o->stats = 1; break;
        case 'v': o->verbose++; break;
        case 'q': o->quiet = 1; break;
        case 'h': ef_options_usage(out); return EF_PARSE_EXIT;
        case OPT_VERSION:
        {
            int maj, min, pat;
            const char *extra;
            exr_get_library_version(&maj, &min, &pat, &extra);
            fprintf(out, "exrfog %s (OpenEXRCore %d.%d.%d, OpenColorIO %s, OpenImageIO loaded for --preview)\n",
                   EXRFOG_VERSION, maj, min, pat, ef_ocio_version());
        }
            return EF_PARSE_EXIT;
        case ':':
            return ef_fail(err, "option '%s' needs a value", argv[scan.optind - 1]), EF_PARSE_USAGE;
        default: {
            /* Inside a cluster (-in.exr: 'i' unknown, "n.exr" left) the
             * element is still argv[optind]; else the one just passed. */
            const int inside = scan.nextchar && *scan.nextchar;
            const char *elem = argv[inside ? scan.optind : scan.optind - 1];
            if (scan.optopt > 0 && scan.optopt < 128 && elem[0] == '-' && elem[1] != '-')
                return ef_fail(err, "unknown option '-%c' in '%s' (see exrfog --help; a file "
                                    "whose name starts with '-' is written ./%s, or after --)",
                               scan.optopt, elem, elem), EF_PARSE_USAGE;
            return ef_fail(err, "unknown option '%s' (see exrfog --help)", elem), EF_PARSE_USAGE;
        }
        }
    }
    *cur_arg = NULL;   /* later errors are not about one option's number */
    /* A name no file can hold would fill every later message, pushing out
     * its reason: refused here, its value abbreviated. */
    const struct {
        const char *opt, *v;
    } names[] = { { "layer", o->layer }, { "depth-channel", o->depth_channel },
                  { "colorspace", o->colorspace }, { "preview-view", o->preview_view },
                  { "output-colorspace", o->output_colorspace },
                  { "output-display", o->output_display },
                  { "view", o->nviews > 0 ? o->views[0] : NULL },
                  { "view", o->nviews > 1 ? o->views[1] : NULL } };
    for (size_t k = 0; k < sizeof names / sizeof names[0]; ++k)
        if (names[k].v && strlen(names[k].v) > 1024)
            return ef_fail(err, "--%s '%s' is longer than any name exrfog reads (1024 bytes at "
                                "most)", names[k].opt, names[k].v), EF_PARSE_USAGE;
    for (int k = 2; k < o->nviews; ++k)
        if (strlen(o->views[k]) > 1024)
            return ef_fail(err, "--view '%s' is longer than any name exrfog reads (1024 bytes at "
                                "most)", o->views[k]), EF_PARSE_USAGE;
    if (o->output_colorspace && o->output_display)
        return ef_fail(err, "--output-colorspace and --output-display both say how a non-EXR "
                            "output is encoded; give one"), EF_PARSE_USAGE;
    if (o->camera_file && (o->cam.w2c.set || o->cam.c2w.set))
        return ef_fail(err, "--camera-file and --%s both give the camera's pose; give one",
                       o->cam.w2c.set ? "world-to-camera" : "camera-to-world"), EF_PARSE_USAGE;
    if ((focal > 0) != (aperture > 0))
        return ef_fail(err, "--%s needs --%s too (the horizontal field of view is "
                            "2 atan(aperture / (2 focal length)))",
                       focal > 0 ? "focal-length" : "aperture", focal > 0 ? "aperture" : "focal-length"),
               EF_PARSE_USAGE;
    if (focal > 0) {
        if (o->cam.fov.set)
            return ef_fail(err, "--fov and --focal-length/--aperture both set the field of view; "
                                "give one"), EF_PARSE_USAGE;
        o->cam.fov.v = 2 * atan(aperture / (2 * focal)) * (180 / 3.14159265358979323846);
        o->cam.fov.set = 1;
        if (!(o->cam.fov.v > 0 && o->cam.fov.v < 180))
            return ef_fail(err, "--focal-length %g with --aperture %g gives a field of view of %g "
                                "degrees, not between 0 and 180", focal, aperture, o->cam.fov.v),
                   EF_PARSE_USAGE;
    }
    if (scan.optind < argc)
        o->input = argv[scan.optind++];
    if (scan.optind < argc)
        return ef_fail(err, "unexpected argument '%s' (one INPUT, and the output with -o)", argv[scan.optind]),
               EF_PARSE_USAGE;
    if (o->input)
        record(o, o->input);
    if (!o->input)
        return ef_fail(err, "no INPUT given (usage: exrfog [OPTIONS] INPUT -o OUTPUT)"), EF_PARSE_USAGE;
    if (o->json && !o->explain)
        return ef_fail(err, "--json goes with --explain (exrfog --explain --json INPUT)"),
               EF_PARSE_USAGE;
    if (!o->explain && !o->output)
        return ef_fail(err, "no output given (add -o OUTPUT)"), EF_PARSE_USAGE;
    if (o->output && !o->output[0])
        return ef_fail(err, "-o: the output name is empty (give a file name)"), EF_PARSE_USAGE;
    if (o->preview && !o->preview[0])
        return ef_fail(err, "--preview: the file name is empty (give a name such as preview.png)"),
               EF_PARSE_USAGE;
    ef_colour_setup(colour, o->colorconfig, o->colorspace);
    f.scene_file = o->scene_file;
    ef_scene_found found;
    const ef_parse_result br = ef_scene_build(&o->scene, &f, colour, &found, err);
    o->scene_text = found.scene_text;
    o->up_set |= found.up_set;
    o->time_set |= found.time_set;
    o->aov |= found.aov;
    if (br != EF_PARSE_RUN)
        return br;
    int shadowed = 0;
    for (int i = 0; i < o->scene.nlight; ++i)
        shadowed |= o->scene.light[i].shadow != NULL;
    if ((o->aov & EF_AOV_LIT) && !shadowed)
        return ef_fail(err, "--aov lit: no --light has a shadow= map (the lit AOV holds one "
                            "channel per shadowed light)"), EF_PARSE_USAGE;
    if ((o->aov & EF_AOV_LIGHT) && !ef_scene_lit(&o->scene))
        return ef_fail(err, "--aov light: there is no --light (the light AOVs hold one layer "
                            "per light)"), EF_PARSE_USAGE;
    if (!o->explain && o->scene.ncomp == 0)
        return ef_fail(err, "no fog given (add --fog SPEC or --scene FILE, e.g. --fog exp:density=0.02)"),
               EF_PARSE_USAGE;
    if (o->cam.near_.set && o->cam.far_.set && !(o->cam.far_.v > o->cam.near_.v))
        return ef_fail(err, "--far %g must be greater than --near %g", o->cam.far_.v, o->cam.near_.v),
               EF_PARSE_USAGE;
    return EF_PARSE_RUN;
}
