/* PLACEHOLDER: being written; replaced wholesale. */
#include "fog.h"
static const char *const no_keys[] = { NULL };
static int no_set(ef_fog_component *c, int k, const char *v, ef_err *e) { (void) c; (void) k; (void) v; return ef_fail(e, "not yet"); }
static int no_finish(ef_fog_component *c, const ef_fog_context *x, ef_err *e) { (void) c; (void) x; return ef_fail(e, "not yet"); }
static void no_tau(const ef_fog_component *c, const ef_ray *r, double t[3]) { (void) c; (void) r; t[0] = t[1] = t[2] = 0; }
const ef_fog_model ef_fog_halfspace = { .name = "halfspace", .keys = no_keys, .set = no_set, .finish = no_finish, .tau = no_tau };
const ef_fog_model ef_fog_halfspace_linear = { .name = "halfspace-linear", .keys = no_keys, .set = no_set, .finish = no_finish, .tau = no_tau };
const ef_fog_model ef_fog_halfspace_smooth = { .name = "halfspace-smooth", .keys = no_keys, .set = no_set, .finish = no_finish, .tau = no_tau };
