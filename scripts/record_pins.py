#!/usr/bin/env python3
"""Record the bit-for-bit pins (tests/pins.py) of this machine's OpenCL device from an old commit's code.

Usage, from the repository root, with the project's virtual environment (nothing is installed)::

    git worktree add --detach /tmp/old-bfa2a93 bfa2a93
    .venv/bin/python scripts/record_pins.py --source /tmp/old-bfa2a93 ground spectral view_nodes display

``--source`` is a checkout of the commit the pins belong to (tests/pins.py, ``PINS[name].commit``; the
script refuses another commit). Its ``clsky`` (and top-level ``anim``, where it has one) is imported
instead of the installed one: the editable install's import hook is removed first, since it would
otherwise lend today's ``clsky.kernels`` / ``clsky.anim`` to the old package, and the script checks
that the modules and the OpenCL sources it uses are the old tree's. Without ``--source`` it runs the
current code (to compare with what a test computes). It prints the device description and, for each
pin, the values to paste into the test's mapping under that device.
"""

from __future__ import annotations

import argparse
import importlib.util
import pathlib
import pprint
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _load_pins():
    spec = importlib.util.spec_from_file_location("pins", ROOT / "tests" / "pins.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["pins"] = module
    spec.loader.exec_module(module)
    return module


def _use_source(source: pathlib.Path) -> None:
    """Import clsky from ``source`` only: drop the editable install's finders, put ``source`` first."""
    def editable(hook):
        return "__editable__" in getattr(hook, "__module__", "")      # setuptools' finder classes and hook

    sys.meta_path[:] = [finder for finder in sys.meta_path if not editable(finder)]
    sys.path_hooks[:] = [hook for hook in sys.path_hooks if not editable(hook)]
    sys.path_importer_cache.clear()
    sys.path.insert(0, str(source))
    import clsky
    from clsky import _cl

    kernels = pathlib.Path(str(_cl.kernel_directory()))
    for label, path in (("clsky", pathlib.Path(clsky.__file__)), ("OpenCL sources", kernels)):
        if source not in path.resolve().parents:
            sys.exit(f"record_pins: {label} come from {path}, not from --source {source}")


def _check_modules(source: pathlib.Path) -> None:
    """Exit with an error if a clsky or anim module used came from outside ``source``."""
    for name, module in sorted(sys.modules.items()):
        path = getattr(module, "__file__", None)
        if name.split(".")[0] in ("clsky", "anim") and path and source not in pathlib.Path(path).resolve().parents:
            sys.exit(f"record_pins: module {name} came from {path}, not from --source {source}: values void")


def _commit_of(checkout, what) -> str:
    """The commit ``checkout`` (as typed) is at; exits with one line where it is no directory, git is missing,
    or it is no git checkout (with git's own reason)."""
    if not pathlib.Path(checkout).is_dir():
        sys.exit(f"record_pins: {what} {checkout} is no directory")
    try:
        done = subprocess.run(["git", "-C", str(checkout), "rev-parse", "HEAD"], capture_output=True, text=True)
    except FileNotFoundError:
        sys.exit("record_pins: git is not installed: it tells which commit the pins' code is at")
    if done.returncode != 0:
        reason = (done.stderr.strip().splitlines() or ["git rev-parse failed"])[-1]
        sys.exit(f"record_pins: {what} {checkout} is no git checkout with a commit: {reason}")
    return done.stdout.strip()


def main(argv=None) -> int:
    pins = _load_pins()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="+", choices=sorted(pins.PINS), help="pins to record")
    parser.add_argument("--source", type=pathlib.Path, help="checkout of the pins' commit (default: today's code)")
    args = parser.parse_args(argv)
    if args.source is not None:
        head = _commit_of(args.source, "--source")
        source = args.source.resolve()
        for name in args.names:
            if not head.startswith(pins.PINS[name].commit):
                sys.exit(f"record_pins: pin {name!r} belongs to commit {pins.PINS[name].commit}; "
                         f"--source is at {head[:7]}")
        _use_source(source)
    else:
        head = _commit_of(ROOT, "this checkout")
    import clsky
    from clsky import _cl

    ctx = _cl.make_context()
    device = _cl.describe_device(ctx.devices[0])
    print(f"# clsky from {pathlib.Path(clsky.__file__).parent} (commit {head[:7]}), device {device!r}")
    for name in args.names:
        pin = pins.PINS[name]
        print(f"# {name} -> {pin.test}")
        for key, compute in pin.cases.items():
            with tempfile.TemporaryDirectory() as scratch:
                values = compute(ctx, scratch)
            print(f"{key!r}: " if key is not None else "", end="")
            pprint.pprint(values, width=110)
    if args.source is not None:
        _check_modules(source)
    return 0


if __name__ == "__main__":
    sys.exit(main())
