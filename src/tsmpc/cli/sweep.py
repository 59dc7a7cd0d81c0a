"""``tsmpc sweep``: Monte-Carlo and parameter sweeps on Dask (issue 8)."""

from __future__ import annotations

from pathlib import Path

import typer

from tsmpc.cli import app
from tsmpc.cli._common import fail


@app.command("sweep")
def sweep_cmd(
    sweep_file: Path = typer.Argument(..., help="Sweep file (TOML): base config, axes, duration."),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="Address of a running Dask scheduler (default: a LocalCluster)."),
    workers: int = typer.Option(2, "--workers", min=1, help="LocalCluster worker processes."),
    out: Path = typer.Option(Path("results/sweep"), "--out", help="Output folder."),
    resume: bool = typer.Option(False, "--resume", help="Skip runs whose record is already in --out."),
    no_plots: bool = typer.Option(False, "--no-plots", help="Skip the summary plots."),
    dry_run: bool = typer.Option(
        False, "--dry-run", help="Check the cluster plumbing: tasks sleep instead of simulating."),
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
    try:
        spec = load_sweep(sweep_file)  # every problem is reported before any task starts
    except TsmpcError as err:
        fail(err)
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
            res = run_sweep(spec, out, scheduler=scheduler, workers=workers, resume=resume,
                            run_fn=dry_fn if dry_run else run_task, progress=on_record, plots=not no_plots)
        except TsmpcError as err:
            fail(err)
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
