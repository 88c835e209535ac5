"""Observability of the parameters: scaled Jacobians, singular values, identifiable
subsets, the observability indices O1–O5 and optimal pose selection.

Column scaling
--------------
The identification Jacobian mixes m/m and m/rad columns, so its singular values
depend on units.  :func:`column_scales` offers

* ``"norm"`` — every column scaled to unit norm over the given poses (the usual
  choice for rank decisions; the result is unit-free but depends on the pose set);
* ``"tolerance"`` — every column multiplied by the parameter's expected error, by
  default 0.1 mm for lengths and 0.05° for angles, the deviations seed 003 §3.5
  imposes in its influence analysis.  Scaled columns are then metres of tool error
  per expected parameter error, the same for every pose set, so indices of different
  sets (and sizes) can be compared;
* an explicit ``(p,)`` array of factors.

The scaled Jacobian is ``J_s = J diag(s)``; a parameter step is ``dx = diag(s) dx_s``.

Observability indices (Sun & Hollerbach 2008, "Observability index selection for
robot calibration", ICRA, which compares them), from the singular values σ1 ≥ … ≥ σp
of the scaled ``J`` (``3n x p`` or ``6n x p`` — singular values of ``J`` itself,
not eigenvalues of ``JᵀJ``) for ``n`` poses:

* O1 = (σ1 σ2 … σp)^(1/p) / √n — Borm & Menq 1991 (IJRR 10(1)); maximising it is
  D-optimal design (the determinant of ``JᵀJ``);
* O2 = σp / σ1 — the inverse condition number (Driels & Pathre 1990); we use the
  inverse so that, like the others, larger is better;
* O3 = σp — the minimum singular value (Nahvi, Hollerbach & Hayward 1994);
* O4 = σp² / σ1 — the noise amplification index (Nahvi & Hollerbach 1996);
* O5 = 1 / (1/σ1 + … + 1/σp) — Sun & Hollerbach 2008 (A-optimality).

Pose selection (:func:`select_poses`) maximises one index over subsets of a candidate
pool: a greedy construction (each step adds the candidate that raises the index
most; until ``JᵀJ`` has full rank a tiny ridge keeps the determinant informative),
then exchanges in the spirit of DETMAX (Mitchell 1974): a selected pose is swapped
for the candidate that improves the index most, pass after pass, until no swap
helps.  Each pose adds ``B_iᵀ B_i`` to the information matrix ``M = J_sᵀ J_s``, so
adding and swapping are rank-3 (or rank-6) updates: for O1 the determinant lemma
``det(M + Bᵀ B) = det M · det(I + B M⁻¹ Bᵀ)`` scores every candidate with one small
batched product; for O2–O5 the exact index is computed (batched ``eigvalsh``, whose
square roots are the singular values of the stacked ``J``) for a shortlist of
candidates ranked by that determinant gain.

How far any pose set can get: :func:`design_efficiency_bound` turns one design into
an upper bound on the O1 of every design (Kiefer–Wolfowitz equivalence theorem), so a
selection can be certified near-optimal and impossible targets recognised.
"""

from __future__ import annotations

from robocal.identify.design_bound import DesignBound, design_efficiency_bound
from robocal.identify.observability_indices import (
    ANGLE_TOLERANCE,
    INDICES,
    LENGTH_TOLERANCE,
    IndexName,
    ObservabilityIndices,
    Rows,
    column_scales,
    identifiable_parameters,
    observability,
    observability_indices,
    parameter_tolerances,
    scaled_jacobian,
    singular_values,
)
from robocal.identify.pose_selection import PoseSelection, select_poses
from robocal.model.rank import Dropped, IdentifiableSubset, identifiable_subset

__all__ = [
    "ANGLE_TOLERANCE",
    "INDICES",
    "LENGTH_TOLERANCE",
    "DesignBound",
    "Dropped",
    "IdentifiableSubset",
    "IndexName",
    "ObservabilityIndices",
    "PoseSelection",
    "Rows",
    "column_scales",
    "design_efficiency_bound",
    "identifiable_parameters",
    "identifiable_subset",
    "observability",
    "observability_indices",
    "parameter_tolerances",
    "scaled_jacobian",
    "select_poses",
    "singular_values",
]
