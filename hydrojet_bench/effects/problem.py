"""The rod problem: everything a solve needs, in SI units, as plain arrays.

A model builds a `RodProblem` from the parameters and the jet forces, lets each enabled
effect edit it, then hands it to the numerical kernel. Effects never see the kernel: this
class is the whole vocabulary of physics they can change, which is what lets one effect
work unchanged in both the Cosserat and the PRB model:

* constitutive law: bending/torsional stiffness and intrinsic curvature as functions of
  arc length (sampled on ``arc_length_m``), plus a cubic strain-stiffening coefficient;
* section strain: shear and axial compliance (none: the paper's inextensible,
  unshearable rod);
* distributed loads: force per length (base frame) and moment per length (body frame);
* tip loads: follower force/moment (tip frame, e.g. the jets and w_d) and dead forces
  applied at a point given in the tip frame (e.g. the capsule's weight);
* actuation map: jet gains and the jet-ring angle;
* base boundary: a rotational clamp compliance, optionally with play (hysteresis), which
  makes the solve depend on the previous clamp rotation;
* measurement: fixed mounting rotations of the base and tip sensors (and the base
  sensor's origin, the lever arm of its mounting).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..params import ModelParameters, RodParameters, actuation_matrix


_IDENTITY = np.eye(3)


@lru_cache(maxsize=64)
def _section_stiffness(rod: RodParameters, arc_length_bytes: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Bending (E I) and torsional (G J) stiffness, N m^2, at the arc lengths (m) packed in
    ``arc_length_bytes``; shared and read-only. Every step of a recording is packed under
    its own gravity with the same rod, and these cost more than the rest of the nominal
    problem."""
    arc_length_m = np.frombuffer(arc_length_bytes)
    bending = np.asarray(rod.youngs_modulus_pa(arc_length_m), dtype=float) * rod.second_moment_m4
    torsion = np.asarray(rod.shear_modulus_pa(arc_length_m), dtype=float) * rod.polar_moment_m4
    bending.flags.writeable = False
    torsion.flags.writeable = False
    return bending, torsion


# slots: an effect assigning a misspelt attribute (problem.jet_gain = ...) gets an
# AttributeError instead of silently changing nothing.
@dataclass(slots=True)
class RodProblem:
    """Mutable description of one static solve. Arrays indexed by sample point have
    ``len(arc_length_m)`` rows; the model chooses the sample points."""

    params: ModelParameters
    jet_forces_n: np.ndarray
    arc_length_m: np.ndarray
    # Constitutive law, at each sample point.
    bending_stiffness_x_nm2: np.ndarray
    bending_stiffness_y_nm2: np.ndarray
    torsional_stiffness_nm2: np.ndarray
    intrinsic_curvature_in_body_1_m: np.ndarray
    # m_b = K (u - u0 + beta |u_b - u0_b|^2 (u_b - u0_b)) on the bending components (m^2).
    cubic_stiffening_m2: float = 0.0
    # Section strain v = e3 + C n_body at each sample point: C's diagonal (shear x, shear y,
    # extension), 1/N, i.e. 1 / (kappa G A) and 1 / (E A); zeros (the default) keep the
    # rod inextensible and unshearable.
    strain_compliance_in_body_1_n: np.ndarray = field(default=None)  # type: ignore[assignment]
    # Distributed loads, at each sample point.
    distributed_force_in_base_n_m: np.ndarray = field(default=None)  # type: ignore[assignment]
    distributed_moment_in_body_nm_m: np.ndarray = field(default=None)  # type: ignore[assignment]
    # Actuation map: tip-frame force = A(jet_ring_angle_rad) @ (jet_gains * jet_forces_n).
    jet_gains: np.ndarray = field(default_factory=lambda: np.ones(3))
    jet_ring_angle_rad: float = 0.0
    # Tip loads besides the jets.
    tip_follower_force_in_tip_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tip_follower_moment_in_tip_nm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tip_dead_force_in_base_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tip_dead_moment_in_base_nm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # Sum of outer(offset_in_tip, force_in_base) over dead forces applied off the tip
    # point: their moment about the tip is eps_abc (R_tip T)_bc, for any number of them.
    tip_dead_force_arm_m_n: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    # Base clamp: rotation = play(compliance * base moment); zero compliance is rigid.
    base_compliance_rad_per_nm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    base_play_rad: float = 0.0
    # Where the clamp stopped at the previous solve (rad): the path state the solver
    # carries. Effects must not read it: a model reuses its packing along a path and
    # only swaps this in (`ShootingModel.prepare`).
    previous_base_rotation_vector_rad: np.ndarray = field(default_factory=lambda: np.zeros(3))
    # Measurement: sensor orientation = body orientation @ mounting rotation.
    base_sensor_mounting: np.ndarray = field(default_factory=lambda: _IDENTITY.copy())
    tip_sensor_mounting: np.ndarray = field(default_factory=lambda: _IDENTITY.copy())
    # The base sensor's origin in the clamp frame (m): the point a base_sensor_mounting
    # turns the sensor about, so the clamp origin read from the sensor moves with it.
    base_sensor_offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        samples = len(self.arc_length_m)
        if self.distributed_force_in_base_n_m is None:
            self.distributed_force_in_base_n_m = np.zeros((samples, 3))
        if self.distributed_moment_in_body_nm_m is None:
            self.distributed_moment_in_body_nm_m = np.zeros((samples, 3))
        if self.strain_compliance_in_body_1_n is None:
            self.strain_compliance_in_body_1_n = np.zeros((samples, 3))

    @classmethod
    def nominal(cls, params: ModelParameters, jet_forces_n: np.ndarray,
                arc_length_m: np.ndarray) -> "RodProblem":
        """The paper's model with no effect applied: linear E, isotropic section, jets and
        w_d at the tip, rigid clamp, sensors aligned with the body frames."""
        bending, torsion = _section_stiffness(params.rod, np.asarray(arc_length_m, dtype=float).tobytes())
        samples = len(arc_length_m)
        return cls(
            params=params,
            jet_forces_n=np.asarray(jet_forces_n, dtype=float),
            arc_length_m=arc_length_m,
            # Copies: an effect may edit them in place.
            bending_stiffness_x_nm2=bending.copy(),
            bending_stiffness_y_nm2=bending.copy(),
            torsional_stiffness_nm2=torsion.copy(),
            intrinsic_curvature_in_body_1_m=np.zeros((samples, 3)),
            jet_ring_angle_rad=params.jets.ring_angle_rad,
            tip_follower_force_in_tip_n=np.array(params.disturbance.force_n, dtype=float),
            tip_follower_moment_in_tip_nm=np.array(params.disturbance.moment_nm, dtype=float),
        )

    def add_tip_dead_force(self, force_in_base_n: np.ndarray, point_in_tip_m: np.ndarray) -> None:
        """A force of fixed direction (e.g. a weight) applied at a point fixed in the tip
        frame (e.g. the capsule's centre of mass)."""
        force = np.asarray(force_in_base_n, dtype=float)
        self.tip_dead_force_in_base_n = self.tip_dead_force_in_base_n + force
        # The outer product (np.outer's own operation, without its checks: every packing
        # under a weight makes one).
        point = np.asarray(point_in_tip_m, dtype=float).ravel()
        self.tip_dead_force_arm_m_n = self.tip_dead_force_arm_m_n + point[:, np.newaxis] * force[np.newaxis, :]

    def actuation_matrix(self) -> np.ndarray:
        """Effective 3x3 map from commanded jet forces (N) to the tip-frame follower force."""
        return actuation_matrix(float(self.jet_ring_angle_rad)) * self.jet_gains[None, :]

    @property
    def depends_on_previous_state(self) -> bool:
        return self.base_play_rad > 0.0 and bool(np.any(self.base_compliance_rad_per_nm > 0.0))
