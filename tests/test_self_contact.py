"""Self-contact (flexbody.own_surface): a flexible body's outer surface touching itself.

References: the same collision run as two bodies (the parts of one body that no links join
touch exactly as two bodies do: the same events and trajectories); conservation of linear
and angular momentum in free space; the energy ledger; Newton's e = 1 losing nothing; and
the run without self-contact, whose surface passes through itself (so each check can fail).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import flexbody
from flexbody.model import load_model
from flexbody.surface import boundary, crossings
from flexbody.surface_contact import closest_features

from .conftest import needs_cc

pytestmark = needs_cc

ICOSAHEDRON = {"shape": "mesh", "file": str(Path(flexbody.__file__).parent / "scenes" / "icosahedron.obj"),
               "scale": 0.1, "center": True, "mass_total": 0.65, "stiffness": 2000.0, "damping": 0.2,
               "damper": "axial", "collide": True}
ICOSAHEDRA = {"name": "icosahedra", "gravity": [0.0, 0.0, 0.0],
              "bodies": [{**ICOSAHEDRON, "name": "a", "position": [-0.15, 0.01, 1.0], "rotation": [0.3, 0.2, 0.0],
                          "velocity": [1.0, 0.0, 0.0]},
                         {**ICOSAHEDRON, "name": "b", "position": [0.15, -0.01, 1.02], "rotation": [0.0, -0.4, 0.1],
                          "velocity": [-1.0, 0.0, 0.0], "angular_velocity": [0.0, 0.0, 3.0]}],
              "contacts": [{"bodies": ["a", "b"], "friction": 0.3, "restitution": 0.5}],
              "simulation": {"t_end": 0.15, "output_dt": 0.005}}


def _as_one_body(table: dict) -> dict:
    """The scene's two bodies as one body of two parts that no links join, touching itself
    with the pair's laws: the same particles, links, surfaces and initial motion."""
    scene = flexbody.load_scene(table)
    parts = scene.bodies
    first = np.r_[0, np.cumsum([b.n_particles for b in parts])]
    one = {"name": "both", "position": [0.0] * scene.dim, "self_contact": True, "damper": parts[0].damper,
           "particles": np.vstack([b.initial_positions() for b in parts]).tolist(),
           "particle_velocities": np.vstack([b.initial_velocities() for b in parts]).tolist(),
           "links": [[int(i + k), int(j + k)] for b, k in zip(parts, first) for i, j in b.links],
           "surface": np.vstack([b.surface + k for b, k in zip(parts, first)]).tolist(),
           "masses": np.concatenate([b.masses for b in parts]).tolist(),
           "stiffness": np.concatenate([b.stiffness for b in parts]).tolist(),
           "damping": np.concatenate([b.damping for b in parts]).tolist()}
    laws = {k: v for k, v in (table.get("contacts") or [{}])[0].items() if k != "bodies"}
    out = {k: v for k, v in table.items() if k not in ("bodies", "contacts")}
    return {**out, "name": table["name"] + "_one", "bodies": [one], "contacts": [{"bodies": ["both", "both"], **laws}]}


def _colliding_rings() -> dict:
    import tomllib

    return tomllib.loads((Path(flexbody.__file__).parent / "scenes" / "colliding_rings.toml").read_text())


@pytest.mark.parametrize("table", [_colliding_rings(), ICOSAHEDRA], ids=["2D rings", "3D icosahedra"])
def test_two_parts_of_one_body_touch_each_other_as_two_bodies_do(table):
    """No link joins the two parts, so neither is in the other's neighbourhood: every
    particle watches the other part's whole surface, and the run equals the two-body run
    (the same events, at the same times, and the same motion; measured 2e-13 m in 2D,
    1.6e-14 m in 3D).  The surfaces really touch: there are impacts."""
    apart, one = (flexbody.simulate(flexbody.load_scene(t)) for t in (table, _as_one_body(table)))
    assert apart.status == one.status == "success", (apart.message, one.message)
    assert (apart.events_kind == "impact").sum() >= 5
    np.testing.assert_array_equal(one.events_particle, apart.events_particle)
    np.testing.assert_array_equal(one.events_kind, apart.events_kind)
    np.testing.assert_allclose(one.events_time, apart.events_time, rtol=0, atol=1e-10)
    np.testing.assert_allclose(one.positions, apart.positions, rtol=0, atol=1e-9)


def _u_lattice(layers: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A U of 1 cm cells: arms 3 cells thick and 10 tall, 8 cells apart, on a 3-cell base,
    triangulated mirror-symmetrically; with ``layers`` > 1, extruded in z into that many
    layers of particles 1 cm apart, each prism split into 3 tetrahedra.  The particles
    (n, 2 or 3) and the cells (triangles or tetrahedra)."""
    cells = [(i, j) for i in range(14) for j in range(10) if i < 3 or i >= 11 or j < 3]
    nodes = sorted({(i + a, j + b) for i, j in cells for a in (0, 1) for b in (0, 1)})
    index = {n: k for k, n in enumerate(nodes)}
    triangles = []
    for i, j in cells:
        a, b, c, d = index[(i, j)], index[(i + 1, j)], index[(i + 1, j + 1)], index[(i, j + 1)]
        rising = ((min(i, 13 - i) + j) % 2 == 0) == (i < 7)  # the right half mirrors the left's diagonals
        triangles += [(a, b, c), (a, c, d)] if rising else [(a, b, d), (b, c, d)]
    x = (np.array(nodes, float) - [7.0, 0.0]) * H
    if layers < 2:
        return x, np.array(triangles)
    n = len(x)
    tetrahedra = []
    for k in range(layers - 1):
        for a, b, c in (sorted(t) for t in triangles):  # sorted corners: shared faces split alike
            lo, hi = np.array([a, b, c]) + k * n, np.array([a, b, c]) + (k + 1) * n
            tetrahedra += [(lo[0], lo[1], lo[2], hi[2]), (lo[0], lo[1], hi[1], hi[2]), (lo[0], hi[0], hi[1], hi[2])]
    return np.vstack([np.column_stack([x, np.full(n, k * H)]) for k in range(layers)]), np.array(tetrahedra)


H = 0.01  # the U's cell size (m)


def _u_body(self_contact: bool, restitution: float = 0.0, friction: float = 0.0, layers: int = 0) -> dict:
    """The U (:func:`_u_lattice`; 0.005 kg particles, k = 2 000 N/m, axial dampers) in free
    space, its arms swinging together, 2 m/s at their tips in 2D and 1 m/s in 3D (zero
    momentum and angular momentum): their tips' inner faces meet."""
    x, cells = _u_lattice(layers)
    dim = x.shape[1]
    links = sorted({tuple(sorted((int(t[p]), int(t[q])))) for t in cells for p in range(dim + 1) for q in range(p)})
    v = np.zeros_like(x)
    arms = np.abs(x[:, 0]) > 3.5 * H
    v[arms, 0] = -np.sign(x[arms, 0]) * (2.0 if dim == 2 else 1.0) * x[arms, 1] / (10 * H)
    body = {"name": "u", "particles": x.tolist(), "links": [list(k) for k in links],
            "surface": boundary(x, cells).tolist(), "mass": 0.005, "stiffness": 2000.0, "damping": 0.05,
            "damper": "axial", "position": [0.0] * dim, "particle_velocities": v.tolist(), "self_contact": self_contact}
    down = [0.0, -10.0, 0.0][:dim]
    table = {"name": "u", "gravity": [0.0] * dim, "grounds": [{"point": down, "normal": [0.0, 1.0, 0.0][:dim]}],
             "bodies": [body], "simulation": {"t_end": 0.3 if dim == 2 else 0.1, "output_dt": 0.002, "rtol": 1e-9,
                                             "atol": 1e-12}}
    if self_contact:
        table["contacts"] = [{"bodies": ["u", "u"], "restitution": restitution, "friction": friction}]
    return table


def _momenta(result) -> tuple[np.ndarray, np.ndarray]:
    m, x, v = result.masses, result.positions, result.velocities
    spin = np.cross(x, v) if x.shape[-1] == 3 else x[..., 0] * v[..., 1] - x[..., 1] * v[..., 0]
    return np.einsum("i,tid->td", m, v), np.einsum("i,ti...->t...", m, spin)


def _crossed_samples(result, surface) -> int:
    return sum(len(crossings(x, surface)) > 0 for x in result.positions)


@pytest.mark.parametrize("restitution, friction", [(0.0, 0.0), (1.0, 0.0),
                                                    pytest.param(0.0, 0.5, marks=pytest.mark.slow)])
def test_a_bent_body_closing_on_itself_stops_at_its_own_surface(restitution, friction):
    """The U's arms meet: with self-contact the surface never crosses itself, nothing is
    inside by more than 1e-9 m, momentum and angular momentum stay 0 (free space, axial
    dampers), and the ledger closes; e = 1 loses no energy in the impacts, e = 0 does, and
    friction does work.  Without self-contact the arms pass through each other."""
    table = _u_body(True, restitution, friction)
    result = flexbody.simulate(flexbody.load_scene(table))
    surface = np.array(table["bodies"][0]["surface"])
    assert result.status == "success", result.message
    assert result.stats["impacts"] >= 10
    assert _crossed_samples(result, surface) == 0
    assert result.stats["max_penetration_m"] <= 1e-9
    p, L = _momenta(result)
    assert np.abs(p).max() < 1e-12 and np.abs(L).max() < 1e-12
    assert result.stats["energy_drift_relative"] < 1e-6
    loss = result.impact_loss[-1] / result.stats["energy_initial_J"]
    assert (abs(loss) < 1e-9) if restitution == 1.0 else (loss > 1e-3)
    if friction:
        assert result.stats["slips"] + result.stats["sticks"] > 0 and result.stats["friction_work_J"] > 0.0

    through = flexbody.simulate(flexbody.load_scene(_u_body(False)))
    assert through.stats["events"] == 0 and _crossed_samples(through, surface) > 10


def test_a_particles_neighbourhood_is_what_its_links_reach_and_never_another_part():
    """Each surface particle leaves out its own elements and those with a vertex within
    reach through the links (2 margins here), and nothing of a part no link joins it to."""
    model = load_model(flexbody.load_scene(_as_one_body(_colliding_rings())))
    own = model.own
    rings = model.particle_body  # one body; its two rings are particles 0-11 and 12-23
    part = (np.arange(len(rings)) >= 12).astype(int)
    pairs = np.divmod(own.excluded, len(model.elements))
    assert (part[pairs[0]] == part[model.elements[pairs[1], 0]]).all()
    for p in np.unique(model.elements):
        mine = np.flatnonzero((model.elements == p).any(axis=1))
        assert own.left_out(np.full(len(mine), p), mine).all()
    # an 11-gon of radius 0.1 m: sides 0.0563 m, the margin; reach 2 sides (spokes: 0.1 m):
    # the particles 2 sides away each way, so the 6 sides that have one of those 5 for a vertex
    counts = np.bincount(pairs[0], minlength=len(rings))[np.unique(model.elements)]
    assert counts.tolist() == [6] * 22


def test_a_particle_coming_at_its_own_surface_from_inside_stops_the_run_naming_it():
    """A hollow ring (16 particles on a circle, perimeter links only) whose top particle is
    thrown down across its inside: the surface's inside is taken for material, so its gap
    to the far side jumps from "far" to half a margin deep where it comes within reach.
    That is no contact: the run stops there with ``unsupported``, naming the particle,
    instead of resolving one."""
    n = 16
    angle = 2 * np.pi * np.arange(n) / n
    x = 0.1 * np.column_stack([np.cos(angle), np.sin(angle)])
    v = np.zeros_like(x)
    v[4] = [0.0, -3.0]  # the top particle
    ring = [[i, (i + 1) % n] for i in range(n)]
    table = {"name": "poke", "gravity": [0.0, 0.0], "grounds": [{"point": [0.0, -10.0], "normal": [0.0, 1.0]}],
             "bodies": [{"name": "ring", "particles": x.tolist(), "links": ring, "surface": ring, "mass": 0.02,
                         "stiffness": 50.0, "damping": 0.0, "position": [0.0, 0.0], "particle_velocities": v.tolist(),
                         "self_contact": True}],
             "simulation": {"t_end": 0.2, "output_dt": 0.002}}
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "unsupported" and result.t[-1] < 0.2
    assert re.search(r"particle \d+ came at its own surface from inside, 0\.0\d+ m deep", result.message), result.message


@pytest.mark.slow
def test_a_3d_body_closing_on_itself_keeps_its_arms_out_of_each_other():
    """The U extruded to 3 layers (348 particles, tetrahedra): its arms' tips meet face to
    face at 1 m/s.  No surface particle of the left arm gets inside the right arm (the
    NumPy narrow phase over the right arm's faces at every sample: -2.6e-15 m at worst;
    without self-contact 8.9 mm), momenta stay 0, the ledger closes.  (Edges of the tips
    still pass through each other, 2 mm, as two bodies' do without ``edges = true``.)"""
    deepest = {}
    for self_contact in (True, False):
        table = _u_body(self_contact, layers=3)
        result = flexbody.simulate(flexbody.load_scene(table))
        assert result.status == "success", result.message
        x0 = np.array(table["bodies"][0]["particles"])
        surface = np.array(table["bodies"][0]["surface"])
        arm = lambda side: (side * x0[surface][:, :, 0] > 3.5 * H).all(axis=1) & (x0[surface][:, :, 1] > 2.5 * H).all(axis=1)
        left, right = np.unique(surface[arm(-1)]), surface[arm(1)]
        pairs = np.array([(p, e) for p in left for e in range(len(right))])
        deepest[self_contact] = min(closest_features(x, x, right, pairs).gap.min() for x in result.positions)
        if self_contact:
            assert result.stats["impacts"] >= 10 and result.stats["max_penetration_m"] <= 1e-9
            p, L = _momenta(result)
            assert np.abs(p).max() < 1e-12 and np.abs(L).max() < 1e-12
            assert result.stats["energy_drift_relative"] < 1e-6
    assert deepest[True] > -1e-9 and deepest[False] < -1e-3


def test_the_bundled_u_closing_is_the_tested_u():
    """``flexbody run u_closing`` runs the U of :func:`_u_body` (e = 0, frictionless)."""
    bundled, tested = flexbody.load_scene("u_closing"), flexbody.load_scene(_u_body(True))
    a, b = bundled.bodies[0], tested.bodies[0]
    np.testing.assert_allclose(a.initial_positions(), b.initial_positions(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(a.initial_velocities(), b.initial_velocities(), rtol=0, atol=1e-15)
    assert a.links == b.links and np.array_equal(a.surface, b.surface) and a.self_contact
    np.testing.assert_array_equal(a.masses, b.masses)
    np.testing.assert_array_equal(a.stiffness, b.stiffness)
    np.testing.assert_array_equal(a.damping, b.damping)
    assert bundled.contacts == tested.contacts and bundled.simulation == tested.simulation
