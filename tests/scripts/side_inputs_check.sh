#!/bin/sh
# -o and --preview over a file the run reads besides INPUT (issue 46): the
# --depth file, a sun's and a spot's shadow= map and a map's shadow-camera= file (on the command line and
# in a --scene file), the --sky-light environment, the --scene file, the
# --camera-file, the --colorconfig and a layered file= profile, named as
# written, through a symbolic link and through a hard link; and in a
# sequence, frame 1's output over frame 2's depth. Each is refused with
# exit 2 and a message naming the file, before anything is written: every
# input keeps its bytes and no file appears or goes. -o INPUT (in place)
# stays allowed.
# usage: side_inputs_check.sh EXRFOG MAKE_SAMPLE SOURCE_DIR TMPDIR
set -u
exrfog=$1 make_sample=$2 src=$3 tmp=$4/side_inputs
fail=0
bad() { echo "FAIL: $*"; fail=1; }

rm -rf "$tmp" && mkdir -p "$tmp" || exit 1
cd "$tmp" || exit 1
"$make_sample" a.exr --size 64x36 >/dev/null || exit 1
"$make_sample" d.exr --size 64x36 --seed 2 >/dev/null || exit 1
"$make_sample" sun.exr --size 64x64 --sun-view 0.3,1,0.2 >/dev/null || exit 1
cp d.exr spot.exr && cp d.exr env.exr || exit 1
printf '# height density\n0 0.2\n5 0.05\n20 0\n' > prof.txt
printf '{"convention": "exr", "fov": 60, "frames": {"1": {"camera_to_world": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,2,0,1]}}}\n' > cam.json
cp "$src/share/ocio/exrfog-config.ocio" cfg.ocio || exit 1
w2c=$(oiiotool --info -v sun.exr | sed -n 's/.*worldToCamera: //p')
printf '{"convention": "exr", "ortho_width": 240, "frames": {"1": {"world_to_camera": [%s]}}}\n' "$w2c" > suncam.json
printf '{"fog": ["exp:density=0.03"], "lights": ["spot:position=0,1.7,0:aim=0,0,-1:cone=40:intensity=3:shadow=spot.exr"]}\n' > scene.json

fog="--fog exp:density=0.05"
sun="--light sun:towards=0.3,1,0.2:intensity=3:shadow=sun.exr"
spot="--light spot:position=0,1.7,0:aim=0,0,-1:cone=40:intensity=3:shadow=spot.exr"

# Each side input and the run that reads it (OUT is the output's place).
cases="depth|d.exr|--depth d.exr $fog
sun|sun.exr|$fog $sun
spot|spot.exr|$fog $spot
suncam|suncam.json|$fog $sun:shadow-camera=suncam.json
scene-map|spot.exr|--scene scene.json
scene|scene.json|--scene scene.json
sky|env.exr|$fog --sky-light env.exr:intensity=0.5
camera|cam.json|$fog --camera-file cam.json
config|cfg.ocio|$fog --colorconfig cfg.ocio
profile|prof.txt|--fog layered:file=prof.txt"

# The runs read their inputs as they are: each is fine with its own output.
echo "$cases" | while IFS='|' read -r name file args; do
  # shellcheck disable=SC2086
  "$exrfog" a.exr -o ok.exr $args -q 2>err.txt || { echo "FAIL: $name: the run itself fails"; cat err.txt; exit 1; }
done || fail=1
rm -f ok.exr

snapshot() { for f in *; do [ "$f" = err.txt ] || { printf '%s ' "$f"; cksum < "$f"; }; done; }

# refused NAME FILE OUT FLAG ARGS...: the run with FLAG OUT exits 2, names
# FILE's role, and changes no file.
refused() {
  what=$1 file=$2 out=$3 flag=$4
  shift 4
  before=$(snapshot)
  "$exrfog" a.exr "$flag" "$out" "$@" -q >/dev/null 2>err.txt
  rc=$?
  [ $rc = 2 ] || { bad "$what: $flag $out over $file: exit $rc, not 2"; cat err.txt; }
  grep -q "writing it would replace a file this run reads; nothing was written" err.txt ||
    { bad "$what: $flag $out over $file: no message"; cat err.txt; }
  [ "$(snapshot)" = "$before" ] || bad "$what: $flag $out over $file: files changed"
}

while IFS='|' read -r name file args; do
  ln -sf "$file" sym.exr
  ln -f "$file" hard.exr
  # shellcheck disable=SC2086
  refused "$name" "$file" "$file" -o $args
  # shellcheck disable=SC2086
  refused "$name (symlink)" "$file" sym.exr -o $args
  # shellcheck disable=SC2086
  refused "$name (hard link)" "$file" hard.exr -o $args
  # shellcheck disable=SC2086
  refused "$name (preview)" "$file" "$file" --preview -o out.exr $args
  rm -f sym.exr hard.exr
done <<EOF
$cases
EOF
"$exrfog" a.exr -o d.exr --depth d.exr $fog 2>err.txt
grep -q "^exrfog: d.exr: -o names the --depth file: writing" err.txt || { bad "the depth message"; cat err.txt; }
ln -sf sun.exr sym.exr
"$exrfog" a.exr -o sym.exr $fog $sun 2>err.txt
grep -q "^exrfog: sym.exr: -o names the shadow= map of light sun1 (sun.exr, the same file)" err.txt ||
  { bad "the shadow map's message"; cat err.txt; }
rm -f sym.exr

# A sequence: frame 1's output is frame 2's depth (by name, and by a link).
mkdir seq && cp a.exr seq/s.1.exr && cp a.exr seq/s.2.exr && cp d.exr seq/z.2.exr &&
  cp d.exr seq/z.1.exr || exit 1
ln -s z.2.exr seq/o.1.exr
before=$(cd seq && snapshot)
"$exrfog" 'seq/s.%d.exr' -o 'seq/o.%d.exr' --frames 1,2 --depth 'seq/z.%d.exr' $fog 2>err.txt
rc=$?
[ $rc = 2 ] || { bad "sequence: frame 1's output onto frame 2's depth: exit $rc, not 2"; cat err.txt; }
grep -q "names frame 2's --depth file (seq/z.2.exr) as frame 1's output: it would be overwritten before it is read" err.txt ||
  { bad "sequence: the message"; cat err.txt; }
[ "$(cd seq && snapshot)" = "$before" ] || bad "sequence: files changed"
rm seq/o.1.exr
# A preview pattern over the depth of another frame.
ln -s z.1.exr seq/p.2.exr
"$exrfog" 'seq/s.%d.exr' -o 'seq/o.%d.exr' --preview 'seq/p.%d.exr' --frames 1,2 --depth 'seq/z.%d.exr' $fog 2>err.txt
[ $? = 2 ] && grep -q "preview" err.txt || { bad "sequence: a preview over frame 1's depth"; cat err.txt; }
[ -e seq/o.1.exr ] && bad "sequence: output written after a refusal"
rm seq/p.2.exr

# In place, INPUT onto itself, stays allowed (a single image and a sequence).
cp a.exr in.exr
"$exrfog" in.exr -o in.exr $fog -q || bad "-o INPUT in place is refused"
cmp -s in.exr a.exr && bad "-o INPUT in place did not write"
"$exrfog" 'seq/s.%d.exr' -o 'seq/s.%d.exr' --frames 1,2 --depth 'seq/z.%d.exr' $fog -q ||
  bad "a sequence in place is refused"

# --failed-list (issue 47): it is rewritten at the end of the run, so it
# may name no file the run reads or writes (it left such a file empty,
# exit 0), and no FIFO (which blocked the run for ever): each refused with
# exit 2 before any work, every file kept.
ln -sf ../sun.exr seq/map.exr
for fl in seq/s.1.exr seq/z.2.exr seq/o.2.exr seq/map.exr; do
  before=$(cd seq && snapshot)
  "$exrfog" 'seq/s.%d.exr' -o 'seq/o.%d.exr' --frames 1,2 --depth 'seq/z.%d.exr' $fog $sun \
    --failed-list "$fl" -q 2>err.txt
  rc=$?
  [ $rc = 2 ] && grep -q -- "--failed-list $fl" err.txt ||
    { bad "--failed-list $fl: exit $rc"; cat err.txt; }
  [ "$(cd seq && snapshot)" = "$before" ] || bad "--failed-list $fl: files changed"
done
mkfifo seq/fifo || exit 1
timeout 20 "$exrfog" 'seq/s.%d.exr' -o 'seq/o.%d.exr' --frames 1,2 --depth 'seq/z.%d.exr' $fog \
  --failed-list seq/fifo -q 2>err.txt
rc=$?
[ $rc = 2 ] && grep -q "not a regular file" err.txt || { bad "--failed-list FIFO: exit $rc"; cat err.txt; }
rm -f seq/fifo seq/map.exr
"$exrfog" 'seq/s.%d.exr' -o 'seq/o.%d.exr' --frames 1,2 --depth 'seq/z.%d.exr' $fog \
  --failed-list seq/failed.txt -q 2>err.txt || { bad "--failed-list of its own: refused"; cat err.txt; }
[ -f seq/failed.txt ] && [ ! -s seq/failed.txt ] || bad "--failed-list of its own: not an empty list"

[ $fail = 0 ] && echo "side inputs: -o and --preview over each, by name and by link, refused; sequences too; --failed-list too"
exit $fail
