"""One static report page per run: ``report.html`` in the output folder of compare/run.

Self-contained: the figures are embedded as base64 PNG, the style sheet is inline, there is no
script and no network resource, so the page opens from a file, an e-mail or an archive years
later. It holds the RMSE table (the paper's rows beside ours on the paper's reference), the
timing table, the events, the scenario, the versions, the config and links to the data files.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Iterable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tsmpc.report.tables import COMFORT_COLUMNS, comfort_cell, comfort_rows, rmse_rows
from tsmpc.sim.log import atomic_write_text

__all__ = ["FIGURE_CAPTIONS", "render_report", "write_report"]

#: Figure file stem → caption, in the order of the page.
FIGURE_CAPTIONS: dict[str, str] = {
    "circuit": "Reference and driven paths, with a zoom at the largest lateral error.",
    "errors": "Tracking errors e_x, e_y, e_θ and the speed and yaw-rate errors.",
    "differences": "Each method's tracking errors minus the baseline's (NL when present): "
                   "what separates methods whose curves overlap above.",
    "velocities": "Speed and yaw rate: reference and plant.",
    "control": "Inner control actions (F_xR, δ) with their saturation limits and the outer "
               "MPC outputs (v_ref, ω_ref) with the MPC's input bounds.",
    "friction": "Friction force felt by the plant against the MHE-UIO estimate; μ(road).",
    "solve_time": "Per-step MPC solve time against the T_c deadline (log scale).",
}

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0 auto;max-width:1180px;
padding:1.2em 2em;color:#1d232a;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #d0d7de;padding-bottom:.2em;margin-top:1.6em}
.sub{color:#57606a;margin-top:0}
table{border-collapse:collapse;margin:.6em 0 1em;font-size:.92em}
th,td{border:1px solid #d0d7de;padding:.3em .6em;text-align:right}
th{background:#f3f5f7}td:first-child,th:first-child{text-align:left}
tr.paper td{color:#6e7781;font-style:italic}
tr.bad td{background:#ffebe9}
figure{margin:1em 0 2em}figure img{max-width:100%;border:1px solid #e1e4e8}
figcaption{color:#57606a;font-size:.92em}
pre{background:#f6f8fa;padding:.8em;overflow:auto;font-size:.85em}
nav a{margin-right:1em}
.ok{color:#1a7f37}.warn{color:#cf222e;font-weight:bold}
"""


def _e(v: Any) -> str:
    return html.escape(str(v), quote=True)


def _num(v: Any, fmt: str = ".3f") -> str:
    try:
        return format(float(v), fmt)
    except (TypeError, ValueError):
        return _e(v)


def _table(tid: str, head: Iterable[str], rows: Iterable[tuple[Iterable[str], str]]) -> str:
    """An HTML table; ``rows`` are (already escaped cells, row class)."""
    out = [f'<table id="{tid}"><thead><tr>' + "".join(f"<th>{_e(h)}</th>" for h in head)
           + "</tr></thead><tbody>"]
    for cells, cls in rows:
        attr = f' class="{cls}"' if cls else ""
        out.append(f"<tr{attr}>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _rmse_table(metrics: dict[str, Any]) -> str:
    paper = bool(metrics.get("scenario", {}).get("paper_reference"))
    rows = []
    for lab, vals in rmse_rows(metrics, paper):
        if lab.endswith("(diverged)"):  # as the terminal prints it: no RMSE of a run cut short
            rows.append(([_e(lab), "diverged", *(["—"] * (len(vals) - 1))], "bad"))
            continue
        rows.append(([_e(lab), *(_num(v) for v in vals)], "paper" if lab.endswith("(paper)") else ""))
    return _table("table-rmse", ("approach", "x [m]", "y [m]", "θ [rad]", "v [m/s]", "ω [rad/s]"), rows)


def _timing_table(metrics: dict[str, Any]) -> str:
    rows = []
    for name, m in metrics["methods"].items():
        ratio = m.get("mpc_ms_ratio_to_REF")
        term = m.get("termination", "completed")
        cells = [_e(name), _num(m["mpc_ms"]["median"]), _num(m["mpc_ms"]["p95"]),
                 _num(m["mpc_ms"]["p99"]), _num(m["mpc_ms"]["max"], ".2f"),
                 "–" if ratio is None else _num(ratio, ".1f"),
                 _num(m["mhe_ms"]["median"]), _num(m["mhe_ms"]["p99"]),
                 _num(m["max_abs_lateral_m"]), _num(m["friction_rmse_N"], ".0f"),
                 _num(m["realtime_factor"], ".1f"), _num(m.get("wall_s", float("nan")), ".1f"),
                 _e(term)]
        rows.append((cells, "" if term == "completed" else "bad"))
    head = ("method", "MPC median [ms]", "MPC p95", "MPC p99", "MPC max", "× REF", "MHE median [ms]",
            "MHE p99", "max |e_y| [m]", "F̂ RMSE [N]", "real-time ×", "wall [s]", "termination")
    return _table("table-timing", head, rows)


def _comfort_table(metrics: dict[str, Any]) -> str:
    rows = [([_e(lab), *(comfort_cell(v, d) for v, (_, _, d) in zip(vals, COMFORT_COLUMNS, strict=True))],
             "bad" if lab.endswith("(diverged)") else "")
            for lab, vals in comfort_rows(metrics)]
    return _table("table-comfort", ("method", *(h for _, h, _ in COMFORT_COLUMNS)), rows)


def _events_table(metrics: dict[str, Any]) -> str:
    names: list[str] = []
    for m in metrics["methods"].values():
        for k in m.get("events", {}):
            if k not in names:
                names.append(k)
    rows = [([_e(k), *(_e(m.get("events", {}).get(k, 0)) for m in metrics["methods"].values())],
             "bad" if any(m.get("events", {}).get(k, 0) for m in metrics["methods"].values()) else "")
            for k in names]
    if any(m.get("plan_delay_s") for m in metrics["methods"].values()):  # the governor's cost in time
        rows.append(([_e("behind plan [s]"),
                      *(_e(f"{m['plan_delay_s']:.1f}" if "plan_delay_s" in m else "—")
                        for m in metrics["methods"].values())], "bad"))
    return _table("table-events", ("event", *metrics["methods"]), rows)


def _kv_table(tid: str, data: dict[str, Any]) -> str:
    return _table(tid, ("field", "value"), (([_e(k), _e(v)], "") for k, v in data.items()))


def render_report(
    metrics: dict[str, Any],
    figures: dict[str, bytes],
    data_files: Iterable[str] = (),
    config_toml: str | None = None,
    title: str | None = None,
) -> str:
    """The report page as a string.

    Args:
        metrics: the ``metrics.json`` content (methods, scenario, versions).
        figures: figure stem → PNG bytes, embedded in the order of :data:`FIGURE_CAPTIONS`
            (unknown stems after them).
        data_files: file names in the output folder, linked relatively.
        config_toml: the run's config, shown verbatim.
        title: page title (default from the scenario and methods).
    """
    sc = metrics.get("scenario", {})
    methods = list(metrics.get("methods", {}))
    command = "compare" if len(methods) > 1 else "run"
    title = title or f"tsmpc {command} — {sc.get('name', '?')} — {', '.join(methods)}"
    paper_rows = any(lab.endswith("(paper)")
                     for lab, _ in rmse_rows(metrics, bool(sc.get("paper_reference"))))
    inner = ("oracle: the inner loop on the true plant state, no friction compensation"
             if metrics.get("oracle") else "the inner loop on the MHE-UIO estimate")
    failed = [n for n, m in metrics["methods"].items() if m.get("termination", "completed") != "completed"]
    status = (f'<span class="warn">{_e(", ".join(failed))} did not complete</span>' if failed
              else '<span class="ok">every method completed</span>')
    order = [k for k in FIGURE_CAPTIONS if k in figures] + [k for k in figures if k not in FIGURE_CAPTIONS]
    parts = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_e(title)}</h1>",
        f'<p class="sub">{status}; simulated {_num(sc.get("tracked_steps", 0), ".0f")} MPC steps '
        f'at T_c = {_e(sc.get("Tc", "?"))} s; {_e(inner)}; '
        f'generated {datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")} by tsmpc '
        f'{_e(metrics.get("versions", {}).get("tsmpc", "?"))}.</p>',
        '<nav><a href="#tables">tables</a><a href="#figures">figures</a><a href="#scenario">scenario</a>'
        '<a href="#versions">versions</a><a href="#files">data files</a></nav>',
        '<h2 id="tables">Tracking RMSE</h2>',
        "<p>Root-mean-square errors over the run (m, rad, m/s, rad/s)"
        + ("; the paper's Table 5 rows in grey italics." if paper_rows else ".") + "</p>",
        _rmse_table(metrics),
        "<h2>Solve times, tracking and real-time factor</h2>",
        "<p>Per-step wall times measured inside the closed loop.</p>",
        _timing_table(metrics),
        "<h2>Comfort and effort</h2><p>From the true plant state and the commands every T_d: body-frame "
        "lateral acceleration and jerk, longitudinal jerk, steering and force-command rates (each "
        "derivative after a 5 Hz zero-phase low-pass), and the settling time of |e_y| into 0.10 m "
        "(definitions: <code>tsmpc.sim.comfort</code>).</p>",
        _comfort_table(metrics),
        "<h2>Events</h2><p>Counted inside <code>step()</code>: solver fallbacks, soft terminal sets, "
        "clipped scheduling variables, rejected measurements, saturations.</p>",
        _events_table(metrics),
        '<h2 id="figures">Figures</h2>',
    ]
    if not order:
        parts.append("<p>No figures (the run used <code>--no-plots</code>).</p>")
    for stem in order:
        b64 = base64.b64encode(figures[stem]).decode("ascii")
        cap = FIGURE_CAPTIONS.get(stem, stem)
        parts.append(f'<figure id="fig-{_e(stem)}"><img alt="{_e(stem)}" '
                     f'src="data:image/png;base64,{b64}"><figcaption><b>{_e(stem)}</b>: {_e(cap)}'
                     f"</figcaption></figure>")
    parts += ['<h2 id="scenario">Scenario</h2>', _kv_table("table-scenario", sc),
              '<h2 id="versions">Versions</h2>', _kv_table("table-versions", metrics.get("versions", {}))]
    if config_toml is not None:
        parts += ["<h2>Config</h2>", f"<pre>{_e(config_toml)}</pre>"]
    files = sorted(set(data_files))
    parts.append('<h2 id="files">Data files</h2><ul>')
    parts += [f'<li><a href="{_e(f)}">{_e(f)}</a></li>' for f in files]
    parts += ["</ul>", "</body></html>", ""]
    return "\n".join(parts)


def write_report(out_dir: str | Path, metrics: dict[str, Any], files: Iterable[Path] = ()) -> Path:
    """Write ``report.html`` into ``out_dir`` (atomically) from the metrics and the ``files``
    written by this run (its PNG figures are embedded, the rest linked); returns its path.

    Only this run's files are used: stale figures of an earlier run in the folder are ignored."""
    from tsmpc.textfile import read_bytes, read_text

    out = Path(out_dir)
    figures = {Path(p).stem: read_bytes(p, "figure (PNG)") for p in files
               if Path(p).suffix == ".png" and Path(p).parent == out}
    names = [Path(f).name for f in files if Path(f).parent == out and Path(f).suffix != ".png"]
    cfg_path = out / "config.toml"
    config_toml = read_text(cfg_path, "config file (TOML)") if cfg_path.is_file() else None
    path = out / "report.html"
    atomic_write_text(path, render_report(metrics, figures, names, config_toml))
    return path
