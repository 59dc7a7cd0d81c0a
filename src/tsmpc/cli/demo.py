"""``tsmpc plant-demo``: open-loop plant run, a smoke test of the installation."""

from __future__ import annotations

from pathlib import Path

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import (
    check_environment,
    check_interrupted,
    deferred_interrupts,
    finite,
    handle_interrupts,
    load_config_or_exit,
)


@app.command("plant-demo")
def plant_demo(
    config: Path | None = typer.Option(None, "--config", help="TOML config file."),
    duration: float = typer.Option(10.0, min=0.0, help="Simulated time [s]."),
) -> None:
    """Accelerate and steer the Pacejka plant open loop and print the final state."""
    import time

    import numpy as np

    from tsmpc.vehicle.plant import STATE_NAMES, Plant

    finite("--duration", duration, lo=0.0, hi=3600.0)
    cfg = load_config_or_exit(config)
    check_environment()
    x = np.array([0.0, 0.0, 0.0, 5.0, 0.0, 0.0])
    n = round(duration / cfg.rates.Td)
    try:
        # The plant (its kernels loaded, its steps) is compiled code: a signal sets a flag,
        # checked after every step.
        with handle_interrupts(), deferred_interrupts():
            plant = Plant(cfg.vehicle, cfg.tyre, cfg.rates.h)
            t0 = time.perf_counter()
            for k in range(n):
                t = k * cfg.rates.Td
                u = (9000.0 if t < 5.0 else 6500.0, 0.05 * np.sin(0.5 * t))
                x = plant.step(x, u, 0.9, cfg.rates.plant_per_inner)
                check_interrupted()
    except KeyboardInterrupt as sig:
        typer.secho(f"interrupted ({sig})", err=True, fg=typer.colors.RED)
        raise typer.Exit(getattr(sig, "code", 130)) from None
    wall = time.perf_counter() - t0
    typer.echo(", ".join(f"{s}={v:.4f}" for s, v in zip(STATE_NAMES, x, strict=True)))
    typer.echo(f"{duration:.1f} s simulated in {wall:.3f} s wall")
