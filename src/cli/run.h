/* The exrfog program: options -> files -> camera -> stream -> output. */
#ifndef EF_RUN_H
#define EF_RUN_H

/* Runs exrfog; returns the exit status (0 ok, 1 runtime error, 2 usage). */
int ef_main(int argc, char **argv);

#include <stdio.h>

/* ef_main for the library (exrfog_run): messages go to msgs (NULL:
 * stderr), --explain to out (NULL: stdout), progress (may be NULL) gets the fraction done and stops the run
 * by returning non-zero (status 3), and err receives the last error as
 * "FILE: message" ("" on success). One run at a time per process. */
int ef_run_lib(int argc, char **argv, FILE *msgs, FILE *out, int (*progress)(void *, double),
               void *user, char *err, size_t errlen);

#endif
