"""The held contacts' forces between bodies in C (flexbody.held_rows, generated/runtime/held_rows.c).

References: a particle resting on a segment (the force by hand), the dense ``J M^-1 J^T``
of rows built from the NumPy twins of the element kernels solved by
:func:`flexbody.dynamics.contact_solve`, and the NumPy branch of
``BodyContactModel._solve`` at the states a pile of discs, two spheres and a box sliding
down a wedge pass through.
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody import body_contact
from flexbody.constants import VELOCITY_ROUNDOFF
from flexbody.assembly import _kernels_module
from flexbody.bench_bodies import bodies_scene_table
from flexbody.dynamics import contact_solve
from flexbody.model import load_model
from flexbody.scene import load_scene

from .conftest import HAS_CC

pytestmark = pytest.mark.skipif(not HAS_CC, reason="needs a C compiler")
K = _kernels_module()
G = 9.81


def held_rows(masses, dim):
    from flexbody.held_rows import CompiledHeldRows

    return CompiledHeldRows(np.asarray(masses, float), dim)


def dense_reference(x, v, masses, acc, ground_particles, ground_normals, slot_points):
    """The rows' forces and the accelerations after them, through the dense ``J (m, n dim)``
    built from the NumPy kernels, ``W = J M^-1 J^T`` and :func:`contact_solve`."""
    n, d = x.shape
    rows, bias = [], []
    for i, normal in zip(ground_particles, ground_normals):
        row = np.zeros((n, d))
        row[i] = normal
        rows.append(row.ravel())
        bias.append(0.0)
    for points in slot_points:
        column = [z[:, None] for z in x[points]] + [z[:, None] for z in v[points]]
        if d == 2:
            _, s, normal, _ = K.segment_2d(*column[:3])
            weights = [1.0, -(1.0 - s[0, 0]), -s[0, 0]]
            _, _, gap_bias, *_ = K.segment_2d_velocity(*column)
        else:
            _, bary, normal, _ = K.triangle_3d(*column[:4])
            weights = [1.0] + list(-bary[:, 0])
            _, _, gap_bias = K.triangle_3d_velocity(*column)
        row = np.zeros((n, d))
        for particle, w in zip(points, weights):
            row[particle] += w * normal[:, 0]
        rows.append(row.ravel())
        bias.append(gap_bias[0, 0])
    J = np.array(rows)
    inverse = np.repeat(1.0 / np.asarray(masses, float), d)
    lam = contact_solve((J * inverse) @ J.T, -(J @ acc + np.array(bias)))
    return lam, acc + inverse * (J.T @ lam)


def test_a_particle_resting_on_a_segment_gets_the_force_by_hand():
    # a -> b along -x: the body lies below the segment, its outward normal is +y
    x = np.array([[0.5, 0.0], [1.0, 0.0], [-1.0, 0.0]])  # the particle at s = 0.25 from a
    masses = np.array([0.1, 0.2, 0.4])
    acc = np.array([0.0, -G, 0.0, 1.0, 0.0, -2.0])
    s = 0.25
    gap_acc = -G - (1 - s) * 1.0 - s * (-2.0)
    W = 1 / masses[0] + (1 - s) ** 2 / masses[1] + s**2 / masses[2]
    lam = held_rows(masses, 2)(x, np.zeros_like(x), acc, [], np.zeros((0, 2)), np.array([[0, 1, 2]]))
    assert lam == pytest.approx([-gap_acc / W], rel=1e-14)
    np.testing.assert_allclose(acc.reshape(3, 2)[:, 1], [-G + lam[0] / masses[0], 1.0 - (1 - s) * lam[0] / masses[1],
                                                        -2.0 - s * lam[0] / masses[2]], rtol=1e-14)
    after = acc.reshape(3, 2)[:, 1]
    assert after[0] - (1 - s) * after[1] - s * after[2] == pytest.approx(0.0, abs=1e-13)  # held: no gap acceleration


@pytest.mark.parametrize("dim", [2, 3])
def test_rows_sharing_particles_match_the_dense_contact_solve(dim):
    """Random rows on a pool of particles (some share, some stand apart; one slot twice,
    which the ordered Cholesky drops) against the dense reference, with velocities."""
    rng = np.random.default_rng(7 + dim)
    for trial in range(20):
        n = 40
        x, v = rng.normal(size=(n, dim)), rng.normal(size=(n, dim))
        masses = rng.uniform(0.05, 2.0, n)
        acc = rng.normal(size=n * dim)
        slots = np.array([rng.choice(n, dim + 1, replace=False) for _ in range(12)])
        slots = np.vstack([slots, slots[3]])  # a dependent row
        grounds = rng.choice(n, 5, replace=False)
        normals = rng.normal(size=(5, dim))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        lam_ref, acc_ref = dense_reference(x, v, masses, acc.copy(), grounds, normals, slots)
        got = acc.copy()
        lam = held_rows(masses, dim)(x, v, got, grounds, normals, slots)
        assert lam is not None
        scale = np.abs(lam_ref).max()
        np.testing.assert_allclose(lam, lam_ref, rtol=0, atol=1e-9 * scale, err_msg=f"trial {trial}")
        np.testing.assert_allclose(got, acc_ref, rtol=0, atol=1e-9 * np.abs(acc_ref).max(), err_msg=f"trial {trial}")
        assert lam[-1] == 0.0  # the repeated slot: dropped, its twin carries it


@pytest.mark.parametrize("dim", [2, 3])
def test_rows_laid_out_once_give_the_calls_numbers_bit_for_bit(dim):
    """``laid_out`` (a segment's right-hand side: its rows checked once) against the call
    with every argument, on random rows sharing particles, read from a whole state
    (positions, velocities, then more entries); then its refusals."""
    rng = np.random.default_rng(11 + dim)
    n = 30
    masses = rng.uniform(0.05, 2.0, n)
    rows = held_rows(masses, dim)
    slots = np.array([rng.choice(n, dim + 1, replace=False) for _ in range(10)])
    grounds = rng.choice(n, 4, replace=False)
    normals = rng.normal(size=(4, dim))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    laid_out = rows.laid_out(grounds, normals, slots)
    for trial in range(5):
        state = rng.normal(size=2 * n * dim + 3)
        acc = rng.normal(size=n * dim)
        expected_acc = acc.copy()
        expected = rows(state[: n * dim].reshape(n, dim), state[n * dim : 2 * n * dim].reshape(n, dim), expected_acc,
                        grounds, normals, slots)
        got = laid_out(state, acc)
        np.testing.assert_array_equal(got, expected)
        np.testing.assert_array_equal(acc, expected_acc)
    with pytest.raises(ValueError, match="acc must be"):
        laid_out(state, np.zeros(n * dim - 1))
    with pytest.raises(ValueError, match="positions and velocities"):
        laid_out(state[: 2 * n * dim - 1], acc)
    with pytest.raises(ValueError, match="slot_points must be particle indices"):
        rows.laid_out(grounds, normals, np.array([[0, 1, n] + [2] * (dim - 2)]))


def test_nearly_dependent_rows_are_dropped_against_every_rows_largest_entry():
    """A particle of 1 kg on two grounds 7e-6 rad apart beside one of 10 g on a ground: the
    pair's second pivot, (7e-6)^2 of the heavy block's scale, lies below 1e-12 of the light
    particle's (the largest diagonal entry of all the rows) and is dropped, as
    contact_solve drops it on the whole matrix; within its own block it would be kept, and
    the pair, pulled 0.3 m/s^2 along the grounds, would push and pull with 4e4 N."""
    x = np.array([[0.0, 0.0], [1.0, 0.0]])
    masses = np.array([1.0, 0.01])
    normals = np.array([[0.0, 1.0], [np.sin(7e-6), np.cos(7e-6)], [0.0, 1.0]])
    acc = np.array([0.3, -G, 0.0, -G])  # pulled along the grounds too: the pair's rows disagree
    lam_ref, acc_ref = dense_reference(x, np.zeros_like(x), masses, acc.copy(), [0, 0, 1], normals,
                                       np.zeros((0, 3), int))
    lam = held_rows(masses, 2)(x, np.zeros_like(x), acc, [0, 0, 1], normals, np.zeros((0, 3), int))
    np.testing.assert_allclose(lam, lam_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lam, [masses[0] * G, 0.0, masses[1] * G], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(acc, acc_ref, rtol=0, atol=1e-9)


def test_bad_arrays_are_refused_before_c_reads_them():
    rows = held_rows([0.1, 0.2, 0.4], 2)
    x = np.zeros((3, 2))
    with pytest.raises(ValueError, match="acc must be"):
        rows(x, x, np.zeros(5), [], np.zeros((0, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="slot_points must be particle indices"):
        rows(x, x, np.zeros(6), [], np.zeros((0, 2)), np.array([[0, 1, 3]]))
    with pytest.raises(ValueError, match="positions and velocities"):
        rows(np.zeros((2, 2)), x, np.zeros(6), [], np.zeros((0, 2)), np.array([[0, 1, 2]]))


def test_where_c_hands_back_the_model_answers_by_numpy(monkeypatch):
    """Every user of the C rows falls back to NumPy's contact_solve where C hands back (a
    pivot below the drop threshold): the same numbers as the NumPy path, bit for bit."""
    from flexbody.held_rows import LaidOutRows

    model, states = _states_of(_box_on_wedge(), every=40)
    monkeypatch.setattr(LaidOutRows, "__call__", lambda *args: None)  # the model's rows, laid out per contact set
    compiled = model._held_rows
    for y, p, held, push, elements in states:
        model.element_of[:] = elements
        model._held_rows = None
        ydot, lam = model.rhs(y, p, held, push)
        model._held_rows = compiled
        np.testing.assert_array_equal(model.rhs(y, p, held, push)[0], ydot)
        np.testing.assert_array_equal(model.rhs_function(p, held, push)(0.0, y), ydot)
        np.testing.assert_array_equal(model.forces_function(p, held, push)(y), lam)
        np.testing.assert_array_equal(model.held_forces(y, p, held, push), lam)


def test_an_indefinite_matrix_is_handed_back_untouched():
    """A pivot below the drop threshold (here a negative mass) returns None and leaves the
    accelerations as they were: the caller's contact_solve decides (pivoted, or a blow-up)."""
    x = np.array([[0.5, 0.0], [1.0, 0.0], [-1.0, 0.0]])
    acc = np.array([0.0, -G, 0.0, 0.0, 0.0, 0.0])
    before = acc.copy()
    assert held_rows([-0.1, 0.2, 0.4], 2)(x, np.zeros_like(x), acc, [], np.zeros((0, 2)), np.array([[0, 1, 2]])) is None
    np.testing.assert_array_equal(acc, before)


def _states_of(table: dict, every: int) -> tuple[body_contact.BodyContactModel, list]:
    """The model of ``table`` (C) and every ``every``-th state its right-hand side saw with held
    slots, with the held codes, pushes and elements."""
    scene = load_scene(table)
    model = load_model(scene)
    model.grows = False  # the run keeps this model, its table whole (not one of the pairs in reach)
    seen, make = [], model.rhs_function

    def recording(p, held, push):  # the steps' right-hand sides
        f = make(p, held, push)

        def g(t, y):
            if (np.asarray(held)[model.n_ground_contacts :] != 0).any():
                seen.append((y.copy(), p.copy(), held.copy(), push.copy(), model.element_of.copy()))
            return f(t, y)

        return g

    model.rhs_function = recording
    result = flexbody.simulate(scene, model=model)
    assert result.status == "success", result.message
    del model.rhs_function
    return model, seen[::every]


def _disc_pile() -> dict:
    return bodies_scene_table(4, 40, 0.3, True)  # the bodies study's pile, small


def _sphere_pair() -> dict:
    spheres = [{"name": f"s{k}", "shape": "sphere", "count": 30, "radius": 0.1, "center": True, "mass_total": 0.5,
                "stiffness": 2000.0, "damping": 0.5, "damper": "relative", "position": [0.05 * k, 0.0, 0.15 + 0.22 * k],
                "rotation": [0.1 * k, 0.05, 0.0], "collide": True} for k in range(2)]
    return {"name": "spheres", "bodies": spheres, "gravity": [0.0, 0.0, -9.81],
            "simulation": {"t_end": 0.3, "output_dt": 0.01, "method": "RK45", "rtol": 1e-6, "atol": 1e-9}}


def _box_on_wedge() -> dict:
    """A flexible box sliding (no friction) down a flexible wedge on the ground: the wedge's
    foot, held on the ground, is a vertex of the face the box is held on, so their rows are
    solved together."""
    angle = np.arctan2(0.2, 0.6)
    along, normal = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    corner = np.array([-0.3, 0.0]) + 0.25 * along + 1e-6 * normal
    box = [corner, corner + 0.05 * along, corner + 0.05 * (along + normal), corner + 0.05 * normal]
    bodies = [{"name": "wedge", "shape": "polygon", "vertices": [[-0.3, 0.0], [0.3, 0.0], [0.3, 0.2]], "mass": 1.0,
               "stiffness": 2e4, "damping": 2.0, "collide": True, "position": [0.0, 0.0]},
              {"name": "box", "shape": "polygon", "vertices": [c.tolist() for c in box], "mass": 0.05,
               "stiffness": 2e3, "damping": 0.2, "collide": True, "position": [0.0, 0.0]}]
    return {"name": "box_on_wedge", "bodies": bodies, "gravity": [0.0, -9.81],
            "simulation": {"t_end": 0.2, "output_dt": 0.01, "method": "RK45", "rtol": 1e-6, "atol": 1e-9}}


@pytest.mark.parametrize("table", [_disc_pile, _sphere_pair, _box_on_wedge], ids=["discs_2d", "spheres_3d", "wedge_2d"])
def test_the_c_rows_equal_the_numpy_rows_along_a_run(table):
    model, states = _states_of(table(), every=5)
    assert len(states) > 20  # the pile rests on its held slots for a while
    coupled_grounds = 0
    compiled = model._held_rows
    weight = 9.81 * model.masses.max()
    for y, p, held, push, elements in states:
        model.element_of[:] = elements
        model._held_rows = compiled
        # the segment's functions, laid out once for the contact set: rhs's numbers, bit for bit
        ydot, lam = model.rhs(y, p, held, push)
        np.testing.assert_array_equal(model.rhs_function(p, held, push)(0.0, y), ydot)
        np.testing.assert_array_equal(model.forces_function(p, held, push)(y), lam)
        c = model._solve(y, p, held, push)
        model._held_rows = None
        reference = model._solve(y, p, held, push)
        np.testing.assert_array_equal(c.rows, reference.rows)
        coupled_grounds += bool((c.rows < model.n_ground_contacts).any())
        # forces to rounding of the larger of the forces and a particle's weight (a slot
        # just held can push with 1e-16 N: its round-off is the pile's, not its own)
        scale = max(np.abs(reference.lam).max(), weight)
        np.testing.assert_allclose(c.lam, reference.lam, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(c.ydot, reference.ydot, rtol=0, atol=1e-10 * np.abs(reference.ydot).max())
        # the contacts coupled to each held slot's: the C blocks, then SciPy's components
        on = np.asarray(held) != 0
        for slot in np.flatnonzero(on[model.n_ground_contacts :])[:3] + model.n_ground_contacts:
            seed = np.zeros(model.n_contacts, bool)
            seed[slot] = True
            model._held_rows = compiled
            blocks = model.coupled_with(y[: model.nq], p, seed, on)
            model._held_rows = None
            np.testing.assert_array_equal(blocks, model.coupled_with(y[: model.nq], p, seed, on))
            # the block's forces from its own particles and rows: the whole right-hand side's, bit for bit
            model._held_rows = compiled
            alone = np.where(blocks & on, held, 0).astype(held.dtype)
            np.testing.assert_array_equal(model.held_forces(y, p, alone, push), model.rhs(y, p, alone, push)[1])
        model._held_rows = compiled
    if table is _box_on_wedge:
        assert coupled_grounds == len(states)  # the wedge's foot: ground rows solved with the slots


def _rough_spheres() -> dict:
    """Two rough flexible spheres (mu = 0.4), the upper one landing on the lower with a
    sideways speed: its contacts slide, then stick."""
    table = _sphere_pair()
    table["bodies"][1]["velocity"] = [0.4, 0.1, 0.0]
    table["contacts"] = [{"bodies": ["s0", "s1"], "friction": 0.4}]
    table["grounds"] = [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "friction": 0.4}]
    return table


def _ring_stack() -> dict:
    """The bundled ring_stack (2D, mu = 0.5 between the bodies), the upper ring thrown
    sideways: it lands sliding and sticks."""
    import tomllib
    from pathlib import Path

    table = tomllib.loads((Path(flexbody.__file__).parent / "scenes" / "ring_stack.toml").read_text())
    table["simulation"]["t_end"] = 0.4
    table["bodies"][2]["velocity"] = [0.3, 0.0]  # the upper ring lands sliding
    return table


@pytest.mark.parametrize("table", [_ring_stack, _rough_spheres], ids=["rings_2d", "spheres_3d"])
def test_the_c_friction_rows_equal_the_numpy_rows_along_a_run(table):
    """The held rows with friction (sticking rows held, sliding ones dragged) solved in C
    (fb_held_friction, fb_held_slips) against the NumPy rows of the same states: forces,
    friction, slip rates, tangents and the right-hand side to rounding of the forces'
    accelerations; stick and slide both met.  A slide whose slip is within 1e3 of the
    velocities' round-off (slipping at 2e-13 m/s, its friction follows that slip) has its
    direction from the rounding alone, which the two sums make differently (2e-4 rad
    apart, measured): such states are counted, not compared."""
    model, states = _states_of(table(), every=3)
    compiled, stuck, slid, rounding = model._held_rows, 0, 0, 0
    compiled.friction_solves[:] = [0, 0]  # those of the run are not counted: the states' are
    for y, p, held, push, elements in states:
        model.element_of[:] = elements
        model._held_rows = compiled
        c = model._solve(y, p, held, push)
        model._held_rows = None
        reference = model._solve(y, p, held, push)
        model._held_rows = compiled
        np.testing.assert_array_equal(c.rows, reference.rows)
        np.testing.assert_array_equal(c.stick, reference.stick)
        speed = max(np.abs(y[model.nq : model.nq + model.nu]).max(), 1.0)
        np.testing.assert_allclose(c.tangents, reference.tangents, rtol=0, atol=1e-14)
        np.testing.assert_allclose(c.slip, reference.slip, rtol=0, atol=1e-14 * speed)
        sliding = np.asarray(held)[c.rows] == body_contact.SLIDING
        if (sliding & (np.linalg.norm(c.slip, axis=1) < 1e3 * VELOCITY_ROUNDOFF * speed)).any():
            rounding += 1
            continue
        stuck += bool(c.stick.any())
        slid += bool(sliding.any())
        force = max(np.abs(reference.lam).max(), 9.81 * model.masses.max())
        np.testing.assert_allclose(c.lam, reference.lam, rtol=0, atol=1e-12 * force)
        np.testing.assert_allclose(c.lam_t, reference.lam_t, rtol=0, atol=1e-12 * force)
        np.testing.assert_allclose(c.ydot, reference.ydot, rtol=0, atol=1e-12 * force / model.masses.min())
    assert stuck > 5 and slid > 5 and rounding < (stuck + slid) / 4, (stuck, slid, rounding)
    solved, handed_back = compiled.friction_solves
    assert solved > 10 * handed_back, (solved, handed_back)  # C answered: NumPy was not compared with itself


def test_friction_rows_of_a_particle_on_a_ground_give_the_forces_by_hand():
    """One particle (m = 0.2 kg) held on a ground y = 0 with a sideways pull a_x = 3 m/s^2:
    sticking, its normal force is m g and its friction -m a_x (it stays put); sliding along
    +x (its tangent t = (-n_y, n_x) = (-1, 0), so drag mu = 0.5 along t) the friction is
    -mu m g along x and it speeds up at a_x - mu g."""
    m, mu, a_x = 0.2, 0.5, 3.0
    rows = held_rows([m], 2)
    x, v, frame = np.zeros((1, 2)), np.zeros((1, 2)), np.array([[[0.0, 1.0], [-1.0, 0.0]]])
    acc = np.array([a_x, -G])
    lam_n, lam_t = rows.friction(x, v, acc, [0], frame, np.zeros((0, 3), int), [mu], np.array([True]),
                                 np.zeros((1, 1)))
    assert lam_n[0] == pytest.approx(m * G, rel=1e-14) and lam_t[0, 0] == pytest.approx(m * a_x, rel=1e-14)
    np.testing.assert_allclose(acc, 0.0, atol=1e-14)
    acc = np.array([a_x, -G])
    lam_n, lam_t = rows.friction(x, v, acc, [0], frame, np.zeros((0, 3), int), [mu], np.array([False]),
                                 np.array([[mu]]))
    assert lam_n[0] == pytest.approx(m * G, rel=1e-14) and lam_t[0, 0] == pytest.approx(mu * m * G, rel=1e-14)
    np.testing.assert_allclose(acc, [a_x - mu * G, 0.0], atol=1e-14)


def test_a_sticking_contact_that_pulls_is_handed_back_to_the_twins_split():
    """The same particle pulled off its ground (a_y = +g) while sticking: its normal force is
    -m g, and the NumPy twin, which splits sticking friction as mu lam_n, scales its tangent
    column by sqrt(1e-300) and leaves it no friction, where the exact solve gives it m a_x
    (a fuzzed 2D pile: 0.14 N in C, none in NumPy, the right-hand sides 9 % apart).  C
    hands such a problem back; pushed onto the ground it answers."""
    rows = held_rows([0.2], 2)
    frame = np.array([[[0.0, 1.0], [-1.0, 0.0]]])
    for a_y, handed_back in ((G, True), (-G, False)):
        acc = np.array([3.0, a_y])
        answer = rows.friction(np.zeros((1, 2)), np.zeros((1, 2)), acc, [0], frame, np.zeros((0, 3), int), [0.5],
                               np.array([True]), np.zeros((1, 1)))
        assert (answer is None) == handed_back


def test_dependent_friction_rows_are_handed_back_untouched():
    """The same ground row twice on one particle: its rows are dependent (the least-squares
    twin picks among the answers), so C hands back and leaves the accelerations alone."""
    rows = held_rows([0.2], 2)
    frames = np.array([[[0.0, 1.0], [-1.0, 0.0]]] * 2)
    acc = np.array([3.0, -G])
    assert rows.friction(np.zeros((1, 2)), np.zeros((1, 2)), acc, [0, 0], frames, np.zeros((0, 3), int),
                         [0.5, 0.5], np.array([True, True]), np.zeros((2, 1))) is None
    np.testing.assert_array_equal(acc, [3.0, -G])


def test_a_singular_frictional_block_with_no_small_pivot_is_handed_back():
    """A fuzz's two rough boxes on a frictionless ground (tests/reference/
    friction_rows_singular.npz, from fuzz_friction_pair_near_tie.json): 11 held rows, two
    sliding, five sticking, whose 21 x 21 matrix has a singular value of 5e-15 (of 118) while
    partial pivoting's least pivot is 1e-9 of its largest.  Solved through it, a ground
    row's force read -5.0 N where NumPy's least squares gives 1.4 N, and the run warned of a
    held force of -400 N.  The block's condition, not its pivots, hands it back."""
    from pathlib import Path

    data = np.load(Path(__file__).parent / "reference" / "friction_rows_singular.npz")
    acc = data["acc"].copy()
    answer = held_rows(data["masses"], 3).friction(data["x"], data["v"], acc, data["at"], data["frames"],
                                                    data["points"], data["mu"], data["stick"], data["drag"])
    assert answer is None
    np.testing.assert_array_equal(acc, data["acc"])


@pytest.mark.parametrize("dim", [2, 3])
def test_row_blocks_are_the_connected_components_of_rows_and_particles(dim):
    """Against SciPy's connected components of the graph of rows and the particles they
    move; blocks numbered in the order of their lowest rows."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(dim)
    for _ in range(30):
        n = int(rng.integers(20, 200))
        slots = np.array([rng.choice(n, dim + 1, replace=False) for _ in range(int(rng.integers(0, 30)))],
                         int).reshape(-1, dim + 1)
        grounds = rng.choice(n, int(rng.integers(0, 10)), replace=False)
        block = held_rows(np.ones(n), dim).blocks(grounds, slots)
        rows = np.concatenate([np.arange(len(grounds)), len(grounds) + np.repeat(np.arange(len(slots)), dim + 1)])
        particles = np.concatenate([grounds, slots.ravel()])
        m = len(grounds) + len(slots)
        graph = coo_matrix((np.ones(len(rows)), (rows, m + particles)), shape=(m + n, m + n))
        label = connected_components(graph, directed=False)[1][:m]
        np.testing.assert_array_equal(label[:, None] == label[None, :], block[:, None] == block[None, :])
        first_rows = [int(np.flatnonzero(block == b)[0]) for b in range(block.max(initial=-1) + 1)]
        assert first_rows == sorted(first_rows)


@pytest.mark.parametrize("dim", [2, 3])
def test_free_accelerations_of_some_particles_are_the_right_hand_sides(dim):
    """The assembled C model's free accelerations of listed particles alone equal its whole
    right-hand side's with nothing held, bit for bit; the others are left at 0."""
    if dim == 2:
        table = bodies_scene_table(2, 30, 0.1, True)
    else:
        table = _sphere_pair()
    model = load_model(load_scene(table))
    inner, rng = model.inner, np.random.default_rng(dim)
    p = model.parameters(load_scene(table))
    y = np.concatenate([rng.normal(size=inner.nq) * 0.1, rng.normal(size=inner.nu), [0.0, 0.0]])
    push = np.where(rng.random(inner.n_contacts) < 0.2, rng.random(inner.n_contacts), 0.0)
    listed = rng.choice(inner.n_particles, 7, replace=False)
    acc = inner.free_accelerations(y, p, push, listed).reshape(-1, dim)
    whole = inner.rhs(y, p, np.zeros(inner.n_contacts, np.intc), push)[0][inner.nq : inner.nq + inner.nu].reshape(-1, dim)
    np.testing.assert_array_equal(acc[listed], whole[listed])
    assert not np.delete(acc, listed, axis=0).any()


def test_a_segments_functions_keep_the_contact_set_they_were_made_with():
    """The caller's held codes changed after a segment's functions were made: they answer
    for the set they were made with."""
    model, states = _states_of(_disc_pile(), every=25)
    y, p, held, push, elements = states[-1]
    model.element_of[:] = elements
    held = held.copy()
    f, forces = model.rhs_function(p, held, push), model.forces_function(p, held, push)
    ydot, lam = model.rhs(y, p, held, push)
    held[np.flatnonzero(held[model.n_ground_contacts :])[0] + model.n_ground_contacts] = 0
    np.testing.assert_array_equal(f(0.0, y), ydot)
    np.testing.assert_array_equal(forces(y), lam)


def test_a_segments_functions_follow_a_held_slot_handed_to_another_element():
    """A frozen right-hand side and forces function whose held slot moved to another element
    since (a hand-over) answer as the model does now, not as laid out."""
    model, states = _states_of(_disc_pile(), every=25)
    y, p, held, push, elements = states[-1]
    model.element_of[:] = elements
    f, forces = model.rhs_function(p, held, push), model.forces_function(p, held, push)
    slot = int(np.flatnonzero(np.asarray(held)[model.n_ground_contacts :])[0])
    element = model.element_of[slot]
    model.element_of[slot] = model._neighbour[element, 0]  # its neighbour beyond its first vertex
    assert model.element_of[slot] != element
    ydot, lam = model.rhs(y, p, held, push)
    np.testing.assert_array_equal(f(0.0, y), ydot)
    np.testing.assert_array_equal(forces(y), lam)
    model.element_of[slot] = element
    assert not np.array_equal(f(0.0, y), ydot)  # the element matters: the test can fail


def _seesaw() -> dict:
    """The bundled seesaw (rigid wedge and plank, a flexible disc; friction everywhere) to
    0.3 s: the disc lands on the plank's end and rests there."""
    import tomllib
    from pathlib import Path

    table = tomllib.loads((Path(flexbody.__file__).parent / "scenes" / "seesaw.toml").read_text())
    table["simulation"]["t_end"] = 0.3
    return table


def test_the_kept_answers_are_each_states_own():
    """The coupled dynamics keeps its last few answers by state (a step's end is asked after
    its midpoint, at the state of the stepper's last stage): asked again at an earlier
    state, between others, each answer is a fresh solve's there, bit for bit, and one whose
    slip directions, held codes or elements changed since is solved again (rigid frames and
    friction: the NumPy rows)."""
    model, states = _states_of(_seesaw(), every=15)
    assert len(states) > 8 and model._frictional
    solves, solve = [0], model._solve

    def counted(*args):
        solves[0] += 1
        return solve(*args)

    model._solve = counted
    for k in range(len(states) - 2):
        for i in (k, k + 1, k, k + 2, k + 1, k):  # each asked again after others
            y, p, held, push, elements = states[i]
            model.element_of[:] = elements
            ydot, lam = model.rhs(y, p, held, push)
            fresh = solve(y, p, held, push)
            np.testing.assert_array_equal(ydot, fresh.ydot)
            np.testing.assert_array_equal(lam, fresh.lam)
    assert solves[0] == len(states)  # the states asked again were answered from those kept
    # a state with a sliding contact, its friction along one slip direction, then the other
    y, p, held, push, elements = [s for s in states if (np.asarray(s[2]) == body_contact.SLIDING).any()][-1]
    model.element_of[:] = elements
    sliding = np.flatnonzero(np.asarray(held) == body_contact.SLIDING)
    answers = []
    for direction in ([1.0, 0.0], [-1.0, 0.0]):
        model._slip[sliding] = direction
        answers.append(model.rhs(y, p, held, push))
        np.testing.assert_array_equal(answers[-1][0], solve(y, p, held, push).ydot)
    assert not np.array_equal(answers[0][1], answers[1][1])  # the slips matter: the test can fail
    fewer = np.array(held)
    fewer[sliding[0]] = 0
    np.testing.assert_array_equal(model.rhs(y, p, fewer, push)[1], solve(y, p, fewer, push).lam)
    assert not np.array_equal(answers[1][1], solve(y, p, fewer, push).lam)
    assert solves[0] == len(states) + 3
