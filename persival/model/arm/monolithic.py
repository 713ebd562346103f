"""An independent check of arm states: the monolithic formulation (docs/theory.md, 3.7).

The arm is solved muscle by muscle (persival.model.arm.muscle_unit); here a state goes back into
the formulation the paper states: the whole mesh at once, every face tied to the free elbow
hinge, the joint's moment balance by virtual work.
"""

from __future__ import annotations

import numpy as np

from persival.model.arm.arm_state import ArmState
from persival.model.fe.constraints import Hinge
from persival.model.fe.solver import QuasiStaticSolver

__all__ = ["verify_equilibrium"]


def verify_equilibrium(arm, state: ArmState) -> tuple[float, float]:
    """Check a state in the monolithic formulation, independently of the muscle units:
    every muscle's faces tied to the elbow (ball joints on the lines of action,
    :class:`Hinge`), the whole mesh assembled at once. Returns the largest nodal force
    residual of the free DOFs (N) and the hinge's moment residual from virtual work,
    f . dx/dtheta - M_ext (N mm). Only for line-tied muscles without bones (the monolithic
    form has neither contact terms nor forearm ties)."""
    nodes, reference, O, I, is_insertion, counts = [], [], [], [], [], []
    muscles = arm.spec.ordered_muscles()
    other = [m.name for m in muscles if m.wraps or m.insertion_tie != "line"]
    if other:
        raise ValueError(f"verify_equilibrium checks line-tied muscles without bones; {other} have bones or "
                         "forearm ties (their own checks: tests/model/test_contact.py)")
    for m in muscles:
        insertion_ref = arm.body_end(m, m.mesh_angle_deg)
        for end in ("origin", "insertion"):
            ids = arm.mesh.node_sets[f"{m.name}/{end}"]
            nodes.append(ids)
            counts.append(len(ids))
            reference.append(np.full(len(ids), m.mesh_angle_deg))
            O.append(np.tile(m.origin, (len(ids), 1)))
            I.append(np.tile(insertion_ref, (len(ids), 1)))
            is_insertion.append(np.full(len(ids), end == "insertion"))
    # the body ends (a wrapped path's end slides along its first segment, docs/theory.md, 3.4)
    repeats = np.array(counts)
    line_ends = lambda theta: np.repeat(np.repeat([arm.body_end(m, theta) for m in muscles], 2, axis=0),  # noqa: E731
                                        repeats, axis=0)
    elbow = Hinge(
        "elbow", np.concatenate(nodes), arm.centre, arm.axis, np.concatenate(reference), start_deg=state.elbow_angle_deg,
        free=True, external_moment=arm.external_moment,
        muscle_lines=(np.vstack(O), np.vstack(I), np.concatenate(is_insertion)), line_ends=line_ends,
    )
    solver = QuasiStaticSolver(arm.mesh, arm.material, [elbow], arm.options)
    activation = arm.cell_activation(state.activations)
    u = state.displacement.ravel()
    f = solver.assembler.internal_force(u, arm.material, activation)
    moment, _ = solver.hinge_balance(u, state.elbow_angle_deg, activation)
    return float(np.abs(f[solver.free]).max()), float(moment)
