"""The particles formulation of any scene, assembled from the element kernels.

No scene is derived or compiled: the runtime builds index arrays from the scene (links,
their damper laws, particles, contacts) and evaluates the element kernels of
``generated/kernels`` over them, in C (``generated/runtime/assembly.c``, one library per
install) or in NumPy (``generated/kernels/kernels.py``, vectorised over elements).  Time
and memory are O(particles + links); the mass matrix is diagonal, so contacts are solved
per particle (exactly: ``J M^-1 J^T`` is block diagonal by particle).

q are the particle positions in N, ``(n, dim)`` flattened; u their velocities; the
parameter vector p is in the order of the whole-scene derivation (masses, stiffness,
damping, rest lengths, gravity, then each ground's point and normal), so the assembled
and the derived equations can be compared at the same ``(y, p)``.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import json

import numpy as np

from . import runtime
from .cbuild import kernels_dir
from .constants import HELD, REBOUND, SETTLE, SLIDING
from .model import Model, singular_matrix_error
from .scene import Scene

FloatArray = np.ndarray
IntArray = np.ndarray


def scene_parameters(scene: Scene) -> FloatArray:
    """The parameter vector ``p`` of ``scene`` (see the module docstring), shape (np,)."""
    bodies = scene.bodies
    grounds = [np.concatenate([g.point, g.normal]) for g in scene.grounds]
    parts = [scene.masses] + [np.concatenate([getattr(b, name) for b in bodies]) if bodies else np.zeros(0)
                              for name in ("stiffness", "damping", "rest_lengths")]
    return np.concatenate(parts + [np.asarray(scene.gravity, float)] + grounds).astype(float)


def _kernel_sources_digest() -> str:
    """Hash of the element kernels' generated sources (from their manifest)."""
    manifest = json.loads((kernels_dir() / "manifest.json").read_text())
    return hashlib.sha256(json.dumps(manifest["sha256"], sort_keys=True).encode()).hexdigest()


class AssembledModel(Model):
    """Common part of both backends: index arrays, sizes, parameters.

    Attributes
    ----------
    links : ndarray of int, shape (n_links, 2)
    axial : ndarray of bool, shape (n_links,)
        True where the link's damper is axial, False where it is relative.
    masses : ndarray, shape (n,)
    """

    formulation = "particles"

    def __init__(self, scene: Scene) -> None:
        self.dim = scene.dim
        self.n_particles = n = scene.n_particles
        self.n_grounds = len(scene.grounds)
        self.links = np.ascontiguousarray(scene.links(), dtype=np.intc).reshape(-1, 2)
        self.axial = np.concatenate([np.full(len(b.links), b.damper == "axial") for b in scene.bodies])
        self.masses = scene.masses.copy()
        # Contact laws per ground (mu, e): runtime data, not parameters of the derived equations.
        self.laws = np.array([[g.friction, g.restitution] for g in scene.grounds], float).reshape(-1, 2)
        self._slip = np.zeros((self.n_particles * len(scene.grounds), 3))  # the NumPy twin's FbSystem.slip
        self._slip_held = np.zeros(len(self._slip), np.intc)  # FbSystem.slip_held
        self._tangential_push = np.zeros_like(self._slip)  # and its FbSystem.tangential_push
        self.nq = self.nu = n * self.dim
        self.ny = 2 * self.nq + 2
        self.n_contacts = n * self.n_grounds
        self.contacts = np.indices((n, self.n_grounds)).reshape(2, -1).T  # (particle, ground), particle-major
        text = json.dumps([self.dim, n, self.n_grounds, self.links.tolist(), self.axial.tolist()])
        self.digest = hashlib.sha256(f"assembled|{text}|{_kernel_sources_digest()}".encode()).hexdigest()[:16]

    def parameters(self, scene: Scene) -> FloatArray:
        return scene_parameters(scene)

    def slip_directions(self, p) -> FloatArray:
        """Each sliding contact's slip direction at the start of the step, shape (nc, dim), a
        writable view (``FbSystem.slip``): past the stop the friction force continues along it
        (see ``coulomb`` in assembly.c).  Zero it for outputs: then the law is the physical one."""
        return self._slip[:, : self.dim]

    def slips_held(self, p) -> np.ndarray:
        """Where a sliding contact's friction keeps its slip direction through the whole step,
        shape (nc,), int, a writable view (``FbSystem.slip_held``): a 3D slip slower than the
        speed tolerance at the step's start, or inside its cone and slow enough for friction
        alone to stop it within the step (see ``friction_event`` in integrator.c).  Zero it
        with the directions for outputs."""
        return self._slip_held

    def tangential_pushes(self, p) -> FloatArray:
        """The thesis impact mode's tangential force on each pushed contact (N), shape (nc, dim),
        a writable view (``FbSystem.tangential_push``): :func:`flexbody.contact.resolve` sets
        it when a window starts and zeroes it when the window ends; the right-hand side applies
        it where ``push`` is nonzero."""
        return self._tangential_push[:, : self.dim]

    def _split(self, y):
        return y[: self.nq].reshape(-1, self.dim), y[self.nq : 2 * self.nq].reshape(-1, self.dim)

    def _views(self, p):
        """Masses (n,), packed link parameters (3, n_links), gravity (dim,), grounds (G, 2, dim)."""
        n, nl, d = self.n_particles, len(self.links), self.dim
        link_par = p[n : n + 3 * nl].reshape(3, nl)
        gravity = p[n + 3 * nl : n + 3 * nl + d]
        grounds = p[n + 3 * nl + d :].reshape(self.n_grounds, 2, d)
        return p[:n], link_par, gravity, grounds

    def ground_normals(self, p) -> FloatArray:
        """Each ground's unit normal, shape (n_grounds, dim) (from ``p``)."""
        return self._views(np.asarray(p, float))[3][:, 1]

    # ------------------------------------------------------------------ sparse Jacobian
    def jacobian_function(self, p, held):
        """``J(t, y)`` of the constrained right-hand side as a sparse matrix (ny, ny).

        Exact for free contacts; a held particle's acceleration rows are projected onto its
        constraint (the variation of the constraint itself is neglected), which is what an
        implicit method's Newton iteration needs.
        """
        from scipy import sparse

        n, d, nq, nl = self.n_particles, self.dim, self.nq, len(self.links)
        codes = np.asarray(held).reshape(n, self.n_grounds)
        held = codes != 0
        masses, _, _, grounds = self._views(np.asarray(p, float))
        # Each link's force on i depends on [x_i, x_j, v_i, v_j]; i gets +f/m_i, j gets -f/m_j.
        ends = self.links.astype(np.int64)
        col_particle = np.stack([ends[:, 0], ends[:, 1], ends[:, 0], ends[:, 1]], axis=1)  # (nl, 4)
        col_offset = np.array([0, 0, nq, nq])  # x or v block
        a, b, k = np.meshgrid(np.arange(d), np.arange(d), np.arange(4), indexing="ij")  # row comp, col comp, block
        rows_i = nq + d * ends[:, 0, None, None, None] + a
        rows_j = nq + d * ends[:, 1, None, None, None] + a
        cols = col_offset[k] + d * col_particle[:, None, None, :] + b
        rows = np.concatenate([rows_i, rows_j]).ravel()
        cols = np.concatenate([cols, cols]).ravel()
        sign_mass = np.concatenate([1.0 / masses[ends[:, 0]], -1.0 / masses[ends[:, 1]]])
        kinematics = sparse.coo_matrix((np.ones(nq), (np.arange(nq), nq + np.arange(nq))), shape=(self.ny, self.ny))
        projector = self._held_projector(held, grounds, codes)

        def jacobian(t, y):
            jac = self.link_jacobians(y, p).reshape(nl, d, 4, d)  # (link, row comp, block, col comp)
            values = (np.concatenate([jac, jac]).transpose(0, 1, 3, 2) * sign_mass[:, None, None, None]).ravel()
            A = sparse.coo_matrix((values, (rows, cols)), shape=(self.ny, self.ny)).tocsr()
            if projector is not None:
                A = projector @ A
            return (A + kinematics).tocsc()

        return jacobian

    def _held_projector(self, held, grounds, codes=None):
        """``P`` (ny, ny) that projects held particles' acceleration rows onto their constraints;
        a sticking particle (held on one ground with friction, code HELD) has all of them zero
        (its acceleration is held at 0; a sliding one's friction is left out)."""
        from scipy import sparse

        if not held.any():
            return None
        d, nq = self.dim, self.nq
        blocks = []
        for i in np.flatnonzero(held.any(axis=1)):
            J = grounds[held[i], 1, :]  # the normals of its held grounds: d gap / dx, (k, d)
            P = np.eye(d) - J.T @ np.linalg.solve(J @ J.T, J)
            g = np.flatnonzero(held[i])
            if codes is not None and len(g) == 1 and self.laws[g[0], 0] > 0.0 and codes[i, g[0]] == HELD:
                P = np.zeros((d, d))
            r = nq + d * i + np.arange(d)
            blocks.append((np.repeat(r, d), np.tile(r, d), (P - np.eye(d)).ravel()))
        rows, cols, vals = (np.concatenate(x) for x in zip(*blocks))
        return sparse.eye(self.ny, format="csr") + sparse.coo_matrix((vals, (rows, cols)), shape=(self.ny, self.ny))


class AssembledC(runtime.SystemModel, AssembledModel):
    """The assembled particles formulation in C (the runtime library)."""

    backend = "c"

    def __init__(self, scene: Scene) -> None:
        super().__init__(scene)
        self.lib = runtime.library()
        self._axial = np.ascontiguousarray(self.axial, dtype=np.intc)
        self._threads_wanted = 0

    def _bind(self, p: np.ndarray) -> runtime.FbSystem:
        """An FbSystem of this assembly with parameters ``p`` bound (copied into C)."""
        lib = self.lib
        handle = lib.fb_asm_new(self.dim, self.n_particles, len(self.links), self.n_grounds,
                                self.links.ctypes.data, self._axial.ctypes.data)
        if not handle:
            raise MemoryError(f"cannot allocate the assembly of {self.n_particles} particles")
        self.threads = lib.fb_asm_threads(handle, self._threads_wanted)
        lib.fb_asm_bind(handle, p.ctypes.data)
        lib.fb_asm_laws(handle, np.ascontiguousarray(self.laws).ctypes.data)
        system = runtime.FbSystem()
        lib.fb_asm_system(handle, ctypes.addressof(system))
        if not (self.laws[:, 0] > 0.0).any():
            system.friction = None  # no friction anywhere: event location skips it
            system.slip = None
            system.slip_held = None
            system.tangential_push = None
        system.owner = _AssemblyHandle(lib, handle)
        return system

    def free_accelerations(self, y, p, push, particles: IntArray) -> FloatArray:
        """The free accelerations (links, gravity, pushes; no held contact's force) of
        ``particles (k,)`` alone, as :meth:`rhs` sums them, bit for bit: shape (n * dim,),
        zero for the other particles."""
        y, push = np.ascontiguousarray(y, float), np.ascontiguousarray(push, float)
        particles = np.ascontiguousarray(particles, np.intc)
        acc = np.zeros(self.nu)
        self.lib.fb_asm_free_accelerations(self.system(p).data, y.ctypes.data, push.ctypes.data, len(particles),
                                           particles.ctypes.data, acc.ctypes.data)
        return acc

    def use_threads(self, threads: int) -> int:
        """Let the right-hand side use up to ``threads`` threads (0: OpenMP's default, the
        cores or OMP_NUM_THREADS), at most one per 4096 links; ``threads`` then says how many
        it uses.  The values do not depend on it, bit for bit.  Returns the limit it replaces."""
        before, self._threads_wanted = self._threads_wanted, int(threads)
        if self._threads_wanted != before:
            self._system_cache = None  # bound again, with the new limit, when next asked for
        return before

    def slip_directions(self, p) -> FloatArray:
        return self._contact_vectors(self.system(p).slip)

    def slips_held(self, p) -> np.ndarray:
        address = self.system(p).slip_held
        if not address:
            return np.zeros(self.n_contacts, np.intc)
        return np.frombuffer((ctypes.c_int * self.n_contacts).from_address(address), dtype=np.intc)

    def tangential_pushes(self, p) -> FloatArray:
        return self._contact_vectors(self.system(p).tangential_push)

    def _contact_vectors(self, address: int | None) -> FloatArray:
        """A writable view (nc, dim) of an FbSystem's per-contact (nc, 3) array, zeros if NULL."""
        if not address:
            return np.zeros((self.n_contacts, self.dim))
        buffer = (ctypes.c_double * (3 * self.n_contacts)).from_address(address)
        return np.frombuffer(buffer, dtype=float).reshape(-1, 3)[:, : self.dim]

    def outputs(self, y, p):
        """Positions and velocities (n, dim) and energies (4,) at one state."""
        y = np.ascontiguousarray(y, dtype=float)
        x, v, e = np.empty((self.n_particles, self.dim)), np.empty((self.n_particles, self.dim)), np.empty(4)
        self.lib.fb_sys_outputs(self._address(p), y.ctypes.data, x.ctypes.data, v.ctypes.data, e.ctypes.data)
        return x, v, e

    def link_jacobians(self, y, p):
        """d(force on i)/d[x_i, x_j, v_i, v_j] per link, shape (n_links, dim, 4 dim)."""
        y = np.ascontiguousarray(y, dtype=float)
        out = np.empty((len(self.links), self.dim, 4 * self.dim))
        self.lib.fb_asm_link_jacobians(self.system(p).data, y.ctypes.data, out.ctypes.data)
        return out


class _AssemblyHandle:
    """Frees a C assembly when the FbSystem holding it goes."""

    def __init__(self, lib, handle: int) -> None:
        self.lib, self.handle = lib, handle

    def __del__(self) -> None:
        self.lib.fb_asm_free(self.handle)


def _kernels_module():
    """The generated NumPy kernels (``generated/kernels/kernels.py``), loaded once."""
    global _KERNELS
    if _KERNELS is None:
        spec = importlib.util.spec_from_file_location("flexbody_kernels", kernels_dir() / "kernels.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        _KERNELS = module
    return _KERNELS


_KERNELS = None


class AssembledNumpy(AssembledModel):
    """The assembled particles formulation in NumPy: the generated kernels vectorised over
    elements (no compiler needed)."""

    backend = "numpy"

    def __init__(self, scene: Scene) -> None:
        super().__init__(scene)
        self.k = _kernels_module()
        tag = f"{self.dim}d"
        self._link_force = {False: getattr(self.k, f"link_relative_{tag}_force"),
                            True: getattr(self.k, f"link_axial_{tag}_force")}
        self._link_energy = {False: getattr(self.k, f"link_relative_{tag}_energy"),
                             True: getattr(self.k, f"link_axial_{tag}_energy")}
        self._link_jacobian = {False: getattr(self.k, f"link_relative_{tag}_jacobian"),
                               True: getattr(self.k, f"link_axial_{tag}_jacobian")}
        self._particle = getattr(self.k, f"particle_{tag}")
        self._ground = getattr(self.k, f"ground_{tag}")
        self._split_kernel = getattr(self.k, f"split_{tag}")
        self._groups = [(law, np.flatnonzero(self.axial == law)) for law in (False, True) if (self.axial == law).any()]

    def _link_inputs(self, x, v, link_par, index):
        i, j = self.links[index, 0], self.links[index, 1]
        return np.moveaxis(x[i], 1, 0), np.moveaxis(x[j], 1, 0), np.moveaxis(v[i], 1, 0), \
            np.moveaxis(v[j], 1, 0), link_par[:, index]

    def _contacts(self, x, grounds):
        """Gaps (n, G) and gap Jacobian rows (n, G, dim) from the ground kernel."""
        n, G, d = self.n_particles, self.n_grounds, self.dim
        xs = np.repeat(x, G, axis=0).T  # (d, n G), particle-major
        P = np.tile(grounds[:, 0, :], (n, 1)).T
        N = np.tile(grounds[:, 1, :], (n, 1)).T
        gap, J, _, _ = self._ground(xs, P, N)
        return gap[0].reshape(n, G), np.moveaxis(J[0], 0, -1).reshape(n, G, d)

    def gaps(self, q, p):
        _, _, _, grounds = self._views(np.asarray(p, float))
        return self._contacts(np.asarray(q, float).reshape(-1, self.dim), grounds)[0].ravel()

    def _accelerations(self, x, v, p, push):
        """Unconstrained accelerations (n, dim), damping power and impact power."""
        masses, link_par, gravity, grounds = self._views(p)
        force = np.zeros_like(x)
        power = 0.0
        for law, index in self._groups:
            f, pw = self._link_force[law](*self._link_inputs(x, v, link_par, index))
            for a in range(self.dim):
                force[:, a] += np.bincount(self.links[index, 0], f[a], self.n_particles)
                force[:, a] -= np.bincount(self.links[index, 1], f[a], self.n_particles)
            power += float(pw.sum())
        fg, _, _ = self._particle(x.T, v.T, masses[None, :], np.repeat(gravity[:, None], self.n_particles, 1))
        force += fg.T
        impact_power = 0.0
        if np.any(push):
            _, J = self._contacts(x, grounds)
            push = np.asarray(push, float).reshape(self.n_particles, self.n_grounds)
            pushed = (push != 0.0)[:, :, None]
            tangential = np.where(pushed, self.tangential_pushes(p).reshape(*push.shape, self.dim), 0.0)
            window = np.einsum("ng,ngd->ngd", push, J) + tangential
            force += window.sum(axis=1)
            impact_power = -float(np.einsum("ngd,nd->", window, v))
        return force / masses[:, None], power, impact_power

    def _constrain(self, x, w, p, stop):
        """Per particle: impulses or forces lam (n, G) with J_S (w + J_S^T lam / m) = 0."""
        masses, _, _, grounds = self._views(p)
        stop = np.asarray(stop, bool).reshape(self.n_particles, self.n_grounds)
        lam = np.zeros(stop.shape)
        if not stop.any():
            return lam
        _, J = self._contacts(x, grounds)
        for i in np.flatnonzero(stop.any(axis=1)):
            Js = J[i, stop[i]]
            A = Js @ Js.T / masses[i]
            if np.linalg.eigvalsh(A).min() <= 0.0:
                raise singular_matrix_error()
            ls = np.linalg.solve(A, -(Js @ w[i]))
            w[i] += Js.T @ ls / masses[i]
            lam[i, stop[i]] = ls
        return lam

    def rhs(self, y, p, held, push):
        p = np.asarray(p, float)
        x, v = self._split(np.asarray(y, float))
        acc, power, impact_power = self._accelerations(x, v, p, push)
        lam = self._constrain(x, acc, p, held)
        if (self.laws[:, 0] > 0.0).any():
            impact_power += self._coulomb(x, v, acc, lam, p, held)[3]
        return np.concatenate([v.ravel(), acc.ravel(), [power, impact_power]]), lam.ravel()

    def _coulomb(self, x, v, acc, lam, p, held):
        """Coulomb friction on the particles held on one ground (the twin of ``coulomb`` in
        assembly.c): updates ``acc (n, dim)``; returns each contact's tangential velocity and
        force (n, G, dim), sticking slack (n, G; inf without friction) and the power friction
        dissipates (W)."""
        masses, _, _, grounds = self._views(p)
        n, G, d = self.n_particles, self.n_grounds, self.dim
        held = np.asarray(held).reshape(n, G)
        normals = np.broadcast_to(grounds[None, :, 1, :], (n, G, d)).reshape(-1, d).T
        _, vt, _ = self._split_kernel(np.repeat(v, G, axis=0).T, normals)
        vt = vt.T.reshape(n, G, d)
        ft, slack, power = np.zeros((n, G, d)), np.full((n, G), np.inf), 0.0
        single = np.count_nonzero(held, axis=1) == 1
        i = np.flatnonzero(single)
        g = np.argmax(held[i] != 0, axis=1)
        mu = self.laws[g, 0]
        i, g, mu = i[mu > 0.0], g[mu > 0.0], mu[mu > 0.0]
        if not len(i):
            return vt, ft, slack, power
        m, normal = masses[i], grounds[g, 1, :]
        _, at, pull = self._split_kernel(acc[i].T, normal.T)
        at, pull = at.T, pull[0]
        sticking = held[i, g] != SLIDING
        # Sticking: the tangential force cancels the tangential pull.
        ft[i, g] = np.where(sticking[:, None], -m[:, None] * at, 0.0)
        slack[i, g] = mu * lam[i, g] - m * pull  # sliding: the slack it would have sticking (>= 0 inside its cone)
        # Sliding: mu lam against v_t, or against the pull from rest; past the stop (v_t against
        # the step's starting direction) along that direction, as coulomb in assembly.c.
        speed = np.linalg.norm(vt[i, g], axis=1)
        direction = self._slip[i * G + g, :d]
        unit = np.sum(direction**2, axis=1)
        past = (unit > 0.0) & ((np.sum(vt[i, g] * direction, axis=1) < 0.0) | (speed == 0.0)
                               | (self._slip_held[i * G + g] != 0))
        along = np.where(past[:, None], direction, np.where((speed > 0.0)[:, None], vt[i, g], at))
        size = np.where(past, np.sqrt(unit), np.where(speed > 0.0, speed, pull))
        force = mu * np.maximum(lam[i, g], 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            slide = np.where(((~sticking) & (size > 0.0))[:, None], -force[:, None] * along / size[:, None], 0.0)
        ft[i, g] += slide
        acc[i] += np.where(sticking[:, None], -at, slide / m[:, None])
        power = -float(np.sum(slide * vt[i, g]))  # mu lam |v_t| before the stop
        return vt, ft, slack, power

    def friction(self, y, p, held, push):
        """Each contact's tangential velocity and force (nc, dim) and sticking slack (nc,), as
        :meth:`flexbody.runtime.SystemModel.friction`."""
        p = np.asarray(p, float)
        x, v = self._split(np.asarray(y, float))
        acc, _, _ = self._accelerations(x, v, p, push)
        lam = self._constrain(x, acc, p, held)
        vt, ft, slack, _ = self._coulomb(x, v, acc, lam, p, held)
        return vt.reshape(-1, self.dim), ft.reshape(-1, self.dim), slack.ravel()

    def contact_state(self, y, p, held, push):
        p = np.asarray(p, float)
        x, v = self._split(np.asarray(y, float))
        gaps, J = self._contacts(x, self._views(p)[3])
        return gaps.ravel(), np.einsum("ngd,nd->ng", J, v).ravel(), self.rhs(y, p, held, push)[1]

    def impact(self, y, p, stop):
        p = np.asarray(p, float)
        out = np.array(y, float)
        x, v = self._split(out)
        v_before = v.copy()
        lam = self._constrain(x, v, p, stop)  # v is a view into out
        masses, _, _, grounds = self._views(p)
        self._contact_laws(v, lam, masses, grounds, np.asarray(stop).reshape(lam.shape))
        loss = 0.5 * float(np.sum(masses * (np.sum(v_before**2, axis=1) - np.sum(v**2, axis=1))))
        return out, loss

    def settle(self, y, p, stop) -> np.ndarray:
        """``y`` with each particle with ``stop[c]`` set onto the grounds it is below: the
        least move with J_S (x + dx) - P = max(gap, 0) (the twin of ``settle`` in assembly.c)."""
        out = np.array(y, float)
        x, _ = self._split(out)
        _, _, _, grounds = self._views(np.asarray(p, float))
        stop = np.asarray(stop, bool).reshape(self.n_particles, self.n_grounds)
        gaps, J = self._contacts(x, grounds)
        for i in np.flatnonzero((stop & (gaps < 0.0)).any(axis=1)):
            Js, below = J[i, stop[i]], np.maximum(-gaps[i, stop[i]], 0.0)
            x[i] += Js.T @ np.linalg.solve(Js @ Js.T, below)
        return out

    def _contact_laws(self, v, lam, masses, grounds, stop):
        """Restitution and the friction impulse after the plastic impulses ``lam (n, G)``, on
        particles stopped on one ground (the twin of ``contact_laws`` in assembly.c)."""
        single = np.count_nonzero(stop, axis=1) == 1
        particles = np.flatnonzero(single)
        g = np.argmax(stop[particles] != 0, axis=1)
        mu, e = self.laws[g, 0], np.where(stop[particles, g] == REBOUND, self.laws[g, 1], 0.0)
        settle = stop[particles, g] == SETTLE
        active = (mu != 0.0) | (e != 0.0) | settle
        particles, g, mu, e, settle = particles[active], g[active], mu[active], e[active], settle[active]
        if not len(particles):
            return
        normal = grounds[g, 1, :]  # (k, d): the ground kernel's normal is the unit normal itself
        stopped = np.maximum(lam[particles, g], 0.0) / masses[particles]  # -v_n-; held: 0 up to round-off
        v[particles] += (e * stopped)[:, None] * normal
        _, vt, speed = self._split_kernel(v[particles].T, normal.T)
        impulse, speed = mu * (1.0 + e) * stopped, speed[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            keep = np.where((impulse >= speed) | settle, 0.0, 1.0 - impulse / speed)
        moving = speed > 0.0
        v[particles[moving]] -= ((1.0 - keep[moving]) * vt[:, moving]).T

    def outputs(self, y, p):
        """Positions and velocities (n, dim) and energies (4,) at one state."""
        X, V, E, _ = self.trajectory(np.asarray(y, float)[None], p, np.zeros((1, self.n_contacts), bool),
                                     np.zeros((1, self.n_contacts)))
        return X[0], V[0], E[0]

    def trajectory(self, Y, p, held, push):
        p = np.asarray(p, float)
        Y = np.asarray(Y, float)
        nt = len(Y)
        X = Y[:, : self.nq].reshape(nt, -1, self.dim)
        V = Y[:, self.nq : 2 * self.nq].reshape(nt, -1, self.dim)
        masses, link_par, gravity, _ = self._views(p)
        x, v = np.moveaxis(X, 0, -1), np.moveaxis(V, 0, -1)  # (n, d, nt)
        _, potential, kinetic = self._particle(np.moveaxis(x, 1, 0), np.moveaxis(v, 1, 0), masses[None, :, None],
                                               np.broadcast_to(gravity[:, None, None], (self.dim, *x.shape[::2])))
        spring = np.zeros(nt)
        power = np.zeros(nt)
        for law, index in self._groups:
            i, j = self.links[index, 0], self.links[index, 1]
            inputs = (np.moveaxis(x[i], 1, 0), np.moveaxis(x[j], 1, 0), np.moveaxis(v[i], 1, 0),
                      np.moveaxis(v[j], 1, 0), link_par[:, index, None])
            spring += self._link_energy[law](*inputs)[0][0].sum(axis=0)
            power += self._link_force[law](*inputs)[1][0].sum(axis=0)
        E = np.column_stack([kinetic[0].sum(axis=0), spring, potential[0].sum(axis=0), power])
        lam = np.zeros((nt, self.n_contacts))
        for k in np.flatnonzero(np.any(held, axis=1) | np.any(np.asarray(push) != 0, axis=1)):
            lam[k] = self.rhs(Y[k], p, held[k], push[k])[1]
        return X.copy(), V.copy(), E, lam

    def link_jacobians(self, y, p):
        """d(force on i)/d[x_i, x_j, v_i, v_j] per link, shape (n_links, dim, 4 dim)."""
        x, v = self._split(np.asarray(y, float))
        link_par = self._views(np.asarray(p, float))[1]
        out = np.empty((len(self.links), self.dim, 4 * self.dim))
        for law, index in self._groups:
            out[index] = np.moveaxis(self._link_jacobian[law](*self._link_inputs(x, v, link_par, index))[0], -1, 0)
        return out


def assembled_model(scene: Scene, backend: str = "c") -> AssembledModel:
    """The assembled particles-formulation model of ``scene`` (``backend`` "c" or "numpy")."""
    return {"c": AssembledC, "numpy": AssembledNumpy}[backend](scene)
