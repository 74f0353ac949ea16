"""Speed versus accuracy: what each numerical knob costs and buys, measured on rendered frames.

A *candidate* is a way to make a frame: a table (its :class:`clsky.TableSettings`, looked up per
pixel) or a per-pixel ray march (its samples per ray). Each candidate is timed (table build, frame
render) and compared, frame by frame, with a *reference*: a ray march with many samples whose higher
orders come from a fine table. Frames: an all-sky fisheye from the ground at four sun elevations (day,
golden hour, sunset, civil twilight). Errors: the 95th percentile of the relative HDR luminance error
and the mean CIELAB Delta E (:func:`anim.metrics.compare_frames`), worst over the four frames.

How far the reference has converged is measured by computing it twice, the second time with every
count doubled (:func:`reference_convergence`), frame by frame: errors below that change are not
resolved. (Measured at 128 x 128: 0.04 % by day, 0.07 % at golden hour, 0.3 % at sunset, 2.6 % in
civil twilight, where the higher orders dominate and follow the table's sun axis.)
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

import clsky
from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer

from . import metrics
from .cameras import FisheyeCamera, sun_direction

__all__ = ["SUN_ELEVATIONS", "Candidate", "default_candidates", "reference_settings", "render_reference",
           "reference_convergence", "measure", "pareto_front"]

#: Sun elevations [deg] of the frames: day, golden hour, sunset, civil twilight.
SUN_ELEVATIONS = {"day": 45.0, "golden hour": 8.0, "sunset": 1.0, "civil twilight": -4.0}
SUN_AZIMUTH = 200.0


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One way to make a frame: table lookup with ``table`` settings, or a ray march of ``samples``."""

    label: str
    knob: str
    table: clsky.TableSettings | None = None
    samples: int | None = None
    fast_math: bool = False

    @property
    def method(self):
        return "lut" if self.samples is None else "raymarch"


def default_candidates(base: clsky.TableSettings | None = None):
    """The sweep: each knob moved away from ``base`` (default settings), plus ray marches."""
    base = base or clsky.TableSettings(mode="physical")
    width, height, depth = base.size
    table = [
        ("default", "default", base),
        ("W / 2", "table size", base.replace(size=(width // 2, height, depth))),
        ("W x 2", "table size", base.replace(size=(width * 2, height, depth))),
        ("H / 2", "table size", base.replace(size=(width, height // 2, depth))),
        ("H x 2", "table size", base.replace(size=(width, height * 2, depth))),
        ("D / 2", "table size", base.replace(size=(width, height, depth // 2))),
        ("D x 2", "table size", base.replace(size=(width, height, depth * 2))),
        ("all / 2", "table size", base.replace(size=(width // 2, height // 2, depth // 2))),
        ("linear mapping", "mapping", base.replace(mapping="linear")),
        ("view steps 15", "view/sun steps", base.replace(view_steps=15, multiple_view_steps=10)),
        ("view steps 60", "view/sun steps", base.replace(view_steps=60, multiple_view_steps=40)),
        ("sun steps 15", "view/sun steps", base.replace(sun_steps=15)),
        ("sun steps 60", "view/sun steps", base.replace(sun_steps=60)),
        ("uniform sampling", "sampling", base.replace(sampling="uniform")),
        ("sun rays re-marched", "transmittance", base.replace(sun_transmittance="march")),
        ("gather 64 x 32", "gather quadrature", base.replace(gather_theta_steps=64, gather_phi_steps=32)),
        ("order tolerance 1e-2", "order tolerance", base.replace(order_tolerance=1e-2)),
        ("order tolerance 1e-3", "order tolerance", base.replace(order_tolerance=1e-3)),
        ("single scattering only", "order tolerance", base.replace(orders=1)),
        ("float32", "precision", base.replace(dtype="float32")),
    ]
    candidates = [Candidate(label, knob, settings) for label, knob, settings in table]
    candidates.append(Candidate("fast math", "fast-math", base, fast_math=True))
    candidates += [Candidate(f"ray march {n} samples", "ray march samples", base, samples=n)
                   for n in (16, 32, 48, 96)]
    return candidates


def reference_settings(scale=1):
    """Table and ray-march settings of the reference; ``scale`` = 2 doubles every count that matters:
    the ray march's samples, sun steps and transmittance table, and the table's view and sun steps,
    gather quadrature and view and sun axes (the table only feeds the higher orders, which vary slowly
    with altitude: its altitude axis stays at 32)."""
    table = clsky.TableSettings(mode="physical", size=(32, 256 * scale, 32 * scale),
                                view_steps=120 * scale, multiple_view_steps=None, sun_steps=240 * scale,
                                transmittance_size=(128 * scale, 512 * scale), order_tolerance=1e-5,
                                gather_theta_steps=256 * scale, gather_phi_steps=128 * scale)
    march = RAYMARCH_DEFAULTS.replace(view_steps=256 * scale, sun_steps=256 * scale,
                                      transmittance_size=(128 * scale, 512 * scale))
    return table, march


def _frames(renderer, method, prepared):
    frames = {}
    for name, elevation in SUN_ELEVATIONS.items():
        sun = sun_direction(90.0 - elevation, SUN_AZIMUTH)
        render = renderer.render_table if method == "lut" else renderer.render_raymarch
        frames[name] = render(prepared, sun, 0.0)
    return frames


def render_reference(size=128, scale=1, atmosphere="physical"):
    """The reference frames {name: HDR (size, size, 3)} and the fisheye's valid mask."""
    table_settings, march = reference_settings(scale)
    table = clsky.ScatteringTable.build(atmosphere, table_settings)
    renderer = SkyRenderer(table, march)
    directions, valid = FisheyeCamera(size).directions()
    return _frames(renderer, "raymarch", renderer.prepare(directions, valid)), valid


def _errors(reference, frames, valid):
    """Worst over the frames of the 95th-percentile relative error and of the mean Delta E, and per frame."""
    per_frame = {name: metrics.compare_frames(reference[name], frames[name], valid) for name in reference}
    return (max(m["p95_rel"] for m in per_frame.values()), max(m["mean_delta_e"] for m in per_frame.values()),
            per_frame)


def reference_convergence(size=128, atmosphere="physical"):
    """How much the reference frames change when every count is doubled, per frame:
    {frame name: compare_frames metrics (p95_rel, mean_delta_e, ...)}."""
    coarse, valid = render_reference(size, 1, atmosphere)
    fine, _ = render_reference(size, 2, atmosphere)
    return _errors(fine, coarse, valid)[2]


def measure(candidates, reference, valid, atmosphere="physical", progress=None):
    """One row per candidate: build and render times [s], worst p95 relative error, worst mean Delta E,
    and the p95 error per frame."""
    size = valid.shape[0]
    directions, _ = FisheyeCamera(size).directions()
    rows = []
    for index, candidate in enumerate(candidates):
        settings = candidate.table
        start = time.perf_counter()
        table = clsky.ScatteringTable.build(atmosphere, settings, fast_math=candidate.fast_math)
        build = time.perf_counter() - start
        ray = None if candidate.samples is None else RAYMARCH_DEFAULTS.replace(view_steps=candidate.samples)
        renderer = SkyRenderer(table, ray, fast_math=candidate.fast_math)
        prepared = renderer.prepare(directions, valid)
        _frames(renderer, candidate.method, prepared)                       # warm-up (compilation)
        start = time.perf_counter()
        frames = _frames(renderer, candidate.method, prepared)
        render = (time.perf_counter() - start) / len(frames)
        p95, delta_e, per_frame = _errors(reference, frames, valid)
        row = {"candidate": candidate.label, "knob": candidate.knob, "method": candidate.method,
               "build_s": build, "render_s": render, "p95_rel": p95, "mean_delta_e": delta_e}
        row.update({f"p95_rel {name}": m["p95_rel"] for name, m in per_frame.items()})
        rows.append(row)
        if progress is not None:
            progress("candidates", index + 1, len(candidates))
    return rows


def pareto_front(rows, cost="render_s", error="p95_rel"):
    """The rows no other row beats in both cost and error, cheapest first."""
    ordered = sorted(rows, key=lambda r: (r[cost], r[error]))
    front, best = [], np.inf
    for row in ordered:
        if row[error] < best:
            front.append(row)
            best = row[error]
    return front


def pareto_plot(rows, path, title="clsky: speed versus accuracy", force=False):
    """Error versus render time of every candidate (log-log), Pareto fronts joined; a PNG with two
    panels: the worst of the four frames, and the day frame alone (where table knobs differ).

    matplotlib draws it (a well-kept plotting library does this better than hand-written code); it is
    the ``bench`` extra: ``pip install 'clsky[bench]'``.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as error:
        raise ImportError("the accuracy plot needs matplotlib: pip install 'clsky[bench]'") from error
    from clsky.table import atomic_write

    figure, panels = plt.subplots(1, 2, figsize=(11, 4.6), dpi=100)
    for axes, error, subtitle in ((panels[0], "p95_rel", "worst of the four frames"),
                                  (panels[1], "p95_rel day", f"day (sun {SUN_ELEVATIONS['day']:g} deg up)")):
        for method, marker in (("lut", "o"), ("raymarch", "s")):
            chosen = [r for r in rows if r["method"] == method]
            axes.scatter([1e3 * r["render_s"] for r in chosen], [100 * r[error] for r in chosen], marker=marker,
                         label="table lookup" if method == "lut" else "ray march")
        front = pareto_front(rows, error=error)
        for r in front:
            axes.annotate(r["candidate"], (1e3 * r["render_s"], 100 * r[error]), fontsize=7, xytext=(4, 3),
                          textcoords="offset points")
        axes.plot([1e3 * r["render_s"] for r in front], [100 * r[error] for r in front], "k--", lw=0.8,
                  label="Pareto front (labelled)")
        axes.set_xscale("log")
        axes.set_yscale("log")
        axes.set_xlabel("render time per 128 x 128 frame [ms]")
        axes.set_ylabel("95th-percentile relative error [%]")
        axes.set_title(subtitle, fontsize=9)
        axes.grid(True, which="both", lw=0.3)
        axes.legend(fontsize=7)
    figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    with atomic_write(path, overwrite=force) as temporary:
        figure.savefig(temporary, format="png")
    plt.close(figure)
    return path
