"""PoCL programs built from their binaries kept on disk, not from source.

PoCL caches what it compiles (``~/.cache/pocl``), but it finds a program there by a hash of its
*preprocessed* source: every build from source, a cache hit included, first runs Clang's preprocessor
over the program and PoCL's OpenCL C headers. That takes 22-28 ms a program on the 2-core machine
(perf: ``clang::Lexer``, ``DoPrintPreprocessedInput``), whatever the program's size; the default
``clsky animate`` builds 23 programs (0.6 s of its main thread before the first kernel, 11 of them for the
plan's pilot table) and a small ``clsky render`` 16. The same program created from its binary (PoCL's LLVM
bitcode, ``CL_PROGRAM_BINARIES``) builds in under 1 ms. PyOpenCL keeps binaries in a disk cache of its
own for runtimes that do not cache (``pyopencl.cache``), but not for PoCL, which does; and its cache
serialises processes with a lock file that a killed process leaves behind (the next ones wait a minute
for it). So clsky keeps PoCL's binaries itself, as llama.cpp's OpenCL backend does for every runtime
(ggml-opencl's ``cl-program-cache``):

- the key is a SHA-256 of the program's source text, its build options as PyOpenCL passes them
  (``PYOPENCL_BUILD_OPTIONS`` added; its include path without the virtual environment's place), the device (name, vendor, version, driver
  version), the platform (name, version: PoCL's includes its LLVM version and build), PyOpenCL's version
  and PoCL's build variables (:data:`POCL_BUILD_VARIABLES`);
- the file, ``programs/<key>.bin`` in clsky's cache directory (:mod:`clsky._cache`), holds a format line,
  the SHA-256 of the binary and the binary; it lands atomically (a unique temporary, renamed);
- a file is used only when its format line and digest check out, and a binary that PoCL refuses anyway
  is built from source instead; either way the file is written again from the new build;
- the program returned is one built from a binary, the first time too (:func:`build`; the source build's
  own only where PoCL refuses the binary it just gave).

A program from its binary is the same LLVM bitcode that PoCL would have found in its own cache: PoCL then
compiles its work-group functions from it at the first launch of each kernel (once per machine: it caches
those too, under the binary program's hash; a machine whose PoCL cache holds them under the source
program's hash compiles them once more), and the kernels compute the same bits (tests/test_program_binaries.py;
the default animation's frames and metrics, README "Speed"). Only PoCL devices take this path, and only
single-device contexts (clsky's): elsewhere programs are built from source as PyOpenCL does it (NVIDIA's
driver caches by itself, PyOpenCL's cache serves the others).
"""

from __future__ import annotations

import hashlib
import os
import pathlib

import pyopencl as cl

from ._cache import cache_directory, store

__all__ = ["FORMAT_LINE", "applies", "binary_path", "build"]

#: PoCL's environment variables that change what it compiles from a source (its extra Clang flags, the
#: CPU it targets): their values join the key.
POCL_BUILD_VARIABLES = ("POCL_EXTRA_BUILD_FLAGS", "POCL_LLVM_CPU_NAME")
#: The first line of a program binary's file; a file that starts otherwise is not used.
FORMAT_LINE = b"clsky program binary 1\n"
_DIGEST_SIZE = 32


def _runtime_options(context, options) -> str:
    """The build options as PyOpenCL hands them to the runtime: with what the environment's
    ``PYOPENCL_BUILD_OPTIONS`` adds to every build, and its include path (``-I .../pyopencl/cl``) written
    as ``<pyopencl>/cl``, so that a new virtual environment finds the binaries of the old one (clsky's
    programs include no file: the path changes no code)."""
    try:
        text = cl.Program._process_build_options(context, list(options))[0].decode("utf-8", "replace")
    except (AttributeError, TypeError):        # a PyOpenCL without that classmethod: the same inputs
        text = "\n".join([*options, "PYOPENCL_BUILD_OPTIONS=" + os.environ.get("PYOPENCL_BUILD_OPTIONS", "")])
    return text.replace(os.path.dirname(os.path.abspath(cl.__file__)), "<pyopencl>")


def applies(context) -> bool:
    """Whether programs of ``context`` are kept as binaries: one device, of PoCL."""
    devices = context.devices
    return len(devices) == 1 and devices[0].platform.name == "Portable Computing Language"


def binary_path(context, source: str, options) -> pathlib.Path | None:
    """The file of the program ``source`` built with ``options`` for ``context``'s device; None where
    :func:`applies` does not hold or there is no cache directory."""
    directory = cache_directory("programs")
    if directory is None or not applies(context):
        return None
    device = context.devices[0]
    platform = device.platform
    words = [FORMAT_LINE.decode(), source, _runtime_options(context, options), device.name, device.vendor,
             device.version, device.driver_version, platform.name, platform.version, cl.VERSION_TEXT,
             *(f"{name}={os.environ.get(name, '')}" for name in POCL_BUILD_VARIABLES)]
    key = hashlib.sha256("\0".join(words).encode("utf-8")).hexdigest()
    return directory / f"{key}.bin"


def _read(path: pathlib.Path) -> bytes | None:
    """The binary in the file at ``path`` if its format line and digest check out, else None."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    header = len(FORMAT_LINE) + _DIGEST_SIZE
    if len(data) <= header or not data.startswith(FORMAT_LINE):
        return None
    binary = data[header:]
    return binary if hashlib.sha256(binary).digest() == data[len(FORMAT_LINE):header] else None


def _write(path: pathlib.Path, binary: bytes) -> bool:
    def write(file):
        file.write(FORMAT_LINE)
        file.write(hashlib.sha256(binary).digest())
        file.write(binary)
    return store(path, write)


def _from_binary(context, binary: bytes, options):
    """The program built from ``binary``, or None where the runtime refuses it."""
    try:
        return cl.Program(context, context.devices, [binary]).build(options=options)
    except cl.Error:
        return None


def build(context, source: str, options) -> cl.Program:
    """``cl.Program(context, source).build(options)``, from the binary kept on disk where there is a valid
    one (module docstring). Without one, the program is built from source, its binary kept for the next
    process, and the program returned is the one built from that binary (the source build's where the
    runtime refuses it): PoCL keys the work-group functions it compiles at a kernel's first launch by
    the program's hash, which differs between a program from source and one from its binary, so that
    every run launches binary programs and a machine compiles each kernel's functions once, not once
    from source and again from the binary.
    Build errors are PyOpenCL's, from the source build."""
    options = list(options)
    path = binary_path(context, source, options)
    if path is not None:
        binary = _read(path)
        program = None if binary is None else _from_binary(context, binary, options)
        if program is not None:
            return program
    program = cl.Program(context, source).build(options=options)
    if path is not None:
        binaries = program.get_info(cl.program_info.BINARIES)
        if len(binaries) == 1 and binaries[0]:
            binary = bytes(binaries[0])
            _write(path, binary)
            program = _from_binary(context, binary, options) or program
    return program
