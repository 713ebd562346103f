"""The built-in upper-limb model: five tet10 muscles, rigid bones, elbow angle from equilibrium.

SPEC 3.3. Each muscle is a swept solid meshed stress free in its own pose; its origin face
is fixed to the humerus, its insertion face is tied to the forearm, which rotates about the
elbow hinge. The unknowns are the muscle displacements and the elbow angle theta; theta's
equation is the moment balance about the hinge of the insertion forces, gravity on forearm
plus hand and a passive joint moment that stiffens beyond the anatomical limits. Muscles do
not touch each other or the bones (no contact, unlike the paper's mortar contact).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from persival.model.arm_file import MUSCLE_ORDER, Muscle, load_model_file
from persival.model.assembly import MaterialField, Tet10Assembler
from persival.model.constraints import Hinge
from persival.model.geometry import swept_solid_mesh
from persival.model.mesh import Tet10Mesh
from persival.model.solver import ConvergenceError, QuasiStaticSolver, SolverOptions


def rotation_about(axis: np.ndarray, theta_deg: float) -> np.ndarray:
    """Rotation matrix about a unit axis (Rodrigues)."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    t = np.radians(theta_deg)
    return np.eye(3) + np.sin(t) * K + (1.0 - np.cos(t)) * (K @ K)


def muscle_profile(muscle: Muscle, s: np.ndarray, length: float) -> tuple[np.ndarray, np.ndarray]:
    """Radius and muscle fraction gamma_M along the normalized centre-line position s.

    Pure tendon over the tendon lengths, a linear muscle-tendon blend over
    ``transition_length`` (SPEC 3.1 mixture), a full belly between the tendons:
    r = r_t + (r_b - r_t) sin(pi x)^(1/2). A slimmer (sin^2) taper would put pure muscle of a
    tenth of the belly's cross-section in series with the belly; under tension those necks
    take the whole stretch and reach the steep passive range (c4 = 42.6) long before the belly.
    """
    s_a = muscle.tendon_length[0] / length
    s_b = 1.0 - muscle.tendon_length[1] / length
    if s_b - s_a <= 2.0 * muscle.transition_length / length:
        raise ValueError(f"muscle {muscle.name!r}: tendons and transitions are longer than the muscle ({length:.0f} mm)")
    r_tendon = muscle.tendon_radius[0] + (muscle.tendon_radius[1] - muscle.tendon_radius[0]) * s
    inside = (s > s_a) & (s < s_b)
    bump = np.where(inside, np.sqrt(np.abs(np.sin(np.pi * (s - s_a) / (s_b - s_a)))), 0.0)
    radius = r_tendon + (muscle.belly_radius - r_tendon) * bump
    ramp = muscle.transition_length / length
    gamma = np.clip(np.minimum(s - s_a, s_b - s) / ramp, 0.0, 1.0)
    return radius, gamma


@dataclass
class ArmState:
    """One equilibrium of the arm (also the warm-start token for nearby solves)."""

    activations: np.ndarray  # (5,) biceps, brachialis, brachioradialis, triceps, anconeus
    elbow_angle_deg: float
    displacement: np.ndarray  # (n_nodes, 3) mm, all muscles
    moment_residual: float  # N mm at convergence
    muscle_moments: dict[str, float]  # N mm about the hinge axis (flexion positive)
    muscle_forces: dict[str, float]  # N, magnitude of the insertion force
    external_moment: float  # N mm, gravity + passive joint
    max_volume_change: float
    statistics: dict = field(default_factory=dict)
    wall_time_s: float = 0.0

    def summary(self) -> dict:
        return {
            "activations": {n: float(a) for n, a in zip(MUSCLE_ORDER, self.activations)},
            "elbow_angle_deg": self.elbow_angle_deg,
            "moment_residual_Nmm": self.moment_residual,
            "muscle_moments_Nmm": self.muscle_moments,
            "muscle_forces_N": self.muscle_forces,
            "external_moment_Nmm": self.external_moment,
            "max_abs_J_minus_1": self.max_volume_change,
            "newton": self.statistics,
            "wall_time_s": self.wall_time_s,
        }


class ArmModel:
    """The FE upper limb: ``solve(activations) -> ArmState`` (SPEC 3.3).

    Meshing happens once at construction; the activation-free equilibrium (the hanging arm)
    is solved once and cached, and every other state continues from it or from a nearby
    solved state given as ``warm_start``.
    """

    base_angle_deg = 20.0  # the muscles are first brought from their mesh poses to this angle

    def __init__(self, model_file: str | Path | None = None, profile: str = "quick", options: SolverOptions | None = None):
        self.spec, self.model_hash = load_model_file(model_file)
        self.profile = profile
        self.spec.profile(profile)  # unknown profile -> clear error
        self.options = options or SolverOptions()
        joint = self.spec.joint
        self.axis = np.asarray(joint.axis, dtype=float) / np.linalg.norm(joint.axis)
        self.centre = np.asarray(joint.centre, dtype=float)
        self.mesh, self.muscle_cells, self.muscle_nodes = self._build_mesh()
        self.material = self._material()
        self.assembler = Tet10Assembler(self.mesh)
        # Both end faces of every muscle ride on the elbow hinge as ball joints aligned with the
        # muscle's line of action (Hinge.muscle_lines): origins at fixed points, insertions on
        # the forearm.
        nodes, reference, O, I, is_insertion = [], [], [], [], []
        for m in self.spec.ordered_muscles():
            insertion_ref = self.forearm_point(m.insertion, m.mesh_angle_deg)
            for end in ("origin", "insertion"):
                ids = self.mesh.node_sets[f"{m.name}/{end}"]
                nodes.append(ids)
                reference.append(np.full(len(ids), m.mesh_angle_deg))
                O.append(np.tile(m.origin, (len(ids), 1)))
                I.append(np.tile(insertion_ref, (len(ids), 1)))
                is_insertion.append(np.full(len(ids), end == "insertion"))
        self._tied = (np.concatenate(nodes), np.concatenate(reference))
        self._lines = (np.vstack(O), np.vstack(I), np.concatenate(is_insertion))
        self.elbow = Hinge(
            "elbow", self._tied[0], self.centre, self.axis, self._tied[1], start_deg=self.base_angle_deg,
            free=True, external_moment=self.external_moment, muscle_lines=self._lines,
        )
        # the free elbow: its moment balance and joint stiffness drive the staggered iteration
        self.solver = QuasiStaticSolver(self.mesh, self.material, [self.elbow], self.options, assembler=self.assembler)
        # the same ties with the angle prescribed (per node: each muscle may start in its own pose)
        self._posing = Hinge(
            "elbow", self._tied[0], self.centre, self.axis, self._tied[1], start_deg=self._tied[1],
            end_deg=self.base_angle_deg, muscle_lines=self._lines,
        )
        self._posing_solver = QuasiStaticSolver(self.mesh, self.material, [self._posing], self.options, assembler=self.assembler)
        self._base: ArmState | None = None

    def set_options(self, options: SolverOptions) -> None:
        """Solver options of every solve of this model (retries use smaller load steps)."""
        self.options = self.solver.options = self._posing_solver.options = options

    # -- geometry -----------------------------------------------------------------------------
    def forearm_point(self, p: np.ndarray, theta_deg: float) -> np.ndarray:
        """A forearm-frame point (given at theta = 0) at elbow angle theta."""
        return self.centre + (np.asarray(p, dtype=float) - self.centre) @ rotation_about(self.axis, theta_deg).T

    def centre_line(self, muscle: Muscle, stations: int = 33) -> np.ndarray:
        """Stations along origin -> via points -> insertion in the muscle's mesh pose."""
        knots = np.array([muscle.origin, *muscle.via, self.forearm_point(muscle.insertion, muscle.mesh_angle_deg)])
        seg = np.linalg.norm(np.diff(knots, axis=0), axis=1)
        if np.any(seg <= 0):
            raise ValueError(f"muscle {muscle.name!r}: consecutive centre-line points coincide")
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        s = np.linspace(0.0, cum[-1], stations)
        return np.column_stack([np.interp(s, cum, knots[:, k]) for k in range(3)])

    def centre_line_length(self, muscle: Muscle) -> float:
        """Length (mm) of the muscle's centre line in its mesh pose: the scale of its tissue layout."""
        return float(np.linalg.norm(np.diff(self.centre_line(muscle), axis=0), axis=1).sum())

    def _build_mesh(self):
        points, cells, node_sets, cell_data = [], [], {}, {"muscle": [], "fibre": [], "arclength": []}
        muscle_cells, muscle_nodes = {}, {}
        offset = 0
        for index, muscle in enumerate(self.spec.ordered_muscles()):
            line = self.centre_line(muscle)
            radius, _ = muscle_profile(muscle, np.linspace(0.0, 1.0, len(line)), self.centre_line_length(muscle))
            mesh = swept_solid_mesh(line, radius, self.spec.mesh_size(self.profile, muscle.name))
            points.append(mesh.points)
            cells.append(mesh.cells + offset)
            start_cell = sum(len(c) for c in cells[:-1])
            muscle_cells[muscle.name] = np.arange(start_cell, start_cell + mesh.n_cells)
            muscle_nodes[muscle.name] = np.arange(offset, offset + mesh.n_nodes)
            node_sets[f"{muscle.name}/origin"] = mesh.node_sets["origin"] + offset
            node_sets[f"{muscle.name}/insertion"] = mesh.node_sets["insertion"] + offset
            cell_data["muscle"].append(np.full(mesh.n_cells, index))
            cell_data["fibre"].append(mesh.cell_data["fibre"])
            cell_data["arclength"].append(mesh.cell_data["arclength"])
            offset += mesh.n_nodes
        mesh = Tet10Mesh(
            np.vstack(points), np.vstack(cells), node_sets=node_sets,
            cell_data={k: np.concatenate(v) for k, v in cell_data.items()},
        )
        mesh.check()
        return mesh, muscle_cells, muscle_nodes

    def _material(self) -> MaterialField:
        n = self.mesh.n_cells
        gamma, k, pre = np.empty(n), np.empty(n), np.empty(n)
        for muscle in self.spec.ordered_muscles():
            cells = self.muscle_cells[muscle.name]
            _, g = muscle_profile(muscle, self.mesh.cell_data["arclength"][cells], self.centre_line_length(muscle))
            gamma[cells] = g
            k[cells] = g * muscle.bulk_modulus[0] + (1.0 - g) * muscle.bulk_modulus[1]
            pre[cells] = muscle.fibre_prestretch
        self.mesh.cell_data["muscle_fraction"] = gamma
        return MaterialField.from_cells(4, self.mesh.cell_data["fibre"], gamma, k, pre)

    def line_moment_arm(self, muscle: Muscle, theta_deg: float) -> float:
        """Moment arm (mm, flexion positive) of the straight origin-insertion line at theta."""
        origin = np.asarray(muscle.origin, dtype=float)
        insertion = self.forearm_point(muscle.insertion, theta_deg)
        direction = (origin - insertion) / np.linalg.norm(origin - insertion)
        return float(np.cross(insertion - self.centre, direction) @ self.axis)

    # -- loads --------------------------------------------------------------------------------
    def gravity_moment(self, theta_deg: float) -> float:
        """Moment of the forearm's weight about the hinge (N mm, flexion positive): -m g r sin(theta)."""
        fa = self.spec.forearm
        return -fa.mass * fa.gravity * fa.centre_of_mass * np.sin(np.radians(theta_deg))

    def passive_joint_moment(self, theta_deg: float) -> float:
        """K [exp((theta_min - theta)/w) - exp((theta - theta_max)/w)]: stiffens beyond the limits."""
        j = self.spec.joint
        lo, hi = j.limits_deg
        return j.limit_moment * (np.exp((lo - theta_deg) / j.limit_width_deg) - np.exp((theta_deg - hi) / j.limit_width_deg))

    def external_moment(self, theta_rad: float) -> tuple[float, float]:
        """Gravity + passive joint moment and its derivative per radian (the hinge's load)."""
        theta = np.degrees(theta_rad)
        fa, j = self.spec.forearm, self.spec.joint
        lo, hi = j.limits_deg
        w = j.limit_width_deg
        M = self.gravity_moment(theta) + self.passive_joint_moment(theta)
        dM = -fa.mass * fa.gravity * fa.centre_of_mass * np.cos(theta_rad)
        dM += j.limit_moment * (-np.exp((lo - theta) / w) - np.exp((theta - hi) / w)) / w * (180.0 / np.pi)
        return float(M), float(dM)

    # -- solves -------------------------------------------------------------------------------
    def cell_activation(self, activations: np.ndarray) -> np.ndarray:
        return np.asarray(activations, dtype=float)[self.mesh.cell_data["muscle"]]

    @staticmethod
    def validate_activations(activations) -> np.ndarray:
        a = np.asarray(activations, dtype=float)
        if a.shape != (5,):
            raise ValueError(f"need 5 activations ({', '.join(MUSCLE_ORDER)}), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("activations must be finite")
        if np.any((a < 0) | (a > 1)):
            raise ValueError(f"activations must lie in [0, 1], got {a.tolist()}")
        return a

    def base_state(self) -> ArmState:
        """The hanging arm (all activations 0), solved once per model and cached on disk.

        The muscles are first brought from their own mesh poses to ``base_angle_deg`` with the
        angle prescribed (minutes), then the joint is released. The result is kept in
        ``$PERSIVAL_CACHE`` (default ``~/.cache/persival``) under a key of the model file,
        the profile, the package version and the mesh itself; a cached state is re-checked by
        one joint evaluation before it is used.
        """
        if self._base is None:
            t0 = time.perf_counter()
            cached = self._base_cache_file()
            start = None
            if cached.exists():
                try:
                    with np.load(cached, allow_pickle=False) as z:
                        start = (z["displacement"], float(z["elbow_angle_deg"]), {})
                except (OSError, KeyError, ValueError):
                    start = None  # unreadable: solve again
            if start is None or start[0].shape != self.mesh.points.shape:
                self._posing.start_deg[:] = self._tied[1]
                self._posing.end_deg[:] = self.base_angle_deg
                posed = self._posing_solver.solve(0.0)
                start = (posed.displacement, self.base_angle_deg, {"posing": posed.statistics.as_dict()})
            state = self._equilibrium(np.zeros(5), start[0], start[1], np.zeros(5))
            state.statistics.update(start[2])
            state.wall_time_s = time.perf_counter() - t0
            self._write_base_cache(cached, state)
            self._base = state
        return self._base

    def _base_cache_file(self) -> Path:
        import hashlib
        import os

        from persival import __version__

        digest = hashlib.sha256()
        digest.update(f"{self.model_hash}/{self.profile}/{__version__}".encode())
        digest.update(self.mesh.points.tobytes())
        digest.update(self.mesh.cells.tobytes())
        root = Path(os.environ.get("PERSIVAL_CACHE", Path.home() / ".cache" / "persival"))
        return root / f"hanging-arm-{digest.hexdigest()[:24]}.npz"

    @staticmethod
    def _write_base_cache(path: Path, state: ArmState) -> None:
        import os
        import tempfile

        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
            with os.fdopen(fd, "wb") as handle:
                np.savez(handle, displacement=state.displacement, elbow_angle_deg=state.elbow_angle_deg)
            os.replace(tmp, path)
        except OSError:
            pass  # a read-only home only costs the next run the posing

    def solve(self, activations, warm_start: ArmState | None = None) -> ArmState:
        """Equilibrium for the five activations, continued from ``warm_start`` (or the hanging arm)."""
        target = self.validate_activations(activations)
        t0 = time.perf_counter()
        start = warm_start if warm_start is not None else self.base_state()
        state = self._equilibrium(target, start.displacement, start.elbow_angle_deg, start.activations)
        state.wall_time_s = time.perf_counter() - t0
        return state

    # -- the joint equilibrium (staggered) --------------------------------------------------------
    def _muscles_at(self, theta, u_start, theta_start, activation, activation_start, stats):
        """Muscle equilibrium with the elbow angle prescribed (moving theta_start -> theta and
        the activation along), and the joint's moment residual g and stiffness dg/dtheta there."""
        self._posing.start_deg[:] = theta_start
        self._posing.end_deg[:] = theta
        solution = self._posing_solver.solve(
            self.cell_activation(activation), initial_displacement=u_start,
            initial_activation=self.cell_activation(activation_start),
        )
        for key, value in solution.statistics.as_dict().items():
            if isinstance(value, (int, float)):
                stats[key] = stats.get(key, 0) + value
        # g = dPi/dtheta; dg/dtheta is the joint stiffness with the muscles re-equilibrated
        g, dg = self.solver.hinge_balance(solution.displacement, theta, self.cell_activation(activation))
        return solution, g, dg

    def _equilibrium(self, target, displacement, angle, start_activations) -> ArmState:
        """Solve dPi/dtheta = 0 by a safeguarded 1-D Newton iteration on theta, the muscles
        re-equilibrated at every trial angle (an equivalent of the bordered system, SPEC 3.3).

        Why not the monolithic bordered Newton of QuasiStaticSolver: the muscles swing with the
        joint, so the linearized step moves their interiors along tangents while their end faces
        move on arcs; the second-order mismatch in the stiff tendons (about 100 N for 0.8 deg)
        swamps the small moment imbalance and the line search refuses every step. Prescribing
        the angle lets the solver place the faces exactly.
        """
        opts = self.options
        stats: dict = {"joint_iterations": 0}
        theta, u = float(angle), displacement
        solution, g, dg = self._muscles_at(theta, u, theta, target, start_activations, stats)
        lo, hi = -np.inf, np.inf  # bracket of the root: g(lo) < 0 < g(hi) (g grows with theta when stable)
        lower, upper = self.spec.joint.limits_deg
        for _ in range(60):
            if abs(g) <= opts.moment_atol:
                break
            if g > 0:
                hi = min(hi, theta)
            else:
                lo = max(lo, theta)
            step = -np.degrees(g / dg) if dg > 0 else (-opts.joint_max_step if g > 0 else opts.joint_max_step)
            step = float(np.clip(step, -opts.joint_max_step, opts.joint_max_step))
            trial = theta + step
            if not lo < trial < hi:  # Newton left the bracket: bisect
                trial = 0.5 * (lo + hi) if np.isfinite(lo) and np.isfinite(hi) else theta + step
            trial = float(np.clip(trial, lower - 30.0, upper + 30.0))
            solution, g, dg = self._muscles_at(trial, solution.displacement, theta, target, target, stats)
            theta = trial
            stats["joint_iterations"] += 1
        else:
            raise ConvergenceError(f"joint equilibrium not found: moment residual {g:.3e} N mm at {theta:.2f} deg")
        u = solution.displacement
        f = self.assembler.internal_force(u.ravel(), self.material, self.cell_activation(target)).reshape(-1, 3)
        # A muscle's moment on the forearm is minus the work of its tied faces' forces per
        # unit rotation (the hinge's virtual work, both faces included).
        velocity, _ = self.elbow.velocity(self.mesh.points, theta)
        work = np.zeros((self.mesh.n_nodes, 3))
        work[self.elbow.nodes] = velocity
        moments, forces = {}, {}
        for name in MUSCLE_ORDER:
            nodes = self.muscle_nodes[name]
            moments[name] = float(-np.sum(f[nodes] * work[nodes]))
            forces[name] = float(np.linalg.norm(f[self.mesh.node_sets[f"{name}/insertion"]].sum(axis=0)))
        return ArmState(
            activations=target.copy(),
            elbow_angle_deg=float(theta),
            displacement=u.copy(),
            moment_residual=float(g),
            muscle_moments=moments,
            muscle_forces=forces,
            external_moment=self.external_moment(np.radians(theta))[0],
            max_volume_change=solution.max_volume_change,
            statistics=stats,
        )


__all__ = ["ArmModel", "ArmState", "ConvergenceError", "muscle_profile", "rotation_about"]
