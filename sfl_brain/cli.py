"""The ``sfl`` command: run, check, study, list, inspect, worker, report."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from . import __version__
from .scenario import ScenarioError, load
from .status import EXIT_BAD_INPUT, EXIT_CODES, EXIT_ENVIRONMENT, BadInput, EnvironmentProblem, RunStatus


def _load_or_exit(scenario: str, overrides: tuple[str, ...] = (), seed: int | None = None):
    try:
        return load(scenario, list(overrides), seed)
    except ScenarioError as exc:
        click.echo(f"sfl: invalid scenario\n{exc}", err=True)
        sys.exit(EXIT_BAD_INPUT)


def exit_process(code: int) -> None:
    """End the command with ``code``: ``rrlog.exit_process`` (a recording a full disk has stuck is not waited for)."""
    from .rrlog import exit_process as leave

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
@click.argument("scenario", type=click.Path(dir_okay=False))
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
@click.option("--quiet", is_flag=True, help="no progress bar")
def run_command(
    scenario, overrides, seed, out, viewer, viewer_url, realtime, listen, connect, zenoh_config, quiet
) -> None:
    """Run SCENARIO: one process per module, until the protocol completes."""
    from .progress import ProgressView
    from .run import run

    plan = _load_or_exit(scenario, overrides, seed)
    view = ProgressView(plan, enabled=not quiet)

    def ready(sup, seconds):
        view.ready(seconds)
        if listen:
            from .worker import join_command

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
            )
        )
    view.report(run_dir, summary)
    exit_process(summary["exit_code"])


@main.command()
@click.argument("scenario", type=click.Path(dir_okay=False))
@click.option("--vary", "vary", multiple=True, metavar="KEY.PATH=V1,V2,...", help="values to run (one run each)")
@click.option("--seeds", default="", metavar="S1,S2,...", help="seeds to run each value with")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE", help="override for every run")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True, help="study folder")
@click.option("--quiet", is_flag=True, help="no progress bar")
def study(scenario, vary, seeds, overrides, out, quiet) -> None:
    """Run SCENARIO once per combination of --vary values and --seeds, then report them together.

    Every combination is checked before the first run starts. Runs go to OUT/<name>; the
    figures and the table (with success rate against vigilance) go to OUT/report. A run that did
    not complete (stalled, failed) is marked in the table and left out of every mean. The exit
    code is the worst run's: 1 if any failed, else 3 if any stalled.
    """
    import itertools

    from .progress import ProgressView
    from .report import write_report
    from .run import run

    axes = []
    for item in vary:
        key, sep, values = item.partition("=")
        if not sep or not values:
            click.echo(f"sfl: --vary {item!r}: expected KEY.PATH=V1,V2,...", err=True)
            sys.exit(EXIT_BAD_INPUT)
        axes.append([(key, v) for v in values.split(",")])
    try:
        seed_list = [int(x) for x in seeds.split(",") if x.strip()] or [None]
    except ValueError:
        click.echo(f"sfl: --seeds {seeds!r}: expected integers separated by commas", err=True)
        sys.exit(EXIT_BAD_INPUT)
    runs = []
    for combo in itertools.product(*axes):
        for seed in seed_list:
            sets = [*overrides, *(f"{k}={v}" for k, v in combo)]
            name = "_".join(f"{k.rsplit('.', 1)[-1]}{v}" for k, v in combo) or "run"
            name += "" if seed is None else f"_seed{seed}"
            runs.append((name, _load_or_exit(scenario, sets, seed)))
    click.echo(f"sfl: study of {len(runs)} runs into {out}")
    done: list[Path] = []
    unfinished: dict[str, list[str]] = {}
    for i, (name, plan) in enumerate(runs, 1):
        view = ProgressView(plan, enabled=not quiet)
        click.echo(f"sfl: [{i}/{len(runs)}] {name}")
        with view:
            run_dir, summary = _start_or_exit(
                lambda plan=plan, name=name, view=view: run(
                    plan, out / name, on_progress=view.update, on_ready=lambda sup, s, v=view: v.ready(s)
                )
            )
        view.report(run_dir, summary)
        if summary["status"] == RunStatus.INTERRUPTED:
            exit_process(summary["exit_code"])
        done.append(run_dir)
        if summary["status"] != RunStatus.COMPLETED:
            unfinished.setdefault(summary["status"], []).append(name)
    path = write_report(done, out / "report")
    click.echo(f"sfl: report written to {path}")
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
    from .records import inspect_run

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
    width = max(16, *map(len, summary))
    for k, v in summary.items():
        click.echo(f"{k:>{width}}: {v:.4g}" if isinstance(v, float) else f"{k:>{width}}: {v}")


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
    from .worker import WorkerError, resolve_secret, run_worker

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
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("docs/results"))
def report(run_dirs, out) -> None:
    """Write the figures (PNG) and a Markdown table of RUN_DIRS to OUT."""
    from .records import run_status
    from .report import write_report

    for run_dir in run_dirs:
        if not (run_dir / "scenario.yaml").exists():
            click.echo(f"sfl: {run_dir}: no scenario.yaml (is this a run folder?)", err=True)
            sys.exit(EXIT_BAD_INPUT)
    for run_dir in run_dirs:
        status, why = run_status(run_dir)
        if status != RunStatus.COMPLETED:
            click.echo(f"sfl: {run_dir} is {status} ({why}): marked in the report, left out of its means", err=True)
    path = write_report(list(run_dirs), out)
    click.echo(f"sfl: report written to {path}")


if __name__ == "__main__":
    main()
