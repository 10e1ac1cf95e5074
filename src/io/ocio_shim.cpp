#include "ocio_shim.h"

// Thin OpenColorIO shim (C in, C out). Colour management arrives with a
// later issue; for now the library is linked and reported by --version.
#include <OpenColorIO/OpenColorIO.h>

extern "C" const char *ef_ocio_version(void)
{
    return OCIO_NAMESPACE::GetVersion();
}
