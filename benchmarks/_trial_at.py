"""One process timing one-process humanoid trials of the code in another checkout (``benchmarks/humanoid_against.py``).

    python benchmarks/_trial_at.py ROOT TRIALS SECONDS [KERNEL]

Imports the checkout at ROOT as its own install would (its ``pyproject.toml``'s package folders: ``sfl_brain``,
``sfl_brain.modules`` from ``modules/``, ``sfl_brain.bodies`` from ``bodies/``), never this environment's editable
install, and checks that every module it timed came from ROOT. Then its own ``benchmarks/humanoid.py`` builds the
trial (b) as that revision defined it: the CPG controller on the body's link in one process, the finish line out of
reach so that every trial lasts SECONDS; one warm-up trial, then TRIALS timed ones. Prints one line of JSON: wall and
CPU s per trial, and the trial's distance and fall (the same trial or not, against another revision's).
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time
import tomllib
from pathlib import Path


def import_checkout(root: Path) -> None:
    """The packages of the checkout at ``root`` under their installed names, before anything imports them."""
    folders = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    for name in sorted(folders, key=lambda n: n.count(".")):  # sfl_brain before sfl_brain.bodies
        folder = root / folders[name]
        spec = importlib.util.spec_from_file_location(
            name, folder / "__init__.py", submodule_search_locations=[str(folder)]
        )
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        if "." in name:
            parent, _, child = name.rpartition(".")
            setattr(sys.modules[parent], child, module)


def main(argv: list[str]) -> int:
    root, trials, seconds = Path(argv[0]).resolve(), int(argv[1]), float(argv[2])
    kernel = argv[3] if len(argv) > 3 else None
    import_checkout(root)
    sys.path.insert(0, str(root / "benchmarks"))
    spec = importlib.util.spec_from_file_location("_humanoid_at", root / "benchmarks" / "humanoid.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    bench.SECONDS = seconds  # module globals the revision's new_body and whole_trial read
    bench.BODY_PARAMS = {"duration": seconds, "finish_line": 1000.0}
    body = bench.new_body()
    params = bench.CPGParams(**bench.CONTROLLER_PARAMS, **({"kernel": kernel} if kernel else {}))
    controller = bench.CPGController(params)
    body.link = bench.InProcessLink(controller)
    used = [sys.modules[type(x).__module__].__file__ for x in (body, controller)]
    outside = [f for f in used if not Path(f).resolve().is_relative_to(root)]
    assert not outside, f"timed code from outside {root}: {outside}"
    bench.whole_trial(body)  # warm-up
    walls, cpus, metrics = [], [], {}
    for _ in range(trials):
        cpu = time.process_time()
        wall, metrics = bench.whole_trial(body)
        cpus.append(time.process_time() - cpu)
        walls.append(wall)
    print(json.dumps({"wall": walls, "cpu": cpus, "distance": metrics.get("distance"), "fell": metrics.get("fell")}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
