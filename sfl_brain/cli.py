"""The ``sfl`` command: run, check, study, list, inspect, worker, report."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from . import __version__
from .scenario.errors import ScenarioError
from .scenario.plan import load
from .status import EXIT_BAD_INPUT, EXIT_CODES, EXIT_ENVIRONMENT, BadInput, EnvironmentProblem, RunStatus


def _load_or_exit(scenario: str, overrides: tuple[str, ...] = (), seed: int | None = None):
    try:
        return load(scenario, list(overrides), seed)
    except ScenarioError as exc:
        click.echo(f"sfl: invalid scenario\n{exc}", err=True)
        sys.exit(EXIT_BAD_INPUT)


def exit_process(code: int) -> None:
    """End the command with ``code``: ``rrlog.exit_process`` (a recording a full disk has stuck is not waited for)."""
    from .recording.rrlog import exit_process as leave

    leave(code)


def _start_or_exit(start):
    """Run ``start()``; a problem found before the run exists ends the command with one line."""
    try:
        return start()
    except BadInput as exc:
        click.echo(f"sfl: {exc}", err=True)
        sys.exit(EXIT_BAD_INPUT)
    except EnvironmentProblem as exc:
        click.echo(f"sfl: {exc}", err=True)
        sys.exit(EXIT_ENVIRONMENT)


@click.group(
    context_settings={"help_option_names": ["-h", "--help"]},
    epilog="Exit codes: 0 completed, 1 failed, 2 bad input, 3 stalled, 4 environment "
    "(port in use, run folder not writable, disk full, no display), 130 interrupted.",
)
@click.version_option(__version__, "--version", prog_name="sfl-brain", message="%(prog)s %(version)s")
@click.option(
    "--log-level",
    type=click.Choice(["DEBUG", "INFO", "WARNING", "ERROR"], case_sensitive=False),
    default=None,
    help="log level of the supervisor (stderr; default WARNING) and of every module process (logs/*.log; "
    "default INFO); also env SFL_LOG_LEVEL",
)
def main(log_level: str | None) -> None:
    """sfl-brain: success-failure learning for robots, as processes over Zenoh, recorded in Rerun."""
    import logging
    import os

    if log_level:
        os.environ["SFL_LOG_LEVEL"] = log_level.upper()  # the module processes inherit it
    logging.basicConfig(
        level=os.environ.get("SFL_LOG_LEVEL", "WARNING"), format="%(asctime)s sfl %(levelname)s %(message)s"
    )


@main.command()
@click.argument("scenario", type=click.Path(dir_okay=False))
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE", help="override a scenario value")
def check(scenario: str, overrides: tuple[str, ...]) -> None:
    """Validate SCENARIO without starting anything (exit 2 on problems)."""
    plan = _load_or_exit(scenario, overrides)
    procs = ", ".join(i.name + (f" (+{i.colocated.name})" if i.colocated else "") for i in plan.instances)
    proto = plan.scenario.protocol
    shape = (
        f"{len(proto.conditions)} conditions x {proto.trials // len(proto.conditions) // proto.repeats} grid points x "
        f"{proto.repeats} repeats = {proto.trials} trials"
        if proto.kind == "conditions"
        else f"{plan.dim}-D space"
    )
    click.echo(f"{scenario}: ok — protocol {proto.kind}, {shape}, processes: {procs}")


@main.command("run")
@click.argument("scenario", type=click.Path(dir_okay=False), required=False)
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE", help="override a scenario value")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=None, help="override the scenario's seed")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None, help="run folder")
@click.option("--viewer", is_flag=True, help="stream to a live Rerun viewer (spawned on 127.0.0.1)")
@click.option("--viewer-url", default=None, help="stream to an already running viewer at this gRPC url")
@click.option("--realtime", is_flag=True, help="pace the body to wall-clock time")
@click.option("--listen", multiple=True, help="Zenoh endpoint to listen on (default: a free 127.0.0.1 port)")
@click.option("--connect", multiple=True, help="Zenoh endpoint to connect to")
@click.option(
    "--zenoh-config",
    type=click.Path(dir_okay=False, exists=True),
    default=None,
    help="a Zenoh JSON5 config merged under sfl's own (TLS for network endpoints; docs/reliability.md)",
)
@click.option(
    "--resume",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="go on with the interrupted learn run in this folder (its own scenario.yaml; no SCENARIO)",
)
@click.option("--quiet", is_flag=True, help="no progress bar")
def run_command(
    scenario, overrides, seed, out, viewer, viewer_url, realtime, listen, connect, zenoh_config, resume, quiet
) -> None:
    """Run SCENARIO: one process per module, until the protocol completes (--resume RUN_DIR: go on with an
    interrupted learn run, replaying its recorded trials first)."""
    resumed = None
    if resume is not None:
        from .runtime.run import prepare_resume

        options = (("SCENARIO", scenario), ("--set", overrides), ("--seed", seed), ("--out", out))
        given = [name for name, value in options if value not in (None, ())]
        if given:
            click.echo(f"sfl: --resume runs the folder's own scenario.yaml; drop {', '.join(given)}", err=True)
            sys.exit(EXIT_BAD_INPUT)
        plan, resumed = _start_or_exit(lambda: prepare_resume(resume))
        scenario, out = str(resume / "scenario.yaml"), resume
    elif scenario is None:
        click.echo("sfl: run needs a SCENARIO (or --resume RUN_DIR)", err=True)
        sys.exit(EXIT_BAD_INPUT)
    else:
        plan = _load_or_exit(scenario, overrides, seed)
    # the runtime (Zenoh, Rerun, pyarrow: about 1.5 s of imports) only once the scenario is known to be good
    from .recording.budget import TimeBudget, process_age
    from .runtime.progress import ProgressView
    from .runtime.run import run

    budget = TimeBudget(launched=process_age())  # the time budget's start-up begins at this process's launch

    view = ProgressView(plan, enabled=not quiet)

    def ready(sup, seconds):
        view.ready(seconds)
        if listen:
            from .runtime.worker import join_command

            join = join_command(
                scenario,
                listen[0],
                sup.run_id,
                overrides=overrides,
                seed=plan.scenario.seed,
                secret_file=sup.secret_file,
            )
            click.echo(f"sfl: run id {sup.run_id}; workers may join with: {join}")

    with view:
        run_dir, summary = _start_or_exit(
            lambda: run(
                plan,
                out,
                viewer=viewer_url or viewer,
                realtime=realtime,
                listen=list(listen) or None,
                connect=list(connect) or None,
                on_progress=view.update,
                on_ready=ready,
                zenoh_config=zenoh_config,
                resume=resumed,
                budget=budget,
            )
        )
    view.report(run_dir, summary)
    exit_process(summary["exit_code"])


def _study_options(command):
    """--k, --distinct and --window: what the study report measures (``sfl study`` and ``sfl report``)."""
    from .recording.metrics import DISTINCT, K_GOOD
    from .study.study import WINDOW

    command = click.option(
        "--window", type=int, default=WINDOW, show_default=True, help="trials in the success rate's moving window"
    )(command)
    command = click.option(
        "--distinct",
        type=float,
        default=DISTINCT,
        show_default=True,
        help="distance (unit cube) from every good gait before it that makes a success a new good gait",
    )(command)
    return click.option(
        "--k", "k", type=int, default=K_GOOD, show_default=True, help="count failures before K distinct good gaits"
    )(command)


def _check_study_options(k: int, distinct: float, window: int) -> None:
    """Exit 2 in one line on a study report setting out of range."""
    checks = (("--k", k, k >= 1), ("--distinct", distinct, distinct > 0), ("--window", window, window >= 1))
    for name, value, ok in checks:
        if not ok:
            click.echo(f"sfl: {name} {value}: expected more than 0", err=True)
            sys.exit(EXIT_BAD_INPUT)


def _study_settings(k: int, distinct: float, window: int, said: dict | None = None):
    """The study report's settings (checked)."""
    from .report.study import StudySettings

    _check_study_options(k, distinct, window)
    return StudySettings(k=k, distinct=distinct, window=window, said=said or {})


@main.command()
@click.argument("scenario", type=click.Path(dir_okay=False))
@click.option("--vary", "vary", multiple=True, metavar="KEY.PATH=V1,V2,...", help="values to run (one run each)")
@click.option("--seeds", default="", metavar="S1,S2,...", help="seeds to run each value with")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE", help="override for every run")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True, help="study folder")
@click.option("--jobs", type=int, default=1, show_default=True, help="runs at once on this machine")
@click.option(
    "--cluster",
    default=None,
    metavar="ADDRESS",
    help="run on a Dask cluster: its scheduler's address (tcp://host:port) or scheduler file (sfl-brain[cluster])",
)
@_study_options
@click.option("--quiet", is_flag=True, help="plain lines instead of the progress view")
def study(scenario, vary, seeds, overrides, out, jobs, cluster, k, distinct, window, quiet) -> None:
    """Run SCENARIO once per combination of --vary values and --seeds, then report them together.

    Every combination is checked before the first run starts. Runs go to OUT/<name> (--jobs at once, or as tasks
    on a Dask cluster with --cluster); the figures and the table go to OUT/report: the groups of runs (by what was
    varied) compared on learning curves and failures before K good gaits, and the success rate against vigilance.
    Run again, the study keeps every run that ended completed or stalled and runs the others again from scratch
    (their old folders moved to OUT/attempts/). A run that did not complete is named at the end, marked in the
    report and left out of every mean. The exit code is the worst run's: 1 if any failed, else 3 if any stalled;
    130 when interrupted (run the same command to resume).
    """
    from .report.report import write_report
    from .study.cluster import DaskRunner, connect
    from .study.study import (
        FINAL,
        LocalRunner,
        StudyInterrupted,
        kept_outcomes,
        plan_study,
        run_study,
        triage,
        write_manifest,
    )
    from .study.view import StudyView

    if jobs < 1:
        click.echo(f"sfl: --jobs {jobs}: expected 1 or more runs at once", err=True)
        sys.exit(EXIT_BAD_INPUT)
    ctx = click.get_current_context()
    if cluster is not None and ctx.get_parameter_source("jobs") != click.core.ParameterSource.DEFAULT:
        click.echo("sfl: --jobs and --cluster: choose one (a cluster runs as many at once as it has threads)", err=True)
        sys.exit(EXIT_BAD_INPUT)
    _check_study_options(k, distinct, window)  # before anything runs
    try:
        planned = plan_study(scenario, vary, seeds, overrides)
    except BadInput as exc:
        click.echo(f"sfl: {exc}", err=True)
        sys.exit(EXIT_BAD_INPUT)
    except ScenarioError as exc:
        click.echo(f"sfl: invalid scenario\n{exc}", err=True)
        sys.exit(EXIT_BAD_INPUT)
    runs = [run for run, _ in planned]
    runner = (
        DaskRunner(_start_or_exit(lambda: connect(cluster)), out, {r.name: p for r, p in planned})
        if cluster is not None
        else LocalRunner(scenario, out, jobs)
    )
    try:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            click.echo(f"sfl: cannot write the study folder {out}: {exc.strerror or exc}", err=True)
            sys.exit(EXIT_ENVIRONMENT)
        held = _start_or_exit(lambda: triage(out, planned))
        kept = kept_outcomes(out, held.kept)
        command = {
            "scenario": str(scenario),
            "vary": list(vary),
            "seeds": seeds,
            "set": list(overrides),
            "k": k,
            "distinct": distinct,
            "window": window,
        }
        write_manifest(out, command, runs, kept)
        click.echo(
            f"sfl: study of {len(runs)} runs into {out}: {len(held.todo)} to run ({runner.describe()})"
            + (f", {len(kept)} kept from before (completed or stalled)" if kept else "")
        )
        for name, status, where in held.moved:
            click.echo(f"sfl: {name} was {status}: its folder moved to {where}; it runs again from scratch")
        interrupted = None
        with StudyView(runs, kept, quiet) as view:
            try:
                outcomes = run_study(held.todo, runner, view.show)
            except StudyInterrupted as stop:
                outcomes, interrupted = stop.outcomes, stop
    finally:
        runner.close()
    outcomes = {**kept, **outcomes}
    write_manifest(out, command, runs, outcomes)
    if interrupted is not None:
        stopped = [r.name for r in runs if r.name not in outcomes or outcomes[r.name].status not in FINAL]
        click.echo(
            f"sfl: study interrupted; {len(runs) - len(stopped)} of {len(runs)} runs are done and kept. The same "
            f"command resumes it: the {len(stopped)} others run again from scratch ({', '.join(stopped)})",
            err=True,
        )
        exit_process(EXIT_CODES[RunStatus.INTERRUPTED])
    folders = [out / r.name for r in runs if (out / r.name / "scenario.yaml").exists()]
    said = {n: f"{o.status}: {o.reason}" for n, o in outcomes.items() if o.status != RunStatus.COMPLETED}
    if folders:
        path = write_report(folders, out / "report", study=_study_settings(k, distinct, window, said))
        click.echo(f"sfl: report written to {path}")
    unfinished: dict[str, list[str]] = {}
    for run in runs:
        if outcomes[run.name].status != RunStatus.COMPLETED:
            unfinished.setdefault(outcomes[run.name].status, []).append(run.name)
    for status, names in unfinished.items():
        click.echo(
            f"sfl: {len(names)} of {len(runs)} runs {status}, marked in the report and left out of its means: "
            f"{', '.join(names)}",
            err=True,
        )
    for status in (RunStatus.FAILED, RunStatus.STALLED):
        if status in unfinished:
            exit_process(EXIT_CODES[status])
    exit_process(0)


@main.command("list")
@click.argument("name", required=False)
def list_command(name: str | None) -> None:
    """Show the registered module and body implementations, or one of them in full (NAME: a
    registered name, package.module:Class or file.py:Class): its parameters and, for a body, its
    sensor and command signals; for a controller, what it reads and writes."""
    from .body import Body, Controller
    from .registry import ImplError, registered, resolve

    if name is not None:
        try:
            cls, reference = resolve(name, Path.cwd())
        except ImplError as exc:
            hint = f" (did you mean `{exc.suggestion}`?)" if exc.suggestion else ""
            click.echo(f"sfl: {exc}{hint}; registered: {', '.join(sorted(registered()))}", err=True)
            sys.exit(EXIT_BAD_INPUT)
        for line in _describe(cls, reference):
            click.echo(line)
        return
    rows = []
    for key, reference in sorted(registered().items()):
        try:
            cls, _ = resolve(key)
        except Exception as exc:  # a broken third-party entry point must not hide the others
            rows.append((key, "?", f"cannot load {reference}: {exc}"))
            continue
        kind = "body" if issubclass(cls, Body) else "controller" if issubclass(cls, Controller) else "brain"
        rows.append((key, kind, cls.describe()))
    width = max(len(r[0]) for r in rows) if rows else 0
    for key, kind, text in rows:
        click.echo(f"{key:<{width}}  {kind:<10}  {text}")
    click.echo("\nsfl list NAME shows one in full (parameters, signals).")


def _describe(cls, reference: str) -> list[str]:
    """The lines of ``sfl list NAME``."""
    from .body import Body, Controller
    from .signals import table

    lines = [f"{cls.__name__} ({reference}): {cls.describe()}", "", "parameters (params:)"]
    for key, field in cls.Params.model_fields.items():
        default = field.get_default(call_default_factory=True)
        lines.append(f"  {key} = {default!r}" + (f"  {field.description}" if field.description else ""))
    if issubclass(cls, Body):
        if cls.SENSORS:
            lines += ["", *table(cls.SENSORS, "sensors (one tick, in this order)")]
        if cls.COMMANDS:
            lines += ["", *table(cls.COMMANDS, "commands (one tick, in this order)")]
        if not cls.COMMANDS:
            lines += ["", "takes no commands: it needs no controller"]
        if cls.METRICS:
            shown = ", ".join(f"{name} ({unit})" if unit else name for name, unit in cls.METRICS.items())
            lines += ["", f"trial metrics (m_<metric> columns): {shown}"]
    if issubclass(cls, Controller):
        reads, writes = cls.signals(cls.Params())  # a CPG's depend on its circuit: here the default one's
        depends = " (with the default parameters)" if (reads, writes) != (cls.READS, cls.WRITES) else ""
        lines += [
            "",
            f"reads sensors{depends}:  {', '.join(reads) or '(none)'}",
            f"writes commands{depends}: {', '.join(writes) or '(none)'}",
        ]
        if cls.NEURONS:
            lines.append(f"neurons shown on logged trials: {len(cls.NEURONS)} ({', '.join(cls.NEURONS[:4])}, ...)")
    if getattr(cls, "TRIAL_PARAMS", ()):
        lines += ["", f"trial parameters (space targets, conditions): {', '.join(cls.TRIAL_PARAMS)}"]
    return lines


@main.command()
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="print the summary as one JSON object")
def inspect(run_dir: Path, as_json: bool) -> None:
    """Summarise a finished or interrupted run."""
    from .recording.records import inspect_run

    try:
        summary = inspect_run(run_dir)
    except FileNotFoundError as exc:
        click.echo(f"sfl: {exc}", err=True)
        sys.exit(EXIT_BAD_INPUT)
    except OSError as exc:
        click.echo(f"sfl: cannot read {run_dir}: {exc.strerror or exc}", err=True)
        sys.exit(EXIT_ENVIRONMENT)
    if as_json:
        click.echo(json.dumps(summary))
        return
    budget = summary.pop("time_budget", None)
    width = max(16, *map(len, summary))
    for k, v in summary.items():
        click.echo(f"{k:>{width}}: {v:.4g}" if isinstance(v, float) else f"{k:>{width}}: {v}")
    if budget is not None:
        from .recording.budget import budget_lines

        click.echo(f"{'time_budget':>{width}}: where the wall time went (seconds, share)")
        for line in budget_lines(budget):
            click.echo(f"{'':>{width - 8}}{line}")


@main.command()
@click.argument("scenario", type=click.Path(dir_okay=False))
@click.option("--connect", required=True, multiple=True, help="the run's Zenoh endpoint")
@click.option("--run-id", required=True, help="the run id printed by sfl run")
@click.option("--name", default="ext0", help="worker suffix (unique per worker)")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE", help="the run's --set overrides")
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=None, help="the run's --seed")
@click.option(
    "--secret-file",
    type=click.Path(dir_okay=False),
    default=None,
    help="file holding the run secret (the run folder's `secret`); default: $SFL_RUN_SECRET",
)
@click.option("--wait", type=click.FloatRange(0, None), default=30.0, show_default=True, help="s to wait for the run")
@click.option("--zenoh-config", type=click.Path(dir_okay=False), default=None, help="Zenoh JSON5 config (TLS, ...)")
def worker(scenario, connect, run_id, name, overrides, seed, secret_file, wait, zenoh_config) -> None:
    """Serve trials for a running run: a body worker with its controller in this process.

    Exits 0 when the run ends, 130 on Ctrl-C, 1 if no run answers within --wait seconds."""
    from .runtime.worker import WorkerError, resolve_secret, run_worker

    plan = _load_or_exit(scenario, overrides, seed)
    try:
        secret = resolve_secret(secret_file)
        code = run_worker(
            plan, list(connect), run_id, name, secret=secret, wait=wait, zenoh_config=zenoh_config, say=click.echo
        )
    except WorkerError as exc:
        click.echo(f"sfl worker: {exc}", err=True)
        code = exc.code
    sys.exit(code)


@main.command()
@click.argument("run_dirs", nargs=-1, required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="where to write (default: STUDY_DIR/report for one study folder, else docs/results)",
)
@_study_options
def report(run_dirs, out, k, distinct, window) -> None:
    """Write the figures (PNG) and a Markdown table of RUN_DIRS to OUT.

    A study folder (made by sfl study) stands for its runs, and the page starts with the study's groups compared
    (learning curves, failures before K good gaits, a table of means with 95 % intervals); so does a page of learn
    runs whose scenarios differ by more than the seed (e.g. a cma run and a tpe run)."""
    from .recording.records import run_status
    from .report.report import write_report
    from .report.study import differ, is_study, study_runs

    folders, said, studies = [], {}, []
    for run_dir in run_dirs:
        if run_dir.is_dir() and is_study(run_dir):
            found, seen = study_runs(run_dir)
            folders += found
            said.update(seen)
            studies.append(run_dir)
            if not found:
                click.echo(f"sfl: {run_dir}: a study folder with no run folder in it", err=True)
                sys.exit(EXIT_BAD_INPUT)
        elif not (run_dir / "scenario.yaml").exists():
            click.echo(f"sfl: {run_dir}: no scenario.yaml (is this a run folder or a study folder?)", err=True)
            sys.exit(EXIT_BAD_INPUT)
        else:
            folders.append(run_dir)
    # runs that differ by more than the seed (a cma run and a tpe run) are compared as a study's groups are
    settings = _study_settings(k, distinct, window, said) if studies or differ(folders) else None
    if out is None:
        out = studies[0] / "report" if len(studies) == 1 and len(run_dirs) == 1 else Path("docs/results")
    for run_dir in folders:
        status, why = run_status(run_dir)
        if status != RunStatus.COMPLETED:
            click.echo(f"sfl: {run_dir} is {status} ({why}): marked in the report, left out of its means", err=True)
    for name in set(said) - {f.name for f in folders}:
        click.echo(f"sfl: {name} has no run folder ({said[name]}): named in the report, in none of its means", err=True)
    path = write_report(folders, out, study=settings)
    click.echo(f"sfl: report written to {path}")


if __name__ == "__main__":
    main()
