/* Error reporting shared by every layer: a message buffer the caller owns.
 * Messages say what is wrong and, when known, how to fix it; the CLI adds
 * the "exrfog: FILE: " prefix. */
#ifndef EF_ERROR_H
#define EF_ERROR_H

#include <stddef.h>

typedef struct ef_err {
    char msg[1024];
    const char *file;   /* the file the message is about, when the callee knows better */
    char file_copy[4096];  /* backs file when the path dies with the callee's data */
} ef_err;

/* Points err->file at a copy of path kept in err itself (err may be NULL),
 * for paths owned by something the failure releases. */
void ef_err_set_file(ef_err *err, const char *path);

/* Formats into err->msg (printf-style) and returns -1, so callers can
 * `return ef_fail(err, ...)`. err may be NULL. */
int ef_fail(ef_err *err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

#endif
