"""Bone drilling: the layered bone, the drill, and the thrust and torque of the cutting law
(:mod:`vgtarm.drilling.bone`; the same arithmetic in C in ``model/csrc/vgt_drill.h``; ``docs/drilling.md``),
and a first drilling loop under hybrid force and position control in the tool frame with layer
and breakthrough detection from the observer's estimate (:mod:`.control`, :mod:`.loop`, in NumPy;
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
    HybridController,
    check_settings,
)
from .loop import SERIES, TARGETS, DrillingResult, drilling_figure, drilling_run, perturbed_bone, summarise

__all__ = [
    "COEFFICIENT_NAMES",
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
    "HybridController",
    "Layer",
    "Material",
    "bone_from_dict",
    "check_settings",
    "drilling_figure",
    "drilling_forces",
    "drilling_forces_at",
    "drilling_run",
    "engagement",
    "engagement_slope",
    "feed_law",
    "layer_index",
    "layer_weights",
    "load_bone",
    "perturbed_bone",
    "summarise",
]
