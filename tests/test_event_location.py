"""Event location on a step's dense output (flexbody.events): the earliest root of every
contact whose event function fired, and the contacts of the same instant.

The event functions here are closed forms of time (the "state" is the time itself), so
each root is known exactly and can be checked against the located instant.
"""

import numpy as np
import pytest

from flexbody.constants import GROUP_TIME
from flexbody.events import EventFunctions, _earliest, locate


class _Closed:
    """Event functions g_c(t) given in closed form; counts whole-vector and single evaluations."""

    def __init__(self, functions):
        self.functions = functions
        self.free = np.ones(len(functions), bool)
        self.whole = self.single = 0

    def __call__(self, y):
        self.whole += 1
        return np.array([f(y[0]) for f in self.functions])

    def free_gaps(self, y, only=None):  # the free contacts' functions (those ``only``), inf for the others
        return np.where(self.free & (True if only is None else only), self(y), np.inf)

    def one(self, y, c):
        self.single += 1
        return float(self.functions[c](y[0]))


def _locate(functions, ta=0.0, tb=1.0, held=()):
    events = _Closed(functions)
    events.free[list(held)] = False  # a held contact's function (its force) is evaluated whole
    ga, gb = events(np.array([ta])), events(np.array([tb]))
    fired = np.flatnonzero((ga > 0) & (gb <= 0))
    return _earliest(events, lambda t: np.array([t]), fired, ta, tb, ga, gb), events


def test_earliest_root_and_its_instant():
    roots = [0.3, 0.1, 0.1 + 0.5 * GROUP_TIME, 0.2, 0.1 + 3 * GROUP_TIME]
    crossing, _ = _locate([lambda t, r=r: r - t for r in roots])
    assert crossing.t == pytest.approx(0.1, abs=1e-14)
    assert crossing.t >= 0.1 - 1e-15  # never before the root: the restart must not find it again
    assert np.flatnonzero(crossing.contacts).tolist() == [1, 2]  # within GROUP_TIME of the earliest only


def test_a_misleading_chord_does_not_hide_an_earlier_root():
    # contact 0's chord crosses first (at 0.3) but its root is at 0.3 ** (1/3) = 0.669;
    # contact 1's chord and root are at 0.5: the instant is 0.5, contact 1 alone
    for held in ((), (0,), (1,)):  # impacts only, or a lift-off among them
        crossing, _ = _locate([lambda t: 0.3 - t**3, lambda t: 0.5 - t], held=held)
        assert crossing.t == pytest.approx(0.5, abs=1e-14)
        assert np.flatnonzero(crossing.contacts).tolist() == [1]


def test_simultaneous_roots_form_one_instant_whatever_the_order():
    # four contacts crossing at the same time (a body landing flat), listed in two orders
    slopes = [1.0, 2.0, 0.5, 3.0]
    for order in (slopes, slopes[::-1]):
        crossing, _ = _locate([lambda t, s=s: s * (0.25 - t) for s in order])
        assert crossing.t == pytest.approx(0.25, abs=1e-14)
        assert crossing.contacts.all()


def test_one_root_search_per_instant_when_the_chords_order_the_roots():
    # 50 contacts fired in the bracket, roots spread over it: one is searched, not 50
    roots = np.linspace(0.2, 0.9, 50)
    crossing, events = _locate([lambda t, r=r: r - t for r in roots[::-1]])
    assert crossing.t == pytest.approx(0.2, abs=1e-14)
    assert np.flatnonzero(crossing.contacts).tolist() == [49]
    assert events.single < 60 and events.whole <= 4  # ends, the root, its group time


class _Step(_Closed):
    """:class:`_Closed` as :func:`flexbody.events.locate` needs it: free contacts between
    bodies, armed at their surfaces (floor 0), none just released."""

    def __init__(self, functions):
        super().__init__(functions)
        self.between_bodies = np.ones(len(functions), bool)
        self.phases = type("Phases", (), {"floor": np.zeros(len(functions))})()
        self.gap_tolerance = 1e-12
        self.model = type("Model", (), {"corners": False})()  # no bodies' corners to pass through

    def held_functions(self, y):
        return np.where(self.free, np.inf, self(y))

    def rearm(self, g_mid, g_new):
        pass


def test_a_contact_found_inside_at_anothers_crossing_dipped_first_and_is_the_instant():
    """Contact 0 crosses at 0.62; contact 1 dips through its surface over [0.55, 0.65] and
    is above it at every point checked (the step's ends and midpoint).  Stopping at 0.62
    would leave contact 1 0.03 inside, unseen (the next step starts past it): the instant
    is contact 1's own crossing, at 0.55."""
    events = _Step([lambda t: 0.62 - t, lambda t: abs(t - 0.6) - 0.05])
    dense = lambda t: np.array([t])  # noqa: E731
    g_old, g_new = events(dense(0.0)), events(dense(1.0))
    crossing = locate(events, dense, 0.0, 1.0, g_old, g_new)
    assert crossing.t == pytest.approx(0.55, abs=1e-14)
    assert np.flatnonzero(crossing.contacts).tolist() == [1]
    # without the dip, contact 0's crossing is the instant
    events = _Step([lambda t: 0.62 - t, lambda t: abs(t - 0.6) + 0.05])
    crossing = locate(events, dense, 0.0, 1.0, events(dense(0.0)), events(dense(1.0)))
    assert crossing.t == pytest.approx(0.62, abs=1e-14)
    assert np.flatnonzero(crossing.contacts).tolist() == [0]


class _Released(_Step):
    """:class:`_Step` whose functions are gaps, each contact armed at its floor
    (``phases.floor``) and re-armed at the ground at a midpoint as
    :meth:`flexbody.events.EventFunctions.rearm` does."""

    def __init__(self, functions, floor):
        super().__init__(functions)
        self.phases.floor = np.array(floor, float)

    def __call__(self, y):
        return super().__call__(y) - self.phases.floor

    def one(self, y, c):
        return super().one(y, c) - float(self.phases.floor[c])

    def rearm(self, g_mid, g_new):
        EventFunctions.rearm(self, g_mid, g_new)


def test_a_contact_re_armed_at_the_midpoint_and_found_inside_at_anothers_crossing_is_the_instant():
    """Contact 1 was released a hair inside its surface (gap -8e-15, armed at -1e-12), is
    clear of it at the midpoint (re-armed at 0), and dips in over [0.60, 0.62], between the
    points checked; contact 0 crosses at 0.615, inside that dip.  Re-armed, contact 1 reads
    below its floor at the step's start too: it is still the instant, at 0.60 (measured: a
    3D box's corner particle 3.06e-9 m inside another box's edge at a ground contact's
    instant, unseen)."""
    events = _Released([lambda t: 0.615 - t, lambda t: min(t - 8e-15, abs(t - 0.61) - 0.01)], [0.0, -1e-12])
    dense = lambda t: np.array([t])  # noqa: E731
    g_old, g_new = events(dense(0.0)), events(dense(1.0))
    crossing = locate(events, dense, 0.0, 1.0, g_old, g_new)
    assert events.phases.floor[1] == 0.0  # re-armed at the midpoint
    assert crossing.t == pytest.approx(0.60, abs=1e-14)
    assert np.flatnonzero(crossing.contacts).tolist() == [1]


class _Island(_Step):
    """A held contact whose force from its block alone (``one``) already pulls at the
    step's start, while the whole problem's (``__call__``) still pushes there."""

    def one(self, y, c):
        self.single += 1
        return float(self.functions[c](y[0])) - 0.6


def test_a_held_contact_whose_block_alone_disagrees_is_rooted_on_the_whole_problem():
    """The lift-off of a held contact is where the whole problem's force reaches 0 (0.5),
    the force the instant's resolve agrees with; the block's alone (rounding apart, a
    redundant row's share) would put it at the step's start, where resolve keeps the
    contact held and the next step would find the same event again, without end."""
    events = _Island([lambda t: 0.5 - t])
    events.free[:] = False
    dense = lambda t: np.array([t])  # noqa: E731
    crossing = locate(events, dense, 0.0, 1.0, events(dense(0.0)), events(dense(1.0)))
    assert crossing.t == pytest.approx(0.5, abs=1e-14)
    assert crossing.contacts.tolist() == [True]


@pytest.mark.parametrize("g, root, most", [
    (lambda t: 0.3 - t, 0.3, 4),
    (lambda t: 0.3 - t**3, 0.3 ** (1 / 3), 9),
    (lambda t: np.cos(3 * t), np.pi / 6, 9),
    (lambda t: 1e-8 - 1e7 * (t - 0.7), 0.7 + 1e-15, 5),  # a contact force falling at 1e7 N/s
    (lambda t: 1.0 - np.exp(100 * (t - 0.9)), 0.9, 14),  # flat, then steep
    (lambda t: -np.tanh(1e6 * (t - 0.123)), 0.123, 28),  # a step smoothed over 1e-6
    (lambda t: np.sign(0.37 - t) * abs(0.37 - t) ** 0.5, 0.37, 45),  # infinite slope at the root
    (lambda t: np.sign(0.437 - t) * abs(0.437 - t) ** 9, 0.437, 55),  # flat at the root: interpolation helps little
    (lambda t: 1.0 if t < 0.61 else -1.0, 0.61, 52),  # a jump: bisection halves [0, 1] to 1e-15 in 49
])
def test_first_fired_is_on_the_fired_side_within_the_tolerance(g, root, most):
    from flexbody.events import first_fired

    seen = []

    def counted(t):
        seen.append(t)
        return g(t)

    xtol = 1e-15
    t = first_fired(counted, 0.0, 1.0, g(0.0), g(1.0), xtol)
    assert g(t) <= 0.0  # a restart from t must not find the same event again
    assert root - 4 * np.spacing(root) <= t <= root + 2 * (xtol + 4 * np.finfo(float).eps)  # |t| <= 1
    assert 0.0 not in seen and 1.0 not in seen  # the ends' values are reused
    assert len(seen) <= most  # SciPy's brentq and a bisection to the fired side took 16-20 in a pile


def test_first_fired_finds_where_a_plateau_of_zeros_starts():
    """A free contact's gap can read exactly 0 from its root on (a particle met on a coplanar
    face's plane): with ``plateaus`` the root is the plateau's start, not the bracket's end,
    whose value is 0 too (taken there, a box was held 1e-4 m past the face it met and slid
    through the other box); an isolated zero costs one point beside it."""
    from flexbody.events import first_fired

    xtol, eps = 1e-15, np.finfo(float).eps
    for root in (0.29, 0.5, 0.9):
        seen = []

        def g(t):
            seen.append(t)
            return max(0.0, root - t)

        t = first_fired(g, 0.0, 1.0, root, 0.0, xtol, plateaus=True)
        assert root <= t <= root + 2 * (xtol + 4 * eps) and len(seen) <= 110  # two per halving at most
        assert first_fired(g, 0.0, 1.0, root, 0.0, xtol) == 1.0  # a held function's 0 is its root
    seen = []
    t = first_fired(lambda t: seen.append(t) or 0.3 - t, 0.0, 1.0, 0.3, -0.7, xtol, plateaus=True)
    assert t == pytest.approx(0.3, abs=4 * eps) and len(seen) <= 5


def test_first_fired_counts_a_nan_as_fired_and_takes_an_empty_bracket():
    from flexbody.events import first_fired

    def g(t):  # a state that stops being finite between the bracket's ends
        return 1.0 if t < 0.4 else np.nan if t < 0.6 else -1.0

    t = first_fired(g, 0.0, 1.0, 1.0, -1.0, 1e-15)
    assert not g(t) > 0.0 and t == pytest.approx(0.4, abs=1e-14)
    assert first_fired(g, 0.7, 0.7, 1.0, -1.0, 1e-15) == 0.7


def test_first_fired_returns_within_its_tolerance_wherever_a_jump_lies():
    """A jump's bisection ends with brackets of every width up to the tolerance: the fired
    end is within 2 (xtol + 4 eps t) after the jump at each of 401 positions."""
    from flexbody.events import first_fired

    xtol, eps = 1e-15, np.finfo(float).eps
    for root in np.linspace(0.05, 0.95, 401):
        t = first_fired(lambda t: 1.0 if t < root else -1.0, 0.0, 1.0, 1.0, -1.0, xtol)
        assert root <= t <= root + 2 * (xtol + 4 * eps)  # |t| <= 1


def test_a_slide_from_rest_keeps_its_pull_when_its_first_step_is_taken_again():
    """A contact the last instant set sliding from rest (``Phases.started``) slides along its
    pull in its first step, whatever round-off slip it has; a step taken again from the same
    start, shorter (a body moved too far in it, or a held contact sank), is that first step
    too.  Its round-off slip, across the fall line here, would turn its friction across it."""
    from flexbody import load_scene
    from flexbody.constants import SLIDING
    from flexbody.contact import Phases
    from flexbody.model import load_model

    tilt = np.radians(15.0)  # tan 15 deg = 0.27 > mu = 0.1: it slides
    normal = [np.sin(tilt), 0.0, np.cos(tilt)]
    fall = np.array([np.cos(tilt), 0.0, -np.sin(tilt)])  # down the slope
    scene = load_scene({
        "name": "slope", "gravity": [0.0, 0.0, -9.81],
        "grounds": [{"point": [0.0, 0.0, 0.0], "normal": normal, "friction": 0.1}],
        "bodies": [{"name": "p", "particles": [[0.0, 0.0, 0.0]], "links": [], "stiffness": [], "damping": [],
                    "mass": 0.1, "position": [0.0, 0.0, 0.0], "velocity": [0.0, 0.0, 0.0],
                    "rotation": [0.0, 0.0, 0.0], "angular_velocity": [0.0, 0.0, 0.0]}],
        "simulation": {"t_end": 1.0, "output_dt": 0.1}})
    model = load_model(scene, backend="numpy")
    p = model.parameters(scene)
    phases = Phases.all_free(model.n_contacts)
    phases.phase[:] = SLIDING
    phases.started[:] = True
    y = np.zeros(model.nq + model.nu)
    y[model.nq + 1] = 1e-20  # a round-off slip across the fall line
    events = EventFunctions(model, p, phases, np.full(1, 1e-12), 1e-12, 1e-9, np.full(1, 0.1))
    for _ in range(2):  # the first step, then the same step again from its start
        events.renew(y.copy(), 1e-4)
        assert events.from_rest[0]
        np.testing.assert_allclose(events.direction[0], fall, atol=1e-12)
    later = y.copy()
    later[: model.nq] += 1e-9 * fall  # the next step starts elsewhere: its slip is its own
    events.renew(later, 1e-4)
    assert not events.from_rest[0]
    np.testing.assert_allclose(events.direction[0], [0.0, 1.0, 0.0], atol=1e-12)
