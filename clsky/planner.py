"""Compute only what a scene requires: from a scene description to the least table that serves it.

A :class:`Scene` says what will be rendered: the sun elevations of its path, the observer's altitudes,
the view elevations its cameras see, the light components wanted and an error budget. :func:`plan_scene`
turns it into a :class:`Plan`: table settings, the ray march's quadrature, and each decision with its
reason, printed by :meth:`Plan.describe` with the work saved against the full table of the same quality.

What the plan decides, and why:

* **Sun axis**: only the sun cosines the scene can reach, plus the margins that the curvature of the
  Earth and the higher orders need (:func:`sun_margins`). Along a view ray the local zenith turns by
  the central angle gamma between the ray's points; the sun's zenith angle there changes by up to gamma.
  The ray march reads the higher orders at every point of its pixel rays (both ways: +- gamma_view, the
  longest pixel ray's angle); the table's scatter reads them along its canonical rays, which run toward
  the sun's azimuth, so toward a *higher* sun (up to + gamma_table, the longest ray through the
  atmosphere: 2 acos(Rp / Ra), 20.2 deg for Ra - Rp = 100 km), except that a ray passing under the sun
  sees it sink again, to no lower than 90 deg - gamma_table. The nodes keep the quality level's
  spacing (:mod:`clsky.quality`), so a narrower range costs proportionally fewer nodes.
* **Altitude and view axes** stay whole whatever the scene: the gather integrates the in-scatter over
  every view direction, and every view ray crosses all altitudes up to the top. The plan reports the
  part the scene itself reaches.
* **Resolution and orders** come from the quality level the budget asks for
  (:func:`clsky.quality.level_for_budget`), or the first finer one whose ray march's error measured against
  the reference, plus the reference's own estimated error (:func:`promise_bounds`), fits the budget over
  the sun path (the reference level where none does, said so); a level's promise is taken to hold only down to
  the sun where that bound was last within it (:func:`promise_measured_down_to`), and a plan whose sun goes
  lower says what was measured there.
* **Higher orders** are dropped when a pilot (a small table on the planned sun range, ray-marched on a
  coarse fisheye over the cameras' view elevations at the path's lowest, highest and horizon suns) shows
  that they add less than half the budget, or when the scene does not want them. The pilot's share is
  kept on disk for the next plan of the same scene on the same device and code (:func:`pilot_share`).
* **Mie** is dropped (its scattering set to 0: the Mie channels hold zeros) only when the scene does
  not want it; an atmosphere without Mie has nothing to drop.
* **Renderer** (:mod:`clsky.renderer_choice`): the cheapest of the table lookup, the per-frame sky-view
  map and the ray march whose measured error over the sun path fits the budget, costed for frames of the
  scene's pixels (:attr:`Plan.renderer`). The table lookup alone serves the scene only where its measured
  error (:data:`LOOKUP_ERROR`) fits at the path's lowest sun, and on frames where it is the cheaper (below
  about 630 000 pixels: the sky-view map's own march costs the same whatever the frame, its reading less
  a pixel); the sky-view map (the ray march read at a map's nodes) where its error fits (measured against
  the reference from the ground; from above, the level's ray-march error plus the map's own), on frames large
  enough to pay for its map (about 7900 pixels); otherwise the ray
  march. The sky-view map and the ray march need the ray march's quadrature and margins, and so does an
  animation that renders the ray march whatever the plan picks (``plan_scene(..., ray_march=True)``; the
  plan then says which lookup would do; ``clsky animate --method compare`` compares the ray march with the
  sky-view map when the plan picks it or the ray march). The 4D table lookup is not a choice of the plan: its
  table is a build of its own, which pays only over a frame count the plan does not know
  (:mod:`clsky.renderer_choice`).
* **Azimuth harmonics** (:func:`azimuth_harmonics`): the orders k >= 2 carry the view-sun azimuth
  (:mod:`clsky.azimuth`, M = :attr:`clsky.quality.QualityLevel.twilight_harmonics`, 2) when the
  scene's sun goes below :data:`HARMONICS_BELOW_DEG` (+30 deg), the azimuth average (M = 0) otherwise.
  Against the Monte Carlo (README, "Twilight against Monte Carlo") the azimuth average is too bright
  by +6 % on average at 0 deg and +134 % at -6 deg, while M = 2 stays within the tracer's noise (p95
  0.7-2.2 % from +10 to -6 deg). By day its worst view (4 deg up, across the sun) stays over issue
  11's 2 % bar up to +20 deg: p95 of the deviation (four views, three channels) 2.7 % at +10 deg,
  2.1 % at +20 deg, 1.8 % at +30 deg (tracer's standard errors 0.1-0.7 %).
  It costs about 5 times the table build (each order scattered and gathered at 3 azimuths; measured
  81 against 16 CPU-s for the default animation's table) and 1.4 times the ray-marched frame (3
  lookups per sample), so scenes whose sun stays at or above +30 deg, where the azimuth average
  meets the bar, keep it (README, "Twilight against Monte Carlo").
* **View nodes** (:func:`view_sampling`, for the table and the ray march alike): 'ground_end' when an
  observer is above the ground, Keller & Bohn's otherwise. Keller & Bohn's nodes bunch at the
  observer while, looking down, the haze lies at the ground end: on rays that hit the ground their
  single scattering is 4.6 % off from 10 km and 291 % from 100 km (worst channel, 30 steps), where
  'ground_end' stays within 1.82 %; no altitude measured (1 to 100 km) does worse with it, and it
  moves no node of a ray that leaves the atmosphere. From the ground no view ray hits the ground, so
  the quality levels' nodes (measured as they are) stay, and ground scenes keep their tables and
  frames bit for bit (README, "Views from altitude").
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math

import numpy as np

from . import _cl
from ._cache import cache_directory, source_digest, store
from ._files import read_user_text
from .atmosphere import AtmosphereParameters, as_atmosphere
from .ground import check_ground_mode, sky_irradiance
from .errors import check_choice, check_flag, check_instance, check_integer, check_range
from .mapping import cos_to_v
from .quality import QUALITY_LEVELS, QualityLevel, level_for_budget, quality_level
from .renderer_choice import (DEFAULT_PIXELS, LOOKUP_ERROR, RAY_MARCH_ERROR, REFERENCE_RESOLUTION, RENDERERS,
                              choose_renderer, error_at, error_over, estimate_basis, renderer_row, with_resolution)
from .settings import SAMPLINGS, SCATTERING_MODES, TableSettings

__all__ = ["Scene", "Plan", "plan_scene", "sun_margins", "sun_axis", "sees_ground", "view_sampling",
           "azimuth_harmonics", "promise_bounds", "promise_measured_down_to", "LOOKUP_ERROR", "COMPONENTS",
           "HARMONICS_BELOW_DEG"]

#: Light components a scene may want.
COMPONENTS = ("rayleigh", "mie", "multiple")


@dataclasses.dataclass(frozen=True)
class Scene:
    """What a scene will render.

    Parameters
    ----------
    sun_elevations_deg : (low, high)
        Lowest and highest sun elevation of the sun path [deg], in [-90, 90].
    altitudes_m : (low, high)
        Lowest and highest observer altitude [m], in [0, 1e8] (default the ground).
    view_elevations_deg : (low, high)
        Lowest and highest view elevation the cameras see [deg], in [-90, 90] (default an all-sky
        fisheye: 0 to 90).
    components : tuple of str
        Wanted light: any of 'rayleigh', 'mie', 'multiple' (higher orders); 'rayleigh' is required.
    error_budget : float
        Relative error allowed in rendered frames, in (0, 1] (default 0.01: 1 %).
    quality : str, optional
        A named level (:data:`clsky.quality.QUALITY_LEVELS`) instead of the one the budget picks.
    pixels : int
        Pixels rendered a frame, in [1, 2^31 - 1] (default :data:`clsky.renderer_choice.DEFAULT_PIXELS`,
        the default animation's 512 x 512 fisheye): which renderer is the cheapest depends on it.
    """

    sun_elevations_deg: tuple
    altitudes_m: tuple = (0.0, 0.0)
    view_elevations_deg: tuple = (0.0, 90.0)
    components: tuple = COMPONENTS
    error_budget: float = 0.01
    quality: str | None = None
    pixels: int = DEFAULT_PIXELS

    def __post_init__(self):
        object.__setattr__(self, "sun_elevations_deg", check_range("sun_elevations_deg", self.sun_elevations_deg,
                                                                   -90.0, 90.0))
        object.__setattr__(self, "altitudes_m", check_range("altitudes_m", self.altitudes_m, 0.0, 1e8))
        object.__setattr__(self, "view_elevations_deg",
                           check_range("view_elevations_deg", self.view_elevations_deg, -90.0, 90.0))
        components = (tuple(self.components) if isinstance(self.components, (tuple, list, set, frozenset))
                      else (self.components,))
        if any(not isinstance(c, str) for c in components) or any(c not in COMPONENTS for c in components) \
                or "rayleigh" not in components:
            raise ValueError(f"components must be a subset of {list(COMPONENTS)} that holds 'rayleigh', "
                             f"got {self.components!r}")
        object.__setattr__(self, "components", components)
        level_for_budget(self.error_budget)                       # validates error_budget
        if self.quality is not None:
            quality_level(self.quality)                           # validates quality
        object.__setattr__(self, "pixels", check_integer("pixels", self.pixels, 1, 2 ** 31 - 1))


@dataclasses.dataclass(frozen=True)
class Plan:
    """The least work that serves a :class:`Scene` (see the module docstring).

    Attributes
    ----------
    scene : Scene
    level : QualityLevel
        The quality the plan meets.
    atmosphere : AtmosphereParameters
        The atmosphere to build (Mie removed if the scene does not want it).
    table : TableSettings
        The table to build: the level's, on the planned sun range.
    ray : TableSettings or None
        The ray march's quadrature (of the ray march, or of the sky-view map's nodes), or None when the
        table lookup alone meets the budget and no ray march was asked for (``plan_scene(...,
        ray_march=True)`` keeps it, with ``renderer`` 'lut' still the cheapest renderer within the budget).
    decisions : tuple of (topic, decision, reason)
    renderer : str
        The cheapest renderer that meets the budget (:func:`clsky.renderer_choice.choose_renderer`), a
        ``clsky animate --method``: 'lut', 'skyview' or 'raymarch'.
    """

    scene: Scene
    level: QualityLevel
    atmosphere: AtmosphereParameters
    table: TableSettings
    ray: TableSettings | None
    decisions: tuple
    renderer: str = "raymarch"

    @property
    def budget(self) -> float:
        """The error budget the plan meets: the scene's, or its named quality level's."""
        return self.level.budget if self.scene.quality else self.scene.error_budget

    @property
    def full_table(self) -> TableSettings:
        """The table of the same quality over the whole sun axis (what the plan is measured against)."""
        return self.level.table.replace(mode=self.table.mode, sampling=self.table.sampling,
                                        azimuth_harmonics=self.table.azimuth_harmonics,
                                        source_stride=self.table.source_stride)

    @property
    def work_fraction(self) -> float:
        """Planned table cells over the full table's (the cost of every order scales with the cells)."""
        return float(np.prod(self.table.size)) / float(np.prod(self.full_table.size))

    def describe(self) -> str:
        """The plan as text: one line per decision, then the work against the full table."""
        lines = [f"scene plan ({self.level.name} quality, error budget {100 * self.budget:g} %):"]
        width = max(len(topic) for topic, _, _ in self.decisions)
        for topic, decision, reason in self.decisions:
            lines.append(f"  {topic:<{width}}  {decision}  ({reason})")
        w, h, d = self.table.size
        fw, fh, fd = self.full_table.size
        lines.append(f"  {'work':<{width}}  table {w} x {h} x {d} = {w * h * d} cells, "
                     f"{100 * self.work_fraction:.0f} % of the full table's {fw} x {fh} x {fd} = {fw * fh * fd}")
        return "\n".join(lines)


def view_sampling(altitudes_m) -> tuple:
    """(sampling, reason): the node placement along view rays (``TableSettings.sampling``) for
    observers at altitudes ``altitudes_m`` = (low, high) [m].

    'ground_end' when the highest observer is above the ground: its rays that hit the ground then get
    nodes clustered at the ground end, where the haze is. On those rays Keller & Bohn's nodes are up to
    4.6 % off from 10 km, 50 % from 32.7 km and 291 % from 100 km; 'ground_end' at most 1.82 %, and
    no worse than Keller & Bohn's at any altitude measured (1 to 100 km; worst of the six Ibar
    channels, 30 view steps, against :mod:`clsky.ray_quadrature`; README, "Views from altitude",
    bench/bench_view_nodes.py). Every other ray keeps Keller & Bohn's nodes bit for bit.
    'keller_bohn' (the quality levels') for observers on the ground, none of whose view rays hits the
    ground.

    Parameters
    ----------
    altitudes_m : (low, high)
        Lowest and highest observer altitude [m], 0 <= low <= high <= 1e8 (as :class:`Scene`).

    Returns
    -------
    (str, str)
        The ``TableSettings.sampling`` name and the reason, as :meth:`Plan.describe` prints it.
    """
    low, high = check_range("altitudes_m", altitudes_m, 0.0, 1e8)
    if high > 0.0:
        return "ground_end", (f"an observer at {high:g} m: rays that hit the ground get nodes at their ground "
                              "end, where the haze is (Keller & Bohn's are 4.6 % off from 10 km, 291 % from 100 km)")
    return "keller_bohn", "observers on the ground: no view ray hits the ground"


#: The highest observer [m] for whom the lookups' and the sky-view map's measured errors
#: (:mod:`clsky.renderer_choice`: the lookups' from the ground, the map's own against the ray march the worst of
#: the ground and 10 km) are taken: above it the plan ray-marches. From 10 km the sky-view map was 0.13-0.19 % off
#: the ray march by day and up to 0.60 % at -10 deg (README "Sky-view table"), from 30 km 1.0 % at the horizon,
#: from 1000 km 13.9 %, where the plan promised 0.45 % (a probe of the planner, 2026-12-07).
RENDERER_ERRORS_MEASURED_UP_TO_M = 10e3

def promise_bounds(name):
    """((sun elevation [deg], bound), ...), ascending: how far quality level ``name``'s ray march may be off the
    converged sky at each measured sun, as far as the benchmarks can tell: its error measured against the
    reference (:func:`measured_errors`) plus how far the reference itself is resolved there
    (:func:`clsky.renderer_choice.with_resolution`; for the 'reference' level, that resolution alone)."""
    return with_resolution(measured_errors(name), name)


def promise_measured_down_to(level):
    """The lowest sun [deg] down to which quality ``level``'s promise was measured to hold, or None where it was
    not at the highest measured sun: walking down the measured elevations, the last before the first whose
    bound (:func:`promise_bounds`: the measured error plus the reference's resolution) exceeds the level's
    budget, and no lower than the lowest sun at which the reference's resolution was measured. Measured
    2026-12-07/08 (bench/bench_quality.py, bench_quality_dusk.py): the draft holds its 10 % down to -4 deg (14 %
    off at -6), the default level its 1 % down to -6 deg (0.80 + 0.14 % there, 0.996 + 0.18 % at -8), the high
    level its 0.1 % down to +1 deg (0.027 + 0.018 % there; at -4 deg 0.076 % off the reference, which resolves
    0.09 % itself), the reference its 0.05 % down to +1 deg (its resolution, 0.09 % at -4 deg). Until
    2026-12-08 the rule took the measured error alone, down to -4 deg at most (where the reference's resolution
    was measured): every level held to -4 deg. A plan whose sun goes lower says what its level measured there,
    and a plan by error budget takes the fastest level whose bound over the path fits the budget."""
    floor = min(sun for sun, _ in REFERENCE_RESOLUTION)
    holds = None
    for sun, bound in sorted(promise_bounds(level.name), reverse=True):
        if bound > level.budget or sun < floor:
            break
        holds = sun
    return holds


#: A table planned for a sun path that goes below this elevation [deg] scatters its orders with their source
#: read at every view node (``TableSettings.source_stride`` 1), whatever its level's stride: read at every other
#: one, the draft and default levels were 10.7 and 1.2 % off the reference at -6 deg (9.2 and 0.88 % at every
#: node), the default 1.60 % at -8 deg (0.91 %); at -4 deg the default 0.68 % against 0.60 % (a probe,
#: 2026-12-07; README "Quality levels"). The default animation's planned table takes 25 % more CPU time for it
#: (8.30 against 6.61-6.76 CPU-s, docs/speed-log.md).
SOURCE_EVERY_NODE_BELOW_DEG = -4.0

def measured_errors(name):
    """A quality level's measured ray-march errors ((sun elevation [deg], p95), ...), ascending
    (:data:`clsky.renderer_choice.RAY_MARCH_ERROR`: bench/bench_quality.py from -4 deg up,
    bench/bench_quality_dusk.py below)."""
    return RAY_MARCH_ERROR[name]


#: A scene whose sun goes below this elevation [deg] gets the higher orders with azimuth harmonics
#: (:func:`azimuth_harmonics`). Issue 11 asks for 2 % (95th percentile) at 0 deg and above; the azimuth
#: average misses it up to +20 deg (p95 of four views' deviation from the tracer: 3.6 % at +5, 2.7 % at
#: +10, 2.1 % at +20 deg; across the sun, 4 deg up) and meets it at +30 deg (1.8 %).
HARMONICS_BELOW_DEG = 30.0


def azimuth_harmonics(level: QualityLevel, sun_elevations_deg, mode="physical") -> tuple:
    """(M, reason): the ``TableSettings.azimuth_harmonics`` of a table for a sun path
    ``sun_elevations_deg`` = (low, high) [deg] at quality ``level`` (module docstring).

    The level's own table setting when it has one (the 'reference' level carries harmonics at every
    sun); else ``level.twilight_harmonics`` when the lowest sun is below :data:`HARMONICS_BELOW_DEG`
    and the scheme is 'physical' (the harmonics need it); else 0, the azimuth average.
    """
    low, _ = check_range("sun_elevations_deg", sun_elevations_deg, -90.0, 90.0)
    if mode != "physical":
        return 0, f"the {mode} scheme has no azimuth harmonics"
    if level.table.azimuth_harmonics:
        return level.table.azimuth_harmonics, f"the {level.name} level carries them at every sun"
    if low < HARMONICS_BELOW_DEG and level.twilight_harmonics:
        return level.twilight_harmonics, (
            f"the sun goes down to {low:g} deg, below {HARMONICS_BELOW_DEG:g}: the azimuth average is "
            f"2.1 % off at +20 deg, +6 % at 0 deg and +134 % at -6 deg against the Monte Carlo, M = 2 "
            f"within 2.2 %")
    return 0, (f"the sun stays at or above {HARMONICS_BELOW_DEG:g} deg, where the azimuth average is "
               f"within 2 % of the Monte Carlo (1.8 % at +30 deg)")


def _ray_angle(planet_radius, top_radius, radius, mu):
    """Central angle [rad] between a ray's start (radius, view cosine mu) and where it leaves the
    atmosphere or meets the ground (arrays); 0 for a ray from above the top that misses the atmosphere
    (it reads nothing)."""
    discriminant_ground = radius * radius * (mu * mu - 1.0) + planet_radius ** 2
    discriminant_top = radius * radius * (mu * mu - 1.0) + top_radius ** 2
    hits_ground = (mu < 0.0) & (discriminant_ground >= 0.0)
    to_ground = -radius * mu - np.sqrt(np.maximum(discriminant_ground, 0.0))
    to_top = -radius * mu + np.sqrt(np.maximum(discriminant_top, 0.0))
    length = np.where(hits_ground, to_ground, to_top)
    end = np.sqrt(radius * radius + 2.0 * radius * mu * length + length * length)
    angle = np.arccos(np.clip((radius + length * mu) / end, -1.0, 1.0))
    misses = (radius > top_radius) & ((mu >= 0.0) | (discriminant_top < 0.0))
    return np.where(misses, 0.0, angle)


def sun_margins(atmosphere: AtmosphereParameters, scene: Scene, orders=True, ray_march=True):
    """(below, above) [deg]: how far beyond the scene's sun elevations the table's sun axis must reach.

    With higher orders, the table's scatter reads them along its rays at a sun up to gamma_table =
    2 acos(Rp / Ra) (its longest ray's central angle) higher, or, for a sun within gamma_table of the
    zenith, down to 90 deg - gamma_table (the ray passes under it). A ray march also reads them along
    its pixel rays, at sun angles up to gamma_view either way (the longest pixel ray's central angle,
    :func:`_largest_ray_angle`). A lookup from above the top of the atmosphere reads the table where each
    ray enters it, at that point's own sun, up to gamma_entry = acos(Ra / r) either way (r: the highest
    observer's radius; 0 inside), its single scattering too; and a ray march over a reflecting ground
    reads the sky's irradiance there at each ground point's own sun, up to acos(Rp / r) from the
    observer's (where its cameras look below the ground's horizon), its higher orders kept or not. So
    below = max(gamma_view, gamma_entry, low + gamma_table - 90) and above = max(gamma_view, gamma_entry)
    + gamma_table, for the path's lowest elevation ``low``; without higher orders max(gamma_entry, the
    ground's) both ways.

    Until 2026-12-07 an observer above the top took gamma_table for gamma_view and no margin for its
    lookups: from 400 km the 3D lookup's far limb was 7.3 % too bright, from 1000 km 22 % at the draft
    level (a probe of the planner).
    """
    rp, ra = atmosphere.planet_radius, atmosphere.top_radius
    radius = rp + scene.altitudes_m[1]
    entry = math.degrees(math.acos(ra / radius)) if radius > ra else 0.0
    if not orders:
        ground = math.degrees(math.acos(rp / radius))          # the farthest ground point's central angle
        seen = ray_march and atmosphere.has_ground and sees_ground(atmosphere, scene)
        return (max(entry, ground), max(entry, ground)) if seen else (entry, entry)
    gamma_table = math.degrees(2.0 * math.acos(rp / ra))
    # the largest angle over the observers' range: at its ends, or where the lowest view grazes the ground
    # (rp / cos(view) - rp: there the analytic limb enters; it may lie inside the range)
    altitudes = list(scene.altitudes_m)
    lowest_view = math.radians(scene.view_elevations_deg[0])
    if lowest_view < 0.0:
        grazing = rp / math.cos(lowest_view) - rp
        if altitudes[0] < grazing < altitudes[1]:
            altitudes.append(grazing)
    gamma_view = max(_largest_ray_angle(rp, ra, rp + altitude, scene.view_elevations_deg)
                     for altitude in altitudes) if ray_march else 0.0
    reach = max(gamma_view, entry)
    return max(reach, scene.sun_elevations_deg[0] + gamma_table - 90.0), reach + gamma_table


def sees_ground(atmosphere: AtmosphereParameters, scene: Scene) -> bool:
    """Whether a camera of ``scene`` sees the ground: its lowest view below the lowest observer's horizon,
    -acos(Rp / r) (of a range of observers, the lowest sees the ground at the highest views)."""
    radius = atmosphere.planet_radius + scene.altitudes_m[0]
    return scene.view_elevations_deg[0] < -math.degrees(math.acos(atmosphere.planet_radius / radius))


def _largest_ray_angle(planet_radius, top_radius, radius, view_elevations_deg):
    """The largest central angle [deg] of the rays from ``radius`` at view elevations in
    ``view_elevations_deg`` (:func:`_ray_angle`), sampled at 2001 elevations and, where the range holds
    the ground's horizon, its limit there: a ray that grazes the ground goes on to the top, acos(Rp / r)
    + acos(Rp / Ra) (the samples fell short of it by up to 0.09 deg)."""
    low, high = np.radians(view_elevations_deg)
    largest = float(np.max(_ray_angle(planet_radius, top_radius, radius, np.sin(np.linspace(low, high, 2001)))))
    if radius > planet_radius:
        horizon = -math.acos(planet_radius / radius)         # the elevation of the ground's horizon
        if low <= horizon <= high:
            largest = max(largest, math.acos(planet_radius / radius) + math.acos(planet_radius / top_radius))
    return math.degrees(largest)


def sun_axis(atmosphere: AtmosphereParameters, scene: Scene, level: QualityLevel, mapping="nonlinear",
             orders=True, ray_march=True):
    """The sun axis a scene needs: (sun_cos_range, nodes, (low, high) elevations [deg], margins [deg]).

    The path's elevations widened by :func:`sun_margins` (and to the 2e-3 in cosine that a table's
    range needs at least, for a fixed sun without margins), with as many nodes as keep the level's
    spacing in w.
    """
    margins = sun_margins(atmosphere, scene, orders, ray_march)
    low = max(-90.0, scene.sun_elevations_deg[0] - margins[0])
    high = min(90.0, scene.sun_elevations_deg[1] + margins[1])
    cos_low, cos_high = math.sin(math.radians(low)), math.sin(math.radians(high))
    if cos_high - cos_low < 2e-3:
        middle = min(max(0.5 * (cos_low + cos_high), -1.0 + 1e-3), 1.0 - 1e-3)
        cos_low, cos_high = middle - 1e-3, middle + 1e-3
        low, high = math.degrees(math.asin(cos_low)), math.degrees(math.asin(cos_high))
    w_low, w_high = (float(w) for w in cos_to_v(np.array([cos_low, cos_high]), mapping))
    return (cos_low, cos_high), level.sun_nodes(w_low, w_high), (low, high), margins


def _pilot_settings(table):
    """(table settings, ray settings) of the pilot of a plan's ``table``: the planned sun range and view
    nodes (the pilot took 'keller_bohn' whatever the plan's were: 2 points off in its share from 100 km),
    16 x 64 nodes and enough sun nodes, 'draft' quadrature, the azimuth average (the first order's ground
    light is then its single scattering's, :func:`_higher_orders_share`); a 16-step ray march."""
    from .render import RAYMARCH_DEFAULTS

    pilot = quality_level("draft").table.replace(size=(16, 64, max(8, min(64, table.size[2]))),
                                                 sun_cos_range=table.sun_cos_range, mode=table.mode,
                                                 sampling=table.sampling, azimuth_harmonics=0)
    return pilot, RAYMARCH_DEFAULTS.replace(view_steps=16, transmittance_size=(32, 128), sampling=table.sampling)


def _higher_orders_share(atmosphere, table, scene, ctx=None):
    """Largest share of the higher orders in ray-marched pixels (95th percentile over a 24 x 24 fisheye
    from the lowest observer) at the path's lowest, highest and horizon suns, from a pilot table
    (:func:`_pilot_settings`, the plan's view nodes). The fisheye spans the elevations the scene's cameras
    see (``scene.view_elevations_deg``; the default 0 to 90, the upper hemisphere, with its radius
    linear in elevation): a pilot of the sky alone found no light above the atmosphere (0 %, from where a
    camera sees the Earth below) and dropped the higher orders there."""
    from .render import SkyRenderer
    from .table import ScatteringTable

    pilot, ray = _pilot_settings(table)
    pilot_table = ScatteringTable.build(atmosphere, pilot, ctx=ctx)
    renderer = SkyRenderer(pilot_table, ray, ctx=ctx)
    # the ray march's single scattering does not depend on the table: without the gathered sum, and with a
    # reflecting ground the first order's sky irradiance on it (what a table of orders = 1 holds), the same
    # table gives what the plan renders with the higher orders dropped. With every order's irradiance the
    # ground's higher orders counted as the first's: a camera looking at the ground saw 'at most 0 %' and
    # lost 2.9 % (albedo 0.1) to 10.8 % (albedo 1) of its light (a probe of the planner, 2026-12-07)
    # (E_1 from the pilot's own single scattering, its first order, as a build of orders = 1 takes it: the same
    # bits, without a second build of 0.03-0.04 s; the pilot has no azimuth harmonics, :func:`_pilot_settings`)
    first_ground = None if pilot_table.ground_irradiance is None else \
        sky_irradiance(atmosphere, pilot, pilot_table.orders[0], factored=True)
    single = SkyRenderer(dataclasses.replace(pilot_table, gathered=None, ground_irradiance=first_ground), ray, ctx=ctx)
    n = 24
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n * 2.0 - 1.0
    radius = np.hypot(x, y)
    inside = radius < 1.0
    lowest, highest = np.radians(scene.view_elevations_deg)
    elevation = highest - radius[inside] * (highest - lowest)
    azimuth = np.arctan2(x[inside], y[inside])
    directions = np.stack([np.cos(elevation) * np.sin(azimuth), np.cos(elevation) * np.cos(azimuth),
                           np.sin(elevation)], axis=-1)
    low, high = scene.sun_elevations_deg
    share = 0.0
    for elevation_deg in sorted({low, high, min(max(0.0, low), high)}):
        e = math.radians(elevation_deg)
        sun = np.array([0.0, math.cos(e), math.sin(e)])
        altitude = scene.altitudes_m[0]
        total = renderer.render_raymarch(directions, sun, altitude) @ [0.2126, 0.7152, 0.0722]
        first = single.render_raymarch(directions, sun, altitude) @ [0.2126, 0.7152, 0.0722]
        lit = total > 0.0
        if lit.any():
            share = max(share, float(np.percentile((total[lit] - first[lit]) / total[lit], 95)))
    renderer.close()
    single.close()
    return share


# The pilot's share, kept on disk ---------------------------------------------------------------------

#: Layout of a kept pilot share; a file of another layout is not read (and is rewritten).
PILOT_FORMAT = 2


def pilot_share(atmosphere: AtmosphereParameters, table: TableSettings, scene: Scene, ctx=None) -> float:
    """:func:`_higher_orders_share` of ``scene`` with the plan's ``table``, kept in clsky's cache
    directory (:mod:`clsky._cache`) for the next plan of the same scene.

    The pilot (a table and six ray-marched fisheyes) took about 0.45 s of one core at every plan, about
    a tenth of a default ``clsky render`` (README "Scene plan"). Its share is kept in a small JSON file
    under the key of everything it is computed from: the code (:func:`clsky._cache.source_digest`),
    NumPy's version, the device (name, vendor, versions of device, driver and platform), the kernels' form
    (``clsky._cl.VECTOR_WIDTH``, ``CUBE_ROOT``), the atmosphere, the pilot's table and ray settings, the
    path's sun elevations, the cameras' view elevations and the lowest altitude. A file is read only
    when its key is the whole key and its share a number in [0, 1] (a kept -1 dropped the higher orders
    as adding "at most -100 %"; JSON keeps a float's every
    bit); anything else is computed again and rewritten. Without a cache directory, or where it cannot be
    written, the pilot runs every time. A process-wide setting added later that changes the pilot's values
    must join the key."""
    pilot, ray = _pilot_settings(table)
    device = (ctx if ctx is not None else _cl.make_context()).devices[0]
    key = {"format": PILOT_FORMAT, "clsky": source_digest(), "numpy": np.__version__,
           "device": [device.name, device.vendor, device.version, device.driver_version, device.platform.name,
                      device.platform.version],
           "kernels": {"vector_width": _cl.VECTOR_WIDTH, "cube_root": _cl.CUBE_ROOT},
           "atmosphere": repr(atmosphere), "pilot": repr(pilot), "ray": repr(ray),
           "sun_elevations_deg": [float(e) for e in scene.sun_elevations_deg],
           "view_elevations_deg": [float(e) for e in scene.view_elevations_deg],
           "altitude_m": float(scene.altitudes_m[0])}
    text = json.dumps(key, sort_keys=True)
    directory = cache_directory("pilot-shares")
    path = None if directory is None else directory / f"{hashlib.sha256(text.encode()).hexdigest()[:32]}.json"
    share = None if path is None else _kept_share(path, key)
    if share is None:
        share = float(_higher_orders_share(atmosphere, table, scene, ctx=ctx))
        if path is not None:
            kept = {"key": key, "share": share}
            store(path, lambda file: file.write(json.dumps({**kept, "sha256": _digest(kept)}, sort_keys=True).encode()))
    return share


def _digest(kept) -> str:
    """SHA-256 (hex) of a kept share's key and share, as JSON: a digit of the share changed on disk (0.33 to
    0.03) was read, and a render dropped its higher orders without a word (clsky._cache: each reader checks
    its files' digests)."""
    return hashlib.sha256(json.dumps(kept, sort_keys=True).encode()).hexdigest()


def _kept_share(path, key):
    """The share kept at ``path`` for exactly ``key``, or None (no file, another key, a damaged file: one
    whose digest is not its key's and share's)."""
    try:
        kept = json.loads(read_user_text(path, limit=2**16))
    except (OSError, ValueError, RecursionError):      # missing, unreadable, a FIFO, not UTF-8, not JSON
        return None
    if not isinstance(kept, dict) or kept.get("key") != key:
        return None
    share = kept.get("share")
    if type(share) is not float or not math.isfinite(share) or not 0.0 <= share <= 1.0:     # a share's range
        return None
    if kept.get("sha256") != _digest({"key": key, "share": share}):
        return None
    return share


def _percent(fraction) -> str:
    """``fraction`` in per cent for a plan's reasons: 3 significant digits, whole numbers from 1000 % on
    (a 3D lookup in twilight: '1026 %', not '1.03e+03 %')."""
    return f"{100 * fraction:.0f}" if fraction >= 10.0 else f"{100 * fraction:.3g}"


def path_ends(low, high, apart=()) -> tuple[str, str]:
    """A sun path's ends [deg] as the plan prints them: 6 significant digits (a path computed from the sun's
    positions ends at 59.99425... deg, not at 60: '59.9943'), more only where 6 would show two different values
    as one: the two ends (89.99999 to 90 deg, not '90 to 90'), or an end and a value of ``apart`` that the plan
    prints beside it (a sun at -4.0000001 deg 'as measured at -4 deg', not '-4 deg as measured at -4 deg')."""
    values = (low, high, *apart)
    for digits in range(6, 18):
        shown = [f"{value:.{digits}g}" for value in values]
        if all(a == b or shown[i] != shown[j] for i, a in enumerate(values) for j, b in enumerate(values) if i < j):
            break
    return shown[0], shown[1]


def _at_lowest_sun(path) -> str:
    """'at the lowest sun, ``low`` deg' for a plan's reasons (``path``: (low, high) [deg], its low end as
    :func:`path_ends` prints it), saying so where the table lookup's error was not measured that low or that
    high (:data:`clsky.renderer_choice.LOOKUP_ERROR`: the estimate then is the nearest measured sun's,
    :func:`clsky.renderer_choice.error_over`)."""
    low, high = path
    lowest, highest = _measured_suns()
    beyond = ""
    if low < lowest:
        beyond = f" (as measured at {lowest:g} deg, the lowest measured)"
    elif low > highest:
        beyond = f" (as measured at {highest:g} deg, the highest measured)"
    return f"at the lowest sun, {path_ends(low, high, apart=(lowest, highest))[0]} deg{beyond}"


def _measured_suns():
    """The lowest and highest sun elevations [deg] the table lookup's error was measured at (LOOKUP_ERROR), which
    the plan prints beside the path's ends (:func:`path_ends`'s ``apart``)."""
    measured = [elevation for elevation, _ in LOOKUP_ERROR]
    return min(measured), max(measured)


def _costlier(method, chosen, pixels) -> str:
    """Why the plan passed over the renderer ``method`` for ``chosen`` (a
    :class:`clsky.renderer_choice.RendererRow`) although both fit the budget: their measured costs a frame
    of ``pixels`` pixels."""
    row = renderer_row(method)
    return (f"it costs more a frame of {pixels} pixels ({row.frame_cpu_ms(pixels):.3g} against "
            f"{chosen.frame_cpu_ms(pixels):.3g} CPU-ms, measured)")


def _level_measured_within(level, budget, low, high):
    """``level`` or the first finer one whose ray march's bound over the sun path [low, high] [deg]
    (:func:`promise_bounds`, interpolated in log error, the nearest measured value beyond) fits ``budget``;
    the reference level where none does. Above :func:`promise_measured_down_to` each level's bound is within
    its promise, so this only moves a path that goes lower (a default level 1.3 % off at -10 deg is no level
    'within 1 %')."""
    names = list(QUALITY_LEVELS)
    for name in names[names.index(level.name):]:
        if error_over(promise_bounds(name), low, high) <= budget:
            return QUALITY_LEVELS[name]
    return QUALITY_LEVELS["reference"]


def _below_measured_note(level, sun_elevations_deg, holds):
    """The plan's words for a sun path (low, high) [deg] that goes below ``holds``, the level's
    :func:`promise_measured_down_to` (None: nowhere): what ``level``'s ray march measured against the reference
    at the measured suns of the path below that (and at the nearest measured ones beyond its ends, whose values
    the plan takes there: :func:`measured_errors`), how far the reference itself was resolved there (the
    'reference' level: that alone), and below which sun it was not measured."""
    low, high = sun_elevations_deg
    points = measured_errors(level.name)
    floor = max((sun for sun, _ in points if sun <= low), default=low)
    ceiling = min((sun for sun, _ in points if sun >= high), default=high)
    measured = sorted(((sun, error) for sun, error in points
                       if floor <= sun <= ceiling and (holds is None or sun < holds)), reverse=True)
    said = ", ".join(f"{100 * error:.3g} % at {sun:g} deg" for sun, error in measured)
    if said and level.name != "reference":
        resolution = sorted(error_at(REFERENCE_RESOLUTION, [sun for sun, _ in measured]))
        said += (" (the reference's own estimated error there: " + " to ".join(dict.fromkeys(
            f"{100 * r:.2g}" for r in (resolution[0], resolution[-1]))) + " %)")
    lowest_measured = min((sun for sun, _ in points), default=0.0)
    unmeasured = f"not measured below {lowest_measured:g} deg" if low < lowest_measured else ""
    # a path end between two measured suns: the figure the plan took there (interpolated), which a plan by
    # budget compared with the budget and the measured figures beside it do not show
    added = "" if level.name == "reference" else " with the reference's own estimated error"
    between = (f"{_percent(error_at(promise_bounds(level.name), low))} % at {low:g} deg{added} (interpolated)"
               if floor < low < max(sun for sun, _ in points) else "")
    where = ("not measured to hold at any sun" if holds is None else
             f"measured to hold with the sun down to {holds:g} deg: below it")
    off = "its own estimated error" if level.name == "reference" else "off the reference by"
    return (f"; {where}, down to {low:g} deg here, " + "; ".join(part for part in (
        f"{off} {said}" if said else "", between, unmeasured) if part))


def plan_scene(scene: Scene, atmosphere="physical", mode="physical", ctx=None, ray_march=None, samples=None,
               keep_orders=False, sampling=None) -> Plan:
    """The least table (and ray march) that renders ``scene`` within its error budget.

    Parameters
    ----------
    scene : Scene
    atmosphere : AtmosphereParameters or str
        The atmosphere, or a preset name.
    mode : {'physical', 'atmosphere-plus'}
        Scheme of the higher orders.
    ctx : pyopencl.Context, optional
        For the pilot that decides whether the higher orders are needed.
    ray_march : bool, optional
        True when frames will be ray-marched whatever the budget says (an animation comparing the two
        renderers): the sun axis then keeps the ray march's margins.
    samples : int, optional
        The ray march's samples per ray when the caller sets them (``clsky animate --samples``), in [2,
        4096], instead of the quality level's: the plan's ray march and its printed line say so (its
        error estimates stay those measured with the level's samples).
    keep_orders : bool
        The caller's table needs the higher orders whatever the pilot finds they add (a 4D table over a
        reflecting ground carries the ground's light in their channels, and so does the 3D table for a
        lookup whose cameras see it): kept, with the sun axis' margins they need.
    sampling : {'uniform', 'keller_bohn', 'ground_end'}, optional
        The view nodes when the caller sets them (``--sampling``), instead of :func:`view_sampling`'s: the
        plan's table, ray march and pilot take them, and its printed line says so (it said the planner's
        while the table took the caller's).
    """
    check_instance("scene", scene, Scene, "a Scene (sun path, altitudes, views, components, error budget)")
    atmosphere = as_atmosphere(atmosphere)
    check_choice("mode", mode, SCATTERING_MODES)
    _cl.check_context(ctx)
    ray_march = ray_march is not None and check_flag("ray_march", ray_march)     # 'no' was true
    samples = check_integer("samples", samples, 2, 4096, optional=True)
    keep_orders = check_flag("keep_orders", keep_orders)
    check_choice("sampling", sampling, SAMPLINGS, optional=True)
    check_ground_mode(atmosphere, mode)     # before the pilot: a plan the build would refuse is no plan
    level = quality_level(scene.quality) if scene.quality else level_for_budget(scene.error_budget)
    budget = level.budget if scene.quality else scene.error_budget
    promised = level
    if not scene.quality:
        level = _level_measured_within(level, budget, *scene.sun_elevations_deg)
    bound = error_over(promise_bounds(level.name), *scene.sun_elevations_deg)
    if scene.quality:
        why = ""
    elif level.budget > budget:             # below every level's promise: the most accurate one, said so
        why = f"; no level promises {100 * budget:g} %: the most accurate one"
    elif bound > budget:                    # no level measured within it over this path: the same, said so
        why = (f"; no level's measured error, plus the reference's own estimated error, fits {100 * budget:g} % "
               f"over the path: the most accurate one (up to {_percent(bound)} % over it)")
    elif level is not promised:
        why = (f"; the fastest level whose measured error, plus the reference's own estimated error, fits "
               f"{100 * budget:g} % over the path ({promised.name}: up to "
               f"{_percent(error_over(promise_bounds(promised.name), *scene.sun_elevations_deg))} % over it)")
    else:
        why = f"; the fastest level within {100 * budget:g} %"
    holds = promise_measured_down_to(level)
    if holds is None or scene.sun_elevations_deg[0] < holds:
        why += _below_measured_note(level, scene.sun_elevations_deg, holds)
    decisions = [("quality", level.name, f"promises {100 * level.budget:g} % or better{why}")]

    if "mie" in scene.components or atmosphere.mie_scattering == 0.0:
        decisions.append(("Mie", "kept" if atmosphere.mie_scattering > 0 else "none",
                          "wanted by the scene" if atmosphere.mie_scattering > 0 else "the atmosphere has none"))
    else:
        atmosphere = atmosphere.replace(mie_scattering=0.0)
        decisions.append(("Mie", "dropped", "not wanted by the scene"))

    planned, because = view_sampling(scene.altitudes_m)
    if sampling is None:
        sampling = planned
    else:
        because = "asked for" + (f"; the planner's: {planned}, for {because}" if sampling != planned else "")
    harmonics, harmonics_because = azimuth_harmonics(level, scene.sun_elevations_deg, mode)
    every_node = level.table.source_stride > 1 and scene.sun_elevations_deg[0] < SOURCE_EVERY_NODE_BELOW_DEG
    table = level.table.replace(mode=mode, sampling=sampling, azimuth_harmonics=harmonics,
                                source_stride=1 if every_node else level.table.source_stride)
    source_note = (f"; their source read at every view node: the sun goes below {SOURCE_EVERY_NODE_BELOW_DEG:g} deg, "
                   f"where every other node put the level's frames past its promise" if every_node else "")
    chosen, estimate, estimates = choose_renderer(scene.sun_elevations_deg, budget, level.name, pixels=scene.pixels,
                                                  altitude_m=scene.altitudes_m[1])
    lookup_error, at_lowest = estimates["lut"], _at_lowest_sun(scene.sun_elevations_deg)
    lookup_note = f"the table lookup's {_percent(lookup_error)} % {at_lowest}, exceeds the budget"
    if scene.altitudes_m[1] > 0.0 and lookup_error <= budget:
        # its error is measured from the ground, and grows from above it, looking down (a review of the
        # altitude rule, 2026-12-07: against the ray march, sun at 5 deg, 0.15 % from the ground, 2.0 % from 3
        # km, 4.2 % from 10 km): the cheapest of the others
        lookup_note = (f"the table lookup's {_percent(lookup_error)} % {at_lowest} is measured from the ground, "
                       f"and grows from above it (2 % off the ray march looking down from 3 km, 4 % from 10 km)")
        if chosen.method == "lut" and scene.altitudes_m[1] <= RENDERER_ERRORS_MEASURED_UP_TO_M:
            others = tuple(row for row in RENDERERS if row.method != "lut")
            chosen, estimate, _ = choose_renderer(scene.sun_elevations_deg, budget, level.name, others,
                                                  pixels=scene.pixels, altitude_m=scene.altitudes_m[1])
    ray = level.ray if samples is None else level.ray.replace(view_steps=samples)
    march = f"ray march, {ray.view_steps} samples per ray" + (
        "" if samples is None else f" (asked for; the {level.name} level's {level.ray.view_steps})")
    if scene.altitudes_m[1] > RENDERER_ERRORS_MEASURED_UP_TO_M and chosen.method != "raymarch":
        reason = (lookup_note if chosen.method == "lut" else
                  f"the {chosen.description}'s error was measured from the ground and holds to "
                  f"{RENDERER_ERRORS_MEASURED_UP_TO_M / 1e3:g} km, not from {scene.altitudes_m[1] / 1e3:g} km (it is "
                  f"1 % at the horizon from 30 km, 14 % from 1000 km)")
        chosen, estimate = renderer_row("raymarch"), estimates["raymarch"]
        decisions.append(("renderer", march, reason))
    elif chosen.method == "lut" and ray_march:
        decisions.append(("renderer", march,
                          f"asked for; the table lookup alone would do: {_percent(lookup_error)} % {at_lowest}"))
    elif chosen.method == "lut":
        ray = None
        decisions.append(("renderer", "table lookup", f"its error {at_lowest}, is {_percent(lookup_error)} % "
                          f"({estimate_basis(chosen, level.name, scene.sun_elevations_deg)})"))
    elif chosen.method == "raymarch":
        reason = lookup_note
        map_taken = scene.altitudes_m[1] <= RENDERER_ERRORS_MEASURED_UP_TO_M
        if estimates["skyview"] <= budget and map_taken:    # tiny frames: marching every pixel costs less than the map
            reason += (f"; the sky-view map's {_percent(estimates['skyview'])} % fits, but "
                       + _costlier("skyview", chosen, scene.pixels))
        elif map_taken:                                     # the map was over the budget too: said, and why
            basis = estimate_basis(renderer_row("skyview"), level.name, scene.sun_elevations_deg, scene.altitudes_m[1])
            reason += f"; the sky-view map's {_percent(estimates['skyview'])} % ({basis}) exceeds it too"
        if estimates["raymarch"] > budget:                  # the most accurate renderer misses it as well
            basis = estimate_basis(chosen, level.name, scene.sun_elevations_deg, scene.altitudes_m[1])
            reason += (f"; the ray march itself, {_percent(estimates['raymarch'])} % ({basis}), exceeds it too: no "
                       f"renderer fits the budget")
        decisions.append(("renderer", march, reason))
    else:
        lookup_fits = lookup_error <= budget and scene.altitudes_m[1] == 0.0
        basis = estimate_basis(chosen, level.name, scene.sun_elevations_deg, scene.altitudes_m[1])
        would = (f"the {chosen.description}'s {_percent(estimate)} % ({basis}) fits; "
                 + ("so does the table lookup, but " + _costlier("lut", chosen, scene.pixels) if lookup_fits
                    else lookup_note))
        decisions.append(("renderer", march, f"asked for; {would}") if ray_march
                         else ("renderer", f"{chosen.description} (--method {chosen.method}), {march} at its nodes",
                               would))

    if ray is not None:
        ray = ray.replace(sampling=sampling)
    decisions.append(("view nodes", sampling, because))

    def on_sun_axis(settings, orders):
        cos_range, nodes, elevations, margins = sun_axis(atmosphere, scene, level, settings.mapping, orders,
                                                         ray is not None)
        return settings.replace(size=settings.size[:2] + (nodes,), sun_cos_range=cos_range), elevations, margins

    table, elevations, margins = on_sun_axis(table, orders=True)
    if "multiple" not in scene.components:
        table, elevations, margins = on_sun_axis(table.replace(orders=1, azimuth_harmonics=0), orders=False)
        decisions.append(("higher orders", "dropped", "not wanted by the scene"))
    else:
        share = pilot_share(atmosphere, table, scene, ctx=ctx)
        # the 3D lookup reads a reflecting ground's light from the higher orders' channels (an orders = 1 table
        # holds none: the ground was black, a review found), as a 4D table does (keep_orders)
        lookup_ground = chosen.method == "lut" and atmosphere.has_ground and sees_ground(atmosphere, scene)
        if share < 0.5 * budget and (keep_orders or lookup_ground):
            whose = "the caller's lookup's" if keep_orders else "the table lookup's, which sees the ground"
            decisions.append(("higher orders", f"until an order adds < {table.order_tolerance:g}",
                              f"they add at most {100 * share:.3g} % (pilot), kept: the table carries a reflecting "
                              f"ground's light in them ({whose}){source_note}"))
            decisions.append(("azimuth harmonics", f"M = {harmonics}", harmonics_because))
        elif share < 0.5 * budget:
            table, elevations, margins = on_sun_axis(table.replace(orders=1, azimuth_harmonics=0), orders=False)
            decisions.append(("higher orders", "dropped", f"they add at most {100 * share:.3g} % (pilot), "
                              f"under half the budget"))
        else:
            decisions.append(("higher orders", f"until an order adds < {table.order_tolerance:g}",
                              f"they add up to {100 * share:.3g} % of the light (pilot){source_note}"))
            decisions.append(("azimuth harmonics", f"M = {harmonics}", harmonics_because))

    w_low, w_high = table.sun_w_range
    decisions.append(("sun axis", f"elevations {elevations[0]:.1f} to {elevations[1]:.1f} deg, "
                      f"{table.size[2]} nodes ({100 * (w_high - w_low):.2g} % of the axis)",
                      f"the path's {' to '.join(path_ends(*scene.sun_elevations_deg, apart=_measured_suns()))} deg "
                      f"+ {min(margins[1], 90.0 - scene.sun_elevations_deg[1]):.1f} deg above and "
                      f"{min(margins[0], 90.0 + scene.sun_elevations_deg[0]):.1f} deg below for curvature and "
                      f"orders"))
    whole_because = {"altitude": "view rays cross every altitude", "view": "the gather integrates every direction"}
    if table.orders == 1:
        whole_because = dict.fromkeys(whole_because, "without higher orders that part would do, but only the "
                                                     "sun axis takes sub-ranges")
    decisions.append(("altitude axis", f"whole, {table.size[0]} nodes",
                      f"the scene reaches {scene.altitudes_m[0]:g} to {scene.altitudes_m[1]:g} m; "
                      + whole_because["altitude"]))
    decisions.append(("view axis", f"whole, {table.size[1]} nodes",
                      f"the cameras see {scene.view_elevations_deg[0]:.1f} to {scene.view_elevations_deg[1]:.1f} "
                      "deg; " + whole_because["view"]))
    return Plan(scene, level, atmosphere, table, ray, tuple(decisions), chosen.method)
