"""Numerical settings of a scattering table: the knobs users trade speed for accuracy with."""

from __future__ import annotations

import dataclasses

import numpy as np

from .errors import (ParameterError, check_choice, check_integer, dataclass_from_dict, is_finite_real,
                     is_real_number, ordered_items)

__all__ = ["TableSettings", "MAPPINGS", "SAMPLINGS", "SUN_TRANSMITTANCE_METHODS", "MIE_LAYOUTS",
           "SCATTERING_MODES", "PARAMETERIZATIONS", "computed_sun_nodes"]

#: Texture mappings of the 3D table, name -> index passed to OpenCL (mapping.cl).
MAPPINGS = {"linear": 0, "nonlinear": 1}
#: Node placement along rays: uniform, Keller & Bohn's (i/n)^3 (view) and (i/n)^2 (sun), or
#: ground_end: Keller & Bohn's, except that view rays hitting the ground get 1 - (1 - i/n)^3, clustered
#: at the ground end (kernels/view_ray.cl).
SAMPLINGS = ("uniform", "keller_bohn", "ground_end")
#: How the sunlight's transmittance to a sample is found: re-marched, or read from a 2D table.
SUN_TRANSMITTANCE_METHODS = ("march", "table")
#: Schemes for the orders k >= 2 (see clsky/orders.py).
SCATTERING_MODES = ("atmosphere-plus", "physical")
#: Channels stored per cell: Rayleigh r, g, b + Mie r, g, b, or the notes' Rayleigh r, g, b + one Mie.
MIE_LAYOUTS = {"per-wavelength": 6, "notes": 4}

#: Table parameterizations: Elek's 3D (altitude, view zenith, sun zenith; the azimuth dropped), or
#: 4D with the view-sun azimuth as a fourth axis and Bruneton's horizon-split view mapping (clsky/table4d.py).
PARAMETERIZATIONS = ("elek3d", "4d")
#: Settings that enter :meth:`TableSettings.to_dict` (and so the parameters hash) only away from their
#: defaults: they came after tables were saved, whose hashes must not change; the first two after the 3D
#: tables only, ``source_stride`` and ``orders_sun_stride`` after the 4D ones too.
_LATE_FIELDS = {"parameterization": "elek3d", "azimuth_size": 16}
_LATER_FIELDS = {"source_stride": 1, "orders_sun_stride": 1}

#: Most azimuthal harmonics of the higher orders (``azimuth_harmonics``; clsky/azimuth.py).
MAX_AZIMUTH_HARMONICS = 64
_MAX_CELLS = 2**31 // 8   # keeps every flat index (times channels) inside a signed 32-bit int


def computed_sun_nodes(depth, stride=1):
    """The sun nodes of an axis of ``depth`` nodes that a scatter of sun ``stride`` (1 or 2;
    ``TableSettings.orders_sun_stride``) computes: every one, or every other one and the last
    (kernels/multiple.cl: scatter); the others :func:`clsky.reference.fill_between_sun_nodes` fills (its
    kernel: fill_between_suns). Here, beside the setting, for both the OpenCL engine and its NumPy twin."""
    if stride not in (1, 2):
        raise ValueError(f"sun_stride must be 1 or 2, got {stride!r}")
    return sorted(set(range(0, depth, stride)) | {depth - 1})


def check_sun_cos_range(value, name="sun_cos_range"):
    """``value`` as (low, high), the sun cosines a table's sun axis covers: two cosines -1 <= low < high <= 1,
    at least 1e-3 apart; ParameterError naming ``name`` otherwise (TableSettings, and the lookup engines,
    which took a reversed, NaN or out-of-range one and returned 1e-12 where their NumPy twin gave NaN)."""
    error = ParameterError(name, "two cosines -1 <= low < high <= 1, high - low >= 1e-3", value)
    items = ordered_items(value)
    if items is None or len(items) != 2 or not all(is_finite_real(v) for v in items):
        raise error
    low, high = (float(v) for v in items)
    if not -1.0 <= low < high <= 1.0 or high - low < 1e-3:
        raise error
    return low, high


@dataclasses.dataclass(frozen=True)
class TableSettings:
    """How a scattering table is discretised and computed.

    Parameters
    ----------
    size : (W, H, D)
        Nodes along altitude, view zenith and sun zenith; each in [2, 4096] (default 32 x 256 x 32).
    mapping : {'nonlinear', 'linear'}
        Texture mapping of the axes (mapping.cl).
    view_steps, sun_steps : int
        Trapezoid steps along the view ray and along each sun ray, in [1, 4096] (default 30 each).
    sampling : {'keller_bohn', 'uniform', 'ground_end'}
        Node placement along rays. Keller & Bohn's (default) agrees with the Monte Carlo path tracer
        within 1.3 % at 30 + 30 steps where uniform nodes overestimate by up to 39 % (near the ground,
        toward a low sun), and keeps optically thick atmospheres from diverging (README).
        'ground_end' is Keller & Bohn's except on view rays that hit the ground, whose nodes cluster
        at the ground end (1 - (1 - i/n)^3): for views from altitude it cuts the error of single
        scattering from 254 % to 1.6 % (95th percentile of the worst channel over observers at 1 to
        100 km) and leaves every other ray's nodes bit for bit as they were (README, "Views from
        altitude").
    sun_transmittance : {'table', 'march'}
        Read the sun's column densities from a 2D table of ``transmittance_size`` nodes (default), or
        re-march every sun ray. The table is 5x faster for single scattering and, at the default
        sizes, as accurate: against a converged table, rendered radiance differs by 0.39 % (median)
        either way (README, "Physics": "Defaults chosen by measurement").
    transmittance_size : (TW, TH)
        Nodes of that 2D table along altitude and zenith cosine, each in [2, 4096].
    mie_layout : {'per-wavelength', 'notes'}
        6 channels (Mie per wavelength, default) or the notes' 4 (one Mie channel, the mean of the three).
    dtype : {'float64', 'float32'}
        Precision of the kernels.
    mode : {'atmosphere-plus', 'physical'}
        Scheme of the higher orders (clsky/orders.py): the notes' factored chains, or the consistent
        scheme with cross terms and each event's own phase.
    orders : 'auto' or int
        'auto' iterates until an order adds less than ``order_tolerance`` (at most ``max_orders``);
        an integer K in [1, 1000] computes exactly the orders 1..K (1: single scattering only).
    order_tolerance : float
        In (0, 1): the stopping criterion of 'auto' (default 1e-4, defined in clsky/orders.py).
    max_orders : int
        In [2, 1000]: the most orders 'auto' computes (default 100).
    gather_theta_steps, gather_phi_steps : int
        Trapezoid steps of the sphere integral of the gather over Theta in [0, pi] and Phi in
        [0, 2 pi], each in [2, 8192] (defaults 256 and 128).
    sun_cos_range : (low, high)
        Sun-zenith cosines the sun axis covers, -1 <= low < high <= 1, high - low >= 1e-3 (default
        (-1, 1), the whole axis). The D nodes are spread evenly in the mapping's w between them
        (clsky/mapping.py); a scene planner (clsky/planner.py) narrows it to a sun path plus the margin
        that higher orders need. Lookups outside the range read its nearest end.
    azimuth_harmonics : int
        In [0, 64] (default 0): the orders k >= 2 of the physical mode carry the view-sun azimuth as a
        cosine series of this many harmonics, computed at as many + 1 azimuths along true rays
        (clsky/azimuth.py), at most ``gather_phi_steps / 2`` (the gather's Phi trapezoid aliases more);
        0 is the azimuth-averaged canonical-frame scheme. At the 'default' level,
        2 brings the ray march within the Monte Carlo's noise (p95 of the deviation <= 2.2 %) from +5
        down to -6 deg sun elevation, where 0 is +0.9 to +133 % too bright on average (README,
        "Twilight against Monte Carlo"). Needs mode 'physical'. The scene planner sets 2 when a
        scene's sun goes below +30 deg (:func:`clsky.planner.azimuth_harmonics`), the 'reference'
        quality level at every sun. Each order is scattered at M + 1 azimuths (order 2 with M + 1
        lookups per sample) and gathered per harmonic.
    parameterization : {'elek3d', '4d'}
        'elek3d' (default): the 3D table above. '4d': a fourth axis of ``azimuth_size`` nodes in the
        view-sun azimuth [0, pi], and the view axis split at the horizon (Bruneton 2017): single
        scattering (factored, phase applied at lookup) and the higher orders (phase applied) along the
        true ray of every node (clsky/table4d.py). Needs mode 'physical' and the per-wavelength Mie
        layout; ``size`` then gives the nodes along altitude, view zenith (an even H >= 4: H / 2 for the
        rays that hit the ground, H / 2 for those that reach space) and sun zenith; the higher orders
        are computed on the 3D grid of ``size`` and ``mapping`` as in the 3D physical table.
    azimuth_size : int
        Nodes of the 4D table's azimuth axis, in [2, 1024] (default 16), spread evenly in [0, pi].
    multiple_view_steps : int or None
        Trapezoid steps along the view ray when scattering the orders k >= 2, in [1, 4096]; None
        uses ``view_steps``. The higher orders are smooth and dim: 20 (default) instead of 30 makes
        each order a third cheaper for a median error of 0.48 % instead of 0.39 % (README, "Physics":
        "Defaults chosen by measurement").
    source_stride : int
        1 (default) or 2: the view nodes per lookup of the higher orders' source (the gathered table)
        in every integral of it along a view ray: a table's scatter of the orders (kernels/multiple.cl)
        and the 4D table's integrals of them, and, in the settings of a ray march, the per-pixel ray
        march and the sky-view map's nodes (kernels/view_ray.cl: integrate_gathered). 2
        looks it up at every other node and the last, linear in distance between: the default
        animation's ray march takes about a fifth less CPU time for a change of its luminance of about
        2e-4 by day and up to 2e-3 in civil twilight, a scatter of its table a quarter (M = 0) to a
        third (M = 2) less for a change of the frames under 1e-3 with the sun at -4 deg and above
        (docs/speed-log.md; 7e-3 at -8 deg, README "Quality levels"). The 'draft' and 'default' quality
        levels take it for both, but for the table of a scene plan whose sun goes below -4 deg, where it put
        their frames past their promises (:data:`clsky.planner.SOURCE_EVERY_NODE_BELOW_DEG`).
    orders_sun_stride : int
        1 (default) or 2: the sun nodes a table's scatter of the orders k >= 3 computes
        (:data:`clsky.orders.SUN_STRIDE_FROM_ORDER`; kernels/multiple.cl: scatter). 2 computes every other
        sun node and the last, and gives each node between two computed ones the geometric mean of theirs
        (the orders' radiance falls off about exponentially along the sun axis; their mean where either is
        not positive: :func:`clsky.reference.fill_between_sun_nodes`). The orders k >= 3 carry a few per cent
        of the light; interpolated so, they moved a bright cell by 1-2e-4 at the 95th percentile in twilight
        (up to 7.8e-3 in the worst cells, at -3 deg), the default and high quality levels' frames by at most
        3.4e-4 and 8.3e-5, for 14-16 % of their builds' CPU time (docs/speed-log.md); those two levels take
        it. It does nothing in a ray march's settings, for a table of at most 2 orders, or on a sun axis of
        2 nodes (but enters the parameters hash at 2).
    """

    size: tuple = (32, 256, 32)
    mapping: str = "nonlinear"
    view_steps: int = 30
    sun_steps: int = 30
    sampling: str = "keller_bohn"
    sun_transmittance: str = "table"
    transmittance_size: tuple = (64, 256)
    mie_layout: str = "per-wavelength"
    dtype: str = "float64"
    mode: str = "atmosphere-plus"
    orders: object = "auto"
    order_tolerance: float = 1e-4
    max_orders: int = 100
    gather_theta_steps: int = 256
    gather_phi_steps: int = 128
    multiple_view_steps: object = 20
    sun_cos_range: tuple = (-1.0, 1.0)
    azimuth_harmonics: int = 0
    parameterization: str = "elek3d"
    azimuth_size: int = 16
    source_stride: int = 1
    orders_sun_stride: int = 1

    def __post_init__(self):
        object.__setattr__(self, "size", self._check_size("size", self.size, 3))
        object.__setattr__(self, "transmittance_size",
                           self._check_size("transmittance_size", self.transmittance_size, 2))
        if int(np.prod(self.size)) > _MAX_CELLS:
            raise ParameterError("size", f"at most {_MAX_CELLS} cells (W x H x D)", self.size)
        object.__setattr__(self, "view_steps", check_integer("view_steps", self.view_steps, 1, 4096))
        object.__setattr__(self, "sun_steps", check_integer("sun_steps", self.sun_steps, 1, 4096))
        check_choice("mapping", self.mapping, MAPPINGS)
        check_choice("sampling", self.sampling, SAMPLINGS)
        check_choice("sun_transmittance", self.sun_transmittance, SUN_TRANSMITTANCE_METHODS)
        check_choice("mie_layout", self.mie_layout, MIE_LAYOUTS)
        check_choice("mode", self.mode, SCATTERING_MODES)
        if not (isinstance(self.orders, str) and self.orders == "auto"):
            try:
                object.__setattr__(self, "orders", check_integer("orders", self.orders, 1, 1000))
            except ParameterError as error:
                raise ParameterError("orders", "'auto' or an integer in [1, 1000]", error.value) from None
        object.__setattr__(self, "max_orders", check_integer("max_orders", self.max_orders, 2, 1000))
        object.__setattr__(self, "gather_theta_steps", check_integer("gather_theta_steps", self.gather_theta_steps, 2, 8192))
        object.__setattr__(self, "gather_phi_steps", check_integer("gather_phi_steps", self.gather_phi_steps, 2, 8192))
        object.__setattr__(self, "multiple_view_steps",
                           check_integer("multiple_view_steps", self.multiple_view_steps, 1, 4096, optional=True))
        object.__setattr__(self, "sun_cos_range", check_sun_cos_range(self.sun_cos_range))
        object.__setattr__(self, "azimuth_harmonics",
                           check_integer("azimuth_harmonics", self.azimuth_harmonics, 0, MAX_AZIMUTH_HARMONICS))
        if self.azimuth_harmonics and self.mode != "physical":
            raise ParameterError("azimuth_harmonics", "0 unless mode is 'physical'", self.azimuth_harmonics)
        if self.azimuth_harmonics > self.gather_phi_steps // 2:
            # beyond, the gather's Phi trapezoid aliases the harmonics: they stop decaying (measured, 8 steps:
            # M = 4 within 1.8 % of the reference at -3 deg, M = 8 80 % off, M = 64 490 %)
            raise ParameterError("azimuth_harmonics", f"at most gather_phi_steps / 2 = {self.gather_phi_steps // 2} "
                                                      f"(each harmonic sampled twice a period by the gather)",
                                 self.azimuth_harmonics)
        self._check_parameterization()
        object.__setattr__(self, "source_stride", check_integer("source_stride", self.source_stride, 1, 2))
        object.__setattr__(self, "orders_sun_stride",
                           check_integer("orders_sun_stride", self.orders_sun_stride, 1, 2))
        tolerance = self.order_tolerance
        if not is_real_number(tolerance) or not 0.0 < tolerance < 1.0:
            raise ParameterError("order_tolerance", "a number in (0, 1)", tolerance)
        object.__setattr__(self, "order_tolerance", float(tolerance))
        try:
            dtype = None if self.dtype is None else np.dtype(self.dtype)   # np.dtype(None) is float64
        except TypeError:
            dtype = None
        if dtype not in (np.float32, np.float64):
            raise ParameterError("dtype", "'float64' or 'float32'", self.dtype)
        object.__setattr__(self, "dtype", dtype.name)

    def _check_parameterization(self):
        """The 4D parameterization's own constraints (clsky/table4d.py)."""
        check_choice("parameterization", self.parameterization, PARAMETERIZATIONS)
        object.__setattr__(self, "azimuth_size", check_integer("azimuth_size", self.azimuth_size, 2, 1024))
        if self.parameterization != "4d":
            return
        if self.mode != "physical":
            raise ParameterError("parameterization", "'elek3d' unless mode is 'physical'", self.parameterization)
        if self.mie_layout != "per-wavelength":
            raise ParameterError("mie_layout", "'per-wavelength' with the '4d' parameterization", self.mie_layout)
        if self.size[1] % 2 or self.size[1] < 4:
            raise ParameterError("size", "an even number of view nodes H >= 4 with the '4d' parameterization "
                                 "(H / 2 on each side of the horizon)", self.size)
        if int(np.prod(self.size)) * self.azimuth_size > _MAX_CELLS:
            raise ParameterError("azimuth_size", f"at most {_MAX_CELLS} cells (W x H x D x azimuth_size)",
                                 self.azimuth_size)

    @property
    def is_4d(self) -> bool:
        """True for the 4D parameterization (clsky/table4d.py)."""
        return self.parameterization == "4d"

    @staticmethod
    def _check_size(name, value, count):
        items = ordered_items(value)
        if items is None or len(items) != count:
            raise ParameterError(name, f"{count} integers", value)
        return tuple(check_integer(name, v, 2, 4096, index=i) for i, v in enumerate(items))

    @property
    def sun_w_range(self) -> tuple:
        """(w_low, w_high): the texture coordinates the sun axis spans (the kernels' ``sun_range``)."""
        from .mapping import sun_w_range
        return sun_w_range(self.mapping, self.sun_cos_range)

    @property
    def scatter_settings(self) -> "TableSettings":
        """These settings as the scatter of the higher orders uses them (its view steps)."""
        if self.multiple_view_steps is None:
            return self
        return self.replace(view_steps=self.multiple_view_steps, multiple_view_steps=None)

    @property
    def factored_channels(self) -> int:
        """Channels of the factored part (Rayleigh r, g, b + Mie per wavelength, or the notes' one Mie)."""
        return MIE_LAYOUTS[self.mie_layout]

    @property
    def has_multiple_block(self) -> bool:
        """True when the table carries 3 channels of higher orders with their phase applied (physical
        mode with orders beyond the first)."""
        return self.mode == "physical" and self.orders != 1

    @property
    def channels(self) -> int:
        """Channels per cell of the table: the factored part, plus 3 in the physical mode's multiple block."""
        return self.factored_channels + (3 if self.has_multiple_block else 0)

    def replace(self, **changes) -> "TableSettings":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        """The settings as JSON-ready values; the late fields (``parameterization``, ``azimuth_size``;
        ``source_stride``, ``orders_sun_stride``) only where they differ from their defaults, so that a 3D
        table's (any table's) parameters hash is what it was."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()
                if not (k in _LATE_FIELDS and v == _LATE_FIELDS[k] and self.parameterization == "elek3d")
                and not (k in _LATER_FIELDS and v == _LATER_FIELDS[k])}

    @classmethod
    def from_dict(cls, data: dict) -> "TableSettings":
        """Inverse of :meth:`to_dict`; unknown fields raise ValueError."""
        return dataclass_from_dict(cls, data, "table settings", "table settings")
