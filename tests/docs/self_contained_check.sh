#!/usr/bin/env bash
# self_contained_check.sh: self_contained.sh against a repository whose answer is known.
# A scratch git repository holds one line per kind of reference outside the repository
# (each must be reported, by file and line) and lines that only look alike (identifiers
# such as MCP_SPECTRA_H, the word "notes", docs/ citations, relative paths through a
# folder of the same name; none may be), plus a binary file with a reference in it
# (skipped), an untracked file (checked) and an ignored one (not). Exit 0 when the
# report is exactly the expected one, and the clean repository passes.
set -u
here=$(cd "$(dirname "$0")" && pwd)
tmp=$(mktemp -d) || exit 2
trap 'rm -rf "$tmp"' EXIT
cd "$tmp" || exit 2
git init -q . || exit 2

# Built from pieces, so that this file does not match the patterns itself.
S=SP""EC N=no""tes Y=ST""YLE W=wo""rk D=sha""red
{
    echo "/* sure.c: SURE ($S \"SURE\"; Firmino 2024) */"          # 1
    echo "see ../$D/$N/oidn.md for the network"                     # 2
    echo "    /* the values of $N 3.2 */"                           # 3
    echo "# modules by hand ($N/libraries.md 1.2)"                  # 4
    echo " * reproducible ($Y 12). */"                              # 5
    echo "the papers are in /$W/$D/papers"                          # 6
    echo "as $S's model says"                                       # 7
    echo "$S.md is the reference"                                   # 8
    echo "(${N}/flip.md §3)"                                        # 9
    echo "$N section 5 of the OIDN page"                            # 10
    echo "a note of $N/stratification.md"                           # 11
    echo "#ifndef MCP_${S}TRA_H"                                    # 12: clean
    echo "OPT_NO_${S}TRA and ${S}TRA_LIMIT"                         # 13: clean
    echo "release $N and more $N; footnotes 3"                      # 14: clean
    echo "docs/mathematics.md §3.2 and docs/oidn-network.md §3.7"   # 15: clean
    echo "/tmp/$W/out and ./$W/x and ~/$W/y"                        # 16: clean
    echo "YAML_SINGLE_QUOTED_SCALAR_${Y}"                           # 17: clean
    echo "${D}_lib/${N}/x and docs/${D}.md"                         # 18: clean
} >code.c
printf 'weights\0%s\n' "$S 3.2" >blob.bin                           # binary: skipped
echo "ignored.txt" >.gitignore
echo "($S \"blend\")" >ignored.txt                                  # ignored: not read
git add code.c blob.bin .gitignore || exit 2
echo "($S \"blend\")" >untracked.md                                 # untracked: read

out=$(bash "$here/self_contained.sh" "$tmp")
rc=$?
expected="code.c:1
code.c:2
code.c:3
code.c:4
code.c:5
code.c:6
code.c:7
code.c:8
code.c:9
code.c:10
code.c:11
untracked.md:1"
got=$(printf '%s\n' "$out" | grep -E '^[^ ]+:[0-9]+:' | cut -d: -f1,2 | sort -t: -k1,1 -k2,2n)
fail=0
if [ "$rc" -ne 1 ]; then
    echo "exit status $rc with references present, expected 1"; fail=1
fi
if [ "$got" != "$expected" ]; then
    echo "reported:"; printf '%s\n' "$got"; echo "expected:"; printf '%s\n' "$expected"
    fail=1
fi
if ! printf '%s\n' "$out" | tail -n 1 | grep -qx '4 files checked, 12 references outside the repository'; then
    echo "summary line: $(printf '%s\n' "$out" | tail -n 1)"; fail=1
fi

# Without the references it passes.
sed -i '1,11d' code.c && rm -f untracked.md
out=$(bash "$here/self_contained.sh" "$tmp")
rc=$?
if [ "$rc" -ne 0 ]; then
    echo "clean repository: exit status $rc, expected 0"; printf '%s\n' "$out"; fail=1
fi
[ $fail -eq 0 ] && echo "self_contained.sh: 12 of 12 references found, 7 look-alikes and a binary passed"
exit $fail
