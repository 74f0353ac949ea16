"""clsky.program_binaries: PoCL programs from binaries kept on disk, the same kernels as from source."""

from __future__ import annotations

import os
import types

import numpy as np
import pyopencl as cl
import pytest

from clsky import _cl, program_binaries

#: A kernel whose results depend on the compiled code's last bits (exp, pow, division, FMA contraction).
SOURCE = """
__kernel void values(__global const double *x, __global double *y)
{
    const size_t i = get_global_id(0);
    const double v = x[i];
    y[i] = exp(-v * 0.37) * pow(v + 1.0, 1.0 / 2.4) / (1.0 + v * v) + SCALE * v;
}
"""
OPTIONS = ["-DSCALE=0.125"]


@pytest.fixture
def context():
    context = _cl.make_context()
    if not program_binaries.applies(context):
        pytest.skip("programs are kept as binaries on PoCL only")
    return context


@pytest.fixture
def cache_home(tmp_path, monkeypatch):
    monkeypatch.delenv("CLSKY_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    return tmp_path


def run(context, program):
    queue = cl.CommandQueue(context)
    x = np.linspace(0.0, 40.0, 4099)
    x_d = cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=x)
    y_d = cl.Buffer(context, cl.mem_flags.WRITE_ONLY, x.nbytes)
    cl.Kernel(program, "values")(queue, x.shape, None, x_d, y_d)
    y = np.empty_like(x)
    cl.enqueue_copy(queue, y, y_d)
    return y


def spy_on_source_builds(monkeypatch):
    """A list that gets one entry a source build of a program."""
    builds = []
    original = cl.Program.__init__

    def init(self, *args):
        if len(args) == 2:
            builds.append(args[1])
        original(self, *args)
    monkeypatch.setattr(cl.Program, "__init__", init)
    return builds


def test_the_second_build_comes_from_the_binary_and_computes_the_same_bits(context, cache_home, monkeypatch):
    builds = spy_on_source_builds(monkeypatch)
    path = program_binaries.binary_path(context, SOURCE, OPTIONS)
    assert path.parent == cache_home / "clsky" / "programs" and not path.exists()
    first = program_binaries.build(context, SOURCE, OPTIONS)
    assert len(builds) == 1 and path.is_file()
    # the first build's program is the one made from its binary too (no source: PoCL's work-group
    # functions are then compiled under one program hash only)
    assert first.get_info(cl.program_info.SOURCE) == ""
    from_binary = program_binaries.build(context, SOURCE, OPTIONS)
    assert len(builds) == 1                                  # no second source build
    from_source = cl.Program(context, SOURCE).build(options=OPTIONS)
    assert np.array_equal(run(context, from_source), run(context, from_binary))
    assert np.array_equal(run(context, first), run(context, from_binary))


def test_other_options_or_source_are_other_files(context, cache_home, monkeypatch):
    path = program_binaries.binary_path(context, SOURCE, OPTIONS)
    assert program_binaries.binary_path(context, SOURCE, ["-DSCALE=0.25"]) != path
    assert program_binaries.binary_path(context, SOURCE + "\n", OPTIONS) != path
    assert program_binaries.binary_path(context, SOURCE, OPTIONS) == path
    # what the environment adds to every build: PyOpenCL's options, PoCL's flags and target
    for name, value in [("PYOPENCL_BUILD_OPTIONS", "-cl-fast-relaxed-math"), ("POCL_EXTRA_BUILD_FLAGS", "-O0"),
                        ("POCL_LLVM_CPU_NAME", "znver3")]:
        with monkeypatch.context() as patch:
            patch.setenv(name, value)
            assert program_binaries.binary_path(context, SOURCE, OPTIONS) != path, name
    assert program_binaries.binary_path(context, SOURCE, OPTIONS) == path


def test_the_key_does_not_hold_the_virtual_environments_place(context):
    """PyOpenCL adds -I <its package>/cl to every build: a new virtual environment keeps the keys."""
    options = program_binaries._runtime_options(context, OPTIONS)
    assert "-DSCALE=0.125" in options and "<pyopencl>" in options
    assert os.path.dirname(cl.__file__) not in options


def flip_a_binary_byte(path):
    data = bytearray(path.read_bytes())
    data[-100] ^= 0x01
    path.write_bytes(bytes(data))


def truncate(path):
    path.write_bytes(path.read_bytes()[:40])


def another_format(path):
    path.write_bytes(b"clsky program binary 0\n" + path.read_bytes()[len(program_binaries.FORMAT_LINE):])


def garbage_with_its_digest(path):
    """Bytes that are no program but carry a correct digest: the runtime refuses them."""
    program_binaries._write(path, b"BC\xc0\xde" + bytes(range(256)) * 8)


@pytest.mark.parametrize("damage", [flip_a_binary_byte, truncate, another_format, garbage_with_its_digest])
def test_a_damaged_file_is_built_from_source_and_written_again(context, cache_home, monkeypatch, damage):
    reference = run(context, program_binaries.build(context, SOURCE, OPTIONS))
    path = program_binaries.binary_path(context, SOURCE, OPTIONS)
    damage(path)
    builds = spy_on_source_builds(monkeypatch)
    program = program_binaries.build(context, SOURCE, OPTIONS)
    assert len(builds) == 1
    assert np.array_equal(run(context, program), reference)
    program_binaries.build(context, SOURCE, OPTIONS)
    assert len(builds) == 1                                  # the file was written again, and used


def test_a_cache_that_cannot_be_written_only_costs_the_source_builds(context, cache_home, monkeypatch):
    (cache_home / "clsky").write_text("a file where the directory would be")
    builds = spy_on_source_builds(monkeypatch)
    reference = run(context, program_binaries.build(context, SOURCE, OPTIONS))
    assert np.array_equal(run(context, program_binaries.build(context, SOURCE, OPTIONS)), reference)
    assert len(builds) == 2


def test_a_build_error_is_pyopencls_and_writes_nothing(context, cache_home):
    with pytest.raises(cl.RuntimeError, match="undeclared|undefined|error"):
        program_binaries.build(context, SOURCE.replace("SCALE", "NO_SUCH_NAME"), [])
    assert not (cache_home / "clsky" / "programs").exists() or not any((cache_home / "clsky" / "programs").iterdir())


def fake_context(platform_name, devices=1):
    device = types.SimpleNamespace(platform=types.SimpleNamespace(name=platform_name))
    return types.SimpleNamespace(devices=[device] * devices)


def test_only_single_pocl_devices_keep_binaries():
    assert program_binaries.applies(fake_context("Portable Computing Language"))
    assert not program_binaries.applies(fake_context("Portable Computing Language", devices=2))
    assert not program_binaries.applies(fake_context("NVIDIA CUDA"))
    assert not program_binaries.applies(fake_context("Intel(R) OpenCL"))
    assert program_binaries.binary_path(fake_context("NVIDIA CUDA"), SOURCE, OPTIONS) is None
