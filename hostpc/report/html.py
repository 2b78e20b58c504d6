"""One self-contained HTML file of a diagnosis: every plot embedded as a base64 PNG, no
external scripts, styles or fonts, so it opens anywhere (and can be archived with a run)."""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence
from pathlib import Path

import hostpc
from hostpc.diagnostics import Diagnosis
from hostpc.diagnostics.pipeline import variables_of
from hostpc.report import plots

DISPLAY = {"rad": ("deg", math.degrees(1.0)), "m": ("mm", 1e3),
           "rad/(N m)": ("deg/(N m)", math.degrees(1.0)), "1": ("ppm", 1e6)}

STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px;
       color: #222; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.6em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: right; }
th { background: #f4f4f4; } td.name, th.name { text-align: left; font-family: monospace; }
.verdict { padding: 0.8em 1em; border-radius: 6px; font-size: 1.1em; font-weight: bold; }
.good { background: #e5f5e0; border: 1px solid #74c476; }
.bad { background: #fee0d2; border: 1px solid #fb6a4a; }
.significant { color: #c00; font-weight: bold; }
img { max-width: 100%; height: auto; display: block; margin: 0.5em 0; }
.row { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
code { background: #f4f4f4; padding: 0 0.2em; }
"""


def _e(value: object) -> str:
    return html.escape(str(value))


def _mm(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value * 1e3:.4f}"


def _num(value: float | None, digits: int = 3) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _p(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.2g}"


def _display(value: float | None, unit: str) -> tuple[str, str]:
    shown, factor = DISPLAY.get(unit, (unit, 1.0))
    if value is None or not math.isfinite(value):
        return "-", shown
    return f"{value * factor:+.5g}", shown


def _table(header: Sequence[str], rows: Iterable[Sequence[str]], name_columns: int = 1,
           flags: Iterable[bool] | None = None) -> str:
    """An HTML table; cells are already escaped; the first name_columns are left-aligned."""
    head = "".join(f'<th class="name">{h}</th>' if k < name_columns else f"<th>{h}</th>"
                   for k, h in enumerate(header))
    body = []
    flag_list = list(flags) if flags is not None else None
    for r, row in enumerate(rows):
        cls = ' class="significant"' if flag_list and flag_list[r] else ""
        cells = "".join(f'<td class="name">{c}</td>' if k < name_columns else f"<td>{c}</td>"
                        for k, c in enumerate(row))
        body.append(f"<tr{cls}>{cells}</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _img(uri: str, alt: str) -> str:
    return f'<img src="{uri}" alt="{_e(alt)}">'


def _summary(diagnosis: Diagnosis) -> str:
    a = diagnosis.check.adequacy
    rows = [
        ("chi2 / dof", f"{_num(a.chi2_dof)} (dof {a.dof})"),
        ("expected band", f"{_num(a.chi2_band[0])} .. {_num(a.chi2_band[1])}"),
        ("p (chi2 this large)", _p(a.p_value)),
        ("in-sample RMS / max [mm]", f"{_mm(a.rms)} / {_mm(a.max)}"),
        (f"held-out RMS / max [mm] ({a.cv_folds}-fold)", f"{_mm(a.cv_rms)} / {_mm(a.cv_max)}"),
        ("held-out whitened RMS [sigma]", _num(a.cv_whitened_rms)),
        ("noise per sample, corrected [mm]", _mm(a.noise_rms)),
        ("noise the covariances state [mm]", _mm(a.expected_noise_rms)),
        ("whitened noise ratio (measured / stated)", _num(a.noise_scale)),
        ("outliers (sample: leave-one-out sigma)",
         ", ".join(f"#{o.sample}: {o.sigma:.3g}" for o in diagnosis.outliers) or "none"),
    ]
    return _table(("quantity", "value"), [(_e(k), _e(v)) for k, v in rows])


def _candidates(diagnosis: Diagnosis) -> str:
    rows = [(_e(c.effect), _num(c.delta_bic, 1), _num(c.delta_bic_full, 1), _mm(c.rms),
             _mm(c.cv_rms), _num(c.chi2_dof), _p(c.p_value),
             _e(", ".join(c.selected) or "-") if c.testable
             else "not testable: no degrees of freedom left")
            for c in diagnosis.candidates]
    rows += [(_e(s.effect), "-", "-", "-", "-", "-", "-", _e(f"skipped: {s.reason}"))
             for s in diagnosis.check.skipped]
    flags = [c.significant for c in diagnosis.candidates] + [False] * len(diagnosis.check.skipped)
    return _table(("effect", "delta BIC", "delta BIC (all)", "RMS [mm]", "held-out [mm]",
                   "chi2/dof", "p", "parameters the data need"), rows, flags=flags)


def _interactions(diagnosis: Diagnosis, top: int = 15) -> str:
    shown = diagnosis.interactions[:top]
    rows = [(_e(i.parameter), _e(i.variable), _num(i.score, 1), _p(i.p_value), _e(i.basis))
            for i in shown]
    return _table(("parameter", "varies with", "score", "p", "basis"), rows, name_columns=2,
                  flags=[i.significant for i in shown])


def _ladder(diagnosis: Diagnosis) -> str:
    if not diagnosis.ladder:
        return ("<p>Run <code>hostpc diagnose DATASET --ladder</code> to fit the nested models "
                "and watch the error fall.</p>")
    rows = [(str(s.step), _e(s.added or "(current model)"), _mm(s.rms), _mm(s.cv_rms),
             _mm(s.cv_max), _num(s.cv_whitened_rms), _num(s.chi2_dof),
             "adequate" if s.adequate else "NOT adequate") for s in diagnosis.ladder]
    table = _table(("step", "added", "RMS [mm]", "held-out RMS [mm]", "held-out max [mm]",
                    "held-out [sigma]", "chi2/dof", "verdict"), rows, name_columns=2)
    notes = ""
    if diagnosis.check.outliers:
        excluded = ", ".join(f"#{k}" for k in diagnosis.check.excluded)
        notes += f"<p>Fitted without the outlier samples {_e(excluded)}.</p>"
    if diagnosis.ladder_stop:
        notes += f"<p>Stopped: {_e(diagnosis.ladder_stop)}.</p>"
    return _img(plots.ladder_chart(diagnosis), "ladder chart") + notes + table


def _parameters(diagnosis: Diagnosis) -> str:
    rows = []
    for p in diagnosis.fit.parameters.values():
        value, unit = _display(p.value, p.unit)
        sigma = "fixed" if p.fixed else _display(p.std, p.unit)[0].lstrip("+")
        rows.append((_e(p.name), value, sigma, _e(unit)))
    table = _table(("parameter", "value", "sigma", "unit"), rows)
    correlations = diagnosis.fit.correlations
    listed = "".join(f"<li><code>{_e(a)}</code> ~ <code>{_e(b)}</code>: {rho:+.3f}</li>"
                     for a, b, rho in correlations[:20])
    strong = (f"<p>Strong correlations (|rho| &gt; 0.9):</p><ul>{listed}</ul>" if listed
              else "<p>No correlation above 0.9.</p>")
    return (f'<div class="row"><div>{table}</div><div>'
            f'{_img(plots.correlation_matrix(diagnosis), "correlation matrix")}'
            f"{strong}</div></div>")


def _identifiability(diagnosis: Diagnosis) -> str:
    fit = diagnosis.fit
    directions = "".join(f"<li>{_e(d.description)}</li>" for d in fit.unidentifiable)
    text = (f"<ul>{directions}</ul>" if directions
            else "<p>Every parameter is identifiable from these measurements.</p>")
    return (f"<p>Jacobian rank {fit.rank} of {len(fit.names)}, condition number "
            f"{fit.condition_number:.3g}.</p>{text}"
            f'{_img(plots.singular_values(diagnosis), "singular values")}')


def render_html(diagnosis: Diagnosis, title: str | None = None) -> str:
    """The report as one HTML string."""
    check = diagnosis.check
    fit = diagnosis.fit
    a = check.adequacy
    title = title or f"zerocal diagnosis: {diagnosis.source or 'dataset'}"
    verdict_class = "good" if a.adequate else "bad"
    verdict = "adequate" if a.adequate else "NOT adequate"
    advice = "".join(f"<li>{_e(s)}</li>" for s in diagnosis.advice)
    outliers = set(check.excluded)
    worst = _table(("sample", "|residual| [mm]", "whitened [sigma]"),
                   [(str(w.index) + (" (outlier)" if w.index in outliers else ""), _mm(w.norm),
                     _num(w.whitened_norm, 2)) for w in diagnosis.residuals.worst],
                   flags=[w.index in outliers for w in diagnosis.residuals.worst])
    patterns = _table(("variable", "chi2", "dof", "p"),
                      [(_e(p.variable), _num(p.chi2, 1), str(p.dof), _p(p.p_value))
                       for p in diagnosis.residuals.patterns],
                      flags=[p.significant for p in diagnosis.residuals.patterns])
    variables = variables_of(fit)
    sections = [
        f"<h1>{_e(title)}</h1>",
        f"<p>Method <code>{_e(fit.problem.method)}</code>, {fit.residuals_raw.shape[0]} "
        f"samples, model <code>{_e(', '.join(check.effects))}</code>, significance "
        f"{diagnosis.alpha:g} per family of tests. zerocal {_e(hostpc.__version__)}.</p>",
        f'<div class="verdict {verdict_class}">The model is {verdict}.</div>',
        f"<h2>Advice</h2><ol>{advice}</ol>",
        f"<h2>Is the model adequate?</h2>{_summary(diagnosis)}",
        "<h2>Model vs measurement</h2>",
        _img(plots.model_vs_measurement(diagnosis), "model vs measurement"),
        f'<div class="row">{_img(plots.whitened_histogram(diagnosis), "whitened residuals")}'
        f"<div><p>Worst samples</p>{worst}</div></div>",
        "<h2>Where does it fail?</h2>",
        _img(plots.residuals_vs_variables(diagnosis, variables), "residuals vs variables"),
        f"<p>Binned residuals against each variable (red: significant after correction for "
        f"{len(diagnosis.residuals.patterns)} variables).</p>{patterns}",
        "<h2>Which effect is missing?</h2>",
        f'<div class="row">{_img(plots.candidate_ranking(diagnosis), "candidate ranking")}'
        f"<div>{_candidates(diagnosis)}</div></div>",
        f"<p>Effect-agnostic search: {check.n_interaction_tests} (parameter, variable) pairs "
        f"tested.</p>",
        f'<div class="row">{_img(plots.interaction_ranking(diagnosis), "interactions")}'
        f"<div>{_interactions(diagnosis)}</div></div>",
        f"<h2>Ladder</h2>{_ladder(diagnosis)}",
        f"<h2>Parameters</h2>{_parameters(diagnosis)}",
        f"<h2>Identifiability</h2>{_identifiability(diagnosis)}",
    ]
    body = "\n".join(sections)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{_e(title)}</title><style>{STYLE}</style></head>\n"
            f"<body>\n{body}\n</body></html>\n")


def write_report(path: str | Path, diagnosis: Diagnosis, title: str | None = None) -> Path:
    """Write the self-contained HTML report of a diagnosis to ``path``; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_html(diagnosis, title), encoding="utf-8")
    return path
