"""Spectral radiance: any number N of wavelengths, computed as batches of three through the same kernels.

The kernels compute three channels (``atmosphere_t``'s real4 coefficients). N wavelengths are
ceil(N / 3) batches of three, the last one padded by repeating its last wavelength; each batch is an
:class:`~clsky.atmosphere.AtmosphereParameters` made from a base atmosphere (:func:`batch_atmospheres`):

* beta_R(lambda) = 8 pi^3 (n^2 - 1)^2 / (3 N_R lambda^4) at each wavelength
  (:func:`clsky.atmosphere.rayleigh_scattering_coefficient`, n = 1.0003, N_R = 2.545e25 m^-3);
* the ozone cross-section per wavelength (:func:`clsky.ozone.cross_section_serdyuchenko2014`);
* Mie per wavelength by the base's Angstrom exponent (``mie_angstrom_exponent``; 0: the same beta_M);
* the incident light is the extraterrestrial solar spectrum at the batch's wavelengths
  (:func:`clsky.solar.with_solar_spectrum`), so the radiance is in W m^-2 sr^-1 nm^-1.

Everything else (geometry, scale heights, phase functions, ozone profile) is the base's. Each batch
builds an ordinary :class:`~clsky.table.ScatteringTable` and renders through an ordinary
:class:`~clsky.render.SkyRenderer`; :class:`SpectralTable` and :class:`SpectralRenderer` assemble the
(..., N) spectral radiance and drop the padding. The gather matrices depend on the grid and the phase
functions, not on the wavelengths: the batches share them (cached in :mod:`clsky.multiple`, the
physical mode's first-gather stacks kept for the duration of a build by
:func:`clsky.multiple.keeping_first_gather_stacks`).

The default wavelengths of N (:func:`spectral_wavelengths`) are the midpoints of N equal cells of
:data:`SPECTRAL_RANGE` (360 to 830 nm), as Bruneton's precomputed-luminance mode places them; with
:func:`clsky.colorimetry.spectral_to_xyz` the integral over the visible range is then the midpoint
rule. N is at most :data:`MAX_WAVELENGTHS` = 47 (10 nm cells; finer grids would put the first node
below 365 nm, where the shipped 10 nm bins of the ozone and solar data have no centre).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .atmosphere import AtmosphereParameters, as_atmosphere, rayleigh_scattering_coefficient
from .errors import ParameterError, check_instance, is_integer
from .ozone import cross_section_serdyuchenko2014
from .solar import ABSOLUTE_UNITS, with_solar_spectrum

__all__ = ["SPECTRAL_RANGE", "MIN_WAVELENGTHS", "MAX_WAVELENGTHS", "MIN_COLOUR_WAVELENGTHS", "DATA_RANGE",
           "spectral_wavelengths", "check_wavelengths", "wavelength_batches", "batch_atmospheres", "SpectralTable",
           "SpectralRenderer"]

#: The visible range the default grids divide [nm].
SPECTRAL_RANGE = (360.0, 830.0)
#: Least and largest N of a default grid.
MIN_WAVELENGTHS, MAX_WAVELENGTHS = 3, 47
#: Least N of a default grid whose spectra become colours (``clsky animate --wavelengths N``, whose frames
#: are :func:`clsky.colorimetry.spectral_to_xyz`'s midpoint rule on the grid): against 1 nm sums, the
#: sun's spectrum, Rayleigh light (E_sun lambda^-4) and a reddened sun (30 air masses of Rayleigh) are
#: off by 0.0042 to 0.17 in x or y or by 0.8 to 22 % in Y for every N from 3 to 11 (N = 3 turns the
#: sun's own spectrum magenta, xy (0.370, 0.191) for (0.324, 0.333)); by at most 0.0072 and 0.36 % from
#: 12 to 47 (measured 2026-12-07; tests/test_spectral.py). A table of fewer wavelengths, for their
#: radiance alone, is the API's (:class:`SpectralTable`).
MIN_COLOUR_WAVELENGTHS = 12
#: Wavelengths the shipped ozone and solar bins cover (their first and last bin centres) [nm].
DATA_RANGE = (365.0, 835.0)
#: The refractive index and number density the batches' beta_R follow (docs/physics.md).
REFRACTIVE_INDEX, NUMBER_DENSITY = 1.0003, 2.545e25


def spectral_wavelengths(count):
    """The midpoints of ``count`` equal cells of :data:`SPECTRAL_RANGE` [nm].

    Examples
    --------
    >>> spectral_wavelengths(3).round(2).tolist()
    [438.33, 595.0, 751.67]
    >>> spectral_wavelengths(47)[[0, -1]].tolist()
    [365.0, 825.0]
    """
    if not is_integer(count) or not MIN_WAVELENGTHS <= count <= MAX_WAVELENGTHS:
        raise ParameterError("wavelengths", f"an integer in [{MIN_WAVELENGTHS}, {MAX_WAVELENGTHS}] or a list of "
                                            f"wavelengths [nm]", count)
    low, high = SPECTRAL_RANGE
    step = (high - low) / count
    return low + (np.arange(count) + 0.5) * step


def check_wavelengths(wavelengths):
    """``wavelengths`` as an increasing float64 array [nm]: an integer N gives :func:`spectral_wavelengths`;
    a sequence must hold at least 3 strictly increasing values in :data:`DATA_RANGE`.

    Raises
    ------
    ValueError
        (:class:`clsky.errors.ParameterError`, field ``wavelengths``) otherwise.
    """
    if is_integer(wavelengths):
        return spectral_wavelengths(int(wavelengths))
    try:
        values = np.asarray(wavelengths, dtype=np.float64)
    except (TypeError, ValueError):
        values = None
    low, high = DATA_RANGE
    if (values is None or values.ndim != 1 or values.size < 3 or not np.all(np.isfinite(values))
            or np.any(values < low) or np.any(values > high) or np.any(np.diff(values) <= 0)):
        raise ParameterError("wavelengths", f"an integer in [{MIN_WAVELENGTHS}, {MAX_WAVELENGTHS}] or at least 3 "
                                            f"increasing wavelengths in [{low:g}, {high:g}] nm", wavelengths)
    return values


def wavelength_batches(wavelengths):
    """The batches of three [nm] covering ``wavelengths`` in order, the last padded with its last value.

    Examples
    --------
    >>> wavelength_batches([400.0, 500.0, 600.0, 700.0])
    [(400.0, 500.0, 600.0), (700.0, 700.0, 700.0)]
    """
    values = [float(w) for w in check_wavelengths(wavelengths)]
    batches = []
    for start in range(0, len(values), 3):
        batch = values[start:start + 3]
        batches.append(tuple(batch + [batch[-1]] * (3 - len(batch))))
    return batches


def batch_atmospheres(base: AtmosphereParameters, wavelengths, refractive_index=REFRACTIVE_INDEX,
                      number_density=NUMBER_DENSITY):
    """The atmospheres of the batches (module docstring): one per :func:`wavelength_batches` batch.

    Examples
    --------
    >>> from clsky import preset
    >>> [a.wavelengths for a in batch_atmospheres(preset("physical"), 4)]
    [(418.75, 536.25, 653.75), (771.25, 771.25, 771.25)]
    """
    check_instance("base", base, AtmosphereParameters, "an AtmosphereParameters (the batches' other fields)")
    atmospheres = []
    for batch in wavelength_batches(wavelengths):
        beta = rayleigh_scattering_coefficient(refractive_index, number_density, batch)
        atmosphere = base.replace(wavelengths=batch, rayleigh_scattering=tuple(float(b) for b in beta),
                                  ozone_cross_section=tuple(float(s) for s in cross_section_serdyuchenko2014(batch)))
        atmospheres.append(with_solar_spectrum(atmosphere))
    return atmospheres


@dataclasses.dataclass(frozen=True)
class SpectralTable:
    """The scattering tables of N wavelengths: one :class:`~clsky.table.ScatteringTable` per batch of three.

    Attributes
    ----------
    wavelengths : numpy.ndarray (N,)
        [nm], increasing.
    tables : tuple of ScatteringTable
        One per batch (:func:`wavelength_batches`); each batch atmosphere's incident light is the solar
        spectrum, and each table's metadata records ``units`` and its ``spectral_batch``.
    record : dict
        ``units`` (:data:`clsky.solar.ABSOLUTE_UNITS`), ``wavelengths_nm``, ``batches``, ``build_seconds``
        (wall) and ``build_cpu_seconds`` (this process).
    """

    wavelengths: np.ndarray
    tables: tuple
    record: dict

    @classmethod
    def build(cls, atmosphere: AtmosphereParameters | str = "physical", wavelengths=15, settings=None,
              backend="opencl", ctx=None, fast_math=False, progress=None, keep_orders=True) -> "SpectralTable":
        """Build every batch's table with :meth:`ScatteringTable.build` (same ``settings``, ``backend``,
        ``ctx``, ``fast_math``; ``progress(stage, done, total)`` gets stage ``'batch'`` before each batch).

        Parameters
        ----------
        atmosphere : AtmosphereParameters or preset name
            The base atmosphere (its coefficients at three wavelengths are replaced, module docstring).
        wavelengths : int or sequence of float
            N (:func:`spectral_wavelengths`) or the wavelengths [nm] (:func:`check_wavelengths`).
        keep_orders : bool
            Keep each batch's orders (K tables); False drops them as soon as the batch is built, so
            that a build holds one batch's orders at a time (renderers read data and gathered only).

        Examples
        --------
        >>> from clsky import TableSettings
        >>> spectral = SpectralTable.build("physical", 4, TableSettings(size=(8, 16, 8), mode="physical"))
        >>> len(spectral.tables), spectral.record["units"]
        (2, 'W m^-2 sr^-1 nm^-1')
        """
        from .multiple import keeping_first_gather_stacks
        from .table import ScatteringTable

        base = as_atmosphere(atmosphere)
        values = check_wavelengths(wavelengths)
        atmospheres = batch_atmospheres(base, values)
        start, cpu = time.perf_counter(), time.process_time()
        tables = []
        with keeping_first_gather_stacks():
            for index, batch in enumerate(atmospheres):
                if progress is not None:
                    progress("batch", index, len(atmospheres))
                table = ScatteringTable.build(batch, settings, backend=backend, ctx=ctx, fast_math=fast_math,
                                              progress=progress)
                table.metadata["spectral_batch"] = {"index": index, "of": len(atmospheres),
                                                    "wavelengths_nm": list(batch.wavelengths)}
                tables.append(table if keep_orders else dataclasses.replace(table, orders=()))
                del table       # else the last batch's orders stay alive through the next batch's build
        record = {"units": ABSOLUTE_UNITS, "wavelengths_nm": values.tolist(), "batches": len(tables),
                  "build_seconds": time.perf_counter() - start, "build_cpu_seconds": time.process_time() - cpu}
        return cls(values, tuple(tables), record)

    @property
    def units(self) -> str:
        return self.record["units"]

    @property
    def settings(self):
        """The TableSettings every batch was built with."""
        return self.tables[0].settings

    @property
    def orders_record(self) -> dict:
        """Each batch's orders record, in batch order."""
        return {"batches": [table.orders_record for table in self.tables]}

    @property
    def metadata(self) -> dict:
        """:attr:`record` with each batch's metadata."""
        return {**self.record, "batch_metadata": [table.metadata for table in self.tables]}

    def assemble(self, batch_values):
        """(..., N) from one (..., 3) array per batch, the padding dropped."""
        stacked = np.concatenate([np.asarray(v, dtype=np.float64) for v in batch_values], axis=-1)
        return stacked[..., : self.wavelengths.size]


class SpectralRenderer:
    """Renders (..., N) spectral radiance [W m^-2 sr^-1 nm^-1] of a :class:`SpectralTable`: one
    :class:`~clsky.render.SkyRenderer` per batch. Its frame methods (``render_table``, ``render_lut4d``,
    ``render_raymarch``, ``render_skyview``) and ``prepare`` take the SkyRenderer's arguments (but
    ``render_skyview``'s ``sky_map``, which must be None: it computes a map per batch itself); the
    SkyRenderer's helpers of several suns or of one batch's maps (``render_raymarch_suns``, ``skyview_map``,
    ``skyview_maps``, ``view_zenith_angles``) are not here: a spectral frame is assembled from every batch.

    Parameters
    ----------
    spectral_table : SpectralTable
    ray_settings, ctx, fast_math
        As :class:`~clsky.render.SkyRenderer` takes them, for every batch.
    """

    def __init__(self, spectral_table: SpectralTable, ray_settings=None, ctx=None, fast_math=False):
        from .render import SkyRenderer

        self.table = check_instance("spectral_table", spectral_table, SpectralTable,
                                    "a SpectralTable (SpectralTable.build)")
        self.renderers, self.closed = [], False
        try:
            for table in spectral_table.tables:
                self.renderers.append(SkyRenderer(table, ray_settings, ctx=ctx, fast_math=fast_math))
        except BaseException:
            self.close()
            raise

    @property
    def wavelengths(self):
        return self.table.wavelengths

    @property
    def units(self) -> str:
        return self.table.units

    def _check_open(self):
        if self.closed:
            raise ValueError("this SpectralRenderer is closed (close() or the end of its with block): make a new one")

    def prepare(self, directions, valid=None):
        """The directions uploaded once for every batch's renderer (pass the result as ``directions``)."""
        self._check_open()
        return _Prepared(tuple(r.prepare(directions, valid) for r in self.renderers))

    def _render(self, name, directions, sun_direction, altitude, valid, **options):
        self._check_open()
        if not isinstance(directions, _Prepared):
            directions = self.prepare(directions, valid)
        elif valid is not None:
            raise ValueError("valid must be given to prepare(), not with prepared directions")
        try:
            return self.table.assemble(getattr(renderer, name)(prepared, sun_direction, altitude, **options)
                                       for renderer, prepared in zip(self.renderers, directions.per_renderer))
        except ValueError:
            self._check_open()          # closed by another thread during the call: named as this renderer
            raise

    def render_table(self, directions, sun_direction, altitude=0.0, valid=None):
        """Spectral radiance (..., N) by table lookup (:meth:`clsky.render.SkyRenderer.render_table`)."""
        return self._render("render_table", directions, sun_direction, altitude, valid)

    def render_lut4d(self, directions, sun_direction, altitude=0.0, valid=None):
        """Spectral radiance (..., N) by lookup in the batches' 4D tables (a SpectralTable built with
        ``parameterization='4d'``; :meth:`clsky.render.SkyRenderer.render_lut4d`). Such a table's render_table
        refuses and names this method."""
        return self._render("render_lut4d", directions, sun_direction, altitude, valid)

    def render_raymarch(self, directions, sun_direction, altitude=0.0, valid=None, sun_disc=True):
        """Spectral radiance (..., N) by ray march (:meth:`clsky.render.SkyRenderer.render_raymarch`; with
        ``sun_disc``, its sun's disc)."""
        return self._render("render_raymarch", directions, sun_direction, altitude, valid, sun_disc=sun_disc)

    def render_skyview(self, directions, sun_direction, altitude=0.0, valid=None, settings=None, sky_map=None):
        """Spectral radiance (..., N) from per-frame sky-view maps, one per batch
        (:meth:`clsky.render.SkyRenderer.render_skyview`), each computed here: ``sky_map`` (the
        SkyRenderer's map computed already) must be None, a spectral frame's maps being one per batch."""
        if sky_map is not None:
            raise ValueError("sky_map: a SpectralRenderer computes one sky-view map per wavelength batch itself; "
                             "pass None")
        return self._render("render_skyview", directions, sun_direction, altitude, valid, settings=settings)

    def close(self):
        """Close every batch's renderer (:meth:`clsky.render.SkyRenderer.close`); the methods then raise
        ValueError. Closing twice is harmless."""
        self.closed = True
        for renderer in self.renderers:
            renderer.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


@dataclasses.dataclass(frozen=True)
class _Prepared:
    """Directions prepared by every batch's renderer (:meth:`SpectralRenderer.prepare`)."""

    per_renderer: tuple

    @property
    def shape(self):
        return self.per_renderer[0].shape

