"""Regenerate ``thesis_ball_events.json``: the thesis ball's event list from tight runs.

``python tests/reference/make_thesis_ball_events.py`` (a few minutes).  The event times come
from the compiled DOP853 at rtol = 1e-12, atol = 1e-15 in the particles formulation,
cross-checked against SciPy's DOP853 at the same tolerances in the floating formulation
(another integrator code path and other coordinates); the largest time difference between
the two is stored.  The counts are checked against the independent implementation of the
design brief's contact study (/work/shared/anchors/contact.md, "Provenance": DOP853 at
rtol = atol = 1e-12 over 2 s, 29 impacts of which 8 not held, 18 lift-offs).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import flexbody

OUT = Path(__file__).with_name("thesis_ball_events.json")


def main() -> None:
    ball = flexbody.load_scene("thesis_ball")
    a = flexbody.simulate(ball, method="dop853", backend="c", formulation="particles", rtol=1e-12, atol=1e-15)
    b = flexbody.simulate(ball, method="DOP853", backend="c", formulation="floating", rtol=1e-12, atol=1e-15)
    assert a.success and b.success, (a.message, b.message)
    pairs_a = list(zip(a.events_particle.tolist(), a.events_kind.tolist()))
    pairs_b = list(zip(b.events_particle.tolist(), b.events_kind.tolist()))
    assert pairs_a == pairs_b, "the two tight runs disagree on the event sequence"
    counts = (a.stats["impacts"], a.stats["not_held"], a.stats["liftoffs"])
    assert counts == (29, 8, 18), counts  # contact.md's independent implementation
    spread = float(np.abs(a.events_time - b.events_time).max())
    data = {
        "scene": "thesis_ball (bundled), t_end = 2 s",
        "provenance": (
            "Counts: the independent SciPy event driver of the design brief's contact study "
            "(/work/shared/anchors/contact.md, 'Provenance': DOP853, rtol = atol = 1e-12, 2 s: 29 impacts, "
            "8 of them not held, 18 lift-offs, 47 event instants). Particles, kinds and times: flexbody's "
            "compiled dop853 at rtol 1e-12, atol 1e-15 (particles formulation), cross-checked against SciPy's "
            "DOP853 at the same tolerances in the floating formulation; they agree on every (particle, kind) "
            "pair and on the times to cross_check_max_time_difference_s. Regenerate with "
            "tests/reference/make_thesis_ball_events.py."
        ),
        "impacts": counts[0], "not_held": counts[1], "liftoffs": counts[2],
        "event_instants": len(np.unique(a.events_time)),
        "cross_check_max_time_difference_s": spread,
        "events": [{"time": float(t), "particle": int(p), "kind": str(k), "held": bool(h)}
                   for t, p, k, h in zip(a.events_time, a.events_particle, a.events_kind, a.events_held)],
    }
    OUT.write_text(json.dumps(data, indent=1) + "\n")
    print(f"wrote {OUT}: {len(data['events'])} events, {data['event_instants']} instants, cross-check {spread:.2e} s")


if __name__ == "__main__":
    main()
