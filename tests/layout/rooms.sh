#!/usr/bin/env bash
# tests/layout/rooms.sh SOURCE_DIR: the includes of common/ run one way (docs/library.md,
# "Inside common/"). Every file of common/ lies in a room, a room includes only itself
# and the rooms below it in the table, and nothing in common/ includes the folders
# built on it (jobs/, cli/, ops/, estimate/, blend/, perceptual/, ...). An include is
# followed to the file it names: a quoted one relative to the including file, a
# <mcpost/NAME.h> one to the public header NAME.h of the tree (CMake mirrors each from
# its folder into build/include/mcpost/). Fails naming the file, its line and what it
# includes.
set -euo pipefail
cd "$1"

# The rooms, lowest first, each with the rooms it may include besides itself.
declare -A allowed=(
    [core]=""
    [yaml]="core"
    [io]="core"
    [filter]="core"
    [dump]="core io"
    [report]="core io filter"
    [metrics]="core io filter report"
)
# The folders of the library and its users: every header outside common/ that an
# include could name lies in one of them.
folders=(common estimate blend perceptual ops jobs cli python samples tools bench tests
         include)

# The public headers by name: a <mcpost/NAME.h> include names the one NAME.h of these
# folders that is not internal (internal headers are never included that way).
declare -A public=()
while IFS= read -r h; do
    name=${h##*/}
    case $name in *internal.h | *_shim.h) continue ;; esac
    if [ -n "${public[$name]:-}" ]; then
        echo "rooms.sh: two headers called $name: ${public[$name]} and $h" >&2
        exit 1
    fi
    public[$name]=$h
done < <(find "${folders[@]}" -name '*.h' -not -path 'tests/*' | LC_ALL=C sort)

fail=0
files=0
includes=0
while IFS= read -r f; do
    files=$((files + 1))
    rel=${f#common/}
    room=${rel%%/*}
    if [ "$room" = "$rel" ] || [ -z "${allowed[$room]+set}" ]; then
        echo "rooms.sh: $f is in no room of common/ (rooms: ${!allowed[*]};" \
            "a new one goes into the table here and into docs/library.md)" >&2
        fail=1
        continue
    fi
    while IFS=: read -r line target; do
        case $target in
        '<mcpost/'*)
            name=${target#<mcpost/}
            name=${name%>}
            path=${public[$name]:-}
            if [ -z "$path" ]; then
                echo "rooms.sh: $f:$line includes <mcpost/$name>, no header of the tree" >&2
                fail=1
                continue
            fi
            ;;
        '"'*)
            name=${target#\"}
            name=${name%\"}
            path=$(realpath -m --relative-to=. "$(dirname "$f")/$name")
            ;;
        *) continue ;; # a system or library header
        esac
        includes=$((includes + 1))
        case $path in
        common/*/*)
            to=${path#common/}
            to=${to%%/*}
            [ "$to" = "$room" ] && continue
            case " ${allowed[$room]} " in *" $to "*) continue ;; esac
            echo "rooms.sh: $f:$line includes $path: common/$room/ may include" \
                "${allowed[$room]:-no other room}, not common/$to/ (docs/library.md," \
                "\"Inside common/\")" >&2
            fail=1
            ;;
        *)
            echo "rooms.sh: $f:$line includes $path: common/ includes nothing outside" \
                "its rooms (docs/library.md, \"Inside common/\")" >&2
            fail=1
            ;;
        esac
    done < <(grep -n '^[[:space:]]*#[[:space:]]*include' "$f" |
        sed 's/^\([0-9]*\):[[:space:]]*#[[:space:]]*include[[:space:]]*\([<"][^>"]*[>"]\).*/\1:\2/')
done < <(find common -type f \( -name '*.c' -o -name '*.h' -o -name '*.cpp' \) | LC_ALL=C sort)

if [ "$fail" -ne 0 ]; then
    echo "rooms.sh: common/'s includes do not run one way" >&2
    exit 1
fi
echo "rooms.sh: $files files in ${#allowed[@]} rooms, $includes includes of mcpost's" \
    "own headers, each to its own room or one below"
