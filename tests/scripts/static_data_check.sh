#!/bin/sh
# The library keeps nothing per run in statics: the writable static data
# (nm -S: symbols of .data and .bss, local or global) of libexrfog.so stays
# at or below 64 KiB. Prints the largest, for whoever breaks it.
# Usage: static_data_check.sh LIBEXRFOG.so
set -eu
lib=$1
nm -S --size-sort "$lib" | awk 'NF == 4 && $3 ~ /^[bBdD]$/' | tail -5
total=0
for h in $(nm -S "$lib" | awk 'NF == 4 && $3 ~ /^[bBdD]$/ { print $2 }'); do
  total=$((total + 0x$h))
done
echo "static_data: $total bytes of writable static data in $lib (limit 65536)"
[ "$total" -le 65536 ]
