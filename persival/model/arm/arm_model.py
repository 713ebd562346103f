"""The built-in upper-limb model's equilibria: five tet10 muscles, elbow angle from the moment balance.

docs/theory.md, section 3. Each muscle's origin face is fixed to the humerus, its insertion face is tied to the
forearm, which rotates about the elbow hinge (mesh, kinematics and the hinge's external loads:
:mod:`persival.model.arm.body`). The unknowns are the muscle displacements and the elbow angle
theta; theta's equation is the moment balance about the hinge of the muscles (their insertion
forces and the forces they press on the bones they wrap over: frictionless penalty contact,
docs/theory.md, 3.5), gravity and the passive joint moment. Muscles do not touch each other (the paper's
mortar contact does). The hanging arm is kept in the state cache.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from persival.model.anatomy.bone_fields import bone_fields
from persival.model.anatomy.muscle_schema import Muscle
from persival.model.anatomy.muscle_sweep import muscle_profile
from persival.model.anatomy.obstacles import bone_obstacles
from persival.model.anatomy.walls import septum_sides, wall_obstacles
from persival.model.arm.arm_cache import ArmStateCache
from persival.model.arm.arm_state import ArmState
from persival.model.arm.body import ArmBody
from persival.model.arm.joint_root import joint_root
from persival.model.arm.muscle_group import MuscleGroup
from persival.model.arm.muscle_state import MusclePath, MuscleState
from persival.model.arm.muscle_unit import MuscleUnit
from persival.model.arm.progress import SolveTracker
from persival.model.fe.assembly import MaterialField
from persival.model.fe.mesh import Tet10Mesh
from persival.model.fe.rotations import rotation_about
from persival.model.fe.solver import ConvergenceError, SolverOptions
from persival.vocabulary import check_activation_vector

__all__ = ["ArmModel", "ArmState", "muscle_profile", "rotation_about"]


class ArmModel(ArmStateCache, ArmBody):
    """The FE upper limb: ``solve(activations) -> ArmState`` (docs/theory.md, section 3).

    Meshing happens once at construction. Every muscle is its own FE problem
    (:class:`~persival.model.arm.muscle_unit.MuscleUnit`: its state depends on its origin-insertion
    length and its activation only), and the elbow angle solves the scalar moment balance
    ``g(theta) = sum_m T_m dL_m/dtheta - M_ext(theta) = 0``. Every solve continues from a
    nearby solved state (``warm_start``, default the hanging arm).
    """

    start_angle_deg = 20.0  # first guess of the hanging arm

    def __init__(self, model_file: str | Path | None = None, profile: str = "quick", options: SolverOptions | None = None):
        super().__init__(model_file, profile)
        # atol: 1e-6 N on nodal forces of muscles pulling 10-400 N keeps the moment residual
        # below 1e-4 N mm; a tighter floor sits at round-off in nearly unloaded states
        self.options = options or SolverOptions(atol=1e-6)
        self.units = {m.name: self._unit(m) for m in self.spec.ordered_muscles()}
        # muscles that touch each other: one FE problem per group (docs/theory.md, 3.5)
        self.groups = {}
        for names in self.spec.contact.touching:
            group = MuscleGroup([self.units[n] for n in names], self.spec.contact.penalty,
                                self.spec.contact.attachment_mm, self.options)
            self.groups.update({n: group for n in names})
        self._base: ArmState | None = None

    def _unit(self, muscle: Muscle) -> MuscleUnit:
        nodes, cells = self.muscle_nodes[muscle.name], self.muscle_cells[muscle.name]
        mesh = Tet10Mesh(
            self.mesh.points[nodes], self.mesh.cells[cells] - nodes[0],
            node_sets={end: self.mesh.node_sets[f"{muscle.name}/{end}"] - nodes[0] for end in ("origin", "insertion")},
        )
        mf = self.material
        material = MaterialField(mf.fibre[cells], mf.muscle_fraction[cells], mf.bulk_modulus[cells],
                                 mf.fibre_prestretch[cells], mf.parameters, mf.matrix_prestretch[cells])
        path = MusclePath(
            origin=np.asarray(muscle.origin, dtype=float),
            insertion=lambda theta, m=muscle: self.body_end(m, theta),
            geometry=lambda theta, m=muscle: self.muscle_length(m, theta),
            mesh_angle_deg=muscle.mesh_angle_deg,
            bones=self._bones_of(muscle, mesh.points) if muscle.wraps else None,
            penalty=self.spec.contact.penalty,
            contact_smoothing_mm=self.spec.contact.smoothing_mm,
            attachment_mm=self.spec.contact.attachment_mm,
            insertion_tie=muscle.insertion_tie,
            hinge=(self.centre, self.axis),
        )
        return MuscleUnit(muscle.name, mesh, material, path, self.options)

    def _bones_of(self, muscle: Muscle, mesh_points: np.ndarray):
        """theta -> the capsules of the bones and the walls ``muscle`` wraps over, world frame
        (docs/theory.md, 3.5); a septum keeps the muscle on the side it is meshed on."""
        bone_names = {b.name for b in self.spec.bones}
        bones = [self.spec.bone(name) for name in muscle.wraps if name in bone_names]
        walls = [self.spec.wall(name) for name in muscle.wraps if name not in bone_names]
        sides = septum_sides(walls, self.centre, self.axis, muscle.mesh_angle_deg, mesh_points)
        fields = bone_fields(self.spec) if self.spec.contact.bone_surfaces and bones else None
        return lambda theta: (bone_obstacles(bones, self.centre, self.axis, theta, fields)
                              + wall_obstacles(walls, self.centre, self.axis, theta, sides))

    def set_options(self, options: SolverOptions) -> None:
        """Solver options of every solve of this model (retries use smaller load steps)."""
        self.options = options
        for unit in [*self.units.values(), *self.groups.values()]:
            unit.options = options

    # -- solves -------------------------------------------------------------------------------
    def base_state(self, progress=None, cache: bool = True) -> ArmState:
        """The hanging arm (all activations 0): every muscle continued from its mesh pose.
        ``progress(SolveProgress)`` is called at every load step (persival.model.arm.progress).

        With ``cache`` it is read from the on-disk cache of this model and mesh when there
        (:mod:`persival.model.arm.state_cache`; the joint equilibrium is re-converged from it, one
        Newton iteration per muscle) and written there after a fresh solve. A hanging arm
        solved elsewhere (from the response tables, in seconds instead of 80 s of continuation
        from the mesh poses) is put there by :meth:`adopt_base_state`.
        ``statistics["from_cache"]`` says which happened.
        """
        if self._base is None:
            t0 = time.perf_counter()
            cached = self._cached_base() if cache else None
            if cached is not None:
                rest, start, angle = cached
                self._set_rest_states(rest)
                state = self._equilibrium(np.zeros(5), start, angle, SolveTracker(progress, "cached rest state"))
            else:
                tracker = SolveTracker(progress, "rest state")
                rest = self.rest_states(tracker, cache=cache)
                tracker.phase = "joint equilibrium"
                state = self._equilibrium(np.zeros(5), rest, self.start_angle_deg, tracker)
                if cache:
                    self._save_cache(state)
            state.statistics["from_cache"] = cached is not None
            state.wall_time_s = time.perf_counter() - t0
            self._base = state
        return self._base

    def equilibrium_from(self, activations, start: dict[str, MuscleState], angle_deg: float, progress=None) -> ArmState:
        """Joint equilibrium for ``activations`` continued from given muscle states near
        ``angle_deg`` (e.g. interpolated from response tables, persival.tables.response_table)."""
        target = check_activation_vector(activations)
        t0 = time.perf_counter()
        state = self._equilibrium(target, start, float(angle_deg), SolveTracker(progress))
        state.wall_time_s = time.perf_counter() - t0
        return state

    retry_steps = (1.0, 0.5, 0.25)  # first load step of each try, relative to options.initial_step

    def solve(self, activations, warm_start: ArmState | None = None, progress=None) -> ArmState:
        """Equilibrium for the five activations, continued from ``warm_start`` (or the hanging arm);
        ``progress`` as in :meth:`base_state`.

        Retry ladder (as the campaign simulator's): a try whose muscles do not converge is
        repeated with smaller first activation steps (``retry_steps``); when every try fails, the
        ConvergenceError names each try's reason. ``statistics["tries"]`` counts them.
        """
        target = check_activation_vector(activations)
        t0 = time.perf_counter()
        start = warm_start if warm_start is not None else self.base_state(progress)
        if warm_start is None and not np.any(target):
            return start  # the hanging arm itself (its statistics are those of its solve)
        state = self._with_retries(target, lambda: self._equilibrium(target, start.muscle_states, start.elbow_angle_deg,
                                                                     SolveTracker(progress)))
        state.wall_time_s = time.perf_counter() - t0
        return state

    def hold(self, activations, angle_deg: float, warm_start: ArmState | None = None, progress=None) -> ArmState:
        """The arm held at ``angle_deg`` by a brace (an isometric state, as on a dynamometer): every
        muscle in its own equilibrium at that angle (docs/theory.md, 3.8), continued from its rest state
        (or from ``warm_start``'s muscles). The joint is not balanced: ``moment_residual`` is
        g(theta) = -sum M_m - M_ext, the moment the brace exerts on the forearm (flexion positive;
        also ``statistics["brace_moment_Nmm"]``). Same retry ladder as :meth:`solve`.
        """
        target = check_activation_vector(activations)
        lower, upper = self.spec.joint.limits_deg
        if not (np.isfinite(angle_deg) and lower <= angle_deg <= upper):
            raise ValueError(f"the held elbow angle must lie within the joint limits [{lower:g}, {upper:g}] deg, "
                             f"got {angle_deg}")
        t0 = time.perf_counter()
        start = warm_start.muscle_states if warm_start is not None else self.rest_states(SolveTracker(progress, "rest state"))

        def held() -> ArmState:
            stats: dict = {"joint_iterations": 0, "iterations": 0}
            tracker = SolveTracker(progress, f"held at {angle_deg:g} deg")
            tracker.joint(0, angle_deg)
            g, dg, states = self.moment_balance(float(angle_deg), target, start, stats, tracker)
            state = self._arm_state(target, float(angle_deg), g, dg, states, stats)
            state.statistics.update(held_at_deg=float(angle_deg), brace_moment_Nmm=float(g))
            return state

        state = self._with_retries(target, held)
        state.wall_time_s = time.perf_counter() - t0
        return state

    def _with_retries(self, target, attempt):
        """``attempt()`` with the first activation step of ``retry_steps``, in turn, until one
        converges; every reason in the ConvergenceError otherwise. ``statistics["tries"]`` counts them."""
        options, reasons = self.options, []
        try:
            for scale in self.retry_steps:
                self.set_options(replace(options, initial_step=options.initial_step * scale))
                try:
                    state = attempt()
                    break
                except ConvergenceError as exc:
                    reasons.append(f"first step {options.initial_step * scale:g}: {exc}")
            else:
                raise ConvergenceError(f"activations {target.tolist()} failed {len(reasons)} tries: " + "; ".join(reasons))
        finally:
            self.set_options(options)
        state.statistics["tries"] = len(reasons) + 1
        return state

    # -- the joint equilibrium ----------------------------------------------------------------------
    def moment_balance(self, theta_deg: float, activations, start: dict[str, MuscleState], statistics: dict | None = None,
                       tracker: SolveTracker | None = None):
        """The joint's moment residual g = dPi/dtheta (N mm) at a prescribed angle, the joint
        stiffness dg/dtheta (N mm/rad, the muscles re-equilibrated) and the muscle states.

        g = -sum_m M_m - M_ext: a muscle's work on the joint is ``-M_m = T L' + dPi_c/dtheta``
        (module muscle_unit); g < 0 turns the forearm towards flexion.
        """
        states, g, dg = {}, 0.0, 0.0
        activation = {m.name: float(a) for m, a in zip(self.spec.ordered_muscles(), activations)}
        for muscle in self.spec.ordered_muscles():
            if muscle.name in states:
                continue  # solved with its group
            group = self.groups.get(muscle.name)
            if group is not None:
                solved = group.solve(theta_deg, {n: activation[n] for n in group.names}, {n: start[n] for n in group.names},
                                     tracker and tracker.muscle(" + ".join(group.names)))
            else:
                # near corrections keep their start's slope (chord in theta: dg need not be exact)
                solved = {muscle.name: self.units[muscle.name].solve(theta_deg, activation[muscle.name], start[muscle.name],
                                                                     tracker and tracker.muscle(muscle.name),
                                                                     fresh_slope=False)}
            states.update(solved)
        for state in states.values():
            g -= state.moment
            dg -= state.moment_slope
            if statistics is not None:
                statistics["iterations"] = statistics.get("iterations", 0) + state.iterations
                statistics["muscle_solves"] = statistics.get("muscle_solves", 0) + 1
        M, dM = self.external_moment(np.radians(theta_deg))
        return g - M, dg - dM, states

    def moment_tolerance(self, states: dict[str, MuscleState]) -> float:
        """The joint's moment tolerance (N mm) at these muscle states: options.moment_atol, or
        options.moment_rtol of the muscles' summed |moments| where that is larger (their noise
        floor: a state of 3e4 N mm of summed moments stalled at 2.3e-4 N mm against 1e-4)."""
        summed = sum(abs(s.moment) for s in states.values())
        return max(self.options.moment_atol, self.options.moment_rtol * summed)

    def _equilibrium(self, target, start: dict[str, MuscleState], angle: float, tracker: SolveTracker) -> ArmState:
        """The arm at the root of the joint's moment balance g(theta) = 0 (persival.model.arm.joint_root)."""
        theta, g, dg, states, stats = joint_root(self, target, start, angle, tracker)
        return self._arm_state(target, theta, g, dg, states, stats)

    def _arm_state(self, target, theta: float, g: float, dg: float, states: dict[str, MuscleState], stats: dict) -> ArmState:
        """The ArmState of muscle states at theta, with the joint's residual g and stiffness dg."""
        moments = {name: s.moment for name, s in states.items()}
        forces = {name: s.tension for name, s in states.items()}
        stats["max_penetration_mm"] = max(s.max_penetration for s in states.values())
        stats["contact_force_N"] = {name: s.contact_force for name, s in states.items() if s.contact_force}
        stats["joint_stiffness_Nmm_per_rad"] = float(dg)
        stats["moment_tolerance_Nmm"] = self.moment_tolerance(states)
        stats["hand_load_kg"] = self.hand_load_kg
        return ArmState(
            activations=np.asarray(target, dtype=float).copy(),
            elbow_angle_deg=theta,
            displacement=self.displacement(states, theta),
            moment_residual=float(g),
            muscle_moments=moments,
            muscle_forces=forces,
            external_moment=self.external_moment(np.radians(theta))[0],
            max_volume_change=max(s.max_volume_change for s in states.values()),
            muscle_states=states,
            statistics=stats,
        )

    def displacement(self, states: dict[str, MuscleState], theta_deg: float) -> np.ndarray:
        """World-frame displacements (n_nodes, 3) of all muscles: each muscle's solution turned
        with its line of action (module muscle_unit)."""
        u = np.zeros_like(self.mesh.points)
        for muscle in self.spec.ordered_muscles():
            state = states[muscle.name]
            if abs(state.angle_deg - theta_deg) > 1e-9:
                raise ValueError(f"{muscle.name}: a state at {state.angle_deg} deg placed at {theta_deg} deg")
            nodes = self.muscle_nodes[muscle.name]
            u[nodes] = self.units[muscle.name].positions(state) - self.mesh.points[nodes]
        return u

    def verify_equilibrium(self, state: ArmState) -> tuple[float, float]:
        """The state's residuals in the monolithic formulation (persival.model.arm.monolithic)."""
        from persival.model.arm.monolithic import verify_equilibrium

        return verify_equilibrium(self, state)

__all__ = ["ArmModel", "ArmState", "ConvergenceError", "muscle_profile", "rotation_about"]
