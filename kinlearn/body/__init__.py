"""The robot: URDF → serial chain and limits, its kinematics, the state layout.

==============  =============================================================================
robots          :class:`Robot`, :func:`load_robot`, :func:`register_robot`,
                :func:`unregister_robot`, :func:`available_robots`, :data:`ROBOTS`
kinematics      :class:`Kinematics`, :data:`BACKENDS`, :func:`dls_step`; the function
                ``kinematics(robot, backend)`` is ``kinlearn.kinematics`` (``kinlearn.body.kinematics``
                is its module)
states          :class:`StateLayout` (s = [θ, ef])
==============  =============================================================================

Each name is imported when first used (``kinlearn --help`` reads the bundled robots' names without torch).
"""

from typing import TYPE_CHECKING

from ..lazy import lazy_package

if TYPE_CHECKING:
    from .kinematics import BACKENDS, Kinematics, dls_step
    from .robot import ROBOTS, Robot, available_robots, load_robot, register_robot, unregister_robot
    from .state import StateLayout

__all__ = [
    "BACKENDS",
    "ROBOTS",
    "Kinematics",
    "Robot",
    "StateLayout",
    "available_robots",
    "dls_step",
    "load_robot",
    "register_robot",
    "unregister_robot",
]

__getattr__, __dir__ = lazy_package(__name__, __file__, __all__)
