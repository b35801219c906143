"""Entry point the runtime calls (in a child process) to derive a model it lacks.

``python -m derivation.ondemand TOPOLOGY_JSON FORMULATION OUT_DIR SOURCE``
"""

from __future__ import annotations

import sys
from pathlib import Path

from flexbody.topology import Topology

from .codegen import render
from .mechanics import derive
from .writer import write_model


def main(argv: list[str]) -> int:
    topology_json, formulation, out_dir, source = argv
    model = derive(Topology.from_json(topology_json), formulation)
    files = render(model, source=source, command=f"flexbody derive {source} --formulation {formulation}")
    write_model(files, Path(out_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
