"""The atmosphere as the kernels see it: one ``atmosphere_t`` struct in a ``__constant`` buffer.

The C declaration is generated from the NumPy dtype (``pyopencl.tools.match_dtype_to_c_struct``), so
the two can never drift apart. The ozone fields come last, so that the fields before them keep their
offsets; the kernels read them only when built with ``-DOZONE`` (:func:`feature_defines`). The
ground's albedo follows, read only with ``-DGROUND``.
"""

from __future__ import annotations

import numpy as np
import pyopencl as cl

from . import _cl
from .atmosphere import MIE_PHASE_METHODS, RAYLEIGH_PHASE_METHODS, AtmosphereParameters

STRUCT_NAME = "atmosphere_t"


def _fields(dtype):
    real = np.dtype(dtype)
    real4 = _cl.real_vector_dtype(dtype, 4)
    return (
        ("beta_rayleigh", real4),          # beta_R for r, g, b (.w = 0) [1/m]
        ("incident_light", real4),         # I_I for r, g, b (.w = 0)
        ("beta_mie", real4),               # beta_M, scattering, for r, g, b (.w = 0) [1/m]
        ("beta_mie_extinction", real4),    # beta_M^e for r, g, b (.w = 0) [1/m]
        ("planet_radius", real),           # Rp [m]
        ("top_radius", real),              # Ra [m]
        ("rayleigh_scale_height", real),   # H_R [m]
        ("mie_scale_height", real),        # H_M [m]
        ("mie_g", real),                   # Cornette-Shanks g, notes' sign convention
        ("rayleigh_phase", np.int32),      # index into RAYLEIGH_PHASE_METHODS
        ("mie_phase", np.int32),           # index into MIE_PHASE_METHODS
        ("ozone_extinction", real4),       # sigma_O3 n_max for r, g, b (.w = 0) [1/m], at the tent's peak
        ("ozone_peak_altitude", real),     # tent peak [m]
        ("ozone_half_width", real),        # tent half width [m]
        ("ground_albedo", real),           # Lambertian albedo a of the ground, in [0, 1]
    )


def feature_defines(atmosphere: AtmosphereParameters) -> list[str]:
    """The compile-time features of ``atmosphere``: ``-DOZONE=1`` when it has ozone, ``-DGROUND=1``
    when its ground reflects; none for the atmosphere-plus preset (the program is then the one
    without either)."""
    return ((["-DGROUND=1"] if atmosphere.has_ground else [])
            + (["-DOZONE=1"] if atmosphere.has_ozone else []))


def declaration(device, dtype) -> _cl.Source:
    """The generated C declaration of ``atmosphere_t`` for ``dtype`` on ``device``."""
    _, text = _cl.struct_dtype(device, STRUCT_NAME, _fields(dtype), dtype)
    return _cl.Source(f"{STRUCT_NAME} ({np.dtype(dtype).name}, generated)", text)


def to_device(queue, atmosphere: AtmosphereParameters, dtype):
    """A read-only buffer holding ``atmosphere`` as one ``atmosphere_t``."""
    struct, _ = _cl.struct_dtype(queue.device, STRUCT_NAME, _fields(dtype), dtype)
    record = np.zeros(1, dtype=struct)
    record["beta_rayleigh"] = tuple(atmosphere.rayleigh_scattering) + (0.0,)
    record["incident_light"] = tuple(atmosphere.incident_light) + (0.0,)
    record["beta_mie"] = tuple(atmosphere.mie_scattering_channels) + (0.0,)
    record["beta_mie_extinction"] = tuple(atmosphere.mie_extinction_channels) + (0.0,)
    record["planet_radius"] = atmosphere.planet_radius
    record["top_radius"] = atmosphere.top_radius
    record["rayleigh_scale_height"] = atmosphere.rayleigh_scale_height
    record["mie_scale_height"] = atmosphere.mie_scale_height
    record["mie_g"] = atmosphere.mie_g
    record["rayleigh_phase"] = RAYLEIGH_PHASE_METHODS[atmosphere.rayleigh_phase]
    record["mie_phase"] = MIE_PHASE_METHODS[atmosphere.mie_phase]
    record["ozone_extinction"] = tuple(atmosphere.ozone_extinction) + (0.0,)
    record["ozone_peak_altitude"] = atmosphere.ozone_peak_altitude
    record["ozone_half_width"] = atmosphere.ozone_half_width
    record["ground_albedo"] = atmosphere.ground_albedo
    mf = cl.mem_flags
    return cl.Buffer(queue.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=record)
