"""Constants shared by the Python runtime and the generated C (one source for both).

The code generator renders these into ``generated/runtime/fb_runtime.h``; the Python
modules import them from here, so a phase code or a tolerance cannot differ between the
two paths.
"""

#: Contact phases (see :mod:`flexbody.contact`).  HELD sticks where the ground has friction;
#: SLIDING is held along the normal and slips along the ground against Coulomb friction.
#: The two held along the normal are the odd codes (:attr:`flexbody.contact.Phases.held`).
FREE, HELD, PUSHED, SLIDING = 0, 1, 2, 3
#: Event kinds as the compiled fixed point reports them.
IMPACT, LIFTOFF, STICK, SLIP = 0, 1, 2, 3
#: What an impulse does to a contact (``stop[c]`` of ``FbSystem.impact``): nothing, stop its
#: normal velocity (plastic), or reverse it by the ground's restitution ``v_n+ = -e v_n-``.
#: Both apply the ground's Coulomb friction impulse, ``min(m |v_t|, mu P_n)`` against ``v_t``.
#: SETTLE also zeroes the tangential velocity (a sliding contact that comes to rest).
KEEP, STOP, REBOUND, SETTLE = 0, 1, 2, 3
#: A rebound that would rise less than this fraction of the scene's size is plastic: it
#: ends the Zeno accumulation of ever smaller bounces (DESIGN §6).
ZENO_RISE = 1e-9
#: Event roots closer than this (s) are one instant.
GROUP_TIME = 1e-12
#: A speed below this (relative to the largest speed, at least 1 m/s) is round-off of the
#: velocities (a joint stop or a rigid body's spin leaves ~1e-17 m/s): a slip of that
#: size gives no sliding direction, a normal speed of that size is at rest.
VELOCITY_ROUNDOFF = 1e-13
#: Status codes of the compiled integrator (``fb_integrate``).
REACHED, EVENT, STEP_COLLAPSE, NON_FINITE, SINGULAR, TOO_SLOW = 0, 1, -1, -2, -3, -4

#: The feature of a surface a particle is closest to: the element itself (a segment in 2D, a
#: triangle in 3D), an edge of it (3D) or a vertex (see :mod:`flexbody.surface_contact`).
FACE, EDGE, VERTEX = 0, 1, 2

#: How the compiled pivots of Lemke's method end (``fb_lemke``, :mod:`flexbody.lcp`).
LEMKE_SOLVED, LEMKE_RAY, LEMKE_LIMIT = 0, 1, 2

#: Rendered into C as ``#define FB_<NAME> <value>``.
C_DEFINES = {
    "FREE": FREE, "HELD": HELD, "PUSHED": PUSHED, "SLIDING": SLIDING,
    "IMPACT": IMPACT, "LIFTOFF": LIFTOFF, "STICK": STICK, "SLIP": SLIP,
    "KEEP": KEEP, "STOP": STOP, "REBOUND": REBOUND, "SETTLE": SETTLE,
    "GROUP_TIME": repr(GROUP_TIME), "REACHED": REACHED, "EVENT": EVENT, "STEP_COLLAPSE": STEP_COLLAPSE,
    "NON_FINITE": NON_FINITE, "SINGULAR": SINGULAR, "TOO_SLOW": TOO_SLOW,
    "FACE": FACE, "EDGE": EDGE, "VERTEX": VERTEX,
    "LEMKE_SOLVED": LEMKE_SOLVED, "LEMKE_RAY": LEMKE_RAY, "LEMKE_LIMIT": LEMKE_LIMIT,
}  # fmt: skip
