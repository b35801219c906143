"""The named choices of a scene and of the command line.

Kept apart from :mod:`flexbody.scene` (which needs NumPy) so that ``flexbody --help``
and argument errors answer without importing NumPy, SciPy or matplotlib.
"""

from __future__ import annotations

SHAPES = ("ring", "ellipse", "polygon", "chain", "disc", "sphere", "box", "mesh")
#: Presets that are bodies in space only (the others lie in T's x-y plane, in 2D or 3D).
SPATIAL_SHAPES = ("sphere", "box", "mesh")
DAMPERS = ("relative", "axial")
#: Compiled in C (generated integrator.c, needs backend "c"), then SciPy's solve_ivp methods.
COMPILED_METHODS = ("dopri5", "dop853")
METHODS = COMPILED_METHODS + ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
FORMULATIONS = ("particles", "floating")
BACKENDS = ("c", "numpy")
IMPACT_MODES = ("instant", "thesis")

#: Upper bounds that keep a scene or a run allocatable (a typo such as ``count = 1e12``
#: must be an error, not a MemoryError or an hour of swapping).
MAX_PARTICLES = 1_000_000
MAX_SAMPLES = 10_000_000
#: Default ``--max-wall-time`` of ``flexbody run`` (s).
DEFAULT_MAX_WALL_TIME = 600.0
#: Default ``simulation.chatter_impacts``: a particle with more impacts than this within
#: ``CHATTER_WINDOW`` (in a row without being held, those slowing as a Zeno cascade does
#: not counted, or held and released again) is chattering, and the run stops
#: (:meth:`flexbody.driver._Run.check_guards`, :data:`CASCADE_FALL`).
CHATTER_IMPACTS = 25
#: The chatter guard's window (s).
CHATTER_WINDOW = 1e-3
#: An impact in a row of rebounds (none held) that comes in slower than this fraction of the
#: one before continues a Zeno cascade, which the plastic threshold ends: it is not counted
#: toward the bound.  A particle of a flexible body bouncing on a ground at e = 0.923, its
#: springs' pull far above gravity, came in at e times its last speed each time, 90 impacts
#: from 0.73 m/s down to the threshold's 7.7e-4 m/s, 40 of them within its last 1 ms, and
#: ended held; the guard stopped it at the 26th within 1 ms.  At this fraction a cascade
#: falls at least 1 % an impact: from 10 m/s to 1e-6 m/s within 1 604 impacts.  Rows that
#: do not slow (a particle rattling between two surfaces at e = 1, at one speed) count whole.
CASCADE_FALL = 0.99
