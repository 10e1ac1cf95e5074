/* The ordered writer's ring (see exr_ring.h). */
#include "exr_ring.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

double ef_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double) ts.tv_sec + 1e-9 * (double) ts.tv_nsec;
}

int ef_unit_write(exr_context_t out, int part, int tiled, const ef_unit_buf *b)
{
    for (int i = 0; i < b->n; ++i) {
        const exr_result_t rv =
            tiled ? exr_write_tile_chunk(out, part, b->y[i], b->ty[i], 0, 0, b->data + b->off[i],
                                         b->size[i])
                  : exr_write_scanline_chunk(out, part, b->y[i], b->data + b->off[i], b->size[i]);
        if (rv)
            return i + 1;
    }
    return 0;
}

uint8_t *ef_unit_reserve(ef_unit_buf *o, size_t n, int y, int ty)
{
    if (o->n >= EF_UNIT_MAX_CHUNKS)
        return NULL;
    if (o->len + n > o->cap || !o->data) {
        size_t cap = (o->len + n) * 2 + 64;
        uint8_t *d = realloc(o->data, cap);
        if (!d)
            return NULL;
        o->data = d;
        o->cap = cap;
    }
    uint8_t *at = o->data + o->len;
    o->y[o->n] = y;
    o->ty[o->n] = ty;
    o->off[o->n] = o->len;
    o->size[o->n] = n;
    o->n++;
    o->len += n;
    return at;
}

int ef_unit_append(ef_unit_buf *o, const void *p, size_t n, int y, int ty)
{
    uint8_t *at = ef_unit_reserve(o, n, y, ty);
    if (!at)
        return -1;
    memcpy(at, p, n);
    return 0;
}

void ef_unit_free(ef_unit_buf *o)
{
    free(o->data);
    memset(o, 0, sizeof *o);
}

int ef_ring_slots(int nthreads)
{
    /* Each thread can finish about four units past a slow head unit
     * before it waits. */
    return 4 * (nthreads < 1 ? 1 : nthreads);
}

int ef_ring_init(ef_ring *r, int nslots, int nunits, ef_ring_write_fn write, void *user)
{
    memset(r, 0, sizeof *r);
    r->nslots = nslots < 1 ? 1 : nslots;
    r->nunits = nunits;
    r->write = write;
    r->user = user;
    r->slot = calloc((size_t) r->nslots, sizeof *r->slot);
    r->ready = calloc((size_t) r->nslots, 1);
    if (!r->slot || !r->ready) {
        free(r->slot);
        free(r->ready);
        return -1;
    }
    pthread_mutex_init(&r->lock, NULL);
    pthread_cond_init(&r->space, NULL);
    return 0;
}

void ef_ring_destroy(ef_ring *r)
{
    for (int i = 0; r->slot && i < r->nslots; ++i)
        ef_unit_free(&r->slot[i]);
    free(r->slot);
    free(r->ready);
    pthread_mutex_destroy(&r->lock);
    pthread_cond_destroy(&r->space);
}

int ef_ring_claim(ef_ring *r)
{
    int u = -1;
    pthread_mutex_lock(&r->lock);
    while (!r->failed && r->next < r->nunits && r->next >= r->written + r->nslots) {
        const double t0 = ef_now();
        pthread_cond_wait(&r->space, &r->lock);
        r->wait_s += ef_now() - t0;
    }
    if (!r->failed && r->next < r->nunits)
        u = r->next++;
    pthread_mutex_unlock(&r->lock);
    return u;
}

int ef_ring_put(ef_ring *r, int u, ef_unit_buf *b)
{
    pthread_mutex_lock(&r->lock);
    const int s = u % r->nslots;
    ef_unit_buf t = r->slot[s];
    r->slot[s] = *b;
    *b = t;
    b->n = 0;
    b->len = 0;
    r->ready[s] = 1;
    if (!r->writing) {
        r->writing = 1;
        while (!r->failed && r->ready[r->written % r->nslots]) {
            const int w = r->written, ws = w % r->nslots;
            /* Slot ws stays ours while unlocked: nobody claims unit
             * w + nslots before written passes w. */
            pthread_mutex_unlock(&r->lock);
            const int bad = r->write(r->user, w, &r->slot[ws]);
            pthread_mutex_lock(&r->lock);
            r->ready[ws] = 0;
            r->written++;
            if (bad)
                r->failed = 1;
            pthread_cond_broadcast(&r->space);
        }
        r->writing = 0;
    }
    const int failed = r->failed;
    pthread_mutex_unlock(&r->lock);
    return failed ? -1 : 0;
}

void ef_ring_fail(ef_ring *r)
{
    pthread_mutex_lock(&r->lock);
    r->failed = 1;
    pthread_cond_broadcast(&r->space);
    pthread_mutex_unlock(&r->lock);
}
