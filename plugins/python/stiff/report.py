"""Self-contained HTML report of a diagnosis: matplotlib figures (Agg) embedded as base64 PNG,
no external files or scripts. `diagnosis_report(d)` returns the HTML text."""
from __future__ import annotations

import base64
import html
import io
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["diagnosis_report"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;max-width:1100px;margin:2em auto;
color:#222;line-height:1.45;padding:0 1em}
h1{font-size:1.5em} h2{font-size:1.2em;margin-top:2em;border-bottom:1px solid #ddd}
.verdict{padding:1em 1.2em;border-radius:8px;margin:1em 0;font-size:1.05em}
.missing_effect{background:#fff4e0;border-left:6px solid #e69500}
.adequate{background:#e8f6ea;border-left:6px solid #2e8b3a}
.ambiguous{background:#eef0fb;border-left:6px solid #4a57c8}
.unexplained{background:#fbeaea;border-left:6px solid #c0392b}
table{border-collapse:collapse;font-size:.92em;margin:.6em 0}
td,th{border-bottom:1px solid #e4e4e4;padding:.25em .6em;text-align:right}
td:first-child,th:first-child,td.l,th.l{text-align:left}
.num{font-size:1.6em;font-weight:600} .cards{display:flex;gap:1.2em;flex-wrap:wrap}
.card{background:#f7f7f7;border-radius:8px;padding:.6em 1em;min-width:10em}
img{max-width:100%} code{background:#f2f2f2;padding:.1em .3em;border-radius:3px}
.small{color:#666;font-size:.9em}
"""


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96, bbox_inches="tight")
    plt.close(fig)
    return '<img alt="figure" src="data:image/png;base64,' + base64.b64encode(buf.getvalue()).decode() + '">'


def _um(v, spec=".2f") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v * 1e6:{spec}} um"


def _e(s) -> str:
    return html.escape(str(s))


def _residual_figure(d) -> str:
    res = d["residuals"]
    floor = d["noise_floor_m"]
    idx = np.arange(len(res))
    r = np.array([p["residual_m"] for p in res]) * 1e6
    norm = np.array([p["norm_m"] for p in res]) * 1e6
    out = np.array([p["outlier"] for p in res], dtype=bool)
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.6), sharex=True,
                             gridspec_kw={"height_ratios": [1.2, 1]})
    ax = axes[0]
    # Residual vectors: an arrow per pose, (x, z) components drawn from the pose's position on
    # the axis; colour = y component.
    q = ax.quiver(idx, np.zeros_like(idx), r[:, 0], r[:, 2], r[:, 1], cmap="coolwarm",
                  angles="xy", scale_units="xy", scale=1.0 / 0.6 * max(1e-9, np.abs(r).max()) / 3,
                  width=0.003)
    ax.set_ylim(-1.05 * 3, 1.05 * 3)
    ax.set_yticks([])
    ax.set_ylabel("residual vector\n(x right, z up)")
    fig.colorbar(q, ax=ax, label="y [um]", pad=0.01)
    ax.set_title("Residual of every calibration pose (measured - predicted)")
    ax = axes[1]
    colors = np.where(out, "#c0392b", "#4a78c8")
    ax.bar(idx, norm, color=colors)
    if floor > 0:
        ax.axhline(floor * 1e6 * math.sqrt(3), color="k", ls="--", lw=1, label="noise floor x sqrt(3)")
        ax.axhline(3 * floor * 1e6 * math.sqrt(3), color="k", ls=":", lw=1, label="3x")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel("|residual| [um]")
    ax.set_xlabel("pose (row); red = outlier, excluded from the tests")
    return _png(fig)


def _ranking_figure(d) -> str:
    cands = [c for c in d["candidates"] if c["testable"]]
    if not cands:
        return "<p>No testable candidate.</p>"
    names = [c["effect"] for c in cands][::-1]
    drop = [c["expected_rms_drop_m"] * 1e6 for c in cands][::-1]
    lp = [-(c["log10_p"] if c["log10_p"] is not None else -300) for c in cands][::-1]
    sig = [c["significant"] for c in cands][::-1]
    fig, axes = plt.subplots(1, 2, figsize=(10, 0.35 * len(cands) + 1.5), sharey=True)
    col = ["#e69500" if s else "#9aa5b1" for s in sig]
    axes[0].barh(names, drop, color=col)
    axes[0].set_xlabel("expected RMS drop [um]")
    axes[0].set_title("effect size")
    axes[1].barh(names, lp, color=col)
    axes[1].set_xlabel("-log10 p (partial F)")
    axes[1].set_title("evidence (orange = significant after Holm)")
    axes[1].set_xscale("symlog", linthresh=3)
    return _png(fig)


def _added_variable_figure(d) -> str:
    cands = [c for c in d["candidates"] if c.get("added_variable")]
    if not cands:
        return ""
    fig, axes = plt.subplots(1, len(cands), figsize=(3.6 * len(cands), 3.5), squeeze=False)
    for ax, c in zip(axes[0], cands):
        x = np.array(c["added_variable"]["fitted_m"]) * 1e6
        y = np.array(c["added_variable"]["residual_m"]) * 1e6
        ax.scatter(x, y, s=8, alpha=0.6, color="#4a78c8")
        lim = max(1e-9, np.abs(np.concatenate([x, y])).max())
        ax.plot([-lim, lim], [-lim, lim], color="#e69500", lw=1)
        ax.set_title(f"#{c['rank']} {c['effect']}", fontsize=10)
        ax.set_xlabel("candidate component, projected [um]")
        ax.set_ylabel("current residual [um]")
    fig.suptitle("Added-variable plots: slope 1 and little scatter = the candidate explains the residual",
                 fontsize=10)
    fig.tight_layout()
    return _png(fig)


def _covariate_figure(d) -> str:
    cov = d["where"]["covariates"]
    if not cov:
        return ""
    cov = sorted(cov, key=lambda c: c["p_value"])[:20][::-1]
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(cov) + 1.2))
    vals = [-math.log10(max(c["p_value"], 1e-300)) for c in cov]
    # Red: structure (significant and a tenth of the residual or more); amber: significant but
    # too small to be structure (docs/diagnosis.md, section 3, rule 1).
    ax.barh([c["covariate"] for c in cov], vals,
            color=[("#c0392b" if c.get("structure", True) else "#e0a030") if c["significant"]
                   else "#9aa5b1" for c in cov])
    ax.set_xlabel("-log10 p (residual vs covariate, partial F; red = significant after Holm and "
                  "a tenth of the residual or more, amber = significant, smaller)")
    ax.set_title("Where the model fails: residual structure")
    return _png(fig)


def _validation_figure(d) -> str:
    series = []
    steps = d.get("steps", [])
    if len(steps) > 1:
        for s in steps:
            if "validation_error_m" in s:
                series.append((s["model"], s["validation_error_m"]))
    else:
        if "validation_error_m" in d["fit"]:
            series.append((d["fit"]["model"], d["fit"]["validation_error_m"]))
        if d.get("after") and "validation_error_m" in d["after"]:
            series.append((d["after"]["model"] + " (suggested)", d["after"]["validation_error_m"]))
    if not series:
        return ""
    fig, ax = plt.subplots(figsize=(10, 3.4))
    n = len(series)
    width = 0.8 / n
    for i, (name, err) in enumerate(series):
        e = np.array(err) * 1e6
        ax.bar(np.arange(len(e)) + (i - (n - 1) / 2) * width, e, width=width,
               label=f"{name}: RMS/axis {np.sqrt(np.mean(e ** 2) / 3):.1f} um")
    floor = d.get("validation", {}).get("floor_m", 0)
    if floor:
        ax.axhline(floor * 1e6 * math.sqrt(3), color="k", ls="--", lw=1, label="floor x sqrt(3)")
    ax.set_xlabel("validation pose")
    ax.set_ylabel("|prediction error| [um]")
    ax.legend(fontsize=8)
    ax.set_title("Validation error per pose, before / after")
    return _png(fig)


def _steps_figure(d) -> str:
    steps = d.get("steps", [])
    if len(steps) < 2:
        return ""
    fig, ax = plt.subplots(figsize=(7, 3.2))
    x = np.arange(len(steps))
    ax.plot(x, [s["rms_m"] * 1e6 for s in steps], "o-", label="fit RMS")
    if all("validation_rms_m" in s for s in steps):
        ax.plot(x, [s["validation_rms_m"] * 1e6 for s in steps], "s-", label="validation RMS")
    if d["noise_floor_m"] > 0:
        ax.axhline(d["noise_floor_m"] * 1e6, color="k", ls="--", lw=1, label="noise floor")
    ax.set_xticks(x, [("+" + s["added"]) if s["added"] else s["model"] for s in steps], rotation=20)
    ax.set_ylabel("RMS per axis [um]")
    ax.legend(fontsize=8)
    ax.set_title("The loop: the error falls as effects are added")
    return _png(fig)


def _table(headers, rows) -> str:
    h = "".join(f"<th>{_e(x)}</th>" for x in headers)
    body = "".join("<tr>" + "".join(f"<td>{x}</td>" for x in r) + "</tr>" for r in rows)
    return f"<table><tr>{h}</tr>{body}</table>"


def diagnosis_report(d, title: str = "stiff diagnose") -> str:
    """HTML text of the report for a Diagnosis (or its JSON dict)."""
    d = dict(d)
    fit = d["fit"]
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title>",
             f"<style>{_CSS}</style></head><body>", f"<h1>{_e(title)}</h1>"]
    parts.append(f"<div class='verdict {_e(d['verdict'])}'><b>Verdict: {_e(d['verdict'])}</b><br>"
                 f"{_e(d['summary'])}")
    if d.get("suggested_command") and d["verdict"] in ("missing_effect", "ambiguous"):
        parts.append(f"<br>Next: <code>{_e(d['suggested_command'])}</code>")
    parts.append("</div>")
    cards = [("model", _e(d["model"])), ("fit RMS", _um(fit["rms_m"])),
             ("noise floor", _um(d["noise_floor_m"]) + "<div class='small'>" + _e(d["noise_source"])
              + (", force error along the compliance" if d.get("noise_force_error") else "")
              + "</div>")]
    if "validation" in d:
        cards.append(("validation RMS", _um(d["validation"]["rms_m"])
                      + f"<div class='small'>floor {_um(d['validation']['floor_m'])}</div>"))
    if d["noise_floor_m"] > 0:
        cards.append(("chi2 / dof", f"{fit['chi2']:.0f} / {fit['dof']}"
                      + f"<div class='small'>p = {fit['chi2_p']:.2g}</div>"))
    parts.append("<div class='cards'>" + "".join(
        f"<div class='card'><div class='small'>{k}</div><div class='num'>{v}</div></div>" for k, v in cards)
        + "</div>")

    parts.append("<h2>1. How good is the model</h2>")
    parts.append("<p>Fit and validation error against the noise floor; the omnibus test compares "
                 "chi2 = RSS/sigma^2 with chi2<sub>n-p</sub>.</p>")
    parts.append(_residual_figure(d))
    w = d["where"]
    parts.append("<h2>2. Where it fails</h2>")
    parts.append(_table(["pose", "row", "|residual|", "sigma units", "outlier"],
                        [[_e(p["id"]), p["row"] + 1, _um(p["norm_m"]),
                          "-" if p["norm_sigma"] is None else f"{p['norm_sigma']:.1f}",
                          "yes" if p["outlier"] else ""] for p in w["worst_poses"]]))
    parts.append(_table(["axis", "RMS", "chi2 p"],
                        [[a["axis"], _um(a["rms_m"]), f"{a['chi2_p']:.2g}"] for a in w["axes"]]))
    parts.append(_covariate_figure(d))
    parts.append("<h2>3. What is missing</h2>")
    parts.append(_ranking_figure(d))
    rows = []
    for c in d["candidates"]:
        if c["testable"]:
            rows.append([c["rank"], f"<span class='l'>{_e(c['effect'])}</span>", f"{c['statistic']:.3g}",
                         c["df"], f"{c['p_value']:.2g}", f"{c['p_adjusted']:.2g}",
                         _um(c["expected_rms_drop_m"]), "yes" if c["identifiable"] else "partly",
                         _e("+".join(c["group"]) if len(c["group"]) > 1 else ""),
                         f"<code>{_e(c['command'])}</code>"])
        else:
            rows.append(["-", _e(c["effect"]), "-", "-", "-", "-", "-", "no", "",
                         f"<span class='small'>{_e(c['reason'])}</span>"])
    parts.append(_table(["rank", "candidate", "F", "df", "p", "p (Holm)", "RMS drop", "identifiable",
                         "group", "command / reason"], rows))
    parts.append(_added_variable_figure(d))
    if d.get("experiment"):
        parts.append(f"<p><b>Discriminating experiment:</b> {_e(d['experiment'])}</p>")
    if d.get("outside_rival"):
        parts.append(f"<p><b>Also explained by a mechanism outside the library:</b> "
                     f"{_e(d['outside_rival'])} (see the verdict)</p>")
    if d.get("unexplained_signature"):
        parts.append(f"<p><b>Signature of the unexplained structure:</b> {_e(d['unexplained_signature'])}</p>")
    parts.append("<h2>4. Before / after</h2>")
    parts.append(_validation_figure(d))
    steps = d.get("steps", [])
    hist = list(steps)
    if len(steps) <= 1 and d.get("after"):
        a = dict(d["after"])
        a.update(step="suggested", added=d["candidates"][0]["effect"] if d["candidates"] else "",
                 verdict="(not run)")
        hist.append(a)
    parts.append(_table(["step", "added", "model", "fit RMS", "validation RMS", "chi2 p", "verdict"],
                        [[s["step"], _e(s["added"] or "-"), _e(s["model"]), _um(s["rms_m"]),
                          _um(s.get("validation_rms_m")), f"{s['chi2_p']:.2g}", _e(s["verdict"])]
                         for s in hist]))
    parts.append(_steps_figure(d))
    if d.get("warnings"):
        parts.append("<h2>Warnings</h2><ul>" + "".join(f"<li>{_e(x)}</li>" for x in d["warnings"]) + "</ul>")
    parts.append("<p class='small'>Statistics: group score / partial-F tests (Rao 1948) on candidate "
                 "regressors projected off the current model, Holm (1979) correction, added-variable "
                 "plots (Cook &amp; Weisberg 1982). See docs/diagnosis.md.</p></body></html>")
    return "\n".join(parts)
