"""Issue 9, class 6: messages name what the user typed, print numbers short, and say when PoCL's
kernel cache is what is missing (the command line through a subprocess)."""

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from clsky.anim.animate import AnimationConfig
from clsky.atmosphere import AtmosphereParameters
from clsky.errors import ParameterError, check_integer, check_real, short
from clsky.settings import TableSettings

import forked_cli


ANIMATION_COMMANDS = ("animate", "render", "bench")


def clsky(*args, cwd, env=None):
    """``python -m clsky`` (clsky's commands) or ``python -m clsky.anim`` (extended by anim's, as the
    ``clsky`` console script is), forked from a process that has imported clsky (tests/forked_cli.py; a
    new interpreter where ``env`` is given)."""
    package = "clsky.anim" if args[0] in ANIMATION_COMMANDS else "clsky"
    return forked_cli.run(package, *args, cwd=cwd, env=env)


def one_line_error(result):
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("clsky: error:")
    return lines[0]


@pytest.mark.parametrize("args,named", [
    (["--size", "0", "0", "0"], "--size W must be"),
    (["--size", "8", "1", "4"], "--size H must be"),
    (["--size", "8", "8", "5000"], "--size D must be"),
    (["--order-tolerance", "nan"], "--order-tolerance must be"),
    (["--view-steps", "0"], "--view-steps must be"),
    (["--sun-steps", "99999"], "--sun-steps must be"),
    (["--multiple-view-steps", "0"], "--multiple-view-steps must be"),
    (["--azimuth-harmonics", "-1", "--mode", "physical"], "--azimuth-harmonics must be"),
    (["--azimuth-harmonics", "2", "--mode", "atmosphere-plus"], "--azimuth-harmonics must be"),
    (["--max-orders", "1"], "--max-orders must be"),
    (["--orders", "0"], "--orders must be"),
    (["--gather-steps", "1", "8"], "--gather-steps THETA must be"),
    (["--gather-steps", "8", "1"], "--gather-steps PHI must be"),
    (["--transmittance-size", "1", "8"], "--transmittance-size TW must be"),
    (["--transmittance-size", "8", "1"], "--transmittance-size TH must be"),
])
def test_table_errors_name_the_option(tmp_path, args, named):
    line = one_line_error(clsky("table", "--progress", "none", *args, cwd=tmp_path))
    assert named in line, line
    assert "size[" not in line and "_" not in line.split(" must ")[0], line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args,named", [
    (["--table-size", "4096", "4096", "4096"], "--table-size must be"),
    (["--table-size", "1", "33", "7"], "--table-size W must be"),
    (["--table-size", "9", "33", "5000"], "--table-size D must be"),
    (["--size", "8"], "--size must be"),
    (["--location", "45", "5", "--hours", "10", "5"], "--hours END must be"),
    # an option the frames would not use is named as such before its value is looked at
    (["--hours", "10", "5"], "--hours sets real sun positions: give --location LAT LON too"),
    (["--error-budget", "nan"], "--error-budget must be"),
    (["--preset", "venus"], "--preset must be"),
    (["--location", "45", "5", "--step-minutes", "0.001"], "--step-minutes must be"),
    # the last day datetime can hold: its end overflowed (a traceback); past 3000 pvlib's Delta T is unknown
    (["--location", "45", "5", "--date", "9999-12-31"], "--date must be a day whose frames, to 24 h UTC, fall in "
                                                        "the years 1 to 3000"),
    (["--location", "45", "5", "--date", "3000-12-31", "--hours", "0", "24.5"], "--date must be"),
    (["--max-elevation", "-10"], "--max-elevation must be at least the start elevation"),
])
def test_animate_errors_name_the_option(tmp_path, args, named):
    line = one_line_error(clsky("animate", "--progress", "none", *args, cwd=tmp_path))
    assert named in line, line


@pytest.mark.parametrize("command,args", [
    ("animate", ["--frames", str(10**300)]),
    ("animate", ["--size", str(10**300)]),
    ("animate", ["--samples", str(10**300)]),
    ("animate", ["--table-size", "8", "8", str(10**300)]),
    ("render", ["--size", str(-10**300)]),
    ("table", ["--size", "8", "8", str(10**300)]),
    ("table", ["--orders", str(10**300)]),
    ("table", ["--max-orders", str(10**300)]),
    ("table", ["--view-steps", str(10**300)]),
    ("table", ["--gather-steps", str(10**300), "8"]),
    ("bench", ["accuracy", "--size", str(10**300)]),
])
def test_numbers_in_messages_are_short(tmp_path, command, args):
    line = one_line_error(clsky(command, *args, cwd=tmp_path))
    assert len(line) < 200 and "1e+300" in line, line


@pytest.mark.parametrize("value, shown", [("nan", "nan"), ("1e308", "1e+308"), ("-361", "-361")])
def test_render_sun_azimuth_names_the_option_and_its_range(tmp_path, value, shown):
    """--heading's range, [-360, 720] degrees: 1e308 rendered, though its radians kept no precision."""
    line = one_line_error(clsky("render", "--sun-azimuth", value, cwd=tmp_path))
    assert line == f"clsky: error: --sun-azimuth must be in [-360, 720] degrees, got {shown}", line


def test_short_numbers():
    assert short(10**300) == "1e+300" and short(-(10**5000)) == "-1e+5000"
    assert short(0.25) == "0.25" and short(4096) == "4096" and short(float("nan")) == "nan"
    assert len(short("x" * 1000)) <= 60


def test_short_numbers_never_print_as_another_number():
    """A value just outside a range printed with 6 digits read as its bound ("cos_view must be in [-1, 1],
    got 1" for 1.0000001): a number whose 6 digits are not itself prints every digit it takes."""
    assert short(1.0000001) == "1.0000001" and short(0.1 + 0.2) == "0.30000000000000004"
    assert short(np.float32(0.1)) == "0.1"              # float32's own shortest digits, not float64's
    assert short(1e-300) == "1e-300" and short(float("inf")) == "inf"
    with pytest.raises(ValueError, match=r"got 1\.0000001$"):
        check_real("cos_view", 1.0000001, -1.0, 1.0)


def test_numbers_too_large_for_a_float_are_refused_by_name():
    """``10**400`` made float() raise OverflowError inside the checks (an AtmosphereParameters field, a
    camera's heading, a range's bound): now the parameter's ValueError."""
    with pytest.raises(ValueError, match=r"heading_deg must be a finite number.*got 1e\+400"):
        check_real("heading_deg", 10**400)
    with pytest.raises(ValueError, match=r"planet_radius must be a finite real number, got 1e\+400"):
        AtmosphereParameters(planet_radius=10**400)
    with pytest.raises(ValueError, match=r"sun_cos_range must be"):
        TableSettings(sun_cos_range=(-1, 10**400))
    with pytest.raises(ValueError, match=r"refractive_index must be a finite real number"):
        AtmosphereParameters.from_refractive_index(10**400)
    with pytest.raises(ValueError, match=r"refractive_index must be a real number in \[1, 10\], got 1e\+200"):
        AtmosphereParameters.from_refractive_index(1e200)
    with pytest.raises(ValueError, match=r"location must be None or \(latitude in \[-90, 90\].*got \(1e\+400, 0\)"):
        AnimationConfig(location=(10**400, 0))


def test_an_integer_parameter_given_a_float_says_so():
    """``size[0] must be an integer ..., got 8`` for 8.0 (a table file's JSON) read as a contradiction."""
    with pytest.raises(ValueError, match=r"size\[0\] must be an integer in \[2, 4096\], got 8 \(float\)$"):
        TableSettings(size=(8.0, 16, 8))


def test_parameter_error_carries_field_and_index():
    with pytest.raises(ParameterError) as caught:
        TableSettings(size=(8, 1, 8))
    assert (caught.value.field, caught.value.index) == ("size", 1)
    assert str(caught.value) == "size[1] must be an integer in [2, 4096], got 1"
    assert caught.value.reworded("--size H") == "--size H must be an integer in [2, 4096], got 1"


def test_optional_parameter_reworded_for_the_user_leaves_none_out():
    """None is what leaving an option or scene key out gives: the API's message offers it, the typed
    name's does not."""
    with pytest.raises(ParameterError) as caught:
        check_integer("samples", 0, 2, 4096, optional=True)
    assert str(caught.value) == "samples must be None or an integer in [2, 4096], got 0"
    assert caught.value.reworded("--samples") == "--samples must be an integer in [2, 4096], got 0"


@pytest.mark.parametrize("command,args,expected", [
    ("render", ["--samples", "0"], "clsky: error: --samples must be an integer in [2, 4096], got 0"),
    ("animate", ["--ground-albedo", "2"], "clsky: error: --ground-albedo must be a number in [0, 1], got 2"),
])
def test_optional_options_messages_offer_what_can_be_typed(tmp_path, command, args, expected):
    assert one_line_error(clsky(command, *args, cwd=tmp_path)) == expected


UNWRITABLE = "/proc/clsky-unwritable"       # not even root can create a directory there


def test_unwritable_default_pocl_cache_falls_back_with_a_note(tmp_path):
    env = {"PATH": "/usr/bin:/bin", "HOME": UNWRITABLE, "XDG_CACHE_HOME": UNWRITABLE, "TMPDIR": str(tmp_path)}
    result = clsky("devices", cwd=tmp_path, env=env)
    assert result.returncode == 0, result.stdout + result.stderr
    notes = result.stderr.strip().splitlines()
    assert len(notes) == 1 and notes[0].startswith("clsky: note:") and "POCL_CACHE_DIR" in notes[0], notes
    assert any(line.startswith("* ") for line in result.stdout.splitlines())


def test_unwritable_pocl_cache_dir_is_named(tmp_path):
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "POCL_CACHE_DIR": UNWRITABLE}
    result = clsky("devices", cwd=tmp_path, env=env)
    assert result.returncode == 1
    assert "POCL_CACHE_DIR" in result.stdout and "not a writable directory" in result.stdout, result.stdout
    result = clsky("table", "--size", "4", "8", "4", "--progress", "none", cwd=tmp_path, env=env)
    assert result.returncode == 1
    assert "POCL_CACHE_DIR" in result.stderr and "install" not in result.stderr, result.stderr


def test_a_pocl_cache_dir_that_is_a_file_is_one_line_before_any_work(tmp_path):
    """POCL_CACHE_DIR naming a regular file: PoCL lists its device but fails every build, which ended in a
    77-line PyOpenCL traceback after the checks; now one line naming it, before the table."""
    (tmp_path / "afile").write_text("hi")
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "POCL_CACHE_DIR": str(tmp_path / "afile")}
    result = clsky("table", "--size", "4", "8", "4", "--progress", "none", "-o", "t.npz", cwd=tmp_path, env=env)
    assert result.returncode == 1 and len(result.stderr.splitlines()) == 1, result.stderr
    assert result.stderr.startswith(f"clsky: error: PoCL's kernel cache POCL_CACHE_DIR={tmp_path / 'afile'} is not "
                                    f"a writable directory")
    assert not (tmp_path / "t.npz").exists()
    devices = clsky("devices", cwd=tmp_path, env=env)          # it listed the device as usable, exit 0
    assert devices.returncode == 1 and "POCL_CACHE_DIR" in devices.stderr, devices.stderr
    # with PYOPENCL_CTX naming that device: the cache, not "PYOPENCL_CTX selects none of the devices" (exit 2)
    devices = clsky("devices", cwd=tmp_path, env={**env, "PYOPENCL_CTX": "0:0"})
    assert devices.returncode == 1 and "POCL_CACHE_DIR" in devices.stderr, devices.stderr


def test_a_kernel_cache_on_a_full_disk_is_named(tmp_path, monkeypatch):
    """POCL_CACHE_DIR on a full disk: an empty test file could still be made there, and the first build ended
    in PyOpenCL's traceback; a cache needs some free space (MIN_CACHE_FREE_BYTES) as well."""
    import collections

    from clsky import _cl

    full = collections.namedtuple("statvfs", "f_bavail f_frsize")(10, 4096)
    monkeypatch.setattr(_cl.os, "statvfs", lambda path: full)
    monkeypatch.setenv("POCL_CACHE_DIR", str(tmp_path))
    _cl.pocl_cache_problem.cache_clear()
    try:
        problem = _cl.pocl_cache_problem()
    finally:
        _cl.pocl_cache_problem.cache_clear()
    assert problem == (f"PoCL's kernel cache POCL_CACHE_DIR={tmp_path} has 0.039 MiB free, under the 4 MiB its builds "
                       f"need (PoCL then finds no device, or fails every build); set POCL_CACHE_DIR to a writable "
                       f"directory with 4 MiB free")
    # without POCL_CACHE_DIR, the default cache and its fallback say the same, not "not writable"
    monkeypatch.delenv("POCL_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    _cl.pocl_cache_problem.cache_clear()
    try:
        problem = _cl.pocl_cache_problem()
    finally:
        _cl.pocl_cache_problem.cache_clear()
    assert problem.startswith(f"PoCL's kernel cache {tmp_path / 'xdg' / 'pocl'} (from XDG_CACHE_HOME) has 0.039 MiB "
                              f"free, under the 4 MiB its builds need, and the fallback "), problem
    assert "not usable: it has 0.039 MiB free" in problem, problem


def test_an_unusable_home_falls_back_for_pyopencls_cache_too(tmp_path):
    """HOME unusable and XDG_CACHE_HOME unset: clsky's fallback covered PoCL's cache but not PyOpenCL's
    (pytools', under ~/.cache): a render ended in '[Errno 2] No such file or directory' and two stray
    tracebacks. Now the run works, with the note."""
    env = {"PATH": "/usr/bin:/bin", "HOME": UNWRITABLE, "TMPDIR": str(tmp_path),
           "CLSKY_CACHE_DIR": str(tmp_path / "clsky-cache")}
    result = clsky("render", "--size", "16", "--quality", "draft", "--method", "lut", "-o", "x.png", cwd=tmp_path,
                   env=env)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "x.png").exists() and "Traceback" not in result.stderr
    assert result.stderr.startswith("clsky: note: PoCL's kernel cache"), result.stderr


@pytest.mark.parametrize("planted", ["symlink", "world-writable"])
def test_a_fallback_cache_someone_else_made_is_not_used(monkeypatch, tmp_path, planted):
    """The fallback's name in the shared temporary directory is predictable: a directory made there first
    by someone else (here a link to another directory) would have received the compiled kernels and
    supplied binaries to load. It is refused, and the problem says why. One of this user's that others may
    write (an earlier clsky's, made under a umask of 002) is made private and used."""
    import tempfile

    from clsky import _cl

    shared = tmp_path / "shared"
    shared.mkdir()
    fallback = shared / f"clsky-pocl-cache-{os.getuid()}"
    if planted == "symlink":
        (tmp_path / "elsewhere").mkdir(mode=0o700)
        fallback.symlink_to(tmp_path / "elsewhere")
    else:
        fallback.mkdir()
        fallback.chmod(0o777)
    monkeypatch.delenv("POCL_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", UNWRITABLE)
    monkeypatch.setattr(tempfile, "tempdir", str(shared))
    problem = _cl.pocl_cache_problem.__wrapped__()
    if planted == "symlink":
        assert problem is not None and str(fallback) in problem and "it is a link or a file" in problem
        assert "POCL_CACHE_DIR" not in _cl.os.environ
    else:
        assert problem is None and _cl.os.environ["POCL_CACHE_DIR"] == str(fallback)
        assert fallback.stat().st_mode & 0o777 == 0o755


@pytest.mark.parametrize("selector", ["0:9", "9"])
def test_a_pyopencl_ctx_that_names_no_device_is_bad_input(tmp_path, selector):
    """PYOPENCL_CTX selecting nothing: exit status 2 as `clsky devices` gives it (the computing commands gave
    1). (An index beyond the devices that matches a device's name is PyOpenCL's to take: '0:4090' names an
    RTX 4090.)"""
    env = {**os.environ, "PYOPENCL_CTX": selector}
    result = clsky("render", "--size", "16", "--quality", "draft", "-o", "r.png", cwd=tmp_path, env=env)
    assert one_line_error(result).startswith(f"clsky: error: PYOPENCL_CTX='{selector}' selects no device")
    assert clsky("devices", cwd=tmp_path, env=env).returncode == 2 and not (tmp_path / "r.png").exists()


def test_the_fallback_moves_xdg_cache_home_only_where_the_cache_home_is_unwritable(monkeypatch, tmp_path):
    """~/.cache writable but ~/.cache/pocl not (a file there): PoCL's cache moves, XDG_CACHE_HOME stays (it
    moved clsky's own cache and PyOpenCL's to the temporary directory mid-run)."""
    import tempfile

    from clsky import _cl

    home = tmp_path / "home"
    (home / ".cache").mkdir(parents=True)
    (home / ".cache" / "pocl").write_text("a file")
    monkeypatch.setenv("HOME", str(home))
    for name in ("POCL_CACHE_DIR", "XDG_CACHE_HOME"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert _cl.pocl_cache_problem.__wrapped__() is None
    assert _cl.os.environ["POCL_CACHE_DIR"].startswith(str(tmp_path)) and "XDG_CACHE_HOME" not in _cl.os.environ


def test_pocl_cache_problem_in_process(monkeypatch, tmp_path):
    """The check itself (not cached: ``__wrapped__``): a default cache that cannot be written falls back
    to a private one under the temporary directory; a POCL_CACHE_DIR that cannot is named, not replaced."""
    import tempfile

    from clsky import _cl

    monkeypatch.delenv("POCL_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", UNWRITABLE)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert _cl.pocl_cache_problem.__wrapped__() is None
    assert _cl.os.environ["POCL_CACHE_DIR"].startswith(str(tmp_path))
    monkeypatch.setenv("POCL_CACHE_DIR", UNWRITABLE)
    problem = _cl.pocl_cache_problem.__wrapped__()
    assert "POCL_CACHE_DIR" in problem and UNWRITABLE in problem
    monkeypatch.setenv("POCL_CACHE_DIR", str(tmp_path))
    assert _cl.pocl_cache_problem.__wrapped__() is None


# Missing optional dependencies: one line, before any work -------------------------------------------

def _without(tmp_path, *packages):
    """An environment in which importing each of ``packages`` fails as if it were not installed: a
    package of that name that raises ImportError, first on PYTHONPATH."""
    blocked = tmp_path / "blocked"
    for package in packages:
        (blocked / package).mkdir(parents=True)
        (blocked / package / "__init__.py").write_text(f"raise ImportError('{package} blocked by the test')\n")
    return {**os.environ, "PYTHONPATH": str(blocked)}


@pytest.mark.parametrize("args,missing,named", [
    (["render", "--size", "16"], "PIL", "PNG images need PIL: pip install 'clsky[anim]'"),
    (["animate", "--frames", "2", "--size", "16", "--progress", "none"], "PIL",
     "PNG images need PIL: pip install 'clsky[anim]'"),
    (["bench", "accuracy", "--size", "16", "--quick", "--progress", "none"], "matplotlib",
     "the accuracy plots need matplotlib: pip install 'clsky[bench]'"),
])
def test_missing_extra_is_one_line_before_any_work(tmp_path, args, missing, named):
    """Without Pillow (PNG) or matplotlib (the accuracy plots) the command stops before it computes
    anything, with exit status 2 and a line saying what to install; nothing is written."""
    work = tmp_path / "work"
    work.mkdir()
    line = one_line_error(clsky(*args, cwd=work, env=_without(tmp_path, missing)))
    assert named in line, line
    assert list(work.iterdir()) == []


def test_a_path_with_a_line_break_stays_one_line(tmp_path):
    """``clsky info $'missing\\nline.npz'`` printed its error on two lines."""
    line = one_line_error(clsky("info", "missing\nline.npz", cwd=tmp_path))
    assert line == "clsky: error: missing\\nline.npz: no such file"


def test_a_reader_that_leaves_ends_the_output_quietly(tmp_path):
    """``clsky info FILE | head -1``: a reader that leaves before the output ended it with "clsky: error:
    [Errno 32] Broken pipe" and status 1. Now nothing is printed, and the status is SIGPIPE's (128 + 13)."""
    frame = pathlib.Path(__file__).resolve().parents[1] / "docs" / "frame.png"
    process = subprocess.Popen([sys.executable, "-m", "clsky", "info", str(frame)], cwd=tmp_path,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()                                  # the reader is gone before the first line
    _, err = process.communicate(timeout=120)
    assert process.returncode == 141 and err == b"", err


def test_a_time_step_longer_than_the_hours_names_the_option(tmp_path):
    """--hours 12 12.1 with the default 10-minute step gave one sun position: "need at least 2 frames, got 1",
    after the table's build and naming no option."""
    line = one_line_error(clsky("animate", "--location", "45", "7", "--hours", "12", "12.1", "-o", "h.mp4",
                                cwd=tmp_path))
    assert line.startswith("clsky: error: --step-minutes must be at most 6 minutes, the time from 12 h to 12.1 h"), line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["table", "render"])
def test_the_ozone_column_has_one_range_in_every_command(tmp_path, command):
    """clsky table refused --ozone-column 1e308 through the optical-depth check ("here 6.58e+303", no unit
    one types), clsky render with its range in DU: both now say the range."""
    line = one_line_error(clsky(command, "--ozone-column", "1e308", cwd=tmp_path))
    assert line == "clsky: error: --ozone-column must be a number in [0, 100000] DU, got 1e+308"
