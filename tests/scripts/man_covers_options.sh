#!/bin/sh
# usage: man_covers_options.sh EXRFOG MANPAGE
# Fails when a long option listed by `exrfog --help` has no .Fl entry in
# the man page.
bin=$1 man=$2
text=$(sed 's/\\//g' "$man")   # mdoc writes - as \-
missing=
for opt in $("$bin" --help | grep -o -- '--[a-z][a-z-]*' | sort -u); do
    name=${opt#--}
    printf '%s\n' "$text" | grep -q -- "Fl -$name\\b" || missing="$missing $opt"
done
if [ -n "$missing" ]; then
    echo "not documented in $man:$missing"
    exit 1
fi
echo "all options of --help are in $man"
