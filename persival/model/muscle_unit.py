"""One muscle-tendon unit between its origin and insertion faces, solved in its own frame.

SPEC 3.3 ties each muscle's end faces to its line of action (ball joints: the origin face
turns about the fixed origin point O, the insertion face rides on the forearm's insertion
point I(theta), and both faces turn by the minimal rotation Q(theta) that takes the mesh-pose
line direction d_ref to the current one d(theta); see :class:`~persival.model.constraints.Hinge`).
Because the law is objective and the muscles carry no body force, the deformed muscle at
elbow angle theta is exactly the rigid motion ``x = O + Q(theta) (y - O)`` of the solution
``y`` of a simpler problem: origin face held in its mesh pose, insertion face translated along
d_ref by ``L(theta) - L_mesh`` (L = |I - O|). A muscle's state therefore depends on two numbers,
its origin-insertion length L and its activation a, and its work on the joint is
``T dL/dtheta`` with the tension ``T = dPi/dL`` (the axial reaction of the insertion face).
The rigid rotation does no work (the muscle's own moment balance), so nothing is lost.

This turns the joint equilibrium into one scalar equation in theta (see ArmModel), and each
muscle into a small FE problem solved on its own: five solves of a few thousand DOFs instead
of one of all of them, and a table of solved (L, a) states per muscle that warm-starts every
new state by interpolation.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, replace
from itertools import pairwise

import numpy as np

from persival.model.assembly import MaterialField, Tet10Assembler
from persival.model.constraints import Dirichlet
from persival.model.mesh import Tet10Mesh
from persival.model.solver import ConvergenceError, QuasiStaticSolver, SolverOptions


@dataclass
class MuscleState:
    """Equilibrium of one muscle at origin-insertion length ``length`` and activation ``activation``."""

    length: float  # mm, |I - O|
    activation: float
    displacement: np.ndarray  # (n_nodes, 3) mm, in the muscle's mesh-pose frame
    tension: float  # N, dPi/dL: positive when the muscle pulls its ends together
    stiffness: float  # N/mm, dT/dL with the interior re-equilibrated (Schur complement)
    max_volume_change: float
    iterations: int = 0
    # du/dL (n_nodes, 3) mm/mm at fixed activation, the interior re-equilibrated: the slope of
    # the state along its length (cubic Hermite guesses between tabulated states); None if unknown
    sensitivity: np.ndarray | None = None


def line_rotation(d_ref: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The minimal rotation taking unit vector d_ref to unit vector d (the Hinge's face rotation).

    Q = I + [v]x + [v]x^2 / (1 + cos), v = d_ref x d.
    """
    v = np.cross(d_ref, d)
    c = float(d_ref @ d)
    if c <= -1.0 + 1e-12:
        raise ValueError("the line of action reversed its direction")
    V = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + V + V @ V / (1.0 + c)


class MuscleUnit:
    """The FE problem of one muscle with its length and activation prescribed."""

    small_step_mm = 1.0  # length changes up to this are taken in one load step (then halved if needed)
    library_gap_mm = 8.0  # solved states at most this far apart are interpolated as a start
    library_spacing_mm = 0.25  # a new state this close to a kept one is not kept
    library_size = 600  # states kept per muscle (each n_nodes x 3 floats)

    def __init__(
        self,
        name: str,
        mesh: Tet10Mesh,
        material: MaterialField,
        origin: np.ndarray,
        insertion: np.ndarray,
        options: SolverOptions | None = None,
    ) -> None:
        self.name = name
        self.mesh = mesh
        self.material = material
        self.origin = np.asarray(origin, dtype=float)
        axis = np.asarray(insertion, dtype=float) - self.origin
        self.mesh_length = float(np.linalg.norm(axis))
        if self.mesh_length <= 0:
            raise ValueError(f"muscle {name!r}: origin and insertion coincide")
        self.direction = axis / self.mesh_length
        self.assembler = Tet10Assembler(mesh)
        self._origin_face = Dirichlet("origin", mesh.node_sets["origin"])
        self._insertion_face = Dirichlet("insertion", mesh.node_sets["insertion"])
        self.solver = QuasiStaticSolver(mesh, material, [self._origin_face, self._insertion_face], options,
                                        assembler=self.assembler)
        # the insertion face's unit axial translation: dx/dL of the constrained DOFs
        self._axial = np.zeros(self.assembler.n_dofs)
        self._axial[self._insertion_face.dofs] = np.tile(self.direction, len(self._insertion_face.nodes))
        # solved states by activation, sorted by length: starts for later solves (_from_library)
        self._library: dict[float, list[MuscleState]] = {}

    @property
    def options(self) -> SolverOptions:
        return self.solver.options

    @options.setter
    def options(self, value: SolverOptions) -> None:
        self.solver.options = value

    def rest_state(self, progress=None) -> MuscleState:
        """The passive equilibrium at the mesh length (activation 0), solved once.

        With a fibre prestretch lambda_0 > 1 the mesh pose carries a small passive fibre
        stress (SPEC 3.3) and is not yet in equilibrium. Newton from the mesh pose can fail
        on it (the passive law's c4 = 42.6 makes the tangent far stiffer than the stress
        suggests), so the prestretch is switched on by continuation, 1 -> lambda_0.
        ``progress(share)`` is called after every accepted load step (share of the prestretch).
        """
        if getattr(self, "_rest", None) is None:
            u = np.zeros((self.mesh.n_nodes, 3))
            full = self.material
            try:
                for before, share in pairwise((0.0, 0.6, 0.8, 0.9, 0.95, 0.98, 1.0)):
                    self.solver.material = replace(full, fibre_prestretch=1.0 + share * (full.fibre_prestretch - 1.0))
                    self._insertion_face.start[:] = 0.0
                    self._insertion_face.end[:] = 0.0
                    step = None if progress is None else (lambda t, a=before, b=share: progress(a + t * (b - a)))
                    u = self.solver.solve(0.0, initial_displacement=u, progress=step).displacement
            except ConvergenceError as exc:
                raise ConvergenceError(f"muscle {self.name!r}: the prestressed mesh pose has no equilibrium: {exc}") from exc
            finally:
                self.solver.material = full
            F = self.assembler.deformation_gradient(u.ravel())
            tension, stiffness, slope = self._stiffness(u, 0.0)
            self._rest = MuscleState(self.mesh_length, 0.0, u, tension, stiffness, float(np.abs(np.linalg.det(F) - 1).max()),
                                     sensitivity=slope)
        return self._rest

    def solve(self, length: float, activation: float, start: MuscleState | None = None, progress=None,
              fresh_slope: bool = True) -> MuscleState:
        """Equilibrium at (length, activation), continued from ``start`` (default: the mesh pose).

        The insertion face moves from the start length to ``length`` while the activation
        moves along: the solver's load stepping is the continuation. ``progress(t)`` is called
        after every accepted load step (persival.model.progress); it changes nothing solved.
        ``fresh_slope=False``: a state within ``small_step_mm`` of a start with known slope
        keeps the start's stiffness and du/dL (a chord: the joint iteration's last corrections
        need its tension, exact, but not a factorization for a derivative that barely moved).
        """
        if not np.isfinite(length) or length <= 0:
            raise ValueError(f"muscle {self.name!r}: length must be positive, got {length}")
        start = start or self.rest_state(progress)
        if start.length == length and start.activation == activation and np.isfinite(start.tension):
            if start.sensitivity is None:  # e.g. a rest state from an older cache: complete it
                start = replace(start, sensitivity=self._stiffness(start.displacement, activation)[2])
            return start  # already the equilibrium there (e.g. the joint iteration's first angle)
        near = abs(length - start.length) <= self.small_step_mm and activation == start.activation
        # a start this near (the joint iteration's corrections) beats any interpolation of kept
        # states; with its slope du/dL the first-order predictor needs no factorization of its own
        if near and start.sensitivity is not None:
            guess = start.displacement + (length - start.length) * start.sensitivity
            state = self.solve_from_guess(float(length), float(activation), guess, progress, max_iterations=6,
                                          slope_from=None if fresh_slope else start)
        else:
            state = None if near else self._from_library(float(length), float(activation), progress)
        if state is None:
            state = self._continue(float(length), float(activation), start, progress=progress)
        self._remember(state)
        return state

    def _from_library(self, length: float, activation: float, progress=None) -> MuscleState | None:
        """Newton from the interpolation of two solved states of the same activation that
        bracket ``length`` (within ``library_gap_mm``); None if there are none or it fails.

        Linear interpolation in L keeps the insertion face exactly where L puts it. Passive
        muscles going slack are the expensive part of a state (a bowed muscle bending further:
        100 to 200 Newton iterations by continuation); between solved neighbours it takes a few.
        """
        states = self._library.get(activation)
        if not states:
            return None
        lengths = [s.length for s in states]
        k = bisect.bisect_left(lengths, length)
        if k == 0 or k == len(states):
            return None
        lo, hi = states[k - 1], states[k]
        if hi.length - lo.length > self.library_gap_mm:
            return None
        w = (length - lo.length) / (hi.length - lo.length)
        return self.solve_from_guess(length, activation, (1.0 - w) * lo.displacement + w * hi.displacement, progress)

    def solve_from_guess(self, length: float, activation: float, guess: np.ndarray, progress=None,
                         max_iterations: int = 12, slope_from: MuscleState | None = None) -> MuscleState | None:
        """Plain Newton at (length, activation) from a guessed displacement (no load stepping);
        None if it does not converge within ``max_iterations``. The guess's insertion face is
        put where ``length`` puts it, so an interpolation of neighbouring states is a good guess.
        ``slope_from``: take stiffness and du/dL from this nearby state (see :meth:`solve`).
        """
        self._insertion_face.start[:] = self._insertion_face.end[:] = (length - self.mesh_length) * self.direction
        options = self.solver.options
        self.solver.options = replace(options, initial_step=1.0, min_step=1.0,
                                      max_iterations=min(options.max_iterations, max_iterations))
        try:
            solution = self.solver.solve(activation, initial_displacement=guess, initial_activation=activation,
                                         progress=progress)
        except ConvergenceError:
            return None
        finally:
            self.solver.options = options
        if slope_from is not None:
            return MuscleState(length, activation, solution.displacement, self._tension(solution), slope_from.stiffness,
                               solution.max_volume_change, solution.statistics.iterations, slope_from.sensitivity)
        return self._state(length, activation, solution)

    def _remember(self, state: MuscleState) -> None:
        states = self._library.setdefault(state.activation, [])
        lengths = [s.length for s in states]
        k = bisect.bisect_left(lengths, state.length)
        near = [s for s in states[max(k - 1, 0) : k + 1] if abs(s.length - state.length) < self.library_spacing_mm]
        if near or sum(len(v) for v in self._library.values()) >= self.library_size:
            return
        states.insert(k, state)

    def _continue(self, length: float, activation: float, start: MuscleState, detour: bool = True,
                  progress=None) -> MuscleState:
        self._insertion_face.start[:] = (start.length - self.mesh_length) * self.direction
        self._insertion_face.end[:] = (length - self.mesh_length) * self.direction
        options = self.solver.options
        if abs(length - start.length) <= self.small_step_mm and activation == start.activation:
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
            return self._state(length, activation, solution)
        finally:
            self.solver.options = options
        if detour and activation != start.activation and start.length != self.mesh_length:
            # Activating a slack, bowed muscle at fixed ends can snap through (the bow pulls
            # straight), where load stepping stalls. The same state is reached without a limit
            # point from the straight mesh pose: activate there first, then change the length.
            # A fallback, not a guarantee (on the coarse mesh isometric activation at the mesh
            # pose itself stalls for the biceps and the brachioradialis): if it fails too, the
            # error reports the direct path.
            try:
                taut = self._continue(self.mesh_length, activation, self.rest_state(), detour=False, progress=progress)
                return self._continue(length, activation, taut, detour=False, progress=progress)
            except ConvergenceError:
                pass
        raise ConvergenceError(
            f"muscle {self.name!r} from length {start.length:.1f} mm, activation {start.activation:.2f} "
            f"to {length:.1f} mm, {activation:.2f}: {failure}"
        ) from failure

    def _state(self, length: float, activation: float, solution) -> MuscleState:
        if solution.tangent is not None:  # the converged tangent, preconditioned by the last factorization
            tension = self._tension(solution)
            stiffness, slope = self.solver.condensed_response(solution.tangent, self._axial, reuse_factorization=True)
            slope = slope.reshape(-1, 3)
        else:
            tension, stiffness, slope = self._stiffness(solution.displacement, activation)
        return MuscleState(
            length, activation, solution.displacement, tension, stiffness,
            solution.max_volume_change, solution.statistics.iterations, slope,
        )

    def _tension(self, solution) -> float:
        """T = dPi/dL: the axial part of the insertion face's reaction (what _stiffness sums)."""
        return float(self.direction @ solution.reactions["insertion"].force)

    def _stiffness(self, displacement: np.ndarray, activation: float) -> tuple[float, float, np.ndarray]:
        """Tension dPi/dL, axial stiffness dT/dL = g.K.g - (K g)_f . K_ff^-1 (K g)_f and the
        sensitivity du/dL (n_nodes, 3) of the same solve."""
        per_cell = np.full(self.mesh.n_cells, activation)
        K, f = self.assembler.tangent(np.asarray(displacement).ravel(), self.material, per_cell)
        stiffness, slope = self.solver.condensed_response(K, self._axial)
        return float(self._axial @ f), stiffness, slope.reshape(-1, 3)

    def positions(self, state: MuscleState, rotation: np.ndarray) -> np.ndarray:
        """World node positions of a state whose line of action is turned by ``rotation``."""
        y = self.mesh.points + state.displacement
        return self.origin + (y - self.origin) @ rotation.T


__all__ = ["ConvergenceError", "MuscleState", "MuscleUnit", "line_rotation"]
