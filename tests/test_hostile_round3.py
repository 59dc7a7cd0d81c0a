"""Hostile inputs, round three (issue 38 item 3): every value a user can type goes through one
parser (``tsmpc.config.parse_toml`` for files, ``apply_overrides`` for ``--set``), which owns
every error it can meet:

* an integer of more than 4,300 digits (Python's ``int()`` refuses it with a bare ``ValueError``,
  which surfaced as "internal error", exit 1) — in ``--set``, a config file, a sweep file's
  ``seed`` or ``batch``, a sweep's base config;
* control characters in ``--set`` (``vehicle.mass=700\\n[mpc]\\nN=2`` was TOML of its own whose
  ``[mpc]`` part was silently dropped);
* non-finite values where a finite one is required.

Every case exits 2 with one line naming the item, field or file, and writes nothing.
``{D}`` is the folder of input files, ``{O}`` a fresh output path.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config, apply_overrides, parse_toml
from tsmpc.errors import ConfigError

runner = CliRunner()

BIG = "7" * 5000  # more than sys.get_int_max_str_digits() = 4300
HEX = "0x" + "f" * 5000  # parses at any length, but str() of it raises ValueError
RUN = ["run", "--no-plots", "--duration", "1", "--out", "{O}"]

#: Input files: (name, text).
FILES = [
    ("cfg-mass-digits.toml", f"[vehicle]\nmass = {BIG}\n"),
    ("cfg-seed-digits.toml", f"seed = {BIG}\n"),
    ("cfg-seed-negative-digits.toml", f"seed = -{BIG}\n"),
    ("cfg-seed-hex.toml", f"seed = {HEX}\n"),
    ("cfg-Q-binary.toml", f"[mpc]\nQ = [1, 0b{'1' * 16000}, 1]\n"),
    ("sweep-batch-hex.toml", f'name = "t"\nduration_s = 1.0\nbatch = {HEX}\n'),
    ("sweep-batch-digits.toml", f'name = "t"\nduration_s = 1.0\nbatch = {BIG}\n'),
    ("sweep-seed-digits.toml", f'name = "t"\nduration_s = 1.0\n[grid]\nseed = [1, {BIG}]\n'),
    ("sweep-random-seed-digits.toml",
     f'name = "t"\nduration_s = 1.0\n[random]\nn = 2\nseed = {BIG}\n'
     'ranges = { mass_scale = [0.9, 1.1] }\n'),
    ("sweep-config-digits.toml", f'name = "t"\nduration_s = 1.0\n[config.mpc]\nN = {BIG}\n'),
    ("sweep-base-digits.toml", 'name = "t"\nduration_s = 1.0\nbase_config = "cfg-mass-digits.toml"\n'),
    ("sweep-config-mass-inf.toml", 'name = "t"\nduration_s = 1.0\n[config.vehicle]\nmass = inf\n'),
    ("sweep-lateral-nan.toml", 'name = "t"\nduration_s = 1.0\nmax_lateral_m = nan\n'),
    ("sweep-duration-inf.toml", 'name = "t"\nduration_s = inf\n'),
    ("wp.csv", "x,y\n0,0\n60,5\n120,40\n150,100\n"),
]

CASES: list[tuple[str, list[str], str]] = [
    # --set: one KEY=VALUE, on one line (a newline would start TOML of its own)
    ("set-newline-section", [*RUN, "--set", "vehicle.mass=700\n[mpc]\nN=2"], "--set 'vehicle.mass=700"),
    ("set-newline-key", [*RUN, "--set", "vehicle.mass=700\nseed=3"], "control character"),
    ("set-cr", [*RUN, "--set", "vehicle.mass=700\r"], "control character"),
    ("set-nul", [*RUN, "--set", "vehicle.mass=700\x00"], "control character"),
    ("set-escape", [*RUN, "--set", "vehicle.mass=\x1b[31m700"], "control character"),
    ("set-newline-in-key", [*RUN, "--set", "vehicle\n.mass=700"], "control character"),
    ("compare-set-newline", ["compare", "--methods", "ref", "--duration", "1", "--no-plots", "--out",
                             "{O}", "--set", "vehicle.mass=700\n[mpc]\nN=2"], "control character"),
    # more than 4,300 digits
    ("set-mass-digits", [*RUN, "--set", f"vehicle.mass={BIG}"], "more than 4300 digits"),
    ("set-seed-digits", [*RUN, "--set", f"seed={BIG}"], "more than 4300 digits"),
    ("set-seed-negative-digits", [*RUN, "--set", f"seed=-{BIG}"], "more than 4300 digits"),
    ("set-N-digits-in-list", [*RUN, "--set", f"mpc.Q=[1, {BIG}, 1]"], "more than 4300 digits"),
    ("set-mass-hex", [*RUN, "--set", f"vehicle.mass={HEX}"], "more than 4300 digits"),
    ("set-seed-octal", [*RUN, "--set", f"seed=0o{'7' * 5000}"], "more than 4300 digits"),
    ("config-seed-hex", [*RUN, "--config", "{D}/cfg-seed-hex.toml"], "line 1"),
    ("config-Q-binary", [*RUN, "--config", "{D}/cfg-Q-binary.toml"], "line 2"),
    ("config-mass-digits", [*RUN, "--config", "{D}/cfg-mass-digits.toml"], "more than 4300 digits"),
    ("config-seed-digits", [*RUN, "--config", "{D}/cfg-seed-digits.toml"], "line 1"),
    ("config-seed-negative-digits", [*RUN, "--config", "{D}/cfg-seed-negative-digits.toml"],
     "more than 4300 digits"),
    ("design-mass-digits", ["design", "--config", "{D}/cfg-mass-digits.toml"], "more than 4300 digits"),
    *[(f"sweep-{name}", ["sweep", f"{{D}}/sweep-{name}.toml", "--dry-run", "--out", "{O}"], needle)
      for name, needle in [("batch-digits", "line 3"), ("batch-hex", "line 3"), ("seed-digits", "line 4"),
                           ("random-seed-digits", "more than 4300 digits"),
                           ("config-digits", "more than 4300 digits"),
                           ("base-digits", "base_config"),
                           ("config-mass-inf", "vehicle.mass"), ("lateral-nan", "max_lateral_m"),
                           ("duration-inf", "duration_s")]],
    # non-finite where a finite number is required
    *[(f"set-{field}-{word}", [*RUN, "--set", f"{field}={word}"], field)
      for field in ("vehicle.mass", "vehicle.inertia", "rates.Tc", "noise.scale", "tyre.mu_dry")
      for word in ("inf", "nan", "-inf")],
    ("set-mass-overflow", [*RUN, "--set", "vehicle.mass=1e999"], "vehicle.mass"),
    ("set-Q-inf", [*RUN, "--set", "mpc.Q=[1, inf, 1]"], "mpc.Q"),
    ("set-divergence-nan", [*RUN, "--set", "divergence_bound_m=nan"], "divergence_bound_m"),
    # plan --out is a file: a name that reads as a folder is refused (it wrote a file "out/new")
    ("plan-out-trailing-slash", ["plan", "{D}/wp.csv", "--open", "--out", "{O}/"], "names a folder"),
    ("plan-out-trailing-slash-existing", ["plan", "{D}/wp.csv", "--open", "--out", "{D}/"],
     "names a folder"),
    ("plan-out-dot", ["plan", "{D}/wp.csv", "--open", "--out", "{O}/."], "names a folder"),
    ("plan-out-empty", ["plan", "{D}/wp.csv", "--open", "--out", ""], "--out: empty"),
    ("show-out-empty", ["show-reference", "{D}/wp.csv", "--out", ""], "--out: empty"),
]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("round3")
    for name, text in FILES:
        (d / name).write_text(text)
    return d


@pytest.mark.timeout(60)
@pytest.mark.parametrize(("argv", "needle"), [pytest.param(a, n, id=i) for i, a, n in CASES])
def test_hostile_value_exits_2_with_one_line(files: Path, tmp_path: Path, argv: list[str],
                                             needle: str) -> None:
    out = tmp_path / "out"
    args = [a.replace("{D}", str(files)).replace("{O}", str(out)) for a in argv]
    res = runner.invoke(app, args)
    text = res.output
    assert "Traceback" not in text and "internal error" not in text, text[:3000]
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2, text[:3000]
    errors = [ln for ln in text.splitlines() if ln.lstrip(" │").lower().startswith("error:")]
    assert len(errors) == 1, text[:3000]
    assert needle in errors[0], text[:3000]
    assert len(text) < 4000  # the 5000 digits are not echoed back
    assert not out.exists() or not any(out.iterdir())  # nothing written


@pytest.mark.parametrize("text", [f"seed = {BIG}\n", f"[vehicle]\nmass = {BIG}\n",
                                  f"[mpc]\nQ = [1, {BIG}]\n", f"x = 0x{'f' * 5000}\n"])
def test_parse_toml_owns_the_digit_limit(text: str) -> None:
    with pytest.raises(ConfigError, match="more than 4300 digits") as info:
        parse_toml(text, "f.toml")
    assert str(info.value).startswith("f.toml: ")


@pytest.mark.parametrize(("item", "word"), [
    ("vehicle.mass=700\n[mpc]\nN=2", "control character"),
    (f"vehicle.mass={BIG}", "more than 4300 digits"),
    ("vehicle.mass=" + "[" * 100_000 + "]" * 100_000, "--set"),
])
def test_apply_overrides_refuses_with_a_config_error(item: str, word: str) -> None:
    with pytest.raises(ConfigError, match=word) as info:
        apply_overrides(Config(), [item])
    assert "\n" not in str(info.value)


def test_a_single_value_still_works() -> None:
    cfg = apply_overrides(Config(), ["vehicle.mass=700", "mpc.N=20", "seed=4300"])
    assert (cfg.vehicle.mass, cfg.mpc.N, cfg.seed) == (700.0, 20, 4300)


# -- a failed allocation ends with one line (issue 38 item 3) ---------------------------------
def _no_memory(*_a, **_k):
    raise MemoryError("Unable to allocate 15.0 GiB for an array with shape (8000000, 250)")


#: (id, module, attribute made to raise MemoryError, argv): in the run, in the sweep's client.
MEMORY = [
    ("run-experiment", "tsmpc.sim.experiment", "run", ["run", "--duration", "1", "--no-plots"]),
    ("sweep-aggregate", "tsmpc.sweep", "aggregate", ["sweep", "{S}", "--dry-run", "--workers", "1",
                                                      "--no-plots"]),
]


@pytest.mark.timeout(120)
@pytest.mark.parametrize(("module", "attr", "argv"), [pytest.param(m, a, v, id=i) for i, m, a, v in MEMORY])
def test_a_memory_error_ends_with_one_line_and_partial(tmp_path: Path, monkeypatch, module: str,
                                                       attr: str, argv: list[str]) -> None:
    import importlib
    import json

    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "t"\nduration_s = 1.0\n[grid]\nseed = [1]\n')
    monkeypatch.setattr(importlib.import_module(module), attr, _no_memory)
    out = tmp_path / "out"
    res = runner.invoke(app, [a.replace("{S}", str(sweep)) for a in argv] + ["--out", str(out)])
    text = res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 1, text
    assert "Traceback" not in text and "internal error" not in text, text
    errors = [ln for ln in text.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "out of memory" in errors[0], text
    marker = json.loads((out / "PARTIAL").read_text())
    assert marker["status"] == "failed" and "out of memory" in marker["reason"]


@pytest.mark.timeout(60)
def test_a_memory_error_outside_the_guarded_work_ends_with_one_line(tmp_path: Path) -> None:
    """Before the output folder exists (loading the config): the entry point's last net."""
    import subprocess
    import sys

    code = ("import sys, tsmpc.config as c\n"
            "def oom(*a, **k): raise MemoryError()\n"
            "c.load_config = oom\n"
            "import tsmpc.cli._common as k; k.load_config = oom\n"
            "from tsmpc.cli import main\n"
            "sys.argv = ['tsmpc', 'design']\n"
            "main()\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=50,
                         cwd=tmp_path)
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr and "internal error" not in res.stderr, res.stderr
    assert res.stderr.startswith("error: out of memory") and res.stderr.count("\n") == 1, res.stderr


@pytest.mark.parametrize(("exc", "status"), [(MemoryError("no"), "failed"), (ValueError("bad"), "error")])
def test_a_run_that_ran_out_of_memory_is_failed_not_a_result(monkeypatch, tmp_path: Path,
                                                             exc: Exception, status: str) -> None:
    """The machine failed the run, not the controller: ``failed`` (re-run by --resume)."""
    import tsmpc.sweep as sw

    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "t"\nduration_s = 1.0\n')
    (task,) = sw.expand(sw.load_sweep(sweep))

    def boom(_task):
        raise exc
    monkeypatch.setattr(sw, "_simulate", boom)
    monkeypatch.setattr(sw, "_prepare", boom)
    assert sw.run_task(task)["status"] == status
    assert [r["status"] for r in sw.run_batch([task])] == [status]


@pytest.mark.timeout(60)
def test_show_reference_out_with_a_trailing_slash_writes_into_that_folder(tmp_path: Path) -> None:
    """``show-reference … --out DIR/`` (docs/planning.md) writes DIR/FILE-stem.png, never a
    file named DIR (``Path`` drops the trailing slash: the option is read as typed)."""
    wp = tmp_path / "wp.csv"
    wp.write_text("x,y\n0,0\n60,5\n120,40\n150,100\n")
    ref = tmp_path / "ref.csv"
    assert runner.invoke(app, ["plan", str(wp), "--open", "--out", str(ref)]).exit_code == 0
    res = runner.invoke(app, ["show-reference", str(ref), "--out", f"{tmp_path / 'new'}/"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "new").is_dir()
    assert (tmp_path / "new" / "ref.png").read_bytes()[:4] == b"\x89PNG"
