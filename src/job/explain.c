/* What a run tells about itself: --explain (text and JSON), the resolved
 * camera of -v, and --stats's lines on the noise components. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "ms.h"
#include "sky_light.h"
#include "aov.h"
#include "job_impl.h"
#include "version.h"

static void print_vec(FILE *out, const char *label, const double v[3], const char *src)
{
    fprintf(out, "  %-11s (%.9g, %.9g, %.9g)%s%s\n", label, v[0], v[1], v[2], src ? "  from " : "",
           src ? src : "");
}

/* The resolved camera, channels and conventions, as --explain and -v show them. */
static void explain_channels(FILE *out, const ef_options *o, const ef_channel_plan *plan,
                             const ef_depth_conv *conv, int conv_ok);
static void explain_scene(ef_job *J, FILE *out, const ef_channel_plan *plan);

/* The camera block of --explain. */
static void explain_camera(FILE *out, const ef_camera *cam, const char *whose)
{
    static const double fwd[3] = { 0, 0, 1 }, upc[3] = { 0, 1, 0 };
    double f[3], u[3];
    ef_camera_to_world_dir(cam, fwd, f);
    ef_camera_to_world_dir(cam, upc, u);
    fprintf(out, "camera%s:\n", whose);
    print_vec(out, "position", cam->pos, cam->src_pose);
    print_vec(out, "forward", f, NULL);
    print_vec(out, "up", u, NULL);
    fprintf(out, "  %-11s %.6g deg horizontal  from %s\n", "fov", cam->hfov_deg, cam->src_fov);
    if (cam->proj != EF_PROJ_NONE)
        fprintf(out, "  %-11s %s\n", "projection", cam->src_proj);
    if (cam->near_.set)
        fprintf(out, "  %-11s %.9g  from %s\n", "near", cam->near_.v, cam->src_near);
    if (cam->far_.set)
        fprintf(out, "  %-11s %.9g  from %s\n", "far", cam->far_.v, cam->src_far);
    if (cam->warning[0])
        fprintf(out, "  warning:    %s\n", cam->warning);
}

void ef_explain(ef_job *J, FILE *out, const ef_exr_file *in, const ef_channel_plan *plan,
                const ef_camera *cam, const ef_depth_conv *conv, int conv_ok)
{
    const ef_options *o = &J->o;
    fprintf(out, "input: %s (%d part%s)\n", in->path, in->nparts, in->nparts > 1 ? "s" : "");
    if (!plan) {
        /* What was found before the first thing that was not: the
         * camera of the first part's header, when it has one. */
        if (cam)
            explain_camera(out, cam, " (the first part's header)");
        fprintf(out, "colour, depth and views: not resolved (see the error)\n");
        explain_scene(J, out, NULL);
        return;
    }
    if (!cam) {
        fprintf(out, "camera: not resolved (see the error)\n");
        explain_channels(out, o, plan, NULL, 0);
        explain_scene(J, out, plan);
        return;
    }
    explain_camera(out, cam, "");
    explain_channels(out, o, plan, conv, conv_ok);
    explain_scene(J, out, plan);
}

/* The colour and depth channels --explain found, and the depth mode. */
static void explain_channels(FILE *out, const ef_options *o, const ef_channel_plan *plan,
                             const ef_depth_conv *conv, int conv_ok)
{
    fprintf(out, "colour: %s, %s, %s%s%s (part %d)\n", plan->rgb[0].name, plan->rgb[1].name,
           plan->rgb[2].name, plan->alpha.part >= 0 ? ", alpha " : ", no alpha (alpha = 1)",
           plan->alpha.part >= 0 ? plan->alpha.name : "", plan->rgb[0].part);
    fprintf(out, "depth: %s (part %d%s%s), mode %s\n", plan->depth.name, plan->depth.part,
           o->depth_file ? " of " : "", o->depth_file ? o->depth_file : "",
           ef_depth_mode_name(o->depth_mode));
    if (conv && conv_ok && (conv->mode != EF_DEPTH_PLANAR && conv->mode != EF_DEPTH_RADIAL &&
                            conv->mode != EF_DEPTH_INVERSE))
        fprintf(out, "  clip planes near %.9g far %.9g  from %s\n", conv->near_, conv->far_, conv->src_clip);
}

/* What --explain says of the scene (none of it needs the file). */
static void explain_scene(ef_job *J, FILE *out, const ef_channel_plan *plan)
{
    const ef_options *o = &J->o;
    fprintf(out, "sky rule: depth non-finite, <= 0 (planar/radial/inverse), >= %g once linearised, or at "
           "the far plane (buffer modes)\n", EF_SKY_DISTANCE);
    if (o->scene.sky == EF_SKY_FOG)
        fprintf(out, "  sky pixels: fogged to infinity (--sky fog)\n");
    else if (o->scene.sky == EF_SKY_KEEP)
        fprintf(out, "  sky pixels: kept unchanged (--sky keep)\n");
    else
        fprintf(out, "  sky pixels: a background at distance %g (--sky distance=%g)\n",
               o->scene.sky_distance, o->scene.sky_distance);
    for (int i = 0; i < o->scene.ncomp; ++i)
        fprintf(out, "fog: %s\n", o->scene.comp[i].spec);
    for (int i = 0; i < o->scene.nlight; ++i) {
        const ef_light *l = &o->scene.light[i];
        fprintf(out, "light %s: %s\n", l->name, l->spec);
        if (l->planet > 0)
            fprintf(out, "  over a planet of radius %g scene units (the sun's path by Chapman's "
                         "function; general quadrature)\n", l->planet);
        if (l->shadow)
            fprintf(out, "  shadow map %s: %d x %d, %s, camera from %s, bias %g, slope %g, "
                         "outside %s\n",
                    l->shadow_path, l->shadow->w, l->shadow->h,
                    l->shadow->ortho ? "orthographic" : "perspective",
                    l->shadow_camera[0] ? l->shadow_camera : "its header", l->shadow_opts.bias,
                    l->shadow_opts.slope, l->shadow_opts.outside_lit ? "lit" : "shadow");
        if (l->shadow && l->shadow->ntilt)
            fprintf(out, "  penumbra: %d directions over the sun's disc of %g degrees (filtered, "
                         "not exact)\n",
                    l->shadow->ntilt, l->shadow->angle * 180 / 3.14159265358979);
        if (l->multiple && l->lms) {
            ef_ms_info in;
            ef_lms_get_info(l->lms, &in);
            fprintf(out, "  multiple scattering: solved about the lamp in uniform fog over %d "
                         "radial nodes and %d directions, %d Legendre terms, orders 3 and up "
                         "by GMRES in %d iterations (residual %.1e); discretisation estimated "
                         "at %.1e of the largest source; %.3f s\n",
                    in.nodes, in.kept, in.nh, in.iterated, in.tail_rel, in.disc_rel, in.seconds);
            if (ef_lms_is_scaled(l->lms))
                fprintf(out, "  multiple scattering in this fog, which is not uniform: the "
                             "uniform fog's field read at each node of the lamp's quadrature, "
                             "scaled by the optical distance from the lamp (an approximation; "
                             "its estimate joins --aov error)\n");
            if (ef_lms_is_spot(l->lms))
                fprintf(out, "  a spot's multiple scattering: the point lamp's field at each "
                             "node of its quadrature (in and outside the cone) times the cone's "
                             "share averaged over where the light reaching the node first "
                             "scattered (exact with isotropic phase; with another phase, an "
                             "approximation whose estimate joins --aov error)\n");
        } else if (l->multiple) {
            ef_ms_info in;
            ef_ms_get_info(l->ms, &in);
            if (!l->ms)
                fprintf(out, "  multiple scattering: nothing to add (the sun at or below the "
                             "horizon, or no fog its light reaches)\n");
            else if (in.volume)
                fprintf(out, "  multiple scattering: solved by Monte Carlo in the volume, %d photons "
                             "of the beam on a grid of %d voxels a side, harmonics to degree 3 "
                             "(its noise, grid and harmonics estimated into --aov error); "
                             "%.3f s\n",
                        in.photons, in.kept, in.seconds);
            else
                fprintf(out, "  multiple scattering: plane-parallel solve over %d depth nodes (%d kept "
                             "in its table) to %s, "
                             "%d directions per hemisphere, %d azimuthal modes solved directly and "
                             "%d order by order; orders left out within %.1e and discretisation "
                             "estimated at %.1e of the largest source; %.3f s\n",
                        in.nodes, in.kept, l->has_ground ? "the ground" : "the fog's own depth", in.nh,
                        in.direct, in.iterated, in.tail_rel, in.disc_rel, in.seconds);
        }
    }
    if (o->scene.sky_light)
        fprintf(out, "sky light: %s (%d x %d; %d phase convolution%s)\n", o->scene.sky_light_spec,
                o->scene.sky_light->src_w, o->scene.sky_light->src_h, o->scene.sky_light->nconv,
                o->scene.sky_light->nconv == 1 ? "" : "s");
    if (o->scene.sky_light && o->scene.sky_multiple) {
        ef_ms_info in;
        ef_ms_get_info(o->scene.sky_ms, &in);
        if (!o->scene.sky_ms)
            fprintf(out, "  multiple scattering: nothing to add (no fog above the ground)\n");
        else
            fprintf(out, "  multiple scattering: the sky carried through the fog, every order "
                         "(in place of its unattenuated single scattering): %d depth nodes (%d "
                         "kept) to %s, %d directions per hemisphere, %d azimuthal modes solved "
                         "directly and %d order by order; discretisation estimated at %.1e of "
                         "the largest source; %.3f s\n",
                    in.nodes, in.kept, o->scene.sky_has_ground ? "the ground" : "the fog's own depth",
                    in.nh, in.direct, in.iterated, in.disc_rel, in.seconds);
    }
    fprintf(out, "fog colour: %g, %g, %g (working space)\n", o->scene.color[0], o->scene.color[1],
           o->scene.color[2]);
    fprintf(out, "up axis: %g, %g, %g; %g scene units per metre%s%s\n", o->scene.ctx.up[0],
            o->scene.ctx.up[1], o->scene.ctx.up[2], o->scene.ctx.units_per_meter,
            o->scene_file ? "; scene file " : "", o->scene_file ? o->scene_file : "");
    fprintf(out, "time: %.9g s\n", o->scene.ctx.time);
    if (ef_colour_space(&J->colour)[0])
        fprintf(out, "working colour space: %s  from %s; OpenColorIO config: %s\n",
                ef_colour_space(&J->colour), ef_colour_space_source(&J->colour), ef_colour_config_where(&J->colour));
    if (o->aov) {
        const char *names[EF_AOV_MAX_CHANNELS];
        const int n = ef_aov_channels(o->aov, &o->scene, names);
        fprintf(out, "aov channels (part %d):", plan ? plan->rgb[0].part : -1);
        for (int i = 0; i < n; ++i)
            fprintf(out, " %s", names[i]);
        if (o->aov & EF_AOV_P)
            fprintf(out, "; fog_P relative to %.9g, %.9g, %.9g", o->aov_origin[0],
                    o->aov_origin[1], o->aov_origin[2]);
        fputc('\n', out);
    }
}

/* A JSON string (NULL: null), escaped. */
static void json_str(FILE *out, const char *v)
{
    if (!v) {
        fputs("null", out);
        return;
    }
    fputc('"', out);
    for (const unsigned char *c = (const unsigned char *) v; *c; ++c) {
        if (*c == '"' || *c == '\\')
            fprintf(out, "\\%c", *c);
        else if (*c < 0x20)
            fprintf(out, "\\u%04x", *c);
        else
            fputc(*c, out);
    }
    fputc('"', out);
}

/* A JSON number (non-finite: null, which JSON has instead). */
static void json_num(FILE *out, double v)
{
    if (isfinite(v))
        fprintf(out, "%.17g", v);
    else
        fputs("null", out);
}

static void json_vec(FILE *out, const double *v, int n)
{
    fputc('[', out);
    for (int k = 0; k < n; ++k) {
        if (k)
            fputs(", ", out);
        json_num(out, v[k]);
    }
    fputc(']', out);
}

/* --explain --json: the facts of --explain as one JSON object, for scripts
 * (and exrfog.explain() in Python). */
void ef_explain_json(ef_job *J, FILE *out, const ef_exr_file *in, const ef_channel_plan *plans,
                     const ef_camera *cams, const int *conv_ok, int nplans)
{
    const ef_options *o = &J->o;
    static const double fwd[3] = { 0, 0, 1 }, upc[3] = { 0, 1, 0 };
    fputs("{\n  \"version\": ", out);
    json_str(out, EXRFOG_VERSION);
    fputs(",\n  \"input\": ", out);
    json_str(out, in->path);
    fprintf(out, ",\n  \"parts\": %d,\n  \"views\": [", in->nparts);
    for (int v = 0; v < nplans; ++v) {
        const ef_channel_plan *pl = &plans[v];
        const ef_camera *cam = &cams[v];
        double f[3], u[3];
        ef_camera_to_world_dir(cam, fwd, f);
        ef_camera_to_world_dir(cam, upc, u);
        fputs(v ? ",\n    {" : "\n    {", out);
        fputs("\"view\": ", out);
        json_str(out, pl->view[0] ? pl->view : NULL);
        fprintf(out, ", \"default_view\": %s,\n     \"camera\": {\"position\": ",
                pl->default_view ? "true" : "false");
        json_vec(out, cam->pos, 3);
        fputs(", \"forward\": ", out);
        json_vec(out, f, 3);
        fputs(", \"up\": ", out);
        json_vec(out, u, 3);
        fputs(", \"hfov_deg\": ", out);
        json_num(out, cam->hfov_deg);
        fputs(", \"near\": ", out);
        if (cam->near_.set)
            json_num(out, cam->near_.v);
        else
            fputs("null", out);
        fputs(", \"far\": ", out);
        if (cam->far_.set)
            json_num(out, cam->far_.v);
        else
            fputs("null", out);
        fputs(", \"pose_source\": ", out);
        json_str(out, cam->src_pose);
        fputs(", \"fov_source\": ", out);
        json_str(out, cam->src_fov);
        fputs(", \"projection\": ", out);
        json_str(out, cam->proj != EF_PROJ_NONE ? cam->src_proj : NULL);
        fputs(", \"warning\": ", out);
        json_str(out, cam->warning[0] ? cam->warning : NULL);
        fprintf(out, "},\n     \"colour\": {\"part\": %d, \"channels\": [", pl->rgb[0].part);
        for (int k = 0; k < 3; ++k) {
            json_str(out, pl->rgb[k].name);
            fputs(k < 2 ? ", " : "], \"alpha\": ", out);
        }
        json_str(out, pl->alpha.part >= 0 ? pl->alpha.name : NULL);
        fputs("},\n     \"depth\": {\"file\": ", out);
        json_str(out, o->depth_file ? o->depth_file : in->path);
        fprintf(out, ", \"part\": %d, \"channel\": ", pl->depth.part);
        json_str(out, pl->depth.name);
        fputs(", \"mode\": ", out);
        json_str(out, ef_depth_mode_name(o->depth_mode));
        fputs(", \"conversion_error\": ", out);
        json_str(out, conv_ok[v] ? NULL : "the depth mode needs clip planes or a projection");
        fputs("}}", out);
    }
    fputs("\n  ],\n  \"sky\": ", out);
    json_str(out, o->scene.sky == EF_SKY_FOG ? "fog" : o->scene.sky == EF_SKY_KEEP ? "keep" : "distance");
    fputs(", \"sky_distance\": ", out);
    json_num(out, o->scene.sky == EF_SKY_DISTANCE_MODE ? o->scene.sky_distance : NAN);
    fputs(",\n  \"fog\": [", out);
    for (int i = 0; i < o->scene.ncomp; ++i) {
        if (i)
            fputs(", ", out);
        json_str(out, o->scene.comp[i].spec);
    }
    fputs("],\n  \"lights\": [", out);
    for (int i = 0; i < o->scene.nlight; ++i) {
        const ef_light *l = &o->scene.light[i];
        fputs(i ? ", {\"name\": " : "{\"name\": ", out);
        json_str(out, l->name);
        fputs(", \"spec\": ", out);
        json_str(out, l->spec);
        fputs(", \"planet\": ", out);
        if (l->planet > 0)
            json_num(out, l->planet);
        else
            fputs("null", out);
        fputs(", \"shadow\": ", out);
        if (l->shadow) {
            fputs("{\"path\": ", out);
            json_str(out, l->shadow_path);
            fprintf(out, ", \"width\": %d, \"height\": %d, \"projection\": ", l->shadow->w,
                    l->shadow->h);
            json_str(out, l->shadow->ortho ? "orthographic" : "perspective");
            fputs(", \"camera_file\": ", out);
            if (l->shadow_camera[0])
                json_str(out, l->shadow_camera);
            else
                fputs("null", out);
            fputs(", \"bias\": ", out);
            json_num(out, l->shadow_opts.bias);
            fputs(", \"slope\": ", out);
            json_num(out, l->shadow_opts.slope);
            fputs(", \"outside\": ", out);
            json_str(out, l->shadow_opts.outside_lit ? "lit" : "shadow");
            fprintf(out, ", \"penumbra\": %d", l->shadow->ntilt);
            fputc('}', out);
        } else {
            fputs("null", out);
        }
        fputs(", \"scattering\": ", out);
        json_str(out, l->multiple ? "multiple" : "single");
        if (l->lms || l->ms) {
            ef_ms_info in;
            if (l->lms) {
                ef_lms_get_info(l->lms, &in);
                fprintf(out, ", \"multiple\": {\"radial_nodes\": %d, \"directions\": %d, "
                             "\"legendre_terms\": %d, \"gmres_iterations\": %d, \"local\": %s, "
                             "\"cone_averaged\": %s, \"residual\": ",
                        in.nodes, in.kept, in.nh, in.iterated,
                        ef_lms_is_local(l->lms) ? "true" : "false",
                        ef_lms_is_spot(l->lms) ? "true" : "false");
            } else {
                ef_ms_get_info(l->ms, &in);
                fprintf(out, ", \"multiple\": {\"nodes\": %d, \"kept\": %d, \"directions\": %d, "
                             "\"direct_modes\": %d, \"iterated_modes\": %d, \"volume\": %s, "
                             "\"photons\": %d, \"tail_rel\": ",
                        in.nodes, in.kept, in.nh, in.direct, in.iterated,
                        in.volume ? "true" : "false", in.photons);
            }
            json_num(out, in.tail_rel);
            fputs(", \"discretisation_rel\": ", out);
            json_num(out, in.disc_rel);
            fputs(", \"seconds\": ", out);
            json_num(out, in.seconds);
            fputc('}', out);
        }
        fputc('}', out);
    }
    fputs("], \"sky_light\": ", out);
    json_str(out, o->scene.sky_light ? o->scene.sky_light_spec : NULL);
    fputs(",\n  \"fog_colour\": ", out);
    json_vec(out, o->scene.color, 3);
    fputs(", \"up\": ", out);
    json_vec(out, o->scene.ctx.up, 3);
    fputs(", \"units_per_meter\": ", out);
    json_num(out, o->scene.ctx.units_per_meter);
    fputs(", \"time\": ", out);
    json_num(out, o->scene.ctx.time);
    fputs(",\n  \"colour_space\": ", out);
    if (ef_colour_space(&J->colour)[0]) {
        fputs("{\"name\": ", out);
        json_str(out, ef_colour_space(&J->colour));
        fputs(", \"source\": ", out);
        json_str(out, ef_colour_space_source(&J->colour));
        fputs(", \"config\": ", out);
        json_str(out, ef_colour_config_where(&J->colour));
        fputc('}', out);
    } else {
        fputs("null", out);
    }
    const char *names[EF_AOV_MAX_CHANNELS];
    const int n = ef_aov_channels(o->aov, &o->scene, names);
    fputs(",\n  \"aov\": [", out);
    for (int i = 0; i < n; ++i) {
        if (i)
            fputs(", ", out);
        json_str(out, names[i]);
    }
    fputs("], \"aov_origin\": ", out);
    json_vec(out, o->aov_origin, 3);
    fputs("\n}\n", out);
}

/* --stats: one line per component whose optical depth is numerical. Only
 * the surface segment's evaluation of each fogged pixel is counted (not
 * the segment to infinity behind a partly transparent pixel). */
void ef_print_tau_stats(ef_job *J, const ef_fog_scene *s, const ef_tau_stats *st)
{
    int any = 0;
    for (int i = 0; i < s->ncomp; ++i)
        any |= s->comp[i].model->tau_info != NULL;
    if (any && st[0].timed > 0)
        /* before the per-component lines: it varies from run to run */
        fprintf(J->msg,
                "exrfog: stats: fog time per pixel (every component, one core): mean %.2f "
                "us, p99.9 %.3g us, max %.3g us (%.3g us where the thread was not "
                "descheduled; costliest pixel re-timed %.3g us)\n",
                st[0].time_sum / st[0].timed / 1e3,
                ef_stats_quantile(st[0].time_hist, st[0].timed, 0.999) / 1e3,
                st[0].time_max / 1e3, st[0].time_max_clean / 1e3,
                st[0].time_max_retimed / 1e3);
    for (int i = 0; i < s->ncomp; ++i) {
        const ef_fog_component *c = &s->comp[i];
        if (!c->model->tau_info)
            continue;
        const ef_tau_stats *t = &st[i];
        const double n = t->pixels > 0 ? t->pixels : 1.0;
        fprintf(J->msg,
                "exrfog: stats: fog[%d] %.60s%s: %.0f pixels; per pixel: noise evaluations mean "
                "%.1f p99.9 %.3g max %.0f, cells walked mean %.1f, octaves dropped mean %.2f, "
                "over the work bound %.0f pixels; error estimate (tau) max %.3g mean %.3g, "
                "(|dT|, as --aov error) max %.3g; the error output a bound on %.0f pixels, "
                "a quadrature's estimate on %.0f, a statistical estimate on %.0f (octaves "
                "dropped, the clamp's share or a stop)\n",
                i, c->spec, strlen(c->spec) > 60 ? "..." : "", t->pixels, t->evals / n,
                ef_stats_quantile(t->evals_hist, t->pixels, 0.999), t->evals_max,
                t->cells / n, t->dropped / n, t->over, t->err_max,
                (t->err_sum + t->err_sum_lo) / n, t->dT_max, t->pixels - t->quad - t->stat,
                t->quad, t->stat);
    }
}
