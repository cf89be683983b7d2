"""The conditions protocol: each condition x grid point x repeat run as a trial, judged survived or not."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .. import messages as m
from ..events import Progress
from .conductor import Conductor
from .service import RunError


@dataclass(frozen=True)
class Case:
    """One trial of a conditions protocol: the condition it runs under, its point of the grid (trial parameter ->
    value) and its repeat (which start)."""

    condition: str
    point: dict
    repeat: int


def condition_cases(proto) -> list[Case]:
    """Every trial of a conditions protocol, in the order they are run: condition by condition (as the file lists
    them), the grid's points in order (its last key varying fastest), the repeats of each point."""
    keys = list(proto.grid)
    points = [dict(zip(keys, values, strict=True)) for values in itertools.product(*proto.grid.values())]
    return [Case(name, point, r) for name in proto.conditions for point in points for r in range(proto.repeats)]


def repeat_seed(run_seed: int, repeat: int) -> int:
    """Seed of every trial of repeat ``repeat`` in a conditions protocol: one start per repeat, the same in every
    condition and at every grid point (paired comparisons)."""
    return int(np.random.SeedSequence([run_seed, 11, repeat]).generate_state(1)[0])


def survived(judge: str, result: m.TrialResult) -> bool:
    """A trial's verdict for a conditions protocol: the body's success, or (``upright``) no fall."""
    if judge == "success":
        return bool(result.success)
    fell = result.metrics.get("fell")
    if not isinstance(fell, bool):
        raise RunError(
            f"protocol.judge is 'upright' but the body reports no metric `fell` (true/false); it reports "
            f"{sorted(result.metrics)}"
        )
    return not fell


def run_conditions(c: Conductor) -> dict:
    """A set of trials under named conditions (E4.3-E4.7, E5.3): every condition x grid point x repeat, fanned out
    over the body workers, no learning. Each row holds its condition, repeat, the trial parameters the condition and
    the grid set, and whether the trial ``survived`` (``protocol.judge``)."""
    proto = c.plan.scenario.protocol
    cases = condition_cases(proto)
    progress = Progress(planned=len(cases))
    base: dict[str, dict] = {"body": {}, "controller": {}}
    for key, value in c.plan.scenario.conditions.items():  # the scenario's own conditions: every trial
        owner, _, param = key.partition(".")
        base[owner][param] = value

    def request(trial_id: int, case: Case) -> m.TrialRequest:
        params = {"body": dict(base["body"]), "controller": dict(base["controller"])}
        given = {**proto.conditions[case.condition], **case.point}
        for target, source in proto.follow.items():  # a parameter that takes another's value (follow)
            if source in given:
                given[target] = given[source]
        for key, value in given.items():
            owner, _, param = key.partition(".")
            params[owner][param] = value
        return m.TrialRequest(
            trial_id=trial_id,
            seed=repeat_seed(c.plan.scenario.seed, case.repeat),
            body_params=params["body"],
            controller_params=params["controller"],
            log=c.should_log_body(trial_id),
        )

    requests = (request(i, case) for i, case in enumerate(cases))
    for sent, result, wall in c.trials(requests):
        case = cases[sent.trial_id]
        fields = {"condition": case.condition, "repeat": case.repeat, **proto.conditions[case.condition], **case.point}
        verdict = {"survived": survived(proto.judge, result)}
        c.record_trial(progress, sent.trial_id, result, wall, fields, verdict)
    return {
        "planned_trials": len(cases),
        "stop_reason": f"every condition, grid point and repeat run ({len(cases)} trials)",
    }
