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
    orders (D, H, W, 6) factored (atmosphere-plus) or (D, H, W, 3) phased (physical); finite, >= 0. Or
    none: a table whose orders were dropped (an animation's, ``dataclasses.replace(table, orders=())``,
    which its frame farm sends to the workers as a file); ``orders_record`` still counts those computed.
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
values (:meth:`ScatteringTable.validate`: finite, >= 0 but for the harmonics m >= 1, at most
:data:`clsky.lookup.MAX_TABLE_VALUE` in size) do not fit its settings. Against a forged file, whose checksums the
forger recomputes: before any member is read, the archive's directory must list no foreign member, no
compressed member (:func:`_check_stored`: a 1.7 MB file of deflated zeros took 1.8 GB of memory under
settings that declared a large grid) and no member that inflates beyond twice its settings' float64 values
(:func:`_array_limits`), and before the orders are read their count must be one the settings compute;
``gathered`` must be present exactly when ``orders_record`` counts higher orders (without it the ray march
drops them); the metadata clsky reads back (version, backend, device, units, build seconds, fast_math)
must be what a build writes.

Raw export (:meth:`ScatteringTable.export_raw`): ``<name>.bin`` holds little-endian float32 values,
cell after cell in the order i = x + y W + z W H (x: altitude, y: view zenith, z: sun zenith), C
channels per cell; ``<name>.json`` documents that layout, the mappings, the atmosphere and settings.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import hashlib
import json
import math
import re
import time
import tokenize
import zipfile
import zlib
from typing import Callable

import numpy as np

from . import __version__
from ._files import (StagedWrites, as_path, atomic_write, binary_and_header, check_output, check_suffix,
                     open_regular_file)
from .atmosphere import AtmosphereParameters, as_atmosphere
from .errors import check_flag, check_instance, is_integer, is_real_number, short
from .lookup import check_queries, check_table_values
from .phase import phase_description
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
    """TableFormatError unless every value of ``array`` is finite and >= 0 (radiances [1/sr]), at most
    :data:`clsky.lookup.MAX_TABLE_VALUE` (:func:`clsky.lookup.check_table_values`)."""
    check_table_values(name, array, nonnegative=True, error=TableFormatError)


def check_finite_signed(name, array):
    """TableFormatError unless every value of ``array`` is finite, of either sign (the azimuth harmonics
    m >= 1 of a gathered table), at most :data:`clsky.lookup.MAX_TABLE_VALUE` in size."""
    check_table_values(name, array, nonnegative=False, error=TableFormatError)


#: The axes of a table's arrays by their count, for the messages: 4D data, grids, the ground's irradiance.
_AXES = {5: "(A, D, H, W, C)", 4: "(D, H, W, C)", 2: "(D, C)"}


def check_table_array(name, array, shape, dtypes, check_values=True, axes=None):
    """Check one of a table's arrays: a NumPy array of ``shape`` (whose axes ``axes`` names, default by their
    count), a dtype in ``dtypes``, and (when ``check_values``) finite non-negative values; TableFormatError
    names ``name`` and what is wrong."""
    if not isinstance(array, np.ndarray):
        raise TableFormatError(f"{name} must be a NumPy array, got {type(array).__name__}")
    if array.shape != tuple(shape):
        raise TableFormatError(f"{name} has shape {array.shape}, the settings need {tuple(shape)} "
                               f"{axes or _AXES.get(len(shape), '')}".rstrip())
    if array.dtype not in [np.dtype(d) for d in dtypes]:
        raise TableFormatError(f"{name} has dtype {array.dtype}, expected {' or '.join(map(str, dtypes))}")
    if check_values:
        check_finite_nonnegative(name, array)


def data_shape(settings: TableSettings) -> tuple:
    """The shape a table's ``data`` has: (D, H, W, C), or (A, D, H, W, C) for the 4D parameterization."""
    width, height, depth = settings.size
    if settings.is_4d:
        from . import table4d

        return table4d.data_shape(settings)
    return (depth, height, width, settings.channels)


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


def _read_only(array: np.ndarray) -> np.ndarray:
    """A view of ``array`` that cannot be written through (``array`` itself keeps its flags)."""
    view = array.view()
    view.flags.writeable = False
    return view


@dataclasses.dataclass(frozen=True, eq=False)
class ScatteringTable:
    """A precomputed scattering table with everything that defines it. Its arrays are checked when it is
    made (:meth:`validate`) and held as read-only views: a table is not edited in place (make another,
    ``dataclasses.replace``, which checks again).

    Attributes
    ----------
    atmosphere : AtmosphereParameters
    settings : TableSettings
    data : numpy.ndarray, shape (D, H, W, C)
        Per cell [1/sr], without I_I: channels :data:`CHANNEL_NAMES` [C]. The factored channels
        (Ibar summed over orders in the atmosphere-plus mode, single scattering in the physical mode)
        carry no phase; the physical mode's 3 last channels hold the higher orders, phase applied. With
        ``orders='auto'``, the sums over orders include the geometric tail of those not computed:
        r / (1 - r) times the last order, r = ``orders_record['tail_ratio']`` (:mod:`clsky.orders`).
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
        self._hold_read_only()

    def _hold_read_only(self):
        """Hold the arrays as read-only views once checked: data edited in place after the checks
        (table.data[...] = -5) reached the lookups and renderers as negative or NaN radiance; the caller's own
        arrays keep their flags."""
        for name in ("data", "gathered", "ground_irradiance"):
            if isinstance(getattr(self, name), np.ndarray):
                object.__setattr__(self, name, _read_only(getattr(self, name)))
        object.__setattr__(self, "orders", tuple(_read_only(order) if isinstance(order, np.ndarray) else order
                                                 for order in self.orders))

    def __setstate__(self, state):
        """Unpickled and deep-copied tables (which skip ``__post_init__``) hold read-only arrays too."""
        self.__dict__.update(state)
        self._hold_read_only()

    def validate(self, check_values=True):
        """Check every array against the settings, as :meth:`load` and construction do.

        ``data`` (D, H, W, C) with C = ``settings.channels``, float64 (as built) or ``settings.dtype``;
        ``orders[k - 1]`` (D, H, W, :func:`order_channels`), float32 (as stored) or float64, at most
        :func:`max_orders_kept` of them, as many as ``orders_record["orders"]`` says (or none: dropped); ``gathered``
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
                check_table_array("gathered", self.gathered, (harmonics + 1,) + grid + (6,), full_precision, False,
                                  axes="(M + 1, D, H, W, C)")
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
        if recorded is None:            # a table made by hand, without a record
            return
        if not is_integer(recorded) or not 1 <= recorded <= limit:
            raise TableFormatError(f"orders_record's orders must be an integer in [1, {limit}] (the orders computed), "
                                   f"got {short(recorded)}")
        if self.orders and recorded != len(self.orders):
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
            Default: the 'atmosphere-plus' preset.
        settings : TableSettings, optional
            Default: :func:`clsky.ground.default_settings` of ``atmosphere``, TableSettings' defaults with
            mode 'physical' for a reflecting ground (which the atmosphere-plus mode refuses).
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
        atmosphere = as_atmosphere(atmosphere)
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
        return data_shape(self.settings)

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
            Observer altitude [m], in [0, 1e10] (:data:`clsky.lookup.MAX_QUERY_ALTITUDE`; above the
            atmosphere, seen from space).
        cos_view, cos_sun, cos_scatter : array_like
            Cosines of the view zenith, sun zenith and scattering angle, each in [-1, 1]. They are not
            checked against each other: a cos_scatter that the two zenith angles do not allow (outside
            cos_view cos_sun -+ sin_view sin_sun) gets the phase functions at that angle and the table
            at those zeniths, a finite value of no geometry.
        backend : {'opencl', 'numpy'}
        engine : TableLookupEngine, optional
            Reused across calls to avoid rebuilding (OpenCL backend); a
            :class:`~clsky.lookup4d.TableLookup4DEngine` for a 4D table, whose lookup is quadrilinear
            in (altitude, view, sun, azimuth) (:mod:`clsky.table4d`).

        Returns
        -------
        numpy.ndarray
            float64 radiance of shape (..., 3) (the arguments broadcast together; (3,) for scalars) at the
            table's three wavelengths, the incident light and phase functions applied, in the table's
            units (``metadata["units"]``: relative to I_I per sr, or W m^-2 sr^-1 nm^-1 for an atmosphere
            lit by the solar spectrum).
        """
        # the kernel indexes data by the settings' size; its values were checked when the table was made (built,
        # loaded or constructed): the lookups do not scan them again (table_checked)
        self.validate(check_values=False)
        check_queries(altitude, cos_view, cos_sun, cos_scatter)
        if self.settings.is_4d:
            return self._radiance4d(altitude, cos_view, cos_sun, cos_scatter, backend, engine)
        if backend == "numpy":
            from . import reference

            return reference.lookup(self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter,
                                    self.settings.mapping, self.settings.sun_cos_range, table_checked=True)
        if backend != "opencl":
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
        from .lookup import TableLookupEngine

        check_instance("engine", engine, TableLookupEngine, "None or a TableLookupEngine (a 3D table's)", optional=True)
        engine = engine or TableLookupEngine(dtype=self.settings.dtype)
        return engine.radiance(self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter,
                               self.settings.mapping, self.settings.sun_cos_range, table_checked=True)

    def _radiance4d(self, altitude, cos_view, cos_sun, cos_scatter, backend, engine):
        """:meth:`radiance` of a 4D table (:class:`clsky.lookup4d.TableLookup4DEngine` or its twin)."""
        arguments = (self.atmosphere, self.data, altitude, cos_view, cos_sun, cos_scatter, self.settings.mapping,
                     self.settings.sun_cos_range)
        if backend == "numpy":
            from . import reference

            return reference.lookup4d(*arguments, table_checked=True)
        if backend != "opencl":
            raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
        from .lookup4d import TableLookup4DEngine

        check_instance("engine", engine, TableLookup4DEngine, "None or a TableLookup4DEngine (a 4D table's)",
                       optional=True)
        engine = engine or TableLookup4DEngine(dtype=self.settings.dtype)
        return engine.radiance(*arguments, table_checked=True)

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
        check_flag("overwrite", overwrite)
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
            truncated archive, wrong version, missing or extra member, a member larger than its settings
            allow, checksum, hash, shape, dtype, NaN, infinite, negative or too large values, a gathered
            source that does not go with the recorded orders, metadata clsky cannot read back); the
            message names the file and what is wrong.
        ValueError
            ``path`` is no file path (None, a number, bytes, an empty string, a NUL character).
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
        metadata = _json_member(contents, "metadata")
        _check_metadata(metadata)
        record = _json_member(contents, "orders_record")
        if "orders" not in record:
            raise TableFormatError("orders_record lacks orders, the count of orders computed")
        _check_orders_record(record)
        if is_integer(record["orders"]) and ("gathered" in contents) != (record["orders"] != 1):   # else validate's
            # the ray march adds the gathered source of the orders k >= 2: without it a file of higher orders
            # renders without them (24 % darker), with it a single-scattering file adds light it lacks (a
            # table made in memory may drop it: the pilot's single-scattering march does)
            raise TableFormatError(f"gathered must be present exactly when the table has higher orders: orders_record "
                                   f"counts {short(record['orders'])} orders, gathered is "
                                   f"{'present' if 'gathered' in contents else 'missing'}")
        orders = tuple(contents[f"order_{k}"] for k in range(1, order_count + 1))
        return cls(atmosphere, settings, contents["data"], metadata, orders, record, contents.get("gathered"),
                   contents.get("ground_irradiance"))

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
        check_flag("overwrite", overwrite)
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
            "phase_functions": phase_description(self.atmosphere),
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
            description["mapping_formulas"]["nodes"] = (
                "u = x/(W-1), y: view_4d (not v), w = w_low + (w_high - w_low) * z/(D-1), a: azimuth_4d"
                + ("; the view mappings v above and v = y/(H-1) are those of the 3D grid of azimuth_harmonics only"
                   if self.settings.azimuth_harmonics and self.gathered is not None else ""))
            description["radiance"] = ("I = I_I * (F_R(c) * Ibar_R + F_M(c) * Ibar_M + multiple), c = cos theta "
                                       "(phase_functions), channels interpolated quadrilinearly, never across the "
                                       "horizon (y = H/2-1 to H/2)")
        harmonics = self.settings.azimuth_harmonics if self.gathered is not None else 0
        if harmonics:
            # a 4D table's higher orders come from the orders of the 3D table of its W x H x D (clsky/table4d.py)
            nodes, multiple = (
                ("x, y, z: the nodes of the 3D grid of the same W x H x D (mapping_formulas[mapping]: the 3D view "
                 "mapping, not view_4d)",
                 "the multiple_* channels above are these harmonics' light integrated along each 4D node's own ray "
                 "(at its azimuth), not an azimuth average") if self.settings.is_4d else
                ("x, y, z: the table's nodes",
                 "the multiple_* channels above are the azimuth average of the orders k >= 2 (harmonic 0 of their "
                 "radiance)"))
            description["azimuth_harmonics"] = {
                "M": harmonics,
                "offset_values": int(self.data.size),
                "shape": {"harmonics": harmonics + 1, "D": depth, "H": height, "W": width, "channels": 6},
                "layout": ("values[offset_values + (((m*D + z)*H + y)*W + x) * 6 + c]; m: harmonic 0..M, "
                           f"{nodes}, c: Rayleigh r, g, b, Mie r, g, b"),
                "quantity": ("G_m: cosine harmonics of the gathered in-scatter source of the orders k >= 2 "
                             "(phase applied, in units of I_I), summed over the orders"),
                "radiance": ("along a view ray: I_I * sum_s beta_s / (4 pi) * Integral rho_s T "
                             "max(0, sum_m G_m,s cos(m phi)) ds, phi the local view-sun azimuth "
                             f"(clsky/azimuth.py); {multiple}"),
            }
        try:                        # strict JSON, before any file: a NaN in the metadata was written as NaN
            text = json.dumps(description, indent=2, allow_nan=False) + "\n"
        except ValueError:
            raise ValueError("the raw export's header would hold NaN or infinite values (the table's metadata "
                             "or orders record): its JSON is strict") from None
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
                temporary.write_text(text)
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
        return short(member.item()) + ("" if member.dtype.kind == "U" else f" ({member.dtype})")
    if isinstance(member, np.ndarray):
        return f"a {member.dtype} array of shape {member.shape}"
    return f"a {type(member).__name__}"


def _read_members(path) -> dict:
    """Every member of the .npz archive at ``path``, read whole; TableFormatError (naming ``path``)
    if it is not a readable one, FileNotFoundError if it does not exist."""
    try:
        stream = open_regular_file(path)    # once: a FIFO swapped in after a check of the name blocked its open
    except (FileNotFoundError, NotADirectoryError):          # a path through a file: none there either
        raise FileNotFoundError(f"{path} does not exist") from None
    except OSError as error:
        what = ("not a regular file" if isinstance(error, IsADirectoryError) or error.errno == errno.EINVAL
                else f"not readable: {_describe_error(error)}")
        raise TableFormatError(f"{path} is not a clsky table file ({what})") from None
    with stream:
        return _read_archive(stream, path)


def _read_archive(stream, path) -> dict:
    """:func:`_read_members` of the file open as ``stream``."""
    what = _not_an_archive(stream)
    if what:
        raise TableFormatError(f"{path} is not a clsky table file ({what})")
    try:
        stream.seek(0)
        archive = np.load(stream, allow_pickle=False)
    except _READ_ERRORS as error:
        raise TableFormatError(f"{path} is not a clsky table file (not a readable .npz archive: "
                               f"{_describe_error(error)})") from error
    try:
        with archive:
            _check_names(archive.files, path)
            _check_stored(archive, path)
            sizes = _member_sizes(archive)
            small = [name for name in archive.files if name not in _ARRAY_MEMBERS and not name.startswith("order_")]
            for name in small:
                _check_size(path, name, sizes[name], _MAX_TEXT_BYTES)
            contents = {name: archive[name] for name in small}
            settings = _file_settings(contents)
            limits = _array_limits(settings)
            _check_order_count(archive.files, settings, path)
            for name in sorted(set(archive.files) - set(small)):
                _check_size(path, name, sizes[name], limits.get(name.split("_")[0], limits["data"]))
                contents[name] = archive[name]
            return contents
    except TableFormatError:
        raise
    except _READ_ERRORS as error:
        raise TableFormatError(f"{path} is damaged (reading its members: {_describe_error(error)})") from error


#: The array members (besides order_1 ... order_K); every other member is a scalar or a JSON text.
_ARRAY_MEMBERS = ("data", "gathered", "ground_irradiance")
#: The largest scalar or JSON member read [bytes] (the settings, the atmosphere, the metadata, the orders'
#: record and the checksums take a few kB).
_MAX_TEXT_BYTES = 16 * 2**20
#: What an array member may add to its values' bytes: its .npy header.
_NPY_HEADER_BYTES = 4096


def _member_sizes(archive) -> dict:
    """Each member's size once inflated [bytes], from the zip archive's directory: known before reading it."""
    sizes = {}
    for info in archive.zip.infolist():
        name = info.filename[:-len(".npy")] if info.filename.endswith(".npy") else info.filename
        sizes[name] = max(sizes.get(name, 0), info.file_size)
    return sizes


def _check_size(path, name, size, limit):
    """TableFormatError unless member ``name`` inflates to at most ``limit`` bytes: a 2 MB file of
    deflated zeros took 2 GB of memory and 12 s before its member was refused (a larger one would
    exhaust the memory), where the directory tells its size first."""
    if size > limit:
        raise TableFormatError(f"{path}: member {name} inflates to {size} bytes, more than the {limit} its table's "
                               f"settings allow (damaged or forged file)")


def _check_stored(archive, path):
    """TableFormatError naming ``path`` for a compressed member, from the archive's directory before any
    member is read: clsky writes its tables' members stored (``np.savez``), so that what a file takes in
    memory is what it takes on disk. A forged file's settings may declare any grid up to their limits, and
    so allow a member of gigabytes, which a few MB of deflated zeros held (1.7 MB of them took 1.8 GB of
    memory before the checks after them, 2026-12-07)."""
    import zipfile

    for info in archive.zip.infolist():
        if info.compress_type != zipfile.ZIP_STORED:
            name = info.filename[:-len(".npy")] if info.filename.endswith(".npy") else info.filename
            raise TableFormatError(f"{path}: member {name} is compressed (zip method {info.compress_type}); clsky's "
                                   f"table files store their members uncompressed, as ScatteringTable.save writes "
                                   f"them (damaged or forged file)")


def _file_settings(contents) -> TableSettings | None:
    """The settings of an archive's small members ``contents``, or None where they cannot be read (the
    checks after the members are read name what is wrong with them)."""
    try:
        return TableSettings.from_dict(_json_member(contents, "settings"))
    except (ValueError, TypeError, KeyError, AttributeError):
        return None


def _check_order_count(names, settings, path):
    """TableFormatError naming ``path`` for more order_K members than ``settings`` (:func:`_file_settings`;
    None: unknown) compute, before they are read (each was read first, then counted: 5 forged orders took
    3.6 GB)."""
    if settings is None:
        return
    limit = max_orders_kept(settings)
    count = len(_order_numbers(names))
    if count > limit:
        raise TableFormatError(f"{path}: {count} orders kept, the settings compute at most {limit}")


def _array_limits(settings) -> dict:
    """The most bytes each kind of array member may take (``data``, ``gathered``, ``order``, ``ground``),
    from the file's ``settings`` (:func:`_file_settings`): twice its float64 values, and a header (a member
    somewhat off in shape or dtype is read, and the checks after name what is wrong with it); where the
    settings cannot be read (None), half the host's available memory for all (those checks name the
    settings)."""
    if settings is None:
        from .resources import host_available_bytes

        available = host_available_bytes() or 2**40
        return {"data": available // 2}
    width, height, depth = settings.size
    cells = width * height * depth
    values = {"data": math.prod(data_shape(settings)), "gathered": (settings.azimuth_harmonics + 1) * cells * 6,
              "order": cells * 6, "ground": depth * 3}
    return {kind: 2 * 8 * count + _NPY_HEADER_BYTES for kind, count in values.items()}


#: The first bytes of a zip archive (an .npz): a member's local header, or the end record of an empty one.
_ZIP_MAGICS = (b"PK\x03\x04", b"PK\x05\x06")
#: The first bytes of a single NumPy array (.npy).
_NPY_MAGIC = b"\x93NUMPY"


def _not_an_archive(stream) -> str | None:
    """What the file open as ``stream`` is, judged by its first bytes, when it is not a zip archive; None
    when it may be one. Without it, numpy took any other file for a pickle and told the user that it
    "contains pickled (object) data" they could "load unsafely" (a text file, random bytes)."""
    try:
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


def _order_numbers(names) -> list:
    """K of every member order_K among ``names``, in order."""
    return sorted(int(match.group(1)) for match in map(re.compile(r"order_([1-9][0-9]{0,3})").fullmatch, names)
                  if match)


def _unexpected(names) -> list:
    """The names that are no table member, sorted."""
    orders = {f"order_{k}" for k in _order_numbers(names)}
    return sorted(set(names) - set(REQUIRED_MEMBERS) - set(OPTIONAL_MEMBERS) - orders)


def _check_names(names, path):
    """TableFormatError naming ``path`` for members no table has, from the archive's directory before any
    member is read (a foreign member could inflate to any size)."""
    if "format_version" not in names:
        raise TableFormatError(f"{path}: not a clsky table file (no format_version member)")
    unexpected = _unexpected(names)
    if unexpected:
        raise TableFormatError(f"{path}: unexpected members {unexpected}")


def _check_membership(contents) -> int:
    """Check that the archive holds the required members, order_1 ... order_K, optionally gathered
    and ground_irradiance, and nothing else; returns K."""
    missing = [name for name in REQUIRED_MEMBERS if name not in contents]
    if missing:
        raise TableFormatError(f"not a clsky table file (missing {missing})")
    orders = _order_numbers(contents)
    unexpected = _unexpected(contents)
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


#: The metadata a build writes that clsky reads back (``clsky info``, the animation's units in its frames'
#: headers), and what each must be: one line of text, a finite duration, a flag.
_METADATA_TEXTS = ("clsky_version", "backend", "device", "units")


def _check_metadata(metadata):
    """TableFormatError unless the metadata clsky reads back is what a build writes: a forged file's
    ``build_seconds`` of [1, 2] ended ``clsky info`` in TypeError, and a version or units with a newline
    would add lines to its output and to the frames' headers."""
    for key in _METADATA_TEXTS:
        _check_one_line(f"metadata's {key}", metadata.get(key, ""), 200)
    seconds = metadata.get("build_seconds", 0.0)
    if not is_real_number(seconds) or not 0.0 <= seconds < math.inf:
        raise TableFormatError(f"metadata's build_seconds must be a number of seconds >= 0, got {short(seconds)}")
    if not isinstance(metadata.get("fast_math", False), bool):
        raise TableFormatError(f"metadata's fast_math must be true or false, got {short(metadata['fast_math'])}")


def _check_one_line(name, value, limit):
    """TableFormatError unless ``value`` is one line of at most ``limit`` printable characters."""
    if not isinstance(value, str) or len(value) > limit or not value.isprintable():
        raise TableFormatError(f"{name} must be one line of printable text, got {short(value)}")


def _check_orders_record(record):
    """TableFormatError unless what clsky prints of the orders record (``clsky info``, ``clsky table``'s
    warning) is what a build writes: a forged reason with a newline or a terminal's escape codes was printed
    as it was, and a "converged" of "no" printed "converged"."""
    if "reason" in record:
        _check_one_line("orders_record's reason", record["reason"], 1000)
    if not isinstance(record.get("converged", False), bool):
        raise TableFormatError(f"orders_record's converged must be true or false, got {short(record['converged'])}")


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
