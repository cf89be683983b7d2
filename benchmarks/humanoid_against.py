"""The one-process humanoid trial of this checkout beside the same trial of an earlier revision, in one run.

    python benchmarks/humanoid_against.py [REV] [--repeats 9] [--seconds 16]

Issue 31 asks for a one-process humanoid trial >= 1.4x the speed of the code it was filed against. ``REV`` (default
``ee74889``, the last commit before issue 31 was filed: nothing was committed between it and the issue) is checked out
into a temporary ``git worktree`` and imported from there as its own install would be (``_trial_at.py``); each item
runs in a process of its own, the items in a shuffled order each round, so that all see the same machine load:

(rev)     the revision's trial (b): its CPG controller on the body's link, in one process;
(b)       this checkout's (b), the numpy CPG;
(b-numba) this checkout's (b) on the compiled CPG kernel (``CPGParams.kernel: numba``; skipped without numba).

Every trial lasts ``--seconds`` of simulated time (the finish line out of reach; chapter 5's learning trials last 16 s
on average). Times are medians over the rounds of each process's timed trial (after a warm-up trial), ratios medians
of the ratios within a round. The trials' distances are printed: the same trial or not. Exit 2 on a bad ``REV`` (not a
commit of this repository, or without ``benchmarks/humanoid.py``).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import random
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _floor import machine_load  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
FILED_AGAINST = "ee74889"  # issue 31's baseline: the last commit before the issue was filed


def git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


def trial_at(root: Path, seconds: float, kernel: str | None = None) -> dict:
    """One process: a warm-up trial and one timed trial of the checkout at ``root``."""
    args = [sys.executable, str(HERE / "_trial_at.py"), str(root), "1", str(seconds), *([kernel] if kernel else [])]
    done = subprocess.run(args, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"the trial of the code at {root} could not run: {last}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser()
    parser.add_argument("rev", nargs="?", default=FILED_AGAINST, help=f"the earlier revision (default {FILED_AGAINST})")
    parser.add_argument("--repeats", type=int, default=9, help="rounds")
    parser.add_argument("--seconds", type=float, default=16.0, help="simulated s of a trial (default 16)")
    args = parser.parse_args(argv)
    commit = git("rev-parse", "--verify", "--quiet", f"{args.rev}^{{commit}}").stdout.strip()
    if not commit:
        print(f"humanoid_against.py: REV: expected a commit of {ROOT}, got {args.rev!r}", file=sys.stderr)
        raise SystemExit(2)
    if git("cat-file", "-e", f"{commit}:benchmarks/humanoid.py").returncode != 0:
        print(f"humanoid_against.py: REV: {args.rev} has no benchmarks/humanoid.py to build its trial", file=sys.stderr)
        raise SystemExit(2)
    items = ["rev", "b"] + (["b-numba"] if importlib.util.find_spec("numba") is not None else [])
    print(f"before: {machine_load()}", flush=True)
    with tempfile.TemporaryDirectory(prefix="sfl-against-") as tmp:
        tree = Path(tmp) / "rev"
        added = git("worktree", "add", "--detach", "--quiet", str(tree), commit)
        if added.returncode != 0:
            raise RuntimeError(f"git worktree add failed: {added.stderr}")
        try:
            where = {"rev": (tree, None), "b": (ROOT, None), "b-numba": (ROOT, "numba")}
            runs: dict[str, list[dict]] = {item: [] for item in items}
            rounds = random.Random(0)
            try:
                for _ in range(args.repeats):
                    order = list(items)
                    rounds.shuffle(order)
                    for item in order:
                        root, kernel = where[item]
                        runs[item].append(trial_at(root, args.seconds, kernel))
            except RuntimeError as e:
                print(f"humanoid_against.py: {e}", file=sys.stderr)
                raise SystemExit(2) from None
            print(f"after: {machine_load()}", flush=True)
        finally:
            git("worktree", "remove", "--force", str(tree))
    wall = {item: [r["wall"][0] for r in rs] for item, rs in runs.items()}
    cpu = {item: [r["cpu"][0] for r in rs] for item, rs in runs.items()}
    out: dict[str, float] = {}
    print(f"humanoid: one {args.seconds:g}-s trial in one process, {args.repeats} rounds, each item in its own process")
    names = {"rev": f"(rev) {args.rev} ({commit[:7]})", "b": "(b) this checkout", "b-numba": "(b-numba) compiled CPG"}
    for item in items:
        out[item] = statistics.median(wall[item])
        runs_item = runs[item][0]
        print(f"  {names[item]:<34} {out[item] * 1e3:7.1f} ms  (CPU {statistics.median(cpu[item]) * 1e3:7.1f} ms, "
              f"{args.seconds / out[item]:5.1f}x real time)  distance {runs_item['distance']!r}")  # fmt: skip
    same = runs["rev"][0]["distance"] == runs["b"][0]["distance"]
    print(f"  the same trial in both revisions: {'yes' if same else 'no'} (the numpy CPG's distances "
          f"{'equal' if same else 'differ'})")  # fmt: skip
    for item in items[1:]:
        ratio = statistics.median(a / b for a, b in zip(wall["rev"], wall[item], strict=True))
        out[f"rev/{item}"] = ratio
        print(f"  (rev)/({item}) = {ratio:.2f}x  (issue 31's goal for a one-process trial: >= 1.4x)")
    return out


if __name__ == "__main__":
    main()
