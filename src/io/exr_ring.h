/* The ordered writer's ring: workers encode units (bands of chunks, or
 * single chunks) in parallel; a finished unit is parked in the ring, and
 * whoever finds the write turn free writes every consecutive finished unit
 * from the head, so no worker waits for a slow neighbour to be written.
 *
 * Memory bound: a worker may only claim unit u while u < written + nslots,
 * so at most nslots units are pending; with the workers' own buffers, at
 * most nslots + nthreads encoded units exist at once (each at most the
 * unit's raw size, as a chunk that does not shrink is stored raw). A
 * worker waits only when the ring is full, i.e. when the head unit is
 * still being encoded while nslots - 1 later units are done; that time is
 * counted in wait_s.
 *
 * Depends only on pthreads and OpenEXRCore (bench/floor links it too). */
#ifndef EF_EXR_RING_H
#define EF_EXR_RING_H

#include <openexr.h>
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

/* The encoded chunks of one unit, in write order (a row of tiles under
 * --edges: up to 1,024 tiles). */
#define EF_UNIT_MAX_CHUNKS 1024
typedef struct ef_unit_buf {
    uint8_t *data;
    size_t len, cap;
    int n;
    int y[EF_UNIT_MAX_CHUNKS];    /* scanline start, or tile x */
    int ty[EF_UNIT_MAX_CHUNKS];   /* tile y */
    size_t off[EF_UNIT_MAX_CHUNKS], size[EF_UNIT_MAX_CHUNKS];
} ef_unit_buf;

/* Monotonic seconds. */
double ef_now(void);

/* Writes b's chunks to part `part` of out (scanline or one-level tiles).
 * Returns 0, or the failing chunk's index + 1. */
int ef_unit_write(exr_context_t out, int part, int tiled, const ef_unit_buf *b);

/* Appends one chunk's bytes (keyed by y, ty). Returns 0 or -1. */
int ef_unit_append(ef_unit_buf *o, const void *p, size_t n, int y, int ty);
/* Appends one chunk of n bytes for the caller to fill, valid until the next
 * append: returns where they go, or NULL (out of memory or chunks). */
uint8_t *ef_unit_reserve(ef_unit_buf *o, size_t n, int y, int ty);
void ef_unit_free(ef_unit_buf *o);

/* Writes unit u's chunks; called in unit order, one call at a time, with
 * the ring unlocked. Returns 0, or -1 to fail the ring. */
typedef int (*ef_ring_write_fn)(void *user, int u, const ef_unit_buf *b);

typedef struct ef_ring {
    pthread_mutex_t lock;
    pthread_cond_t space;
    int nslots, nunits;
    int next;                 /* next unit to claim */
    int written;              /* units written */
    int writing;              /* a thread is writing the head */
    int failed;
    ef_unit_buf *slot;        /* nslots buffers; slot u % nslots holds unit u */
    uint8_t *ready;           /* slot holds a finished, unwritten unit */
    ef_ring_write_fn write;
    void *user;
    double wait_s;            /* summed over threads: time blocked on a full ring */
} ef_ring;

/* The slot count that keeps nthreads workers busy. */
int ef_ring_slots(int nthreads);

int ef_ring_init(ef_ring *r, int nslots, int nunits, ef_ring_write_fn write, void *user);
void ef_ring_destroy(ef_ring *r);

/* The next unit to work on, or -1 when every unit is claimed or the ring
 * failed. Blocks while the ring is full. */
int ef_ring_claim(ef_ring *r);

/* Parks unit u (claimed here) and writes what is ready when the write turn
 * is free. *b is swapped with an empty buffer of the ring (its memory is
 * reused). Returns 0, or -1 when the ring has failed. */
int ef_ring_put(ef_ring *r, int u, ef_unit_buf *b);

/* Stops the ring: claims return -1, waiters wake. */
void ef_ring_fail(ef_ring *r);

#endif
