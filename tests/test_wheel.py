"""A normal (non-editable) install ships the kernels: build a wheel, install it into an empty
directory, and build every OpenCL program from that installed copy in a fresh interpreter."""

import os
import pathlib
import shutil
import subprocess
import sys
import textwrap
import zipfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent


def build_wheel(tmp_path):
    """The wheel of the repository's files as a clean clone has them: setuptools builds in the
    source tree and reuses its build/ folder, so a stale build/lib (an earlier layout's packages) in a
    developer's checkout would otherwise end up in the wheel. Tracked and untracked-not-ignored files
    are copied (git ls-files); outside a git checkout, the tree without build/ and the usual caches."""
    source = tmp_path / "source"
    listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"], cwd=ROOT,
                            capture_output=True)
    if listed.returncode == 0:
        for name in filter(None, listed.stdout.decode().split("\0")):
            if (ROOT / name).is_file():
                (source / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(ROOT / name, source / name)
    else:
        shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns("build", ".venv", "node_modules", ".git",
                                                                     "*.egg-info", "__pycache__"))
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(source)],
                   check=True, cwd=tmp_path)
    (wheel,) = wheels.glob("clsky-*.whl")
    return wheel


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """One wheel for both tests (building it took 4-5 s of each)."""
    return build_wheel(tmp_path_factory.mktemp("wheel"))


BUILD_EVERY_PROGRAM = textwrap.dedent("""
    import pathlib, sys
    import clsky, clsky._cl as cl_
    from clsky.lookup import TableLookupEngine
    from clsky.lookup4d import TableLookup4DEngine
    from clsky.settings import TableSettings
    from clsky.single import SingleScatteringEngine
    from clsky.transmittance import TransmittanceEngine
    installed = pathlib.Path(sys.argv[1]).resolve()
    assert pathlib.Path(clsky.__file__).resolve().is_relative_to(installed), clsky.__file__
    source = pathlib.Path(str(cl_.kernel_directory().joinpath("single.cl"))).resolve()
    assert source.is_relative_to(installed), source
    for dtype in ("float64", "float32"):
        TransmittanceEngine(dtype=dtype)
        TransmittanceEngine(dtype=dtype, sampling="keller_bohn")
        TableLookupEngine(dtype=dtype)
        TableLookup4DEngine(dtype=dtype)
        for sun in ("march", "table"):
            SingleScatteringEngine(TableSettings(dtype=dtype, sun_transmittance=sun, sampling="keller_bohn"))
            SingleScatteringEngine(TableSettings(dtype=dtype, sun_transmittance=sun))
    table = clsky.ScatteringTable.build("physical", TableSettings(size=(8, 8, 4), mode="physical"))   # -DOZONE -DGROUND
    assert (table.data >= 0).all()
    table4d = clsky.ScatteringTable.build("physical", TableSettings(size=(8, 8, 4), mode="physical",
                                                                    parameterization="4d", azimuth_size=3))
    assert (table4d.data >= 0).all()
    print("built every program from", cl_.kernel_directory())
""")


def test_wheel_ships_kernels_and_builds_every_program(wheel, tmp_path):
    names = zipfile.ZipFile(wheel).namelist()
    kernel_files = sorted(p.name for p in (ROOT / "kernels").glob("*.cl"))
    assert sorted(n.split("/")[-1] for n in names if n.startswith("clsky/kernels/")) == kernel_files
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
                    str(wheel)], check=True, cwd=tmp_path)
    environment = dict(os.environ, PYTHONPATH=str(target))
    result = subprocess.run([sys.executable, "-c", BUILD_EVERY_PROGRAM, str(target)], cwd=tmp_path,
                            env=environment, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "built every program" in result.stdout


def test_wheel_installs_nothing_but_clsky(wheel, tmp_path):
    """Issue 13 item 3: the animation package (the repository's top-level anim/) installs as
    clsky.anim; nothing outside the clsky name lands in site-packages (an installed top-level
    ``anim`` could collide with any other package of that generic name)."""
    top_level = {name.split("/")[0] for name in zipfile.ZipFile(wheel).namelist()}
    assert {name for name in top_level if not name.endswith(".dist-info")} == {"clsky"}
    assert len(top_level) == 2, top_level                     # clsky/ and its one dist-info
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
                    str(wheel)], check=True, cwd=tmp_path)
    installed = {p.name for p in target.iterdir()} - {"bin"}  # --target puts the console script in bin/
    assert {name for name in installed if not name.endswith(".dist-info")} == {"clsky"}
    assert not (target / "anim").exists()
    check = textwrap.dedent("""
        import pathlib, sys
        import clsky.anim.animate, clsky.anim.cli
        installed = pathlib.Path(sys.argv[1]).resolve()
        assert pathlib.Path(clsky.anim.animate.__file__).resolve().is_relative_to(installed / "clsky" / "anim")
        try:
            import anim
        except ImportError:
            print("no top-level anim")
    """)
    result = subprocess.run([sys.executable, "-c", check, str(target)], cwd=tmp_path,
                            env=dict(os.environ, PYTHONPATH=str(target)), capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "no top-level anim" in result.stdout
    entry_points = (next(target.glob("clsky-*.dist-info")) / "entry_points.txt").read_text()
    assert "clsky = clsky.anim.cli:main" in entry_points
