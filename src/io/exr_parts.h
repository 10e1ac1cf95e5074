/* Copying a part of an EXR file into another as it is (exr_parts.c): the
 * header, the chunks undecoded, and the output file's writer; what the flat
 * stream and the deep pass both do to the parts beside the one they fog. */
#ifndef EF_EXR_PARTS_H
#define EF_EXR_PARTS_H

#include "exr_io.h"

#include <stddef.h>
#include <stdint.h>

/* Whether part p of f is deep (scanline or tiled). */
int ef_exr_part_is_deep(const ef_exr_file *f, int part);

/* Grows the buffer *p of *cap bytes to at least need bytes (doubling).
 * Returns 0, or -1 when out of memory (*p is then unchanged). */
int ef_deep_grow(void **p, size_t *cap, size_t need);

/* The attributes of in's part pin onto out's part pout (which has its
 * channels, compression and storage already): exrfog/parameters = params
 * and this run's history line appended to exrfog/history (each NULL:
 * none), user-typed attributes, then every attribute not yet set, checked
 * one by one (Core 3.1.5 can stop copying early yet report success). */
int ef_exr_copy_attrs(const ef_exr_file *in, int pin, exr_context_t out, int pout,
                      const char *params, const char *history, ef_err *err);

/* Core's write_fn to a descriptor the caller created (pwrite; EINTR
 * retried): user is an ef_exr_sink, whose errnum keeps the first error. */
typedef struct ef_exr_sink {
    int fd;
    int errnum;
} ef_exr_sink;
int64_t ef_exr_sink_write(exr_const_context_t ctx, void *user, const void *buf, uint64_t sz,
                          uint64_t off, exr_stream_error_func_ptr_t error_cb);

/* Adds part p of in to out (its next part, index p) as it is: storage,
 * tiles (one level; mip and rip maps are refused), channels, compression,
 * line order and every attribute, plus history and parameters. */
int ef_exr_define_part_copy(const ef_exr_file *in, int p, exr_context_t out,
                            const char *history, const char *params, ef_err *err);
/* Copies every chunk of part p of in, flat or deep, scanline or tiled, into
 * part p of out as it is (no decoding), in increasing y. */
int ef_exr_copy_part_chunks(const ef_exr_file *in, int p, exr_context_t out, ef_err *err);

#endif
