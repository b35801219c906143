"""Simulation results: the arrays of DESIGN.md §2, status, statistics, saving as one folder."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .paths import check_output_dir, staged_folder

#: Array keys of result.npz, in the order of DESIGN.md §2 (plus events_held, events_surface and links).
ARRAY_KEYS = (
    "t", "positions", "velocities", "contact_force", "kinetic", "spring", "gravity", "damping_work",
    "impact_loss", "friction_force", "friction_work", "events_time", "events_particle", "events_kind",
    "events_held", "events_surface", "masses", "links",
)  # fmt: skip

#: Status values and what each means.
STATUSES = {
    "success": "The simulation reached t_end.",
    "chattering": "A particle kept impacting at vanishing speed (an accumulation of impacts).",
    "no_progress": "Events kept firing without time advancing.",
    "step_size_collapse": "The integrator's step size collapsed.",
    "blow_up": "The state became non-finite or the mass matrix singular.",
    "max_events": "The maximum number of events was reached.",
    "too_slow": "The run exceeded its max_wall_time.",
    "unsupported": ("The scene reached a situation flexbody refuses to approximate (a frictional corner, "
                    "a contact against a body folded over itself)."),
}


@dataclass(eq=False)  # identity: arrays have no single truth value (compare them with numpy)
class SimulationResult:
    """Everything a run produced.

    Attributes
    ----------
    t : ndarray, shape (nt,)
    positions, velocities : ndarray, shape (nt, n, dim)
        Particles in N (dim = 2 or 3).
    contact_force : ndarray, shape (nt, n)
        Normal constraint force on each particle (N, >= 0), summed over its contacts: with
        the grounds, and where it touches another body's surface (or an edge contact's
        edge of it: there (1 - s) and s of the force on its two ends).  The reaction on the
        surface touched is not in it.
    kinetic, spring, gravity, damping_work, impact_loss : ndarray, shape (nt,)
        The energy ledger (J), with ``friction_work``: their sum stays at its initial value.
        ``impact_loss`` holds what impulses took, normal and tangential.
    events_time, events_particle, events_kind, events_held : ndarray, shape (ne,)
        Each impact, lift-off, stick or slip (``events_kind``: ``"impact"``,
        ``"liftoff"``, ``"stick"``, ``"slip"``); ``events_held`` is False for an impacted
        particle that leaves at once because holding it would need a pulling force.
    events_surface : ndarray of int, shape (ne,)
        What each event's particle touches: the index of the body whose surface it is (in
        the scene's bodies; its own for a self-contact), or -1 for a ground.
    masses : ndarray, shape (n,)
    links : ndarray of int, shape (n_links, 2)
        Particle pairs joined by a spring and damper (for drawing the body).
    friction_force : ndarray, shape (nt, n, dim)
        Tangential contact force on each particle (N; summed over its contacts, as
        ``contact_force``; 0 without friction).
    friction_work : ndarray, shape (nt,)
        Energy dissipated by sliding friction so far (J, >= 0, non-decreasing).
    status : str
        One of :data:`STATUSES`; ``message`` says what happened and what to change.
    stats : dict
        Method, tolerances, backend, formulation, wall time, RHS evaluations, steps,
        events, max penetration, energy drift.
    """

    t: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    contact_force: np.ndarray
    kinetic: np.ndarray
    spring: np.ndarray
    gravity: np.ndarray
    damping_work: np.ndarray
    impact_loss: np.ndarray
    events_time: np.ndarray
    events_particle: np.ndarray
    events_kind: np.ndarray
    events_held: np.ndarray
    masses: np.ndarray
    links: np.ndarray
    friction_force: np.ndarray | None = None  # zeros when not given (a run without friction)
    friction_work: np.ndarray | None = None
    events_surface: np.ndarray | None = None  # all -1 (grounds) when not given (a result from before the key)
    status: str = "success"
    message: str = STATUSES["success"]
    stats: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.friction_force is None:
            self.friction_force = np.zeros(np.shape(self.velocities))
        if self.friction_work is None:
            self.friction_work = np.zeros(len(self.t))
        if self.events_surface is None:
            self.events_surface = np.full(len(self.events_time), -1, dtype=int)

    @property
    def success(self) -> bool:
        return self.status == "success"

    @property
    def total_energy(self) -> np.ndarray:
        """Kinetic + spring + gravity + damping work + impact loss + friction work, shape (nt,)."""
        return self.kinetic + self.spring + self.gravity + self.damping_work + self.impact_loss + self.friction_work

    def arrays(self) -> dict[str, np.ndarray]:
        return {key: getattr(self, key) for key in ARRAY_KEYS}

    def save(self, out_dir: str | Path, extra_files: dict[str, bytes | Callable[[Path], object]] | None = None) -> Path:
        """Write ``result.npz`` and ``summary.json`` (and ``extra_files``) as the folder ``out_dir``.

        ``extra_files`` maps a relative path to its bytes, or to a function that writes
        that path (a file or a folder) when given it inside the folder being written.

        The files are written into a temporary folder beside ``out_dir``, which then
        replaces ``out_dir`` whole (:func:`flexbody.paths.staged_folder`): a crash leaves
        either the previous folder or the new one, never a mix, and the folder holds only
        this result's files (no figures of an earlier run beside it).

        Raises
        ------
        flexbody.errors.InputError
            If ``out_dir`` cannot be a result folder (see :func:`flexbody.paths.check_output_dir`):
            a file, a folder of other files (it would be deleted), the current folder.
        """
        check_output_dir(str(out_dir), option="out_dir")  # never replace a folder of other files
        with staged_folder(out_dir) as staging:
            np.savez_compressed(staging / "result.npz", **self.arrays())
            summary = dict(self.stats, status=self.status, message=self.message)
            (staging / "summary.json").write_text(json.dumps(summary, indent=1, default=_plain) + "\n")
            for name, data in (extra_files or {}).items():
                path = staging / name
                path.parent.mkdir(parents=True, exist_ok=True)
                if callable(data):  # a writer: for a sub-folder, or files too many to hold in memory
                    data(path)
                else:
                    path.write_bytes(data)
        return Path(out_dir)


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def load_result(out_dir: str | Path) -> SimulationResult:
    """Read a result written by :meth:`SimulationResult.save`."""
    out_dir = Path(out_dir)
    with np.load(out_dir / "result.npz") as data:
        arrays = {key: data[key] for key in ARRAY_KEYS if key in data}  # older results lack the friction keys, events_surface
    summary = json.loads((out_dir / "summary.json").read_text())
    status, message = summary.pop("status"), summary.pop("message")
    return SimulationResult(**arrays, status=status, message=message, stats=summary)
