/* Every line a run shows its host: errors, warnings and notes, each as
 * "exrfog: FILE: ..." on the job's message stream, with names from files
 * escaped; the last error is kept for the library's exrfog_error. */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "job_impl.h"

/* The length of the valid UTF-8 sequence at s (1..4), or 0 when the
 * bytes there are not one (overlong, surrogate, beyond U+10FFFF, cut). */
static int utf8_len(const unsigned char *s)
{
    const unsigned c = s[0];
    int n;
    unsigned min;
    if (c >= 0xc2 && c <= 0xdf)
        n = 2, min = 0x80;
    else if (c >= 0xe0 && c <= 0xef)
        n = 3, min = 0x800;
    else if (c >= 0xf0 && c <= 0xf4)
        n = 4, min = 0x10000;
    else
        return 0;
    unsigned v = c & (0x3fu >> (n - 1));
    for (int k = 1; k < n; ++k) {
        if ((s[k] & 0xc0) != 0x80)
            return 0;
        v = v << 6 | (s[k] & 0x3fu);
    }
    if (v < min || v > 0x10ffff || (v >= 0xd800 && v <= 0xdfff))
        return 0;
    return n;
}

/* Writes s with control bytes and bytes that are not valid UTF-8 as
 * \xNN: names in messages come from the file, and a hostile one must not
 * drive the terminal or garble its encoding. */
void ef_job_put_clean(ef_job *J, const char *s)
{
    FILE *out = J->msg;
    for (const unsigned char *c = (const unsigned char *) s; *c;) {
        if (*c < 0x20 || *c == 0x7f) {
            fprintf(out, "\\x%02x", *c++);
        } else if (*c < 0x80) {
            fputc(*c++, out);
        } else {
            const int n = utf8_len(c);
            if (!n) {
                fprintf(out, "\\x%02x", *c++);
                continue;
            }
            fwrite(c, 1, (size_t) n, out);
            c += n;
        }
    }
}

/* Prints "exrfog: " and the formatted error, keeps it, returns status. */
int ef_job_say(ef_job *J, int status, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(J->last_error, sizeof J->last_error, fmt, ap);
    va_end(ap);
    ef_progress_clear(J->active_pg);
    fputs("exrfog: ", J->msg);
    ef_job_put_clean(J, J->last_error);
    fputc('\n', J->msg);
    return status;
}

/* Prints "exrfog: FILE: message"; the callee's idea of FILE wins. */
int ef_job_report(ef_job *J, const char *file, const ef_err *err, int status)
{
    const char *f = err->file ? err->file : file;
    ef_progress_clear(J->active_pg);
    snprintf(J->last_error, sizeof J->last_error, "%s: %s", f, err->msg);
    fputs("exrfog: ", J->msg);
    ef_job_put_clean(J, f);
    fputs(": ", J->msg);
    ef_job_put_clean(J, err->msg);
    fputc('\n', J->msg);
    return status;
}

/* "exrfog: FILE: warning: TEXT", and the host's warning hook. */
void ef_job_warn(ef_job *J, const char *file, const char *msg)
{
    ef_progress_clear(J->active_pg);
    fputs("exrfog: ", J->msg);
    ef_job_put_clean(J, file);
    fputs(": warning: ", J->msg);
    ef_job_put_clean(J, msg);
    fputc('\n', J->msg);
    if (J->h.warning)
        J->h.warning(J->h.warning_user, file, msg);
}

/* A line for the user that is neither an error nor a warning. */
void ef_job_note(ef_job *J, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    ef_progress_clear(J->active_pg);
    vfprintf(J->msg, fmt, ap);
    va_end(ap);
}
