/* Command-line options of exrfog: parsing and the usage text. */
#ifndef EF_OPTIONS_H
#define EF_OPTIONS_H

#include "parse_result.h"
#include "camera.h"
#include "depth.h"
#include "error.h"
#include "scene.h"

#include <stdio.h>

struct ef_colour;

#define EF_MAX_CHAN_TYPES 64

/* --deep: what a deep input becomes. */
enum { EF_DEEP_MODE_SAMPLES = 0, EF_DEEP_MODE_FOG, EF_DEEP_MODE_FLATTEN };
#define EF_DEEP_DEFAULT_TOL 1e-3
/* The finest --deep-tol: below it the bound asks for more than double
 * precision computes a fog sample's transmittance to (the closed forms'
 * 1e-13 relative, summed over a pixel's samples) and far more than a float
 * channel stores (6e-8). */
#define EF_DEEP_TOL_FLOOR 1e-9
/* Below this --deep-tol a run is warned of its cost. */
#define EF_DEEP_TOL_COSTLY 1e-5

typedef struct ef_options {
    const char *input, *output, *depth_file, *layer, *depth_channel, *preview, *scene_file;
    char *scene_text;         /* the scene file's contents as read (owned), or NULL */
    ef_depth_mode depth_mode;
    int depth_mode_set;       /* --depth-mode was given */
    int up_set;               /* --up-axis or the scene file's "up" was given */
    int up_auto;              /* --up-axis auto: z for a Z-up camera family, else y */
    ef_fog_scene scene;
    ef_cam_flags cam;
    int compression;          /* -1: keep the input's */
    int zip_level;            /* -1: OpenEXRCore's default */
    int codec;                /* --codec: EF_CODEC_LIBDEFLATE (0, default) or EF_CODEC_ZLIB */
    float dwa_level;          /* --compression dwaa:LEVEL, or -1 */
    int pixel_type;           /* -1: keep; else EXR_PIXEL_HALF/FLOAT */
    int out_dt;               /* -d TYPE for a non-EXR output: EF_DT_*, 0: the format's */
    const char *output_colorspace;   /* --output-colorspace NAME, or NULL */
    const char *output_display;      /* --output-display "DISPLAY, VIEW", or NULL */
    int crop_data;            /* --crop data: a non-EXR output is the data window */
    /* -d CHANNEL=TYPE, as oiiotool: per-channel types over pixel_type */
    const char *chan_type_name[EF_MAX_CHAN_TYPES];
    int chan_type[EF_MAX_CHAN_TYPES], nchan_type;
    int threads;              /* 0: all cores */
    const char *frames;       /* --frames LIST, or NULL: every frame on disk */
    double fps;               /* --fps, for the default time of a frame */
    int keep_going;           /* --keep-going */
    const char *failed_list;  /* --failed-list FILE: failed frames, one per line */
    int time_set;             /* --time or the scene file's "time" was given */
    const char *views[16];    /* --view NAME, repeatable */
    const char *camera_file;  /* --camera-file FILE (may hold a frame pattern) */
    const char *colorconfig;  /* --colorconfig FILE, or NULL */
    const char *colorspace;   /* --colorspace NAME, or NULL */
    const char *preview_view; /* --preview-view "DISPLAY, VIEW", or NULL */
    const char *fog_color;    /* --fog-color as written (read again per working space) */
    int nviews;
    int explain, json, stats, verbose, quiet;
    unsigned aov;             /* EF_AOV_* bits: --aov and the scene file's "aov" */
    int has_aov_origin;       /* --aov-origin given */
    double aov_origin[3];     /* subtracted from fog_P */
    int deep_mode, deep_set;  /* --deep (EF_DEEP_MODE_*) and whether it was given */
    double deep_tol;          /* --deep-tol */
    int deep_grey;            /* --deep-grey-alpha */
    int edges;                /* --edges: 1 unmix, 0 off */
    char params[2048];        /* the options as given, for exrfog/parameters */
} ef_options;

/* Parses argv. EF_PARSE_EXIT after --help/--version (already printed to
 * out); EF_PARSE_USAGE with err set, quoting the offending text;
 * EF_PARSE_FAIL when a file named by an option (--scene, a fog profile) is
 * unreadable or wrong, with err->file naming it. Release o with
 * ef_options_free whatever the result. */
/* The options that cannot change the output file (threads, messages,
 * the preview and its view, the output's name, a sequence's frame list,
 * --keep-going, --failed-list): the one list that both exrfog/parameters
 * and exrfog/history leave them out by. c is getopt's value. */
int ef_option_neutral(int c);

/* How many entries of argv, from i, an output-neutral option takes there
 * (it and its value: 1 or 2, long names by unique prefix as getopt_long
 * reads them), or 0 when argv[i] is anything else. */
int ef_option_neutral_span(char **argv, int argc, int i);

ef_parse_result ef_options_parse(int argc, char **argv, ef_options *o, struct ef_colour *colour,
                                 FILE *out, ef_err *err);

/* Releases what parsing allocated (the fog components' data). */
void ef_options_free(ef_options *o);

/* Prints the usage text. */
void ef_options_usage(FILE *out);

#endif
