/* Property test (issue 8): every numeric option and every key of every
 * model, given each hostile value, either is refused as a usage error
 * (exit 2, "exrfog: ..." on stderr) or runs (exit 0) with an output whose
 * every float channel is finite (the input has no NaN or inf). Nothing else
 * is allowed: no exit 1, no crash, no NaN/inf pixel.
 *
 * exrfog runs by fork/exec without a shell, so empty strings and raw bytes
 * reach it exactly. */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "testutil.h"

static const char *const hostile[] = {
    "0",     "-0",   "-1",   "nan",  "inf",    "-inf", "1e308", "-1e308",
    "1.7976931348623157e308", "5e-324", "1e-400", "",    "1e",    "+",
    "1,,2",  "\xd9\xa1\xd9\xa2", /* Arabic-Indic digits one, two */
    "\xff",  "1e15", "1e-300",
};

/* A command line template: the hostile value replaces "@" inside one
 * argument (several "@" in one argument all take it). */
typedef struct tmpl {
    const char *args[8];
} tmpl;

static const tmpl cases[] = {
    /* options */
    { { "--fog", "exp:density=0.02", "--fog-color", "@" } },
    { { "--fog", "exp:density=0.02", "--fog-color", "@,0.5,0.5" } },
    { { "--fog", "exp:density=0.02", "--units-per-meter", "@" } },
    { { "--fog", "noise:density=0.02:scale=10:velocity=1,2,3", "--time", "@" } },
    { { "--fog", "exp:density=0.02", "--aov", "P", "--aov-origin", "@,0,0" } },
    { { "--fog", "exp:density=0.02", "--fov", "@" } },
    { { "--fog", "exp:density=0.02", "--near", "@" } },
    { { "--fog", "exp:density=0.02", "--focal-length", "@", "--aperture", "36" } },
    { { "--fog", "exp:density=0.02", "--focal-length", "35", "--aperture", "@" } },
    { { "--fog", "exp:density=0.02", "--far", "@" } },
    { { "--fog", "exp:density=0.02", "--threads", "@" } },
    { { "--fog", "exp:density=0.02", "--up-axis", "@,1,0" } },
    { { "--fog", "exp:density=0.02", "--sky", "distance=@" } },
    { { "--fog", "exp:density=0.02", "--compression", "zip:@" } },
    { { "--fog", "exp:density=0.02", "--fov", "40", "--world-to-camera",
        "@,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1" } },
    { { "--fog", "exp:density=0.02", "--fov", "40", "--world-to-camera",
        "@,0,0,0,0,@,0,0,0,0,@,0,0,0,0,1" } },
    { { "--fog", "exp:density=0.02", "--fov", "40", "--camera-to-world",
        "1,0,0,0,0,1,0,0,0,0,1,0,@,0,0,1" } },
    /* linear, exp, exp2 */
    { { "--fog", "linear:start=@:end=100" } },
    { { "--fog", "linear:start=1:end=@" } },
    { { "--fog", "exp:density=@" } },
    { { "--fog", "exp:density=@,0.01,0.02" } },
    { { "--fog", "exp:visibility=@" } },
    { { "--fog", "exp2:density=@" } },
    { { "--fog", "exp2:visibility=@" } },
    { { "--fog", "exp:density=0.02:color=@" } },
    { { "--fog", "exp:density=0.02:color=@,0.5,0.5" } },
    /* half-spaces and height */
    { { "--fog", "halfspace:plane=0,1,0,@:density=0.1" } },
    { { "--fog", "halfspace:plane=@,1,0,0:density=0.1" } },
    { { "--fog", "halfspace:plane=0,1,0,0:density=@" } },
    { { "--fog", "halfspace:plane=0,1,0,0:visibility=@" } },
    { { "--fog", "halfspace-linear:plane=0,1,0,@:slope=0.01" } },
    { { "--fog", "halfspace-linear:plane=0,1,0,0:slope=@" } },
    { { "--fog", "halfspace-smooth:plane=0,1,0,0:density=0.1:sharpness=@" } },
    { { "--fog", "halfspace-smooth:plane=0,1,0,@:density=0.1:sharpness=1" } },
    { { "--fog", "height:density=@:falloff=0.1" } },
    { { "--fog", "height:density=0.1:falloff=@" } },
    { { "--fog", "height:density=0.1:falloff=0.1:base=@" } },
    { { "--fog", "height:visibility=@:falloff=0.1" } },
    { { "--fog", "height:density=0.1:falloff=0.1:up=@,1,0" } },
    /* layered */
    { { "--fog", "layered:heights=0,@:densities=0.1,0" } },
    { { "--fog", "layered:heights=@,10:densities=0.1,0" } },
    { { "--fog", "layered:heights=0,10:densities=@,0" } },
    /* volumes */
    { { "--fog", "box:min=@,-1,-50:max=5,5,0:density=0.1" } },
    { { "--fog", "box:min=-5,-1,-50:max=@,5,0:density=0.1" } },
    { { "--fog", "box:min=-5,-1,-50:max=5,5,0:density=@" } },
    { { "--fog", "box:min=-5,-1,-50:max=5,5,0:visibility=@" } },
    { { "--fog", "convex:planes=0,1,0,@,0,-1,0,-5:density=0.1" } },
    { { "--fog", "convex:planes=@,1,0,0,0,-1,0,-5:density=0.1" } },
    { { "--fog", "convex:planes=0,1,0,0,0,-1,0,-5:density=@" } },
    /* noise */
    { { "--fog", "noise:density=@:scale=10" } },
    { { "--fog", "noise:visibility=@:scale=10" } },
    { { "--fog", "noise:density=0.02:scale=@" } },
    { { "--fog", "noise:density=0.02:scale=10:octaves=@" } },
    { { "--fog", "noise:density=0.02:scale=10:lacunarity=@" } },
    { { "--fog", "noise:density=0.02:scale=10:gain=@" } },
    { { "--fog", "noise:density=0.02:scale=10:contrast=@" } },
    { { "--fog", "noise:density=0.02:scale=10:offset=@,0,0" } },
    { { "--fog", "noise:density=0.02:scale=10:velocity=@,0,0", "--time", "2" } },
    { { "--fog", "noise:density=0.02:scale=10:seed=@" } },
    { { "--fog", "noise:density=0.02:scale=10:falloff=@" } },
    { { "--fog", "noise:density=0.02:scale=10:falloff=0.1:base=@" } },
    { { "--fog", "noise:density=0.02:scale=10:min=@,-5,-50:max=5,5,0" } },
    { { "--fog", "noise:density=0.02:scale=10:min=-5,-5,-50:max=@,5,0" } },
    { { "--fog", "noise:density=0.02:scale=10:tol=@" } },
    { { "--fog", "noise:density=0.02:scale=10:method=steps:steps=@" } },
    { { "--fog", "noise-separable:density=0.02:scale=10:pieces=@:method=preintegrated" } },
    { { "--fog", "noise-separable:density=@:scale=10:method=preintegrated" } },
    { { "--fog", "noise-separable:density=0.02:scale=@:method=preintegrated" } },
    { { "--fog", "noise-separable:density=0.02:scale=10:falloff=@:method=preintegrated" } },
    { { "--fog", "noise-separable:density=0.02:scale=10:falloff=0.1:base=@:method=preintegrated" } },
    { { "--fog", "noise-separable:density=0.02:scale=10:falloff=0.1:base=@" } },
    { { "--fog", "noise:density=0.02:scale=10:contrast=2:falloff=0.1:base=@" } },
    { { "--fog", "noise:density=0.02:scale=10:method=exact:falloff=0.1:base=@" } },
    { { "--fog", "noise:density=0.02:scale=@:method=exact" } },
    { { "--fog", "noise:density=0.02:scale=@:contrast=2" } },
};

/* Values that parse as numbers but underflow: they must be called out of range. */
static int underflows(const char *v)
{
    return !strcmp(v, "5e-324") || !strcmp(v, "1e-400");
}

/* Whether the hostile value lands in a real-valued field (not a count). */
static int real_valued(const tmpl *t)
{
    for (int a = 0; a < 8 && t->args[a]; ++a)
        if (strstr(t->args[a], "--threads") || strstr(t->args[a], "zip:@") ||
            strstr(t->args[a], "octaves=@") || strstr(t->args[a], "steps=@") ||
            strstr(t->args[a], "pieces=@") || strstr(t->args[a], "sky"))
            return 0;
    return 1;
}

static char *subst(const char *arg, const char *v)
{
    size_t n = 1;
    for (const char *p = arg; *p; ++p)
        n += *p == '@' ? strlen(v) : 1;
    char *out = malloc(n), *q = out;
    for (const char *p = arg; *p; ++p) {
        if (*p == '@') {
            memcpy(q, v, strlen(v));
            q += strlen(v);
        } else {
            *q++ = *p;
        }
    }
    *q = '\0';
    return out;
}

/* Every HALF/FLOAT value of every part finite. Returns the count of
 * non-finite values, or -1 when the file cannot be read. */
static long nonfinite(const char *path)
{
    const int np = tu_nparts(path);
    if (np < 1)
        return -1;
    long bad = 0;
    for (int p = 0; p < np; ++p) {
        tu_image im;
        if (tu_read_image(path, p, &im))
            return -1;
        for (int c = 0; c < im.nch; ++c) {
            if (im.type[c] == EXR_PIXEL_UINT)
                continue;
            /* By contract (issue 7) the P and distance AOVs are infinite on
             * sky pixels; NaN is never allowed. */
            const int sky_inf = !strncmp(im.ch[c], "fog_P.", 6) || !strcmp(im.ch[c], "fog_distance.Z");
            const float *f = im.plane[c];
            for (long i = 0; i < (long) im.w * im.h; ++i)
                bad += isnan(f[i]) || (isinf(f[i]) && !sky_inf);
        }
        tu_image_free(&im);
    }
    return bad;
}

static void printable(const char *s, char *buf, size_t cap)
{
    size_t n = 0;
    for (const unsigned char *c = (const unsigned char *) s; *c && n + 5 < cap; ++c)
        n += (size_t) (*c < 0x20 || *c >= 0x7f ? snprintf(buf + n, cap - n, "\\x%02x", *c)
                                               : snprintf(buf + n, cap - n, "%c", *c));
    buf[n] = '\0';
}

int main(void)
{
    const char *bin = getenv("EXRFOG_BIN"), *mk = getenv("EXRFOG_MAKE_SAMPLE");
    if (!bin || !mk) {
        fprintf(stderr, "test_hostile: set EXRFOG_BIN and EXRFOG_MAKE_SAMPLE\n");
        return 1;
    }
    char *in = tu_path("hostile_in.exr"), *out = tu_path("hostile_out.exr"),
         *errf = tu_path("hostile.stderr");
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "'%s' '%s' --size 24x16 >/dev/null", mk, in);
    if (system(cmd) != 0 || nonfinite(in) != 0) {
        fprintf(stderr, "test_hostile: cannot make a finite input with %s\n", mk);
        return 1;
    }
    long runs = 0, refused = 0, failures = 0;
    for (size_t t = 0; t < sizeof cases / sizeof cases[0]; ++t)
        for (size_t h = 0; h < sizeof hostile / sizeof hostile[0]; ++h) {
            char *argv[24];
            int argc = 0;
            argv[argc++] = (char *) bin;
            argv[argc++] = in;
            argv[argc++] = "-o";
            argv[argc++] = out;
            argv[argc++] = "-q";
            for (int a = 0; a < 8 && cases[t].args[a]; ++a)
                argv[argc++] = subst(cases[t].args[a], hostile[h]);
            argv[argc] = NULL;
            unlink(out);
            struct timespec t0, t1;
            clock_gettime(CLOCK_MONOTONIC, &t0);
            pid_t pid = fork();
            if (pid == 0) {
                /* A hang shows up as SIGXCPU, not as a stuck suite. */
                struct rlimit cpu = { 60, 60 }, core = { 0, 0 };
                setrlimit(RLIMIT_CPU, &cpu);
                setrlimit(RLIMIT_CORE, &core);
                const int fd = open(errf, O_WRONLY | O_CREAT | O_TRUNC, 0644);
                dup2(fd, 2);
                const int nul = open("/dev/null", O_WRONLY);
                dup2(nul, 1);
                execv(bin, argv);
                _exit(127);
            }
            int st = 0;
            waitpid(pid, &st, 0);
            ++runs;
            clock_gettime(CLOCK_MONOTONIC, &t1);
            const double secs = (double) (t1.tv_sec - t0.tv_sec) + 1e-9 * (double) (t1.tv_nsec - t0.tv_nsec);
            if (getenv("HOSTILE_TIMES"))
                fprintf(stderr, "%.3f s: %s %s %s\n", secs, argv[5], argc > 6 ? argv[6] : "",
                        argc > 7 ? argv[7] : "");
            char msg[600] = "";
            FILE *f = fopen(errf, "r");
            if (f) {
                size_t n = fread(msg, 1, sizeof msg - 1, f);
                msg[n] = '\0';
                fclose(f);
            }
            const char *why = NULL;
            if (!WIFEXITED(st)) {
                why = "crashed";
            } else if (WEXITSTATUS(st) == 2) {
                ++refused;
                if (strncmp(msg, "exrfog: ", 8) || strlen(msg) < 20)
                    why = "exit 2 without an \"exrfog: \" message";
                else if (underflows(hostile[h]) && real_valued(&cases[t]) &&
                         !strstr(msg, "out of range"))
                    why = "an underflowing number not reported as out of range";
            } else if (WEXITSTATUS(st) == 0) {
                const long bad = nonfinite(out);
                if (bad < 0)
                    why = "exit 0 but the output cannot be read";
                else if (bad > 0)
                    why = "exit 0 with NaN/inf values in the output";
            } else {
                why = "exit status neither 0 nor 2";
            }
            if (why) {
                ++failures;
                char line[1200] = "", pv[64];
                for (int a = 5; a < argc; ++a) {
                    char pa[300];
                    printable(argv[a], pa, sizeof pa);
                    strncat(line, " ", sizeof line - strlen(line) - 1);
                    strncat(line, pa, sizeof line - strlen(line) - 1);
                }
                printable(hostile[h], pv, sizeof pv);
                fprintf(stderr, "FAIL [%s]:%s: %s (exit %d)\n  %s", pv, line, why,
                        WIFEXITED(st) ? WEXITSTATUS(st) : -WTERMSIG(st), msg);
            }
            for (int a = 5; a < argc; ++a)
                free(argv[a]);
        }
    printf("test_hostile: %ld runs, %ld refused with exit 2, %ld accepted with finite output, "
           "%ld failures\n", runs, refused, runs - refused - failures, failures);
    unlink(out);
    unlink(errf);
    free(in);
    free(out);
    free(errf);
    return failures ? 1 : 0;
}
