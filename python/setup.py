"""pip install ./python: the loopsfm package with its C++ core, built by the project's CMake.

The core (_loopsfm) is the CMake target of that name: it is taken from the build tree named by
LOOPSFM_BUILD_DIR, else ../build, and built there first when it is missing or out of date
(`cmake --build` of that one target; a tree that does not exist yet is configured as
scripts/build does). Nothing is downloaded: the build uses Debian's packages (scripts/setup),
and the package needs NumPy (Debian's python3-numpy; in a venv, --system-site-packages).
"""

import glob
import os
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import Distribution, setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
SOURCE_DIR = HERE.parent


def build_dir() -> Path:
    return Path(os.environ.get("LOOPSFM_BUILD_DIR", SOURCE_DIR / "build")).resolve()


def built_core() -> Path:
    """Builds the _loopsfm target and returns the path of the extension module."""
    tree = build_dir()
    if not (tree / "CMakeCache.txt").exists():
        subprocess.check_call(["cmake", "-S", str(SOURCE_DIR), "-B", str(tree),
                               "-DCMAKE_BUILD_TYPE=Release",
                               f"-DPython3_EXECUTABLE={sys.executable}"])
    subprocess.check_call(["cmake", "--build", str(tree), "--target", "_loopsfm", "-j",
                           str(os.cpu_count() or 1)])
    found = glob.glob(str(tree / "python" / "loopsfm" / "_loopsfm*.so"))
    if not found:
        sys.exit(f"loopsfm: {tree} built no Python module: is pybind11-dev installed "
                 "(scripts/setup)?")
    return Path(found[0])


class BuildWithCore(build_py):
    """The Python files, and the core from the CMake build beside them."""

    def run(self):
        super().run()
        target = Path(self.build_lib) / "loopsfm"
        target.mkdir(parents=True, exist_ok=True)
        shutil.copy2(built_core(), target)


class BinaryDistribution(Distribution):
    """The wheel holds a compiled module: tagged for this Python and platform."""

    def has_ext_modules(self):
        return True


setup(
    name="loopsfm",
    version="0.1.0",
    description="Camera poses and a sparse 3D point cloud from video, with loop closing",
    packages=["loopsfm"],
    package_data={"loopsfm": ["_loopsfm.pyi", "py.typed"]},
    python_requires=">=3.9",
    install_requires=["numpy"],
    cmdclass={"build_py": BuildWithCore},
    distclass=BinaryDistribution,
)
