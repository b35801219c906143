"""The command line's failures: clear and early (exit 2 for a mistake, 1 for a failure or a
bug), nothing written, and no process left behind."""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from flexbody.cli import BUG, main
from flexbody.errors import InputError
from flexbody.paths import check_output_dir, staged_folder

DUMBBELL = ["dumbbell", "--t-end", "0.05", "--no-figures", "--quiet"]


def run_cli(*args, cwd=None, env=None, timeout=300):
    return subprocess.run([sys.executable, "-m", "flexbody.cli", *args], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=timeout)


def one_error_line(stderr: str, says: str) -> None:
    """Exactly one line, ``error: ...``, containing ``says``; no traceback."""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and says in lines[0], stderr


def listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


# ----------------------------------------------------------------- the output folder, before any work


def test_out_below_an_existing_file(tmp_path):
    (tmp_path / "existing_file.txt").write_text("keep")
    run = run_cli("run", *DUMBBELL, "--out", str(tmp_path / "existing_file.txt" / "sub"))
    assert run.returncode == 2
    one_error_line(run.stderr, "existing_file.txt is a file, not a folder")
    assert listing(tmp_path) == {"existing_file.txt"} and (tmp_path / "existing_file.txt").read_text() == "keep"


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc (Linux)")
def test_out_where_no_folder_can_be_made():
    run = run_cli("run", *DUMBBELL, "--out", "/proc/x")
    assert run.returncode == 2
    one_error_line(run.stderr, "cannot create a folder in /proc")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only folder")
def test_out_in_a_read_only_folder(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        run = run_cli("run", *DUMBBELL, "--out", str(locked / "out"))
    finally:
        locked.chmod(0o755)
    assert run.returncode == 2
    one_error_line(run.stderr, "cannot create a folder in")
    assert listing(locked) == set()


def test_out_on_a_read_only_file_system(tmp_path, monkeypatch):
    """As root (CI) no folder is read-only by its mode: stand in the error a read-only mount gives."""
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))

    monkeypatch.setattr(tempfile, "mkdtemp", read_only)
    with pytest.raises(InputError, match="cannot create a folder in .*Read-only file system"):
        check_output_dir(str(tmp_path / "out"))


@pytest.mark.parametrize("out, says", [("", "is empty"), (".", "is the current folder"), ("..", "its parents")])
def test_out_empty_or_the_current_folder(tmp_path, out, says):
    (tmp_path / "mine.txt").write_text("keep")
    run = run_cli("run", *DUMBBELL, "--out", out, cwd=tmp_path)
    assert run.returncode == 2
    one_error_line(run.stderr, says)
    assert listing(tmp_path) == {"mine.txt"}


def test_out_a_folder_of_other_files_is_not_replaced(tmp_path):
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "thesis.tex").write_text("keep")
    run = run_cli("run", *DUMBBELL, "--out", str(tmp_path / "notes"))
    assert run.returncode == 2
    one_error_line(run.stderr, "no previous result")
    assert listing(tmp_path) == {"notes", "notes/thesis.tex"}


def test_rerun_replaces_the_previous_result_whole(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("summary.json", "result.npz", "fig5_1_free_fall.png", "drop.gif"):  # an earlier run with figures
        (out / name).write_text("old")
    assert main(["run", *DUMBBELL, "--out", str(out)]) == 0
    assert listing(out) == {"result.npz", "summary.json"}
    assert json.loads((out / "summary.json").read_text())["t_end"] == 0.05
    assert listing(tmp_path) == {"out", "out/result.npz", "out/summary.json"}  # no staging folder left


def test_staged_folder_leaves_the_old_folder_when_writing_fails(tmp_path):
    target = tmp_path / "result"
    target.mkdir()
    (target / "summary.json").write_text("old")
    with pytest.raises(RuntimeError), staged_folder(target) as staging:
        (staging / "result.npz").write_text("new")
        raise RuntimeError("crash between the two files")
    assert listing(tmp_path) == {"result", "result/summary.json"}
    assert (target / "summary.json").read_text() == "old"
    with staged_folder(target) as staging:
        (staging / "summary.json").write_text("new")
    assert listing(tmp_path) == {"result", "result/summary.json"}
    assert (target / "summary.json").read_text() == "new"


# ----------------------------------------------------------------- options: one rule, one message


@pytest.mark.parametrize("options, says", [
    (["--impact-dt", "1e-3"], "`impact_dt` = 0.001: is only used with impact = \"thesis\""),
    (["--impact-dt", "0"], "`impact_dt` = 0.0"),
    (["--impact-dt", "-1"], "`impact_dt` = -1.0"),
    (["--impact-dt", "nan"], "`impact_dt` = nan"),
    (["--impact", "thesis", "--impact-dt", "inf"], "`impact_dt` = inf: must be a finite number > 0"),
    (["--rtol", "-1e-6"], "`rtol` = -1e-06: must be in [1e-14, 1)"),
    (["--chatter-impacts", "-3"], "`chatter_impacts` = -3: must be an integer >= 1"),
    (["--rtol=-1e-6"], "`rtol` = -1e-06: must be in [1e-14, 1)"),
    (["--atol", "-1"], "`atol` = -1.0: must be in (0, 1)"),
    (["--t-end", "-2"], "`t_end` = -2.0"),
    (["--t-end", "inf"], "`t_end` = inf"),
    (["--t-end", "1", "--output-dt", "5"], "`output_dt` = 5.0: must be <= t_end"),
    (["--t-end", "1e12"], "at most 1e+07 are allowed"),
    (["--max-wall-time", "0"], "`--max-wall-time` = 0.0"),
    (["--max-wall-time", "-5"], "`--max-wall-time` = -5.0"),
    (["--max-wall-time", "nan"], "`--max-wall-time` = nan"),
])
def test_bad_options_exit_2_before_any_work(tmp_path, capsys, options, says):
    out = tmp_path / "never"
    assert main(["run", "dumbbell", "--out", str(out), *options]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and says in err and "Traceback" not in err, err
    assert not out.exists()


def test_argument_errors_are_argparse_errors_with_exit_2(tmp_path):
    run = run_cli("run", "dumbbell", "--out", str(tmp_path / "o"), "--method", "Euler")
    assert run.returncode == 2 and "invalid choice: 'Euler'" in run.stderr and "Traceback" not in run.stderr


def test_help_and_argument_errors_import_no_numerical_package():
    code = ("import sys\nfrom flexbody.cli import main\n"
            "for argv in (['--help'], ['run', '--help'], ['run', 'x', '--out', 'o', '--method', 'Euler']):\n"
            "    try:\n        main(argv)\n    except SystemExit:\n        pass\n"
            "print([m for m in ('numpy', 'scipy', 'matplotlib', 'sympy') if m in sys.modules])")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.stdout.strip().splitlines()[-1] == "[]", run.stdout + run.stderr


# ----------------------------------------------------------------- failures and bugs


def test_an_internal_error_is_a_bug_not_a_user_mistake(tmp_path, monkeypatch, capsys):
    import flexbody.runner as runner

    def broken(*args, **kwargs):
        raise ValueError("an internal ValueError")  # once mapped to exit 2, "your mistake"

    monkeypatch.setattr(runner, "simulate", broken)
    out = tmp_path / "never"
    assert main(["run", *DUMBBELL, "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "an internal ValueError" in err and err.strip().endswith(BUG)
    assert not out.exists()


def test_a_stiffness_the_integrator_cannot_step_ends_too_slow(tmp_path):
    """stiffness = 1e20: the compiled integrator takes ~1e-11 s steps inside one C call; it
    checks the wall-time budget itself, so --max-wall-time ends the run, with exit 1; the
    message counts its steps (their mean length says: tiny) and events."""
    scene = tmp_path / "stiff.toml"
    bundled = Path(__file__).parents[1] / "src" / "flexbody" / "scenes" / "thesis_ball.toml"
    scene.write_text(bundled.read_text().replace("stiffness = 2000.0", "stiffness = 1e20"))
    out = tmp_path / "never"
    run = run_cli("run", str(scene), "--out", str(out), "--no-figures", "--quiet", "--max-wall-time", "2", timeout=120)
    assert run.returncode == 1, run.stderr
    assert "simulation failed (too_slow)" in run.stderr and "Traceback" not in run.stderr
    steps, mean = re.search(r"\((\d+) steps, ([0-9.e+-]+) s each on average, and \d+ events\)", run.stderr).groups()
    assert int(steps) > 1000 and float(mean) < 1e-6
    assert not out.exists()


def test_the_overdamped_warning_is_printed_once(tmp_path):
    scene = tmp_path / "creep.toml"
    bundled = Path(__file__).parents[1] / "src" / "flexbody" / "scenes" / "dumbbell.toml"
    scene.write_text(bundled.read_text().replace("stiffness = 2000.0", "stiffness = 1.0").replace(
        "damping = 0.5", "damping = 10.0"))
    run = run_cli("run", str(scene), "--out", str(tmp_path / "o"), "--t-end", "0.05", "--no-figures", "--quiet")
    assert run.returncode == 0, run.stderr
    assert run.stderr.count("not underdamped") == 1 and run.stderr.startswith("warning: "), run.stderr


def test_derive_check_of_a_users_scene_says_where_its_model_lives(tmp_path):
    scene = tmp_path / "mine.toml"
    bundled = Path(__file__).parents[1] / "src" / "flexbody" / "scenes" / "dumbbell.toml"
    scene.write_text(bundled.read_text().replace('name = "dumbbell"', 'name = "mine"'))
    run = run_cli("derive", str(scene), "--check")
    assert run.returncode == 0, run.stderr
    assert "not a bundled scene" in run.stdout and "cache" in run.stdout and "--out DIR" in run.stdout
    assert "regenerate" not in run.stdout + run.stderr


# ----------------------------------------------------------------- no orphan derivation


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc; PR_SET_DEATHSIG is Linux's")
def test_killing_run_while_it_derives_ends_the_derivation(tmp_path):
    """A never-seen topology in the floating formulation (the only one derived per scene; a
    fresh, empty cache) is derived in a child; SIGKILL the parent (no finally runs) and the
    child must go at once, not when its derivation (minutes for this 30-particle ring)
    would have ended."""
    scene = tmp_path / "ring.toml"
    scene.write_text('[[bodies]]\nshape = "ring"\ncount = 30\nradius = 0.1\nmass = 0.05\nstiffness = 2000.0\n'
                     'damping = 0.5\nposition = [0.0, 0.5]\n[simulation]\nt_end = 0.1\n')
    env = dict(os.environ, FLEXBODY_CACHE=str(tmp_path / "cache"))
    parent = subprocess.Popen([sys.executable, "-m", "flexbody.cli", "run", str(scene), "--out", str(tmp_path / "o"),
                               "--formulation", "floating"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    children: list[int] = []
    try:
        deadline = time.monotonic() + 60
        while not children and time.monotonic() < deadline and parent.poll() is None:
            time.sleep(0.05)
            children = _children(parent.pid)
        assert children, "the derivation child never started"
        time.sleep(0.5)  # let the child pass its launcher (it asks for the death signal first)
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 5
        while any(map(_alive, children)) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not any(map(_alive, children)), "the derivation outlived flexbody run"
        said = parent.stderr.read()
        assert "deriving the equations of ring (30 particles, formulation floating) with SymPy" in said, said
    finally:
        parent.kill()
        for pid in filter(_alive, children):  # an orphan is no longer our child: kill it by its id
            os.kill(pid, signal.SIGKILL)
