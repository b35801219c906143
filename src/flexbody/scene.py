"""Scene files: the TOML schema of DESIGN.md §2, loaded into immutable, validated objects.

A scene names bodies (particles, links, masses, spring and damper constants, initial
pose and velocity), the grounds they fall on, gravity and the simulation settings.
:func:`load_scene` reads a path, a bundled scene's name or a mapping, checks every field,
and raises one :class:`SceneError` listing every problem (field, value, rule).

Units are SI throughout: m, kg, s, N/m, N·s/m.

Bodies touching each other (DESIGN.md §6; simulated by :mod:`flexbody.body_contact`
between flexible and rigid bodies, with friction, and a flexible body's outer surface
with itself (:mod:`flexbody.own_surface`); what it cannot run yet ``flexbody run``
refuses, naming the bodies)::

    [[bodies]]
    name = "ball"
    rigid = false          # default; true: no springs or dampers (stiffness, damping,
                           # damper, rest_lengths are then an error)
    collide = false        # default; true: may touch every other body with collide = true
    self_contact = false   # default; true: may touch its own surface (flexible bodies;
                           # not near each particle, see flexbody.own_surface)
    surface = [[1, 2], [2, 3], ...]   # optional: [i, j] segments in 2D, [i, j, k] triangles
                                      # in 3D, outward; default: the shape's (below)

    [[contacts]]           # optional, any number; implies collide for this pair only
    bodies = ["ball", "floor"]   # two body names (the same twice: needs self_contact = true)
    friction = 0.0         # Coulomb mu >= 0, default 0
    restitution = 0.0      # Newton e in [0, 1], default 0
    edges = false          # default; true (3D): edges touch edges too

Pairs that touch: each ``[[contacts]]`` entry (each pair once), then every pair of bodies
with ``collide = true`` and every body with ``self_contact = true`` not listed there, with
friction 0 and restitution 0 (:attr:`Scene.contacts`).  A body's surface comes from its
shape (:mod:`flexbody.presets`: ring, ellipse and polygon perimeters, the disc's lattice
boundary, sphere hull, box faces, a mesh's boundary faces; none for a chain, explicit
particles or a planar shape in 3D) unless ``surface`` is given.  Every body in a pair
needs a closed, outward surface (:mod:`flexbody.surface`): a gap's sign needs an inside.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from . import presets
from ._fields import Problems, TableReader, Words
from .choices import (  # noqa: F401  (re-exported: the choices are part of the scene schema)
    BACKENDS,
    CHATTER_IMPACTS,
    COMPILED_METHODS,
    DAMPERS,
    FORMULATIONS,
    IMPACT_MODES,
    MAX_PARTICLES,
    MAX_SAMPLES,
    METHODS,
    SHAPES,
    SPATIAL_SHAPES,
)
from .errors import InputError, shown
from .surface import closure_problem, degenerate, empty, signed_measure
from .topology import BodyTopology, Topology, gauge_particles

DEFAULT_GRAVITY = (0.0, -9.81)
BODY_KEYS = (
    "name", "shape", "count", "radius", "radii", "center", "vertices", "spacing", "size", "file", "scale",
    "particles", "links", "mass", "masses", "mass_total", "stiffness", "damping", "damper", "rest_lengths",
    "position", "angle", "rotation", "velocity", "angular_velocity", "particle_velocities", "rigid", "collide",
    "surface", "self_contact",
)  # fmt: skip
#: Keys of a body that only a flexible body uses (a rigid body has no springs or dampers).
ELASTIC_KEYS = ("stiffness", "damping", "damper", "rest_lengths")
CONTACT_KEYS = ("bodies", "friction", "restitution", "edges")
SIMULATION_KEYS = (
    "t_end", "output_dt", "method", "rtol", "atol", "impact", "impact_dt", "formulation", "backend",
    "chatter_impacts",
)  # fmt: skip
#: Geometry keys each shape takes (``None``: explicit ``particles`` and ``links``); any other
#: geometry key beside them is an error, not silently ignored.
SHAPE_KEYS = {
    "ring": ("count", "radius", "center"),
    "ellipse": ("count", "radii", "center"),
    "polygon": ("vertices", "center"),
    "chain": ("count", "spacing"),
    "disc": ("count", "radius"),
    "sphere": ("count", "radius", "center"),
    "box": ("count", "size"),
    "mesh": ("file", "scale", "center"),
    None: ("particles", "links"),
}
GEOMETRY_KEYS = ("count", "radius", "radii", "center", "vertices", "spacing", "size", "file", "scale", "particles",
                 "links")
#: Scene names name folders (``generated/<name>_<formulation>/``): keep them portable.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_.-]{1,64}")
NAME_RULE = "must be 1 to 64 characters from A-Z a-z 0-9 _ . - (it names output folders)"


class SceneError(InputError):
    """A scene failed validation; ``problems`` lists every field that is wrong."""

    def __init__(self, source: str, problems: list[str]) -> None:
        self.source = source
        self.problems = list(problems)
        lines = "\n".join(f"  - {p}" for p in problems)
        super().__init__(f"scene {source} has {len(problems)} problem(s):\n{lines}")


class OverdampedLinkWarning(UserWarning):
    """A link's damping is at or above critical (thesis eq. 3.12): 4 k mu - c^2 <= 0."""


def _frozen(array: Any) -> np.ndarray:
    out = np.array(array, dtype=float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class Ground:
    """A half-plane: a particle's gap is ``(x - point) . normal`` (>= 0 outside).

    ``friction`` is Coulomb's mu (one coefficient, static = kinetic) and ``restitution``
    Newton's e (``v_n+ = -e v_n-`` at an impact); both 0 by default: frictionless and
    plastic, the thesis's ground.
    """

    point: tuple[float, ...]
    normal: tuple[float, ...]  # unit length
    friction: float = 0.0
    restitution: float = 0.0


@dataclass(frozen=True, eq=False)
class Body:
    """One flexible body: particles in frame T, links, constants and initial motion.

    Attributes
    ----------
    points : ndarray, shape (n, dim)
        Particle positions in frame T.
    links : tuple of (int, int)
        Particle pairs joined by a spring and a damper, indices within the body.
    masses : ndarray, shape (n,)
    stiffness, damping, rest_lengths : ndarray, shape (n_links,)
    damper : {"relative", "axial"}
        ``relative``: f = c (V_j - V_i) (thesis eq. 3.8); ``axial``: only the component of
        the relative velocity along the link (a central force, conserves angular momentum).
    position : tuple, (dim,)
        Origin of T in N (q1, q2[, q3]): the centre of a ring, ellipse, disc, sphere or box,
        the midpoint of a chain, the origin of the coordinates of a polygon's ``vertices``,
        of a mesh file's vertices (after ``scale``) or of explicit ``particles`` (see
        :mod:`flexbody.presets`).
    angle : float
        2D: rotation of T about N3 (q3), rad.  0 in 3D.
    rotation : tuple, (3,)
        3D: T's orientation in N as a rotation vector (axis times angle, rad); the zero
        vector (the default) leaves T aligned with N.  ``(0, 0, 0)`` in 2D.
    velocity : tuple, (dim,)
        Initial velocity of T's origin.
    angular_velocity : float or tuple (3,)
        Initial spin of T about its origin: a scalar (about N3) in 2D, a vector in 3D.
    particle_velocities : ndarray, shape (n, dim)
        Added to the rigid-body velocity of each particle.
    surface : ndarray of int, shape (m, dim)
        What other bodies' particles can hit, indices within the body: segments ``[i, j]``
        in 2D, triangles ``[i, j, k]`` in 3D, outward (see :mod:`flexbody.surface`).  From
        the shape (see :mod:`flexbody.presets`) unless the scene gives ``surface``; shape
        (0, dim) for a body without one (a chain, explicit particles, a planar shape in 3D).
    rigid : bool
        A rigid body: the floating frame T without elastic coordinates (no springs, no
        dampers; ``stiffness`` and ``damping`` are 0).  Default false.
    collide : bool
        The body may touch every other body with ``collide = true`` (friction 0,
        restitution 0 unless a ``[[contacts]]`` entry for the pair says otherwise).
        Default false.
    self_contact : bool
        The body's particles may hit its own surface.  Default false.
    """

    name: str
    points: np.ndarray
    links: tuple[tuple[int, int], ...]
    masses: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest_lengths: np.ndarray
    damper: str
    position: tuple[float, ...]
    angle: float
    velocity: tuple[float, ...]
    angular_velocity: float | tuple[float, ...]
    particle_velocities: np.ndarray
    rotation_vector: tuple[float, ...] = (0.0, 0.0, 0.0)
    surface: np.ndarray = field(default_factory=lambda: empty(2))
    rigid: bool = False
    collide: bool = False
    self_contact: bool = False

    @property
    def n_particles(self) -> int:
        return len(self.points)

    @property
    def dim(self) -> int:
        return len(self.position)

    def rotation(self) -> np.ndarray:
        """Rotation matrix from T to N, shape (dim, dim)."""
        if self.dim == 3:
            return rotation_matrix(self.rotation_vector)
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([[c, -s], [s, c]])

    def initial_positions(self) -> np.ndarray:
        """Particle positions in N, shape (n, dim)."""
        return np.asarray(self.position) + self.points @ self.rotation().T

    def initial_velocities(self) -> np.ndarray:
        """Particle velocities in N, shape (n, dim): rigid motion plus the per-particle extra."""
        r = self.points @ self.rotation().T
        if self.dim == 3:
            spin = np.cross(np.asarray(self.angular_velocity, float), r)
        else:
            spin = self.angular_velocity * np.column_stack([-r[:, 1], r[:, 0]])
        return np.asarray(self.velocity) + spin + self.particle_velocities


def rotation_matrix(rotation_vector) -> np.ndarray:
    """The rotation by the rotation vector ``axis * angle`` (Rodrigues), shape (3, 3); the
    zero vector gives the identity."""
    w = np.asarray(rotation_vector, dtype=float)
    angle = float(np.linalg.norm(w))
    if angle == 0.0:
        return np.eye(3)
    k = w / angle
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


@dataclass(frozen=True)
class BodyContact:
    """Two bodies that may touch: the particles of each can hit the other's surface.

    Attributes
    ----------
    bodies : (int, int)
        Indices into ``Scene.bodies``, first <= second; equal for a body's self-contact.
    friction : float
        Coulomb's mu between the two (static = kinetic); default 0.
    restitution : float
        Newton's e between the two, in [0, 1]; default 0 (plastic).
    edges : bool
        Whether their surfaces' edges touch each other too (3D, with the pair's friction
        and restitution: :class:`flexbody.edge_contact.EdgeSlots`);
        default False: only a particle of one touches the other's surface, and edges that
        meet pass through each other (measured).
    """

    bodies: tuple[int, int]
    friction: float = 0.0
    restitution: float = 0.0
    edges: bool = False


@dataclass(frozen=True)
class SimulationSettings:
    """Numerical settings of a run; every field can be overridden from the CLI."""

    t_end: float
    output_dt: float
    method: str | None = None  # None: dopri5 with the C backend, RK45 with NumPy
    rtol: float = 1e-6
    atol: float = 1e-9
    impact: str = "instant"
    impact_dt: float | None = None
    formulation: str = "particles"
    backend: str = "c"
    #: The chatter guard's bound: more impacts of one particle than this within 1 ms stop the run.
    chatter_impacts: int = CHATTER_IMPACTS


@dataclass(frozen=True, eq=False)
class Scene:
    """A validated scene. Global particle index: bodies in file order, then particle order."""

    name: str
    gravity: tuple[float, ...]
    grounds: tuple[Ground, ...]
    bodies: tuple[Body, ...]
    simulation: SimulationSettings
    source: str = "<mapping>"
    warnings: tuple[str, ...] = field(default=())
    #: The pairs of bodies that may touch: ``[[contacts]]`` entries in file order, then the
    #: pairs of ``collide = true`` bodies and the ``self_contact = true`` bodies not listed there.
    contacts: tuple[BodyContact, ...] = ()

    @property
    def dim(self) -> int:
        return len(self.gravity)

    @property
    def rigid_bodies(self) -> list[str]:
        """Names of the bodies with ``rigid = true`` (they run on the floating formulation)."""
        return [b.name for b in self.bodies if b.rigid]

    def surfaces(self) -> tuple[np.ndarray, np.ndarray]:
        """Every body's surface with global particle indices.

        Returns
        -------
        elements : ndarray of int, shape (m, dim)
            Segments (2D) or triangles (3D), bodies in file order.
        owner : ndarray of int, shape (m,)
            The index in ``bodies`` of each element's body.
        """
        offsets = np.cumsum([0] + [b.n_particles for b in self.bodies])
        elements = [np.asarray(b.surface, dtype=np.intp).reshape(-1, self.dim) + o
                    for b, o in zip(self.bodies, offsets)]
        owner = [np.full(len(e), k, dtype=np.intp) for k, e in enumerate(elements)]
        return np.vstack(elements), np.concatenate(owner)

    @property
    def n_particles(self) -> int:
        return sum(b.n_particles for b in self.bodies)

    @property
    def masses(self) -> np.ndarray:
        """All particle masses, shape (n,)."""
        return np.concatenate([b.masses for b in self.bodies])

    def links(self) -> np.ndarray:
        """All links with global particle indices, shape (n_links, 2)."""
        offsets = np.cumsum([0] + [b.n_particles for b in self.bodies])
        pairs = [np.asarray(b.links, dtype=int).reshape(-1, 2) + o for b, o in zip(self.bodies, offsets)]
        return np.vstack(pairs) if pairs else np.zeros((0, 2), int)

    def initial_positions(self) -> np.ndarray:
        """All particle positions in N, shape (n, dim)."""
        return np.vstack([b.initial_positions() for b in self.bodies])

    def initial_velocities(self) -> np.ndarray:
        """All particle velocities in N, shape (n, dim)."""
        return np.vstack([b.initial_velocities() for b in self.bodies])

    def topology(self) -> Topology:
        """What selects a generated model: dimension, particles, links, dampers, grounds."""
        return Topology(
            dim=self.dim,
            n_grounds=len(self.grounds),
            bodies=tuple(
                BodyTopology(
                    n_particles=b.n_particles,
                    links=b.links,
                    damper=b.damper,
                    gauge=gauge_particles(b.points),
                    rigid=b.rigid,
                )
                for b in self.bodies
            ),
        )

    def parameters(self) -> dict[str, float]:
        """Numerical values of every model parameter, by the names the derivation uses."""
        values: dict[str, float] = {}
        offset = link_offset = 0
        for body in self.bodies:
            for i, m in enumerate(body.masses):
                values[f"m{offset + i}"] = float(m)
            for l_ in range(len(body.links)):
                values[f"k{link_offset + l_}"] = float(body.stiffness[l_])
                values[f"c{link_offset + l_}"] = float(body.damping[l_])
                values[f"L{link_offset + l_}"] = float(body.rest_lengths[l_])
            offset += body.n_particles
            link_offset += len(body.links)
        for axis, g in zip("xyz", self.gravity):
            values[f"g_{axis}"] = g
        for j, ground in enumerate(self.grounds):
            for axis, a, b in zip("xyz", ground.point, ground.normal):
                values[f"P{j}_{axis}"] = a
                values[f"n{j}_{axis}"] = b
        return values


# --------------------------------------------------------------------------- loading


def bundled_scenes() -> list[str]:
    """Names of the scenes shipped with flexbody (usable instead of a path)."""
    folder = resources.files("flexbody") / "scenes"
    return sorted(p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml"))


def resolve_scene_path(name_or_path: str | Path) -> Path:
    """Path of a scene file given a path or a bundled scene's name."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    if path.suffix == "" and str(name_or_path) in bundled_scenes():
        return Path(str(resources.files("flexbody") / "scenes" / f"{name_or_path}.toml"))
    raise SceneError(
        str(name_or_path),
        [f"`SCENE` = {str(name_or_path)!r}: is neither a file nor a bundled scene {bundled_scenes()}"],
    )


def _plain(table: Any) -> Any:
    """A scene table built in Python with NumPy values as TOML would give it: arrays as
    lists, NumPy scalars as Python numbers and booleans, tuples as lists (mappings copied)."""
    if isinstance(table, Mapping):
        return {key: _plain(value) for key, value in table.items()}
    if isinstance(table, np.ndarray):
        return table.tolist()
    if isinstance(table, np.generic):
        return table.item()
    if isinstance(table, (list, tuple)):
        return [_plain(value) for value in table]
    return table


def load_scene(source: str | Path | Mapping[str, Any]) -> Scene:
    """Load and validate a scene.

    Parameters
    ----------
    source : path, bundled scene name, or mapping
        A TOML file, the name of a bundled scene (``"thesis_ball"``), or the parsed table
        (NumPy arrays and scalars in it are read as the lists and numbers TOML would give).

    Raises
    ------
    SceneError
        Listing every problem found, each naming the field, its value and the rule.
    """
    if isinstance(source, Mapping):
        try:
            return _build(_plain(source), "<mapping>", default_name="scene")
        except RecursionError:
            raise SceneError("<mapping>", ["nested too deeply (arrays or tables inside each other)"]) from None
    if not isinstance(source, (str, os.PathLike)):
        raise SceneError(repr(source)[:60], [f"`source` = {shown(source)}: must be a scene file's path, a bundled "
                                             "scene's name or a mapping of its tables"])
    path = resolve_scene_path(source)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(str(path), [f"not valid TOML: {exc}"]) from None
    except UnicodeDecodeError as exc:
        raise SceneError(str(path), [f"not UTF-8 text (TOML files must be UTF-8): byte {exc.start} is "
                                     f"{exc.object[exc.start:exc.start + 1]!r}"]) from None
    except RecursionError:
        raise SceneError(str(path), ["nested too deeply (arrays or tables inside each other)"]) from None
    except OSError as exc:
        raise SceneError(str(path), [f"cannot be read: {exc.strerror or exc}"]) from None
    # A file name need not be a valid scene name: its stem is made one.
    stem = re.sub(r"[^A-Za-z0-9_.-]", "_", path.stem)[:64] or "scene"
    return _build(data, str(path), default_name=stem, folder=path.parent)


def _build(data: dict[str, Any], source: str, default_name: str, folder: Path | None = None) -> Scene:
    """Validate a parsed scene; ``folder`` is where relative paths in it (mesh files) start."""
    folder = folder or Path.cwd()
    problems = Problems()
    top = TableReader(data, "", problems, ("name", "gravity", "grounds", "bodies", "contacts", "simulation"))
    name = top.string("name", default_name)
    if name is not None and not NAME_PATTERN.fullmatch(name):
        top.fail("name", name, NAME_RULE)
    gravity, dim = _gravity(top)
    grounds = _grounds(top.raw("grounds", None), dim, gravity, problems)
    raw_bodies = top.raw("bodies", None)
    bodies: list[Body] = []
    if not isinstance(raw_bodies, list) or not raw_bodies:
        top.fail("bodies", raw_bodies, "is required: a non-empty array of [[bodies]] tables")
    else:
        for b, table in enumerate(raw_bodies):
            body = _body(TableReader(table, f"bodies[{b}]", problems, BODY_KEYS), dim, folder)
            if body is not None:
                bodies.append(body)
    _check_unique_names(raw_bodies, problems)
    listed = _listed_contacts(top.raw("contacts", None), raw_bodies, problems, dim)
    simulation = _simulation(TableReader(top.raw("simulation", None), "simulation", problems, SIMULATION_KEYS))
    top.finish()
    total = sum(b.n_particles for b in bodies)
    if total > MAX_PARTICLES:
        top.fail("bodies", f"{total} particles", f"a scene may have at most {MAX_PARTICLES} particles")
    if not problems:
        _check_above_ground(bodies, grounds, problems)
    contacts = _contact_pairs(bodies, listed or [])
    if not problems:
        _check_contact_surfaces(bodies, raw_bodies, contacts, problems)
    if problems or simulation is None:
        raise SceneError(source, problems.items)
    notes = _overdamped_links(bodies)
    for note in notes:
        warnings.warn(note, OverdampedLinkWarning, stacklevel=3)
    return Scene(
        name=name or default_name,
        gravity=tuple(gravity),
        grounds=tuple(grounds),
        bodies=tuple(bodies),
        simulation=simulation,
        source=source,
        warnings=tuple(notes),
        contacts=tuple(contacts),
    )


def _gravity(top: TableReader) -> tuple[tuple[float, ...], int]:
    """Gravity and the scene's dimension, which its length fixes (2: planar, 3: spatial)."""
    raw = top.raw("gravity", None)
    if raw is None:
        return DEFAULT_GRAVITY, 2
    if not (isinstance(raw, (list, tuple)) and len(raw) in (2, 3)):
        top.fail("gravity", raw, "must be a list of 2 (planar) or 3 (spatial) finite numbers: its length fixes "
                 "the dimension")
        return DEFAULT_GRAVITY, 2
    gravity = top.vector("gravity", len(raw))
    return (gravity or (0.0,) * len(raw)), len(raw)


def _grounds(raw: Any, dim: int, gravity: tuple[float, ...], problems: Problems) -> list[Ground]:
    if raw is None:  # through the origin, against gravity (y >= 0 for the default gravity)
        down = _unit(gravity)
        up = tuple(0.0 - g for g in down) if down is not None else (0.0,) * (dim - 1) + (1.0,)
        if down is None and dim == 2:
            up = (0.0, 1.0)
        return [Ground(point=(0.0,) * dim, normal=up)]
    if not isinstance(raw, list):
        problems.add("grounds", raw, "must be an array of [[grounds]] tables")
        return []
    if not raw:  # contacts are the subject of flexbody; for free flight put a ground far below
        problems.add("grounds", raw, "must have at least one ground (for free flight, put one far below)")
        return []
    grounds: list[Ground] = []
    for j, table in enumerate(raw):
        reader = TableReader(table, f"grounds[{j}]", problems, ("point", "normal", "friction", "restitution"))
        point = reader.vector("point", dim)
        normal = reader.vector("normal", dim)
        friction = reader.number("friction", 0.0, check=lambda v: v >= 0.0, rule="must be >= 0 (Coulomb's mu)")
        restitution = reader.number("restitution", 0.0, check=lambda v: 0.0 <= v <= 1.0,
                                    rule="must be in [0, 1] (Newton's e: 0 plastic, 1 elastic)")
        reader.finish()
        if normal is None:
            continue
        unit = _unit(normal)
        if unit is None:
            reader.fail("normal", list(normal), "must be a non-zero vector")
            continue
        if point is None:
            continue
        if friction is None or restitution is None:
            continue
        ground = Ground(point=point, normal=unit, friction=friction, restitution=restitution)
        for i, other in enumerate(grounds):
            clash = _redundant(ground, other, f"grounds[{i}]")
            if clash:
                reader.fail("normal", list(normal), f"{clash}; drop one of them")
                break
        else:
            grounds.append(ground)
    return grounds


def _unit(vector: tuple[float, ...]) -> tuple[float, ...] | None:
    """``vector`` scaled to unit length, or None for the zero vector.

    Scaled by its largest component first, so huge components (1.7e308) do not overflow
    and tiny ones (5e-324) do not underflow to a zero length.
    """
    scale = max(abs(v) for v in vector)
    if scale == 0.0:
        return None
    scaled = [v / scale for v in vector]
    length = math.hypot(*scaled)
    return tuple(v / length for v in scaled)


def _redundant(a: Ground, b: Ground, b_name: str) -> str:
    """Why two grounds cannot both be in a scene ("" if they can).

    Two parallel grounds facing the same way are one ground too many: the lower one is
    never reached, and coincident ones would hold a particle twice with the same
    constraint (a singular contact matrix).  Facing each other on one line they leave
    no room between them.
    """
    na, nb = np.asarray(a.normal), np.asarray(b.normal)
    if float(np.linalg.norm(na - (na @ nb) * nb)) > 1e-9:  # not parallel
        return ""
    offset = float((np.asarray(a.point) - np.asarray(b.point)) @ na)
    coincide = abs(offset) <= 1e-12 * max(1.0, *map(abs, a.point), *map(abs, b.point))
    if float(na @ nb) > 0.0:
        if coincide:
            return f"this ground is the same as {b_name}"
        return f"this ground is parallel to {b_name} and faces the same way, so one of them is never reached"
    return f"this ground faces {b_name} on the same line, leaving no room between them" if coincide else ""


_PARTICLE_LIMIT = " (a scene has at most 1 million particles)"


#: A body's points (n, dim), links, mass shares (None: equal) and surface (m, dim).
Geometry = tuple[np.ndarray, list[tuple[int, int]], "np.ndarray | None", np.ndarray]


def _geometry(r: TableReader, dim: int, folder: Path) -> Geometry | None:
    """A body's points in T (n, dim), links, mass shares (None: equal) and the shape's surface
    (m, dim), from a preset ``shape`` or explicit ``particles`` (no surface).  Planar presets
    lie in T's x-y plane (z = 0 in 3D), where they enclose no volume: no surface."""
    shape = r.string("shape", None, choices=SHAPES)
    if r.has("shape") and shape is None:
        return None
    takes = SHAPE_KEYS[shape]
    for key in GEOMETRY_KEYS:
        if r.has(key) and key not in takes:
            what = f'shape = "{shape}"' if shape else "explicit `particles` and `links` (no `shape`)"
            r.fail(key, r.raw(key), f"is not used with {what}, which takes {', '.join(takes)}: remove it")
    if shape in SPATIAL_SHAPES and dim != 3:
        r.fail("shape", shape, f"is a body in space: it needs a 3D scene (gravity with 3 components); planar shapes "
               f"are {', '.join(x for x in SHAPES if x not in SPATIAL_SHAPES)}")
        return None
    if shape is None:
        points = r.vectors("particles", dim)
        links = r.raw("links")
        if points is not None and len(points) == 0:
            r.fail("particles", points, "a body needs at least one particle")
            return None
        if points is not None and len(points) > MAX_PARTICLES:
            r.fail("particles", points, f"a body may have at most {MAX_PARTICLES} particles")
            return None
        if points is None:
            return None
        if not isinstance(links, list) or not all(
            isinstance(p, list) and len(p) == 2 and all(isinstance(i, int) and not isinstance(i, bool) for i in p)
            for p in links
        ):
            r.fail("links", links, "must be a list of [i, j] particle index pairs (integers)")
            return None
        return np.array(points, dtype=float).reshape(-1, dim), [tuple(p) for p in links], None, empty(dim)
    if shape in SPATIAL_SHAPES:
        return _spatial_geometry(r, shape, folder)
    planar = _planar_geometry(r, shape)
    if planar is None:
        return None
    points, links, outline = planar
    if dim == 3:
        return np.column_stack([points, np.zeros(len(points))]), links, None, empty(3)
    return points, links, None, outline


def _planar_geometry(r: TableReader, shape: str) -> tuple[np.ndarray, list[tuple[int, int]], np.ndarray] | None:
    if shape in ("ring", "ellipse"):
        count = r.integer("count", minimum=2, maximum=MAX_PARTICLES, why=_PARTICLE_LIMIT)
        center = r.boolean("center", False)
        if shape == "ring":
            radius = r.number("radius", check=lambda v: v > 0, rule="must be > 0 (m)")
            radii = None if radius is None else (radius, radius)
        else:
            radii = r.vector("radii", 2)
            if radii is not None and min(radii) <= 0:
                r.fail("radii", list(radii), "both semi-axes must be > 0 (m)")
                radii = None
        if count is None or radii is None or center is None:
            return None
        return (*presets.ellipse(count, radii, center), presets.ellipse_surface(count, center))
    if shape == "polygon":
        vertices = r.vectors("vertices", 2)
        center = r.boolean("center", False)
        if vertices is not None and len(vertices) < 3:
            r.fail("vertices", vertices, "a polygon needs at least 3 vertices")
            return None
        if vertices is None or center is None:
            return None
        return (*presets.polygon(vertices, center), presets.polygon_surface(vertices, center))
    if shape == "disc":
        count = r.integer("count", minimum=1, maximum=MAX_PARTICLES, why=_PARTICLE_LIMIT)
        radius = r.number("radius", check=lambda v: v > 0, rule="must be > 0 (m)")
        if count is None or radius is None:
            return None
        return presets.disc_with_surface(count, radius)
    count = r.integer("count", minimum=1, maximum=MAX_PARTICLES, why=_PARTICLE_LIMIT)
    spacing = r.number("spacing", check=lambda v: v > 0, rule="must be > 0 (m)")
    if count is None or spacing is None:
        return None
    return (*presets.chain(count, spacing), empty(2))  # an open line: no inside


def _spatial_geometry(r: TableReader, shape: str, folder: Path) -> Geometry | None:
    if shape == "sphere":
        count = r.integer("count", minimum=4, maximum=MAX_PARTICLES, why=_PARTICLE_LIMIT)
        radius = r.number("radius", check=lambda v: v > 0, rule="must be > 0 (m)")
        center = r.boolean("center", False)
        if count is None or radius is None or center is None:
            return None
        points, links = presets.sphere(count, radius, center)
        return points, links, None, presets.sphere_surface(points, center)
    if shape == "box":
        raw = r.raw("count", None)
        ok = isinstance(raw, list) and len(raw) == 3 and all(
            isinstance(c, int) and not isinstance(c, bool) and c >= 1 for c in raw)
        if not ok:
            r.fail("count", raw, "must be [nx, ny, nz]: three integers >= 1 (particles along each edge)")
        elif raw[0] * raw[1] * raw[2] > MAX_PARTICLES:
            r.fail("count", raw, f"gives {raw[0] * raw[1] * raw[2]} particles{_PARTICLE_LIMIT}")
            ok = False
        elif raw[0] * raw[1] * raw[2] < 2:
            r.fail("count", raw, "a box needs at least 2 particles")
            ok = False
        size = r.vector("size", 3)
        if size is not None and min(size) <= 0:
            r.fail("size", list(size), "every edge length must be > 0 (m)")
            size = None
        if not ok or size is None:
            return None
        return (*presets.box(tuple(raw), size), None, presets.box_surface(tuple(raw)))
    file = r.string("file", None)
    scale = r.number("scale", 1.0, check=lambda v: v > 0, rule="must be > 0 (a factor on the file's coordinates)")
    center = r.boolean("center", False)
    if file is None:
        if not r.has("file"):
            r.fail("file", None, 'is required with shape = "mesh": a mesh file (OBJ, STL, PLY, Gmsh .msh, VTK), '
                   "relative to the scene file")
        return None
    path = (folder / file) if not Path(file).is_absolute() else Path(file)
    if not path.is_file():
        r.fail("file", file, f"no such file ({path})")
        return None
    if scale is None or center is None:
        return None
    try:
        points, links, shares, outline = presets.mesh(path, center)
    except presets.MeshError as exc:
        r.fail("file", file, str(exc))
        return None
    if len(points) > MAX_PARTICLES:
        r.fail("file", file, f"has {len(points)} vertices{_PARTICLE_LIMIT}")
        return None
    return points * scale, links, shares, outline


def _body(r: TableReader, dim: int, folder: Path) -> Body | None:
    name = r.string("name", _default_body_name(r.path))
    rigid = r.boolean("rigid", False)
    collide = r.boolean("collide", False)
    self_contact = r.boolean("self_contact", False)
    geometry = _geometry(r, dim, folder)
    points = None if geometry is None else geometry[0]
    shares = None if geometry is None else geometry[2]
    links: list[tuple[int, int]] = [] if geometry is None else geometry[1]
    n = None if points is None else len(points)
    nl = None if geometry is None else len(links)
    links_ok = geometry is not None and _check_links(r, points, links)
    if sum(map(r.has, ("mass", "masses", "mass_total"))) != 1:
        r.fail("mass", r.raw("mass", None), "give exactly one of `mass` (each particle), `masses` (a list) or "
               "`mass_total` (the body's, spread by each particle's share)")
        masses = None
    elif r.has("mass"):
        m = r.number("mass", check=lambda v: v > 0, rule="must be > 0 (kg)")
        masses = None if m is None else [m] * (n or 1)
    elif r.has("mass_total"):
        total = r.number("mass_total", check=lambda v: v > 0, rule="must be > 0 (kg)")
        # A mesh's share is its vertex's part of the area (volume); any other body: equal shares.
        share = shares if shares is not None else np.full(n or 1, 1.0 / (n or 1))
        masses = None if total is None else (total * share).tolist()
    else:
        masses = r.scalar_or_list("masses", n, minimum=0.0, strict=True, item="particle")
    if rigid and self_contact:
        r.fail("self_contact", True, "a rigid body cannot touch itself (its shape never changes): remove it, or set "
               "rigid = false")
    if rigid:  # no springs or dampers: their constants would be ignored, so they are a mistake
        for key in ELASTIC_KEYS:
            if r.has(key):
                r.fail(key, r.raw(key), "is not used with rigid = true (a rigid body has no springs or dampers): "
                       "remove it, or set rigid = false")
        stiffness = damping = [0.0] * (nl or 0)
        damper = "relative"
    else:
        stiffness = r.scalar_or_list("stiffness", nl, minimum=0.0, strict=False, item="link")
        damping = r.scalar_or_list("damping", nl, minimum=0.0, strict=False, item="link")
        damper = r.string("damper", "relative", choices=DAMPERS)
    surface = None if geometry is None else geometry[3]
    if r.has("surface"):
        surface = _explicit_surface(r, n, dim)
    rest = None
    if not rigid and r.has("rest_lengths"):
        rest = r.scalar_or_list("rest_lengths", nl, minimum=0.0, strict=True, item="link")
    position = r.vector("position", dim)
    velocity = r.vector("velocity", dim, (0.0,) * dim)
    if dim == 3:  # orientation as a rotation vector, spin as a vector
        if r.has("angle"):
            r.fail("angle", r.raw("angle"), "is planar (a turn about N3): in 3D give `rotation = [rx, ry, rz]`, a "
                   "rotation vector (axis times angle, rad)")
        angle = 0.0
        rotation = r.vector("rotation", 3, (0.0, 0.0, 0.0))
        spin = r.vector("angular_velocity", 3, (0.0, 0.0, 0.0))
    else:
        if r.has("rotation"):
            r.fail("rotation", r.raw("rotation"), "is for 3D scenes: in 2D give `angle` (rad, about N3)")
        angle = r.number("angle", 0.0)
        rotation = (0.0, 0.0, 0.0)
        spin = r.number("angular_velocity", 0.0)
    extra = np.zeros((n or 0, dim))
    if r.has("particle_velocities"):
        given = r.vectors("particle_velocities", dim, count=n)
        if given is not None:
            extra = np.array(given, dtype=float).reshape(-1, dim)
    r.finish()
    if not links_ok or surface is None or None in (masses, stiffness, damping, damper, position, angle, rotation,
                                                   velocity, spin, rigid, collide, self_contact):
        return None
    if rest is None:
        rest = [float(np.linalg.norm(points[i] - points[j])) for i, j in links]
    return Body(
        name=name or "body",
        points=_frozen(points),
        links=tuple((int(i), int(j)) for i, j in links),
        masses=_frozen(masses),
        stiffness=_frozen(stiffness),
        damping=_frozen(damping),
        rest_lengths=_frozen(rest),
        damper=damper,
        position=position,
        angle=angle,
        velocity=velocity,
        angular_velocity=spin,
        particle_velocities=_frozen(extra),
        rotation_vector=rotation,
        surface=_frozen_indices(surface),
        rigid=rigid,
        collide=collide,
        self_contact=self_contact,
    )


def _default_body_name(path: str) -> str:
    """A body without ``name`` is called after its place: ``bodies[2]`` is ``body2``."""
    return path.replace("bodies", "body").replace("[", "").replace("]", "")


def _frozen_indices(array: np.ndarray) -> np.ndarray:
    out = np.array(array, dtype=np.intp)
    out.setflags(write=False)
    return out


def _explicit_surface(r: TableReader, n: int | None, dim: int) -> np.ndarray | None:
    """A given ``surface``: elements of ``dim`` different particles of the body, each once.

    Closedness and orientation are checked later, for the bodies that may touch others."""
    raw = r.raw("surface")
    kind = "[i, j] segments" if dim == 2 else "[i, j, k] triangles"
    if not isinstance(raw, list) or not raw or not all(
        isinstance(e, list) and len(e) == dim and all(isinstance(i, int) and not isinstance(i, bool) for i in e)
        for e in raw
    ):
        r.fail("surface", raw, f"must be a non-empty list of {kind} (particle indices within the body, integers)")
        return None
    if n is None:  # the particles failed: nothing to check the indices against
        return None
    missing = [k for k, e in enumerate(raw) if not all(0 <= i < n for i in e)]
    _report_elements(r, raw, missing, f"refers to a missing particle (the body has particles 0..{n - 1})")
    repeated = [k for k, e in enumerate(raw) if len(set(e)) < dim and 0 <= min(e) and max(e) < n]
    _report_elements(r, raw, repeated, "repeats a particle: a segment needs 2 different particles, a triangle 3")
    first: dict[tuple[int, ...], int] = {}  # each element's particles, in any order, once
    duplicate = []
    for k, e in enumerate(raw):
        key = tuple(sorted(e))
        if len(set(key)) < dim or not (0 <= key[0] and key[-1] < n):
            continue
        if key in first:
            duplicate.append(k)
        else:
            first[key] = k
    if duplicate:
        earlier = first[tuple(sorted(raw[duplicate[0]]))]
        _report_elements(r, raw, duplicate, f"duplicate element: the same particles as surface[{earlier}]")
    if missing or repeated or duplicate:
        return None
    return np.array(raw, dtype=np.intp).reshape(-1, dim)


def _report_elements(r: TableReader, elements: list, indices: list[int], rule: str) -> None:
    """One problem for the first offending surface element, counting the others."""
    if indices:
        more = f" (and {len(indices) - 1} more elements like it)" if len(indices) > 1 else ""
        r.fail(f"surface[{indices[0]}]", elements[indices[0]], rule + more)


def _check_links(r: TableReader, points: np.ndarray, links: list[tuple[int, int]]) -> bool:
    """Links join two different existing particles, once, at a nonzero distance; no two
    particles start at the same point.  O(n log n): a ring of 5000 particles is checked
    in milliseconds (a pairwise test took 90 s)."""
    n = len(points)
    bad_index = [l_ for l_, (i, j) in enumerate(links) if not (0 <= i < n and 0 <= j < n)]
    _report(r, links, bad_index, f"refers to a missing particle (the body has particles 0..{n - 1})")
    bad = set(bad_index)
    self_links = [l_ for l_, (i, j) in enumerate(links) if i == j and l_ not in bad]
    _report(r, links, self_links, "links a particle to itself")
    bad.update(self_links)
    kept = np.array([l_ for l_ in range(len(links)) if l_ not in bad], dtype=np.intp)
    pairs = np.array([links[l_] for l_ in kept], dtype=np.intp).reshape(-1, 2)
    ordered = np.sort(pairs, axis=1)
    _, first = np.unique(ordered, axis=0, return_index=True)
    repeated = np.setdiff1d(np.arange(len(kept)), first)
    _report(r, links, kept[repeated].tolist(), "duplicate link (the same pair appears twice)")
    zero = np.flatnonzero(np.all(points[pairs[:, 0]] == points[pairs[:, 1]], axis=1))
    _report(r, links, kept[zero].tolist(), "zero-length link: the two particles start at the same point")
    # Particles at the same point (exact equality, as the zero-length rule), found by sorting.
    _, group, counts = np.unique(points, axis=0, return_inverse=True, return_counts=True)
    group = group.reshape(-1)
    linked = {(int(i), int(j)) for i, j in ordered[zero]}
    shared = []
    for g in np.flatnonzero(counts > 1):
        members = np.flatnonzero(group == g).tolist()
        if not (len(members) == 2 and tuple(members) in linked):  # already reported as a zero-length link
            shared.append(members)
    if shared:
        more = f" (and {len(shared) - 1} more such groups)" if len(shared) > 1 else ""
        r.fail("particles", shared[0], f"particles of one body start at the same point{more}")
    return not (bad or repeated.size or zero.size or shared)


def _report(r: TableReader, links: list, indices: list[int], rule: str) -> None:
    """One problem for the first offending link, counting the others (not one line each)."""
    if indices:
        more = f" (and {len(indices) - 1} more links like it)" if len(indices) > 1 else ""
        r.fail(f"links[{indices[0]}]", list(links[indices[0]]), rule + more)


def _simulation(r: TableReader) -> SimulationSettings | None:
    t_end = r.number("t_end", check=lambda v: v > 0, rule="must be > 0 (s)")
    output_dt = r.number("output_dt", None, check=lambda v: v > 0, rule="must be > 0 (s)")
    method = r.string("method", None, choices=METHODS)
    rtol = r.number("rtol", 1e-6, check=lambda v: 1e-14 <= v < 1, rule="must be in [1e-14, 1)")
    atol = r.number("atol", 1e-9, check=lambda v: 0 < v < 1, rule="must be in (0, 1)")
    impact = r.string("impact", "instant", choices=IMPACT_MODES)
    impact_dt = r.number("impact_dt", None, check=lambda v: v > 0, rule="must be > 0 (s)")
    if impact == "thesis" and impact_dt is None and not r.has("impact_dt"):
        r.fail("impact_dt", None, 'is required when impact = "thesis" (the time step ΔT of eq. 4.6, s)')
    formulation = r.string("formulation", "particles", choices=FORMULATIONS)
    backend = r.string("backend", "c", choices=BACKENDS)
    chatter_impacts = r.integer("chatter_impacts", CHATTER_IMPACTS, minimum=1)
    r.finish()
    if None in (t_end, rtol, atol, impact, formulation, backend, chatter_impacts) or \
            (r.has("method") and method is None):
        return None
    if (output_dt is None and r.has("output_dt")) or (impact == "thesis" and impact_dt is None):
        return None  # already reported
    output_dt = output_dt if output_dt is not None else t_end / 1000.0
    problems = timing_problems(t_end, output_dt, impact, impact_dt)
    for key, value, rule in problems:
        r.fail(key, value, rule)
    if problems:
        return None
    return SimulationSettings(
        t_end=t_end,
        output_dt=output_dt,
        method=method,
        rtol=rtol,
        atol=atol,
        impact=impact,
        impact_dt=impact_dt,
        formulation=formulation,
        backend=backend,
        chatter_impacts=chatter_impacts,
    )


def timing_problems(
    t_end: float, output_dt: float, impact: str, impact_dt: float | None
) -> list[tuple[str, Any, str]]:
    """The rules that tie ``t_end``, ``output_dt``, ``impact`` and ``impact_dt`` together.

    Shared by the scene file and the overrides of :func:`flexbody.simulate` (and so the
    command line), so both say the same.

    Returns
    -------
    list of (field, value, rule)
        Empty when the settings are consistent.
    """
    out: list[tuple[str, Any, str]] = []
    finite_t_end = _positive(t_end)
    if not finite_t_end:
        out.append(("t_end", t_end, "must be a finite number > 0 (s)"))
    if not _positive(output_dt):
        out.append(("output_dt", output_dt, "must be a finite number > 0 (s)"))
    elif finite_t_end and output_dt > t_end:
        out.append(("output_dt", output_dt, f"must be <= t_end = {t_end:g} s (one output sample at least)"))
    elif finite_t_end and not t_end / output_dt < MAX_SAMPLES:  # also catches t_end / output_dt = inf
        out.append(("output_dt", output_dt, f"gives {t_end / output_dt:.3g} output samples over t_end = "
                    f"{t_end:g} s; at most {MAX_SAMPLES:.0e} are allowed: raise output_dt or lower t_end"))
    if impact == "thesis" and not _positive(impact_dt):
        out.append(("impact_dt", impact_dt, 'must be a finite number > 0 (s) with impact = "thesis" '
                    "(the ΔT of thesis eq. 4.6)"))
    if impact == "instant" and impact_dt is not None:
        out.append(("impact_dt", impact_dt, 'is only used with impact = "thesis"; choose that mode or drop it'))
    return out


def _positive(value: Any) -> bool:
    """A finite float > 0 (False for None, nan, inf)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0


def _check_above_ground(bodies: list[Body], grounds: list[Ground], problems: Problems) -> None:
    for b, body in enumerate(bodies):
        x = body.initial_positions()
        for j, ground in enumerate(grounds):
            gaps = (x - np.asarray(ground.point)) @ np.asarray(ground.normal)
            below = np.flatnonzero(gaps < 0.0)
            if below.size:
                problems.add(
                    f"bodies[{b}].position",
                    list(body.position),
                    f"particles {below.tolist()} start below grounds[{j}] (gap {gaps[below].min():.3g} m < 0)",
                )


def _overdamped_links(bodies: list[Body]) -> list[str]:
    notes = []
    for b, body in enumerate(bodies):
        if body.rigid:  # no springs, no dampers
            continue
        bad = []
        for l_, (i, j) in enumerate(body.links):
            mu = body.masses[i] * body.masses[j] / (body.masses[i] + body.masses[j])
            if 4.0 * body.stiffness[l_] * mu - body.damping[l_] ** 2 <= 0.0:
                bad.append(l_)
        if bad:
            notes.append(
                f"bodies[{b}]: links {bad} are not underdamped (4 k mu - c^2 <= 0 with the reduced mass mu, "
                "thesis eq. 3.12): the body will not vibrate but creep; lower `damping` or raise `stiffness`"
            )
    return notes


# --------------------------------------------------------------------------- bodies touching


def _listed_contacts(raw: Any, raw_bodies: Any, problems: Problems, dim: int) -> list[BodyContact] | None:
    """The ``[[contacts]]`` tables, checked against the body names (read from the raw tables,
    so a mistake in a body does not hide one here); None when any is wrong."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        problems.add("contacts", raw, "must be an array of [[contacts]] tables")
        return None
    tables = raw_bodies if isinstance(raw_bodies, list) else []
    names = [t.get("name", _default_body_name(f"bodies[{b}]")) if isinstance(t, Mapping) else None
             for b, t in enumerate(tables)]
    self_contact = [isinstance(t, Mapping) and t.get("self_contact") is True for t in tables]
    out: list[BodyContact] = []
    where: dict[tuple[int, int], int] = {}
    ok = True
    for k, table in enumerate(raw):
        r = TableReader(table, f"contacts[{k}]", problems, CONTACT_KEYS)
        pair = r.raw("bodies")
        friction = r.number("friction", 0.0, check=lambda v: v >= 0.0, rule="must be >= 0 (Coulomb's mu)")
        restitution = r.number("restitution", 0.0, check=lambda v: 0.0 <= v <= 1.0,
                               rule="must be in [0, 1] (Newton's e: 0 plastic, 1 elastic)")
        edges = r.boolean("edges", False)
        if edges and dim != 3:
            r.fail("edges", edges, "applies to 3D bodies only (edges of triangle surfaces; a 2D boundary's "
                   "segments meet at particles)")
            edges = None
        r.finish()
        indices = _contact_bodies(r, pair, names, self_contact)
        if indices is not None and indices in where:
            r.fail("bodies", pair, f"this pair is already listed in contacts[{where[indices]}] (list each pair once)")
            indices = None
        if indices is None or friction is None or restitution is None or edges is None:
            ok = False
            continue
        if edges and indices[0] == indices[1]:
            r.fail("edges", edges, "applies between two bodies, not to a body's self-contact")
            ok = False
            continue
        where[indices] = k
        out.append(BodyContact(bodies=indices, friction=friction, restitution=restitution, edges=edges))
    return out if ok else None


def _contact_bodies(r: TableReader, pair: Any, names: list, self_contact: list[bool]) -> tuple[int, int] | None:
    """The body indices of a ``[[contacts]]`` entry's ``bodies``, sorted, or None (reported)."""
    if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(p, str) for p in pair)):
        r.fail("bodies", pair, 'is required: a list of two body names, e.g. ["ball", "floor"]')
        return None
    unknown = [p for p in pair if p not in names]
    if unknown:
        known = [n for n in names if isinstance(n, str)]
        r.fail("bodies", pair, f"names no body of the scene: {sorted(set(unknown))}; the bodies are {known}")
        return None
    first, second = sorted(names.index(p) for p in pair)
    if first == second and not self_contact[first]:
        r.fail("bodies", pair, f"lists body {pair[0]!r} twice: a body touches itself only with "
               f"`self_contact = true` on it")
        return None
    return first, second


def _contact_pairs(bodies: list[Body], listed: list[BodyContact]) -> list[BodyContact]:
    """The listed pairs, then every pair of ``collide = true`` bodies and every
    ``self_contact = true`` body not listed, with friction 0 and restitution 0."""
    pairs = list(listed)
    seen = {c.bodies for c in listed}
    colliding = [b for b, body in enumerate(bodies) if body.collide]
    implied = [(a, b) for i, a in enumerate(colliding) for b in colliding[i + 1:]]
    implied += [(b, b) for b, body in enumerate(bodies) if body.self_contact]
    for key in sorted(implied):
        if key not in seen:
            pairs.append(BodyContact(bodies=key))
    return pairs


def _check_unique_names(raw_bodies: Any, problems: Problems) -> None:
    """No two bodies share a name (contacts, results and figures name them), each repeat
    reported at its own index, whatever else is wrong."""
    first: dict[str, int] = {}
    for b, table in enumerate(raw_bodies if isinstance(raw_bodies, list) else []):
        name = table.get("name") if isinstance(table, dict) else None
        if not isinstance(name, str):
            continue
        if name in first:
            problems.add(f"bodies[{b}].name", name, f"body names must be unique (bodies[{first[name]}] has it too)")
        first.setdefault(name, b)


def _check_contact_surfaces(bodies: list[Body], raw_bodies: list, contacts: list[BodyContact],
                            problems: Problems) -> None:
    """Every body that may touch one has a closed, outward surface (a gap's sign needs an
    inside), and so has every surface given explicitly, whether or not its body may touch."""
    partners: dict[int, list[str]] = {}
    for c in contacts:
        a, b = c.bodies
        partners.setdefault(a, []).append(repr(bodies[b].name) if a != b else "itself")
        if a != b:
            partners.setdefault(b, []).append(repr(bodies[a].name))
    for b in sorted(set(partners) | {b for b, table in enumerate(raw_bodies) if "surface" in table}):
        body = bodies[b]
        given = "surface" in raw_bodies[b]
        shape = raw_bodies[b].get("shape")
        value: Any = body.surface.tolist() if given else Words(
            f"(from shape = {shape!r})" if shape else "(none: explicit particles)")
        touches = (f"body {body.name!r} may touch {', '.join(partners[b])}, which needs a closed surface" if b in partners
                   else f"body {body.name!r} gives a surface, which must be closed (its contacts with other bodies use it)")
        fix = "" if given else f"; give `surface = {_SURFACE_EXAMPLE[body.dim]}` (outward)"
        if len(body.surface) == 0:
            if shape in SPATIAL_SHAPES or (shape and body.dim == 2):
                what = f'shape = "{shape}" has none'
            elif shape:
                what = f'shape = "{shape}" is flat in 3D (it encloses no volume)'
            else:
                what = "explicit particles have none unless given"
            problems.add(f"bodies[{b}].surface", value, f"{touches} (a gap's sign needs an inside); {what}{fix}")
            continue
        why = closure_problem(body.surface)
        if why:
            problems.add(f"bodies[{b}].surface", value, f"is not closed: {why}; {touches}{fix}")
            continue
        flat = degenerate(body.points, body.surface)
        if flat.size:
            k, what = int(flat[0]), "zero length" if body.dim == 2 else "zero area (collinear corners)"
            more = f" (and {flat.size - 1} more like it)" if flat.size > 1 else ""
            problems.add(f"bodies[{b}].surface", value,
                         f"element {k}, {body.surface[k].tolist()}, has {what}{more}: an element needs a normal; "
                         f"{touches}")
            continue
        measure = signed_measure(body.points, body.surface)
        if measure <= 0.0:
            unit, noun = ("m^2", "area") if body.dim == 2 else ("m^3", "volume")
            way = "counter-clockwise" if body.dim == 2 else "counter-clockwise seen from outside"
            problems.add(f"bodies[{b}].surface", value,
                         f"encloses a signed {noun} of {measure:.3g} {unit} <= 0: it faces inward (or is flat); "
                         f"reverse the order of every element (outward normals: {way})")


_SURFACE_EXAMPLE = {2: "[[i, j], ...]", 3: "[[i, j, k], ...]"}
