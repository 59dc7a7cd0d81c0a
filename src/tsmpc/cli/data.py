"""``tsmpc data fetch`` (download the paper's reference and the race tracks, hashes pinned) and
``tsmpc data where`` (which folder each dataset is read from): a shell over :mod:`tsmpc.datasets`."""

from __future__ import annotations

from pathlib import Path

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import EXIT_FAILED, EXIT_INVALID, check_environment, check_path_text, fail

data_app = typer.Typer(name="data", help="The paper's reference and the race tracks: download them, "
                       "see where they are read from.", no_args_is_help=True, rich_markup_mode=None)
app.add_typer(data_app, name="data")


@data_app.command("fetch")
def fetch_cmd(
    which: str = typer.Argument("all", help="paper, tracks or all."),
    mirror: str | None = typer.Option(None, "--mirror", help="Base URL (or folder) replacing "
                                      "https://raw.githubusercontent.com: it serves the same paths "
                                      "<owner>/<repo>/<commit>/<file> [env: TSMPC_DATA_MIRROR]."),
    target: Path | None = typer.Option(None, "--dir", help="Data folder to fill [default: the "
                                       "cache's data/ folder, $TSMPC_CACHE_DIR or ~/.cache/tsmpc]."),
) -> None:
    """Download the paper's planner reference (authors' repository) and the TUMFTM race tracks,
    each checked against its pinned SHA-256, with a README.txt of origin and licence."""
    from tsmpc import datasets
    from tsmpc.errors import ConfigError, TsmpcError
    from tsmpc.paths import folder_problem

    check_environment(kernels=False)
    if target is not None:
        check_path_text(target, "--dir")
        problem = folder_problem(target)
        if problem:
            fail(ConfigError(f"--dir {target}: {problem}"))
    try:
        files = datasets.fetch(which, mirror=mirror, root=target,
                               progress=lambda text: typer.echo(f"fetching {text}", err=True))
    except datasets.DataHashError as err:
        fail(err, EXIT_INVALID)
    except datasets.DataFetchError as err:
        fail(err, EXIT_FAILED)
    except TsmpcError as err:
        fail(err, EXIT_INVALID)
    for f in files:
        typer.echo(str(f))


@data_app.command("where")
def where_cmd() -> None:
    """Print where each dataset is read from (first found: $TSMPC_DATA_DIR, the cache, the
    checkout's ../shared/data) or the command that downloads it; exit 1 when one is missing."""
    from tsmpc import datasets

    check_environment(kernels=False)
    missing = False
    for name in datasets.DATASETS:
        path = datasets.find(name)
        if path is None:
            missing = True
            typer.echo(f"{name}: missing: run `{datasets.fetch_command(name)}`")
        else:
            typer.echo(f"{name}: {path}")
    searched = "; ".join(f"{label} {root}" for label, root in datasets.data_roots())
    typer.echo(f"searched, in order: {searched}")
    if missing:
        raise typer.Exit(EXIT_FAILED)
