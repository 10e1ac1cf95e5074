#!/bin/sh
# The Debian package: cpack -G DEB builds it from this build; it holds the
# program, library, header, pkg-config and CMake files, Python module, man
# page, OCIO config and Blender add-on; lintian (when installed) reports no
# error; unpacked into a fresh root, the program runs from there.
# usage: deb_check.sh BUILD_DIR SOURCE_DIR
set -eu
build=$1 src=$2
d=$(mktemp -d)
trap 'rm -rf "$d"' EXIT
(cd "$build" && cpack -G DEB -B "$d/out" >/dev/null)
deb=$(ls "$d"/out/exrfog_*.deb)
dpkg-deb --info "$deb" | grep -q '^ Package: exrfog$'
dpkg-deb --info "$deb" | grep -q '^ Depends: .*libopenexr'
dpkg-deb --contents "$deb" | awk '{print $6}' > "$d/list"
for f in usr/bin/exrfog usr/include/exrfog.h usr/lib/libexrfog.so.0 usr/lib/libexrfog.a \
         usr/lib/pkgconfig/exrfog.pc usr/lib/cmake/exrfog/exrfogConfig.cmake \
         usr/lib/python3/dist-packages/exrfog/__init__.py usr/share/man/man1/exrfog.1.gz \
         usr/share/exrfog/ocio/exrfog-config.ocio usr/share/exrfog/blender/exrfog_blender.py \
         usr/share/doc/exrfog/copyright usr/lib/exrfog/libexrfog_oiio.so usr/lib/exrfog/libexrfog_cxx.so; do
  grep -q "^\./$f\$" "$d/list" || { echo "deb_check: $f is not in the package" >&2; exit 1; }
done
if command -v lintian >/dev/null 2>&1; then
  lintian --tag-display-limit 0 "$deb" > "$d/lintian" 2>&1 || true
  cat "$d/lintian"
  if grep -q '^E: ' "$d/lintian"; then echo "deb_check: lintian errors" >&2; exit 1; fi
fi
dpkg-deb -x "$deb" "$d/root"
"$d/root/usr/bin/exrfog" --version
# an sRGB fog colour (OpenColorIO) and a PNG preview (OpenImageIO): both
# on-demand modules load from the package, not from the build tree
LD_DEBUG=files "$d/root/usr/bin/exrfog" "$src/samples/sample.exr" -o "$d/out.exr" \
  --fog exp:density=0.02 --fog-color '#b0c0d0' --preview "$d/p.png" 2> "$d/ld.log"
[ -s "$d/out.exr" ] && [ -s "$d/p.png" ]
for m in libexrfog_cxx.so libexrfog_oiio.so; do
  grep -Eq "file=$d/root/usr/(bin/\.\./)?lib/exrfog/$m " "$d/ld.log" ||
    { grep "$m" "$d/ld.log" >&2; echo "deb_check: $m not loaded from the package" >&2; exit 1; }
done
echo "deb check passed"
