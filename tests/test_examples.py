"""Every ```python block of README.md and every script in examples/ runs (no snippet can rot)."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from _paths import need_data

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), re.S | re.M)
#: The datasets an example reads (not bundled): missing, its test skips naming `tsmpc data fetch`.
NEEDS = {"baseline_table.py": ("paper", "tracks"), "fusion_ablation.py": ("paper",),
         "generalisation_table.py": ("paper",), "mechanism_ablation.py": ("paper",),
         "mismatch_table.py": ("paper", "tracks"),
         "paper_ablation.py": ("paper",), "paper_explained.py": ("paper",), "race_tracks.py": ("tracks",),
         "capped_tracks.py": ("tracks",)}
#: Arguments for the shortened test runs: one local Dask worker (a second would cost its start,
#: imports and kernel loads, ~5 s of CPU, for nothing).
ARGS = {"mismatch_table.py": ["--workers", "1"]}
#: MPC steps of the shortened runs: three run every block, table and figure end to end (ten cost
#: the suite 23 s more of CPU, measured: 114 against 91 s); paper_ablation's launch figure reads
#: its runs' first seconds.
STEPS = {"paper_ablation.py": "10"}


def test_the_readme_has_python_blocks_and_examples_exist() -> None:
    assert len(BLOCKS) >= 2 and len(EXAMPLES) >= 3


@pytest.mark.parametrize("i", range(len(BLOCKS)))
def test_readme_python_block_runs(i: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    exec(compile(BLOCKS[i], f"README.md python block {i + 1}", "exec"), {"__name__": "__readme__"})


def test_the_readme_loop_is_examples_cascade_loop() -> None:
    script = (ROOT / "examples" / "cascade_loop.py").read_text(encoding="utf-8")
    body = script.split('"""', 2)[2].strip()
    assert any(b.strip() == body for b in BLOCKS), "README's loop and examples/cascade_loop.py differ"


@pytest.mark.slow
@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.name)
def test_example_script_runs(script: Path, tmp_path: Path) -> None:
    if "commonroad" in script.name and importlib.util.find_spec("vehiclemodels") is None:
        pytest.skip("the [commonroad] extra is not installed")
    for name in NEEDS.get(script.name, ()):
        need_data(name)
    env = {**os.environ, "TSMPC_EXAMPLE_STEPS": STEPS.get(script.name, "3"),
           "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    # from another folder: the examples find their data relative to themselves, not the cwd
    res = subprocess.run([sys.executable, str(script), *ARGS.get(script.name, [])], capture_output=True,
                         text=True, env=env, timeout=600, cwd=tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip(), "the example printed nothing"


def test_every_default_on_fusion_switch_is_a_row_of_the_mechanism_ablation() -> None:
    """Issue 34's rule (a mechanism stays only where it pays) needs every default-on switch measured:
    each bool of ``[fusion]`` that is on by default is one controller of examples/mechanisms.toml
    and one row of examples/mechanism_ablation.py."""
    import tomllib

    from tsmpc.config import FusionSettings

    spec = importlib.util.spec_from_file_location("mechanism_ablation",
                                                  ROOT / "examples" / "mechanism_ablation.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = {path for path, _ in mod.MECHANISMS.values()}
    sweep = tomllib.loads((ROOT / "examples" / "mechanisms.toml").read_text(encoding="utf-8"))
    off = {f"{g}.{k}" for name, c in sweep["controllers"].items() if name in sweep["grid"]["controller"]
           for g, tab in c.items() for k, v in tab.items() if v is False}
    on = {f"fusion.{k}" for k, f in FusionSettings.model_fields.items() if f.default is True}
    assert on and on <= rows and on <= off, (on - rows, on - off)
