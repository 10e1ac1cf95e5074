/* The job layer: one run of exrfog (a command line's worth of frames and
 * views) as an object on the heap. The program (src/cli) and the library
 * (src/lib) are its two clients; it keeps nothing per process, installs no
 * signal handler and prints only where its hooks say. */
#ifndef EF_JOB_H
#define EF_JOB_H

#include <stddef.h>
#include <stdio.h>

/* Temporary files the host may have to remove on a fatal signal: add is
 * called once a temporary file exists (name: the destination as the user
 * wrote it), drop once it is renamed into place or removed. Both may be
 * called from worker threads of one job, never concurrently for one job. */
typedef struct ef_temp_hooks {
    void (*add)(void *user, const char *tmp, const char *name);
    void (*drop)(void *user, const char *tmp);
    void *user;
} ef_temp_hooks;

/* What a job may do to its host: every field may be 0/NULL. */
typedef struct ef_job_hooks {
    FILE *msg;                /* errors, warnings, notes, -v, --stats; NULL: nowhere */
    FILE *out;                /* --explain, --help, --version; NULL: nowhere */
    int bar;                  /* draw the progress bar on msg when it is a terminal */
    /* The host owns the process's standard error (the program): raw lines
     * other libraries print on descriptor 2 (libpng's) during a read are
     * captured into exrfog's own messages. A library host leaves it 0. */
    int own_stderr;
    /* Called with the fraction done (monotonic, 1.0 at the end of a
     * successful run); a non-zero return cancels the run (status 3). */
    int (*progress)(void *user, double fraction);
    void *progress_user;
    /* Called for every warning with the file it is about and the text
     * (also printed on msg as "exrfog: FILE: warning: TEXT"). */
    void (*warning)(void *user, const char *file, const char *text);
    void *warning_user;
    const ef_temp_hooks *temps;
    /* The run's stop flag, or NULL for one of its own: set by the host
     * (a signal handler, another thread) to stop the run at the next unit
     * of work or noise ray, status 3; the job sets it when the progress
     * hook answers non-zero. */
    _Atomic int *cancel;
} ef_job_hooks;

/* Runs the command line argv[0..argc) (argv[0] is the program's name and
 * is not read as an option). Returns the exit status: 0, 1 runtime error,
 * 2 usage error, 3 cancelled. err receives the last error as "FILE:
 * message" ("" on success). argv is not modified. */
int ef_job_run(const ef_job_hooks *hooks, int argc, const char *const *argv, char *err,
               size_t errlen);

#endif
