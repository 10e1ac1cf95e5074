/* The exrfog program: a client of libexrfog's whole-run API. */
#include "exrfog.h"

int main(int argc, char **argv)
{
    exrfog_context *ctx = exrfog_context_create();
    if (!ctx)
        return 1;
    exrfog_set_print(ctx, 1);
    const exrfog_result r = exrfog_run(ctx, argc, (const char *const *) argv);
    exrfog_context_destroy(ctx);
    return (int) r;
}
