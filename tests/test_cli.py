"""The command line: clsky devices and clsky table, run as a user would (a subprocess)."""

import subprocess
import sys

import numpy as np
import pytest

from clsky import ScatteringTable

import forked_cli


def clsky(*args, cwd):
    return forked_cli.run("clsky", *args, cwd=cwd)


def test_devices_lists_the_chosen_device(tmp_path):
    result = clsky("devices", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    chosen = [line for line in result.stdout.splitlines() if line.startswith("* ")]
    assert len(chosen) == 1
    assert "fp64 yes" in chosen[0]


def test_devices_says_when_pyopencl_ctx_selects_none(tmp_path):
    """With a PYOPENCL_CTX that matches no device the listing has no '*': the devices are listed (what to
    choose from), then one line says so, exit 2, as every other command refuses to run with it."""
    import os

    env = dict(os.environ, PYOPENCL_CTX="no-such-platform")
    result = subprocess.run([sys.executable, "-m", "clsky", "devices"], cwd=tmp_path, env=env, capture_output=True,
                            text=True)
    assert result.returncode == 2
    assert "fp64" in result.stdout and not any(line.startswith("* ") for line in result.stdout.splitlines())
    assert result.stderr.strip().splitlines() == [
        "clsky: error: PYOPENCL_CTX='no-such-platform' selects none of the devices above: unset it (clsky then picks "
        "one), or give PLATFORM:DEVICE by their order (0:0 the first; PyOpenCL matches other numbers and words in "
        "the devices' names)"]


def test_table_writes_a_loadable_file_and_raw_export(tmp_path):
    result = clsky("table", "--preset", "physical", "--size", "8", "16", "6", "-o", "sky.npz", "--raw", "sky",
                   "--progress", "none", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = result.stdout.strip().splitlines()
    assert len(summary) == 1 and "built in" in summary[0] and "8x16x6" in summary[0]
    table = ScatteringTable.load(tmp_path / "sky.npz")
    assert table.settings.size == (8, 16, 6)
    # the physical preset's ground (0.1) needs the physical scheme, its default without --mode: 6 factored
    # channels of single scattering plus 3 of the higher orders
    assert (table.settings.mode, table.settings.channels) == ("physical", 9)
    assert (tmp_path / "sky.bin").stat().st_size == 8 * 16 * 6 * 9 * 4
    assert np.isfinite(table.data).all() and (table.data >= 0).all()


def test_table_exports_a_4d_table_as_the_glsl_snippets_textures(tmp_path):
    """`--texture NAME` (the layout docs/lookup4d.glsl reads, which only the Python API wrote): beside the
    table and its --raw export, in one summary line; the same files as ScatteringTable.export_texture."""
    from clsky.export4d import texture_volumes

    words = ["table", "--preset", "physical", "--parameterization", "4d", "--size", "6", "8", "6", "--azimuth-size",
             "4", "--quality", "draft", "--progress", "none", "-o", "t.npz"]
    result = clsky(*words, "--texture", "tex", "--raw", "raw", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("-> t.npz, raw.bin, raw.json, tex.bin, tex.json")
    table = ScatteringTable.load(tmp_path / "t.npz")
    expected = texture_volumes(table.data).ravel()
    np.testing.assert_array_equal(np.fromfile(tmp_path / "tex.bin", dtype="<f4"), expected)
    # one name for both exports, and a 3D table's --texture: one line each, nothing written
    three_d = ["table", "--preset", "physical", "--size", "6", "8", "6", "--quality", "draft", "--progress", "none"]
    for line, message in (([*words[:-2], "--texture", "same", "--raw", "same.json", "-o", "u.npz"],
                           "--raw and --texture must name different files, got 'same.json' and 'same': each "
                           "writes NAME.bin and NAME.json"),
                          ([*three_d, "--texture", "t3", "-o", "v.npz"],
                           "--texture exports a 4d table as textures for docs/lookup4d.glsl: give "
                           "--parameterization 4d (--raw exports any table)")):
        refused = clsky(*line, cwd=tmp_path)
        assert refused.returncode == 2 and refused.stderr == f"clsky: error: {message}\n", refused.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["raw.bin", "raw.json", "t.npz", "tex.bin", "tex.json"]


@pytest.mark.parametrize("orders,expected", [
    ("1", "single scattering only"),
    ("3", "3 orders as asked (--orders 3)"),
    ("auto", " orders, converged;"),
])
def test_table_summary_says_how_many_orders_and_why(tmp_path, orders, expected):
    """A count of orders is what was asked for, not a failure to converge: only --orders auto says
    whether its stopping rule was met."""
    result = clsky("table", "--size", "4", "16", "4", "--orders", orders, "--progress", "none", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert expected in result.stdout and "not converged" not in result.stdout, result.stdout


@pytest.mark.parametrize("args,expected", [
    (["--azimuth-size", "8"], "--azimuth-size sets the 4d table's azimuth axis: give --parameterization 4d"),
    (["--orders", "3", "--order-tolerance", "1e-3"],
     "--order-tolerance sets when --orders auto stops, and --orders 3 computes 3 orders"),
    (["--orders", "2", "--max-orders", "5"], "--max-orders sets when --orders auto stops, and --orders 2 computes"),
    (["--orders", "1", "--max-orders", "5"],        # it said '--orders 1 computes 1 orders'
     "--max-orders sets when --orders auto stops, and --orders 1 computes single scattering only"),
    (["--orders", "1", "--gather-steps", "64", "32"],
     "--gather-steps sets the higher orders, which --orders 1 (single scattering only) does not compute"),
    (["--orders", "1", "--multiple-view-steps", "10"], "--multiple-view-steps sets the higher orders"),
    (["--orders", "1", "--mode", "physical", "--azimuth-harmonics", "2"], "--azimuth-harmonics sets the higher orders"),
])
def test_table_refuses_options_it_would_not_use(tmp_path, args, expected):
    """An option the table would ignore is refused in one line naming it and why, before any work."""
    result = clsky("table", "--progress", "none", *args, cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clsky: error: " + expected), result.stderr
    assert list(tmp_path.iterdir()) == []


def test_table_with_quality_and_sun_elevations(tmp_path):
    """--quality starts from a level's settings (draft: 16 x 128, 15 view steps), --sun-elevations plans
    the sun axis for that path (10 to 30 deg, plus the margins of a ray march from the ground: gamma =
    acos(Rp / Ra) = 10.09 deg below, 3 gamma above) at the level's node spacing; an explicit option
    still wins."""
    result = clsky("table", "--preset", "physical", "--mode", "physical", "--quality", "draft", "--sun-elevations",
                   "10", "30", "--sun-steps", "12", "--orders", "2", "-o", "day.npz", "--progress", "none",
                   cwd=tmp_path)       # two orders: the planner's M = 2 costs 3 scatters and gathers per order
    assert result.returncode == 0, result.stderr
    settings = ScatteringTable.load(tmp_path / "day.npz").settings
    assert settings.size[:2] == (16, 128) and settings.view_steps == 15 and settings.sun_steps == 12
    low, high = settings.sun_cos_range
    gamma = np.degrees(np.arccos(6371.0 / 6471.0))
    assert low == pytest.approx(np.sin(np.radians(10.0 - gamma)), abs=1e-12)
    assert high == pytest.approx(np.sin(np.radians(30.0 + 3 * gamma)), abs=1e-12)
    assert settings.size[2] == 37          # w from 0.443 to 0.977 at 0.015 spacing; the whole axis takes 68
    assert settings.azimuth_harmonics == 2       # the planner's choice for a sun going below +30 deg


def test_table_with_twilight_sun_elevations_gets_the_planners_harmonics(tmp_path):
    """--sun-elevations reaching below +30 deg: the scene planner's M = 2 (clsky.planner.azimuth_harmonics);
    a typed --azimuth-harmonics wins."""
    for extra, expected in (([], 2), (["--azimuth-harmonics", "0"], 0)):
        result = clsky("table", "--preset", "physical", "--quality", "draft", "--sun-elevations", "-6", "5",
                       "--size", "6", "16", "6", "--orders", "2", "-o", "dusk.npz", "--force", "--progress", "none",
                       *extra, cwd=tmp_path)
        assert result.returncode == 0, result.stderr
        assert ScatteringTable.load(tmp_path / "dusk.npz").settings.azimuth_harmonics == expected


def test_table_refuses_to_overwrite_without_force(tmp_path):
    (tmp_path / "sky.npz").write_bytes(b"precious")
    result = clsky("table", "--size", "8", "8", "4", "-o", "sky.npz", "--progress", "none", cwd=tmp_path)
    assert result.returncode == 2
    assert "--force" in result.stderr
    assert (tmp_path / "sky.npz").read_bytes() == b"precious"
    result = clsky("table", "--size", "8", "8", "4", "-o", "sky.npz", "--progress", "none", "--force", cwd=tmp_path)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("sweep", [False, True], ids=["single", "sweep"])
@pytest.mark.parametrize("when", ["build", "commit"])
def test_an_output_another_run_wrote_meanwhile_is_refused_by_option(tmp_path, monkeypatch, capsys, sweep, when):
    """Two runs on one output without --force both pass the check before the work; the one that writes
    second is refused in one line naming the option of the file the other run wrote (it gave the
    library's "pass force=True" hint), and the other run's file is kept. Written during the build, the
    other run's sky.json is found when this run stages its files (none lands); written as this run puts
    its files in place (sky.npz, sky.bin, then sky.json), it finds two of them in place already, which
    the message names, and which are not the files to blame."""
    from clsky import _files, cli

    def the_other_run_writes():
        (tmp_path / "sky.json").write_bytes(b"the other run's")

    build, commit = ScatteringTable.build, _files.StagedWrites.commit

    def build_then_the_other_run_writes(*args, **kwargs):
        table = build(*args, **kwargs)
        the_other_run_writes()
        return table

    def the_other_run_writes_then_commit(self):
        the_other_run_writes()
        return commit(self)

    if when == "build":
        monkeypatch.setattr(ScatteringTable, "build", build_then_the_other_run_writes)
    else:
        monkeypatch.setattr(_files.StagedWrites, "commit", the_other_run_writes_then_commit)
    monkeypatch.chdir(tmp_path)
    words = ["--size", "8", "8", "4", "--orders", "1", "-o", "sky.npz", "--raw", "sky"]
    if sweep:
        (tmp_path / "lines.txt").write_text(" ".join(words) + "\n")
        words = ["--sweep", "lines.txt"]
    assert cli.main(["table", "--progress", "none", *words]) == 2
    where = "lines.txt line 1: " if sweep else ""
    placed = "; this run's files already in place: sky.npz, sky.bin" if when == "commit" else ""
    printed = capsys.readouterr()
    assert printed.err == (f"clsky: error: {where}--raw: sky.json exists: another process wrote it "
                           f"during this run; use --force to overwrite it{placed}\n")
    # no summary line says '-> sky.npz' for a table that was not written (a sweep printed them as it built)
    assert "->" not in printed.out
    expected = {"sky.json"} | ({"sky.npz", "sky.bin"} if placed else set()) | ({"lines.txt"} if sweep else set())
    assert {path.name for path in tmp_path.iterdir()} == expected
    assert (tmp_path / "sky.json").read_bytes() == b"the other run's"


def test_a_refused_sweep_prints_no_line_nor_warning_of_its_tables(tmp_path, monkeypatch, capsys):
    """A sweep whose files do not land (here the commit finds another run's file) printed its tables'
    '-> FILE' lines and their orders warnings as it built them; now each table's line and warning come
    once the files land, and here none."""
    from clsky import _files, cli

    commit = _files.StagedWrites.commit

    def the_other_run_writes_then_commit(self):
        (tmp_path / "b.npz").write_bytes(b"the other run's")
        return commit(self)

    monkeypatch.setattr(_files.StagedWrites, "commit", the_other_run_writes_then_commit)
    monkeypatch.chdir(tmp_path)
    line = "--size 8 8 4 --mode physical --max-orders 2 -o {}\n"         # not converged at 2 orders: a warning
    (tmp_path / "lines.txt").write_text(line.format("a.npz") + line.format("b.npz"))
    assert cli.main(["table", "--progress", "none", "--sweep", "lines.txt"]) == 2
    printed = capsys.readouterr()
    assert printed.out == "" and "warning" not in printed.err and printed.err.count("\n") == 1, printed
    monkeypatch.setattr(_files.StagedWrites, "commit", commit)
    for name in ("a.npz", "b.npz"):           # a.npz was put in place before b.npz was found (the message says)
        (tmp_path / name).unlink(missing_ok=True)
    assert cli.main(["table", "--progress", "none", "--sweep", "lines.txt"]) == 0
    printed = capsys.readouterr()
    assert printed.out.count("-> a.npz") == 1 and printed.out.count("-> b.npz") == 1
    assert printed.err.count("clsky: warning: ") == 2


@pytest.mark.parametrize("args,named", [
    (["--size", "1", "16", "6"], "--size W"),
    (["--size", "8", "16"], "--size"),
    (["--view-steps", "0"], "--view-steps"),
    (["--preset", "venus"], "--preset"),
    (["--dtype", "float16"], "--dtype"),
    (["-o", "sky.txt"], "--output"),
    (["-o", ""], "--output must be a file path, got an empty one"),      # it wrote table.npz
    # the level's M = 2 against the PHI typed: not "--azimuth-harmonics", which was not typed
    (["--quality", "reference", "--gather-steps", "64", "3"],
     "--gather-steps PHI must be at least twice the azimuth harmonics (M = 2, the --quality level's or the scene "
     "planner's), 4, got 3"),
    (["-o", "missing/sky.npz"], "directory"),
    (["--transmittance-size", "1", "8"], "--transmittance-size TW"),
    (["--quality", "best"], "--quality"),
    (["--sun-elevations", "30", "10"], "--sun-elevations"),
    (["--sun-elevations", "-100", "10"], "--sun-elevations"),
    # a check of the build's, which named the API's 'orders' (and, on a --sweep line, lost the line's prefix)
    (["--parameterization", "4d", "--preset", "physical", "--orders", "1", "--size", "8", "32", "8"],
     "clsky: error: --orders must be more than 1 for a reflecting ground"),
])
def test_bad_arguments_one_line_exit_2(tmp_path, args, named):
    result = clsky("table", "--progress", "none", *args, cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("clsky: error:") and named in lines[0]
    assert list(tmp_path.iterdir()) == []


# The `clsky` script (clsky.anim.cli:main) with the anim extra's packages made unimportable, as in an
# install without `[anim]`: None in sys.modules makes `import PIL` raise ImportError.
_WITHOUT_ANIM_EXTRA = ("import sys\n"
                       "for name in ('PIL', 'imageio', 'imageio_ffmpeg', 'pvlib', 'OpenEXR'):\n"
                       "    sys.modules[name] = None\n"
                       "from clsky.anim.cli import main\n"
                       "sys.exit(main(sys.argv[1:]))\n")


@pytest.mark.parametrize("args, expected", [
    (("table", "--help"), "usage: clsky table"),
    (("info", "--help"), "usage: clsky info"),
    (("animate", "--help"), "--hdr [{exr,hdr,npy}]"),
    (("devices",), "fp64 yes"),
])
def test_clsky_script_runs_without_the_anim_extra(tmp_path, args, expected):
    """Every command builds the animation commands' options: they must not import Pillow, imageio,
    pvlib or OpenEXR (the `anim` extra), or every `clsky` command fails without it."""
    result = subprocess.run([sys.executable, "-c", _WITHOUT_ANIM_EXTRA, *args], cwd=tmp_path,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert expected in result.stdout
    assert result.stderr == ""


def another_run_writes_before_commit(monkeypatch, path):
    """Every StagedWrites.commit of the test finds ``path`` written by another run just before it."""
    from clsky import _files

    commit = _files.StagedWrites.commit

    def the_other_run_writes_then_commit(self):
        path.write_text("the other run's")
        return commit(self)

    monkeypatch.setattr(_files.StagedWrites, "commit", the_other_run_writes_then_commit)


def test_a_frame_whose_output_another_run_wrote_meanwhile_names_the_option(tmp_path, monkeypatch, capsys):
    """Two `clsky render` runs on one -o without --force: the one that lands second was refused in the
    library's words ('pass force=True ...'); now one line naming --output, as a table's and an animation's."""
    from clsky.anim import cli as anim_cli

    another_run_writes_before_commit(monkeypatch, tmp_path / "p.png")
    monkeypatch.chdir(tmp_path)
    assert anim_cli.main(["render", "--size", "16", "--table-size", "8", "32", "8", "--method", "lut",
                          "-o", "p.png"]) == 2
    assert capsys.readouterr().err == ("clsky: error: --output: p.png exists: another process wrote it during this "
                                       "run; use --force to overwrite it\n")
    assert (tmp_path / "p.png").read_text() == "the other run's"


def test_an_animation_whose_output_another_run_wrote_meanwhile_names_the_option(tmp_path, monkeypatch, capsys):
    """Two `clsky animate` runs on one -o: the one that lands second was refused in the library's words
    ('pass force=True (a table's save and exports: overwrite=True)'); now one line naming --output."""
    from clsky.anim import cli as anim_cli

    another_run_writes_before_commit(monkeypatch, tmp_path / "c_metrics.csv")
    monkeypatch.chdir(tmp_path)
    assert anim_cli.main(["animate", "--size", "16", "--frames", "2", "--table-size", "8", "32", "8", "--method",
                          "lut", "--progress", "none", "-o", "c.mp4"]) == 2
    error = capsys.readouterr().err
    assert error.startswith("clsky: error: --output: c_metrics.csv exists: another process wrote it during this "
                            "run; use --force to overwrite it") and error.count("\n") == 1, error
    assert (tmp_path / "c_metrics.csv").read_text() == "the other run's"
