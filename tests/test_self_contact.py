"""Self-contact (flexbody.own_surface): a flexible body's outer surface touching itself.

References: the same collision run as two bodies (the parts of one body that no links join
touch exactly as two bodies do: the same events and trajectories); conservation of linear
and angular momentum in free space; the energy ledger; Newton's e = 1 losing nothing; and
the run without self-contact, whose surface passes through itself (so each check can fail).
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

import flexbody
from flexbody.model import load_model
from flexbody.surface import boundary, crossings
from flexbody.surface_contact import closest_features

from .conftest import needs_cc, reference_table

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


def _u_lattice(layers: int = 0, gap: int = 8, height: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """A U of 1 cm cells: arms 3 cells thick and ``height`` tall, ``gap`` cells apart, on a
    3-cell base, triangulated mirror-symmetrically; with ``layers`` > 1, extruded in z into
    that many layers of particles 1 cm apart, each prism split into 3 tetrahedra.  The
    particles (n, 2 or 3) and the cells (triangles or tetrahedra)."""
    width = 6 + gap
    cells = [(i, j) for i in range(width) for j in range(height) if i < 3 or i >= 3 + gap or j < 3]
    nodes = sorted({(i + a, j + b) for i, j in cells for a in (0, 1) for b in (0, 1)})
    index = {n: k for k, n in enumerate(nodes)}
    triangles = []
    for i, j in cells:
        a, b, c, d = index[(i, j)], index[(i + 1, j)], index[(i + 1, j + 1)], index[(i, j + 1)]
        # the right half mirrors the left's diagonals
        rising = ((min(i, width - 1 - i) + j) % 2 == 0) == (i < width / 2)
        triangles += [(a, b, c), (a, c, d)] if rising else [(a, b, d), (b, c, d)]
    x = (np.array(nodes, float) - [width / 2, 0.0]) * H
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
    assert re.search(r"particle \d+ of body .ring. came at its own surface from inside, 0\.0\d+ m behind it", result.message), result.message


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


def _u_model(layers: int = 0):
    scene = flexbody.load_scene(_u_body(True, layers=layers))
    return scene, load_model(scene)


def test_a_slot_handed_onto_its_own_neighbourhood_is_set_free():
    """A particle held on an element of its own surface slides past the element's end onto
    a neighbour in its own neighbourhood (which it does not watch): its slot leaves (set
    free, no element), and its gap reads ``margin`` there (the rim)."""
    scene, model = _u_model()
    own, E, ng = model.own, model.elements, model.n_ground_contacts
    found = next((slot, e, corner) for slot in range(model.n_primary) for e in range(len(E))
                 for corner in range(2)
                 if model.slot_particle[slot] not in E[e] and not own.left_out([model.slot_particle[slot]], [e])[0]
                 and own.left_out([model.slot_particle[slot]], [model._neighbour[e, corner]])[0])
    slot, e, corner = found
    particle, after = model.slot_particle[slot], model._neighbour[e, corner]
    x = scene.initial_positions().copy()
    shared = np.intersect1d(E[e], E[after])[0]
    other = E[e][E[e] != shared][0]
    along = (x[shared] - x[other]) / np.linalg.norm(x[shared] - x[other])
    x[particle] = x[shared] + 1e-4 * along  # just past the element's end, on its line
    y = np.concatenate([x.ravel(), np.zeros(x.size), np.zeros(model.ny - 2 * x.size)])
    held = np.zeros(model.n_contacts, np.intc)
    held[ng + slot] = 1
    model.element_of[slot] = e
    moved = model.switch_elements(y, model.parameters(scene), held, 1e-12, 1e-9)
    assert moved.leave.tolist() == [ng + slot] and not len(moved.stay) and not len(moved.approach)
    assert model.element_of[slot] == -1
    assert model._surface_gaps(x, np.array([slot]))[0][slot] == model.margin


def test_a_feature_on_the_rim_of_the_neighbourhood_reads_no_gap():
    """A vertex one of whose elements is in the particle's neighbourhood gives no gap; a
    vertex of the rest does.  In 3D an edge counts as rim only through its own two
    triangles (an edge near the neighbourhood whose triangles are both outside it reads)."""
    from flexbody.constants import EDGE, FACE, VERTEX
    from flexbody.surface_contact import SurfaceContact

    for layers in (0, 3):
        scene, model = _u_model(layers)
        own, E = model.own, model.elements
        dim = E.shape[1]
        rows = []  # (particle, element, feature, kind, rim?)
        for particle in np.unique(E)[:40]:
            mine = own.left_out(np.full(len(E), particle), np.arange(len(E)))
            for vertex in np.unique(E[~mine])[:30]:
                around = np.flatnonzero((E == vertex).any(axis=1))
                if particle in E[around]:
                    continue
                rows.append((particle, around[0], [vertex] + [-1] * (dim - 1), VERTEX, bool(mine[around].any())))
            if dim == 3:
                for a, b in {tuple(sorted(t)) for t in E[~mine][:, :2]}:
                    two = np.flatnonzero((E == a).any(axis=1) & (E == b).any(axis=1))
                    if particle in (a, b) or len(two) != 2:
                        continue
                    rows.append((particle, two[0], [a, b, -1], EDGE, bool(mine[two].any())))
        k = len(rows)
        contact = SurfaceContact(particle=np.array([r[0] for r in rows]), kind=np.array([r[3] for r in rows]),
                                 element=np.array([r[1] for r in rows]), feature=np.array([r[2] for r in rows]),
                                 weights=np.zeros((k, dim)), gap=np.full(k, 1e-3), normal=np.zeros((k, dim)))
        keep, gap = own.read(contact)
        rim = np.array([r[4] for r in rows])
        assert rim.any() and (~rim).any()
        np.testing.assert_array_equal(keep, ~rim)
        if dim == 3:
            edge = contact.kind == EDGE
            near_rim = edge & ~rim & np.array([own.left_out(np.full(len(np.flatnonzero((E == r[2][0]).any(axis=1))), r[0]),
                                                            np.flatnonzero((E == r[2][0]).any(axis=1))).any()
                                               for r in rows])
            assert near_rim.any() and keep[near_rim].all()  # read, though a triangle at an end is left out
        face = dataclasses.replace(contact, kind=np.full(k, FACE))
        assert own.read(face)[0].all()  # a face of the rest always reads


def test_a_particle_deep_inside_its_own_body_reads_a_reflected_gap():
    """Behind its own surface by more than INSIDE margins, a particle's gap is reflected,
    continuous at that depth and 0 at twice it; its gaps as measured say it is inside."""
    from flexbody.own_surface import INSIDE
    from flexbody.surface_contact import SurfaceContact

    scene, model = _u_model()
    own, m = model.own, model.margin
    depth = np.array([0.0, 0.5, 0.99, 1.0, 1.01, 1.5, 2.0, 3.0, 4.0]) * INSIDE * m
    k = len(depth)
    particle = np.unique(model.elements)[0]
    element = np.flatnonzero(~own.left_out(np.full(len(model.elements), particle), np.arange(len(model.elements))))[0]
    contact = SurfaceContact(particle=np.full(k, particle), kind=np.zeros(k, int), element=np.full(k, element),
                             feature=np.tile(model.elements[element], (k, 1)), weights=np.full((k, 2), 0.5),
                             gap=-depth, normal=np.zeros((k, 2)))
    keep, gap = own.read(contact)
    assert keep.all()
    np.testing.assert_allclose(gap, np.where(depth <= INSIDE * m, -depth, -2 * INSIDE * m + depth), atol=1e-15)
    np.testing.assert_array_equal(own.inside(contact), depth > INSIDE * m)


def test_one_self_contact_slots_gap_equals_its_entry_of_all_gaps():
    """The U bent (its arms' tips 2 mm apart, seen from every particle): each self slot's
    gap alone (event location's) equals its entry of the whole sweep, and none reads its
    own elements (a gap of 0 at the particle)."""
    scene, model = _u_model()
    x = scene.initial_positions().copy()
    arms = np.abs(x[:, 0]) > 3.5 * H
    x[arms, 0] -= np.sign(x[arms, 0]) * (3.9 * H) * x[arms, 1] / (10 * H)  # tips 8 cells apart close to 0.2 cells
    q = x.ravel()
    p = model.parameters(scene)
    every = model.gaps(q, p)
    ng = model.n_ground_contacts
    alone = np.array([model.gap(q, p, ng + s) for s in range(model.n_primary)])
    np.testing.assert_allclose(alone, every[ng : ng + model.n_primary], rtol=0, atol=1e-15)
    assert (alone > 0).all() and (alone < model.margin).sum() >= 4  # the tips see each other


@pytest.mark.parametrize("ground, stiffness", [(-0.2, 50.0), (-0.1, 200.0)])
def test_a_hollow_ring_crushed_flat_stops_where_its_top_reaches_its_bottom_from_inside(ground, stiffness):
    """A hollow ring (perimeter links only, no bending stiffness) dropped at 3 m/s folds flat
    on the ground; its top comes at its bottom from inside, which self-contact does not
    take for a contact: the run stops there, cleanly, naming the particle; no particle
    read as inside anything.  (Its gap used to jump where it came within reach, and the
    instant located on that jump raised a KeyError in one of these two.)"""
    n = 16
    angle = 2 * np.pi * np.arange(n) / n
    ring = [[i, (i + 1) % n] for i in range(n)]
    table = {"name": "drop", "gravity": [0.0, -9.81], "grounds": [{"point": [0.0, ground], "normal": [0.0, 1.0]}],
             "bodies": [{"name": "ring", "particles": (0.1 * np.column_stack([np.cos(angle), np.sin(angle)])).tolist(),
                         "links": ring, "surface": ring, "mass": 0.02, "stiffness": stiffness, "damping": 0.0,
                         "position": [0.0, 0.0], "velocity": [0.0, -3.0], "self_contact": True}],
             "simulation": {"t_end": 0.3, "output_dt": 0.002}}
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "unsupported" and "came at its own surface from inside" in result.message, result.message
    assert result.stats["max_penetration_m"] < 1e-9


def test_two_far_parts_held_vertex_on_vertex_are_no_fold_at_rounding_depth():
    """A fuzzed U (arms 6 cells apart, 10 tall) whose arms' tips meet and are held vertex
    on vertex (tests/reference/u_apex_crossing.npz: the positions at that moment): the two
    inner faces, hinged at the held point, cross there by 1.8e-11 m of rounding.  Two bodies'
    faces are never tested so; one body's are: within a neighbourhood any crossing is a fold,
    beyond them only one deeper than ``depth`` (the driver's 1e3 gap tolerances)."""
    x0, cells = _u_lattice(gap=6, height=13)
    links = sorted({tuple(sorted((int(t[p]), int(t[q])))) for t in cells for p in range(3) for q in range(p)})
    table = {"name": "u", "gravity": [0.0, 0.0], "grounds": [{"point": [0.0, -10.0], "normal": [0.0, 1.0]}],
             "bodies": [{"name": "u", "particles": x0.tolist(), "links": [list(k) for k in links],
                         "surface": boundary(x0, cells).tolist(), "mass": 0.01, "stiffness": 100.0, "damping": 0.0,
                         "position": [0.0, 0.0], "self_contact": True}],
             "simulation": {"t_end": 0.1}}
    scene = flexbody.load_scene(table)
    model = load_model(scene)
    x = np.load(Path(__file__).parent / "reference" / "u_apex_crossing.npz")["x"]
    y = np.concatenate([x.ravel(), np.zeros(x.size), np.zeros(model.ny - 2 * x.size)])
    p = model.parameters(scene)
    crossed = crossings(x, np.array(table["bodies"][0]["surface"]))
    assert len(crossed) == 1
    assert model.fold(y, p, depth=1e-9) is None
    assert "cross" in model.fold(y, p, depth=1e-12)[1]
    x_folded = x.copy()
    x_folded[[54, 88]] = x[[88, 54]]  # the faces' lower ends swapped: a crossing 3.2e-6 m deep
    y[: x.size] = x_folded.ravel()
    assert "cross" in model.fold(y, p, depth=1e-9)[1]


def test_a_lattice_collapsing_with_nothing_near_is_refused_at_the_first_sample_it_crosses_itself():
    """A fuzz's strip (tests/reference/fuzz_flap_hinge.json: 78 particles on a ground, its end
    flipped over onto it): its hinge's triangles invert and two boundary segments one apart
    cross, within a neighbourhood, with no contact near (each particle's neighbourhood is
    not watched).  A body with self-contact has its own surface checked at every output
    sample: refused there (before: `success`, crossing at 8 samples, up to 0.6 mm deep)."""
    table = reference_table("fuzz_flap_hinge")
    result = flexbody.simulate(flexbody.load_scene(table))
    surface = np.array(table["bodies"][0]["surface"])
    assert result.status == "unsupported" and "has folded over" in result.message, result.message
    crossed = [k for k, x in enumerate(result.positions) if len(crossings(x, surface))]
    assert crossed in ([], [len(result.t) - 1])  # none before the stop
