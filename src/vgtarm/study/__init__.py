"""Studies at scale: seeded sweeps and Monte Carlo draws of closed-loop runs on Dask.

:mod:`.spec` reads a study file and expands it into points with stable ids, :mod:`.runner` runs
them on a Dask cluster, :mod:`.store` keeps one atomic file per finished run and the results
tables, :mod:`.report` summarises them. ``dask[distributed]`` and ``pyarrow`` (the ``study``
extra) are needed to run a study, not to import this package.
"""

from .spec import PARAMETERS, Point, Study, load_study, parse_study
from .store import TIMING_COLUMNS, Store

__all__ = ["PARAMETERS", "TIMING_COLUMNS", "Point", "Store", "Study", "load_study", "parse_study"]
