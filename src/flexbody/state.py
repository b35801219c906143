"""Initial state of a scene in a model's coordinates (q, u)."""

from __future__ import annotations

import numpy as np

from .errors import InputError
from .model import Model
from ._fields import Problems
from .scene import Scene, SceneError

#: A 3D floating body may not start with T's middle angle closer than this to +-90 deg (the
#: gimbal lock of its X-Y-Z angles, where the mass matrix is singular), in degrees.
GIMBAL_MARGIN_DEG = 10.0


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def initial_coordinates(scene: Scene, model: Model) -> tuple[np.ndarray, np.ndarray]:
    """``q (nq,)`` and ``u (nu,)`` that place every particle where the scene says.

    For ``floating`` each body's T is rebuilt from its gauge (see
    :func:`flexbody.topology.gauge_particles`): origin at the anchor particle, x-axis
    towards the reference particle (in 3D, x-y plane through the third particle); its spin
    is the gauge particles' rigid rotation about the anchor, and the particles' velocities
    in T are what remains.

    A rigid 3D body's T starts along its gauge particles' frame, or along N's axes where
    that frame would start near the lock (:func:`_rigid_frame`).

    Raises
    ------
    InputError
        A flexible 3D floating body that starts within ``GIMBAL_MARGIN_DEG`` of its angles'
        gimbal lock (T's z-axis along N's x-axis).
    """
    from .mixed import MixedModel

    inner = getattr(model, "inner", model)  # a body-contact model wraps it
    if isinstance(inner, MixedModel):
        return inner.initial_coordinates(scene)
    x, v = scene.initial_positions(), scene.initial_velocities()
    if model.formulation == "particles":
        return x.ravel().copy(), v.ravel().copy()
    q, u, first = [], [], 0
    for k, body in enumerate(model.manifest["topology"]["bodies"]):
        n = body["n_particles"]
        gauge = body["gauge"]
        xb, vb = x[first : first + n], v[first : first + n]
        if body.get("rigid") and n > 1:
            _check_rigid_motion(xb, vb, scene, k)
        if len(gauge) == 3 and n > 1:
            qb, ub = (_rigid_3d(xb, vb, gauge) if body.get("rigid")  # T alone: its particles are fixed in it
                      else _floating_3d(xb, vb, gauge, scene.bodies[k].name))
            q += qb
            u += ub
            first += n
            continue
        anchor, reference = gauge[:2]
        q += list(xb[anchor])
        u += list(vb[anchor])
        if n > 1:
            r = xb[reference] - xb[anchor]
            theta = np.arctan2(r[1], r[0])
            omega = _cross2(r, vb[reference] - vb[anchor]) / (r @ r)
            q.append(theta)
            u.append(omega)
            if body.get("rigid"):  # T alone: its particles are fixed in it
                first += n
                continue
            c, s = np.cos(theta), np.sin(theta)
            to_t = np.array([[c, s], [-s, c]])  # N components -> T components
            for i in range(n):
                if i == anchor:
                    continue
                ri = xb[i] - xb[anchor]
                rel = vb[i] - vb[anchor] - omega * np.array([-ri[1], ri[0]])
                local, local_v = to_t @ ri, to_t @ rel
                q.append(local[0])
                u.append(local_v[0])
                if i != reference:
                    q.append(local[1])
                    u.append(local_v[1])
        first += n
    return np.array(q), np.array(u)


def _check_rigid_motion(x: np.ndarray, v: np.ndarray, scene: Scene, body: int) -> None:
    """A rigid body's initial velocities must be a rigid motion ``v_i = v_c + w x r_i``.

    Raises
    ------
    flexbody.scene.SceneError
        At the body's ``particle_velocities``, saying how far off they are.
    """
    r = x - x.mean(axis=0)
    dv = v - v.mean(axis=0)
    if x.shape[1] == 2:  # least squares w: dv_i = w (-r_y, r_x)
        perp = np.column_stack([-r[:, 1], r[:, 0]])
        w = float(np.sum(perp * dv)) / max(float(np.sum(perp * perp)), 1e-300)
        residual = dv - w * perp
    else:
        A = np.concatenate([np.array([[0.0, ri[2], -ri[1]], [-ri[2], 0.0, ri[0]], [ri[1], -ri[0], 0.0]]) for ri in r])
        w = np.linalg.lstsq(A, dv.ravel(), rcond=None)[0]
        residual = dv - np.cross(w, r)
    scale = max(float(np.abs(v).max()), float(np.abs(dv).max()), 1e-12)
    if np.abs(residual).max() > 1e-9 * scale:
        problems = Problems()
        problems.add(f"bodies[{body}].particle_velocities", scene.bodies[body].particle_velocities.tolist(),
                     f"body {scene.bodies[body].name!r} is rigid, and these are not a rigid motion (off by up to "
                     f"{np.abs(residual).max():.3g} m/s); give it only `velocity` and `angular_velocity`")
        raise SceneError(scene.source, problems.items)


def rigid_parameters(scene: Scene, topology) -> dict[str, float]:
    """The fixed coordinates in T of each rigid body's particles (``rx<i>``, ``ry<i>``[, ``rz<i>``]):
    their initial positions in the frame T that :func:`initial_coordinates` starts the body in."""
    values: dict[str, float] = {}
    x, v = scene.initial_positions(), scene.initial_velocities()
    first = 0
    for body in topology.bodies:
        n, gauge = body.n_particles, body.gauge
        if body.rigid and n > 1:
            xb, vb = x[first : first + n], v[first : first + n]
            if len(gauge) == 3:
                R = _rigid_frame(xb, vb, gauge)[0]
            else:
                r = xb[gauge[1]] - xb[gauge[0]]
                c, s = r / np.linalg.norm(r)
                R = np.array([[c, -s], [s, c]])  # T's axes in N, as columns
            for i in range(n):
                if i != gauge[0]:
                    for axis, value in zip("xyz", R.T @ (xb[i] - xb[gauge[0]])):
                        values[f"r{axis}{first + i}"] = float(value)
        first += n
    return values


def gauge_frame(x: np.ndarray, v: np.ndarray, gauge) -> tuple[np.ndarray, np.ndarray]:
    """T of a 3D body from its gauge particles, and T's angular velocity.

    Parameters
    ----------
    x, v : ndarray, shape (n, 3)
        The body's particle positions and velocities in N.
    gauge : (anchor, reference, third)

    Returns
    -------
    R : ndarray, shape (3, 3)
        T's axes in N, as columns: x towards the reference, y in the plane of the third.
    omega : ndarray, shape (3,)
        T's angular velocity in N, ``omega = 1/2 sum_k e_k x e_k'``.
    """
    anchor, reference, third = gauge
    d, dd = x[reference] - x[anchor], v[reference] - v[anchor]
    e1 = d / np.linalg.norm(d)
    e1d = (dd - (dd @ e1) * e1) / np.linalg.norm(d)
    w, wd = x[third] - x[anchor], v[third] - v[anchor]
    p = w - (w @ e1) * e1
    pd = wd - (wd @ e1 + w @ e1d) * e1 - (w @ e1) * e1d
    e2 = p / np.linalg.norm(p)
    e2d = (pd - (pd @ e2) * e2) / np.linalg.norm(p)
    e3, e3d = np.cross(e1, e2), np.cross(e1d, e2) + np.cross(e1, e2d)
    omega = 0.5 * (np.cross(e1, e1d) + np.cross(e2, e2d) + np.cross(e3, e3d))
    return np.column_stack([e1, e2, e3]), omega


def xyz_angles(R: np.ndarray) -> np.ndarray:
    """Body-fixed X-Y-Z angles ``(alpha, beta, gamma)`` of ``R = Rx(alpha) Ry(beta) Rz(gamma)``, shape (3,)."""
    beta = np.arcsin(np.clip(R[0, 2], -1.0, 1.0))
    return np.array([np.arctan2(-R[1, 2], R[2, 2]), beta, np.arctan2(-R[0, 1], R[0, 0])])


def xyz_rates(angles: np.ndarray, omega_t: np.ndarray) -> np.ndarray:
    """The angles' rates (3,) for an angular velocity with components ``omega_t`` (3,) in T."""
    _, b, c = angles
    B = np.array([[np.cos(b) * np.cos(c), np.sin(c), 0.0],
                  [-np.cos(b) * np.sin(c), np.cos(c), 0.0],
                  [np.sin(b), 0.0, 1.0]])  # omega_t = B @ rates
    return np.linalg.solve(B, omega_t)


def _rigid_frame(x: np.ndarray, v: np.ndarray, gauge) -> tuple[np.ndarray, np.ndarray]:
    """A rigid 3D body's T at the start, its axes in N as columns (3, 3): its gauge
    particles' frame (:func:`gauge_frame`), or N's axes where that frame's X-Y-Z angles would
    start within ``GIMBAL_MARGIN_DEG`` of their gimbal lock; and the body's angular velocity
    in N (3,), the same in any frame fixed in it.  Any such frame will do (its particles'
    places in T are parameters, :func:`rigid_parameters`), and N's starts the angles at 0,
    as far from the lock as they can be (a fuzz's rigid sphere was refused 2.3 deg from it)."""
    R, omega = gauge_frame(x, v, gauge)
    return (R if abs(np.degrees(xyz_angles(R)[1])) <= 90.0 - GIMBAL_MARGIN_DEG else np.eye(3)), omega


def _rigid_3d(x: np.ndarray, v: np.ndarray, gauge) -> tuple[list, list]:
    """A rigid 3D body's six coordinates and their rates: T's origin at the anchor particle,
    its axes :func:`_rigid_frame`'s."""
    R, omega = _rigid_frame(x, v, gauge)
    angles = xyz_angles(R)
    anchor = gauge[0]
    return list(x[anchor]) + list(angles), list(v[anchor]) + list(xyz_rates(angles, R.T @ omega))


def _floating_3d(x: np.ndarray, v: np.ndarray, gauge, name: str) -> tuple[list, list]:
    anchor, reference, third = gauge
    R, omega = gauge_frame(x, v, gauge)
    angles = xyz_angles(R)
    if abs(np.degrees(angles[1])) > 90.0 - GIMBAL_MARGIN_DEG:
        raise InputError(
            f"body {name!r}: in the floating formulation its frame T (origin at particle {anchor}, x-axis through "
            f"particle {reference}, x-y plane through particle {third}) starts with its z-axis "
            f"{90.0 - abs(np.degrees(angles[1])):.3g} deg from N's x-axis; T's X-Y-Z angles must start at least "
            f"{GIMBAL_MARGIN_DEG:g} deg from that gimbal lock: rotate the body, or use the particles formulation"
        )
    rates = xyz_rates(angles, R.T @ omega)
    q, u = list(x[anchor]) + list(angles), list(v[anchor]) + list(rates)
    for i in range(len(x)):
        if i == anchor:
            continue
        r = x[i] - x[anchor]
        local, local_v = R.T @ r, R.T @ (v[i] - v[anchor] - np.cross(omega, r))
        kept = 1 if i == reference else 2 if i == third else 3
        q += list(local[:kept])
        u += list(local_v[:kept])
    return q, u
