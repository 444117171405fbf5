#!/usr/bin/env bash
# The U-Net's working memory is bounded by default (max_memory_mb, 2048): under an
# address-space limit (ulimit -v) that the whole image's activations do not fit in, a
# bounded run goes in tiles and writes the bits of the unbounded one; with a bound
# above the limit the same run fails with one line, not a crash. 2400x1600 with the
# official weights: the unbounded run needs more than 1700 MB of address space (its
# activations alone are 1.48 GB), the bounded one (900 MB: crops of up to 1400 x 1400,
# tiles of 624 and 352 pixels of margin) runs within 1100 (peak resident 0.96 GB);
# the limit is 1200.
#   unet_memory_bound.sh BUILD_DIR
set -euo pipefail
build=$1
mcpost=$build/mcpost
work=$build/test-tmp/unet_memory_bound
rm -rf "$work" && mkdir -p "$work" && cd "$work"
"$build/mcpost-procedural" --width 2400 --height 1600 --spp 4 --seed 3 -o in >/dev/null
mv in_0000.exr in.exr
"$mcpost" denoise in.exr --denoiser unet -o whole.exr --quiet
limit_kb=$((1200 * 1024))
set +e
( ulimit -v "$limit_kb"; "$mcpost" denoise in.exr --denoiser unet \
    --denoiser-opt max_memory_mb=900 -o tiled.exr --quiet ) 2>bounded.err
bounded=$?
( ulimit -v "$limit_kb"; "$mcpost" denoise in.exr --denoiser unet \
    --denoiser-opt max_memory_mb=100000 -o untiled.exr --quiet ) 2>unbounded.err
unbounded=$?
set -e
echo "bounded (900 MB) under ulimit -v ${limit_kb} kB: exit $bounded"
echo "unbounded under the same limit: exit $unbounded: $(cat unbounded.err)"
[ "$bounded" -eq 0 ] || { cat bounded.err; echo "FAIL: the bounded run failed"; exit 1; }
"$mcpost" metrics tiled.exr whole.exr --json > same.json
python3 - "$work/same.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
mse = j.get("mse", j.get("tests", [{}])[0].get("mse") if "tests" in j else None)
if isinstance(mse, dict): mse = mse.get("value", mse.get("mean"))
print("tiled against whole: MSE", mse)
sys.exit(0 if mse == 0 else 1)
PY
[ "$unbounded" -ne 0 ] && [ "$unbounded" -lt 128 ] ||
    { echo "FAIL: without a bound the run should fail cleanly (exit $unbounded)"; exit 1; }
[ "$(wc -l < unbounded.err)" -eq 1 ] || { echo "FAIL: not one line"; exit 1; }
[ ! -e untiled.exr ] || { echo "FAIL: a failed run left its output"; exit 1; }
echo PASS
