"""The colour-true display (anim/display.py, issue 10 item 5).

1. ``--tone-map atmosphere-plus`` is the notes' curve bit for bit: the same arrays as
   :func:`clsky.anim.tonemap.tone_map` for any input, and the atmosphere-plus preset's animation frames and
   metrics hash to what the code before this module wrote.
2. The chosen curve keeps the hue of saturated sky blues (Oklab) where the notes' curve turns it, and
   keeps more of their saturation; the table in the README's "Display" section is these numbers.
3. Closed forms: the meter's log-average, the smoothing's rate limit, the white balance maps the
   sun's colour to D65, the sRGB transfer function.
4. Auto-exposure over a rendered sunrise-to-sunset sweep: the temporal-jump metric of anim/metrics.py
   shows it smoother than the scene, with no flicker; synthetic meter noise is damped.
5. Bad values: ParameterError naming the parameter; in the CLI one line, exit status 2, naming the option.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from PIL import Image

from clsky.anim import metrics, tonemap
from clsky.anim.animate import AnimationConfig, _camera, render_animation
from clsky.anim.display import (DEFAULT_TONE_MAP, TONE_CURVES, AutoExposure, Display, linear_srgb_to_oklab, meter_ev,
                          smoothed_ev, srgb_encode, white_balance_matrix)
from clsky.errors import ParameterError

import forked_cli
import pins
from pins import pinned_for_device

RNG = np.random.default_rng(10)


# 1. atmosphere-plus bit for bit ------------------------------------------------------------------

def hdr_samples():
    """HDR values over the whole range the renderer gives: zeros, twilight 1e-9, day 0.5, sun 1e3."""
    frame = 10.0 ** RNG.uniform(-9, 3, size=(17, 13, 3))
    frame[0] = 0.0
    return frame


@pytest.mark.parametrize("ev", [0.0, 1.0, -2.0, 3.5])
def test_atmosphere_plus_is_tone_map_bit_for_bit(ev):
    """encode(frame, EV) == tone_map(frame, 2^EV) exactly (the same function is called on the same
    array: the pipeline adds no arithmetic with D65 and a fixed EV); the 8-bit frames too, dithered."""
    frame = hdr_samples()
    display = Display(tone_map="atmosphere-plus")
    assert_array_equal(display.encode(frame, ev), tonemap.tone_map(frame, 2.0 ** ev))
    for seed in (0, 7):
        assert_array_equal(display.to_uint8(frame, ev, dither=True, seed=seed),
                           tonemap.to_uint8(tonemap.tone_map(frame, 2.0 ** ev), dither=True, seed=seed))
    # Delta E through the pipeline is the old Delta E: the same decoding of the same values.
    other = frame * 1.1
    old = metrics.compare_frames(frame, other, exposure=2.0 ** ev)
    new = metrics.compare_frames(frame, other, display=lambda pixels: display.linear(pixels, ev))
    assert new == old


def test_atmosphere_plus_preset_defaults_to_the_notes_curve():
    """The atmosphere-plus preset keeps the notes' display (curve, fixed EV 0, no white balance); the
    physical preset's absolute frames (cd/m^2) get auto-exposure and the sun's white by default."""
    plus = AnimationConfig(preset="atmosphere-plus")
    assert plus.tone_map == "atmosphere-plus" and not plus.absolute
    assert plus.exposure == 0.0 and plus.auto_exposure is False and plus.white_balance == "d65"
    physical = AnimationConfig()
    assert physical.tone_map == DEFAULT_TONE_MAP == "luminance-reinhard" and physical.absolute
    assert physical.exposure == 0.0 and physical.auto_exposure is True and physical.white_balance == "sun"
    fixed = AnimationConfig(auto_exposure=False, white_balance="d65", exposure=-13.0)
    assert (fixed.auto_exposure, fixed.white_balance, fixed.exposure) == (False, "d65", -13.0)


#: Recorded by the code before anim/display.py (commit bfa2a93), per OpenCL device (PoCL's code
#: generation changes the last bits between CPUs; tests/pins.py): SHA-256 of the decoded pixels of the
#: three frames of the animation of tests/pins.py (display_frames), and its per-frame metrics
#: (pins.METRIC_KEYS). The skylake entry was recorded by bfa2a93's own code (scripts/record_pins.py
#: --source <bfa2a93 checkout> display): the same 8-bit frames as on haswell, metrics that differ from
#: haswell's in the last one or two bits.
BASE_FRAMES = {
    "pthread-haswell-AMD EPYC (PoCL 3.1+debian)": (
        ["7e33492ea62ea4620cb17b1b1bda46137702f83768c7340a06375ff10044d668",
         "7fedfa4a382857dd099d48b8f49456b552bd1abfc27ca0c45c4dc020fd821e23",
         "c4e67006dbc6a893718bd874166240f69bae9ae88dd867a8784551232a7146c4"],
        [[0.041682234294391864, 1.204402884526378, 2.8225618475681173, 3.093521136350119,
          10.694550350315776, 7.799808030993745e-05],
         [0.01933054608030158, 0.012738483010173144, 0.02163172660126402, 0.025572303141927044,
          0.32280611128999215, 0.0018568964761201772],
         [0.041682234294391864, 1.204402884526378, 2.8225618475681173, 3.093521136350119,
          10.694550350315776, 7.799808030993745e-05]]),
    "pthread-skylake-avx512-AMD EPYC (PoCL 3.1+debian)": (
        ["7e33492ea62ea4620cb17b1b1bda46137702f83768c7340a06375ff10044d668",
         "7fedfa4a382857dd099d48b8f49456b552bd1abfc27ca0c45c4dc020fd821e23",
         "c4e67006dbc6a893718bd874166240f69bae9ae88dd867a8784551232a7146c4"],
        [[0.04168223429439187, 1.2044028845263783, 2.822561847568119, 3.0935211363501183,
          10.69455035031578, 7.799808030993743e-05],
         [0.019330546080301537, 0.012738483010173211, 0.02163172660126386, 0.025572303141926926,
          0.3228061112899884, 0.001856896476120177],
         [0.04168223429439187, 1.2044028845263783, 2.822561847568119, 3.0935211363501183,
          10.69455035031578, 7.799808030993743e-05]]),
}


@pytest.mark.parametrize("tone_map", [None, "atmosphere-plus"])
def test_atmosphere_plus_frames_are_those_before_the_display(tmp_path, cl_context, tone_map):
    """The atmosphere-plus preset's compare animation (table | ray march | error panels, dithered),
    by default and with tone_map='atmosphere-plus', writes the frames and metrics the code before
    this module wrote on this device (skipped on a device without a recording): the 8-bit frames bit
    for bit, the metrics to 1e-12 relative. The metrics are host-side float64 reductions (NumPy, and
    OpenBLAS for the colour conversion), whose last bits follow the kernels those libraries pick for the
    host CPU, which the OpenCL device's description does not name: two machines that both report
    'pthread-skylake-avx512-AMD EPYC' gave the recorded values and values 1 ulp off, with the same
    frames (2026-12-02; on the second NumPy reports OpenBLAS's 'Haswell' kernels; the first's were not
    recorded)."""
    frame_hashes, frame_metrics = pinned_for_device(BASE_FRAMES, cl_context)
    hashes, rows = pins.display_frames(cl_context, tmp_path, tone_map)
    assert hashes == frame_hashes
    np.testing.assert_allclose(rows, frame_metrics, rtol=1e-12, atol=0.0)


# 2. Hue and saturation -------------------------------------------------------------------------------

def sky_blues():
    """Three saturated sky blues, linear sRGB scaled to Y = 0.18 (mid-grey at EV 0): the physical
    preset's zenith with the sun 30 deg high (its relative 3-wavelength r, g, b, as they were shown
    before the colorimetric conversion), and the ColorChecker's 'blue sky'
    and 'blue' patches (colour-science's xyY, 2014 batch, taken as XYZ)."""
    import colour

    checker = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"].data
    to_rgb = colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB
    blues = {"clsky zenith": np.array([0.12296, 0.25533, 0.46752]),
             "blue sky": to_rgb @ colour.xyY_to_XYZ(checker["blue sky"]),
             "blue": to_rgb @ colour.xyY_to_XYZ(checker["blue"])}
    return {name: rgb * 0.18 / (rgb @ [0.2126, 0.7152, 0.0722]) for name, rgb in blues.items()}


def lch(rgb):
    """Oklab lightness, chroma and hue angle [deg]."""
    lightness, a, b = linear_srgb_to_oklab(rgb)
    return lightness, math.hypot(a, b), math.degrees(math.atan2(b, a))


def saturation_and_hue(curve, rgb, ev):
    """(saturation kept = (C/L)_out / (C/L)_in, hue shift [deg]) of ``rgb`` shown at ``ev``."""
    l_in, c_in, h_in = lch(rgb)
    l_out, c_out, h_out = lch(Display(tone_map=curve).linear(rgb[None], ev)[0])
    return (c_out / l_out) / (c_in / l_in), (h_out - h_in + 180.0) % 360.0 - 180.0


@pytest.mark.parametrize("name", ["clsky zenith", "blue sky", "blue"])
def test_chosen_curve_keeps_the_hue_the_notes_curve_turns(name):
    """The luminance curve scales r, g, b by one factor (Oklab's cube root is homogeneous: the hue
    angle cannot change) and the gamut mapping keeps L and h by construction, so the hue holds to
    rounding (1e-6 deg) wherever saturation is left (> 1 %, where the hue angle is defined); from EV -2
    to +4. The notes' curve turns the clsky zenith by 10.2 deg at EV +2 and 38.5 deg at +4 (measured)."""
    rgb = sky_blues()[name]
    for ev in (-2.0, 0.0, 2.0, 4.0):
        kept, shift = saturation_and_hue(DEFAULT_TONE_MAP, rgb, ev)
        if kept > 0.01:
            assert abs(shift) < 1e-6, (ev, kept, shift)
    notes = {ev: saturation_and_hue("atmosphere-plus", sky_blues()["clsky zenith"], ev) for ev in (2.0, 4.0)}
    assert notes[2.0][1] < -8.0 and notes[4.0][1] < -30.0


def test_chosen_curve_keeps_the_most_saturation():
    """Saturation kept, summed over the three blues at EV -2, 0, +2, +4 (the README table): the chosen
    curve keeps the most of every candidate; in gamut (EV <= 0 for all three, +2 for the two lighter
    ones) it keeps all of it, to rounding."""
    totals = {curve: sum(saturation_and_hue(curve, rgb, ev)[0] for rgb in sky_blues().values()
                         for ev in (-2.0, 0.0, 2.0, 4.0)) for curve in TONE_CURVES}
    assert max(totals, key=totals.get) == DEFAULT_TONE_MAP, totals
    for name, rgb in sky_blues().items():
        for ev in (-2.0, 0.0) + ((2.0,) if name != "blue" else ()):
            assert saturation_and_hue(DEFAULT_TONE_MAP, rgb, ev)[0] == pytest.approx(1.0, abs=1e-9)


def _whole_array_gamut_bisection(rgb):
    """The gamut mapping as first written (before its blocks and reused arrays): whole-array expressions."""
    from clsky.anim.display import GAMUT_STEPS, _matrices, linear_srgb_to_oklab

    rgb = np.array(rgb, dtype=np.float64)
    outside = ((rgb < 0.0) | (rgb > 1.0)).any(axis=-1)
    m = _matrices()
    lightness, a, b = linear_srgb_to_oklab(rgb[outside]).T
    lightness = np.minimum(lightness, 1.0)

    def mix(matrix, x, y, z):
        return [matrix[i, 0] * x + matrix[i, 1] * y + matrix[i, 2] * z for i in range(3)]

    def shown(t):
        return mix(m["lms_to_rgb"], *[c * c * c for c in mix(m["lab_to_lms"], lightness, t * a, t * b)])

    low, high = np.zeros(len(a)), np.ones(len(a))
    for _ in range(GAMUT_STEPS):
        middle = 0.5 * (low + high)
        red, green, blue = shown(middle)
        inside = (red >= 0.0) & (red <= 1.0) & (green >= 0.0) & (green <= 1.0) & (blue >= 0.0) & (blue <= 1.0)
        low, high = np.where(inside, middle, low), np.where(inside, high, middle)
    rgb[outside] = np.stack(shown(low), axis=-1)
    return np.clip(rgb, 0.0, 1.0)


def test_gamut_mapping_in_blocks_is_the_whole_array_bisection():
    """The gamut mapping runs its bisection in blocks of GAMUT_BLOCK pixels with reused arrays, for speed:
    bit for bit the whole-array bisection, on 2.5 blocks of random colours (a third out of the gamut by a
    negative channel, a third above 1, exposed as the luminance curve leaves them)."""
    from clsky.anim.display import GAMUT_BLOCK, _into_gamut

    rng = np.random.default_rng(5)
    rgb = rng.random((int(2.5 * GAMUT_BLOCK), 3)) * np.array([1.5, 1.2, 2.0]) - np.array([0.2, 0.1, 0.05])
    rgb[::3] = rng.random((len(rgb[::3]), 3)) * 0.9 + 0.05          # some in the gamut, left alone
    assert 0.3 < ((rgb < 0) | (rgb > 1)).any(axis=-1).mean() < 0.9
    assert_array_equal(_into_gamut(rgb), _whole_array_gamut_bisection(rgb))


@pytest.mark.parametrize("curve", sorted(TONE_CURVES))
def test_curves_stay_in_the_display_range(curve):
    """No NaN, no value outside [0, 1] for any valid input: zeros, 1e-300, 1e300 (overflowing at +40
    EV), XYZ colours outside the sRGB gamut (negative channels)."""
    frame = np.concatenate([hdr_samples().reshape(-1, 3), [[0, 0, 0], [1e-300] * 3, [1e300, 1.0, 0.0]]])
    for source, values in (("rec709", frame), ("xyz", np.array([[0.1, 0.05, 0.9], [0.6, 0.3, 0.0]]))):
        display = Display(tone_map=curve, source=source)
        for ev in (-40.0, 0.0, 40.0):
            if curve == "atmosphere-plus" and ev == 40.0:   # the notes' tone_map overflows to inf -> 1
                with np.errstate(over="ignore"):
                    assert display.encode(values, ev).max() == 1.0
                continue
            shown = display.linear(values, ev)
            assert np.isfinite(shown).all() and shown.min() >= 0.0 and shown.max() <= 1.0
            encoded = display.encode(values, ev)
            assert np.isfinite(encoded).all() and encoded.min() >= 0.0 and encoded.max() <= 1.0


# 3. Closed forms -----------------------------------------------------------------------------------

def test_meter_is_the_log_average():
    """A uniform frame of Y = y meters at log2(key / y) exactly (one log, one exp: 1e-12; key 0.36 by
    default); half black: the black half counts as the floor 1e-3 P99, so the log-average is sqrt(1e-3) y."""
    assert meter_ev(np.full(100, 0.05)) == pytest.approx(math.log2(0.36 / 0.05), abs=1e-12)
    assert meter_ev(np.full(100, 0.05), key=0.18) == pytest.approx(math.log2(0.18 / 0.05), abs=1e-12)
    half = np.concatenate([np.zeros(50), np.full(50, 2.0)])
    assert meter_ev(half) == pytest.approx(math.log2(0.36 / (2.0 * math.sqrt(1e-3))), abs=1e-12)
    assert meter_ev(np.zeros(10)) == 20.0 and meter_ev(np.full(4, 1e-30)) == 20.0


def test_smoothing_closed_form():
    """ev_k = ev_(k-1) + clip(s (target - ev_(k-1)), +-max_step): the first frame takes the target."""
    assert smoothed_ev(None, 3.0) == 3.0
    assert smoothed_ev(0.0, 1.0, smoothing=0.5, max_step_ev=2.0) == 0.5
    assert smoothed_ev(0.0, 10.0, smoothing=0.5, max_step_ev=2.0) == 2.0
    assert smoothed_ev(0.0, -10.0, smoothing=0.5, max_step_ev=2.0) == -2.0


def test_white_balance_maps_the_sun_to_d65():
    """The sun's colour becomes sRGB white of the same luminance (von Kries maps the source white
    exactly: 1e-12), both the atmosphere-plus preset's I_I taken as linear Rec. 709 and the physical
    preset's sRGB of the solar spectrum through the frames' conversion; D65 white stays white."""
    from clsky.anim.animate import three_wavelength_frame_to_linear_srgb
    from clsky import colorimetry
    from clsky.solar import solar_irradiance_astm_g173

    wavelengths = (650.0, 510.0, 475.0)
    for sun in (np.array([20.34476934, 16.90704305, 23.4530816]),
                three_wavelength_frame_to_linear_srgb(solar_irradiance_astm_g173(wavelengths), wavelengths)):
        balanced = Display(white_balance="sun", sun_white=sun).linear_srgb(sun)
        y = sun @ colorimetry.SRGB_TO_XYZ[1]
        assert_allclose(balanced, [y, y, y], rtol=1e-12)
    assert_allclose(white_balance_matrix(colorimetry.D65_WHITE_XYZ), np.eye(3), rtol=0, atol=1e-12)


def test_srgb_transfer_function():
    """IEC 61966-2-1: 12.92 x below 0.0031308, 1.055 x^(1/2.4) - 0.055 above (closed form, 1e-15)."""
    x = np.array([0.0, 0.001, 0.0031308, 0.01, 0.18, 0.5, 1.0])
    expected = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    assert_allclose(srgb_encode(x), expected, rtol=0, atol=1e-15)


def test_srgb_encode_is_colour_sciences_bit_for_bit():
    """srgb_encode writes out colour-science's sRGB encoding for speed: the same bits on values around the
    break point, at 0 and 1, beyond them (clipped) and on a random frame, NaN kept."""
    import colour

    rng = np.random.default_rng(3)
    x = np.concatenate([[0.0, 1.0, 0.0031308, np.nextafter(0.0031308, 1.0), np.nextafter(0.0031308, 0.0), -0.5,
                         1.5, 5e-324, np.nan], rng.random(100000), rng.random(1000) * 0.004])
    expected = np.asarray(colour.cctf_encoding(np.clip(x, 0.0, 1.0), function="sRGB"), dtype=np.float64)
    assert_array_equal(srgb_encode(x), expected)


# 4. Auto-exposure over time ------------------------------------------------------------------------

def display_means(hdr, valid, display):
    evs, means = [], []
    for frame in hdr:
        ev = display.exposure(frame, valid)
        evs.append(ev)
        means.append(metrics.mean_luminance(display.linear(frame, ev)[None], valid)[0])
    return np.array(evs), np.array(means)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory, cl_context):
    """A rendered sunrise-to-sunset sweep with auto-exposure: 60 frames from -6 deg to 60 deg and back
    (2.2 deg a frame), 24 x 24 fisheye, ray march; its EVs, its HDR frames and its 8-bit frames."""
    directory = tmp_path_factory.mktemp("sweep")
    config = AnimationConfig(frames=60, size=24, table_size=(9, 33, 7), method="raymarch", auto_exposure=True,
                             white_balance="d65", dither=False, hdr=True, output=str(directory / "sky.mp4"))
    result = render_animation(config, ctx=cl_context)
    hdr = np.stack([np.load(f) for f in sorted((directory / "sky_frames").glob("*.npy"))]).astype(np.float64)
    png = np.stack([np.asarray(Image.open(f)) for f in sorted((directory / "sky_frames").glob("*.png"))])
    return config, np.array([row["exposure_ev"] for row in result.rows]), hdr, png


def test_auto_exposure_sweep_is_smoother_than_the_scene(sweep):
    """Temporal-jump metric (clsky.anim.metrics.temporal_jumps: the displayed frames' mean luminance against
    the scene's HDR mean): the largest jump of the display is at most 0.6 of the scene's (measured 0.43
    against 0.83, frames in cd/m^2), the mean jump at most half (0.034 against 0.088), the excess over the
    scene's jump at most 0.05 at every frame (measured +0.007, the exposure's lag after sunrise); and no flicker: the
    EV turns once (falling to noon, rising after), never back and forth."""
    config, evs, hdr, png = sweep
    valid = _camera(config).directions()[1]
    display = Display(auto_exposure=AutoExposure())
    replayed, shown = display_means(hdr, valid, display)
    # the EVs the animation used, from the float32 HDR files (Y to 6e-8: EV to 1e-7)
    assert_allclose(replayed, evs, rtol=0, atol=1e-6)
    decoded = metrics.mean_luminance(_srgb_decode(png[..., :3] / 255.0), valid)
    assert_allclose(decoded, shown, rtol=0.02, atol=1.0 / 255)       # the PNGs show them (8-bit rounding)
    scene = metrics.mean_luminance(hdr, valid)
    jumps = metrics.temporal_jumps(shown, scene, floor=0.5 / 255)
    assert jumps["table_jumps"].max() <= 0.6 * jumps["raymarch_jumps"].max()
    assert jumps["table_jumps"].mean() <= 0.5 * jumps["raymarch_jumps"].mean()
    assert jumps["excess"].max() <= 0.05
    steps = np.diff(evs)
    signs = np.sign(steps[np.abs(steps) > 1e-9])
    assert int((np.diff(signs) != 0).sum()) == 1


def _srgb_decode(values):
    import colour

    return colour.cctf_decoding(values, function="sRGB")


def test_auto_exposure_damps_meter_flicker():
    """A uniform sky brightening 0.2 EV a frame, its meter disturbed by +-0.25 EV on alternate frames:
    unsmoothed, the display flickers by the disturbance; smoothed (s = 0.5) the alternation is damped to
    s / (2 - s) = 1/3 of it (first-order filter), so the largest display jump is at most 0.4 of the
    unsmoothed one."""
    frames = 40
    y = 0.01 * 2.0 ** (0.2 * np.arange(frames))
    noise = 0.25 * (-1.0) ** np.arange(frames)
    hdr = (y * 2.0 ** noise)[:, None, None, None] * np.ones((frames, 4, 4, 3))
    # the disturbance is in the meter only: the shown frame is the undisturbed sky
    results = {}
    for label, auto in (("smoothed", AutoExposure()), ("unsmoothed", AutoExposure(smoothing=1.0, max_step_ev=40))):
        display = Display(auto_exposure=auto)
        means = []
        for k in range(frames):
            ev = display.exposure(hdr[k])
            means.append(metrics.mean_luminance(display.linear(y[k] * np.ones((1, 4, 4, 3)), ev))[0])
        results[label] = metrics.relative_jumps(np.array(means), 0.5 / 255)[5:]
    assert results["smoothed"].max() <= 0.4 * results["unsmoothed"].max()


# 5. Bad values -------------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, field", [
    (dict(tone_map="agx"), "tone_map"), (dict(white_balance="d50"), "white_balance"),
    (dict(exposure_ev=float("nan")), "exposure_ev"), (dict(exposure_ev=41.0), "exposure_ev"),
    (dict(white_balance="sun"), "sun_white"), (dict(white_balance="sun", sun_white=[1.0, -1.0, 1.0]), "sun_white"),
    (dict(source="lab"), "source"), (dict(auto_exposure=True), "auto_exposure"),
])
def test_display_refuses_bad_parameters(kwargs, field):
    with pytest.raises(ParameterError) as caught:
        Display(**kwargs)
    assert caught.value.field == field


@pytest.mark.parametrize("kwargs, field", [(dict(key=0.0), "key"), (dict(smoothing=1.5), "smoothing"),
                                           (dict(max_step_ev=0.0), "max_step_ev"),
                                           (dict(min_ev=5.0, max_ev=1.0), "max_ev")])
def test_auto_exposure_refuses_bad_parameters(kwargs, field):
    with pytest.raises(ParameterError) as caught:
        AutoExposure(**kwargs)
    assert caught.value.field == field


def test_display_refuses_nan_frames_and_exposures():
    with pytest.raises(ValueError, match="NaN"):
        Display().encode(np.array([[np.nan, 0.0, 0.0]]), 0.0)
    for curve in ("atmosphere-plus", DEFAULT_TONE_MAP):
        with pytest.raises(ParameterError) as caught:
            Display(tone_map=curve).encode(np.ones((1, 3)), float("nan"))
        assert caught.value.field == "ev"


@pytest.mark.parametrize("args, named", [
    (["--tone-map", "agx"], "--tone-map"), (["--white-balance", "d50"], "--white-balance"),
    (["--exposure", "41"], "--exposure"), (["--exposure", "nan"], "--exposure"),
])
def test_cli_bad_display_options_one_line_exit_2(tmp_path, args, named):
    result = forked_cli.run("clsky.anim", "render", *args, "-o", "x.png", cwd=tmp_path, timeout=120)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and named in lines[0], result.stderr


# 6. The physical preset's absolute frames -------------------------------------------------------------

def _srgb_matrix_by_hand():
    """XYZ -> linear sRGB from the IEC 61966-2-1 chromaticities, written out (no clsky code)."""
    xy = [(0.64, 0.33), (0.30, 0.60), (0.15, 0.06), (0.3127, 0.3290)]
    xyz = np.array([[x / y, 1.0, (1.0 - x - y) / y] for x, y in xy])
    primaries = xyz[:3].T * np.linalg.solve(xyz[:3].T, xyz[3])
    return np.linalg.inv(primaries), primaries[1]


def _power_law_xyz_by_hand(radiance, wavelengths):
    """XYZ [cd/m^2] of radiance (n, 3) at three wavelengths: L(lambda) = E_sun(lambda) r(lambda), log r
    piecewise linear in log lambda through the three samples, the end exponents beyond them (clipped to
    +-8), 683 lm/W x sum over 1 nm of colour-science's CIE 1931 CMFs (the module docstring's closed form)."""
    import colour

    from clsky.solar import solar_irradiance_astm_g173

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    grid, bars = np.array(cmfs.wavelengths), np.array(cmfs.values)
    order = np.argsort(wavelengths)
    lam = np.array(wavelengths)[order]
    ratio = radiance[:, order] / solar_irradiance_astm_g173(lam)
    log_r = np.log(np.maximum(ratio, 1e-12 * ratio.max(axis=1, keepdims=True)))
    slopes = np.diff(log_r, axis=1) / np.diff(np.log(lam))
    low = grid <= lam[1]
    anchor = np.where(low, 0, 1)
    slope = slopes[:, anchor]
    beyond = (grid < lam[0]) | (grid > lam[2])
    slope[:, beyond] = np.clip(slope[:, beyond], -8.0, 8.0)
    r = np.exp(log_r[:, anchor] + slope * np.log(grid / lam[anchor]))
    sun = solar_irradiance_astm_g173(np.clip(grid, 365.0, 835.0))
    return 683.0 * (r * sun) @ bars


@pytest.fixture(scope="module")
def physical_frame(cl_context):
    """The physical preset's ray-marched frame (16 px fisheye, 9 x 33 x 7 table, sun 20 deg high), as
    the animation converts it, and the same table rendered with the preset's relative I_I."""
    import dataclasses

    from clsky.anim.animate import make_renderer, ray_settings, render_frame
    from clsky.anim.cameras import sun_direction
    from clsky.render import SkyRenderer

    config = AnimationConfig(size=16, method="raymarch", table_size=(9, 33, 7), dither=False,
                             auto_exposure=False, white_balance="d65", exposure=-12.0)
    directions, valid = _camera(config).directions()
    renderer, table = make_renderer(config, ctx=cl_context)
    sun = sun_direction(70.0, 180.0)
    hdr = render_frame(renderer, renderer.prepare(directions, valid), sun, config)["raymarch"]
    with SkyRenderer(dataclasses.replace(table, atmosphere=config.atmosphere), ray_settings(config),
                     ctx=cl_context) as relative:
        notes = relative.render_raymarch(directions, sun, valid=valid)
    return config, table, valid, hdr, notes


def test_physical_frame_is_the_conversion_by_hand(physical_frame):
    """A physical frame's pixels are the pipeline written out: the notes' relative radiance times
    E_sun(lambda) / I_I (absolute units: the table carries no I_I), the power-law reconstruction
    integrated against the CMFs at 1 nm, the sRGB matrix from the chromaticities (1e-6: the tabulated
    conversion is 5e-7 from the exact one); then the display at a fixed EV -12, luminance-reinhard,
    the sRGB function, 8 bits (within one code value where rounding meets the 1e-6), and the
    auto-exposure's first EV: log2(0.36 / log-average Y) with the 1e-3 P99 floor (2e-6 EV: Y to 1e-6
    is 1.4e-6 EV)."""
    from clsky.anim.animate import display, display_frames
    from clsky.solar import ABSOLUTE_UNITS, solar_irradiance_astm_g173

    config, table, valid, hdr, notes = physical_frame
    assert table.metadata["units"] == ABSOLUTE_UNITS
    wavelengths = table.atmosphere.wavelengths
    absolute = notes[valid] * solar_irradiance_astm_g173(wavelengths) / np.array(config.atmosphere.incident_light)
    to_rgb, y_row = _srgb_matrix_by_hand()
    rgb = np.maximum(_power_law_xyz_by_hand(absolute, wavelengths) @ to_rgb.T, 0.0)
    assert_allclose(hdr[valid], rgb, rtol=1e-6, atol=0)
    assert 1e3 < (rgb @ y_row).mean() < 1e4                    # a day sky: thousands of cd/m^2

    y = rgb @ y_row
    exposed = y * 2.0 ** -12
    shown = rgb * (2.0 ** -12 / (1.0 + exposed))[:, None]       # Y / (1 + Y) on luminance, chroma kept
    inside = (shown <= 1.0).all(axis=1)
    assert inside.mean() > 0.9                                  # the sun's pixel (gamut-mapped) aside
    encoded = np.where(shown <= 0.0031308, 12.92 * shown, 1.055 * shown ** (1 / 2.4) - 0.055)
    ev, images, _ = display_frames(display(config, table), {"raymarch": hdr}, valid, config)
    assert ev == -12.0
    code = images["raymarch"][valid][inside].astype(int)
    assert np.abs(code - np.floor(255.0 * encoded[inside] + 0.5)).max() <= 1

    auto = AnimationConfig(**{**config.__dict__, "auto_exposure": True, "exposure": 0.0})
    metered = display(auto, table).exposure(hdr, valid)
    floor = 1e-3 * np.percentile(y, 99)
    assert metered == pytest.approx(math.log2(0.36 / math.exp(np.mean(np.log(np.maximum(y, floor))))), abs=2e-6)


def test_physical_frames_sun_white_balance(physical_frame):
    """White balance 'sun' (the physical preset's default) shows the sun's own spectrum as neutral: the
    sun's sRGB by hand (the reconstruction is exact for E_sun itself) is balanced to r = g = b (1e-6: the
    pipeline's sun is the tabulated conversion's), and it has the solar spectrum's chromaticity (x 0.3236,
    y 0.3331, README "Spectral radiance and units"; to 1e-4, the printed digits)."""
    from clsky.anim.animate import display
    from clsky.solar import solar_irradiance_astm_g173

    config, table, _, _, _ = physical_frame
    sun_config = AnimationConfig(**{**config.__dict__, "white_balance": "sun"})
    pipeline = display(sun_config, table)
    wavelengths = table.atmosphere.wavelengths
    xyz = _power_law_xyz_by_hand(solar_irradiance_astm_g173(wavelengths)[None], wavelengths)[0]
    to_rgb, _ = _srgb_matrix_by_hand()
    sun_rgb = xyz @ to_rgb.T
    balanced = pipeline.linear_srgb(sun_rgb)
    assert_allclose(balanced, np.full(3, balanced.mean()), rtol=1e-6)
    assert_allclose(xyz[:2] / xyz.sum(), [0.3236, 0.3331], atol=1e-4)


@pytest.mark.parametrize("preset, units", [("physical", "linear sRGB [cd/m^2]"),
                                           ("atmosphere-plus", "relative (incident light I_I per sr)")])
def test_frame_units_in_the_metrics_json(tmp_path, cl_context, preset, units):
    """<stem>_metrics.json records the frames' units (table.frame_units), the table's (metadata.units)
    and the display the preset's defaults resolved to."""
    import json

    from clsky.solar import ABSOLUTE_UNITS, RELATIVE_UNITS

    mode = "physical" if preset == "physical" else "atmosphere-plus"
    config = AnimationConfig(frames=2, size=16, table_size=(9, 33, 7), method="lut", preset=preset, mode=mode,
                             output=str(tmp_path / "sky.mp4"))
    render_animation(config, ctx=cl_context)
    record = json.loads((tmp_path / "sky_metrics.json").read_text(encoding="utf-8"))
    assert record["table"]["frame_units"].startswith(units)
    assert record["table"]["metadata"]["units"] == (ABSOLUTE_UNITS if preset == "physical" else RELATIVE_UNITS)
    absolute = preset == "physical"
    assert (record["display"]["auto_exposure"] is not None) == absolute
    assert record["display"]["white_balance"] == ("sun" if absolute else "d65")


def test_dusk_zenith_is_still_blue(cl_context):
    """The physical preset's dusk (sun 3 deg below the horizon) through the colorimetric conversion:
    the zenith is blue in bench_dusk's sense, b > g > r by at least 2 % each in the linear values
    (24 px fisheye, 16 x 64 x 32 table, ray march; measured b/g 1.854, g/r 1.036; the README's
    128 px, default-quality figures are bench/bench_dusk.py's), and in the 8-bit frame."""
    from clsky.anim.animate import display, display_frames, make_renderer, render_frame
    from clsky.anim.cameras import sun_direction

    config = AnimationConfig(size=24, method="raymarch", table_size=(16, 64, 32), dither=False)
    directions, valid = _camera(config).directions()
    renderer, table = make_renderer(config, ctx=cl_context)
    hdr = render_frame(renderer, renderer.prepare(directions, valid), sun_direction(93.0, 180.0), config)
    heights = np.where(valid, directions[..., 2], -2.0)
    zenith = heights >= np.sort(heights, axis=None)[-4]                 # the 4 pixels nearest the zenith
    r, g, b = hdr["raymarch"][zenith].mean(axis=0)
    assert b > 1.02 * g and g > 1.02 * r, (r, g, b)
    _, images, _ = display_frames(display(config, table), hdr, valid, config)
    r8, g8, b8 = images["raymarch"][zenith].astype(float).mean(axis=0)
    assert b8 > g8 > r8, (r8, g8, b8)


@pytest.mark.parametrize("curve", sorted(TONE_CURVES))       # atmosphere-plus among them
@pytest.mark.parametrize("white_balance", ["d65", "sun"])
def test_encode_and_linear_are_the_two_calls_bit_for_bit(curve, white_balance):
    """Display.encode_and_linear (one tone-curve evaluation for the 8-bit frame and Delta E) returns
    exactly encode() and linear(): the animation's frames and metrics must not change by a bit. The
    frame spans dark, bright and saturated (out-of-gamut after white balance) pixels."""
    rng = np.random.default_rng(12)
    frame = np.concatenate([rng.random((64, 3)) * 10.0 ** rng.uniform(-3, 3, (64, 1)),
                            [[5.0, 0.0, 0.0], [0.0, 0.0, 9.0], [0.0, 0.0, 0.0], [1e4, 1e4, 1e4]]]).reshape(17, 4, 3)
    pipeline = Display(curve, 1.5, white_balance=white_balance, sun_white=np.array([1.0, 0.9, 0.7]))
    for ev in (-3.0, 0.0, 2.5):
        encoded, linear = pipeline.encode_and_linear(frame, ev)
        assert encoded.tobytes() == pipeline.encode(frame, ev).tobytes()
        assert linear.tobytes() == pipeline.linear(frame, ev).tobytes()


@pytest.mark.parametrize("arguments, message", [
    (dict(key=math.nan), r"^key must be a number in \(0, 1\], got nan"),           # returned NaN
    (dict(key=0), r"^key must be a number in \(0, 1\], got 0"),                     # a math domain error
    (dict(min_ev=5, max_ev=-5), r"^max_ev must be a number in \[5, 60\], got -5"),   # returned -5
])
def test_meter_ev_refuses_what_cannot_be_metered(arguments, message):
    with pytest.raises(ValueError, match=message):
        meter_ev(np.ones(4), **arguments)


def test_smoothed_ev_refuses_a_non_finite_ev():
    with pytest.raises(ValueError, match=r"^metered must be a finite number, got nan"):
        smoothed_ev(0.0, math.nan)                                                   # returned NaN
    for arguments, message in ((dict(smoothing=math.nan), r"^smoothing must be a number in \(0, 1\]"),
                               (dict(max_step_ev=-3.0), r"^max_step_ev must be a number in \(0, 40\]")):
        with pytest.raises(ValueError, match=message):                              # NaN, or a step back
            smoothed_ev(0.0, 1.0, **arguments)
    assert smoothed_ev(None, 3.0) == 3.0 and smoothed_ev(0.0, 10.0) == 2.0           # max_step_ev 2


def test_metered_ev_refuses_a_mask_of_another_shape():
    """A mask of another shape than the frame's was NumPy's IndexError."""
    display = Display(auto_exposure=AutoExposure())
    with pytest.raises(ValueError, match=r"^valid must be a mask of the frame's shape \(4, 4\), got shape \(3, 3\)"):
        display.metered_ev(np.ones((4, 4, 3)), np.ones((3, 3), dtype=bool))
    assert math.isfinite(display.metered_ev(np.ones((4, 4, 3)), np.ones((4, 4), dtype=bool)))
