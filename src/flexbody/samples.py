"""The contact set at each output sample, kept sparse.

The driver records, for every output sample, what its step integrated: each contact's law
code (``Phases.held``), the thesis windows' pushes and tangential pushes, and the element
each slot between bodies was held on.  Its outputs (contact forces, the held contacts'
lowest gaps) are computed from them after the run.  Kept as dense (samples, contacts)
arrays they grew with the square of the number of bodies (a slot per surface vertex and
other body): a pile of 20 discs of 199 particles has 40 460 contacts, and its 1 001
samples took 1.9 GB.  Here each call of :meth:`ContactSamples.keep` stores its arrays'
entries that differ from their fill (the held contacts, the pushed ones, the slots with an
element: a few hundred), once for all the samples it covers, and :meth:`ContactSamples.dense`
rebuilds a few samples' arrays at a time.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

#: Samples rebuilt at once hold at most about this many contact entries (4 M: 32 MB of float64).
CHUNK_ENTRIES = 1 << 22


class _Sparse(NamedTuple):
    """The entries of one array (flattened to its first axis) that differ from ``fill``."""

    at: np.ndarray  # (k,) indices along the first axis
    values: np.ndarray  # (k, ...) their values

    @classmethod
    def of(cls, array: np.ndarray, fill: float) -> _Sparse:
        array = np.asarray(array)
        differs = array if fill == 0 and array.ndim == 1 else array != fill
        at = np.flatnonzero(differs if differs.ndim == 1 else differs.reshape(len(array), -1).any(axis=1))
        return cls(at, array[at])  # a copy (fancy indexing)


class SampleContacts(NamedTuple):
    """Some samples' contact sets, dense: ``held`` (m, nc) np.intc codes, ``push`` (m, nc) N,
    ``tangential`` (m, nc, dim) N or None, ``elements`` (m, ns) or None."""

    held: np.ndarray
    push: np.ndarray
    tangential: np.ndarray | None
    elements: np.ndarray | None


class ContactSamples:
    """The contact set of each output sample, kept sparse.

    Parameters
    ----------
    n_contacts : int
        Contacts of the model (nc).
    n_slots : int
        Its slots between bodies (ns; 0: no elements are kept).
    dim : int
    tangential : bool
        Whether the thesis windows' tangential pushes are kept (thesis mode with friction).
    """

    def __init__(self, n_contacts: int, n_slots: int, dim: int, tangential: bool) -> None:
        self.n_contacts, self.n_slots, self.dim = n_contacts, n_slots, dim
        self.has_tangential = tangential
        # each kept run of samples, [start, stop), and its arrays' entries: the driver keeps
        # them in time order, so the runs' starts and stops both ascend
        self._starts: list[int] = []
        self._stops: list[int] = []
        self._records: list[dict[str, _Sparse]] = []
        # the table each run was kept in (its indices), and each later table's place of the
        # contacts and slots of the one before (see move): runs kept before a move are read
        # through them at dense(), so a move costs nothing however many runs came before
        self._table_of: list[int] = []
        self._moves: list[tuple[np.ndarray, np.ndarray]] = []
        self._to_now: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def keep(self, start: int, stop: int, held: np.ndarray, push: np.ndarray, tangential: np.ndarray | None = None,
             elements: np.ndarray | None = None) -> None:
        """Samples ``start:stop`` integrated this contact set: ``held`` (nc,) codes, ``push``
        (nc,), ``tangential`` (nc, dim) (kept where :attr:`has_tangential`) and ``elements``
        (ns,) (kept where the model has slots)."""
        if stop <= start:
            return
        # kept again (sample 0: the given state, then the instant at t = 0's outcome): the
        # new set replaces the old for these samples; runs stay disjoint and ascending
        if self._stops and self._stops[-1] > stop:
            raise ValueError(f"samples {start}:{stop} kept inside samples kept up to {self._stops[-1]}: "
                             "keep them in order")
        while self._starts and self._starts[-1] >= start:
            self._starts.pop(), self._stops.pop(), self._records.pop(), self._table_of.pop()
        if self._stops and self._stops[-1] > start:
            self._stops[-1] = start
        record = {"held": _Sparse.of(held, 0), "push": _Sparse.of(push, 0.0)}
        if self.has_tangential:
            record["tangential"] = _Sparse.of(tangential, 0.0)
        if self.n_slots:
            record["elements"] = _Sparse.of(elements, -1)
        self._records.append(record)
        self._table_of.append(len(self._moves))
        self._starts.append(start)
        self._stops.append(stop)

    def move(self, index: np.ndarray, n_contacts: int, slot_index: np.ndarray, n_slots: int) -> None:
        """The contacts move to a table of ``n_contacts`` (``n_slots`` slots): contact ``i`` to
        ``index[i]``, slot ``j`` to ``slot_index[j]`` (each >= 0, distinct); the new ones
        read their fill in the samples kept so far (free, no element)."""
        self._moves.append((np.asarray(index, np.intp), np.asarray(slot_index, np.intp)))
        self._to_now.clear()
        self.n_contacts, self.n_slots = n_contacts, n_slots

    def _now(self, table: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Where the contacts and slots of table ``table`` are in the present one (None: it is)."""
        if table == len(self._moves):
            return None
        if not self._to_now:  # every table's at once, the newest first: a table's places are its next's, moved
            index = slot_index = None
            for k in range(len(self._moves) - 1, -1, -1):
                moved, moved_slots = self._moves[k]
                index, slot_index = (moved, moved_slots) if index is None else (index[moved], slot_index[moved_slots])
                self._to_now[k] = index, slot_index
        return self._to_now[table]

    def dense(self, rows: slice) -> SampleContacts:
        """The samples ``rows`` (a slice with start and stop, of kept samples) as dense arrays: ``held`` (m, nc)
        np.intc, ``push`` (m, nc), ``tangential`` (m, nc, dim) or None, ``elements`` (m, ns)
        np.intp or None."""
        m = rows.stop - rows.start
        out = {"held": np.zeros((m, self.n_contacts), np.intc), "push": np.zeros((m, self.n_contacts)),
               "tangential": np.zeros((m, self.n_contacts, self.dim)) if self.has_tangential else None,
               "elements": np.full((m, self.n_slots), -1, np.intp) if self.n_slots else None}
        first, last = bisect.bisect_right(self._stops, rows.start), bisect.bisect_left(self._starts, rows.stop)
        for i in range(first, last):  # the runs that overlap rows
            a, b = max(self._starts[i], rows.start) - rows.start, min(self._stops[i], rows.stop) - rows.start
            now = self._now(self._table_of[i])
            for name, kept in self._records[i].items():
                at = kept.at if now is None else (now[1] if name == "elements" else now[0])[kept.at]
                out[name][a:b, at] = kept.values  # (k,) or (k, dim): broadcast over the samples
        return SampleContacts(**out)

    def chunks(self, n: int) -> Iterator[slice]:
        """The first ``n`` samples in slices of at most :data:`CHUNK_ENTRIES` contact entries
        each (at least one sample; one empty slice where ``n`` is 0, so that callers build
        their empty outputs as for any other)."""
        size = max(1, CHUNK_ENTRIES // max(1, self.n_contacts * (self.dim if self.has_tangential else 1)))
        for start in range(0, max(n, 1), size):
            yield slice(start, min(n, start + size))
