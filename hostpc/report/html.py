"""One self-contained HTML file of a diagnosis: every figure inline SVG, no external
scripts, styles or fonts, so it opens anywhere (and can be archived with a run).

``diagnosis_body`` is the diagnosis as HTML sections (also the second half of a
calibration's report, hostpc.report.calibration); ``render_html`` the page of it alone."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import hostpc
from hostpc.diagnostics import Diagnosis
from hostpc.diagnostics.candidates import Candidate
from hostpc.diagnostics.pipeline import variables_of
from hostpc.report import plots
from hostpc.report.effect_sizes import effect_sizes
from hostpc.report.markup import escape as _e
from hostpc.report.markup import figure, page
from hostpc.report.markup import mm as _mm
from hostpc.report.markup import num as _num
from hostpc.report.markup import p_value as _p
from hostpc.report.markup import prose as _prose
from hostpc.report.markup import table as _table


def _img(svg: str, alt: str) -> str:
    """An inline figure (``alt`` is carried by the SVG's own title)."""
    del alt
    return figure(svg)


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
             else "not testable: no degrees of freedom left",
             _e(c.not_taken or "taken") if c.testable else "-")
            for c in diagnosis.candidates]
    rows += [(_e(s.effect), "-", "-", "-", "-", "-", "-", _e(f"skipped: {s.reason}"), "-")
             for s in diagnosis.check.skipped]
    flags = [c.significant for c in diagnosis.candidates] + [False] * len(diagnosis.check.skipped)
    return _table(("effect", "delta BIC", "delta BIC (all)", "RMS [mm]", "held-out [mm]",
                   "chi2/dof", "p", "parameters the data need", "why not taken"), rows,
                  flags=flags)


def changes_the_fit(candidate: Candidate) -> bool:
    """Whether adding the candidate changes the fit: it was tested and the data need at
    least one of its parameters (else its delta BIC is 0 and it has no bar to draw)."""
    return (candidate.testable and bool(candidate.selected)
            and candidate.delta_bic is not None and candidate.delta_bic != 0.0)


def _candidate_chart(diagnosis: Diagnosis) -> str:
    """The candidates' delta BIC chart, or one sentence when no candidate changes the fit
    (a chart of zero-length bars is an empty frame)."""
    if any(changes_the_fit(c) for c in diagnosis.candidates):
        return _img(plots.candidate_ranking(diagnosis), "candidate ranking")
    tested = sum(c.testable for c in diagnosis.candidates)
    return (f'<p id="no-candidate-changes">No candidate effect changes the fit: the data '
            f"need none of the parameters of the {tested} effects tested (delta BIC 0 for "
            f"each; the table lists them).</p>")


def _interactions(diagnosis: Diagnosis, top: int = 15) -> str:
    shown = diagnosis.interactions[:top]
    rows = [(_e(i.parameter), _e(i.variable), _num(i.score, 1), _p(i.p_value), _e(i.basis))
            for i in shown]
    return _table(("parameter", "varies with", "score", "p", "basis"), rows, name_columns=2,
                  flags=[i.significant for i in shown])


def _ladder(diagnosis: Diagnosis) -> str:
    if not diagnosis.ladder:
        where = (f"<code>hostpc diagnose {_e(diagnosis.source)} --ladder</code>"
                 if diagnosis.source else "<code>hostpc diagnose</code> with "
                 "<code>--ladder</code> on this dataset")
        return f"<p>Run {where} to fit the nested models and watch the error fall.</p>"
    rows = [(str(s.step), _e(s.change or "(current model)"), _mm(s.rms), _mm(s.cv_rms),
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
    if diagnosis.detectable:
        seen = "".join(f"<li>{_e(d.sentence)}</li>" for d in diagnosis.detectable)
        notes += f"<p>What these poses can see (80 % power):</p><ul>{seen}</ul>"
    if diagnosis.confounded:
        pairs = "".join(
            f"<li>{_e(c.sentence)}: <code>{_e(command)}</code></li>" if command is not None
            else f"<li>{_e(c.sentence)}: {_e(diagnosis.separate_instruction(c))}</li>"
            for c in diagnosis.confounded
            for command in (diagnosis.separate_command(c),))
        notes += f"<p>Confounded candidates:</p><ul>{pairs}</ul>"
    return _img(plots.ladder_chart(diagnosis), "ladder chart") + notes + table


def _parameters(diagnosis: Diagnosis, truth: Mapping[str, Any] | None,
                skip: Sequence[str]) -> str:
    correlations = diagnosis.fit.correlations
    listed = "".join(f"<li><code>{_e(a)}</code> ~ <code>{_e(b)}</code>: {rho:+.3f}</li>"
                     for a, b, rho in correlations[:20])
    strong = (f"<p>Strong correlations (|rho| &gt; 0.9):</p><ul>{listed}</ul>" if listed
              else "<p>No correlation above 0.9.</p>")
    return (f'<div class="row"><div>{effect_sizes(diagnosis.fit, truth, skip)}</div><div>'
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


def diagnosis_body(diagnosis: Diagnosis, truth: Mapping[str, Any] | None = None,
                   skip_parameters: Sequence[str] = (),
                   advice_sentences: Sequence[str] | None = None) -> str:
    """The diagnosis as HTML sections (no page shell): the model's verdict, advice
    (``advice_sentences`` instead of the diagnosis's own, if given: a calibration report's,
    hostpc.report.run_advice), adequacy, residual views, candidates, ladder, parameters
    (effect sizes; against ``truth`` for a simulated run, without the effects in
    ``skip_parameters``) and identifiability."""
    check = diagnosis.check
    fit = diagnosis.fit
    a = check.adequacy
    verdict_class = "good" if a.adequate else "bad"
    verdict = "adequate" if a.adequate else "NOT adequate"
    sentences = diagnosis.advice if advice_sentences is None else advice_sentences
    advice = "".join(f"<li>{_prose(s)}</li>" for s in sentences)
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
    skipped = (" (joint offsets: in the offsets table above)"
               if "joint_offsets" in skip_parameters else "")
    sections = [
        f"<p>Method <code>{_e(fit.problem.method)}</code>, {fit.residuals_raw.shape[0]} "
        f"samples, model <code>{_e(', '.join(check.effects))}</code>, significance "
        f"{diagnosis.alpha:g} per family of tests. zerocal {_e(hostpc.__version__)}.</p>",
        f'<div class="verdict {verdict_class}" id="model-verdict">The model is {verdict}.</div>',
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
        f'<div class="row">{_candidate_chart(diagnosis)}'
        f"<div>{_candidates(diagnosis)}</div></div>",
        f"<p>Effect-agnostic search: {check.n_interaction_tests} (parameter, variable) pairs "
        f"tested.</p>",
        (f'<div class="row">{_img(plots.interaction_ranking(diagnosis), "interactions")}'
         f"<div>{_interactions(diagnosis)}</div></div>" if diagnosis.interactions else ""),
        f"<h2>Ladder</h2>{_ladder(diagnosis)}",
        f"<h2>Parameters: effect sizes{skipped}</h2>"
        f"{_parameters(diagnosis, truth, skip_parameters)}",
        f"<h2>Identifiability</h2>{_identifiability(diagnosis)}",
    ]
    return "\n".join(sections)


def render_html(diagnosis: Diagnosis, title: str | None = None,
                truth: Mapping[str, Any] | None = None) -> str:
    """The report of a diagnosis as one HTML string; ``truth``: a simulator's truth dict,
    to compare the effect sizes with (hostpc.report.effect_sizes)."""
    title = title or f"zerocal diagnosis: {diagnosis.source or 'dataset'}"
    return page(title, f"<h1>{_e(title)}</h1>\n" + diagnosis_body(diagnosis, truth))


def write_report(path: str | Path, diagnosis: Diagnosis, title: str | None = None,
                 truth: Mapping[str, Any] | None = None) -> Path:
    """Write the self-contained HTML report of a diagnosis to ``path``; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render_html(diagnosis, title, truth), encoding="utf-8")
    return path
