/* Foreign image formats through OpenImageIO, loaded on demand: previews
 * (8-bit, any format it writes, by extension), deliverables in other
 * formats than EXR, and depth and images imported from them. */
#ifndef EF_FOREIGN_H
#define EF_FOREIGN_H

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

/* Sample types of a deliverable (-d): 0 is the writer's choice from float. */
enum { EF_DT_UINT8 = 1, EF_DT_UINT10, EF_DT_UINT12, EF_DT_UINT16, EF_DT_HALF, EF_DT_FLOAT };

/* How a fogged frame becomes a non-EXR file. */
typedef struct ef_oiio_deliver {
    int type;                 /* EF_DT_*, or 0: float, the writer converts */
    int full_window;          /* the display window (else the data window) */
    int unassociate;          /* colour divided by alpha before encode; straight alpha */
    /* Colour from the working space to the file's, on n RGB triples in
     * place (0, or -1 on failure); NULL: written as it is. */
    int (*encode)(void *user, float *rgb, long n);
    void *encode_user;
    const char *colorspace;   /* oiio:ColorSpace, or NULL */
    const char *dpx_transfer, *dpx_colorimetric;   /* DPX's labels, or NULL */
} ef_oiio_deliver;

/* Writes channels names[0..n) (R, G, B and maybe A) of part `part` of the
 * EXR src to dst in the format of dst_fmt's extension (NULL: dst's),
 * through OpenImageIO, as d says. src and dst may be /proc/self/fd/N
 * names, so that what is read and written is the caller's own open file
 * whatever its name has become. Returns 0, or -1 with a message in err. */
int ef_oiio_convert_exr(const char *src, int part, const char *const *names, int n,
                        const char *dst, const char *dst_fmt, const ef_oiio_deliver *d,
                        char *err, size_t errlen);

/* What the writer of ext's format (".png") accepts, writing only a 1x1
 * probe in a private directory: 0 with *got (the EF_DT_ type it settled
 * on for a request of dt, 0 meaning float) and *alpha (whether it holds
 * alpha); -1 with the writer's reason when it refuses nch channels. */
int ef_oiio_output_probe(const char *ext, int dt, int nch, int *got, int *alpha, char *err,
                         size_t errlen);

/* Reads the first image of src (any format OpenImageIO reads: a 32-bit
 * TIFF depth pass...) as float and writes it to the open descriptor dst_fd
 * as a float EXR, ZIP, with its channel names (a single channel is
 * called Z) and its origin and full window. An image of more than
 * max_pixels (0: no bound but 2^28 values) is refused before it is read.
 * Returns 0, or -1 with a message. */
int ef_oiio_image_to_exr(const char *src, int dst_fd, double max_pixels, char *err, size_t errlen);

#ifdef __cplusplus
}
#endif

#endif
