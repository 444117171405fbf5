#!/usr/bin/env bash
# help.sh SOURCE_DIR BIN_DIRS: `mcpost help` against the docs, and every subcommand's
# --help examples run.
#  - `mcpost help TOPIC` prints docs/TOPIC.md byte for byte (built into the tool), for
#    every topic `mcpost help` lists, and the list names conventions, jobs, denoisers
#    with each page's title;
#  - an unknown topic is one line on stderr, nothing on stdout, exit status 2;
#  - every subcommand's --help ends with two or three examples, and each runs from the
#    source folder (exit status 0), as its text says.
set -u
src=${1:?usage: help.sh SOURCE_DIR BIN_DIRS}
export PATH="${2:?usage: help.sh SOURCE_DIR BIN_DIRS}:$PATH"
cd "$src" || exit 2
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }

topics=$(mcpost help | awk '/^  [a-z]/ { print $1 }')
for want in conventions jobs denoisers; do
    grep -qx "$want" <<<"$topics" || fail "mcpost help does not list '$want'"
done
for topic in $topics; do
    if ! mcpost help "$topic" | cmp -s - "docs/$topic.md"; then
        fail "mcpost help $topic differs from docs/$topic.md"
    fi
    title=$(head -n 1 "docs/$topic.md" | sed 's/^# //')
    mcpost help | grep -qF -- "$title" || fail "mcpost help does not give $topic's title '$title'"
done
echo "topics: $(echo $topics)"

out=$(mcpost help no-such-topic 2>/tmp/help_err.$$); rc=$?
err=$(cat /tmp/help_err.$$); rm -f /tmp/help_err.$$
[ $rc -eq 2 ] || fail "unknown topic: exit status $rc, not 2"
[ -z "$out" ] || fail "unknown topic: printed on stdout: $out"
[ "$(printf '%s\n' "$err" | wc -l)" -eq 1 ] || fail "unknown topic: not one line: $err"
grep -qF "unknown topic 'no-such-topic'" <<<"$err" || fail "unknown topic: message: $err"
echo "unknown topic: $err"

# every subcommand's examples: the lines after "examples" that start with "  mcpost",
# each continued by a trailing backslash
commands=$(mcpost --help | awk '/^subcommands:/ { on = 1; next } /^$/ { on = 0 } on { print $1 }')
[ -n "$commands" ] || fail "mcpost --help lists no subcommands"
for cmd in $commands; do
    # a continued line is joined as the shell joins it: backslash-newline removed
    examples=$(mcpost "$cmd" --help | awk '
        /^examples/ { on = 1; next }
        !on { next }
        cont { line = substr(line, 1, length(line) - 1) $0 }
        !cont && /^  mcpost / { line = substr($0, 3) }
        cont || /^  mcpost / {
            cont = /\\$/
            if (!cont) print line
        }')
    n=$(grep -c . <<<"$examples")
    if [ "$n" -lt 2 ] || [ "$n" -gt 3 ]; then
        fail "mcpost $cmd --help: $n examples, not 2 or 3"
    fi
    while IFS= read -r ex; do
        [ -n "$ex" ] || continue
        if timeout 300 bash -o pipefail -c "$ex" >/tmp/help_ex.$$ 2>&1 </dev/null; then
            echo "ok mcpost $cmd --help: $(head -n 1 <<<"$ex")"
        else
            fail "mcpost $cmd --help example exited $?: $ex"
            tail -n 5 /tmp/help_ex.$$ | sed 's/^/    /'
        fi
    done <<<"$examples"
done
rm -f /tmp/help_ex.$$
echo "$failures failures"
[ $failures -eq 0 ]
