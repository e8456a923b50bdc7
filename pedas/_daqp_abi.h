/* The part of DAQP's C interface that pedas/_qpkernel.c calls: the structures as DAQP 0.11.0 declares them
 * (csrc/include/types.h and api.h of its source distribution; DAQP is MIT-licensed, (c) 2022 Daniel Arnstrom) and
 * the few constants it uses (csrc/include/constants.h).
 *
 * The functions are not linked: the kernel looks them up in the daqp module Python has loaded (the wheel exports
 * them), so it runs DAQP's own compiled code. The layouts below must be those of that build, so pedas.qp uses this
 * path only for the DAQP versions in pedas.qp.DAQP_DIRECT_VERSIONS, and the kernel checks the workspace after setup
 * (its sizes and DAQP's default settings where this layout puts them) before it trusts it.
 */
#ifndef PEDAS_DAQP_ABI_H
#define PEDAS_DAQP_ABI_H

typedef struct {
    int n;
    int m;
    int ms;
    double *H;
    double *f;
    double *A;
    double *bupper;
    double *blower;
    int *sense;
    int *break_points;
    int nh;
    int problem_type;
} DAQPProblem;

typedef struct {
    double primal_tol;
    double dual_tol;
    double zero_tol;
    double pivot_tol;
    double progress_tol;
    int cycle_tol;
    int iter_limit;
    double fval_bound;
    double eps_prox;
    double eta_prox;
    double rho_soft;
    double rel_subopt;
    double abs_subopt;
    double sing_tol;
    double refactor_tol;
    double time_limit;
    double w_soft;
    int eq_reduction;
    int presolve;
} DAQPSettings;

typedef struct {   /* every pointer the kernel does not read is kept as void * (same size and place) */
    DAQPProblem *qp;
    int n;
    int m;
    int ms;
    double *M, *dupper, *dlower, *Rinv, *v;
    int *sense;
    double *scaling, *RinvD;
    double *x, *xold, *lam, *lam_star, *u;
    double fval;
    double *L, *D, *xldl, *zldl;
    int reuse_ind;
    int *WS;
    int n_active;
    int iterations;
    int sing_ind;
    int *prox_mask;
    int n_prox;
    double soft_slack;
    DAQPSettings *settings;
    void *bnb;
    int outer_iter;
    void *hierarchy, *avi, *eq, *timer;
    double *Mu;
    double *rho_ls, *rho_us, *w_ls, *w_us;
    int state;
} DAQPWorkspace;

typedef struct {
    double *x;
    double *lam;
    double fval;
    double soft_slack;
    int exitflag;
    int iter;
    int nodes;
    double solve_time;
    double setup_time;
} DAQPResult;

#define DAQP_UPDATE_v 4
#define DAQP_UPDATE_d 8
#define DAQP_UPDATE_sense 16
#define DAQP_DEFAULT_PRIM_TOL 1e-6
#define DAQP_DEFAULT_ITER_LIMIT 10000
#define DAQP_DEFAULT_EPS_PROX (-1e-6)

#endif
