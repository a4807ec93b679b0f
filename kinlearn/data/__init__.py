"""What the robot experiences and what it is asked: motor babbling, endpoint pairs, recorded logs, and
the planning problems every planner takes.

===================  ==========================================================================
babbling             :func:`babble`, :class:`BabblingConfig`, :class:`Transitions`,
                     :func:`save_transitions`, :func:`load_transitions`
endpoint pairs       :func:`make_endpoints`, :class:`EndpointConfig`, :class:`EndpointPairs`,
                     :func:`save_endpoints`, :func:`load_endpoints`
recorded data        :class:`Observations`, :func:`load_recorded`, :func:`load_data`,
                     :func:`load_observations`, :func:`save_recorded`
planning problems    :class:`Problem` (also ``kinlearn.Problem``); obstacle benchmark sets:
                     :func:`make_problems`, :class:`ProblemConfig`, :class:`ProblemSet`
===================  ==========================================================================

Each name is imported when first used.
"""

from typing import TYPE_CHECKING

from ..lazy import lazy_package

if TYPE_CHECKING:
    from .babbling import BabblingConfig, Transitions, babble, load_transitions, save_transitions
    from .endpoints import EndpointConfig, EndpointPairs, load_endpoints, make_endpoints, save_endpoints
    from .problem import Problem
    from .problems import ProblemConfig, ProblemSet, make_problems
    from .recorded import Observations, load_data, load_observations, load_recorded, save_recorded

__all__ = [
    "BabblingConfig",
    "EndpointConfig",
    "EndpointPairs",
    "Observations",
    "Problem",
    "ProblemConfig",
    "ProblemSet",
    "Transitions",
    "babble",
    "load_data",
    "load_endpoints",
    "load_observations",
    "load_recorded",
    "load_transitions",
    "make_endpoints",
    "make_problems",
    "save_endpoints",
    "save_recorded",
    "save_transitions",
]

__getattr__, __dir__ = lazy_package(__name__, __file__, __all__)
