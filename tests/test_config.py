"""Config validation: defaults are the paper's, bad fields are named, TOML round-trips."""

from __future__ import annotations

from pathlib import Path

import pytest

from tsmpc.config import Config, Rates, TyreModel, load_config, replace
from tsmpc.errors import ConfigError


def test_defaults_are_paper_table_1(cfg: Config) -> None:
    v = cfg.vehicle
    assert (v.a, v.b, v.mass, v.inertia) == (0.758, 1.036, 683.0, 560.94)
    assert (v.cornering_stiffness, v.frontal_area, v.air_density) == (25000.0, 1.91, 1.184)
    assert (v.drag_coefficient, v.mu_nominal, v.g) == (0.36, 0.5, 9.81)
    assert cfg.rates.inner_per_outer == 10 and cfg.rates.plant_per_inner == 10
    assert cfg.tyre.model is TyreModel.PACEJKA
    assert cfg.mpc.N == 40 and cfg.mhe.N == 30


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "c.toml"
    p.write_text(text)
    return p


def test_toml_round_trip(tmp_path: Path, cfg: Config) -> None:
    changed = replace(cfg, seed=7)
    p = _write(tmp_path, changed.to_toml())
    assert load_config(p) == changed


@pytest.mark.parametrize(
    ("text", "field", "reason"),
    [
        ("[vehicle]\nmass = -683.0\n", "vehicle.mass", "greater than"),
        ("[rates]\nTc = 0.1\nTd = 0.03\n", "rates", "Tc/Td"),
        ("[rates]\nTd = 0.0101\n", "rates", "Tc/Td"),
        ("[vehicle]\nmas = 683.0\n", "vehicle.mas", "unknown field"),
        ("[mpc]\nN = 'forty'\n", "mpc.N", "integer"),
        ("[tyre]\nmodel = 'brush'\n", "tyre.model", "linear"),
        ("[mpc]\nQ = [1.0, 2.0]\n", "mpc", "Q: expected 3"),
        ("[kinematic_box]\nv_d = [18.0, 1.0]\n", "kinematic_box", "lower bound"),
        ("bogus_section = 1\n", "bogus_section", "unknown field"),
    ],
)
def test_bad_config_names_the_field(tmp_path: Path, text: str, field: str, reason: str) -> None:
    with pytest.raises(ConfigError) as exc:
        load_config(_write(tmp_path, text))
    msg = str(exc.value)
    assert field in msg and reason in msg
    assert isinstance(exc.value, ValueError)


def test_unreadable_and_invalid_toml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_config(_write(tmp_path, "[vehicle\n"))


def test_rates_ratios() -> None:
    r = Rates(Tc=0.05, Td=0.005, h=0.0005)
    assert (r.inner_per_outer, r.plant_per_inner) == (10, 10)
    with pytest.raises(ValueError, match="Td/h"):
        Rates(Td=0.01, h=0.003)


def test_frozen(cfg: Config) -> None:
    with pytest.raises(Exception, match="frozen"):
        cfg.vehicle.mass = 1.0  # type: ignore[misc]
