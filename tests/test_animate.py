"""Animations (anim/animate.py) and the ``clsky animate`` / ``clsky render`` commands.

1. render_animation with tiny configurations: the MP4 (decoded with imageio), the PNG frames, the
   metrics CSV and JSON; single-panel methods; refusing to overwrite without force, overwriting with it.
2. The command line run as a user would (a subprocess): a small animation, one frame, bad values.
3. Real sun positions (pvlib), and the default configuration's sizes.
"""

from __future__ import annotations

import csv
import datetime
import json
import pathlib

import numpy as np
import pytest

from clsky import resources
from clsky.anim import metrics
from clsky.anim.animate import AnimationConfig, render_animation

import forked_cli

imageio_v3 = pytest.importorskip("imageio.v3")

TINY = dict(size=32, table_size=(9, 33, 7))
#: metric columns of a 'compare' run (clsky.anim.metrics.compare_frames plus the temporal excess)
METRIC_COLUMNS = ("rmse", "median_rel", "p95_rel", "max_rel", "mean_delta_e", "temporal_excess_jump")


def composite_shape(size):
    """(H, W) of a 'compare' frame of a size x size camera: table | ray march | error image with its
    legend, 4-pixel gutters, cropped to even sizes for H.264 (yuv420p)."""
    panel = np.zeros((size, size, 3), np.uint8)
    error = metrics.error_image(np.zeros((size, size)))
    height, width = metrics.composite([panel, panel, error]).shape[:2]
    return height - height % 2, width - width % 2


def read_csv(path):
    with open(path, newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def snapshot(directory):
    """{relative path: (bytes, inode, mtime_ns)} of every file under ``directory``."""
    return {str(path.relative_to(directory)): (path.read_bytes(), path.stat().st_ino, path.stat().st_mtime_ns)
            for path in sorted(directory.rglob("*")) if path.is_file()}


# 1. render_animation ------------------------------------------------------------------------------

def test_compare_animation_writes_video_frames_and_metrics(tmp_path, cl_context):
    config = AnimationConfig(frames=5, output=str(tmp_path / "sky.mp4"), **TINY)
    result = render_animation(config, ctx=cl_context)

    height, width = composite_shape(32)
    video = imageio_v3.imread(tmp_path / "sky.mp4")
    assert video.shape == (5, height, width, 3)

    names = sorted(path.name for path in (tmp_path / "sky_frames").iterdir())
    assert names == [f"frame_{index:05d}.png" for index in range(5)]
    for name in names:
        assert imageio_v3.imread(tmp_path / "sky_frames" / name).shape == (height, width, 3)

    rows = read_csv(tmp_path / "sky_metrics.csv")
    assert [int(row["frame"]) for row in rows] == list(range(5))
    for column in METRIC_COLUMNS:
        assert column in rows[0], f"column {column} missing from {list(rows[0])}"
        assert all(np.isfinite(float(row[column])) for row in rows)
    assert all(row["time"] == "" for row in rows)              # a sweep has no clock times

    record = json.loads((tmp_path / "sky_metrics.json").read_text(encoding="utf-8"))
    assert record["config"]["frames"] == 5 and record["config"]["size"] == 32
    assert record["config"]["table_size"] == [9, 33, 7]
    assert record["table"]["orders"]["converged"] is True
    assert record["table"]["orders"]["orders"] >= 2
    temporal = record["temporal"]
    for key in ("table_jumps", "raymarch_jumps", "excess"):
        assert len(temporal[key]) == 5
    assert temporal["worst_frames"] and all(0 <= index < 5 for index in temporal["worst_frames"])
    # an explicit table size: no plan, the 3D table lookup is the lookup compared, named in every output
    assert all(row["lookup"] == "table lookup" for row in rows)
    assert record["lookup"] == temporal["lookup"] == "table lookup" and record["plan"] is None

    assert len(result.rows) == 5
    assert {path.name for path in result.paths} >= {"sky_metrics.csv", "sky_metrics.json", *names}
    assert "5 frames" in result.summary and "worst frame" in result.summary


def test_result_paths_include_the_mp4(tmp_path, cl_context):
    config = AnimationConfig(frames=2, method="lut", output=str(tmp_path / "sky.mp4"), **TINY)
    result = render_animation(config, ctx=cl_context)
    assert (tmp_path / "sky.mp4").is_file()
    assert tmp_path / "sky.mp4" in result.paths


@pytest.mark.parametrize("method", ["lut", "raymarch", "skyview"])
def test_single_method_writes_single_panel_frames(tmp_path, cl_context, method):
    config = AnimationConfig(frames=5, method=method, output=str(tmp_path / "sky.mp4"), **TINY)
    render_animation(config, ctx=cl_context)
    assert imageio_v3.imread(tmp_path / "sky.mp4").shape == (5, 32, 32, 3)
    frames = sorted((tmp_path / "sky_frames").iterdir())
    assert len(frames) == 5
    assert all(imageio_v3.imread(frame).shape == (32, 32, 3) for frame in frames)
    assert len(read_csv(tmp_path / "sky_metrics.csv")) == 5


def test_rerun_without_force_refuses_and_touches_nothing(tmp_path, cl_context):
    config = AnimationConfig(frames=5, method="lut", output=str(tmp_path / "sky.mp4"), **TINY)
    render_animation(config, ctx=cl_context)
    before = snapshot(tmp_path)
    assert len(before) == 5 + 3                                # frames, MP4, CSV, JSON

    with pytest.raises(FileExistsError):
        render_animation(config, ctx=cl_context)
    assert snapshot(tmp_path) == before                        # same bytes, same inodes, same times

    forced = AnimationConfig(frames=5, method="lut", output=str(tmp_path / "sky.mp4"), force=True, **TINY)
    render_animation(forced, ctx=cl_context)
    after = snapshot(tmp_path)
    assert sorted(after) == sorted(before)
    for name, (_, inode, _) in before.items():                 # atomic writes: new files renamed in
        assert after[name][1] != inode, f"{name} was not rewritten"


# 2. The command line ------------------------------------------------------------------------------

def clsky(*args, cwd):
    return forked_cli.run("clsky.anim", *args, cwd=cwd)


SMALL_ARGS = ("--size", "32", "--table-size", "9", "33", "7")


def test_cli_animate_small_run(tmp_path):
    result = clsky("animate", "--frames", "4", *SMALL_ARGS, "--progress", "none", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert len(lines) == 1, result.stdout
    assert "4 frames" in lines[0] and "worst frame" in lines[0] and "sky.mp4" in lines[0]
    assert (tmp_path / "sky.mp4").stat().st_size > 0
    assert sorted(path.name for path in (tmp_path / "sky_frames").iterdir()) == \
        [f"frame_{index:05d}.png" for index in range(4)]
    assert len(read_csv(tmp_path / "sky_metrics.csv")) == 4
    assert (tmp_path / "sky_metrics.json").is_file()


def test_cli_animate_planned_run_prints_the_plan(tmp_path):
    """Without --table-size the scene plan decides the table: printed first, then the summary; the
    metrics JSON records it and the table covers the sun path's part of the sun axis only."""
    result = clsky("animate", "--frames", "3", "--size", "24", "--quality", "draft", "--start-elevation", "10",
                   "--max-elevation", "30", "--progress", "none", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("scene plan (draft quality") and "3 frames" in lines[-1]
    assert any(line.strip().startswith("sun axis") for line in lines)
    record = json.loads((tmp_path / "sky_metrics.json").read_text())
    assert record["plan"]["quality"] == "draft" and 0.0 < record["plan"]["work_fraction"] < 0.5
    low, high = record["table"]["settings"]["sun_cos_range"]
    assert low <= np.sin(np.radians(10.0)) and high >= np.sin(np.radians(30.0)) and high - low < 1.0


def test_planned_compare_uses_the_plans_lookup_the_sky_view_map(tmp_path, cl_context):
    """'compare' with a plan compares the ray march with the plan's renderer: down to -4 deg the 3D
    lookup's measured 1026 % exceeds the draft budget (10 %), the sky-view map's 6.58 % (measured against the
    reference at -4 deg) fits; on frames this small (24 x 24) marching every pixel costs less than the
    map's 8192 rays, so the plan picks the ray march (clsky.renderer_choice), and the comparison's lookup
    is the map, the closest lookup, either way (lookup_of). Its frame is the first panel, labelled, and
    its metrics are the sky-view map's against the ray march, rendered here independently of the
    animation."""
    from clsky.anim.animate import lookup_of, make_renderer, planned_animation, three_wavelength_frame_to_linear_srgb
    from clsky import skyview

    config = AnimationConfig(frames=2, size=24, quality="draft", start_elevation_deg=-4.0, max_elevation_deg=5.0,
                             output=str(tmp_path / "sky.mp4"))
    result = render_animation(config, ctx=cl_context)
    record = json.loads((tmp_path / "sky_metrics.json").read_text(encoding="utf-8"))
    assert record["plan"]["renderer"] == "raymarch"
    assert record["lookup"] == record["temporal"]["lookup"] == "sky-view map"
    assert all(row["lookup"] == "sky-view map" for row in record["frames"])
    assert len(record["temporal"]["table_jumps"]) == 2 and "sky-view map against the ray march" in result.summary

    # the same frame rendered directly: the sky-view map of the plan's table against its ray march
    planned = planned_animation(config, ctx=cl_context)
    positions, directions, valid, plan = planned.positions, planned.directions, planned.valid, planned.plan
    assert lookup_of(config, plan) == "skyview"
    # the plan the animation recorded is the one planned_animation makes (the same work, bit for bit)
    assert (record["plan"]["quality"], record["plan"]["work_fraction"]) == (plan.level.name, plan.work_fraction)
    renderer, _ = make_renderer(config, plan, ctx=cl_context)
    prepared = renderer.prepare(directions, valid)
    sun = positions[0].direction
    wavelengths = renderer.table.atmosphere.wavelengths        # absolute frames: linear sRGB in cd/m^2
    lookup = three_wavelength_frame_to_linear_srgb(renderer.render_skyview(
        prepared, sun, config.altitude, settings=skyview.SkyViewSettings(skyview.DEFAULT_SIZE)), wavelengths)
    march = three_wavelength_frame_to_linear_srgb(renderer.render_raymarch(prepared, sun, config.altitude), wavelengths)
    expected = metrics.compare_frames(march, lookup, valid)
    # the same kernels on the same inputs: float64 sums in the same order; 1e-9 allows for nothing but
    # the metrics' float64 reductions
    assert record["frames"][0]["p95_rel"] == pytest.approx(expected["p95_rel"], rel=1e-9, abs=1e-15)
    renderer.close()

    # the composite's first panel is labelled "sky-view map": inside the label's opaque box (the pixels a
    # black and a white panel share once labelled) the frame is that label, not "table lookup"
    def labelled(label, fill):
        return metrics.composite([np.full((24, 24, 3), fill, np.uint8)], [label])

    box = np.all(labelled("sky-view map", 0) == labelled("sky-view map", 255), axis=-1)
    first = imageio_v3.imread(tmp_path / "sky_frames" / "frame_00000.png")[:, :24]
    assert box.sum() > 50
    assert np.array_equal(first[box], labelled("sky-view map", 0)[box])
    assert not np.array_equal(first[box], labelled("table lookup", 0)[box])


def test_cli_render_writes_one_png(tmp_path):
    result = clsky("render", *SMALL_ARGS, "--method", "lut", "-o", "one.png", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert len(result.stdout.splitlines()) == 1
    assert [path.name for path in tmp_path.iterdir()] == ["one.png"]
    assert imageio_v3.imread(tmp_path / "one.png").shape == (32, 32, 3)


def test_cli_render_plans_for_its_one_sun(tmp_path):
    """One frame, planned: the table covers the sun's elevation plus the margins that the 24 x 24
    fisheye's pixel rays need (its lowest pixel centre is 1.1 deg up: 9.0 deg below, 29.2 above)."""
    result = clsky("render", "--size", "24", "--quality", "draft", "--sun-elevation", "3", "-o", "one.png", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("scene plan (draft quality, error budget 10 %)") and lines[-1].startswith("frame ")
    assert any("elevations -6.0 to 32.2 deg" in line for line in lines), result.stdout
    assert "auto-exposure's" not in lines[-1]             # a day sky meters well inside the limit


def test_cli_render_says_a_night_sky_meets_the_exposure_limit(tmp_path):
    """The sun 30 deg down: a sky of some 1e-7 cd/m^2, which auto-exposure lifts by its whole +20 EV to a
    grey like a dim day's (a polar night's animation did so with no word); the frame's line says so."""
    result = clsky("render", "--size", "16", "--quality", "draft", "--sun-elevation", "-30", "-o", "night.png",
                   cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    line = result.stdout.splitlines()[-1]
    assert "at +20.00 EV)" in line and line.endswith(
        "; 1 frame at auto-exposure's +20 EV limit: a sky too dark to meter, shown brighter than it is "
        "(--no-auto-exposure --exposure EV fixes one exposure) -> night.png"), line


@pytest.mark.parametrize("evs,exposure,auto,expected", [
    ([20.0, 19.96, 19.9, 3.0], 0.0, None, "2 frames"),       # within EXPOSURE_LIMIT_MARGIN_EV of +20
    ([18.0], -2.0, None, "1 frame"),                          # the compensation moves the limit
    ([19.9, 3.0], 0.0, None, None),
    ([20.0], 0.0, False, None),                               # a fixed exposure has no limit
])
def test_exposure_limit_note_counts_the_frames_at_the_limit(evs, exposure, auto, expected):
    from clsky.anim.animate import exposure_limit_note

    note = exposure_limit_note(AnimationConfig(exposure=exposure, auto_exposure=auto), evs)
    if expected is None:
        assert note == ""
    else:
        assert note.startswith(f"{expected} at auto-exposure's +20 EV limit: a sky too dark to meter"), note


@pytest.mark.parametrize("command,args,named", [
    ("animate", ["--frames", "1"], "--frames"),
    ("animate", ["--size", "8"], "--size"),
    ("animate", ["--camera", "perspective", "--fov", "0"], "--fov"),
    ("animate", ["--table-size", "1", "33", "7"], "--table-size"),
    ("animate", ["--method", "foo"], "--method"),
    ("animate", ["--output", "x.avi"], "--output"),
    ("animate", ["--location", "100", "0"], "--location"),
    ("animate", ["--error-budget", "0"], "--error-budget"),
    ("animate", ["--error-budget", "1.5"], "--error-budget"),
    ("animate", ["--quality", "best"], "--quality"),
    ("render", ["--sampling", "lowest"], "--sampling"),
    ("render", ["--sun-elevation", "95"], "--sun-elevation"),
], ids=lambda value: " ".join(value) if isinstance(value, list) else value)
def test_cli_bad_values_one_line_exit_2(tmp_path, command, args, named):
    extra = ["--progress", "none"] if command == "animate" else []
    result = clsky(command, *extra, *args, cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("clsky: error:") and named in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []


DUSK_SCENE = pathlib.Path(__file__).resolve().parents[1] / "examples" / "dusk.toml"


@pytest.mark.parametrize("args,expected", [
    (["--frames", "2", "--location", "45", "5"],
     "clsky: error: --frames sets the sweep, which real sun positions (--location) replace: their frames are "
     "every --step-minutes from --hours START to END"),
    (["--location", "45", "5", "--start-elevation", "-3"], "clsky: error: --start-elevation sets the sweep"),
    (["--scene", str(DUSK_SCENE), "--max-elevation", "5"],
     f"clsky: error: --max-elevation sets the sweep, which real sun positions ({DUSK_SCENE}: sun.location) "
     "replace"),
    (["--hours", "5", "6"], "clsky: error: --hours sets real sun positions: give --location LAT LON too (the "
                            "sweep takes --frames, --start-elevation and --max-elevation)"),
    (["--date", "2026-06-21"], "clsky: error: --date sets real sun positions"),
    (["--step-minutes", "5"], "clsky: error: --step-minutes sets real sun positions"),
    # the sweep's option is refused in --location's name: a --location out of range is named first
    (["--location", "999", "5", "--frames", "3"], "clsky: error: --location must be (latitude in [-90, 90], "
                                                  "longitude in [-180, 180]) degrees, got (999, 5)"),
], ids=lambda value: " ".join(value) if isinstance(value, list) else None)
def test_cli_refuses_options_of_the_sun_path_not_taken(tmp_path, args, expected):
    """An option of the sweep with real positions (or the reverse) would be ignored: it is refused, in one
    line naming the option, before any work (the scene file's own keys of both paths are not); the option
    its message names is checked before it."""
    _refused(tmp_path, ["animate", "--progress", "none", *args], expected)


@pytest.mark.parametrize("args,expected", [
    (["render", "--fov", "30"], "--fov sets the perspective camera's view, not the fisheye's (--camera perspective)"),
    (["animate", "--camera", "equirectangular", "--pitch", "0"],
     "--pitch sets the perspective camera's view, not the equirectangular's"),
    (["render", "--camera", "equirectangular", "--heading", "90"], "--heading turns the fisheye and the perspective "
     "camera: the equirectangular panorama's columns are fixed azimuths, north at its left edge"),
    (["animate", "--method", "lut", "--samples", "64"], "--samples sets the ray march, which method 'lut' does not render"),
    (["render", "--method", "lut4d", "--samples", "64"], "--samples sets the ray march, which method 'lut4d'"),
    (["animate", "--method", "raymarch", "--skyview-size", "32", "64"],
     "--skyview-size sets the sky-view map, which method 'raymarch' does not read"),
    (["render", "--table-size", "8", "16", "8", "--skyview-size", "32", "64"],
     "--skyview-size sets the sky-view map, which method 'compare' does not read with --table-size: without a "
     "scene plan it compares the ray march with the 3D table lookup"),
    (["render", "--quality", "draft", "--error-budget", "0.5"],
     "--error-budget picks a quality level, and --quality names one (draft): give one of them"),
], ids=lambda value: " ".join(value) if isinstance(value, list) else None)
def test_cli_refuses_options_the_frames_would_not_use(tmp_path, args, expected):
    """Each option that the command line's camera, method or quality level leaves unused is refused rather
    than ignored: one line naming it and why, exit 2, nothing written."""
    _refused(tmp_path, args if args[0] == "render" else [*args, "--progress", "none"], "clsky: error: " + expected)


@pytest.mark.parametrize("args", [
    ["render", "--camera", "perspective", "--fov", "30", "--pitch", "5", "--heading", "10", "--method", "skyview",
     "--skyview-size", "8", "16", "--samples", "8", "--quality", "draft"],
    ["animate", "--camera", "fisheye", "--heading", "10", "--method", "compare", "--skyview-size", "8", "16",
     "--error-budget", "0.05", "--location", "45", "5", "--date", "2026-06-21", "--hours", "4", "6"],
    ["animate", "--frames", "3", "--start-elevation", "-3", "--max-elevation", "20", "--method", "raymarch",
     "--samples", "8"],
], ids=["render perspective skyview", "animate real positions", "animate sweep"])
def test_cli_takes_the_options_its_frames_use(args):
    """The same options where they are used (the perspective camera's view, the sky-view map's size and
    the ray march's samples with --method skyview, whose map is ray-marched; 'compare' may read the map;
    each sun path's own options): the check that refuses the others passes them (the refusals above run
    the command end to end; this checks the parsed options only, without a render)."""
    from clsky import cli as clsky_cli
    from clsky.anim import cli as anim_cli
    from clsky.anim import scene

    parser, _ = clsky_cli.build_parser(extensions=(anim_cli.register,))
    parsed = parser.parse_args(args)
    scene.apply_scene(parsed, parsed.scene_parser)
    typed = {word[2:].replace("-", "_") for word in args if word.startswith("--")}
    assert typed <= set(parsed.given_options)       # the check sees each as typed
    anim_cli._check_options_used(parsed)            # raises UsageError for an option the frames would not use


def _refused(tmp_path, args, expected):
    """`clsky ARGS` exits 2 with its last stderr line beginning with ``expected`` (an earlier line may say
    that an option overrides the scene's), and writes nothing."""
    result = clsky(*args, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith(expected), lines
    assert all(line.startswith("clsky: ") for line in lines) and list(tmp_path.iterdir()) == []


def test_cli_refuses_existing_output_without_force(tmp_path):
    (tmp_path / "sky.mp4").write_bytes(b"precious")
    result = clsky("animate", "--frames", "2", *SMALL_ARGS, "--progress", "none", cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("clsky: error:") and "--force" in lines[0] and "sky.mp4" in lines[0]
    assert (tmp_path / "sky.mp4").read_bytes() == b"precious"
    assert [path.name for path in tmp_path.iterdir()] == ["sky.mp4"]


def test_animation_runs_with_one_blas_thread(monkeypatch, tmp_path, cl_context):
    """render_animation (so ``clsky animate`` too) keeps NumPy's BLAS on one thread from its start, the
    table's build included (PoCL's workers own the cores), and gives the limit back when it ends, by an
    exception here."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from clsky.anim import animate

    def blas_threads():
        return sorted({pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"})

    seen = []

    class Stop(Exception):
        pass

    def make_renderer(*args, **kwargs):
        seen.append(blas_threads())
        raise Stop

    monkeypatch.setattr(animate, "make_renderer", make_renderer)
    with threadpool_limits(limits=2, user_api="blas"):
        assert blas_threads() == [2]
        with pytest.raises(Stop):
            render_animation(AnimationConfig(frames=2, output=str(tmp_path / "sky.mp4"), **TINY), ctx=cl_context)
        assert seen == [[1]]
        assert blas_threads() == [2]


# 3. Real sun positions and the defaults -----------------------------------------------------------

def test_real_sun_positions_one_frame_each(tmp_path, cl_context):
    pytest.importorskip("pvlib")
    config = AnimationConfig(location=(48.0, 11.0), date=datetime.date(2024, 6, 21), start_hour=2.0,
                             end_hour=20.0, step_minutes=240, output=str(tmp_path / "sky.mp4"), **TINY)
    result = render_animation(config, ctx=cl_context)
    hours = [2, 6, 10, 14, 18]                                 # start + k x 4 h <= 20 h
    rows = read_csv(tmp_path / "sky_metrics.csv")
    assert len(rows) == len(result.rows) == len(hours)
    times = [datetime.datetime.fromisoformat(row["time"]) for row in rows]
    assert [t.hour for t in times] == hours and all(t.date() == datetime.date(2024, 6, 21) for t in times)
    assert len(list((tmp_path / "sky_frames").iterdir())) == len(hours)
    assert imageio_v3.imread(tmp_path / "sky.mp4").shape[0] == len(hours)
    # Munich at the June solstice: night at 02:00 UTC, the sun high at 10:00 UTC (local noon ~11:15)
    zeniths = [float(row["sun_zenith_deg"]) for row in rows]
    assert zeniths[0] > 90.0 and zeniths[2] < 30.0


def test_default_configuration_sizes():
    config = AnimationConfig()
    assert config.frames == 120
    assert config.camera == "fisheye"
    assert config.image_shape() == (512, 512)


# 4. Who owns the cores --------------------------------------------------------------------------------

def _record_blas_threads(monkeypatch):
    """A list that receives, at each frame's comparison, the thread counts of the BLAS libraries."""
    from threadpoolctl import threadpool_info

    seen, frame_comparison = [], metrics.frame_comparison

    def recording(*args, **kwargs):
        seen.append({info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"})
        return frame_comparison(*args, **kwargs)

    monkeypatch.setattr(metrics, "frame_comparison", recording)
    return seen


def test_frame_loop_runs_host_blas_on_one_thread(tmp_path, cl_context, monkeypatch):
    """The frame loop's host matrix products run on one BLAS thread: PoCL's workers own the cores
    (docs/speed-log.md); the limit is lifted after the animation. Run with two BLAS threads (the test
    session keeps one: tests/conftest.py)."""
    from threadpoolctl import threadpool_info, threadpool_limits

    def threads():       # by library: the animation may load another BLAS (SciPy's) on the way
        return {info["filepath"]: info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"}

    with threadpool_limits(limits=2, user_api="blas"):
        before = threads()
        assert set(before.values()) == {2}, before
        seen = _record_blas_threads(monkeypatch)
        render_animation(AnimationConfig(frames=2, output=str(tmp_path / "sky.mp4"), **TINY), ctx=cl_context)
        assert seen == [{1}, {1}], seen
        after = threads()
        assert {path: after[path] for path in before} == before


@pytest.mark.slow
def test_one_blas_thread_gives_the_same_bytes_as_two(tmp_path, cl_context, monkeypatch, request):
    """The frames and metrics of the frame loop on one BLAS thread are byte for byte those of the same
    animation with BLAS on two threads (BLAS splits rows among threads, not the three-term sums).
    256 x 256 frames: the products' (N, 3) @ (3, 3) sizes (N ~ 51 000 valid pixels for Delta E,
    65 536 for the display) are above OpenBLAS's threshold for threading them (m n k > 262 144), so
    the two-thread run really splits them; 48-pixel frames would not. Slow: 7 s of CPU, 11-47 s wall on
    the loaded 2-core machine."""
    from threadpoolctl import threadpool_limits

    import clsky.anim.animate

    seen = _record_blas_threads(monkeypatch)
    outputs = {}
    limits = threadpool_limits(limits=2, user_api="blas")      # the session's one thread (tests/conftest.py)
    request.addfinalizer(limits.restore_original_limits)
    for name in ("one thread", "two threads"):
        if name == "two threads":
            monkeypatch.setattr(clsky.anim.animate, "host_blas_single_threaded",
                                lambda: threadpool_limits(limits=2, user_api="blas"))
        directory = tmp_path          # one output path for both: the PNGs carry the scene, output included
        config = AnimationConfig(frames=2, size=256, samples=8, table_size=TINY["table_size"],
                                 output=str(directory / "sky.mp4"), force=name == "two threads")
        render_animation(config, ctx=cl_context)
        record = json.loads((directory / "sky_metrics.json").read_text(encoding="utf-8"))
        outputs[name] = ([path.read_bytes() for path in sorted((directory / "sky_frames").iterdir())],
                         (directory / "sky_metrics.csv").read_bytes(), record["frames"], record["temporal"])
    assert seen[:2] == [{1}, {1}] and len(seen) == 4, seen
    frames, csv_bytes, rows, temporal = outputs["one thread"]
    assert len(frames) == 2 and outputs["two threads"] == (frames, csv_bytes, rows, temporal)


def _position(renders, frames):
    """Where ``frames`` (a render's dict, held in ``renders`` so that no other object takes its id) came
    in render order: its frame index."""
    return next(index for index, rendered in enumerate(renders) if rendered is frames)


def test_overlapped_frames_are_the_bytes_of_serial_ones(tmp_path, cl_context, monkeypatch):
    """The overlapped frame pipeline (clsky.anim.pipeline: frame i + 1 rendered on a worker thread while
    host threads display and compare the frames before it and the caller writes) writes byte for byte
    the PNG frames, MP4, metrics CSV and the JSON's frame rows and temporal jumps of the same animation
    rendered frame after frame on one thread: the same calls on the same inputs, consumed in order;
    with one host thread (the 2-core machine's choice) and with three (several frames displayed at
    once, the auto-exposure smoothed in order between render and display). 5 frames, so that with three
    host threads four frames are in flight while another is written and the last has no successor."""
    import time

    import clsky.anim.animate

    # earlier frames convert slower, so that with three threads later frames reach their exposure first:
    # the smoothing must still take them in frame order
    convert, renders = clsky.anim.animate.convert_frames, []
    render = clsky.anim.animate.render_frame

    def recorded_render(*args, **kwargs):
        frames = render(*args, **kwargs)
        renders.append(frames)
        return frames

    def slow_convert(renderer, config, frames):
        time.sleep(0.05 * max(0, 3 - _position(renders, frames) % 5))
        return convert(renderer, config, frames)

    monkeypatch.setattr(clsky.anim.animate, "render_frame", recorded_render)
    monkeypatch.setattr(clsky.anim.animate, "convert_frames", slow_convert)
    outputs = {}
    for workers in (None, 1, 3):                  # None: without the overlap
        renders.clear()
        monkeypatch.setattr(clsky.anim.animate, "OVERLAP_FRAMES", workers is not None)
        monkeypatch.setattr(clsky.anim.animate, "HOST_FRAME_WORKERS", workers)
        config = AnimationConfig(frames=5, output=str(tmp_path / "sky.mp4"), force=workers is not None, **TINY)
        assert config.auto_exposure
        render_animation(config, ctx=cl_context)
        record = json.loads((tmp_path / "sky_metrics.json").read_text(encoding="utf-8"))
        outputs[workers] = ([path.read_bytes() for path in sorted((tmp_path / "sky_frames").iterdir())],
                            (tmp_path / "sky.mp4").read_bytes(), (tmp_path / "sky_metrics.csv").read_bytes(),
                            record["frames"], record["temporal"])
    assert len(outputs[None][0]) == 5
    assert len({row["exposure_ev"] for row in outputs[None][3]}) > 1      # the smoothing had work to do
    assert outputs[1] == outputs[None]
    assert outputs[3] == outputs[None]


def test_suns_per_ray_march_launch_write_the_same_bytes(tmp_path, cl_context, monkeypatch):
    """An animation whose ray march takes 4 suns a launch (clsky.anim.animate.frames_rendered,
    SkyRenderer.render_raymarch_suns; the CPUs' default) writes byte for byte the frames, MP4 and metrics of
    one sun a launch: 6 frames, launches of 4 and 2 suns (the second padded to 4), with a ground (albedo 0.3)."""
    from clsky import render
    from clsky.render import SkyRenderer

    launches = []
    marched = SkyRenderer.render_raymarch_suns

    def recorded(self, directions, sun_directions, *args, **kwargs):
        launches.append(len(list(sun_directions)))
        return marched(self, directions, sun_directions, *args, **kwargs)

    monkeypatch.setattr(SkyRenderer, "render_raymarch_suns", recorded)
    outputs = {}
    for suns in (1, 4):
        launches.clear()
        monkeypatch.setattr(render, "RAY_MARCH_SUNS", suns)
        config = AnimationConfig(frames=6, ground_albedo=0.3, output=str(tmp_path / "sky.mp4"), force=suns > 1,
                                 **TINY)
        render_animation(config, ctx=cl_context)
        outputs[suns] = ([path.read_bytes() for path in sorted((tmp_path / "sky_frames").iterdir())],
                         (tmp_path / "sky.mp4").read_bytes(), (tmp_path / "sky_metrics.csv").read_bytes())
        # the animation's frames: launches of (at most) 4 suns; the plan's pilot frames and the sky-view
        # map's nodes march one sun each
        assert sorted(n for n in launches if n > 1) == ([] if suns == 1 else [2, 4]), launches
    assert len(outputs[1][0]) == 6
    assert outputs[4] == outputs[1]


def test_planned_animation_plans_the_configured_camera_and_suns():
    """planned_animation: the configuration's sun positions (or those given, passed through), its camera's
    pixel directions and valid mask, and no plan with an explicit table_size."""
    from clsky.anim.animate import planned_animation, sun_positions
    from clsky.anim.cameras import FisheyeCamera
    from clsky.anim.sunpath import SunPosition

    config = AnimationConfig(frames=3, **TINY)
    planned = planned_animation(config)
    assert planned.plan is None
    assert [(p.zenith_deg, p.azimuth_deg) for p in planned.positions] == \
        [(p.zenith_deg, p.azimuth_deg) for p in sun_positions(config)]
    directions, valid = FisheyeCamera(TINY["size"]).directions()
    assert (planned.camera.width, planned.camera.height) == (TINY["size"], TINY["size"])
    np.testing.assert_array_equal(planned.valid, valid)
    np.testing.assert_array_equal(planned.directions[valid], directions[valid])
    given = [SunPosition(80.0, 180.0)]
    assert planned_animation(config, given).positions is given


def test_frames_rendered_takes_the_suns_in_order(cl_context):
    """frames_rendered's function renders the suns in their order, once each: another sun raises."""
    from clsky.anim.animate import frames_rendered, lookup_of, make_renderer, planned_animation

    config = AnimationConfig(frames=3, **TINY)
    planned = planned_animation(config)
    positions, directions, valid = planned.positions, planned.directions, planned.valid
    renderer, _ = make_renderer(config, None, ctx=cl_context)
    with renderer:
        render = frames_rendered(renderer, renderer.prepare(directions, valid), config, lookup_of(config), positions)
        render(positions[0])
        with pytest.raises(ValueError, match="frames_rendered: sun 1 called out of order"):
            render(positions[2])


def test_host_frame_workers(monkeypatch):
    """One a core, at least one, at most MAX_HOST_FRAME_WORKERS; HOST_FRAME_WORKERS overrides; none
    without the overlap; fewer where the frames in flight would not fit the memory."""
    import clsky.anim.animate as animate

    for cores, expected in ((1, 1), (2, 2), (3, 3), (4, 4), (16, 8), (64, animate.MAX_HOST_FRAME_WORKERS)):
        monkeypatch.setattr(animate, "host_cores", lambda cores=cores: cores)
        assert animate.host_frame_workers() == expected, cores
    monkeypatch.setattr(animate, "HOST_FRAME_WORKERS", 3)
    assert animate.host_frame_workers() == 3
    monkeypatch.setattr(animate, "HOST_FRAME_WORKERS", 0)
    with pytest.raises(ValueError, match="HOST_FRAME_WORKERS"):
        animate.host_frame_workers()
    monkeypatch.setattr(animate, "HOST_FRAME_WORKERS", 4)
    monkeypatch.setattr(animate, "OVERLAP_FRAMES", False)
    assert animate.host_frame_workers() == 0
    monkeypatch.setattr(animate, "OVERLAP_FRAMES", True)
    # memory: each thread adds a frame's processing, up to one thread a frame; with room for two threads'
    # frames but not three, four threads asked for become two
    short = AnimationConfig(frames=2, size=1024, **{k: v for k, v in TINY.items() if k != "size"})
    assert animate.memory_estimate(short, animate.sun_positions(short), 4).peak_bytes() == \
        animate.memory_estimate(short, animate.sun_positions(short), 2).peak_bytes()
    config = AnimationConfig(frames=6, size=1024, **{k: v for k, v in TINY.items() if k != "size"})
    positions = animate.sun_positions(config)
    peaks = {n: animate.memory_estimate(config, positions, n).peak_bytes() for n in (1, 2, 3, 4)}
    assert peaks[1] < peaks[2] < peaks[3] < peaks[4]
    room = (peaks[2] + peaks[3]) // 2
    monkeypatch.setattr(animate, "machine_limits", lambda device=None: resources.MemoryLimits(room))
    assert animate.check_animation_memory(config, positions) == 2
    monkeypatch.setattr(animate, "machine_limits", lambda device=None: resources.MemoryLimits(peaks[1] // 2))
    with pytest.raises(resources.InsufficientMemoryError):                  # not even one thread's frames fit
        animate.check_animation_memory(config, positions)


def test_exposure_order_calls_next_ev_in_frame_order_whatever_thread_comes_first():
    """Frames shown on several threads smooth their exposures in frame order (_ExposureOrder): four
    threads started last frame first all wait for their turn; the Display sees frames 0, 1, 2, 3."""
    import threading

    from clsky.anim.animate import _ExposureOrder

    class Recording:
        def __init__(self):
            self.seen = []

        def next_ev(self, metered):
            self.seen.append(metered)
            return -metered

    pipeline = Recording()
    order = _ExposureOrder(pipeline)
    results = {}
    threads = [threading.Thread(target=lambda i=i: results.__setitem__(i, order.next_ev(i, i))) for i in (3, 2, 1, 0)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=10)
    assert not any(thread.is_alive() for thread in threads)
    assert pipeline.seen == [0, 1, 2, 3] and results == {0: 0, 1: -1, 2: -2, 3: -3}


def test_exposure_order_after_a_failure_raises_instead_of_waiting():
    """A frame that fails before its turn (fail()) releases the frames after it with an error; so does one
    whose own next_ev raises."""
    import threading

    from clsky.anim.animate import _ExposureOrder

    class Failing:
        def next_ev(self, metered):
            raise ValueError("metering")

    errors = []

    def waiting(order, index):
        try:
            order.next_ev(index, 0.0)
        except RuntimeError as error:
            errors.append(str(error))

    for cause in ("fail", "next_ev"):
        order = _ExposureOrder(Failing())
        thread = threading.Thread(target=waiting, args=(order, 1))
        thread.start()
        if cause == "fail":
            order.fail(0)
        else:
            with pytest.raises(ValueError, match="metering"):
                order.next_ev(0, 0.0)
        thread.join(timeout=10)
        assert not thread.is_alive()
    assert errors == ["frame 1 not shown: frame 0 before it failed"] * 2


def test_exposure_order_a_later_failure_lets_the_frames_before_it_go_on():
    """Frame 2 fails while frame 1 waits for frame 0: frames 0 and 1 are smoothed as usual, frame 3 raises
    naming frame 2 (the caller, taking results in order, meets frame 2's own error first)."""
    import threading

    from clsky.anim.animate import _ExposureOrder

    class Recording:
        def __init__(self):
            self.seen = []

        def next_ev(self, metered):
            self.seen.append(metered)
            return metered

    pipeline = Recording()
    order = _ExposureOrder(pipeline)
    results = {}

    def frame(index):
        try:
            results[index] = order.next_ev(index, float(index))
        except RuntimeError as error:
            results[index] = str(error)

    waiting = [threading.Thread(target=frame, args=(index,)) for index in (1, 3)]
    for thread in waiting:
        thread.start()
    order.fail(2)
    frame(0)
    for thread in waiting:
        thread.join(timeout=10)
    assert not any(thread.is_alive() for thread in waiting)
    assert pipeline.seen == [0.0, 1.0]
    assert results == {0: 0.0, 1: 1.0, 3: "frame 3 not shown: frame 2 before it failed"}


def test_a_frame_failing_on_a_host_thread_stops_the_animation_with_its_error(tmp_path, cl_context, monkeypatch):
    """Frame 2's conversion fails on one of three host threads: the animation raises that error (the
    frames after it, waiting for its exposure, stop too) and writes nothing."""
    import clsky.anim.animate

    import time

    convert, render, renders = clsky.anim.animate.convert_frames, clsky.anim.animate.render_frame, []

    def recorded_render(*args, **kwargs):
        frames = render(*args, **kwargs)
        renders.append(frames)
        return frames

    def failing(renderer, config, frames):
        index = _position(renders, frames)
        if index == 2:
            raise ArithmeticError("conversion of the third frame")
        time.sleep(0.1 if index < 2 else 0.0)     # frames 0 and 1 still converting when frame 2 fails
        return convert(renderer, config, frames)

    monkeypatch.setattr(clsky.anim.animate, "HOST_FRAME_WORKERS", 3)
    monkeypatch.setattr(clsky.anim.animate, "render_frame", recorded_render)
    monkeypatch.setattr(clsky.anim.animate, "convert_frames", failing)
    config = AnimationConfig(frames=6, output=str(tmp_path / "sky.mp4"), **TINY)
    with pytest.raises(ArithmeticError, match="third frame"):
        render_animation(config, ctx=cl_context)
    assert sorted(path.name for path in tmp_path.iterdir()) == []
