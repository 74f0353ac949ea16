"""Bit-for-bit pins: results of an older commit, recorded per OpenCL device.

Five tests check that today's code gives, bit for bit, what the code before a change gave (SHA-256 of
float64 arrays, or of the decoded pixels of PNG frames). PoCL compiles each kernel for the CPU it runs
on (``pthread-haswell``, ``pthread-skylake-avx512``, ...), and its code generation (FMA contraction,
vector width) changes the last bits, so each pin is a mapping {device description: recorded values}
(:func:`clsky._cl.describe_device`), and a test checks only on a device with a recording
(:func:`pinned_for_device`; it skips elsewhere, naming the devices recorded).

The computations live here, in one place, written against the API that the old commits and today's
code share, so that the values of a new device are recorded by running *the old commit's code* on the
same inputs as the test (the pin means "bit for bit the code before X", not "the code of today"):

    git worktree add --detach /tmp/old-bfa2a93 bfa2a93
    .venv/bin/python scripts/record_pins.py --source /tmp/old-bfa2a93 ground spectral view_nodes display
    git worktree add --detach /tmp/old-275bfcf 275bfcf
    .venv/bin/python scripts/record_pins.py --source /tmp/old-275bfcf ozone

and pasting the printed entries into the tests' mappings (or, where every value equals another device's,
naming that device in :data:`SAME_VALUES_AS`). :data:`PINS` names, for each pin, the commit
it belongs to; scripts/record_pins.py refuses a source tree at another commit.

Since 2026-12-03 the kernels take the mapping's cube roots by three Halley steps instead of OpenCL's
``cbrt`` (``clsky._cl.CUBE_ROOT``; within 3 ulp, the last bits of 9-22 % of a table's values change):
the pins run today's code with ``cbrt`` (:func:`_library_cube_root`), the choice every pinned commit
made, so that they still hold each refactor to its commit bit for bit; tests/test_cube_root.py checks
the Halley root on its own and the tables and frames it gives against ``cbrt``'s.

Where the old and today's APIs differ, the functions below take the path both accept (noted there):
the field ``ground_albedo`` (absent before the ground, whose atmospheres are all black), the package
``anim`` (``clsky.anim`` today) and ``AnimationConfig.tone_map`` (absent before anim/display.py).
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest


def sha256(array) -> str:
    """SHA-256 of an array's bytes as contiguous float64."""
    return hashlib.sha256(np.ascontiguousarray(array, dtype=np.float64).tobytes()).hexdigest()


#: Devices whose recorded values are, every one, those of another device: {device: the device it shares
#: them with}. PoCL generates code for its LLVM target (``skylake-avx512``) whatever the CPU's vendor: an
#: Intel Xeon's recording (scripts/record_pins.py from bfa2a93's and 275bfcf's code, 2026-12-05) equalled
#: the AMD EPYC's of the same target in all five pins, and differed from the ``haswell`` one's.
SAME_VALUES_AS = {
    "pthread-skylake-avx512-Intel(R) Xeon(R) Processor (PoCL 3.1+debian)":
        "pthread-skylake-avx512-AMD EPYC (PoCL 3.1+debian)",
}


def pinned_for_device(pins: dict, ctx):
    """The values ``pins`` recorded for the device of ``ctx`` (or for the device it shares them with,
    :data:`SAME_VALUES_AS`); skips the test on a device without any (PoCL's code generation differs
    between devices, so another device's bits prove nothing)."""
    from clsky import _cl

    device = _cl.describe_device(ctx.devices[0])
    recorded = device if device in pins else SAME_VALUES_AS.get(device, device)
    if recorded not in pins:
        pytest.skip(f"bit-for-bit values recorded on {', '.join(sorted(pins))}, not on {device} "
                    f"(scripts/record_pins.py records a device)")
    return pins[recorded]


def black_preset(name):
    """The preset ``name`` with a black ground (as tests/conftest.py's), also under the code before the
    ground (e.g. commit bfa2a93), whose atmospheres were all black and had no ``ground_albedo`` field."""
    from clsky import preset

    atmosphere = preset(name)
    if any(field.name == "ground_albedo" for field in dataclasses.fields(atmosphere)):
        atmosphere = atmosphere.replace(ground_albedo=0.0)
    return atmosphere


def _unit(vectors):
    vectors = np.asarray(vectors, dtype=np.float64)
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


#: Directions and sun of the table pins (pixels from the ground: 2 up, 1 5.7 deg below the horizon).
DIRECTIONS = _unit([[0, 0, 1.0], [0.6, 0, 0.8], [0, 0.995, -0.0998749]])
SUN = _unit([0.0, 0.99, 0.141067])
#: ... plus a view down steeply, for the ground pin.
GROUND_DIRECTIONS = _unit([[0, 0, 1.0], [0.6, 0, 0.8], [0, 0.995, -0.0998749], [0.3, 0.0, -0.95]])
#: The view-node pin's directions (three of them look down) and sun (not normalised: it was
#: recorded as given, and 0.6^2 + 0.8^2 rounds to 1 anyway).
VIEW_NODE_DIRECTIONS = _unit([[0, 0, 1.0], [0.6, 0, 0.8], [0.99, 0, -0.125], [0.3, 0.2, -0.9], [0, 0.995, -0.0998749]])
VIEW_NODE_SUN = np.array([0.0, 0.6, 0.8])


def _library_cube_root():
    """A context in which every engine made takes the mapping's cube roots with OpenCL's ``cbrt``
    (``clsky._cl.CUBE_ROOT = "library"``), as every commit before 2026-12-03's did. A tree without
    the choice has nothing to switch."""
    import contextlib
    from unittest import mock

    from clsky import _cl

    if not hasattr(_cl, "CUBE_ROOT"):
        return contextlib.nullcontext()
    return mock.patch.object(_cl, "CUBE_ROOT", "library")


def _whole_labels():
    """A context in which the composites' labels are drawn whole, clipped at their panel's edge, as every
    commit before 2026-12-07 drew them (a label is cut to the letters its panel holds since: the 24-pixel
    frames' labels, and nothing else of them). A tree without the cut has nothing to switch."""
    import contextlib
    from unittest import mock

    try:
        from clsky.anim import metrics
    except ModuleNotFoundError:                    # before the package moved: top-level anim/
        from anim import metrics
    if not hasattr(metrics, "_fitted_label"):
        return contextlib.nullcontext()
    def whole(font, label, width, height):
        return str(label) if label else None

    return mock.patch.object(metrics, "_fitted_label", whole)


def _every_node():
    """A context in which the quality levels' ray marches and tables look the higher orders' source up at
    every view node (``TableSettings.source_stride = 1``), as every commit before a98be11 (2026-12-03) did
    for the ray march and every one before the scatter's stride (2026-12-03, later) for the table (the
    'draft' and 'default' levels take 2 since), and scatter the orders at every sun node
    (``orders_sun_stride = 1``), as every commit before 2026-12-07's did (the 'default' and 'high' levels
    take 2 since). A tree without these settings has nothing to switch."""
    import contextlib
    import dataclasses
    from unittest import mock

    from clsky import settings

    fields = {field.name for field in dataclasses.fields(settings.TableSettings)}
    every = {name: 1 for name in ("source_stride", "orders_sun_stride") if name in fields}
    if not every:
        return contextlib.nullcontext()
    from clsky import quality

    levels = {name: dataclasses.replace(level, ray=level.ray.replace(**every), table=level.table.replace(**every))
              for name, level in quality.QUALITY_LEVELS.items()}
    return mock.patch.dict(quality.QUALITY_LEVELS, levels)


def table_hashes(atmosphere, settings, directions, sun, renders, ctx) -> tuple:
    """Hashes of a table's ``data`` and ``gathered``, then of the pixels of each ``(method, altitude)``
    in ``renders`` (method 'raymarch' or 'table', altitude [m]); cube roots by ``cbrt``."""
    from clsky import ScatteringTable
    from clsky.render import SkyRenderer

    with _library_cube_root():
        table = ScatteringTable.build(atmosphere, settings, ctx=ctx)
        hashes = [sha256(table.data), sha256(table.gathered)]
        with SkyRenderer(table, ctx=ctx) as renderer:
            for method, altitude in renders:
                hashes.append(sha256(getattr(renderer, f"render_{method}")(directions, sun, altitude)))
    return tuple(hashes)


def preset_from_the_ground(ctx, name, mode, sun_transmittance) -> tuple:
    """Preset ``name`` (black ground), TableSettings(size=(8, 32, 8), orders=3, mode, sun_transmittance):
    data, gathered, ray-marched and table-rendered pixels of DIRECTIONS, sun SUN, from the ground."""
    from clsky import TableSettings

    settings = TableSettings(size=(8, 32, 8), orders=3, mode=mode, sun_transmittance=sun_transmittance)
    return table_hashes(black_preset(name), settings, DIRECTIONS, SUN, [("raymarch", 0.0), ("table", 0.0)], ctx)


def black_ground(ctx) -> tuple:
    """The physical preset (ozone, black ground), TableSettings(size=(8, 32, 8), orders=3,
    mode='physical'): data, gathered, ray-marched and table-rendered pixels of GROUND_DIRECTIONS from
    the ground, ray-marched pixels from 30 km (sun SUN)."""
    from clsky import TableSettings

    settings = TableSettings(size=(8, 32, 8), orders=3, mode="physical")
    return table_hashes(black_preset("physical"), settings, GROUND_DIRECTIONS, SUN,
                        [("raymarch", 0.0), ("table", 0.0), ("raymarch", 30000.0)], ctx)


def view_nodes(ctx) -> tuple:
    """atmosphere-plus, TableSettings(size=(8, 32, 8), orders=3) (Keller & Bohn's nodes, the default):
    data, gathered, then the default ray march of VIEW_NODE_DIRECTIONS, sun VIEW_NODE_SUN, from 0,
    32.7, 100 and 150 km."""
    from clsky import TableSettings

    renders = [("raymarch", altitude) for altitude in (0.0, 32.7e3, 100e3, 150e3)]
    return table_hashes(black_preset("atmosphere-plus"), TableSettings(size=(8, 32, 8), orders=3),
                        VIEW_NODE_DIRECTIONS, VIEW_NODE_SUN, renders, ctx)


#: The metrics of a compare animation that the display pin records, per frame.
METRIC_KEYS = ("rmse", "median_rel", "p95_rel", "max_rel", "mean_delta_e", "floor")


def _plain_sum_of_orders():
    """A context in which ``orders="auto"`` sums the orders plainly and stops at the first relative
    addition below the tolerance, as every commit before the geometric tail did (clsky.orders,
    2026-12-03): :func:`clsky.orders.geometric_ratio` then finds no ratio, the one switch of the tail
    and of its stopping test. A tree without the tail has nothing to switch."""
    import contextlib
    from unittest import mock

    import clsky.orders

    stack = contextlib.ExitStack()
    if hasattr(clsky.orders, "geometric_ratio"):
        import clsky.azimuth

        for module in (clsky.orders, clsky.azimuth):
            stack.enter_context(mock.patch.object(module, "geometric_ratio", lambda totals: None))
    return stack


def display_frames(ctx, directory, tone_map=None) -> tuple:
    """The atmosphere-plus preset's compare animation (table | ray march | error panels, dithered, 3
    frames of 24 px), written under ``directory``: SHA-256 of each PNG frame's decoded pixels, and each
    frame's METRIC_KEYS; the source of the ray march's higher orders at every node and the orders scattered
    at every sun node (:func:`_every_node`), the labels whole (:func:`_whole_labels`). ``tone_map`` None
    leaves the config's default (the only choice before anim/display.py). Its table sums the orders plainly
    (:func:`_plain_sum_of_orders`), as the pinned commit did: so the pin also holds the orders loop without
    the tail to its results, bit for bit; cube roots by ``cbrt`` (:func:`_library_cube_root`)."""
    import pathlib

    from PIL import Image

    try:
        from clsky.anim.animate import AnimationConfig, render_animation
    except ModuleNotFoundError:                    # before the package moved: top-level anim/
        from anim.animate import AnimationConfig, render_animation
    options = {} if tone_map is None else {"tone_map": tone_map}
    directory = pathlib.Path(directory)
    config = AnimationConfig(frames=3, size=24, table_size=(9, 33, 7), preset="atmosphere-plus",
                             mode="atmosphere-plus", start_elevation_deg=-4.0, max_elevation_deg=30.0,
                             output=str(directory / "sky.mp4"), **options)
    with _plain_sum_of_orders(), _library_cube_root(), _every_node(), _whole_labels():
        result = render_animation(config, ctx=ctx)
    frames = sorted((directory / "sky_frames").glob("*.png"))
    hashes = [hashlib.sha256(np.asarray(Image.open(f)).tobytes()).hexdigest() for f in frames]
    return hashes, [[row[key] for key in METRIC_KEYS] for row in result.rows]


@dataclasses.dataclass(frozen=True)
class Pin:
    """One pinned computation: the test that holds its values, the commit they are the results of, and
    its cases {key in the test's mapping: function of (ctx, scratch directory)}."""

    test: str
    commit: str
    cases: dict


PINS = {
    "ground": Pin("tests/test_ground.py::OLD_HASHES", "bfa2a93",
                  {None: lambda ctx, tmp: black_ground(ctx)}),
    "ozone": Pin("tests/test_ozone.py::OLD_HASHES", "275bfcf",
                 {(mode, sun): (lambda ctx, tmp, mode=mode, sun=sun:
                                preset_from_the_ground(ctx, "atmosphere-plus", mode, sun))
                  for mode, sun in (("atmosphere-plus", "march"), ("physical", "table"))}),
    "spectral": Pin("tests/test_spectral.py::OLD_HASHES", "bfa2a93",
                    {(name, mode, sun): (lambda ctx, tmp, name=name, mode=mode, sun=sun:
                                         preset_from_the_ground(ctx, name, mode, sun))
                     for name, mode, sun in (("atmosphere-plus", "atmosphere-plus", "march"),
                                             ("atmosphere-plus", "physical", "table"),
                                             ("physical", "physical", "table"))}),
    "view_nodes": Pin("tests/test_view_nodes.py::BIT_HASHES", "bfa2a93",
                      {None: lambda ctx, tmp: view_nodes(ctx)}),
    "display": Pin("tests/test_display.py::BASE_FRAMES", "bfa2a93",
                   {None: lambda ctx, tmp: display_frames(ctx, tmp)}),
}
