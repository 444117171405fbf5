#!/usr/bin/env bash
# compare_page.sh MCPOST SOURCE_DIR DIR: the page of `mcpost compare` in headless
# Chromium. Two renders of the Cornell box against its reference, with gates, into DIR;
# then check_page.sh (images load, nothing overflows, a verdict per section, as many
# colour bars as report.json has maps, the wipe's slider moves the split, the display
# controls redraw every HDR render and the wipe follows), and on top of it: a wipe in
# each test's section, four HDR renders (test and reference twice), the gate's verdict
# in words on the page, and exit status 3 (a warning) from compare.
# Skipped (77) without chromium, as check_page.sh.
set -uo pipefail
mcpost=${1:?usage: compare_page.sh MCPOST SOURCE_DIR DIR} src=${2:?} dir=${3:?}
here=$(cd "$(dirname "$0")" && pwd)
cornell=$src/samples/fixtures/cornell
fail() { echo "compare_page: $*" >&2; exit 1; }

rm -rf "$dir"
mkdir -p "$(dirname "$dir")"
"$mcpost" compare "$cornell/cornell_reference.exr" "$cornell/series/cornell_spp0016.exr" \
    "$cornell/series/cornell_spp0256.exr" -o "$dir" --quiet --flip ldr \
    --fail 'flip_ldr.mean > 0.5' --warn 'relmse > 0.1' > "$dir.out"
rc=$?
[ $rc -eq 3 ] || fail "compare exited $rc, want 3 (the 16-spp render has relMSE 0.4 > 0.1)"
tail -n 1 "$dir.out" | grep -q '^WARNING: relmse > 0.1' || fail "last line: $(tail -n 1 "$dir.out")"

result=$("$here/check_page.sh" "$dir" 1280 760)
rc=$?
echo "$result"
[ $rc -eq 77 ] && exit 77
[ $rc -eq 0 ] || fail "check_page.sh failed"
grep -q 'sections=3 compares=2 hdr=4 display=4/4' <<<"$result" ||
    fail "want 3 sections (summary, 2 tests), 2 wipes, 4 HDR renders all redrawn"
grep -q 'class="verdict bad">gate WARNING' "$dir/report.html" && fail "a warning is not red"
grep -q 'class="verdict info">gate WARNING: relmse &gt; 0.1' "$dir/report.html" ||
    fail "no verdict 'gate WARNING: relmse > 0.1' on the page"
grep -q 'class="verdict good">gate PASS; relMSE' "$dir/report.html" ||
    fail "no verdict 'gate PASS' for the 256-spp render"
echo "compare page: PASS"
