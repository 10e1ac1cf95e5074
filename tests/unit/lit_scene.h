/* A lit scene and a ray for the multiple-scattering tests (test_ms,
 * test_lms): include after cmocka.h, scene.h and lit.h. */
#ifndef EF_TEST_LIT_SCENE_H
#define EF_TEST_LIT_SCENE_H

#include <math.h>

/* s with one fog and one light, its lights' solves built (the test fails
 * with the message otherwise). */
static inline void scene_with(ef_fog_scene *s, const char *fog, const char *light)
{
    ef_err err = { 0 };
    ef_scene_init(s);
    if (ef_scene_add(s, fog, &err) || ef_scene_add_light(s, light, &err) ||
        ef_scene_prepare_lights(s, &err))
        fail_msg("'%s' with '%s': %s", fog, light, err.msg);
}

/* The ray from org along (dx, dy, dz), normalised, of length dist. */
static inline ef_ray ray(const double org[3], double dx, double dy, double dz, double dist)
{
    const double n = sqrt(dx * dx + dy * dy + dz * dz);
    ef_ray r = { { dx / n, dy / n, dz / n }, dist, dist, { org[0], org[1], org[2] } };
    return r;
}

#endif
