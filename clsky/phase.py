"""Phase functions (NumPy), mirroring ``kernels/phase.cl``. None carries the 1/(4 pi): each averages to
1 over the sphere, except the notes' modified Rayleigh (mean 1.2533, an artistic choice).

Argument: c = cos(theta) = dot(Sun, V); c = 1 looks straight at the sun.

References
----------
Cornette, W. M. & Shanks, J. G. (1992). Physically reasonable analytic expression for the
single-scattering phase function. Applied Optics 31(16), 3152, doi:10.1364/AO.31.003152.
``docs/physics.md`` (sign convention of g: the notes' g = -0.85 with "+2 g c" peaks toward the sun).
"""

from __future__ import annotations

import numpy as np

__all__ = ["rayleigh", "rayleigh_modified_atmosphereplus", "mie_cornette_shanks",
           "RAYLEIGH_PHASES", "MIE_PHASES", "PHASE_MEANS", "PHASE_FORMULAS", "rayleigh_phase", "mie_phase",
           "phase_description"]


def rayleigh(c):
    """True Rayleigh phase 3/4 (1 + c^2); mean 1 over the sphere."""
    c = np.asarray(c, dtype=np.float64)
    return 0.75 * (1.0 + c * c)


def rayleigh_modified_atmosphereplus(c):
    """The Atmosphere Plus notes' 0.8 (7/5 + c^2 / 2); mean 1.2533 over the sphere (not 1)."""
    c = np.asarray(c, dtype=np.float64)
    return 0.8 * (1.4 + 0.5 * c * c)


def mie_cornette_shanks(c, g):
    """Cornette-Shanks 3(1-g^2) / (2(2+g^2)) (1+c^2) / (1+g^2+2gc)^(3/2), notes' sign convention.

    With g < 0 (notes: -0.85) the forward lobe points at the sun (c = 1).

    The base 1 + g^2 + 2gc is at least (1 - |g|)^2 (its value at the peak, c = -sign(g)), but it is
    formed from terms of size ~2: below half that least value it is rounding noise (float32 kernels
    rounded it to 0 or below with |g| near 1) and replaced by the least value, as in kernels/phase.cl;
    above, it stays as formed, bit for bit the plain formula (in float64 and |g| <= MAX_MIE_G it always
    does).
    """
    c = np.asarray(c, dtype=np.float64)
    g2 = g * g
    least = (1.0 - abs(g)) ** 2
    formed = 1.0 + g2 + 2.0 * g * c
    base = np.where(formed < 0.5 * least, least, formed)
    return 1.5 * (1.0 - g2) / (2.0 + g2) * (1.0 + c * c) / base ** 1.5


#: Mean of each phase function over the sphere, (1 / 4 pi) Integral F d omega, exact: Cornette-Shanks is
#: normalised for every g by its prefactor; the modified Rayleigh is 0.8 (7/5 + 1/6).
PHASE_MEANS = {"rayleigh": 1.0, "modified_atmosphereplus": 0.8 * (1.4 + 1.0 / 6.0), "cornette_shanks": 1.0}

#: Each phase function written out, for the headers of exported tables (an engine's own lookup applies them).
PHASE_FORMULAS = {"rayleigh": "3/4 (1 + c^2)", "modified_atmosphereplus": "0.8 (7/5 + c^2/2)",
                  "cornette_shanks": "3 (1 - g^2) / (2 (2 + g^2)) (1 + c^2) / (1 + g^2 + 2 g c)^(3/2)"}

#: Registries, keyed by AtmosphereParameters.rayleigh_phase / .mie_phase.
RAYLEIGH_PHASES = {"rayleigh": rayleigh, "modified_atmosphereplus": rayleigh_modified_atmosphereplus}
MIE_PHASES = {"cornette_shanks": mie_cornette_shanks}


def rayleigh_phase(atmosphere, c):
    """The Rayleigh phase function chosen by ``atmosphere``, at cosine c."""
    return RAYLEIGH_PHASES[atmosphere.rayleigh_phase](c)


def mie_phase(atmosphere, c):
    """The Mie phase function chosen by ``atmosphere``, at cosine c."""
    return MIE_PHASES[atmosphere.mie_phase](c, atmosphere.mie_g)


def phase_description(atmosphere) -> dict:
    """The phase functions of ``atmosphere`` as an exported table's header gives them (JSON-ready): F_R and
    F_M written out (:data:`PHASE_FORMULAS`) with g, and their conventions: c = dot(Sun, V), no 1 / (4 pi),
    and the notes' sign of g, for which a negative g peaks toward the sun (the usual 1 + g^2 - 2 g c with
    this g would put the Mie peak opposite the sun)."""
    return {
        "F_R": PHASE_FORMULAS[atmosphere.rayleigh_phase],
        "F_M": PHASE_FORMULAS[atmosphere.mie_phase],
        "g": atmosphere.mie_g,
        "c": "cos theta = dot(sun direction, view direction): 1 looking straight at the sun",
        "normalization": (f"no 1/(4 pi): F_R's mean over the sphere is {PHASE_MEANS[atmosphere.rayleigh_phase]:.4f}, "
                          f"F_M's {PHASE_MEANS[atmosphere.mie_phase]:.4f}"),
        "sign_of_g": ("the notes' convention, + 2 g c in F_M's base: g < 0 peaks toward the sun (c = 1); the "
                      "usual Henyey-Greenstein form 1 + g^2 - 2 g c takes -g"),
    }
