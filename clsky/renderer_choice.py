"""Which renderer a scene's frames need: the cheapest whose measured error fits the error budget.

One row per renderer (:data:`RENDERERS`): its ``--method`` name, its measured cost a frame (a part per
frame and a part per pixel) and its measured error against sun elevation, with where each figure comes
from. :func:`choose_renderer` takes
the cheapest row whose estimated error over the scene's sun path fits the budget; the ray march, the
plan's reference, when none does. A new renderer is one more row: its cost, its errors and whether they
add to the ray march's.

A row's cost is its own table's build (``build_cpu_s``: 0 for the rows that read the plan's 3D table or
none) plus ``frames`` times its cost per frame: a part per frame (``fixed_cpu_ms``: the sky-view map's own
ray march) and a part per rendered pixel (``pixel_cpu_ns``), measured side by side by
bench/bench_renderer_costs.py (README "Scene plan"). So which row is the cheaper depends on the frame's
pixels (:class:`clsky.planner.Scene`'s ``pixels``): the sky-view map's map costs about 14 ms whatever the
frame and its reading 18 ns a pixel, the 3D table lookup 39 ns a pixel, so the lookup is the cheaper below
about 630 000 pixels (an all-sky fisheye about 900 pixels a side) and the map above, where it is both
cheaper and closer to the ray march; the ray march, 1.6 us a pixel, costs less than the map's own march
below about 7900 pixels (a fisheye about 100 pixels a side). The 4D table lookup (``'lut4d'``) needs a
table of its own, 12 CPU-s to build for the default scene, and reads 46 ns a pixel: it saves 7.4 ms a frame
against the sky-view map on the default 512 x 512 fisheye, so it pays from about 1700 frames on there, and
it costs more than the map from about 470 000 pixels on. The scene plan does not know how many frames it
serves (:class:`clsky.planner.Scene` has no frame count), so it calls :func:`choose_renderer` with
``frames=None``, which leaves out every row with a build of its own: the plan never picks 'lut4d'
(``clsky animate --method lut4d`` / ``compare4d`` asks for it). A caller that knows the frame count passes
it and the build is counted.

A row's error is either its own error against the reference frames (``on_ray_march=False``: the 3D
lookup replaces the ray march; README "Speed versus accuracy") or what it adds to the ray march its
frames are made from (``on_ray_march=True``: the sky-view map is the ray march read at its nodes,
README "Sky-view table"). The latter is estimated as the quality level's measured ray-march error
(:data:`RAY_MARCH_ERROR`) plus the row's, as if the two erred with one sign at the same pixels; where the row
was measured against the reference itself, for the level's table, with the observer on the ground
(``on_reference``: the sky-view map, -12 to 45 deg, bench/bench_quality.py and bench_quality_dusk.py), that
measurement instead, for a scene seen from the ground (:func:`estimated_error`). The sum is the more
cautious: at -6 deg the default level's ray march is 0.80 % off and the map 0.31 % off the ray march (the
worst observer), and the map measured 0.83 % off the reference (README "Quality levels").
Between the measured elevations the error is interpolated in log error; beyond them, the nearest
value; over a sun path, the worst of the path's ends and of the measured elevations inside it. Every
figure was measured against the reference, which is itself off the converged sky by its own estimated
error (:data:`REFERENCE_RESOLUTION`: 0.02 % by day, 0.09 % at -4 deg, more below; an estimate from below):
the estimate a budget is compared with adds it (:func:`with_resolution`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .errors import check_choice, check_integer, check_range, check_real

__all__ = ["RendererRow", "RENDERERS", "DEFAULT_PIXELS", "LOOKUP4D_ERROR", "RAY_MARCH_ERROR", "LOOKUP_ERROR",
           "REFERENCE_RESOLUTION", "SKYVIEW_ON_REFERENCE", "renderer_row", "choose_renderer", "estimated_error",
           "estimate_basis", "error_at", "error_over", "worst_over", "with_resolution"]

#: Measured error of the 3D table lookup (95th percentile, relative, default table, 64 x 64 all-sky fisheye
#: from the ground, physical preset with ozone and ground, the harmonics M = 2 in the table and the
#: reference; README "Speed versus accuracy", 2026-12-02) by sun elevation [deg]: it grows toward the
#: horizon, where the missing azimuth of the 3D table dominates, whatever the table's size (the sweep
#: against the azimuth-averaged reference, earlier that day: 4.99, 0.381, 0.0417, 0.0105).
LOOKUP_ERROR = ((-4.0, 10.26), (1.0, 0.361), (8.0, 0.0419), (45.0, 0.0141))

#: How far the reference (the 'reference' quality level, ``clsky.anim.accuracy``) is resolved, by sun elevation
#: [deg]: the sum of the changes (p95, relative, 64 x 64 fisheye from the ground) of its frames when each group
#: of its counts is doubled in turn (its sun nodes; its view axis with the gather's steps; its table's
#: quadrature; its ray march's), standing for the change of doubling them all at once: the reference's own
#: estimated error. An estimate from below: a count whose error falls as its spacing to the power p changes the
#: frames on doubling by 1 - 2^-p of that error (three quarters for p = 2, a half for p = 1). From -4 deg up
#: bench/bench_quality.py (docs/quality_reference.csv, 2026-12-07), below bench/bench_quality_dusk.py
#: (docs/quality_dusk_reference.csv, 2026-12-08), both on the Intel Xeon. The scene planner adds it to a level's
#: measured error before it takes the level's promise to hold (:func:`clsky.planner.promise_bounds`) and before
#: a renderer's estimate is compared with a budget (:func:`choose_renderer`): a level measured within its
#: promise by less than this is within it as far as the reference can tell, and no further.
REFERENCE_RESOLUTION = ((-12.0, 0.00278), (-10.0, 0.00247), (-8.0, 0.0018), (-6.0, 0.0014),
                        (-4.0, 0.000902), (1.0, 0.000182), (8.0, 0.000217), (45.0, 0.000216))

#: Measured error of each quality level's ray march against the reference (p95, 64 x 64 fisheye from the
#: ground) by sun elevation [deg], the levels' tables as the scene planner gives them: from -4 deg up,
#: bench/bench_quality.py (README "Quality levels", docs/quality.csv), each level planned for the four frames'
#: path -4 to 45 deg; below, bench/bench_quality_dusk.py (README "Quality levels", below civil twilight,
#: docs/quality_dusk.csv), each planned for the path -12 to 45 deg (their tables reading the orders' source at
#: every view node there); both 2026-12-07, the Intel Xeon. The 'reference' level's: how far the reference
#: itself is resolved (:data:`REFERENCE_RESOLUTION`). A measured error depends on where the sun falls between
#: the plan's sun nodes, so on the path planned for: the default animation's own plan (-6 to 60 deg) was 0.89 %
#: off at -6 deg (0.80 % here; a probe, 2026-12-07) and 0.56 % at -4 deg (0.68 %; README "Scene plan"), the
#: draft planned for -6 deg alone 9.2 % (14.1 %; a probe).
RAY_MARCH_ERROR = {
    "draft": ((-12.0, 0.297), (-10.0, 0.236), (-8.0, 0.123), (-6.0, 0.141),
              (-4.0, 0.0627), (1.0, 0.0158), (8.0, 0.0247), (45.0, 0.0286)),
    "default": ((-12.0, 0.0150), (-10.0, 0.0130), (-8.0, 0.00996), (-6.0, 0.0080),
                (-4.0, 0.00676), (1.0, 0.00178), (8.0, 0.00287), (45.0, 0.00351)),
    "high": ((-12.0, 0.00238), (-10.0, 0.00139), (-8.0, 0.000846), (-6.0, 0.000942),
             (-4.0, 0.000764), (1.0, 0.000271), (8.0, 0.000406), (45.0, 0.000516)),
    "reference": REFERENCE_RESOLUTION,
}

#: The sky-view map's error against the reference itself, the observer on the ground (p95, 64 x 64 fisheye,
#: the default 64 x 128 map of each level's table as the plan gives it; the same runs and tables as
#: :data:`RAY_MARCH_ERROR`'s, their sky-view map column): {level: ((sun elevation [deg], p95), ...)}. The
#: default level's map is within 0.11 % of its ray march's error (0.83 against 0.80 % at -6 deg, 0.79 against
#: 0.68 % at -4), where the sum of the two (:data:`RAY_MARCH_ERROR` and the row's own against the ray march,
#: 0.31 % at -6 deg, the worst observer) would say 1.1 %; the draft's within 0.31 % (6.58 against 6.27 % at -4);
#: the high level's 0.05-0.14 % above its ray march's, past its 0.1 % at every sun but +1 deg (0.11 % by day,
#: 0.18 % at -6 deg). Measured for one path, like RAY_MARCH_ERROR: the default animation's own plan (-6 to 60
#: deg) had its map 0.92 % off at -6 deg (a probe, 2026-12-07).
SKYVIEW_ON_REFERENCE = {
    "draft": ((-12.0, 0.297), (-10.0, 0.236), (-8.0, 0.122), (-6.0, 0.141),
              (-4.0, 0.0658), (1.0, 0.0156), (8.0, 0.0251), (45.0, 0.0284)),
    "default": ((-12.0, 0.0157), (-10.0, 0.0133), (-8.0, 0.0101), (-6.0, 0.00826),
                (-4.0, 0.00785), (1.0, 0.00177), (8.0, 0.00306), (45.0, 0.00351)),
    "high": ((-12.0, 0.00293), (-10.0, 0.00250), (-8.0, 0.00220), (-6.0, 0.00176),
             (-4.0, 0.00158), (1.0, 0.00084), (8.0, 0.00112), (45.0, 0.00113)),
}


#: Measured error of the 4D table lookup (p95 against the ray march of the table's own orders, 1024^2 fisheye
#: from the ground, 16 x 128 x 128 x 16 table, physical preset; README "The 4D table", bench/bench_lookup4d.py,
#: 2026-12-02) by sun elevation [deg]: 0.58 % at +30, 0.34 % at +5, 0.32 % at 0, 2.13 % at -4, 3.9 % at -6.
LOOKUP4D_ERROR = ((-6.0, 0.039), (-4.0, 0.0213), (0.0, 0.0032), (5.0, 0.0034), (30.0, 0.0058))


#: Rendered pixels a frame when the caller does not say: the default animation's 512 x 512 fisheye
#: (its all-sky disc: :class:`clsky.anim.cameras.FisheyeCamera`).
DEFAULT_PIXELS = 205892


@dataclasses.dataclass(frozen=True)
class RendererRow:
    """One renderer the plan may pick.

    Attributes
    ----------
    method : str
        Its ``clsky animate --method`` name.
    description : str
        As the plan prints it.
    fixed_cpu_ms : float
        Process CPU time of a frame that does not depend on its pixels [ms] (the sky-view map's own march).
    pixel_cpu_ns : float
        Process CPU time per rendered pixel [ns]: a frame of N pixels costs fixed_cpu_ms + N pixel_cpu_ns
        (:meth:`frame_cpu_ms`; measured, bench/bench_renderer_costs.py).
    error : tuple of (sun elevation [deg], p95 relative error)
        Its measured error (see the module docstring), ascending in elevation.
    on_ray_march : bool
        True when ``error`` adds to the ray march's (its frames are made from the ray march).
    source : str
        Where the figures come from.
    build_cpu_s : float
        Process CPU time of the table of its own that it needs [s] (0: none, or the plan's 3D table,
        which every renderer's plan builds).
    on_reference : tuple
        ((quality level, ((sun elevation [deg], p95 relative error), ...)), ...): where an ``on_ray_march`` row
        was measured against the reference itself, the observer on the ground, for that level's tables,
        ascending in elevation (:func:`estimated_error`); pairs, so that a row stays hashable.
    """

    method: str
    description: str
    fixed_cpu_ms: float
    pixel_cpu_ns: float
    error: tuple
    on_ray_march: bool
    source: str
    build_cpu_s: float = 0.0
    on_reference: tuple = ()

    def frame_cpu_ms(self, pixels):
        """Process CPU time [ms] of one frame of ``pixels`` rendered pixels."""
        return self.fixed_cpu_ms + pixels * self.pixel_cpu_ns * 1e-6

    def cost_cpu_s(self, frames, pixels):
        """Process CPU time [s] of ``frames`` frames of ``pixels`` pixels: the build plus the frames."""
        return self.build_cpu_s + frames * self.frame_cpu_ms(pixels) / 1000.0


#: The renderers, with their measured costs and errors. Costs: process CPU of a frame from the ground (HDR
#: frame on the host), bench/bench_renderer_costs.py (README "Scene plan"), 2026-12-06, Intel Xeon, 2 cores,
#: PoCL, the default animation's planned table (32 x 128 x 208, M = 2) and ray march; a line through
#: fisheyes of 256, 512 and 1024 pixels a side (within 2 % of each); one frame a call (an animation
#: marches its sky-view maps and ray march four suns a launch on a CPU, cheaper a frame). A run minutes
#: before, in the machine's slow state, measured every cost 10-25 % higher and the crossovers between rows
#: within 5 % of these. The sky-view map's errors: p95 against the per-pixel ray march of the table the planner
#: gives the observer at the default level, the worst of the ground and 10 km looking up or tilted down (README
#: "Sky-view table", bench/bench_skyview.py, two runs of 2026-12-07 and 08, the same to the digit;
#: tests/test_skyview.py's small table had said 0.16 % at -4 deg, the planned tables 0.29 %), taken for every
#: level (the other levels' tables were not measured); and against the reference itself, per level, from the
#: ground (:data:`SKYVIEW_ON_REFERENCE`).
RENDERERS = (
    RendererRow("lut", "table lookup", 1.0, 38.5, LOOKUP_ERROR, False,
                "README 'Speed versus accuracy' (error) and 'Scene plan' (cost)"),
    RendererRow("skyview", "sky-view map 64 x 128", 13.8, 18.2,
                ((-12.0, 0.00553), (-10.0, 0.00599), (-8.0, 0.00432), (-6.0, 0.00314), (-4.0, 0.00292),
                 (0.0, 0.00145), (1.0, 0.00148), (5.0, 0.00171), (10.0, 0.00182), (30.0, 0.00187), (45.0, 0.00183)),
                True, "README 'Sky-view table' (error against the ray march) and 'Quality levels' (against the "
                "reference); README 'Scene plan' (cost)", on_reference=tuple(SKYVIEW_ON_REFERENCE.items())),
    RendererRow("lut4d", "4D table lookup", 0.8, 45.6, LOOKUP4D_ERROR, True,
                "README 'The 4D table' (error against the ray march of its orders); README 'Scene plan' (cost and "
                "build)", build_cpu_s=12.4),
    RendererRow("raymarch", "ray march", 1.5, 1574.3, ((0.0, 0.0),), True,
                "README 'Scene plan' (cost); the plan's reference: its error is the quality level's "
                "(RAY_MARCH_ERROR)"),
)


def error_at(error, at):
    """``error`` ((elevation [deg], p95), ..., ascending in elevation) at the sun elevations ``at`` [deg] (an
    array): interpolated in log error between the measured elevations (linearly throughout if any value is 0),
    the nearest value beyond them."""
    elevations, values = (np.asarray(v, dtype=float) for v in zip(*error))
    if np.all(values > 0.0):
        return np.exp(np.interp(at, elevations, np.log(values)))
    return np.interp(at, elevations, values)


def worst_over(error, low, high):
    """(sun elevation [deg], p95): where ``error`` ((elevation, p95), ...) is worst over sun elevations [low,
    high] [deg], and its value there: at one of the ends or of the measured elevations between them
    (:func:`error_at`; interpolated in log error, the worst is at one of them)."""
    elevations = np.asarray([elevation for elevation, _ in error], dtype=float)
    at = np.concatenate([[low, high], elevations[(elevations > low) & (elevations < high)]])
    values = error_at(error, at)
    return float(at[np.argmax(values)]), float(values.max())


def error_over(error, low, high):
    """The worst of ``error`` ((elevation, p95), ...) over sun elevations [low, high] [deg] (:func:`worst_over`)."""
    return worst_over(error, low, high)[1]


def _measured_on_reference(row, level, altitude_m):
    """``row``'s error measured against the reference for ``level``'s tables ((sun elevation, p95), ...), or ()
    where there is none or it does not apply: it was measured from the ground, and so serves observers on it
    (``altitude_m`` 0) only, as the 3D lookup's errors do (:func:`clsky.planner.plan_scene`)."""
    return dict(row.on_reference).get(level, ()) if altitude_m == 0.0 else ()


def _estimate_nodes(row, level, altitude_m):
    """(elevations [deg], p95, what each is, whether it was measured there) of :func:`estimated_error` at its
    nodes: 'reference' where the measurement against the reference gives it, 'floor' where the ray march's
    error does (the measurement was lower), 'sum' where the ray march's error plus the row's does; measured
    where the figures it is made of were measured at that elevation, not interpolated."""
    march, direct = RAY_MARCH_ERROR[level], _measured_on_reference(row, level, altitude_m)
    nodes = np.array(sorted({elevation for elevation, _ in march + row.error + direct}))
    values = error_at(march, nodes) + error_at(row.error, nodes)
    kinds = np.array(["sum"] * len(nodes), dtype=object)
    measured_at = {kind: {elevation for elevation, _ in table} for kind, table in
                   (("march", march), ("own", row.error), ("reference", direct))}
    adds = any(error for _, error in row.error)     # a row that adds nothing (the ray march's) needs no own node
    measured = np.array([sun in measured_at["march"] and (sun in measured_at["own"] or not adds) for sun in nodes])
    if direct:
        spanned = (nodes >= direct[0][0]) & (nodes <= direct[-1][0])
        # never better than the ray march its frames are made from (the draft's map measured 0.122 % at -8 deg
        # against its ray march's 0.123 %: a measurement on one plan's tables, whose sun nodes fall elsewhere on
        # another's)
        on_reference, floor = error_at(direct, nodes[spanned]), error_at(march, nodes[spanned])
        values[spanned] = np.maximum(on_reference, floor)
        kinds[spanned] = np.where(on_reference >= floor, "reference", "floor")
        measured[spanned] = [sun in measured_at["reference" if kind == "reference" else "march"]
                             for sun, kind in zip(nodes[spanned], kinds[spanned])]
    return nodes, values, kinds, measured


def estimated_error(row, level, altitude_m=0.0):
    """A renderer row's estimated error ((sun elevation [deg], p95), ...) for quality level ``level``'s tables
    and observers up to ``altitude_m`` [m]. A row measured against the reference (``on_ray_march`` False): its
    own. A row whose frames are made from the ray march: at each elevation measured for either, the level's
    ray-march error (:data:`RAY_MARCH_ERROR`) plus the row's own; over the elevations that the row's
    measurement against the reference for the level spans (``on_reference``), that measurement instead, but
    no less than the ray march's, when the observers are on the ground. Interpolated between those
    elevations like any measured error (:func:`error_at`), the two kinds of figure meet without a step."""
    if not row.on_ray_march:
        return row.error
    nodes, values, _, _ = _estimate_nodes(row, level, altitude_m)
    return tuple(zip(nodes.tolist(), values.tolist()))


def with_resolution(error, level):
    """``error`` ((sun elevation [deg], p95), ..., ascending), measured against the reference, as an estimate of
    the error against the converged sky: plus how far the reference itself is resolved
    (:data:`REFERENCE_RESOLUTION`) at each elevation of either, interpolated like any measured error
    (:func:`error_at`), as if the two erred with one sign at the same pixels. ``level``: the quality level whose
    ray march the figures are made from, or None for figures of their own (the 3D lookup's); for the
    'reference' level's ray march, ``error`` as it is (its figures are that resolution already)."""
    if level == "reference":
        return tuple(error)
    nodes = sorted({sun for sun, _ in tuple(error) + REFERENCE_RESOLUTION})
    return tuple(zip(nodes, (error_at(error, nodes) + error_at(REFERENCE_RESOLUTION, nodes)).tolist()))


def _compared(row, level, altitude_m):
    """What :func:`choose_renderer` compares with a budget for ``row`` ((sun elevation [deg], p95), ...): its
    :func:`estimated_error` plus the reference's own (:func:`with_resolution`; the figures of a row not made
    from the ray march are its own, whatever the level)."""
    return with_resolution(estimated_error(row, level, altitude_m), level if row.on_ray_march else None)


def renderer_row(method, rows=RENDERERS) -> RendererRow:
    """The row of ``rows`` whose ``--method`` name is ``method`` (ParameterError for a name of none)."""
    check_choice("method", method, [row.method for row in rows])
    return next(row for row in rows if row.method == method)


def estimate_basis(row, level, sun_elevations_deg, altitude_m=0.0) -> str:
    """How ``row``'s estimated error over the sun path (low, high) [deg] was made, in the scene plan's words:
    at its worst sun, the row's own measured error, its error against the reference (``on_reference``), the ray
    march's where that was lower, or the ray march's plus its own (:func:`estimated_error`); 'measured at' a
    sun where the figures were, 'interpolated at' one between measured suns, and between two kinds of figure,
    both."""
    marched_from = level if row.on_ray_march else None

    def resolution(at):
        if marched_from == "reference":     # its figures are the reference's own error already
            return ""
        return f", + the reference's own estimated error, {100 * float(error_at(REFERENCE_RESOLUTION, at)):.2g} %"

    if marched_from == "reference" and not any(error for _, error in row.error):    # the ray march's own row
        worst = worst_over(RAY_MARCH_ERROR["reference"], *sun_elevations_deg)[0]
        return f"the reference's own estimated error, at {worst:g} deg"
    if not row.on_ray_march:
        worst = worst_over(_compared(row, level, altitude_m), *sun_elevations_deg)[0]
        return "measured" + resolution(worst)
    nodes, _, kinds, measured = _estimate_nodes(row, level, altitude_m)
    # the worst of what choose_renderer compares; its nodes are the estimate's, as REFERENCE_RESOLUTION's suns
    # are among every level's ray-march suns (tested)
    compared = _compared(row, level, altitude_m)
    if [sun for sun, _ in compared] != nodes.tolist():
        raise ValueError(f"REFERENCE_RESOLUTION has suns that the {level!r} level's RAY_MARCH_ERROR lacks")
    values = np.array([value for _, value in compared])
    own = any(error for _, error in row.error)
    said = {"reference": "measured against the reference",
            "floor": "the ray march's, measured (the map measured less)",
            "sum": "estimated: the ray march's + its own, measured" if own else "the ray march's, measured"}
    short = {"reference": "its measurement against the reference", "floor": "the ray march's",
             "sum": "the ray march's + its own" if own else "the ray march's"}
    # the worst sun, or beyond the measured elevations the nearest one, whose value it takes
    worst = min(max(worst_over(tuple(zip(nodes, values)), *sun_elevations_deg)[0], nodes[0]), nodes[-1])
    at = int(np.searchsorted(nodes, worst))
    if nodes[at] == worst and measured[at]:
        return f"{said[kinds[at]]} at {worst:g} deg{resolution(worst)}"
    below, above = (kinds[at], kinds[at]) if nodes[at] == worst else (kinds[at - 1], kinds[at])
    if below == above:
        return f"{said[above]}, interpolated at {worst:g} deg{resolution(worst)}"
    return f"interpolated at {worst:g} deg between {short[below]} and {short[above]}{resolution(worst)}"


def choose_renderer(sun_elevations_deg, budget, level="default", rows=RENDERERS, frames=None, pixels=DEFAULT_PIXELS,
                    altitude_m=0.0):
    """(row, estimated error, {method: estimated error}): the cheapest row of ``rows`` whose estimated error over
    the sun path ``sun_elevations_deg`` = (low, high) [deg] fits ``budget`` (relative), for the ray march of
    quality level ``level`` (a name of :data:`RAY_MARCH_ERROR`) and observers up to ``altitude_m`` [m]; the
    'raymarch' row when none fits. The estimate is the worst over the path of :func:`estimated_error` (until
    2026-12-07, the ray march's worst plus the row's worst, wherever each was), plus the reference's own
    estimated error (:func:`with_resolution`, since 2026-12-08: until then the figures against the reference
    alone, so the default animation's sky-view map, 0.83 % off it at -6 deg, fitted 1 % with no word of the
    reference's own 0.14 % there). The cost of ``frames`` frames of ``pixels`` rendered pixels each
    (:meth:`RendererRow.cost_cpu_s`) decides; with ``frames=None`` (the frame count unknown) the rows with a build
    of their own are left out (module docstring) and the cost of one frame decides. ValueError naming an
    argument that is no such value: the path's elevations in [-90, 90], low <= high; the budget in (0, 1];
    frames and pixels at least 1 (a negative count made the dearest row cheapest); the altitude in [0, 1e8] m."""
    low, high = check_range("sun_elevations_deg", sun_elevations_deg, -90.0, 90.0)
    check_real("budget", budget, 0.0, 1.0, low_open=True)
    check_choice("level", level, list(RAY_MARCH_ERROR))
    check_integer("frames", frames, 1, 10**9, optional=True)
    check_integer("pixels", pixels, 1, 2**31 - 1)
    check_real("altitude_m", altitude_m, 0.0, 1e8)
    estimates = {row.method: error_over(_compared(row, level, altitude_m), low, high) for row in rows}
    candidates = [row for row in rows if frames is not None or row.build_cpu_s == 0.0]
    for row in sorted(candidates, key=lambda r: r.cost_cpu_s(1 if frames is None else frames, pixels)):
        if estimates[row.method] <= budget:
            return row, estimates[row.method], estimates
    fallback = renderer_row("raymarch", rows)
    return fallback, estimates[fallback.method], estimates
