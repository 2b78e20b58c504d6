"""FIT.json, the output of `hostpc fit --json` (`FitResult.to_dict`), validated at the file
edge before any guard rail reads it.

`hostpc push FIT.json` writes a controller from this file, so nothing in it is trusted:

- the JSON itself: UTF-8, no duplicated key at any level (the second would silently win),
  no NaN / Infinity literal, no integer with thousands of digits, not nested without end;
- strict types (pydantic, strict mode): booleans are JSON booleans (``"false"`` is not
  false), numbers are JSON numbers (``"0.1"`` is not a number), integers are integers;
- every statistic finite and in range: ``chi2 >= 0``, ``dof > 0`` (a fit without degrees
  of freedom cannot be judged), ``chi2_dof`` equal to chi2 / dof, values, standard
  deviations (>= 0), ``chi2_dof_with_calibration``, rms, correlations in [-1, 1];
- consistency: a fixed parameter has no standard deviation (the writer writes null; 0 is
  accepted), ``n_parameters`` counts the parameters, every parameter belongs to one of the
  ``effects``, each held null direction names a fixed parameter of the file and one
  coefficient per participant, the joint offsets are ``q1..qn`` in order (or a kinematic
  tree's ``chain.qk`` labels), a joint offset is below half a turn (rad; 100 m for a
  prismatic joint);
- the robot: a fit of a built-in robot carries one joint offset per joint of that robot
  (the push then compares the robot's name, a guard rail, and the joint count, always,
  with the controller's).

A bad file raises InputError (CLI exit code 2) with one line naming the file and the field,
ending with the command that makes a good one.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any

from pydantic import Field, StrictBool, StrictInt, StrictStr

from hostpc.calibrate.strict_json import StrictFile, parse_strict_json, validate_strict
from hostpc.errors import InputError
from hostpc.model.joint_offsets import is_offset, offset_name
from hostpc.model.joint_offsets import labels as offset_labels

MAX_JOINT_OFFSET_RAD = math.pi
"""Largest joint offset a fit can hold (rad): a zero offset is corrected by degrees."""
MAX_JOINT_OFFSET_M = 100.0
"""Largest offset of a prismatic joint (m)."""
MAX_PARAMETER = 1e6
"""Largest magnitude of any other parameter (SI): a delta from nominal, never that large."""
RELATIVE_TOLERANCE = 1e-9
"""How closely chi2_dof must equal chi2 / dof (JSON round trip of a float)."""
REMEDY = "make it again with `hostpc fit DATASET --json > FIT.json`"

Finite = Annotated[float, Field(allow_inf_nan=False)]
NonNegative = Annotated[float, Field(allow_inf_nan=False, ge=0.0)]
Count = Annotated[int, Field(strict=True, ge=0)]




class ParameterEntry(StrictFile):
    """One parameter: value (SI delta from nominal), std (null where held), unit, fixed."""

    value: Finite
    std: NonNegative | None = None
    unit: StrictStr = ""
    fixed: StrictBool


class NullDirectionEntry(StrictFile):
    """A held null direction: the parameter held and the combination it belongs to."""

    fixed: StrictStr
    parameters: list[StrictStr]
    coefficients: list[Finite]
    description: StrictStr = ""


class CorrelationEntry(StrictFile):
    """A strong correlation between two parameters."""

    a: StrictStr
    b: StrictStr
    rho: Annotated[float, Field(allow_inf_nan=False, ge=-1.0 - 1e-9, le=1.0 + 1e-9)]


class RobotIdentityEntry(StrictFile):
    """The fit's robot: its name and the fingerprint of its nominal kinematics
    (hostpc.model.context.robot_identity)."""

    name: StrictStr
    kinematics: StrictStr


class KeptSamplesEntry(StrictFile):
    """model_adequacy.kept_samples: a robust-loss fit judged on the samples its loss keeps
    (hostpc.diagnostics.robust_kept.KeptSamples)."""

    loss: StrictStr
    left_out: Annotated[list[Count], Field(min_length=1)]
    max_weight: NonNegative
    chi2: NonNegative
    dof: StrictInt
    n_kept: Count


class ModelAdequacyEntry(StrictFile):
    """model_adequacy, the part a push reads (the rest is for people)."""

    kept_samples: KeptSamplesEntry | None = None
    #: the diagnosis to run when the model does not explain the data (names the dataset)
    next: StrictStr | None = None


class MeasuredUnderEntry(StrictFile):
    """measured_under: the controller's zero offsets (rad) the fit's dataset was measured
    under, when it lay in a run folder (hostpc.calibrate.measured_under)."""

    run: StrictStr
    dataset: StrictStr
    zero_offsets: Annotated[list[Annotated[float, Field(
        allow_inf_nan=False, ge=-MAX_JOINT_OFFSET_RAD, le=MAX_JOINT_OFFSET_RAD)]],
        Field(min_length=1)]


class FitDocument(StrictFile):
    """The fields of `FitResult.to_dict` (hostpc/fitting/result.py); unknown keys ignored.
    Required: what the push reads (parameters, chi2, dof, converged)."""

    method: StrictStr = ""
    robot: StrictStr | None = None
    robot_identity: RobotIdentityEntry | None = None  # absent in fits made before it
    effects: list[StrictStr] = []
    #: the fit dataset's nominal frames, SI (hostpc.dataset.writing.frames_to_json); absent
    #: in fits made before it
    frames: dict[StrictStr, Any] | None = None
    parameters: Annotated[dict[StrictStr, ParameterEntry], Field(min_length=1)]
    rms: NonNegative | None = None
    max: NonNegative | None = None
    chi2: NonNegative
    dof: StrictInt
    chi2_dof: NonNegative | None = None
    converged: StrictBool
    iterations: Count | None = None
    message: StrictStr = ""
    rank: Count | None = None
    n_parameters: Count | None = None
    n_samples: Count | None = None
    singular_values: list[NonNegative] = []
    condition_number: NonNegative | None = None
    unidentifiable: list[NullDirectionEntry] = []
    correlations: list[CorrelationEntry] = []
    cv_rms: NonNegative | None = None
    cv_folds: Count | None = None
    loss: StrictStr = ""
    chi2_dof_with_calibration: NonNegative | None = None
    model_adequacy: ModelAdequacyEntry | None = None
    measured_under: MeasuredUnderEntry | None = None  # absent: outside a run folder


def parse_fit_text(text: str, source: str) -> Any:
    """The JSON document of FIT.json; InputError for anything `json` would bend."""
    return parse_strict_json(text, source, REMEDY)


def validate_fit_document(document: Any, source: str, *, offsets: bool = True) -> FitDocument:
    """The validated document (see the module docstring); InputError naming the field.
    ``offsets=False`` accepts a fit without joint offsets (a nominal model predicts too:
    `hostpc predict`); a push needs them."""
    if not isinstance(document, dict):
        raise InputError(f"{source}: expected a JSON object (the output of "
                         f"`hostpc fit DATASET --json`), got {type(document).__name__}")
    for key in ("parameters", "converged", "chi2", "dof"):
        if key not in document:
            raise InputError(f"{source}: no {key!r}: not the output of `hostpc fit --json`; "
                             f"{REMEDY}")
    fit = validate_strict(FitDocument, document, source, REMEDY)
    _check_consistency(fit, source, offsets)
    return fit


def _fail(source: str, where: str, why: str) -> InputError:
    return InputError(f"{source}: {where}: {why}; {REMEDY}")


def _check_consistency(fit: FitDocument, source: str, offsets: bool) -> None:
    """Raise InputError if the fields of a well-typed document disagree with each other."""
    if fit.dof <= 0:
        raise InputError(f"{source}: dof: {fit.dof}, a fit without degrees of freedom cannot "
                         "be judged; add samples, then `hostpc fit DATASET --json > FIT.json`")
    if fit.chi2_dof is not None and not math.isclose(
            fit.chi2_dof, fit.chi2 / fit.dof, rel_tol=RELATIVE_TOLERANCE, abs_tol=1e-300):
        raise _fail(source, "chi2_dof", f"{fit.chi2_dof!r} is not chi2 / dof = "
                    f"{fit.chi2 / fit.dof!r}")
    _check_kept(fit, source)
    if fit.n_parameters is not None and fit.n_parameters != len(fit.parameters):
        raise _fail(source, "n_parameters", f"{fit.n_parameters} but "
                    f"{len(fit.parameters)} parameters are listed")
    effects = set(fit.effects)
    for name, entry in fit.parameters.items():
        where = f"parameters.{name}"
        effect, dot, _ = name.partition(".")
        if not (effect and dot and name[-1] != "."):
            raise _fail(source, where, "expected a name EFFECT.PARAMETER")
        if effects and effect not in effects:
            raise _fail(source, where, f"effect {effect!r} is not in effects {sorted(effects)}")
        if entry.fixed and entry.std not in (None, 0.0):
            raise _fail(source, f"{where}.std", f"{entry.std!r} for a fixed parameter "
                        "(a held parameter has no standard deviation)")
        _check_range(name, entry, source)
    for k, direction in enumerate(fit.unidentifiable):
        where = f"unidentifiable[{k}]"
        held = fit.parameters.get(direction.fixed)
        if held is None or not held.fixed:
            raise _fail(source, f"{where}.fixed", f"{direction.fixed!r} is not a fixed "
                        "parameter of this fit")
        unknown = [p for p in direction.parameters if p not in fit.parameters]
        if unknown:
            raise _fail(source, f"{where}.parameters", f"{unknown[0]!r} is not a parameter "
                        "of this fit")
        if len(direction.coefficients) != len(direction.parameters):
            raise _fail(source, f"{where}.coefficients", f"{len(direction.coefficients)} "
                        f"coefficients for {len(direction.parameters)} parameters")
    for k, pair in enumerate(fit.correlations):
        for side in (pair.a, pair.b):
            if side not in fit.parameters:
                raise _fail(source, f"correlations[{k}]", f"{side!r} is not a parameter")
    _check_joint_offsets(fit, source, offsets)


def _check_kept(fit: FitDocument, source: str) -> None:
    """The samples a robust loss left out of the chi-square test: of this fit's loss, each
    once and a sample of the fit, with fewer (positive) degrees of freedom than the fit."""
    kept = None if fit.model_adequacy is None else fit.model_adequacy.kept_samples
    if kept is None:
        return
    where = "model_adequacy.kept_samples"
    if kept.loss != fit.loss or kept.loss in ("", "linear"):
        raise _fail(source, f"{where}.loss", f"{kept.loss!r}, but the fit's loss is "
                    f"{fit.loss!r} (only a robust loss leaves samples out)")
    n_samples = fit.n_samples
    if len(set(kept.left_out)) != len(kept.left_out) or (
            n_samples is not None and max(kept.left_out) >= n_samples):
        raise _fail(source, f"{where}.left_out", "expected distinct samples of the fit")
    if not 0 < kept.dof < fit.dof:
        raise _fail(source, f"{where}.dof", f"{kept.dof}, expected 1..{fit.dof - 1} (fewer "
                    "than the fit's: samples are left out)")


def _check_range(name: str, entry: ParameterEntry, source: str) -> None:
    if is_offset(name):
        limit, unit = ((MAX_JOINT_OFFSET_M, "m") if entry.unit == "m"
                       else (MAX_JOINT_OFFSET_RAD, "rad"))
    else:
        limit, unit = MAX_PARAMETER, entry.unit
    if not abs(entry.value) <= limit:
        raise _fail(source, f"parameters.{name}.value", f"{entry.value:.6g} {unit} is "
                    f"outside the possible range (|value| <= {limit:g})")


_SERIAL_LABEL = re.compile(r"q[1-9][0-9]*")
_TREE_LABEL = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\.q[1-9][0-9]*")


def joint_offset_labels(fit: FitDocument) -> list[str]:
    """The labels of the fit's joint offsets (``q1``.., or ``head.q1``..), in file order."""
    return offset_labels(fit.parameters)


def _check_joint_offsets(fit: FitDocument, source: str, required: bool) -> None:
    labels = joint_offset_labels(fit)
    if not labels and not required:
        return
    if not labels:
        raise InputError(f"{source}: the fit has no joint_offsets parameters: nothing to "
                         "push; fit with them: `hostpc fit DATASET --effects joint_offsets,"
                         "... --json > FIT.json`")
    serial = [f"q{j + 1}" for j in range(len(labels))]
    if labels != serial and not (all(_TREE_LABEL.fullmatch(label) for label in labels)
                                 and len(set(labels)) == len(labels)):
        wrong = next((label for label, want in zip(labels, serial, strict=True)
                      if label != want), labels[0])
        raise _fail(source, f"parameters.{offset_name(wrong)}", "the joint offsets must be "
                    f"q1..q{len(labels)} in order (or a kinematic tree's chain.qk labels)")
    if fit.robot is not None:
        joints = _robot_joint_count(fit.robot)  # another name: the push compares it
        if joints is not None and joints != len(labels):
            raise _fail(source, "parameters", f"{len(labels)} joint offsets, but a "
                        f"{fit.robot} has {joints} joints")


def _robot_joint_count(name: str) -> int | None:
    """Joints of a built-in robot or kinematic tree, None if ``name`` is neither."""
    from hostpc.kinematics.humanoid import get_tree, tree_names
    from hostpc.kinematics.robots import get_robot, names

    if name in names():
        return get_robot(name).n
    if name in tree_names():
        return get_tree(name).n
    return None
