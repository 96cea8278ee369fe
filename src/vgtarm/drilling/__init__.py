"""Bone drilling: the layered bone, the drill, and the thrust and torque of the cutting law
(:mod:`vgtarm.drilling.bone`; the same arithmetic in C in ``model/csrc/vgt_drill.h``; ``docs/drilling.md``),
and the drilling loop under hybrid force and position control in the tool frame with layer and
breakthrough detection from the observer's estimate (:mod:`.control`, :mod:`.loop`; in C by
:mod:`.compiled`, held to the NumPy loop; studies of seeded bones in :mod:`.study`;
``docs/drilling_control.md``)."""

from __future__ import annotations

from .bone import (
    COEFFICIENT_NAMES,
    FEMUR,
    HEADER,
    Bone,
    Drill,
    DrillingForces,
    Layer,
    Material,
    bone_from_dict,
    drilling_forces,
    drilling_forces_at,
    engagement,
    engagement_slope,
    feed_law,
    layer_index,
    layer_weights,
    load_bone,
)
from .control import (
    FEEDBACKS,
    MODES,
    PHASES,
    Detector,
    DrillingPlant,
    DrillingSettings,
    DrillingSetup,
    HybridController,
    check_settings,
)
from .loop import (
    ENGINES,
    SERIES,
    TARGETS,
    DrillingResult,
    drilling_figure,
    drilling_run,
    drilling_setup,
    perturbed_bone,
    summarise,
)

__all__ = [
    "COEFFICIENT_NAMES",
    "ENGINES",
    "FEEDBACKS",
    "FEMUR",
    "HEADER",
    "MODES",
    "PHASES",
    "SERIES",
    "TARGETS",
    "Bone",
    "Detector",
    "Drill",
    "DrillingForces",
    "DrillingPlant",
    "DrillingResult",
    "DrillingSettings",
    "DrillingSetup",
    "HybridController",
    "Layer",
    "Material",
    "bone_from_dict",
    "check_settings",
    "drilling_figure",
    "drilling_forces",
    "drilling_forces_at",
    "drilling_run",
    "drilling_setup",
    "engagement",
    "engagement_slope",
    "feed_law",
    "layer_index",
    "layer_weights",
    "load_bone",
    "perturbed_bone",
    "summarise",
]
