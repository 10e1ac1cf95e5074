/* Putting a result in place safely: a temporary file created exclusively
 * beside the destination, renamed over it only when everything succeeded,
 * removed on failure and on every catchable fatal signal. */
#ifndef EF_OUTPUT_H
#define EF_OUTPUT_H

#include <limits.h>
#include <sys/types.h>

#include "error.h"
#include "job.h"

typedef struct ef_output {
    const char *name;          /* as the user gave it: every message names it */
    char path[PATH_MAX];       /* where the result goes: name, or its symlink's target */
    char tmp[PATH_MAX];        /* the temporary file, while it exists */
    int fd;                    /* open on tmp, or -1 */
    int existed;               /* path held a regular file: its mode and owner are kept */
    dev_t dev;
    const ef_temp_hooks *hooks;   /* told of the temporary file, or NULL */
    ino_t ino;
} ef_output;

/* Checks that name is a regular file or does not exist (a symlink is
 * followed to its target, which must exist), and creates the temporary
 * file .NAME.exrfog-PID-RANDOM.tmp[suffix] in the destination's directory
 * (O_EXCL, O_NOFOLLOW; the destination's permission bits and, when
 * allowed, owner). Tells hooks of it (for removal on a fatal signal). Returns 0,
 * 2 for a usage error (a directory, FIFO, device, socket, dangling link),
 * or 1 (the directory is missing or not writable...), with err set. */
int ef_output_open(ef_output *o, const char *name, const char *suffix, const ef_temp_hooks *hooks,
                   ef_err *err);

/* Closes the temporary file (fd stays open when keep_fd) and renames it
 * over the destination. Returns 0, or 1 with err set (the temporary file
 * is then removed). */
int ef_output_commit(ef_output *o, ef_err *err);

/* Closes and removes the temporary file, if any. Safe to call twice. */
void ef_output_abort(ef_output *o);


/* Whether two paths name the same existing file. */
int ef_output_same_file(const char *a, const char *b);

#endif
