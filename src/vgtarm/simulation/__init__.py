"""Closed-loop simulation of the manipulator under computed force or switching control."""

from .external import ExternalForce
from .reference import JointReference
from .result import GAActivation, SimulationResult
from .scenario import Scenario
from .simulator import INTEGRATORS, simulate

__all__ = ["INTEGRATORS", "ExternalForce", "GAActivation", "JointReference", "Scenario", "SimulationResult", "simulate"]
