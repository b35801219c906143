"""``flexbody sweep``: designs, validation, rows equal to single runs, failures, resume, shutdown.

Needs the sweep extra (Dask, pandas, pyarrow); skipped without it.  Clusters here have
1-2 workers and a handful of runs of a two-particle body.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")
psutil = pytest.importorskip("psutil")

from flexbody.cli import main  # noqa: E402
from flexbody.result import SimulationResult, load_result  # noqa: E402
from flexbody.sweep import (  # noqa: E402
    OBSERVABLES,
    SweepError,
    _locate,
    design_points,
    observables,
    parse_axis,
    run_one,
    sweep,
)

from .conftest import HAS_CC  # noqa: E402

pytestmark = pytest.mark.skipif(not HAS_CC, reason="the sweep runs the compiled C backend")

#: A two-particle body, tilted so one particle lands first.  {k}, {c}: its stiffness and damping.
TINY = """
name = "tiny"
[[bodies]]
name = "b"
particles = [[-0.1, 0.0], [0.1, 0.0]]
links = [[0, 1]]
mass = 0.05
stiffness = {k!r}
damping = {c!r}
position = [0.0, 0.3]
angle = 0.3
[simulation]
t_end = {t_end!r}
rtol = {rtol!r}
"""


def tiny(tmp_path, k=2000.0, c=0.5, t_end=1.0, rtol=1e-6, name="tiny.toml"):
    path = tmp_path / name
    path.write_text(TINY.format(k=k, c=c, t_end=t_end, rtol=rtol))
    return path


def same(a, b) -> bool:
    """Bit for bit, NaN equal to NaN."""
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def our_children() -> dict[int, psutil.Process]:
    """This process's descendants, without multiprocessing's resource tracker (it lives as long as we do)."""
    children = {}
    for p in psutil.Process().children(recursive=True):
        with contextlib.suppress(psutil.Error):
            if "resource_tracker" not in " ".join(p.cmdline()):
                children[p.pid] = p
    return children


def assert_no_new_children(before: dict[int, psutil.Process]) -> None:
    """Every process started since ``before`` has ended (allowing a moment for it to be reaped)."""
    new = [p for pid, p in our_children().items() if pid not in before]
    _, alive = psutil.wait_procs(new, timeout=10)
    assert not alive, [(p.pid, p.cmdline()) for p in alive]


# ------------------------------------------------------------------------- designs and fields


def test_specs_lists_ranges_and_log_ranges():
    assert parse_axis("f", "1e3,1e4,22,true,dopri5").values == (1000.0, 10000.0, 22, True, "dopri5")
    assert parse_axis("f", "1:3:5").values == (1.0, 1.5, 2.0, 2.5, 3.0)
    assert np.allclose(parse_axis("f", "1e3:1e5:3:log").values, [1e3, 1e4, 1e5], rtol=1e-15)
    grid = design_points([parse_axis("a", "1,2"), parse_axis("b", "x,y,z")])
    assert grid == [(1, "x"), (1, "y"), (1, "z"), (2, "x"), (2, "y"), (2, "z")]


@pytest.mark.parametrize("design", ["lhs", "sobol"])
def test_sampled_designs_stay_in_their_ranges_and_spread_out(design):
    axes = [parse_axis("k", "1e2:1e6:log", design), parse_axis("c", "0:2", design)]
    points = np.array(design_points(axes, design, samples=16, seed=3))
    assert points.shape == (16, 2)
    assert (points[:, 0] >= 1e2).all() and (points[:, 0] <= 1e6).all()
    assert (points[:, 1] >= 0).all() and (points[:, 1] <= 2).all()
    # Both designs put exactly one point in each of 16 equal strata per coordinate
    # (the log axis stratified in log space); a plain random sample almost never does.
    unit = np.column_stack([(np.log10(points[:, 0]) - 2) / 4, points[:, 1] / 2])
    for column in unit.T:
        assert sorted(np.floor(16 * column).astype(int)) == list(range(16))
    assert np.array_equal(points, design_points(axes, design, samples=16, seed=3))  # seeded: reproducible


def test_dotted_paths_by_name_index_and_vector_component():
    table = {"bodies": [{"name": "ball", "position": [0.0, 0.5]}], "simulation": {"t_end": 1.0}}
    assert _locate(table, "bodies.ball.position.1") == (table["bodies"][0]["position"], 1)
    assert _locate(table, "bodies.0.stiffness") == (table["bodies"][0], "stiffness")
    assert _locate(table, "simulation.rtol") == (table["simulation"], "rtol")


# ------------------------------------------------------------------------- one clear error


@pytest.mark.parametrize("vary, says", [
    (["bodies.ball2.stiffness=1,2"], "no element named 'ball2'"),
    (["bodies.3.stiffness=1,2"], "has 1 element(s), no index 3"),
    (["bodies.ball.position.7=1"], "no index 7"),
    (["bodies.0.stiffness=1e3,-5"], "`bodies[0].stiffness` = -5"),
    (["grounds.0.friction=0.1,-0.2"], "`grounds[0].friction` = -0.2"),
    (["simulation.rtol=1e-6,5"], "`simulation.rtol` = 5"),
    (["simulation.backend=numpy"], "`method` = 'dopri5'"),
    (["bodies.ball.stiffness=1e3:1e5"], "needs --samples N"),
    (["bodies.ball.stiffness=1e3:x:3"], "'x' is not a finite number"),
    (["bodies.ball.stiffness=0:1e5:4:log"], "log range needs bounds > 0"),
    (["bodies.ball.stiffness"], "write FIELD=SPEC"),
    (["bodies.ball.stiffness=1,2", "--samples", "8"], "needs `--design lhs`"),
    (["bodies.ball.stiffness=1,2", "--max-wall-time", "0"], "`--max-wall-time` = 0.0"),
    (["bodies.ball.stiffness=1,2", "--workers", "0"], "`--workers` = 0: must be >= 1"),
])
def test_bad_field_or_value_is_one_clear_error_and_writes_nothing(tmp_path, capsys, vary, says):
    out = tmp_path / "never"
    args = ["sweep", "thesis_ball", "--out", str(out), "--vary", vary[0], *vary[1:]]
    if "simulation.backend=numpy" in vary:
        args += ["--vary", "simulation.method=dopri5"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and says in err and "Traceback" not in err, err
    assert not out.exists()


def test_every_invalid_run_is_named_in_the_one_error(tmp_path):
    with pytest.raises(SweepError) as caught:
        sweep(tiny(tmp_path), {"bodies.b.stiffness": [-1.0, 2e3, -3.0], "bodies.b.mass": [0.05, 0.0]}, tmp_path / "x")
    text = str(caught.value)
    assert text.startswith("5 of 6 varied scenes are invalid")  # all but (2e3, 0.05)
    assert "run 0 (bodies.b.stiffness=-1.0, bodies.b.mass=0.05)" in text and "run 5 " in text
    assert "run 2 " not in text
    assert not (tmp_path / "x").exists()


# ------------------------------------------------------------------------- observables


def test_contact_observables_from_events():
    """Hand-made events: co-timed impacts are taken together; the contact ends when nobody is held."""
    t = np.linspace(0.0, 3.0, 7)  # 0, 0.5, ..., 3
    heights = np.array([1.0, 0.5, 0.1, 0.2, 0.7, 0.9, 0.4])
    positions = np.stack([np.zeros((7, 2)), np.zeros((7, 2))], axis=1)
    positions[:, :, 1] = heights[:, None]
    force = np.zeros((7, 2))
    force[2, 0], force[3] = 3.0, [1.0, 1.5]
    result = SimulationResult(
        t=t, positions=positions, velocities=np.zeros_like(positions), contact_force=force,
        kinetic=np.zeros(7), spring=np.zeros(7), gravity=np.zeros(7), damping_work=np.zeros(7), impact_loss=np.zeros(7),
        events_time=np.array([1.0, 1.0, 1.25, 1.75, 2.0, 2.9]),
        events_particle=np.array([0, 1, 1, 1, 0, 0]),
        events_kind=np.array(["impact", "impact", "liftoff", "impact", "liftoff", "impact"]),
        events_held=np.array([False, True, True, False, True, True]),
        masses=np.array([1.0, 3.0]), links=np.zeros((0, 2), int),
        stats={"impacts": 4, "liftoffs": 2, "max_penetration_m": 0.0, "energy_drift_relative": 0.0,
               "wall_time_s": 0.0, "rhs_evaluations": 1},
    )
    # At t = 1 particle 0's impact is not held but particle 1's, at the same instant, is; particle 1
    # lifts off at 1.25 and nobody is held: the first contact lasts 0.25 s.
    row = observables(result, gravity=(0.0, -9.81))
    assert row["first_contact_duration_s"] == 0.25
    assert row["rebound_height_m"] == 0.9  # the highest sample at or after t = 1.25
    assert row["peak_contact_force_N"] == 3.0
    assert (row["impacts"], row["liftoffs"], row["status"]) == (4, 2, "success")


def test_a_body_landing_flat_rests_on_its_weight():
    """Two particles landing flat together stop (plastic impacts) and stay: the ground carries the
    whole weight, sum lambda = (m1 + m2) g, and the body never leaves."""
    scene = {"bodies": [{"name": "bar", "particles": [[-0.05, 0.0], [0.05, 0.0]], "links": [[0, 1]],
                         "masses": [0.2, 0.3], "stiffness": 100.0, "damping": 1.0, "position": [0.0, 0.2]}],
             "simulation": {"t_end": 0.5}}
    row = run_one(0, scene)
    assert row["status"] == "success" and row["impacts"] == 2 and row["liftoffs"] == 0
    assert row["peak_contact_force_N"] == pytest.approx(0.5 * 9.81, rel=1e-12)
    assert math.isnan(row["first_contact_duration_s"]) and math.isnan(row["rebound_height_m"])


def test_a_run_that_raises_is_a_row(monkeypatch):
    import flexbody.sweep as sweep_module

    def broken(*args, **kwargs):
        raise RuntimeError("deliberately broken")

    monkeypatch.setattr(sweep_module, "simulate", broken)
    row = run_one(7, {"bodies": [{"name": "b", "particles": [[0.0, 0.0], [0.1, 0.0]], "links": [[0, 1]], "mass": 0.1,
                                  "stiffness": 10.0, "damping": 0.0, "position": [0.0, 1.0]}],
                      "simulation": {"t_end": 1.0}})
    assert row["run"] == 7 and row["status"] == "error"
    assert row["message"] == "RuntimeError: deliberately broken"
    assert all(math.isnan(row[key]) for key in OBSERVABLES)


def test_a_runs_cpu_is_its_own_threads_not_the_process(tmp_path):
    """task_cpu_s counts the thread that ran the run: a second thread burning CPU meanwhile (as a
    worker's event loop or a second worker thread would) is not in it, but is in the process's CPU."""
    import threading

    from flexbody.sweep import _model_for
    from flexbody.scene import load_scene

    scene = load_scene(tiny(tmp_path, t_end=30.0, rtol=1e-10))
    _model_for(scene)
    stop, burnt = threading.Event(), []

    def burn():
        start = time.thread_time()
        while not stop.is_set():
            sum(range(1000))
        burnt.append(time.thread_time() - start)

    process = time.process_time()
    burner = threading.Thread(target=burn)
    burner.start()
    row = run_one(0, scene)
    stop.set()
    burner.join()
    process = time.process_time() - process
    assert row["status"] == "success"
    # The two threads share the GIL, so the burner got a good part of the CPU: the row must not hold it.
    assert burnt[0] > 0.2 * process
    assert row["task_cpu_s"] <= 1.1 * (process - burnt[0]) + 0.005


def test_the_local_workers_start_without_dasks_malloc_trim_setting(monkeypatch):
    """Dask's nannies set MALLOC_TRIM_THRESHOLD_=65536 in the workers (and in this process's
    environment), which makes glibc mmap every array >= 128 KiB afresh: ~1800 page faults per
    thesis-ball run.  Our LocalCluster starts its workers without it."""
    from flexbody.sweep import _Engine

    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    with _Engine(None, 1) as client:
        assert list(client.run(os.environ.get, "MALLOC_TRIM_THRESHOLD_").values()) == [None]
    assert "MALLOC_TRIM_THRESHOLD_" not in os.environ


# ------------------------------------------------------------------------- on a cluster


def test_rows_equal_single_runs_failed_runs_are_rows_and_the_cluster_is_shut_down(tmp_path):
    """Grid k x c on 2 workers: each successful row equals `flexbody run` of the same scene, bit for
    bit; the stiffest undamped run fails (an accumulation of impacts) and is a row; no worker outlives it."""
    before = our_children()
    out = tmp_path / "sweep"
    stiffness, damping = [1e3, 1e5, 1e10], [0.0, 0.5]
    frame = sweep(tiny(tmp_path), {"bodies.b.stiffness": stiffness, "bodies.b.damping": damping}, out,
                  workers=2, batch=1, progress=False)
    assert_no_new_children(before)
    assert list(frame["run"]) == list(range(6))
    assert list(zip(frame["bodies.b.stiffness"], frame["bodies.b.damping"])) == \
        [(k, c) for k in stiffness for c in damping]
    # At 1e10 N/m the nearly rigid bar lands in cascades of impacts of its particles. Undamped,
    # one particle is held and released again more than 25 times within 1 ms: chattering, a
    # failed row. Damped (ratio 2e-5), its cascades end held and it runs on.
    stiff = (frame["bodies.b.stiffness"] == 1e10) & (frame["bodies.b.damping"] == 0.0)
    assert (frame.loc[stiff, "status"] == "chattering").all()
    assert frame.loc[stiff, "message"].str.contains("held and released again 26 times").all()
    assert frame.loc[stiff, "first_contact_duration_s"].isna().all()
    assert (frame.loc[~stiff, "status"] == "success").all()
    # Every worker loaded the model once, for its first run.
    for _, runs in frame.groupby("worker"):
        assert (runs["model_load_s"] > 0).sum() == 1
    for row in frame[~stiff].to_dict("records"):
        single = tmp_path / f"run{row['run']}"
        scene = tiny(tmp_path, k=row["bodies.b.stiffness"], c=row["bodies.b.damping"], name=f"s{row['run']}.toml")
        assert main(["run", str(scene), "--out", str(single), "--no-figures", "--quiet"]) == 0
        summary = json.loads((single / "summary.json").read_text())
        for key in ("impacts", "liftoffs", "max_penetration_m", "energy_drift_relative", "rhs_evaluations"):
            assert row[key] == summary[key], key
        expected = observables(load_result(single), (0.0, -9.81))
        for key in OBSERVABLES:
            if key != "wall_time_s":
                assert same(row[key], expected[key]), key
    # The same rows on disk: Parquet exactly, CSV to the last digit; one picture per observable.
    assert pd.read_parquet(out / "sweep.parquet").equals(frame)
    csv = pd.read_csv(out / "sweep.csv")
    for key in OBSERVABLES:
        assert all(same(float(a), float(b)) for a, b in zip(csv[key], frame[key].astype(float)))
    info = json.loads((out / "sweep.json").read_text())
    assert info["design"]["points"] == [[k, c] for k in stiffness for c in damping]
    assert info["counts"] == {"success": 5, "chattering": 1} and info["finished"]
    assert {p.name for p in out.glob("*.png")} == {f"{key}.png" for key in OBSERVABLES}
    # The folder holds a sweep now: a second one there is refused, nothing changes.
    with pytest.raises(SweepError, match="already holds a sweep"):
        sweep(tiny(tmp_path), {"bodies.b.stiffness": stiffness}, out, workers=1, progress=False)
    # Nor does a sweep go into a folder of other files (tmp_path holds the scenes): nothing written there.
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(SweepError, match="holds other files"):
        sweep(tiny(tmp_path), {"bodies.b.stiffness": stiffness}, tmp_path, workers=1, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_the_cluster_is_shut_down_when_the_sweep_fails(tmp_path, monkeypatch):
    import flexbody.sweep as sweep_module

    def fail(self, rows):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(sweep_module._RowLog, "add", fail)
    before = our_children()
    with pytest.raises(OSError, match="disk full"):
        sweep(tiny(tmp_path), {"bodies.b.stiffness": [1e3, 2e3, 3e3]}, tmp_path / "out", workers=1, progress=False)
    assert_no_new_children(before)


def test_ctrl_c_stops_the_workers_keeps_finished_rows_and_resume_runs_only_the_rest(tmp_path):
    scene = tiny(tmp_path, t_end=8.0, rtol=1e-9)
    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "flexbody.cli", "sweep", str(scene), "--vary", "bodies.b.stiffness=1e3:1e4:24",
               "--out", str(out), "--workers", "1", "--batch", "1", "--no-figures", "--quiet"]
    # as from a terminal: a test run started in the background inherits SIGINT ignored (the
    # shell's rule for background jobs), and Python then never raises KeyboardInterrupt
    sweep_run = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 start_new_session=True,
                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    parent = psutil.Process(sweep_run.pid)
    children: dict[int, tuple[psutil.Process, str]] = {}
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        for child in parent.children(recursive=True):
            # read again at every look: a child caught between fork and exec still shows
            # its parent's command line (read once, the worker was missed: a flaky failure)
            with contextlib.suppress(psutil.Error):
                children[child.pid] = (child, " ".join(child.cmdline()))
        csv = out / "sweep.csv"
        if csv.exists() and len(csv.read_text().splitlines()) >= 4:  # header + 3 rows
            break
        time.sleep(0.05)
    else:
        pytest.fail("the sweep wrote no rows")
    os.killpg(sweep_run.pid, signal.SIGINT)  # as a terminal's Ctrl-C: to every process of the sweep
    _, err = sweep_run.communicate(timeout=60)
    assert sweep_run.returncode == 130 and "--resume" in err, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err  # the workers leave it to the client
    assert any("spawn_main" in command for _, command in children.values())  # we saw the worker
    # No child outlives the sweep by more than a moment (multiprocessing's resource tracker, for one,
    # ends only when it sees its parent gone).
    _, alive = psutil.wait_procs([p for p, _ in children.values()], timeout=10)
    stray = [(p.pid, p.status(), children[p.pid][1]) for p in alive if p.status() != psutil.STATUS_ZOMBIE]
    assert not stray, stray
    first = pd.read_parquet(out / "sweep.parquet")
    assert 3 <= len(first) < 24 and first["status"].eq("success").all()
    assert pd.read_csv(out / "sweep.csv")["run"].tolist() == first["run"].tolist()
    assert json.loads((out / "sweep.json").read_text())["finished"] is None
    # A half-written last line (a kill mid-write) is dropped, its run done again.
    with open(out / "sweep.csv", "a") as f:
        f.write("23,10000.0,0.0")
    frame = sweep(scene, ["bodies.b.stiffness=1e3:1e4:24"], out, workers=1, resume=True, figures=False,
                  progress=False)
    assert list(frame["run"]) == list(range(24))
    kept = frame[frame["run"].isin(first["run"])].reset_index(drop=True)
    assert kept.equals(first)  # the finished rows stay as they were, not run again
    new_workers = set(frame.loc[~frame["run"].isin(first["run"]), "worker"])
    assert new_workers.isdisjoint(set(first["worker"]))  # the rest ran on the new cluster
    with pytest.raises(SweepError, match="differ"):
        sweep(scene, ["bodies.b.stiffness=1e3:1e4:25"], out, workers=1, resume=True, progress=False)


def test_a_failed_task_is_rows_and_resume_runs_them_again(tmp_path, monkeypatch):
    """When the task itself fails on the worker (here: a function that takes no such arguments,
    as a lost worker would fail it), its runs are rows with status error; resume retries them."""
    import flexbody.sweep as sweep_module

    monkeypatch.setattr(sweep_module, "run_batch", math.sqrt)
    out = tmp_path / "out"
    frame = sweep(tiny(tmp_path), {"bodies.b.stiffness": [1e3, 2e3]}, out, workers=1, figures=False, progress=False)
    assert frame["status"].tolist() == ["error", "error"]
    assert frame["message"].str.startswith("TypeError:").all()
    monkeypatch.undo()
    frame = sweep(tiny(tmp_path), {"bodies.b.stiffness": [1e3, 2e3]}, out, workers=1, resume=True, figures=False,
                  progress=False)
    assert frame["status"].tolist() == ["success", "success"]


def test_a_worker_reuses_a_model_only_for_scenes_that_make_the_same_model():
    """A model keeps what it takes from its scene when it is made (the contact laws, the
    masses, where bodies may touch their initial places): a worker's second scene with another
    ground friction gets its own model and the run a fresh model gives (keyed on the topology
    alone it ran with the first scene's friction: 1.05 m off, friction work 1.22 J for 0.057 J);
    the same scene again reuses it."""
    import tomllib

    import flexbody
    from flexbody.scene import load_scene, resolve_scene_path
    from flexbody.sweep import _model_for

    table = tomllib.loads(resolve_scene_path("ball_on_incline").read_text())

    def with_friction(mu):
        return load_scene(dict(table, grounds=[dict(table["grounds"][0], friction=mu)] + table["grounds"][1:]))

    first, _ = _model_for(with_friction(0.1))
    second, _ = _model_for(with_friction(0.9))
    assert second is not first and _model_for(with_friction(0.9))[0] is second
    reused, fresh = flexbody.simulate(with_friction(0.9), model=second), flexbody.simulate(with_friction(0.9))
    np.testing.assert_array_equal(reused.positions, fresh.positions)
    assert reused.friction_work[-1] == fresh.friction_work[-1]
