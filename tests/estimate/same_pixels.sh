# same_pixels.sh: sourced by the U-Net's banded and bounded runs' tests (unet_bands.sh,
# unet_memory_bound.sh), with $mcpost set. Pixels are compared as PFM bytes (cmp): EXR
# files of the same pixels may differ in which zip chunks are stored raw.

# same_pixels A.exr B.exr: the same float bits in R, G, B, or the script fails
same_pixels() {
    "$mcpost" convert "$1" "${1%.exr}.pfm" >/dev/null
    "$mcpost" convert "$2" "${2%.exr}.pfm" >/dev/null
    cmp "${1%.exr}.pfm" "${2%.exr}.pfm" ||
        { echo "FAIL: $1 and $2 differ"; exit 1; }
    echo "same bits: $1 $2"
}
