#!/bin/sh
# Regenerates the seed corpus fuzz/corpus/ from samples/sample.exr with
# oiiotool: 32x18 crops in every compression exrfog reads, scanline and
# tiled, single and multi-part, with and without camera attributes; plus
# the multi-part files of make_multipart_seeds.c (depth in another part
# with other chunking). Needs oiiotool, clang or cc, libopenexr-dev.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
src="$here/../samples/sample.exr"
out="$here/corpus"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out"
oi() { oiiotool -q --nosoftwareattrib "$@"; }

W2C="0.994522,0.00729154,0.104274,0,0,0.997564,-0.0697565,0,0.104528,-0.0693743,-0.992099,0,0,-1.69586,0.118586,1"
W2NDC="0.913418,0.0409109,0.104274,0.104274,-0.0348782,-1.57073,-0.0697565,-0.0697565,-0.405525,-0.389241,-0.9921,-0.992099,0.059293,2.67024,0.018586,0.118586"
W2S="1.8268,0.0818,0.1043,0.1043,-0.0698,3.1415,-0.0698,-0.0698,-0.8111,0.7785,-0.9921,-0.9921,0.1186,-5.3405,0.0186,0.1186"
C2W="0.994522,0,-0.104528,0,0.00729154,0.997564,0.0693743,0,-0.104274,0.0697565,-0.992099,0,0.176833,1.69586,-0.0049,1"

# Plain 32x18 RGBA half + Z float, no attributes beyond the required ones.
oi "$src" --resize 32x18 --eraseattrib ".*" -d half -d Z=float -o "$tmp/plain.exr"
EXR="--attrib:type=matrix worldToCamera $W2C --attrib:type=matrix worldToNDC $W2NDC --attrib:type=float CameraFov 60"
ARN="--attrib:type=matrix worldToCamera $W2C --attrib:type=matrix worldToScreen $W2S --attrib:type=float CameraFov 54.4 --attrib:type=float arnold/camera/near_clip 0.1 --attrib:type=float arnold/camera/far_clip 1000"
VRAY="--attrib:type=matrix cameraTransform $C2W --attrib:type=float cameraFov 60 --attrib:type=float cameraNearClip 0.1 --attrib:type=float cameraFarClip 1e30"
RS="--attrib:type=matrix rs/camera/transform $C2W --attrib:type=float rs/camera/fov 1.0472 --attrib:type=float rs/camera/nearPlane 0.1 --attrib:type=float rs/camera/farPlane 500"
p="$tmp/plain.exr"
D="-d half -d Z=float"

# shellcheck disable=SC2086
{
oi "$p" $D $EXR --compression piz -o "$out/scan_piz_exrcam.exr"
oi "$p" $D --compression zip --tile 16 16 -o "$out/tile16_zip_nocam.exr"
oi "$p" $D --compression rle -o "$out/scan_rle_nocam.exr"
oi "$p" $D $ARN --compression none --crop 20x10+3+2 -o "$out/scan_none_arnold_crop.exr"
oi "$p" $D $VRAY --compression pxr24 -o "$out/scan_pxr24_vray.exr"
oi "$p" $D $RS --compression b44 --tile 8 8 -o "$out/tile8_b44_redshift.exr"
oi "$p" $D $EXR --compression b44a -o "$out/scan_b44a_exrcam.exr"
oi "$p" $D --compression zips --attrib openexr:lineOrder decreasingY -o "$out/scan_zips_decy.exr"
oi "$p" -d float --compression zip --tile 32 8 -o "$out/tile32x8_zip_float.exr"
# A mip-mapped tiled texture (exrfog fogs level 0 only).
oi "$p" $D $EXR --compression zip -otex:resize=0 "$out/tile_mip_zip.exr"
# Data window off the origin and negative, 1-row and 1-column images.
oi "$p" $D --crop 12x6+0+0 --origin -4-3 --fullsize 16x10+0+0 --compression rle -o "$out/scan_rle_negorigin.exr"
oi "$p" $D --crop 32x1+0+5 --compression zip -o "$out/scan_zip_1row.exr"
oi "$p" $D --crop 1x18+7+0 --compression piz --tile 16 16 -o "$out/tile_piz_1col.exr"
# Extra uint and half channels beside the colour (ids pass through).
oi "$p" --ch "R,G,B,A,Z,id=0,N.Z=1" -d half -d Z=float -d id=uint --compression zip -o "$out/scan_zip_uint_normals.exr"
# Layer naming used by Blender: ViewLayer.Combined.* and ViewLayer.Depth.Z.
oi "$p" $D --ch "ViewLayer.Combined.R=R,ViewLayer.Combined.G=G,ViewLayer.Combined.B=B,ViewLayer.Combined.A=A,ViewLayer.Depth.Z=Z" \
    --compression zip -o "$out/scan_zip_blender.exr"
# Multi-part: colour in part "rgba", depth in part "depth" (depth.Z).
oi "$p" $D --ch R,G,B,A --attrib oiio:subimagename rgba "$p" --ch Z --attrib oiio:subimagename depth \
    --siappend $EXR $D --compression zip -o "$out/multipart_zip_rgba_depth.exr"
# Multi-part: depth part first, colour part "rgba" second.
oi "$p" $D --ch Z --attrib oiio:subimagename depth "$p" --ch R,G,B --attrib oiio:subimagename rgba \
    --siappend $D --compression piz -o "$out/multipart_piz_depthfirst.exr"
# Camera numbers as double and int; a camera attribute of the wrong type.
oi "$p" $D --attrib:type=matrix cameraTransform $C2W --attrib:type=double cameraFov 60.5 \
    --attrib:type=int cameraNearClip 1 --attrib:type=double cameraFarClip 100.25 --compression zip \
    --crop 16x4+0+0 -o "$out/scan_zip_vray_double_int.exr"
oi "$p" $D --attrib:type=string CameraFov wide --compression zip --crop 16x4+0+0 \
    -o "$out/scan_zip_badtype.exr"
}
${CC:-cc} -std=c11 -D_POSIX_C_SOURCE=200809L -O1 -I/usr/include/OpenEXR \
    "$here/make_multipart_seeds.c" -o "$tmp/make_multipart_seeds" -lOpenEXRCore-3_1 -lm
"$tmp/make_multipart_seeds" "$out"
ls -l "$out"
