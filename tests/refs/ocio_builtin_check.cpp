// exrfog's config (share/ocio) against OpenColorIO's own built-in
// transforms, which were derived independently by the OCIO/ACES authors:
// each pair of config spaces must convert like the matching BuiltinTransform.
// Usage: ocio_builtin_check CONFIG. Exit 0 when all agree within 1e-6.
#include <OpenColorIO/OpenColorIO.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace OCIO = OCIO_NAMESPACE;

static double compare(const OCIO::ConstConfigRcPtr &cfg, const char *src, const char *dst, const char *style)
{
    OCIO::ConstCPUProcessorRcPtr ours = cfg->getProcessor(src, dst)->getDefaultCPUProcessor();
    OCIO::BuiltinTransformRcPtr bt = OCIO::BuiltinTransform::Create();
    bt->setStyle(style);
    OCIO::ConstCPUProcessorRcPtr ref = cfg->getProcessor(bt)->getDefaultCPUProcessor();
    static const float probes[][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.18f, 0.18f, 0.18f},
                                      {0.3f, 0.7f, 2.0f}, {0.002f, 0.01f, 0.5f}};
    double err = 0;
    for (const float *v : probes) {
        float a[3] = {v[0], v[1], v[2]}, b[3] = {v[0], v[1], v[2]};
        ours->applyRGB(a);
        ref->applyRGB(b);
        for (int i = 0; i < 3; ++i)
            err = std::max(err, (double) std::fabs(a[i] - b[i]));
    }
    std::printf("%-12s -> %-27s vs %-45s max diff %.2e\n", src, dst, style, err);
    return err;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        std::fprintf(stderr, "usage: ocio_builtin_check CONFIG\n");
        return 2;
    }
    try {
        OCIO::ConstConfigRcPtr cfg = OCIO::Config::CreateFromFile(argv[1]);
        double err = 0;
        err = std::max(err, compare(cfg, "ACEScg", "ACES2065-1", "ACEScg_to_ACES2065-1"));
        err = std::max(err, compare(cfg, "ACEScg", "Linear Rec.709 (sRGB)", "UTILITY - ACES-AP1_to_LINEAR-REC709_BFD"));
        err = std::max(err, compare(cfg, "ACES2065-1", "CIE-XYZ-D65", "UTILITY - ACES-AP0_to_CIE-XYZ-D65_BFD"));
        err = std::max(err, compare(cfg, "CIE-XYZ-D65", "sRGB - Display", "DISPLAY - CIE-XYZ-D65_to_sRGB"));
        err = std::max(err, compare(cfg, "CIE-XYZ-D65", "Rec.1886 Rec.709 - Display",
                                    "DISPLAY - CIE-XYZ-D65_to_REC.1886-REC.709"));
        return err <= 1e-6 ? 0 : 1;
    } catch (const std::exception &e) {
        std::fprintf(stderr, "ocio_builtin_check: %s\n", e.what());
        return 1;
    }
}
