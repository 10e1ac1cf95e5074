/* Helpers shared by the lit fog tests (include after cmocka.h). */
#ifndef EF_TLIT_H
#define EF_TLIT_H

#include <math.h>

#include "lit.h"

/* s from the fog SPECs (NULL-terminated) and one light (or none), checked
 * as a run would check it; a refusal fails the test. */
static inline void scene_of(ef_fog_scene *s, const char *const *specs, const char *light)
{
    ef_err err;
    ef_scene_init(s);
    for (int i = 0; specs[i]; ++i)
        if (ef_scene_add(s, specs[i], &err))
            fail_msg("'%s' did not parse: %s", specs[i], err.msg);
    if (light && ef_scene_add_light(s, light, &err))
        fail_msg("'%s' did not parse: %s", light, err.msg);
    if (ef_lights_check(s, &err))
        fail_msg("scene refused: %s", err.msg);
}

/* The ray from org along (dx, dy, dz) normalised, dist long. */
static inline ef_ray ray_of(const double org[3], double dx, double dy, double dz, double dist)
{
    const double n = sqrt(dx * dx + dy * dy + dz * dz);
    ef_ray r = { { dx / n, dy / n, dz / n }, dist, dist, { org[0], org[1], org[2] } };
    return r;
}

#endif
