"""Diagnostics: is the model adequate, where does it fail, which effect is missing.

    import hostpc
    diagnosis = hostpc.diagnose("run/dataset.json", ladder=True)
    print(diagnosis.adequate, diagnosis.candidates[0].effect)
    for sentence in diagnosis.advice:
        print(sentence)

See docs/diagnostics.md for the walk-through and the JSON schema.

The results are frozen dataclasses. Those that hold arrays (or a fit, which does) are
declared ``eq=False``: a field-wise ``==`` would raise on the arrays and their hash on
hashing one, so they compare (and hash) by identity, and Python generates no ``__eq__``
and ``__hash__`` for them at import (~0.5 % of ``hostpc diagnose``'s instructions).
"""

from hostpc.diagnostics.adequacy import Adequacy, HeldOut, held_out_residuals
from hostpc.diagnostics.candidates import Candidate, SkippedCandidate
from hostpc.diagnostics.diagnosis import Diagnosis, LadderStep, ModelCheck
from hostpc.diagnostics.interactions import Interaction
from hostpc.diagnostics.outliers import Outlier
from hostpc.diagnostics.pipeline import DEFAULT_ALPHA, diagnose
from hostpc.diagnostics.residual_analysis import ResidualAnalysis, VariablePattern

__all__ = ["diagnose", "Diagnosis", "ModelCheck", "LadderStep", "Adequacy", "HeldOut",
           "Candidate", "SkippedCandidate", "Interaction", "Outlier", "ResidualAnalysis",
           "VariablePattern", "held_out_residuals", "DEFAULT_ALPHA"]
