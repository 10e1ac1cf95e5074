#!/usr/bin/env bash
# Fogs a frame range as GNU parallel jobs: one exrfog task per chunk of
# frames, on this machine or across hosts. Frames are independent, so the
# result is the same pixels as one `exrfog --frames FIRST-LAST` run.
#
#   exrfog-parallel.sh [-j JOBS] [-c CHUNK] [-t THREADS] [-S SSHLOGINFILE]
#                      FIRST-LAST -- EXRFOG_ARGUMENTS...
#
#   -j JOBS          jobs at once per host (default: parallel's, one per CPU)
#   -c CHUNK         frames per job (default 10)
#   -t THREADS       exrfog --threads per job (default 1: the jobs fill the CPUs)
#   -S SSHLOGINFILE  run across the hosts listed there (parallel --sshloginfile);
#                    paths must be the same on every host (shared storage) and
#                    exrfog installed on each
#   EXRFOG           the exrfog binary (default: exrfog on PATH)
#
# Example, 4 hosts, 100 frames in chunks of 5:
#   exrfog-parallel.sh -S hosts.txt -c 5 1001-1100 -- /show/shot.#.exr \
#       -o /show/fog.#.exr --scene /show/fog.json
#
# Exit status: 0 when every chunk succeeded, else non-zero (parallel's count
# of failed jobs); each failed frame is named on stderr by exrfog.
set -euo pipefail
jobs= chunk=10 threads=1 sshlogin=
while getopts "j:c:t:S:" opt; do
  case $opt in
    j) jobs=$OPTARG ;;
    c) chunk=$OPTARG ;;
    t) threads=$OPTARG ;;
    S) sshlogin=$OPTARG ;;
    *) echo "usage: exrfog-parallel.sh [-j JOBS] [-c CHUNK] [-t THREADS] [-S SSHLOGINFILE] FIRST-LAST -- EXRFOG_ARGS..." >&2; exit 2 ;;
  esac
done
shift $((OPTIND - 1))
range=${1:-}
[ $# -ge 1 ] && shift
[ "${1:-}" = "--" ] && shift
if ! [[ $chunk =~ ^[1-9][0-9]*$ ]] || [ $# -eq 0 ] || ! [[ $range =~ ^(-?[0-9]+)-(-?[0-9]+)$ ]]; then
  echo "usage: exrfog-parallel.sh [-j JOBS] [-c CHUNK] [-t THREADS] [-S SSHLOGINFILE] FIRST-LAST -- EXRFOG_ARGS..." >&2
  exit 2
fi
first=${BASH_REMATCH[1]} last=${BASH_REMATCH[2]}
command -v parallel >/dev/null || { echo "exrfog-parallel.sh: GNU parallel is not installed (apt install parallel)" >&2; exit 2; }
chunks=()
for ((f = first; f <= last; f += chunk)); do
  e=$((f + chunk - 1)); [ $e -gt $last ] && e=$last
  chunks+=("$f-$e")
done
popts=(--will-cite --halt never --line-buffer)
[ -n "$jobs" ] && popts+=(-j "$jobs")
[ -n "$sshlogin" ] && popts+=(--sshloginfile "$sshlogin" --workdir .)
# -q keeps the progress bars of concurrent jobs off the terminal.
exec parallel "${popts[@]}" -q "${EXRFOG:-exrfog}" --frames {} --threads "$threads" -q "$@" ::: "${chunks[@]}"
