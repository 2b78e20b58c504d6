"""Physical laws as candidates: a logged load times the gravity torque it exerts.

A payload logged per pose (``extra.payload``, kg: any ``extra.*`` variable whose name says
load, payload or mass) bends each joint by its compliance times the torque the load's
weight exerts about it: ``dq_j = c_j * m * tau_j(q)``, tau_j the gravity torque of one kg at
the flange (N m per kg, from the chain's point Jacobian). A "q3 linear in payload" effect
approximates that badly (the lever arm changes with the pose); this law is the candidate
instead. It is generated per dataset (its source is a plugin, so ``--write-plugins``
writes it when the ladder adds it) and ranked with the built-in candidates: same F-test,
same held-out test, the Bonferroni family one larger.

Temperature times link length is the built-in ``thermal_expansion``.
"""

from __future__ import annotations

import re

from hostpc.diagnostics.frame_candidates import load
from hostpc.model.effect import Effect, ModelContext

LOAD_WORDS = ("payload", "load", "mass")

_TEMPLATE = '''"""{variable} times the gravity torque of each joint: a generated zerocal effect.

Written by `hostpc diagnose --ladder --write-plugins`: the logged load {variable} (kg),
held at the flange, bends joint j by c_j * {variable} * tau_j(q), tau_j the torque one kg
at the flange exerts about joint j (N m per kg; c_j in rad/(N m), 0 where {variable} is
not recorded). Load it with
    hostpc fit DATASET --plugin THIS_FILE --effects +{name}
"""

import numpy as np

from hostpc.kinematics import GRAVITY, forward, joint_screws, point_jacobian
from hostpc.model.effect import Effect


class {class_name}(Effect):
    name = "{name}"
    hook = "joint"
    is_linear = True
    unit = "rad/(N m)"
    description = "compliance under the logged load {variable} (generated law)"
    variable = "{variable}"

    def parameter_names(self, ctx):
        return ctx.per_joint_names("c")

    def basis(self, ctx):
        poses = forward(ctx.chain, ctx.q_cmd)
        flange = poses.T_base_flange[:, :3, 3]
        arm = point_jacobian(joint_screws(ctx.chain, poses), flange)  # (N, 3, n)
        torque = np.einsum("nkj,k->nj", arm, GRAVITY)  # N m per kg at the flange
        load = np.nan_to_num(ctx.variable(self.variable), nan=0.0)
        n = ctx.n_joints
        basis = np.zeros((ctx.n_samples, n, n))
        basis[:, np.arange(n), np.arange(n)] = load[:, None] * torque
        return basis
'''


def load_variables(context: ModelContext) -> list[str]:
    """The logged variables that name a load (``extra.payload``)."""
    return [name for name in context.variables if name.startswith("extra.")
            and any(word in name.lower() for word in LOAD_WORDS)]


def law_effects(context: ModelContext) -> dict[str, type[Effect]]:
    """The generated law candidates of a model context, by name (none on a kinematic tree:
    its joints are not one serial chain)."""
    if any("." in label for label in context.joint_labels):
        return {}
    effects = {}
    for variable in load_variables(context):
        name = re.sub(r"\W", "_", f"{variable.removeprefix('extra.')}_times_gravity_torque")
        source = _TEMPLATE.format(variable=variable, name=name.lower(),
                                  class_name="".join(p.capitalize() for p in name.split("_")))
        effects[name.lower()] = load(name.lower(), source)
    return effects
