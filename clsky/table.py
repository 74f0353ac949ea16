"""The scattering table as a product: build, look up, save, load, export for GPU engines.

File format (``.npz``, uncompressed: compression saves little on these values and costs seconds;
:data:`FORMAT_VERSION` 5). Members:

``format_version``
    int64 scalar, 5 (4 until the settings gained ``azimuth_harmonics``, which enters the parameters hash
    and the shape of ``gathered``: a version-4 file is refused, "rebuild the table").
``data``
    (D, H, W, C) table values at full precision (float64 as built, or the settings' dtype), finite, >= 0;
    (A, D, H, W, C) with the settings' ``parameterization`` '4d' (clsky/table4d.py). That setting enters
    the settings' JSON only away from its default, so 3D files and their hashes are as before and the
    format version did not change (a clsky without it refuses a 4D file: "unknown table settings").
``order_1``, ``order_2``, ..., ``order_K``
    Every scattering order, stored as float32 for inspection: order 1 (D, H, W, 6) factored, higher
    orders (D, H, W, 6) factored (atmosphere-plus) or (D, H, W, 3) phased (physical); finite, >= 0.
``gathered``
    (D, H, W, 6), the sum of the gathered in-scatter tables for the ray march, finite, >= 0; with
    ``azimuth_harmonics`` = M > 0, (M + 1, D, H, W, 6), its cosine harmonics (harmonic 0 >= 0); absent
    for single scattering.
``ground_irradiance``
    (D, 3) float64, the sky's irradiance on a reflecting ground per sun node (clsky/ground.py), finite,
    >= 0; present exactly when the atmosphere's ground_albedo is > 0 (files of a black ground, and so
    every file written before the ground existed, have none: it came without a version change).
``atmosphere``, ``settings``, ``metadata``, ``orders_record``
    JSON objects (0-d unicode strings): the parameters, the provenance, how the iteration stopped.
``parameters_hash``
    SHA-256 of the atmosphere and settings (:func:`parameters_hash`): identifies the parameters.
``checksums``
    JSON object, member name -> SHA-256 of that member (:func:`array_checksum`: its dtype, shape and
    bytes), for every other member. It detects corruption and careless edits, not a deliberate
    forgery (it has no key): the checks on shapes, dtypes and values are what keeps a forged file
    from reaching a kernel.

:meth:`ScatteringTable.load` refuses with :class:`TableFormatError`, naming the file and what is wrong,
any file that is not such an archive, has another version (older files: rebuild the table), misses
or adds a member, fails a checksum or the parameters hash, or holds arrays whose shape, dtype or
values (:meth:`ScatteringTable.validate`) do not fit its settings.

Raw export (:meth:`ScatteringTable.export_raw`): ``<name>.bin`` holds little-endian float32 values,
cell after cell in the order i = x + y W + z W H (x: altitude, y: view zenith, z: sun zenith), C
channels per cell; ``<name>.json`` documents that layout, the mappings, the atmosphere and settings.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import re
import time
import tokenize
import zipfile
import zlib
from typing import Callable

import numpy as np

from . import __version__
from ._files import StagedWrites, as_path, atomic_write, binary_and_header, check_output, check_suffix
from .atmosphere import PRESETS, AtmosphereParameters, preset
from .errors import check_instance, short
from .lookup import check_queries
from .settings import TableSettings
from .solar import radiance_units

__all__ = ["ScatteringTable", "TableFormatError", "FORMAT_VERSION", "BACKENDS", "atomic_write",
           "CHANNEL_NAMES", "array_checksum", "check_table_array"]

# 3: settings carry sun_cos_range (the sun axis' sub-range); 4: a checksum of every member
FORMAT_VERSION = 5
BACKENDS = ("opencl", "numpy")
_MULTIPLE_NAMES = ("multiple_r", "multiple_g", "multiple_b")
CHANNEL_NAMES = {6: ("rayleigh_r", "rayleigh_g", "rayleigh_b", "mie_r", "mie_g", "mie_b"),
                 4: ("rayleigh_r", "rayleigh_g", "rayleigh_b", "mie")}
CHANNEL_NAMES[9] = CHANNEL_NAMES[6] + _MULTIPLE_NAMES
CHANNEL_NAMES[7] = CHANNEL_NAMES[4] + _MULTIPLE_NAMES


class TableFormatError(ValueError):
    """A table (or table file) that clsky must not use: unreadable file, wrong version, checksum or
    hash, or arrays whose shape, dtype or values do not fit the settings."""


def parameters_hash(atmosphere: AtmosphereParameters, settings: TableSettings) -> str:
    """SHA-256 of the canonical JSON of the atmosphere and the settings."""
    text = json.dumps({"atmosphere": atmosphere.to_dict(), "settings": settings.to_dict()},
                      sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def array_checksum(array) -> str:
    """SHA-256 of an array's dtype (``dtype.str``), shape and bytes in C order, as a hex string.

    Examples
    --------
    >>> array_checksum(np.zeros(2)) == array_checksum(np.zeros(2))
    True
    >>> array_checksum(np.zeros(2)) == array_checksum(np.zeros(2, dtype=np.float32))
    False
    """
    array = np.asarray(array)
    digest = hashlib.sha256(json.dumps({"dtype": array.dtype.str, "shape": list(array.shape)}).encode())
    digest.update(np.ascontiguousarray(array).reshape(-1).view(np.uint8))
    return digest.hexdigest()


def check_finite_nonnegative(name, array):
    """TableFormatError unless every value of ``array`` is finite and >= 0 (radiances [1/sr])."""
    _check_values(name, array, nonnegative=True)


def check_finite_signed(name, array):
    """TableFormatError unless every value of ``array`` is finite, of either sign (the azimuth harmonics
    m >= 1 of a gathered table)."""
    _check_values(name, array, nonnegative=False)


def _check_values(name, array, nonnegative):
    """The two checks above by the array's minimum and maximum only (NaN propagates through both), no
    array of their own: ``np.abs`` of the default animation's harmonics, checked as non-negative before,
    took 82 MB of memory, which cost 0.04-0.54 s of one core at the end of the table's build where the
    machine had not handed such memory out lately (docs/speed-log.md), against 0.02 s for the reductions.
    The values are counted only for the error."""
    if array.size == 0:
        return
    low, high = array.min(), array.max()
    if (low >= 0 if nonnegative else low > -np.inf) and high < np.inf:
        return
    counts = {"NaN": np.isnan(array).sum(), "infinite": np.isinf(array).sum(),
              "negative": (array < 0).sum() if nonnegative else 0}
    found = " and ".join(f"{int(count)} {kind}" for kind, count in counts.items() if count)
    expected = "finite and >= 0" if nonnegative else "finite"
    raise TableFormatError(f"{name} holds {found} values (a table's values are {expected})")


def check_table_array(name, array, shape, dtypes, check_values=True):
    """Check one of a table's arrays: a NumPy array of ``shape``, a dtype in ``dtypes``, and (when
    ``check_values``) finite non-negative values; TableFormatError names ``name`` and what is wrong."""
    if not isinstance(array, np.ndarray):
        raise TableFormatError(f"{name} must be a NumPy array, got {type(array).__name__}")
    if array.shape != tuple(shape):
        raise TableFormatError(f"{name} has shape {array.shape}, the settings need {tuple(shape)} (D, H, W, C)")
    if array.dtype not in [np.dtype(d) for d in dtypes]:
        raise TableFormatError(f"{name} has dtype {array.dtype}, expected {' or '.join(map(str, dtypes))}")
    if check_values:
        check_finite_nonnegative(name, array)


def order_channels(settings: TableSettings, k: int) -> int:
    """Channels of order ``k`` (1-based): 6 factored for single scattering and the atmosphere-plus
    mode's higher orders, 3 phased for the physical mode's (clsky/orders.py)."""
    return 6 if k == 1 or settings.mode == "atmosphere-plus" else 3


def max_orders_kept(settings: TableSettings) -> int:
    """The most orders a build with ``settings`` computes."""
    return settings.max_orders if settings.orders == "auto" else settings.orders


def to_layout(data6, mie_layout):
    """Factored per-wavelength (D, H, W, 6) values in the requested layout (the notes' layout averages
    the three Mie channels into one); channels after the sixth (the physical mode's phased higher
    orders) are kept as they are."""
    if mie_layout == "notes":
        return np.concatenate([data6[..., :3], data6[..., 3:6].mean(axis=-1, keepdims=True), data6[..., 6:]],
                              axis=-1)
    return data6


@dataclasses.dataclass(frozen=True, eq=False)
class ScatteringTable:
    """A precomputed scattering table with everything that defines it.

    Attributes
    ----------
    atmosphere : AtmosphereParameters
    settings : TableSettings
    data : numpy.ndarray, shape (D, H, W, C)
        Per cell [1/sr], without I_I: channels :data:`CHANNEL_NAMES` [C]. The factored channels
        (Ibar summed over orders in the atmosphere-plus mode, single scattering in the physical mode)
        carry no phase; the physical mode's 3 last channels hold the higher orders, phase applied.
        With ``settings.parameterization`` '4d': (A, D, H, W, C), a fourth axis of A =
        ``settings.azimuth_size`` view-sun azimuths and the view axis split at the horizon
        (:mod:`clsky.table4d`); ``orders``, ``gathered`` and ``ground_irradiance`` are then those of
        the 3D grid the orders were computed on.
    metadata : dict
        Provenance: clsky version, backend, device, build seconds, and ``units`` of the rendered radiance
        (:func:`clsky.solar.radiance_units`: W m^-2 sr^-1 nm^-1 with the solar spectrum, else relative).
    orders : tuple of numpy.ndarray
        Every order's table (float64 when built, float32 when loaded from a file): order 1 (D, H, W, 6) factored; higher orders (D, H, W, 6)
        factored (atmosphere-plus) or (D, H, W, 3) phased (physical). See :mod:`clsky.orders`.
    orders_record : dict
        How the iteration went: orders computed, converged or not and why, each order's relative
        addition and share.
    gathered : numpy.ndarray (D, H, W, 6) or None
        Sum of the gathered in-scatter tables of the orders (:class:`clsky.orders.OrdersResult`), for
        the per-pixel ray march; None when only single scattering was computed. With
        ``settings.azimuth_harmonics`` = M > 0: (M + 1, D, H, W, 6), its cosine harmonics
        (:mod:`clsky.azimuth`).
    ground_irradiance : numpy.ndarray (D, 3) or None
        With a reflecting ground (``atmosphere.ground_albedo`` > 0): the sky's irradiance on the ground
        per sun node [units of I_I], sum of the orders k >= 1 (:mod:`clsky.ground`), for the ray march;
        None (and required to be None) for a black ground.
    """

    atmosphere: AtmosphereParameters
    settings: TableSettings
    data: np.ndarray
    metadata: dict = dataclasses.field(default_factory=dict)
    orders: tuple = ()
    orders_record: dict = dataclasses.field(default_factory=dict)
    gathered: np.ndarray | None = None
    ground_irradiance: np.ndarray | None = None

    def __post_init__(self):
        try:
            object.__setattr__(self, "orders", tuple(self.orders))
        except TypeError:
            raise TableFormatError(f"orders must be a sequence of arrays, got {type(self.orders).__name__}") from None
        self.validate()

    def validate(self, check_values=True):
        """Check every array against the settings, as :meth:`load` and construction do.

        ``data`` (D, H, W, C) with C = ``settings.channels``, float64 (as built) or ``settings.dtype``;
        ``orders[k - 1]`` (D, H, W, :func:`order_channels`), float32 (as stored) or float64, at most
        :func:`max_orders_kept` of them, as many as ``orders_record["orders"]`` says; ``gathered``
        None or (D, H, W, 6), dtype as ``data``; ``ground_irradiance`` (D, 3) float64 with a reflecting
        ground, None without; with ``check_values``, every value finite and >= 0 (the gathered harmonics m >= 1,
        of either sign, finite).

        Parameters
        ----------
        check_values : bool
            Also scan the values (one pass over every array); shapes and dtypes are always checked.

        Raises
        ------
        TableFormatError
            Naming the array and what is wrong.
        """
        if not isinstance(self.atmosphere, AtmosphereParameters):
            raise TableFormatError(f"atmosphere must be AtmosphereParameters, got {type(self.atmosphere).__name__}")
        if not isinstance(self.settings, TableSettings):
            raise TableFormatError(f"settings must be TableSettings, got {type(self.settings).__name__}")
        for name in ("metadata", "orders_record"):
            if not isinstance(getattr(self, name), dict):
                raise TableFormatError(f"{name} must be a dict, got {type(getattr(self, name)).__name__}")
        width, height, depth = self.settings.size
        grid = (depth, height, width)
        full_precision = sorted({"float64", self.settings.dtype}, reverse=True)
        check_table_array("data", self.data, self.data_shape, full_precision, check_values)
        if self.gathered is not None:
            harmonics = self.settings.azimuth_harmonics
            if harmonics:   # M + 1 cosine harmonics: m >= 1 may be negative (clsky/azimuth.py)
                check_table_array("gathered", self.gathered, (harmonics + 1,) + grid + (6,), full_precision, False)
                if check_values:
                    check_finite_nonnegative("gathered", self.gathered[0])
                    check_finite_signed("gathered", self.gathered[1:])
            else:
                check_table_array("gathered", self.gathered, grid + (6,), full_precision, check_values)
        if self.atmosphere.has_ground:
            if self.ground_irradiance is None:
                raise TableFormatError(f"ground_irradiance is missing: the atmosphere's ground reflects "
                                       f"(ground_albedo {self.atmosphere.ground_albedo:g})")
            check_table_array("ground_irradiance", self.ground_irradiance, (depth, 3), ("float64",), check_values)
        elif self.ground_irradiance is not None:
            raise TableFormatError("ground_irradiance must be None: the atmosphere's ground is black (ground_albedo 0)")
        self._validate_orders(grid, check_values)

    def _validate_orders(self, grid, check_values):
        """The orders' count (against the settings and the record), shapes, dtypes and values."""
        limit = max_orders_kept(self.settings)
        if len(self.orders) > limit:
            raise TableFormatError(f"{len(self.orders)} orders kept, the settings compute at most {limit}")
        for k, order in enumerate(self.orders, start=1):
            check_table_array(f"order_{k}", order, grid + (order_channels(self.settings, k),),
                              ("float32", "float64"), check_values)
        recorded = self.orders_record.get("orders")
        if self.orders and recorded is not None and recorded != len(self.orders):
            raise TableFormatError(f"orders_record counts {recorded!r} orders, the table keeps {len(self.orders)}")

    # Building -------------------------------------------------------------------------------------
    @classmethod
    def build(cls, atmosphere: AtmosphereParameters | str = "atmosphere-plus",
              settings: TableSettings | None = None, backend="opencl", ctx=None, fast_math=False,
              progress: Callable[[str, int, int], None] | None = None) -> "ScatteringTable":
        """Compute the table: single scattering, then the orders ``settings`` asks for.

        Parameters
        ----------
        atmosphere : AtmosphereParameters or preset name
        settings : TableSettings, optional
        backend : {'opencl', 'numpy'}
            OpenCL kernels, or their NumPy twins (:mod:`clsky.reference`).
        ctx : pyopencl.Context, optional
        fast_math : bool
            Build kernels with -cl-fast-relaxed-math (opt-in).
        progress : callable, optional
            ``progress(stage, done, total)`` as the work advances (see :func:`clsky.orders.compute_orders`).

        Raises
        ------
        ValueError
            An argument of the wrong type (naming it), or a backend that is none of ``BACKENDS``.
        InsufficientMemoryError
            Before any work, when the build needs more memory than the host or device has
            (:func:`clsky.resources.check_memory`).

        Examples
        --------
        >>> table = ScatteringTable.build("physical", TableSettings(size=(8, 16, 8), mode="physical"))
        >>> table.data.shape
        (8, 16, 8, 9)
        >>> table.orders_record["converged"]
        True
        """
        if isinstance(atmosphere, str):
            atmosphere = preset(atmosphere)
        check_instance("atmosphere", atmosphere, AtmosphereParameters,
                       f"an AtmosphereParameters or a preset name {list(PRESETS)}")
        if settings is None:
            from .ground import default_settings

            settings = default_settings(atmosphere)
        check_instance("settings", settings, TableSettings, "a TableSettings or None (the atmosphere's default)")
        if progress is not None and not callable(progress):
            raise ValueError(f"progress must be None or a callable progress(stage, done, total), got "
                             f"{short(progress)} ({type(progress).__name__})")
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
        if settings.is_4d:
            from .table4d import check_atmosphere

            check_atmosphere(atmosphere, settings)
        from .orders import compute_orders
        from .resources import check_table_memory

        check_table_memory(settings, backend, ctx)
        start = time.perf_counter()
        result = compute_orders(atmosphere, settings, backend=backend, ctx=ctx, fast_math=fast_math,
                                progress=progress)
        if settings.is_4d:     # the same orders, then the view-ray integrals at the 4D nodes
            from .table4d import compute_data

            data = compute_data(atmosphere, settings, result.gathered, backend, ctx, fast_math,
                                result.ground_irradiance)
        else:
            data = to_layout(result.combined(settings.mode), settings.mie_layout)
        seconds = time.perf_counter() - start
        metadata = {"clsky_version": __version__, "backend": backend, "device": result.record.pop("device"),
                    "build_seconds": seconds, "fast_math": bool(fast_math), "units": radiance_units(atmosphere)}
        try:
            return cls(atmosphere, settings, data, metadata, tuple(result.orders), result.record, result.gathered, result.ground_irradiance)
        except TableFormatError as error:
            cause = " (or fast_math removed a guard)" if fast_math else ""
            raise TableFormatError(f"the computed table is unusable: {error}; the atmosphere or settings are "
                                   f"beyond what the numerics support{cause}") from error

    # Using ----------------------------------------------------------------------------------------
    @property
    def data_shape(self) -> tuple:
        """The shape ``data`` must have: (D, H, W, C), or (A, D, H, W, C) for the 4D parameterization."""
        width, height, depth = self.settings.size
        if self.settings.is_4d:
            from .table4d import data_shape

            return data_shape(self.settings)
        return (depth, height, width, self.settings.channels)

    @property
    def parameters_hash(self) -> str:
        return parameters_hash(self.atmosphere, self.settings)

    @property
    def channel_names(self):
        return CHANNEL_NAMES[self.settings.channels]

    def radiance(self, altitude, cos_view, cos_sun, cos_scatter, backend="opencl", engine=None):
        """Radiance r, g, b for arbitrary geometry (see :meth:`clsky.lookup.TableLookupEngine.radiance`).

        Parameters
        ----------
        altitude : array_like
            Observer altitude [m], >= 0.
        cos_view, cos_sun, cos_scatter : array_like
            Cosines of the view zenith, sun zenith and scattering angle.
        backend : {'opencl', 'numpy'}
        engine : TableLookupEngine, optional
            Reused across calls to avoid rebuilding (OpenCL backend); a
            :class:`~clsky.lookup4d.TableLookup4DEngine` for a 4D table, whose lookup is quadrilinear
            in (altitude, view, sun, azimuth) (:mod:`clsky.table4d`).
        """
        self.validate(check_values=False)    # the kernel indexes data by the settings' size
        check_queries(altitude, cos_view, cos_sun, cos_scatter)
        if self.settings.is_4d:
            return self._radiance4d(altitude, cos_view, cos_sun, cos_scatter, backend, engine)
        if backend == "numpy":
            from . import reference

            return reference.lookup(self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter,
                                    self.settings.mapping, self.settings.sun_cos_range)
        if backend != "opencl":
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
        from .lookup import TableLookupEngine

        check_instance("engine", engine, TableLookupEngine, "None or a TableLookupEngine (a 3D table's)", optional=True)
        engine = engine or TableLookupEngine(dtype=self.settings.dtype)
        return engine.radiance(self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter,
                               self.settings.mapping, self.settings.sun_cos_range)

    def _radiance4d(self, altitude, cos_view, cos_sun, cos_scatter, backend, engine):
        """:meth:`radiance` of a 4D table (:class:`clsky.lookup4d.TableLookup4DEngine` or its twin)."""
        arguments = (self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter, self.settings.mapping,
                     self.settings.sun_cos_range)
        if backend == "numpy":
            from . import reference

            return reference.lookup4d(*arguments)
        if backend != "opencl":
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
        from .lookup4d import TableLookup4DEngine

        check_instance("engine", engine, TableLookup4DEngine, "None or a TableLookup4DEngine (a 4D table's)",
                       optional=True)
        engine = engine or TableLookup4DEngine(dtype=self.settings.dtype)
        return engine.radiance(*arguments)

    # Files ----------------------------------------------------------------------------------------
    def save(self, path, overwrite=False, staging=None):
        """Write the table to ``path`` (.npz, format in the module docstring) atomically; never
        overwrites unless ``overwrite``.

        The path is checked (:func:`clsky._files.check_output`) before anything is written. With
        ``staging`` (a :class:`clsky._files.StagedWrites`) the file lands when that set commits.

        Raises
        ------
        ValueError
            ``path`` does not end in .npz, or a name too long for the file system.
        TableFormatError
            The table's arrays no longer pass :meth:`validate` (edited in place since construction),
            or an order exceeds the float32 range it is stored in: no file is written.
        FileExistsError
            ``path`` exists and not ``overwrite``.
        IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError
            ``path`` is a directory, or its directory is missing or not writable.
        """
        path = check_suffix(path, ".npz")
        members = self._file_members()
        with atomic_write(path, overwrite, staging=staging) as temporary:
            with open(temporary, "wb") as stream:
                np.savez(stream, **members)
        return path

    def _file_members(self) -> dict:
        """The archive's members (module docstring), ``checksums`` last."""
        self.validate()
        orders = {f"order_{k}": np.asarray(order, dtype=np.float32) for k, order in enumerate(self.orders, start=1)}
        for name, order in orders.items():
            check_finite_nonnegative(f"{name} (as float32)", order)
        members = {"data": self.data, "format_version": np.array(FORMAT_VERSION, dtype=np.int64),
                   "atmosphere": _json_text(self.atmosphere.to_dict()),
                   "settings": _json_text(self.settings.to_dict()), "metadata": _json_text(self.metadata),
                   "orders_record": _json_text(self.orders_record),
                   "parameters_hash": np.array(self.parameters_hash), **orders}
        if self.gathered is not None:
            members["gathered"] = self.gathered
        if self.ground_irradiance is not None:
            members["ground_irradiance"] = self.ground_irradiance
        members["checksums"] = _json_text({name: array_checksum(value) for name, value in members.items()})
        return members

    @classmethod
    def load(cls, path) -> "ScatteringTable":
        """Read a table written by :meth:`save` and check everything the module docstring lists.

        Raises
        ------
        FileNotFoundError
            ``path`` does not exist.
        TableFormatError
            The file is not a clsky table of this version that passes every check (unreadable or
            truncated archive, wrong version, missing or extra member, checksum, hash, shape, dtype,
            NaN, infinite or negative values); the message names the file and what is wrong.
        """
        path = as_path(path)
        contents = _read_members(path)
        try:
            return cls._from_members(contents)
        except TableFormatError as error:
            raise TableFormatError(f"{path}: {error}") from error

    @classmethod
    def _from_members(cls, contents) -> "ScatteringTable":
        """The table an archive's members describe (:meth:`load`, messages without the file name)."""
        version = _format_version(contents)
        if version != FORMAT_VERSION:
            raise TableFormatError(f"table format version {version}; this clsky reads version {FORMAT_VERSION} "
                                   f"(rebuild the table with `clsky table`)")
        order_count = _check_membership(contents)
        _verify_checksums(contents)
        try:
            atmosphere = AtmosphereParameters.from_dict(_json_member(contents, "atmosphere"))
            settings = TableSettings.from_dict(_json_member(contents, "settings"))
        except (ValueError, TypeError, KeyError, AttributeError) as error:
            if isinstance(error, TableFormatError):
                raise
            raise TableFormatError(f"invalid parameters: {_shorten(str(error))}") from error
        stored_hash = contents["parameters_hash"]
        if not _is_text(stored_hash) or parameters_hash(atmosphere, settings) != stored_hash.item():
            raise TableFormatError("parameters hash does not match its parameters (corrupted or edited file)")
        orders = tuple(contents[f"order_{k}"] for k in range(1, order_count + 1))
        return cls(atmosphere, settings, contents["data"], _json_member(contents, "metadata"), orders,
                   _json_member(contents, "orders_record"), contents.get("gathered"), contents.get("ground_irradiance"))

    def export_texture(self, path, overwrite=False, staging=None):
        """A 4D table for engines: ``<path>.bin`` (three RGBA float32 3D textures, sun and azimuth packed
        in the depth) and ``<path>.json``, read by ``docs/lookup4d.glsl`` (:mod:`clsky.export4d`).
        Returns the two paths; ValueError for a 3D table."""
        from .export4d import export_texture

        return export_texture(self, path, overwrite, staging)

    def export_raw(self, path, overwrite=False, staging=None):
        """Write ``<path>.bin`` (float32 values) and ``<path>.json`` (layout header) for GPU engines
        (:func:`clsky._files.binary_and_header`: ``sky``, ``sky.bin`` and ``sky.json`` name the same pair).

        A table whose higher orders carry azimuth harmonics (``settings.azimuth_harmonics`` = M > 0,
        :mod:`clsky.azimuth`) also exports them: its ``multiple_*`` channels hold their azimuth average
        (harmonic 0), and the gathered harmonics G_m (M + 1, D, H, W, 6), the source the ray march
        integrates, follow the table's values in the same ``.bin``; the header's ``azimuth_harmonics``
        entry gives their offset, layout and formula. Without harmonics the export is as before.

        Returns the two paths. Both paths are checked before either is written (as in :meth:`save`),
        and they land together (renamed one after the other once both are written; with
        ``staging``, when that set commits); existing files are kept unless ``overwrite``.
        """
        self.validate()
        binary, header = binary_and_header(path)
        for target in (binary, header):
            check_output(target, force=overwrite)
        width, height, depth = self.settings.size
        channels = self.settings.channels
        description = {
            "format": "clsky raw scattering table",
            "format_version": FORMAT_VERSION,
            "dtype": "float32",
            "byte_order": "little",
            "binary": binary.name,
            "size": {"W": width, "H": height, "D": depth, "channels": channels},
            "layout": ("values[(x + y*W + z*W*H) * channels + c]; x: altitude node, y: view-zenith node, "
                       "z: sun-zenith node, c: channel"),
            "channels": list(self.channel_names),
            "mapping": self.settings.mapping,
            "mapping_formulas": {
                "nonlinear": {"u": "sqrt(h/Ha)", "v": "0.5*(1+sign(cos_view)*|cos_view|^(1/3))",
                              "w": "0.5*(1+sign(cos_sun)*|cos_sun|^(1/3))"},
                "linear": {"u": "h/Ha", "v": "0.5*(cos_view+1)", "w": "0.5*(cos_sun+1)"},
                "nodes": "u = x/(W-1), v = y/(H-1), w = w_low + (w_high - w_low) * z/(D-1)",
            },
            "sun_cos_range": list(self.settings.sun_cos_range),
            "sun_w_range": {"w_low": self.settings.sun_w_range[0], "w_high": self.settings.sun_w_range[1]},
            "radiance": ("I = I_I * (F_R(cos theta) * Ibar_R + F_M(cos theta) * Ibar_M [+ multiple]), "
                         "all channels interpolated trilinearly in (u, v, w); the multiple_* channels "
                         "(physical mode) already include their phase"),
            "orders_record": self.orders_record,
            "incident_light": list(self.atmosphere.incident_light),
            "units": radiance_units(self.atmosphere),
            "atmosphere": self.atmosphere.to_dict(),
            "settings": self.settings.to_dict(),
            "parameters_hash": self.parameters_hash,
            "metadata": self.metadata,
        }
        if self.settings.is_4d:     # clsky/table4d.py, clsky/mapping.py
            description["size"]["A"] = self.settings.azimuth_size
            description["layout"] = ("values[(x + y*W + z*W*H + a*W*H*D) * channels + c]; x: altitude node, y: view "
                                     "node (0..H/2-1 rays that hit the ground, H/2..H-1 rays that reach space), z: "
                                     "sun-zenith node, a: azimuth node, c: channel")
            description["mapping_formulas"]["view_4d"] = (
                "rho = sqrt(h(2Rp+h)), K = sqrt(Ha(2Rp+Ha)); ground (mu < -rho/(Rp+h)): y = (H/2-1)(d_ground-h)/(rho-h); "
                "space: y = H/2 + (H/2-1)(1 - (d_top-(Ha-h))/(rho+K-(Ha-h)))")
            description["mapping_formulas"]["azimuth_4d"] = "a = (A-1) phi / pi, phi in [0, pi] the view-sun azimuth"
            description["radiance"] = ("I = I_I * (F_R(nu) * Ibar_R + F_M(nu) * Ibar_M + multiple), channels "
                                       "interpolated quadrilinearly, never across the horizon (y = H/2-1 to H/2)")
        harmonics = self.settings.azimuth_harmonics if self.gathered is not None else 0
        if harmonics:
            description["azimuth_harmonics"] = {
                "M": harmonics,
                "offset_values": int(self.data.size),
                "shape": {"harmonics": harmonics + 1, "D": depth, "H": height, "W": width, "channels": 6},
                "layout": ("values[offset_values + (((m*D + z)*H + y)*W + x) * 6 + c]; m: harmonic 0..M, "
                           "x, y, z: the table's nodes, c: Rayleigh r, g, b, Mie r, g, b"),
                "quantity": ("G_m: cosine harmonics of the gathered in-scatter source of the orders k >= 2 "
                             "(phase applied, in units of I_I), summed over the orders"),
                "radiance": ("along a view ray: I_I * sum_s beta_s / (4 pi) * Integral rho_s T "
                             "max(0, sum_m G_m,s cos(m phi)) ds, phi the local view-sun azimuth "
                             "(clsky/azimuth.py); the multiple_* channels above are the azimuth "
                             "average of the orders k >= 2 (harmonic 0 of their radiance)"),
            }
        with contextlib.ExitStack() as stack:
            if staging is None:
                staging = stack.enter_context(StagedWrites())
            with atomic_write(binary, overwrite, staging=staging) as temporary:
                if harmonics:
                    with open(temporary, "wb") as stream:
                        self.data.astype("<f4").tofile(stream)
                        self.gathered.astype("<f4").tofile(stream)
                else:
                    self.data.astype("<f4").tofile(temporary)
            with atomic_write(header, overwrite, staging=staging) as temporary:
                temporary.write_text(json.dumps(description, indent=2) + "\n")
        return binary, header


# File members -------------------------------------------------------------------------------------
#: Members every table file holds (besides order_1 ... order_K and the optional gathered).
REQUIRED_MEMBERS = ("format_version", "data", "atmosphere", "settings", "metadata", "orders_record",
                    "parameters_hash", "checksums")
#: Members a table file may hold besides those and the orders.
OPTIONAL_MEMBERS = ("gathered", "ground_irradiance")
#: What reading a damaged archive raises, in numpy and zipfile (a member's header, payload or CRC;
#: numpy tokenizes an npy header, so a flipped bracket there raises TokenError).
_READ_ERRORS = (OSError, EOFError, ValueError, KeyError, TypeError, UnicodeError, OverflowError, MemoryError,
                NotImplementedError, SyntaxError, RecursionError, tokenize.TokenError, zipfile.BadZipFile,
                zlib.error)


def _json_text(value) -> np.ndarray:
    """``value`` as a JSON string member (0-d unicode array)."""
    return np.array(json.dumps(value))


def _is_text(member) -> bool:
    return isinstance(member, np.ndarray) and member.shape == () and member.dtype.kind == "U"


def _shorten(text, limit=200) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _describe_error(error) -> str:
    return _shorten(f"{type(error).__name__}: {error}")


def _describe_member(member) -> str:
    """A short description of a member's value for a message: the scalar itself, else its kind."""
    if isinstance(member, np.ndarray) and member.shape == ():
        return short(member.item())
    if isinstance(member, np.ndarray):
        return f"a {member.dtype} array of shape {member.shape}"
    return f"a {type(member).__name__}"


def _read_members(path) -> dict:
    """Every member of the .npz archive at ``path``, read whole; TableFormatError (naming ``path``)
    if it is not a readable one, FileNotFoundError if it does not exist."""
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    if not path.is_file():
        raise TableFormatError(f"{path} is not a clsky table file (not a regular file)")
    what = _not_an_archive(path)
    if what:
        raise TableFormatError(f"{path} is not a clsky table file ({what})")
    try:
        archive = np.load(path, allow_pickle=False)
    except _READ_ERRORS as error:
        raise TableFormatError(f"{path} is not a clsky table file (not a readable .npz archive: "
                               f"{_describe_error(error)})") from error
    try:
        with archive:
            return {name: archive[name] for name in archive.files}
    except _READ_ERRORS as error:
        raise TableFormatError(f"{path} is damaged (reading its members: {_describe_error(error)})") from error


#: The first bytes of a zip archive (an .npz): a member's local header, or the end record of an empty one.
_ZIP_MAGICS = (b"PK\x03\x04", b"PK\x05\x06")
#: The first bytes of a single NumPy array (.npy).
_NPY_MAGIC = b"\x93NUMPY"


def _not_an_archive(path) -> str | None:
    """What the file at ``path`` is, judged by its first bytes, when it is not a zip archive; None when it
    may be one. Without it, numpy took any other file for a pickle and told the user that it "contains
    pickled (object) data" they could "load unsafely" (a text file, random bytes)."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(len(_NPY_MAGIC))
    except OSError as error:
        return f"not readable: {_describe_error(error)}"
    if not head:
        return "an empty file"
    if head.startswith(_ZIP_MAGICS):
        return None
    if head == _NPY_MAGIC:
        return "a single .npy array, not an .npz archive"
    return "not an .npz archive: its first bytes are not a zip archive's"


def _format_version(contents) -> int:
    """The archive's format version: an integer scalar."""
    if "format_version" not in contents:
        raise TableFormatError("not a clsky table file (no format_version member)")
    member = contents["format_version"]
    if not (isinstance(member, np.ndarray) and member.shape == () and member.dtype.kind in "iu"):
        raise TableFormatError(f"format_version must be an integer, got {_describe_member(member)}")
    return int(member)


def _check_membership(contents) -> int:
    """Check that the archive holds the required members, order_1 ... order_K, optionally gathered
    and ground_irradiance, and nothing else; returns K."""
    missing = [name for name in REQUIRED_MEMBERS if name not in contents]
    if missing:
        raise TableFormatError(f"not a clsky table file (missing {missing})")
    orders = sorted(int(match.group(1)) for match in map(re.compile(r"order_([1-9][0-9]{0,3})").fullmatch, contents)
                    if match)
    unexpected = sorted(set(contents) - set(REQUIRED_MEMBERS) - set(OPTIONAL_MEMBERS) - {f"order_{k}" for k in orders})
    if unexpected:
        raise TableFormatError(f"unexpected members {unexpected}")
    if orders != list(range(1, len(orders) + 1)):
        raise TableFormatError(f"orders must be order_1 to order_{len(orders)}, got "
                               f"{', '.join(f'order_{k}' for k in orders)}")
    return len(orders)


def _verify_checksums(contents):
    """Check every member against the ``checksums`` member (module docstring)."""
    checksums = _json_member(contents, "checksums")
    listed, present = set(checksums), set(contents) - {"checksums"}
    if listed != present:
        raise TableFormatError(f"checksums list {sorted(listed)}, the file holds {sorted(present)}")
    failed = [name for name in sorted(present) if checksums[name] != array_checksum(contents[name])]
    if failed:
        raise TableFormatError(f"{', '.join(failed)} do{'es' if len(failed) == 1 else ''} not match "
                               f"the stored checksum (corrupted or edited file)")


def _json_member(contents, name) -> dict:
    """The JSON object a string member holds."""
    member = contents[name]
    if not _is_text(member):
        raise TableFormatError(f"{name} must be a JSON string, got {_describe_member(member)}")
    try:
        value = json.loads(member.item())
    except (ValueError, RecursionError) as error:
        raise TableFormatError(f"{name} is not valid JSON ({error})") from error
    if not isinstance(value, dict):
        raise TableFormatError(f"{name} must be a JSON object, got {type(value).__name__}")
    return value
