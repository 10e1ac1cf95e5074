/* DWAA/DWAB through the OpenEXR C++ library (OpenEXRCore 3.1.5 cannot
 * decode or encode DWA): a whole-file transcoder that streams every part
 * block by block, so exrfog can turn a DWA input into a file Core reads and
 * Core's output into a DWA file. C interface over src/io/exr_dwa.cpp. */
#ifndef EF_EXR_DWA_H
#define EF_EXR_DWA_H

#include <stddef.h>

#include "error.h"

#ifdef __cplusplus
extern "C" {
#endif

struct ef_exr_file;

/* The library's default dwaCompressionLevel (also oiiotool's). */
#define EF_DWA_DEFAULT_LEVEL 45.0f

/* How many parts of an opened file are DWAA or DWAB compressed (0 when
 * none). ef_exr_open refuses such files, so this is for any struct whose
 * ctx is a Core read context. */
int ef_exr_dwa_parts(const struct ef_exr_file *f);

/* The same from a path: reads the headers only (Core parses DWA headers
 * fine). Returns the count, or -1 with a message when path is not an EXR
 * Core can open. */
int ef_exr_dwa_parts_path(const char *path, ef_err *err);

/* What a file's DWA parts are: how many parts, how many DWA, the first DWA
 * part's compression (EXR_COMPRESSION_DWAA/DWAB) and dwaCompressionLevel
 * (-1 when absent), and whether DWA parts differ in kind. Reads headers
 * only. Returns 0, or -1 with a message (not an EXR...). */
typedef struct ef_dwa_info {
    int nparts, ndwa, compression, mixed;
    float level;
} ef_dwa_info;
int ef_exr_dwa_info(const char *path, ef_dwa_info *info, ef_err *err);

/* Copies every part of in_path to out_fd (a new, empty, seekable file the
 * caller opened for writing; it owns the name, renames or removes it;
 * out_name only names it in messages and is never opened):
 *   - a part whose input compression is DWAA/DWAB gets dwa_parts_to
 *     (an exr_compression_t, typically EXR_COMPRESSION_ZIP; -1 keeps it);
 *   - then all_parts_to, when >= 0, is given to every part (DWAA/DWAB
 *     allowed); -1 keeps what the first rule left;
 *   - a DWA output part gets dwaCompressionLevel dwa_level, or when
 *     dwa_level < 0 the input part's own dwaCompressionLevel attribute, or
 *     EF_DWA_DEFAULT_LEVEL; the attribute is written with that value.
 * Every attribute is kept (compression and dwaCompressionLevel updated);
 * every channel keeps its pixel type, and its values are exactly those the
 * library's decoder produced (re-encoding into DWA quantises only the half
 * channels DWA treats as colour: R, G, B, Y, BY, RY, with any layer
 * prefix; the rest is lossless). Parts whose compression (and DWA level)
 * does not change are copied chunk by chunk without decoding. Scanline
 * parts go through blocks of a few chunks, tiled parts one tile row at a
 * time, every mip/rip level kept: memory is bounded by the block size,
 * not the image height. Deep and subsampled parts are refused.
 * threads >= 2 sets the C++ library's global thread count (Imf's pool is
 * process-wide; the previous count is restored on return); 0 or 1 decode
 * and encode on the calling thread. Returns 0, or -1 with a message in
 * msg (which says which file is at fault and what to do). */
int ef_dwa_transcode(const char *in_path, int out_fd, const char *out_name, int dwa_parts_to,
                     int all_parts_to, float dwa_level, int threads, char *msg, size_t msglen);

#ifdef __cplusplus
}
#endif

#endif
