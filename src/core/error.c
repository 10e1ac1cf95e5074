#include "error.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void ef_err_set_file(ef_err *err, const char *path)
{
    if (!err)
        return;
    snprintf(err->file_copy, sizeof err->file_copy, "%s", path);
    err->file = err->file_copy;
}

/* The longest '...' span of s longer than keep bytes: its start (after
 * the quote) and length, or NULL. */
static char *longest_quote(char *s, size_t keep, size_t *len)
{
    char *best = NULL;
    *len = 0;
    for (char *a = strchr(s, '\''); a; ) {
        char *b = strchr(a + 1, '\'');
        if (!b)
            break;
        const size_t n = (size_t) (b - a - 1);
        if (n > keep && n > *len) {
            best = a + 1;
            *len = n;
        }
        a = strchr(b + 1, '\'');
    }
    return best;
}

int ef_fail(ef_err *err, const char *fmt, ...)
{
    if (!err)
        return -1;
    va_list ap, ap2;
    va_start(ap, fmt);
    va_copy(ap2, ap);
    const int need = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    char *full = need >= 0 ? malloc((size_t) need + 1) : NULL;
    if (!full) {
        vsnprintf(err->msg, sizeof err->msg, fmt, ap2);
        va_end(ap2);
        return -1;
    }
    vsnprintf(full, (size_t) need + 1, fmt, ap2);
    va_end(ap2);
    /* A message too long for msg loses its longest quoted values' middles
     * (head, an ellipsis and the length stay), so the reason and the fix
     * that follow them always fit. */
    const size_t keep = 60;
    size_t n;
    char *q;
    while (strlen(full) >= sizeof err->msg && (q = longest_quote(full, keep + 24, &n)) != NULL) {
        size_t head = keep;
        while (head > 0 && ((unsigned char) q[head] & 0xc0) == 0x80)
            --head;   /* not inside a UTF-8 sequence */
        char tag[48];
        const int t = snprintf(tag, sizeof tag, "...(%zu bytes)", n);
        memmove(q + head + (size_t) t, q + n, strlen(q + n) + 1);
        memcpy(q + head, tag, (size_t) t);
    }
    snprintf(err->msg, sizeof err->msg, "%s", full);
    free(full);
    return -1;
}
