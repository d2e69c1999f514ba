"""The result of a CPD registration: a frozen value with its transform and posterior."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from posedrift._validation import check_points, check_scalar
from posedrift.registration import _estep


class ConvergenceWarning(RuntimeWarning):
    """A registration stopped at ``max_iter`` before meeting its tolerance."""


@dataclass(frozen=True, eq=False)
class CPDResult:
    """A finished Coherent Point Drift registration of ``source`` onto ``target``.

    Attributes
    ----------
    kind : {"rigid", "affine", "nonrigid"}
        The transform family.
    moved : (M, D) float
        The transformed source, in the input's units.
    sigma2 : float
        Final GMM variance sigma^2, in the input's units squared.
    iterations : int
        EM iterations run.
    converged : bool
        Whether the relative change of the objective fell below ``tol``.
    objective : float
        Final value of the negative log-likelihood (plus ``smoothness / 2 tr(W' G W)``
        for nonrigid), in normalized units, without constant terms.
    rotation : (D, D) float or None
        Rigid only: rotation R with ``moved = scale * source @ R.T + translation``.
    scale : float or None
        Rigid only: the isotropic scale s.
    matrix : (D, D) float or None
        Rigid (``s R``) and affine (B): ``moved = source @ matrix.T + translation``.
    translation : (D,) float or None
        Rigid and affine: the translation t, input units.
    """

    kind: str
    moved: np.ndarray
    sigma2: float
    iterations: int
    converged: bool
    objective: float
    rotation: np.ndarray | None = None
    scale: float | None = None
    matrix: np.ndarray | None = None
    translation: np.ndarray | None = None
    # --- private state in normalized units (not part of the public API) ---
    _target_n: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    _source_n: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    _moved_n: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    _coef: np.ndarray | None = field(default=None, repr=False)  # exact nonrigid W (M, D)
    _sigma2_n: float = field(default=1.0, repr=False)
    _outlier_c: float = field(default=0.0, repr=False)
    _centre: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    _unit: float = field(default=1.0, repr=False)
    _kernel_width: float | None = field(default=None, repr=False)
    # low-rank nonrigid: the displacement is G(p, landmarks) @ _landmark_coef
    _landmarks: np.ndarray | None = field(default=None, repr=False)
    _landmark_coef: np.ndarray | None = field(default=None, repr=False)

    def correspondence(self) -> tuple[np.ndarray, np.ndarray]:
        """For each target point, its most probable source point.

        Computed from the final posterior in blocks (never an M x N array).

        Returns
        -------
        indices : (N,) int
            Index into ``source`` of the most probable source point.
        probability : (N,) float
            Its posterior probability ``P[m, n]`` (in [0, 1]; the rest of the mass goes
            to other source points and to the outlier component).
        """
        return _estep.posterior_argmax(
            self._target_n, self._moved_n, self._sigma2_n, self._outlier_c
        )

    def transfer_labels(self, labels, n_labels: int) -> np.ndarray:
        """Posterior mass of each source label, per target point.

        Parameters
        ----------
        labels : (M,) int
            Label of each source point, in ``[0, n_labels)``.
        n_labels : int
            Number of labels (15 body parts for the tracker).

        Returns
        -------
        mass : (N, n_labels) float
            ``mass[n, j] = sum of P[m, n] over source points m with label j``. Rows sum
            to the inlier share of each target point (``1 - P(outlier | x_n)``), not to 1:
            a target point far from every source point has a small row. Normalize the
            rows yourself if you need a distribution. Computed in blocks from the final
            posterior (never an M x N array); where the compiled kernel is built, each
            entry to 1e-12 (source points whose kernel value is below 1e-12 of the
            outlier term are left out, as in the E-step).
        """
        m = self._moved_n.shape[0]
        n_labels = int(
            check_scalar(
                n_labels,
                "n_labels",
                low=1,
                include_low=True,
                integer=True,
                caller="transfer_labels",
            )
        )
        lab = np.asarray(labels)
        if lab.shape != (m,) or not np.issubdtype(lab.dtype, np.integer):
            raise ValueError(
                f"The 'labels' argument of transfer_labels must be an integer array of shape "
                f"({m},). Got {lab.dtype} array of shape {lab.shape} instead."
            )
        if m and (lab.min() < 0 or lab.max() >= n_labels):
            raise ValueError(
                f"The 'labels' argument of transfer_labels must lie in [0, {n_labels}). "
                f"Got values in [{lab.min()}, {lab.max()}] instead."
            )
        return _estep.posterior_label_mass(
            self._target_n,
            self._moved_n,
            self._sigma2_n,
            self._outlier_c,
            lab,
            n_labels,
            truncate_eps=_estep.TRUNCATE_EPS,
        )

    def apply(self, points) -> np.ndarray:
        """Apply the same transform to other points.

        Parameters
        ----------
        points : (K, D) float
            Points in the source's frame and units.

        Returns
        -------
        moved : (K, D) float
            For nonrigid, ``p + G(p, source) W`` with the exact Gaussian kernel (the
            coherent displacement field's continuous extension); ``apply(source)``
            reproduces ``moved``. After a low-rank registration the field is the
            Nyström one, ``G(p, landmarks) A`` (the field the registration fitted), so
            ``apply(source)`` reproduces ``moved`` there too.
        """
        d = self.moved.shape[1]
        pts = check_points(points, "points", dim=d, min_points=0, caller="apply")
        if self.kind in ("rigid", "affine"):
            return pts @ self.matrix.T + self.translation
        from posedrift.registration._cpd import gaussian_kernel

        pn = (pts - self._centre) / self._unit
        out = pn.copy()
        if self._landmarks is not None:
            centres, coef = self._landmarks, self._landmark_coef
        else:
            centres, coef = self._source_n, self._coef
        step = max(1, (1 << 21) // max(1, centres.shape[0]))
        for start in range(0, len(pn), step):
            blk = pn[start : start + step]
            out[start : start + step] += gaussian_kernel(blk, centres, self._kernel_width) @ coef
        return out * self._unit + self._centre
