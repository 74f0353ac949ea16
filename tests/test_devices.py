"""Device choice and the errors a user without a usable device sees."""

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from clsky import _cl


class FakePlatform:
    def __init__(self, version, name="Portable Computing Language"):
        self.version = version
        self.name = name


class FakeDevice:
    def __init__(self, version, gpu=False, units=2, platform="Portable Computing Language"):
        self.platform = FakePlatform(version, platform)
        self.type = _cl.cl.device_type.GPU if gpu else _cl.cl.device_type.CPU
        self.max_compute_units = units
        self.name = f"device of {version}"


def test_prefers_gpu_then_newest_pocl_release(monkeypatch):
    pip_build = FakeDevice("OpenCL 3.0 PoCL 3.0-rc2  Linux")
    debian = FakeDevice("OpenCL 3.0 PoCL 3.1+debian  Linux")
    monkeypatch.setattr(_cl, "_all_devices", lambda: [pip_build, debian])
    assert _cl.default_device() is debian
    gpu = FakeDevice("OpenCL 3.0 CUDA", gpu=True)
    monkeypatch.setattr(_cl, "_all_devices", lambda: [pip_build, gpu, debian])
    assert _cl.default_device() is gpu


def test_prefers_intels_cpu_runtime_to_pocl_but_not_to_a_gpu(monkeypatch):
    """Intel's CPU runtime, registered by scripts/intel_opencl.sh, renders the same frames 1.4-1.5x faster
    in the ray march than PoCL 3.1 here (README "Speed"): chosen before PoCL, after any GPU; an Intel GPU
    (same platform name, GPU type) ranks as a GPU."""
    debian = FakeDevice("OpenCL 3.0 PoCL 3.1+debian  Linux", units=4)
    intel_cpu = FakeDevice("OpenCL 3.1 LINUX", platform="Intel(R) OpenCL")
    monkeypatch.setattr(_cl, "_all_devices", lambda: [debian, intel_cpu])
    assert _cl.default_device() is intel_cpu
    intel_gpu = FakeDevice("OpenCL 3.0 NEO", gpu=True, platform="Intel(R) OpenCL Graphics")
    monkeypatch.setattr(_cl, "_all_devices", lambda: [debian, intel_cpu, intel_gpu])
    assert _cl.default_device() is intel_gpu
    assert _cl.describe_device(intel_cpu) == "device of OpenCL 3.1 LINUX (Intel(R) OpenCL, OpenCL 3.1 LINUX)"


def test_no_device_says_how_to_install_one(monkeypatch):
    monkeypatch.setattr(_cl, "_all_devices", lambda: [])
    with pytest.raises(_cl.NoDeviceError, match="pocl-opencl-icd"):
        _cl.default_device()


def test_float64_without_fp64_says_what_to_do(monkeypatch):
    monkeypatch.setattr(_cl, "has_fp64", lambda device: False)
    device = FakeDevice("OpenCL 3.0 PoCL 3.1")
    with pytest.raises(_cl.NoDeviceError, match="float32"):
        _cl.check_dtype(device, np.float64)
    _cl.check_dtype(device, np.float32)          # float32 needs no fp64


def test_bad_pyopencl_ctx_is_a_clear_error(monkeypatch):
    monkeypatch.setenv("PYOPENCL_CTX", "99")
    with pytest.raises(_cl.NoDeviceError, match="PYOPENCL_CTX"):
        _cl.make_context()


@pytest.mark.parametrize("files, expected", [
    ({"v2": "200000 100000\n"}, 2),
    ({"v2": "150000 100000\n"}, 2),                  # 1.5 CPUs: two threads may run at once
    ({"v2": "50000 100000\n"}, 1),
    ({"v2": "max 100000\n"}, None),
    ({"v1_quota": "-1\n", "v1_period": "100000\n"}, None),
    ({"v1_quota": "300000\n", "v1_period": "100000\n"}, 3),
    ({"v2": "garbled"}, None),
    ({}, None),
])
def test_cgroup_cpu_quota_limits_the_host_threads(tmp_path, monkeypatch, files, expected):
    """A container's CPU quota (cgroup v2 cpu.max, else v1's cfs files) caps host_cores, which the affinity
    mask alone would not: a 2-CPU container on a many-core host must not start a thread per core."""
    paths = {}
    for name in _cl.CGROUP_CPU_FILES:
        paths[name] = tmp_path / name
        if name in files:
            paths[name].write_text(files[name])
    monkeypatch.setattr(_cl, "CGROUP_CPU_FILES", paths)
    assert _cl.cgroup_cpu_limit() == expected
    monkeypatch.setattr(_cl.os, "sched_getaffinity", lambda pid: set(range(64)), raising=False)
    assert _cl.host_cores() == (64 if expected is None else expected)


def test_describe_device_names_the_pocl_build():
    assert _cl.describe_device(FakeDevice("OpenCL 3.0 PoCL 3.1+debian  Linux")).endswith("(PoCL 3.1+debian)")


def test_successful_build_logs_are_quiet_unless_asked(monkeypatch, recwarn):
    """Intel's CPU runtime logs every build ('Compilation started', ...), also of PyOpenCL's own kernels,
    and PyOpenCL turns a non-empty log into a CompilerWarning: the command line runs within
    quiet_compiler_output, which hides them unless PYOPENCL_COMPILER_OUTPUT asks for the logs."""
    import warnings

    monkeypatch.delenv("PYOPENCL_COMPILER_OUTPUT", raising=False)
    with _cl.quiet_compiler_output():
        warnings.warn("Non-empty compiler output encountered", _cl.cl.CompilerWarning)
    assert not [w for w in recwarn if issubclass(w.category, _cl.cl.CompilerWarning)]
    monkeypatch.setenv("PYOPENCL_COMPILER_OUTPUT", "1")
    with pytest.warns(_cl.cl.CompilerWarning):
        with _cl.quiet_compiler_output():
            warnings.warn("Non-empty compiler output encountered", _cl.cl.CompilerWarning)


def test_builds_write_no_compiler_warnings_to_the_terminal_unless_asked(cl_context, capfd, monkeypatch):
    """PoCL's clang writes '<n> warnings generated.' straight to file descriptor 2, past Python's
    warning filters: on a CPU without AVX-512 a first `clsky animate` printed six such lines (every
    builtin called on a double8 warns that the argument changes the ABI). build_program passes -w
    (clsky._cl.NO_WARNINGS) unless PYOPENCL_COMPILER_OUTPUT asks for the logs. The kernel below warns
    where the compiler is clang (PoCL, Intel's CPU runtime: an unused comparison, a warning clang gives by
    default); each build gets a new source so that no program cache answers it. A device whose compiler
    does not warn about it is skipped."""
    import uuid
    import warnings

    def source():
        return _cl.Source("warns.cl", f"/* {uuid.uuid4()} */\n__kernel void warns(__global double *out) {{\n"
                                      "    int n = 1;\n    n == 2;\n    out[get_global_id(0)] = n;\n}\n")

    monkeypatch.setenv("PYOPENCL_COMPILER_OUTPUT", "1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", _cl.cl.CompilerWarning)      # PyOpenCL prints the log it was asked for
        asked = _cl.build_program(cl_context, (source(),))
    log = asked.get_build_info(cl_context.devices[0], _cl.cl.program_build_info.LOG)
    if "warning" not in log.lower():
        pytest.skip(f"{cl_context.devices[0].name!r} does not warn about an unused comparison")
    capfd.readouterr()
    monkeypatch.delenv("PYOPENCL_COMPILER_OUTPUT")
    quiet = _cl.build_program(cl_context, (source(),))
    assert "warning" not in quiet.get_build_info(cl_context.devices[0], _cl.cl.program_build_info.LOG).lower()
    assert "warning" not in capfd.readouterr().err.lower()


def test_float32_builds_ask_for_correctly_rounded_division_where_the_device_offers_it(monkeypatch):
    """float32 programs are built with -cl-fp32-correctly-rounded-divide-sqrt when the device lists it
    (on an H200 without it, float32 frames were 3x further from float64's than on PoCL:
    clsky._cl.FP32_CORRECTLY_ROUNDED); never for float64 (always correctly rounded) nor with fast math
    (which asks for the opposite)."""
    from clsky import TableSettings
    from clsky.single import SingleScatteringEngine

    settings = TableSettings(size=(8, 32, 8))
    single = SingleScatteringEngine(settings.replace(dtype="float32"))
    offered = _cl.correctly_rounded_divide_sqrt(single.device)
    assert (_cl.FP32_CORRECTLY_ROUNDED in single.build_options()) == offered
    assert _cl.FP32_CORRECTLY_ROUNDED not in SingleScatteringEngine(settings).build_options()
    monkeypatch.setattr(_cl, "correctly_rounded_divide_sqrt", lambda device: True)
    assert _cl.FP32_CORRECTLY_ROUNDED in SingleScatteringEngine(settings.replace(dtype="float32")).build_options()
    fast = SingleScatteringEngine(settings.replace(dtype="float32"), fast_math=True)
    assert _cl.FP32_CORRECTLY_ROUNDED not in fast.build_options()
    monkeypatch.setattr(_cl, "correctly_rounded_divide_sqrt", lambda device: False)
    assert _cl.FP32_CORRECTLY_ROUNDED not in SingleScatteringEngine(settings.replace(dtype="float32")).build_options()


def test_vector_width_is_one_lane_on_a_gpu_and_double8_elsewhere():
    """A GPU's work-items are its SIMT lanes: the scalar kernels (on an H200 the ray march in 3 ms a
    512 x 512 frame against 7 for double8); CPUs' vector units: double8 (PoCL's scalar march costs 6.4x)."""
    assert _cl.VECTOR_WIDTH is None
    assert _cl.default_vector_width(FakeDevice("OpenCL 3.0 CUDA", gpu=True)) == 1
    assert _cl.default_vector_width(FakeDevice("OpenCL 3.0 PoCL 3.1+debian  Linux")) == 8


@pytest.mark.slow
def test_gpu_checks_script_runs_and_keeps_what_it_measured(tmp_path):
    """scripts/gpu_checks.sh, the checks a session with a GPU runs (README "Speed", GPUs), at its smoke
    sizes on whatever device clsky picks here (about 40 s on PoCL): every step's log, the kept animations of
    both vector widths, the profile with every launch's device time, the copies' timings; and it refuses
    an output directory that exists."""
    root = pathlib.Path(__file__).resolve().parent.parent
    script = root / "scripts" / "gpu_checks.sh"
    out = tmp_path / "checks"
    env = {**os.environ, "SMOKE": "1", "PY": sys.executable}
    result = subprocess.run([str(script), str(out)], env=env, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert "(*: the device clsky uses" in (out / "devices.txt").read_text()
    assert " passed" in (out / "tests.txt").read_text().splitlines()[-1]
    assert "| round | device | width |" in (out / "bench_runtimes.txt").read_text()
    assert "| table | W x H x D |" in (out / "bench_orders.txt").read_text()
    assert "| render | best |" in (out / "bench_render.txt").read_text()
    assert "| run | frames | wall [s] | CPU [s] |" in (out / "bench_animate.txt").read_text()
    profile = (out / "profile.txt").read_text()
    assert "(first_gather)" in profile and "  scatter " in profile and "launches not profiled: 0" in profile
    # 3 and 6 channels: reads 3 ways (rectangular, contiguous, packed), writes 2
    assert (out / "copies.txt").read_text().count(" ms") == 10
    for configuration in ("0", "1"):
        assert (out / "anim" / configuration / "sky_metrics.csv").is_file()
        assert len(list((out / "anim" / configuration / "sky_frames").glob("*.png"))) == 2
    again = subprocess.run([str(script), str(out)], env=env, capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "exists already" in again.stderr


def test_gpu_checks_script_runs_only_the_steps_asked(tmp_path):
    """ONLY (a short device lease): the steps named, separated by any blanks, and no other; a name that is
    no step exits 2 before anything is written."""
    script = pathlib.Path(__file__).resolve().parent.parent / "scripts" / "gpu_checks.sh"
    env = {**os.environ, "SMOKE": "1", "PY": sys.executable}
    bad = subprocess.run([str(script), str(tmp_path / "bad")], env={**env, "ONLY": "copies profiles"},
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "no step 'profiles'" in bad.stderr and not (tmp_path / "bad").exists()
    out = tmp_path / "checks"
    result = subprocess.run([str(script), str(out)], env={**env, "ONLY": "copies\tprofile"}, capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert sorted(path.name for path in out.iterdir() if path.is_file()) == ["copies.txt", "devices.txt",
                                                                             "machine.txt", "profile.txt"]


def test_intel_opencl_script_installs_where_its_argument_says_from_where_it_was_given(tmp_path):
    """scripts/intel_opencl.sh DIR: a relative DIR is the caller's (it was resolved after the script's cd to
    the checkout: an 800 MB install landed in the checkout, outside .gitignore); without DIR, .intel-opencl
    in the checkout. A copy of the script in a stand-in checkout whose .venv's python and clsky record their
    calls (pip's install makes the library the script looks for; the platform check passes)."""
    checkout, caller = tmp_path / "checkout", tmp_path / "caller"
    for folder in (checkout / "scripts", checkout / ".venv" / "bin", caller):
        folder.mkdir(parents=True)
    script = checkout / "scripts" / "intel_opencl.sh"
    script.write_text((pathlib.Path(__file__).resolve().parent.parent / "scripts" / "intel_opencl.sh").read_text())
    calls = tmp_path / "calls"
    stand_ins = {"python": 'if [ "$1" = -m ]; then\n'
                           '    while [ "$1" != --prefix ]; do shift; done\n'
                           '    mkdir -p "$2/lib" && touch "$2/lib/libintelocl.so"\n'
                           'fi\n',
                 "clsky": ""}
    for name, body in stand_ins.items():
        stand_in = checkout / ".venv" / "bin" / name
        stand_in.write_text(f'#!/usr/bin/env bash\necho "{name} $*" >> "{calls}"\n{body}exit 0\n')
        stand_in.chmod(0o755)
    script.chmod(0o755)
    # a `prefix` in the caller's environment is no argument (it was taken for one); an empty one is the default
    environment = {**os.environ, "prefix": str(tmp_path / "elsewhere")}
    for argument, expected in ((["my-intel"], caller / "my-intel"), ([], checkout / ".intel-opencl"),
                               ([""], checkout / ".intel-opencl"), (["-x"], caller / "-x")):
        result = subprocess.run([str(script), *argument], cwd=caller, capture_output=True, text=True, timeout=60,
                                env=environment)
        assert result.returncode == 0, result.stderr
        assert (expected / "vendors" / "intel-cpu.icd").read_text().strip() == str(expected / "lib" / "libintelocl.so")
        assert f"OCL_ICD_VENDORS={expected}/vendors" in result.stderr
    assert not (checkout / "my-intel").exists() and not (caller / ".intel-opencl").exists()
    assert not (tmp_path / "elsewhere").exists()


def test_record_pins_names_a_source_that_is_no_checkout(tmp_path):
    """scripts/record_pins.py --source DIR where DIR is no git checkout: one line with git's reason (it was a
    CalledProcessError traceback, git's reason captured and never shown), before any pin is computed."""
    script = pathlib.Path(__file__).resolve().parent.parent / "scripts" / "record_pins.py"
    result = subprocess.run([sys.executable, str(script), "ground", "--source", str(tmp_path)], capture_output=True,
                            text=True, timeout=120, env={**os.environ, "GIT_CEILING_DIRECTORIES": str(tmp_path.parent)})
    assert result.returncode == 1 and result.stdout == ""
    assert result.stderr.startswith(f"record_pins: --source {tmp_path} is no git checkout with a commit: ")
    assert result.stderr.count("\n") == 1 and "not a git repository" in result.stderr, result.stderr
    # as typed, and a directory that is not there named as such
    missing = subprocess.run([sys.executable, str(script), "ground", "--source", "nothere"], capture_output=True,
                             text=True, timeout=120, cwd=tmp_path)
    assert missing.returncode == 1 and missing.stderr == "record_pins: --source nothere is no directory\n"


def test_an_engine_builds_its_plain_program_only_when_it_launches_from_it(cl_context):
    """clsky._cl.Engine builds its plain program (no compile-time features) at its first use: a table of
    the physical preset (ozone, a ground) launches only the feature variants of the single-scattering and
    transmittance programs, so their plain programs are never built (7 of the default animation's 22
    builds were such), nor does its renderer's sky-view lookup build a plain sky-view program for the
    view zenith angles (one more); the preset without features (atmosphere-plus) builds and uses the plain
    ones. The orders' multiple-scattering engines take their gathers and sums from the scatter's feature
    variant, with azimuth harmonics (clsky.azimuth) and without (clsky.orders), so that no plain
    multiple-scattering program is built either (two more). A context of its own, so that other tests'
    builds do not count."""
    import pyopencl as cl

    import clsky
    from clsky.render import SkyRenderer
    from conftest import SMALL_TABLE

    def built(context, name):
        """The option sets of the programs built in ``context`` whose last source is ``name``."""
        return [options for (pointer, sources, options) in _cl._program_cache
                if pointer == context.int_ptr and sources[-1] == name]

    features = cl.Context(devices=[cl_context.devices[0]])
    clsky.ScatteringTable.build(clsky.preset("physical"), SMALL_TABLE, ctx=features)
    clsky.ScatteringTable.build(clsky.preset("physical"), SMALL_TABLE.replace(azimuth_harmonics=0), ctx=features)
    for name in ("single.cl", "transmittance.cl", "multiple.cl"):
        variants = built(features, name)
        assert variants and all("-DOZONE=1" in options and "-DGROUND=1" in options for options in variants), name
    # the renderer's sky-view lookup: its view zenith angles come from the lookup's own feature variant
    table = clsky.ScatteringTable.build(clsky.preset("physical"), SMALL_TABLE, ctx=features)
    renderer = SkyRenderer(table, ctx=features)
    renderer.render_skyview(renderer.prepare(np.array([[0.0, 0.6, 0.8], [0.6, 0.0, 0.8]])), (0.0, 0.0, 1.0))
    variants = built(features, "skyview.cl")
    assert variants and all("-DOZONE=1" in options and "-DGROUND=1" in options for options in variants), variants
    plain = cl.Context(devices=[cl_context.devices[0]])
    clsky.ScatteringTable.build(clsky.preset("atmosphere-plus").replace(ground_albedo=0.0),
                                SMALL_TABLE.replace(mode="atmosphere-plus", azimuth_harmonics=0), ctx=plain)
    for name in ("single.cl", "transmittance.cl", "multiple.cl"):
        variants = built(plain, name)
        assert variants and not any("-DOZONE=1" in options for options in variants), name
