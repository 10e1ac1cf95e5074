/* The program's fatal-signal handling: the temporary files a signal must
 * remove, and the line that says which signal stopped the run. */
#ifndef EF_CLI_SIGNALS_H
#define EF_CLI_SIGNALS_H

#include "job.h"

/* Installs the handlers for every catchable fatal signal the caller does
 * not ignore; each removes the registered temporary files, says which
 * signal stopped the run (once one exists) and dies by the same signal. */
void ef_cli_signals_install(void);

/* The hooks a job registers its temporary files through. */
const ef_temp_hooks *ef_cli_signal_temps(void);

#endif
