"""The controller on a real-time target (issue 25): computed force control with the observer,
exported as a self-contained C99 folder (:func:`export_controller`), and the simulated loop closed
through the exported, compiled code (:func:`simulate_exported`), held to the simulation bit for bit;
force-controlled drilling's controller the same way (:func:`export_drilling`, :mod:`.drilling`).

Layer: above :mod:`vgtarm.simulation` (it reuses its checks, arrays and plant), below the app.
"""

from __future__ import annotations

from .controller import ExportedController, ExportError, export_controller
from .drilling import export_drilling
from .loop import CompiledExport, simulate_exported

__all__ = [
    "CompiledExport",
    "ExportError",
    "ExportedController",
    "export_controller",
    "export_drilling",
    "simulate_exported",
]
