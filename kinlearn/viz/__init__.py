"""Looking at plans: a GIF of the arm moving (:func:`animate_plan`, matplotlib) and an interactive
3-D view in the browser (:func:`show_plan`, viser).

Both take plain inputs: a :class:`~kinlearn.Robot`, a joint path ``(N, dof)``, and optionally
waypoints ``(M, 3)`` and the obstacles: a :class:`~kinlearn.collision.Scene` (``scene=``: spheres,
boxes in any orientation, cylinders), or spheres ``(K, 4)`` ``[x, y, z, r]``, boxes ``(B, 6)``
``[centre, half extents]`` (or ``(B, 15)`` with a rotation) and cylinders ``(C, 14)``, in metres. Their libraries are optional extras, imported only when used:
``pip install kinlearn[plots]`` for the animation, ``pip install kinlearn[viewer]`` for the viewer.
"""

from .animate import animate_plan
from .viewer import PlanViewer, show_plan

__all__ = ["PlanViewer", "animate_plan", "show_plan"]
