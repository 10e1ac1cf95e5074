/* Checks ef_noise3 and ef_fbm_eval bit for bit (0 ulp) against
 * tests/refs/perlin_ref.py, an independent plain-Python implementation of the
 * noise contract. The script writes seeded random records as hex floats:
 *   n x y z value
 *   f octaves lacunarity gain qx qy qz value
 * Usage: noise_ref_check SCRIPT SEED NOISE_COUNT FBM_COUNT
 * Exits 0 when every record matches, 1 on a mismatch or a short run, 77
 * (skipped) when python3 cannot be run. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include "noise.h"

static int same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

int main(int argc, char **argv)
{
    if (argc != 5) {
        fprintf(stderr, "usage: %s SCRIPT SEED NOISE_COUNT FBM_COUNT\n", argv[0]);
        return 2;
    }
    const long want_n = atol(argv[3]), want_f = atol(argv[4]);
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "python3 '%s' gen %s %ld %ld", argv[1], argv[2], want_n, want_f);
    FILE *in = popen(cmd, "r");
    if (!in) {
        fprintf(stderr, "noise_ref_check: cannot run python3; skipped\n");
        return 77;
    }
    char line[1024];
    long nn = 0, nf = 0, bad = 0, nlines = 0;
    while (fgets(line, sizeof line, in)) {
        ++nlines;
        double x[3], got, want;
        if (line[0] == 'n') {
            if (sscanf(line, "n %la %la %la %la", &x[0], &x[1], &x[2], &want) != 4)
                goto malformed;
            got = ef_noise3(x[0], x[1], x[2]);
            ++nn;
            if (!same_bits(got, want) && bad++ < 10)
                fprintf(stderr, "noise3(%a, %a, %a) = %.17g (%a), python %.17g (%a)\n", x[0],
                        x[1], x[2], got, got, want, want);
        } else if (line[0] == 'f') {
            int oct;
            double lac, gain;
            if (sscanf(line, "f %d %la %la %la %la %la %la", &oct, &lac, &gain, &x[0], &x[1],
                       &x[2], &want) != 7)
                goto malformed;
            ef_fbm f;
            ef_fbm_init(&f, oct, lac, gain);
            got = ef_fbm_eval(&f, x);
            ++nf;
            if (!same_bits(got, want) && bad++ < 10)
                fprintf(stderr,
                        "fbm(octaves %d, lacunarity %a, gain %a; %a, %a, %a) = %.17g (%a), "
                        "python %.17g (%a)\n",
                        oct, lac, gain, x[0], x[1], x[2], got, got, want, want);
        } else {
            goto malformed;
        }
    }
    const int st = pclose(in);
    if (nlines == 0 && WIFEXITED(st) && WEXITSTATUS(st) == 127) {
        fprintf(stderr, "noise_ref_check: python3 not found; skipped\n");
        return 77;
    }
    if (!WIFEXITED(st) || WEXITSTATUS(st) != 0) {
        fprintf(stderr, "noise_ref_check: '%s' failed (status %d)\n", cmd, st);
        return 1;
    }
    printf("noise3: %ld points, fbm: %ld points, %ld differ\n", nn, nf, bad);
    if (nn != want_n || nf != want_f) {
        fprintf(stderr, "noise_ref_check: expected %ld + %ld records, read %ld + %ld\n", want_n,
                want_f, nn, nf);
        return 1;
    }
    return bad ? 1 : 0;
malformed:
    fprintf(stderr, "noise_ref_check: malformed record: %s", line);
    pclose(in);
    return 1;
}
