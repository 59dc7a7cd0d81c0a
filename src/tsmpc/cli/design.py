"""``tsmpc design``: solve (or load from the cache) the LMI designs and print them."""

from __future__ import annotations

from pathlib import Path

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import check_environment, fail, load_config_or_exit, solve_design


@app.command("design")
def design(
    config: Path | None = typer.Option(None, "--config", help="TOML config file."),
    as_json: bool = typer.Option(False, "--json", help="Print the designs as JSON."),
    no_cache: bool = typer.Option(False, "--no-cache", help="Re-solve even if a cached design exists."),
) -> None:
    """Kinematic LQR-LMI + terminal set and dynamic TS-LMI-LQR: S, P, gains, certificates, times."""
    import json
    import time
    from dataclasses import asdict

    import numpy as np

    from tsmpc.errors import TsmpcError
    from tsmpc.synthesis.cache import design_to_dict, load_or_design_dynamic, load_or_design_kinematic
    from tsmpc.synthesis.certificates import MIN_RELATIVE_MARGIN, worst

    cfg = load_config_or_exit(config)
    check_environment(kernels=False)
    try:  # no design for this config (infeasible, solver failure): exit 2 naming the likely field
        t0 = time.perf_counter()
        kd = solve_design("kinematic", lambda c: load_or_design_kinematic(c, use_cache=not no_cache), cfg)
        t1 = time.perf_counter()
        dd = solve_design("dynamic", lambda c: load_or_design_dynamic(c, use_cache=not no_cache), cfg)
        t2 = time.perf_counter()
    except TsmpcError as err:
        fail(err)
        return
    if as_json:
        out = {"kinematic": design_to_dict(kd), "dynamic": design_to_dict(dd),
               "wall_s": {"kinematic": t1 - t0, "dynamic": t2 - t1},
               "smallest_margin": {name: asdict(worst(d.certificates))
                                   for name, d in (("kinematic", kd), ("dynamic", dd))}}
        typer.echo(json.dumps(out, indent=1))
        return

    from rich.console import Console
    from rich.table import Table

    con = Console()
    np.set_printoptions(precision=4, suppress=False, linewidth=120)
    con.print(f"[bold]Kinematic design[/] (solve {kd.solve_time_s:.2f} s, status {kd.status}, "
              f"wall {t1 - t0:.2f} s)")
    con.print(f"terminal set S =\n{kd.S}\nterminal cost P =\n{kd.P}")
    con.print(f"[bold]Dynamic design[/] (solve {dd.solve_time_s:.2f} s, status {dd.status}, "
              f"wall {t2 - t1:.2f} s; {dd.formulation})")
    con.print(f"grid: max spectral radius {dd.grid_max_rho:.5f}, "
              f"max Lyapunov ratio {dd.grid_max_decrease:.6f}")
    con.print(f"K (vertex 0, physical units) =\n{dd.K[0]}")
    table = Table(title="Certificates (λmax of a matrix that must be ≺ 0; a relative margin "
                  f"<= -{MIN_RELATIVE_MARGIN:g} is required)")
    table.add_column("design")
    table.add_column("smallest margin: certificate")
    table.add_column("absolute", justify="right")
    table.add_column("relative", justify="right")
    table.add_column("imposed in the SDP", justify="right")
    table.add_column("all hold")
    for name, d in (("kinematic", kd), ("dynamic", dd)):
        w = worst(d.certificates)
        table.add_row(name, w.name, f"{w.margin:.3e}", f"{w.relative:.3e}", f"{d.margin_imposed:.0e}",
                      str(all(c.holds for c in d.certificates)))
    con.print(table)
