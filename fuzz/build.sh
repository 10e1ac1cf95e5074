#!/bin/sh
# Builds the libFuzzer target fuzz_exr (ASan + UBSan + LeakSanitizer) from the
# project's core and OpenEXRCore I/O sources.
#   fuzz/build.sh [BUILD_DIR]             -> BUILD_DIR/fuzz_exr, BUILD_DIR/fuzz_cli
#   fuzz/build.sh --coverage [BUILD_DIR]  -> BUILD_DIR/fuzz_exr_cov (llvm-cov build)
# BUILD_DIR defaults to build-fuzz/ at the top of the repository. Needs clang
# with libFuzzer and libopenexr-dev (OpenEXRCore 3.1).
set -eu
cov=0
if [ "${1:-}" = "--coverage" ]; then
    cov=1
    shift
fi
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
out=${1:-"$root/build-fuzz"}
CC=${CC:-clang}
mkdir -p "$out/generated"
printf '#ifndef EF_VERSION_H\n#define EF_VERSION_H\n#define EXRFOG_VERSION "fuzz"\n#endif\n' \
    > "$out/generated/version.h"
if [ $cov = 1 ]; then
    flags="-fsanitize=fuzzer -fprofile-instr-generate -fcoverage-mapping"
    exe="$out/fuzz_exr_cov"
else
    flags="-fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined"
    exe="$out/fuzz_exr"
fi
# foreign.c and ocio_shim.cpp need OIIO/OCIO and are not on the file path.
# shellcheck disable=SC2086
$CC -std=c11 -D_POSIX_C_SOURCE=200809L -g -O1 -fno-omit-frame-pointer $flags \
    -Wall -Wextra \
    -I "$root/src/core" -I "$root/src/io" -I "$out/generated" -I /usr/include/OpenEXR \
    -o "$exe" \
    "$here/fuzz_exr.c" "$root"/src/core/*.c "$root"/src/io/exr_*.c "$root/src/io/half_conv.c" \
    -lOpenEXRCore-3_1 -ldeflate -lm -lpthread -ldl
echo "built $exe"
# fuzz_cli: the option parser, SPECs, scene files and profiles (no OIIO/OCIO).
if [ $cov = 1 ]; then
    exe="$out/fuzz_cli_cov"
else
    exe="$out/fuzz_cli"
fi
# colour.c needs the OCIO shim (C++): compiled apart, linked with clang++.
CXX=${CXX:-clang++}
# shellcheck disable=SC2086
$CXX -std=c++17 -g -O1 -fno-omit-frame-pointer $(echo $flags | sed 's/-fsanitize=fuzzer,/-fsanitize=fuzzer-no-link,/; s/-fsanitize=fuzzer /-fsanitize=fuzzer-no-link /') \
    -I "$root/src/io" $(pkg-config --cflags OpenColorIO) -c "$root/src/io/ocio_shim.cpp" \
    -o "$out/ocio_shim.o"
# shellcheck disable=SC2086
$CC -std=c11 -D_POSIX_C_SOURCE=200809L -g -O1 -fno-omit-frame-pointer $flags \
    -Wall -Wextra \
    -I "$root/src/core" -I "$root/src/io" -I "$root/src/job" -I "$out/generated" \
    -I /usr/include/OpenEXR -c "$here/fuzz_cli.c" "$root/src/job/args.c" \
    "$root/src/job/argscan.c" "$root/src/job/scene_build.c" "$root/src/job/colour.c"
mv fuzz_cli.o args.o argscan.o scene_build.o colour.o "$out/"
# shellcheck disable=SC2086
$CC -std=c11 -D_POSIX_C_SOURCE=200809L -g -O1 -fno-omit-frame-pointer $flags -Wall -Wextra \
    -I "$root/src/core" -I "$root/src/io" -I "$out/generated" -I /usr/include/OpenEXR \
    -c "$root"/src/core/*.c "$root"/src/io/exr_*.c "$root/src/io/half_conv.c" "$root/src/io/scene_file.c" \
    "$root/src/io/camera_file.c"
mkdir -p "$out/obj" && mv ./*.o "$out/obj/"
# shellcheck disable=SC2086
$CXX $flags -o "$exe" "$out/fuzz_cli.o" "$out/args.o" "$out/argscan.o" "$out/scene_build.o" \
    "$out/colour.o" "$out/ocio_shim.o" \
    $(ls "$out"/obj/*.o | grep -v camera_file) \
    -lOpenEXRCore-3_1 -ldeflate -ljansson $(pkg-config --libs OpenColorIO) -lm -lpthread -ldl
echo "built $exe"
# fuzz_camfile: camera files (JSON and Nuke .chan).
[ $cov = 1 ] && exe="$out/fuzz_camfile_cov" || exe="$out/fuzz_camfile"
# shellcheck disable=SC2086
$CC -std=c11 -D_POSIX_C_SOURCE=200809L -g -O1 -fno-omit-frame-pointer $flags -Wall -Wextra \
    -I "$root/src/core" -I "$root/src/io" -I "$out/generated" -o "$exe" \
    "$here/fuzz_camfile.c" "$root"/src/core/*.c "$root/src/io/camera_file.c" \
    "$root/src/io/scene_file.c" -ljansson -lm
echo "built $exe"
# fuzz_ocio: OpenColorIO configs through the shim (names, colours, displays).
[ $cov = 1 ] && exe="$out/fuzz_ocio_cov" || exe="$out/fuzz_ocio"
# shellcheck disable=SC2086
$CC -std=c11 -D_POSIX_C_SOURCE=200809L -g -O1 -fno-omit-frame-pointer $flags -Wall -Wextra \
    -I "$root/src/io" -c "$here/fuzz_ocio.c" -o "$out/fuzz_ocio.o"
# shellcheck disable=SC2086
$CXX $flags -o "$exe" "$out/fuzz_ocio.o" "$out/ocio_shim.o" $(pkg-config --libs OpenColorIO) -ldl
echo "built $exe"
# fuzz_depth: --depth images through OpenImageIO (the module's reader).
[ $cov = 1 ] && exe="$out/fuzz_depth_cov" || exe="$out/fuzz_depth"
# shellcheck disable=SC2086
$CXX -std=c++17 -g -O1 -fno-omit-frame-pointer $(echo $flags | sed 's/-fsanitize=fuzzer,/-fsanitize=fuzzer-no-link,/; s/-fsanitize=fuzzer /-fsanitize=fuzzer-no-link /') \
    -I "$root/src/io" $(pkg-config --cflags OpenImageIO) -c "$root/src/io/oiio/oiio_module.cpp" \
    -o "$out/oiio_module.o"
# shellcheck disable=SC2086
$CC -std=c11 -D_POSIX_C_SOURCE=200809L -g -O1 -fno-omit-frame-pointer $flags -Wall -Wextra \
    -c "$here/fuzz_depth.c" -o "$out/fuzz_depth.o"
# shellcheck disable=SC2086
$CXX $flags -o "$exe" "$out/fuzz_depth.o" "$out/oiio_module.o" $(pkg-config --libs OpenImageIO) -ldl
echo "built $exe"
