"""``tsmpc sweep``: Monte-Carlo and parameter sweeps on Dask (issue 8)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import (
    PARTIAL_MARKER,
    check_environment,
    check_out_dir,
    console,
    deferred_interrupts,
    design_status,
    fail,
    finite,
    guarded_run,
    mark_partial,
    refuse_ineffective,
)
from tsmpc.errors import ConfigError


@app.command("sweep")
def sweep_cmd(
    sweep_file: Path = typer.Argument(..., help="Sweep file (TOML): base config, axes, duration."),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="Address of a running Dask scheduler (default: a LocalCluster)."),
    workers: int = typer.Option(2, "--workers", min=1, help="LocalCluster worker processes."),
    out: Path | None = typer.Option(None, "--out", help="Output folder (default: a new folder "
                                    "results/sweep, results/sweep-2, …; --resume needs it)."),
    resume: bool = typer.Option(False, "--resume", help="Skip runs whose record is already in --out "
                                "(unreadable records are set aside and re-run)."),
    retry_failed: bool | None = typer.Option(
        None, "--retry-failed/--no-retry-failed",
        help="With --resume: re-run the runs lost to worker failures [default: on]."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Skip the summary plots."),
    dry_run: bool = typer.Option(
        False, "--dry-run", help="Check the cluster plumbing: tasks sleep instead of simulating."),
    connect_timeout: float = typer.Option(
        5.0, "--connect-timeout", help="Seconds to wait for --scheduler before giving up."),
    max_runs: int = typer.Option(
        10_000, "--max-runs", min=1, max=100_000,
        help="Refuse a sweep with more runs than this (grid points × random draws)."),
    batch: int | None = typer.Option(
        None, "--batch", min=1, max=1024,
        help="Runs per Dask task, stepped together by the batched kernel [default: the sweep "
        "file's 'batch', 64]; 1: each run its own task, bit for bit as 'tsmpc run'."),
) -> None:
    """Run every point of a sweep as a Dask task; write one record per run, the aggregate table
    (CSV, Parquet) and summary plots."""
    from tsmpc.errors import TsmpcError
    from tsmpc.sweep import load_sweep

    con = console()
    from tsmpc.extras import MissingExtraError, require

    try:  # before any work (the batch kernel's compile takes minutes): a sweep needs Dask
        for module in ("distributed", "pandas", "pyarrow"):
            require(module, "tsmpc sweep")
    except MissingExtraError as err:
        fail(err)
    check_environment(kernels=not dry_run)
    finite("--connect-timeout", connect_timeout, lo=0.0, lo_open=True, hi=600.0)
    if workers > 64:
        fail(ConfigError(f"--workers = {workers}: at most 64 local worker processes"))
    refuse_ineffective({
        "workers": (scheduler is not None, "--scheduler runs the tasks on that cluster's workers"),
        "connect_timeout": (scheduler is None, "it bounds the wait for --scheduler (a local "
                            "cluster is started, not connected to)"),
        "retry_failed": (not resume, "failed records are retried only when resuming (--resume)"),
        "batch": (dry_run, "--dry-run tasks sleep instead of simulating, one run each"),
    })
    try:
        spec = load_sweep(sweep_file, max_runs=max_runs)  # every problem before any task starts
    except TsmpcError as err:
        fail(err)
    if batch is not None:
        spec = spec.model_copy(update={"batch": batch})
    if out is None and resume:
        fail(ConfigError("--resume needs --out: the folder of the sweep to finish"))
    if out is None:
        from tsmpc.cli._outdir import claim_default_out

        out = claim_default_out("sweep")
        created = True
    else:
        try:
            created = not out.exists()
        except OSError:  # e.g. a name too long: check_out_dir names the problem
            created = False
    if resume:
        check_out_dir(out, overwrite=True)  # records on disk are kept and skipped
    else:
        check_out_dir(out, overwrite=False, hint="pass --resume to finish the sweep in it")
    try:
        _sweep(con, spec, out, created, scheduler=scheduler, workers=workers, resume=resume,
               retry_failed=retry_failed, no_plots=no_plots, dry_run=dry_run,
               connect_timeout=connect_timeout)
    except BaseException:  # interrupted or failed: a folder this sweep made and left empty goes
        if created:
            _remove_if_empty(out)
        raise


def _remove_if_empty(out: Path) -> None:
    """Remove ``out`` (made by this sweep) when it holds no run record: only its marker, an
    empty ``runs/`` and ``sweep.json`` — nothing to resume, nothing to look at."""
    import shutil

    try:
        runs = out / "runs"
        if runs.is_dir() and any(runs.iterdir()):
            return
        if any(p.name not in (PARTIAL_MARKER, "runs", "sweep.json") and not p.name.startswith(".tsmpc-")
               for p in out.iterdir()):
            return
        shutil.rmtree(out)
    except OSError:
        pass  # leave it: PARTIAL says what it is


def _sweep(con: Any, spec: Any, out: Path, created: bool, *, scheduler: str | None, workers: int,
           resume: bool, retry_failed: bool | None, no_plots: bool, dry_run: bool,
           connect_timeout: float) -> None:
    """The sweep's work on its checked output folder ``out`` (see :func:`sweep_cmd`)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
    from rich.text import Text

    from tsmpc.errors import TsmpcError
    from tsmpc.sweep import base_config, expand, run_sweep, run_task
    from tsmpc.sweep import dry_run as dry_fn

    designs = None
    if not dry_run:  # one pair of designs serves every run: solved before any run starts
        try:
            designs = design_status(base_config(spec))
        except TsmpcError as err:
            if created and out.is_dir() and not any(out.iterdir()):  # leave no trace
                out.rmdir()
            fail(err)
    n = len(expand(spec))
    where = scheduler or f"a local cluster of {workers} worker processes"
    con.print(Text.assemble("sweep ", (spec.name, "bold"), f": {n} runs on {where} → {out}"))
    counts: dict[str, int] = {}
    with Progress(TextColumn("[bold]runs"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TextColumn("{task.description}", markup=False), TimeElapsedColumn(),
                  TimeRemainingColumn(), console=con) as progress:
        task = progress.add_task("", total=n)

        def on_record(done: int, total: int, rec: dict) -> None:
            counts[rec["status"]] = counts.get(rec["status"], 0) + 1
            progress.update(task, completed=done, description=" ".join(f"{k}={v}" for k, v in counts.items()))

        hint = f"the records finished so far are in {out / 'runs'}; finish the sweep with --resume"
        with guarded_run(out, what="sweep", on_interrupt=hint):
            mark_partial(out, "running")
            if not dry_run and scheduler is None:  # local workers share this machine's kernel cache
                from tsmpc import kernels

                with deferred_interrupts():  # numba/LLVM call back into Python: never raise there
                    kernels.warmup()
                    if spec.batch > 1:  # the batched-run kernel too (tsmpc.sim.batch)
                        from tsmpc.sim import batch

                        batch.warmup()
            try:
                res = run_sweep(spec, out, scheduler=scheduler, workers=workers, resume=resume,
                                run_fn=dry_fn if dry_run else run_task, progress=on_record,
                                plots=not no_plots, connect_timeout=connect_timeout,
                                design_fn=(lambda _cfg: designs) if designs else design_status,
                                retry_failed=retry_failed, shield=deferred_interrupts)
            except ConfigError as err:  # e.g. no scheduler answered: nothing ran
                (out / PARTIAL_MARKER).unlink(missing_ok=True)
                if created and not any(out.iterdir()):  # leave no trace of a sweep that never ran
                    out.rmdir()
                fail(err)
            progress.stop()
            _summary(con, spec.name, res, out)
            if not res.complete:  # the cluster lost tasks, or runs failed: not a finished sweep
                _unfinished(res, out)
            (out / PARTIAL_MARKER).unlink(missing_ok=True)


def _unfinished(res: Any, out: Path) -> None:
    """A sweep that ended without a result for every run: PARTIAL ``failed`` naming the runs
    (``missing``: no record; ``failed``: a record saying ``failed``) and one line, exit 1.
    ``--resume`` runs exactly those."""
    from tsmpc.cli._common import EXIT_FAILED

    failed = [] if res.table is None or not len(res.table) else \
        [str(i) for i in res.table.loc[res.table["status"] == "failed", "id"]]
    failed_set = set(failed)
    missing = [i for i in res.incomplete if i not in failed_set]
    why = []
    if missing:
        why.append(f"{len(missing)} have no record"
                   + (f" (the cluster lost their tasks: {res.lost_reason[:300]})" if res.lost else ""))
    if failed:
        why.append(f"{len(failed)} failed (lost to worker failures or out of memory)")
    msg = (f"sweep unfinished: {len(res.incomplete)} of {res.n_runs} runs have no result — "
           f"{'; '.join(why)}; {out / PARTIAL_MARKER} names them; finish with --resume --out {out}")
    mark_partial(out, "failed", reason=msg, missing=missing, failed=failed)
    fail(msg, EXIT_FAILED)


def _summary(con: Any, name: str, res: Any, out: Path) -> None:
    """The table of statuses and the runs that did not complete (user strings printed as text)."""
    from rich.table import Table
    from rich.text import Text

    t = Table(title=Text(f"sweep {name}: {res.n_runs} runs ({res.executed} run now, "
                         f"{res.skipped} resumed)"))
    for col in ("status", "runs", "RMSE y median [m]", "max |e_y| worst [m]", "MPC median [ms]"):
        t.add_column(Text(col), justify="right")
    tab = res.table
    if len(tab):
        for status, grp in tab.groupby("status"):
            t.add_row(str(status), str(len(grp)), _fmt(grp.get("rmse_y"), "median"),
                      _fmt(grp.get("max_abs_lateral_m"), "max"), _fmt(grp.get("mpc_median_ms"), "median"))
    con.print(t)
    bad = tab[tab["status"] != "completed"] if len(tab) else tab
    for _, row in bad.iterrows():
        con.print(Text.assemble((str(row["id"]), "yellow"), f" {row['method']} {row['scenario']} "
                                f"{row['track']}: {row['status']}: {row['reason']}"))
    have = set(tab["id"]) if tab is not None and len(tab) else set()
    records = res.n_runs - sum(1 for i in res.incomplete if i not in have)
    con.print(Text.assemble(f"wrote {len(res.files)} files; {records} of {res.n_runs} records in ",
                            (str(out), "bold")))


def _fmt(col: object, how: str) -> str:
    if col is None:
        return "-"
    v = getattr(col, how)()
    return "-" if v != v else f"{v:.3f}"
