"""Device choice and the errors a user without a usable device sees."""

import numpy as np
import pytest

from clsky import _cl


class FakePlatform:
    def __init__(self, version):
        self.version = version
        self.name = "Portable Computing Language"


class FakeDevice:
    def __init__(self, version, gpu=False, units=2):
        self.platform = FakePlatform(version)
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


def test_describe_device_names_the_pocl_build():
    assert _cl.describe_device(FakeDevice("OpenCL 3.0 PoCL 3.1+debian  Linux")).endswith("(PoCL 3.1+debian)")
