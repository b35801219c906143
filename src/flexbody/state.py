"""Initial state of a scene in a model's coordinates (q, u)."""

from __future__ import annotations

import numpy as np

from .model import Model
from .scene import Scene


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def initial_coordinates(scene: Scene, model: Model) -> tuple[np.ndarray, np.ndarray]:
    """``q (nq,)`` and ``u (nu,)`` that place every particle where the scene says.

    For ``floating`` each body's T is rebuilt from its gauge (see
    :func:`flexbody.topology.gauge_particles`): origin at the anchor particle, x-axis
    towards the reference particle; its spin is the reference particle's angular rate
    about the anchor, and the particles' velocities in T are what remains.
    """
    x, v = scene.initial_positions(), scene.initial_velocities()
    if model.formulation == "particles":
        return x.ravel().copy(), v.ravel().copy()
    q, u, first = [], [], 0
    for body in model.manifest["topology"]["bodies"]:
        n = body["n_particles"]
        anchor, reference = body["gauge"]
        xb, vb = x[first : first + n], v[first : first + n]
        q += list(xb[anchor])
        u += list(vb[anchor])
        if n > 1:
            r = xb[reference] - xb[anchor]
            theta = np.arctan2(r[1], r[0])
            omega = _cross2(r, vb[reference] - vb[anchor]) / (r @ r)
            q.append(theta)
            u.append(omega)
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
