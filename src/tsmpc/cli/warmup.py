"""``tsmpc warmup``: compile the numba kernels ahead of time (tsmpc.kernels)."""

from __future__ import annotations

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import check_environment, deferred_interrupts, fail, handle_interrupts


@app.command("warmup")
def warmup_cmd() -> None:
    """Compile the real-time kernels now (first run only; later processes load them from the cache)."""
    from tsmpc import kernels

    if not kernels.enabled():
        typer.echo("kernels are switched off (TSMPC_NO_JIT is set): nothing to compile")
        return
    check_environment()  # an unusable NUMBA_CACHE_DIR / cache folder: exit 2 naming it
    try:
        with handle_interrupts(), deferred_interrupts():  # never raise inside numba/LLVM callbacks
            ok, seconds = kernels.warmup()
            engine_ok = False
            if ok:  # the whole-run engine too (tsmpc.sim.engine): its first compile takes longest
                import time

                from tsmpc.sim import engine

                t0 = time.perf_counter()
                engine_ok = engine.warmup()
                if engine_ok:  # and the batched-run kernel of sweeps (tsmpc.sim.batch)
                    from tsmpc.sim import batch

                    batch.warmup()
                seconds += time.perf_counter() - t0
    except KeyboardInterrupt as sig:
        typer.secho(f"interrupted ({sig})", err=True, fg=typer.colors.RED)
        raise typer.Exit(getattr(sig, "code", 130)) from None
    if not ok:
        fail(f"compiled kernels unavailable ({kernels.failure() or 'numba failed'}): simulations "
             "use the numpy implementations", code=1)
    what = "kernels and run engine" if engine_ok else "kernels (run engine off)"
    typer.echo(f"{what} ready in {seconds:.1f} s (cache: {kernels.numba_cache_dir()})")
