"""Load a generated model and evaluate it through one interface, in C or NumPy.

The runtime never imports SymPy: a model is read from ``generated/`` (or the cache),
and a scene whose model does not exist yet is derived in a separate process.

Array conventions: ``q (nq,)``, ``u (nu,)``, ``p (np,)`` in manifest order; the state of
the right-hand side is ``y = [q, u, w]`` with ``w = [damping work, impact work]``.
"""

from __future__ import annotations

import ctypes
import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from . import cbuild, dynamics
from .paths import cache_root, generated_root, model_dir_name
from .scene import Scene, load_scene

FloatArray = np.ndarray


class ModelError(RuntimeError):
    """A generated model is missing, stale or does not match the scene."""


def singular_matrix_error() -> FloatingPointError:
    """What a nonzero status of a generated C function means."""
    return FloatingPointError("mass or contact matrix not positive definite at this state")


class Model:
    """A generated model; the backend subclasses fill in the evaluation.

    Every evaluation takes ``q (nq,)``, ``u (nu,)`` and ``p (np,)`` and returns a new
    array (never a reused buffer: SciPy's integrators keep references to them).
    """

    backend = ""

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)
        self.manifest = json.loads((self.directory / "manifest.json").read_text())
        m = self.manifest
        self.digest: str = m["digest"]
        self.formulation: str = m["formulation"]
        self.q_names: tuple[str, ...] = tuple(m["q_names"])
        self.u_names: tuple[str, ...] = tuple(m["u_names"])
        self.p_names: tuple[str, ...] = tuple(m["p_names"])
        self.nq, self.nu, self.np = len(self.q_names), len(self.u_names), len(self.p_names)
        self.ny = self.nq + self.nu + 2
        self.n_particles: int = m["n_particles"]
        self.n_contacts: int = m["n_contacts"]
        self.contacts = np.array(m["contacts"], dtype=int).reshape(-1, 2)  # (particle, ground)
        n_grounds = self.n_contacts // max(self.n_particles, 1)
        if not np.array_equal(self.contacts, np.indices((self.n_particles, n_grounds)).reshape(2, -1).T):
            raise ModelError(f"{self.directory}: contacts must be every (particle, ground) pair, particle-major")
        self.shapes = {name: tuple(f["shape"]) for name, f in m["functions"].items()}

    def parameters(self, scene: Scene) -> FloatArray:
        """The parameter vector ``p (np,)`` of ``scene`` in this model's order."""
        values = scene.parameters()
        missing = [name for name in self.p_names if name not in values]
        if missing:
            raise ModelError(f"scene {scene.name!r} gives no value for model parameters {missing}")
        return np.array([values[name] for name in self.p_names], dtype=float)

    def _call(self, name: str, q, u, p, a=None) -> FloatArray:  # pragma: no cover - abstract
        raise NotImplementedError

    def mass_matrix(self, q, p) -> FloatArray:
        """M(q, p), shape (nu, nu)."""
        return self._call("mass_matrix", q, None, p)

    def forcing(self, q, u, p) -> FloatArray:
        """F(q, u, p), shape (nu,)."""
        return self._call("forcing", q, u, p)

    def energies(self, q, u, p) -> FloatArray:
        """[kinetic, spring, gravity, damping power], shape (4,)."""
        return self._call("energies", q, u, p)

    def positions(self, q, p) -> FloatArray:
        """Particle positions in N, shape (n, 2)."""
        return self._call("positions", q, None, p)

    def velocities(self, q, u, p) -> FloatArray:
        """Particle velocities in N, shape (n, 2)."""
        return self._call("velocities", q, u, p)

    def gaps(self, q, p) -> FloatArray:
        """Gap of each contact (particle * n_grounds + ground), shape (nc,)."""
        return self._call("gaps", q, None, p)

    def gap_jacobian(self, q, p) -> FloatArray:
        """d gaps / dq, shape (nc, nu)."""
        return self._call("gap_jacobian", q, None, p)

    def gap_bias(self, q, u, p) -> FloatArray:
        """d/dt(gap_jacobian) u, shape (nc,)."""
        return self._call("gap_bias", q, u, p)

    def forcing_jacobians(self, q, u, p, a) -> tuple[FloatArray, FloatArray]:
        """d(F - M a)/dq, shape (nu, nq), and dF/du, shape (nu, nu)."""
        return self._call("jacobian_q", q, u, p, a), self._call("jacobian_u", q, u, p)

    def rhs(self, y, p, held, push) -> tuple[FloatArray, FloatArray]:
        """Contact-constrained right-hand side.

        Parameters
        ----------
        y : ndarray, shape (ny,)
            State ``[q, u, damping work, impact work]``.
        p : ndarray, shape (np,)
        held : ndarray of int, shape (nc,)
            1 where a contact is held (gap acceleration 0), else 0.
        push : ndarray, shape (nc,)
            Prescribed normal force per contact (thesis impact mode), else 0.

        Returns
        -------
        ydot : ndarray, shape (ny,)
        lam : ndarray, shape (nc,)
            Normal constraint force of held contacts (>= 0 when it pushes), 0 elsewhere.
        """
        raise NotImplementedError  # pragma: no cover

    def contact_state(self, y, p, held, push) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Gaps, normal velocities ``J u`` and held-contact forces at ``y``, each shape (nc,)."""
        return dynamics.contact_state(self, y, p, held, push)

    def trajectory(self, Y, p, held, push) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Outputs along states ``Y (nt, ny)`` with contact sets ``held``, ``push`` (nt, nc).

        Returns positions and velocities (nt, n, 2), energies (nt, 4), contact forces (nt, nc).
        """
        Y = np.asarray(Y, dtype=float)
        Q, U = Y[:, : self.nq].T, Y[:, self.nq : self.nq + self.nu].T
        X = np.moveaxis(self._call("positions", Q, U, p), -1, 0)
        V = np.moveaxis(self._call("velocities", Q, U, p), -1, 0)
        E = np.moveaxis(self._call("energies", Q, U, p), -1, 0)
        lam = np.zeros((len(Y), self.n_contacts))
        for k in np.flatnonzero(np.any(held, axis=1) | np.any(push != 0, axis=1)):
            lam[k] = self.rhs(Y[k], p, held[k], push[k])[1]
        return X, V, E, lam

    def impact(self, y, p, stop) -> tuple[FloatArray, float]:
        """Impulses that zero the normal velocity of every contact in ``stop`` (bool (nc,)).

        Returns the state after them, shape (ny,), and the kinetic energy they removed (J).
        """
        return dynamics.impact(self, y, p, stop)

    def rhs_function(self, p, held, push):
        """``f(t, y) -> ydot`` for SciPy, with the contact set frozen."""
        def f(t, y):
            return self.rhs(y, p, held, push)[0]

        return f

    def jacobian_function(self, p, held):
        """``J(t, y) -> (ny, ny)`` of the constrained right-hand side, for implicit methods."""
        return lambda t, y: dynamics.state_jacobian(self, y, p, held)


class _ScalarMath:
    """The functions generated expressions call, on Python floats (for single states)."""

    sqrt, sin, cos = staticmethod(math.sqrt), staticmethod(math.sin), staticmethod(math.cos)

    @staticmethod
    def sign(x: float) -> float:
        return float((x > 0.0) - (x < 0.0))


class NumpyModel(Model):
    """Evaluates the generated NumPy module (``model.py``); accepts batched q and u.

    A single state is evaluated on Python floats with scalar math functions (about 3x
    faster than on NumPy scalars); batches, on NumPy arrays.
    """

    backend = "numpy"

    def __init__(self, directory: Path) -> None:
        super().__init__(directory)
        name = f"flexbody_generated_{self.digest}"
        spec = importlib.util.spec_from_file_location(name, self.directory / "model.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        self.module = module
        self.scalar = all(hasattr(_ScalarMath, f) for f in self.manifest.get("python_math", ["?"]))

    def _call(self, name, q, u, p, a=None):
        q = np.asarray(q, float)
        fn = getattr(self.module, name)
        if q.ndim == 1 and self.scalar:
            lists = [None if x is None else np.asarray(x, float).tolist() for x in (u, a)]
            out = fn(q.tolist(), lists[0], np.asarray(p, float).tolist(), lists[1], _ScalarMath)
        else:
            out = fn(q, u, np.asarray(p, float), a)
        return out[0] if name == "damping_power" else out

    def rhs(self, y, p, held, push):
        return dynamics.constrained_rhs(self, y, p, held, push)


class CModel(Model):
    """Evaluates the compiled C module (``model.c``) through ctypes."""

    backend = "c"

    def __init__(self, directory: Path) -> None:
        super().__init__(directory)
        self.library_path = cbuild.library_path(self.directory)
        lib = ctypes.CDLL(str(self.library_path))
        lib.fb_digest.restype = ctypes.c_char_p
        if lib.fb_digest().decode() != self.digest:
            raise ModelError(f"{self.library_path} was built for another model than {self.directory}")
        ptr = ctypes.c_void_p
        self._fn = {}
        for name in self.shapes:  # every generated function the manifest lists
            fn = getattr(lib, f"fb_{name}")
            fn.argtypes = [ptr] * 5
            fn.restype = None
            self._fn[name] = fn
        self._rhs = lib.fb_rhs
        self._rhs.argtypes = [ctypes.c_double] + [ptr] * 6
        self._rhs.restype = ctypes.c_int
        self._contact_state = lib.fb_contact_state
        self._contact_state.argtypes = [ptr] * 7
        self._impact = lib.fb_impact
        self._impact.argtypes = [ptr] * 5
        self._trajectory = lib.fb_trajectory
        self._trajectory.argtypes = [ctypes.c_int] + [ptr] * 8
        self._time_rhs = lib.fb_time_rhs
        self._time_rhs.argtypes = [ctypes.c_int] + [ptr] * 4
        self._time_rhs.restype = ctypes.c_double
        # Raw entry points of the compiled path (addresses, not arrays): see flexbody.compiled.
        d, i = ctypes.c_double, ctypes.c_int
        self.fb_integrate = lib.fb_integrate
        self.fb_integrate.argtypes = [i, d, ptr, d, ptr, ptr, ptr, ptr, ptr, d, d, d, ptr, i] + [ptr] * 9
        self.fb_integrate.restype = i
        self.fb_resolve = lib.fb_resolve
        self.fb_resolve.argtypes = [d] + [ptr] * 8 + [d, ptr, ptr, i, d] + [ptr] * 7
        self.fb_resolve.restype = i
        self._zeros = np.zeros(max(self.nu, self.nq, 1))

    def _call(self, name, q, u, p, a=None):
        q = np.ascontiguousarray(q, dtype=float)
        u = self._zeros if u is None else np.ascontiguousarray(u, dtype=float)
        a = self._zeros if a is None else np.ascontiguousarray(a, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        out = np.empty(self.shapes[name])
        self._fn[name](q.ctypes.data, u.ctypes.data, p.ctypes.data, a.ctypes.data, out.ctypes.data)
        return out[0] if name == "damping_power" else out

    def rhs(self, y, p, held, push):
        y = np.ascontiguousarray(y, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        held = np.ascontiguousarray(held, dtype=np.intc)
        push = np.ascontiguousarray(push, dtype=float)
        ydot, lam = np.empty(self.ny), np.empty(self.n_contacts)
        status = self._rhs(0.0, y.ctypes.data, p.ctypes.data, held.ctypes.data, push.ctypes.data,
                           ydot.ctypes.data, lam.ctypes.data)
        if status:
            raise singular_matrix_error()
        return ydot, lam

    def contact_state(self, y, p, held, push):
        y = np.ascontiguousarray(y, dtype=float)
        held = np.ascontiguousarray(held, dtype=np.intc)
        gaps, vn, lam = np.empty(self.n_contacts), np.empty(self.n_contacts), np.empty(self.n_contacts)
        if self._contact_state(y.ctypes.data, p.ctypes.data, held.ctypes.data, push.ctypes.data, gaps.ctypes.data,
                               vn.ctypes.data, lam.ctypes.data):
            raise singular_matrix_error()
        return gaps, vn, lam

    def impact(self, y, p, stop):
        y = np.ascontiguousarray(y, dtype=float)
        stop = np.ascontiguousarray(stop, dtype=np.intc)
        out, loss = np.empty(self.ny), ctypes.c_double(0.0)
        if self._impact(y.ctypes.data, p.ctypes.data, stop.ctypes.data, out.ctypes.data, ctypes.addressof(loss)):
            raise singular_matrix_error()
        return out, loss.value

    def rhs_function(self, p, held, push):
        # Pointers of the frozen inputs are taken once: the call is ~1 µs, not ~5.
        keep = [np.ascontiguousarray(p, dtype=float), np.ascontiguousarray(held, dtype=np.intc),
                np.ascontiguousarray(push, dtype=float), np.empty(self.n_contacts)]
        p_ptr, held_ptr, push_ptr, lam_ptr = (a.ctypes.data for a in keep)
        rhs, ny = self._rhs, self.ny

        def f(t, y):
            y = np.ascontiguousarray(y, dtype=float)
            ydot = np.empty(ny)
            if rhs(t, y.ctypes.data, p_ptr, held_ptr, push_ptr, ydot.ctypes.data, lam_ptr):
                raise singular_matrix_error()
            return ydot

        f.keep = keep  # keep the buffers alive as long as f
        return f

    def trajectory(self, Y, p, held, push):
        Y = np.ascontiguousarray(Y, dtype=float)
        held = np.ascontiguousarray(held, dtype=np.intc)
        push = np.ascontiguousarray(push, dtype=float)
        n = len(Y)
        X, V = np.empty((n, self.n_particles, 2)), np.empty((n, self.n_particles, 2))
        E, lam = np.empty((n, 4)), np.empty((n, self.n_contacts))
        self._trajectory(n, Y.ctypes.data, p.ctypes.data, held.ctypes.data, push.ctypes.data, X.ctypes.data,
                         V.ctypes.data, E.ctypes.data, lam.ctypes.data)
        return X, V, E, lam

    def time_rhs(self, y, p, held, push, calls: int = 20000) -> float:
        """Mean seconds per right-hand-side call at ``y``, timed inside C (no Python overhead)."""
        y = np.ascontiguousarray(y, dtype=float)
        held = np.ascontiguousarray(held, dtype=np.intc)
        push = np.ascontiguousarray(push, dtype=float)
        return self._time_rhs(calls, y.ctypes.data, p.ctypes.data, held.ctypes.data, push.ctypes.data)


BACKENDS = {"c": CModel, "numpy": NumpyModel}


def find_model_dir(scene: Scene, formulation: str) -> Path | None:
    """The folder of an existing generated model for ``scene``'s topology, or None."""
    digest = scene.topology().digest(formulation)
    candidates = [generated_root() / model_dir_name(scene.name, formulation)]
    if generated_root().is_dir():
        candidates += sorted(generated_root().glob("*/manifest.json"))
    candidates.append(cache_root() / "models" / digest)
    for path in candidates:
        folder = path.parent if path.name == "manifest.json" else path
        manifest = folder / "manifest.json"
        if manifest.is_file() and json.loads(manifest.read_text()).get("digest") == digest:
            return folder
    return None


def derive_on_demand(scene: Scene, formulation: str) -> Path:
    """Derive and generate ``scene``'s model into the cache, in a separate process.

    SymPy runs in a child process (with a fixed hash seed, for deterministic output), so
    this process never imports it.  One line on standard error says what is happening
    and roughly how long it takes.  The child ends with this process: it is killed if
    this call is interrupted, and on Linux also if this process is killed
    (:mod:`flexbody.subprocesses`).
    """
    from .subprocesses import run_tied

    digest = scene.topology().digest(formulation)
    out = cache_root() / "models" / digest
    n = scene.n_particles
    # Measured (DESIGN.md §6): 16/32/64/100 particles take ~45/55/125/175 s to derive and compile.
    estimate = 30 + 1.5 * n
    print(f"deriving the equations of {scene.name} ({n} particles, formulation {formulation}) with SymPy; "
          f"this usually takes ~{estimate:.0f} s (once: the model is cached in {out})", file=sys.stderr, flush=True)
    env = dict(os.environ, PYTHONHASHSEED="0")
    args = [scene.topology().to_json(), formulation, str(out), scene.source]
    run = run_tied("derivation.ondemand", args, env=env, capture=True)
    if run.returncode != 0:
        raise ModelError(f"deriving the model of {scene.source} failed:\n{run.stdout}{run.stderr}")
    return out


def load_model(scene: Scene | str | Path, backend: str = "c", formulation: str | None = None) -> Model:
    """Load the generated model of a scene, deriving it first if it does not exist.

    Parameters
    ----------
    scene : Scene, path or bundled scene name
    backend : {"c", "numpy"}
        ``c`` compiles ``model.c`` on first use (cached); ``numpy`` needs no compiler.
    formulation : {"particles", "floating"}, optional
        Defaults to the scene's ``simulation.formulation``.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if backend not in BACKENDS:
        raise ValueError(f"`backend` = {backend!r}: must be one of {sorted(BACKENDS)}")
    formulation = formulation or scene.simulation.formulation
    if formulation not in ("particles", "floating"):
        raise ValueError(f"`formulation` = {formulation!r}: must be 'particles' or 'floating'")
    folder = find_model_dir(scene, formulation) or derive_on_demand(scene, formulation)
    return BACKENDS[backend](folder)
