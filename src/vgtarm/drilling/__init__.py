"""Bone drilling: the layered bone, the drill, and the thrust and torque of the cutting law
(:mod:`vgtarm.drilling.bone`; the same arithmetic in C in ``csrc/vgt_drill.h``). See
``docs/drilling.md``."""

from __future__ import annotations

from .bone import (
    COEFFICIENT_NAMES,
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

__all__ = [
    "COEFFICIENT_NAMES",
    "HEADER",
    "Bone",
    "Drill",
    "DrillingForces",
    "Layer",
    "Material",
    "bone_from_dict",
    "drilling_forces",
    "drilling_forces_at",
    "engagement",
    "engagement_slope",
    "feed_law",
    "layer_index",
    "layer_weights",
    "load_bone",
]
