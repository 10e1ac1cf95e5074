/* The files a run reads, and the refusal of an output that would replace
 * one of them (job_impl.h: ef_job_reads, ef_output_clash). */
#include "job_impl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lit.h"
#include "output.h"
#include "scene.h"
#include "sky_light.h"

/* Appends (role, path) to the list when there is room and a path. */
static void add(ef_read_list *r, const char *role, const char *path, int per_frame)
{
    if (!path || !path[0] || r->n >= EF_MAX_READS)
        return;
    ef_read_file *f = &r->f[r->n++];
    snprintf(f->role, sizeof f->role, "%s", role);
    snprintf(f->path, sizeof f->path, "%s", path);
    f->per_frame = per_frame;
}

/* A frame pattern's path for frame (has_frame), or the path as written. */
static void add_pattern(ef_read_list *r, const char *role, const char *pattern, int has_frame,
                        long frame)
{
    if (!pattern)
        return;
    ef_frame_pattern p;
    char path[4096];
    if (has_frame && ef_frame_pattern_find(pattern, &p) &&
        !ef_frame_path(pattern, &p, frame, path, sizeof path))
        add(r, role, path, 1);
    else
        add(r, role, pattern, 1);
}

void ef_job_reads(const ef_job *J, int has_frame, long frame, int with_input, ef_read_list *r)
{
    const ef_options *o = &J->o;
    r->n = 0;
    if (with_input)
        add_pattern(r, "INPUT", o->input, has_frame, frame);
    add_pattern(r, "--depth file", o->depth_file, has_frame, frame);
    add_pattern(r, "--camera-file", o->camera_file, has_frame, frame);
    add(r, "--scene file", o->scene_file, 0);
    add(r, "--colorconfig", o->colorconfig, 0);
    const ef_fog_scene *s = &o->scene;
    char role[120];
    for (int i = 0; i < s->ncomp; ++i)
        if (s->comp[i].path) {
            snprintf(role, sizeof role, "file= of fog component %d", i + 1);
            add(r, role, s->comp[i].path, 0);
        }
    for (int i = 0; i < s->nlight; ++i)
        if (s->light[i].shadow_path[0]) {
            snprintf(role, sizeof role, "shadow= map of light %s", s->light[i].name);
            add(r, role, s->light[i].shadow_path, 0);
            if (s->light[i].shadow_camera[0]) {
                snprintf(role, sizeof role, "shadow-camera= file of light %s", s->light[i].name);
                add(r, role, s->light[i].shadow_camera, 0);
            }
        }
    if (s->sky_light)
        add(r, "--sky-light environment", s->sky_light->path, 0);
}

const char *ef_read_article(const ef_read_file *f)
{
    return strcmp(f->role, "INPUT") ? "the " : "";
}

const ef_read_file *ef_output_clash(const ef_read_list *r, const char *out)
{
    for (int i = 0; i < r->n; ++i)
        /* the same name, or the same file through a link (symbolic or hard) */
        if (!strcmp(out, r->f[i].path) || ef_output_same_file(out, r->f[i].path))
            return &r->f[i];
    return NULL;
}
