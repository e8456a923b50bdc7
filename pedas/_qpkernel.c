/* The per-step work of the MPCs around the QP solver's own calls, compiled: what numpy did in ~25-30 calls of
 * ~0.5-1 us each is one loop nest per stage here.
 *
 * Stepper (pedas/mpc.py, SparseMpc.set_step): this step's q, l, u of eq. (9) / (10) written in place.
 *   set(v0, v_lo, v_hi, grade, v_ref, d_its0, d_hard_lo, d_s_its, ft_prev, d_rel0, v_p, v_lin, ft_lin,
 *       safe_margin)
 *
 * Kernel (pedas/qp.py, DaqpCondensedBackend):
 *   fill(q, l, u)        finiteness of the data; f = Z'q + Z'PE b_eq and DAQP's bounds l - K b_eq, u - K b_eq
 *                        (simple bounds first, then general rows), clipped to +-bound. False (nothing written)
 *                        when q, l or u is not finite.
 *   check(z, lam, x)     x = E b_eq + Z z (into x), the largest violation of l <= A x <= u, and the KKT measures
 *                        (stationarity, duality gap) of DAQP's (z, lam) on its QP in z. Returns the 3 floats.
 *   open_daqp(...)       DAQP set up on this QP, its C functions called directly (pedas/_daqp_abi.h)
 *   solve(cold, x)       DAQP's update and solve on what fill wrote, then check for an optimal exit.
 *
 * Horizon (pedas/controller.py, PedasController): the prediction stage (predict), the reference stage's vectors
 *   (reference) and the green wave's look-ups (line_min, v_min), with numpy's interp and elementwise operations.
 *
 * The numbers that reach a drive (q, l, u, f, the bounds, x) are computed as scipy's CSR product kernel and numpy's
 * elementwise operations compute them (the same operations in the same order; cos and sin are the C library's,
 * which numpy's float64 cos and sin call): each row summed from +0.0 in the order of its stored entries, then one
 * addition; no FMA contraction (built with -ffp-contract=off), no reassociation. So they are the same bits as the
 * numpy formulation (tests/pedas/test_qp_kernel.py compares them with it on random data). The check values decide a
 * verdict only (pedas.qp: tolerances with margins of many orders of magnitude). No BLAS anywhere. cos and sin are
 * the C library's on both sides, so they agree on any machine where numpy calls the C library for float64 cos and
 * sin (numpy 2 on x86-64 without AVX-512 SVML; the Makefile and pedas disable AVX-512 paths for numpy).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <dlfcn.h>
#include <time.h>

#include "_daqp_abi.h"

typedef struct {      /* a CSR matrix, copied in at construction */
    Py_ssize_t rows, cols;
    int64_t *indptr, *indices;
    double *data;
} Csr;

/* ---- Kernel: DaqpCondensedBackend's fill and check ------------------------------------------------------------- */

typedef struct {
    PyObject_HEAD
    Py_ssize_t nx, m, neq, nf, nb;   /* QP variables and rows; equality rows; DAQP variables and constraints */
    double bound;
    int64_t *eq_rows, *gather;       /* b_eq = l[eq_rows]; DAQP bound i = src[gather[i]] */
    Csr vec, map, A, H, G;           /* [Z' | Z'PE; K], [E | Z], the QP's A, DAQP's H, DAQP's general rows */
    double *in, *vec_out, *map_out, *src, *ax, *r;   /* work vectors */
    Py_buffer f, lohi;               /* DAQP's f and [lower | upper] bounds: numpy arrays DAQP reads */
    int have_f, have_lohi;
    int tried, ready;                /* __init__ ran once; it succeeded (fill and check need it) */
    /* DAQP called directly (open_daqp): its functions in the loaded daqp module, the workspace, the problem it
     * points to (H, A and sense owned here; f and the bounds are the buffers above), the solution buffers */
    void *dl;
    void (*daqp_solve)(DAQPResult *, DAQPWorkspace *);
    int (*daqp_update_ldp)(int, DAQPWorkspace *, DAQPProblem *);
    void (*free_daqp_workspace)(DAQPWorkspace *);
    void (*free_daqp_ldp)(DAQPWorkspace *);
    DAQPWorkspace *work;
    DAQPProblem qp;
    double *qp_H, *qp_A, *z, *lam;
    int *sense;
    int daqp_ready;                  /* open_daqp succeeded (solve needs it) */
    double solver_seconds;           /* wall time of the last solve's DAQP calls (update + solve) */
} Kernel;

/* no keyword arguments, one __init__ */
static int init_once(int *tried, PyObject *kw, const char *what) {
    if (kw != NULL && PyDict_GET_SIZE(kw) > 0) {
        PyErr_Format(PyExc_TypeError, "%s() takes no keyword arguments", what);
        return -1;
    }
    if (*tried) {
        PyErr_Format(PyExc_RuntimeError, "a %s is set up once", what);
        return -1;
    }
    *tried = 1;
    return 0;
}

static int require_ready(int ready, const char *what) {
    if (!ready)
        PyErr_Format(PyExc_RuntimeError, "the %s is not set up", what);
    return ready ? 0 : -1;
}

/* a METH_FASTCALL method's entry: `want` arguments (else TypeError with the usage line), then require_ready */
static int method_entry(Py_ssize_t nargs, Py_ssize_t want, const char *usage, int ready, const char *what) {
    if (nargs != want) {
        PyErr_SetString(PyExc_TypeError, usage);
        return -1;
    }
    return require_ready(ready, what);
}

static void csr_free(Csr *c) {
    free(c->indptr);
    free(c->indices);
    free(c->data);
}

/* y = C x, each row from +0.0 in stored order (scipy's csr_matvec on a zero-filled y) */
static void csr_product(const Csr *c, const double *x, double *y) {
    for (Py_ssize_t i = 0; i < c->rows; i++) {
        double sum = 0.0;
        for (int64_t k = c->indptr[i]; k < c->indptr[i + 1]; k++)
            sum += c->data[k] * x[c->indices[k]];
        y[i] = sum;
    }
}

/* a held C-contiguous view is n items of the given struct format ('d' or 'q'/'l' for int64), or an error (the view
 * released) */
static int check_view(Py_buffer *view, const char *fmt, Py_ssize_t n, const char *name) {
    const char *f = view->format ? view->format : "B";
    if (*f == '<' || *f == '=' || *f == '@') f++;
    int ok;
    if (fmt[0] == 'd')
        ok = strcmp(f, "d") == 0 && view->itemsize == 8;
    else
        ok = (strcmp(f, "q") == 0 || strcmp(f, "l") == 0) && view->itemsize == 8;
    if (!ok || (n >= 0 && view->len / view->itemsize != n)) {
        const char *type = fmt[0] == 'd' ? "float64" : "int64";
        if (n >= 0)
            PyErr_Format(PyExc_ValueError, "%s: expected %zd contiguous %s values", name, n, type);
        else
            PyErr_Format(PyExc_ValueError, "%s: expected contiguous %s values", name, type);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* a C-contiguous buffer of n items of the given struct format (check_view), or an error */
static int get_buffer(PyObject *obj, Py_buffer *view, const char *fmt, Py_ssize_t n, const char *name, int writable) {
    if (PyObject_GetBuffer(obj, view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0)) < 0)
        return -1;
    return check_view(view, fmt, n, name);
}

/* a copy of a 1-d array (n items, or any length if n < 0; the length into *len) */
static void *copy_array(PyObject *obj, const char *fmt, Py_ssize_t n, const char *name, Py_ssize_t *len) {
    Py_buffer view;
    if (get_buffer(obj, &view, fmt, n, name, 0) < 0)
        return NULL;
    size_t bytes = view.len > 0 ? (size_t)view.len : 1;
    void *out = malloc(bytes);
    if (out == NULL) {
        PyBuffer_Release(&view);
        PyErr_NoMemory();
        return NULL;
    }
    memcpy(out, view.buf, (size_t)view.len);
    if (len) *len = view.len / view.itemsize;
    PyBuffer_Release(&view);
    return out;
}

/* a CSR matrix from the tuple (indptr, indices, data, rows, cols), checked: indices in range, indptr monotone */
static int csr_from(PyObject *t, Csr *c, const char *name) {
    PyObject *ip, *ix, *dt;
    Py_ssize_t rows, cols, nnz, nd, nip;
    if (!PyTuple_Check(t)) {
        PyErr_Format(PyExc_TypeError, "%s: a tuple (indptr, indices, data, rows, cols)", name);
        return -1;
    }
    if (!PyArg_ParseTuple(t, "OOOnn", &ip, &ix, &dt, &rows, &cols))
        return -1;
    if (rows < 0 || cols < 0) {
        PyErr_Format(PyExc_ValueError, "%s: negative shape", name);
        return -1;
    }
    c->rows = rows;
    c->cols = cols;
    if (!(c->indptr = copy_array(ip, "q", rows + 1, name, &nip))) return -1;
    if (!(c->indices = copy_array(ix, "q", -1, name, &nnz))) return -1;
    if (!(c->data = copy_array(dt, "d", nnz, name, &nd))) return -1;
    if (c->indptr[0] != 0 || c->indptr[rows] != nnz) goto bad;
    for (Py_ssize_t i = 0; i < rows; i++)
        if (c->indptr[i + 1] < c->indptr[i]) goto bad;
    for (Py_ssize_t k = 0; k < nnz; k++)
        if (c->indices[k] < 0 || c->indices[k] >= cols) goto bad;
    return 0;
bad:
    PyErr_Format(PyExc_ValueError, "%s: not a valid CSR matrix", name);
    return -1;
}

static void Kernel_dealloc(Kernel *self) {
    csr_free(&self->vec);
    csr_free(&self->map);
    csr_free(&self->A);
    csr_free(&self->H);
    csr_free(&self->G);
    free(self->eq_rows);
    free(self->gather);
    free(self->in);
    free(self->vec_out);
    free(self->map_out);
    free(self->src);
    free(self->ax);
    free(self->r);
    if (self->work != NULL) {   /* as daqp.Model's __dealloc__ */
        self->free_daqp_workspace(self->work);
        self->free_daqp_ldp(self->work);
        free(self->work);
    }
    free(self->qp_H);
    free(self->qp_A);
    free(self->z);
    free(self->lam);
    free(self->sense);
    if (self->dl != NULL) dlclose(self->dl);
    if (self->have_f) PyBuffer_Release(&self->f);
    if (self->have_lohi) PyBuffer_Release(&self->lohi);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Kernel(nx, m, bound, eq_rows, gather, vec, map, A, H, G, f, lohi): vec, map, A, H, G as CSR tuples
 * (indptr, indices, data, rows, cols); f and lohi the arrays fill writes (DAQP reads them) */
static int Kernel_init(Kernel *self, PyObject *args, PyObject *kw) {
    PyObject *eq, *ga, *vec, *map, *A, *H, *G, *f, *lohi;
    Py_ssize_t nx, m, ng;
    double bound;
    if (init_once(&self->tried, kw, "Kernel") < 0)
        return -1;
    if (!PyArg_ParseTuple(args, "nndOOOOOOOOO", &nx, &m, &bound, &eq, &ga, &vec, &map, &A, &H, &G, &f, &lohi))
        return -1;
    if (nx < 0 || m < 0) {
        PyErr_SetString(PyExc_ValueError, "negative QP size");
        return -1;
    }
    self->nx = nx;
    self->m = m;
    self->bound = bound;
    if (!(self->eq_rows = copy_array(eq, "q", -1, "eq_rows", &self->neq))) return -1;
    if (!(self->gather = copy_array(ga, "q", -1, "gather", &self->nb))) return -1;
    if (self->nb % 2) {
        PyErr_SetString(PyExc_ValueError, "gather: one index per lower and upper bound");
        return -1;
    }
    self->nb /= 2;
    if (csr_from(vec, &self->vec, "vec") < 0 || csr_from(map, &self->map, "map") < 0 || csr_from(A, &self->A, "A") < 0
        || csr_from(H, &self->H, "H") < 0 || csr_from(G, &self->G, "G") < 0)
        return -1;
    self->nf = self->H.rows;
    ng = self->G.rows;
    Py_ssize_t nf = self->nf, neq = self->neq, nb = self->nb;
    if (self->vec.rows != 2 * nf + nb || self->vec.cols != nx + neq || self->map.rows != 2 * nx
        || self->map.cols != neq + nf || self->A.rows != m || self->A.cols != nx || self->H.cols != nf
        || self->G.cols != nf || nb != nf + ng) {
        PyErr_SetString(PyExc_ValueError, "the kernel's matrices do not fit together");
        return -1;
    }
    for (Py_ssize_t i = 0; i < neq; i++)
        if (self->eq_rows[i] < 0 || self->eq_rows[i] >= m) goto bad_index;
    for (Py_ssize_t i = 0; i < 2 * nb; i++)
        if (self->gather[i] < 0 || self->gather[i] >= 2 * (m + 1)) goto bad_index;
    self->in = malloc(sizeof(double) * (size_t)(nx + neq + nf));
    self->vec_out = malloc(sizeof(double) * (size_t)(2 * nf + nb));
    self->map_out = malloc(sizeof(double) * (size_t)(2 * nx));
    self->src = malloc(sizeof(double) * (size_t)(2 * (m + 1)));
    self->ax = malloc(sizeof(double) * (size_t)(m > 0 ? m : 1));
    self->r = malloc(sizeof(double) * (size_t)(nf > 0 ? nf : 1));
    if (!self->in || !self->vec_out || !self->map_out || !self->src || !self->ax || !self->r) {
        PyErr_NoMemory();
        return -1;
    }
    memset(self->in, 0, sizeof(double) * (size_t)(nx + neq + nf));
    self->src[m] = -INFINITY;
    self->src[2 * m + 1] = INFINITY;
    if (get_buffer(f, &self->f, "d", nf, "f", 1) < 0) return -1;
    self->have_f = 1;
    if (get_buffer(lohi, &self->lohi, "d", 2 * nb, "lohi", 1) < 0) return -1;
    self->have_lohi = 1;
    self->ready = 1;
    return 0;
bad_index:
    PyErr_SetString(PyExc_ValueError, "an index of eq_rows or gather is out of range");
    return -1;
}

/* the sum of squares of a vector: NaN or inf iff an entry is not finite (entries <= 1e30: no overflow) */
static double sumsq(const double *v, Py_ssize_t n) {
    double s = 0.0;
    for (Py_ssize_t i = 0; i < n; i++)
        s += v[i] * v[i];
    return s;
}

static PyObject *Kernel_fill(Kernel *self, PyObject *const *args, Py_ssize_t nargs) {
    if (method_entry(nargs, 3, "fill(q, l, u)", self->ready, "kernel") < 0)
        return NULL;
    Py_buffer q, l, u;
    const Py_ssize_t nx = self->nx, m = self->m, neq = self->neq, nf = self->nf, nb = self->nb;
    if (get_buffer(args[0], &q, "d", nx, "q", 0) < 0) return NULL;
    if (get_buffer(args[1], &l, "d", m, "l", 0) < 0) { PyBuffer_Release(&q); return NULL; }
    if (get_buffer(args[2], &u, "d", m, "u", 0) < 0) { PyBuffer_Release(&q); PyBuffer_Release(&l); return NULL; }
    const double *qv = q.buf, *lv = l.buf, *uv = u.buf;
    /* the data check first: refused data leave everything as it was */
    if (!(sumsq(qv, nx) + sumsq(lv, m) + sumsq(uv, m) < INFINITY)) {
        PyBuffer_Release(&q); PyBuffer_Release(&l); PyBuffer_Release(&u);
        Py_RETURN_FALSE;
    }
    double *in = self->in, *vo = self->vec_out, *src = self->src;
    memcpy(in, qv, sizeof(double) * (size_t)nx);                 /* [q | b_eq | ...] */
    for (Py_ssize_t i = 0; i < neq; i++)
        in[nx + i] = lv[self->eq_rows[i]];
    csr_product(&self->vec, in, vo);                              /* [Z'q | Z'PE b_eq | K b_eq] */
    double *f = self->f.buf, *lohi = self->lohi.buf;
    for (Py_ssize_t i = 0; i < nf; i++)
        f[i] = vo[i] + vo[nf + i];
    memcpy(src, lv, sizeof(double) * (size_t)m);                  /* [l | -inf | u | +inf] */
    memcpy(src + m + 1, uv, sizeof(double) * (size_t)m);
    const double *kb = vo + 2 * nf, lo = -self->bound, hi = self->bound;
    for (Py_ssize_t i = 0; i < 2 * nb; i++) {
        double b = src[self->gather[i]] - kb[i < nb ? i : i - nb];
        /* numpy's clip: max with the lower, then min with the upper bound, a NaN kept */
        if (!isnan(b)) {
            b = b > lo ? b : lo;
            b = b < hi ? b : hi;
        }
        lohi[i] = b;
    }
    PyBuffer_Release(&q); PyBuffer_Release(&l); PyBuffer_Release(&u);
    Py_RETURN_TRUE;
}

/* the largest of max(l - Ax) and max(Ax - u); NaN if any is NaN */
static double violation(Kernel *self, const double *x) {
    const Py_ssize_t m = self->m;
    const double *l = self->src, *u = self->src + m + 1;
    double *ax = self->ax, worst = -INFINITY;
    int nan = 0;
    csr_product(&self->A, x, ax);
    for (Py_ssize_t i = 0; i < m; i++) {
        double a = l[i] - ax[i], b = ax[i] - u[i];
        nan |= isnan(a) | isnan(b);
        if (a > worst) worst = a;
        if (b > worst) worst = b;
    }
    return nan ? NAN : worst;
}

/* x = E b_eq + Z z (into x), its violation of l <= A x <= u and, with lam, the KKT measures of DAQP's (z, lam) on
 * its QP in z (stationarity, duality gap; NaN without lam) */
static void check_into(Kernel *self, const double *z, const double *lam, double *x, double out[3]) {
    const Py_ssize_t nx = self->nx, neq = self->neq, nf = self->nf, nb = self->nb;
    double *in = self->in, *mo = self->map_out;
    /* x = E b_eq + Z z: the product over [b_eq | z], then one addition */
    memcpy(in + nx + neq, z, sizeof(double) * (size_t)nf);
    csr_product(&self->map, in + nx, mo);
    for (Py_ssize_t i = 0; i < nx; i++)
        x[i] = mo[i] + mo[nx + i];
    out[0] = violation(self, x);
    out[1] = out[2] = NAN;
    if (lam == NULL)
        return;
    const double *f = self->f.buf, *lo = self->lohi.buf, *hi = lo + nb;
    double *r = self->r, zhz = 0.0, fz = 0.0, lamb = 0.0, rmax = 0.0, fmax = 1.0;
    int nan = 0;
    /* r = Hz (zhz = z'Hz along), then + G'lam_general + f + lam_simple */
    for (Py_ssize_t i = 0; i < nf; i++) {
        double s = 0.0;
        for (int64_t k = self->H.indptr[i]; k < self->H.indptr[i + 1]; k++)
            s += self->H.data[k] * z[self->H.indices[k]];
        r[i] = s;
        zhz += z[i] * s;
        fz += f[i] * z[i];
    }
    for (Py_ssize_t g = 0; g < self->G.rows; g++) {
        double lg = lam[nf + g];
        for (int64_t k = self->G.indptr[g]; k < self->G.indptr[g + 1]; k++)
            r[self->G.indices[k]] += self->G.data[k] * lg;
    }
    for (Py_ssize_t i = 0; i < nf; i++) {
        double a = fabs(r[i] + f[i] + lam[i]);
        nan |= isnan(a);
        if (a > rmax) rmax = a;
        if (fabs(f[i]) > fmax) fmax = fabs(f[i]);
    }
    /* each multiplier times the bound it pushes against: lam > 0 the upper, else the lower */
    for (Py_ssize_t i = 0; i < nb; i++)
        lamb += lam[i] * (lam[i] > 0.0 ? hi[i] : lo[i]);
    out[1] = nan ? NAN : rmax / fmax;
    double obj = fabs(0.5 * zhz + fz);
    out[2] = fabs(zhz + fz + lamb) / (obj > 1.0 ? obj : 1.0);
}

static PyObject *Kernel_check(Kernel *self, PyObject *const *args, Py_ssize_t nargs) {
    if (method_entry(nargs, 3, "check(z, lam, x)", self->ready, "kernel") < 0)
        return NULL;
    Py_buffer zb, lb, xb;
    int have_lam = args[1] != Py_None;
    if (get_buffer(args[0], &zb, "d", self->nf, "z", 0) < 0) return NULL;
    if (have_lam && get_buffer(args[1], &lb, "d", self->nb, "lam", 0) < 0) { PyBuffer_Release(&zb); return NULL; }
    if (get_buffer(args[2], &xb, "d", self->nx, "x", 1) < 0) {
        PyBuffer_Release(&zb);
        if (have_lam) PyBuffer_Release(&lb);
        return NULL;
    }
    double out[3];
    check_into(self, zb.buf, have_lam ? lb.buf : NULL, xb.buf, out);
    if (have_lam) PyBuffer_Release(&lb);
    PyBuffer_Release(&zb);
    PyBuffer_Release(&xb);
    return Py_BuildValue("(ddd)", out[0], out[1], out[2]);
}

/* open_daqp(path, H, A, sense, primal_tol, iter_limit): DAQP set up on this kernel's QP as daqp.Model.setup does
 * it (DAQP's default settings, then primal_tol, iter_limit and eps_prox = 0 written as the Model's settings setter
 * writes them), calling the functions of the daqp module loaded from path. H (nf x nf) and A (the general rows,
 * (nb - nf) x nf) C-ordered float64, sense nb int64; f and the bounds are the arrays fill writes. */
static PyObject *Kernel_open_daqp(Kernel *self, PyObject *args) {
    const char *path;
    PyObject *Hobj, *Aobj, *sobj;
    double primal_tol;
    int iter_limit;
    if (!PyArg_ParseTuple(args, "sOOOdi", &path, &Hobj, &Aobj, &sobj, &primal_tol, &iter_limit))
        return NULL;
    if (require_ready(self->ready, "kernel") < 0)
        return NULL;
    if (self->work != NULL || self->dl != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "DAQP is set up once");
        return NULL;
    }
    const Py_ssize_t nf = self->nf, nb = self->nb;
    Py_ssize_t ns;
    int64_t *sense = NULL;
    if (!(self->qp_H = copy_array(Hobj, "d", nf * nf, "H", NULL))) return NULL;
    if (!(self->qp_A = copy_array(Aobj, "d", (nb - nf) * nf, "A", NULL))) return NULL;
    if (!(sense = copy_array(sobj, "q", nb, "sense", &ns))) return NULL;
    self->sense = malloc(sizeof(int) * (size_t)(nb > 0 ? nb : 1));
    self->z = calloc((size_t)(nf > 0 ? nf : 1), sizeof(double));     /* daqp.Model's zero-filled x and lam */
    self->lam = calloc((size_t)(nb > 0 ? nb : 1), sizeof(double));
    if (!self->sense || !self->z || !self->lam) {
        free(sense);
        return PyErr_NoMemory();
    }
    for (Py_ssize_t i = 0; i < nb; i++)
        self->sense[i] = (int)sense[i];
    free(sense);
    /* the module Python loaded (RTLD_NOLOAD: never a second copy) */
    self->dl = dlopen(path, RTLD_NOW | RTLD_NOLOAD);
    if (self->dl == NULL) {
        PyErr_Format(PyExc_ImportError, "the daqp module %s is not loaded", path);
        return NULL;
    }
    void (*allocate_daqp_settings)(DAQPWorkspace *) = (void (*)(DAQPWorkspace *))dlsym(self->dl,
                                                                                       "allocate_daqp_settings");
    int (*setup_daqp_main)(DAQPProblem *, DAQPWorkspace *, double *, int) =
        (int (*)(DAQPProblem *, DAQPWorkspace *, double *, int))dlsym(self->dl, "setup_daqp_main");
    self->daqp_solve = (void (*)(DAQPResult *, DAQPWorkspace *))dlsym(self->dl, "daqp_solve");
    self->daqp_update_ldp = (int (*)(int, DAQPWorkspace *, DAQPProblem *))dlsym(self->dl, "daqp_update_ldp");
    self->free_daqp_workspace = (void (*)(DAQPWorkspace *))dlsym(self->dl, "free_daqp_workspace");
    self->free_daqp_ldp = (void (*)(DAQPWorkspace *))dlsym(self->dl, "free_daqp_ldp");
    if (!allocate_daqp_settings || !setup_daqp_main || !self->daqp_solve || !self->daqp_update_ldp
        || !self->free_daqp_workspace || !self->free_daqp_ldp) {
        PyErr_Format(PyExc_ImportError, "the daqp module %s does not export DAQP's C functions", path);
        return NULL;
    }
    self->qp = (DAQPProblem){(int)nf, (int)nb, (int)nf, self->qp_H, self->f.buf, self->qp_A,
                             (double *)self->lohi.buf + nb, self->lohi.buf, self->sense, NULL, 0, 0};
    DAQPWorkspace *work = calloc(1, sizeof(DAQPWorkspace));
    if (work == NULL)
        return PyErr_NoMemory();
    allocate_daqp_settings(work);
    double setup_time = 0.0;
    int flag = setup_daqp_main(&self->qp, work, &setup_time, 0);
    if (flag < 0) {   /* setup freed the workspace's arrays, not the settings it did not allocate */
        free(work->settings);
        free(work);
        PyErr_Format(PyExc_ValueError, "DAQP's setup failed (exit %d)", flag);
        return NULL;
    }
    self->work = work;   /* freed by DAQP's own functions in any case */
    /* the layout check: the sizes and DAQP's defaults must be where this layout has them */
    DAQPSettings *s = work->settings;
    if (work->n != nf || work->m != nb || work->ms != nf || work->qp != &self->qp || s == NULL
        || s->primal_tol != DAQP_DEFAULT_PRIM_TOL || s->iter_limit != DAQP_DEFAULT_ITER_LIMIT
        || s->eps_prox != DAQP_DEFAULT_EPS_PROX) {
        PyErr_SetString(PyExc_RuntimeError, "DAQP's workspace does not have the layout this kernel was built for");
        return NULL;
    }
    s->primal_tol = primal_tol;
    s->iter_limit = iter_limit;
    s->eps_prox = 0.0;
    self->daqp_ready = 1;
    Py_RETURN_NONE;
}

static double seconds(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* solve(cold, x) -> (flag, iterations, solve_time, violation, stationarity, gap): DAQP's update (f and the bounds
 * fill wrote; the constraint senses too when cold, which clears the working set) and solve, as daqp.Model's update
 * and solve call them; for an optimal exit (1, 2: pedas.qp._DAQP_STATUS) x and the check as check() computes them,
 * else x untouched and NaN measures. The update's own flag is not used, as by the Model before: a failed update
 * shows in the solve's exit flag. */
static PyObject *Kernel_solve(Kernel *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "solve(cold, x)");
        return NULL;
    }
    if (!self->daqp_ready) {
        PyErr_SetString(PyExc_RuntimeError, "DAQP is not set up (open_daqp)");
        return NULL;
    }
    int cold = PyObject_IsTrue(args[0]);
    if (cold < 0)
        return NULL;
    Py_buffer xb;
    if (get_buffer(args[1], &xb, "d", self->nx, "x", 1) < 0)
        return NULL;
    DAQPResult res = {self->z, self->lam, 0.0, 0.0, 0, 0, 0, 0.0, 0.0};
    double t0 = seconds();
    self->daqp_update_ldp(DAQP_UPDATE_v | DAQP_UPDATE_d | (cold ? DAQP_UPDATE_sense : 0), self->work, &self->qp);
    self->daqp_solve(&res, self->work);
    self->solver_seconds = seconds() - t0;
    double out[3] = {NAN, NAN, NAN};
    if (res.exitflag == 1 || res.exitflag == 2)
        check_into(self, self->z, self->lam, xb.buf, out);
    PyBuffer_Release(&xb);
    return Py_BuildValue("(iidddd)", res.exitflag, res.iter, res.solve_time, out[0], out[1], out[2]);
}

static PyMethodDef Kernel_methods[] = {
    {"fill", (PyCFunction)(void (*)(void))Kernel_fill, METH_FASTCALL,
     "fill(q, l, u) -> bool: the data check, then f and DAQP's bounds (False: q, l or u not finite, nothing written)"},
    {"check", (PyCFunction)(void (*)(void))Kernel_check, METH_FASTCALL,
     "check(z, lam, x) -> (violation, stationarity, gap): x = E b_eq + Z z written into x; lam None: NaN measures"},
    {"open_daqp", (PyCFunction)Kernel_open_daqp, METH_VARARGS,
     "open_daqp(path, H, A, sense, primal_tol, iter_limit): DAQP set up on this QP, its functions called directly"},
    {"solve", (PyCFunction)(void (*)(void))Kernel_solve, METH_FASTCALL,
     "solve(cold, x) -> (flag, iterations, solve_time, violation, stationarity, gap): DAQP's update and solve on "
     "the vectors fill wrote, then the check of an optimal solution (x written)"},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Kernel_members[] = {
    {"solver_seconds", T_DOUBLE, offsetof(Kernel, solver_seconds), READONLY,
     "wall time (s) of the last solve's DAQP calls, update + solve"},
    {NULL, 0, 0, 0, NULL},
};

static PyTypeObject KernelType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "pedas._qpkernel.Kernel",
    .tp_basicsize = sizeof(Kernel),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "the condensed DAQP backend's per-step data and checks (pedas.qp.DaqpCondensedBackend)",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Kernel_init,
    .tp_dealloc = (destructor)Kernel_dealloc,
    .tp_methods = Kernel_methods,
    .tp_members = Kernel_members,
};

/* ---- Stepper: SparseMpc.set_step ------------------------------------------------------------------------------ */

typedef struct {
    PyObject_HEAD
    Py_ssize_t n;
    /* positions in q, l, u (-1: absent) */
    Py_ssize_t i_v0, i_d0, dyn_v, v_lim, j_up, j_dn, d_hard, d_soft, i_r0, dyn_r, safe, q_v0, q_ft, iv_n;
    int follow, convex, lin_v2, lin_f2, track_v;
    double c_r, c_grade, c_const, big, dft, kn, lu, dt, d_min, pa10, pa01, pa11, two_pa20, two_pa02, two_z1, two_zv;
    Py_buffer buf[6];   /* q, l, u, and the MPC's kept linearisation point v_lin, fb_lin and v_ref */
    int held;           /* how many of buf are held */
    int tried, ready;
} Stepper;

enum { SQ, SL, SU, SVLIN, SFBLIN, SVREF };

static void Stepper_dealloc(Stepper *self) {
    for (int i = 0; i < self->held; i++)
        PyBuffer_Release(&self->buf[i]);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Stepper(q, l, u, v_lin, fb_lin, v_ref, positions, flags, constants): positions a tuple of 14 ints (i_v0, i_d0,
 * dyn_v, v_lim, j_up, j_dn, d_hard, d_soft, i_r0, dyn_r, safe, q_v0, q_ft, iv_n; -1 where absent), flags
 * (follow, convex, lin_v2, lin_f2, track_v), constants a tuple of 16 floats (c_r, c_grade, c_const, big, dFt,
 * kn, lu, dt, d_min, pa10, pa01, pa11, 2 pa20, 2 pa02, 2 zeta1, 2 zeta_v) */
static int Stepper_init(Stepper *self, PyObject *args, PyObject *kw) {
    PyObject *vec[6], *pos, *flags, *cst;
    if (init_once(&self->tried, kw, "Stepper") < 0)
        return -1;
    if (!PyArg_ParseTuple(args, "OOOOOOO!O!O!", &vec[0], &vec[1], &vec[2], &vec[3], &vec[4], &vec[5],
                          &PyTuple_Type, &pos, &PyTuple_Type, &flags, &PyTuple_Type, &cst))
        return -1;
    Py_ssize_t *p[] = {&self->i_v0, &self->i_d0, &self->dyn_v, &self->v_lim, &self->j_up, &self->j_dn,
                       &self->d_hard, &self->d_soft, &self->i_r0, &self->dyn_r, &self->safe, &self->q_v0,
                       &self->q_ft, &self->iv_n};
    if (!PyArg_ParseTuple(pos, "nnnnnnnnnnnnnn", p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], p[9], p[10],
                          p[11], p[12], p[13]))
        return -1;
    if (!PyArg_ParseTuple(flags, "ppppp", &self->follow, &self->convex, &self->lin_v2, &self->lin_f2,
                          &self->track_v))
        return -1;
    if (!PyArg_ParseTuple(cst, "dddddddddddddddd", &self->c_r, &self->c_grade, &self->c_const, &self->big,
                          &self->dft, &self->kn, &self->lu, &self->dt, &self->d_min, &self->pa10, &self->pa01,
                          &self->pa11, &self->two_pa20, &self->two_pa02, &self->two_z1, &self->two_zv))
        return -1;
    static const char *names[] = {"q", "l", "u", "v_lin", "fb_lin", "v_ref"};
    for (int i = 0; i < 6; i++) {
        /* u as long as l; fb_lin and v_ref as long as v_lin (which sets N) */
        Py_ssize_t n = i == SU ? self->buf[SL].len / 8 : (i > SVLIN ? self->buf[SVLIN].len / 8 : -1);
        if (get_buffer(vec[i], &self->buf[i], "d", n, names[i], 1) < 0)
            return -1;
        self->held = i + 1;
    }
    const Py_ssize_t n = self->n = self->buf[SVLIN].len / 8, nq = self->buf[SQ].len / 8, m = self->buf[SL].len / 8;
    /* every block inside its vector */
    Py_ssize_t rows[][2] = {{self->i_v0, 1}, {self->i_d0, 1}, {self->dyn_v, n}, {self->v_lim, n}, {self->j_up, 1},
                            {self->j_dn, 1}, {self->d_hard, n}, {self->d_soft, n}};
    for (size_t i = 0; i < sizeof(rows) / sizeof(rows[0]); i++)
        if (rows[i][0] < 0 || rows[i][0] + rows[i][1] > m) goto bad;
    if (self->follow && (self->i_r0 < 0 || self->i_r0 >= m || self->dyn_r < 0 || self->dyn_r + n > m
                         || self->safe < 0 || self->safe + n > m))
        goto bad;
    if (self->q_v0 < 0 || self->q_v0 + n + 1 > nq || self->q_ft < 0 || self->q_ft + n > nq
        || self->iv_n != self->q_v0 + n)
        goto bad;
    self->ready = 1;
    return 0;
bad:
    PyErr_SetString(PyExc_ValueError, "a block of the stepper lies outside q, l or u");
    return -1;
}

/* a number as a double (None and non-numbers: TypeError) */
static int as_double(PyObject *obj, const char *name, double *out) {
    if (obj == Py_None) {
        PyErr_Format(PyExc_TypeError, "%s: a number, not None", name);
        return -1;
    }
    *out = PyFloat_AsDouble(obj);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

/* an optional argument: NULL for None, else its buffer of n float64 */
static int opt_buffer(PyObject *obj, Py_buffer *view, Py_ssize_t n, const char *name, const double **out) {
    if (obj == Py_None) {
        *out = NULL;
        return 0;
    }
    if (get_buffer(obj, view, "d", n, name, 0) < 0)
        return -1;
    *out = view->buf;
    return 1;
}

/* numpy's maximum / minimum of two float64: a NaN propagates, and of two equal values (0.0 and -0.0) the second */
static inline double np_max(double a, double b) { return (isnan(a) || a > b) ? a : b; }
static inline double np_min(double a, double b) { return (isnan(a) || a < b) ? a : b; }

static PyObject *Stepper_set(Stepper *self, PyObject *const *args, Py_ssize_t nargs) {
    if (method_entry(nargs, 14, "set(v0, v_lo, v_hi, grade, v_ref, d_its0, d_hard_lo, d_s_its, ft_prev, d_rel0, v_p, "
                                "v_lin, ft_lin, safe_margin)", self->ready, "stepper") < 0)
        return NULL;
    const Py_ssize_t n = self->n;
    double v0, d_its0, d_s_its, d_rel0, v_p, ft_prev = 0.0, margin = 0.0;
    if (as_double(args[0], "v0", &v0) < 0 || as_double(args[5], "d_its0", &d_its0) < 0
        || as_double(args[7], "d_s_its", &d_s_its) < 0 || as_double(args[9], "d_rel0", &d_rel0) < 0
        || as_double(args[10], "v_p", &v_p) < 0 || (args[8] != Py_None && as_double(args[8], "ft_prev", &ft_prev) < 0))
        return NULL;
    /* safe_margin: a number, or N values (an array of one dimension: its view is acquired once and kept) */
    Py_buffer b[8];
    const double *v_lo, *v_hi, *grade, *v_ref, *d_hard, *v_lin, *ft_lin, *mg = NULL;
    int held[8] = {0};
    PyObject *res = NULL;
    if (!PyFloat_Check(args[13]) && !PyLong_Check(args[13]) && PyObject_CheckBuffer(args[13])) {
        if (PyObject_GetBuffer(args[13], &b[7], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
            return NULL;
        if (b[7].ndim == 0) {   /* a 0-d array is a number */
            PyBuffer_Release(&b[7]);
        } else {
            if (check_view(&b[7], "d", n, "safe_margin") < 0)
                return NULL;
            held[7] = 1;
            mg = b[7].buf;
        }
    }
    if (mg == NULL && as_double(args[13], "safe_margin", &margin) < 0)
        return NULL;
    if ((held[0] = opt_buffer(args[1], &b[0], n, "v_lo", &v_lo)) < 0) goto done;
    if ((held[1] = opt_buffer(args[2], &b[1], n, "v_hi", &v_hi)) < 0) goto done;
    if ((held[2] = opt_buffer(args[3], &b[2], n, "grade", &grade)) < 0) goto done;
    if ((held[3] = opt_buffer(args[4], &b[3], n, "v_ref", &v_ref)) < 0) goto done;
    if ((held[4] = opt_buffer(args[6], &b[4], n, "d_hard_lo", &d_hard)) < 0) goto done;
    if ((held[5] = opt_buffer(args[11], &b[5], n, "v_lin", &v_lin)) < 0) goto done;
    if ((held[6] = opt_buffer(args[12], &b[6], n, "ft_lin", &ft_lin)) < 0) goto done;
    if (!v_lo || !v_hi || !grade || (!self->follow && !v_ref)) {
        PyErr_SetString(PyExc_TypeError, "v_lo, v_hi, grade (and v_ref without a leader) are arrays");
        goto done;
    }
    double *q = self->buf[SQ].buf, *l = self->buf[SL].buf, *u = self->buf[SU].buf, big = self->big;
    l[self->i_v0] = u[self->i_v0] = v0;
    l[self->i_d0] = u[self->i_d0] = d_its0 / self->lu;
    /* eq. (3a) right-hand side: c = c_const - c_grade (c_r cos(theta) + sin(theta)) */
    for (Py_ssize_t k = 0; k < n; k++) {
        double w = cos(grade[k]) * self->c_r;
        w = (w + sin(grade[k])) * self->c_grade;
        l[self->dyn_v + k] = u[self->dyn_v + k] = self->c_const - w;
        l[self->v_lim + k] = np_max(v_lo[k], -big);
        u[self->v_lim + k] = np_min(v_hi[k], big);
        l[self->d_hard + k] = d_hard ? np_max(d_hard[k], -big) : -big;
    }
    if (args[8] == Py_None) {
        u[self->j_up] = big;
        l[self->j_dn] = -big;
    } else {
        u[self->j_up] = self->dft + ft_prev / self->kn;
        l[self->j_dn] = -self->dft + ft_prev / self->kn;
    }
    double dsoft = d_s_its / self->lu;
    dsoft = big < dsoft ? big : dsoft;   /* Python's min(d_s_its / LU, BIG) */
    for (Py_ssize_t k = 0; k < n; k++)
        u[self->d_soft + k] = dsoft;
    if (self->follow) {
        l[self->i_r0] = u[self->i_r0] = d_rel0 / self->lu;
        double r = self->dt * v_p / self->lu;
        for (Py_ssize_t k = 0; k < n; k++) {
            l[self->dyn_r + k] = u[self->dyn_r + k] = r;
            l[self->safe + k] = ((mg ? mg[k] : margin) + self->d_min) / self->lu;
        }
    }
    /* the linear cost: power (eq. 5) on k = 0..N-1, tracking on v_1..v_N */
    double *qv0 = q + self->q_v0, *qft = q + self->q_ft, *vb = self->buf[SVLIN].buf, *fb = self->buf[SFBLIN].buf;
    if (self->convex) {
        for (Py_ssize_t k = 0; k < n; k++) {
            qv0[k] = self->pa10;
            qft[k] = self->pa01;
        }
    } else {
        for (Py_ssize_t k = 0; k < n; k++) {
            vb[k] = v_lin ? v_lin[k] : v0;
            fb[k] = ft_lin ? ft_lin[k] / self->kn : 0.0;
            /* a11 v F ~ a11 (vbar F + Fbar v - vbar Fbar): first-order Taylor at the previous trajectory */
            qv0[k] = fb[k] * self->pa11 + self->pa10;
            qft[k] = vb[k] * self->pa11 + self->pa01;
            if (self->lin_v2) qv0[k] = qv0[k] + vb[k] * self->two_pa20;
            if (self->lin_f2) qft[k] = qft[k] + fb[k] * self->two_pa02;
        }
    }
    q[self->iv_n] = 0.0;
    double *qv1 = qv0 + 1, *vr = self->buf[SVREF].buf;
    if (!self->follow) {
        for (Py_ssize_t k = 0; k < n; k++) {
            qv1[k] = qv1[k] - v_ref[k] * self->two_z1;   /* zeta1 (v_{k+1} - v_ref,k)^2, eq. (9a) */
            vr[k] = v_ref[k];
        }
    } else if (self->track_v) {
        double t = self->two_zv * v_p;                   /* zeta_v (v_{k+1} - v_p)^2 */
        for (Py_ssize_t k = 0; k < n; k++)
            qv1[k] = qv1[k] - t;
    }
    res = Py_None;
    Py_INCREF(res);
done:
    for (int i = 0; i < 8; i++)
        if (held[i] > 0) PyBuffer_Release(&b[i]);
    return res;
}

static PyMethodDef Stepper_methods[] = {
    {"set", (PyCFunction)(void (*)(void))Stepper_set, METH_FASTCALL,
     "set(v0, v_lo, v_hi, grade, v_ref, d_its0, d_hard_lo, d_s_its, ft_prev, d_rel0, v_p, v_lin, ft_lin, "
     "safe_margin): this step's q, l, u in place (pedas.mpc.SparseMpc.set_step)"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject StepperType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "pedas._qpkernel.Stepper",
    .tp_basicsize = sizeof(Stepper),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "an MPC's per-step q, l, u (pedas.mpc.SparseMpc.set_step)",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Stepper_init,
    .tp_dealloc = (destructor)Stepper_dealloc,
    .tp_methods = Stepper_methods,
};

/* ---- Horizon: PedasController._predict ------------------------------------------------------------------------ */

/* numpy's binary_search_with_guess (numpy/_core/src/multiarray/compiled_base.c): the index j with
 * arr[j] <= key < arr[j + 1], -1 below arr[0], len above arr[len - 1], len - 1 at it; the same guesses, so the same
 * j on any sorted table, repeated values included */
#define LIKELY_IN_CACHE_SIZE 8
static Py_ssize_t search_with_guess(double key, const double *arr, Py_ssize_t len, Py_ssize_t guess) {
    Py_ssize_t imin = 0, imax = len;
    if (key > arr[len - 1])
        return len;
    else if (key < arr[0])
        return -1;
    if (len <= 4) {
        Py_ssize_t i;
        for (i = 1; i < len && key >= arr[i]; ++i)
            ;
        return i - 1;
    }
    if (guess > len - 3) guess = len - 3;
    if (guess < 1) guess = 1;
    if (key < arr[guess]) {
        if (key < arr[guess - 1]) {
            imax = guess - 1;
            if (guess > LIKELY_IN_CACHE_SIZE && key >= arr[guess - LIKELY_IN_CACHE_SIZE])
                imin = guess - LIKELY_IN_CACHE_SIZE;
        } else {
            return guess - 1;
        }
    } else {
        if (key < arr[guess + 1]) {
            return guess;
        } else {
            if (key < arr[guess + 2]) {
                return guess + 1;
            } else {
                imin = guess + 2;
                if (guess < len - LIKELY_IN_CACHE_SIZE - 1 && key < arr[guess + LIKELY_IN_CACHE_SIZE])
                    imax = guess + LIKELY_IN_CACHE_SIZE;
            }
        }
    }
    while (imin < imax) {
        const Py_ssize_t imid = imin + ((imax - imin) >> 1);
        if (key >= arr[imid])
            imin = imid + 1;
        else
            imax = imid;
    }
    return imin - 1;
}

/* numpy's interp(x, xp, fp) with the default left and right (fp[0], fp[-1]), value by value as numpy computes it */
static void np_interp(const double *x, Py_ssize_t n, const double *dx, const double *dy, Py_ssize_t len, double *res) {
    const double lval = dy[0], rval = dy[len - 1];
    if (len == 1) {
        for (Py_ssize_t i = 0; i < n; i++)
            res[i] = (x[i] < dx[0]) ? lval : ((x[i] > dx[0]) ? rval : dy[0]);
        return;
    }
    Py_ssize_t j = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        const double xv = x[i];
        if (isnan(xv)) {
            res[i] = xv;
            continue;
        }
        j = search_with_guess(xv, dx, len, j);
        if (j == -1) {
            res[i] = lval;
        } else if (j == len) {
            res[i] = rval;
        } else if (j == len - 1) {
            res[i] = dy[j];
        } else if (dx[j] == xv) {
            res[i] = dy[j];
        } else {
            const double slope = (dy[j + 1] - dy[j]) / (dx[j + 1] - dx[j]);
            res[i] = slope * (xv - dx[j]) + dy[j];
            if (isnan(res[i])) {
                res[i] = slope * (xv - dx[j + 1]) + dy[j + 1];
                if (isnan(res[i]) && dy[j] == dy[j + 1])
                    res[i] = dy[j];
            }
        }
    }
}

/* interp(x, xp, fp, out): numpy's interp(x, xp, fp) written into out (the tests compare the two) */
static PyObject *interp(PyObject *mod, PyObject *const *args, Py_ssize_t nargs) {
    (void)mod;
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "interp(x, xp, fp, out)");
        return NULL;
    }
    Py_buffer b[4];
    PyObject *res = NULL;
    int held = 0;
    if (get_buffer(args[0], &b[0], "d", -1, "x", 0) < 0) return NULL;
    held = 1;
    if (get_buffer(args[1], &b[1], "d", -1, "xp", 0) < 0) goto done;
    held = 2;
    Py_ssize_t len = b[1].len / 8, n = b[0].len / 8;
    if (len < 1) {
        PyErr_SetString(PyExc_ValueError, "xp: at least one point");
        goto done;
    }
    if (get_buffer(args[2], &b[2], "d", len, "fp", 0) < 0) goto done;
    held = 3;
    if (get_buffer(args[3], &b[3], "d", n, "out", 1) < 0) goto done;
    held = 4;
    np_interp(b[0].buf, n, b[1].buf, b[2].buf, len, b[3].buf);
    res = Py_None;
    Py_INCREF(res);
done:
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&b[i]);
    return res;
}

enum { HS, HGRADE, HVMAX, HVENV, HVMIN, HLIMIT, HDPS, HDPV, NTABLE };
enum { OVLIN, OFTLIN, OSPRED, OSGRADE, OGRADE, OVMAX, OVDP, OVENV, OVREF, OVLO, OVHI, OREACH, OWORK, OVHICF, OMARGIN,
       NOUT };
enum { MODE_GREEN_WAVE, MODE_DP, MODE_STOP };

typedef struct {
    PyObject_HEAD
    Py_ssize_t n;                   /* N, the horizon */
    double dt, two_a_stop, cruise_look, safe_backoff;
    double *table[NTABLE];          /* the route grid s and its profiles; the DP reference's s and v */
    Py_ssize_t len, dp_len;
    double *depart, *reach, *recover;  /* the horizon's ramps a_depart dt k, a_reach dt k, psi_recovery k; k = 1..N */
    Py_buffer out[NOUT];            /* the controller's work vectors, written in place */
    int held;
    int tried, ready;
} Horizon;

static void Horizon_dealloc(Horizon *self) {
    for (int i = 0; i < NTABLE; i++)
        free(self->table[i]);
    free(self->depart);
    free(self->reach);
    free(self->recover);
    for (int i = 0; i < self->held; i++)
        PyBuffer_Release(&self->out[i]);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Horizon(tables, dt, ramps, constants, outputs): tables a tuple of the route grid s and its profiles grade, v_max,
 * v_env, v_min, limit and the DP reference's s and v (copied); ramps (a_depart dt k, a_reach dt k, psi_recovery k)
 * for k = 1..N (copied); constants (2 a_stop, cruise_look, safe_backoff); outputs a tuple of the N-vectors the stages
 * write: v_lin, ft_lin, s_pred, s_grade, grade, v_max, v_DP, v_env (predict), v_ref, v_lo, v_hi, reach, a work
 * vector (reference), the car-following v_hi and safe margin (follow) */
static int Horizon_init(Horizon *self, PyObject *args, PyObject *kw) {
    PyObject *tables, *ramps, *outs;
    if (init_once(&self->tried, kw, "Horizon") < 0)
        return -1;
    if (!PyArg_ParseTuple(args, "O!dO!(ddd)O!", &PyTuple_Type, &tables, &self->dt, &PyTuple_Type, &ramps,
                          &self->two_a_stop, &self->cruise_look, &self->safe_backoff, &PyTuple_Type, &outs))
        return -1;
    if (PyTuple_GET_SIZE(tables) != NTABLE || PyTuple_GET_SIZE(ramps) != 3 || PyTuple_GET_SIZE(outs) != NOUT) {
        PyErr_SetString(PyExc_TypeError, "Horizon: 8 tables, 3 ramps and 15 outputs");
        return -1;
    }
    static const char *tnames[] = {"s", "grade", "v_max", "v_env", "v_min", "limit", "dp_s", "dp_v"};
    for (int i = 0; i < NTABLE; i++) {
        Py_ssize_t want = i == HS || i == HDPS ? -1 : (i == HDPV ? self->dp_len : self->len);
        Py_ssize_t got;
        if (!(self->table[i] = copy_array(PyTuple_GET_ITEM(tables, i), "d", want, tnames[i], &got)))
            return -1;
        if (i == HS) self->len = got;
        if (i == HDPS) self->dp_len = got;
    }
    if (self->len < 1 || self->dp_len < 1) {
        PyErr_SetString(PyExc_ValueError, "the route grid and the DP reference need at least one point");
        return -1;
    }
    static const char *onames[] = {"v_lin", "ft_lin", "s_pred", "s_grade", "grade", "v_max", "v_dp", "v_env",
                                   "v_ref", "v_lo", "v_hi", "reach", "work", "v_hi_cf", "margin"};
    for (int i = 0; i < NOUT; i++) {
        if (get_buffer(PyTuple_GET_ITEM(outs, i), &self->out[i], "d", i ? self->out[0].len / 8 : -1, onames[i], 1)
            < 0)
            return -1;
        self->held = i + 1;
    }
    self->n = self->out[0].len / 8;
    if (self->n < 1) {
        PyErr_SetString(PyExc_ValueError, "v_lin: a horizon of at least one step");
        return -1;
    }
    if (!(self->depart = copy_array(PyTuple_GET_ITEM(ramps, 0), "d", self->n, "depart", NULL))) return -1;
    if (!(self->reach = copy_array(PyTuple_GET_ITEM(ramps, 1), "d", self->n, "reach", NULL))) return -1;
    if (!(self->recover = copy_array(PyTuple_GET_ITEM(ramps, 2), "d", self->n, "recover", NULL))) return -1;
    self->ready = 1;
    return 0;
}

#define OUT(i) ((double *)self->out[i].buf)

/* predict(s, v, prev_v, prev_ft) -> limit: PedasController._predict. v_lin = (v, prev_v[2:]) and ft_lin =
 * (prev_ft[1:], prev_ft[-1]) (v and 0 without a previous plan: prev_v and prev_ft None); s_pred = s + dt cumsum(
 * max(v_lin, 0)) at k = 1..N; s_grade = (s, s_pred[:-1]); grade, v_max, v_DP, v_env interpolated there as numpy's
 * interp does; returns the speed limit interpolated at s. The same operations in numpy's order (a cumulative sum
 * is sequential in numpy as well). */
static PyObject *Horizon_predict(Horizon *self, PyObject *const *args, Py_ssize_t nargs) {
    if (method_entry(nargs, 4, "predict(s, v, prev_v, prev_ft)", self->ready, "horizon") < 0)
        return NULL;
    const Py_ssize_t n = self->n;
    double s, v;
    if (as_double(args[0], "s", &s) < 0 || as_double(args[1], "v", &v) < 0)
        return NULL;
    double *vl = OUT(OVLIN), *fl = OUT(OFTLIN), *sp = OUT(OSPRED), *sg = OUT(OSGRADE);
    if ((args[2] == Py_None) != (args[3] == Py_None)) {
        PyErr_SetString(PyExc_TypeError, "prev_v and prev_ft: both arrays or both None");
        return NULL;
    }
    if (args[2] == Py_None) {
        for (Py_ssize_t k = 0; k < n; k++) {
            vl[k] = v;
            fl[k] = 0.0;
        }
    } else {
        Py_buffer pv, pf;
        if (get_buffer(args[2], &pv, "d", n + 1, "prev_v", 0) < 0) return NULL;
        if (get_buffer(args[3], &pf, "d", n, "prev_ft", 0) < 0) { PyBuffer_Release(&pv); return NULL; }
        const double *a = pv.buf, *b = pf.buf;
        vl[0] = v;
        memcpy(vl + 1, a + 2, sizeof(double) * (size_t)(n - 1));
        memcpy(fl, b + 1, sizeof(double) * (size_t)(n - 1));
        fl[n - 1] = b[n - 1];
        PyBuffer_Release(&pv);
        PyBuffer_Release(&pf);
    }
    double acc = 0.0;
    for (Py_ssize_t k = 0; k < n; k++) {
        double w = np_max(vl[k], 0.0);
        acc = k ? acc + w : w;   /* np.add.accumulate */
        sp[k] = acc * self->dt + s;
    }
    sg[0] = s;
    memcpy(sg + 1, sp, sizeof(double) * (size_t)(n - 1));
    double *const *tb = self->table;
    np_interp(sg, n, tb[HS], tb[HGRADE], self->len, OUT(OGRADE));
    np_interp(sp, n, tb[HS], tb[HVMAX], self->len, OUT(OVMAX));
    np_interp(sp, n, tb[HDPS], tb[HDPV], self->dp_len, OUT(OVDP));
    np_interp(sp, n, tb[HS], tb[HVENV], self->len, OUT(OVENV));
    double limit;
    np_interp(&s, 1, tb[HS], tb[HLIMIT], self->len, &limit);
    return PyFloat_FromDouble(limit);
}

/* bisect.bisect_left on the DP positions: the first index with dp_s[i] >= x */
static Py_ssize_t bisect_left(const double *a, Py_ssize_t len, double x) {
    Py_ssize_t lo = 0, hi = len;
    while (lo < hi) {
        Py_ssize_t mid = (lo + hi) / 2;
        if (a[mid] < x)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* reference(s, v, v_gw, target, stop_expected, free) -> (mode, max v_hi): PedasController._reference's vectors
 * after predict, in place. v_ref = min(v_env, v_gw) with a green-wave band (mode 0), else v_DP floored by its
 * look-ahead maximum reached with the departure ramp, capped by the curve envelope (mode 1); with a stop target
 * (m: the stop line less stop_aim d_s,ITS; None: no stop envelope) capped by sqrt(2 a_stop max(target - (s_pred - s),
 * 0)), mode 2 (stop) when that envelope binds at k = N or `stop_expected`; reach = v - a_reach dt k; v_hi =
 * max(v_max, reach); v_lo = min(v_min at s_pred, v) in modes 0 and 1 when `free` (no leader), else 0, then
 * min(v_lo, v_hi). numpy's elementwise operations in numpy's order. */
static PyObject *Horizon_reference(Horizon *self, PyObject *const *args, Py_ssize_t nargs) {
    if (method_entry(nargs, 6, "reference(s, v, v_gw, target, stop_expected, free)", self->ready, "horizon") < 0)
        return NULL;
    const Py_ssize_t n = self->n;
    double s, v, v_gw = 0.0, target = 0.0;
    int have_gw = args[2] != Py_None, have_target = args[3] != Py_None;
    if (as_double(args[0], "s", &s) < 0 || as_double(args[1], "v", &v) < 0
        || (have_gw && as_double(args[2], "v_gw", &v_gw) < 0)
        || (have_target && as_double(args[3], "target", &target) < 0))
        return NULL;
    int stop_expected = PyObject_IsTrue(args[4]), free_road = PyObject_IsTrue(args[5]);
    if (stop_expected < 0 || free_road < 0)
        return NULL;
    double *vr = OUT(OVREF), *venv = OUT(OVENV), *vdp = OUT(OVDP), *sp = OUT(OSPRED), *w = OUT(OWORK);
    int mode;
    if (have_gw) {
        for (Py_ssize_t k = 0; k < n; k++)
            vr[k] = np_min(venv[k], v_gw);
        mode = MODE_GREEN_WAVE;
    } else {
        const double *dps = self->table[HDPS], *dpv = self->table[HDPV];
        const Py_ssize_t len = self->dp_len;
        Py_ssize_t j0 = bisect_left(dps, len, s), j1 = bisect_left(dps, len, s + self->cruise_look);
        double cruise;
        if (j0 < len) {   /* the maximum over dp_v[j0:max(j1, j0 + 1)], NaN propagated as numpy's max */
            Py_ssize_t end = j1 > j0 + 1 ? j1 : j0 + 1;
            cruise = dpv[j0];
            for (Py_ssize_t i = j0 + 1; i < end; i++)
                cruise = np_max(cruise, dpv[i]);
        } else {
            cruise = dpv[len - 1];
        }
        for (Py_ssize_t k = 0; k < n; k++) {
            double r = np_min(self->depart[k] + v, cruise);
            r = np_max(vdp[k], r);
            vr[k] = np_min(r, venv[k]);
        }
        mode = MODE_DP;
    }
    if (have_target) {
        for (Py_ssize_t k = 0; k < n; k++) {
            double e = target - (sp[k] - s);
            w[k] = sqrt(np_max(e, 0.0) * self->two_a_stop);
        }
        if (w[n - 1] < vr[n - 1] || stop_expected)
            mode = MODE_STOP;
        for (Py_ssize_t k = 0; k < n; k++)
            vr[k] = np_min(vr[k], w[k]);
    }
    double *reach = OUT(OREACH), *vhi = OUT(OVHI), *vlo = OUT(OVLO), *vmax = OUT(OVMAX);
    double hi_max = 0.0;
    for (Py_ssize_t k = 0; k < n; k++) {
        reach[k] = v - self->reach[k];
        vhi[k] = np_max(vmax[k], reach[k]);
        /* numpy's argmax: the first largest, or the first NaN */
        if (k == 0 || (!isnan(hi_max) && (isnan(vhi[k]) || vhi[k] > hi_max)))
            hi_max = vhi[k];
    }
    if (mode != MODE_STOP && free_road) {
        np_interp(sp, n, self->table[HS], self->table[HVMIN], self->len, vlo);
        for (Py_ssize_t k = 0; k < n; k++)
            vlo[k] = np_min(vlo[k], v);
    } else {
        for (Py_ssize_t k = 0; k < n; k++)
            vlo[k] = 0.0;
    }
    for (Py_ssize_t k = 0; k < n; k++)
        vlo[k] = np_min(vlo[k], vhi[k]);
    return Py_BuildValue("(id)", mode, hi_max);
}

/* follow(v, psi): PedasController._solve's car-following bounds after reference, in place. v_hi_cf = min(v_hi,
 * max(max(v_DP, min(v + a_depart dt k, v_max)), reach)); margin = min(safe_backoff, psi_recovery k + psi) (m).
 * numpy's elementwise operations in numpy's order. */
static PyObject *Horizon_follow(Horizon *self, PyObject *const *args, Py_ssize_t nargs) {
    if (method_entry(nargs, 2, "follow(v, psi)", self->ready, "horizon") < 0)
        return NULL;
    double v, psi;
    if (as_double(args[0], "v", &v) < 0 || as_double(args[1], "psi", &psi) < 0)
        return NULL;
    const double *vmax = OUT(OVMAX), *vdp = OUT(OVDP), *reach = OUT(OREACH), *vhi = OUT(OVHI);
    double *cf = OUT(OVHICF), *margin = OUT(OMARGIN);
    for (Py_ssize_t k = 0; k < self->n; k++) {
        double x = np_min(self->depart[k] + v, vmax[k]);
        x = np_max(vdp[k], x);
        x = np_max(x, reach[k]);
        cf[k] = np_min(vhi[k], x);
        margin[k] = np_min(self->safe_backoff, self->recover[k] + psi);
    }
    Py_RETURN_NONE;
}

/* v_min(s) -> the lowest speed at s, interpolated on the route grid (numpy's interp) */
static PyObject *Horizon_v_min(Horizon *self, PyObject *arg) {
    if (require_ready(self->ready, "horizon") < 0)
        return NULL;
    double s, out;
    if (as_double(arg, "s", &s) < 0)
        return NULL;
    np_interp(&s, 1, self->table[HS], self->table[HVMIN], self->len, &out);
    return PyFloat_FromDouble(out);
}

/* line_min(s, d, frac) -> the lowest v_max at s + d frac (frac: the points along the way to a stop line, as a
 * fraction of d): numpy's interp at those points, then the minimum (argmin's first smallest, or the first NaN) */
static PyObject *Horizon_line_min(Horizon *self, PyObject *const *args, Py_ssize_t nargs) {
    if (method_entry(nargs, 3, "line_min(s, d, frac)", self->ready, "horizon") < 0)
        return NULL;
    double s, d;
    if (as_double(args[0], "s", &s) < 0 || as_double(args[1], "d", &d) < 0)
        return NULL;
    Py_buffer fb;
    if (get_buffer(args[2], &fb, "d", -1, "frac", 0) < 0)
        return NULL;
    const Py_ssize_t m = fb.len / 8;
    if (m < 1 || m > 64) {
        PyBuffer_Release(&fb);
        PyErr_SetString(PyExc_ValueError, "frac: 1 to 64 points");
        return NULL;
    }
    double x[64], y[64];
    const double *f = fb.buf;
    for (Py_ssize_t i = 0; i < m; i++)
        x[i] = s + d * f[i];   /* numpy: s + (d * frac) */
    PyBuffer_Release(&fb);
    np_interp(x, m, self->table[HS], self->table[HVMAX], self->len, y);
    double lo = y[0];
    for (Py_ssize_t i = 1; i < m && !isnan(lo); i++)
        if (isnan(y[i]) || y[i] < lo)
            lo = y[i];
    return PyFloat_FromDouble(lo);
}

static PyMethodDef Horizon_methods[] = {
    {"predict", (PyCFunction)(void (*)(void))Horizon_predict, METH_FASTCALL,
     "predict(s, v, prev_v, prev_ft) -> limit: the prediction stage of PedasController.step, its vectors in place"},
    {"reference", (PyCFunction)(void (*)(void))Horizon_reference, METH_FASTCALL,
     "reference(s, v, v_gw, target, stop_expected, free) -> (mode, max v_hi): v_ref and the speed bounds in place"},
    {"follow", (PyCFunction)(void (*)(void))Horizon_follow, METH_FASTCALL,
     "follow(v, psi): the car-following MPC's v_hi and safe margin in place"},
    {"v_min", (PyCFunction)Horizon_v_min, METH_O, "v_min(s) -> the lowest speed at s (numpy's interp)"},
    {"line_min", (PyCFunction)(void (*)(void))Horizon_line_min, METH_FASTCALL,
     "line_min(s, d, frac) -> the lowest v_max at s + d frac (numpy's interp, then the minimum)"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject HorizonType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "pedas._qpkernel.Horizon",
    .tp_basicsize = sizeof(Horizon),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "the controller's prediction stage (pedas.controller.PedasController._predict)",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Horizon_init,
    .tp_dealloc = (destructor)Horizon_dealloc,
    .tp_methods = Horizon_methods,
};

static PyMethodDef module_methods[] = {
    {"interp", (PyCFunction)(void (*)(void))interp, METH_FASTCALL,
     "interp(x, xp, fp, out): numpy's interp(x, xp, fp) into out, as the Horizon computes it"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_qpkernel",
    "Compiled per-step work of the controller: Stepper (pedas.mpc.SparseMpc.set_step), Kernel (the data, DAQP's calls "
    "and the checks of pedas.qp.DaqpCondensedBackend) and Horizon (the prediction and reference stages of "
    "pedas.controller.PedasController).", -1, module_methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__qpkernel(void) {
    PyTypeObject *types[] = {&KernelType, &StepperType, &HorizonType};
    PyObject *mod = PyModule_Create(&module);
    if (mod == NULL)
        return NULL;
    for (size_t i = 0; i < sizeof(types) / sizeof(types[0]); i++) {
        if (PyType_Ready(types[i]) < 0 || PyModule_AddObjectRef(mod, strrchr(types[i]->tp_name, '.') + 1,
                                                                (PyObject *)types[i]) < 0) {
            Py_DECREF(mod);
            return NULL;
        }
    }
    return mod;
}
