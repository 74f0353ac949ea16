"""The plots of the speed/accuracy sweep (:mod:`clsky.anim.accuracy`): the Pareto plot and error versus sun elevation.

Both read the sweep's rows (:func:`clsky.anim.accuracy.measure`, or its CSV through :func:`read_csv`):

- :func:`pareto_plot`: error against render time (log-log), one panel for the worst of the frames and one
  per sun elevation (:data:`clsky.anim.accuracy.SUN_ELEVATIONS`). Only the candidates on each panel's Pareto
  front carry a text label, stacked so that no two labels overlap (:func:`stack_labels`) and tied to
  their points by a leader line; every other candidate is an unlabelled marker whose colour and shape
  name its knob in the legend (the numbers of each: the README's table, or the CSV).
- :func:`elevation_plot`: the 95th-percentile error against sun elevation, one line per candidate on the
  worst-frame Pareto front, over a band per renderer (table lookup, ray march) spanning all of its
  candidates; the horizon and civil twilight (sun 0 to 6 deg below the horizon) are marked.

matplotlib draws them (Agg backend), the ``bench`` extra: ``pip install 'clsky[bench]'``. The files are
written atomically (:func:`clsky._files.atomic_write`), checked before the drawing.
"""

from __future__ import annotations

import csv
import io
import math
import pathlib

import numpy as np

from clsky._files import read_user_text
from clsky.errors import require_extra

from .accuracy import SUN_ELEVATIONS, pareto_front

__all__ = ["read_csv", "stack_labels", "knob_styles", "draw_pareto", "draw_elevation", "pareto_plot",
           "elevation_plot", "elevation_plot_path", "plot_csv", "sweep_titles", "write_sweep"]

#: Civil twilight: the sun between 0 and 6 deg below the horizon [deg] (the usual definition).
CIVIL_TWILIGHT = (-6.0, 0.0)
#: Text columns of the sweep's CSV; every other column is a number.
TEXT_COLUMNS = ("candidate", "knob", "method")
RENDERERS = {"lut": "table lookup", "raymarch": "ray march", "lut4d": "4D table lookup", "skyview": "sky-view map"}
#: Colour maps of the lines of each renderer in the elevation plot.
RENDERER_COLOURS = {"lut": "Blues", "raymarch": "Oranges", "lut4d": "Greens", "skyview": "Purples"}
#: Sun elevations within this many degrees of the horizon get a linear axis in the elevation plot; beyond
#: it the axis is logarithmic (symlog), so that twilight, sunset and golden hour are not squeezed by day.
ELEVATION_LINEAR = 10.0
#: How far along its row [axes fraction] a front label moves to clear the markers beside its point.
CLEARANCE = 0.3
#: The smallest font [pt] a panel's front labels shrink to where they do not fit its height.
MIN_LABEL_FONTSIZE = 4.0


def _pyplot():
    require_plotting()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def require_plotting():
    """ImportError saying how to install matplotlib (the ``bench`` extra) when it is missing: called
    by ``clsky bench accuracy`` before it measures anything."""
    require_extra("matplotlib", "the accuracy plots", "pip install 'clsky[bench]'")


def read_csv(path):
    """The rows of a sweep's CSV (:func:`clsky.anim.writers.write_csv` of :func:`clsky.anim.accuracy.measure`): a list
    of dicts, numbers as float. Raises ValueError naming the file and column when a number does not parse or
    is no finite number >= 0 (times, errors: a NaN or a negative time drew a plot of nothing), a column the
    plots need (render time, worst and per-elevation errors) is missing, or the file is no UTF-8 text."""
    try:
        text = read_user_text(path)
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a CSV file (not UTF-8 text)") from None
    rows = list(csv.DictReader(io.StringIO(text, newline="")))
    needed = {"candidate", "knob", "method", "render_s", "p95_rel"} | {f"p95_rel {n}" for n in SUN_ELEVATIONS}
    missing = sorted(needed - set(rows[0] if rows else ()))
    if missing:
        raise ValueError(f"{path}: no rows, or missing columns {missing}")
    parsed = []
    for line, row in enumerate(rows, start=2):
        entry = {}
        for key, value in row.items():
            if key in TEXT_COLUMNS:
                entry[key] = value
                continue
            try:
                entry[key] = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"{path}, line {line}: column {key!r} is not a number: {value!r}") from None
            if not 0.0 <= entry[key] < math.inf:
                raise ValueError(f"{path}, line {line}: column {key!r} must be a finite number >= 0, got {value!r}")
        parsed.append(entry)
    return parsed


def stack_labels(positions, spacing, low=0.0, high=1.0, heights=None):
    """Label positions along one axis, as close as possible to ``positions`` (least squares) with at
    least ``spacing`` between any two, then moved inside [``low``, ``high``] where they fit.

    The order is kept: sorted, the labels must satisfy p[i+1] - p[i] >= g[i] (``spacing``); with
    q[i] = p[i] - (g[0] + ... + g[i-1]) that is q non-decreasing, so the least-squares fit is the isotonic
    regression of those differences (pool-adjacent-violators). With ``heights`` (each label's, in the order
    of ``positions``), the gap between two neighbours is the mean of their heights instead, and each label's
    extent (its position -+ half its height) is kept inside [``low``, ``high``]. Returns an array in the
    order of ``positions``."""
    positions = np.asarray(positions, dtype=float)
    order = np.argsort(positions, kind="stable")
    if heights is None:
        gaps, half = np.full(max(len(positions) - 1, 0), float(spacing)), np.zeros(len(positions))
    else:
        sorted_heights = np.asarray(heights, dtype=float)[order]
        gaps, half = (sorted_heights[:-1] + sorted_heights[1:]) / 2, sorted_heights / 2
    offsets = np.concatenate([[0.0], np.cumsum(gaps)])[:len(positions)]
    target = positions[order] - offsets
    blocks = []                                     # [mean, count] of pooled runs
    for value in target:
        blocks.append([value, 1])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            mean, count = blocks.pop()
            blocks[-1] = [(blocks[-1][0] * blocks[-1][1] + mean * count) / (blocks[-1][1] + count),
                          blocks[-1][1] + count]
    fitted = np.concatenate([np.full(count, mean) for mean, count in blocks]) if blocks else np.empty(0)
    stacked = fitted + offsets
    for index in range(len(stacked)):               # inside [low, high]: push up from low, then down from high
        stacked[index] = max(stacked[index], low + half[index] if index == 0 else stacked[index - 1] + gaps[index - 1])
    for index in reversed(range(len(stacked))):
        stacked[index] = min(stacked[index], high - half[index] if index == len(stacked) - 1
                             else stacked[index + 1] - gaps[index])
    result = np.empty_like(stacked)
    result[order] = stacked
    return result


def knob_styles(rows):
    """{knob: (colour, marker)}: the table-lookup knobs as circles in ten colours (other shapes beyond
    ten), the ray-march knobs as squares in dark colours of their own, the 4D-lookup knobs as green
    filled pluses, the sky-view knobs as purple diamonds."""
    import matplotlib

    colours = matplotlib.colormaps["tab10"].colors
    dark = ("black", "0.45", "saddlebrown", "darkslategray")
    shapes = "o^vD<>"
    styles = {}
    for method in RENDERERS:
        knobs = list(dict.fromkeys(r["knob"] for r in rows if r["method"] == method))
        for i, knob in enumerate(knobs):
            if method == "lut":
                styles[knob] = (colours[i % 10], shapes[(i // 10) % len(shapes)])
            elif method == "lut4d":
                styles[knob] = (("forestgreen", "darkolivegreen")[i % 2], "P")
            elif method == "skyview":
                styles[knob] = (("purple", "indigo")[i % 2], "D")
            else:
                styles[knob] = (dark[i % len(dark)], "s")
    return styles


def _limits(values, margin):
    """Log-axis limits around ``values``, ``margin`` decades beyond them."""
    low, high = np.log10(min(values)), np.log10(max(values))
    return 10 ** (low - margin), 10 ** (high + margin)


def _pareto_panel(axes, rows, error, styles, fontsize):
    """One panel: every candidate by knob, its Pareto front joined and labelled (labels stacked). A log
    axis cannot show a zero error or time: such rows (an exact match, a timer too coarse) are left out
    of the panel and named in its corner."""
    hidden = [r["candidate"] for r in rows if not (r[error] > 0 and r["render_s"] > 0)]
    rows = [r for r in rows if r["candidate"] not in hidden]
    if hidden:
        axes.text(0.99, 0.01, "not shown (0 on a log axis): " + ", ".join(hidden), transform=axes.transAxes,
                  ha="right", va="bottom", fontsize=fontsize, color="0.3", gid="hidden")
    if not rows:
        return
    times = [1e3 * r["render_s"] for r in rows]
    errors = [100 * r[error] for r in rows]
    front = pareto_front(rows, error=error)
    front_names = {r["candidate"] for r in front}
    for knob, (colour, marker) in styles.items():
        chosen = [r for r in rows if r["knob"] == knob]
        axes.scatter([1e3 * r["render_s"] for r in chosen], [100 * r[error] for r in chosen], s=22, color=colour,
                     marker=marker, edgecolors=["k" if r["candidate"] in front_names else "none" for r in chosen],
                     linewidths=0.8, label=knob, zorder=3)
    axes.plot([1e3 * r["render_s"] for r in front], [100 * r[error] for r in front], "k--", lw=0.7, zorder=2,
              label="Pareto front (labelled)")
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.set_xlim(*_limits(times, 0.08))
    axes.set_ylim(*_limits(errors, 0.25))
    axes.grid(True, which="both", lw=0.3, alpha=0.6)
    for axis, (low, high) in ((axes.xaxis, axes.get_xlim()), (axes.yaxis, axes.get_ylim())):
        # fewer than two powers of ten on the axis: matplotlib labels the minor ticks, '2x10^0 3x10^04x10^0'
        if math.floor(math.log10(high)) - math.ceil(math.log10(low)) < 1:
            _plain_ticks(axis)
    axes.tick_params(which="both", labelsize=fontsize + 1)
    # labels: stacked in axes coordinates, at least one label's lines apart, right of their point (left of
    # it in the right part of the panel, or where it fits) and clear of the markers in their row nearby,
    # inside the panel (a label too long for it is wrapped), each on a white box with a leader line
    box = axes.get_window_extent()
    line = 1.4 * fontsize * axes.figure.dpi / 72.0 / box.height      # text line height [axes fraction]
    to_axes = axes.transAxes.inverted()
    markers = to_axes.transform(axes.transData.transform(np.column_stack([times, errors])))
    points = to_axes.transform(axes.transData.transform([(1e3 * r["render_s"], 100 * r[error]) for r in front]))
    offset = 10.0 / box.width
    for _ in range(4):          # a smaller font where the front's labels do not fit the panel's height
        texts = [_fitted_label(axes, r["candidate"], fontsize, 1.0 - 2.0 * offset) for r in front]
        extents = [(text.count("\n") + 1) * line for text in texts]     # each label's height [axes fraction]
        if sum(extents) <= 0.98 or fontsize <= MIN_LABEL_FONTSIZE:
            break
        fontsize = max(MIN_LABEL_FONTSIZE, fontsize * 0.98 / sum(extents))
        line = 1.4 * fontsize * axes.figure.dpi / 72.0 / box.height
    heights = stack_labels(points[:, 1], line, low=0.01, high=0.99, heights=extents)
    for r, text, (x, _), height in zip(front, texts, points, heights):
        width = _text_width(axes, text, fontsize)
        starts = {}                         # side: where the label begins (left side: where it ends)
        for side in (1.0, -1.0):
            row = markers[(np.abs(markers[:, 1] - height) < 0.6 * line) & (side * (markers[:, 0] - x) >= 0)
                          & (side * (markers[:, 0] - x) < CLEARANCE)]
            edge = x if len(row) == 0 else (row[:, 0].max() if side > 0 else row[:, 0].min())
            starts[side] = edge + side * offset
        preferred = (1.0, -1.0) if x < 0.6 else (-1.0, 1.0)
        fitting = [side for side in preferred if 0.0 <= starts[side] - (side < 0) * width
                   and starts[side] + (side > 0) * width <= 1.0]
        side = fitting[0] if fitting else max(preferred, key=lambda s: 1.0 - starts[s] if s > 0 else starts[s])
        width = min(width, 1.0)
        start = min(starts[side], 1.0 - width) if side > 0 else max(starts[side], width)
        axes.annotate(text, (1e3 * r["render_s"], 100 * r[error]), xytext=(start, height),
                      textcoords="axes fraction", ha="left" if side > 0 else "right", va="center",
                      fontsize=fontsize, bbox=dict(boxstyle="square,pad=0.1", fc="white", ec="none", alpha=0.85),
                      arrowprops=dict(arrowstyle="-", lw=0.5, color="0.45", shrinkA=0, shrinkB=3), zorder=4,
                      gid=f"front:{r['candidate']}")


def _plain_ticks(axis):
    """Ticks at 1, 2 and 5 times the powers of ten, labelled as plain numbers, no minor labels: on a log axis
    spanning less than a decade matplotlib labels every minor tick in scientific form, overlapping."""
    import matplotlib.ticker as ticker

    axis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(ticker.FormatStrFormatter("%g"))
    axis.set_minor_formatter(ticker.NullFormatter())


def _text_width(axes, text, fontsize):
    """The width of ``text`` at ``fontsize`` as drawn in ``axes`` [axes fraction]."""
    sample = axes.text(0.0, 0.0, text, fontsize=fontsize, transform=axes.transAxes)
    try:
        extent = sample.get_window_extent(axes.figure.canvas.get_renderer())
    finally:
        sample.remove()
    return extent.width / axes.get_window_extent().width


def _fitted_label(axes, text, fontsize, room):
    """``text``, or it broken into lines at spaces where it is wider than ``room`` [axes fraction]: a front
    label ran out of its panel (the day panel's longest ray-march label) and off the figure's edge."""
    words, lines = [], []
    for word in text.split(" "):            # a word wider than the room is cut where it must be
        while len(word) > 1 and _text_width(axes, word, fontsize) > room:
            cut = max(1, max(n for n in range(1, len(word)) if n == 1
                             or _text_width(axes, word[:n], fontsize) <= room))
            words.append(word[:cut])
            word = word[cut:]
        words.append(word)
    for word in words:
        if lines and _text_width(axes, f"{lines[-1]} {word}", fontsize) <= room:
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word)
    return "\n".join(lines)


def draw_pareto(rows, size=128, title="clsky: speed versus accuracy"):
    """The Pareto figure of ``rows`` (see the module): a large panel for the worst frame, four small
    ones for the sun elevations, one legend of the knobs. ``size``: the frames' side [px], for the axis
    label. Returns the matplotlib Figure (the caller closes it)."""
    plt = _pyplot()
    styles = knob_styles(rows)
    figure = plt.figure(figsize=(14, 7.2), dpi=100)
    grid = figure.add_gridspec(2, 4, left=0.055, right=0.99, top=0.9, bottom=0.2, wspace=0.28, hspace=0.38,
                               width_ratios=(1.3, 1.3, 1, 1))
    worst = figure.add_subplot(grid[:, :2])
    _pareto_panel(worst, rows, "p95_rel", styles, fontsize=8)
    worst.set_title(f"worst of the {len(SUN_ELEVATIONS)} frames", fontsize=10)
    worst.set_xlabel(f"render time per {size} x {size} frame [ms]")
    worst.set_ylabel("95th-percentile relative error [%]")
    for index, (name, elevation) in enumerate(SUN_ELEVATIONS.items()):
        axes = figure.add_subplot(grid[index // 2, 2 + index % 2])
        _pareto_panel(axes, rows, f"p95_rel {name}", styles, fontsize=6.5)
        axes.set_title(f"{name} (sun {elevation:g} deg)", fontsize=9)
        if index >= 2:
            axes.set_xlabel("render time [ms]", fontsize=8)
        if index % 2 == 0:
            axes.set_ylabel("p95 error [%]", fontsize=8)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], ls="", marker=marker, color=colour, ms=5, label=knob)
               for knob, (colour, marker) in styles.items()]
    handles.append(Line2D([], [], ls="--", color="k", lw=0.7, label="Pareto front (labelled)"))
    figure.legend(handles=handles, loc="lower center", ncol=6, fontsize=8, frameon=False,
                  title="knob moved from the defaults (black edge: on that panel's Pareto front)",
                  title_fontsize=8)
    figure.suptitle(title, fontsize=11)
    return figure


def draw_elevation(rows, title="clsky: where each renderer fails"):
    """Error against sun elevation (see the module): one line per candidate on the worst-frame Pareto
    front, over one band per renderer spanning all its candidates. Returns the Figure."""
    plt = _pyplot()
    import matplotlib

    names = sorted(SUN_ELEVATIONS, key=SUN_ELEVATIONS.get)
    elevations = [SUN_ELEVATIONS[n] for n in names]
    figure, axes = plt.subplots(figsize=(9, 5.6), dpi=100)
    figure.subplots_adjust(left=0.09, right=0.66, top=0.9, bottom=0.16)
    axes.axvspan(*CIVIL_TWILIGHT, color="0.88", zorder=0, label="civil twilight (sun 0 to 6 deg down)")
    axes.axvline(0.0, color="0.3", lw=0.9, zorder=1, label="horizon")
    front = pareto_front(rows)
    for method, renderer in RENDERERS.items():
        mine = [r for r in rows if r["method"] == method]
        if not mine:
            continue
        errors = 100 * np.array([[r[f"p95_rel {n}"] for n in names] for r in mine])
        colours = matplotlib.colormaps[RENDERER_COLOURS[method]]
        on_front = [r for r in front if r["method"] == method]
        if len(mine) > 1:
            axes.fill_between(elevations, errors.min(axis=0), errors.max(axis=0), color=colours(0.5), alpha=0.18,
                              lw=0, zorder=1, label=f"{renderer}: all {len(mine)} candidates (range)")
        elif not on_front:          # a band of one candidate has no height: its numbers were drawn nowhere
            axes.plot(elevations, errors[0], ls=":", marker=".", lw=1.0, color=colours(0.6), zorder=2,
                      label=f"{_line_label(method, mine[0]['candidate'])} (its one candidate)",
                      gid=f"only:{mine[0]['candidate']}")
        for index, r in enumerate(on_front):
            shade = 0.45 + 0.5 * index / max(1, len(on_front) - 1)
            axes.plot(elevations, [100 * r[f"p95_rel {n}"] for n in names], marker="os^vD<>"[index % 7], ms=4,
                      lw=1.2, color=colours(shade), label=_line_label(method, r["candidate"]), zorder=3,
                      gid=f"front:{r['candidate']}")
    hidden = [f"{r['candidate']} ({n})" for r in rows for n in names if not r[f"p95_rel {n}"] > 0]
    if hidden:                  # a log axis drops them silently: named, as the Pareto panels name theirs
        axes.text(0.99, 0.01, "not shown (0 on a log axis): " + ", ".join(hidden), transform=axes.transAxes,
                  ha="right", va="bottom", fontsize=7, color="0.3", gid="hidden", wrap=True)
    axes.set_yscale("log")
    axes.set_xscale("symlog", linthresh=ELEVATION_LINEAR, linscale=2.0)
    axes.set_xlim(min(CIVIL_TWILIGHT[0], min(elevations)) - 2, max(elevations) + 5)
    axes.set_xticks(elevations, [f"{e:g}\n{n}" for n, e in zip(names, elevations)], fontsize=8)
    axes.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    axes.set_xlabel(f"sun elevation [deg] (linear within {ELEVATION_LINEAR:g} deg of the horizon, logarithmic "
                    "beyond)")
    axes.set_ylabel("95th-percentile relative error [%]")
    axes.grid(True, which="both", lw=0.3, alpha=0.6)
    axes.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False,
                title="lines: on the Pareto front\n(render time vs worst error)", title_fontsize=8)
    axes.set_title(title, fontsize=11)
    return figure


#: How a candidate's label names its renderer where it does (the elevation plot's legend adds it otherwise).
RENDERER_WORDS = {"lut": "table lookup", "raymarch": "ray march", "lut4d": "4D table", "skyview": "sky-view"}


def _line_label(method, candidate):
    """'ray march 16 samples' and '4D table 16 x 128 x 128 x 16' as they are; 'linear mapping' as 'table
    lookup: linear mapping' ('4D table lookup: 4D table ...' ran out of the figure)."""
    return candidate if candidate.startswith(RENDERER_WORDS[method]) else f"{RENDERERS[method]}: {candidate}"


def _save(figure, path, force, staging):
    from clsky._files import atomic_write

    plt = _pyplot()
    try:
        with atomic_write(path, overwrite=force, staging=staging) as temporary:
            figure.savefig(temporary, format="png")
    finally:
        plt.close(figure)
    return path


def pareto_plot(rows, path, title="clsky: speed versus accuracy", force=False, size=128, staging=None):
    """Write :func:`draw_pareto` of ``rows`` as a PNG at ``path``, atomically; an existing file only
    with ``force``. ``staging`` (a :class:`clsky._files.StagedWrites`): the file lands when that set
    commits. Returns ``path``."""
    from clsky._files import check_output

    check_output(path, force)
    return _save(draw_pareto(rows, size, title), path, force, staging)


def elevation_plot(rows, path, title="clsky: where each renderer fails", force=False, staging=None):
    """Write :func:`draw_elevation` of ``rows`` as a PNG at ``path``, as :func:`pareto_plot` does."""
    from clsky._files import check_output

    check_output(path, force)
    return _save(draw_elevation(rows, title), path, force, staging)


def sweep_titles(level="reference"):
    """The titles of a sweep's two plots (Pareto, elevation), saying what the errors are against where it is
    not the 'reference' quality level (a smoke run's cheaper stand-in; the CSV's rows do not say)."""
    against = "" if level == "reference" else f" (against the {level!r} level)"
    return "clsky: speed versus accuracy" + against, "clsky: where each renderer fails" + against


def write_sweep(rows, csv_path, plot, elevation, size, level="reference", force=False):
    """A sweep's CSV and its two plots (:func:`pareto_plot`, :func:`elevation_plot`, titled by
    :func:`sweep_titles`), landing together (:class:`clsky._files.StagedWrites`): `clsky bench accuracy`'s
    and bench/bench_accuracy.py's outputs."""
    from clsky._files import StagedWrites

    from .writers import write_csv

    pareto_title, elevation_title = sweep_titles(level)
    with StagedWrites() as staging:
        write_csv(csv_path, rows, force=force, staging=staging)
        pareto_plot(rows, plot, title=pareto_title, force=force, size=size, staging=staging)
        elevation_plot(rows, elevation, title=elevation_title, force=force, staging=staging)
    return csv_path, plot, elevation


def elevation_plot_path(plot):
    """The elevation plot's default path beside the Pareto plot ``plot``: 'accuracy.png' ->
    'accuracy_elevation.png'."""
    plot = pathlib.Path(plot)
    return plot.with_name(f"{plot.stem}_elevation{plot.suffix}")


def plot_csv(csv_path, plot, elevation=None, size=128, force=False):
    """Both plots from a sweep's CSV, without measuring again: the Pareto plot at ``plot`` and the
    elevation plot at ``elevation`` (default :func:`elevation_plot_path`). ``size``: the frames' side
    [px] of that sweep (the CSV does not record it). Both paths are checked before either is drawn, and
    both land together (:class:`clsky._files.StagedWrites`). Returns the two paths."""
    from clsky._files import StagedWrites, check_output

    elevation = elevation_plot_path(plot) if elevation is None else elevation
    rows = read_csv(csv_path)
    for path in (plot, elevation):
        check_output(path, force)
    with StagedWrites() as staging:
        pareto_plot(rows, plot, force=force, size=size, staging=staging)
        elevation_plot(rows, elevation, force=force, staging=staging)
    return plot, elevation
