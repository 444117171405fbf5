"""Builds the Python module `mcpost` for the interpreter that runs pip.

    pip install --no-build-isolation .     # into that interpreter (or venv)
    pip wheel --no-build-isolation .       # a wheel of the same

The module is the one CMake builds (python/CMakeLists.txt): build_ext runs the
project's CMake with Python3_EXECUTABLE set to sys.executable, in a temporary build
folder, installs it into a temporary prefix (which gives the module its install RPATH)
and takes from there what the module needs at run time. In site-packages that is:

    mcpost.cpython-3X-<arch>.so          the module, RPATH $ORIGIN/mcpost.libs
    mcpost.libs/libmcpost.so.N           the shared library
    mcpost.libs/mcpost/*.so              its plug-ins (OpenImageIO, OpenCV), found
                                         beside the library (common/core/paths.c)
    mcpost.libs/share/mcpost/            its data: the U-Net's weights, found relative
                                         to the library (MCP_DATA_FROM_LIB)
    mcpost.libs/bin/                     mcpost and mcpost-procedural, which the library
                                         runs (an adaptive stage's renderer, in
                                         run_job), found relative to it (common/core/shell.c)

CMake is configured with the lib and data folders inside mcpost.libs, so the library
looks for its plug-ins and data there, relative to itself, wherever the wheel is
installed. Environment: CMAKE_BUILD_PARALLEL_LEVEL (jobs; default: every core),
MCPOST_CMAKE_ARGS (more CMake arguments, split as a shell would).
"""
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent
LIBS = "mcpost.libs"  # the folder beside the module (auditwheel's naming)


def abi_version():
    """The shared library's ABI version, its soname's number (MCP_ABI_VERSION)."""
    text = (ROOT / "CMakeLists.txt").read_text()
    m = re.search(r"set\(MCP_ABI_VERSION\s+([0-9]+)\)", text)
    if not m:
        sys.exit("setup.py: no set(MCP_ABI_VERSION N) in " + str(ROOT / "CMakeLists.txt"))
    return m.group(1)


def project_version():
    """The version in CMakeLists.txt's project(), the library's one version."""
    text = (ROOT / "CMakeLists.txt").read_text()
    m = re.search(r"project\(mcpost\s+VERSION\s+([0-9][0-9.]*)", text)
    if not m:
        sys.exit("setup.py: no project(mcpost VERSION x.y.z) in " + str(ROOT / "CMakeLists.txt"))
    return m.group(1)


def check_prerequisites():
    """Stops with one clear line where the build would fail later, in CMake's output."""
    try:
        import numpy  # noqa: F401 (the module is compiled against this numpy)
    except ImportError:
        sys.exit(
            f"setup.py: mcpost is built against the numpy of the Python that runs pip "
            f"({sys.executable}), which has none: in a venv, create it with "
            f"`python3 -m venv --system-site-packages` to see Debian's python3-numpy "
            f"(or install numpy into it first), and pass --no-build-isolation to pip")
    if not shutil.which("cmake"):
        sys.exit("setup.py: cmake not found on PATH (Debian: apt-get install cmake; "
                 "README.md lists every package the build needs)")


def run(cmd):
    print("setup.py: " + " ".join(shlex.quote(str(c)) for c in cmd), flush=True)
    subprocess.run([str(c) for c in cmd], check=True)


class CMakeBuildExt(build_ext):
    def build_extension(self, ext):
        if self.inplace or getattr(self, "editable_mode", False):
            # an editable install would put the module and mcpost.libs/ into the
            # source tree; the build tree already is the editable form
            sys.exit("setup.py: `pip install -e` (an in-place build) is not supported: "
                     "`./setup.sh build` builds build/python, which python3 then imports "
                     "as it changes (docs/python.md)")
        check_prerequisites()
        module = Path(self.get_ext_fullpath(ext.name))
        with tempfile.TemporaryDirectory(prefix="mcpost-pip-") as tmp:
            build, stage = Path(tmp, "build"), Path(tmp, "stage")
            # The configured prefix is the interpreter's site-packages: the paths the
            # library keeps as fallbacks (install RPATH, plug-in and data folders) then
            # name where `pip install` puts the files, never the temporary folder; the
            # install itself goes to `stage` (--prefix below).
            prefix = sysconfig.get_path("platlib")
            configure = [
                "cmake", "-S", ROOT, "-B", build,
                f"-DPython3_EXECUTABLE={sys.executable}",
                "-DMCPOST_PYTHON=ON",  # fail, saying why, rather than build no module
                "-DMCPOST_TESTS=OFF", "-DMCPOST_BENCH=OFF",
                f"-DCMAKE_INSTALL_PREFIX={prefix}",
                f"-DCMAKE_INSTALL_LIBDIR={LIBS}",
                f"-DCMAKE_INSTALL_DATADIR={LIBS}/share",
                f"-DCMAKE_INSTALL_BINDIR={LIBS}/bin",
                "-DMCPOST_PYTHON_INSTALL_DIR=.",
            ] + shlex.split(os.environ.get("MCPOST_CMAKE_ARGS", ""))
            run(configure)
            jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL") or str(os.cpu_count() or 1)
            run(["cmake", "--build", build, "-j", jobs])
            run(["cmake", "--install", build, "--prefix", stage])

            built = sorted(stage.glob("mcpost*.so"))
            if len(built) != 1:
                sys.exit(f"setup.py: expected one module mcpost*.so in {stage}, found "
                         f"{[p.name for p in built]}")
            module.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(built[0], module)
            # only what runs: no headers, static library, CMake or pkg-config files;
            # the library under its soname, the one name the module asks for (a wheel
            # holds no symlinks, and copies under other names would double it)
            libs = module.parent / LIBS
            shutil.rmtree(libs, ignore_errors=True)  # nothing stale from an earlier build
            soname = "libmcpost.so." + abi_version()
            # the U-Net (the default denoiser) needs its weights: a wheel without them
            # would fail only at the first denoise
            weights = stage / LIBS / "share" / "mcpost" / "rt_hdr_alb_nrm.tza"
            for src in [stage / LIBS / soname, weights, stage / LIBS / "bin" / "mcpost"]:
                if not src.is_file():
                    sys.exit(f"setup.py: the CMake install in {stage} has no "
                             f"{src.relative_to(stage)}")
            files = [stage / LIBS / soname]
            files += sorted((stage / LIBS / "mcpost").glob("*.so"))  # the plug-ins
            files += sorted(weights.parent.iterdir())  # the data, with the weights
            files += sorted((stage / LIBS / "bin").iterdir())  # the programs
            for src in files:
                dst = libs / src.relative_to(stage / LIBS)
                dst.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(src, dst)  # follows the soname's symlink: a real file



# pip runs setup.py for a wheel (bdist_wheel) even to install; with
# --no-build-isolation it installs no build requirements, and without the wheel package
# setuptools would say only "invalid command 'bdist_wheel'"
try:
    import wheel  # noqa: F401
except ImportError:
    sys.exit(f"setup.py: the Python that runs pip ({sys.executable}) has no wheel "
             f"package: use Debian's python3 (apt-get install python3-wheel "
             f"python3-setuptools python3-pip python3-venv), or a venv made from it with "
             f"`/usr/bin/python3 -m venv --system-site-packages`")

setup(
    version=project_version(),
    # the extension's sources are the CMake project's; setuptools compiles nothing
    ext_modules=[Extension("mcpost", sources=[])],
    cmdclass={"build_ext": CMakeBuildExt},
    # no Python packages: without this, setuptools would take the source folders
    # (cli/, common/, ...) for packages and refuse the layout
    packages=[],
    py_modules=[],
)
