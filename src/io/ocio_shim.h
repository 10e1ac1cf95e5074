/* OpenColorIO behind a C interface. */
#ifndef EF_OCIO_SHIM_H
#define EF_OCIO_SHIM_H

#ifdef __cplusplus
extern "C" {
#endif

/* The linked OpenColorIO version string. */
const char *ef_ocio_version(void);

#ifdef __cplusplus
}
#endif

#endif
