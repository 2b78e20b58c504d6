"""Which effect a residual pattern ("parameter P varies with variable V") is: every effect
says which patterns it models (``Effect.explains``), so a plugin effect that declares its
patterns is named like a built-in one; the advice and the generated effects (auto_effects.py)
ask here."""

from __future__ import annotations

from collections.abc import Iterable

from hostpc.model.effect import Effect, ModelContext
from hostpc.model.registry import builtin_effects


def pattern_effect(parameter: str, variable: str, context: ModelContext | None = None,
                   effects: Iterable[type[Effect]] | None = None) -> str | None:
    """The effect(s) a "parameter varies with variable" pattern is ("a or b" when several
    model it), or None. effects: the effects to ask, in order (default: the built-ins);
    context: the model's, for effects whose answer depends on the robot."""
    candidates = builtin_effects().values() if effects is None else effects
    names = [cls.name for cls in candidates if cls.explains(parameter, variable, context)]
    return " or ".join(dict.fromkeys(names)) or None
