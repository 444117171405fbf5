#!/usr/bin/env bash
# cli/heap.c: a subcommand executes mcpost again with glibc.malloc.hugetlb=1 in
# GLIBC_TUNABLES (the heap on transparent huge pages), and the programs it runs see
# GLIBC_TUNABLES as the user had it. An external denoiser command records its own
# environment and mcpost's memory map ($PPID: the /bin/sh that runs the command is
# mcpost's child; "hg" in the heap's VmFlags is glibc's madvise(MADV_HUGEPAGE)) and
# copies its input. MCPOST_HUGE_PAGES=0 turns the second process off; a tunable the
# user names is left alone; the outputs are the same bits either way.
#   huge_pages.sh BUILD_DIR
set -euo pipefail
build=$1
source "$(dirname "$0")/../support/work_dir.sh"
begin_work_dir "$build" huge_pages
mcpost=$build/mcpost
"$build/mcpost-procedural" --width 64 --height 48 --spp 4 --seed 3 -o in >/dev/null
fail=0
check() { # check WHAT CONDITION...
    local what=$1
    shift
    "$@" || { echo "FAIL: $what"; fail=1; }
}
# denoise_recording NAME [ENV...]: runs the external denoiser with the environment
# ENV, leaving NAME.child (the command's environment), NAME.parent (mcpost's
# /proc/PID/smaps) and NAME.exr
denoise_recording() {
    local name=$1
    shift
    env "$@" "$mcpost" denoise in_0000.exr --denoiser external --denoiser-command \
        "env > $work/$name.child; cat /proc/\$PPID/smaps > $work/$name.parent; cp {color} {output}" \
        -o "$name.exr" >/dev/null
}
denoise_recording plain -u GLIBC_TUNABLES -u MCPOST_HUGE_PAGES
denoise_recording off -u GLIBC_TUNABLES MCPOST_HUGE_PAGES=0
denoise_recording user -u MCPOST_HUGE_PAGES GLIBC_TUNABLES=glibc.malloc.check=0
denoise_recording named -u MCPOST_HUGE_PAGES GLIBC_TUNABLES=glibc.malloc.hugetlb=0
# a sanitizer's build (its allocator is its own: one process), which also wants its
# runtime first of all libraries, so that the case below is not run there
sanitized=$(grep -c '^MCPOST_SANITIZE:BOOL=ON' "$build/CMakeCache.txt" || true)
# a library preloaded (another malloc, a profiler): left alone. libc itself stands in
[ "$sanitized" = 0 ] && denoise_recording preload -u MCPOST_HUGE_PAGES -u GLIBC_TUNABLES \
    LD_PRELOAD="$(ldd "$mcpost" | awk '/libc\.so/ { print $3 }')"

# heap_has_huge_pages SMAPS: the [heap] mapping was advised MADV_HUGEPAGE
heap_has_huge_pages() {
    awk '/\[heap\]/ { heap = 1; next }
         heap && /^VmFlags:/ { seen = 1; hg = / hg/; exit }
         END { exit !(seen && hg) }' "$1"
}
export -f heap_has_huge_pages

# the second process runs where the kernel has transparent huge pages and glibc the
# tunable (2.35 and later), and not in a sanitizer's build
thp=/sys/kernel/mm/transparent_hugepage/enabled
glibc=$(getconf GNU_LIBC_VERSION | awk '{ print $2 }')
if [ -r "$thp" ] && ! grep -q '\[never\]' "$thp" &&
   awk -v v="$glibc" 'BEGIN { split(v, p, "."); exit !(p[1] > 2 || p[2] >= 35) }' &&
   [ "$sanitized" = 0 ]; then
    check "mcpost's heap is not on huge pages" heap_has_huge_pages plain.parent
    check "with the user's tunables, mcpost's heap is not on huge pages" \
        heap_has_huge_pages user.parent
else
    echo "no transparent huge pages, glibc $glibc or a sanitizer: mcpost runs once"
fi
check "MCPOST_HUGE_PAGES=0 still put the heap on huge pages" \
    bash -c '! heap_has_huge_pages off.parent'
check "a tunable the user named (hugetlb=0) was changed" \
    bash -c '! heap_has_huge_pages named.parent'
[ "$sanitized" = 0 ] && check "with LD_PRELOAD mcpost still put the heap on huge pages" \
    bash -c '! heap_has_huge_pages preload.parent'
check "the command saw mcpost's GLIBC_TUNABLES" bash -c '! grep -q GLIBC_TUNABLES plain.child'
check "the command saw mcpost's tunable" \
    grep -qx 'GLIBC_TUNABLES=glibc.malloc.check=0' user.child
check "mcpost's saved copy leaked to the command" \
    bash -c '! grep -q MCPOST_SAVED user.child plain.child'
for o in off user named preload; do
    [ -f $o.exr ] || continue
    check "$o.exr differs from plain.exr" cmp -s plain.exr $o.exr
done
[ $fail -eq 0 ] && echo "ok: the heap's second process and the environment it passes on"
exit $fail
