/* The program's fatal-signal handling (see signals.h). Process state is
 * right here: the program runs one job, and a handler can read nothing
 * but statics. */
#define _GNU_SOURCE 1
#include "signals.h"

#include <limits.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

/* The temporary files a signal must remove, and the message it prints.
 * Written before a slot is marked live, read only by the handler. */
#define SLOTS 6
static char slot_path[SLOTS][PATH_MAX];
static volatile sig_atomic_t slot_live[SLOTS];
static char sig_prefix[PATH_MAX + 64];
static volatile sig_atomic_t sig_prefix_len;

static const struct {
    int sig;
    const char *what;
} fatal[] = {
    { SIGINT, "SIGINT (interrupted)" },
    { SIGTERM, "SIGTERM (terminated)" },
    { SIGHUP, "SIGHUP (the terminal went away)" },
    { SIGQUIT, "SIGQUIT (quit)" },
    { SIGPIPE, "SIGPIPE (a pipe closed)" },
    { SIGXFSZ, "SIGXFSZ (the file size limit, see ulimit -f)" },
    { SIGXCPU, "SIGXCPU (the CPU time limit, see ulimit -t)" },
    { SIGALRM, "SIGALRM (an alarm, e.g. timeout)" },
    { SIGVTALRM, "SIGVTALRM (a timer)" },
    { SIGPROF, "SIGPROF (a profiling timer)" },
    { SIGUSR1, "SIGUSR1" },
    { SIGUSR2, "SIGUSR2" },
#if !defined(__SANITIZE_ADDRESS__)
    /* Faults: under ASan its own report matters more. */
    { SIGSEGV, "SIGSEGV (a crash: please report it)" },
    { SIGBUS, "SIGBUS (a bus error: the input may have changed while read)" },
    { SIGFPE, "SIGFPE (a crash: please report it)" },
    { SIGILL, "SIGILL (a crash: please report it)" },
    { SIGABRT, "SIGABRT (aborted)" },
#endif
};

static void put(const char *s)
{
    ssize_t r = write(2, s, strlen(s));
    (void) r;
}

/* Async-signal-safe: unlink, write, then die by the same signal. */
static void on_fatal(int sig)
{
    int removed = 0;
    for (int i = 0; i < SLOTS; ++i)
        if (slot_live[i]) {
            slot_live[i] = 0;
            removed |= unlink(slot_path[i]) == 0;
        }
    if (sig_prefix_len) {
        ssize_t r = write(2, sig_prefix, (size_t) sig_prefix_len);
        (void) r;
        const char *what = "a signal";
        for (size_t k = 0; k < sizeof fatal / sizeof fatal[0]; ++k)
            if (fatal[k].sig == sig)
                what = fatal[k].what;
        put("stopped by ");
        put(what);
        put(removed ? "; the output was not written (temporary file removed)\n"
                    : "; the output was not written\n");
    }
    signal(sig, SIG_DFL);
    raise(sig);
}

void ef_cli_signals_install(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_fatal;
    sigemptyset(&sa.sa_mask);
    for (size_t k = 0; k < sizeof fatal / sizeof fatal[0]; ++k)
        sigaddset(&sa.sa_mask, fatal[k].sig);
    for (size_t k = 0; k < sizeof fatal / sizeof fatal[0]; ++k) {
        struct sigaction old;
        /* A signal the caller ignores (nohup, SIG_IGN for SIGPIPE) stays ignored. */
        if (sigaction(fatal[k].sig, NULL, &old) == 0 && old.sa_handler == SIG_IGN)
            continue;
        sigaction(fatal[k].sig, &sa, NULL);
    }
}

/* "exrfog: NAME: " with control and non-ASCII bytes escaped, for the handler. */
static void set_prefix(const char *name)
{
    size_t n = 0;
    const size_t cap = sizeof sig_prefix - 8;
    n += (size_t) snprintf(sig_prefix, cap, "exrfog: ");
    for (const unsigned char *c = (const unsigned char *) name; *c && n + 5 < cap; ++c) {
        if (*c < 0x20 || *c >= 0x7f)
            n += (size_t) snprintf(sig_prefix + n, cap - n, "\\x%02x", *c);
        else
            sig_prefix[n++] = (char) *c;
    }
    sig_prefix[n++] = ':';
    sig_prefix[n++] = ' ';
    sig_prefix[n] = '\0';
    sig_prefix_len = (sig_atomic_t) n;
}

static int slot_of(const char *tmp)
{
    for (int i = 0; i < SLOTS; ++i)
        if (slot_live[i] && strcmp(slot_path[i], tmp) == 0)
            return i;
    return -1;
}

static void slot_add(const char *tmp)
{
    for (int i = 0; i < SLOTS; ++i)
        if (!slot_live[i]) {
            snprintf(slot_path[i], sizeof slot_path[i], "%s", tmp);
            slot_live[i] = 1;
            return;
        }
}

static void slot_drop(const char *tmp)
{
    const int i = slot_of(tmp);
    if (i >= 0)
        slot_live[i] = 0;
}

/* The slots are written only from the job's thread that opens or closes
 * outputs; the handler reads a slot only once it is marked live. */
static void temp_add(void *user, const char *tmp, const char *name)
{
    (void) user;
    /* The first temporary file of a frame names the frame's output: a
     * signal in frame 3 of a sequence names frame 3's. (A signal while the
     * prefix is rewritten finds its length 0 and says nothing.) */
    int live = 0;
    for (int i = 0; i < SLOTS; ++i)
        live |= slot_live[i] != 0;
    if (!live) {
        sig_prefix_len = 0;
        set_prefix(name);
    }
    slot_add(tmp);
}

static void temp_drop(void *user, const char *tmp)
{
    (void) user;
    slot_drop(tmp);
}

static const ef_temp_hooks temps = { temp_add, temp_drop, NULL };

const ef_temp_hooks *ef_cli_signal_temps(void)
{
    return &temps;
}
