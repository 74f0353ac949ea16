"""clsky: daylight and twilight skies from precomputed atmospheric scattering, on OpenCL."""

from .atmosphere import PRESETS, AtmosphereParameters, preset
from .settings import TableSettings

__version__ = "0.1.0"
__all__ = ["AtmosphereParameters", "PRESETS", "preset", "TableSettings", "__version__"]
