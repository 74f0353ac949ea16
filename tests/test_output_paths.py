"""Issue 9, class 4: every output path is checked before the work.

An output that cannot be written (a read-only place, a missing parent, a parent that is a file, a
directory in the way, a name too long for the file system) is refused before any table is built:
the API raises FileExistsError, IsADirectoryError, FileNotFoundError, NotADirectoryError,
PermissionError or ValueError naming the path; the command line exits 2 with one line that names the
option and the path (never raw errno text about a temporary file), and writes nothing.

"Read-only" is tested as it really fails for root (the tests run as root, where os.access says yes
to a mode 0555 directory and writing there succeeds): an immutable directory (``chattr +i``, where
the file system supports it) and /sys (os.access says yes, creating a file fails). A mode 0555
directory is tested when not running as root.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import subprocess
import tempfile

import numpy as np
import pytest

from clsky import ScatteringTable, TableSettings
from clsky._files import StagedWrites, atomic_write, check_output, check_output_directory
from clsky.anim.writers import FrameWriter, write_csv, write_json, write_png

import forked_cli
from conftest import black_preset

NAME_MAX = os.pathconf(tempfile.gettempdir(), "PC_NAME_MAX")
#: A big table: if an output check came after the build, the command would run for minutes (and the
#: test time out) instead of exiting at once.
SLOW_TABLE = ("--size", "64", "512", "64", "--backend", "numpy")


def _sys_refuses_files():
    try:
        fd, name = tempfile.mkstemp(dir="/sys")
    except OSError:
        return os.path.isdir("/sys") and os.access("/sys", os.W_OK)
    os.close(fd)
    os.unlink(name)
    return False


SYS_READ_ONLY = _sys_refuses_files()
needs_sys = pytest.mark.skipif(not SYS_READ_ONLY, reason="needs a /sys where os.access says yes, creating fails")


@pytest.fixture
def immutable_directory(tmp_path):
    """A directory nobody, root included, can create files in (chattr +i); skipped where unsupported."""
    directory = tmp_path / "locked"
    directory.mkdir()
    (directory / "old.npz").write_bytes(b"old")
    if subprocess.run(["chattr", "+i", str(directory)], capture_output=True).returncode != 0:
        pytest.skip("chattr +i is not supported here")
    try:
        yield directory
    finally:
        subprocess.run(["chattr", "-i", str(directory)], check=True)


def clsky(*args, cwd, timeout=60):
    return forked_cli.run("clsky.anim", *args, cwd=cwd, timeout=timeout)


def assert_usage_error(result, *named):
    """Exit 2, one line on stderr naming each of ``named``, no raw errno text, no summary."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("clsky: error: "), lines[0]
    for text in named:
        assert text in lines[0], (text, lines[0])
    assert "Errno" not in lines[0] and ".part" not in lines[0]
    assert result.stdout == ""


def listing(directory):
    return sorted(path.name for path in pathlib.Path(directory).iterdir())


# 1. The API: check_output and the writers -------------------------------------------------------------

def test_check_output_refuses_what_cannot_be_written(tmp_path):
    (tmp_path / "old.png").write_bytes(b"old")
    (tmp_path / "folder.png").mkdir()
    (tmp_path / "file").write_bytes(b"")
    cases = [
        (tmp_path / "old.png", FileExistsError, "old.png exists"),
        (tmp_path / "folder.png", IsADirectoryError, "is a directory"),
        (tmp_path / "missing" / "x.png", FileNotFoundError, "directory .*missing does not exist"),
        (tmp_path / "file" / "x.png", NotADirectoryError, "file is not a directory"),
        (tmp_path / ("n" * (NAME_MAX + 1) + ".png"), ValueError, f"allows {NAME_MAX}"),
    ]
    for path, error, message in cases:
        with pytest.raises(error, match=message):
            check_output(path)
    check_output(tmp_path / "old.png", force=True)              # force: an existing file may go
    with pytest.raises(IsADirectoryError):
        check_output(tmp_path / "folder.png", force=True)       # never a directory
    with pytest.raises(FileExistsError, match="^--output: .*old.png exists; use --force"):
        check_output(tmp_path / "old.png", option="--output")
    assert listing(tmp_path) == ["file", "folder.png", "old.png"]     # the probe leaves nothing


def test_check_output_refuses_a_name_that_ends_in_a_separator(tmp_path):
    """'x.npz/' names a directory, not the file x.npz that pathlib reads it as."""
    with pytest.raises(IsADirectoryError, match=r"^--raw: .*x\.npz/ names a directory \(its trailing '/', '/\.' or "
                                                r"'/\.\.'\), not a file$"):
        check_output(f"{tmp_path}/x.npz/", option="--raw")
    assert check_output(tmp_path / "x.npz") == tmp_path / "x.npz"


def test_check_output_directory(tmp_path):
    (tmp_path / "file").write_bytes(b"")
    check_output_directory(tmp_path / "new" / "deeper")       # created later with parents=True
    with pytest.raises(NotADirectoryError, match="file"):
        check_output_directory(tmp_path / "file")
    with pytest.raises(NotADirectoryError, match="file"):
        check_output_directory(tmp_path / "file" / "frames")
    with pytest.raises(ValueError, match="bytes long"):
        check_output_directory(tmp_path, names=["f" * NAME_MAX + ".png"])
    assert listing(tmp_path) == ["file"]


@needs_sys
def test_read_only_place_as_root_is_found_by_the_probe():
    with pytest.raises(PermissionError, match="cannot create a file in directory /sys"):
        check_output("/sys/sky.png")
    with pytest.raises(PermissionError, match="/sys"):
        write_png("/sys/sky.png", np.zeros((2, 2, 3), np.uint8))


def test_immutable_directory(immutable_directory):
    with pytest.raises(PermissionError, match="locked"):
        check_output(immutable_directory / "new.png")
    with pytest.raises(PermissionError, match="locked"):
        write_json(immutable_directory / "new.json", {})
    assert listing(immutable_directory) == ["old.npz"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write in a mode 0555 directory")
def test_read_only_mode_directory(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        with pytest.raises(PermissionError, match="locked"):
            check_output(locked / "new.png")
    finally:
        locked.chmod(0o755)


def test_name_at_the_limit_still_gets_a_temporary_that_fits(tmp_path):
    """A name of exactly NAME_MAX bytes is legal: the temporary's prefix is shortened, not refused."""
    target = tmp_path / ("m" * (NAME_MAX - 4) + ".csv")
    write_csv(target, [{"a": 1}])
    assert listing(tmp_path) == [target.name]
    with StagedWrites() as staging:
        temporary = staging.stage(tmp_path / ("t" * (NAME_MAX - 5) + ".json"))
        assert len(temporary.name) <= NAME_MAX and temporary.name.endswith(".json")
        temporary.write_text("{}")


@pytest.mark.parametrize("writer", ["png", "json", "csv"])
def test_writers_raise_before_writing(tmp_path, writer):
    write = {"png": lambda path: write_png(path, np.zeros((2, 2, 3), np.uint8)),
             "json": lambda path: write_json(path, {"a": 1}),
             "csv": lambda path: write_csv(path, [{"a": 1}])}[writer]
    (tmp_path / "in_the_way").mkdir()
    with pytest.raises(FileNotFoundError, match="missing"):
        write(tmp_path / "missing" / f"x.{writer}")
    with pytest.raises(IsADirectoryError, match="in_the_way"):
        write(tmp_path / "in_the_way")
    with pytest.raises(ValueError, match="bytes long"):
        write(tmp_path / ("x" * NAME_MAX + f".{writer}"))
    assert listing(tmp_path) == ["in_the_way"]
    assert listing(tmp_path / "in_the_way") == []


def test_frame_writer_checks_every_output_on_entering(tmp_path):
    (tmp_path / "frames_file").write_bytes(b"")
    (tmp_path / "movie.mp4").mkdir()
    with pytest.raises(NotADirectoryError, match="frames_file"):
        with FrameWriter(directory=tmp_path / "frames_file"):
            pass
    with pytest.raises(IsADirectoryError, match="movie.mp4"):
        with FrameWriter(mp4_path=tmp_path / "movie.mp4", force=True):
            pass
    with pytest.raises(FileNotFoundError, match="nowhere"):
        FrameWriter(mp4_path=tmp_path / "nowhere" / "a.mp4").check()
    with pytest.raises(ValueError, match="bytes long"):
        FrameWriter(directory=tmp_path / ("d" * (NAME_MAX + 1))).check()
    assert listing(tmp_path) == ["frames_file", "movie.mp4"]


@pytest.fixture(scope="module")
def tiny_table(cl_context):
    return ScatteringTable.build(black_preset("physical"), TableSettings(size=(4, 8, 4), orders=1), ctx=cl_context)


def test_table_save_and_export_raw_check_first(tmp_path, tiny_table):
    (tmp_path / "sky.json").mkdir()                  # in the way of the raw export's header
    with pytest.raises(FileNotFoundError, match="missing"):
        tiny_table.save(tmp_path / "missing" / "t.npz")
    with pytest.raises(IsADirectoryError, match="sky.json"):
        tiny_table.export_raw(tmp_path / "sky", overwrite=True)
    assert listing(tmp_path) == ["sky.json"]          # not even the .bin: both are checked first
    (tmp_path / "sky.json").rmdir()
    binary, header = tiny_table.export_raw(tmp_path / "sky")
    assert listing(tmp_path) == ["sky.bin", "sky.json"]
    with pytest.raises(FileExistsError, match="sky.bin"):
        tiny_table.export_raw(tmp_path / "sky")


def test_render_animation_checks_before_building_the_table(tmp_path, monkeypatch):
    from clsky.anim import animate

    def no_build(*args, **kwargs):
        raise AssertionError("the table was built before the outputs were checked")

    monkeypatch.setattr(animate, "build_table", no_build)
    (tmp_path / "sky_metrics.csv").mkdir()
    config = animate.AnimationConfig(frames=2, size=16, method="lut", table_size=(4, 8, 4), force=True,
                                     output=str(tmp_path / "sky.mp4"))
    with pytest.raises(IsADirectoryError, match="sky_metrics.csv"):
        animate.render_animation(config)
    (tmp_path / "sky_metrics.csv").rmdir()
    (tmp_path / "sky_frames").mkdir()
    (tmp_path / "sky_frames" / "frame_00001.png").write_bytes(b"old")
    with pytest.raises(FileExistsError, match="frame_00001.png"):
        animate.render_animation(dataclasses.replace(config, force=False))
    assert listing(tmp_path) == ["sky_frames"]


# 2. The command line -------------------------------------------------------------------------------

def test_cli_table_outputs_checked_before_the_build(tmp_path):
    """Each case would take minutes if the table were built first (SLOW_TABLE): the timeout proves
    the order; nothing is written."""
    (tmp_path / "folder.npz").mkdir()
    (tmp_path / "file").write_bytes(b"")
    (tmp_path / "raw.json").mkdir()
    long_name = "n" * (NAME_MAX - 3) + ".npz"
    cases = [
        (["-o", "missing/t.npz"], ["--output", "directory missing does not exist"]),
        (["-o", "folder.npz", "--force"], ["--output", "folder.npz is a directory"]),
        (["-o", "file/t.npz"], ["--output", "file is not a directory"]),
        (["-o", long_name], ["--output", "bytes long"]),
        (["-o", "t.npz", "--raw", "missing/raw"], ["--raw", "missing"]),
        (["-o", "t.npz", "--raw", "raw", "--force"], ["--raw", "raw.json is a directory"]),
        (["-o", "t.npz", "--raw", "r" * (NAME_MAX - 3)], ["--raw", "bytes long"]),
        # names without a file name: '' exported nothing, silently; '.json' wrote hidden .json.bin, .json.json
        (["-o", "t.npz", "--raw", ""], ["--raw must be a file name (NAME gives NAME.bin and NAME.json), got ''"]),
        (["-o", "t.npz", "--raw", ".json"], ["--raw must be a file name", "got '.json'"]),
        (["-o", "t.npz", "--raw", "folder.npz/"], ["--raw must be a file name"]),
    ]
    if SYS_READ_ONLY:
        cases.append((["-o", "/sys/t.npz"], ["--output", "cannot create a file in directory /sys"]))
    for args, named in cases:
        result = clsky("table", *SLOW_TABLE, "--progress", "none", *args, cwd=tmp_path)
        assert_usage_error(result, *named)
    assert listing(tmp_path) == ["file", "folder.npz", "raw.json"]     # no t.npz without its raw export


def test_raw_export_names(tmp_path, tiny_table):
    """NAME.bin and NAME.json: a typed .bin or .json is the pair's own suffix, any other dot belongs to
    the name (pathlib's with_suffix wrote sky.bin for 'sky.v2'); the command line's summary names them."""
    from clsky._files import binary_and_header

    assert binary_and_header(tmp_path / "sky.json") == (tmp_path / "sky.bin", tmp_path / "sky.json")
    assert binary_and_header("h2.5km") == (pathlib.Path("h2.5km.bin"), pathlib.Path("h2.5km.json"))
    for bad in ("", ".bin", "..", "out/", 3):
        with pytest.raises(ValueError, match="^path must be a file name"):
            binary_and_header(bad)
    assert tiny_table.export_raw(tmp_path / "sky.bin") == (tmp_path / "sky.bin", tmp_path / "sky.json")
    assert tiny_table.export_raw(tmp_path / "sky.v2") == (tmp_path / "sky.v2.bin", tmp_path / "sky.v2.json")
    with pytest.raises(ValueError, match="^path must be a file name"):
        tiny_table.export_raw(tmp_path / ".json")
    assert listing(tmp_path) == ["sky.bin", "sky.json", "sky.v2.bin", "sky.v2.json"]
    result = clsky("table", "--size", "4", "8", "4", "--orders", "1", "--progress", "none", "-o", "t.npz", "--raw",
                   "dusk.v2", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.rstrip().endswith("-> t.npz, dusk.v2.bin, dusk.v2.json"), result.stdout


def test_cli_table_into_an_immutable_directory(immutable_directory):
    result = clsky("table", *SLOW_TABLE, "--progress", "none", "-o", "locked/old.npz", "--force",
                   cwd=immutable_directory.parent)
    assert_usage_error(result, "--output", "locked")
    assert listing(immutable_directory) == ["old.npz"]


ANIMATE = ("animate", "--progress", "none", "--frames", "2", "--size", "16", "--method", "lut",
           "--table-size", "64", "512", "64")


def test_cli_animate_checks_the_mp4_frames_and_metrics_first(tmp_path):
    """The MP4, <stem>_frames/ and <stem>_metrics.csv/.json are all checked before the (slow) table:
    no MP4 without its metrics."""
    (tmp_path / "a_frames").write_bytes(b"")            # a file where the frame folder goes
    (tmp_path / "b_metrics.json").mkdir()
    (tmp_path / "c.mp4").mkdir()
    metrics_too_long = "m" * (NAME_MAX - 12) + ".mp4"    # fits, but <stem>_metrics.json does not
    cases = [
        (["-o", "a.mp4"], ["--output", "a_frames exists and is not a directory"]),
        (["-o", "b.mp4", "--force"], ["--output", "b_metrics.json is a directory"]),
        (["-o", "c.mp4", "--force"], ["--output", "c.mp4 is a directory"]),
        (["-o", "missing/d.mp4"], ["--output", "directory missing does not exist"]),
        (["-o", metrics_too_long], ["--output", "bytes long"]),
    ]
    if SYS_READ_ONLY:
        cases.append((["-o", "/sys/e.mp4"], ["--output", "/sys"]))
    for args, named in cases:
        assert_usage_error(clsky(*ANIMATE, *args, cwd=tmp_path), *named)
    assert listing(tmp_path) == ["a_frames", "b_metrics.json", "c.mp4"]


@pytest.mark.parametrize("command,output", [("animate", ".mp4"), ("render", ".png"), ("table", ".npz"),
                                            ("render", "dir/.png"), ("render", "x.png/"), ("table", "t.npz/"),
                                            ("render", "x.png/.")])
def test_cli_refuses_an_output_named_by_its_suffix_alone(tmp_path, command, output):
    """'-o .png' names a hidden file without a suffix (pathlib's reading; animate took '.mp4' and wrote
    '.mp4_frames/'), and 'x.png/' a directory (pathlib drops the '/': the file x.png was written): refused,
    naming the NAME it lacks, before any work."""
    (tmp_path / "dir").mkdir()
    args = {"animate": ANIMATE, "render": ("render", "--size", "16"), "table": ("table", *SLOW_TABLE)}[command]
    extension = output[output.index("."):].rstrip("/.")          # '.png' of 'x.png/.' too
    result = clsky(*args, "-o", output, cwd=tmp_path)
    assert_usage_error(result, "--output must", f"in {extension} after a file name (NAME{extension}), "
                                               f"got {output!r}")
    assert listing(tmp_path) == ["dir"] and listing(tmp_path / "dir") == []


@pytest.mark.parametrize("command,output", [("render", "caf\udce9.png"), ("table", "caf\udce9.npz"),
                                            ("render", "d\udcff/x.png")])
def test_cli_refuses_an_output_name_that_is_not_utf8(tmp_path, command, output):
    """A name of bytes that are not UTF-8 (``-o $'caf\\xe9.png'``; Python reads such a byte as a lone
    surrogate) failed after the work, where clsky wrote it into the frame's metadata ('surrogates not
    allowed'): refused before any, naming the option and the bytes."""
    args = {"render": ("render", "--size", "16"), "table": ("table", *SLOW_TABLE)}[command]
    result = clsky(*args, "-o", output, cwd=tmp_path)
    shown = os.fsencode(output).decode("utf-8", "backslashreplace")
    assert_usage_error(result, f"--output: {shown} is not UTF-8 text: clsky prints its outputs' names")
    assert listing(tmp_path) == []
    with pytest.raises(ValueError, match="is not UTF-8 text"):
        check_output(tmp_path / output)


def test_cli_animate_refuses_old_frames_without_force(tmp_path):
    (tmp_path / "sky_frames").mkdir()
    (tmp_path / "sky_frames" / "frame_00007.png").write_bytes(b"old")
    result = clsky(*ANIMATE, cwd=tmp_path)
    assert_usage_error(result, "--output", "frame_00007.png exists", "--force")


def test_cli_render_and_bench_check_their_outputs(tmp_path):
    (tmp_path / "folder.png").mkdir()
    result = clsky("render", "--size", "16", "--method", "lut", "--table-size", "64", "512", "64",
                   "-o", "folder.png", "--force", cwd=tmp_path)
    assert_usage_error(result, "--output", "folder.png is a directory")
    result = clsky("bench", "accuracy", "--size", "16", "--progress", "none", "--plot", "missing/p.png",
                   cwd=tmp_path)
    assert_usage_error(result, "--plot", "missing")
    result = clsky("bench", "accuracy", "--size", "16", "--progress", "none", "-o", "folder.png.csv", "--plot",
                   "folder.png", "--force", cwd=tmp_path)
    assert_usage_error(result, "--plot", "folder.png is a directory")
    for option, name, suffix in (("--plot", ".png", ".png"), ("--output", ".csv", ".csv"),
                                 ("--elevation-plot", "e.csv", ".png")):
        result = clsky("bench", "accuracy", "--size", "16", "--progress", "none", option, name, cwd=tmp_path)
        assert_usage_error(result, f"{option} must end in {suffix} after a file name (NAME{suffix}), got '{name}'")
    assert listing(tmp_path) == ["folder.png"]


def test_atomic_write_error_names_the_target_not_a_temporary(tmp_path):
    with pytest.raises(FileNotFoundError) as error:
        with atomic_write(tmp_path / "gone" / "t.npz"):
            pass
    assert "gone" in str(error.value) and ".t.npz." not in str(error.value)


# 3. After the checks: what a failure midway leaves ------------------------------------------------

def test_a_write_error_names_the_target(tmp_path):
    def full_disk(temporary):
        raise OSError(28, "No space left on device", str(temporary))

    with pytest.raises(OSError, match=r"^cannot write .*t\.npz: no space left on device$"):
        with atomic_write(tmp_path / "t.npz") as temporary:
            full_disk(temporary)
    assert listing(tmp_path) == []


def test_a_full_disk_on_an_open_file_names_the_target(tmp_path):
    """A real full disk fails a write() to the open temporary: its OSError names no file (clsky render on a
    full tmpfs said only '[Errno 28] No space left on device')."""
    with pytest.raises(OSError, match=r"^cannot write .*sky\.png: no space left on device$"):
        with atomic_write(tmp_path / "sky.png") as temporary, open(temporary, "wb"):
            raise OSError(28, "No space left on device")
    assert listing(tmp_path) == []


def test_a_rename_failing_midway_is_reported_and_leaves_no_temporary(tmp_path, monkeypatch):
    """Documented in StagedWrites: the files renamed so far are new, the others keep their old
    contents, no temporary is left, and the error says which is which."""
    from clsky import _files

    place = _files._place

    def fail_on_b(temporary, target, overwrite):
        if target.name == "b.txt":
            raise PermissionError(13, "Permission denied", str(target))
        place(temporary, target, overwrite)

    monkeypatch.setattr(_files, "_place", fail_on_b)
    (tmp_path / "b.txt").write_text("old b")
    with pytest.raises(PermissionError, match=r"could not put .*b\.txt in place.*already in place: .*a\.txt"):
        with StagedWrites() as staging:
            for name in ("a.txt", "b.txt", "c.txt"):
                staging.stage(tmp_path / name, overwrite=True).write_text("new " + name)
    assert {name: (tmp_path / name).read_text() for name in listing(tmp_path)} == \
        {"a.txt": "new a.txt", "b.txt": "old b"}


# Failures during the writing: named by the output, every temporary cleaned up that can be -------------------

def test_a_short_write_names_the_output(tmp_path):
    """NumPy's short writes on a full disk (np.save, tofile) raise an OSError with neither errno nor file,
    '3072 requested and 992 written', which reached the user as it was: now the output is named."""
    with pytest.raises(OSError, match=r"^cannot write .*a\.npy: a short write \(3072 requested and 992 written\): "
                                      r"is the disk full\?$"):
        with atomic_write(tmp_path / "a.npy"):
            raise OSError("3072 requested and 992 written")
    assert list(tmp_path.iterdir()) == []


def test_temporaries_are_deleted_as_far_as_possible_and_the_error_kept(tmp_path, monkeypatch):
    """A folder made read-only during a run: the first temporary that could not be deleted stopped the
    clean-up (the others, in folders still writable, stayed) and its PermissionError replaced the run's own
    error. Each temporary is now deleted if it can be, and the run's error is the one raised."""
    (tmp_path / "locked").mkdir()
    unlink = pathlib.Path.unlink

    def refuse_in_locked(path, missing_ok=False):
        if path.parent.name == "locked":
            raise PermissionError(13, "Permission denied", str(path))
        return unlink(path, missing_ok=missing_ok)

    monkeypatch.setattr(pathlib.Path, "unlink", refuse_in_locked)
    with pytest.raises(RuntimeError, match="^the run's own error$"):
        with StagedWrites() as staging:
            for target in (tmp_path / "locked" / "a.png", tmp_path / "b.png", tmp_path / "c.png"):
                staging.stage(target)
            raise RuntimeError("the run's own error")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["locked"]
    assert len(list((tmp_path / "locked").iterdir())) == 1          # the one that could not go


def test_an_exr_the_bindings_cannot_write_is_named_by_its_output(tmp_path, monkeypatch):
    """OpenEXR's bindings raise RuntimeError on a full disk: `--hdr exr` ended in a traceback naming the
    hidden temporary. It is now an OSError of the file, named by its output."""
    pytest.importorskip("OpenEXR")
    from clsky.anim import exr

    OpenEXR = exr.require_openexr()

    class FullDisk:
        def __init__(self, *args):
            pass

        def write(self, name):
            raise RuntimeError(f'Failed to write pixel data to image file "{name}". No space left on device.')

    monkeypatch.setattr(OpenEXR, "File", FullDisk)
    with pytest.raises(OSError, match=r"^cannot write .*frame\.exr: no space left on device$"):
        exr.write_exr(tmp_path / "frame.exr", np.ones((2, 2, 3)))
    assert list(tmp_path.iterdir()) == []

    class Failing(FullDisk):             # another failure of the file: its words, the temporary not named
        def write(self, name):
            raise RuntimeError(f'Failed to write pixel data to image file "{name}". Something Else.')

    monkeypatch.setattr(OpenEXR, "File", Failing)
    (tmp_path / "MyFrames").mkdir()
    with pytest.raises(OSError, match=r"^cannot write .*MyFrames/Frame\.exr: failed to write pixel data to image file "
                                      r"the file\. Something Else\.$"):
        exr.write_exr(tmp_path / "MyFrames" / "Frame.exr", np.ones((2, 2, 3)))
