#!/usr/bin/env bash
# links.sh SOURCE_DIR [PAGE...]: every relative link in README.md and docs/*.md points at
# a file that exists and, with #anchor, at a heading of that page (GitHub's anchors:
# lower case, punctuation other than - and _ dropped, spaces to -). A failure names the
# page and line.
set -u
cd "${1:?usage: links.sh SOURCE_DIR [PAGE...]}" || exit 2
shift
[ $# -gt 0 ] || set -- README.md docs/*.md

# the anchors of a page's headings (outside fenced blocks)
anchors() {
    awk '/^```/ { f = !f; next } !f && /^#+ / { sub(/^#+ /, ""); print }' "$1" |
        tr 'A-Z' 'a-z' | sed -e 's/[^a-z0-9 _-]//g' -e 's/ /-/g'
}

failures=0 links=0
for page in "$@"; do
    dir=$(dirname "$page")
    # "LINE<TAB>TARGET" for every [text](target) outside fenced blocks
    while IFS=$'\t' read -r line target; do
        [ -n "$target" ] || continue
        case $target in http://*|https://*|mailto:*) continue ;; esac
        links=$((links + 1))
        file=${target%%#*} anchor=
        [ "$file" != "$target" ] && anchor=${target#*#}
        [ -n "$file" ] && path=$dir/$file || path=$page
        if [ ! -e "$path" ]; then
            echo "$page:$line: link to a missing file: $target"
            failures=$((failures + 1))
        elif [ -n "$anchor" ] && ! anchors "$path" | grep -qxF -- "$anchor"; then
            echo "$page:$line: no heading for #$anchor in $path"
            failures=$((failures + 1))
        fi
    done < <(awk '/^```/ { f = !f; next }
                  !f { s = $0
                       while (match(s, /\]\([^) ]+\)/)) {
                           print FNR "\t" substr(s, RSTART + 2, RLENGTH - 3)
                           s = substr(s, RSTART + RLENGTH)
                       } }' "$page")
done
echo "$links links checked, $failures broken"
[ $links -gt 0 ] && [ $failures -eq 0 ]
