#include "frames.h"

#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* More frames than this in one --frames list is a typo, not a shot. */
#define EF_MAX_FRAMES 1000000
/* Frame numbers have at most nine digits. */
#define EF_MAX_FRAME 999999999

int ef_frame_pattern_find(const char *path, ef_frame_pattern *p)
{
    memset(p, 0, sizeof *p);
    /* Only the file name may hold the pattern: a directory named "take#2"
     * is a directory. */
    const char *slash = strrchr(path, '/');
    const char *name = slash ? slash + 1 : path;
    for (const char *s = name; *s; ++s) {
        if (*s == '#' || *s == '@') {
            const char c = *s;
            const char *e = s;
            while (*e == c)
                ++e;
            p->has = 1;
            p->at = (size_t) (s - path);
            p->len = (size_t) (e - s);
            p->width = (int) p->len * (c == '#' ? 4 : 1);
            s = e - 1;
        } else if (*s == '%') {
            const char *e = s + 1;
            int w = 0;
            if (*e == '0')
                ++e;
            while (isdigit((unsigned char) *e) && w < 100)
                w = w * 10 + (*e++ - '0');
            if (*e != 'd')
                continue;
            p->has = 1;
            p->at = (size_t) (s - path);
            p->len = (size_t) (e + 1 - s);
            p->width = w;
            s = e;
        }
    }
    return p->has;
}

int ef_frame_path(const char *path, const ef_frame_pattern *p, long frame, char *out, size_t len)
{
    if (!p->has) {
        const int n = snprintf(out, len, "%s", path);
        return n < 0 || (size_t) n >= len ? -1 : 0;
    }
    char num[160];
    const int w = p->width < 100 ? p->width : 100;
    if (frame < 0)
        snprintf(num, sizeof num, "-%0*ld", w > 1 ? w - 1 : 1, -frame);
    else
        snprintf(num, sizeof num, "%0*ld", w, frame);
    const int n = snprintf(out, len, "%.*s%s%s", (int) p->at, path, num, path + p->at + p->len);
    return n < 0 || (size_t) n >= len ? -1 : 0;
}

/* A signed decimal frame number at *s (advanced past it). */
static int read_frame(const char **s, long *v)
{
    const char *b = *s;
    char *end;
    if (!(isdigit((unsigned char) b[0]) || (b[0] == '-' && isdigit((unsigned char) b[1]))))
        return -1;
    errno = 0;
    const long x = strtol(b, &end, 10);
    if (errno || x > EF_MAX_FRAME || x < -EF_MAX_FRAME)
        return -2;
    *v = x;
    *s = end;
    return 0;
}

int ef_frames_parse(const char *text, long **frames, int *n, ef_err *err)
{
    long *f = NULL;
    int cnt = 0, cap = 0;
    *frames = NULL;
    *n = 0;
    const char *s = text;
    int rc = 0;
    while (*s) {
        long a, b, step = 1;
        if ((rc = read_frame(&s, &a)) != 0)
            goto bad;
        b = a;
        if (*s == '-') {
            ++s;
            if ((rc = read_frame(&s, &b)) != 0)
                goto bad;
            if (*s == 'x') {
                ++s;
                if (!isdigit((unsigned char) *s) || (rc = read_frame(&s, &step)) != 0 || step < 1)
                    goto bad;
            }
            if (b < a) {
                free(f);
                return ef_fail(err, "--frames '%s': the range %ld-%ld runs backwards (write "
                                    "%ld-%ld)", text, a, b, b, a);
            }
        }
        for (long k = a; k <= b; k += step) {
            if (cnt >= EF_MAX_FRAMES) {
                free(f);
                return ef_fail(err, "--frames '%s' names more than %d frames", text, EF_MAX_FRAMES);
            }
            if (cnt == cap) {
                cap = cap ? 2 * cap : 64;
                long *nf = realloc(f, (size_t) cap * sizeof *nf);
                if (!nf) {
                    free(f);
                    return ef_fail(err, "out of memory for --frames");
                }
                f = nf;
            }
            f[cnt++] = k;
        }
        if (*s == ',' && s[1])
            ++s;
        else if (*s)
            goto bad;
    }
    if (!cnt)
        goto bad;
    *frames = f;
    *n = cnt;
    return 0;
bad:
    free(f);
    if (rc == -2)
        return ef_fail(err, "--frames '%s': frame numbers run from -%d to %d", text, EF_MAX_FRAME,
                       EF_MAX_FRAME);
    return ef_fail(err, "--frames '%s' is not a frame list (e.g. 1-100, 1-100x2, 1,5,10-20)", text);
}

static int cmp_long(const void *a, const void *b)
{
    const long x = *(const long *) a, y = *(const long *) b;
    return (x > y) - (x < y);
}

int ef_frames_on_disk(const char *path, const ef_frame_pattern *p, long **frames, int *n,
                      ef_err *err)
{
    *frames = NULL;
    *n = 0;
    const char *slash = strrchr(path, '/');
    char dir[4096];
    if (slash)
        snprintf(dir, sizeof dir, "%.*s", slash == path ? 1 : (int) (slash - path), path);
    else
        snprintf(dir, sizeof dir, ".");
    const char *name = slash ? slash + 1 : path;
    const size_t pre = p->at - (size_t) (name - path);
    const char *post = path + p->at + p->len;
    const size_t postlen = strlen(post);
    DIR *d = opendir(dir);
    if (!d) {
        ef_fail(err, "cannot read the directory of the sequence: %s", strerror(errno));
        ef_err_set_file(err, dir);
        return -1;
    }
    long *f = NULL;
    int cnt = 0, cap = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        const char *nm = e->d_name;
        const size_t len = strlen(nm);
        if (len < pre + postlen + 1 || strncmp(nm, name, pre) || strcmp(nm + len - postlen, post))
            continue;
        const char *num = nm + pre, *end = nm + len - postlen;
        const char *dig = num + (*num == '-');
        const size_t nd = (size_t) (end - dig);
        if (nd < 1 || nd > 9)
            continue;
        int ok = 1;
        for (const char *c = dig; c < end; ++c)
            ok &= isdigit((unsigned char) *c) != 0;
        /* Padded patterns: exactly the width (the sign counts in it), or
         * more digits without a leading zero when the number needs them. */
        const size_t total = (size_t) (end - num);
        if (!ok || (p->width > 0 && total < (size_t) p->width) ||
            (p->width > 0 && total > (size_t) p->width && *dig == '0') ||
            (p->width == 0 && nd > 1 && *dig == '0'))
            continue;
        long v = strtol(dig, NULL, 10);
        if (*num == '-')
            v = -v;
        if (cnt >= EF_MAX_FRAMES)
            break;
        if (cnt == cap) {
            cap = cap ? 2 * cap : 64;
            long *nf = realloc(f, (size_t) cap * sizeof *nf);
            if (!nf) {
                free(f);
                closedir(d);
                return ef_fail(err, "out of memory listing the sequence");
            }
            f = nf;
        }
        f[cnt++] = v;
    }
    closedir(d);
    if (cnt)
        qsort(f, (size_t) cnt, sizeof *f, cmp_long);
    *frames = f;
    *n = cnt;
    return 0;
}
