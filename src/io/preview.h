/* Preview images through OpenImageIO (any format it writes, by extension). */
#ifndef EF_PREVIEW_H
#define EF_PREVIEW_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Writes an 8-bit RGB image (rows of w*3 bytes) to path (which may be a
 * /proc/self/fd/N name) in the format of fmt's extension (NULL: path's).
 * Returns 0, or -1 with a message in err. */
int ef_preview_write(const char *path, const char *fmt, int w, int h, const unsigned char *rgb,
                     char *err, size_t errlen);

/* Whether a preview can be written in path's format (by its extension),
 * writing nothing. Returns 0, or -1 with a message in err. */
int ef_preview_check(const char *path, char *err, size_t errlen);

/* Writes channels names[0..n) (R, G, B and maybe A) of part `part` of the
 * EXR src to dst in the format of dst_fmt's extension (NULL: dst's),
 * through OpenImageIO. src and dst may be /proc/self/fd/N names, so that
 * what is read and written is the caller's own open file whatever its
 * name has become. Returns 0, or -1 with a message in err. */
int ef_oiio_convert_exr(const char *src, int part, const char *const *names, int n,
                        const char *dst, const char *dst_fmt, char *err, size_t errlen);

/* Reads the first image of src (any format OpenImageIO reads: a 32-bit
 * TIFF depth pass...) as float and writes it to the open descriptor dst_fd
 * as a float EXR, ZIP, with its channel names (a single channel is
 * called Z) and its origin and full window. Returns 0, or -1 with a
 * message. */
int ef_oiio_image_to_exr(const char *src, int dst_fd, char *err, size_t errlen);

#ifdef __cplusplus
}
#endif

#endif
