"""Intel's CPU OpenCL runtime, the opt-in second runtime (``scripts/intel_opencl.sh``, README "Speed"):
the README's lines that install and use it, run as written (the install into a temporary directory, given
as the script's argument, so that the checkout is left as it was), the device clsky then picks, the frames
it renders against PoCL's, and the kernels against their NumPy twins on it.

Slow: the install downloads about 250 MB from PyPI (seconds here), and the twin tests take a minute or more.
"""

from __future__ import annotations

import os
import pathlib
import platform
import shlex
import subprocess
import sys

import numpy as np
import pytest

from test_readme import COMMANDS, check_outputs, reduced

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                                 reason="Intel's CPU OpenCL runtime is built for x86-64 only")]

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: the README's install line, and the start of the line that uses the runtime (a clsky command follows)
INSTALL = "./scripts/intel_opencl.sh"
USE = "OCL_ICD_VENDORS=$PWD/.intel-opencl/vendors .venv/bin/clsky "
#: the test files that compare kernels with their NumPy twins (and the extremes: no NaN, Inf or negative
#: radiance leaves a kernel); their default-suite cases, 1124 tests, took 53 s on Intel's runtime here
#: with its kernel cache warm
TWIN_TESTS = ["test_single_twin.py", "test_multiple.py", "test_azimuth.py", "test_render.py", "test_lookup.py",
              "test_table4d.py", "test_skyview.py", "test_ground.py", "test_ozone.py", "test_analytic.py",
              "test_scales.py", "test_spectral.py", "test_table.py", "test_view_nodes.py", "test_extremes.py",
              "test_colorimetry_cl.py"]


@pytest.fixture(scope="module")
def vendors(tmp_path_factory) -> pathlib.Path:
    """The README's install line, run into a temporary directory: the OpenCL vendors directory it wrote."""
    assert INSTALL in COMMANDS, "the README no longer shows the install line"
    prefix = tmp_path_factory.mktemp("intel-opencl")
    result = subprocess.run([str(ROOT / INSTALL), str(prefix)], cwd=ROOT, capture_output=True, text=True,
                            timeout=1200)
    assert result.returncode == 0, result.stderr[-3000:]
    assert (prefix / "vendors" / "intel-cpu.icd").read_text().strip() == str(prefix / "lib" / "libintelocl.so")
    return prefix / "vendors"


def clsky_env(vendors, selector=None):
    env = {key: value for key, value in os.environ.items() if key != "PYOPENCL_CTX"}
    env["OCL_ICD_VENDORS"] = str(vendors)
    if selector:
        env["PYOPENCL_CTX"] = selector
    return env


def test_clsky_picks_intels_runtime_when_it_is_registered(vendors):
    """Both runtimes are listed (the script keeps the drivers already registered) and clsky's choice is
    Intel's (clsky._cl.default_device); PYOPENCL_CTX=portable still picks PoCL."""
    listing = subprocess.run([str(pathlib.Path(sys.executable).parent / "clsky"), "devices"], env=clsky_env(vendors),
                             capture_output=True, text=True, check=True).stdout
    chosen = [line for line in listing.splitlines() if line.startswith("*")]
    platforms = [line for line in listing.splitlines() if line.strip().startswith("platform:")]
    assert any("Intel(R) OpenCL" in line for line in platforms) and any("PoCL" in line for line in platforms)
    lines = listing.splitlines()
    assert len(chosen) == 1 and "Intel(R) OpenCL" in lines[lines.index(chosen[0]) + 1], listing
    listing = subprocess.run([str(pathlib.Path(sys.executable).parent / "clsky"), "devices"],
                             env=clsky_env(vendors, "portable"), capture_output=True, text=True, check=True).stdout
    lines = listing.splitlines()
    chosen = [line for line in lines if line.startswith("*")]
    assert len(chosen) == 1 and "PoCL" in lines[lines.index(chosen[0]) + 1], listing


def test_readme_use_line_renders_pocls_frames(vendors, tmp_path):
    """The README's line that uses the runtime, at the reduced size of tests/test_readme.py, writes what it
    should, with no warning on stderr (Intel's runtime logs every build: clsky._cl.quiet_compiler_output),
    and its 8-bit frames are PoCL's: the two runtimes' float64 radiances differ by about 1e-12 (relative;
    the default animation's metrics, README "Speed"), so a code value can change only where a value lies
    within that of a rounding boundary. Allowed: 1 in 10^4 values off by one code (none was, in the 120
    frames of the default animation)."""
    lines = [line for line in COMMANDS if line.startswith(USE)]
    assert lines, "the README no longer shows how to use the runtime"
    from PIL import Image

    for line in lines:
        argv = ["clsky", *shlex.split(line[len(USE):])]
        frames = {}
        for name, selector in (("intel", None), ("pocl", "portable")):
            directory = tmp_path / name
            directory.mkdir()
            result = subprocess.run(reduced(argv), cwd=directory, env=clsky_env(vendors, selector), capture_output=True,
                                    text=True, timeout=600)
            assert result.returncode == 0 and not result.stderr.strip(), result.stderr[-2000:]
            check_outputs(argv, directory)
            frames[name] = np.stack([np.asarray(Image.open(path)).astype(int)
                                     for path in sorted(directory.glob("*_frames/frame_*.png"))])
        difference = np.abs(frames["intel"] - frames["pocl"])
        assert difference.max() <= 1 and (difference > 0).mean() <= 1e-4, (difference.max(), (difference > 0).mean())


def test_kernels_match_their_twins_on_intels_runtime(vendors):
    """The kernel-versus-twin tests of the default suite, with their own tolerances, on Intel's runtime
    (PYOPENCL_CTX=intel): the kernels assume nothing of PoCL (its compiler, work-group sizes, double8 as
    the fast path). The bit-for-bit pins recorded on PoCL skip there (tests/pins.py)."""
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "not slow",
                             *(str(ROOT / "tests" / name) for name in TWIN_TESTS)],
                            cwd=ROOT, env=clsky_env(vendors, "intel"), capture_output=True, text=True, timeout=1800)
    assert result.returncode == 0, result.stdout[-5000:]
    assert " passed" in result.stdout.splitlines()[-1], result.stdout[-2000:]
