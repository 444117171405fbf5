#!/usr/bin/env bash
# pip_install.sh PYTHON SOURCE_DIR WORK: the install researchers do (docs/python.md,
# "Install"), with nothing from the network: a fresh venv over PYTHON's packages
# (--system-site-packages, for Debian's numpy, setuptools and wheel), `pip install
# --no-build-isolation --no-index SOURCE_DIR` into it, then the module imported from the
# venv (not from a build tree) gives numpy's MSE and runs the U-Net on its shipped
# weights. Exits 77 (a ctest skip) when PYTHON cannot make such a venv.
set -euo pipefail
[ $# -eq 3 ] || { echo "usage: pip_install.sh PYTHON SOURCE_DIR WORK" >&2; exit 2; }
python=$1 src=$2 work=$3
skip() { echo "pip_install: skipped: $*"; exit 77; }

"$python" -c 'import ensurepip, venv' 2>/dev/null ||
    skip "$python has no venv/ensurepip (Debian: python3-venv)"
"$python" -c 'import setuptools, wheel' 2>/dev/null ||
    skip "$python has no setuptools or wheel (Debian: python3-setuptools python3-wheel)"

# Only what a user's shell would have: no build tree on the path (ctest's PYTHONPATH,
# the mcpost-build.pth that setup.sh writes into the user's site-packages, which a venv
# with system site-packages reads, before its own), no pip configuration that could
# bring in other packages (find-links, index URLs)
unset PYTHONPATH
for v in $(compgen -e); do
    case $v in PIP_*) unset "$v" ;; esac
done
export PYTHONNOUSERSITE=1 PIP_CONFIG_FILE=/dev/null PIP_DISABLE_PIP_VERSION_CHECK=1
# the build inside pip is the library's, on every core by default: two keep it from
# starving the tests that ctest -j runs beside it
export CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-2}

rm -rf "$work"
mkdir -p "$work"
work=$(cd "$work" && pwd -P)
"$python" -m venv --system-site-packages "$work/venv" ||
    skip "$python -m venv failed (Debian: python3-venv)"
start=$SECONDS
"$work/venv/bin/pip" install --no-build-isolation --no-index --no-cache-dir "$src"
echo "pip_install: pip install took $((SECONDS - start)) s"

# from a folder with no mcpost in it, so that the import can only find the venv's
cd "$work"
"$work/venv/bin/python" -s -c '
import os, sys
import mcpost, numpy as np
venv = sys.argv[1]
assert os.path.realpath(mcpost.__file__).startswith(venv + "/"), mcpost.__file__
rng = np.random.default_rng(7)
t, r = (rng.random((16, 24, 3), dtype=np.float32) for _ in range(2))
got, want = mcpost.mse(t, r), float(np.mean((t.astype(np.float64) - r) ** 2))
assert abs(got - want) <= 1e-6 * want, (got, want)
# the default denoiser on inputs with albedo and normal is the U-Net: it needs the
# weights shipped beside the library (mcpost.libs/share/mcpost)
c, a, n = (rng.random((32, 32, 3), dtype=np.float32) for _ in range(3))
d = mcpost.denoise(c, albedo=a, normal=n)
assert d.shape == (32, 32, 3) and np.isfinite(d).all(), d.shape
print(f"pip_install: mcpost from {mcpost.__file__}: mse {got:.9g} (numpy {want:.9g}); "
      f"the U-Net denoised 32x32")
' "$work/venv"
