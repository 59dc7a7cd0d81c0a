"""``tsmpc sweep``: Monte-Carlo and parameter sweeps on Dask (issue 8)."""

from __future__ import annotations

from pathlib import Path

import typer

from tsmpc.cli import app
from tsmpc.cli._common import (
    PARTIAL_MARKER,
    Interrupted,
    check_out_dir,
    design_status,
    fail,
    finite,
    handle_interrupts,
    mark_partial,
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
    resume: bool = typer.Option(False, "--resume", help="Skip runs whose record is already in --out."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Skip the summary plots."),
    dry_run: bool = typer.Option(
        False, "--dry-run", help="Check the cluster plumbing: tasks sleep instead of simulating."),
    connect_timeout: float = typer.Option(
        5.0, "--connect-timeout", help="Seconds to wait for --scheduler before giving up."),
) -> None:
    """Run every point of a sweep as a Dask task; write one record per run, the aggregate table
    (CSV, Parquet) and summary plots."""
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
    from rich.table import Table

    from tsmpc.errors import TsmpcError
    from tsmpc.sweep import dry_run as dry_fn
    from tsmpc.sweep import expand, load_sweep, run_sweep, run_task

    console = Console()
    finite("--connect-timeout", connect_timeout, lo=0.0, lo_open=True, hi=600.0)
    if workers > 64:
        fail(ConfigError(f"--workers = {workers}: at most 64 local worker processes"))
    try:
        spec = load_sweep(sweep_file)  # every problem is reported before any task starts
    except TsmpcError as err:
        fail(err)
    if out is None:
        if resume:
            fail(ConfigError("--resume needs --out: the folder of the sweep to finish"))
        from tsmpc.cli._outdir import claim_default_out

        out = claim_default_out("sweep")
    if resume:
        check_out_dir(out, overwrite=True)  # records on disk are kept and skipped
    else:
        check_out_dir(out, overwrite=False, hint="pass --resume to finish the sweep in it")
    n = len(expand(spec))
    where = scheduler or f"a local cluster of {workers} worker processes"
    console.print(f"sweep [bold]{spec.name}[/bold]: {n} runs on {where} → {out}")
    counts: dict[str, int] = {}
    with Progress(TextColumn("[bold]runs"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TextColumn("{task.description}"), TimeElapsedColumn(), TimeRemainingColumn(),
                  console=console) as progress:
        task = progress.add_task("", total=n)

        def on_record(done: int, total: int, rec: dict) -> None:
            counts[rec["status"]] = counts.get(rec["status"], 0) + 1
            progress.update(task, completed=done, description=" ".join(f"{k}={v}" for k, v in counts.items()))

        try:
            with handle_interrupts():
                mark_partial(out, "running")
                res = run_sweep(spec, out, scheduler=scheduler, workers=workers, resume=resume,
                                run_fn=dry_fn if dry_run else run_task, progress=on_record,
                                plots=not no_plots, connect_timeout=connect_timeout,
                                design_fn=design_status)
                (out / PARTIAL_MARKER).unlink(missing_ok=True)
        except TsmpcError as err:
            progress.stop()
            (out / PARTIAL_MARKER).unlink(missing_ok=True)  # nothing ran: nothing partial
            fail(err)
        except Interrupted as sig:
            mark_partial(out, "interrupted", signal=str(sig))
            progress.stop()
            typer.secho(f"interrupted ({sig}): the records finished so far are in {out / 'runs'}; "
                        f"finish the sweep with --resume", err=True, fg=typer.colors.RED)
            raise typer.Exit(sig.code) from None
    t = Table(title=f"sweep {spec.name}: {res.n_runs} runs ({res.executed} run now, {res.skipped} resumed)")
    for col in ("status", "runs", "RMSE y median [m]", "max |e_y| worst [m]", "MPC median [ms]"):
        t.add_column(col.replace("[", "\\["), justify="right")
    tab = res.table
    if len(tab):
        for status, grp in tab.groupby("status"):
            t.add_row(str(status), str(len(grp)), _fmt(grp.get("rmse_y"), "median"),
                      _fmt(grp.get("max_abs_lateral_m"), "max"), _fmt(grp.get("mpc_median_ms"), "median"))
    console.print(t)
    bad = tab[tab["status"] != "completed"] if len(tab) else tab
    for _, row in bad.iterrows():
        console.print(f"[yellow]{row['id']}[/yellow] {row['method']} {row['scenario']} {row['track']}: "
                      f"{row['status']}: {row['reason']}")
    console.print(f"wrote {len(res.files)} files and {res.n_runs} records to [bold]{out}[/bold]")


def _fmt(col: object, how: str) -> str:
    if col is None:
        return "-"
    v = getattr(col, how)()
    return "-" if v != v else f"{v:.3f}"
