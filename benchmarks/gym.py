"""The Gymnasium door's tick against the body's own: what ``sfl/Tick-v0`` adds to ``actuate`` + ``sense``.

    python benchmarks/gym.py [--rounds 15] [--block 200] [--vector 4000]     (tiny: --rounds 2 --block 20 --vector 0)

For the chapter-3 planar walker (``scenarios/quickstart.yaml``) and the humanoid (``scenarios/humanoid_walk.yaml``),
the same fixed sequence of random commands (drawn once from the action space, seed 0), in blocks of ``--block`` steps
taken in turn by every variant, ``--rounds`` rounds; a trial that ends (a fall, the time limit) is restarted untimed:

(a) the body alone: ``body.actuate(command)`` then ``body.sense()``, what any agent needs from the body;
(b) ``TickEnv.step`` called directly (no Gymnasium wrapper): (a) plus the checks of the action, the reward, the
    end of the trial and the observation;
(c) ``gymnasium.make("sfl/Tick-v0")``: (b) behind Gymnasium's wrappers (order enforcing, the passive checker);
(d) (c) with ``normalize=True``: actions in [-1, 1] and observations scaled by the declared ranges.

Times are medians over the rounds of the CPU time per step (``time.process_time``: what this process spent, whatever
else the machine runs); ratios are medians of the ratios within each round. Goal (issue 32): (c) / (a) <= 1.15.

Then, with ``--vector N`` steps per env (0: skipped), steps per wall-clock second of a vector of Tick-v0 planar
walkers in processes of their own (``gymnasium.vector.AsyncVectorEnv``), 1 env and one per usable core, and the
speed-up: how a vector env scales with cores on this machine. The load average is printed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import gymnasium as gym  # noqa: E402
from _floor import machine_load  # noqa: E402

import sfl_brain.gym  # noqa: E402, F401  (registers the ids)
from sfl_brain.runtime.placement import usable_cpus  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BODIES = (
    ("planar walker", ROOT / "scenarios" / "quickstart.yaml"),
    ("humanoid", ROOT / "scenarios" / "humanoid_walk.yaml"),
)


class Variant:
    """One way of stepping: ``step(i)`` takes the i-th command; ``restart()`` starts a new trial (untimed)."""

    def __init__(self, name: str, env, actions: np.ndarray, raw: bool = False, body_only: bool = False) -> None:
        self.name, self.env, self.actions = name, env, actions
        self.unwrapped = env.unwrapped
        self.raw, self.body_only = raw, body_only
        self.i = 0
        self.env.reset(seed=0)

    def block(self, n: int) -> float:
        """CPU seconds per step over ``n`` steps (restarts excluded)."""
        spent, taken = 0.0, 0
        actions, env = self.actions, self.env
        step = self.unwrapped.step if self.raw else env.step
        body = self.unwrapped.body
        while taken < n:
            start = time.process_time()
            ended = False
            while taken < n and not ended:
                command = actions[self.i % len(actions)]
                self.i += 1
                taken += 1
                if self.body_only:
                    body.actuate(command)
                    body.sense()
                    ended = body.done
                else:
                    _, _, terminated, truncated, _ = step(command)
                    ended = terminated or truncated
            spent += time.process_time() - start
            if ended:
                env.reset()
        return spent / n


def door_vs_body(rounds: int, block: int) -> None:
    for label, scenario in BODIES:
        plain = gym.make("sfl/Tick-v0", scenario=str(scenario))
        rng = np.random.default_rng(0)
        space = plain.action_space
        actions = rng.uniform(space.low, space.high, (2000, space.shape[0])).astype(space.dtype)
        normalized = gym.make("sfl/Tick-v0", scenario=str(scenario), normalize=True)
        unit = (2.0 * (actions - space.low) / (space.high - space.low) - 1.0).astype(normalized.action_space.dtype)
        variants = [
            Variant(
                "(a) body: actuate + sense", gym.make("sfl/Tick-v0", scenario=str(scenario)), actions, body_only=True
            ),
            Variant("(b) TickEnv.step, unwrapped", gym.make("sfl/Tick-v0", scenario=str(scenario)), actions, raw=True),
            Variant("(c) gymnasium.make('sfl/Tick-v0')", plain, actions),
            Variant("(d) (c) with normalize=True", normalized, unit),
        ]
        for v in variants:  # warm up: first calls, the passive checker's one-time checks
            v.block(block // 4 + 1)
        samples: dict[str, list[float]] = {v.name: [] for v in variants}
        order = np.random.default_rng(1)
        for _ in range(rounds):
            for k in order.permutation(len(variants)):
                samples[variants[k].name].append(variants[k].block(block))
        base = np.array(samples[variants[0].name])
        print(f"\n{label} ({scenario.name}), {rounds} rounds of {block} steps, CPU time per step:")
        for v in variants:
            s = np.array(samples[v.name])
            ratio = np.median(s / base)
            print(
                f"  {v.name:38s} median {np.median(s) * 1e6:8.1f} us   {1 / np.median(s):8.0f} steps/CPU s"
                f"   / (a) {ratio:5.2f}"
            )
        for v in variants:
            v.env.close()


def vector_scaling(steps: int, rounds: int = 3) -> None:
    """Steps per wall second of 1 env and of one env per usable core, measured in turn ``rounds`` times (medians).
    Every env of both vectors is given the same actions, so each walks the same episodes (falls and resets alike)
    and the two vectors do the same work per env."""
    cores = len(usable_cpus()) or os.cpu_count() or 1
    scenario = str(BODIES[0][1])
    print(
        f"\nvector env of Tick-v0 planar walkers (AsyncVectorEnv, a process each), {steps} steps per env, "
        f"the same actions in every env, {rounds} rounds in turn:"
    )
    sizes = sorted({1, cores})
    envs = {
        n: gym.vector.AsyncVectorEnv([lambda: gym.make("sfl/Tick-v0", scenario=scenario) for _ in range(n)])
        for n in sizes
    }
    space = envs[1].single_action_space
    actions = np.random.default_rng(0).uniform(space.low, space.high, (256, space.shape[0]))
    rates: dict[int, list[float]] = {n: [] for n in sizes}
    try:
        for _ in range(rounds):
            for n, env in envs.items():
                env.reset(seed=0)
                for i in range(50):
                    env.step(np.repeat(actions[i % 256][None], n, axis=0))
                start = time.perf_counter()
                for i in range(steps):
                    env.step(np.repeat(actions[i % 256][None], n, axis=0))
                rates[n].append(n * steps / (time.perf_counter() - start))
    finally:
        for env in envs.values():
            env.close()
    for n in sizes:
        each = ", ".join(f"{r:.0f}" for r in rates[n])
        print(f"  {n} env{'s' if n > 1 else ' '}: median {np.median(rates[n]):8.0f} steps per wall s ({each})")
    if cores > 1:
        ratio = np.median(rates[cores]) / np.median(rates[1])
        print(f"  speed-up with {cores} envs on {cores} usable cores: {ratio:.2f}x (ideal {cores}x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--block", type=int, default=200)
    parser.add_argument("--vector", type=int, default=4000, help="steps per env of the vector test (0: skip it)")
    args = parser.parse_args()
    print(f"load average before: {machine_load()}")
    door_vs_body(args.rounds, args.block)
    if args.vector:
        vector_scaling(args.vector)
    print(f"\nload average after: {machine_load()}")


if __name__ == "__main__":
    main()
