"""What a run is, from the robot to its results: the experiment record, its options and the presets.

- :class:`Experiment` (:mod:`.record`): one run as a frozen, checked record, runnable from Python
  and stored whole in its ``summary.json``;
- :mod:`.options`: every option of a run, declared once (unit, bounds, help), from which the
  command line's flags, the study file's parameters and the presets' keys are generated;
- :mod:`.presets`: the named settings (``low-force``);
- :mod:`.cases`: the paper's two case studies.
"""

from __future__ import annotations

from .options import all_options
from .presets import PRESETS
from .record import Experiment

__all__ = ["PRESETS", "Experiment", "all_options"]
