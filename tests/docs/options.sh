#!/usr/bin/env bash
# options.sh SOURCE_DIR TABLES_DIR [--update]: every docs page's option table is the one
# the operation table gives (ops/, <mcpost/options.h>). A table sits between the lines
# `<!-- options: NAME -->` and `<!-- end options -->`; TABLES_DIR holds NAME.md as the
# build writes them (mcpost-optdoc --write). A page out of date fails, naming it and the
# command that updates it; --update rewrites the pages instead.
set -u
src=${1:?usage: options.sh SOURCE_DIR TABLES_DIR [--update]}
tables=${2:?usage: options.sh SOURCE_DIR TABLES_DIR [--update]}
update=${3:-}
failures=0
checked=0
for page in "$src"/docs/*.md; do
    grep -q '^<!-- options: [a-z_]* -->$' "$page" || continue
    for name in $(sed -n 's/^<!-- options: \([a-z_]*\) -->$/\1/p' "$page"); do
        if [ ! -f "$tables/$name.md" ]; then
            echo "FAIL: $page names operation '$name', which has no table"
            failures=$((failures + 1))
            continue
        fi
        # the page with this block replaced by the generated table
        tmp=$(mktemp)
        awk -v name="$name" -v table="$tables/$name.md" '
            $0 == "<!-- options: " name " -->" {
                print; while ((getline line < table) > 0) print line; skip = 1; next }
            skip && $0 == "<!-- end options -->" { skip = 0 }
            !skip { print }' "$page" > "$tmp"
        checked=$((checked + 1))
        if cmp -s "$tmp" "$page"; then
            echo "ok $page ($name)"
        elif [ "$update" = "--update" ]; then
            cp "$tmp" "$page"
            echo "updated $page ($name)"
        else
            echo "FAIL: $page: the '$name' option table is out of date; run" \
                 "tests/docs/options.sh $src $tables --update"
            failures=$((failures + 1))
        fi
        rm -f "$tmp"
    done
done
[ $checked -gt 0 ] || { echo "FAIL: no page holds an option table"; failures=$((failures + 1)); }
echo "$failures failures"
[ $failures -eq 0 ]
