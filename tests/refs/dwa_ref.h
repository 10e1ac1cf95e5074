/* test_dwa's reference reader: the OpenEXR C++ library (dwa_ref.cpp). */
#ifndef DWA_REF_H
#define DWA_REF_H

#ifdef __cplusplus
extern "C" {
#endif

#define DWA_REF_MAX_CH 16

typedef struct dwa_ref_info {
    int nparts;
    int compression;          /* Imf::Compression == exr_compression_t */
    float level;              /* dwaCompressionLevel attribute, -1 when absent */
    int tiled;
    int dw[4];
    int nch;
    char ch[DWA_REF_MAX_CH][256];
    int type[DWA_REF_MAX_CH]; /* Imf::PixelType == exr_pixel_type_t */
} dwa_ref_info;

/* Header facts of part `part`. Returns 0 or -1 (message on stderr). */
int dwa_ref_header(const char *path, int part, dwa_ref_info *info);

/* Channel `name` of part `part`, data window rows, 32 bits a sample: float
 * (half widened exactly) or uint32 for UINT channels. NULL on failure. The
 * caller frees. */
void *dwa_ref_read(const char *path, int part, const char *name, int *w, int *h);

#ifdef __cplusplus
}
#endif

#endif
