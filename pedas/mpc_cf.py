"""Car-following MPC, eq. (10): u_k = [F_t, F_b, e1, e2, e3] with a frozen-time leader (constant v_p, Sec. 3.5).

As eq. (9) but the speed-tracking term is replaced by zeta1 e3^2, the comfort-distance slack, and the gap d_rel
is a state (3c) with the hard safe distance d_rel >= d_min + h_s v (7a) and the soft comfort distance
d_rel <= d_min + h_c v + e3 (7b). Speeds are bounded by min(v_max, v_DP) (6c).
"""
from __future__ import annotations

import numpy as np

from pedas.mpc import INF, MpcModel, MpcPlan, SparseMpc
from pedas.params import CONTROLLER, MpcWeights



class CarFollowingMpc(SparseMpc):
    """Eq. (10) as a sparse QP built once (DAQP or OSQP, :mod:`pedas.qp`); :meth:`plan` updates the vectors and
    solves."""

    def __init__(self, model: MpcModel, weights: MpcWeights = CONTROLLER.cf_weights, **kw) -> None:
        super().__init__(model, weights, follow=True, **kw)

    def plan(self, v0: float, d_rel0: float, v_p: float, v_lo: np.ndarray, v_hi: np.ndarray, grade: np.ndarray,
             d_its0: float = 0.0, d_hard_lo: np.ndarray | None = None, d_s_its: float = INF,
             ft_prev: float | None = None, v_lin: np.ndarray | None = None,
             ft_lin: np.ndarray | None = None, safe_margin=CONTROLLER.safe_backoff) -> MpcPlan:
        """Solve one step. d_rel0 m gap to the leader, v_p m/s its (frozen) speed; other arguments as
        :meth:`pedas.mpc_rt.ReferenceTrackingMpc.plan`; safe_margin m: back-off of the safe distance eq. (7a)."""
        self.set_step(v0=v0, v_lo=v_lo, v_hi=v_hi, grade=grade, d_its0=d_its0, d_hard_lo=d_hard_lo,
                      d_s_its=d_s_its, ft_prev=ft_prev, d_rel0=d_rel0, v_p=v_p, v_lin=v_lin, ft_lin=ft_lin,
                      safe_margin=safe_margin)
        return self.solve()
