"""Constants shared by the Python runtime and the generated C (one source for both).

The code generator renders these into ``generated/runtime/fb_runtime.h``; the Python
modules import them from here, so a phase code or a tolerance cannot differ between the
two paths.
"""

#: Contact phases (see :mod:`flexbody.contact`).
FREE, HELD, PUSHED = 0, 1, 2
#: Event kinds as the compiled fixed point reports them.
IMPACT, LIFTOFF = 0, 1
#: Event roots closer than this (s) are one instant.
GROUP_TIME = 1e-12
#: Status codes of the compiled integrator (``fb_integrate``).
REACHED, EVENT, STEP_COLLAPSE, NON_FINITE, SINGULAR, TOO_SLOW = 0, 1, -1, -2, -3, -4

#: Rendered into C as ``#define FB_<NAME> <value>``.
C_DEFINES = {
    "FREE": FREE, "HELD": HELD, "PUSHED": PUSHED, "IMPACT": IMPACT, "LIFTOFF": LIFTOFF,
    "GROUP_TIME": repr(GROUP_TIME), "REACHED": REACHED, "EVENT": EVENT, "STEP_COLLAPSE": STEP_COLLAPSE,
    "NON_FINITE": NON_FINITE, "SINGULAR": SINGULAR, "TOO_SLOW": TOO_SLOW,
}  # fmt: skip
