"""The forces of held contacts between bodies on particle coordinates, in C.

:class:`CompiledHeldRows` calls ``fb_held_rows`` of the runtime library
(``generated/runtime/held_rows.c``): the frictionless rows of
:meth:`flexbody.body_contact.BodyContactModel._solve` (the held slots and the ground rows
of the particles they move), their ``J M^-1 J^T`` in the independent blocks of rows that
share particles, each solved by the ordered Cholesky of
:func:`flexbody.dynamics.contact_solve` as a block of the whole matrix (redundant rows
dropped relative to the largest diagonal entry of all the rows, as ``contact_solve`` drops
them).  A pile's right-hand side solves such rows at every
evaluation; in NumPy their assembly cost three times the whole C right-hand side.

With friction (``fb_held_slips``, ``fb_held_friction``): each contact's tangent rows too,
as the frictional branch of ``_solve`` takes them (a sticking contact holds them, a sliding
one's friction is dragged along by its normal force, so the matrix is not symmetric: each
block is inverted).  Where the rows are (nearly) dependent the NumPy twin's least squares chooses
among several answers, so C hands the problem back to it.
"""

from __future__ import annotations

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray


class CompiledHeldRows:
    """``fb_held_rows`` (and with friction ``fb_held_slips``, ``fb_held_friction``) for the
    particles of one model.

    Parameters
    ----------
    masses : ndarray, shape (n,)
        The particles' masses (kg), all positive.
    dim : int
        2 or 3.

    Attributes
    ----------
    friction_solves : list of int
        How many frictional problems :meth:`friction` solved, and how many it handed back.
    """

    def __init__(self, masses: FloatArray, dim: int) -> None:
        from . import runtime

        lib = runtime.library()
        self._call, self._blocks = lib.fb_held_rows, lib.fb_row_blocks
        self._slips, self._friction = lib.fb_held_slips, lib.fb_held_friction
        self.dim = dim
        self.n = len(masses)
        self.inverse_mass = np.ascontiguousarray(1.0 / np.asarray(masses, float))
        self._inverse_mass = self.inverse_mass.ctypes.data  # taken once: each address costs microseconds
        self.friction_solves = [0, 0]

    def __call__(self, x: FloatArray, v: FloatArray, acc: FloatArray, ground_particles: IntArray,
                 ground_normals: FloatArray, slot_points: IntArray) -> FloatArray | None:
        """The rows' forces, adding their accelerations to ``acc`` in place.

        Parameters
        ----------
        x, v : ndarray, shape (n, dim)
            Positions and velocities.
        acc : ndarray, shape (n * dim,)
            The free accelerations, C-contiguous (a slice of the right-hand side).
        ground_particles : ndarray of int, shape (k_g,)
        ground_normals : ndarray, shape (k_g, dim)
            The held ground rows: each one's particle and its ground's unit normal.
        slot_points : ndarray of int, shape (k_s, dim + 1)
            The held slots: each one's particle, then its element's vertices.

        Returns
        -------
        lam : ndarray, shape (k_g + k_s,) or None
            The forces (N), ground rows first; None, with ``acc`` unchanged, where a pivot
            falls below ``-REDUNDANT`` of the largest diagonal entry (the caller solves with
            :func:`flexbody.dynamics.contact_solve`, whose pivoted fallback copes).
        """
        x, v, *rows = self._checked(x, v, ground_particles, ground_normals, slot_points, frames=False)
        return LaidOutRows(self, *rows).solve(x.ctypes.data, v.ctypes.data, acc)

    def laid_out(self, ground_particles: IntArray, ground_normals: FloatArray, slot_points: IntArray) -> LaidOutRows:
        """:meth:`__call__` for these rows alone (:class:`LaidOutRows`): checked once, as a
        segment's right-hand side solves the same rows at every evaluation."""
        return LaidOutRows(self, *self._checked_rows(ground_particles, ground_normals, slot_points, frames=False))

    def slips(self, x: FloatArray, v: FloatArray, ground_particles: IntArray, ground_frames: FloatArray,
              slot_points: IntArray) -> tuple[FloatArray, FloatArray]:
        """Each held contact's slip rates along its tangents, and those tangents.

        Parameters
        ----------
        x, v : ndarray, shape (n, dim)
        ground_particles : ndarray of int, shape (k_g,)
        ground_frames : ndarray, shape (k_g, dim, dim)
            Each ground row's frame: its ground's unit normal, then its tangents.
        slot_points : ndarray of int, shape (k_s, dim + 1)

        Returns
        -------
        slip : ndarray, shape (k, dim - 1)
            m/s; k = k_g + k_s, ground rows first.
        tangents : ndarray, shape (k, dim - 1, dim)
        """
        x, v, ground_particles, ground_frames, slot_points = self._checked(x, v, ground_particles, ground_frames,
                                                                        slot_points)
        d, k = self.dim, len(ground_particles) + len(slot_points)
        slip, tangents = np.empty((k, d - 1)), np.empty((k, d - 1, d))
        if self._slips(d, x.ctypes.data, v.ctypes.data, len(ground_particles), ground_particles.ctypes.data,
                       ground_frames.ctypes.data, len(slot_points), slot_points.ctypes.data, slip.ctypes.data,
                       tangents.ctypes.data) < 0:
            raise MemoryError(f"cannot allocate the work buffers of {k} held contacts")
        return slip, tangents

    def friction(self, x: FloatArray, v: FloatArray, acc: FloatArray, ground_particles: IntArray,
                 ground_frames: FloatArray, slot_points: IntArray, mu: FloatArray, stick: np.ndarray,
                 drag: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        """The held contacts' forces with friction, adding their accelerations to ``acc`` in
        place: a sticking contact (``stick``) holds its tangent rows too, a sliding one's
        friction is ``drag`` times its normal force (the frictional branch of
        :meth:`flexbody.body_contact.BodyContactModel._solve`).

        Parameters
        ----------
        x, v, ground_particles, ground_frames, slot_points
            As :meth:`slips`.
        acc : ndarray, shape (n * dim,)
            The free accelerations, C-contiguous, written in place.
        mu : ndarray, shape (k,)
            The contacts' friction coefficients (a sticking one's friction is split as mu
            lam_n where it is not unique, as the NumPy twin's least squares does).
        stick : ndarray of bool, shape (k,)
        drag : ndarray, shape (k, dim - 1)
            Friction per newton of normal force along each contact's tangents (0 unless it slides).

        Returns
        -------
        (lam_n, lam_t) : ndarray, shapes (k,) and (k, dim - 1), or None
            The normal forces and the friction along the tangents (N); None, with ``acc``
            unchanged, where the twin's least squares might drop a singular value (a bound
            on its scaled matrix's condition above 1e10: the rows (nearly) dependent, or a
            sticking contact's friction split by a normal force at or below 0) or a term is
            not finite: the twin picks among the answers, or reports the blow-up.
        """
        x, v, ground_particles, ground_frames, slot_points = self._checked(x, v, ground_particles, ground_frames,
                                                                        slot_points)
        self._check_acc(acc)
        d, k = self.dim, len(ground_particles) + len(slot_points)
        mu, stick = np.ascontiguousarray(mu, float), np.ascontiguousarray(stick, np.intc)
        drag = np.ascontiguousarray(drag, float)
        if mu.shape != (k,) or stick.shape != (k,) or drag.shape != (k, d - 1):
            raise ValueError(f"mu and stick must be ({k},) and drag ({k}, {d - 1}); got {mu.shape}, {stick.shape} "
                             f"and {drag.shape}")
        lam_n, lam_t = np.empty(k), np.empty((k, d - 1))
        status = self._friction(d, self.n, x.ctypes.data, v.ctypes.data, self._inverse_mass, len(ground_particles),
                                ground_particles.ctypes.data, ground_frames.ctypes.data, len(slot_points),
                                slot_points.ctypes.data, mu.ctypes.data, stick.ctypes.data, drag.ctypes.data,
                                acc.ctypes.data, lam_n.ctypes.data, lam_t.ctypes.data)
        if status < 0:
            raise MemoryError(f"cannot allocate the work buffers of {k} held contacts")
        self.friction_solves[status] += 1
        return None if status else (lam_n, lam_t)

    def _checked(self, x, v, ground_particles, ground_axes, slot_points, frames: bool = True):
        """The rows' arguments as the C routines take them, checked: ``ground_axes`` each
        ground row's frame (k_g, dim, dim), or with ``frames`` False its normal (k_g, dim)."""
        x, v = np.ascontiguousarray(x, float), np.ascontiguousarray(v, float)
        d = self.dim
        if x.shape != (self.n, d) or v.shape != (self.n, d):
            raise ValueError(f"positions and velocities must be ({self.n}, {d}); got {x.shape} and {v.shape}")
        return x, v, *self._checked_rows(ground_particles, ground_axes, slot_points, frames)

    def _checked_rows(self, ground_particles, ground_axes, slot_points, frames: bool = True):
        """The rows' index and axis arguments of :meth:`_checked`, checked."""
        d = self.dim
        ground_particles = np.ascontiguousarray(ground_particles, np.intc)
        ground_axes = np.ascontiguousarray(ground_axes, float)
        slot_points = np.ascontiguousarray(slot_points, np.intc).reshape(-1, d + 1)
        shape = (len(ground_particles), d, d) if frames else (len(ground_particles), d)
        if ground_axes.shape != shape:
            raise ValueError(f"the ground rows' {'frames' if frames else 'normals'} must be {shape}; "
                             f"got {ground_axes.shape}")
        for name, index in (("ground_particles", ground_particles), ("slot_points", slot_points)):
            if index.size and not (0 <= index.min() and index.max() < self.n):
                raise ValueError(f"{name} must be particle indices in [0, {self.n}); got {index.min()}..{index.max()}")
        return ground_particles, ground_axes, slot_points

    def _check_acc(self, acc: FloatArray) -> None:
        """``acc`` must be the C routines' in-place accelerations (n * dim,)."""
        if acc.dtype != np.float64 or not acc.flags.c_contiguous or acc.shape != (self.n * self.dim,):
            raise ValueError(f"acc must be a C-contiguous float64 array of shape ({self.n * self.dim},), "
                             "written in place")

    def blocks(self, ground_particles: IntArray, slot_points: IntArray) -> IntArray:
        """Which block each row is in, shape (k_g + k_s,): rows joined through a particle
        both move share one (they act on each other), numbered in the order of their lowest
        rows; the rows as for :meth:`__call__` (ground rows first)."""
        ground_particles = np.ascontiguousarray(ground_particles, np.intc)
        slot_points = np.ascontiguousarray(slot_points, np.intc)
        block = np.empty(len(ground_particles) + len(slot_points), np.intc)
        if self._blocks(self.dim, self.n, len(ground_particles), ground_particles.ctypes.data, len(slot_points),
                        slot_points.ctypes.data, block.ctypes.data) < 0:
            raise MemoryError(f"cannot allocate the work buffers of {len(block)} rows' blocks")
        return block


class LaidOutRows:
    """:meth:`CompiledHeldRows.__call__` for one set of frictionless rows, checked and their
    addresses taken once (each costs a microsecond; a pile's right-hand side solved its rows
    some 20 000 times in 0.25 s, each call checking and converting them again).

    Parameters
    ----------
    rows : CompiledHeldRows
    ground_particles : ndarray of int, shape (k_g,)
    ground_normals : ndarray, shape (k_g, dim)
    slot_points : ndarray of int, shape (k_s, dim + 1)
        As for :meth:`CompiledHeldRows.__call__`, checked (:meth:`CompiledHeldRows._checked_rows`).
    """

    def __init__(self, rows: CompiledHeldRows, ground_particles: IntArray, ground_normals: FloatArray,
                 slot_points: IntArray) -> None:
        self._rows, self._kept = rows, (ground_particles, ground_normals, slot_points)  # kept alive: C reads them
        self.n_rows = len(ground_particles) + len(slot_points)
        self._arguments = (len(ground_particles), ground_particles.ctypes.data, ground_normals.ctypes.data,
                           len(slot_points), slot_points.ctypes.data)

    def __call__(self, state: FloatArray, acc: FloatArray) -> FloatArray | None:
        """The rows' forces at ``state`` (positions, then velocities: its first ``2 n dim``
        entries; float64), adding their accelerations to ``acc`` in place, as
        :meth:`CompiledHeldRows.__call__` (None where that returns None).

        Parameters
        ----------
        state : ndarray, shape (>= 2 n dim,)
        acc : ndarray, shape (n * dim,)
            C-contiguous float64, written in place.

        Returns
        -------
        lam : ndarray, shape (k_g + k_s,) or None
        """
        nq = self._rows.n * self._rows.dim
        state = np.ascontiguousarray(state, float)
        if state.shape[0] < 2 * nq:
            raise ValueError(f"the state must hold the {2 * nq} positions and velocities first; got shape {state.shape}")
        at = state.ctypes.data
        return self.solve(at, at + nq * state.itemsize, acc)

    def solve(self, x: int, v: int, acc: FloatArray) -> FloatArray | None:
        """As :meth:`__call__`, the positions and velocities (n, dim) each given by the
        address of their C-contiguous float64 entries (kept alive by the caller)."""
        rows = self._rows
        rows._check_acc(acc)
        lam = np.empty(self.n_rows)
        k_g, ground_particles, ground_normals, k_s, slot_points = self._arguments
        status = rows._call(rows.dim, rows.n, x, v, rows._inverse_mass, k_g, ground_particles, ground_normals, k_s,
                            slot_points, acc.ctypes.data, lam.ctypes.data)
        if status < 0:
            raise MemoryError(f"cannot allocate the held rows' work buffers ({len(lam)} rows)")
        return None if status else lam
