"""Controllers: computed force control (paper eqs. 18-20) and the switching control method."""

from .cfc import ComputedForceControl
from .gains import Gains
from .scm import SwitchingControl, predict_tip_error

__all__ = ["ComputedForceControl", "Gains", "SwitchingControl", "predict_tip_error"]
