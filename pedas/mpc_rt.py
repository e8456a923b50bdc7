"""Reference-tracking MPC, eq. (9): u_k = [F_t, F_b, e1, e2], track v_ref from the green wave or DP (Sec. 3.5).

Constraints: dynamics eq. (3a, 3b), 0 <= F_t <= p3 v + p4 (6a), 0 <= F_b <= F_b,max (6b), v_lo <= v <= v_max
(6c; see docs/controller.md for why v_DP is not an upper bound here), soft jerk limit (8a/b), d_ITS >= 0 while a
stop is required (8c) and the soft stop-line approach d_ITS - e1 <= d_s,ITS (8d).
"""
from __future__ import annotations

import numpy as np

from pedas.mpc import INF, MpcModel, MpcPlan, SparseMpc
from pedas.params import CONTROLLER, MpcWeights


class ReferenceTrackingMpc(SparseMpc):
    """Eq. (9) as a sparse QP built once (DAQP or OSQP, :mod:`pedas.qp`); :meth:`plan` updates the vectors and
    solves."""

    def __init__(self, model: MpcModel, weights: MpcWeights = CONTROLLER.rt_weights, **kw) -> None:
        super().__init__(model, weights, follow=False, **kw)

    def plan(self, v0: float, v_ref: np.ndarray, v_lo: np.ndarray, v_hi: np.ndarray, grade: np.ndarray,
             d_its0: float = 0.0, d_hard_lo: np.ndarray | None = None, d_s_its: float = INF,
             ft_prev: float | None = None, v_lin: np.ndarray | None = None,
             ft_lin: np.ndarray | None = None) -> MpcPlan:
        """Solve one step. v0 m/s; v_ref, v_lo, v_hi (k=1..N) m/s; grade (k=0..N-1) rad; d_its0 m to the stop line;
        d_hard_lo: 0 where d_ITS,k >= 0 holds, -inf elsewhere; d_s_its m (inf = no soft approach); ft_prev N."""
        self.set_step(v0=v0, v_lo=v_lo, v_hi=v_hi, grade=grade, v_ref=v_ref, d_its0=d_its0, d_hard_lo=d_hard_lo,
                      d_s_its=d_s_its, ft_prev=ft_prev, v_lin=v_lin, ft_lin=ft_lin)
        return self.solve()
