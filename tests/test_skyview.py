"""The per-frame sky-view map (clsky/skyview.py, kernels/skyview.cl, SkyRenderer.render_skyview).

1. The sampling kernel against its NumPy twin (reference.render_skyview) on the renderer's own map and
   on random maps: ground, 3 km and space, sun high, low and below the horizon, both azimuth mappings;
   the view zenith angles it reads, computed once per prepared camera, against NumPy's.
2. The mapping: the map read at its own nodes gives the node values (a round trip of the row and
   column mappings); nothing is interpolated across the horizon (a map of 1 above, 0 below).
3. Against the full per-pixel ray march, sharing only the ray march with it: a fisheye at four sun
   elevations, from the ground and from 10 km.
4. Settings validation.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from clsky import ScatteringTable, TableSettings, reference, skyview
from clsky.anim import metrics
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky.errors import ParameterError
from clsky.render import RAYMARCH_DEFAULTS, SUN_ANGULAR_RADIUS_DEG, SkyRenderer, sun_disc_radiance

from conftest import TOLERANCES, max_error_report, require_dtype

logger = logging.getLogger(__name__)

SMALL = TableSettings(size=(9, 33, 7), gather_theta_steps=64, gather_phi_steps=32, mode="physical")
RAY = RAYMARCH_DEFAULTS.replace(view_steps=16, sun_steps=20, transmittance_size=(16, 32))
COS_SUN_RADIUS = math.cos(math.radians(SUN_ANGULAR_RADIUS_DEG))
SUN_AZIMUTH = 150.0
MAP = skyview.SkyViewSettings((16, 24), "sun")


@pytest.fixture(scope="module")
def renderer(cl_context):
    """``renderer(dtype='float64')``: a cached SkyRenderer on a small physical table, ray march RAY."""
    cache = {}

    def get(dtype="float64"):
        require_dtype(cl_context, dtype)
        if dtype not in cache:
            table = ScatteringTable.build("physical", SMALL.replace(dtype=dtype), ctx=cl_context)
            cache[dtype] = SkyRenderer(table, RAY.replace(dtype=dtype), ctx=cl_context)
        return cache[dtype]

    yield get
    for item in cache.values():
        item.close()


def probe_directions(sun, altitude):
    """24 x 32 random unit directions, the exact sun, the zenith, the nadir and directions 1e-7 rad
    above and below the horizon of ``altitude`` (on the ground: 1e-7 above and below mu = 0)."""
    rng = np.random.default_rng(20261202)
    directions = rng.normal(size=(24, 32, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    directions[0, 0] = sun
    directions[0, 1] = (0.0, 0.0, 1.0)
    directions[0, 2] = (0.0, 0.0, -1.0)
    _, angle = skyview.horizon(altitude, 6371e3)
    for k, theta in enumerate((angle - 1e-7, angle + 1e-7)):
        directions[1, k] = (math.sin(theta) * 0.6, math.sin(theta) * 0.8, math.cos(theta))
    return directions


def twin(sky_map, settings, directions, sun, altitude, atmosphere):
    mu_h, angle = skyview.horizon(altitude, atmosphere.planet_radius)
    return reference.render_skyview(sky_map, settings.sky_rows, settings.azimuth_mapping, directions, sun, altitude,
                                    mu_h, angle, sun_disc_radiance(atmosphere, sun, altitude), COS_SUN_RADIUS)


# 1. Kernel against its twin -------------------------------------------------------------------------

@pytest.mark.parametrize("mapping", sorted(skyview.AZIMUTH_MAPPINGS))
@pytest.mark.parametrize("sun_zenith", (30.0, 89.0, 95.0))
@pytest.mark.parametrize("altitude", (0.0, 3000.0, 150e3))
def test_render_skyview_matches_twin(renderer, dtype, altitude, sun_zenith, mapping):
    sky_renderer = renderer(dtype)
    atmosphere = sky_renderer.table.atmosphere
    settings = skyview.SkyViewSettings(MAP.size, mapping)
    sun = sun_direction(sun_zenith, SUN_AZIMUTH)
    directions = probe_directions(sun, altitude)
    actual = sky_renderer.render_skyview(directions, sun, altitude, settings=settings)
    sky_map = sky_renderer.skyview_map(sun, altitude, settings)
    desired = twin(sky_map, settings, directions, sun, altitude, atmosphere)
    assert actual.shape == directions.shape
    assert np.isfinite(actual).all() and (actual >= 0.0).all()
    assert np.isfinite(sky_map).all() and (sky_map >= 0.0).all()
    sky = (directions @ sun) < COS_SUN_RADIUS     # the atol's scale: the sky, not the sun's disc
    tolerance = TOLERANCES[dtype]["render_skyview"]
    logger.info(max_error_report(actual, desired, f"render_skyview {dtype} h={altitude:g} sun {sun_zenith:g}"))
    assert_allclose(actual, desired, rtol=tolerance.rtol, atol=tolerance.atol(desired[sky]))


def test_random_maps_match_twin(renderer, monkeypatch):
    """Any map (random values, so that every node's weight shows), read by kernel and twin alike."""
    sky_renderer = renderer()
    rng = np.random.default_rng(7)
    sun = sun_direction(60.0, SUN_AZIMUTH)
    for altitude in (0.0, 10e3):
        for settings in (skyview.SkyViewSettings((2, 4), "linear"), skyview.SkyViewSettings((33, 17), "sun")):
            sky_map = rng.uniform(0.0, 1.0, size=settings.size[::-1] + (3,))
            monkeypatch.setattr(sky_renderer, "skyview_map", lambda *args, **kwargs: sky_map)
            directions = probe_directions(sun, altitude)
            actual = sky_renderer.render_skyview(directions, sun, altitude, settings=settings)
            desired = twin(sky_map, settings, directions, sun, altitude, sky_renderer.table.atmosphere)
            # values of order 1 combined by bilinear weights: a few ulps (measured 2.2e-16)
            assert_allclose(actual, desired, rtol=1e-12, atol=1e-14)


# 2. The mapping ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("mapping", sorted(skyview.AZIMUTH_MAPPINGS))
@pytest.mark.parametrize("altitude", (0.0, 10e3))
def test_map_read_at_its_nodes_gives_the_node_values(renderer, monkeypatch, altitude, mapping):
    """Row and column mappings round-trip: the nodes' own directions read each node's value (the two
    horizon rows are marched 1e-9 rad off the horizon, so they are left out here: the seam test)."""
    sky_renderer = renderer()
    settings = skyview.SkyViewSettings((12, 20), mapping)
    sky_map = np.random.default_rng(3).uniform(0.5, 1.0, size=(20, 12, 3))
    monkeypatch.setattr(sky_renderer, "skyview_map", lambda *args, **kwargs: sky_map)
    sun = skyview.canonical_sun(sun_direction(100.0, 0.0))     # below the horizon: no disc anywhere
    nodes = skyview.node_directions(settings, altitude, 6371e3)
    rows = [r for r in range(20) if r not in (settings.sky_rows - 1, settings.sky_rows)]
    rows = [r for r in rows if r not in (0, 19)]               # zenith and nadir: every column one point
    actual = sky_renderer.render_skyview(nodes[rows], sun, altitude, settings=settings)
    # a node's coordinate comes back within rounding of an integer: weights 1e-15 off at most
    assert_allclose(actual, sky_map[rows], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("altitude", (0.0, 10e3, 150e3))
def test_nothing_is_interpolated_across_the_horizon(renderer, monkeypatch, altitude):
    """A map of 1 on the sky rows and 0 on the ground rows: 1e-7 rad above the horizon reads exactly 1,
    1e-7 rad below exactly 0, at every azimuth (the sun below the horizon: no disc)."""
    sky_renderer = renderer()
    settings = skyview.SkyViewSettings((8, 10), "sun")
    sky_map = np.zeros((10, 8, 3))
    sky_map[: settings.sky_rows] = 1.0
    monkeypatch.setattr(sky_renderer, "skyview_map", lambda *args, **kwargs: sky_map)
    _, angle = skyview.horizon(altitude, 6371e3)
    azimuth = np.linspace(0.0, 2.0 * math.pi, 37)
    directions = np.stack([np.stack([math.sin(t) * np.cos(azimuth), math.sin(t) * np.sin(azimuth),
                                     np.full_like(azimuth, math.cos(t))], axis=-1)
                           for t in (angle - 1e-7, angle + 1e-7)])
    actual = sky_renderer.render_skyview(directions, sun_direction(100.0, 10.0), altitude, settings=settings)
    assert_array_equal(actual[0], 1.0)
    assert_array_equal(actual[1], 0.0)


def test_node_directions_are_unit_vectors_on_their_side_of_the_horizon():
    for altitude in (0.0, 10e3, 150e3):
        settings = skyview.SkyViewSettings((9, 15), "sun")
        nodes = skyview.node_directions(settings, altitude, 6371e3)
        mu_h, _ = skyview.horizon(altitude, 6371e3)
        assert_allclose(np.linalg.norm(nodes, axis=-1), 1.0, rtol=0, atol=1e-15)
        assert (nodes[: settings.sky_rows, :, 2] >= mu_h).all() and (nodes[settings.sky_rows:, :, 2] < mu_h).all()
        # zenith first, nadir last; columns from the sun's azimuth (y = 0, x > 0) to the opposite one
        assert_allclose(nodes[0, :, 2], 1.0, rtol=0, atol=1e-15)
        assert_allclose(nodes[-1, :, 2], -1.0, rtol=0, atol=1e-15)
        assert (nodes[1, 0, 0] > 0) and (nodes[1, -1, 0] < 0) and abs(nodes[1, -1, 1]) < 1e-15


# 3. Against the full ray march ----------------------------------------------------------------------

#: p95 relative luminance error allowed to the default map (64 x 128, 'sun') against the per-pixel ray
#: march of the same renderer, 64 x 64 fisheye (test table); measured values in the test, worst 0.164 %.
#: 0.4 % is 2.4 times that: the map's bilinear error scales with the square of the node spacing and
#: changes little with the table, while a broken mapping (a half, a row or the azimuth off) gives errors
#: of 10 % and more.
RAYMARCH_P95_TOLERANCE = 0.004


@pytest.mark.parametrize("altitude", (0.0, 10e3))
def test_skyview_frame_is_close_to_the_ray_march(renderer, altitude):
    """The default map against render_raymarch per pixel, sun at +30, +5, 0 and -4 deg: p95 within
    RAYMARCH_P95_TOLERANCE. Measured (p95 %, ground / 10 km looking 46 deg down, so through both
    halves of the map): +30: 0.080 / 0.139, +5: 0.077 / 0.141, 0: 0.094 / 0.145, -4: 0.092 / 0.164."""
    sky_renderer = renderer()
    directions, valid = FisheyeCamera(64).directions()
    if altitude > 0:                                          # looking down at 45 deg: both halves of the map
        directions = directions @ np.array([[1, 0, 0], [0, math.cos(0.8), -math.sin(0.8)],
                                            [0, math.sin(0.8), math.cos(0.8)]]).T
    prepared = sky_renderer.prepare(directions, valid)
    for elevation in (30.0, 5.0, 0.0, -4.0):
        sun = sun_direction(90.0 - elevation, SUN_AZIMUTH)
        expected = sky_renderer.render_raymarch(prepared, sun, altitude)
        actual = sky_renderer.render_skyview(prepared, sun, altitude)
        p95 = metrics.compare_frames(expected, actual, valid)["p95_rel"]
        logger.info(f"skyview vs ray march h={altitude:g} sun {elevation:g} deg: p95 {100 * p95:.3f} %")
        assert p95 <= RAYMARCH_P95_TOLERANCE, (altitude, elevation, p95)


# 4. Validation ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("size, field", [((1, 64), "size[0]"), ((64, 3), "size[1]"), ((64, 4097), "size[1]"),
                                         ((64,), "size"), (64, "size"), ((64.5, 64), "size[0]")])
def test_bad_sizes_are_refused_naming_the_item(size, field):
    with pytest.raises(ParameterError, match=r"^" + field.replace("[", r"\[").replace("]", r"\]") + " must be"):
        skyview.SkyViewSettings(size)


def test_bad_azimuth_mapping_is_refused():
    with pytest.raises(ParameterError, match="^azimuth_mapping must be"):
        skyview.SkyViewSettings((8, 8), "cubic")


def test_animation_config_refuses_a_bad_map_size_naming_the_field():
    from clsky.anim.animate import AnimationConfig

    with pytest.raises(ParameterError, match=r"^skyview_size\[1\] must be an integer in \[4, 4096\]"):
        AnimationConfig(method="skyview", skyview_size=(64, 2))
    assert AnimationConfig(method="skyview").skyview_size is None      # the default map, DEFAULT_SIZE
    assert AnimationConfig(method="skyview", skyview_size=[8, np.int64(6)]).skyview_size == (8, 6)
    # a set gave its items in hash order: {33, 128} became (128, 33), width and height swapped (code review)
    with pytest.raises(ParameterError, match=r"^skyview_size must be two integers \(W, H\), got \{"):
        AnimationConfig(method="skyview", skyview_size={33, 128})


@pytest.mark.parametrize("args, named", [(["--skyview-size", "1", "64"], "--skyview-size W"),
                                         (["--skyview-size", "64", "4097"], "--skyview-size H")])
def test_cli_refuses_a_bad_map_size_one_line_exit_2(tmp_path, args, named):
    import forked_cli

    result = forked_cli.run("clsky.anim", "animate", "--method", "skyview", *args, cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clsky: error:") and named in lines[0], result.stderr
    assert list(tmp_path.iterdir()) == []


def test_render_frame_of_method_skyview_is_the_renderers_skyview(cl_context):
    """``clsky animate --method skyview``'s frame is render_skyview's with the config's map size (the
    atmosphere-plus preset: relative frames, no colour conversion), and nothing else is rendered."""
    from clsky.anim.animate import AnimationConfig, render_frame

    table = ScatteringTable.build("atmosphere-plus", TableSettings(size=(9, 33, 7), gather_theta_steps=64,
                                                                    gather_phi_steps=32), ctx=cl_context)
    with SkyRenderer(table, RAY, ctx=cl_context) as sky_renderer:
        directions, valid = FisheyeCamera(24).directions()
        prepared = sky_renderer.prepare(directions, valid)
        sun = sun_direction(80.0, 120.0)
        config = AnimationConfig(method="skyview", skyview_size=(16, 24), preset="atmosphere-plus",
                                 mode="atmosphere-plus")
        frames = render_frame(sky_renderer, prepared, sun, config)
        expected = sky_renderer.render_skyview(prepared, sun, 0.0, settings=skyview.SkyViewSettings((16, 24)))
        assert list(frames) == ["skyview"]
        assert_array_equal(frames["skyview"], expected)
        other = sky_renderer.render_skyview(prepared, sun, 0.0, settings=skyview.SkyViewSettings((8, 24)))
        assert np.abs(other - expected).max() > 0.0      # the size reaches the map


def test_maps_of_several_suns_are_each_suns_own_map(renderer):
    """skyview_maps marches the map's nodes once for several suns: each map the same bits as skyview_map
    of its sun alone, and render_skyview given that map (sky_map=) the same frame as without it; a map of
    the wrong shape, not numbers, or with a NaN, a negative value or one beyond the renderer's real type (a
    16th of its largest), is refused before the kernel (ValueError)."""
    sky_renderer = renderer()
    suns = [sun_direction(zenith, SUN_AZIMUTH + 7.0 * k) for k, zenith in enumerate((30.0, 85.0, 93.0, 97.0))]
    for altitude in (0.0, 10e3):
        maps = sky_renderer.skyview_maps(suns, altitude, MAP)
        assert maps.shape == (len(suns),) + MAP.size[::-1] + (3,)
        directions = probe_directions(suns[1], altitude)
        for sun, sky_map in zip(suns, maps):
            assert_array_equal(sky_map, sky_renderer.skyview_map(sun, altitude, MAP))
            assert_array_equal(sky_renderer.render_skyview(directions, sun, altitude, settings=MAP, sky_map=sky_map),
                               sky_renderer.render_skyview(directions, sun, altitude, settings=MAP))
    bad_maps = [maps[0][:-1], maps[0].copy(), -maps[0], np.full_like(maps[0], 1e308), [["a"]]]
    bad_maps[1][3, 2, 1] = np.nan
    for bad in bad_maps:
        with pytest.raises(ValueError, match=r"sky_map must be a sky-view map of shape \(\d+, \d+, 3\) "):
            sky_renderer.render_skyview(directions, suns[0], 0.0, settings=MAP, sky_map=bad)
    # a map's radiance carries the incident light (up to 1e12) and the Mie peak: 1e17 is a valid map's
    # (a reviewer's atmosphere), which a table's bound (1e12) refused
    bright = sky_renderer.render_skyview(directions, suns[0], 0.0, settings=MAP, sky_map=np.full_like(maps[0], 1e17))
    assert np.isfinite(bright).all()
    # 1e39 is finite in float64 and infinite in a float32 renderer's map, whose every pixel was then NaN
    with pytest.raises(ValueError, match=r"with finite values in \[0, 2.13e\+37\]"):
        renderer("float32").render_skyview(directions, suns[0], 0.0, settings=MAP, sky_map=np.full_like(maps[0], 1e39))
    with pytest.raises(ValueError, match="at least one sun"):
        sky_renderer.skyview_maps([], 0.0, MAP)


def test_view_zenith_angles_are_computed_once_per_prepared_camera(renderer):
    """render_skyview reads each pixel's view zenith angle from view_zenith_angles, computed at the first
    frame of prepared directions and kept with them (PreparedDirections.derived): the angles are NumPy's
    arctan2(hypot(x, y), z) within 1e-15 rad (both about 1 ulp of pi from the true angle of their inputs;
    a wrong component or axis would be off by O(1)), every pixel's, masked or not; a second frame reads the
    same buffer; the frames of prepared directions are the bits of raw directions' (prepared on the fly, as
    before the angles were kept); ``valid`` beside prepared directions is refused."""
    sky_renderer = renderer()
    sun = sun_direction(93.0, SUN_AZIMUTH)
    directions = probe_directions(sun, 0.0)
    valid = np.ones(directions.shape[:-1], dtype=bool)
    valid[3:5] = False
    prepared = sky_renderer.prepare(directions, valid)
    assert "view_zenith" not in prepared.derived
    first = sky_renderer.render_skyview(prepared, sun, 0.0, settings=MAP)
    angles_d = prepared.derived["view_zenith"]
    assert sky_renderer.view_zenith_angles(prepared) is angles_d
    assert_allclose(angles_d.get(), np.arctan2(np.hypot(directions[..., 0], directions[..., 1]),
                                               directions[..., 2]).ravel(), rtol=0.0, atol=1e-15)
    assert_array_equal(sky_renderer.render_skyview(prepared, sun, 0.0, settings=MAP), first)
    assert prepared.derived["view_zenith"] is angles_d
    assert_array_equal(sky_renderer.render_skyview(directions, sun, 0.0, valid, settings=MAP), first)
    with pytest.raises(ValueError, match="valid must be given to prepare"):
        sky_renderer.render_skyview(prepared, sun, 0.0, valid, settings=MAP)


def test_an_animations_batched_maps_give_each_frame_its_own(cl_context, monkeypatch):
    """frames_rendered takes the sky-view maps four suns a launch on a CPU (as the ray march): every
    frame of a sky-view sequence the same bits as render_frame of its sun alone."""
    from clsky.anim import animate

    table = ScatteringTable.build("atmosphere-plus", TableSettings(size=(9, 33, 7), gather_theta_steps=64,
                                                                    gather_phi_steps=32), ctx=cl_context)
    with SkyRenderer(table, RAY, ctx=cl_context) as sky_renderer:
        monkeypatch.setattr(animate, "ray_march_suns", lambda device: 4)
        directions, valid = FisheyeCamera(24).directions()
        prepared = sky_renderer.prepare(directions, valid)
        config = animate.AnimationConfig(method="skyview", skyview_size=(16, 24), preset="atmosphere-plus",
                                         mode="atmosphere-plus", frames=6)
        positions = animate.sun_positions(config)
        calls = []
        maps_of = sky_renderer.skyview_maps
        monkeypatch.setattr(sky_renderer, "skyview_maps",
                            lambda suns, *args: calls.append(len(suns)) or maps_of(suns, *args))
        render = animate.frames_rendered(sky_renderer, prepared, config, "skyview", positions)
        for sun in positions:
            assert_array_equal(render(sun)["skyview"],
                               animate.render_frame(sky_renderer, prepared, sun.direction, config, "skyview",
                                                    convert=False)["skyview"])
        # 6 frames: a launch of 4 suns, then one of 2; the references' own maps one sun each (skyview_map)
        assert [n for n in calls if n > 1] == [4, 2] and calls.count(1) == len(positions)


def test_spectral_renderer_reads_one_map_per_batch(cl_context):
    """SpectralRenderer.render_skyview: each batch's SkyRenderer.render_skyview with the same settings,
    assembled (12 wavelengths, the least an animation takes: four batches of three); a spectral
    animation's frames (frames_rendered) are those, and a map computed elsewhere is refused (sky_map)."""
    from clsky.spectrum import SpectralRenderer, SpectralTable

    table = SpectralTable.build("physical", 12, SMALL.replace(size=(8, 32, 8)), ctx=cl_context, keep_orders=False)
    with SpectralRenderer(table, RAY, ctx=cl_context) as spectral:
        directions, valid = FisheyeCamera(16).directions()
        sun = sun_direction(70.0, 40.0)
        settings = skyview.SkyViewSettings((8, 12))
        actual = spectral.render_skyview(spectral.prepare(directions, valid), sun, 0.0, settings=settings)
        batches = [r.render_skyview(directions, sun, 0.0, valid, settings=settings) for r in spectral.renderers]
        assert actual.shape == (16, 16, 12)
        assert_array_equal(actual, np.concatenate(batches, axis=-1))
        assert actual[valid].min() > 0.0
        # a spectral animation's frames (frames_rendered: no batched maps for a spectral renderer)
        from clsky.anim import animate

        config = animate.AnimationConfig(method="skyview", skyview_size=(8, 12), wavelengths=12, frames=2)
        positions = [animate.sunpath.SunPosition(20.0, 40.0), animate.sunpath.SunPosition(30.0, 40.0)]
        prepared = spectral.prepare(directions, valid)
        render = animate.frames_rendered(spectral, prepared, config, "skyview", positions)
        for position in positions:
            assert_array_equal(render(position)["skyview"],
                               spectral.render_skyview(prepared, position.direction, 0.0, settings=settings))
        with pytest.raises(ValueError, match="sky_map: a SpectralRenderer computes one sky-view map per"):
            spectral.render_skyview(prepared, sun, 0.0, settings=settings, sky_map=np.zeros((12, 8, 3)))
