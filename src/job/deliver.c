#include "deliver.h"

#include <ctype.h>
#include <stdio.h>
#include <string.h>

static const char *const dt_names[] = { "float", "uint8", "uint10", "uint12", "uint16", "half",
                                        "float" };

/* The sample type users expect of a format when -d says nothing: DPX
 * 10-bit (film and video deliveries), TIFF 16-bit, PNG and JPEG 8-bit;
 * 0 for the rest (the writer's choice from float, as oiiotool). */
static int default_dt(const char *ext)
{
    if (!strcmp(ext, ".dpx"))
        return EF_DT_UINT10;
    if (!strcmp(ext, ".tif") || !strcmp(ext, ".tiff"))
        return EF_DT_UINT16;
    if (!strcmp(ext, ".png") || !strcmp(ext, ".jpg") || !strcmp(ext, ".jpeg") ||
        !strcmp(ext, ".jpe") || !strcmp(ext, ".jfif"))
        return EF_DT_UINT8;
    return 0;
}

/* The plan from the writer's type and alpha and the options. */
static void set_plan(const ef_job *J, ef_deliver *dv, int type, int alpha)
{
    dv->alpha = alpha;
    dv->d.type = type;
    dv->integer = type >= EF_DT_UINT8 && type <= EF_DT_UINT16;
    dv->d.full_window = !J->o.crop_data;
    /* display-referred colour (integers, or any type through a display)
     * is encoded and stored with straight alpha */
    dv->d.unassociate = dv->integer || J->o.output_display != NULL;
}

int ef_deliver_plan(ef_job *J, const char *ext, ef_deliver *dv, ef_err *err)
{
    const ef_options *o = &J->o;
    memset(dv, 0, sizeof *dv);
    size_t n = strlen(ext);
    if (n >= sizeof dv->ext)
        return ef_fail(err, "'%.20s...' is not a file extension any writer knows (use .exr, .png, "
                            ".jpg, .tif or .dpx)", ext), 2;
    /* ext ".png": the lower-case extension, and "PNG" for messages */
    for (size_t i = 0; i <= n; ++i)
        dv->ext[i] = (char) tolower((unsigned char) ext[i]);
    for (size_t i = 1; i <= n; ++i)
        dv->fmt[i - 1] = (char) toupper((unsigned char) ext[i]);
    /* Every frame of a sequence has the same extension and options: the
     * writer is probed once per run. */
    if (J->dl_ok && !strcmp(J->dl_ext, dv->ext)) {
        set_plan(J, dv, J->dl_type, J->dl_alpha);
        return 0;
    }
    if (!strcmp(dv->ext, ".null"))
        return ef_fail(err, "'.null' is OpenImageIO's discard format: nothing would be written "
                            "(name a real file, or use --explain to check a run)"), 2;
    const int want = o->out_dt ? o->out_dt : default_dt(dv->ext);
    int got = 0, alpha = 0;
    char msg[600];
    if (ef_oiio_output_probe(dv->ext, want, 3, &got, &alpha, msg, sizeof msg))
        return ef_fail(err, "cannot write RGB %s files: %s (use .exr, .png, .jpg, .tif or .dpx)",
                       dv->fmt, msg), 2;
    if (want && got != want) {
        char list[128] = "";
        for (int dt = EF_DT_UINT8; dt <= EF_DT_FLOAT; ++dt) {
            int g, a;
            if (!ef_oiio_output_probe(dv->ext, dt, 3, &g, &a, msg, sizeof msg) && g == dt)
                snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", *list ? ", " : "",
                         dt_names[dt]);
        }
        return ef_fail(err, "%s files cannot hold %s samples (-d %s); they hold %s", dv->fmt,
                       dt_names[want], dt_names[want], *list ? list : "none exrfog writes"), 2;
    }
    /* DPX deliveries are RGB; elsewhere alpha goes where the format takes 4 channels. */
    if (alpha && strcmp(dv->ext, ".dpx")) {
        int g4, a4;
        alpha = ef_oiio_output_probe(dv->ext, want, 4, &g4, &a4, msg, sizeof msg) == 0;
    } else {
        alpha = 0;
    }
    set_plan(J, dv, got, alpha);
    snprintf(J->dl_ext, sizeof J->dl_ext, "%s", dv->ext);
    J->dl_type = got;
    J->dl_alpha = alpha;
    J->dl_ok = 1;
    return 0;
}

int ef_deliver_needs_colour(const ef_job *J, const ef_deliver *dv)
{
    return dv->integer || J->o.output_colorspace != NULL || J->o.output_display != NULL;
}

/* The encoder the writer calls: the OCIO processor on RGB triples. */
static int encode(void *user, float *rgb, long n)
{
    return ef_ocio_display_apply(user, rgb, n);
}

/* Whether name holds any of the words (case-insensitive). */
static int has_word(const char *name, const char *const *words)
{
    char low[256];
    size_t i = 0;
    for (; name[i] && i + 1 < sizeof low; ++i)
        low[i] = (char) tolower((unsigned char) name[i]);
    low[i] = '\0';
    for (; *words; ++words)
        if (strstr(low, *words))
            return 1;
    return 0;
}

/* The file's labels from its colour space's name: what OpenImageIO's
 * writers recognise (sRGB gives PNG its sRGB chunk) and DPX's transfer and
 * colorimetric codes, which have no sRGB (User defined, with Rec.709
 * primaries, is the truthful pair). */
static void label(ef_deliver *dv)
{
    static const char *const lin[] = { "linear", "lin_", "acescg", "aces2065", "scene_linear", NULL };
    static const char *const logs[] = { "log", "cct", "acescc", "cineon", NULL };
    static const char *const v709[] = { "709", "1886", NULL };
    static const char *const srgb[] = { "srgb", NULL };
    const int dpx = !strcmp(dv->ext, ".dpx");
    const char *cs = dv->space, *tr = "User defined", *cm = "User defined";
    if (has_word(dv->space, lin)) {
        cs = has_word(dv->space, v709) || has_word(dv->space, srgb) ? "Linear" : dv->space;
        tr = "Linear";
        cm = has_word(dv->space, v709) || has_word(dv->space, srgb) ? "ITU-R 709-4" : cm;
    } else if (has_word(dv->space, logs)) {
        tr = "Logarithmic";
    } else if (has_word(dv->space, srgb)) {
        cs = "sRGB";
        cm = "ITU-R 709-4";
    } else if (has_word(dv->space, v709)) {
        cs = "Rec709";
        tr = cm = "ITU-R 709-4";
    }
    dv->d.colorspace = cs;
    dv->d.dpx_transfer = dpx ? tr : NULL;
    dv->d.dpx_colorimetric = dpx ? cm : NULL;
}

int ef_deliver_colour(ef_job *J, ef_deliver *dv, ef_err *err)
{
    const char *work = ef_colour_space(&J->colour);
    if (!ef_deliver_needs_colour(J, dv)) {
        /* Scene-referred floats, written as they are. */
        snprintf(dv->space, sizeof dv->space, "%s", *work ? work : "Linear");
        label(dv);
        return 0;
    }
    const ef_ocio *cfg = ef_colour_config(&J->colour, err);
    if (!cfg)
        return 1;
    char msg[1200];
    /* A display and view (oiiotool's --ociodisplay) at any -d, else a
     * colour space; the file is labelled by the display's name. */
    if (J->o.output_display)
        dv->proc = ef_ocio_display_open(cfg, *work ? work : NULL, J->o.output_display, dv->space,
                                        sizeof dv->space, msg, sizeof msg);
    else
        dv->proc = ef_ocio_space_open(cfg, *work ? work : NULL, J->o.output_colorspace,
                                      dv->space, sizeof dv->space, msg, sizeof msg);
    if (!dv->proc)
        return ef_fail(err, "%s%s", J->o.output_display ? "--output-display: " : "", msg),
               J->o.output_colorspace || J->o.output_display ? 2 : 1;
    dv->d.encode = encode;
    dv->d.encode_user = dv->proc;
    label(dv);
    return 0;
}

void ef_deliver_free(ef_deliver *dv)
{
    ef_ocio_display_close(dv->proc);
    dv->proc = NULL;
}
