"""``flexbody run``: outputs, exit codes, and nothing written on a mistake or a failure."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from flexbody.cli import main

from .conftest import needs_cc


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "flexbody.cli", *args], capture_output=True, text=True)


@needs_cc
@pytest.mark.slow
def test_main_job_writes_result_summary_figures_and_animation(tmp_path):
    out = tmp_path / "ball"
    run = run_cli("run", "thesis_ball", "--out", str(out))
    assert run.returncode == 0, run.stderr
    names = {p.name for p in out.iterdir()}
    assert names == {"result.npz", "summary.json", "fig5_1_free_fall.png", "fig5_2_impact.png",
                     "fig5_3_colliding_points.png", "fig5_4_energy.png", "drop.gif"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "success" and summary["impacts"] == 29 and summary["liftoffs"] == 18
    with np.load(out / "result.npz") as data:
        assert data["positions"].shape == (2001, 23, 2)
    assert (out / "drop.gif").read_bytes()[:6] == b"GIF89a"
    assert "29 impacts" in run.stdout and "%" in run.stderr  # the summary, and progress


def test_no_figures_and_overrides(tmp_path):
    out = tmp_path / "quick"
    assert main(["run", "thesis_ball", "--out", str(out), "--no-figures", "--t-end", "0.3", "--method", "DOP853",
                 "--rtol", "1e-8", "--atol", "1e-11", "--formulation", "floating", "--backend", "numpy", "--quiet"]) == 0
    assert {p.name for p in out.iterdir()} == {"result.npz", "summary.json"}
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["method"], summary["rtol"], summary["formulation"], summary["backend"], summary["t_end"]) == \
        ("DOP853", 1e-8, "floating", "numpy", 0.3)


@pytest.mark.parametrize("args, says", [
    (["no_such_scene"], "bundled scene"),
    (["thesis_ball", "--rtol", "5"], "`rtol` = 5.0"),
    (["thesis_ball", "--t-end", "-1"], "`t_end` = -1.0"),
    (["thesis_ball", "--impact", "thesis"], "`impact_dt`"),
])
def test_bad_input_is_one_clear_error_and_writes_nothing(tmp_path, args, says):
    out = tmp_path / "never"
    run = run_cli("run", *args, "--out", str(out))
    assert run.returncode == 2
    assert run.stderr.startswith("error:") and says in run.stderr and "Traceback" not in run.stderr
    assert not out.exists()


def test_bad_scene_file_lists_every_problem(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text('[[bodies]]\nshape = "ring"\ncount = 0\nmass = -1\n[simulation]\nt_end = 1\n')
    run = run_cli("run", str(scene), "--out", str(tmp_path / "never"))
    assert run.returncode == 2 and "Traceback" not in run.stderr
    for field in ("bodies[0].count", "bodies[0].mass", "bodies[0].radius", "bodies[0].stiffness", "bodies[0].position"):
        assert field in run.stderr
    assert not (tmp_path / "never").exists()


@needs_cc
def test_failed_simulation_exits_nonzero_says_why_and_writes_nothing(tmp_path, monkeypatch):
    import flexbody.runner as runner

    real = runner.simulate
    monkeypatch.setattr(runner, "simulate", lambda *a, **k: real(*a, **k, max_events=3))
    out = tmp_path / "failed"
    assert main(["run", "thesis_ball", "--out", str(out), "--quiet", "--no-figures"]) == 1
    assert not out.exists()


def _rings_scene(path, collide: bool, contacts: str = "", self_contact: bool = False) -> str:
    """Three small rings side by side, ``collide`` as given (and the first's ``self_contact``),
    plus a ``[[contacts]]`` text."""
    bodies = "".join(f"""
[[bodies]]
name = "ring{k}"
shape = "ring"
count = 6
radius = 0.05
mass = 0.05
stiffness = 2000.0
damping = 0.5
position = [{0.2 * k}, 0.1]
collide = {"true" if collide else "false"}
self_contact = {"true" if self_contact and k == 0 else "false"}
""" for k in range(3))
    path.write_text(f'name = "rings"\ngravity = [0.0, -9.81]\n{bodies}{contacts}\n[simulation]\nt_end = 0.01\n')
    return str(path)


def test_a_large_contact_table_of_colliding_bodies_is_noted(tmp_path, monkeypatch, capsys):
    """Bodies with collide = true whose slots exceed the threshold get a note naming their
    count and the way to fewer ([[contacts]]) where the table is laid out whole (here: a
    body with self-contact); a table that grows with the pairs in reach, listed pairs,
    fewer slots or --quiet do not."""
    from flexbody import runner
    from flexbody.model import load_model
    from flexbody.scene import load_scene

    growing = load_scene(_rings_scene(tmp_path / "growing.toml", True))
    monkeypatch.setattr(runner, "LARGE_CONTACT_TABLE", 0)
    assert runner.contact_table_note(growing, load_model(growing)) is None
    assert main(["run", str(tmp_path / "growing.toml"), "--out", str(tmp_path / "g"), "--no-figures", "--quiet"]) == 0
    out, err = capsys.readouterr()
    # neighbours 0.1 m apart are in reach, the outer two (0.3 m) are not
    assert "contacts between bodies: 2 of the scene's 3 pairs had slots" in out and "note:" not in err
    scene = load_scene(_rings_scene(tmp_path / "rings.toml", True, self_contact=True))
    slots = load_model(scene).n_slots
    assert slots == 3 * 6 * 2 * 2 + 6 * 2  # each ring's 6 vertices against 2 others (one also itself), twinned
    monkeypatch.setattr(runner, "LARGE_CONTACT_TABLE", slots - 1)
    assert main(["run", str(tmp_path / "rings.toml"), "--out", str(tmp_path / "a"), "--no-figures"]) == 0
    err = capsys.readouterr().err
    assert f"note: 3 bodies with collide = true make {slots} contact slots" in err and "[[contacts]]" in err
    assert main(["run", str(tmp_path / "rings.toml"), "--out", str(tmp_path / "b"), "--no-figures", "--quiet"]) == 0
    assert "note:" not in capsys.readouterr().err
    monkeypatch.setattr(runner, "LARGE_CONTACT_TABLE", slots)  # not beyond it
    assert runner.contact_table_note(scene, load_model(scene)) is None
    monkeypatch.setattr(runner, "LARGE_CONTACT_TABLE", 0)
    listed = load_scene(_rings_scene(tmp_path / "listed.toml", False,
                                     '\n[[contacts]]\nbodies = ["ring0", "ring1"]\n'))
    assert runner.contact_table_note(listed, load_model(listed)) is None


def test_a_formulation_asked_for_and_not_run_is_noted(tmp_path, capsys):
    """A scene of rigid bodies alone runs on its frames T whichever formulation is asked for
    (a helper asked for particles and was not told)."""
    assert main(["run", "rigid_bar", "--formulation", "particles", "--out", str(tmp_path / "a"), "--no-figures"]) == 0
    assert "note: `--formulation particles`: a scene of rigid bodies alone runs on their frames T" \
        in capsys.readouterr().err
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["formulation"] == "floating"
    assert main(["run", "rigid_bar", "--formulation", "floating", "--out", str(tmp_path / "b"), "--no-figures"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_the_progress_line_goes_to_standard_error_as_it_is_when_the_run_starts(monkeypatch):
    """The bar's stream was bound when flexbody.progress was first imported: imported inside
    a test that captured standard error, every later run wrote to that capture, closed by
    then ("I/O operation on closed file": test_cli_run failed after test_scene_multibody)."""
    import io

    from flexbody.progress import ProgressBar

    now = io.StringIO()
    monkeypatch.setattr(sys, "stderr", now)
    bar = ProgressBar()
    bar(1.0, 1.0, 3)
    assert "100.0%" in now.getvalue() and "events 3" in now.getvalue()
