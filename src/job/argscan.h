/* A reentrant scanner of command-line options with GNU getopt_long's
 * behaviour (permutation, "--", abbreviated long options, clusters of
 * short options, ':' and '?' returns), but with its state in the caller's
 * struct: any number of runs may parse at once, and the host's own getopt
 * state (optind, optarg) is never touched. */
#ifndef EF_ARGSCAN_H
#define EF_ARGSCAN_H

#include <getopt.h>

typedef struct ef_argscan {
    int optind;               /* the next element of argv to scan */
    const char *optarg;       /* the current option's value, or NULL */
    int optopt;               /* the option character of a '?' or ':' return */
    /* private */
    const char *nextchar;     /* inside a cluster of short options */
    int first_nonopt, last_nonopt;
    int require_order;        /* POSIXLY_CORRECT: stop at the first non-option */
} ef_argscan;

/* Prepares s for a scan of a fresh argv. */
void ef_argscan_init(ef_argscan *s);

/* As getopt_long(argc, argv, optstring, longopts, NULL) with opterr = 0:
 * returns the option's value, ':' (when optstring starts with ':') for a
 * missing value, '?' for an unknown, ambiguous or misused option, or -1 at
 * the end, when s->optind is the first non-option. argv is permuted as
 * glibc permutes it (non-options moved after the options). */
int ef_argscan_next(ef_argscan *s, int argc, char **argv, const char *optstring,
                    const struct option *longopts);

#endif
