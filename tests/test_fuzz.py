"""Hostile scene files: each gets one clear problem per mistake (field, value, rule), never a
traceback, an overflow, a RecursionError or a flood of text."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import flexbody
from flexbody.scene import OverdampedLinkWarning, SceneError, bundled_scenes

from .conftest import body, scene_table

RING = """\
[[bodies]]
shape = "ring"
count = {count}
radius = 0.1
mass = 0.05
stiffness = 2000.0
damping = 0.5
position = [0.0, 0.5]
"""


def problems_in(path) -> list[str]:
    with pytest.raises(SceneError) as info:
        flexbody.load_scene(path)
    return info.value.problems


def problems_of(table) -> list[str]:
    with pytest.raises(SceneError) as info:
        flexbody.load_scene(table)
    return info.value.problems


def write(tmp_path, text: str, name: str = "scene.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def has(problems: list[str], field: str, rule: str) -> bool:
    return any(p.startswith(f"`{field}`") and rule in p for p in problems)


def test_an_integer_too_large_for_a_float_is_a_problem_not_an_overflow(tmp_path):
    text = RING.format(count=8).replace("mass = 0.05", "mass = 1" + "0" * 400) + "[simulation]\nt_end = 1.0\n"
    problems = problems_in(write(tmp_path, text))
    assert has(problems, "bodies[0].mass", "must be a finite number")
    assert all(len(p) < 200 for p in problems), problems  # the 401 digits are abbreviated


@pytest.mark.parametrize("t_end, output_dt", [(1e308, 5e-324), (1e9, 1e-12), (1.0, 2.0)])
def test_output_grids_that_cannot_be_built_are_refused(tmp_path, t_end, output_dt):
    text = RING.format(count=8) + f"[simulation]\nt_end = {t_end!r}\noutput_dt = {output_dt!r}\n"
    problems = problems_in(write(tmp_path, text))
    rule = "must be <= t_end" if output_dt > t_end else "at most 1e+07 are allowed"
    assert has(problems, "simulation.output_dt", rule), problems


@pytest.mark.parametrize("count", ["1000000000000", "1" + "0" * 400])
def test_a_preset_too_large_to_allocate_is_refused(tmp_path, count):
    text = RING.format(count=count) + "[simulation]\nt_end = 1.0\n"
    problems = problems_in(write(tmp_path, text))
    assert has(problems, "bodies[0].count", "at most 1 million particles"), problems
    assert all(len(p) < 200 for p in problems), problems


def test_toml_nested_3000_levels_deep(tmp_path):
    text = RING.format(count=8) + "[simulation]\nt_end = 1.0\n" + "x = " + "[" * 3000 + "]" * 3000 + "\n"
    problems = problems_in(write(tmp_path, text))
    assert problems == ["nested too deeply (arrays or tables inside each other)"]


def test_scene_names_are_limited_and_the_bundled_ones_fit():
    problems = problems_of(scene_table(body(), name="x" * 300))
    assert has(problems, "name", "1 to 64 characters"), problems
    assert has(problems_of(scene_table(body(), name="../../etc")), "name", "1 to 64 characters")
    for name in bundled_scenes():
        assert flexbody.load_scene(name).name == name


def test_a_file_name_that_is_no_valid_scene_name_gives_a_valid_default(tmp_path):
    path = write(tmp_path, RING.format(count=8) + "[simulation]\nt_end = 1.0\n", name="my ball (v2).toml")
    assert flexbody.load_scene(path).name == "my_ball__v2_"


@pytest.mark.parametrize("second, says", [
    ({"point": [0.0, 0.0], "normal": [0.0, 1.0]}, "the same as grounds[0]"),
    ({"point": [5.0, 0.0], "normal": [0.0, 2.0]}, "the same as grounds[0]"),  # same plane, other point and length
    ({"point": [0.0, -1.0], "normal": [0.0, 1.0]}, "parallel to grounds[0] and faces the same way"),
])
def test_duplicate_and_parallel_grounds_are_refused(second, says):
    grounds = [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}, second]
    assert has(problems_of(scene_table(body(), grounds=grounds)), "grounds[1].normal", says)


def test_grounds_that_meet_at_an_angle_are_fine():
    grounds = [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}, {"point": [1.0, 0.0], "normal": [-1.0, 1.0]}]
    assert len(flexbody.load_scene(scene_table(body(), grounds=grounds)).grounds) == 2


@pytest.mark.parametrize("normal, unit", [
    ([1.7e308, 1.7e308], [2 ** -0.5, 2 ** -0.5]),  # the length overflows unless scaled first
    ([5e-324, 0.0], [1.0, 0.0]),  # the length underflows to 0 unless scaled first
    ([0.0, 3.0], [0.0, 1.0]),
])
def test_ground_normals_are_normalised_without_overflow(normal, unit):
    scene = flexbody.load_scene(scene_table(body(), grounds=[{"point": [-10.0, 0.0], "normal": normal}]))
    np.testing.assert_allclose(scene.grounds[0].normal, unit, rtol=1e-15)
    assert np.hypot(*scene.grounds[0].normal) == pytest.approx(1.0, rel=1e-15)


def test_a_body_without_particles_is_one_problem_and_no_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's RuntimeWarnings on empty arrays would raise here
        problems = problems_of(scene_table(body(particles=[], links=[])))
    assert has(problems, "bodies[0].particles", "at least one particle"), problems


def test_a_file_that_is_not_utf8_names_itself(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes('name = "café"\n'.encode("latin-1"))
    with pytest.raises(SceneError) as info:
        flexbody.load_scene(path)
    assert str(path) in str(info.value) and "not UTF-8" in str(info.value)


def test_huge_values_are_not_echoed_whole():
    velocities = [[0.0, 0.0]] * 20_000  # the body has 2 particles: wrong count
    with pytest.raises(SceneError) as info:
        flexbody.load_scene(scene_table(body(particle_velocities=velocities)))
    assert "bodies[0].particle_velocities" in str(info.value)
    assert len(str(info.value)) < 400


def test_a_large_ring_with_one_mistake_is_checked_in_less_than_quadratic_time(tmp_path):
    """20 000 particles: the old pairwise check of coincident points (2e8 Python pairs) took
    over half an hour; sorting takes well under a second.  The timeout only catches a
    quadratic algorithm, it measures nothing."""
    path = write(tmp_path, RING.format(count=20_000).replace("damping = 0.5", "damping = -0.5")
                 + "[simulation]\nt_end = 1.0\n")
    code = f"import flexbody\ntry:\n    flexbody.load_scene({str(path)!r})\nexcept flexbody.SceneError as e:\n    print(e)"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "`bodies[0].damping` = -0.5" in run.stdout, run.stderr


def test_coincident_particles_are_found_by_the_sorted_check():
    problems = problems_of(scene_table(body(particles=[[0.0, 0.0], [0.1, 0.0], [-0.0, 0.0]], links=[[0, 1]])))
    assert has(problems, "bodies[0].particles", "start at the same point"), problems
    assert "[0, 2]" in problems[0]
    square = dict(shape="polygon", vertices=[[0, 0], [1, 0], [1, 0], [0, 1]], particles=None, links=None)
    assert has(problems_of(scene_table(body(**square))), "bodies[0].links[1]", "zero-length link")


@pytest.mark.parametrize("extra, field, shape", [
    ({"shape": "chain", "count": 3, "spacing": 0.1, "radius": 0.2}, "radius", "chain"),
    ({"shape": "ring", "count": 6, "radius": 0.1, "radii": [0.1, 0.2]}, "radii", "ring"),
    ({"shape": "ring", "count": 6, "radius": 0.1, "particles": [[0, 0]], "links": []}, "particles", "ring"),
    ({"shape": "polygon", "vertices": [[0, 0], [1, 0], [0, 1]], "spacing": 0.1}, "spacing", "polygon"),
])
def test_geometry_keys_a_shape_does_not_use_are_errors(extra, field, shape):
    table = body(**dict({"particles": None, "links": None}, **extra))
    assert has(problems_of(scene_table(table)), f"bodies[0].{field}", f'is not used with shape = "{shape}"')


def test_preset_keys_beside_explicit_particles_are_errors():
    assert has(problems_of(scene_table(body(count=3))), "bodies[0].count", "explicit `particles`")


def test_the_overdamped_warning_comes_once_per_body():
    with pytest.warns(OverdampedLinkWarning) as record:
        flexbody.load_scene(scene_table(body(stiffness=1.0, damping=10.0)))
    assert len([w for w in record if w.category is OverdampedLinkWarning]) == 1


def test_impact_dt_without_the_thesis_mode_is_a_problem():
    problems = problems_of(scene_table(body(), simulation={"t_end": 1.0, "impact_dt": 1e-3}))
    assert has(problems, "simulation.impact_dt", 'only used with impact = "thesis"'), problems


def test_a_scene_with_every_check_passing_still_loads(tmp_path):
    text = textwrap.dedent("""\
        name = "ok-scene.v1"
        [[grounds]]
        point = [0.0, 0.0]
        normal = [0.0, 1.0]
        """) + RING.format(count=12) + "[simulation]\nt_end = 1.0\noutput_dt = 1.0\n"
    scene = flexbody.load_scene(write(tmp_path, text))
    assert scene.name == "ok-scene.v1" and scene.n_particles == 12 and scene.simulation.output_dt == 1.0
