"""MuJoCo bridge: the robot exported as MJCF (:func:`to_mjcf`), loaded in MuJoCo with our joint
states mapped onto MuJoCo's (:mod:`.model`), cross-checked against our dynamics (:mod:`.check`),
and stepped by MuJoCo as the plant of our closed loop (:mod:`.plant`,
``simulate(..., plant_engine="mujoco")``). See ``docs/mujoco.md`` for what MuJoCo can and cannot
match. MuJoCo is the optional extra ``vgtarm[mujoco]``; the simulator loads this package only
when asked for the MuJoCo plant.
"""

from .export import to_mjcf

__all__ = ["to_mjcf"]
