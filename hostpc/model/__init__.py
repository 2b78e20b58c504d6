"""The error model: effect plugins, parameter layout, measurement models."""

from hostpc.model.effect import Effect, EffectTerm, ModelContext
from hostpc.model.layout import ParameterLayout, Problem
from hostpc.model.problem import build_problem, default_effects

__all__ = ["Effect", "EffectTerm", "ModelContext", "ParameterLayout", "Problem",
           "build_problem", "default_effects"]
