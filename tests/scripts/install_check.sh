#!/bin/sh
# Installs the build into a temporary prefix and builds a program outside
# the project against it twice, through pkg-config and through
# find_package(exrfog), then runs both on the sample.
# usage: install_check.sh BUILD_DIR SOURCE_DIR SANITIZE(0|1)
set -eu
build=$1 src=$2 sanitize=$3
d=$(mktemp -d)
trap 'rm -rf "$d"' EXIT
cmake --install "$build" --prefix "$d/prefix" >/dev/null
flags=""
[ "$sanitize" = 1 ] && flags="-fsanitize=address,undefined"
libdir=$(dirname "$(find "$d/prefix" -name libexrfog.so | head -1)")
export LD_LIBRARY_PATH="$libdir"
# the installed program finds its library through its RPATH
env -u LD_LIBRARY_PATH "$d/prefix/bin/exrfog" --version
# pkg-config: a dynamic build needs no other package's .pc (the public
# header needs none of them; the .deb's runtime dependencies suffice)
PKG_CONFIG_LIBDIR="$libdir/pkgconfig" pkg-config --cflags --libs exrfog >/dev/null
mkdir "$d/pc"
PKG_CONFIG_PATH="$libdir/pkgconfig" cc $flags "$src/tests/external/use_exrfog.c" \
  $(PKG_CONFIG_PATH="$libdir/pkgconfig" pkg-config --cflags --libs exrfog) -lm -o "$d/pc/use"
"$d/pc/use" "$src/samples/sample.exr" "$d/pc"
# find_package
cmake -S "$src/tests/external" -B "$d/cm" -DCMAKE_PREFIX_PATH="$d/prefix" \
  -DCMAKE_C_FLAGS="$flags" >/dev/null
cmake --build "$d/cm" >/dev/null
mkdir "$d/cmout"
"$d/cm/use_exrfog" "$src/samples/sample.exr" "$d/cmout"
# the static library links on its own with its private dependencies
PKG_CONFIG_PATH="$libdir/pkgconfig" cc $flags "$src/tests/external/use_exrfog.c" \
  $(PKG_CONFIG_PATH="$libdir/pkgconfig" pkg-config --cflags exrfog) "$libdir/libexrfog.a" \
  $(PKG_CONFIG_PATH="$libdir/pkgconfig" pkg-config --static --libs-only-l exrfog | sed 's/-lexrfog//') \
  -lm -o "$d/static_use"
mkdir "$d/st"
"$d/static_use" "$src/samples/sample.exr" "$d/st"
# the installed Python module finds the installed library by itself (a
# sanitized build's library needs the sanitizer's runtime preloaded into
# python, which is no user's concern)
if command -v python3 >/dev/null 2>&1; then
  pre=
  [ "$sanitize" = 1 ] && pre="$(cc -print-file-name=libasan.so):$(cc -print-file-name=libubsan.so)"
  env -u LD_LIBRARY_PATH LD_PRELOAD="$pre" ASAN_OPTIONS=detect_leaks=0 \
    PYTHONPATH="$d/prefix/lib/python3/dist-packages" python3 -c \
    "import exrfog; assert exrfog.library_version() == exrfog.version; exrfog.fog('$src/samples/sample.exr', '$d/py.exr', fog='exp:density=0.02')"
  [ -s "$d/py.exr" ]
  # the farm front end is installed beside the program and runs from there
  env -u LD_LIBRARY_PATH "$d/prefix/bin/exrfog-farm" submit --help >/dev/null
fi
echo "install check passed"
