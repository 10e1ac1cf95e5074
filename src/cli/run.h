/* The exrfog program: options -> files -> camera -> stream -> output. */
#ifndef EF_RUN_H
#define EF_RUN_H

/* Runs exrfog; returns the exit status (0 ok, 1 runtime error, 2 usage). */
int ef_main(int argc, char **argv);

#endif
