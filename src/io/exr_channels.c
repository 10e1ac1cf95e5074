/* Finding the colour and depth channels among the names real tools write. */
#include "exr_io.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct qchan {
    int part, index;
    char name[256];           /* qualified: layer.channel */
    char view[64];            /* the part's view, "" when none */
} qchan;

typedef struct qlist {
    qchan *c;
    int n;
    int one_image;            /* one part and no multiView: a plain image */
} qlist;

static int multiview_names(const ef_exr_file *f, int p, char names[][64], int max);

static int ends_with(const char *s, const char *suffix)
{
    size_t a = strlen(s), b = strlen(suffix);
    return a >= b && !strcmp(s + a - b, suffix);
}

/* The layer a multi-part part stands for: its name without the ".view" or
 * "_view" suffix Nuke and the Beachball frames add; none for a part named
 * as its view or oiiotool's subimageNN. */
static void part_layer(const ef_exr_file *f, int p, char *layer, size_t len, char *view, size_t vlen)
{
    const char *name = NULL, *v = NULL;
    int32_t vl = 0;
    layer[0] = view[0] = '\0';
    if (exr_attr_get_string(f->ctx, p, "view", &vl, &v) == EXR_ERR_SUCCESS && v)
        snprintf(view, vlen, "%.*s", (int) vl, v);
    if (f->nparts < 2 || exr_get_name(f->ctx, p, &name) != EXR_ERR_SUCCESS || !name)
        return;
    snprintf(layer, len, "%s", name);
    /* A part named for its view ("left" with view "left"), or by
     * oiiotool's default ("subimage00"), is that view's whole image: its
     * channels are not a layer of that name. */
    size_t digits = strncmp(name, "subimage", 8) ? 0 : strspn(name + 8, "0123456789");
    if ((view[0] && !strcmp(name, view)) || (digits > 0 && name[8 + digits] == '\0')) {
        layer[0] = '\0';
        return;
    }
    /* The one part of its view, whatever its name ("beauty_L" with view
     * "left"): that view's whole image too. */
    if (view[0]) {
        int same = 0;
        for (int q = 0; q < f->nparts; ++q) {
            const char *w = NULL;
            int32_t wl = 0;
            same += exr_attr_get_string(f->ctx, q, "view", &wl, &w) == EXR_ERR_SUCCESS && w &&
                    (size_t) wl == strlen(view) && !strncmp(w, view, (size_t) wl);
        }
        if (same == 1) {
            layer[0] = '\0';
            return;
        }
    }
    if (view[0]) {
        char sfx[80];
        for (int k = 0; k < 2; ++k) {
            snprintf(sfx, sizeof sfx, "%c%s", k ? '_' : '.', view);
            if (ends_with(layer, sfx) && strlen(layer) > strlen(sfx)) {
                layer[strlen(layer) - strlen(sfx)] = '\0';
                break;
            }
        }
    }
}

static int build_list(const ef_exr_file *f, qlist *q)
{
    int total = 0;
    for (int p = 0; p < f->nparts; ++p) {
        const exr_attr_chlist_t *cl;
        if (exr_get_channels(f->ctx, p, &cl))
            return -1;
        total += cl->num_channels;
    }
    q->c = calloc((size_t) total + 1, sizeof *q->c);
    q->n = 0;
    char views[2][64];
    q->one_image = f->nparts == 1 && multiview_names(f, 0, views, 2) == 0;
    if (!q->c)
        return -1;
    for (int p = 0; p < f->nparts; ++p) {
        const exr_attr_chlist_t *cl;
        char layer[200], view[64];
        exr_get_channels(f->ctx, p, &cl);
        part_layer(f, p, layer, sizeof layer, view, sizeof view);
        for (int c = 0; c < cl->num_channels; ++c) {
            qchan *e = &q->c[q->n++];
            const char *cn = cl->entries[c].name.str;
            e->part = p;
            e->index = c;
            snprintf(e->view, sizeof e->view, "%s", view);
            if (layer[0] && !strchr(cn, '.'))
                snprintf(e->name, sizeof e->name, "%s.%s", layer, cn);
            else
                snprintf(e->name, sizeof e->name, "%s", cn);
        }
    }
    return 0;
}

/* The channel called name, preferring one in a part of the given view. */
static const qchan *find(const qlist *q, const char *name, const char *view)
{
    const qchan *first = NULL;
    for (int i = 0; i < q->n; ++i) {
        if (strcmp(q->c[i].name, name))
            continue;
        if (!view || !strcmp(q->c[i].view, view))
            return &q->c[i];
        if (!first)
            first = &q->c[i];
    }
    return first;
}

static void set_ref(ef_chan_ref *r, const qchan *c)
{
    if (!c) {
        r->part = -1;
        r->index = -1;
        r->name[0] = '\0';
        return;
    }
    r->part = c->part;
    r->index = c->index;
    snprintf(r->name, sizeof r->name, "%s", c->name);
}

static void join(const char *prefix, const char *ch, char *out, size_t len)
{
    if (prefix[0])
        snprintf(out, len, "%s.%s", prefix, ch);
    else
        snprintf(out, len, "%s", ch);
}

/* R, G and B of one layer, all in one part. */
static int try_colour(const qlist *q, const char *prefix, ef_channel_plan *plan)
{
    static const char *const rgb[3] = { "R", "G", "B" };
    const qchan *c[3];
    char name[300];
    for (int k = 0; k < 3; ++k) {
        join(prefix, rgb[k], name, sizeof name);
        c[k] = find(q, name, NULL);
        if (!c[k] || c[k]->part != c[0]->part)
            return 0;
    }
    for (int k = 0; k < 3; ++k)
        set_ref(&plan->rgb[k], c[k]);
    join(prefix, "A", name, sizeof name);
    const qchan *a = find(q, name, c[0]->view);
    set_ref(&plan->alpha, a && a->part == c[0]->part ? a : NULL);
    return 1;
}

/* Names a user might pass to --layer, for the error message. */
static void list_layers(const qlist *q, char *out, size_t len)
{
    out[0] = '\0';
    for (int i = 0; i < q->n; ++i) {
        const char *n = q->c[i].name;
        if (!ends_with(n, ".R"))
            continue;
        if (strlen(out) + strlen(n) + 4 >= len)
            break;
        size_t at = strlen(out);
        snprintf(out + at, len - at, "%s%.*s", at ? ", " : "", (int) (strlen(n) - 2), n);
    }
    if (!out[0])
        snprintf(out, len, "none");
}

static void list_all(const qlist *q, char *out, size_t len)
{
    out[0] = '\0';
    for (int i = 0; i < q->n; ++i) {
        if (strlen(out) + strlen(q->c[i].name) + 8 >= len) {
            strncat(out, ", ...", len - strlen(out) - 1);
            break;
        }
        strncat(out, i ? ", " : "", len - strlen(out) - 1);
        strncat(out, q->c[i].name, len - strlen(out) - 1);
    }
}

static int find_colour(const qlist *q, const char *layer, ef_channel_plan *plan, char *prefix,
                       size_t plen, ef_err *err)
{
    if (layer) {
        snprintf(prefix, plen, "%s", layer);
        if (try_colour(q, layer, plan))
            return 0;
        char layers[600];
        list_layers(q, layers, sizeof layers);
        return ef_fail(err, "no colour channels %s.R, %s.G, %s.B in one part (layers with R: %s)",
                       layer, layer, layer, layers);
    }
    static const char *const plain[] = { "", "rgba", "rgb", "RGBA" };
    for (size_t i = 0; i < sizeof plain / sizeof plain[0]; ++i)
        if (try_colour(q, plain[i], plan)) {
            snprintf(prefix, plen, "%s", plain[i]);
            return 0;
        }
    for (int i = 0; i < q->n; ++i)
        if (ends_with(q->c[i].name, ".Combined.R")) {
            snprintf(prefix, plen, "%.*s", (int) (strlen(q->c[i].name) - 2), q->c[i].name);
            if (try_colour(q, prefix, plan))
                return 0;
        }
    char layers[600];
    list_layers(q, layers, sizeof layers);
    if (strcmp(layers, "none")) /* a layer has R: --layer can help */
        return ef_fail(err, "no colour channels found (no R,G,B, rgba.*, or Blender *.Combined.*; "
                            "layers with R: %s); choose one with --layer NAME", layers);
    char all[600];
    list_all(q, all, sizeof all);
    int lum = 0, plain_y = 0, has_a = 0, has_z = 0;
    for (int i = 0; i < q->n; ++i) {
        const char *n = q->c[i].name, *dot = strrchr(n, '.');
        lum |= !strcmp(dot ? dot + 1 : n, "Y");
        plain_y |= !strcmp(n, "Y");
        has_a |= !strcmp(n, "A");
        has_z |= !strcmp(n, "Z");
    }
    /* The conversion hint only where it works as written: one part, one
     * view, a plain Y (with the A and Z the file has); else none. */
    const int simple = plain_y && q->one_image;
    if (lum && simple)
        return ef_fail(err, "the image is luminance-only (no R,G,B colour; its channels: %s): "
                            "exrfog fogs colour; convert it first, e.g. oiiotool IN --ch "
                            "R=Y,G=Y,B=Y%s%s -o RGB.exr", all, has_a ? ",A" : "",
                       has_z ? ",Z" : "");
    if (lum)
        return ef_fail(err, "the image is luminance-only (no R,G,B colour; its channels: %s): "
                            "exrfog fogs colour; convert each view or part to R,G,B first",
                       all);
    return ef_fail(err, "the image has no R,G,B colour channels (its channels: %s), so there is "
                        "nothing to fog; give exrfog the beauty pass", all);
}

static const qchan *find_depth(const qlist *q, const char *prefix, const char *view)
{
    char name[320];
    const qchan *c;
    /* Same layer as the colour first: Arnold/RenderMan Z beside R,G,B. */
    if (!prefix[0] || !strcmp(prefix, "rgba") || !strcmp(prefix, "rgb") || !strcmp(prefix, "RGBA")) {
        if ((c = find(q, "Z", view)))
            return c;
        /* a multi-part file's "rgba" part with its own Z (rgba.Z) */
        join(prefix, "Z", name, sizeof name);
        if (prefix[0] && (c = find(q, name, view)))
            return c;
    } else {
        join(prefix, "Z", name, sizeof name);
        if ((c = find(q, name, view)))
            return c;
    }
    if ((c = find(q, "depth.Z", view)))
        return c;
    /* Blender: ViewLayer.Combined -> ViewLayer.Depth.Z. */
    if (ends_with(prefix, ".Combined")) {
        snprintf(name, sizeof name, "%.*s.Depth.Z", (int) (strlen(prefix) - 9), prefix);
        if ((c = find(q, name, view)))
            return c;
    }
    if ((c = find(q, "Depth.Z", view)))
        return c;
    return NULL;
}

/* The colour and depth search over prepared channel lists. */
static int find_in_lists(const qlist *q, const qlist *dq, int separate, const char *layer,
                         const char *depth_channel, ef_channel_plan *plan, ef_err *err)
{
    char prefix[256], all[800];
    memset(plan, 0, sizeof *plan);
    if (find_colour(q, layer, plan, prefix, sizeof prefix, err))
        return -1;
    const char *view = q->n ? q->c[0].view : "";
    for (int i = 0; i < q->n; ++i)
        if (q->c[i].part == plan->rgb[0].part)
            view = q->c[i].view;
    const qchan *d;
    if (depth_channel) {
        d = find(dq, depth_channel, view);
        if (!d) {
            list_all(dq, all, sizeof all);
            return ef_fail(err, "no channel named '%s' for --depth-channel (channels: %s)",
                           depth_channel, all);
        }
    } else if (!(d = find_depth(dq, prefix, view)) && separate) {
        d = find(dq, "Z", NULL);   /* a separate depth file may hold only Z */
    }
    if (!d) {
        list_all(dq, all, sizeof all);
        return ef_fail(err, "no depth channel found (looked for Z, depth.Z, *.Depth.Z beside the "
                            "colour; channels: %s); choose one with --depth-channel NAME or "
                            "--depth FILE", all);
    }
    set_ref(&plan->depth, d);
    return 0;
}

int ef_find_channels(const ef_exr_file *f, const ef_exr_file *df, const char *layer,
                     const char *depth_channel, ef_channel_plan *plan, ef_err *err)
{
    qlist q = { 0 }, dq = { 0 };
    int rc = -1;
    memset(plan, 0, sizeof *plan);
    if (build_list(f, &q) || build_list(df, &dq))
        ef_fail(err, "out of memory listing channels");
    else
        rc = find_in_lists(&q, &dq, df != f, layer, depth_channel, plan, err);
    free(q.c);
    free(dq.c);
    return rc;
}

/* The multiView attribute of part p: count of names copied (0: none). */
static int multiview_names(const ef_exr_file *f, int p, char names[][64], int max)
{
    const exr_attribute_t *a = NULL;
    if (exr_get_attribute_by_name(f->ctx, p, "multiView", &a) != EXR_ERR_SUCCESS || !a ||
        a->type != EXR_ATTR_STRING_VECTOR || !a->stringvector)
        return 0;
    int n = 0;
    for (int i = 0; i < a->stringvector->n_strings; ++i) {
        const exr_attr_string_t *sv = &a->stringvector->strings[i];
        if (sv->length <= 0 || sv->length >= 64)
            continue;
        if (n == max)
            return max + 1;   /* more than the caller can take */
        snprintf(names[n], 64, "%.*s", (int) sv->length, sv->str);
        ++n;
    }
    return n;
}

int ef_exr_views(const ef_exr_file *f, char names[][64], int max)
{
    if (f->nparts == 1)
        return multiview_names(f, 0, names, max);
    int n = 0;
    for (int p = 0; p < f->nparts; ++p) {
        const char *v = NULL;
        int32_t vl = 0;
        if (exr_attr_get_string(f->ctx, p, "view", &vl, &v) != EXR_ERR_SUCCESS || !v || vl <= 0 ||
            vl >= 64)
            continue;
        int seen = 0;
        for (int k = 0; k < n; ++k)
            seen |= (int) strlen(names[k]) == vl && !strncmp(names[k], v, (size_t) vl);
        if (seen)
            continue;
        if (n == max)
            return max + 1;   /* more than the caller can take */
        snprintf(names[n++], 64, "%.*s", (int) vl, v);
    }
    return n;
}

/* The view component of a single-part multi-view channel name: the
 * second-to-last segment when it is one of the views ("left.R",
 * "diffuse.left.R"); NULL for the default view's names. */
static const char *name_view(const char *name, char views[][64], int nviews, size_t *at,
                             size_t *len)
{
    const char *last = strrchr(name, '.');
    if (!last)
        return NULL;
    const char *b = last;
    while (b > name && b[-1] != '.')
        --b;
    for (int k = 0; k < nviews; ++k)
        if ((size_t) (last - b) == strlen(views[k]) && !strncmp(b, views[k], (size_t) (last - b))) {
            *at = (size_t) (b - name);
            *len = (size_t) (last - b) + 1;
            return views[k];
        }
    return NULL;
}

/* Keeps the channels of one view: in a multiView part, those of the view
 * renamed without it (left.R -> R), or the unnamed ones for the default
 * view; in a multi-part file, the parts of that view, and view-less parts
 * when keep_plain. */
static void filter_view(const ef_exr_file *f, qlist *q, const char *view, int keep_plain)
{
    char views[EF_MAX_VIEWS][64];
    const int mv = f->nparts == 1 ? multiview_names(f, 0, views, EF_MAX_VIEWS) : 0;
    int n = 0;
    for (int i = 0; i < q->n; ++i) {
        qchan c = q->c[i];
        int keep;
        if (mv) {
            size_t at = 0, len = 0;
            const char *v = name_view(c.name, views, mv, &at, &len);
            if (v && !strcmp(v, views[0]) && strcmp(view, views[0]))
                v = NULL;   /* the default view's name written out: not another view's */
            keep = v ? !strcmp(v, view) : !strcmp(view, views[0]);
            if (keep && v)
                memmove(c.name + at, c.name + at + len, strlen(c.name + at + len) + 1);
        } else {
            keep = !strcmp(c.view, view) || (keep_plain && !c.view[0]);
        }
        if (keep)
            q->c[n++] = c;
    }
    q->n = n;
}

int ef_find_view_channels(const ef_exr_file *f, const ef_exr_file *df, const char *view,
                          const char *layer, const char *depth_channel, ef_channel_plan *plan,
                          ef_err *err)
{
    qlist q = { 0 }, dq = { 0 };
    int rc = -1;
    memset(plan, 0, sizeof *plan);
    if (build_list(f, &q) || build_list(df, &dq)) {
        ef_fail(err, "out of memory listing channels");
        goto done;
    }
    char views[EF_MAX_VIEWS][64];
    filter_view(f, &q, view, 0);
    if (df == f || ef_exr_views(df, views, EF_MAX_VIEWS) > 0)
        filter_view(df, &dq, view, 1);
    if (find_in_lists(&q, &dq, df != f, layer, depth_channel, plan, err)) {
        char msg[sizeof err->msg];
        snprintf(msg, sizeof msg, "%s", err->msg);
        ef_fail(err, "view '%s': %s", view, msg);
        goto done;
    }
    snprintf(plan->view, sizeof plan->view, "%s", view);
    if (f->nparts == 1 && multiview_names(f, 0, views, EF_MAX_VIEWS) > 0) {
        plan->default_view = !strcmp(views[0], view);
        if (!plan->default_view)
            snprintf(plan->chan_view, sizeof plan->chan_view, "%s", view);
    }
    /* The names as the file has them, for messages and --explain. */
    ef_chan_ref *refs[5] = { &plan->rgb[0], &plan->rgb[1], &plan->rgb[2], &plan->alpha, &plan->depth };
    for (int k = 0; k < 5; ++k) {
        const ef_exr_file *src = k == 4 ? df : f;
        const exr_attr_chlist_t *cl;
        if (refs[k]->part >= 0 && f->nparts == 1 && src == f &&
            exr_get_channels(src->ctx, refs[k]->part, &cl) == EXR_ERR_SUCCESS)
            snprintf(refs[k]->name, sizeof refs[k]->name, "%s", cl->entries[refs[k]->index].name.str);
    }
    rc = 0;
done:
    free(q.c);
    free(dq.c);
    return rc;
}
