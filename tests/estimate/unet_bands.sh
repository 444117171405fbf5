#!/usr/bin/env bash
# `mcpost denoise` with the U-Net in bands of rows (docs/denoisers.md, "Images larger
# than memory"): the dump read and the output written a band at a time give the bits of
# the whole-image run, which is the truth here (MCPOST_UNET_BAND_ROWS=whole forces it,
# MCPOST_UNET_BAND_ROWS=N forces bands of N rows). Pixels are compared as PFM bytes
# (cmp): the EXR files may differ in which zip chunks are stored raw.
# 256x1152, small forced bands: 128 rows (crops cut inside the image at both
# ends), 64 rows with tiles of 96 inside them, the default denoiser, and the fixed-bit
# loops' margins; the header attributes are the whole run's; a dump with Inf colour
# fails with the whole run's one line and leaves no output, not even a temporary file.
# The default run under ulimit -v, where the whole image does not fit: unet_memory_bound.sh.
#   unet_bands.sh BUILD_DIR
set -euo pipefail
build=$1
. "$(dirname "$0")/same_pixels.sh"
mcpost=$build/mcpost
source "$(dirname "$0")/../support/work_dir.sh"
begin_work_dir "$build" unet_bands


"$build/mcpost-procedural" --width 256 --height 1152 --spp 2 --seed 5 -o s >/dev/null
MCPOST_UNET_BAND_ROWS=whole "$mcpost" denoise s_0000.exr --denoiser unet -o whole.exr --quiet
MCPOST_UNET_BAND_ROWS=128 "$mcpost" denoise s_0000.exr --denoiser unet -o band128.exr --quiet
same_pixels band128.exr whole.exr
MCPOST_UNET_BAND_ROWS=64 "$mcpost" denoise s_0000.exr --denoiser unet \
    --denoiser-opt tile=96 -o band64.exr --quiet
same_pixels band64.exr whole.exr
# the default denoiser (the U-Net on a dump with albedo and normal) streams too
MCPOST_UNET_BAND_ROWS=192 "$mcpost" denoise s_0000.exr -o default.exr --quiet
same_pixels default.exr whole.exr
"$mcpost" info whole.exr | sed 1d >whole.info
"$mcpost" info band128.exr | sed 1d >band.info
diff whole.info band.info || { echo "FAIL: the headers differ"; exit 1; }
MCPOST_UNET_BAND_ROWS=whole "$mcpost" denoise s_0000.exr --denoiser unet \
    --denoiser-opt fixed_bits=true -o whole_fixed.exr --quiet
MCPOST_UNET_BAND_ROWS=320 "$mcpost" denoise s_0000.exr --denoiser unet \
    --denoiser-opt fixed_bits=true -o band_fixed.exr --quiet
same_pixels band_fixed.exr whole_fixed.exr

"$build/mcpost-procedural" --width 256 --height 640 --spp 2 --seed 7 \
    --firefly-value 1e39 --firefly-probability 1e-4 -o inf >/dev/null
set +e
MCPOST_UNET_BAND_ROWS=whole "$mcpost" denoise inf_0000.exr --denoiser unet -o inf_w.exr \
    --quiet 2>inf_whole.err
w=$?
MCPOST_UNET_BAND_ROWS=128 "$mcpost" denoise inf_0000.exr --denoiser unet -o inf_b.exr \
    --quiet 2>inf_band.err
b=$?
set -e
echo "Inf colour: whole exit $w, bands exit $b: $(cat inf_band.err)"
[ "$w" -eq 1 ] && [ "$b" -eq 1 ] || { echo "FAIL: exit $w, $b (want 1)"; exit 1; }
[ "$(wc -l <inf_band.err)" -eq 1 ] || { echo "FAIL: not one line"; exit 1; }
diff inf_whole.err inf_band.err || { echo "FAIL: the messages differ"; exit 1; }
if ls -a | grep -q '^inf_b\.'; then echo "FAIL: a failed run left a file"; ls -a; exit 1; fi

echo PASS
