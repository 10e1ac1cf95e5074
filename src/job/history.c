/* exrfog/history: the line a run adds to the output's header. */
#include <stdlib.h>
#include <string.h>

#include "job_impl.h"
#include "version.h"


/* Appends s to the buffer b (growing it); returns -1 when out of memory. */
static int grow(char **b, size_t *len, size_t *cap, const char *s, size_t n)
{
    if (*len + n + 1 > *cap) {
        size_t c = *cap ? *cap : 256;
        while (*len + n + 1 > c)
            c *= 2;
        char *nb = realloc(*b, c);
        if (!nb)
            return -1;
        *b = nb;
        *cap = c;
    }
    memcpy(*b + *len, s, n);
    *len += n;
    (*b)[*len] = '\0';
    return 0;
}

/* Appends a, quoted for a POSIX shell when it needs it. */
static int grow_quoted(char **b, size_t *len, size_t *cap, const char *a)
{
    int plain = a[0] != '\0';
    for (const char *c = a; *c; ++c)
        plain &= (*c >= 'a' && *c <= 'z') || (*c >= 'A' && *c <= 'Z') || (*c >= '0' && *c <= '9') ||
                 strchr("_@%+=:,./-", *c) != NULL;
    if (plain)
        return grow(b, len, cap, a, strlen(a));
    if (grow(b, len, cap, "'", 1))
        return -1;
    for (const char *c = a; *c; ++c)
        if (*c == '\'' ? grow(b, len, cap, "'\\''", 4) : grow(b, len, cap, c, 1))
            return -1;
    return grow(b, len, cap, "'", 1);
}

/* The line this run adds to exrfog/history: the version, the command line
 * shell-quoted (less what cannot change the output) and the scene file's
 * contents as read, indented. NULL when out of memory. */
char *ef_history_line(int argc, char **argv, const char *scene_file, const char *scene_text)
{
    char *b = NULL;
    size_t len = 0, cap = 0;
    if (grow(&b, &len, &cap, "exrfog " EXRFOG_VERSION ":", strlen("exrfog " EXRFOG_VERSION ":")))
        return NULL;
    for (int i = 0; i < argc;) {
        /* what cannot change the output is left out (args.c's one list),
         * so that equal outputs get equal headers */
        const int skip = i ? ef_option_neutral_span(argv, argc, i) : 0;
        if (skip) {
            i += skip;
            continue;
        }
        if (grow(&b, &len, &cap, " ", 1) || grow_quoted(&b, &len, &cap, i ? argv[i] : "exrfog")) {
            free(b);
            return NULL;
        }
        ++i;
    }
    if (scene_file && scene_text) {
        int fail = grow(&b, &len, &cap, "\n  scene ", 9) ||
                   grow(&b, &len, &cap, scene_file, strlen(scene_file)) ||
                   grow(&b, &len, &cap, ":", 1);
        for (const char *l = scene_text; !fail && *l;) {
            const char *nl = strchr(l, '\n');
            const size_t n = nl ? (size_t) (nl - l) : strlen(l);
            fail = grow(&b, &len, &cap, "\n    ", 5) || grow(&b, &len, &cap, l, n);
            l += n + (nl != NULL);
        }
        if (fail) {
            free(b);
            return NULL;
        }
    }
    return b;
}
