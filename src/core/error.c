#include "error.h"

#include <stdarg.h>
#include <stdio.h>

void ef_err_set_file(ef_err *err, const char *path)
{
    if (!err)
        return;
    snprintf(err->file_copy, sizeof err->file_copy, "%s", path);
    err->file = err->file_copy;
}

int ef_fail(ef_err *err, const char *fmt, ...)
{
    if (err) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err->msg, sizeof err->msg, fmt, ap);
        va_end(ap);
    }
    return -1;
}
