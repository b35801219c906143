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
import sys
from pathlib import Path

import numpy as np

from . import cbuild, dynamics, runtime
from .errors import InputError
from .paths import cache_root, generated_root, model_dir_name
from .scene import Scene, load_scene

FloatArray = np.ndarray
IntArray = np.ndarray


class ModelError(RuntimeError):
    """A generated model is missing, stale or does not match the scene."""


singular_matrix_error = runtime.singular_matrix_error


class Model:
    """What the driver needs of a model, whichever way it was made.

    Attributes: ``backend`` ("c" or "numpy"), ``formulation``, ``digest`` (identifies the
    equations), ``dim``, sizes ``nq, nu, ny = nq + nu + 2, n_particles, n_contacts`` and
    ``contacts (nc, 2)``: (particle, ground) of each contact, particle-major.  Every
    evaluation takes the state or ``q (nq,)``, ``u (nu,)`` and ``p (np,)`` and returns a new
    array (never a reused buffer: SciPy's integrators keep references to them).
    """

    backend = ""
    formulation = ""
    digest = ""
    coupled = False  # True where contacts couple (a rigid body's, or between bodies): instants are LCPs (flexbody.coupled)
    compiled_segments = True  # with backend "c", segments run in the compiled loop (not for body-body contacts)
    threads = 1  # threads of the right-hand side: more only in the assembled C model of a large body
    dim = 2
    nq = nu = ny = n_particles = n_contacts = 0
    contacts: np.ndarray
    #: Contacts between bodies, past the ground ones (flexbody.body_contact), and each one's
    #: index in ``scene.contacts``: none unless bodies may touch each other.
    n_slots = 0
    corners = False  # whether free contacts can cut through another body's corner (corner_cuts)
    first_edge = 0  # the first edge contact's slot (n_slots: none)
    slot_pair = np.zeros(0, np.intp)
    #: Contact laws (Coulomb mu, Newton e) per ground, then per pair of bodies, shape (k, 2):
    #: none where the model does not keep them.
    laws = np.zeros((0, 2))
    #: Each contact's Coulomb coefficient (nc,), where the model keeps its own (contacts
    #: between bodies: the grounds', then the pairs'); None: the scene's grounds decide.
    mu: FloatArray | None = None
    #: Optional evaluations, None where a model has none: ``friction`` (each contact's
    #: tangential velocity, force and sticking slack), ``settle`` (put stopped particles onto
    #: their grounds) and ``contact_coupling`` (its own contact rows and ``J M^-1 J^T``).
    friction = settle = contact_coupling = None

    @property
    def n_ground_contacts(self) -> int:
        """The first contacts, with the grounds: all of them unless bodies touch each other."""
        return self.n_contacts

    def particle_forces(self, lam: FloatArray, positions: FloatArray | None = None,
                        elements: IntArray | None = None) -> FloatArray:
        """Contact force on each particle, shape (nt, n), from per-contact values ``lam (nt,
        nc)``: the sum over its grounds (the ground contacts are every (particle, ground) pair,
        particle-major).  ``positions`` (nt, n, dim) and the slots' ``elements`` (nt, ns) at
        the same samples are for contacts between bodies (see :mod:`flexbody.body_contact`)."""
        lam = np.atleast_2d(lam)
        ng, n = self.n_ground_contacts, self.n_particles
        return lam[:, :ng].reshape(len(lam), n, ng // n).sum(axis=2)

    def parameters(self, scene: Scene) -> FloatArray:  # pragma: no cover - abstract
        raise NotImplementedError

    def gaps(self, q, p) -> FloatArray:  # pragma: no cover - abstract
        """Gap of each contact (particle * n_grounds + ground), shape (nc,)."""
        raise NotImplementedError

    def held_gaps(self, q, p, rows) -> FloatArray:
        """Gaps of the held contacts ``rows (k,)`` to what holds them, shape (k,)."""
        return self.gaps(q, p)[rows]

    def start_segment(self, free: np.ndarray, q, p) -> None:
        """A segment starts at ``q``: free contacts between bodies (``free`` (nc,) bool) pick
        their element afresh; nothing to do without them."""

    def coupled_with(self, q, p, seeds: np.ndarray, among: np.ndarray, jumped: np.ndarray | None = None) -> np.ndarray:
        """The contacts of ``seeds | among`` (bool (nc,) each) whose impulses and forces can
        act on a seed's, directly or through others of them, bool (nc,): here all of them
        (a frame moves every particle).  An instant's problem over these alone has the
        whole problem's answer on them: the others' rows are a separate block of it.
        ``jumped`` (bool (nu,)): coordinates whose free acceleration jumped at the instant
        (a damper's, beside an impact); the contacts moving them are seeds too."""
        return np.asarray(seeds, bool) | np.asarray(among, bool)

    def same_contacts(self, y, p, hit: np.ndarray) -> np.ndarray:
        """Of the contacts ``hit`` (bool (nc,)), those that are another's contact seen from
        its other side, bool (nc,): none for particles against grounds."""
        return np.zeros(self.n_contacts, bool)

    def corner_cuts(self, ya, yb, p, watched: np.ndarray) -> tuple[IntArray, IntArray, IntArray]:
        """Free contacts that may have passed through another body's convex corner between
        the states ``ya`` and ``yb`` (:meth:`flexbody.body_contact.BodyContactModel.corner_cuts`):
        none for particles against grounds."""
        none = np.zeros(0, np.intp)
        return none, np.zeros((0, 3), np.intp), none

    def gap_rates(self, y, p, held) -> tuple[FloatArray, FloatArray]:
        """Gaps and normal velocities, shape (nc,) each: :meth:`contact_state` without the
        forces (an instant of coupled contacts solves for those itself).  An instant reads
        the rates of free contacts only: a model may leave held contacts' at 0
        (:meth:`flexbody.body_contact.BodyContactModel.gap_rates`)."""
        gaps, vn, _ = self.contact_state(y, p, held, np.zeros(self.n_contacts))
        return gaps, vn

    def gap(self, q, p, c: int) -> float:
        """Gap of contact ``c`` alone, equal to ``gaps(q, p)[c]`` (locating an impact needs no other)."""
        return float(self.gaps_of(q, p, np.array([c]))[0])

    def gap_root(self, output: object, c: int, floor: float, ta: float, tb: float, xtol: float) -> float | None:
        """The instant free contact ``c`` hits in ``[ta, tb]`` on ``output``, a step's dense
        output: the first time its gap less ``floor`` is not above 0 (``tb`` if it stays above
        0 there), as :func:`flexbody.events._root` finds it, without evaluating the whole
        state at each try; None where the model has no such search (this one has none)."""
        return None

    def dense_gaps(self, output: object, contacts: IntArray, floors: FloatArray, t: float) -> FloatArray | None:
        """The gaps of free ``contacts (k,)`` less their ``floors (k,)`` at time ``t`` on
        ``output``, a step's dense output, shape (k,): their event functions there, without
        evaluating the whole state; None where the model has no such evaluation for them
        (this one has none)."""
        return None

    def gaps_of(self, q, p, contacts: IntArray) -> FloatArray:
        """Gaps of ``contacts (k,)`` alone, equal to ``gaps(q, p)[contacts]``, shape (k,)."""
        return self.gaps(q, p)[contacts]

    def point_gaps(self, q, p, gaps: FloatArray) -> FloatArray:
        """``gaps`` (nc,) at ``q`` as the signed distances of points of one body to the other
        (what the penetration counts), shape (nc,): the gaps themselves but for 3D edge
        contacts between bodies (:meth:`flexbody.body_contact.BodyContactModel.point_gaps`)."""
        return gaps

    def rhs(self, y, p, held, push) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - abstract
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
        raise NotImplementedError

    def forces_function(self, p, held, push):
        """``forces(y) -> lam`` (nc,), ``rhs(y, p, held, push)[1]`` with the contact set
        frozen (the event functions' of one segment)."""
        def forces(y):
            return self.rhs(y, p, held, push)[1]

        return forces

    def per_particle(self, y, p, phases, seeds: np.ndarray, gap_tolerance: float) -> bool:
        """Whether a coupled model's instant of the contacts ``seeds`` (bool (nc,)) at state
        ``y`` with ``phases`` (:class:`flexbody.contact.Phases`) is its inner model's, solved
        per particle (:class:`flexbody.body_contact.BodyContactModel`): never here."""
        return False

    def held_forces(self, y, p, held, push) -> FloatArray:
        """``rhs(y, p, held, push)[1]``, shape (nc,): the held contacts' forces alone, which
        a model may find without the whole right-hand side (a block of coupled contacts,
        :meth:`coupled_with`: what locating its lift-off evaluates again and again)."""
        return self.rhs(y, p, held, push)[1]

    def contact_state(self, y, p, held, push) -> tuple[FloatArray, FloatArray, FloatArray]:  # pragma: no cover
        """Gaps, normal velocities ``J u`` and held-contact forces at ``y``, each shape (nc,)."""
        raise NotImplementedError

    def impact(self, y, p, stop) -> tuple[FloatArray, float]:  # pragma: no cover - abstract
        """Impulses that zero the normal velocity of every contact in ``stop`` (int (nc,)).

        ``stop[c]`` is a code of :mod:`flexbody.constants`: KEEP, STOP (plastic) or REBOUND
        (``v_n+ = -e v_n-``).  Models with contact laws (the assembled particles formulation)
        also apply restitution and the Coulomb friction impulse; the others treat REBOUND as STOP.

        Returns the state after them, shape (ny,), and the kinetic energy they removed (J).
        """
        raise NotImplementedError

    def trajectory(self, Y, p, held, push):  # pragma: no cover - abstract
        """Outputs along states ``Y (nt, ny)`` with contact sets ``held``, ``push`` (nt, nc).

        Returns positions and velocities (nt, n, dim), energies (nt, 4), contact forces (nt, nc).
        """
        raise NotImplementedError

    def rhs_function(self, p, held, push):
        """``f(t, y) -> ydot`` for SciPy, with the contact set frozen."""
        def f(t, y):
            return self.rhs(y, p, held, push)[0]

        return f

    def jacobian_function(self, p, held):  # pragma: no cover - abstract
        """``J(t, y)`` of the constrained right-hand side, shape (ny, ny), for implicit methods."""
        raise NotImplementedError


class GeneratedModel(Model):
    """A whole-scene model generated by the derivation (``generated/<scene>_<formulation>/``).

    It evaluates the equations derived for one topology as a whole: the floating
    formulation, and the particles formulation as the oracle of the assembled one and the
    equations ``flexbody show`` prints.  The backend subclasses fill in the evaluation.
    """

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)
        self.manifest = json.loads((self.directory / "manifest.json").read_text())
        m = self.manifest
        self.digest: str = m["digest"]
        self.formulation: str = m["formulation"]
        self.dim = int(m["topology"]["dim"])
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
        #: A rigid body's contacts couple: instants are solved as one LCP (flexbody.coupled).
        self.coupled = any(b.get("rigid") for b in m["topology"]["bodies"])

    def parameters(self, scene: Scene) -> FloatArray:
        """The parameter vector ``p (np,)`` of ``scene`` in this model's order."""
        values = scene.parameters()
        if any(name.startswith(("rx", "ry", "rz")) for name in self.p_names):  # rigid bodies' shapes
            from .state import rigid_parameters

            values |= rigid_parameters(scene, scene.topology())
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

    def particle_jacobian(self, q, p) -> FloatArray:
        """d velocities / du, shape (n * dim, nu): rows particle-major."""
        return self._call("particle_jacobian", q, None, p)

    def particle_bias(self, q, u, p) -> FloatArray:
        """The particles' accelerations at u' = 0, shape (n, dim)."""
        return self._call("particle_bias", q, u, p)

    def forcing_jacobians(self, q, u, p, a) -> tuple[FloatArray, FloatArray]:
        """d(F - M a)/dq, shape (nu, nq), and dF/du, shape (nu, nu)."""
        return self._call("jacobian_q", q, u, p, a), self._call("jacobian_u", q, u, p)

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

    def jacobian_function(self, p, held):
        """``J(t, y) -> (ny, ny)`` of the constrained right-hand side, for implicit methods."""
        return lambda t, y: dynamics.state_jacobian(self, y, p, held)


class _ScalarMath:
    """The functions generated expressions call, on Python floats (for single states)."""

    sqrt, sin, cos = staticmethod(math.sqrt), staticmethod(math.sin), staticmethod(math.cos)

    @staticmethod
    def sign(x: float) -> float:
        return float((x > 0.0) - (x < 0.0))


class NumpyModel(GeneratedModel):
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


class CModel(runtime.SystemModel, GeneratedModel):
    """Evaluates the compiled C module (``model.c``) through ctypes: its generated
    functions directly, the constrained dynamics through the runtime as an FbSystem."""

    backend = "c"

    def __init__(self, directory: Path) -> None:
        super().__init__(directory)
        self.library_path = cbuild.library_path(self.directory)
        lib = cbuild.load(self.library_path)
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
        self._fb_system = lib.fb_system
        self._fb_system.argtypes = [ptr, ptr]
        self._fb_system.restype = None
        self._zeros = np.zeros(max(self.nu, self.nq, 1))

    def _call(self, name, q, u, p, a=None):
        q = np.ascontiguousarray(q, dtype=float)
        u = self._zeros if u is None else np.ascontiguousarray(u, dtype=float)
        a = self._zeros if a is None else np.ascontiguousarray(a, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        out = np.empty(self.shapes[name])
        self._fn[name](q.ctypes.data, u.ctypes.data, p.ctypes.data, a.ctypes.data, out.ctypes.data)
        return out[0] if name == "damping_power" else out

    def gaps(self, q, p):
        return self._call("gaps", q, None, p)

    def _bind(self, p: np.ndarray) -> runtime.FbSystem:
        """This model as an FbSystem with parameters ``p`` (read by C where they lie: kept
        alive by the struct)."""
        system = runtime.FbSystem()
        self._fb_system(ctypes.addressof(system), p.ctypes.data)
        system.keep = p
        return system


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
    # a rigid body costs its frame T alone (about what three particles of a flexible one do)
    estimate = derivation_seconds(sum(b.n_particles if not b.rigid else 3 for b in scene.bodies), formulation, scene.dim)
    print(f"deriving the equations of {scene.name} ({n} particles, formulation {formulation}) with SymPy; "
          f"this usually takes ~{estimate:.0f} s (once: the model is cached in {out})", file=sys.stderr, flush=True)
    env = dict(os.environ, PYTHONHASHSEED="0")
    args = [scene.topology().to_json(), formulation, str(out), scene.source]
    run = run_tied("derivation.ondemand", args, env=env, capture=True)
    if run.returncode != 0:
        raise ModelError(f"deriving the model of {scene.source} failed:\n{run.stdout}{run.stderr}")
    return out


#: The floating formulation is derived whole (Kane, SymPy) per topology; above this many
#: particles that takes minutes (23: ~40 s, 100: ~6 min measured), so it is refused.
FLOATING_MAX_PARTICLES = 40


#: ``flexbody show`` derives a scene's equations whole only up to this many particles
#: without being asked (``--force``): beyond, it says what the derivation would cost.
SHOW_MAX_PARTICLES = 30


#: How much longer a 3D derivation takes than the 2D fit says (see derivation_seconds).
DIM3_FACTOR = {"particles": 10.0, "floating": 3.2}


def derivation_seconds(n_particles: int, formulation: str, dim: int = 2) -> float:
    """A rough estimate (s) of deriving and rendering a whole scene on this class of machine.

    Fitted to measurements on a 2-core VM: 2D particles 9 s at 23 particles and 96 s at 100;
    floating 37 s and 375 s (both grow as about n^1.6).  3D costs more per particle
    (``DIM3_FACTOR``: floating 9.3 s at 5 particles and 23.5 s at 8, 2.9 and 3.5 times the 2D
    fit; particles 16.7 s at 8, ten times it)."""
    base = 9.0 if formulation == "particles" else 37.0
    return base * (max(n_particles, 1) / 23.0) ** 1.6 * (DIM3_FACTOR[formulation] if dim == 3 else 1.0)


def _scene_and_formulation(scene, backend: str, formulation: str | None) -> tuple[Scene, str]:
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if backend not in BACKENDS:
        raise InputError(f"`backend` = {backend!r}: must be one of {sorted(BACKENDS)}")
    formulation = formulation or scene.simulation.formulation
    if formulation not in ("particles", "floating"):
        raise InputError(f"`formulation` = {formulation!r}: must be 'particles' or 'floating'")
    return scene, resolved_formulation(scene, formulation)


def resolved_formulation(scene: Scene, formulation: str) -> str:
    """The formulation a scene runs on when ``formulation`` is asked for: a scene of rigid
    bodies alone is its frames T, derived whole ('floating'), whichever is asked; a scene
    with a flexible body runs on the one asked (with rigid bodies, 'particles' puts their
    frames beside the assembled flexible bodies: :class:`flexbody.mixed.MixedModel`)."""
    if scene.bodies and all(b.rigid for b in scene.bodies):
        return "floating"
    return formulation


def load_derived_model(scene: Scene | str | Path, backend: str = "c", formulation: str | None = None) -> GeneratedModel:
    """Load the whole-scene derived model of a scene, deriving it first if it does not exist.

    This is the floating formulation's only form, and for the particles formulation the
    oracle that the assembled model is tested against (and what ``flexbody show`` prints).
    Rigid bodies are frames T, derived whole on the floating formulation only (the default
    for a scene with one here; :func:`load_model` runs them beside assembled flexible bodies).
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    rigid = scene.rigid_bodies
    if rigid and formulation == "particles":
        raise InputError(f"`formulation` = 'particles': bodies {rigid} are rigid, frames T, which a whole-scene model "
                         "has on the floating formulation only; load_model runs them beside assembled flexible bodies")
    scene, formulation = _scene_and_formulation(scene, backend, "floating" if rigid else formulation)
    folder = find_model_dir(scene, formulation) or derive_on_demand(scene, formulation)
    return BACKENDS[backend](folder)


def load_model(scene: Scene | str | Path, backend: str = "c", formulation: str | None = None) -> Model:
    """Load the model a scene runs on.

    Parameters
    ----------
    scene : Scene, path or bundled scene name
    backend : {"c", "numpy"}
        ``c`` uses the compiled runtime (compiled once per install, cached); ``numpy``
        needs no compiler.
    formulation : {"particles", "floating"}, optional
        Defaults to the scene's ``simulation.formulation``.  ``particles`` is assembled from
        the element kernels at once, for any topology and size; ``floating`` is the
        thesis's frames N and T, derived whole per topology (small bodies only: at most
        ``FLOATING_MAX_PARTICLES`` particles).  Rigid bodies are frames T in both: with
        ``particles`` they are derived alone and run beside the assembled flexible bodies
        (:class:`flexbody.mixed.MixedModel`); a scene of rigid bodies alone runs on ``floating``.
    """
    scene, formulation = _scene_and_formulation(scene, backend, formulation)
    model = _load_model(scene, backend, formulation)
    model.made_for = made_for(scene)
    return model


def _load_model(scene: Scene, backend: str, formulation: str) -> Model:
    """:func:`load_model` on a loaded scene and a resolved formulation."""
    if formulation == "particles" and scene.rigid_bodies:  # flexible bodies assembled, rigid ones frames beside them
        from .body_contact import BodyContactModel
        from .mixed import mixed_model

        return BodyContactModel(scene, mixed_model(scene, backend))
    if formulation == "particles":
        from .assembly import assembled_model

        if couples_contacts(scene, formulation):  # bodies that may touch each other: their contacts are added
            from .body_contact import BodyContactModel

            return BodyContactModel(scene, assembled_model(scene, backend))
        return assembled_model(scene, backend)
    if scene.dim == 3:
        for body, gauge in zip(scene.bodies, (b.gauge for b in scene.topology().bodies)):
            if body.n_particles > 1 and gauge[2] < 0:
                raise InputError(
                    f"`formulation` = 'floating': body {body.name!r} has all its {body.n_particles} particles on one "
                    "line, so in 3D no third particle fixes T's rotation about it; use the particles formulation "
                    "(the default)"
                )
    flexible = sum(b.n_particles for b in scene.bodies if not b.rigid)
    if flexible > FLOATING_MAX_PARTICLES:  # a rigid body costs its frame alone, whatever its particles
        limit = (f"the floating formulation is derived whole per topology and is offered up to "
                 f"{FLOATING_MAX_PARTICLES} of them")
        raise InputError(
            f"`formulation` = 'floating' with {flexible} particles in flexible bodies: {limit}; use the particles "
            "formulation (the default), which runs any size at once"
        )
    model = load_derived_model(scene, backend, formulation)
    if couples_contacts(scene, formulation):  # bodies that may touch each other, or a rigid body's contacts with friction
        from .body_contact import BodyContactModel

        return BodyContactModel(scene, model)
    return model


#: What a model takes from its scene when it is made, beyond the parameters each run passes
#: it (:func:`made_for`), by name.
MADE_FOR = ("topology", "contact laws", "masses", "initial positions of bodies that may touch")


def made_for(scene: Scene) -> tuple:
    """What a model loaded for ``scene`` keeps of it, in the order of :data:`MADE_FOR`: the
    topology, the contact laws (the grounds' and the pairs' friction and restitution, and
    whether a pair's edges touch), the
    particle masses and, where bodies may touch, their initial positions (the contact
    search's reach).  Another scene with the same runs correctly on the same model."""
    laws = tuple((g.friction, g.restitution) for g in scene.grounds) + tuple(
        (c.bodies, c.friction, c.restitution, c.edges) for c in scene.contacts)
    positions = scene.initial_positions().tobytes() if couples_contacts(scene) else b""
    return scene.topology(), laws, scene.masses.tobytes(), positions


def couples_contacts(scene: Scene, formulation: str | None = None) -> bool:
    """Whether :func:`load_model` adds :class:`flexbody.body_contact.BodyContactModel` to the
    scene's model on ``formulation`` (default: the scene's), whose coupled contacts the
    compiled loop does not know: bodies that may touch each other, a rigid body on a ground
    with friction, or rigid and flexible bodies on the particles formulation."""
    formulation = resolved_formulation(scene, formulation or scene.simulation.formulation)
    return (bool(scene.contacts) or bool(scene.rigid_bodies and any(g.friction > 0.0 for g in scene.grounds))
            or bool(scene.rigid_bodies and formulation == "particles"))
