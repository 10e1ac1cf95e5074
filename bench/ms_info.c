/* bench/ms_info: what multiple scattering's solve chooses and costs over
 * the fog's albedo and g (a sun 30 degrees up in height fog, y up): depth
 * nodes, directions per hemisphere, modes solved directly and iterated,
 * the tail bound and the discretisation estimate relative to the largest
 * source, and the solve's time. One line per case (bench/ms.sh). */
#include <stdio.h>

#include "ms.h"
#include "scene.h"

int main(void)
{
    static const double albedo[] = { 0.8, 0.9, 0.95, 0.99, 1.0 };
    static const double g[] = { 0, 0.5, 0.85, 0.95 };
    printf("%-6s %-5s %6s %3s %7s %9s %10s %10s %9s\n", "albedo", "g", "nodes", "nh", "direct",
           "iterated", "tail/max", "disc/max", "solve s");
    for (unsigned a = 0; a < sizeof albedo / sizeof *albedo; ++a)
        for (unsigned j = 0; j < sizeof g / sizeof *g; ++j) {
            ef_fog_scene s;
            ef_scene_init(&s);
            ef_err err = { 0 };
            char fog[256];
            snprintf(fog, sizeof fog,
                     "height:density=0.05:falloff=0.1:base=0:albedo=%g:phase=hg:g=%g", albedo[a],
                     g[j]);
            if (ef_scene_add(&s, fog, &err) ||
                ef_scene_add_light(&s, "sun:towards=0.8,0.577,0.15:scattering=multiple", &err) ||
                ef_scene_prepare_lights(&s, &err)) {
                fprintf(stderr, "ms_info: %s\n", err.msg);
                return 1;
            }
            ef_ms_info in;
            ef_ms_get_info(s.light[0].ms, &in);
            printf("%-6g %-5g %6d %3d %7d %9d %10.2e %10.2e %9.3f\n", albedo[a], g[j], in.nodes,
                   in.nh, in.direct, in.iterated, in.tail_rel, in.disc_rel, in.seconds);
            ef_scene_free(&s);
        }
    return 0;
}
