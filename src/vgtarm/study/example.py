"""The commented example study that ``vgtarm study init FILE`` writes."""

from __future__ import annotations

import re
import textwrap

from ..experiment.options import study_options

_HEAD = """\
# A vgtarm study: computed force control (CFC) against the switching method (SCM) with the tool
# force, over seeds and a controller model whose masses are off by up to 10 %.
# Run it with `vgtarm study run THIS_FILE --out DIR` and read it with `vgtarm study report DIR`.
# Every run of this file: (2 controllers) x (2 model draws) x (4 seeds) = 16 runs.

[study]
name = "cfc-vs-scm"
case = 1                # the paper's case study 1 or 2; or path = "tip.csv" (t,x,y,z rows in s and m,
                        # relative to this file; gains then default to case 1's)
duration = 1.0          # s: run only the first second of the path (leave out for the whole path)
dt = 0.001              # s: control period, the sampling of the reference
rates = "exact"         # reference rates: "exact" or "finite_difference" (the paper's)
# robot = "robot.toml"  # a robot file (default: the shipped reference robot)
seeds = 4               # seeds 0..3 of the disturbance and the GA; or [0, 7, 9]; or {start = 10, count = 4}

# Every combination of the values below is run (a single value is a list of one).
"""

_TAIL = """\
[grid]
controller = ["cfc", "scm"]
external_force = true

# `draws` independent draws of the parameters below (each draw is run with every seed).
# Distributions: {uniform = [a, b]}, {log_uniform = [a, b]}, {normal = [mean, sd]},
# {integers = [a, b]}, {choice = [v1, v2]}.
[random]
draws = 2
seed = 0                # seed of the draws
model_mass = {uniform = [0.9, 1.1]}
"""


def _parameters() -> str:
    """The comment naming every parameter a study takes, each with what it expects, from the
    options' declarations (:func:`vgtarm.experiment.options.study_options`)."""
    lines = ["# Parameters (a grid's or a draw's): each with what it takes."]
    for name, declared in study_options().items():
        expected = _as_toml(declared.expected)
        lines += textwrap.wrap(f"{name}: {expected}", width=100, initial_indent="#   ", subsequent_indent="#       ")
    return "\n".join(lines) + "\n\n"


def _as_toml(expected: str) -> str:
    """A declaration's expected text as a TOML file spells its values: ``["a", "b"]`` for Python's
    ``['a', 'b']``, ``true or false`` for ``True or False``."""
    expected = expected.replace("True or False", "true or false")
    return re.sub(r"\[([^\]]*)\]", lambda m: "[" + m.group(1).replace("'", '"') + "]", expected)


#: The example file: a study of both controllers, with every parameter named in its comments.
EXAMPLE = _HEAD + _parameters() + _TAIL
