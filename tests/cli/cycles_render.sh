#!/usr/bin/env bash
# cycles_render.sh BUILD_DIR SOURCE_DIR: a .blend to an estimate (issue 29).
#
# Saves Blender's factory scene (cube, light, camera) as a Cycles .blend, renders it
# through tools/mcpost-cycles-render.py at 32x32, 2 seeds x 2 chunks x 4 spp, and
# checks what docs/conventions.md ("From a .blend to an estimate") promises:
#   - per seed the checkpoints at 4 and 8 spp, in Cycles' naming (convention blender,
#     the sample count from cycles.ViewLayer.samples, no variance);
#   - the tool merged them (mcpost on PATH) into render_spp0008/0016.exr;
#   - `mcpost estimate` of the merged render succeeds, its variance from replicates,
#     and `estimate --series` over the merged checkpoints does too;
#   - one seed's render alone fails with the one-line error that names the tool;
#   - the tool's --help, inside Blender and out, exits 0.
# Without blender the test is skipped (exit 77); `./setup.sh test` installs it.
set -euo pipefail
BUILD=$(cd "$1" && pwd)
SRC=$(cd "$2" && pwd)
TOOL=$SRC/tools/mcpost-cycles-render.py
MCPOST=$BUILD/mcpost
command -v blender >/dev/null || { echo "cycles_render: no blender: skipped" >&2; exit 77; }

T=$(mktemp -d "${TMPDIR:-/tmp}/mcpost-cycles-test.XXXXXX")
trap 'rm -rf "$T"' EXIT
fail() {
    echo "cycles_render: FAIL: $*" >&2
    exit 1
}

blender -b --factory-startup --python-expr \
    "import bpy; bpy.context.scene.render.engine = 'CYCLES'; bpy.ops.wm.save_as_mainfile(filepath='$T/tiny.blend')" \
    >"$T/save.log" 2>&1 || { cat "$T/save.log" >&2; fail "could not save tiny.blend"; }

python3 "$TOOL" --help | grep -q -- '--seeds K' || fail "--help outside Blender"
blender -b "$T/tiny.blend" --python "$TOOL" -- --help >"$T/help.log" 2>&1 ||
    fail "--help inside Blender exited non-zero"
grep -q -- 'mcpost estimate' "$T/help.log" || fail "--help names no mcpost command"

PATH=$BUILD:$PATH blender -b "$T/tiny.blend" --python "$TOOL" -- --out "$T/r" \
    --seeds 2 --spp 8 --chunks 2 --resolution 32x32 --threads 1 >"$T/render.log" 2>&1 ||
    { tail -n 30 "$T/render.log" >&2; fail "the tool failed"; }
for f in seed0/render_spp0004.exr seed0/render_spp0008.exr seed1/render_spp0004.exr \
    seed1/render_spp0008.exr render_spp0008.exr render_spp0016.exr mcpost-cycles-render.txt; do
    [ -f "$T/r/$f" ] || fail "no $f (tool log: $T/render.log)"
done

"$MCPOST" info "$T/r/seed0/render_spp0008.exr" >"$T/info.txt"
grep -q '^convention: *blender' "$T/info.txt" || fail "seed0 checkpoint: not convention blender"
grep -q '^samples: *8 per pixel' "$T/info.txt" || fail "seed0 checkpoint: not 8 spp"
grep -q '^variance: *none' "$T/info.txt" || fail "seed0 checkpoint has a variance"
grep -q 'Denoising Albedo.R' "$T/info.txt" || fail "seed0 checkpoint: no Denoising Albedo"
grep -q 'Denoising Normal.Z' "$T/info.txt" || fail "seed0 checkpoint: no Denoising Normal"

"$MCPOST" estimate "$T/r/render_spp0016.exr" --denoiser nlm -o "$T/est" >"$T/est.log" 2>&1 ||
    { cat "$T/est.log" >&2; fail "estimate of the merged render"; }
grep -q '"variance_source":[[:space:]]*"replicates"' "$T/est/estimate.json" ||
    fail "estimate.json: variance_source is not replicates"
"$MCPOST" estimate --series "$T/r/render_spp%04d.exr" --spp 8,16 --denoiser nlm \
    -o "$T/series" >"$T/series.log" 2>&1 ||
    { cat "$T/series.log" >&2; fail "estimate --series of the merged checkpoints"; }

# one seed's checkpoints as a series: the variance from its increments, by default
"$MCPOST" estimate --series "$T/r/seed0/render_spp%04d.exr" --spp 4,8 --denoiser nlm \
    -o "$T/seed0" >"$T/seed0.log" 2>&1 ||
    { cat "$T/seed0.log" >&2; fail "estimate --series of one seed's checkpoints"; }
grep -q '"variance_source":[[:space:]]*"increments"' "$T/seed0/estimate.json" ||
    fail "one seed's series: variance_source is not increments"
"$MCPOST" blend "$T/r/seed0/render_spp%04d.exr" --spp 4,8 --denoiser nlm --no-flip \
    -o "$T/blend0" >"$T/blend0.log" 2>&1 ||
    { cat "$T/blend0.log" >&2; fail "blend of one seed's checkpoints"; }
[ -f "$T/blend0/render_spp0008.blend.exr" ] || fail "blend0: no blend written"

if "$MCPOST" estimate "$T/r/seed0/render_spp0008.exr" -o "$T/one" 2>"$T/one.log"; then
    fail "estimate of one seed's render (no variance) succeeded"
fi
[ "$(wc -l <"$T/one.log")" -eq 1 ] || { cat "$T/one.log" >&2; fail "the error is not one line"; }
grep -q 'has no variance: Cycles writes none; render the .blend with tools/mcpost-cycles-render.py' \
    "$T/one.log" || { cat "$T/one.log" >&2; fail "the error does not name the recipe"; }
echo "cycles_render: ok"
