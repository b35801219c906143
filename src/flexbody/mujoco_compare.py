"""The same body in MuJoCo, for a side-by-side comparison (optional: ``pip install flexbody[mujoco]``).

Each particle is a body on slide joints (two in 2D, three in 3D) carrying a small sphere
that collides with the grounds only; each link is a spatial tendon with the link's
stiffness, rest length and damping.  MuJoCo's tendon damping acts along the tendon, so the
comparison uses flexbody's ``axial`` damper.  MuJoCo's contact is soft; it is made as stiff
as MuJoCo recommends (``solref`` time constant = 2 time steps, critically damped), and
still penetrates, where flexbody's contact is exact.

A 2D scene's plane is MuJoCo's x-z plane: flexbody's ``(x, y)`` is MuJoCo's ``(x, 0, y)``.
A 3D scene keeps its axes.
"""

from __future__ import annotations

import contextlib
import time

import numpy as np

from .scene import Scene

SPHERE_RADIUS = 1e-3  # m: the contact geometry of a particle in MuJoCo


def _num(value) -> str:
    return repr(float(value))  # exact, and plain text for NumPy scalars too


def _vec(values) -> str:
    return " ".join(map(_num, values))


def _spatial(scene: Scene) -> np.ndarray:
    """The (dim, 3) map from flexbody's coordinates to MuJoCo's."""
    return np.eye(3) if scene.dim == 3 else np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def mjcf(scene: Scene, timestep: float) -> str:
    """MJCF text of ``scene``: its particles, links, gravity and grounds (2D or 3D)."""
    to3 = _spatial(scene)
    contact = f'solref="{_num(2 * timestep)} 1"'  # the stiffest MuJoCo allows: timeconst >= 2 dt
    parts = [
        f'<mujoco><option timestep="{_num(timestep)}" gravity="{_vec(np.asarray(scene.gravity) @ to3)}" '
        'integrator="implicitfast"/>',
        "<worldbody>",
    ]
    for ground in scene.grounds:
        normal = np.asarray(ground.normal) @ to3
        # the particle's sphere touches the plane when the particle itself reaches the ground
        origin = np.asarray(ground.point) @ to3 - SPHERE_RADIUS * normal
        axis = "" if np.array_equal(normal, [0.0, 0.0, 1.0]) else f' zaxis="{_vec(normal)}"'
        parts.append(f'<geom type="plane" size="10 10 0.1" pos="{_vec(origin)}"{axis} contype="0" '
                     f'conaffinity="1" {contact}/>')
    joints = "".join(f'<joint type="slide" axis="{_vec(axis)}"/>' for axis in to3)
    for i, (x, m) in enumerate(zip(scene.initial_positions() @ to3, scene.masses)):
        parts.append(
            f'<body name="p{i}" pos="{_vec(x)}">{joints}<site name="s{i}"/>'
            f'<geom type="sphere" size="{_num(SPHERE_RADIUS)}" mass="{_num(m)}" contype="1" conaffinity="0" '
            f'{contact}/></body>'
        )
    parts.append("</worldbody><tendon>")
    constants = (np.concatenate([getattr(b, name) for b in scene.bodies]) for name in
                 ("stiffness", "damping", "rest_lengths"))
    for (i, j), k, c, rest in zip(scene.links(), *constants):
        parts.append(
            f'<spatial stiffness="{_num(k)}" damping="{_num(c)}" springlength="{_num(rest)}">'
            f'<site site="s{i}"/><site site="s{j}"/></spatial>'
        )
    parts.append("</tendon></mujoco>")
    return "\n".join(parts)


def run(scene: Scene, timestep: float, repeats: int = 5) -> dict:
    """Simulate ``scene`` in MuJoCo (from the scene's initial velocities); median wall time,
    positions, heights and penetration.

    Returns
    -------
    dict
        ``time_s`` (median over ``repeats`` of an uninterrupted run), ``t (nt,)``,
        ``positions (nt, n, dim)`` (in flexbody's coordinates, m), ``heights (nt, n)``
        (along ``-gravity``, m), ``max_penetration_m`` (the deepest gap below any ground),
        ``diverged_at_s``: None, or when MuJoCo found its state unstable (NaN or huge
        accelerations) and reset it; positions from then on are NaN, and the (already
        meaningless) penetration too.
    """
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf(scene, timestep))
    n, dim = scene.n_particles, scene.dim
    steps = round(scene.simulation.t_end / timestep)
    v0 = scene.initial_velocities().ravel()  # the joints of a particle are its axes, in order

    def start():
        data = mujoco.MjData(model)
        data.qvel[:] = v0
        return data

    times = []
    with _quiet(mujoco):
        for _ in range(repeats):
            data = start()
            begin = time.perf_counter()
            mujoco.mj_step(model, data, nstep=steps)
            times.append(time.perf_counter() - begin)
        data = start()
        x0 = scene.initial_positions()
        positions = np.empty((steps + 1, n, dim))
        positions[0] = x0
        unstable = data.warning[mujoco.mjtWarning.mjWARN_BADQACC]
        diverged = None
        for k in range(1, steps + 1):
            mujoco.mj_step(model, data)
            if unstable.number:  # MuJoCo reset the state after a NaN or huge acceleration: nothing after counts
                diverged = k * timestep
                positions[k:] = np.nan
                break
            positions[k] = x0 + data.qpos.reshape(n, dim)
    up = -np.asarray(scene.gravity) / np.linalg.norm(scene.gravity)
    lowest = min((np.nanmin((positions - g.point) @ np.asarray(g.normal)) for g in scene.grounds), default=0.0)
    penetration = float(max(0.0, -lowest)) if diverged is None else float("nan")
    return {"time_s": float(np.median(times)), "t": np.arange(steps + 1) * timestep, "positions": positions,
            "heights": positions @ up, "max_penetration_m": penetration, "diverged_at_s": diverged,
            "version": mujoco.__version__}


@contextlib.contextmanager
def _quiet(mujoco):
    """Silence MuJoCo's warnings (printed, and appended to MUJOCO_LOG.TXT in the working
    folder): :func:`run` detects and reports the one that matters, instability."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda text: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)
