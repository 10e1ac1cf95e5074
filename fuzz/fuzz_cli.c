/* libFuzzer target: the command line itself (options, SPECs, scene JSON,
 * layered profiles), as src/job/args.c parses it, then the parsed scene
 * evaluated on a fan of rays. One input:
 *   byte 0 = mode: 0 command line only; 1 the rest after the first NUL is a
 *            scene file (--scene FILE); 2 the rest is a layered profile
 *            (--fog layered:file=FILE);
 *   then arguments separated by '\n' (up to 32), then (modes 1, 2) a NUL
 *   and the file's bytes.
 * INPUT and -o are added (nothing is read or written: the parser checks
 * them only for presence). Properties beyond "no crash, no leak, no UB":
 *   - an accepted command line gives finite, non-negative tau (or +inf)
 *     and finite transmittance and colour on every ray, surface and sky;
 *   - every message is printable when FUZZ_CLI_PRINTABLE=1 (the CLI escapes
 *     control bytes when printing; the parser's text itself may hold them).
 * FUZZ_CLI_VERBOSE=1 prints each input's outcome. */
#define _GNU_SOURCE   /* memfd_create */
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "args.h"
#include "colour.h"
#include "scene.h"

#define MAX_ARGS 40

static int file_fd = -1;
static char file_path[64];

static int put_file(const uint8_t *d, size_t n)
{
    if (file_fd < 0) {
        file_fd = memfd_create("exrfog-fuzz-cli", MFD_CLOEXEC);
        if (file_fd < 0) {
            perror("fuzz_cli: memfd_create");
            abort();
        }
        snprintf(file_path, sizeof file_path, "/proc/self/fd/%d", file_fd);
    }
    if (ftruncate(file_fd, 0) != 0)
        return -1;
    return pwrite(file_fd, d, n, 0) == (ssize_t) n ? 0 : -1;
}

/* tau of every component summed must be >= 0 (or +inf); T and F finite. */
static void check_scene(ef_fog_scene *s)
{
    static const double dirs[][3] = { { 0, 0, -1 }, { 0.6, 0, -0.8 }, { 0, 1, 0 },
                                      { 0, -1, 0 }, { 0.577, 0.577, -0.577 }, { 1, 0, 0 } };
    static const double dists[] = { 0.0, 1e-3, 7.5, 1e3, 1e7, INFINITY };
    const double org[3] = { 0.25, 1.7, 0.5 };
    ef_scene_bind(s, org);
    for (size_t i = 0; i < sizeof dirs / sizeof dirs[0]; ++i)
        for (size_t j = 0; j < sizeof dists / sizeof dists[0]; ++j) {
            ef_ray r;
            memcpy(r.org, org, sizeof org);
            memcpy(r.dir, dirs[i], sizeof r.dir);
            const double len = sqrt(r.dir[0] * r.dir[0] + r.dir[1] * r.dir[1] + r.dir[2] * r.dir[2]);
            for (int k = 0; k < 3; ++k)
                r.dir[k] /= len;
            r.dist = dists[j];
            r.planar = dists[j] * 0.8;
            ef_fog_sample surf, inf;
            ef_scene_eval(s, &r, &surf, &inf);
            for (int k = 0; k < 3; ++k)
                if (!(surf.T[k] >= 0 && surf.T[k] <= 1) || !(inf.T[k] >= 0 && inf.T[k] <= 1) ||
                    !isfinite(surf.F[k]) || !isfinite(inf.F[k])) {
                    fprintf(stderr, "fuzz_cli: ray %zu at %g: T %g/%g F %g/%g\n", i, dists[j],
                            surf.T[k], inf.T[k], surf.F[k], inf.F[k]);
                    abort();
                }
        }
}

static int printable(const char *s)
{
    for (const unsigned char *c = (const unsigned char *) s; *c; ++c)
        if (*c < 0x20 || *c == 0x7f)
            return 0;
    return 1;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1 || size > 16384)
        return 0;
    const int mode = data[0] % 3;
    const uint8_t *args = data + 1, *file = NULL;
    size_t alen = size - 1, flen = 0;
    if (mode) {
        const uint8_t *nul = memchr(args, 0, alen);
        if (nul) {
            file = nul + 1;
            flen = (size_t) (data + size - file);
            alen = (size_t) (nul - args);
        } else {
            file = args + alen;
        }
        if (put_file(file, flen))
            return 0;
    }
    char *buf = malloc(alen + 1);
    memcpy(buf, args, alen);
    buf[alen] = '\0';
    char *argv[MAX_ARGS + 8];
    int argc = 0;
    argv[argc++] = "exrfog";
    char spec[96];
    if (mode == 1) {
        argv[argc++] = "--scene";
        argv[argc++] = file_path;
    } else if (mode == 2) {
        snprintf(spec, sizeof spec, "layered:file=%s", file_path);
        argv[argc++] = "--fog";
        argv[argc++] = spec;
    }
    /* No argument section at all (a bare file in modes 1 and 2) adds none,
     * so the file itself gets parsed. */
    for (char *p = alen ? buf : NULL, *nl; p && argc < MAX_ARGS; p = nl ? nl + 1 : NULL) {
        nl = strchr(p, '\n');
        if (nl)
            *nl = '\0';
        argv[argc++] = p;
    }
    argv[argc++] = "in.exr";
    argv[argc++] = "-o";
    argv[argc++] = "out.exr";
    argv[argc] = NULL;
    /* --help and --version print to stdout: keep it quiet. */
    for (int i = 1; i < argc; ++i)
        if (!strncmp(argv[i], "--h", 3) || !strncmp(argv[i], "--v", 3) || !strcmp(argv[i], "-h")) {
            free(buf);
            return 0;
        }
    ef_options o;
    ef_colour colour;
    memset(&colour, 0, sizeof colour);
    ef_err err = { 0 };
    const ef_parse_result pr = ef_options_parse(argc, argv, &o, &colour, stdout, &err);
    if (getenv("FUZZ_CLI_VERBOSE"))
        fprintf(stderr, "fuzz_cli: %d %s\n", (int) pr, pr ? err.msg : "ok");
    if (pr == EF_PARSE_USAGE || pr == EF_PARSE_FAIL) {
        if (!err.msg[0]) {
            fprintf(stderr, "fuzz_cli: a refusal without a message\n");
            abort();
        }
        if (getenv("FUZZ_CLI_PRINTABLE") && !printable(err.msg)) {
            fprintf(stderr, "fuzz_cli: unprintable message: %s\n", err.msg);
            abort();
        }
    }
    if (pr == EF_PARSE_RUN)
        check_scene(&o.scene);
    ef_options_free(&o);
    ef_colour_close(&colour);
    free(buf);
    return 0;
}
