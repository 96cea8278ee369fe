"""MuJoCo bridge: the robot exported as MJCF (:func:`to_mjcf`), loaded in MuJoCo with our joint
states mapped onto MuJoCo's (:mod:`.model`), cross-checked against our dynamics (:mod:`.check`),
and stepped by MuJoCo as the plant of our closed loop (:mod:`.plant`,
``simulate(..., plant_engine="mujoco")``, registered when this package is imported), and as the
plant of force-controlled drilling (:func:`mujoco_drilling_run`, :mod:`.drilling`). See
``docs/mujoco.md`` for what MuJoCo can and cannot match. MuJoCo is the optional extra
``vgtarm[mujoco]``; importing this package does not need it, using it does.
"""

from ..model.robot import Robot
from ..simulation.engines import register_plant_engine
from .drilling import MujocoDrillingPlant, mujoco_drilling_run
from .export import to_mjcf, to_spec
from .plant import MujocoLoop


def _mujoco_plant(plant: Robot, model: Robot) -> MujocoLoop:
    return MujocoLoop(plant, model)


register_plant_engine("mujoco", _mujoco_plant)

__all__ = ["MujocoDrillingPlant", "MujocoLoop", "mujoco_drilling_run", "to_mjcf", "to_spec"]
