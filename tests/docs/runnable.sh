#!/usr/bin/env bash
# runnable.sh SOURCE_DIR BIN_DIRS [PAGE...]: run every command that README.md and
# docs/*.md mark runnable, from the repository root against the build (BIN_DIRS: the
# folders of the built mcpost and mcpost-procedural, colon-separated, put first on PATH),
# so that the docs cannot drift from the tool.
#
# A runnable block is a fenced block whose info string is `sh runnable`. Each command in
# it runs on its own (`bash -o pipefail -c`, no state carried between commands) and must
# exit 0 within MCPOST_DOCS_TIMEOUT seconds [120]. Lines starting with `#` are comments; a
# line ending in `\` continues on the next. When a block shows a prompt (`$ command`),
# only the prompted lines are commands and each line after one, up to the next prompt, is
# output that the command must print (stdout or stderr, as a substring of one line).
# A failure names the page and line: `docs/jobs.md:42: ...`.
set -u
src=${1:?usage: runnable.sh SOURCE_DIR BIN_DIRS [PAGE...]}
bins=${2:?usage: runnable.sh SOURCE_DIR BIN_DIRS [PAGE...]}
shift 2
cd "$src" || exit 2
export PATH="$bins:$PATH"
timeout_s=${MCPOST_DOCS_TIMEOUT:-120}

if [ $# -eq 0 ]; then
    set -- README.md docs/*.md
fi

# Every runnable block, as records "KIND<TAB>PAGE<TAB>LINE<TAB>TEXT": C a command, E a
# line of output the command before it must print.
records=$(awk '
    FNR == 1 { inblock = 0; cont = "" }
    /^```/ {
        if (!inblock && $0 ~ /^```sh[ \t]+runnable[ \t]*$/) {
            inblock = 1; prompted = 0; n = 0; start = FNR; next
        }
        if (inblock) {
            # a whole block is read before its kind (prompted or not) is known
            for (i = 1; i <= n; i++) {
                t = text[i]
                if (prompted) {
                    if (t ~ /^\$ /) print "C\t" FILENAME "\t" line[i] "\t" substr(t, 3)
                    else if (t !~ /^[ \t]*$/) print "E\t" FILENAME "\t" line[i] "\t" t
                } else if (t !~ /^[ \t]*(#|$)/) {
                    print "C\t" FILENAME "\t" line[i] "\t" t
                }
            }
            inblock = 0; next
        }
    }
    inblock {
        # a continued line is joined as the shell joins it: backslash-newline removed
        if (cont != "") { text[n] = substr(text[n], 1, length(text[n]) - 1) $0 }
        else { n++; text[n] = $0; line[n] = FNR }
        if ($0 ~ /^\$ /) prompted = 1
        cont = ($0 ~ /\\$/) ? "yes" : ""
    }
' "$@") || exit 2

tmp=$(mktemp -d) || exit 2
trap 'rm -rf "$tmp"' EXIT
failures=0 commands=0 checked=0
last_ok=0
while IFS=$'\t' read -r kind page line text; do
    [ -n "$kind" ] || continue
    if [ "$kind" = C ]; then
        commands=$((commands + 1))
        start=$(date +%s.%N)
        timeout "$timeout_s" bash -o pipefail -c "$text" >"$tmp/out" 2>&1 </dev/null
        rc=$?
        secs=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
        if [ $rc -ne 0 ]; then
            failures=$((failures + 1)); last_ok=0
            if [ $rc -eq 124 ]; then
                echo "$page:$line: timed out after ${timeout_s} s: $text"
            else
                echo "$page:$line: exit status $rc: $text"
            fi
            tail -n 5 "$tmp/out" | sed 's/^/    /'
        else
            last_ok=1
            echo "ok $page:$line (${secs} s)"
        fi
    else
        [ $last_ok -eq 1 ] || continue
        checked=$((checked + 1))
        if ! grep -qF -- "$text" "$tmp/out"; then
            failures=$((failures + 1))
            echo "$page:$line: the command before did not print: $text"
            tail -n 5 "$tmp/out" | sed 's/^/    /'
        fi
    fi
done <<<"$records"

echo "$commands runnable commands, $checked output lines checked, $failures failures"
[ $commands -gt 0 ] || { echo "no runnable commands found in: $*"; exit 1; }
[ $failures -eq 0 ]
