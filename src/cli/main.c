/* The exrfog program: the job layer's run with the terminal's hooks (stderr
 * for messages, stdout for --explain, the progress bar) and the handlers
 * that remove the run's temporary files on a fatal signal. The program is
 * the only part of exrfog that installs signal handlers. */
#include <stdio.h>
#include <string.h>

#include "job.h"
#include "signals.h"

int main(int argc, char **argv)
{
    ef_cli_signals_install();
    const ef_job_hooks hooks = { .msg = stderr, .out = stdout, .bar = 1, .own_stderr = 1,
                                 .temps = ef_cli_signal_temps() };
    char err[16];
    return ef_job_run(&hooks, argc, (const char *const *) argv, err, sizeof err);
}
