"""The factors of a model scaled from the plant's (mass, inertia, friction): one check.

Kept apart from :mod:`.sanity` so that the parameter records (:mod:`.parameters`, a stack's
description) can check their ``scaled`` factors without importing the joint ranges, which import
them.
"""

from __future__ import annotations

import decimal
import numbers

import numpy as np

from ..errors import InputError, VgtarmError, shown

#: Smallest and largest accepted factor of a scaled model (mass, inertia, friction).
MODEL_FACTOR_RANGE = (1e-3, 1e3)


def model_factor(label: str, value: object, *, where: str = "scaled", error: type[VgtarmError] = InputError) -> float:
    """``value`` checked as the factor ``label`` (mass, inertia, friction) of a model scaled from the
    plant's: a real number in :data:`MODEL_FACTOR_RANGE`, else one ``error`` line that shows the
    value and the accepted range."""
    low, high = MODEL_FACTOR_RANGE
    expected = (
        f"expected a factor in [{low:g}, {high:g}] (the model's {label} as a ratio to the plant's; "
        "beyond, it is no model of the plant)"
    )
    real = isinstance(value, numbers.Real | np.floating | np.integer) and not isinstance(value, bool | np.bool_)
    if not real or isinstance(value, decimal.Decimal):
        raise error(f"{where}: {label} = {shown(value)}: {expected}")
    try:
        number = float(value)  # type: ignore[arg-type]
    except OverflowError:  # an integer beyond any float
        number = float("inf")
    if not low <= number <= high:  # also false for NaN
        raise error(f"{where}: {label} = {shown(value)}: {expected}")
    return number
