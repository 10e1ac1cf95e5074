/* The option scanner (see argscan.h): the algorithm of glibc's
 * _getopt_internal_r, so that every command line is read, permuted and
 * reported exactly as the program always read it. */
#include "argscan.h"

#include <stdlib.h>
#include <string.h>

void ef_argscan_init(ef_argscan *s)
{
    memset(s, 0, sizeof *s);
    s->optind = 1;
    s->first_nonopt = s->last_nonopt = 1;
    s->require_order = getenv("POSIXLY_CORRECT") != NULL;
}

static void reverse(char **a, int lo, int hi)
{
    for (--hi; lo < hi; ++lo, --hi) {
        char *t = a[lo];
        a[lo] = a[hi];
        a[hi] = t;
    }
}

/* Moves the skipped non-options [first, last) after the options scanned
 * since, [last, optind), keeping both orders (what glibc's exchange does). */
static void exchange(ef_argscan *s, char **argv)
{
    reverse(argv, s->first_nonopt, s->last_nonopt);
    reverse(argv, s->last_nonopt, s->optind);
    reverse(argv, s->first_nonopt, s->optind);
    s->first_nonopt += s->optind - s->last_nonopt;
    s->last_nonopt = s->optind;
}

static int nonoption(char *const *argv, int i)
{
    return argv[i][0] != '-' || argv[i][1] == '\0';
}

static int long_option(ef_argscan *s, int argc, char **argv, const char *optstring,
                       const struct option *longopts)
{
    const char *name = s->nextchar, *end = name;
    while (*end && *end != '=')
        ++end;
    const size_t n = (size_t) (end - name);
    const struct option *found = NULL;
    for (const struct option *p = longopts; p->name; ++p)
        if (!strncmp(p->name, name, n) && strlen(p->name) == n) {
            found = p;
            break;
        }
    if (!found) {
        int ambiguous = 0;
        for (const struct option *p = longopts; p->name; ++p)
            if (!strncmp(p->name, name, n)) {
                if (!found)
                    found = p;
                else if (found->has_arg != p->has_arg || found->flag != p->flag ||
                         found->val != p->val)
                    ambiguous = 1;
            }
        if (ambiguous) {
            s->nextchar = NULL;
            s->optind++;
            s->optopt = 0;
            return '?';
        }
    }
    if (!found) {
        s->nextchar = NULL;
        s->optind++;
        s->optopt = 0;
        return '?';
    }
    s->optind++;
    s->nextchar = NULL;
    if (*end) {
        if (!found->has_arg) {
            s->optopt = found->val;
            return '?';
        }
        s->optarg = end + 1;
    } else if (found->has_arg == required_argument) {
        if (s->optind >= argc) {
            s->optopt = found->val;
            return optstring[0] == ':' ? ':' : '?';
        }
        s->optarg = argv[s->optind++];
    }
    return found->val;
}

int ef_argscan_next(ef_argscan *s, int argc, char **argv, const char *optstring,
                    const struct option *longopts)
{
    if (argc < 1)
        return -1;
    s->optarg = NULL;
    if (!s->nextchar || !*s->nextchar) {
        if (s->last_nonopt > s->optind)
            s->last_nonopt = s->optind;
        if (s->first_nonopt > s->optind)
            s->first_nonopt = s->optind;
        if (!s->require_order) {
            if (s->first_nonopt != s->last_nonopt && s->last_nonopt != s->optind)
                exchange(s, argv);
            else if (s->last_nonopt != s->optind)
                s->first_nonopt = s->optind;
            while (s->optind < argc && nonoption(argv, s->optind))
                s->optind++;
            s->last_nonopt = s->optind;
        }
        if (s->optind != argc && !strcmp(argv[s->optind], "--")) {
            s->optind++;
            if (s->first_nonopt != s->last_nonopt && s->last_nonopt != s->optind)
                exchange(s, argv);
            else if (s->first_nonopt == s->last_nonopt)
                s->first_nonopt = s->optind;
            s->last_nonopt = argc;
            s->optind = argc;
        }
        if (s->optind == argc) {
            if (s->first_nonopt != s->last_nonopt)
                s->optind = s->first_nonopt;
            return -1;
        }
        if (nonoption(argv, s->optind)) {
            /* only in require order (permutation skipped every one) */
            return -1;
        }
        if (argv[s->optind][1] == '-') {
            s->nextchar = argv[s->optind] + 2;
            return long_option(s, argc, argv, optstring, longopts);
        }
        s->nextchar = argv[s->optind] + 1;
    }
    const char c = *s->nextchar++;
    const char *spec = strchr(optstring, c);
    if (*s->nextchar == '\0')
        ++s->optind;
    if (!spec || c == ':' || c == ';') {
        s->optopt = c;
        return '?';
    }
    if (spec[1] == ':') {
        if (*s->nextchar != '\0') {
            s->optarg = s->nextchar;
            s->optind++;
        } else if (s->optind == argc) {
            s->optopt = c;
            s->nextchar = NULL;
            return optstring[0] == ':' ? ':' : '?';
        } else {
            s->optarg = argv[s->optind++];
        }
        s->nextchar = NULL;
    }
    return c;
}
