"""Total-Lagrangian SPH for elastic solids (formulation eqs. 13-19; O'Connor & Rogers 2021).

Every quantity is evaluated against the reference configuration ``X`` with the reference
neighbours found once (:func:`sphjax.neighbors.reference_neighbors`):

    L0_a = ( -sum_b V0_b grad0_a W(X_ab) X_ab^T )^-1                         (eq. 15)
    F_a  = -sum_b V0_b x_ab (L0_a grad0_a W(X_ab))^T                         (eq. 16)
    E_a  = 1/2 (F_a^T F_a - I)                                               (eq. 17)
    S_a  = lambda tr(E_a) I + 2 mu E_a                                       (eq. 18)
    mu = E / (2 (1 + nu)),  lambda = E nu / ((1 + nu)(1 - 2 nu))             (eq. 19)
    P_a  = F_a S_a
    Dv_a/Dt = sum_b m0_b (P_a L0_a / rho0_a^2 + P_b L0_b / rho0_b^2) grad0_a W(X_ab)
              + f_a^PF / m0_a + g                                            (eq. 14)

with ``X_ab = X_a - X_b`` and ``x_ab = x_a - x_b``.  The minus signs in eqs. 15-16 make
``L0 ~ I`` and ``F = I`` on the undeformed configuration (VALIDATION.md, "Conventions that
bite").  In 2D the Lamé constants of eq. 19 give plane strain.  The optional penalty force
``f^PF`` is Ganzenmüller's (2015) hourglass control (:mod:`sphjax.solid.penalty`).

Modules: :mod:`~sphjax.solid.correction` (eq. 15), :mod:`~sphjax.solid.deformation`
(eq. 16), :mod:`~sphjax.solid.material` (eqs. 17-19 and PK1), :mod:`~sphjax.solid.penalty`,
:mod:`~sphjax.solid.rhs` (eq. 14).  All are pure functions over ``[M, K]`` neighbour
arrays.
"""

from sphjax.solid.correction import corrected_kernel_gradient, correction_matrix
from sphjax.solid.deformation import deformation_gradient
from sphjax.solid.material import (
    green_lagrange_strain,
    lame_constants,
    pk1_stress,
    st_venant_kirchhoff_stress,
)
from sphjax.solid.penalty import penalty_force
from sphjax.solid.rhs import SolidFields, solid_acceleration, solid_fields

__all__ = [
    "SolidFields",
    "corrected_kernel_gradient",
    "correction_matrix",
    "deformation_gradient",
    "green_lagrange_strain",
    "lame_constants",
    "penalty_force",
    "pk1_stress",
    "solid_acceleration",
    "solid_fields",
    "st_venant_kirchhoff_stress",
]
