"""The compiled runtime library: its C entry points, typed once, and the FbSystem struct.

One library per install (``generated/runtime`` + ``generated/kernels``, compiled on first
use into the cache) holds the integrator, the phase machine's fixed point, the assembled
particles formulation and the element kernels.  Models reach it as an ``FbSystem``
(``generated/runtime/fb_runtime.h``): sizes, a data pointer and five functions.
"""

from __future__ import annotations

import ctypes
import functools

import numpy as np

from . import cbuild

_ptr, _int, _double, _long = ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_long


class FbSystem(ctypes.Structure):
    """``struct FbSystem`` of fb_runtime.h (filled by C: ``fb_asm_system`` or a model's ``fb_system``)."""

    _fields_ = [
        ("nq", _int), ("nu", _int), ("nc", _int), ("ny", _int), ("n_particles", _int), ("dim", _int),
        ("data", _ptr), ("rhs", _ptr), ("gaps", _ptr), ("contact_state", _ptr), ("impact", _ptr),
        ("outputs", _ptr), ("project", _ptr), ("contact", _ptr), ("stencil", _ptr),
        ("friction", _ptr), ("settle", _ptr), ("slip", _ptr), ("slip_held", _ptr),
        ("tangential_push", _ptr),
    ]  # fmt: skip


#: name -> (restype, argtypes) of every entry point the runtime library exports.
SIGNATURES = {
    "fb_work_new": (_ptr, [_int, _int]),
    "fb_work_free": (None, [_ptr]),
    "fb_integrate": (_int, [_ptr, _ptr, _int, _double, _ptr, _double, _ptr, _ptr, _ptr, _ptr, _ptr, _double,
                            _double, _double, _double, _ptr, _int, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _double]),
    "fb_resolve": (_int, [_ptr, _ptr, _double, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _double, _ptr, _ptr,
                          _ptr, _ptr, _ptr, _double, _int, _double, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_trajectory": (_int, [_ptr, _ptr, _long, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_time_rhs": (_double, [_ptr, _ptr, _int, _ptr, _ptr, _ptr]),
    "fb_asm_new": (_ptr, [_int, _int, _int, _int, _ptr, _ptr]),
    "fb_asm_free": (None, [_ptr]),
    "fb_asm_bind": (None, [_ptr, _ptr]),
    "fb_asm_threads": (_int, [_ptr, _int]),
    "fb_asm_laws": (None, [_ptr, _ptr]),
    "fb_asm_system": (None, [_ptr, _ptr]),
    "fb_asm_link_jacobians": (None, [_ptr, _ptr, _ptr]),
    "fb_asm_free_accelerations": (None, [_ptr, _ptr, _ptr, _int, _ptr, _ptr]),
    "fb_sys_rhs": (_int, [_ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_gaps": (None, [_ptr, _ptr, _ptr]),
    "fb_sys_contact_state": (_int, [_ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_impact": (_int, [_ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_outputs": (None, [_ptr, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_friction_all": (_int, [_ptr, _ptr, _ptr, _ptr, _int, _ptr, _ptr, _ptr, _ptr]),
    "fb_sys_contact": (_int, [_ptr, _ptr, _ptr, _ptr, _int, _ptr, _ptr, _ptr, _ptr, _int, _ptr]),
    "fb_sys_settle": (_int, [_ptr, _ptr, _ptr]),
    "fb_closest_features": (_int, [_int, _int, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _double, _ptr, _ptr, _ptr,
                                   _ptr, _ptr, _ptr, _ptr]),
    "fb_gap_root": (_int, [_int, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _int, _int, _ptr, _ptr, _int, _double,
                           _double, _double, _double, _double, _double, _double, _ptr, _ptr]),
    "fb_dense_gaps": (_int, [_int, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _ptr, _int, _ptr, _ptr, _ptr, _ptr, _ptr, _int,
                             _double, _double, _double, _double, _ptr, _ptr]),
    "fb_held_rows": (_int, [_int, _int, _ptr, _ptr, _ptr, _int, _ptr, _ptr, _int, _ptr, _ptr, _ptr]),
    "fb_row_blocks": (_int, [_int, _int, _int, _ptr, _int, _ptr, _ptr]),
    "fb_held_slips": (_int, [_int, _ptr, _ptr, _int, _ptr, _ptr, _int, _ptr, _ptr, _ptr]),
    "fb_held_friction": (_int, [_int, _int, _ptr, _ptr, _ptr, _int, _ptr, _ptr, _int, _ptr, _ptr, _ptr, _ptr, _ptr,
                                _ptr, _ptr]),
    "fb_lemke": (_int, [_int, _ptr, _ptr, _ptr, _int, _double, _double, _ptr, _ptr, _ptr]),
}


@functools.cache
def library() -> ctypes.CDLL:
    """The runtime library, compiled on first use, with every entry point typed."""
    lib = cbuild.load(cbuild.runtime_library_path())
    for name, (restype, argtypes) in SIGNATURES.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    return lib


class Work:
    """The C work buffers of one run (``fb_work_new``), freed with this object."""

    def __init__(self, ny: int, nc: int) -> None:
        self._lib = library()
        self.address = self._lib.fb_work_new(ny, nc)
        if not self.address:
            raise MemoryError(f"cannot allocate the integrator's work buffers for {ny} states and {nc} contacts")

    def __del__(self) -> None:
        if getattr(self, "address", None):
            self._lib.fb_work_free(self.address)
            self.address = None


def batched_call(kernel, inputs: list[np.ndarray], output_shapes: list[tuple[int, ...]]) -> list[np.ndarray]:
    """Call a compiled element kernel ``kernel(k, inputs..., outputs...)`` on ``k`` rows at once.

    Parameters
    ----------
    kernel : ctypes function
        Takes the row count, then one address per input and per output array.
    inputs : list of array_like, each shape (k, ...)
        Row ``e`` of each is the kernel's ``e``-th call's input (copied C-contiguous, float).
    output_shapes : list of tuple of int
        Each output's shape per row.

    Returns
    -------
    list of ndarray, each shape (k, *shape)
    """
    rows = [np.ascontiguousarray(z, dtype=float) for z in inputs]
    k = len(rows[0])
    outputs = [np.empty((k, *shape)) for shape in output_shapes]
    kernel(k, *(z.ctypes.data for z in rows + outputs))
    return outputs


def singular_matrix_error() -> FloatingPointError:
    """What a nonzero status of a C evaluation means."""
    return FloatingPointError("mass or contact matrix not positive definite at this state")


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether arrays ``a`` and ``b`` of 8-byte items (float64, int64; C-contiguous) hold the
    same values bit for bit, as their bytes would compare (NaNs and signed zeros included),
    without copying either."""
    if a.shape != b.shape:
        return False
    # (the kept sweeps' lookups reject most other states by a few items first: body_contact._fingerprint)
    return bool(np.array_equal(a.reshape(-1).view(np.int64), b.reshape(-1).view(np.int64)))


def fixed(a: np.ndarray) -> bool:
    """Whether nobody changes ``a``: read-only and not a view of another array (the driver's
    parameters), so that it can be kept for a later comparison as it is."""
    return a.base is None and not a.flags.writeable


def kept_copy(a: np.ndarray) -> np.ndarray:
    """``a`` to keep for a later comparison (:func:`same_as_kept`): itself where it is
    :func:`fixed`, else a copy."""
    return a if fixed(a) else a.copy()


def same_as_kept(kept: np.ndarray, a: np.ndarray) -> bool:
    """Whether ``a`` is the kept array or holds its values bit for bit (:func:`same_bits`)."""
    return kept is a or same_bits(kept, a)


def _ints(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.intc)


def _floats(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float)


class SystemModel:
    """The C evaluations of a model that offers itself as an FbSystem (``system(p)``),
    through the runtime library's ``fb_sys_*`` entry points: one code path for the
    assembled and the whole-scene C models.  Needs ``ny, n_contacts, n_particles, dim``.
    """

    _system_cache: tuple[np.ndarray, FbSystem] | None = None  # (the parameters bound, their system)

    def system(self, p: np.ndarray) -> FbSystem:
        """This model as an FbSystem with parameters ``p`` (n_p,) bound, kept for the next
        call with the same parameters, bit for bit (:func:`same_bits`: a comparison reads
        every parameter, no copy).  The driver's own ``p``, read-only, is known unchanged
        without looking: it is asked for at every C call."""
        p = _floats(p)
        cached = self._system_cache
        if cached is not None and same_as_kept(cached[0], p):
            return cached[1]
        kept = kept_copy(p)  # nobody changes what is kept
        system = self._bind(kept)
        self._system_cache = (kept, system)
        return system

    def _bind(self, p: np.ndarray) -> FbSystem:  # pragma: no cover - abstract
        """A new FbSystem with parameters ``p`` (unchanged while the system lives)."""
        raise NotImplementedError

    def _address(self, p) -> int:
        return ctypes.addressof(self.system(p))

    def gaps(self, q, p) -> np.ndarray:
        """Gap of each contact, shape (nc,); reads positions only (q may be a whole state)."""
        q = _floats(q)
        out = np.empty(self.n_contacts)
        library().fb_sys_gaps(self._address(p), q.ctypes.data, out.ctypes.data)
        return out

    def rhs(self, y, p, held, push):
        y, held, push = _floats(y), _ints(held), _floats(push)
        ydot, lam = np.empty(self.ny), np.empty(self.n_contacts)
        if library().fb_sys_rhs(self._address(p), y.ctypes.data, held.ctypes.data, push.ctypes.data,
                                ydot.ctypes.data, lam.ctypes.data):
            raise singular_matrix_error()
        return ydot, lam

    def rhs_function(self, p, held, push):
        # Pointers of the frozen inputs are taken once: a call costs ~1 µs of ctypes.
        keep = [_ints(held), _floats(push), np.empty(self.n_contacts)]
        system = self.system(p)
        address, (held_ptr, push_ptr, lam_ptr) = ctypes.addressof(system), (a.ctypes.data for a in keep)
        call, ny = library().fb_sys_rhs, self.ny

        def f(t, y):
            y = _floats(y)
            ydot = np.empty(ny)
            if call(address, y.ctypes.data, held_ptr, push_ptr, ydot.ctypes.data, lam_ptr):
                raise singular_matrix_error()
            return ydot

        f.keep = (keep, system)  # keep the buffers and the system alive as long as f
        return f

    def contact_state(self, y, p, held, push):
        y, held, push = _floats(y), _ints(held), _floats(push)
        gaps, vn, lam = (np.empty(self.n_contacts) for _ in range(3))
        if library().fb_sys_contact_state(self._address(p), y.ctypes.data, held.ctypes.data, push.ctypes.data,
                                          gaps.ctypes.data, vn.ctypes.data, lam.ctypes.data):
            raise singular_matrix_error()
        return gaps, vn, lam

    def contact(self, y, p, held, push, c: int) -> tuple[float, float, float, np.ndarray] | None:
        """Contact ``c`` alone, as event location and the event instant evaluate it: its gap,
        normal velocity, force if held, and the state entries it reads (int array); None where
        contacts couple (whole-scene models)."""
        y, held, push = _floats(y), _ints(held), _floats(push)
        gap, vn, lam, k = ctypes.c_double(0.0), ctypes.c_double(0.0), ctypes.c_double(0.0), ctypes.c_int(0)
        entries = np.empty(self.ny, np.intc)
        status = library().fb_sys_contact(self._address(p), y.ctypes.data, held.ctypes.data, push.ctypes.data,
                                          int(c), ctypes.addressof(gap), ctypes.addressof(vn), ctypes.addressof(lam),
                                          entries.ctypes.data, self.ny, ctypes.addressof(k))
        if status == -2:
            return None
        if status:
            raise singular_matrix_error()
        return gap.value, vn.value, lam.value, entries[: k.value].copy()

    def friction(self, y, p, held, push) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each contact's tangential velocity and tangential contact force (nc, dim) and its
        sticking slack ``mu lam - |ft|`` (nc,; inf without friction), with the contact laws of
        ``held`` (phase codes: HELD sticks, SLIDING slips).  Zeros and inf for systems without
        contact laws (whole-scene models)."""
        y, held, push = _floats(y), _ints(held), _floats(push)
        nc = self.n_contacts
        vt, ft, slack, lam = np.zeros((nc, 3)), np.zeros((nc, 3)), np.full(nc, np.inf), np.zeros(nc)
        status = library().fb_sys_friction_all(self._address(p), y.ctypes.data, held.ctypes.data, push.ctypes.data,
                                               nc, vt.ctypes.data, ft.ctypes.data, slack.ctypes.data, lam.ctypes.data)
        if status not in (0, -2):  # -2: no contact laws, the zeros and inf stand
            raise singular_matrix_error()
        return vt[:, : self.dim], ft[:, : self.dim], slack

    def settle(self, y, p, stop) -> np.ndarray:
        """``y`` with each particle with ``stop[c]`` set onto the grounds it is below (a copy;
        unchanged where the system has no settle, as whole-scene models)."""
        out, stop = np.array(y, float), _ints(stop)
        status = library().fb_sys_settle(self._address(p), out.ctypes.data, stop.ctypes.data)
        if status not in (0, -2):
            raise singular_matrix_error()
        return out

    def impact(self, y, p, stop):
        y, stop = _floats(y), _ints(stop)
        out, loss = np.empty(self.ny), ctypes.c_double(0.0)
        if library().fb_sys_impact(self._address(p), y.ctypes.data, stop.ctypes.data, out.ctypes.data,
                                   ctypes.addressof(loss)):
            raise singular_matrix_error()
        return out, loss.value

    def trajectory(self, Y, p, held, push):
        """Positions and velocities (nt, n, dim), energies (nt, 4) and contact forces (nt, nc)
        along states ``Y (nt, ny)`` with contact sets ``held``, ``push`` (nt, nc)."""
        Y, held, push = _floats(Y), _ints(held), _floats(push)
        n = len(Y)
        X, V = np.empty((n, self.n_particles, self.dim)), np.empty((n, self.n_particles, self.dim))
        E, lam = np.empty((n, 4)), np.empty((n, self.n_contacts))
        work = Work(self.ny, self.n_contacts)
        if library().fb_trajectory(work.address, self._address(p), n, Y.ctypes.data, held.ctypes.data,
                                   push.ctypes.data, X.ctypes.data, V.ctypes.data, E.ctypes.data, lam.ctypes.data):
            raise singular_matrix_error()
        return X, V, E, lam

    def time_rhs(self, y, p, held, push, calls: int = 20000) -> float:
        """Mean seconds per right-hand-side call at ``y``, timed inside C (no Python overhead)."""
        y, held, push = _floats(y), _ints(held), _floats(push)
        work = Work(self.ny, self.n_contacts)
        return library().fb_time_rhs(work.address, self._address(p), calls, y.ctypes.data, held.ctypes.data,
                                     push.ctypes.data)
