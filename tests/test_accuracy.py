"""The speed/accuracy sweep (anim/accuracy.py) and `clsky bench accuracy`."""

import csv
import subprocess
import sys

import numpy as np
import pytest

from clsky.anim import accuracy

import forked_cli


def test_pareto_front_keeps_only_undominated_rows():
    rows = [{"candidate": name, "render_s": cost, "p95_rel": error}
            for name, cost, error in (("a", 1.0, 0.5), ("b", 2.0, 0.1), ("c", 3.0, 0.2), ("d", 0.5, 0.9),
                                      ("e", 2.0, 0.05))]
    assert [r["candidate"] for r in accuracy.pareto_front(rows)] == ["d", "a", "e"]


def test_pareto_front_keeps_equal_rows_and_drops_dominated_ties():
    """Two rows equal in time and error are both undominated (the first alone was kept); a row as fast as
    another but less accurate, or as accurate but slower, is dominated."""
    rows = [{"candidate": name, "render_s": cost, "p95_rel": error}
            for name, cost, error in (("a", 1.0, 1.0), ("b", 1.0, 1.0), ("c", 1.0, 2.0), ("d", 2.0, 1.0),
                                      ("e", 0.5, 3.0))]
    assert [r["candidate"] for r in accuracy.pareto_front(rows)] == ["e", "a", "b"]


def test_the_published_sweep_and_its_readme_text_agree():
    """README "Speed versus accuracy" against docs/accuracy.csv, the fronts recomputed: the table's * marks
    are the worst-frame front; the 4D table at issue 11's size ends that front and no ray march or sky-view
    map is on it (the README said they were); ray marches and sky-view maps are on the day panel's front."""
    import pathlib

    from clsky.anim import accuracy_plot

    root = pathlib.Path(__file__).resolve().parents[1]
    rows = accuracy_plot.read_csv(root / "docs" / "accuracy.csv")
    front = accuracy.pareto_front(rows)
    assert front[-1]["candidate"] == "4D table 16 x 128 x 128 x 16"
    assert not {r["method"] for r in front} & {"raymarch", "skyview"}
    assert max(front[-1][f"p95_rel {name}"] for name in accuracy.SUN_ELEVATIONS) < 0.03
    slower = [r for r in rows if r["method"] in ("raymarch", "skyview")]
    assert min(r["render_s"] for r in slower) > front[-1]["render_s"]
    assert min(r["p95_rel civil twilight"] for r in slower) > 0.108       # "10.8 % or more"
    day = {r["method"] for r in accuracy.pareto_front(rows, error="p95_rel day")}
    assert {"raymarch", "skyview"} <= day
    readme = (root / "README.md").read_text()
    table = readme.split("<!-- bench:accuracy -->")[1].split("<!-- /bench:accuracy -->")[0]
    starred = {line.split(" | ")[0][2:-2] for line in table.splitlines() if line.startswith("| ")
               and line.split(" | ")[0].endswith(" *")}
    assert starred == {r["candidate"] for r in front}


def test_candidates_move_one_knob_each():
    candidates = accuracy.default_candidates()
    labels = [c.label for c in candidates]
    assert len(set(labels)) == len(labels) and labels[0] == "default"
    knobs = {c.knob for c in candidates}
    # the knobs the speed/accuracy issue names
    for knob in ("table size", "mapping", "view/sun steps", "sampling", "transmittance", "gather quadrature",
                 "order tolerance", "precision", "fast-math", "ray march samples", "sky-view map size"):
        assert knob in knobs


def test_4d_candidate_is_measured_with_the_4d_lookup(draft_stand_in_reference):
    """The sweep's 4D table candidates render with render_lut4d ('lut4d') and get finite errors; the
    second is at issue 11's size, a float32 export of at most 256 MB (9 channels of 4 bytes a node)."""
    reference, valid = draft_stand_in_reference
    four = [c for c in accuracy.default_candidates() if c.knob == "parameterization"]
    assert len(four) == 2 and all(c.table.is_4d and c.method == "lut4d" for c in four)
    sized = four[1].table
    assert sized.size == accuracy.LOOKUP4D_SIZE and sized.azimuth_size == accuracy.LOOKUP4D_AZIMUTHS
    assert 150e6 < np.prod(sized.size) * sized.azimuth_size * 9 * 4 <= 256e6
    tiny = accuracy.Candidate("4D", "parameterization", four[0].table.replace(size=(9, 34, 9), azimuth_size=5))
    row, = accuracy.measure([tiny], reference, valid)
    assert row["method"] == "lut4d" and np.isfinite(row["p95_rel"]) and row["p95_rel"] >= 0


def _tiny_rows(reference, valid, march_table=None):
    default = accuracy.default_candidates()[0].table
    small = accuracy.Candidate("small table", "table size", default.replace(size=(9, 33, 9)))
    march = accuracy.Candidate("ray march 48", "ray march samples", march_table or default, samples=48)
    view = accuracy.Candidate("sky-view 64 x 128", "sky-view map size", default, skyview=(64, 128))
    rows = accuracy.measure([small, march, view], reference, valid)
    assert [r["method"] for r in rows] == ["lut", "raymarch", "skyview"]
    for row in rows:
        assert row["build_s"] > 0 and row["render_s"] > 0 and row["mean_delta_e"] >= 0
        assert row["p95_rel"] == max(row[f"p95_rel {name}"] for name in accuracy.SUN_ELEVATIONS)
    return rows


def test_the_sweep_reports_progress_from_its_first_table(monkeypatch, draft_stand_in_reference):
    """`clsky bench accuracy` showed no bar through the reference's four tables (minutes) and the first
    candidate: its first report came after that candidate. The reference now reports before its first
    table and after each frame, the candidates before the first table and after each."""
    import clsky

    calls = []

    class Renderer:                                  # the reference's renderer, recording what it does
        def __init__(self, elevation, *args):
            calls.append(("table", elevation))

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def prepare(self, directions, valid):
            return None

        def render_raymarch(self, prepared, sun, altitude):
            return np.zeros((16, 16, 3))

    with monkeypatch.context() as patch:
        patch.setattr(accuracy, "reference_renderer", Renderer)
        accuracy.render_reference(16, progress=lambda *report: calls.append(report))
    frames = len(accuracy.SUN_ELEVATIONS)
    expected = [("reference", 0, frames)]
    for index, elevation in enumerate(accuracy.SUN_ELEVATIONS.values()):
        expected += [("table", elevation), ("reference", index + 1, frames)]
    assert calls == expected
    calls.clear()
    build = clsky.ScatteringTable.build
    monkeypatch.setattr(clsky.ScatteringTable, "build", lambda *a, **k: calls.append(("build",)) or build(*a, **k))
    reference, valid = draft_stand_in_reference
    tiny = accuracy.Candidate("tiny", "table size", clsky.TableSettings(size=(8, 32, 8), orders=1, mode="physical"))
    accuracy.measure([tiny, tiny], reference, valid, progress=lambda *report: calls.append(report))
    assert calls == [("candidates", 0, 2), ("build",), ("candidates", 1, 2), ("build",), ("candidates", 2, 2)]


def test_measure_gives_every_column(draft_stand_in_reference):
    """The sweep's rows: the renderer, times, and the worst p95 as the maximum over the elevations
    (the draft stand-in and a small table under the ray march: plumbing, not numbers)."""
    small = accuracy.default_candidates()[0].table.replace(size=(9, 33, 9))
    _tiny_rows(*draft_stand_in_reference, march_table=small)


@pytest.mark.slow      # the 'default' stand-in reference carries M = 2: ~170 s to build at load 3
def test_measure_on_tiny_frames(stand_in_reference):
    rows = _tiny_rows(*stand_in_reference)
    # The ray march (48 samples) over the default TableSettings follows the stand-in reference within
    # 0.5 % by day (measured 0.3 %); in twilight its 32 whole-axis sun nodes feed the higher orders
    # coarsely (measured 4.2 %, README "Quality levels"), while a 9 x 33 x 9 table looked up misses
    # twilight by far (measured: hundreds of %).
    assert rows[1]["p95_rel day"] < 0.005
    assert rows[1]["p95_rel"] < 0.1
    assert rows[0]["p95_rel civil twilight"] > 10 * rows[1]["p95_rel civil twilight"]
    # The sky-view map is the same 48-sample ray march at its nodes, read bilinearly: each frame's error
    # stays within 0.5 % (absolute, of p95) of the ray march's (its own difference from the ray march
    # is 0.07 to 0.16 %, tests/test_skyview.py). Measured (sky-view / ray march p95): day 0.059 / 0.011 %,
    # golden hour 0.069 / 0.026 %, sunset 0.497 / 0.473 %, civil twilight 5.361 / 5.267 %.
    for name in accuracy.SUN_ELEVATIONS:
        assert abs(rows[2][f"p95_rel {name}"] - rows[1][f"p95_rel {name}"]) < 0.005, name


@pytest.mark.parametrize("args,named", [(["--size", "8"], "--size"), (["-o", "x.txt"], "--output"),
                                        (["--plot", "x.jpg"], "--plot"),
                                        (["--elevation-plot", "x.jpg"], "--elevation-plot"),
                                        (["--elevation-plot", "accuracy.png"], "--elevation-plot"),
                                        # "PosixPath('.') has an empty name", the elevation plot's derived from
                                        # an unchecked --plot; an empty --elevation-plot took the default
                                        (["--plot", ""], "--plot must be a file path, got an empty one"),
                                        (["--plot", "."], "--plot must end in .png"),
                                        (["--plot", "/"], "--plot must end in .png"),
                                        (["--elevation-plot", ""], "--elevation-plot must be a file path")])
def test_bench_accuracy_bad_arguments(tmp_path, args, named):
    result = forked_cli.run("clsky.anim", "bench", "accuracy", *args, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and named in result.stderr, result.stderr
    assert list(tmp_path.iterdir()) == []


def test_bench_accuracy_checks_the_derived_elevation_plot_before_work(tmp_path):
    """--elevation-plot defaults to <--plot stem>_elevation.png; an existing one stops the run at once
    (before the minutes of the sweep), naming the option, and nothing else is written."""
    (tmp_path / "sky_elevation.png").write_bytes(b"kept")
    result = subprocess.run([sys.executable, "-m", "clsky.anim", "bench", "accuracy", "--plot", "sky.png"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.startswith("clsky: error: --elevation-plot") and "sky_elevation.png exists" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sky_elevation.png"]
    assert (tmp_path / "sky_elevation.png").read_bytes() == b"kept"


@pytest.mark.slow
def test_bench_accuracy_quick_run_writes_csv_and_plot(tmp_path):
    pytest.importorskip("matplotlib")
    result = subprocess.run([sys.executable, "-m", "clsky.anim", "bench", "accuracy", "--quick", "--size", "16",
                             "--reference-quality", "default", "--progress", "none"], cwd=tmp_path,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    with open(tmp_path / "accuracy.csv") as stream:
        rows = list(csv.DictReader(stream))
    assert [r["candidate"] for r in rows] == ["default", "ray march 16 samples", "ray march 48 samples",
                                              "sky-view 32 x 64"]
    assert rows[-1]["method"] == "skyview"
    for name in ("accuracy.png", "accuracy_elevation.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # what the numbers are against, which the CSV does not say
    assert result.stdout.splitlines()[-1] == ("4 candidates on 16 x 16 frames, against the 'default' level's -> "
                                              "accuracy.csv, accuracy.png, accuracy_elevation.png")


# --- the plots (anim/accuracy_plot.py), on hand-made rows: no OpenCL, no sweep ---------------------------

def synthetic_rows():
    """Seven candidates with a known front (worst error against render time): 'fast' (1 ms, 50 %),
    'middle' (2 ms, 10 %) and 'slow' (8 ms, 1 %); 'cluster a/b/c' sit right of 'fast' at the same
    error as each other (dominated by 'fast' or 'middle'), 'march 2' is dominated by 'middle'. Per
    elevation, the errors fall with the sun's height by the row's own factor, worst at -4 deg."""
    spec = (("fast", "table size", "lut", 1.0, 0.5), ("cluster a", "table size", "lut", 1.05, 0.6),
            ("cluster b", "mapping", "lut", 1.06, 0.6), ("cluster c", "sampling", "lut", 1.07, 0.6),
            ("middle", "ray march samples", "raymarch", 2.0, 0.1),
            ("march 2", "ray march samples", "raymarch", 3.0, 0.2),
            ("slow", "ray march samples", "raymarch", 8.0, 0.01))
    rows = []
    for index, (name, knob, method, ms, worst) in enumerate(spec):
        row = {"candidate": name, "knob": knob, "method": method, "build_s": 1.0, "render_s": ms / 1e3,
               "p95_rel": worst, "mean_delta_e": 1.0}
        for name_e, elevation in accuracy.SUN_ELEVATIONS.items():
            # -4 deg: worst; higher suns smaller by (2 + index / 10) per 10 deg above -4
            row[f"p95_rel {name_e}"] = worst / (2 + index / 10) ** ((elevation + 4) / 10)
        rows.append(row)
    return rows


SYNTHETIC_FRONT = ["fast", "middle", "slow"]


def test_front_of_the_synthetic_rows():
    assert [r["candidate"] for r in accuracy.pareto_front(synthetic_rows())] == SYNTHETIC_FRONT


def test_stack_labels_least_squares_with_gaps():
    from clsky.anim.accuracy_plot import stack_labels

    # two at 0.5, gap 0.1: 0.45 and 0.55 (centred, least squares); apart already: unchanged
    np.testing.assert_allclose(stack_labels([0.5, 0.5], 0.1), [0.45, 0.55], rtol=0, atol=1e-12)
    np.testing.assert_allclose(stack_labels([0.9, 0.1], 0.1), [0.9, 0.1], rtol=0, atol=1e-12)
    # three at 0.5 and one at 0.52 (unsorted input): pooled mean 0.505, spread by 0.1 around it
    np.testing.assert_allclose(stack_labels([0.52, 0.5, 0.5, 0.5], 0.1), [0.655, 0.355, 0.455, 0.555],
                               rtol=0, atol=1e-12)
    # at the top edge: pushed down into [0, 1]
    np.testing.assert_allclose(stack_labels([1.0, 1.0], 0.1), [0.9, 1.0], rtol=0, atol=1e-12)


def test_pareto_figure_labels_only_the_front():
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from matplotlib.text import Text

    from clsky.anim.accuracy_plot import draw_pareto

    rows = synthetic_rows()
    figure = draw_pareto(rows, size=32)
    try:
        panels = figure.axes
        assert len(panels) == 1 + len(accuracy.SUN_ELEVATIONS)
        for axes, error in zip(panels, ["p95_rel"] + [f"p95_rel {n}" for n in accuracy.SUN_ELEVATIONS]):
            front = [r["candidate"] for r in accuracy.pareto_front(rows, error=error)]
            assert [t.get_text() for t in axes.texts] == front
            # each label points at its own candidate's (render time [ms], error [%])
            for text, name in zip(axes.texts, front):
                row = next(r for r in rows if r["candidate"] == name)
                np.testing.assert_allclose(text.xy, (1e3 * row["render_s"], 100 * row[error]), rtol=1e-12)
            # no two labels overlap on the canvas (the text's box, without its leader line)
            figure.canvas.draw()
            boxes = [Text.get_window_extent(t) for t in axes.texts]
            for i, first in enumerate(boxes):
                assert not any(first.overlaps(second) for second in boxes[i + 1:]), axes.get_title()
        # every candidate is drawn: the markers of each knob, together, are all the rows
        offsets = np.concatenate([c.get_offsets() for c in panels[0].collections])
        assert len(offsets) == len(rows)
        legend = [t.get_text() for t in figure.legends[0].get_texts()]
        assert legend == ["table size", "mapping", "sampling", "ray march samples", "Pareto front (labelled)"]
    finally:
        plt.close(figure)


def test_worst_frame_front_labels_do_not_overlap_in_a_tie():
    """Two front points at nearly the same place (as 'sun steps 60' and 'sun rays re-marched' in the
    published sweep, 0.01 % apart): their labels are stacked one line apart, not on top of each other."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from matplotlib.text import Text

    from clsky.anim.accuracy_plot import draw_pareto

    rows = synthetic_rows()
    rows[1].update(render_s=1.001e-3, p95_rel=0.4999)            # 'cluster a' joins the front beside 'fast'
    figure = draw_pareto(rows)
    try:
        axes = figure.axes[0]
        assert [t.get_text() for t in axes.texts] == ["fast", "cluster a", "middle", "slow"]
        figure.canvas.draw()
        first, second = (Text.get_window_extent(t) for t in axes.texts[:2])
        assert not first.overlaps(second)
    finally:
        plt.close(figure)


def test_front_labels_stay_inside_their_panels_and_the_legend_inside_its_figure():
    """The published sweep's plots (docs/accuracy.csv): a golden-hour label ran off the figure's edge ('4D
    table 16 x 128 x 1'), day-panel labels into the next panel, and the elevation legend's '4D table
    lookup: 4D table ...' off its figure. Every front label's text lies within its panel, none overlaps
    another, and the legend lies within the figure."""
    pytest.importorskip("matplotlib")
    import pathlib

    import matplotlib.pyplot as plt
    from matplotlib.text import Text

    from clsky.anim.accuracy_plot import draw_elevation, draw_pareto, read_csv

    rows = read_csv(pathlib.Path(__file__).resolve().parents[1] / "docs" / "accuracy.csv")
    figure = draw_pareto(rows, size=64)
    try:
        figure.canvas.draw()
        renderer = figure.canvas.get_renderer()
        for axes in figure.axes:
            panel = axes.get_window_extent()
            labels = [Text.get_window_extent(t, renderer) for t in axes.texts
                      if str(t.get_gid()).startswith("front:")]
            assert labels, axes.get_title()
            for label in labels:        # half a pixel: the rounding of the extents
                assert panel.x0 - 0.5 <= label.x0 and label.x1 <= panel.x1 + 0.5, (axes.get_title(), label)
                assert panel.y0 - 0.5 <= label.y0 and label.y1 <= panel.y1 + 0.5, (axes.get_title(), label)
            assert not any(a.overlaps(b) for i, a in enumerate(labels) for b in labels[i + 1:]), axes.get_title()
    finally:
        plt.close(figure)
    figure = draw_elevation(rows)
    try:
        figure.canvas.draw()
        legend = figure.axes[0].get_legend().get_window_extent(figure.canvas.get_renderer())
        assert 0 <= legend.x0 and legend.x1 <= figure.bbox.width and 0 <= legend.y0 <= legend.y1 <= figure.bbox.height
        assert "4D table 16 x 128 x 128 x 16" in figure.axes[0].get_legend_handles_labels()[1]
    finally:
        plt.close(figure)


def test_tick_labels_of_a_narrow_panel_do_not_overlap():
    """A --quick sweep's times span less than a decade: matplotlib labelled the minor ticks of the small
    panels ('2x10^0 3x10^04x10^0', overlapping, larger than the major label). Such an axis has plain labels
    at 1, 2 and 5 times the powers of ten, none overlapping, all at the panel's font size."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from clsky.anim.accuracy_plot import draw_pareto

    narrow = synthetic_rows()
    for row, ms in zip(narrow, (2.0, 2.2, 2.4, 2.6, 3.0, 3.5, 4.0)):
        row["render_s"] = ms / 1e3
    for rows in (narrow, synthetic_rows()):         # 2-4 ms, and 1-8 ms: one power of ten on the axis
        figure = draw_pareto(rows)
        try:
            figure.canvas.draw()
            renderer = figure.canvas.get_renderer()
            for axes in figure.axes:
                shown = [label for label in axes.get_xticklabels(which="both") if label.get_text()
                         and axes.get_xlim()[0] <= label.get_position()[0] <= axes.get_xlim()[1]]
                assert shown, axes.get_title()
                assert all("times" not in label.get_text() and "^" not in label.get_text() for label in shown)
                extents = [label.get_window_extent(renderer) for label in shown]
                assert not any(a.overlaps(b) for i, a in enumerate(extents) for b in extents[i + 1:]), \
                    axes.get_title()
                assert len({label.get_fontsize() for label in shown}) == 1
        finally:
            plt.close(figure)


def test_labels_of_a_long_front_and_of_a_long_name_stay_inside_their_panels():
    """A front of 14 candidates with two-line names ran down through the panels below and off the figure,
    and a name without spaces wider than its panel out of it: the labels shrink to fit the panel's height
    and a word is cut where it must be."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt
    from matplotlib.text import Text

    from clsky.anim.accuracy_plot import draw_pareto

    rows = []
    for index in range(14):
        row = dict(synthetic_rows()[0], candidate=f"candidate {index} with a name long enough for two lines here",
                   render_s=(1.0 + index) / 1e3, p95_rel=0.5 / (1.0 + index))
        row.update({f"p95_rel {name}": row["p95_rel"] for name in accuracy.SUN_ELEVATIONS})
        rows.append(row)
    rows[3]["candidate"] = "x" * 80
    figure = draw_pareto(rows)
    try:
        figure.canvas.draw()
        renderer = figure.canvas.get_renderer()
        for axes in figure.axes:
            panel = axes.get_window_extent()
            labels = [Text.get_window_extent(t, renderer) for t in axes.texts if str(t.get_gid()).startswith("front:")]
            assert len(labels) == 14, axes.get_title()
            for label in labels:
                assert panel.x0 - 0.5 <= label.x0 and label.x1 <= panel.x1 + 0.5, (axes.get_title(), label)
                assert panel.y0 - 0.5 <= label.y0 and label.y1 <= panel.y1 + 0.5, (axes.get_title(), label)
    finally:
        plt.close(figure)


def test_a_sweeps_files_say_what_they_compare_with(tmp_path, monkeypatch):
    """`clsky bench accuracy --reference-quality default` and bench_accuracy.py --smoke drew plots titled as
    if against the reference level (only the summary line said otherwise, and the script's own copy of
    the writing not even that): one writer (write_sweep) titles both plots by the level."""
    pytest.importorskip("matplotlib")
    from clsky.anim import accuracy_plot

    assert accuracy_plot.sweep_titles() == ("clsky: speed versus accuracy", "clsky: where each renderer fails")
    titles = []
    for name in ("draw_pareto", "draw_elevation"):
        draw = getattr(accuracy_plot, name)
        monkeypatch.setattr(accuracy_plot, name, lambda rows, *a, _draw=draw, **k: titles.append(a[-1]) or
                            _draw(rows, *a, **k))
    written = accuracy_plot.write_sweep(synthetic_rows(), tmp_path / "a.csv", tmp_path / "a.png",
                                        tmp_path / "a_elevation.png", 16, "draft")
    assert titles == ["clsky: speed versus accuracy (against the 'draft' level)",
                      "clsky: where each renderer fails (against the 'draft' level)"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "a.png", "a_elevation.png"]
    assert [p.name for p in written] == ["a.csv", "a.png", "a_elevation.png"]


def test_elevation_figure_draws_a_lone_candidate_and_names_zero_errors():
    """A renderer with one candidate, off the front, had a band of no height: its errors were drawn nowhere,
    while the legend listed 'all 1 candidates (range)'; a zero error vanished from the log axis unnamed."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from clsky.anim.accuracy_plot import draw_elevation

    rows = synthetic_rows()
    rows = [r for r in rows if r["method"] == "lut"] + [r for r in rows if r["candidate"] in ("slow", "march 2")]
    rows.append(dict(rows[0], candidate="sky-view 8 x 8", knob="sky-view map size", method="skyview",
                     render_s=0.5, p95_rel=0.9, **{"p95_rel day": 0.0}))
    figure = draw_elevation(rows)
    try:
        axes = figure.axes[0]
        lone = [line for line in axes.get_lines() if line.get_gid() == "only:sky-view 8 x 8"]
        assert len(lone) == 1
        order = sorted(accuracy.SUN_ELEVATIONS, key=accuracy.SUN_ELEVATIONS.get)
        np.testing.assert_allclose(lone[0].get_ydata(), [100 * rows[-1][f"p95_rel {n}"] for n in order])
        labels = axes.get_legend_handles_labels()[1]
        assert "sky-view 8 x 8 (its one candidate)" in labels and not any("all 1 " in label for label in labels)
        assert "ray march: all 2 candidates (range)" in labels
        named = [t.get_text() for t in axes.texts if t.get_gid() == "hidden"]
        assert named == ["not shown (0 on a log axis): sky-view 8 x 8 (day)"]
    finally:
        plt.close(figure)


def test_elevation_figure_has_one_line_per_front_candidate():
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from clsky.anim.accuracy_plot import draw_elevation

    rows = synthetic_rows()
    figure = draw_elevation(rows)
    try:
        axes = figure.axes[0]
        lines = [line for line in axes.get_lines() if str(line.get_gid()).startswith("front:")]
        assert [line.get_gid() for line in lines] == [f"front:{n}" for n in SYNTHETIC_FRONT]
        order = sorted(accuracy.SUN_ELEVATIONS, key=accuracy.SUN_ELEVATIONS.get)
        for line, name in zip(lines, SYNTHETIC_FRONT):
            row = next(r for r in rows if r["candidate"] == name)
            np.testing.assert_array_equal(line.get_xdata(), [accuracy.SUN_ELEVATIONS[n] for n in order])
            np.testing.assert_allclose(line.get_ydata(), [100 * row[f"p95_rel {n}"] for n in order], rtol=1e-12)
        # the horizon (a vertical line at 0) and civil twilight (a span from -6 to 0 deg)
        horizon = [line for line in axes.get_lines() if line.get_label() == "horizon"]
        assert len(horizon) == 1 and list(horizon[0].get_xdata()) == [0, 0]
        labels = axes.get_legend_handles_labels()[1]
        assert "table lookup: all 4 candidates (range)" in labels and "ray march: all 3 candidates (range)" in labels
        assert axes.get_yscale() == "log"
    finally:
        plt.close(figure)


def test_plots_from_a_csv_are_written_atomically(tmp_path):
    pytest.importorskip("matplotlib")
    from clsky.anim import writers
    from clsky.anim.accuracy_plot import plot_csv, read_csv

    rows = synthetic_rows()
    writers.write_csv(tmp_path / "sweep.csv", rows)
    assert read_csv(tmp_path / "sweep.csv") == rows                # floats round-trip exactly through the CSV
    plot, elevation = plot_csv(tmp_path / "sweep.csv", tmp_path / "a.png", size=32)
    assert elevation == tmp_path / "a_elevation.png"
    for path in (plot, elevation):
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    before = {path: path.read_bytes() for path in (plot, elevation)}
    # existing files without force: refused before drawing, both left as they were, no temporary left over
    with pytest.raises(FileExistsError):
        plot_csv(tmp_path / "sweep.csv", tmp_path / "new.png", elevation, size=32)
    assert not (tmp_path / "new.png").exists()
    assert {path: path.read_bytes() for path in (plot, elevation)} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "a_elevation.png", "sweep.csv"]


def test_read_csv_names_a_bad_cell(tmp_path):
    from clsky.anim.accuracy_plot import read_csv

    path = tmp_path / "sweep.csv"
    path.write_text("candidate,knob,method,render_s,p95_rel,p95_rel day\nx,k,lut,1e-3,0.1,0.01\n")
    with pytest.raises(ValueError, match="missing columns"):
        read_csv(path)
    columns = ["candidate", "knob", "method", "render_s", "p95_rel"] + [f"p95_rel {n}" for n in accuracy.SUN_ELEVATIONS]
    path.write_text(",".join(columns) + "\n" + "x,k,lut,fast,0.1,0.1,0.1,0.1,0.1\n")
    with pytest.raises(ValueError, match="line 2: column 'render_s'"):
        read_csv(path)
    # NaN, infinite and negative numbers drew plots of nothing; non-UTF-8 bytes ended in UnicodeDecodeError
    for cell in ("nan", "-inf", "1e400", "-1e-3"):
        path.write_text(",".join(columns) + "\n" + f"x,k,lut,{cell},0.1,0.1,0.1,0.1,0.1\n")
        with pytest.raises(ValueError, match=f"line 2: column 'render_s' must be a finite number >= 0, got '{cell}'"):
            read_csv(path)
    path.write_bytes(b"candidate,\xff\n")
    with pytest.raises(ValueError, match="sweep.csv: not a CSV file \\(not UTF-8 text\\)"):
        read_csv(path)


def test_a_zero_error_is_named_not_drawn_on_the_log_axes():
    """An exact match (error 0) has no place on a log axis: the panel leaves it out and names it; the
    front of the rest is labelled as before, and both figures draw without error."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from clsky.anim.accuracy_plot import draw_elevation, draw_pareto

    rows = synthetic_rows()
    rows[6]["p95_rel day"] = 0.0                                   # 'slow' matches the reference by day
    day = f"sun {accuracy.SUN_ELEVATIONS['day']:g} deg"
    figure = draw_pareto(rows)
    try:
        axes = next(a for a in figure.axes if day in a.get_title())
        hidden = [t for t in axes.texts if t.get_gid() == "hidden"]
        assert len(hidden) == 1 and hidden[0].get_text().endswith(": slow")
        labels = [t.get_text() for t in axes.texts if t.get_gid() != "hidden"]
        assert labels == [r["candidate"] for r in accuracy.pareto_front(rows[:6], error="p95_rel day")]
        figure.canvas.draw()
    finally:
        plt.close(figure)
    figure = draw_elevation(rows)
    try:
        figure.canvas.draw()
    finally:
        plt.close(figure)


def test_skyview_candidates_get_their_own_markers_and_band():
    """Sky-view rows (method 'skyview'): purple diamonds in the Pareto plot, and their own front line in the
    elevation plot, beside the lookups' and the ray marches' (and their band where they are several)."""
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from clsky.anim.accuracy_plot import draw_elevation, knob_styles

    rows = synthetic_rows()
    errors = {f"p95_rel {n}": 0.001 for n in accuracy.SUN_ELEVATIONS}
    rows.append({"candidate": "sky-view 64 x 128", "knob": "sky-view map size", "method": "skyview",
                 "build_s": 1.0, "render_s": 0.5e-3, "p95_rel": 0.001, "mean_delta_e": 0.1, **errors})
    styles = knob_styles(rows)
    assert styles["sky-view map size"] == ("purple", "D")
    assert all(marker != "D" for knob, (_, marker) in styles.items() if knob != "sky-view map size")
    figure = draw_elevation(rows)
    try:
        labels = figure.axes[0].get_legend_handles_labels()[1]
        # fastest and best: on the front, its line named as the candidate names itself; one candidate draws
        # no band (of no height, once listed as 'all 1 candidates (range)')
        assert "sky-view 64 x 128" in labels and not any(label.startswith("sky-view map") for label in labels)
    finally:
        plt.close(figure)
