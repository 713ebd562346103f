"""One muscle-tendon unit between its origin and insertion faces, solved in its own frame.

docs/theory.md, 3.3: by default each muscle's end faces are tied to its line of action (ball joints: the origin face
turns about the fixed origin point O, the insertion face rides on the forearm's insertion
point I(theta), and both faces turn by the minimal rotation Q(theta) that takes the mesh-pose
line direction d_ref to the current one d(theta); see :class:`~persival.model.fe.constraints.Hinge`).
Because the law is objective and the muscles carry no body force, the deformed muscle at
elbow angle theta is exactly the rigid motion ``x = O + Q(theta) (y - O)`` of the solution
``y`` of a simpler problem: origin face held in its mesh pose, insertion face translated along
d_ref by ``L(theta) - L_mesh`` (L = |I - O|), and the bones the muscle wraps over (docs/theory.md,
3.5) turned into that frame by ``Q(theta)^T`` about O. A muscle's state therefore depends on
two numbers, the elbow angle theta and its activation a, and nothing of the other muscles.
A muscle may instead tie its insertion face rigidly to the forearm (``insertion_tie =
"forearm"``; persival.model.arm.insertion_ties): it is then solved in the world frame, Q = I, with
the face turning about the hinge, and ``T L'`` below becomes the virtual work ``f . dp/dtheta`` of
the face's reaction.

Its work on the joint follows from the envelope theorem applied to
``Pi*(theta) = min_y [Pi_m(y; L(theta)) + Pi_c(y; theta)]``:

    dPi*/dtheta = T dL/dtheta + dPi_c/dtheta|_y,        M = -dPi*/dtheta (flexion positive)

with the tension ``T`` (the axial reaction of the insertion face). Without contact the second
term vanishes and the state depends on L alone. The rigid rotation does no work (the muscle's
own moment balance), so nothing is lost.

This turns the joint equilibrium into one scalar equation in theta (see ArmModel), and each
muscle into a small FE problem solved on its own: five solves of a few thousand DOFs instead
of one of all of them, and a library of solved (theta, a) states per muscle that warm-starts
every new state by interpolation (persival.model.arm.state_library).

One module on purpose (a numerical kernel over 300 lines): one muscle's FE problem, its ties,
contact, rest state and the moment's exact slope (a Schur complement on the same factorization)
share the solver's state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from persival.model.anatomy.obstacles import Faded
from persival.model.arm.insertion_ties import ForearmTie, LineTie
from persival.model.arm.muscle_state import MusclePath, MuscleState
from persival.model.arm.state_library import StateLibrary
from persival.model.fe.assembly import MaterialField, Tet10Assembler
from persival.model.fe.constraints import Dirichlet
from persival.model.fe.contact import ObstacleContact
from persival.model.fe.mesh import Tet10Mesh
from persival.model.fe.solver import ConvergenceError, QuasiStaticSolver, SolverOptions


class MuscleUnit:
    """The FE problem of one muscle with its elbow angle and activation prescribed."""

    small_step_mm = 1.0  # length changes up to this are taken in one load step (then halved if needed)
    small_step_deg = 5.0  # ... if the angle moves no more than this either (the bones move with it)
    library_gap_deg = 10.0  # solved states at most this far apart are interpolated as a start
    contact_step_deg = 0.05  # central differences of the contact energy in theta (exact up to ~1e-6)

    def __init__(self, name: str, mesh: Tet10Mesh, material: MaterialField, path: MusclePath,
                 options: SolverOptions | None = None) -> None:
        self.name = name
        self.mesh = mesh
        self.material = material
        self.path = path
        self.origin = np.asarray(path.origin, dtype=float)
        self.mesh_angle_deg = float(path.mesh_angle_deg)
        ties = {"line": LineTie, "forearm": ForearmTie}
        if path.insertion_tie not in ties:
            raise ValueError(f"muscle {name!r}: insertion_tie must be one of {sorted(ties)}, got {path.insertion_tie!r}")
        self.assembler = Tet10Assembler(mesh)
        try:
            self.tie = ties[path.insertion_tie](mesh.node_sets["insertion"], self.assembler.n_dofs, self.origin, path)
        except ValueError as exc:
            raise ValueError(f"muscle {name!r}: {exc}") from None
        self.mesh_length, self.direction = self.tie.mesh_length, self.tie.direction
        self._origin_face = Dirichlet("origin", mesh.node_sets["origin"])
        self._insertion_face = self.tie.constraint
        self.contact = None
        if path.bones is not None and len(path.bones(self.mesh_angle_deg)):
            tied = np.concatenate([self._origin_face.nodes, self._insertion_face.nodes])
            ends = [mesh.points[self._origin_face.nodes].mean(axis=0), mesh.points[self._insertion_face.nodes].mean(axis=0)]
            self.contact = ObstacleContact.at_nodes(mesh, self.obstacles(self.mesh_angle_deg), path.penalty, exclude=tied,
                                                    ends=ends, end_distance=path.attachment_mm,
                                                    smoothing_mm=path.contact_smoothing_mm)
        self.solver = QuasiStaticSolver(mesh, material, [self._origin_face, self._insertion_face], options,
                                        assembler=self.assembler, extra_terms=[self.contact] if self.contact else None)
        # solved states: starts for later solves (_from_library, TableSolver.guess)
        self.library = StateLibrary()

    @property
    def options(self) -> SolverOptions:
        return self.solver.options

    @options.setter
    def options(self, value: SolverOptions) -> None:
        self.solver.options = value

    # -- kinematics ------------------------------------------------------------------------------
    def length(self, theta_deg: float) -> float:
        return float(self.path.geometry(theta_deg)[0])

    def chart(self, reference_deg: float) -> tuple[Callable[[float], float], float]:
        """The coordinate s(theta) along which this muscle's states are smoothest near a reference
        angle, and ds/dtheta there (per rad): its length L for a muscle without bones (its state
        depends on L alone, however L turns with theta), theta itself (rad) with bones or where
        L' vanishes (a state's du/dtheta = L' du/dL then tells nothing of du/dL). Extrapolations
        from a state at ``reference_deg`` run in it."""
        if self.contact is None and self.tie.keyed_by_length:
            _, dL, _ = self.path.geometry(reference_deg)
            if abs(dL) > 1e-6:
                return self.length, float(dL)
        return (lambda theta: float(np.radians(theta))), 1.0

    def rotation(self, theta_deg: float) -> np.ndarray:
        """Q(theta): the rotation of the unit's frame (the line tie's turn of the line of action;
        the identity for a forearm tie, solved in the world frame)."""
        return self.tie.rotation(theta_deg)

    def obstacles(self, theta_deg: float) -> list:
        """The bones at theta in the muscle's frame: turned by Q(theta)^T about O."""
        if self.path.bones is None:
            return []
        back = self.rotation(theta_deg).T
        return [bone.transformed(back, self.origin) for bone in self.path.bones(theta_deg)]

    def positions(self, state: MuscleState) -> np.ndarray:
        """World node positions of a state: its solution turned with the line of action."""
        y = self.mesh.points + state.displacement
        return self.origin + (y - self.origin) @ self.rotation(state.angle_deg).T

    def _set_path(self, theta_from: float, theta_to: float) -> None:
        """The load steps' path: insertion face from theta_from to theta_to, bones along."""
        self.tie.set_path(theta_from, theta_to)
        if self.contact is not None:
            self.contact.pose = lambda t: self.obstacles(theta_from + t * (theta_to - theta_from))
            self.contact.set_load_factor(0.0)

    # -- solves ----------------------------------------------------------------------------------
    def rest_state(self, progress=None) -> MuscleState:
        """The passive equilibrium at the mesh pose (activation 0), solved once.

        With a fibre prestretch lambda_0 > 1 the mesh pose carries a small passive fibre
        stress (docs/theory.md, 1.6) and is not yet in equilibrium. Newton from the mesh pose can fail
        on it (the passive law's c4 = 42.6 makes the tangent far stiffer than the stress
        suggests), so the prestretch is switched on by continuation, 1 -> lambda_0.
        ``progress(share)`` is called after every accepted load step (share of the prestretch).
        """
        if getattr(self, "_rest", None) is None:
            u = np.zeros((self.mesh.n_nodes, 3))
            full = self.material
            self._set_path(self.mesh_angle_deg, self.mesh_angle_deg)
            try:
                u = self._push_out_of_obstacles(u)
                u = self._switch_on_prestretch(u, progress)
            finally:
                self.solver.material = full
            self._rest = self.response(self.mesh_angle_deg, 0.0, u)
        return self._rest

    def _push_out_of_obstacles(self, u: np.ndarray) -> np.ndarray:
        """Where the mesh pose starts inside a bone (a tendon's approach to its attachment cutting
        a corner of a shaped bone), contact fades in first, the prestretch off: the muscle is
        pushed onto the bone's surface before it is prestressed (docs/theory.md, 3.5)."""
        if self.contact is None or not np.any(self.contact.penetration(self.mesh.points + u) > 0.0):
            return u
        obstacles = self.obstacles(self.mesh_angle_deg)
        self.contact.pose = lambda t: [Faded(obstacle, t) for obstacle in obstacles]
        self.solver.material = replace(self.material, fibre_prestretch=np.ones_like(self.material.fibre_prestretch),
                                       matrix_prestretch=None)
        try:
            return self.solver.solve(0.0, initial_displacement=u).displacement
        except ConvergenceError as exc:
            raise ConvergenceError(f"muscle {self.name!r}: its mesh pose cannot be pushed out of the bones it "
                                   f"starts inside: {exc}") from exc
        finally:
            self._set_path(self.mesh_angle_deg, self.mesh_angle_deg)

    def _switch_on_prestretch(self, u: np.ndarray, progress=None) -> np.ndarray:
        """Continuation of the fibre prestretch 1 -> lambda_0 (and of the matrix's, 1 -> s,
        docs/theory.md 1.7) at the mesh pose through the shares 0.6, 0.8, 0.9, 0.95, 0.98, 1 of
        it; a step where Newton fails is bisected (down to 1/64; lambda_0 = 1.3 needs it on the
        coarse biceps)."""
        full = self.material
        before, targets = 0.0, [0.6, 0.8, 0.9, 0.95, 0.98, 1.0]
        while targets:
            share = targets[0]
            self.solver.material = replace(full, fibre_prestretch=1.0 + share * (full.fibre_prestretch - 1.0),
                                           matrix_prestretch=1.0 + share * (full.matrix_prestretch - 1.0))
            report = None if progress is None else (lambda t, a=before, b=share: progress(a + t * (b - a)))
            try:
                u = self.solver.solve(0.0, initial_displacement=u, progress=report).displacement
            except ConvergenceError as exc:
                if share - before < 1.0 / 64.0:
                    raise ConvergenceError(f"muscle {self.name!r}: the prestressed mesh pose has no equilibrium "
                                           f"beyond {before:.3f} of its prestretch: {exc}") from exc
                targets.insert(0, 0.5 * (before + share))
                continue
            before = targets.pop(0)
        return u

    def solve(self, theta_deg: float, activation: float, start: MuscleState | None = None, progress=None,
              fresh_slope: bool = True) -> MuscleState:
        """Equilibrium at (theta, activation), continued from ``start`` (default: the rest state).

        The insertion face (and the bones) move from the start's angle to ``theta_deg`` while
        the activation moves along: the solver's load stepping is the continuation.
        ``progress(t)`` is called after every accepted load step (persival.model.arm.progress); it
        changes nothing solved. ``fresh_slope=False``: a state within ``small_step_mm`` of a start
        with known slope keeps the start's moment slope and du/dtheta (a chord: the joint
        iteration's last corrections need its moment, exact, but not a factorization for a
        derivative that barely moved).
        """
        if not np.isfinite(theta_deg):
            raise ValueError(f"muscle {self.name!r}: the elbow angle must be finite, got {theta_deg}")
        theta_deg, activation = float(theta_deg), float(activation)
        start = start or self.rest_state(progress)
        if start.angle_deg == theta_deg and start.activation == activation and np.isfinite(start.moment):
            if start.sensitivity is None:  # e.g. a state from an older cache: complete it
                start = self.response(theta_deg, activation, start.displacement)
            return start  # already the equilibrium there (e.g. the joint iteration's first angle)
        near = self._is_near(theta_deg, activation, start)
        # a start this near (the joint iteration's corrections) beats any interpolation of kept
        # states; with its slope du/dtheta the first-order predictor needs no factorization of its own
        if near and start.sensitivity is not None:
            chart, ds = self.chart(start.angle_deg)
            guess = start.displacement + (chart(theta_deg) - chart(start.angle_deg)) / ds * start.sensitivity
            state = self.solve_from_guess(theta_deg, activation, guess, progress, max_iterations=6,
                                          slope_from=None if fresh_slope else start, reuse_factorization=True)
        else:
            state = None if near else self._from_library(theta_deg, activation, progress)
        if state is None:
            state = self._continue(theta_deg, activation, start, progress=progress)
        self.library.add(state)
        return state

    def _is_near(self, theta_deg: float, activation: float, start: MuscleState) -> bool:
        """A joint iteration's correction: same activation, within ``small_step_mm`` and ``small_step_deg``."""
        return (activation == start.activation and abs(theta_deg - start.angle_deg) <= self.small_step_deg
                and abs(self.length(theta_deg) - start.length) <= self.small_step_mm)

    def _from_library(self, theta_deg: float, activation: float, progress=None) -> MuscleState | None:
        """Newton from the interpolation of two solved states of the same activation that
        bracket ``theta_deg`` (within ``library_gap_deg``); None if there are none or it fails.

        Passive muscles going slack are the expensive part of a state (a bowed muscle bending
        further: 100 to 200 Newton iterations by continuation); between solved neighbours it
        takes a few.
        """
        guess = self.library.guess(theta_deg, activation, self.library_gap_deg)
        return None if guess is None else self.solve_from_guess(theta_deg, activation, guess, progress)

    def solve_from_guess(self, theta_deg: float, activation: float, guess: np.ndarray, progress=None,
                         max_iterations: int = 12, slope_from: MuscleState | None = None,
                         reuse_factorization: bool = False) -> MuscleState | None:
        """Plain Newton at (theta, activation) from a guessed displacement (no load stepping);
        None if it does not converge within ``max_iterations``. The guess's insertion face is
        put where theta puts it, so an interpolation of neighbouring states is a good guess.
        ``slope_from``: take the moment slope and du/dtheta from this nearby state (see :meth:`solve`).
        ``reuse_factorization``: Newton directions from this muscle's last factorization where it
        is of a nearby tangent (SolverOptions.reuse_factorization; the joint iteration's corrections).
        """
        self._set_path(theta_deg, theta_deg)
        # the faces exactly where theta puts them: an extrapolation in theta misses the insertion's
        # L(theta) at second order, and a face jump costs the solver a predictor solve
        guess = np.array(guess, dtype=float, copy=True)
        guess[self._origin_face.nodes] = 0.0
        guess[self._insertion_face.nodes] = self._insertion_face.values(self.mesh.points, 1.0).reshape(-1, 3)
        options = self.solver.options
        self.solver.options = replace(options, initial_step=1.0, min_step=1.0,
                                      max_iterations=min(options.max_iterations, max_iterations),
                                      reuse_factorization=reuse_factorization or options.reuse_factorization)
        try:
            solution = self.solver.solve(activation, initial_displacement=guess, initial_activation=activation,
                                         progress=progress)
        except ConvergenceError:
            return None
        finally:
            self.solver.options = options
        if slope_from is not None:
            state = self._scalars(theta_deg, activation, solution.displacement, solution.internal_force)
            return replace(state, moment_slope=slope_from.moment_slope, sensitivity=slope_from.sensitivity,
                           max_volume_change=solution.max_volume_change, iterations=solution.statistics.iterations)
        return self._state(theta_deg, activation, solution)

    def _continue(self, theta_deg: float, activation: float, start: MuscleState, detour: bool = True,
                  progress=None) -> MuscleState:
        self._set_path(start.angle_deg, theta_deg)
        options = self.solver.options
        if self._is_near(theta_deg, activation, start):
            # the joint iteration's late corrections: one load step, Newton from the last state
            self.solver.options = replace(options, initial_step=1.0)
        try:
            solution = self.solver.solve(
                float(activation), initial_displacement=start.displacement, initial_activation=float(start.activation),
                progress=progress,
            )
        except ConvergenceError as exc:
            failure = exc
        else:
            return self._state(theta_deg, activation, solution)
        finally:
            self.solver.options = options
        if detour and activation != start.activation and not start.angle_deg == self.mesh_angle_deg == theta_deg:
            # Activating a slack, bowed muscle at fixed ends can snap through (the bow pulls
            # straight), where load stepping stalls. The same state is reached without a limit
            # point from the straight mesh pose: activate there first, then change the angle
            # (also from the mesh pose itself: changing angle and activation together can stall
            # where the staged path does not, e.g. a biceps pressed onto the humerus).
            # A fallback, not a guarantee (on the coarse mesh isometric activation at the mesh
            # pose itself stalls for the biceps and the brachioradialis): if it fails too, the
            # error reports the direct path.
            try:
                taut = self._continue(self.mesh_angle_deg, activation, self.rest_state(), detour=False, progress=progress)
                return self._continue(theta_deg, activation, taut, detour=False, progress=progress)
            except ConvergenceError:
                pass
        raise ConvergenceError(
            f"muscle {self.name!r} from {start.angle_deg:.1f} deg, activation {start.activation:.2f} "
            f"to {theta_deg:.1f} deg, {activation:.2f}: {failure}"
        ) from failure

    # -- the state's response: moment, its slope and du/dtheta -------------------------------------
    def _state(self, theta_deg: float, activation: float, solution) -> MuscleState:
        """The converged solution's state; its tangent (preconditioned by the last factorization)
        gives the moment slope and du/dtheta without a factorization of its own."""
        state = self.response(theta_deg, activation, solution.displacement, solution.tangent, solution.internal_force)
        return replace(state, max_volume_change=solution.max_volume_change, iterations=solution.statistics.iterations)

    def response(self, theta_deg: float, activation: float, displacement: np.ndarray, K=None,
                 force: np.ndarray | None = None) -> MuscleState:
        """The state of an equilibrium u at (theta, a): tension, moment M = -dPi*/dtheta, its slope
        and du/dtheta (docs/theory.md, 3.7; module docstring). With theta moving, the insertion face moves by
        ``g = dp/dtheta`` (``L'`` times the axial unit motion for the line tie) and the bones' forces
        change at fixed u by ``df_c/dtheta``; with f the internal force (the face's reaction):

            K_ff du_f = -(K g + df_c/dtheta)_f,
            dPi*/dtheta = f.g + P,  P = dPi_c/dtheta|_u                   (f.g = T L', line tie)
            d2Pi*/dtheta2 = g.K du + f.g2 + df_c/dtheta . du + dP/dtheta|_u  (g2 = d2p/dtheta2)

        (the contact terms by central differences of the cheap contact energy and force in theta).
        """
        u = np.asarray(displacement, dtype=float)
        reuse = K is not None
        if K is None:
            self._set_path(theta_deg, theta_deg)
            K, force = self.solver.tangent(u.ravel(), np.full(self.mesh.n_cells, activation))
        g, g2 = self.tie.motion(theta_deg, self.mesh.points)
        P, dP, rate = self._contact_rates(theta_deg, u)
        S, du = self.solver.condensed_response(K, g, reuse_factorization=reuse, force_rate=rate)
        work_slope = S + float(force @ g2) + dP + (0.0 if rate is None else float(rate @ du))
        state = replace(self._scalars(theta_deg, activation, u, force, contact_work=P, motion=g),
                        moment_slope=-float(work_slope), sensitivity=du.reshape(-1, 3))
        if reuse:  # a solver's solution: the caller takes max |J - 1| from it
            return state
        F = self.assembler.deformation_gradient(u.ravel())
        return replace(state, max_volume_change=float(np.abs(np.linalg.det(F) - 1).max()))

    def _scalars(self, theta_deg: float, activation: float, u: np.ndarray, force: np.ndarray,
                 contact_work: float | None = None, motion: np.ndarray | None = None) -> MuscleState:
        """A state with its exact moment (no slope yet): -(f.g + dPi_c/dtheta), f.g = T L' on a line
        tie; ``motion``: g = dp/dtheta when the caller has it already."""
        L = self.length(theta_deg)
        g = self.tie.motion(theta_deg, self.mesh.points)[0] if motion is None else motion
        tension, work = self.tie.tension(force, theta_deg), float(force @ g)
        if contact_work is None:
            contact_work = self._contact_rates(theta_deg, u, slopes=False)[0]
        pressure, depth = 0.0, 0.0
        if self.contact is not None:
            x = self.mesh.points + u
            self.contact.obstacles = tuple(self.obstacles(theta_deg))
            pressure, depth = self.contact.load_and_depth(x)
        return MuscleState(theta_deg, float(L), activation, u, tension, -float(work + contact_work),
                           float("nan"), 0.0, contact_force=pressure, max_penetration=depth)

    def _contact_rates(self, theta_deg: float, u: np.ndarray, slopes: bool = True):
        """P = dPi_c/dtheta|_u (N mm/rad), dP/dtheta|_u and df_c/dtheta|_u (n_dofs,) by central
        differences in theta (zeros and None without bones)."""
        if self.contact is None:
            return 0.0, 0.0, None
        return self.contact.angle_rates(self.mesh.points + u, self.obstacles, theta_deg, self.contact_step_deg, slopes)


__all__ = ["ConvergenceError", "MusclePath", "MuscleState", "MuscleUnit"]
