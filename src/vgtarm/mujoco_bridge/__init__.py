"""MuJoCo bridge (issue 11, in progress): the robot exported as MJCF and loaded in MuJoCo.

Built so far: the export (:func:`to_mjcf`) and the mapping of our joint states onto MuJoCo's
(:class:`MujocoRobot`), checked against our model. Not built yet: the cross-validation command
and MuJoCo as the plant of the closed loop. See ``docs/mujoco.md`` for what MuJoCo can and
cannot match. MuJoCo is the optional extra ``vgtarm[mujoco]``; nothing else imports this package.
"""

from .export import to_mjcf

__all__ = ["to_mjcf"]
