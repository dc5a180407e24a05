"""The linear Kalman filter step of the online filters: predict and update, the equations of filterpy's
``KalmanFilter.predict`` / ``KalmanFilter.update`` ([Bar-Shalom2001] §5.2; Joseph-form covariance update, as filterpy
writes it).

Used by the filters that run in the node processes, sample by sample; the offline smoothers keep filterpy's
``batch_filter`` and ``rts_smoother``. Why our own step for the online filters: importing ``filterpy.kalman`` pulls
in ``scipy.stats``, ``scipy.sparse`` and ``scipy.linalg`` (tens of MB per process) for the two equations below.

Shapes: state x (n, 1), covariance P (n, n); F, Q (n, n); measurement z (m, 1), H (m, n), R (m, m)."""
from __future__ import annotations

import numpy as np

__all__ = ["LinearKalman"]


class LinearKalman:
    """State ``x`` (n, 1) and covariance ``P`` (n, n) of a linear Gaussian model; starts at x = 0, P = I.

    dim_x: n; H (m, n) and R (m, m): the measurement model :meth:`update` uses when it is given none (None: it must be
    given one)."""

    def __init__(self, dim_x: int, H: np.ndarray | None = None, R: np.ndarray | None = None) -> None:
        self.x = np.zeros((dim_x, 1))
        self.P = np.eye(dim_x)
        self.H = H
        self.R = R
        self._eye = np.eye(dim_x)

    def predict(self, F: np.ndarray, Q: np.ndarray) -> None:
        """x <- F x, P <- F P F^T + Q (F, Q: (n, n))."""
        self.x = F @ self.x
        self.P = F @ self.P @ F.T + Q

    def update(self, z: np.ndarray, H: np.ndarray | None = None, R: np.ndarray | None = None) -> None:
        """Fuse the measurement ``z`` (m, 1) = H x + noise of covariance R (default: the filter's H and R).

        K = P H^T (H P H^T + R)^-1, x <- x + K (z - H x), P <- (I - K H) P (I - K H)^T + K R K^T (Joseph form: stays
        symmetric positive semi-definite under rounding). Raises ValueError without H or R (neither given nor the
        filter's), numpy.linalg.LinAlgError for a singular innovation covariance."""
        h = self.H if H is None else H
        r = self.R if R is None else R
        if h is None or r is None:
            raise ValueError("LinearKalman.update needs H and R: give them here or to the filter")
        pht = self.P @ h.T
        gain = pht @ _inverse(h @ pht + r)
        self.x = self.x + gain @ (z - h @ self.x)
        i_kh = self._eye - gain @ h
        self.P = i_kh @ self.P @ i_kh.T + gain @ r @ gain.T


def _inverse(s: np.ndarray) -> np.ndarray:
    """The inverse of the innovation covariance ``s`` (m, m). One or two measurements (every online
    filter's) by the adjugate over the determinant, 1.8-3.2 us a call here against 9.5 us for
    ``numpy.linalg.inv``'s dispatch; more by ``numpy.linalg.inv``. Raises
    numpy.linalg.LinAlgError when singular."""
    m = s.shape[0]
    if m == 1:
        det = float(s[0, 0])
        if det == 0.0:
            raise np.linalg.LinAlgError("Singular matrix")
        return np.array([[1.0 / det]])
    if m == 2:
        a, b, c, d = float(s[0, 0]), float(s[0, 1]), float(s[1, 0]), float(s[1, 1])
        det = a * d - b * c
        if det == 0.0:
            raise np.linalg.LinAlgError("Singular matrix")
        return np.array([[d / det, -b / det], [-c / det, a / det]])
    return np.linalg.inv(s)
