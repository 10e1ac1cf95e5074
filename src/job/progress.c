/* The progress of a run: the host's hook hears the fraction done after
 * every unit of work (monotonic, exactly 1.0 at the end of a successful
 * run), and on a terminal a bar shows frames, pixels, elapsed time and ETA. */
#include <math.h>
#include <stdio.h>
#include <time.h>

#include "job_impl.h"

static double wall_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double) ts.tv_sec + 1e-9 * (double) ts.tv_nsec;
}

static void hms(char *b, size_t n, double s)
{
    const long t = s > 0 && s < 1e7 ? (long) (s + 0.5) : 0;
    if (t >= 3600)
        snprintf(b, n, "%ld:%02ld:%02ld", t / 3600, t / 60 % 60, t % 60);
    else
        snprintf(b, n, "%ld:%02ld", t / 60, t % 60);
}

void ef_progress_init(ef_progress *pg, FILE *msg)
{
    pthread_mutex_init(&pg->lock, NULL);
    pg->t0 = wall_now();
    pg->msg = msg;
}

/* The share of the run done: finished frames plus the current one's. */
static double progress_fraction(const ef_progress *pg)
{
    const double px = (double) pg->px;
    const double frac = pg->frame_px > 0 ? (px < pg->frame_px ? px / pg->frame_px : 1.0) : 0.0;
    return pg->nframes > 0 ? (pg->done + frac) / pg->nframes : frac;
}

/* Draws the bar (pg->lock held). */
static void progress_draw(ef_progress *pg, double t)
{
    const double px = (double) pg->px;
    const double all = progress_fraction(pg);
    char bar[31], el[32], eta[32], fr[64] = "";
    const int fill = (int) (all * 30.0);
    for (int i = 0; i < 30; ++i)
        bar[i] = i < fill ? '#' : '.';
    bar[30] = '\0';
    hms(el, sizeof el, t - pg->t0);
    if (all > 0.001)
        hms(eta, sizeof eta, (t - pg->t0) * (1.0 - all) / all);
    else
        snprintf(eta, sizeof eta, "?");
    if (pg->has_frame)
        snprintf(fr, sizeof fr, "frame %ld (%d/%d) ", pg->frame, pg->done + 1, pg->nframes);
    fprintf(pg->msg, "\r\033[Kexrfog: %s[%s] %3.0f%%  %.1f Mpx  %s elapsed  ETA %s", fr, bar,
            100.0 * all, (pg->px_total + px) / 1e6, el, eta);
    fflush(pg->msg);
    pg->drawn = 1;
    pg->last = t;
}

/* Tells the hook f unless it heard as much already (pg->lock held); a
 * non-zero answer cancels the run. Never 1.0 before the run has ended. */
static void tell(ef_job *J, double f, int final)
{
    ef_progress *pg = &J->pg;
    if (!final && f >= 1.0)
        f = nextafter(1.0, 0.0);
    if (!pg->hook || f <= pg->reported || ef_job_cancelled(J))
        return;   /* a stopped run has nothing more to report */
    pg->reported = f;
    if (pg->hook(pg->hook_user, f))
        atomic_store(J->stop, 1);
}

void ef_progress_add(ef_job *J, long px)
{
    ef_progress *pg = J->active_pg;
    if (!pg)
        return;
    pthread_mutex_lock(&pg->lock);
    pg->px += px;
    tell(J, progress_fraction(pg), 0);
    const double t = pg->draw ? wall_now() : 0;
    if (pg->draw && t - pg->last >= 0.2)
        progress_draw(pg, t);
    pthread_mutex_unlock(&pg->lock);
}

void ef_progress_frame_done(ef_job *J)
{
    ef_progress *pg = J->active_pg;
    if (!pg)
        return;
    pthread_mutex_lock(&pg->lock);
    pg->done++;
    pg->px_total += pg->frame_px;
    pg->frame_px = 0;
    pg->px = 0;
    tell(J, progress_fraction(pg), 0);
    pthread_mutex_unlock(&pg->lock);
}

void ef_progress_finish(ef_job *J)
{
    ef_progress *pg = J->active_pg;
    if (!pg)
        return;
    pthread_mutex_lock(&pg->lock);
    tell(J, 1.0, 1);
    pthread_mutex_unlock(&pg->lock);
}

/* Takes the bar off the terminal so a message can be printed. */
void ef_progress_clear(ef_progress *pg)
{
    if (!pg || !pg->drawn)
        return;
    pthread_mutex_lock(&pg->lock);
    fputs("\r\033[K", pg->msg);
    fflush(pg->msg);
    pg->drawn = 0;
    pg->last = 0;
    pthread_mutex_unlock(&pg->lock);
}
