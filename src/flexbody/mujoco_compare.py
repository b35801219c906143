"""The same ball in MuJoCo, for a side-by-side comparison (optional: ``pip install flexbody[mujoco]``).

Each particle is a body on two planar slide joints carrying a small sphere that collides
with the floor only; each link is a spatial tendon with the link's stiffness, rest length
and damping.  MuJoCo's tendon damping acts along the tendon, so the comparison uses
flexbody's ``axial`` damper.  MuJoCo's contact is soft; it is made as stiff as MuJoCo
recommends (``solref`` time constant = 2 time steps, critically damped), and still
penetrates, where flexbody's contact is exact.
"""

from __future__ import annotations

import time

import numpy as np

from .scene import Scene

SPHERE_RADIUS = 1e-3  # m: the contact geometry of a particle in MuJoCo


def _num(value) -> str:
    return repr(float(value))  # exact, and plain text for NumPy scalars too


def mjcf(scene: Scene, timestep: float) -> str:
    """MJCF text of a single-body scene on the ground y >= 0 (MuJoCo's z is flexbody's y)."""
    (body,) = scene.bodies
    x = scene.initial_positions()
    contact = f'solref="{_num(2 * timestep)} 1"'  # the stiffest MuJoCo allows: timeconst >= 2 dt
    parts = [
        f'<mujoco><option timestep="{_num(timestep)}" gravity="0 0 {_num(scene.gravity[1])}" integrator="implicitfast"/>',
        "<worldbody>",
        f'<geom type="plane" size="10 10 0.1" pos="0 0 {_num(-SPHERE_RADIUS)}" contype="0" conaffinity="1" {contact}/>',
    ]
    for i, (xi, yi) in enumerate(x):
        parts.append(
            f'<body name="p{i}" pos="{_num(xi)} 0 {_num(yi)}"><joint type="slide" axis="1 0 0"/>'
            f'<joint type="slide" axis="0 0 1"/><site name="s{i}"/>'
            f'<geom type="sphere" size="{_num(SPHERE_RADIUS)}" mass="{_num(body.masses[i])}" contype="1" conaffinity="0" {contact}/></body>'
        )
    parts.append("</worldbody><tendon>")
    for (i, j), k, c, rest in zip(body.links, body.stiffness, body.damping, body.rest_lengths):
        parts.append(
            f'<spatial stiffness="{_num(k)}" damping="{_num(c)}" springlength="{_num(rest)}">'
            f'<site site="s{i}"/><site site="s{j}"/></spatial>'
        )
    parts.append("</tendon></mujoco>")
    return "\n".join(parts)


def run(scene: Scene, timestep: float, repeats: int = 5) -> dict:
    """Simulate ``scene`` in MuJoCo; median wall time, heights, penetration, rebound.

    Returns
    -------
    dict
        ``time_s`` (median over ``repeats`` of an uninterrupted run), ``t (nt,)``,
        ``heights (nt, n)`` (particle heights above the ground, m), ``max_penetration_m``.
    """
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf(scene, timestep))
    n = scene.n_particles
    steps = int(round(scene.simulation.t_end / timestep))
    times = []
    for _ in range(repeats):
        data = mujoco.MjData(model)
        start = time.perf_counter()
        mujoco.mj_step(model, data, nstep=steps)
        times.append(time.perf_counter() - start)
    data = mujoco.MjData(model)
    y0 = scene.initial_positions()[:, 1]
    heights = np.empty((steps + 1, n))
    heights[0] = y0
    for k in range(1, steps + 1):
        mujoco.mj_step(model, data)
        heights[k] = y0 + data.qpos[1::2]
    return {"time_s": float(np.median(times)), "t": np.arange(steps + 1) * timestep, "heights": heights,
            "max_penetration_m": float(max(0.0, -heights.min())), "version": mujoco.__version__}
