"""Rigid and flexible bodies in one model, each kind in its own form.

A scene's bodies act on each other only through their contacts, so its free dynamics split
by body: the flexible bodies are assembled from the element kernels on their particle
coordinates (any size, nothing derived per scene, :mod:`flexbody.assembly`), and the rigid
bodies are frames T without elastic coordinates, derived whole by Kane's method for the
rigid bodies alone (:func:`flexbody.model.load_derived_model` on the scene's rigid part: a
frame costs about what three particles do, whatever the size of the flexible bodies).  A
:class:`MixedModel` puts the two side by side as one model of the scene, in the scene's
particle and contact numbering; the contacts that couple through a rigid body (its ground
contacts, contacts between bodies) are solved by :class:`flexbody.body_contact.BodyContactModel`,
which always wraps it.

State layout: ``y = [q_f, q_r, u_f, u_r, w]``: the flexible bodies' particle positions
(their particles in scene order), the rigid frames' coordinates, the same for the
velocities, then ``w = [damping work, impact work]``, shared.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re

import numpy as np

from . import runtime
from .assembly import AssembledModel, assembled_model
from .model import GeneratedModel, Model
from .scene import Scene

FloatArray = np.ndarray
IntArray = np.ndarray


@dataclasses.dataclass(frozen=True)
class ScenePart:
    """One kind of the scene's bodies as a scene of its own.

    Attributes
    ----------
    scene : Scene
        The bodies of that kind alone (no contacts between bodies), the same grounds and gravity.
    particles : ndarray of int, shape (n_part,)
        Each of its particles' index in the whole scene.
    bodies : ndarray of int, shape (b_part,)
        Each of its bodies' index in the whole scene.
    """

    scene: Scene
    particles: IntArray
    bodies: IntArray


def split_scene(scene: Scene) -> tuple[ScenePart, ScenePart]:
    """The flexible bodies and the rigid bodies of ``scene`` as two scenes (in that order)."""
    counts = np.array([b.n_particles for b in scene.bodies])
    first = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)

    def part(rigid: bool, suffix: str) -> ScenePart:
        bodies = np.array([k for k, b in enumerate(scene.bodies) if b.rigid == rigid], np.intp)
        particles = np.concatenate([np.arange(first[k], first[k] + counts[k]) for k in bodies] or
                                   [np.zeros(0, np.intp)]).astype(np.intp)
        sub = dataclasses.replace(scene, name=f"{scene.name}_{suffix}", bodies=tuple(scene.bodies[k] for k in bodies),
                                  contacts=())
        return ScenePart(sub, particles, bodies)

    return part(False, "flexible"), part(True, "rigid")


class MixedModel(Model):
    """Flexible bodies assembled on particles and rigid bodies derived as frames, side by side.

    Parameters
    ----------
    scene : Scene
        With at least one flexible and one rigid body.
    flexible : AssembledModel
        The model of ``split_scene(scene)[0].scene``.
    rigid : GeneratedModel
        The floating-formulation model of ``split_scene(scene)[1].scene`` (frames alone).

    Attributes
    ----------
    rigid_particle : ndarray of bool, shape (n,)
        Whether each particle belongs to a rigid body.
    representative : ndarray of int, shape (n,)
        The particle itself for a flexible one; its rigid body's first particle for a rigid
        one: two contacts act on each other only through a shared representative.
    """

    formulation = "particles"  # the flexible bodies'; a rigid body is its frame in every formulation
    coupled = True
    compiled_segments = False

    def __init__(self, scene: Scene, flexible: AssembledModel, rigid: GeneratedModel) -> None:
        self.flexible, self.rigid = flexible, rigid
        self.flexible_part, self.rigid_part = split_scene(scene)
        self.backend, self.dim = flexible.backend, scene.dim
        self.n_particles, self.n_grounds = scene.n_particles, len(scene.grounds)
        self.masses = scene.masses.copy()
        f, r = flexible, rigid
        self.nq, self.nu = f.nq + r.nq, f.nu + r.nu
        self.ny = self.nq + self.nu + 2
        self.n_contacts = self.n_particles * self.n_grounds
        self.contacts = np.indices((self.n_particles, self.n_grounds)).reshape(2, -1).T  # particle-major
        self.laws = f.laws
        # each part's state entries in the whole state (w shared), and its contacts in the scene's numbering
        w = [self.nq + self.nu, self.nq + self.nu + 1]
        self._y_f = np.concatenate([np.arange(f.nq), self.nq + np.arange(f.nu), w]).astype(np.intp)
        self._y_r = np.concatenate([f.nq + np.arange(r.nq), self.nq + f.nu + np.arange(r.nu), w]).astype(np.intp)
        grounds = np.arange(self.n_grounds)
        self._c_f = (self.flexible_part.particles[:, None] * self.n_grounds + grounds).ravel()
        self._c_r = (self.rigid_part.particles[:, None] * self.n_grounds + grounds).ravel()
        self.rigid_particle = np.zeros(self.n_particles, bool)
        self.rigid_particle[self.rigid_part.particles] = True
        #: Each flexible particle's index among the flexible ones, each rigid one's among the rigid ones.
        self.local = np.zeros(self.n_particles, np.intp)
        self.local[self.flexible_part.particles] = np.arange(len(self.flexible_part.particles))
        self.local[self.rigid_part.particles] = np.arange(len(self.rigid_part.particles))
        self.representative = np.arange(self.n_particles)
        counts = [b.n_particles for b in scene.bodies]
        starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.intp)
        for k in self.rigid_part.bodies:
            self.representative[starts[k] : starts[k + 1]] = starts[k]
        self.q_names = tuple(f"{a}{i}" for i in self.flexible_part.particles for a in "xyz"[: self.dim]) + tuple(
            _renumbered(name, self.rigid_part.bodies) for name in r.q_names)
        self._slip = np.zeros((self.n_contacts, self.dim))
        self._slip_held = np.zeros(self.n_contacts, np.intc)
        self._push_t = np.zeros((self.n_contacts, self.dim))
        # p: the flexible part's parameters first (their count is fixed by its topology), then the rigid part's
        self._n_p_f = len(flexible.parameters(self.flexible_part.scene))
        self._parts_of: tuple[FloatArray, FloatArray, FloatArray] | None = None  # (p, its parts; see _p)
        text = f"{f.digest}|{r.digest}|{self.rigid_part.particles.tolist()}"
        self.digest = hashlib.sha256(f"mixed|{text}".encode()).hexdigest()[:16]

    @property
    def threads(self) -> int:
        """Threads of the right-hand side: the flexible part's (set when its system is made)."""
        return self.flexible.threads

    # ------------------------------------------------------------------ splitting and joining
    def parameters(self, scene: Scene) -> FloatArray:
        """``p``: the flexible part's parameters, then the rigid part's (each in its model's order)."""
        flexible, rigid = split_scene(scene)
        return np.concatenate([self.flexible.parameters(flexible.scene), self.rigid.parameters(rigid.scene)])

    def _p(self, p) -> tuple[FloatArray, FloatArray]:
        """Each part's parameters from the whole ``p``.  For a read-only ``p`` (the driver's,
        which nobody changes) they are read-only copies made once and handed out again: a
        part's C model then knows them for the ones it is bound to without comparing them
        (:meth:`flexbody.runtime.SystemModel.system`; a new slice at every call was compared
        in full each time, ~3 % of a disc landing on a rigid block)."""
        p = np.asarray(p, float)
        if not runtime.fixed(p):
            return p[: self._n_p_f], p[self._n_p_f :]
        if self._parts_of is None or self._parts_of[0] is not p:
            parts = [p[: self._n_p_f].copy(), p[self._n_p_f :].copy()]
            for part in parts:
                part.flags.writeable = False
            self._parts_of = (p, *parts)
        return self._parts_of[1], self._parts_of[2]

    def _parts(self, y, p) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Each part's state and parameters from the whole state ``y (ny,)``."""
        y = np.asarray(y, float)
        return (y[self._y_f], y[self._y_r], *self._p(p))

    def _q(self, q) -> tuple[FloatArray, FloatArray]:
        q = np.asarray(q, float)
        return q[: self.flexible.nq], q[self.flexible.nq : self.nq]

    def _u(self, u) -> tuple[FloatArray, FloatArray]:
        u = np.asarray(u, float)
        return u[: self.flexible.nu], u[self.flexible.nu : self.nu]

    def _joined(self, ydot_f: FloatArray, ydot_r: FloatArray) -> FloatArray:
        ydot = np.zeros(self.ny)
        ydot[self._y_f] = ydot_f
        ydot[self._y_r[:-2]] = ydot_r[:-2]
        ydot[-2:] += ydot_r[-2:]  # the works add
        return ydot

    def _contacts(self, lam_f: FloatArray, lam_r: FloatArray) -> FloatArray:
        out = np.zeros(self.n_contacts)
        out[self._c_f], out[self._c_r] = lam_f, lam_r
        return out

    def _share_slips(self, p_f) -> None:
        """The flexible part's ground contacts slide along this model's slip directions."""
        self.flexible.slip_directions(p_f)[:] = self._slip[self._c_f]
        self.flexible.slips_held(p_f)[:] = self._slip_held[self._c_f]

    # ------------------------------------------------------------------ the model interface
    def particle_state(self, q, u, p) -> tuple[FloatArray, FloatArray | None]:
        """Particle positions and velocities (n, dim) each in N (velocities None without ``u``)."""
        return self.particle_positions(q, p), None if u is None else self.particle_velocities(q, u, p)

    def particle_positions(self, q, p) -> FloatArray:
        """Particle positions (n, dim) in N."""
        (q_f, q_r), (_, p_r) = self._q(q), self._p(p)
        x = np.empty((self.n_particles, self.dim))
        x[self.flexible_part.particles] = q_f.reshape(-1, self.dim)
        x[self.rigid_part.particles] = self.rigid.positions(q_r, p_r)
        return x

    def particle_velocities(self, q, u, p) -> FloatArray:
        """Particle velocities (n, dim) in N."""
        (_, q_r), (u_f, u_r), (_, p_r) = self._q(q), self._u(u), self._p(p)
        v = np.empty((self.n_particles, self.dim))
        v[self.flexible_part.particles] = u_f.reshape(-1, self.dim)
        v[self.rigid_part.particles] = self.rigid.velocities(q_r, u_r, p_r)
        return v

    def ground_normals(self, p) -> FloatArray:
        """Each ground's unit normal, shape (n_grounds, dim): the flexible part's."""
        return self.flexible.ground_normals(self._p(p)[0])

    def rigid_state(self, q, u, p) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The rigid part's ``q_r (nq_r,)``, ``u_r (nu_r,)`` and ``p_r`` (its model's order)."""
        return self._q(q)[1], self._u(u)[1], self._p(p)[1]

    def gaps(self, q, p) -> FloatArray:
        (q_f, q_r), (p_f, p_r) = self._q(q), self._p(p)
        return self._contacts(self.flexible.gaps(q_f, p_f), self.rigid.gaps(q_r, p_r))

    def energies(self, q, u, p) -> FloatArray:
        """[kinetic, spring, gravity, damping power], shape (4,): the parts' summed."""
        y = np.concatenate([q, u, [0.0, 0.0]])
        return self.trajectory(y[None], p, np.zeros((1, self.n_contacts), np.intc), np.zeros((1, self.n_contacts)))[2][0]

    def rhs(self, y, p, held, push) -> tuple[FloatArray, FloatArray]:
        y_f, y_r, p_f, p_r = self._parts(y, p)
        held, push = np.asarray(held, np.intc), np.asarray(push, float)
        self._share_slips(p_f)
        ydot_f, lam_f = self.flexible.rhs(y_f, p_f, held[self._c_f], push[self._c_f])
        ydot_r, lam_r = self.rigid.rhs(y_r, p_r, held[self._c_r], push[self._c_r])
        return self._joined(ydot_f, ydot_r), self._contacts(lam_f, lam_r)

    def contact_state(self, y, p, held, push) -> tuple[FloatArray, FloatArray, FloatArray]:
        y_f, y_r, p_f, p_r = self._parts(y, p)
        held, push = np.asarray(held, np.intc), np.asarray(push, float)
        self._share_slips(p_f)
        f = self.flexible.contact_state(y_f, p_f, held[self._c_f], push[self._c_f])
        r = self.rigid.contact_state(y_r, p_r, held[self._c_r], push[self._c_r])
        return tuple(self._contacts(a, b) for a, b in zip(f, r))

    def friction(self, y, p, held, push) -> tuple[FloatArray, FloatArray, FloatArray]:
        """As :meth:`flexbody.assembly.AssembledModel.friction` for the flexible particles'
        ground contacts; a rigid body's are none here (they couple: held with friction, they
        are solved by :class:`flexbody.body_contact.BodyContactModel`)."""
        y_f, _, p_f, _ = self._parts(y, p)
        held, push = np.asarray(held, np.intc), np.asarray(push, float)
        vt, ft = np.zeros((self.n_contacts, self.dim)), np.zeros((self.n_contacts, self.dim))
        slack = np.full(self.n_contacts, np.inf)
        self._share_slips(p_f)
        vt[self._c_f], ft[self._c_f], slack[self._c_f] = self.flexible.friction(y_f, p_f, held[self._c_f],
                                                                              push[self._c_f])
        return vt, ft, slack

    def slip_directions(self, p) -> FloatArray:
        """Each sliding contact's slip direction at the step's start, (nc, dim), writable."""
        return self._slip

    def slips_held(self, p) -> np.ndarray:
        """Where a sliding contact keeps its direction through the step, (nc,) int, writable."""
        return self._slip_held

    def tangential_pushes(self, p) -> FloatArray:
        """None are pushed: the thesis impact mode is refused with rigid bodies."""
        return self._push_t

    def trajectory(self, Y, p, held, push) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        Y = np.asarray(Y, float)
        held, push = np.asarray(held), np.asarray(push, float)
        p_f, p_r = self._p(p)
        self._share_slips(p_f)
        X_f, V_f, E_f, lam_f = self.flexible.trajectory(Y[:, self._y_f], p_f, held[:, self._c_f], push[:, self._c_f])
        X_r, V_r, E_r, lam_r = self.rigid.trajectory(Y[:, self._y_r], p_r, held[:, self._c_r], push[:, self._c_r])
        nt, n, d = len(Y), self.n_particles, self.dim
        X, V = np.empty((nt, n, d)), np.empty((nt, n, d))
        X[:, self.flexible_part.particles], X[:, self.rigid_part.particles] = X_f, X_r
        V[:, self.flexible_part.particles], V[:, self.rigid_part.particles] = V_f, V_r
        lam = np.zeros((nt, self.n_contacts))
        lam[:, self._c_f], lam[:, self._c_r] = lam_f, lam_r
        return X, V, np.asarray(E_f) + np.asarray(E_r), lam

    def jacobian_function(self, p, held):
        """``J(t, y)`` (ny, ny), sparse: each part's, placed on its entries of the state."""
        from scipy import sparse

        held = np.asarray(held)
        p_f, p_r = self._p(p)
        parts = [(self.flexible.jacobian_function(p_f, held[self._c_f]), self._y_f),
                 (self.rigid.jacobian_function(p_r, held[self._c_r]), self._y_r)]

        def jacobian(t, y):
            y = np.asarray(y, float)
            rows, cols, values = [], [], []
            for function, index in parts:
                block = sparse.coo_matrix(function(t, y[index]))
                rows.append(index[block.row])
                cols.append(index[block.col])
                values.append(block.data)
            shape = (self.ny, self.ny)
            return sparse.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape)

        return jacobian

    def initial_coordinates(self, scene: Scene) -> tuple[FloatArray, FloatArray]:
        """``q (nq,)`` and ``u (nu,)`` placing every particle where ``scene`` says."""
        from .state import initial_coordinates

        x, v = scene.initial_positions(), scene.initial_velocities()
        q_r, u_r = initial_coordinates(self.rigid_part.scene, self.rigid)
        particles = self.flexible_part.particles
        return np.concatenate([x[particles].ravel(), q_r]), np.concatenate([v[particles].ravel(), u_r])


def _renumbered(name: str, bodies: IntArray) -> str:
    """A rigid part's coordinate name (``theta0``, ``beta1``) with its body's index in the whole scene."""
    match = re.fullmatch(r"([A-Za-z_]+)(\d+)", name)
    return name if match is None else f"{match.group(1)}{bodies[int(match.group(2))]}"


def mixed_model(scene: Scene, backend: str = "c") -> MixedModel:
    """The :class:`MixedModel` of a scene with flexible and rigid bodies (``backend`` "c" or "numpy")."""
    from .model import BACKENDS, derive_on_demand, find_model_dir

    flexible, rigid = split_scene(scene)
    folder = find_model_dir(rigid.scene, "floating") or derive_on_demand(rigid.scene, "floating")
    return MixedModel(scene, assembled_model(flexible.scene, backend), BACKENDS[backend](folder))
