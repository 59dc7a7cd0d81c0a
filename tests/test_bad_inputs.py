"""Hostile inputs (issue 12): every bad config, reference, track, waypoint list, sweep file and
CLI value is refused *before any work starts* with exit code 2, one message naming the file or
field, and never a traceback; nothing is simulated. In-process (typer's CliRunner), so the whole
table runs in seconds.

Each case is (id, argv template, needle). ``{D}`` in the template is the folder of input files
made once by the ``files`` fixture, ``{O}`` a fresh output path per case.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app

runner = CliRunner()

GOOD_MPC_Q = "1.133, 0.067, 13.333"

# -- config files: (id, TOML text, needle naming the field) ---------------------------------
CONFIGS = [
    ("mpc-Q-nan", "[mpc]\nQ = [nan, 0.067, 13.333]\n", "mpc.Q"),
    ("mpc-Q-inf", "[mpc]\nQ = [inf, 0.067, 13.333]\n", "mpc.Q"),
    ("mpc-Q-negative", "[mpc]\nQ = [-1.0, 0.067, 13.333]\n", "Q"),
    ("mpc-Q-length", "[mpc]\nQ = [1.0, 2.0]\n", "Q"),
    ("mpc-R-zero", "[mpc]\nR = [0.0, 5.5]\n", "R"),
    ("mpc-R-nan", "[mpc]\nR = [nan, 5.5]\n", "mpc.R"),
    ("mhe-R-inf", "[mhe]\nR = [inf, 0.033]\n", "mhe.R"),
    ("mhe-Q-negative", "[mhe]\nQ = [-1.0, 10.0, 2.0]\n", "Q"),
    ("mhe-P-nan", "[mhe]\nP = [2.0, 2.0, nan]\n", "mhe.P"),
    ("mhe-N-1", "[mhe]\nN = 1\n", "mhe.N"),
    ("mhe-x-bounds", "[mhe]\nx_min = [0.0, 0.1, -1.4]\nx_max = [18.0, -0.1, 1.4]\n", "x_min/x_max"),
    ("kin-lmi-Q-nan", "[kinematic_lmi]\nQ = [nan, 1.5, 3.0]\n", "kinematic_lmi.Q"),
    ("kin-lmi-ubar-inf", "[kinematic_lmi]\nu_bar = [inf, 1.4]\n", "kinematic_lmi.u_bar"),
    ("dyn-lmi-R-nan", "[dynamic_lmi]\nR = [0.001, nan]\n", "dynamic_lmi.R"),
    ("dyn-lmi-Q-inf", "[dynamic_lmi]\nQ = [2500, 0.1, 0.1, 0.1, inf, 9e4]\n", "dynamic_lmi.Q"),
    ("dyn-lmi-grid", "[dynamic_lmi]\ngrid_points = 2\n", "grid_points"),
    ("dyn-lmi-bandwidth", "[dynamic_lmi]\nfilter_bandwidth = 0\n", "filter_bandwidth"),
    ("vehicle-mass-negative", "[vehicle]\nmass = -683.0\n", "vehicle.mass"),
    ("vehicle-mass-nan", "[vehicle]\nmass = nan\n", "vehicle.mass"),
    ("vehicle-mass-inf", "[vehicle]\nmass = inf\n", "vehicle.mass"),
    ("vehicle-mass-huge", "[vehicle]\nmass = 1e9\n", "vehicle.mass"),
    ("vehicle-a-zero", "[vehicle]\na = 0.0\n", "vehicle.a"),
    ("vehicle-inertia-text", "[vehicle]\ninertia = 'heavy'\n", "vehicle.inertia"),
    ("vehicle-stiffness", "[vehicle]\ncornering_stiffness = -1.0\n", "vehicle.cornering_stiffness"),
    ("vehicle-mu-huge", "[vehicle]\nmu_nominal = 50.0\n", "vehicle.mu_nominal"),
    ("rates-ratio", "[rates]\nTc = 0.105\n", "Tc/Td"),
    ("rates-h-zero", "[rates]\nh = 0.0\n", "rates.h"),
    ("rates-h-tiny", "[rates]\nh = 1e-7\nTd = 0.01\n", "rates.h"),
    ("rates-Tc-huge", "[rates]\nTc = 5.0\n", "rates.Tc"),
    ("rates-Td-inf", "[rates]\nTd = inf\n", "rates.Td"),
    ("mpc-N-1", "[mpc]\nN = 1\n", "mpc.N"),
    ("mpc-N-huge", "[mpc]\nN = 100000\n", "mpc.N"),
    ("mpc-u-bounds", "[mpc]\nu_min = [18.0, -1.4]\nu_max = [0.0, 1.4]\n", "u_min/u_max"),
    ("mpc-mode", "[mpc]\nmode = 'magic'\n", "mpc.mode"),
    ("mpc-du-zero", "[mpc]\ndu_max = [0.0, 0.3]\n", "mpc.du_max"),
    ("mpc-soft-inf", "[mpc]\nsoft_penalty = inf\n", "mpc.soft_penalty"),
    ("mpc-iter-max", "[mpc]\niter_max = 0\n", "mpc.iter_max"),
    ("lqr-force-bounds", "[lqr]\nforce_min = 100.0\nforce_max = 0.0\n", "force_min/force_max"),
    ("lqr-delta-negative", "[lqr]\ndelta_max = -0.1\n", "lqr.delta_max"),
    ("lqr-tau-nan", "[lqr]\nspeed_time_constant = nan\n", "lqr.speed_time_constant"),
    ("noise-negative", "[noise]\nv = -1.0\n", "noise.v"),
    ("noise-scale-inf", "[noise]\nscale = inf\n", "noise.scale"),
    ("noise-scale-huge", "[noise]\nscale = 1e9\n", "noise.scale"),
    ("tyre-shape", "[tyre]\nshape_c = 3.0\n", "tyre.shape_c"),
    ("tyre-model", "[tyre]\nmodel = 'brush'\n", "tyre.model"),
    ("tyre-mu-nan", "[tyre]\nmu_tyre = nan\n", "tyre.mu_tyre"),
    ("kin-box-vd", "[kinematic_box]\nv_d = [18.0, 1.0]\n", "v_d"),
    ("kin-box-etheta", "[kinematic_box]\ne_theta = [-4.0, 4.0]\n", "e_theta"),
    ("dyn-box-v-zero", "[dynamic_box]\nv = [0.0, 20.0]\n", "dynamic_box.v"),
    ("dyn-box-alpha-nan", "[dynamic_box]\nalpha = [nan, 0.1]\n", "dynamic_box.alpha"),
    ("planner-vmax-zero", "[planner]\nv_max = 0.0\n", "planner.v_max"),
    ("planner-alat-inf", "[planner]\na_lat_max = inf\n", "planner.a_lat_max"),
    ("seed-negative", "seed = -1\n", "seed"),
    ("seed-float", "seed = 1.5\n", "seed"),
    ("unknown-section", "[mpcc]\nN = 3\n", "mpcc"),
    ("unknown-field", "[mpc]\nhorizon = 3\n", "mpc.horizon"),
    ("invalid-toml", "[mpc\nN = \n", "invalid TOML"),
]


def _png() -> bytes:
    """A valid 1×1 PNG (an image passed where a text file is expected)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\x00\x00\x00\x00")) + chunk(b"IEND", b""))


def _csv(path: Path, data: np.ndarray, header: str = "t,x,y,theta,v,omega,kappa") -> None:
    path.write_text(header + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in data) + "\n")


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tsmpc.planning.circuit import builtin_circuit
    from tsmpc.planning.paper_format import save_paper_format

    d = tmp_path_factory.mktemp("bad")
    for cid, text, _ in CONFIGS:
        (d / f"cfg-{cid}.toml").write_text(text)
    (d / "binary.bin").write_bytes(bytes(range(256)) * 4)
    (d / "latin1.txt").write_bytes("[mpc]\n# caf\xe9\n".encode("latin-1"))
    (d / "image.png").write_bytes(_png())
    (d / "folder").mkdir()
    (d / "afile").write_text("not a folder\n")
    (d / "full").mkdir()
    (d / "full" / "old.txt").write_text("a file of an earlier run\n")
    (d / "existing.csv").write_text("t,x,y,theta,v,omega,kappa\n")

    ref = builtin_circuit(dt=0.1)
    good = np.stack([ref.t, ref.x, ref.y, ref.theta, ref.v, ref.omega, ref.kappa], axis=1)[:300]
    _csv(d / "good.csv", good)
    save_paper_format(ref.slice(0, 300), d / "paper.csv")

    def variant(name: str, f) -> None:
        a = good.copy()
        f(a)
        _csv(d / f"ref-{name}.csv", a)

    variant("nan", lambda a: a.__setitem__((10, 1), np.nan))
    variant("inf", lambda a: a.__setitem__((10, 4), np.inf))
    variant("negative-v", lambda a: a.__setitem__((50, 4), -1.0))
    variant("speed-x2", lambda a: a.__setitem__((slice(None), 4), a[:, 4] * 2))
    variant("omega-wrong", lambda a: a.__setitem__((slice(100, 120), 5), 2.0))
    variant("heading-flipped", lambda a: a.__setitem__((slice(None), 3), a[:, 3] + np.pi))
    variant("time-nonuniform", lambda a: a.__setitem__((20, 0), a[20, 0] + 0.03))
    variant("time-backwards", lambda a: a.__setitem__((slice(None), 0), a[::-1, 0]))
    still = good.copy()
    still[:, 1:3] = still[0, 1:3]
    still[:, 4:] = 0.0
    still[:, 3] = still[0, 3]
    _csv(d / "ref-standstill.csv", still)
    _csv(d / "ref-short.csv", good[:10])
    _csv(d / "ref-one-row.csv", good[:1])
    (d / "ref-6cols.csv").write_text("t,x,y,theta,v,omega,kappa\n" + "\n".join(
        ",".join(str(v) for v in r[:6]) for r in good[:60]) + "\n")
    (d / "ref-text.csv").write_text("t,x,y,theta,v,omega,kappa\n0,0,0,0,fast,0,0\n0.1,1,0,0,1,0,0\n")
    (d / "ref-unknown-header.csv").write_text("a,b,c\n1,2,3\n")
    (d / "empty.csv").write_text("")
    rows = (d / "paper.csv").read_text().splitlines()
    (d / "paper-5rows.csv").write_text("\n".join(rows[:5]) + "\n")
    (d / "paper-ragged.csv").write_text("\n".join([*rows[:5], rows[5] + ",1.0"]) + "\n")
    nan_row = rows[3].replace(rows[3].split(",")[7], "nan", 1)
    (d / "paper-nan.csv").write_text("\n".join([*rows[:3], nan_row, *rows[4:]]) + "\n")
    (d / "paper-text.csv").write_text("\n".join([*rows[:2], "a,b,c", *rows[3:]]) + "\n")
    zero = np.zeros((6, 300))
    zero[3, 100:] = 1.0  # stands still for 10 s, then drives at 1 m/s along x (consistent pose)
    zero[0] = np.cumsum(zero[3]) * 0.1
    (d / "paper-standstill.csv").write_text(
        "\n".join(",".join(repr(float(v)) for v in r) for r in zero) + "\n")

    # tracks and waypoints
    ang = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    ring = np.stack([200 * np.cos(ang), 120 * np.sin(ang), np.full(60, 5.0), np.full(60, 5.0)], axis=1)
    hdr = "# x_m,y_m,w_tr_right_m,w_tr_left_m\n"

    def track(name: str, a: np.ndarray, extra: str = "") -> None:
        (d / f"track-{name}.csv").write_text(hdr + "\n".join(",".join(repr(float(v)) for v in r)
                                                             for r in a) + "\n" + extra)

    track("good", ring)
    track("3pts", ring[::20])
    neg = ring.copy()
    neg[5, 2] = -1.0
    track("negative-width", neg)
    track("3cols", ring, "1.0,2.0,3.0\n")
    nan = ring.copy()
    nan[7, 0] = np.nan
    track("nan", nan)
    track("text", ring, "1.0,two,5,5\n")
    track("half-lap", ring[:31])
    rev = np.vstack([ring[:20], ring[19:9:-1], ring[20:]])
    track("reversal", rev)
    (d / "wp-reversal.csv").write_text("x,y\n0,0\n50,0\n100,0\n60,0\n120,5\n")
    half = "\n".join(f"{float(x)!r},{float(y)!r}" for x, y in ring[:31, :2])
    (d / "wp-half-lap.csv").write_text("x,y\n" + half + "\n")
    (d / "wp-nan.csv").write_text("x,y\n0,0\n50,nan\n100,0\n")
    (d / "wp-text.csv").write_text("x,y\n0,0\n50,north\n")
    (d / "wp-one.csv").write_text("x,y\n0,0\n")
    (d / "wp-huge.csv").write_text("x,y\n0,0\n1e7,0\n2e7,1e3\n")
    (d / "wp-same.csv").write_text("x,y\n5,5\n5,5\n5,5\n")
    (d / "wp-vcap.csv").write_text("x,y,v\n0,0,5\n50,0,-1\n100,10,5\n")
    (d / "wp-good.csv").write_text("x,y\n0,0\n60,0\n120,10\n170,40\n")

    # sweeps
    def sweep(name: str, text: str) -> None:
        (d / f"sweep-{name}.toml").write_text('name = "t"\nduration_s = 2.0\n' + text)

    sweep("noise-inf", "[grid]\nnoise_scale = [inf]\n")
    sweep("mass-inf", "[grid]\nmass_scale = [inf]\n")
    sweep("mass-zero", "[grid]\nmass_scale = [0.0]\n")
    sweep("cornering-nan", "[grid]\ncornering_scale = [nan]\n")
    sweep("seed-negative", "[grid]\nseed = [-3]\n")
    sweep("speed-100", "[grid]\nspeed_scale = [100.0]\n")
    sweep("track-binary", f"[grid]\ntrack = ['{d / 'binary.bin'}']\n")
    sweep("track-5rows", f"[grid]\ntrack = ['{d / 'paper-5rows.csv'}']\n")
    sweep("track-missing", "[grid]\ntrack = ['nowhere.csv']\n")
    sweep("track-waypoints", f"[grid]\ntrack = ['{d / 'wp-good.csv'}']\n")
    sweep("track-3pts", f"[grid]\ntrack = ['{d / 'track-3pts.csv'}']\n")
    sweep("range-inf", "[random]\nn = 2\nranges = { mass_scale = [0.9, inf] }\n")
    sweep("range-nan", "[random]\nn = 2\nranges = { noise_scale = [nan, 1.0] }\n")
    sweep("range-speed", "[random]\nn = 2\nranges = { speed_scale = [1.0, 50.0] }\n")
    sweep("choice-seed", "[random]\nn = 2\nchoices = { seed = [-1, 2] }\n")
    sweep("choice-method", "[random]\nn = 2\nchoices = { method = ['mpc'] }\n")
    sweep("n-zero", "[random]\nn = 0\n")
    sweep("config-nan", "[config.mpc]\nQ = [nan, 0.067, 13.333]\n")
    (d / "sweep-duration-inf.toml").write_text('name = "t"\nduration_s = inf\n')
    sweep("base-nan", "base_config = 'cfg-mpc-Q-nan.toml'\n")
    sweep("base-binary", "base_config = 'binary.bin'\n")
    sweep("lateral-inf", "max_lateral_m = inf\n")
    sweep("retries", "retries = -1\n")
    sweep("friction", "[grid]\nfriction = ['ice']\n")
    sweep("scenario", "[grid]\nscenario = ['hail']\n")
    sweep("good", "[grid]\nmethod = ['ref']\n")
    return d


RUN = ["run", "--no-plots", "--out", "{O}"]
REF = "{D}/ref-"

CASES: list[tuple[str, list[str], str]] = [
    # configs, through `run` (validated before the designs or the simulation)
    *[(f"config-{cid}", [*RUN, "--config", f"{{D}}/cfg-{cid}.toml"], needle)
      for cid, _, needle in CONFIGS],
    ("config-binary", [*RUN, "--config", "{D}/binary.bin"], "binary.bin: binary file"),
    ("config-latin1", [*RUN, "--config", "{D}/latin1.txt"], "latin1.txt: not UTF-8"),
    ("config-image", [*RUN, "--config", "{D}/image.png"], "image.png: binary file"),
    ("config-missing", [*RUN, "--config", "{D}/nowhere.toml"], "nowhere.toml: cannot read"),
    ("config-folder", [*RUN, "--config", "{D}/folder"], "folder: cannot read"),
    ("design-config-nan", ["design", "--config", "{D}/cfg-mpc-Q-nan.toml"], "mpc.Q"),
    ("demo-config-inf", ["plant-demo", "--config", "{D}/cfg-vehicle-mass-inf.toml"], "vehicle.mass"),
    ("compare-config-nan", ["compare", "--out", "{O}", "--config", "{D}/cfg-kin-lmi-Q-nan.toml"],
     "kinematic_lmi.Q"),
    # references
    ("ref-nan", [*RUN, "--reference", REF + "nan.csv"], "ref-nan.csv: line 12: x"),
    ("ref-inf", [*RUN, "--reference", REF + "inf.csv"], "ref-inf.csv: line 12: v"),
    ("ref-negative-speed", [*RUN, "--reference", REF + "negative-v.csv"], "speeds must be >= 0"),
    ("ref-speed-inconsistent", [*RUN, "--reference", REF + "speed-x2.csv"], "x, y and v are inconsistent"),
    ("ref-omega-inconsistent", [*RUN, "--reference", REF + "omega-wrong.csv"],
     "theta and omega are inconsistent"),
    ("ref-heading-flipped", [*RUN, "--reference", REF + "heading-flipped.csv"], "heading are inconsistent"),
    ("ref-time-nonuniform", [*RUN, "--reference", REF + "time-nonuniform.csv"], "uniformly sampled"),
    ("ref-time-backwards", [*RUN, "--reference", REF + "time-backwards.csv"], "strictly increasing"),
    ("ref-standstill", [*RUN, "--reference", REF + "standstill.csv"], "must move"),
    ("ref-short", [*RUN, "--reference", REF + "short.csv"], "N + 2"),
    ("ref-one-row", [*RUN, "--reference", REF + "one-row.csv"], "at least 2 samples"),
    ("ref-6-columns", [*RUN, "--reference", REF + "6cols.csv"], "7 columns"),
    ("ref-text", [*RUN, "--reference", REF + "text.csv"], "non-numeric"),
    ("ref-unknown-header", [*RUN, "--reference", REF + "unknown-header.csv"], "plan it first"),
    ("ref-empty", [*RUN, "--reference", "{D}/empty.csv"], "empty.csv"),
    ("ref-binary", [*RUN, "--reference", "{D}/binary.bin"], "binary.bin: binary file"),
    ("ref-image", [*RUN, "--reference", "{D}/image.png"], "image.png: binary file"),
    ("ref-latin1", [*RUN, "--reference", "{D}/latin1.txt"], "latin1.txt: not UTF-8"),
    ("ref-missing", [*RUN, "--reference", "{D}/nowhere.csv"], "nowhere.csv: cannot read"),
    ("ref-folder", [*RUN, "--reference", "{D}/folder"], "folder: cannot read"),
    ("ref-raw-track", [*RUN, "--reference", "{D}/track-good.csv"], "plan it first with `tsmpc plan"),
    ("compare-raw-track", ["compare", "--out", "{O}", "--reference", "{D}/track-good.csv"],
     "plan it first with `tsmpc plan"),
    ("ref-waypoints", [*RUN, "--reference", "{D}/wp-good.csv"], "plan it first"),
    ("paper-5-rows", [*RUN, "--reference", "{D}/paper-5rows.csv"], "needs 6 rows"),
    ("paper-ragged", [*RUN, "--reference", "{D}/paper-ragged.csv"], "different lengths"),
    ("paper-nan", [*RUN, "--reference", "{D}/paper-nan.csv"], "NaN or inf"),
    ("paper-text", [*RUN, "--reference", "{D}/paper-text.csv"], "non-numeric"),
    ("paper-standstill", [*RUN, "--reference", "{D}/paper-standstill.csv", "--window", "1,300"],
     "must move"),
    ("paper-default-window-too-wide", [*RUN, "--reference", "{D}/paper.csv"], "allowed columns are 1..300"),
    ("window-short", [*RUN, "--reference", "{D}/paper.csv", "--window", "5,20"], "N + 2"),
    ("window-reversed", [*RUN, "--reference", "{D}/paper.csv", "--window", "1316,5"], "FIRST < LAST"),
    ("window-zero", [*RUN, "--reference", "{D}/paper.csv", "--window", "0,100"], "1 <= FIRST"),
    ("window-past-end", [*RUN, "--reference", "{D}/paper.csv", "--window", "5,99999"],
     "allowed columns are 1..300"),
    ("window-text", [*RUN, "--reference", "{D}/paper.csv", "--window", "abc"], "--window"),
    ("window-one-number", [*RUN, "--reference", "{D}/paper.csv", "--window", "5"], "--window"),
    ("window-csv-short", [*RUN, "--reference", "{D}/good.csv", "--window", "1,30"], "N + 2"),
    ("window-csv-past-end", [*RUN, "--reference", "{D}/good.csv", "--window", "1,99999"],
     "allowed rows are 1..300"),
    # CLI values
    ("duration-inf", [*RUN, "--duration", "inf"], "--duration"),
    ("duration-nan", [*RUN, "--duration", "nan"], "--duration"),
    ("duration-zero", [*RUN, "--duration", "0"], "--duration"),
    ("duration-negative", [*RUN, "--duration", "-5"], "--duration"),
    ("seed-negative", [*RUN, "--seed", "-5"], "--seed"),
    ("methods-unknown", ["compare", "--out", "{O}", "--methods", "foo"], "unknown method"),
    ("methods-empty", ["compare", "--out", "{O}", "--methods", ","], "--methods is empty"),
    ("run-two-methods", [*RUN, "--method", "ref,fzn"], "one method"),
    ("scenario-unknown", [*RUN, "--scenario", "hail"], "unknown robustness scenario"),
    ("preset-unknown", [*RUN, "--preset", "bogus"], "unknown preset 'bogus'"),
    ("preset-with-bad-config", [*RUN, "--preset", "paper", "--config", "{D}/cfg-mhe-R-inf.toml"],
     "mhe.R"),
    ("compare-duration-inf", ["compare", "--out", "{O}", "--duration", "inf"], "--duration"),
    ("compare-seed-negative", ["compare", "--out", "{O}", "--seed", "-1"], "--seed"),
    ("out-is-file", ["run", "--out", "{D}/afile"], "exists and is a file"),
    ("out-under-file", ["run", "--out", "{D}/afile/sub"], "afile is a file"),
    ("out-not-empty", ["run", "--out", "{D}/full"], "--overwrite"),
    ("out-unwritable", ["run", "--out", "/proc/tsmpc-out"], "--out /proc/tsmpc-out"),
    ("demo-duration-inf", ["plant-demo", "--duration", "inf"], "--duration"),
    ("demo-duration-nan", ["plant-demo", "--duration", "nan"], "--duration"),
    ("plan-dt-tiny", ["plan", "{D}/track-good.csv", "--out", "{O}.csv", "--dt", "1e-5"], "samples"),
    ("plan-vmax-tiny", ["plan", "{D}/track-good.csv", "--out", "{O}.csv", "--v-max", "1e-3"], "samples"),
    ("plan-vmax-nan", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--v-max", "nan"], "--v-max"),
    ("plan-vmax-inf", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--v-max", "inf"], "--v-max"),
    ("plan-alat-negative", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--a-lat", "-1"], "--a-lat"),
    ("plan-dt-zero", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--dt", "0"], "--dt"),
    ("plan-dt-inf", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--dt", "inf"], "--dt"),
    ("plan-tail-inf", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--tail", "inf"], "--tail"),
    ("plan-tail-negative", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--tail", "-1"], "--tail"),
    ("plan-laps-open", ["plan", "{D}/wp-good.csv", "--out", "{O}.csv", "--open", "--laps", "2"], "laps"),
    ("plan-out-exists", ["plan", "{D}/wp-good.csv", "--out", "{D}/existing.csv"], "--overwrite"),
    ("plan-out-folder", ["plan", "{D}/wp-good.csv", "--out", "{D}/folder"], "is a folder"),
    ("plan-out-under-file", ["plan", "{D}/wp-good.csv", "--out", "{D}/afile/r.csv"], "afile is a file"),
    ("show-window-reversed", ["show-reference", "{D}/paper.csv", "--out", "{O}.png", "--window", "9,3"],
     "FIRST must be < LAST"),
    ("show-binary", ["show-reference", "{D}/binary.bin", "--out", "{O}.png"], "binary.bin: binary file"),
    ("sweep-timeout-zero", ["sweep", "{D}/sweep-good.toml", "--out", "{O}", "--connect-timeout", "0"],
     "--connect-timeout"),
    ("sweep-bad-address", ["sweep", "{D}/sweep-good.toml", "--out", "{O}", "--scheduler", "not-an-address"],
     "not a scheduler address"),
    ("sweep-unreachable", ["sweep", "{D}/sweep-good.toml", "--out", "{O}", "--scheduler",
                           "tcp://127.0.0.1:1", "--connect-timeout", "0.5"], "no scheduler answered"),
    ("sweep-workers", ["sweep", "{D}/sweep-good.toml", "--out", "{O}", "--workers", "1000"], "--workers"),
    ("sweep-out-file", ["sweep", "{D}/sweep-good.toml", "--out", "{D}/afile"], "exists and is a file"),
    # tracks and waypoints
    ("wp-reversal", ["plan", "{D}/wp-reversal.csv", "--out", "{O}.csv"], "direction reversal"),
    ("wp-half-lap-closed", ["plan", "{D}/wp-half-lap.csv", "--closed", "--out", "{O}.csv"], "closing chord"),
    ("wp-nan", ["plan", "{D}/wp-nan.csv", "--out", "{O}.csv"], "wp-nan.csv"),
    ("wp-text", ["plan", "{D}/wp-text.csv", "--out", "{O}.csv"], "numeric"),
    ("wp-one", ["plan", "{D}/wp-one.csv", "--out", "{O}.csv"], "at least 2 rows"),
    ("wp-binary", ["plan", "{D}/binary.bin", "--out", "{O}.csv"], "binary.bin: binary file"),
    ("wp-latin1", ["plan", "{D}/latin1.txt", "--out", "{O}.csv"], "latin1.txt: not UTF-8"),
    ("wp-image", ["plan", "{D}/image.png", "--out", "{O}.csv"], "image.png: binary file"),
    ("wp-missing", ["plan", "{D}/nowhere.csv", "--out", "{O}.csv"], "nowhere.csv: cannot read"),
    ("wp-huge", ["plan", "{D}/wp-huge.csv", "--out", "{O}.csv"], "metres expected"),
    ("wp-all-same", ["plan", "{D}/wp-same.csv", "--out", "{O}.csv"], "distinct waypoints"),
    ("wp-vcap-negative", ["plan", "{D}/wp-vcap.csv", "--out", "{O}.csv"], "v_cap"),
    ("track-3-points", ["plan", "{D}/track-3pts.csv", "--out", "{O}.csv"], "at least 4"),
    ("track-negative-width", ["plan", "{D}/track-negative-width.csv", "--out", "{O}.csv"],
     "widths must be positive"),
    ("track-3-columns", ["plan", "{D}/track-3cols.csv", "--out", "{O}.csv"], "expected 4 values"),
    ("track-nan", ["plan", "{D}/track-nan.csv", "--out", "{O}.csv"], "NaN or inf"),
    ("track-text", ["plan", "{D}/track-text.csv", "--out", "{O}.csv"], "non-numeric"),
    ("track-half-lap", ["plan", "{D}/track-half-lap.csv", "--out", "{O}.csv"], "closing chord"),
    ("track-reversal", ["plan", "{D}/track-reversal.csv", "--out", "{O}.csv"], "direction reversal"),
    ("show-track-reversal", ["show-reference", "{D}/track-reversal.csv", "--out", "{O}.png"],
     "direction reversal"),
    # sweep files
    *[(f"sweep-{name}", ["sweep", f"{{D}}/sweep-{name}.toml", "--out", "{O}"], needle) for name, needle in [
        ("noise-inf", "grid.noise_scale"), ("mass-inf", "grid.mass_scale"), ("mass-zero", "grid.mass_scale"),
        ("cornering-nan", "grid.cornering_scale"), ("seed-negative", "grid.seed"),
        ("speed-100", "grid.speed_scale"), ("track-binary", "binary.bin: binary file"),
        ("track-5rows", "needs 6 rows"), ("track-missing", "nowhere.csv"),
        ("track-waypoints", "plan it first"), ("track-3pts", "at least 4"),
        ("range-inf", "ranges.mass_scale"), ("range-nan", "ranges.noise_scale"),
        ("range-speed", "ranges.speed_scale"), ("choice-seed", "seed"), ("choice-method", "unknown method"),
        ("n-zero", "random.n"), ("config-nan", "mpc.Q"), ("duration-inf", "duration_s"),
        ("base-nan", "mpc.Q"), ("base-binary", "binary.bin: binary file"),
        ("lateral-inf", "max_lateral_m"), ("retries", "retries"), ("friction", "unknown friction"),
        ("scenario", "unknown robustness scenario")]],
    ("sweep-file-binary", ["sweep", "{D}/binary.bin", "--out", "{O}"], "binary.bin: binary file"),
    ("sweep-file-latin1", ["sweep", "{D}/latin1.txt", "--out", "{O}"], "latin1.txt: not UTF-8"),
    ("sweep-file-missing", ["sweep", "{D}/nowhere.toml", "--out", "{O}"], "nowhere.toml: cannot read"),
]


@pytest.mark.parametrize(("argv", "needle"), [pytest.param(a, n, id=i) for i, a, n in CASES])
def test_bad_input_exits_2_with_one_line_naming_it(files: Path, tmp_path: Path, argv: list[str],
                                                   needle: str) -> None:
    out = tmp_path / "out"
    args = [a.replace("{D}", str(files)).replace("{O}", str(out)) for a in argv]
    res = runner.invoke(app, args)
    text = res.output
    assert "Traceback" not in text
    assert isinstance(res.exception, SystemExit), repr(res.exception)  # never an uncaught error
    assert res.exit_code == 2, text
    assert needle in text, text
    # One message: ours ("error: ...") or click's usage error for a malformed option value.
    errors = [ln for ln in text.splitlines() if ln.lstrip(" │").lower().startswith("error:")]
    assert len(errors) == 1, text
    # Validation comes before any work: no output was written.
    assert not out.exists(), "a refused command left its output folder behind"
    assert not Path(f"{out}.csv").exists() and not Path(f"{out}.png").exists()


def test_the_table_has_at_least_100_cases() -> None:
    assert len(CASES) >= 100
    assert len({c[0] for c in CASES}) == len(CASES)
