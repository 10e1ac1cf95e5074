# Shared by the hostile-input checks (sourced): judge LABEL STATUS counts a
# run's outcome ($tmp/stderr, $out) in ran/refused or sets fail=1.
judge() {
    if grep -q 'Sanitizer\|runtime error' "$tmp/stderr"; then
        echo "FAIL: $1: sanitizer report"; head -5 "$tmp/stderr"; fail=1
    elif [ "$2" -eq 0 ]; then
        ran=$((ran + 1))
        [ -s "$out" ] || { echo "FAIL: $1: exit 0 without output"; fail=1; }
    elif [ "$2" -eq 1 ] || [ "$2" -eq 2 ]; then
        refused=$((refused + 1))
        [ -e "$out" ] && { echo "FAIL: $1: output left after exit $2"; fail=1; }
        head -1 "$tmp/stderr" | grep -q '^exrfog: ' ||
            { echo "FAIL: $1: exit $2 without an exrfog: message"; fail=1; }
    else
        echo "FAIL: $1: exit $2"; head -3 "$tmp/stderr"; fail=1
    fi
}
