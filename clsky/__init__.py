"""clsky: daylight and twilight skies from precomputed atmospheric scattering, on OpenCL.

>>> import clsky
>>> table = clsky.ScatteringTable.build("atmosphere-plus", clsky.TableSettings(size=(8, 16, 8)))
>>> rgb = table.radiance(altitude=0.0, cos_view=0.5, cos_sun=0.3, cos_scatter=0.9)
>>> rgb.shape
(3,)
"""

__version__ = "0.1.0"

from .atmosphere import PRESETS, AtmosphereParameters, preset  # noqa: E402
from .resources import InsufficientMemoryError  # noqa: E402
from .settings import TableSettings  # noqa: E402
from .table import ScatteringTable, TableFormatError  # noqa: E402

__all__ = ["AtmosphereParameters", "PRESETS", "preset", "TableSettings", "ScatteringTable",
           "TableFormatError", "InsufficientMemoryError", "__version__"]
