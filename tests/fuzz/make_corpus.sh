#!/usr/bin/env bash
# make_corpus.sh BUILD_DIR: makes the seed corpora (corpus/<target>/) and the
# regression inputs (regressions/<target>/) that are committed beside it, from a
# build's mcpost and mcpost-procedural. Run by hand when a format changes; every file
# stays small (a few KB), except the 100 KB nesting bomb that issue 15 names.
set -euo pipefail
cd "$(dirname "$0")"
build=$(cd "$1" && pwd)
mcpost=$build/mcpost
procedural=$build/mcpost-procedural
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p corpus/{pfm,exr,dump,job,tza,bands} regressions/{pfm,exr,dump,job,tza,bands}

# ---- images and dumps: a 4x3 procedural render, written every way we read ----
"$procedural" --width 4 --height 3 --spp 4 -o "$tmp/d" >/dev/null
d=$tmp/d_0000.exr
cp "$d" corpus/exr/dump_pbrt_zip.exr
for c in none rle zips piz pxr24; do
    "$mcpost" convert "$d" corpus/exr/rgb_$c.exr --channels R,G,B --compression $c
done
"$mcpost" convert "$d" corpus/exr/rgb_half.exr --channels R,G,B --half
"$mcpost" convert "$d" corpus/exr/rgb_tiled.exr --channels R,G,B --tiled 2 --compression none
for conv in mitsuba blender mcpost; do
    "$mcpost" convert "$d" "corpus/dump/$conv.exr" --dump $conv --compression none
done
cp "$d" corpus/dump/pbrt.exr
"$mcpost" convert "$d" corpus/pfm/rgb.pfm --channels R,G,B
"$mcpost" convert "$d" corpus/pfm/grey.pfm --channels R
# a dump in separate files: colour, variance, albedo, normal (PFM), joined by the
# fuzz_dump separator line
"$mcpost" convert "$d" "$tmp/var.pfm" --channels Variance.R,Variance.G,Variance.B
"$mcpost" convert "$d" "$tmp/alb.pfm" --channels Albedo.R,Albedo.G,Albedo.B
"$mcpost" convert "$d" "$tmp/nrm.pfm" --channels N.X,N.Y,N.Z
{
    cat corpus/pfm/rgb.pfm; printf 'MCPPART\n'; cat "$tmp/var.pfm"; printf 'MCPPART\n'
    cat "$tmp/alb.pfm"; printf 'MCPPART\n'; cat "$tmp/nrm.pfm"
} >corpus/dump/separate_pfm.bin
{
    cat corpus/exr/rgb_none.exr; printf 'MCPPART\n'; cat "$tmp/var.pfm"
    printf 'MCPPART\nMCPPART\nMCPPART\n'; cat corpus/pfm/grey.pfm
} >corpus/dump/separate_spp_map.bin

# ---- bands: a 6x37 dump (three zip chunks, two piz ones, tiles of 4) and the small
# files, each after the byte that picks the band height and the bad-value policy
# (fuzz_bands.c: 1 + (byte >> 1) % 64 rows; bit 0 the policy) ----
"$procedural" --width 6 --height 37 --spp 4 -o "$tmp/b" >/dev/null
b=$tmp/b_0000.exr
"$mcpost" convert "$b" "$tmp/b_piz.exr" --compression piz --quiet
"$mcpost" convert "$b" "$tmp/b_tiled.exr" --tiled 4 --quiet
"$mcpost" convert "$b" "$tmp/b_mitsuba.exr" --dump mitsuba --quiet
"$mcpost" convert "$b" "$tmp/b_mcpost.exr" --dump mcpost --quiet
prefixed() { # prefixed BYTE FILE OUT
    { printf "\\$(printf %03o "$1")"; cat "$2"; } >"$3"
}
prefixed 8 "$b" corpus/bands/pbrt_zip.bin
prefixed 13 "$tmp/b_piz.exr" corpus/bands/pbrt_piz.bin
prefixed 10 "$tmp/b_tiled.exr" corpus/bands/pbrt_tiled.bin
prefixed 4 "$tmp/b_mitsuba.exr" corpus/bands/mitsuba.bin
prefixed 31 "$tmp/b_mcpost.exr" corpus/bands/mcpost.bin
prefixed 2 corpus/dump/blender.exr corpus/bands/blender_small.bin
prefixed 3 corpus/exr/rgb_half.exr corpus/bands/rgb_half.bin
prefixed 8 regressions/exr/data_window_30000.exr regressions/bands/data_window_30000.bin
prefixed 9 regressions/dump/newline_in_channel_name.exr \
    regressions/bands/newline_in_channel_name.bin

# ---- jobs: the samples' jobs, renamed onto the files fuzz_job makes ----
for j in ../../samples/jobs/*.yaml; do
    sed -e 's#\.\./[A-Za-z0-9_./-]*%04d\.exr#x_%04d.exr#g' \
        -e 's#\.\./[A-Za-z0-9_./-]*\[0-3\][A-Za-z0-9_./-]*\.exr#r[12].exr#g' \
        -e 's#\.\./[A-Za-z0-9_./-]*\.exr#in.exr#g' "$j" >"corpus/job/$(basename "$j")"
done
cat >corpus/job/series.yaml <<'YAML'
inputs:
  s: {series: 'x_%04d.exr', spp: [1, 2], variance_from: increments}
  r: {replicates: [r1.exr, r2.exr], merge: pooled, pool: 1}
  ref: {image: ref.exr}
output: out/x
stages:
  - estimate: {input: s, reference: ref, taus: [0.01, 0.02]}
  - blend: {input: s}
YAML

# ---- weights: small archives in OIDN's .tza layout (docs/oidn-network.md §2) ----
python3 - corpus/tza <<'PY'
import struct, sys
def tza(path, tensors):
    data, table = bytearray(), bytearray(struct.pack('<I', len(tensors)))
    for name, dims, dtype in tensors:
        n = 1
        for d in dims:
            n *= d
        off = 12 + len(data)
        data += bytes(range(n * (4 if dtype == 'f' else 2) % 256)) * 0 + \
            bytes((i * 37) % 251 for i in range(n * (4 if dtype == 'f' else 2)))
        layout = b'oihw' if len(dims) == 4 else b'x'
        table += struct.pack('<H', len(name)) + name.encode() + bytes([len(dims)])
        table += b''.join(struct.pack('<I', d) for d in dims) + layout + dtype.encode()
        table += struct.pack('<Q', off)
    head = struct.pack('<HBBQ', 0x41D7, 2, 0, 12 + len(data))
    open(path, 'wb').write(head + data + table)
tza(sys.argv[1] + '/two_tensors.tza',
    [('enc_conv0.weight', (2, 1, 3, 3), 'f'), ('enc_conv0.bias', (2,), 'h')])
tza(sys.argv[1] + '/half_conv.tza', [('dec_conv0.weight', (3, 2, 3, 3), 'h')])
PY

# ---- regressions: every input issue 15 names ----
{ printf 'stages:\n  - '; head -c 50000 /dev/zero | tr '\0' '['; head -c 50000 /dev/zero | tr '\0' ']'; printf '\n'; } \
    >regressions/job/nesting_50000.yaml
printf 'inputs:\n  s: {series: renders/x_%%2147483640d.exr, spp: [1]}\nstages:\n  - info: {input: s}\n' \
    >regressions/job/series_width_int_overflow.yaml
printf 'inputs:\n  s: {series: renders/x_%%400000000d.exr, spp: [1, 2, 3, 4, 5, 6, 7, 8]}\nstages:\n  - info: {input: s}\n' \
    >regressions/job/series_width_400M.yaml
printf 'Pf 51110 31110\n-1\n' >regressions/pfm/header_claims_48GiB.pfm
{ printf 'PF4 3\n-1\n'; head -c 144 /dev/zero; } >regressions/pfm/no_space_after_magic.pfm
# an EXR whose dataWindow says 30000x30000 (the header of a 4x3 file, patched)
python3 - corpus/exr/rgb_none.exr regressions/exr/data_window_30000.exr <<'PY'
import struct, sys
b = bytearray(open(sys.argv[1], 'rb').read())
for name in (b'dataWindow\0box2i\0', b'displayWindow\0box2i\0'):
    at = b.index(name) + len(name) + 4  # skip the attribute size
    b[at:at + 16] = struct.pack('<4i', 0, 0, 29999, 29999)
open(sys.argv[2], 'wb').write(bytes(b))
PY
cp regressions/pfm/header_claims_48GiB.pfm regressions/dump/
cp regressions/exr/data_window_30000.exr regressions/dump/
