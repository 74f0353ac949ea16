"""Scene files (issue 13, item 2): ``--scene FILE``, ``--print-scene``, the metadata every output carries,
and ``clsky info``.

Frames are rendered at 16 pixels from an 8 x 32 x 8 table (``--table-size``: no scene plan, a build of a
few seconds), so the comparisons are exact (bytes) and cheap; the README's dusk scene at full size is
slow (its table is the default level's, minutes on two cores).
"""

from __future__ import annotations

import datetime
import json
import os
import pathlib
import re
import sys

import numpy as np
import pytest

import clsky
from clsky.anim import cli

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

Image = pytest.importorskip("PIL.Image")

ROOT = pathlib.Path(__file__).resolve().parent.parent

#: A small animation: 2 frames of 16 px from a small full table, lookup only.
SMALL = ["--size", "16", "--frames", "2", "--table-size", "8", "32", "8", "--method", "lut", "--quality", "draft",
         "--progress", "none"]


@pytest.fixture(autouse=True)
def _allocator_left_alone(monkeypatch):
    """``clsky animate`` tunes its process's C allocator for good (clsky.allocator); run here, in pytest's
    process, it leaves that one as it is (tests/test_allocator.py runs the tuning in subprocesses)."""
    monkeypatch.setattr("clsky.allocator.reuse_freed_memory", lambda environ=None: {})


def run(capsys, *args):
    """``clsky ARGS`` in this process: (exit status, stdout, stderr)."""
    status = cli.main([str(arg) for arg in args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def one_line_error(status, err):
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clsky: error: "), err
    return lines[0]


EVERY_OPTION = ["--camera", "perspective", "--size", "20", "--fov", "60", "--heading", "200", "--pitch", "5",
                "--altitude", "100", "--method", "raymarch", "--preset", "physical", "--mode", "physical",
                "--ground-albedo", "0.3", "--ozone-column", "250", "--error-budget", "0.05", "--quality", "draft",
                "--table-size", "8", "32", "8", "--samples", "20", "--sampling", "ground_end", "--wavelengths", "12",
                "--location", "48.1", "11.6", "--date", "2026-06-21", "--hours", "2.5", "4.5",
                "--step-minutes", "30", "--frames", "7", "--start-elevation", "-4", "--max-elevation", "50",
                "--tone-map", "atmosphere-plus", "--exposure", "1.5", "--auto-exposure", "--white-balance", "sun",
                "--no-dither", "--fps", "12", "-o", "x.mp4", "--hdr", "exr", "--hdr-precision", "half"]


#: Options of a run that are no part of its scene (where it runs, --workers / --scheduler, included: the
#: same frames either way).
RUN_OPTIONS = {"help", "force", "progress", "scene", "print_scene", "workers", "scheduler"}


@pytest.mark.parametrize("command", ["animate", "render"])
def test_every_option_and_config_field_has_a_scene_key(command):
    """SCENE_KEYS is the one table from options to AnimationConfig fields (the command line's config is
    built through it): an option or field added without its key would be dropped silently, so this
    fails instead."""
    import dataclasses

    from clsky.anim import scene
    from clsky.anim.animate import AnimationConfig

    parser = scene.command_parser(command)
    options = {action.dest for action in parser._actions if action.option_strings} - RUN_OPTIONS
    assert options == {key.dest for key, _ in scene.command_keys(parser).values()}
    fields = {field.name for field in dataclasses.fields(AnimationConfig)} - {"force"}
    assert fields <= {key.key for key in scene.SCENE_KEYS}


def test_print_scene_round_trip(tmp_path, capsys, monkeypatch):
    """Every option of a command line lands in its scene with its value, and the scene of that scene is
    the same text: ``--scene`` of ``--print-scene``'s output is the same run. Nothing is written."""
    monkeypatch.chdir(tmp_path)
    status, text, err = run(capsys, "animate", *EVERY_OPTION, "--print-scene")
    assert status == 0 and err == ""
    scene = tomllib.loads(text)
    assert scene["camera"] == {"camera": "perspective", "size": 20, "fov_deg": 60.0, "heading_deg": 200.0,
                               "pitch_deg": 5.0, "altitude": 100.0, "method": "raymarch"}
    assert scene["sky"] == {"preset": "physical", "mode": "physical", "ground_albedo": 0.3, "ozone_column_du": 250.0,
                            "error_budget": 0.05, "quality": "draft", "table_size": [8, 32, 8], "samples": 20,
                            "sampling": "ground_end", "wavelengths": 12}
    assert scene["sun"] == {"frames": 7, "start_elevation_deg": -4.0, "max_elevation_deg": 50.0,
                            "location": [48.1, 11.6], "date": datetime.date(2026, 6, 21), "start_hour": 2.5,
                            "end_hour": 4.5, "step_minutes": 30.0}
    assert scene["display"] == {"tone_map": "atmosphere-plus", "exposure": 1.5, "auto_exposure": True,
                                "white_balance": "sun", "dither": False}
    assert scene["output"] == {"output": "x.mp4", "fps": 12.0, "hdr": "exr", "hdr_precision": "half"}
    (tmp_path / "x.toml").write_text(text)
    status, again, err = run(capsys, "animate", "--scene", "x.toml", "--print-scene")
    assert status == 0 and err == "" and again == text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.toml"]


def test_render_scene_round_trip(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, text, _ = run(capsys, "render", "--sun-elevation", "-2.5", "--sun-azimuth", "250", "--size", "24",
                          "-o", "one.png", "--print-scene")
    assert status == 0
    scene = tomllib.loads(text)
    assert scene["sun"] == {"sun_elevation_deg": -2.5, "sun_azimuth_deg": 250.0}
    assert scene["output"] == {"output": "one.png"} and scene["camera"]["size"] == 24
    (tmp_path / "one.toml").write_text(text)
    assert run(capsys, "render", "--scene", "one.toml", "--print-scene")[1] == text


def test_print_scene_round_trips_a_name_with_del(tmp_path, capsys, monkeypatch):
    """TOML forbids a raw DEL (U+007F) in a string, which JSON's escaping (the scene's strings) leaves: the
    scene of ``-o $'a\\x7fb.mp4'`` could not be read back. Now escaped, as the other control characters."""
    monkeypatch.chdir(tmp_path)
    status, text, _ = run(capsys, "animate", "-o", "a\x7fb.mp4", "--print-scene")
    assert status == 0 and 'output = "a\\u007fb.mp4"' in text
    assert tomllib.loads(text)["output"]["output"] == "a\x7fb.mp4"
    (tmp_path / "d.toml").write_text(text)
    assert run(capsys, "animate", "--scene", "d.toml", "--print-scene")[1] == text


@pytest.mark.parametrize("output,expected", [
    ("a\0b.mp4", "output must be a path ending in .mp4 after a file name (NAME.mp4) without a NUL character"),
    ("caf\udce9.mp4", "output must be a path ending in .mp4 after a file name (NAME.mp4) in UTF-8 text"),
    # a name that holds the words of a reason gets its own (the reason was found in the message, which quotes it)
    ("NUL UTF-8.mov", "output must be a path ending in .mp4 after a file name (NAME.mp4), got 'NUL UTF-8.mov'"),
])
def test_an_animation_output_that_no_file_or_scene_can_hold_is_refused(tmp_path, capsys, monkeypatch, output,
                                                                       expected):
    """A NUL from a scene file (``output = "a\\u0000b.mp4"``) was taken by AnimationConfig and failed later
    as 'embedded null byte', naming nothing; a name of bytes that are not UTF-8 (``-o $'caf\\xe9.mp4'``,
    read by Python as a lone surrogate) failed after the work, where its scene went into the frames'
    metadata. Both are refused by the config, and on the command line before any work, naming the
    option or the scene's key."""
    from clsky.anim.animate import AnimationConfig

    with pytest.raises(ValueError, match=re.escape(expected)):
        AnimationConfig(output=output)
    monkeypatch.chdir(tmp_path)
    if not output.endswith(".mp4"):  # a wrong suffix: the command line's refusal has tests of its own
        return
    if "\0" in output:           # a TOML string can hold a NUL, not a lone surrogate
        (tmp_path / "o.toml").write_text('[output]\noutput = "a\\u0000b.mp4"\n')
        status, _, err = run(capsys, "animate", "--scene", "o.toml")
        assert (status, err) == (2, f"clsky: error: o.toml: output.{expected}, got 'a\\x00b.mp4'\n")
    else:
        status, _, err = run(capsys, "animate", "-o", output, "--print-scene")
        assert status == 2 and err.startswith(f"clsky: error: --{expected}"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == (["o.toml"] if "\0" in output else [])


def test_an_override_shows_the_value_as_typed(tmp_path, capsys, monkeypatch):
    """The override's line formatted a float with %g: '--exposure 1.0000001' was shown as '1', as if the
    option had been typed equal to the scene's value (the rule of clsky.errors.short)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text('[display]\nexposure = 1.0\n')
    status, _, err = run(capsys, "animate", "--scene", "s.toml", "--exposure", "1.0000001", "--print-scene")
    assert status == 0
    assert err == "clsky: --exposure 1.0000001 overrides s.toml's display.exposure = 1.0\n"


def test_the_command_line_wins_and_says_so(tmp_path, capsys, monkeypatch):
    """An option typed wins over the scene, even typed with its default value (--pitch 10), and one
    line on stderr per option names it, its value and the scene's value it replaces."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text('[camera]\nsize = 16\npitch_deg = 5.0\n[display]\nexposure = 1.0\ndither = true\n'
                                     'auto_exposure = true\n')
    status, text, err = run(capsys, "animate", "--scene", "s.toml", "--size", "24", "--no-dither", "--pitch", "10",
                            "--no-auto-exposure", "--print-scene")
    assert status == 0
    assert err.splitlines() == ["clsky: --size 24 overrides s.toml's camera.size = 16",
                                "clsky: --pitch 10 overrides s.toml's camera.pitch_deg = 5.0",
                                "clsky: --no-dither overrides s.toml's display.dither = true (now false)",
                                "clsky: --no-auto-exposure overrides s.toml's display.auto_exposure = true (now false)"]
    scene = tomllib.loads(text)
    assert (scene["camera"]["size"], scene["camera"]["pitch_deg"]) == (24, 10.0)
    assert (scene["display"]["exposure"], scene["display"]["dither"], scene["display"]["auto_exposure"]) == \
        (1.0, False, False)


@pytest.mark.parametrize("command,text,message", [
    ("animate", "[camera]\nsize = 5\n", "s.toml: camera.size must be an integer in [16, 8192], got 5"),
    ("animate", '[camera]\nsize = "big"\n', "s.toml: camera.size must be an integer, got \"big\""),
    ("animate", "[camera]\nsize = 16.5\n", "s.toml: camera.size must be an integer, got 16.5"),
    ("animate", "[camera]\nzoom = 2\n", "s.toml: unknown key camera.zoom; valid keys of [camera] for clsky animate: "
                                        "camera, size, fov_deg, heading_deg, pitch_deg, altitude, method"),
    ("animate", "[lens]\nzoom = 2\n", "s.toml: unknown section [lens]"),
    ("animate", "size = 16\n", "s.toml: size = 16 is outside a section (keys go under [camera], [sky], [sun], [display], [output])"),
    ("animate", "[sky]\nground_albedo = 1.5\n", "s.toml: sky.ground_albedo must be a number in [0, 1], got 1.5"),
    ("animate", '[sky]\npreset = "venus"\n', "s.toml: sky.preset must be one of"),
    ("animate", "[sky]\ntable_size = [8, 1, 8]\n", "s.toml: sky.table_size[1] must be"),
    ("animate", "[sky]\ntable_size = [8, 32]\n", "s.toml: sky.table_size must be a list of 3 integers"),
    ("animate", '[sun]\ndate = "tomorrow"\n', "s.toml: sun.date must be a TOML date (YYYY-MM-DD, unquoted)"),
    ("animate", "[sun]\nlocation = [48.0, 11.0]\nstart_hour = 5.0\nend_hour = 4.0\n",
     "s.toml: sun.end_hour must be after the start hour (5)"),
    ("animate", "[sun]\nsun_elevation_deg = 3.0\n", "s.toml: unknown key sun.sun_elevation_deg (a key of clsky render only)"),
    ("animate", "[display]\ndither = 1\n", "s.toml: display.dither must be true or false, got 1"),
    ("animate", '[output]\noutput = "sky.avi"\n', "s.toml: output.output must be a path ending in .mp4"),
    # its formats first ('None, False, True or one of ...' named values a scene cannot hold or refuses)
    ("animate", '[output]\nhdr = "foo"\n', "s.toml: output.hdr must be one of ['exr', 'hdr', 'npy'] (in the API"),
    ("animate", "[camera\n", "--scene s.toml: not a valid TOML file"),
    # TOML integers have any size: one beyond float's range, for a number, was an OverflowError traceback
    ("render", f"[display]\nexposure = {'9' * 400}\n",
     "s.toml: display.exposure must be a number (of at most about 1.8e308 in size), got 1e+400"),
    ("animate", f"[sun]\nstart_hour = -{'9' * 400}\n",
     "s.toml: sun.start_hour must be a number (of at most about 1.8e308 in size), got -1e+400"),
    ("animate", f"[sun]\nlocation = [{'9' * 400}, 0]\n",
     "s.toml: sun.location must be a list of 2 numbers (of at most about 1.8e308 in size), got [1e+400, 0]"),
    ("animate", f"[camera]\nsize = {'9' * 400}\n", "s.toml: camera.size must be an integer in [16, 8192], got 1e+400"),
    # a table where a value goes was shown by its Python repr in quotes ("{'x': 48}"), and [[camera]] was
    # told to put its keys under [camera] (probe of input files)
    ("animate", "[camera]\nsize.x = 48\n", "s.toml: camera.size must be an integer, got {x = 48}"),
    ("animate", "[[camera]]\nsize = 48\n", "s.toml: [[camera]] makes an array of tables; a scene's keys go under "
                                          "one [camera] section"),
    ("animate", f"[display]\nexposure = {'9' * 5000}\n",
     "--scene s.toml: not a valid TOML file: a number of more than 4300 digits"),
    ("render", "[sun]\nsun_elevation_deg = 100.0\n", "s.toml: sun.sun_elevation_deg must be in [-90, 90] degrees, got 100"),
    ("render", "[sun]\nframes = 3\n", "s.toml: unknown key sun.frames (a key of clsky animate only)"),
    ("render", '[output]\noutput = "sky.jpg"\n', "s.toml: output.output must end in .png"),
])
def test_scene_errors_name_the_file_the_key_and_the_range(tmp_path, capsys, monkeypatch, command, text, message):
    """Checked before any work: exit 2, one line, nothing written."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(text)
    extra = ["--progress", "none"] if command == "animate" else []
    line = one_line_error(*run(capsys, command, "--scene", "s.toml", *extra)[::2])
    assert message in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_a_missing_scene_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    status, _, err = run(capsys, "animate", "--scene", "nowhere.toml")
    assert "--scene: cannot read nowhere.toml: No such file or directory" in one_line_error(status, err)
    assert list(tmp_path.iterdir()) == []
    status, _, err = run(capsys, "animate", "--scene", tmp_path)
    assert f"--scene: cannot read {tmp_path}: Is a directory" in one_line_error(status, err)
    status, _, err = run(capsys, "animate", "--scene", "")        # pathlib's '.': "cannot read ."
    assert one_line_error(status, err) == "clsky: error: --scene must be a file path, got an empty one"
    (tmp_path / "binary.toml").write_bytes(b"\xff\xfe[camera]")
    status, _, err = run(capsys, "render", "--scene", "binary.toml")
    assert "--scene binary.toml: not a TOML file (not UTF-8 text)" in one_line_error(status, err)


@pytest.fixture(scope="module")
def small_runs(tmp_path_factory):
    """The same small animation from a command line (directory a) and from its scene (directory b)."""
    import contextlib
    import io
    import os

    a, b = tmp_path_factory.mktemp("line"), tmp_path_factory.mktemp("scene")
    here = os.getcwd()
    try:
        os.chdir(a)
        assert cli.main(["animate", *SMALL, "-o", "sky.mp4"]) == 0
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            assert cli.main(["animate", *SMALL, "-o", "sky.mp4", "--print-scene"]) == 0
        (b / "scene.toml").write_text(printed.getvalue())
        os.chdir(b)
        assert cli.main(["animate", "--scene", "scene.toml"]) == 0
    finally:
        os.chdir(here)
    return a, b


def test_a_scene_reproduces_its_command_line_bit_for_bit(small_runs):
    """The frames of the command line and of its scene are the same files, byte for byte (pixels and
    text chunks), and the metrics agree row for row."""
    a, b = small_runs
    frames = sorted((a / "sky_frames").glob("frame_*.png"))
    assert len(frames) == 2
    for frame in frames:
        assert frame.read_bytes() == (b / "sky_frames" / frame.name).read_bytes()
    assert (a / "sky_metrics.csv").read_text() == (b / "sky_metrics.csv").read_text()


def test_every_output_carries_the_scene_and_the_version(small_runs):
    """The metrics JSON and each PNG frame hold clsky's version and the scene of the run, which reads
    back as the scene file that made it."""
    _, b = small_runs
    scene = tomllib.loads((b / "scene.toml").read_text())
    metrics = json.loads((b / "sky_metrics.json").read_text())
    assert metrics["clsky_version"] == clsky.__version__
    assert tomllib.loads(metrics["scene"]) == scene
    for frame in sorted((b / "sky_frames").glob("frame_*.png")):
        with Image.open(frame) as image:
            assert image.text["clsky_version"] == clsky.__version__
            assert image.text["scene"] == metrics["scene"]
    assert scene["camera"]["size"] == 16 and scene["sky"]["table_size"] == [8, 32, 8]


def test_render_writes_its_scene_into_the_png(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["render", "--size", "16", "--table-size", "8", "32", "8", "--method", "lut", "--quality", "draft",
            "--sun-elevation", "4", "-o", "one.png"]
    assert run(capsys, *args)[0] == 0
    with Image.open(tmp_path / "one.png") as image:
        pixels, text = np.asarray(image), dict(image.text)
    assert text["clsky_version"] == clsky.__version__
    (tmp_path / "one.toml").write_text(text["scene"])
    assert run(capsys, "render", "--scene", "one.toml", "-o", "two.png")[0] == 0
    with Image.open(tmp_path / "two.png") as image:
        np.testing.assert_array_equal(np.asarray(image), pixels)   # the same frame, exactly
        assert tomllib.loads(image.text["scene"])["output"]["output"] == "two.png"


def test_info_describes_outputs(small_runs, capsys):
    _, b = small_runs
    status, out, _ = run(capsys, "info", b / "sky_frames" / "frame_00001.png")
    assert status == 0
    assert "PNG image" in out and "16 x 16 pixels" in out and f"clsky version  {clsky.__version__}" in out
    assert "size = 16" in out and 'output = "sky.mp4"' in out
    status, out, _ = run(capsys, "info", b / "sky_metrics.json")
    assert status == 0 and "animation metrics" in out and "frames         2" in out
    assert "8 x 32 x 8" in out and "table_size = [8, 32, 8]" in out


@pytest.fixture(scope="module")
def small_table(tmp_path_factory):
    path = tmp_path_factory.mktemp("table") / "t.npz"
    settings = clsky.TableSettings(size=(8, 32, 8), orders=2)
    clsky.ScatteringTable.build(clsky.preset("atmosphere-plus"), settings).save(path)
    return path


def test_info_describes_a_table(small_table, capsys):
    status, out, _ = run(capsys, "info", small_table)
    assert status == 0
    assert out.startswith(f"{small_table}:\n")
    for expected in ("checksums valid", "8 x 32 x 8 (altitude x view zenith x sun zenith), 6 channels, float64",
                     "units ", "orders ", "mode                          atmosphere-plus",
                     f"clsky version                 {clsky.__version__}", "settings.orders               2"):
        assert expected in out, (expected, out)


@pytest.mark.parametrize("damage", ["flip", "truncate"])
def test_info_of_a_damaged_table_is_one_line(small_table, tmp_path, capsys, damage):
    data = bytearray(small_table.read_bytes())
    if damage == "flip":
        data[len(data) // 2] ^= 0xFF
    else:
        data = data[: len(data) // 2]
    broken = tmp_path / "broken.npz"
    broken.write_bytes(bytes(data))
    assert f"clsky: error: {broken}" in one_line_error(*run(capsys, "info", broken)[::2])


def test_exr_frames_carry_the_scene_and_info_reads_them(tmp_path, capsys, monkeypatch):
    """--hdr exr: each EXR frame's header holds the scene and clsky's version beside its units;
    clsky info prints them; a damaged EXR is one line."""
    pytest.importorskip("OpenEXR")
    monkeypatch.chdir(tmp_path)
    assert run(capsys, "animate", *SMALL, "--hdr", "exr", "-o", "sky.mp4")[0] == 0
    exr = tmp_path / "sky_frames" / "frame_00001.exr"
    status, out, _ = run(capsys, "info", exr)
    assert status == 0, out
    assert "OpenEXR image" in out and "16 x 16 pixels, channels B, G, R" in out
    assert re.search(rf"\n  clsky version +{re.escape(clsky.__version__)}\n", out), out
    assert "size = 16" in out and 'hdr = "exr"' in out and "radianceUnits" in out
    # the bindings' enums by name, as exrheader prints them (their repr 'Compression.ZIP_COMPRESSION' before)
    assert re.search(r"\n  compression +ZIP_COMPRESSION\n", out) and re.search(r"\n  lineOrder +INCREASING_Y\n", out)
    with Image.open(tmp_path / "sky_frames" / "frame_00001.png") as image:
        assert image.text["scene"].splitlines()[-1] in out
    broken = tmp_path / "broken.exr"
    broken.write_bytes(exr.read_bytes()[:100])
    assert f"clsky: error: {broken}: not a readable EXR file" in one_line_error(*run(capsys, "info", broken)[::2])


def test_info_reads_an_exr_header_alone_and_refuses_damaged_attribute_types(tmp_path, capfd):
    """clsky info reads an EXR's header only: damaged pixels print nothing of the OpenEXR library's (it
    decoded every pixel, and printed three lines to stderr and a warning to stdout); a scene or
    clskyVersion attribute whose type name is damaged (the bindings return an opaque attribute) is a
    damaged file, one TableFormatError naming it (a traceback, or a message without the file, before);
    another tool's attribute of a type the bindings do not read is shown as such."""
    pytest.importorskip("OpenEXR")
    from clsky.anim.exr import write_exr
    from clsky.info import describe
    from clsky.table import TableFormatError

    good = write_exr(tmp_path / "good.exr", np.ones((4, 6, 3)),
                     attributes={"clskyVersion": clsky.__version__, "scene": "[camera]\nsize = 4\n", "note": "x"})
    data = good.read_bytes()

    def damaged(name, position, value):
        copy = bytearray(data)
        copy[position] = value
        (tmp_path / name).write_bytes(bytes(copy))
        return tmp_path / name

    pixels = damaged("pixels.exr", len(data) - 20, data[-20] ^ 0xFF)
    text = describe(pixels)
    assert "6 x 4 pixels, channels B, G, R" in text and "size = 4" in text
    assert capfd.readouterr() == ("", "")
    for attribute in ("scene", "clskyVersion"):
        at = data.find(attribute.encode() + b"\0string\0") + len(attribute) + 1
        with pytest.raises(TableFormatError, match=rf"^{re.escape(str(tmp_path))}/{attribute}.exr: not a readable "
                                                   rf"EXR file \(its {attribute} attribute is a '\\x97tring', not a "
                                                   rf"string: damaged\)$"):
            describe(damaged(f"{attribute}.exr", at, 0x97))
    # a standard attribute of another type: the bindings' header read stopped there and filled in defaults
    # ('64 x 64 pixels', 'not written by clsky', exit 0)
    at = data.find(b"dataWindow\0box2i\0") + len("dataWindow\0box2")
    with pytest.raises(TableFormatError, match=r"\(its dataWindow attribute is a 'box2f', not a box2i: damaged\)$"):
        describe(damaged("window.exr", at, ord("f")))
    other = data.find(b"note\0string\0") + len("note") + 1             # "xtring": a type the bindings lack
    assert "\n  note                - (an attribute of a type the OpenEXR bindings do not read)\n" in \
        describe(damaged("other.exr", other, ord("x")))


def test_info_reads_a_radiance_hdr_frames_header(tmp_path, capsys):
    """--hdr hdr frames: clsky info prints the size and header lines (it read none before); a file
    without the signature or the resolution line is one line."""
    from clsky.anim.rgbe import write_rgbe

    frame = tmp_path / "frame.hdr"
    write_rgbe(frame, np.full((12, 20, 3), 0.5), {"clskyVersion": clsky.__version__, "sunElevationDeg": -4.0,
                                                  "radianceUnits": "linear sRGB [cd/m^2]"})
    status, out, _ = run(capsys, "info", frame)
    assert status == 0, out
    assert "Radiance RGBE image" in out and "20 x 12 pixels" in out and "32-bit_rle_rgbe" in out
    assert re.search(rf"\n  clsky version +{re.escape(clsky.__version__)}\n", out), out
    assert re.search(r"\n  sunElevationDeg +-4\.0\n", out) and "linear sRGB [cd/m^2]" in out, out
    for name, content, message in (("text.hdr", b"hello", "no '#?' signature"),
                                    ("cut.hdr", frame.read_bytes()[:40], "no '-Y H +X W' resolution line"),
                                    ("empty.hdr", b"", "no '#?' signature")):
        (tmp_path / name).write_bytes(content)
        line = one_line_error(*run(capsys, "info", tmp_path / name)[::2])
        assert line.startswith(f"clsky: error: {tmp_path / name}: not a readable Radiance HDR file") and message in line


def test_info_refuses_other_files(tmp_path, capsys):
    assert "clsky info reads .npz, .png, .json, .exr, .hdr files" in one_line_error(*run(capsys, "info", tmp_path / "x.toml")[::2])
    assert "no such file" in one_line_error(*run(capsys, "info", tmp_path / "x.npz")[::2])
    for name in ("frames", "sky.npz"):                  # a directory, named like a table or not: not "no such file"
        (tmp_path / name).mkdir()
        assert one_line_error(*run(capsys, "info", tmp_path / name)[::2]) == (
            f"clsky: error: {tmp_path / name}: a directory, not a file: clsky info reads .npz, .png, .json, .exr, "
            ".hdr files")
    long = tmp_path / ("e" * 300 + ".npz")               # an OSError of the system's: [Errno 36], exit 1
    assert one_line_error(*run(capsys, "info", long)[::2]) == \
        f"clsky: error: {long}: cannot be read (File name too long)"
    os.mkfifo(tmp_path / "pipe.npz")                    # read, it would wait for a writer for ever
    assert one_line_error(*run(capsys, "info", tmp_path / "pipe.npz")[::2]).endswith("pipe.npz: not a regular file")
    (tmp_path / "x.png").write_bytes(b"not a png")
    assert "not a readable PNG (no PNG signature)" in one_line_error(*run(capsys, "info", tmp_path / "x.png")[::2])
    (tmp_path / "x.json").write_text("{}")
    assert "not an animation's metrics JSON" in one_line_error(*run(capsys, "info", tmp_path / "x.json")[::2])


@pytest.mark.parametrize("document, message", [
    ('{"frames": 3}', "'frames' must be a list, got int"),
    ('{"frames": [], "table": "x"}', "'table' must be an object, got str"),
    ('{"frames": [], "table": {"settings": 5}}', "'settings' must be an object, got int"),
    # accepted before, as they were (clsky writes none of them)
    ('{"frames": [1, 1]}', "its frames must be objects"),
    ('{"frames": [], "clsky_version": ["x"]}', "'clsky_version' must be a string, got list"),
    ('{"frames": [], "table": {"frame_units": {"a": 1}}}', "'frame_units' must be a string, got dict"),
    ('{"frames": [], "table": {"settings": {"size": [[1, 2], 3]}}}', "the table's size must be integers"),
])
def test_info_of_a_malformed_metrics_json_is_one_line(tmp_path, capsys, document, message):
    path = tmp_path / "sky_metrics.json"
    path.write_text(document)
    line = one_line_error(*run(capsys, "info", path)[::2])
    assert line == f"clsky: error: {path}: not an animation's metrics JSON ({message})"


def test_info_refuses_nan_and_shows_line_breaks_and_escapes_as_text(tmp_path, capsys):
    """clsky writes strict JSON: a NaN in a metrics file is refused (it was read). A value's line break or
    a terminal's escape sequence is shown escaped, on its own line (a newline forged lines of the
    description, an escape sequence cleared the terminal)."""
    path = tmp_path / "sky_metrics.json"
    path.write_text('{"frames": [NaN]}')
    assert "NaN is no JSON number" in one_line_error(*run(capsys, "info", path)[::2])
    path.write_text(json.dumps({"frames": [], "clsky_version": "1.0\n  size  9999 x 9999 \x1b[2J"}))
    status, out, _ = run(capsys, "info", path)
    assert status == 0 and "\x1b" not in out and len(out.strip().splitlines()) == 6
    assert "clsky version  1.0\\n  size  9999 x 9999 \\x1b[2J" in out


def _png_with(chunks):
    """A PNG file's bytes of ``chunks`` [(type, data)], each with its length and CRC, after the signature."""
    import struct
    import zlib

    return b"\x89PNG\r\n\x1a\n" + b"".join(struct.pack(">I", len(data)) + kind + data
                                          + struct.pack(">I", zlib.crc32(kind + data)) for kind, data in chunks)


def test_info_of_a_png_reads_no_image_data(tmp_path, capsys):
    """``clsky info`` decoded a PNG's whole image for its text: a 69-byte file claiming 60000 x 60000 pixels
    ended in Pillow's DecompressionBombError (a traceback), and clsky's own composites of 8192-pixel
    frames (over 179 million pixels) would have too. Its header chunks are read, nothing decompressed."""
    import struct

    header = struct.pack(">IIBBBBB", 60000, 60000, 8, 2, 0, 0, 0)
    text = b"clsky_version\0\0\0\0\0" + b"9.9"
    path = tmp_path / "huge.png"
    path.write_bytes(_png_with([(b"IHDR", header), (b"iTXt", text), (b"IDAT", b"\x78\x9c")]))
    status, out, err = run(capsys, "info", path)
    assert status == 0 and "60000 x 60000 pixels, RGB" in out and "clsky version  9.9" in out, out + err
    forged = tmp_path / "forged.png"
    forged.write_bytes(_png_with([(b"IHDR", header), (b"iTXt", b"clsky_version\0\0\0\0\0" + b"9.9\nFAKE LINE"),
                                  (b"IDAT", b"")]))
    status, out, _ = run(capsys, "info", forged)
    assert status == 0 and "FAKE LINE" not in out.splitlines() and "'9.9\\nFAKE LINE'" in out
    damaged = path.read_bytes()
    path.write_bytes(damaged[:20] + bytes([damaged[20] ^ 1]) + damaged[21:])          # in the IHDR data
    assert "not a readable PNG (its 'IHDR' chunk is damaged)" in one_line_error(*run(capsys, "info", path)[::2])
    path.write_bytes(damaged[:33])
    assert "not a readable PNG (it ends before its image data)" in one_line_error(*run(capsys, "info", path)[::2])


def test_info_of_a_deeply_nested_metrics_json_is_one_line(tmp_path, capsys):
    """json.loads of [[[...]]] 100 000 deep ended in RecursionError, a traceback."""
    path = tmp_path / "deep_metrics.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    assert "not a readable JSON file" in one_line_error(*run(capsys, "info", path)[::2])


@pytest.mark.parametrize("command", [("render", "--scene"), ("table", "--sweep")])
def test_scene_and_sweep_files_that_are_no_regular_files_are_one_line(tmp_path, capsys, command):
    """A FIFO without a writer blocked --scene and --sweep for ever, /dev/zero filled the memory: they are
    opened without blocking and must be regular files."""
    fifo = tmp_path / "pipe.txt"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero"):
        line = one_line_error(*run(capsys, *command, path)[::2])
        assert line == f"clsky: error: {command[1]}: cannot read {path}: not a regular file (a FIFO, a device or a socket)"


def test_scene_and_sweep_paths_that_name_no_file_are_one_line(tmp_path, capsys):
    """A directory's error named its descriptor ('Is a directory: 3' from the library's reader), and an
    empty --sweep was read as the current directory ('cannot read .'): named as typed, as --scene is."""
    from clsky._files import read_user_text

    with pytest.raises(IsADirectoryError) as error:
        read_user_text(tmp_path)
    assert error.value.filename == str(tmp_path)
    assert one_line_error(*run(capsys, "table", "--sweep", tmp_path)[::2]) == (
        f"clsky: error: --sweep: cannot read {tmp_path}: Is a directory")
    assert one_line_error(*run(capsys, "table", "--sweep", "")[::2]) == (
        "clsky: error: --sweep must be a file path, got an empty one")


def test_a_sweep_comment_begins_a_word_as_in_the_shell(tmp_path, capsys):
    """shlex ended a word at any '#': '--raw sky#2' wrote sky.bin without a word. As in the shell, a '#'
    begins a comment only where it begins a word outside quotes."""
    from clsky.sweep import read_sweep, without_comment

    (tmp_path / "lines.txt").write_text("-o a.npz --raw sky#2 # a comment\n# a line of comment\n"
                                        "-o 'b #1.npz' --raw c\\ #3 #\n")
    assert read_sweep(tmp_path / "lines.txt") == [(1, ["-o", "a.npz", "--raw", "sky#2"]),
                                                  (3, ["-o", "b #1.npz", "--raw", "c #3"])]
    assert without_comment('"a # b" c#d #e') == '"a # b" c#d '


def test_a_scene_with_a_byte_order_mark_and_one_nested_too_deeply(tmp_path, capsys):
    """A scene saved with a byte-order mark (Windows editors) read "Invalid statement (at line 1, column 1)";
    a value nested 100 000 deep ended in RecursionError."""
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf[output]\noutput = \"x.png\"\n")
    status, out, err = run(capsys, "render", "--scene", bom, "--print-scene")
    assert status == 0 and 'output = "x.png"' in out, err
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n")
    assert one_line_error(*run(capsys, "render", "--scene", deep)[::2]) == (
        f"clsky: error: --scene {deep}: not a valid TOML file: nested too deeply")


def test_info_without_the_anim_extra_is_one_line(tmp_path, capsys, monkeypatch):
    """Describing an EXR needs OpenEXR: without it (None in sys.modules makes its import fail) one line
    saying how to install it, exit status 2. (A PNG's chunks are read without Pillow.)"""
    monkeypatch.setitem(sys.modules, "PIL", None)
    monkeypatch.setitem(sys.modules, "OpenEXR", None)
    for name, needs in (("x.exr", "describing an EXR file needs"),):
        (tmp_path / name).write_bytes(b"not an image")
        line = one_line_error(*run(capsys, "info", tmp_path / name)[::2])
        assert line.startswith(f"clsky: error: {needs}") and "pip install 'clsky[anim]'" in line


@pytest.mark.slow
def test_the_dusk_scene_reproduces_the_readme_picture(tmp_path, capsys, monkeypatch):
    """``clsky animate --scene examples/dusk.toml`` (README 'Scene files') writes docs/scene_dusk.png
    as its third frame: the same text chunks, and the same pixels to within one 8-bit level at no
    more than 0.1 % of them (PoCL compiles for the CPU it runs on, and another CPU's code generation
    moves the last bits of a radiance, which can tip a rounding to 8 bits; on the machine that made
    the picture the files are byte for byte the same). Its scene is the example's. Slow: the scene's
    own size and quality (a default-level table with azimuth harmonics)."""
    monkeypatch.chdir(tmp_path)
    example = ROOT / "examples" / "dusk.toml"
    assert run(capsys, "animate", "--scene", example, "--progress", "none")[0] == 0
    frames = sorted((tmp_path / "dusk_frames").glob("frame_*.png"))
    assert len(frames) == 4
    with Image.open(frames[2]) as image, Image.open(ROOT / "docs" / "scene_dusk.png") as picture:
        assert image.text == picture.text
        difference = np.abs(np.asarray(image, np.int16) - np.asarray(picture, np.int16))
    assert difference.max() <= 1 and np.mean(difference > 0) <= 0.001, \
        f"docs/scene_dusk.png differs: {np.mean(difference > 0):.2%} of the pixels, by up to {difference.max()} levels"
    with Image.open(frames[2]) as image:
        written = tomllib.loads(image.text["scene"])
        assert image.text["clsky_version"] == clsky.__version__
    for section, values in tomllib.loads(example.read_text()).items():
        for key, value in values.items():
            assert written[section][key] == value, (section, key)


@pytest.mark.parametrize("command, output", [("render", "sky.png"), ("animate", "sky_metrics.json")])
def test_an_output_that_is_the_scene_file_is_refused(tmp_path, capsys, monkeypatch, command, output):
    """``clsky render --scene sky.png -o sky.png --force`` replaced the scene with the frame it described
    (an animation's metrics JSON likewise)."""
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / output
    scene.write_text("[output]\n")
    target = "sky.mp4" if command == "animate" else output
    line = one_line_error(*run(capsys, command, "--scene", output, "-o", target, "--force", "--size", "16")[::2])
    assert line.endswith(" is the --scene file itself: write the output elsewhere"), line
    assert scene.read_text() == "[output]\n" and sorted(p.name for p in tmp_path.iterdir()) == [output]
