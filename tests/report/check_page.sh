#!/usr/bin/env bash
# check_page.sh [--run MCPOST JOB] REPORT_DIR [WIDTH...]: opens REPORT_DIR/report.html
# (with --run, first made by `MCPOST run JOB --output REPORT_DIR`) in headless Chromium
# at each window width [1280 760] and fails when an image does not load
# (naturalWidth 0), an element sticks out of its box or the page out of the window, a
# section has no verdict, a table cell holds JSON text, or the page shows fewer
# images or colour bars than report.json lists. Then it takes a screenshot of the
# whole page at the first width: REPORT_DIR/report.png.
#
# The checks run in the page (check_page.js, injected into a copy) and write their
# findings into the DOM, which `chromium --dump-dom` gives back. Without chromium it
# exits 77 (ctest: skipped), unless CI=true: CI must not skip it silently.
set -euo pipefail
mcpost="" job=""
if [ "${1:-}" = --run ]; then
    mcpost=${2:?} job=${3:?}
    shift 3
fi
dir=${1:?usage: check_page.sh [--run MCPOST JOB] REPORT_DIR [WIDTH...]}
shift
widths=("$@")
[ ${#widths[@]} -gt 0 ] || widths=(1280 760)
here=$(cd "$(dirname "$0")" && pwd)

browser=""
for b in ${CHROMIUM:-chromium chromium-browser}; do # CHROMIUM: another browser binary
    [ -n "$browser" ] || ! command -v "$b" >/dev/null || browser=$b
done
if [ -z "$browser" ]; then
    if [ "${CI:-}" = true ]; then
        echo "check_page: chromium not found (CI=true: this check must run; setup.sh test installs it)" >&2
        exit 1
    fi
    echo "check_page: chromium not found: skipped (apt-get install chromium)" >&2
    exit 77
fi

if [ -n "$mcpost" ]; then
    rm -rf "$dir"
    "$mcpost" run "$job" --quiet --output "$dir"
fi
page=$dir/report.html json=$dir/report.json
[ -f "$page" ] && [ -f "$json" ] || { echo "check_page: no report.html/report.json in $dir" >&2; exit 1; }

tmp=$(mktemp -d)
# the page with the checks, in the report's folder (same relative paths)
check=$dir/.report-check.html
trap 'rm -rf "$tmp" "$check"' EXIT
sed '/<\/body>/,$d' "$page" > "$check"
{ echo '<script>'; cat "$here/check_page.js"; echo '</script></body></html>'; } >> "$check"

run_browser() { # run_browser ARGS...: chromium headless, its own profile, output on stdout
    timeout 120 "$browser" --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --no-first-run --user-data-dir="$tmp/profile" "$@" 2>>"$tmp/browser.log"
}

want_figures=$( (grep -o '"caption":' "$json" || true) | wc -l)
want_bars=$( (grep -o '"colormap":' "$json" || true) | wc -l)
status=0 height=0
for w in "${widths[@]}"; do
    run_browser --window-size="$w,900" --virtual-time-budget=15000 --dump-dom \
        "file://$(cd "$dir" && pwd)/.report-check.html" > "$tmp/dom.html" || true
    result=$(sed -n '/<pre id="mcp-check">/,/<\/pre>/p' "$tmp/dom.html" |
             sed -e 's/<pre id="mcp-check">//' -e 's/<\/pre>.*//' -e 's/&gt;/>/g' -e 's/&lt;/</g' -e 's/&amp;/\&/g')
    if [ -z "$result" ]; then
        echo "check_page: width $w: no result from the page (chromium log below)" >&2
        tail -20 "$tmp/browser.log" >&2
        exit 1
    fi
    echo "width $w: $result"
    figures=$(sed -n 's/.* figures=\([0-9]*\).*/\1/p' <<<"$result" | head -1)
    bars=$(sed -n 's/.* bars=\([0-9]*\).*/\1/p' <<<"$result" | head -1)
    [ "$w" != "${widths[0]}" ] || height=$(sed -n 's/.* height=\([0-9]*\).*/\1/p' <<<"$result" | head -1)
    case $result in PASS*) ;; *) status=1 ;; esac
    if [ "$figures" != "$want_figures" ]; then
        echo "check_page: width $w: $figures images shown, report.json lists $want_figures" >&2
        status=1
    fi
    if [ "$bars" != "$want_bars" ]; then
        echo "check_page: width $w: $bars colour bars, report.json has $want_bars maps" >&2
        status=1
    fi
done

# the whole page as a picture, for a person to look at
[ "$height" -gt 0 ] 2>/dev/null || height=4000
[ "$height" -le 30000 ] || height=30000
run_browser --window-size="${widths[0]},$height" --virtual-time-budget=15000 \
    --screenshot="$tmp/report.png" "file://$(cd "$dir" && pwd)/report.html" >/dev/null || true
if [ ! -s "$tmp/report.png" ] || [ "$(head -c 8 "$tmp/report.png" | od -An -tx1 | tr -d ' ')" != 89504e470d0a1a0a ]; then
    echo "check_page: no screenshot (chromium log below)" >&2
    tail -20 "$tmp/browser.log" >&2
    exit 1
fi
mv "$tmp/report.png" "$dir/report.png"
echo "screenshot: $dir/report.png (${widths[0]}x$height)"
exit $status
