/* Putting a result in place safely (see output.h). */
#define _GNU_SOURCE 1
#include "output.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

static const char *kind_of(mode_t m)
{
    return S_ISDIR(m)    ? "a directory"
           : S_ISFIFO(m) ? "a FIFO (named pipe)"
           : S_ISCHR(m)  ? "a character device"
           : S_ISBLK(m)  ? "a block device"
           : S_ISSOCK(m) ? "a socket"
                         : "not a regular file";
}

/* Unpredictable letters for the temporary name. */
static void random_tag(char *buf, size_t n)
{
    static const char abc[] = "abcdefghijklmnopqrstuvwxyz0123456789";
    unsigned char r[32];
    if (n > sizeof r)
        n = sizeof r;
    size_t got = 0;
    while (got < n) {
        const ssize_t k = getrandom(r + got, n - got, 0);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0)
            break;
        got += (size_t) k;
    }
    if (got < n) {
        /* No entropy source (very old kernels): time and address bits;
         * O_EXCL still makes the creation safe, only less unpredictable. */
        unsigned long long x = (unsigned long long) time(NULL) ^ (unsigned long long) (size_t) buf;
        for (size_t i = got; i < n; ++i) {
            x = x * 6364136223846793005ULL + 1442695040888963407ULL;
            r[i] = (unsigned char) (x >> 56);
        }
    }
    for (size_t i = 0; i < n; ++i)
        buf[i] = abc[r[i] % 36];
    buf[n] = '\0';
}

/* Splits path into directory ("." when none) and base name. */
static int split(const char *path, char *dir, size_t dlen, const char **base)
{
    const char *slash = strrchr(path, '/');
    if (!slash) {
        snprintf(dir, dlen, ".");
        *base = path;
        return 0;
    }
    const size_t n = slash == path ? 1 : (size_t) (slash - path);
    if (n >= dlen)
        return -1;
    memcpy(dir, path, n);
    dir[n] = '\0';
    *base = slash + 1;
    return 0;
}

int ef_output_open(ef_output *o, const char *name, const char *suffix, const ef_temp_hooks *hooks,
                   ef_err *err)
{
    memset(o, 0, sizeof *o);
    o->fd = -1;
    o->hooks = hooks && hooks->add ? hooks : NULL;
    o->name = name;
    err->file = name;
    if (!name[0])
        return ef_fail(err, "the file name is empty"), 2;
    if (strlen(name) >= sizeof o->path)
        return ef_fail(err, "the path is longer than the system allows (%d bytes)", PATH_MAX), 2;
    snprintf(o->path, sizeof o->path, "%s", name);
    struct stat st;
    if (lstat(name, &st) == 0 && S_ISLNK(st.st_mode)) {
        /* Written through to the target, as cp and oiiotool do: the link stays. */
        if (stat(name, &st) != 0)
            return ef_fail(err, "is a symbolic link to a missing file; exrfog writes through links "
                                "only to existing files (remove the link, or create its target)"),
                   2;
        char *real = realpath(name, NULL);
        if (!real)
            return ef_fail(err, "cannot resolve the symbolic link: %s", strerror(errno)), 1;
        const int too_long = strlen(real) >= sizeof o->path;
        if (!too_long)
            snprintf(o->path, sizeof o->path, "%s", real);
        free(real);
        if (too_long)
            return ef_fail(err, "the link's target path is too long"), 1;
    }
    if (lstat(o->path, &st) == 0) {
        if (!S_ISREG(st.st_mode))
            return ef_fail(err, "is %s; exrfog replaces only regular files (give a file name)",
                           kind_of(st.st_mode)),
                   2;
        o->existed = 1;
        o->dev = st.st_dev;
        o->ino = st.st_ino;
    } else if (errno != ENOENT) {
        return ef_fail(err, "cannot use this path: %s", strerror(errno)), errno == ENOTDIR ? 2 : 1;
    }
    char dir[PATH_MAX];
    const char *base;
    if (split(o->path, dir, sizeof dir, &base))
        return ef_fail(err, "the path is too long"), 2;
    if (!base[0])
        return ef_fail(err, "names a directory; give a file name"), 2;
    struct stat ds;
    if (stat(dir, &ds) != 0)
        return ef_fail(err, "its directory %s %s", dir,
                       errno == ENOENT ? "does not exist (create it first)" : strerror(errno)),
               1;
    if (!S_ISDIR(ds.st_mode))
        return ef_fail(err, "%s is not a directory", dir), 2;
    /* .NAME.exrfog-PID-RANDOM.tmp[suffix], shortened so it fits NAME_MAX. */
    long name_max = pathconf(dir, _PC_NAME_MAX);
    if (name_max <= 0 || name_max > 4096)
        name_max = 255;
    char tag[16];
    for (int attempt = 0; attempt < 16; ++attempt) {
        random_tag(tag, 10);
        char tail[96];
        snprintf(tail, sizeof tail, ".exrfog-%ld-%s.tmp%s", (long) getpid(), tag,
                 suffix ? suffix : "");
        long keep = name_max - 1 - (long) strlen(tail);
        if (keep < 1)
            return ef_fail(err, "the file system's names are too short for a temporary file"), 1;
        size_t nb = strlen(base);
        if ((long) nb > keep) {
            nb = (size_t) keep;
            while (nb > 0 && ((unsigned char) base[nb] & 0xc0) == 0x80)
                --nb;  /* not inside a UTF-8 sequence */
        }
        const int n = !strchr(o->path, '/')
                          ? snprintf(o->tmp, sizeof o->tmp, ".%.*s%s", (int) nb, base, tail)
                          : snprintf(o->tmp, sizeof o->tmp, "%s%s.%.*s%s", dir,
                                     strcmp(dir, "/") ? "/" : "", (int) nb, base, tail);
        if (n < 0 || (size_t) n >= sizeof o->tmp)
            return ef_fail(err, "the path is too long for a temporary file beside it"), 1;
        o->fd = open(o->tmp, O_RDWR | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC,
                     o->existed ? 0600 : 0666);
        if (o->fd >= 0)
            break;
        if (errno != EEXIST) {
            const int e = errno;
            o->tmp[0] = '\0';
            return ef_fail(err, "cannot create a file in %s: %s%s", dir, strerror(e),
                           e == EACCES || e == EPERM ? " (write elsewhere, or fix the permissions)"
                           : e == ENOSPC             ? " (free some space)"
                           : e == EROFS              ? " (write elsewhere)"
                                                     : ""),
                   1;
        }
    }
    if (o->fd < 0) {
        o->tmp[0] = '\0';
        return ef_fail(err, "cannot find a free temporary name in %s", dir), 1;
    }
    if (o->hooks)
        o->hooks->add(o->hooks->user, o->tmp, name);
    if (o->existed) {
        /* The owner first: chown clears set-id bits, fchmod restores them. */
        if (fchown(o->fd, st.st_uid, st.st_gid) != 0) {
            int r = fchown(o->fd, (uid_t) -1, st.st_gid);
            (void) r;
        }
        if (fchmod(o->fd, st.st_mode & 07777) != 0) {
            const int e = errno;
            ef_output_abort(o);
            return ef_fail(err, "cannot give the new file the old one's permissions: %s",
                           strerror(e)),
                   1;
        }
    }
    err->file = NULL;
    return 0;
}

int ef_output_commit(ef_output *o, ef_err *err)
{
    /* The temporary name must still be the file written through fd: one
     * who can write the directory could have put a link of theirs there,
     * which the rename would make OUTPUT. */
    struct stat mine, now;
    const int have = o->fd >= 0 && fstat(o->fd, &mine) == 0;
    if (o->fd >= 0) {
        const int rc = close(o->fd);
        o->fd = -1;
        if (rc != 0) {
            const int e = errno;
            ef_output_abort(o);
            ef_fail(err, "cannot write the output: %s", strerror(e));
            err->file = o->name;
            return 1;
        }
    }
    if (have && (lstat(o->tmp, &now) != 0 || !S_ISREG(now.st_mode) || now.st_dev != mine.st_dev ||
                 now.st_ino != mine.st_ino)) {
        /* Not ours to remove or move: the name is someone else's now. */
        if (o->hooks && o->hooks->drop)
            o->hooks->drop(o->hooks->user, o->tmp);
        ef_fail(err, "the temporary file %s was replaced while exrfog ran (someone else writes "
                     "this directory); nothing was written", o->tmp);
        o->tmp[0] = '\0';
        err->file = o->name;
        return 1;
    }
    if (rename(o->tmp, o->path) != 0) {
        const int e = errno;
        ef_output_abort(o);
        ef_fail(err, "cannot move the finished file into place: %s", strerror(e));
        err->file = o->name;
        return 1;
    }
    if (o->hooks && o->hooks->drop)
        o->hooks->drop(o->hooks->user, o->tmp);
    o->tmp[0] = '\0';
    return 0;
}

void ef_output_abort(ef_output *o)
{
    if (o->fd >= 0) {
        close(o->fd);
        o->fd = -1;
    }
    if (o->tmp[0]) {
        if (o->hooks && o->hooks->drop)
            o->hooks->drop(o->hooks->user, o->tmp);
        unlink(o->tmp);
        o->tmp[0] = '\0';
    }
}

int ef_output_same_file(const char *a, const char *b)
{
    struct stat sa, sb;
    return stat(a, &sa) == 0 && stat(b, &sb) == 0 && sa.st_dev == sb.st_dev &&
           sa.st_ino == sb.st_ino;
}
