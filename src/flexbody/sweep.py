"""Parameter studies: many variations of one scene, each run as an independent Dask task.

A sweep varies fields of a scene, named by dotted paths into its TOML table
(``bodies.ball.stiffness``, ``bodies.0.damping``, ``simulation.rtol``,
``bodies.ball.position.1``), over a grid (every combination of value lists and ranges) or
a quasi-random design (Latin hypercube or scrambled Sobol points, ``scipy.stats.qmc``).

* Every varied scene is validated before anything runs: one bad value is one error for
  the whole sweep (:class:`SweepError`), and nothing is written.
* The runs go to a Dask ``distributed`` cluster: a ``LocalCluster`` with one
  single-threaded worker process per core by default, or an existing scheduler by
  address.  Each worker process loads a compiled model once per topology and reuses it.
* A run that fails (its status is not ``success``, or it raised) is a row with its status
  and message, never the end of the sweep.
* Rows are appended to ``DIR/sweep.csv`` as they arrive (an interrupted sweep keeps what
  finished; ``resume=True`` skips those runs); ``DIR/sweep.parquet`` is rewritten from
  them every few seconds and at the end, sorted by run.  ``DIR/sweep.json`` records the
  command, the versions and the design.

The result is a pandas ``DataFrame``: its rows mix floats, counts and text (status,
message, paths), it is what Parquet (pyarrow) reads and writes, and it is what users of
Dask already hold.  NumPy structured arrays would need fixed-width strings and a
hand-written Parquet bridge.
"""

from __future__ import annotations

import copy
import csv
import itertools
import json
import math
import os
import platform
import socket
import sys
import time
import tomllib
import warnings
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .errors import InputError
from .driver import _settings, simulate
from .model import Model, load_model, made_for
from .result import SimulationResult
from .scene import (
    OverdampedLinkWarning,
    Scene,
    SceneError,
    load_scene,
    resolve_scene_path,
)

DESIGNS = ("grid", "lhs", "sobol")
#: Observables of each run, in column order, with their meaning (DIR/sweep.json repeats it).
OBSERVABLES = {
    "rebound_height_m": "highest centre-of-mass height (against gravity) after the first contact ends",
    "peak_contact_force_N": "largest total normal contact force over the output samples",
    "first_contact_duration_s": "from the first impact to the first instant no particle is held",
    "impacts": "number of impacts",
    "liftoffs": "number of lift-offs",
    "max_penetration_m": "deepest gap below a ground",
    "energy_drift_relative": "largest change of the energy ledger's sum, relative to the initial energy",
    "wall_time_s": "integration wall time of the run",
    "rhs_evaluations": "right-hand-side evaluations",
}
COUNTS = ("impacts", "liftoffs", "rhs_evaluations")
#: Per-run columns after the observables: outcome, where and how it ran.
TAIL = ("status", "message", "worker", "model_load_s", "task_s", "task_cpu_s")
#: Parquet is rewritten at most this often (s) while rows arrive; the CSV gets every row at once.
PARQUET_EVERY = 5.0
#: An adaptive task holds about this many CPU seconds of runs (see _Batcher).
TASK_SECONDS = 0.5


class SweepError(InputError):
    """A sweep's request is wrong (field, value, design, folder): nothing ran or was written
    (the command line exits 2)."""


# ------------------------------------------------------------------------- fields and designs


@dataclass(frozen=True)
class Axis:
    """One varied field: grid ``values``, or a ``low``..``high`` range for a sampled design."""

    field: str
    values: tuple | None = None
    low: float = math.nan
    high: float = math.nan
    log: bool = False


def _parse_item(text: str) -> Any:
    """A list item as TOML would type it: integer, float, boolean, else a string."""
    text = text.strip()
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def _number(field: str, spec: Any, text: str, what: str) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise SweepError(f"`--vary {field}={spec}`: {what} {text!r} is not a finite number")
    return value


def parse_axis(field: str, spec: Any, design: str = "grid") -> Axis:
    """Read one ``FIELD=SPEC``.

    ``SPEC`` is a list ``"1e3,1e4,1e5"``, a range ``"lo:hi:n"`` or ``"lo:hi:n:log"`` (n
    values, evenly or geometrically spaced), or, for ``lhs``/``sobol`` designs, ``"lo:hi"``
    or ``"lo:hi:log"``.  From Python a list of values (grid) or a ``(lo, hi)`` pair (designs)
    works too.
    """
    if not isinstance(spec, str):
        items = list(spec) if isinstance(spec, Sequence) else [spec]
        if design == "grid":
            if not items:
                raise SweepError(f"`vary[{field!r}]` = {spec!r}: give at least one value")
            return Axis(field, values=tuple(items))
        spec = ":".join(str(x) for x in items)
    if design != "grid":
        parts = spec.split(":")
        if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] not in ("lin", "log")):
            raise SweepError(f"`--vary {field}={spec}`: a {design} design needs a range `lo:hi` or `lo:hi:log` "
                             "for every field")
        low, high = (_number(field, spec, p, "the bound") for p in parts[:2])
        log = len(parts) == 3 and parts[2] == "log"
        _check_range(field, spec, low, high, log)
        return Axis(field, low=low, high=high, log=log)
    if ":" not in spec:
        values = tuple(_parse_item(x) for x in spec.split(","))
        if any(v == "" for v in values):
            raise SweepError(f"`--vary {field}={spec}`: empty list item (write values separated by commas)")
        return Axis(field, values=values)
    parts = spec.split(":")
    if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3] not in ("lin", "log")):
        raise SweepError(f"`--vary {field}={spec}`: a range is `lo:hi:n` or `lo:hi:n:log` (n values); "
                         "`lo:hi` alone needs --samples N and --design lhs|sobol")
    low, high = (_number(field, spec, p, "the bound") for p in parts[:2])
    if not parts[2].isdigit() or int(parts[2]) < 1:
        raise SweepError(f"`--vary {field}={spec}`: the count {parts[2]!r} must be an integer >= 1")
    log = len(parts) == 4 and parts[3] == "log"
    _check_range(field, spec, low, high, log)
    space = np.geomspace if log else np.linspace
    return Axis(field, values=tuple(float(v) for v in space(low, high, int(parts[2]))), low=low, high=high, log=log)


def _check_range(field: str, spec: str, low: float, high: float, log: bool) -> None:
    if log and (low <= 0 or high <= 0):
        raise SweepError(f"`--vary {field}={spec}`: a log range needs bounds > 0")


def design_points(axes: list[Axis], design: str = "grid", samples: int | None = None, seed: int = 0) -> list[tuple]:
    """The varied values of every run, shape (runs, fields): a full grid or ``samples`` points."""
    if design not in DESIGNS:
        raise SweepError(f"`--design` = {design!r}: must be one of {list(DESIGNS)}")
    if design == "grid":
        if samples is not None:
            raise SweepError("`--samples` needs `--design lhs` or `--design sobol` (a grid runs every combination)")
        return list(itertools.product(*(a.values for a in axes)))
    if samples is None or samples < 1:
        raise SweepError(f"`--samples` = {samples!r}: a {design} design needs a number of samples >= 1")
    import inspect

    from scipy.stats import qmc

    engine = qmc.LatinHypercube if design == "lhs" else qmc.Sobol
    # SciPy >= 1.15 calls the seed `rng`; older releases `seed`.
    key = "rng" if "rng" in inspect.signature(engine).parameters else "seed"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # Sobol's balance note for n not a power of 2 (in the README)
        unit = engine(len(axes), **{key: seed}).random(samples)
    columns = []
    for axis, u in zip(axes, unit.T):
        if axis.log:
            columns.append(np.exp(np.log(axis.low) + u * (np.log(axis.high) - np.log(axis.low))))
        else:
            columns.append(axis.low + u * (axis.high - axis.low))
    return [tuple(float(v) for v in row) for row in zip(*columns)]


def _locate(table: dict, field: str) -> tuple[Any, Any]:
    """The container and key that ``field`` (a dotted path) names in a scene table.

    An integer step indexes an array (``bodies.0``); a word after an array of tables picks
    the element of that ``name`` (``bodies.ball``).  The last step may name a key the table
    does not have yet (scene validation then accepts or rejects it).
    """
    steps = field.split(".")
    if not field or "" in steps:
        raise SweepError(f"`--vary {field}`: FIELD must be a dotted path such as bodies.ball.stiffness")
    node: Any = table
    for depth, step in enumerate(steps):
        here = ".".join(steps[:depth]) or "the scene"
        last = depth == len(steps) - 1
        if isinstance(node, list):
            if step.lstrip("-").isdigit():
                index = int(step)
                if not 0 <= index < len(node):
                    raise SweepError(f"`--vary {field}`: {here} has {len(node)} element(s), no index {index}")
            else:
                names = [x.get("name") for x in node if isinstance(x, Mapping)]
                if step not in names:
                    raise SweepError(f"`--vary {field}`: {here} has no element named {step!r} (names: {names})")
                index = names.index(step)
            key = index
        elif isinstance(node, Mapping):
            if step not in node and not last:
                raise SweepError(f"`--vary {field}`: {here} has no `{step}`" +
                                 (" (the scene uses the default ground; add a [[grounds]] table to vary it)"
                                  if step == "grounds" else ""))
            key = step
        else:
            raise SweepError(f"`--vary {field}`: {here} is a value ({node!r}), not a table or an array")
        if last:
            return node, key
        node = node[key]
    raise AssertionError("unreachable")


def _base_table(scene: str | Path | Mapping) -> tuple[dict, str]:
    if isinstance(scene, Mapping):
        return copy.deepcopy(dict(scene)), "<mapping>"
    path = resolve_scene_path(scene)
    try:
        return tomllib.loads(path.read_text()), str(path)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(str(path), [f"not valid TOML: {exc}"]) from None


def varied_table(base: dict, fields: Sequence[str], values: Sequence[Any]) -> dict:
    """A copy of ``base`` with each dotted ``fields[i]`` set to ``values[i]``."""
    table = copy.deepcopy(base)
    for field, value in zip(fields, values):
        container, key = _locate(table, field)
        container[key] = value.item() if isinstance(value, np.generic) else value
    return table


def validate(base: dict, fields: Sequence[str], points: Sequence[tuple]) -> tuple[list[Scene], int]:
    """Load every varied scene; raise one :class:`SweepError` listing the invalid ones.

    Returns the scenes, shape (runs,), and how many have overdamped links (a warning,
    not an error).
    """
    bad, overdamped, scenes = [], 0, []
    for run, values in enumerate(points):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", OverdampedLinkWarning)
            try:
                scene = load_scene(varied_table(base, fields, values))
                _settings(scene, {})
                scenes.append(scene)
            except SceneError as exc:
                bad.append((run, values, exc.problems))
            except ValueError as exc:  # a combination of simulation settings (e.g. dopri5 with numpy)
                bad.append((run, values, str(exc).splitlines()[1:]))
        overdamped += any(issubclass(w.category, OverdampedLinkWarning) for w in caught)
    if bad:
        lines = []
        for run, values, problems in bad[:8]:
            setting = ", ".join(f"{f}={v!r}" for f, v in zip(fields, values))
            lines += [f"  run {run} ({setting}):"] + [f"    - {p.strip().lstrip('- ')}" for p in problems]
        more = f"\n  ... and {len(bad) - 8} more invalid run(s)" if len(bad) > 8 else ""
        raise SweepError(f"{len(bad)} of {len(points)} varied scenes are invalid; nothing was run:\n"
                         + "\n".join(lines) + more)
    return scenes, overdamped


# ------------------------------------------------------------------------- one run (on a worker)

#: Models loaded in this process, by what they take from a scene (:func:`_model_key`): a worker
#: loads each once.
_MODELS: dict[tuple, Model] = {}


def _model_key(scene: Scene) -> tuple:
    """What a model takes from its scene when it is made (:func:`flexbody.model.made_for`),
    its formulation and backend.  Keyed on the topology alone, a sweep of a ground's friction
    ran every scene with the first one's (ball_on_incline: 1.05 m off), and one of a mass
    with the first one's masses in its contacts between bodies."""
    return made_for(scene), scene.simulation.formulation, scene.simulation.backend


def _model_for(scene: Scene) -> tuple[Model, float]:
    """The model of ``scene``'s topology, loaded at most once per process; and the seconds it took."""
    key = _model_key(scene)
    if key in _MODELS:
        return _MODELS[key], 0.0
    start = time.perf_counter()
    _MODELS[key] = load_model(scene, backend=scene.simulation.backend, formulation=scene.simulation.formulation)
    return _MODELS[key], time.perf_counter() - start


def observables(result: SimulationResult, gravity: Sequence[float]) -> dict:
    """The observables of one run (:data:`OBSERVABLES`), plus its status and message.

    The counters, penetration, drift and cost come from ``result.stats`` whatever the
    status; the trajectory observables are NaN for a failed run (its trajectory is cut
    short) and when the run never touched ground or never left it.
    """
    s = result.stats
    row = {key: math.nan for key in OBSERVABLES}
    row.update({key: s[key] for key in ("impacts", "liftoffs", "max_penetration_m", "energy_drift_relative",
                                        "wall_time_s", "rhs_evaluations")})
    row.update(status=result.status, message=result.message)
    if not result.success or not len(result.t):
        return row
    total = result.contact_force.sum(axis=1)  # (nt,)
    row["peak_contact_force_N"] = float(total.max())
    start, end = _first_contact(result)
    if math.isnan(start):
        return row
    row["first_contact_duration_s"] = end - start
    if not math.isnan(end):
        up = -np.asarray(gravity, dtype=float) / np.linalg.norm(gravity)
        height = (result.positions @ up) @ result.masses / result.masses.sum()  # (nt,)
        after = result.t >= end
        if after.any():
            row["rebound_height_m"] = float(height[after].max())
    return row


def _first_contact(result: SimulationResult) -> tuple[float, float]:
    """Time of the first impact and of the first later instant at which no particle is held.

    Events at one instant are taken together (an impact that bounces off at once and one
    that stays held can share it).  The end is NaN if the contact lasts past the run.
    """
    kinds, times = result.events_kind, result.events_time
    impacts = np.flatnonzero(kinds == "impact")
    if not len(impacts):
        return math.nan, math.nan
    first = impacts[0]
    held: Counter = Counter()
    i = first
    while i < len(times):
        t = times[i]
        while i < len(times) and times[i] == t:
            particle = int(result.events_particle[i])
            if kinds[i] == "impact" and result.events_held[i]:
                held[particle] += 1
            elif kinds[i] == "liftoff" and held[particle] > 0:
                held[particle] -= 1
            i += 1
        if not +held:
            return float(times[first]), float(t)
    return float(times[first]), math.nan


def run_one(run: int, scene: Scene | Mapping, max_wall_time: float = math.inf, keep: str | None = None,
            table: Mapping | None = None) -> dict:
    """Run one varied scene and return its row (never raises: an exception becomes the row's status).

    ``scene`` is a validated Scene or a scene table; ``keep`` a folder for the run's result
    (with ``table`` saved beside it as ``scene.json``).
    """
    # The thread's CPU, not the process's: a worker's event loop (and, with nthreads > 1, the other
    # runs) work in other threads of the same process meanwhile.
    start, cpu = time.perf_counter(), time.thread_time()
    row: dict[str, Any] = {"run": run, **{key: math.nan for key in OBSERVABLES}, "status": "error",
                           "worker": f"{socket.gethostname()}:{os.getpid()}", "model_load_s": 0.0}
    try:
        if not isinstance(scene, Scene):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", OverdampedLinkWarning)  # counted once, before the sweep
                table, scene = scene, load_scene(scene)
        model, row["model_load_s"] = _model_for(scene)
        result = simulate(scene, model=model, max_wall_time=max_wall_time)
        row.update(observables(result, scene.gravity))
        if keep is not None:
            folder = Path(keep) / f"run_{run:05d}"
            result.save(folder, extra_files={"scene.json": json.dumps(table or {}, indent=1).encode()})
            row["result_path"] = str(folder)
    except Exception as exc:  # noqa: BLE001 - any failure of one run is that run's row
        row["message"] = f"{type(exc).__name__}: {exc}"
    row["task_s"], row["task_cpu_s"] = time.perf_counter() - start, time.thread_time() - cpu
    return row


def run_batch(batch: list[tuple], max_wall_time: float = math.inf, keep: str | None = None) -> list[dict]:
    """Rows of several runs (one Dask task); ``batch`` holds ``(run, scene[, table])``."""
    return [run_one(*item[:2], max_wall_time, keep, *item[2:]) for item in batch]


# ------------------------------------------------------------------------- rows on disk


def _cell(value: Any) -> Any:
    """A CSV cell that reads back to the same value (floats by repr, missing as empty)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return repr(value) if isinstance(value, float) else value


def _frame(rows: list[dict], columns: list[str]):
    """Rows as a DataFrame sorted by run, with nullable integer counts (NaN for runs that raised)."""
    import pandas as pd

    frame = pd.DataFrame(rows, columns=columns).sort_values("run", kind="stable").reset_index(drop=True)
    frame["run"] = frame["run"].astype("int64")
    for key in COUNTS:
        frame[key] = pd.to_numeric(frame[key]).astype("Int64")
    return frame  # text columns: pandas' default string type, as Parquet reads them back


def _atomic_write(path: Path, write) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    write(tmp)
    os.replace(tmp, path)


class _RowLog:
    """The sweep's rows: appended to ``sweep.csv`` as they arrive, ``sweep.parquet`` rewritten from them."""

    def __init__(self, out: Path | None, columns: list[str], previous: list[dict]) -> None:
        self.out, self.columns, self.rows = out, columns, list(previous)
        self.file = self.writer = None
        self.parquet_time = time.monotonic()
        if out is not None:
            self.flush(sort=True)  # a resumed log restarts clean (a half-written last line is dropped)
            self.file = open(out / "sweep.csv", "a", newline="")
            self.writer = csv.DictWriter(self.file, columns, extrasaction="ignore")

    def add(self, rows: list[dict]) -> None:
        self.rows += rows
        if self.writer is None:
            return
        for row in rows:
            self.writer.writerow({key: _cell(row.get(key)) for key in self.columns})
        self.file.flush()
        if time.monotonic() - self.parquet_time > PARQUET_EVERY:
            self.flush(sort=False)

    def flush(self, sort: bool):
        """Write ``sweep.parquet`` (and, with ``sort``, a sorted ``sweep.csv``); return the frame."""
        frame = _frame(self.rows, self.columns)
        if self.out is not None:
            _atomic_write(self.out / "sweep.parquet", lambda p: frame.to_parquet(p, engine="pyarrow", index=False))
            if sort:
                _atomic_write(self.out / "sweep.csv", lambda p: frame.to_csv(p, index=False))
            self.parquet_time = time.monotonic()
        return frame

    def close(self):
        if self.file is not None:
            self.file.close()
            self.file = self.writer = None
        return self.flush(sort=True)


def _previous_rows(out: Path, columns: list[str]) -> list[dict]:
    """The finished rows of an earlier, interrupted run of the same sweep.

    A last line without its newline (the sweep was killed while writing it) is dropped,
    and so are the rows of tasks that failed as a whole (a lost worker: no ``task_s``),
    so that resuming runs them again.
    """
    import io

    import pandas as pd

    path = out / "sweep.csv"
    if not path.exists():
        return []
    text = path.read_text()
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    try:
        frame = pd.read_csv(io.StringIO(text), keep_default_na=False, na_values=[""])
    except (ValueError, pd.errors.ParserError) as exc:
        raise SweepError(f"`--resume`: cannot read {path} ({exc}); move it away to start the sweep again") from None
    if list(frame.columns) != columns:
        raise SweepError(f"`--resume`: {path} has columns {list(frame.columns)}, this sweep writes {columns}; "
                         "resume with the same options, or choose another --out")
    frame = frame[frame["task_s"].notna()].drop_duplicates("run", keep="last")
    return [{k: (None if isinstance(v, float) and math.isnan(v) and k in TAIL else v) for k, v in row.items()}
            for row in frame.to_dict("records")]


class _Progress:
    """done / failed / remaining and the time left, on standard error (one line, redrawn on a terminal)."""

    def __init__(self, total: int, done: int, failed: int, enabled: bool) -> None:
        self.total, self.done, self.failed, self.enabled = total, done, failed, enabled
        self.resumed = done
        self.start = self.last = time.perf_counter()
        self.tty = sys.stderr.isatty()
        self.last_tenth = -1

    def update(self, rows: list[dict]) -> None:
        self.done += len(rows)
        self.failed += sum(row["status"] != "success" for row in rows)
        if not self.enabled:
            return
        now = time.perf_counter()
        new = self.done - self.resumed
        remaining = self.total - self.done
        left = (now - self.start) / new * remaining if new else math.nan
        line = (f"sweep: {self.done}/{self.total} done ({self.failed} failed), {remaining} remaining, "
                f"{now - self.start:.1f} s elapsed, ~{left:.0f} s left")
        if self.tty:
            if now - self.last >= 0.2 or remaining == 0:
                sys.stderr.write(f"\r{line}   ")
                self.last = now
        else:
            tenth = int(10 * self.done / self.total)
            if tenth > self.last_tenth:
                sys.stderr.write(line + "\n")
                self.last_tenth = tenth
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            sys.stderr.write("\n")


# ------------------------------------------------------------------------- the engine


def _versions() -> dict:
    import dask
    import distributed
    import pandas
    import pyarrow
    import scipy

    return {"flexbody": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "dask": dask.__version__, "distributed": distributed.__version__,
            "pandas": pandas.__version__, "pyarrow": pyarrow.__version__}


def _require_extra() -> None:
    try:
        import distributed  # noqa: F401
        import pandas  # noqa: F401
        import pyarrow  # noqa: F401
    except ImportError as exc:
        raise SweepError(f"`flexbody sweep` needs the sweep extra ({exc.name} is missing): "
                         "pip install 'flexbody[sweep]'") from None


#: Our LocalCluster has no dashboard, so nothing shows its profiles and monitors: sampling them less
#: cut the cluster's idle cost from ~0.12 to ~0.02 cores on the 2-core test machine (README).
#: The nannies also start each worker with MALLOC_TRIM_THRESHOLD_=65536, which fixes glibc's mmap
#: threshold at 128 KiB: every result array of a run (a few hundred KiB) is then a fresh mmap, zeroed
#: page by page by the kernel (1600-1800 page faults and 5-7 ms of system time per thesis-ball run, against
#: 0-20 faults without it; README).  Our workers hold no data between tasks, so there is nothing to trim; a
#: value the user sets in the environment still wins.
QUIET_CLUSTER = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.tick.interval": "1s",
    "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
}


def dask_setup(worker) -> None:
    """Dask preload hook, run in each local worker: ignore SIGINT.

    A terminal's Ctrl-C reaches every process of the sweep; the client answers it by
    cancelling the runs and closing the cluster, so the workers must not die on it first
    (each would print a KeyboardInterrupt traceback).
    """
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


class _Engine:
    """A Dask client: on a new LocalCluster (closed on exit, whatever happens) or an existing scheduler."""

    def __init__(self, scheduler: Any = None, workers: int | None = None) -> None:
        self.scheduler, self.workers = scheduler, workers
        self.client = self.cluster = None
        self.owned = True

    def __enter__(self):
        import dask
        from distributed import Client, LocalCluster

        if self.scheduler is not None and not isinstance(self.scheduler, str):
            self.client, self.owned = self.scheduler, False  # a Client the caller manages
        elif self.scheduler is not None:
            try:
                self.client = Client(self.scheduler, timeout="10s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise SweepError(f"`--scheduler` = {self.scheduler!r}: cannot connect ({exc})") from None
        else:
            try:
                # One single-threaded process per worker: the runs hold the GIL (Python event loop).
                # The preload (dask_setup below) lets only this process handle Ctrl-C.
                with dask.config.set(QUIET_CLUSTER):
                    self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                                dashboard_address=None, preload=["flexbody.sweep"])
                self.client = Client(self.cluster)
            except BaseException:
                self.__exit__()
                raise
        return self.client

    def __exit__(self, *exc) -> None:
        if self.owned and self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        self.client = self.cluster = None

    def describe(self) -> dict:
        """Where the runs go, for sweep.json."""
        info = self.client.scheduler_info()
        kind = "LocalCluster" if self.cluster is not None else "existing scheduler"
        return {"scheduler": kind, "address": info.get("address"), "workers": len(info.get("workers", {})),
                "threads_per_worker": 1 if self.cluster is not None else None}


def _axes(vary: Mapping[str, Any] | Sequence[str], design: str) -> list[Axis]:
    if isinstance(vary, Mapping):
        pairs = list(vary.items())
    else:
        pairs = []
        for item in vary:
            field, sep, spec = str(item).partition("=")
            if not sep or not field.strip() or not spec.strip():
                raise SweepError(f"`--vary {item}`: write FIELD=SPEC, e.g. bodies.ball.stiffness=1e3:1e5:9:log")
            pairs.append((field.strip(), spec.strip()))
    if not pairs:
        raise SweepError("give at least one `--vary FIELD=SPEC`")
    fields = [f for f, _ in pairs]
    for dup in sorted({f for f in fields if fields.count(f) > 1}):
        raise SweepError(f"`--vary {dup}` is given twice")
    return [parse_axis(field, spec, design) for field, spec in pairs]


def sweep(
    scene: str | Path | Mapping[str, Any],
    vary: Mapping[str, Any] | Sequence[str],
    out: str | Path | None = None,
    *,
    design: str = "grid",
    samples: int | None = None,
    seed: int = 0,
    scheduler: Any = None,
    workers: int | None = None,
    batch: int | None = None,
    keep_results: bool = False,
    resume: bool = False,
    figures: bool = True,
    max_wall_time: float = 600.0,
    progress: bool = True,
    command: list[str] | None = None,
):
    """Run a parameter study of ``scene`` on Dask; one row per run.

    Parameters
    ----------
    scene : path, bundled scene name or mapping
        The base scene; its TOML table is varied.
    vary : mapping or sequence of str
        ``{FIELD: SPEC}`` or ``["FIELD=SPEC", ...]``; see :func:`parse_axis`.
    out : path, optional
        Folder for ``sweep.csv``, ``sweep.parquet``, ``sweep.json`` and figures; None
        writes nothing (and cannot resume).
    design : {"grid", "lhs", "sobol"}
        Every combination, or ``samples`` Latin-hypercube / scrambled Sobol points.
    samples, seed : int
        Size and seed of a sampled design.
    scheduler : str or distributed.Client, optional
        ``"tcp://host:8786"`` of a running cluster, or a client; default: a new
        ``LocalCluster`` of ``workers`` processes (default one per core), closed at the end.
    batch : int, optional
        Runs per Dask task.  Each run stays independent (its own row, its own failure);
        grouping runs spreads Dask's cost per task (see the README).  Default: adaptive,
        tasks of about ``TASK_SECONDS`` from the runs finished so far.
    keep_results : bool
        Save each run's ``result.npz``, ``summary.json`` and ``scene.json`` in ``out/runs/``.
    resume : bool
        Skip the runs already in ``out/sweep.csv`` (the design must be the same).
    figures : bool
        Draw line plots (one varied field) or heat maps (two) of each observable.
    max_wall_time : float
        A run taking longer (s) stops with status ``too_slow``.

    Returns
    -------
    pandas.DataFrame
        One row per run, sorted by ``run``: the varied fields, :data:`OBSERVABLES`,
        ``status``, ``message``, ``worker`` (host:pid), ``model_load_s``, ``task_s`` and
        ``task_cpu_s`` (wall seconds of the whole run on its worker, and CPU seconds of
        the thread that ran it), and
        ``result_path`` with ``keep_results``.

    Raises
    ------
    SweepError
        A bad field, value, design, option or folder; nothing ran and nothing was written.
    """
    _require_extra()
    axes = _axes(vary, design)
    fields = [a.field for a in axes]
    points = design_points(axes, design, samples, seed)
    base, source = _base_table(scene)
    for field in fields:
        _locate(base, field)
    scenes, overdamped = validate(base, fields, points)
    if workers is not None and (scheduler is not None or workers < 1):
        raise SweepError(f"`--workers` = {workers}: " + ("must be >= 1" if workers < 1 else
                         "applies to the local cluster only (the scheduler's cluster has its own workers)"))
    if batch is not None and batch < 1:
        raise SweepError(f"`--batch` = {batch}: must be >= 1")
    if not max_wall_time > 0:
        raise SweepError(f"`--max-wall-time` = {max_wall_time}: must be > 0 (s)")
    columns = ["run", *fields, *OBSERVABLES, *TAIL] + (["result_path"] if keep_results else [])
    record = {"fields": fields, "design": design, "samples": samples, "seed": seed,
              "specs": {a.field: {"values": list(a.values) if design == "grid" else None, "low": a.low,
                                  "high": a.high, "log": a.log} for a in axes},
              "points": [list(p) for p in points]}
    out = None if out is None else Path(out)
    previous = _check_out(out, resume, base, record, columns)
    if overdamped and progress:
        print(f"warning: {overdamped} of {len(points)} varied scenes have links that are not underdamped "
              "(thesis eq. 3.12)", file=sys.stderr)
    done = {int(row["run"]) for row in previous}
    # Workers get the validated scenes (not their tables: no second validation); tables only to keep them.
    todo = [(run, scenes[run]) + ((varied_table(base, fields, points[run]),) if keep_results else ())
            for run in range(len(points)) if run not in done]
    if scheduler is None:  # derive and compile each topology's model once, here, before workers race for it
        for one in {_model_key(scene): scene for scene in scenes}.values():
            _model_for(one)
    if scheduler is None:
        workers = workers or os.cpu_count() or 1
    engine = _Engine(scheduler, workers)
    with engine as client:
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
        info = {"command": command or ["flexbody.sweep", repr(vary)], "scene": source, "base_scene": base,
                "design": record, "columns": columns, "observables": OBSERVABLES, "batch": batch,
                "max_wall_time_s": None if math.isinf(max_wall_time) else max_wall_time,
                "keep_results": keep_results, "versions": _versions(), "started": time.strftime("%FT%T%z"),
                "finished": None}
        log = _RowLog(out, columns, previous)
        bar = _Progress(len(points), len(previous), sum(r["status"] != "success" for r in previous), progress)
        if out is not None:
            info["engine"] = engine.describe()
            _write_json(out, info)
        keep = str((out / "runs").resolve()) if keep_results and out is not None else None
        finished = False
        try:
            _collect(client, todo, [dict(zip(fields, p)) for p in points], batch, max_wall_time, keep, log, bar)
            finished = True
        finally:
            bar.close()
            frame = log.close()
            if out is not None:
                info.update(finished=time.strftime("%FT%T%z") if finished else None,
                            counts=frame["status"].value_counts().to_dict())
                _write_json(out, info)
    if out is not None and figures:
        from .sweep_plots import draw

        draw(frame, axes, design, out)
    return frame


def _write_json(out: Path, info: dict) -> None:
    _atomic_write(out / "sweep.json", lambda p: p.write_text(json.dumps(info, indent=1, default=str) + "\n"))


def _check_out(out: Path | None, resume: bool, base: dict, record: dict, columns: list[str]) -> list[dict]:
    """Refuse a folder that would mix two sweeps; return the rows to keep when resuming."""
    if out is None:
        if resume:
            raise SweepError("`--resume` needs `--out` (the folder of the interrupted sweep)")
        return []
    if out.exists() and not out.is_dir():
        raise SweepError(f"`--out` = {str(out)!r}: exists and is not a folder")
    info_path = out / "sweep.json"
    if not resume:
        if info_path.exists() or (out / "sweep.csv").exists():
            raise SweepError(f"`--out` = {str(out)!r}: already holds a sweep; add --resume to finish it, "
                             "or choose another folder")
        if out.is_dir() and any(out.iterdir()):  # as `flexbody run` refuses: its tables and figures would mix in
            raise SweepError(f"`--out` = {str(out)!r}: holds other files; a sweep writes sweep.csv, sweep.parquet, "
                             "sweep.json and its figures there, so name a new or empty folder")
        return []
    if not info_path.exists():
        raise SweepError(f"`--resume`: {str(out)!r} holds no sweep.json (nothing to resume)")
    info = json.loads(info_path.read_text())
    same = json.loads(json.dumps(record)) == info.get("design") and json.loads(json.dumps(base)) == info.get(
        "base_scene")
    if not same or info.get("columns") != columns:
        raise SweepError(f"`--resume`: the scene, design or options differ from those in {info_path}; "
                         "resume with the same SCENE, --vary, --samples, --design, --seed and --keep-results")
    return _previous_rows(out, columns)


class _Batcher:
    """How many runs the next task gets.

    A fixed ``batch``, or adaptive: single runs until some have finished, then as many as
    take about TASK_SECONDS of CPU by the median run so far, so Dask's CPU per task (a few
    ms on a 2-core machine, see the README) stays a small part of each task's CPU; near the
    end never more than an even share of what is left, so no worker idles while another
    finishes a long last task.  CPU, not wall time: on a busy machine a run's wall time
    grows with the other programs, and so does Dask's per task, but the ratio of their CPU
    does not (sized by wall time, tasks shrank to one or two runs at load 8 on 2 cores).
    """

    def __init__(self, batch: int | None, workers: int) -> None:
        self.batch, self.workers = batch, workers
        self.times: list[float] = []

    def observe(self, rows: list[dict]) -> None:
        self.times += [row["task_cpu_s"] for row in rows if row.get("task_cpu_s") == row.get("task_cpu_s")]  # not NaN
        del self.times[:-200]

    def size(self, remaining: int) -> int:
        if self.batch is not None:
            return self.batch
        if not self.times:
            return 1
        per_run = max(float(np.median(self.times)), 1e-6)
        return max(1, min(int(TASK_SECONDS / per_run), remaining // (2 * self.workers), 500))


def _collect(client, todo: list[tuple], varied: list[dict], batch: int | None, max_wall_time: float,
             keep: str | None, log: _RowLog, bar: _Progress) -> None:
    """Submit the runs; record rows (with their ``varied`` values) as they arrive; cancel the rest if interrupted.

    At most two tasks per worker are out at a time (one running, one waiting), so each
    new task can be sized from the runs finished so far.
    """
    from distributed import as_completed

    workers = max(1, len(client.scheduler_info().get("workers", {})))
    batcher = _Batcher(batch, workers)
    pending = list(reversed(todo))  # popped from the end: run order
    out: dict[Any, list[tuple]] = {}
    # Results are fetched by the client's event loop as tasks finish, not one round trip at a time here.
    finished = as_completed([], with_results=True, raise_errors=False)

    def submit() -> None:
        while pending and len(out) < 2 * workers:
            items = [pending.pop() for _ in range(min(batcher.size(len(pending)), len(pending)))]
            future = client.submit(run_batch, items, max_wall_time, keep, pure=False)
            out[future] = items
            finished.add(future)

    try:
        submit()
        for future, result in finished:
            items = out.pop(future)
            rows = result
            if future.status != "finished":  # the task itself failed (worker lost, ...): rows, not a crash
                exc = result[1] if isinstance(result, tuple) else result
                rows = [{"run": run, **{key: math.nan for key in OBSERVABLES}, "status": "error",
                         "message": f"{type(exc).__name__}: {exc}", "worker": None, "model_load_s": math.nan,
                         "task_s": math.nan, "task_cpu_s": math.nan} for run, *_ in items]
            future.release()
            batcher.observe(rows)
            submit()
            for row in rows:
                row.update(varied[row["run"]])
            log.add(rows)
            bar.update(rows)
    finally:
        client.cancel(list(out))


# ------------------------------------------------------------------------- command line and benchmark


def sweep_command(args) -> int:
    """``flexbody sweep``: run the study, print where the rows are; 130 if interrupted."""
    command = {"argv": sys.argv, "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}}
    try:
        frame = sweep(args.scene, args.vary, args.out, design=args.design, samples=args.samples, seed=args.seed,
                      scheduler=args.scheduler, workers=args.workers, batch=args.batch,
                      keep_results=args.keep_results, resume=args.resume, figures=not args.no_figures,
                      max_wall_time=args.max_wall_time, progress=not args.quiet, command=command)
    except KeyboardInterrupt:
        print(f"\ninterrupted: the finished runs are in {args.out}/sweep.csv and sweep.parquet; "
              "run the same command with --resume to run the rest", file=sys.stderr)
        return 130
    counts = ", ".join(f"{n} {status}" for status, n in frame["status"].value_counts().items())
    print(f"{len(frame)} runs ({counts}); wrote {args.out}/sweep.parquet, sweep.csv, sweep.json"
          + ("" if args.no_figures else " and figures"))
    return 0


def _same(a: list, b: list) -> bool:
    """Equal element by element, NaN equal to NaN (bit for bit otherwise)."""
    return len(a) == len(b) and all(x == y or (x != x and y != y) for x, y in zip(a, b))


def _cpu_seconds(processes) -> float:
    """User + system CPU time of this process and of ``processes`` (psutil.Process objects)."""
    own = time.process_time()
    return own + sum(sum(p.cpu_times()[:2]) for p in processes)


def _thread_cpu(processes) -> dict[int, dict[int, tuple[float, float]]]:
    """User and system CPU seconds of every thread of ``processes`` (psutil), by pid and thread id."""
    return {p.pid: {t.id: (t.user_time, t.system_time) for t in p.threads()} for p in processes}


def _minor_faults(pid: int) -> float:
    """Minor page faults of process ``pid`` so far (Linux ``/proc``; NaN elsewhere)."""
    try:
        return float(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[7])
    except (OSError, IndexError, ValueError):
        return math.nan


def _where_cpu_goes(before: dict, after: dict, own: int, workers: set[int], main_cpu: float, validation_cpu: float,
                    runs_cpu: float, runs: int) -> dict:
    """CPU seconds per run by thread, beyond the runs and the validation, between two
    :func:`_thread_cpu` snapshots.

    ``own`` is this process (client, scheduler, nannies), ``main_cpu`` the CPU of its calling
    thread (which ran :func:`sweep`, ``validation_cpu`` of it validating), ``workers`` the
    worker pids, whose main thread runs the event loop, ``runs_cpu`` the runs' own thread CPU
    (``task_cpu_s``).
    """
    def spent(pid: int, keep) -> tuple[float, float]:
        pairs = [(u - before[pid].get(tid, (0.0, 0.0))[0], s - before[pid].get(tid, (0.0, 0.0))[1])
                 for tid, (u, s) in after[pid].items() if keep(tid)]
        return sum(u for u, _ in pairs), sum(s for _, s in pairs)

    client = sum(spent(own, lambda tid: True))
    loops = sum(sum(spent(pid, lambda tid, pid=pid: tid == pid)) for pid in workers)
    others = [spent(pid, lambda tid, pid=pid: tid != pid) for pid in workers]  # the runs' threads and helpers
    return {"client_main_s": (main_cpu - validation_cpu) / runs, "client_other_threads_s": (client - main_cpu) / runs,
            "worker_event_loops_s": loops / runs, "worker_other_threads_s": (sum(map(sum, others)) - runs_cpu) / runs,
            "worker_system_s": sum(s for _, s in others) / runs}


def _warm_process(table: dict) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OverdampedLinkWarning)
        _model_for(load_scene(table))


def _parallel_ceiling(tables: list[dict], workers: int) -> tuple[float, list[dict]]:
    """Wall time of the same runs split over ``workers`` plain processes (no Dask), their
    models loaded before the clock starts: the best these cores allow, the ceiling for the
    sweep's speed-up (cores that share a host's core run slower side by side).  And the rows."""
    import multiprocessing

    numbered = list(enumerate(tables))
    chunks = [numbered[k::workers] for k in range(workers)]
    with multiprocessing.get_context("spawn").Pool(workers, _warm_process, (tables[0],)) as pool:
        pool.map(abs, range(workers), chunksize=1)  # every process started and warm
        start = time.perf_counter()
        rows = pool.map(run_batch, chunks, chunksize=1)
        return time.perf_counter() - start, [row for chunk in rows for row in chunk]


def benchmark(out: Path, quick: bool) -> dict:
    """Thesis ball, stiffness x damping (200 runs): a 2-worker LocalCluster against a serial loop.

    The serial loop calls the same per-run function in this process (scene loading, the
    run, the observables), with the model loaded once.  The sweep's time counts from its
    call to its return (validation, submission, rows written), not the cluster's start.

    Per-run overhead, wall: (workers x sweep time - serial time) / runs, what a worker
    spends on a run beyond the run itself; other programs on the same cores inflate it.
    Per-run overhead, CPU: the CPU seconds of this process (client and scheduler) and of
    the workers, minus those of the runs themselves (measured inside each task) and of
    validating the scenes (the serial loop loads each scene too), per run: what Dask and
    the row writing add, which other programs change less.  It is split by thread (psutil):
    the client's main thread (the sweep call, rows), its other threads (client, scheduler
    and nannies share one event loop), the workers' event loops (their main threads) and
    their other threads beyond the runs; with the runs' system CPU and page faults, which
    showed where the workers' runs lost 27 % (Dask's MALLOC_TRIM_THRESHOLD_, see
    QUIET_CLUSTER).
    """
    import shutil
    import tempfile

    import psutil

    n_k, n_c, workers = (10, 4, 2) if quick else (20, 10, 2)
    vary = {"bodies.ball.stiffness": f"1e3:1e4:{n_k}:log", "bodies.ball.damping": f"0.1:1:{n_c}"}
    base, _ = _base_table("thesis_ball")
    points = design_points(_axes(vary, "grid"))
    tables = [varied_table(base, list(vary), p) for p in points]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OverdampedLinkWarning)
        _model_for(load_scene(tables[0]))
    print(f"sweep benchmark: thesis ball, {len(points)} runs (stiffness {n_k} x damping {n_c}), "
          f"{workers}-worker LocalCluster against a serial loop; {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}")
    me = psutil.Process()
    faults, system = _minor_faults(me.pid), me.cpu_times().system
    start, cpu = time.perf_counter(), time.process_time()
    serial_rows = run_batch(list(enumerate(tables)), 600.0)
    serial, serial_cpu = time.perf_counter() - start, time.process_time() - cpu
    per_run = serial / len(points)
    serial_runs = {"runs_cpu_s": sum(r["task_cpu_s"] for r in serial_rows),
                   "system_s": me.cpu_times().system - system, "minor_faults": _minor_faults(me.pid) - faults}
    print(f"  serial loop: {serial:.2f} s wall, {serial_cpu:.2f} s CPU; {per_run * 1e3:.1f} ms per run "
          f"(integration {np.mean([r['wall_time_s'] for r in serial_rows]) * 1e3:.1f} ms of it); the runs' "
          f"thread CPU {serial_runs['runs_cpu_s']:.2f} s, of it system {serial_runs['system_s']:.2f} s; "
          f"{serial_runs['minor_faults'] / len(points):.0f} page faults per run")
    ceiling, plain_rows = _parallel_ceiling(tables, workers)
    plain_cpu = sum(r["task_cpu_s"] for r in plain_rows)
    print(f"  {workers} plain processes (no Dask), half the runs each: {ceiling:.2f} s, speed-up "
          f"{serial / ceiling:.2f}: the ceiling on these cores; the runs' thread CPU {plain_cpu:.2f} s")
    start = time.perf_counter()
    engine = _Engine(None, workers)
    client = engine.__enter__()
    startup = time.perf_counter() - start
    procs = me.children(recursive=True)
    worker_pids = set(client.run(os.getpid).values())
    print(f"  LocalCluster start: {startup:.2f} s")
    cpu = time.process_time()
    validate(base, list(vary), points)
    validation_cpu = time.process_time() - cpu
    print(f"  validating the {len(points)} scenes: {validation_cpu:.2f} s CPU (also paid by the serial loop, "
          "which loads each scene; not counted as overhead)")
    cases = []
    scratch = Path(tempfile.mkdtemp(prefix="flexbody-sweep-bench-"))
    try:
        for label, batch in (("cold workers, 1 run per task", 1), ("warm workers, 1 run per task", 1),
                             ("warm workers, 5 runs per task", 5), ("warm workers, adaptive tasks (default)", None)):
            load = os.getloadavg()[0]
            threads, faults = _thread_cpu([me, *procs]), sum(map(_minor_faults, worker_pids))
            start, cpu, main = time.perf_counter(), _cpu_seconds(procs), time.thread_time()
            frame = sweep("thesis_ball", vary, scratch / f"{len(cases)}", scheduler=client, batch=batch,
                          figures=False, progress=False)
            elapsed, used, main = time.perf_counter() - start, _cpu_seconds(procs) - cpu, time.thread_time() - main
            faults = sum(map(_minor_faults, worker_pids)) - faults
            same = all(_same(frame[key].tolist(), [r[key] for r in serial_rows])
                       for key in OBSERVABLES if key != "wall_time_s")
            overhead = (workers * elapsed - serial) / len(points)
            runs_cpu = float(frame["task_cpu_s"].sum())
            cpu_overhead = (used - runs_cpu - validation_cpu) / len(points)
            split = _where_cpu_goes(threads, _thread_cpu([me, *procs]), me.pid, worker_pids,
                                    main, validation_cpu, runs_cpu, len(points))
            case = {"label": label, "batch": batch, "time_s": elapsed, "cpu_s": used, "runs_cpu_s": runs_cpu,
                    "speedup": serial / elapsed, "of_ceiling": ceiling / elapsed, "overhead_per_run_s": overhead,
                    "overhead_relative": overhead / per_run,
                    "cpu_overhead_per_run_s": cpu_overhead, "cpu_overhead_relative": cpu_overhead * len(points)
                    / runs_cpu, "load_average": load,
                    "failed": int((frame["status"] != "success").sum()), "identical_to_serial": bool(same),
                    "per_run_by_thread_s": split,
                    "worker_minor_faults_per_run": faults / len(points)}
            cases.append(case)
            print(f"  {label:42s} {elapsed:6.2f} s  speed-up {case['speedup']:.2f} "
                  f"({100 * case['of_ceiling']:.0f} % of the ceiling)  overhead per run: wall "
                  f"{overhead * 1e3:6.2f} ms ({100 * case['overhead_relative']:.0f} %), "
                  f"CPU {cpu_overhead * 1e3:5.2f} ms ({100 * case['cpu_overhead_relative']:.0f} %); "
                  f"load {load:.1f}; identical to serial: {same}")
            system = split["worker_system_s"] * len(points)
            print(f"  {'':42s} runs' thread CPU {runs_cpu:.2f} s (workers' system CPU {system:.2f} s, "
                  f"{faults / len(points):.0f} page faults per run); per run beyond the runs: client main thread "
                  f"{split['client_main_s'] * 1e3:.2f} ms, client/scheduler/nanny threads "
                  f"{split['client_other_threads_s'] * 1e3:.2f} ms, worker event loops "
                  f"{split['worker_event_loops_s'] * 1e3:.2f} ms, other worker threads "
                  f"{split['worker_other_threads_s'] * 1e3:.2f} ms")
    finally:
        engine.__exit__()
        shutil.rmtree(scratch, ignore_errors=True)
    data = {"runs": len(points), "workers": workers, "serial_s": serial, "serial_cpu_s": serial_cpu,
            "validation_cpu_s": validation_cpu,
            "serial_per_run_s": per_run, "serial_runs": serial_runs, "plain_processes_s": ceiling,
            "plain_processes_runs_cpu_s": plain_cpu, "ceiling_speedup": serial / ceiling,
            "cluster_start_s": startup, "cases": cases, "vary": vary,
            "environment": {"cpus": os.cpu_count(), **_versions()}}
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.json").write_text(json.dumps(data, indent=1) + "\n")
    print(f"  saved {out / 'sweep.json'}")
    return data
