"""``tsmpc warmup``: compile the numba kernels ahead of time (tsmpc.kernels)."""

from __future__ import annotations

import typer

from tsmpc.cli import app


@app.command("warmup")
def warmup_cmd() -> None:
    """Compile the real-time kernels now (first run only; later processes load them from the cache)."""
    from tsmpc import kernels

    if not kernels.enabled():
        typer.echo("kernels are switched off (TSMPC_NO_JIT is set): nothing to compile")
        return
    ok, seconds = kernels.warmup()
    if not ok:
        typer.echo("compiled kernels unavailable: simulations use the numpy implementations", err=True)
        raise typer.Exit(1)
    typer.echo(f"kernels ready in {seconds:.1f} s (cache: {kernels.numba_cache_dir()})")
