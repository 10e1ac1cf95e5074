#!/usr/bin/env bash
# exrfog-farm on a real single-node Slurm (tests/scripts/slurm-local) and on GNU
# parallel: a 12-frame sequence with one frame missing fails with that frame
# and its log named, the other eleven are written, a resubmit after the frame
# is restored reruns only it, and every frame equals a sequential exrfog run
# byte for byte. Usage errors are never retried, exit 1 is (--retries).
# usage: farm_check.sh EXRFOG MAKE_SAMPLE SOURCE_DIR TMPDIR
#   (exit 77: skipped, when Slurm is not installed or this is not root and
#   EXRFOG_REQUIRE_SLURM is unset; .ci/setup test --slow installs it)
set -uo pipefail
exrfog=$1 make_sample=$2 src=$3 tmp=$4/farm
farm=$src/src/farm/exrfog-farm
fail=0
bad() { echo "FAIL: $*"; fail=1; }

have_slurm=1
for p in sbatch squeue scontrol slurmctld slurmd munged; do
  command -v "$p" >/dev/null 2>&1 || [ -x "/usr/sbin/$p" ] || have_slurm=0
done
[ "$(id -u)" = 0 ] || have_slurm=0
if [ $have_slurm = 0 ]; then
  [ -n "${EXRFOG_REQUIRE_SLURM:-}" ] && { echo "FAIL: Slurm (or root) is missing"; exit 1; }
  echo "Slurm is not installed (or not root): skipped"; exit 77
fi

rm -rf "$tmp" && mkdir -p "$tmp/seq" || exit 1
cd "$tmp" || exit 1
"$make_sample" frame.exr --size 96x54 --compression zip >/dev/null || exit 1
for f in $(seq 1 12); do cp frame.exr "seq/shot.$(printf %04d "$f").exr"; done
# The fog moves with the frame's time: a frame fogged as another shows.
fog=(--fog 'noise:density=0.05:scale=4:octaves=2:velocity=3,0,1:method=exact')
"$exrfog" seq/shot.#.exr -o seq/ref.#.exr --frames 1-12 "${fog[@]}" -q ||
  { echo "FAIL: the sequential run"; exit 1; }
cmp -s seq/ref.0001.exr seq/ref.0002.exr && bad "frames 1 and 2 fog alike (time does not move the fog)"

D=$tmp/slurm
conf=$("$src/tests/scripts/slurm-local" start "$D") || { echo "FAIL: slurm-local start"; exit 1; }
eval "$conf"
trap '"$src/tests/scripts/slurm-local" stop "$D" >/dev/null 2>&1' EXIT
[ -n "${SLURM_CONF:-}" ] || bad "slurm-local start printed no SLURM_CONF"

# run ENGINE: the missing-frame round, the resubmit, the comparison.
run() {
  local engine=$1 job=$tmp/job-$1 rc
  rm -f seq/fog.*.exr
  mv seq/shot.0007.exr seq/hidden.exr
  "$farm" submit --engine "$engine" --chunk 5 --retries 1 --exrfog "$exrfog" --jobdir "$job" \
      --wait -- seq/shot.#.exr -o seq/fog.#.exr --frames 1-12 "${fog[@]}" >out.txt 2>err.txt
  rc=$?
  [ $rc = 1 ] || { bad "$engine: submit with frame 7 missing: exit $rc, not 1"; cat err.txt; }
  grep -q "frames not written: 7; log $job/logs/chunk-0001.log" err.txt ||
    { bad "$engine: the report does not name frame 7 and its log"; cat err.txt; }
  grep -q "1 of 12 frames failed: 7" err.txt || bad "$engine: no summary naming frame 7"
  [ "$(cat out.txt)" = "$job" ] || bad "$engine: stdout is not the job directory"
  grep -q "missing on disk: 7" "$job/logs/chunk-0001.log" ||
    bad "$engine: the chunk log lacks exrfog's own reason"
  [ "$(grep -c '^== exrfog-farm: chunk 1 ' "$job/logs/chunk-0001.log")" = 2 ] ||
    bad "$engine: exit 1 was not retried once (--retries 1)"
  grep -q -- "attempt 2 of 2, .*" "$job/logs/chunk-0001.log" && \
    grep -q -- "--frames 7 " "$job/logs/chunk-0001.log" ||
    bad "$engine: the retry did not rerun frame 7 alone"
  [ "$(ls seq/fog.*.exr 2>/dev/null | wc -l)" = 11 ] || bad "$engine: not 11 frames written"
  [ -e seq/fog.0007.exr ] && bad "$engine: frame 7 written"
  "$farm" status "$job" >status.txt 2>&1
  rc=$?
  [ $rc = 1 ] || bad "$engine: status exit $rc with a failed chunk"
  grep -Eq '^ +1 +6-10 +failed +1 +2 +7 ' status.txt || { bad "$engine: status line"; cat status.txt; }
  grep -Eq '^ +0 +1-5 +done +0 +1' status.txt || bad "$engine: status of chunk 0"

  mv seq/hidden.exr seq/shot.0007.exr
  "$farm" resubmit "$job" --wait >out.txt 2>err.txt
  rc=$?
  [ $rc = 0 ] || { bad "$engine: resubmit exit $rc"; cat err.txt; }
  grep -q "resubmitting chunk(s) 1$" err.txt || bad "$engine: resubmit did not rerun chunk 1 alone"
  # the frames it reruns, not the chunk's (issue 42: it said 5)
  if [ "$engine" = slurm ]; then
    grep -q "1 chunk(s) of 1 frame(s)" err.txt || { bad "slurm: resubmit miscounts its frames"; cat err.txt; }
  fi
  grep -q -- "--frames 7 " "$job/logs/chunk-0001.log" || bad "$engine: resubmit reran more than frame 7"
  "$farm" status "$job" >status.txt 2>&1 || bad "$engine: status after the resubmit is not 0"
  [ "$(grep -c ' done ' status.txt)" = 3 ] || bad "$engine: not every chunk done"
  for f in $(seq -f %04g 1 12); do
    cmp -s "seq/fog.$f.exr" "seq/ref.$f.exr" || bad "$engine: frame $f differs from the sequential run"
  done
  "$farm" resubmit "$job" 2>err.txt || bad "$engine: resubmit of a finished job"
  grep -q "nothing to resubmit" err.txt || bad "$engine: resubmit of a finished job says what"

  # A usage error is the same on every attempt: never retried.
  "$farm" submit --engine "$engine" --chunk 6 --retries 3 --exrfog "$exrfog" --jobdir "$job-usage" \
      --wait -- seq/shot.#.exr -o seq/u.#.exr --frames 1-12 --fog nosuchfog:density=1 >/dev/null 2>err.txt
  rc=$?
  [ $rc = 2 ] || { bad "$engine: a usage error: exit $rc, not 2"; cat err.txt; }
  for c in 0 1; do
    [ "$(grep -c '^== exrfog-farm: chunk' "$job-usage/logs/chunk-000$c.log")" = 1 ] ||
      bad "$engine: usage error retried (chunk $c)"
  done
  ls seq/u.*.exr >/dev/null 2>&1 && bad "$engine: output after a usage error"
}

# hostile ENGINE: every name the user passes holds what a shell or the
# engine would read (space, ; $( ) backquotes, both quotes, newline, && | >
# * {} ::: %): the working directory, the job directory, the farm script's
# and exrfog's paths, the input and output patterns and a --scene file. The
# frames are written, equal the sequential run's, and nothing is run.
W=$(printf 'w ;$(touch PWN1)`touch PWN2`\x27"\n&& | > * {} ::: %% x')
hostile() {
  local engine=$1 rc
  local h="$tmp/h-$engine-$W"
  mkdir -p "$h/bin $W" "$h/seq $W" || { bad "$engine: cannot make the hostile directories"; return; }
  cp "$exrfog" "$h/bin $W/exrfog $W" && cp "$farm" "$h/bin $W/farm $W" || return
  for f in $(seq 1 4); do cp "seq/shot.$(printf %04d "$f").exr" "$h/seq $W/s $W.$(printf %04d "$f").exr"; done
  printf '{"fog": ["noise:density=0.05:scale=4:octaves=2:velocity=3,0,1:method=exact"]}\n' > "$h/fog $W.json"
  (cd "$h" && "./bin $W/farm $W" submit --engine "$engine" --chunk 3 --exrfog "bin $W/exrfog $W" \
      --jobdir "job $W" --wait -- "seq $W/s $W.#.exr" -o "seq $W/o $W.#.exr" --frames 1-4 \
      --scene "fog $W.json" >"$tmp/out.txt" 2>"$tmp/err.txt")
  rc=$?
  [ $rc = 0 ] || { bad "$engine: hostile names: exit $rc"; cat "$tmp/err.txt"; }
  (cd "$h" && "$exrfog" "seq $W/s $W.#.exr" -o "seq $W/r $W.#.exr" --frames 1-4 --scene "fog $W.json" -q) ||
    bad "$engine: hostile names: the sequential run"
  for f in $(seq -f %04g 1 4); do
    cmp -s "$h/seq $W/o $W.$f.exr" "$h/seq $W/r $W.$f.exr" || bad "$engine: hostile names: frame $f differs"
  done
  cmp -s "$h/seq $W/o $W.0001.exr" "$h/seq $W/o $W.0002.exr" && bad "$engine: hostile names: frames alike"
  [ "$(cat "$tmp/out.txt")" = "$h/job $W" ] || bad "$engine: hostile names: stdout is not the job directory"
  "$h/bin $W/farm $W" status "$h/job $W" >"$tmp/status.txt" 2>&1 || bad "$engine: hostile names: status"
  local pwn
  # a shell would have run in the submitter's, the engine's or the task's directory
  pwn=$( (find "$tmp" -name 'PWN*'; find / /tmp "$HOME" "$D" -maxdepth 1 -name 'PWN*') 2>/dev/null | head -3)
  [ -z "$pwn" ] || bad "$engine: hostile names ran a command: $pwn"
}

run slurm
hostile slurm
# A job submitted without --wait: status follows it to the end.
job=$tmp/job-nowait
"$farm" submit --engine slurm --chunk 4 --exrfog "$exrfog" --jobdir "$job" -- \
    seq/shot.#.exr -o seq/nw.#.exr --frames 1-12 "${fog[@]}" >/dev/null 2>err.txt ||
  bad "slurm: submit without --wait"
for _ in $(seq 60); do
  "$farm" status "$job" >status.txt 2>&1
  rc=$?
  [ $rc = 3 ] || break
  sleep 1
done
[ $rc = 0 ] || { bad "slurm: status of the unwaited job ended $rc"; cat status.txt; }
for f in $(seq -f %04g 1 12); do
  cmp -s "seq/nw.$f.exr" "seq/ref.$f.exr" || bad "slurm (no --wait): frame $f differs"
done
run parallel
hostile parallel

# Stopped runs (issue 47): after Ctrl-C (SIGINT to the submitter's process
# group) or a kill -9 of the lot, no chunk stays "pending" or "running" for
# ever: status says failed or lost, resubmit reruns them to the end, and no
# temporary file is left beside the frames. A damaged state file is named,
# not a Python traceback. (Frames of about 2 s each, one a chunk, two at
# once: the signal comes while two run and two wait.)
slow=(--fog 'noise:density=0.05:scale=0.25:octaves=7:method=exact')
for sig in INT KILL; do
  job=$tmp/job-stop-$sig
  rm -f seq/st.*.exr
  setsid "$farm" submit --engine parallel --chunk 1 --jobs 2 --exrfog "$exrfog" --jobdir "$job" \
      -- seq/shot.#.exr -o seq/st.#.exr --frames 1-4 "${slow[@]}" >/dev/null 2>&1 &
  pid=$!
  sleep 1
  kill -$sig -- -$pid 2>/dev/null
  wait $pid 2>/dev/null
  sleep 1
  "$farm" status "$job" >status.txt 2>&1
  grep -Eq " (pending|running) " status.txt && { bad "SIG$sig: a chunk stays pending or running"; cat status.txt; }
  grep -Eq " (failed|lost) " status.txt || { bad "SIG$sig: no chunk was stopped (too fast?)"; cat status.txt; }
  "$farm" resubmit --wait "$job" >/dev/null 2>err.txt || { bad "SIG$sig: resubmit failed"; cat err.txt; }
  for f in 1 2 3 4; do
    [ -s "seq/st.000$f.exr" ] || bad "SIG$sig: frame $f not written after the resubmit"
  done
  ls -a seq | grep -q "exrfog-" && bad "SIG$sig: temporary files left in seq/"
done
echo '{"state": ' >"$tmp/job-stop-INT/state/chunk-0000.json"
"$farm" status "$tmp/job-stop-INT" 2>err.txt
[ $? = 1 ] && grep -q "chunk-0000.json: not the JSON exrfog-farm writes" err.txt && ! grep -q Traceback err.txt ||
  { bad "a damaged state file: no clear message"; cat err.txt; }

# An output directory that does not exist is refused up front (issue 42),
# for -o and --preview, before a job directory exists.
"$farm" submit --engine parallel --exrfog "$exrfog" --jobdir "$tmp/job-nodir" -- seq/shot.#.exr \
    -o nodir/f.#.exr --frames 1-3 --fog exp:density=0.05 2>err.txt
[ $? = 2 ] && grep -q "nodir/f.#.exr: its directory nodir does not exist" err.txt ||
  { bad "an output directory that does not exist is not refused"; cat err.txt; }
[ -e "$tmp/job-nodir" ] && bad "a job directory was made for a refused submit"
"$farm" submit --engine parallel --exrfog "$exrfog" --jobdir "$tmp/job-nodir" -- seq/shot.#.exr \
    -o seq/f.#.exr --preview=nodir/p.#.png --frames 1-3 --fog exp:density=0.05 2>err.txt
[ $? = 2 ] && grep -q "does not exist" err.txt || bad "a preview directory that does not exist is not refused"

# Usage of the farm itself.
"$farm" submit --engine slurm -- seq/shot.#.exr -o seq/x.#.exr --fog exp:density=1 2>err.txt
[ $? = 2 ] && grep -q "need --frames" err.txt || bad "submit without --frames is not a usage error"
"$farm" status "$tmp/seq" 2>err.txt
[ $? = 2 ] && grep -q "not an exrfog-farm job directory" err.txt || bad "status of a non-job"
"$farm" submit --engine parallel --exrfog "$exrfog" --jobdir "$tmp/job-slurm" -- seq/shot.#.exr -o seq/x.#.exr \
    --frames 1 --fog exp:density=1 2>err.txt
[ $? = 2 ] && grep -q "not empty" err.txt || bad "an existing job directory is reused"

[ $fail = 0 ] && echo "farm: slurm and parallel: failure report, retries, resubmit, 12 frames equal"
exit $fail
