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
"""

from __future__ import annotations

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray


class CompiledHeldRows:
    """``fb_held_rows`` for the particles of one model.

    Parameters
    ----------
    masses : ndarray, shape (n,)
        The particles' masses (kg), all positive.
    dim : int
        2 or 3.
    """

    def __init__(self, masses: FloatArray, dim: int) -> None:
        from . import runtime

        lib = runtime.library()
        self._call, self._blocks = lib.fb_held_rows, lib.fb_row_blocks
        self.dim = dim
        self.n = len(masses)
        self.inverse_mass = np.ascontiguousarray(1.0 / np.asarray(masses, float))
        self._inverse_mass = self.inverse_mass.ctypes.data  # taken once: each address costs microseconds

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
        x, v = np.ascontiguousarray(x, float), np.ascontiguousarray(v, float)
        d = self.dim
        if x.shape != (self.n, d) or v.shape != (self.n, d):
            raise ValueError(f"positions and velocities must be ({self.n}, {d}); got {x.shape} and {v.shape}")
        if acc.dtype != np.float64 or not acc.flags.c_contiguous or acc.shape != (self.n * d,):
            raise ValueError(f"acc must be a C-contiguous float64 array of shape ({self.n * d},), written in place")
        ground_particles = np.ascontiguousarray(ground_particles, np.intc)
        ground_normals = np.ascontiguousarray(ground_normals, float)
        slot_points = np.ascontiguousarray(slot_points, np.intc)
        for name, index in (("ground_particles", ground_particles), ("slot_points", slot_points)):
            if index.size and not (0 <= index.min() and index.max() < self.n):
                raise ValueError(f"{name} must be particle indices in [0, {self.n}); got {index.min()}..{index.max()}")
        lam = np.empty(len(ground_particles) + len(slot_points))
        status = self._call(self.dim, len(x), x.ctypes.data, v.ctypes.data, self._inverse_mass,
                            len(ground_particles), ground_particles.ctypes.data, ground_normals.ctypes.data,
                            len(slot_points), slot_points.ctypes.data, acc.ctypes.data, lam.ctypes.data)
        if status < 0:
            raise MemoryError(f"cannot allocate the held rows' work buffers ({len(lam)} rows)")
        return None if status else lam

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
