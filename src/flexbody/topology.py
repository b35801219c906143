"""Topology: the part of a scene that selects a generated model.

Particle count, links, damper law, dimension and the number of grounds change the
symbolic equations; masses, stiffness, damping, rest lengths, gravity and ground
placement are parameters passed at run time.  The floating formulation also fixes its
gauge from the body's geometry (which particle is pinned at T's origin, which one lies
on T's x-axis and, in 3D, which one lies in T's x-y plane), so that choice is part of the
topology too.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

#: A manual tag; the digest also covers the generator's source files (see generator_fingerprint).
GENERATOR_VERSION = "3"


#: What a whole-scene model is generated from (derivation/ and its templates); editing
#: the element kernels or the runtime does not touch these models' digests.
GENERATOR_SOURCES = ("mechanics.py", "codegen.py", "printers.py", "templates/model.py.jinja",
                     "templates/model.c.jinja", "templates/model.h.jinja", "templates/eom.md.jinja")


@functools.cache
def generator_fingerprint() -> str:
    """Hash of the sources that generate whole-scene models (found without importing them).

    A change to how models are generated changes every digest, so a cached model built by
    an older generator is never reused, and committed models show up as stale.
    """
    spec = importlib.util.find_spec("derivation")
    if spec is None or not spec.submodule_search_locations:
        return GENERATOR_VERSION
    folder = Path(next(iter(spec.submodule_search_locations)))
    digest = hashlib.sha256(GENERATOR_VERSION.encode())
    for name in GENERATOR_SOURCES:
        path = folder / name
        digest.update(name.encode() + b"\0" + (path.read_bytes() if path.is_file() else b""))
    return digest.hexdigest()[:16]


@dataclass(frozen=True)
class BodyTopology:
    n_particles: int
    links: tuple[tuple[int, int], ...]
    damper: str
    gauge: tuple[int, ...]  # (anchor, reference) in 2D, (anchor, reference, third) in 3D, see gauge_particles
    rigid: bool = False  # frame T only: its particles are fixed in T (their coordinates are parameters)


@dataclass(frozen=True)
class Topology:
    dim: int
    n_grounds: int
    bodies: tuple[BodyTopology, ...]

    @property
    def n_particles(self) -> int:
        return sum(b.n_particles for b in self.bodies)

    @property
    def n_links(self) -> int:
        return sum(len(b.links) for b in self.bodies)

    @property
    def has_rigid(self) -> bool:
        return any(b.rigid for b in self.bodies)

    def to_json(self) -> str:
        """Canonical JSON (sorted keys, no spaces): the input of :meth:`digest`.  ``rigid``
        appears only where it is true, so the digests of flexible scenes are what they were."""
        data = asdict(self)
        for body in data["bodies"]:
            if not body["rigid"]:
                del body["rigid"]
        return json.dumps(data, sort_keys=True, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str) -> Topology:
        data = json.loads(text)
        bodies = tuple(
            BodyTopology(
                n_particles=b["n_particles"],
                links=tuple(tuple(link) for link in b["links"]),
                damper=b["damper"],
                gauge=tuple(b["gauge"]),
                rigid=bool(b.get("rigid", False)),
            )
            for b in data["bodies"]
        )
        return cls(dim=data["dim"], n_grounds=data["n_grounds"], bodies=bodies)

    def digest(self, formulation: str) -> str:
        """Hash of topology, formulation and generator (16 hex digits)."""
        text = f"{self.to_json()}|{formulation}|{generator_fingerprint()}"
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def gauge_particles(points: np.ndarray) -> tuple[int, ...]:
    """Gauge of the floating formulation for one body.

    The anchor is the particle nearest the body's geometric centre (the centre particle of
    a ``ring``); it is pinned at T's origin, which fixes translation.  The reference is the
    lowest-indexed other particle; it lies on T's x-axis, which fixes the rotation in 2D
    (three coordinates removed).  In 3D it leaves the rotation about that axis, which the
    third particle fixes: it lies in T's x-y plane (its z in T is not a coordinate), six
    coordinates removed in all.  The third is the particle farthest from the line through
    anchor and reference (the lowest index among equals): the longest lever arm for the
    rotation about T's x-axis, so the mass matrix is best conditioned.  With the rigid
    motions removed, the mass matrix is nonsingular.

    Parameters
    ----------
    points : ndarray, shape (n, dim)

    Returns
    -------
    tuple of int
        ``(anchor, reference)`` in 2D, ``(anchor, reference, third)`` in 3D; -1 where a
        body has no such particle: the reference of a single particle, the third of a
        body whose particles are all on one line (two particles, a straight chain), which
        the floating formulation cannot gauge in 3D (see
        :func:`flexbody.model.load_model`).
    """
    points = np.asarray(points, dtype=float)
    n, dim = points.shape
    if n == 1:
        return (0, -1) if dim == 2 else (0, -1, -1)
    distance = np.linalg.norm(points - points.mean(axis=0), axis=1)
    scale = max(float(np.ptp(points, axis=0).max()), 1e-300)
    anchor = int(np.flatnonzero(distance <= distance.min() + 1e-9 * scale)[0])
    reference = 0 if anchor != 0 else 1
    if dim == 2:
        return (anchor, reference)
    axis = points[reference] - points[anchor]
    axis = axis / np.linalg.norm(axis)
    offset = points - points[anchor]
    off_line = np.linalg.norm(offset - np.outer(offset @ axis, axis), axis=1)  # (n,) distance from the line
    if off_line.max() <= 1e-9 * scale:
        return (anchor, reference, -1)
    third = int(np.flatnonzero(off_line >= off_line.max() - 1e-9 * scale)[0])
    return (anchor, reference, third)
