"""Speed versus accuracy: what each numerical knob costs and buys, measured on rendered frames.

A *candidate* is a way to make a frame: a table (its :class:`clsky.TableSettings`, looked up per
pixel), a per-pixel ray march (its samples per ray), or a per-frame sky-view map (:mod:`clsky.skyview`:
its size; the map's nodes ray-marched with the default ray march). Each candidate is timed (table build, frame
render) and compared, frame by frame, with a *reference*: the 'reference' quality level
(:mod:`clsky.quality`): a 256-sample ray march whose higher orders come from a fine table, one per frame,
whose sun axis covers only the sun angles that frame needs (:func:`clsky.planner.sun_axis`) with nodes
every 0.0015 in w. Frames: an all-sky fisheye from the ground at four sun elevations (day, golden hour,
sunset, civil twilight). Errors: the 95th percentile of the relative HDR luminance error and the mean
CIELAB Delta E (:func:`clsky.anim.metrics.compare_frames`), worst over the four frames.

How far the reference has converged is measured by doubling each group of its counts in turn
(:func:`reference_convergence`, :data:`REFERENCE_GROUPS`), frame by frame: errors below the sum of
those changes are not resolved. The sun axis is what twilight needs most: its higher orders fall off
steeply between sun angles, and over a whole-axis table of 32 sun nodes the ray march is 11 to 13 % off
there (README).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time

import numpy as np

import clsky
from clsky.planner import Scene, azimuth_harmonics, sun_axis
from clsky.quality import QualityLevel, quality_level
from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer

from . import metrics
from .cameras import FisheyeCamera, sun_direction

__all__ = ["SUN_ELEVATIONS", "DUSK_ELEVATIONS", "REFERENCE_GROUPS", "SKYVIEW_SIZES", "Candidate", "default_candidates",
           "reference_level", "reference_renderer", "render_frames", "render_reference", "reference_convergence",
           "measure", "pareto_front"]

#: Sun elevations [deg] of the frames: day, golden hour, sunset, civil twilight.
SUN_ELEVATIONS = {"day": 45.0, "golden hour": 8.0, "sunset": 1.0, "civil twilight": -4.0}
#: Sun elevations [deg] of the frames below civil twilight (bench/bench_quality_dusk.py): the default animation's
#: lowest sun (-6 deg, the end of civil twilight) and three lower, into nautical twilight.
DUSK_ELEVATIONS = {"-6 deg": -6.0, "-8 deg": -8.0, "-10 deg": -10.0, "-12 deg": -12.0}
SUN_AZIMUTH = 200.0


@dataclasses.dataclass(frozen=True)
class Candidate:
    """One way to make a frame: table lookup with ``table`` settings, a ray march of ``samples`` (its higher
    orders' source on every ``source_stride``-th node, ``TableSettings.source_stride``), or a sky-view map
    of ``skyview`` = (W, H) nodes (:class:`clsky.skyview.SkyViewSettings`)."""

    label: str
    knob: str
    table: clsky.TableSettings | None = None
    samples: int | None = None
    fast_math: bool = False
    skyview: tuple | None = None
    source_stride: int = 1

    @property
    def method(self):
        """'skyview' with ``skyview``, 'raymarch' with ``samples``, else 'lut4d' for a 4D table
        (clsky/table4d.py), else 'lut'."""
        if self.skyview is not None:
            return "skyview"
        if self.samples is not None:
            return "raymarch"
        return "lut4d" if self.table.is_4d else "lut"


def default_candidates(base: clsky.TableSettings | None = None):
    """The sweep: each knob moved away from ``base`` (default settings, with the azimuth harmonics the
    scene planner gives the four frames' sun path, :func:`clsky.planner.azimuth_harmonics`), plus ray
    marches."""
    if base is None:
        path = (min(SUN_ELEVATIONS.values()), max(SUN_ELEVATIONS.values()))
        base = clsky.TableSettings(mode="physical",
                                   azimuth_harmonics=azimuth_harmonics(quality_level("default"), path)[0])
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
        ("single scattering only", "order tolerance", base.replace(orders=1, azimuth_harmonics=0)),
        ("float32", "precision", base.replace(dtype="float32")),
        # the 4D table (altitude x view x sun x azimuth, clsky/table4d.py), its orders with 2 harmonics
        ("4D table", "parameterization", base.replace(parameterization="4d",
                                                      azimuth_harmonics=base.azimuth_harmonics or 2)),
        # ... at the size issue 11 asks for (float32 export <= 256 MB: 151 MB), bench_lookup4d's: 128 sun
        # nodes over -14 to 60 deg (the frames' path with the planner's margins), 16 azimuth nodes
        (f"4D table {' x '.join(map(str, LOOKUP4D_SIZE))} x {LOOKUP4D_AZIMUTHS}", "parameterization",
         lookup4d_settings(base)),
    ]
    candidates = [Candidate(label, knob, settings) for label, knob, settings in table]
    candidates.append(Candidate("fast math", "fast-math", base, fast_math=True))
    candidates += [Candidate(f"ray march {n} samples", "ray march samples", base, samples=n)
                   for n in (16, 32, 48, 96)]
    candidates.append(Candidate("ray march 48 samples, source on every other node", "ray march samples", base,
                                samples=48, source_stride=2))        # the default quality level's march
    candidates.append(Candidate("ray march 48 samples, source on every other node, also in the table's scatter",
                                "ray march samples", base.replace(source_stride=2), samples=48,
                                source_stride=2))                      # ... and its table's scatter
    candidates += [Candidate(f"sky-view {w} x {h}", "sky-view map size", base, skyview=(w, h))
                   for w, h in SKYVIEW_SIZES]
    return candidates


#: The sweep's second 4D candidate: (W, H, D) nodes, azimuth nodes and its sun axis [deg] (bench/bench_lookup4d.py's).
LOOKUP4D_SIZE, LOOKUP4D_AZIMUTHS, LOOKUP4D_SUN_DEG = (16, 128, 128), 16, (-14.0, 60.0)


def lookup4d_settings(base: clsky.TableSettings) -> clsky.TableSettings:
    """``base`` as the 4D table of issue 11's size (:data:`LOOKUP4D_SIZE`, :data:`LOOKUP4D_AZIMUTHS` azimuth
    nodes, the sun axis over :data:`LOOKUP4D_SUN_DEG`), its orders with ``base``'s harmonics or 2."""
    return base.replace(parameterization="4d", size=LOOKUP4D_SIZE, azimuth_size=LOOKUP4D_AZIMUTHS,
                        sun_cos_range=tuple(math.sin(math.radians(e)) for e in LOOKUP4D_SUN_DEG),
                        azimuth_harmonics=base.azimuth_harmonics or 2)

#: Map sizes (W, H) of the sweep's sky-view candidates (:mod:`clsky.skyview`).
SKYVIEW_SIZES = ((16, 32), (32, 64), (64, 128))


#: The reference's counts, in groups that its convergence check doubles one at a time (doubling all
#: at once would need 2.9 GB of gather matrices and hours): {group: what doubles}.
REFERENCE_GROUPS = {
    "sun nodes": "the table's sun-axis nodes (half their spacing)",
    "view axis, gather": "the table's view axis and the gather's Theta and Phi steps",
    "table quadrature": "the table's view and sun steps and its transmittance table",
    "ray march": "the ray march's samples, sun steps and transmittance table",
}


def reference_level(doubled=(), level="reference") -> QualityLevel:
    """The quality level ``level`` (:mod:`clsky.quality`; 'reference' unless a test wants a cheaper
    stand-in), with the counts of the groups named in
    ``doubled`` (keys of :data:`REFERENCE_GROUPS`) doubled. The table only feeds the higher orders, which
    vary slowly with altitude: its altitude axis stays at 32 (doubling it changed twilight frames by
    0.06 %, measured)."""
    unknown = set(doubled) - set(REFERENCE_GROUPS)
    if unknown:
        raise ValueError(f"doubled must name groups of {list(REFERENCE_GROUPS)}, got {sorted(unknown)}")
    level = quality_level(level)
    t, ray, spacing = level.table, level.ray, level.sun_node_spacing
    if "sun nodes" in doubled:
        spacing /= 2
    if "view axis, gather" in doubled:
        t = t.replace(size=(t.size[0], 2 * t.size[1], t.size[2]), gather_theta_steps=2 * t.gather_theta_steps,
                      gather_phi_steps=2 * t.gather_phi_steps)
    if "table quadrature" in doubled:
        t = t.replace(view_steps=2 * t.view_steps, sun_steps=2 * t.sun_steps,
                      transmittance_size=tuple(2 * n for n in t.transmittance_size))
    if "ray march" in doubled:
        ray = ray.replace(view_steps=2 * ray.view_steps, sun_steps=2 * ray.sun_steps,
                          transmittance_size=tuple(2 * n for n in ray.transmittance_size))
    return dataclasses.replace(level, table=t, sun_node_spacing=spacing, ray=ray)


def reference_renderer(elevation_deg, doubled=(), atmosphere="physical", level="reference"):
    """A SkyRenderer of the reference for one sun elevation: the reference level's table on the sun
    range that frame needs (its sun, plus the planner's margins for a fisheye from the ground, at the
    level's node spacing) with azimuth harmonics at every sun (the 'reference' level's M = 2; a
    stand-in level's ``twilight_harmonics``: the reference must not share the azimuth average's
    excess, 0.6 % in the day frame against M = 2), and its ray march."""
    level = reference_level(doubled, level)
    atmosphere = clsky.preset(atmosphere) if isinstance(atmosphere, str) else atmosphere
    cos_range, nodes, _, _ = sun_axis(atmosphere, Scene((elevation_deg, elevation_deg)), level)
    # a reference carries the harmonics at every sun, as the 'reference' level does (a stand-in level too)
    harmonics = level.table.azimuth_harmonics or level.twilight_harmonics
    settings = level.table.replace(size=level.table.size[:2] + (nodes,), sun_cos_range=cos_range,
                                   azimuth_harmonics=harmonics)
    return SkyRenderer(clsky.ScatteringTable.build(atmosphere, settings), level.ray)


def render_frames(renderer, method, prepared, skyview=None, elevations=None):
    """The frames {name: HDR} of ``elevations`` ({name: sun elevation [deg]}, default the four of
    :data:`SUN_ELEVATIONS`) by table lookup ('lut', or 'lut4d' in a 4D table), ray march ('raymarch') or sky-view
    map ('skyview', of ``skyview`` = (W, H) nodes, default its default size), with ``prepared`` directions
    (:meth:`clsky.render.SkyRenderer.prepare`)."""
    from clsky.skyview import DEFAULT_SIZE, SkyViewSettings

    frames = {}
    render = {"lut": renderer.render_table, "lut4d": renderer.render_lut4d}.get(method, renderer.render_raymarch)
    if method == "skyview":
        render = functools.partial(renderer.render_skyview, settings=SkyViewSettings(skyview or DEFAULT_SIZE))
    for name, elevation in (SUN_ELEVATIONS if elevations is None else elevations).items():
        sun = sun_direction(90.0 - elevation, SUN_AZIMUTH)
        frames[name] = render(prepared, sun, 0.0)
    return frames


def render_reference(size=128, doubled=(), atmosphere="physical", level="reference", progress=None, elevations=None):
    """The reference frames {name: HDR (size, size, 3)} of ``elevations`` ({name: sun elevation [deg]}, default
    :data:`SUN_ELEVATIONS`) and the fisheye's valid mask. ``progress(stage, done, total)``: stage 'reference',
    reported before the first frame's table (the longest stage of a sweep: minutes) and after each frame."""
    directions, valid = FisheyeCamera(size).directions()
    elevations = SUN_ELEVATIONS if elevations is None else elevations
    frames = {}
    if progress is not None:
        progress("reference", 0, len(elevations))
    for index, (name, elevation) in enumerate(elevations.items()):
        with reference_renderer(elevation, doubled, atmosphere, level) as renderer:
            frames[name] = renderer.render_raymarch(renderer.prepare(directions, valid),
                                                    sun_direction(90.0 - elevation, SUN_AZIMUTH), 0.0)
        if progress is not None:
            progress("reference", index + 1, len(elevations))
    return frames, valid


def _errors(reference, frames, valid):
    """Worst over the frames of the 95th-percentile relative error and of the mean Delta E, and per frame."""
    per_frame = {name: metrics.compare_frames(reference[name], frames[name], valid) for name in reference}
    return (max(m["p95_rel"] for m in per_frame.values()), max(m["mean_delta_e"] for m in per_frame.values()),
            per_frame)


def reference_convergence(reference, valid, atmosphere="physical", progress=None, groups=tuple(REFERENCE_GROUPS),
                          level="reference", elevations=None):
    """How much the reference frames change when each group of its counts (``groups``, default all of
    :data:`REFERENCE_GROUPS`) is doubled: {group: {frame name: p95 relative change}}, plus "sum": the sum
    over those groups per frame, which bounds the change of doubling them all (the changes are small,
    so they add to first order). ``level``: the quality level ``reference`` was rendered at
    (:func:`render_reference`; 'reference' unless a smoke run wants a cheaper stand-in); ``elevations``: its
    frames' ({name: sun elevation [deg]}, default :data:`SUN_ELEVATIONS`)."""
    size = valid.shape[0]
    change = {}
    if progress is not None:
        progress("reference convergence", 0, len(groups))
    for index, group in enumerate(groups):
        finer, _ = render_reference(size, (group,), atmosphere, level, elevations=elevations)
        change[group] = {name: m["p95_rel"] for name, m in _errors(finer, reference, valid)[2].items()}
        if progress is not None:
            progress("reference convergence", index + 1, len(groups))
    change["sum"] = {name: sum(change[g][name] for g in groups) for name in reference}
    return change


def measure(candidates, reference, valid, atmosphere="physical", progress=None):
    """One row per candidate: build and render times [s] (wall, and process CPU time: every thread, the
    OpenCL device's workers included), worst p95 relative error, worst mean Delta E, and the p95 error per
    frame."""
    size = valid.shape[0]
    directions, _ = FisheyeCamera(size).directions()
    rows = []
    if progress is not None:            # the bar from the start: the first candidate's table takes seconds
        progress("candidates", 0, len(candidates))
    for index, candidate in enumerate(candidates):
        settings = candidate.table
        start, cpu = time.perf_counter(), time.process_time()
        table = clsky.ScatteringTable.build(atmosphere, settings, fast_math=candidate.fast_math)
        build, build_cpu = time.perf_counter() - start, time.process_time() - cpu
        ray = None if candidate.samples is None else RAYMARCH_DEFAULTS.replace(view_steps=candidate.samples,
                                                                              source_stride=candidate.source_stride)
        renderer = SkyRenderer(table, ray, fast_math=candidate.fast_math)
        prepared = renderer.prepare(directions, valid)
        render_frames(renderer, candidate.method, prepared, candidate.skyview)      # warm-up (compilation)
        start, cpu = time.perf_counter(), time.process_time()
        frames = render_frames(renderer, candidate.method, prepared, candidate.skyview)
        render, render_cpu = (time.perf_counter() - start) / len(frames), (time.process_time() - cpu) / len(frames)
        p95, delta_e, per_frame = _errors(reference, frames, valid)
        row = {"candidate": candidate.label, "knob": candidate.knob, "method": candidate.method,
               "build_s": build, "build_cpu_s": build_cpu, "render_s": render, "render_cpu_s": render_cpu,
               "p95_rel": p95, "mean_delta_e": delta_e}
        row.update({f"p95_rel {name}": m["p95_rel"] for name, m in per_frame.items()})
        rows.append(row)
        if progress is not None:
            progress("candidates", index + 1, len(candidates))
    return rows


def pareto_front(rows, cost="render_s", error="p95_rel"):
    """The rows no other row dominates (no other is as cheap and as accurate and better in one of the two),
    cheapest first; rows equal in both are all kept (the first of two equal rows alone was kept)."""
    ordered = sorted(rows, key=lambda r: (r[cost], r[error]))
    front, best = [], np.inf
    for row in ordered:
        if row[error] < best or (front and (row[cost], row[error]) == (front[-1][cost], front[-1][error])):
            front.append(row)
            best = row[error]
    return front
