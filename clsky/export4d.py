"""The 4D table for engines: three RGBA 3D textures and a GLSL lookup (issue 11, item 6).

:func:`texture_volumes` packs the 4D table (A, D, H, W, 9) (:mod:`clsky.table4d`) into three RGBA
volumes of W x H x (D A) texels, the sun and azimuth axes sharing the depth as Bruneton (2017) packs
mu_s and nu into one texture axis: texel (x, y, z + D a); t0 = (Ibar_R r, g, b, Ibar_M r),
t1 = (Ibar_M g, b, L r, g), t2 = (L b, 0, 0, 0). :func:`export_texture` writes them as
``<name>.bin`` (little-endian float32, t0 then t1 then t2, each x fastest, then y, then depth) with
``<name>.json``, the header that gives every constant ``docs/lookup4d.glsl`` (:data:`GLSL_SNIPPET`) takes.
That snippet looks up the table quadrilinearly by texelFetch (no hardware filtering: the view axis
must not blend across the horizon, and the depth packs two axes); tests/test_export4d.py compiles it
as OpenCL C and compares it with :func:`clsky.reference.lookup4d`.
"""

from __future__ import annotations

import contextlib
import json

import numpy as np

from ._files import StagedWrites, atomic_write, binary_and_header, check_output
from .errors import check_flag

__all__ = ["texture_volumes", "export_texture", "texture_header", "GLSL_SNIPPET"]

#: The GLSL lookup, relative to the repository root (shipped with the docs, not the wheel).
GLSL_SNIPPET = "docs/lookup4d.glsl"


def texture_volumes(data) -> np.ndarray:
    """(3, D A, H, W, 4) float32: the RGBA volumes t0, t1, t2 of a 4D table's data (A, D, H, W, 9)."""
    data = np.asarray(data)
    if data.ndim != 5 or data.shape[4] != 9:
        raise ValueError(f"a 4D table with its higher orders has data (A, D, H, W, 9), got {data.shape}")
    azimuths, depth, height, width, _ = data.shape
    padded = np.zeros(data.shape[:4] + (12,), dtype=np.float32)
    padded[..., :9] = data
    volumes = padded.reshape(azimuths * depth, height, width, 3, 4)
    return np.ascontiguousarray(np.moveaxis(volumes, 3, 0))


def texture_header(table, binary_name) -> dict:
    """The JSON header of :func:`export_texture`: layout and the snippet's constants."""
    settings, atmosphere = table.settings, table.atmosphere
    width, height, depth = settings.size
    return {
        "format": "clsky 4D scattering table, RGBA textures",
        "binary": binary_name, "dtype": "float32", "byte_order": "little",
        "textures": ["t0 = (Ibar_R r, g, b, Ibar_M r)", "t1 = (Ibar_M g, b, L r, g)", "t2 = (L b, 0, 0, 0)"],
        "texture_size": {"width": width, "height": height, "depth": depth * settings.azimuth_size},
        "layout": "t0, t1, t2 one after the other, each values[((x + y*W + (z + D*a)*W*H) * 4 + c]",
        "size": [width, height, depth, settings.azimuth_size],
        "mapping": {"nonlinear": 1, "linear": 0}[settings.mapping],
        "sun_range": list(settings.sun_w_range),
        "planet_radius": atmosphere.planet_radius, "top_radius": atmosphere.top_radius,
        "incident_light": list(atmosphere.incident_light), "mie_g": atmosphere.mie_g,
        "modified_rayleigh": int(atmosphere.rayleigh_phase == "modified_atmosphereplus"),
        "glsl": GLSL_SNIPPET + ": radiance4d(t0, t1, t2, vec4(size), mapping, sun_range, planet_radius, "
                "top_radius, incident_light, mie_g, modified_rayleigh, h, mu_v, mu_s, nu)",
        "parameters_hash": table.parameters_hash,
    }


def export_texture(table, path, overwrite=False, staging=None):
    """Write ``<path>.bin`` (:func:`texture_volumes`, float32) and ``<path>.json`` (:func:`texture_header`;
    the pair's names as :func:`clsky._files.binary_and_header`) of a 4D table (``parameterization='4d'``
    with higher orders); both checked first, landing together."""
    if not table.settings.is_4d:
        raise ValueError("export_texture needs a 4D table (parameterization '4d'); export_raw writes a 3D one")
    overwrite = check_flag("overwrite", overwrite)
    table.validate()
    binary, header = binary_and_header(path)
    for target in (binary, header):      # before the volumes: two copies of the table (400 MB for 16 x 128 x 128 x 16)
        check_output(target, force=overwrite)
    volumes = texture_volumes(table.data)
    with contextlib.ExitStack() as stack:
        if staging is None:
            staging = stack.enter_context(StagedWrites())
        with atomic_write(binary, overwrite, staging=staging) as temporary:
            volumes.astype("<f4").tofile(temporary)
        with atomic_write(header, overwrite, staging=staging) as temporary:
            temporary.write_text(json.dumps(texture_header(table, binary.name), indent=2) + "\n")
    return binary, header
