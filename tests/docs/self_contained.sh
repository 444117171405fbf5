#!/usr/bin/env bash
# self_contained.sh SOURCE_DIR: no file of the repository points outside it. Every file
# git tracks (and every new file it does not ignore), binary files aside, is searched for
# references to material a clone does not have: the sibling folder of shared notes, the
# specification and notes kept there, by name, section citations of that specification
# or of those notes (the name followed by a section number), the style guide's numbered
# rules, and absolute paths of the machine the project was written on. The mathematics,
# the FLIP and OIDN facts and the library pitfalls the code relies on live in docs/ and
# are cited there (docs/testing.md, "Self-contained"). A failure names the file, the
# line and what it points at. Exit 0: none found; 1: some found; 77: SOURCE_DIR is not
# a git checkout.
set -u
cd "${1:?usage: self_contained.sh SOURCE_DIR}" || exit 2

if ! git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    echo "not a git checkout: nothing to list the files with"
    exit 77
fi

# The patterns are written in pieces so that this file does not match itself.
spec=SP""EC
patterns=(
    "\.\./sha""red|sha""red/(notes|papers|anchors|hooks)/"  # the sibling folder
    "${spec}\.md|ST""YLE\.md"                               # its documents by name
    "(^|[^A-Za-z0-9_])${spec}([^A-Za-z0-9_]|$)"             # citations of the spec
    "no""tes/(oidn|flip|libraries|stratification)\.md"      # its notes
    "(^|[^A-Za-z])no""tes( section)? [0-9]"                 # a note's section number
    "(^|[^A-Za-z_])ST""YLE [0-9]"                           # the style guide's rules
    "(^|[^A-Za-z0-9_.~-])/wo""rk/"                          # the machine's paths
)
regex=$(IFS='|'; echo "${patterns[*]}")

list=$(mktemp) || exit 2
trap 'rm -f "$list"' EXIT
# deleted in the working tree, or a submodule: not a file to read
git ls-files -z --cached --others --exclude-standard |
    while IFS= read -r -d '' f; do [ -f "$f" ] && printf '%s\0' "$f"; done >"$list"
files=$(tr -cd '\0' <"$list" | wc -c)

# -I: binary files (weights, images) are skipped; -H: always name the file
hits=$(xargs -0 grep -I -H -n -E -- "$regex" <"$list" | cut -c1-200)
n=0
if [ -n "$hits" ]; then
    echo "$hits"
    n=$(printf '%s\n' "$hits" | wc -l)
fi
echo "$files files checked, $n references outside the repository"
[ "$files" -gt 0 ] && [ "$n" -eq 0 ]
