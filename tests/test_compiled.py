"""The compiled fixed point (``fb_resolve``) against its Python reference, instant by instant."""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.compiled import IMPACT, SLIP, STICK, CompiledPath
from flexbody.driver import EVENT_KINDS
from flexbody.contact import PUSHED, Phases, resolve
from flexbody.model import load_model

from .conftest import HAS_CC
from .test_runtime import level_ring

pytestmark = pytest.mark.skipif(not HAS_CC, reason="no C compiler")


def compiled_instants(monkeypatch, scene, **options) -> list[dict]:
    """Every event instant of a compiled run: the inputs of the fixed point and what C made of them."""
    instants = []
    original = CompiledPath.resolve

    def spy(self, t, touching, leaving, thesis, impact_dt):
        before = dict(t=t, y=self.y.copy(), phases=self.phases.copy(), touching=np.array(touching, bool),
                      leaving=np.array(leaving, bool), impact="thesis" if thesis else "instant", impact_dt=impact_dt)
        events, not_held, loss = original(self, t, touching, leaving, thesis, impact_dt)
        instants.append(dict(before, after=dict(y=self.y.copy(), phases=self.phases.copy(), events=events,
                                                not_held=not_held.astype(bool), loss=loss),
                             run=dict(p=self.p, gap_tolerance=self.gap_tolerance,
                                      force_tolerance=self.force_tolerance, masses=self.masses,
                                      restitution=self.restitution, min_rebound=self.min_rebound,
                                      speed_tolerance=self.speed_tolerance)))
        return events, not_held, loss

    monkeypatch.setattr(CompiledPath, "resolve", spy)
    result = flexbody.simulate(scene, backend="c", **options)
    assert result.success, result.message
    return instants


def assert_same_as_reference(model, instant):
    run, after = instant["run"], instant["after"]
    ref = resolve(model, instant["t"], instant["y"], run["p"], instant["phases"], instant["touching"],
                  instant["leaving"], gap_tolerance=run["gap_tolerance"], force_tolerance=run["force_tolerance"],
                  masses=run["masses"], impact=instant["impact"], impact_dt=instant["impact_dt"],
                  restitution=run["restitution"], min_rebound=run["min_rebound"],
                  speed_tolerance=run["speed_tolerance"])
    # The same arithmetic (both call the generated fb_contact_state and fb_impact): exactly equal.
    np.testing.assert_array_equal(after["y"], ref.y)
    for name in Phases.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(after["phases"], name), getattr(ref.phases, name), err_msg=name)
    codes = {name: code for code, name in EVENT_KINDS.items()}
    assert after["events"] == [(e.contact, codes[e.kind], e.normal_velocity) for e in ref.events]
    np.testing.assert_array_equal(after["not_held"], ref.not_held)
    assert after["loss"] == ref.impact_loss


@pytest.mark.parametrize("case", ["thesis_ball", "thesis_ball, thesis impacts", "flat landing",
                                  "ball_on_incline", "bouncing bar"])
def test_compiled_fixed_point_equals_the_python_one(monkeypatch, case):
    if case in ("ball_on_incline", "bouncing bar"):
        scene, options = friction_case(case), {}
        instants = compiled_instants(monkeypatch, scene, **options)
        model = load_model(scene, backend="c")
        for instant in instants:
            assert_same_as_reference(model, instant)
        kinds = [kind for i in instants for _, kind, _ in i["after"]["events"]]
        assert STICK in kinds and SLIP in kinds
        if case == "bouncing bar":
            assert any(i["after"]["not_held"].any() for i in instants)  # rebounds
        return
    if case == "flat landing":
        scene, options = level_ring(), {"rtol": 1e-10, "atol": 1e-13}
    else:
        scene = flexbody.load_scene("thesis_ball")
        options = {"t_end": 1.2}
        if "thesis" in case:
            options.update(impact="thesis", impact_dt=1e-3)
    instants = compiled_instants(monkeypatch, scene, **options)
    model = load_model(scene, backend="c")
    for instant in instants:
        assert_same_as_reference(model, instant)
    # The instants exercised what they should: multiple impacts, releases, lift-offs, windows.
    kinds = [kind for i in instants for _, kind, _ in i["after"]["events"]]
    assert kinds.count(IMPACT) >= 2 and len(kinds) > kinds.count(IMPACT)
    if case == "flat landing":
        assert max(len(i["after"]["events"]) for i in instants) >= 2  # two particles hit at once
    elif "thesis" in case:
        assert any((i["phases"].phase == PUSHED).any() for i in instants)
        assert any((i["after"]["phases"].phase == PUSHED).any() for i in instants)
    else:
        assert any(i["after"]["not_held"].any() for i in instants)


def friction_case(name: str):
    """A scene with friction (and restitution) at its ground."""
    if name == "ball_on_incline":
        return flexbody.load_scene("ball_on_incline")
    points = [[x, 0.0] for x in np.linspace(-0.2, 0.2, 5)]
    return flexbody.load_scene({
        "name": "bar", "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 0.3, "restitution": 0.4}],
        "bodies": [{"name": "bar", "particles": points, "links": [[k, k + 1] for k in range(4)] + [[0, 2], [2, 4]],
                    "mass": 0.05, "stiffness": 3000.0, "damping": 0.2, "position": [0.0, 0.1], "angle": 0.05,
                    "velocity": [1.5, 0.0]}],
        "simulation": {"t_end": 0.6, "output_dt": 1e-3},
    })


def test_the_held_codes_are_the_held_phases_and_nothing_else():
    """``Phases.held`` (the right-hand side's codes) is HELD or SLIDING where a contact is held
    along the normal, 0 where it is free or pushed, as np.intc; ``on_ground`` marks the same."""
    from flexbody.contact import FREE, HELD, SLIDING

    phases = Phases.all_free(8)
    phases.phase[:] = [FREE, HELD, PUSHED, SLIDING, SLIDING, PUSHED, HELD, FREE]
    np.testing.assert_array_equal(phases.held, [0, HELD, 0, SLIDING, SLIDING, 0, HELD, 0])
    assert phases.held.dtype == np.intc
    np.testing.assert_array_equal(phases.on_ground, phases.held != 0)
