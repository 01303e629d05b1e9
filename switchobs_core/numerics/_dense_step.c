/* The exact set's step through a dense map in one call: the loops of
 * switchobs_core.numerics.rounding.ErrorEllipsoid.step_dense (its docstring states the set and its
 * allowances; switchobs_core/numerics/dense_kernel.py calls this and passes every coefficient);
 * the O(n^2) pass of switchobs_core.bounds.read's amortised read between anchors (between()); and the
 * balanced norm of a vector (norm(), RoundingBound.xn); a Kalman sample's estimate through a
 * fused map (correct(), KalmanMap.correct); and the exact set's step through a Kalman sample's factored map
 * (sandwich(): Phi~ S Phi~' with scipy's doubles; factored(): the rest of the step and its assembly;
 * open_plan(): an open-loop prior's plan; block(): a prior's block; kappa(): KalmanMap.kappa's sums).
 *
 * step(M, S, aMd, aux, out, rho, c4) -> (tr, ls, alpha, theta)
 *   M, S, aMd, out: C-ordered n x n doubles (out written, not aliased with the others);
 *   aux: 2 n + 11 doubles, (1 / d^2, d^2, kW, kR, gsum, k1, k3, kf, alo, ahi, kth, k2, eta) of the ellipsoid:
 *   every coefficient of the error analysis (a's clamp [alo, ahi], theta's factor kth, c2's k2 and eta)
 *   comes from Python (ErrorEllipsoid._aux), none is written here;
 *   rho, c4: the step's residual and the diagonal's underflow allowance;
 *   tr: the trace of out rounded up, ls: its balanced trace rounded up (ErrorEllipsoid.lam_scaled);
 *   alpha, theta: the outer sum's factors (the caller's overflow guard reads them).
 *
 * Arithmetic: every product and sum is a rounded double operation in a fixed order (no FMA
 * contraction, no reassociation: build with -O2 -ffp-contract=off), so every x86-64 CPU gives the
 * same doubles: the hot loops are written with GCC's vector extension and compiled twice
 * (target_clones: AVX2 where the CPU has it, SSE2 elsewhere), elementwise in the same order. Each entry of T = M S and of Z = T M' is a dot product of length n summed in index
 * order, within gamma_n |a|.|b| as any order; Z is computed on and above its diagonal and mirrored, so
 * it is exactly symmetric (the allowance for the symmetrisation's rounding stays, unused).
 */
#if defined(__FAST_MATH__) || (defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__)
#error "_dense_step.c needs IEEE arithmetic (no -ffast-math / -ffinite-math-only): setup.py's KERNEL_FLAGS"
#endif
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#define STACK_N 40

static double pymax(double a, double b) { return b > a ? b : a; }  /* Python's max(a, b) */
static double pymin(double a, double b) { return b < a ? b : a; }  /* Python's min(a, b) */

static int doubles(const Py_buffer *b)
{
    const char *f = b->format;
    if (f != NULL && (f[0] == '@' || f[0] == '=' || (!PY_BIG_ENDIAN && f[0] == '<')))
        f++;
    return b->itemsize == 8 && f != NULL && f[0] == 'd' && f[1] == 0;
}

/* o as C-ordered doubles of shape (n,) (ndim 1) or (n, n) (ndim 2) */
static int get(PyObject *o, Py_buffer *b, Py_ssize_t n, int ndim, int flags)
{
    if (PyObject_GetBuffer(o, b, flags | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    if (!doubles(b) || b->ndim != ndim || b->shape[0] != n || (ndim == 2 && b->shape[1] != n)) {
        PyBuffer_Release(b);
        PyErr_SetString(PyExc_ValueError, "_dense_step: an array of the wrong shape or type");
        return -1;
    }
    return 0;
}

/* getlen: a C-ordered buffer of exactly len doubles, whatever its shape (correct's and absrows' arrays,
 * whose sizes the caller states), else ValueError. */
static int getlen(PyObject *o, Py_buffer *b, Py_ssize_t len, int flags)
{
    if (PyObject_GetBuffer(o, b, flags | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    if (!doubles(b) || b->len != len * 8) {
        PyBuffer_Release(b);
        PyErr_SetString(PyExc_ValueError, "_dense_step: an array of the wrong size or type");
        return -1;
    }
    return 0;
}

/* whether the memory of a written buffer o and of another b do not overlap (the loops take them restrict) */
static int apart(const Py_buffer *o, const Py_buffer *b)
{
    const char *o0 = o->buf, *b0 = b->buf;
    return o0 + o->len <= b0 || b0 + b->len <= o0;
}

static int aliased(void)
{
    PyErr_SetString(PyExc_ValueError, "_dense_step: an output shares memory with an input");
    return -1;
}

/* c_k = sum_j a_j B_jk for k0 <= k < n (B n x n, C-ordered), each summed in the order of j: blocks
 * of 8 columns kept in registers as pairs (GCC's vector extension: elementwise, the same order and
 * doubles as the scalar loop) */
typedef double v2 __attribute__((vector_size(16)));
static inline v2 ld(const double *p) { v2 v; __builtin_memcpy(&v, p, sizeof v); return v; }
static inline void st(double *p, v2 v) { __builtin_memcpy(p, &v, sizeof v); }
typedef double v4 __attribute__((vector_size(32)));
static inline v4 ld4(const double *p) { v4 v; __builtin_memcpy(&v, p, sizeof v); return v; }
static inline void st4(double *p, v4 v) { __builtin_memcpy(p, &v, sizeof v); }

static void row_times(Py_ssize_t n, Py_ssize_t k0, const double *restrict a, const double *restrict B,
                      double *restrict c)
{
    Py_ssize_t j, k;
    for (k = k0; k + 8 <= n; k += 8) {
        v2 a0 = {a[0], a[0]};
        v2 c0 = a0 * ld(B + k), c1 = a0 * ld(B + k + 2), c2 = a0 * ld(B + k + 4), c3 = a0 * ld(B + k + 6);
        for (j = 1; j < n; j++) {
            const double *b = B + j * n + k;
            v2 aj = {a[j], a[j]};
            c0 = c0 + aj * ld(b);
            c1 = c1 + aj * ld(b + 2);
            c2 = c2 + aj * ld(b + 4);
            c3 = c3 + aj * ld(b + 6);
        }
        st(c + k, c0);
        st(c + k + 2, c1);
        st(c + k + 4, c2);
        st(c + k + 6, c3);
    }
    for (; k + 2 <= n; k += 2) {
        v2 a0 = {a[0], a[0]};
        v2 c0 = a0 * ld(B + k);
        for (j = 1; j < n; j++) {
            v2 aj = {a[j], a[j]};
            c0 = c0 + aj * ld(B + j * n + k);
        }
        st(c + k, c0);
    }
    for (; k < n; k++) {
        double z = a[0] * B[k];
        for (j = 1; j < n; j++)
            z = z + a[j] * B[j * n + k];
        c[k] = z;
    }
}

/* rows c_r = a_r B (r = 0..3, a_r = A[r n ..]) from column k0 on: blocks of 4 rows by 8 columns kept in
 * registers (eight accumulators: each load of B serves four rows), then 4 columns, then the last 1-3
 * columns row by row */
__attribute__((target_clones("avx2", "default")))
static void rows4_times(Py_ssize_t n, Py_ssize_t k0, const double *restrict A, const double *restrict B,
                        double *restrict C)
{
    const double *a0 = A, *a1 = A + n, *a2 = A + 2 * n, *a3 = A + 3 * n;
    Py_ssize_t j, k, r, w;
/* one row's pair of accumulators: (c0, c1) = a_j (b0, b1), or (c0, c1) += a_j (b0, b1) */
#define FIRST(a, c0, c1) v4 c0 = a[0] * b0, c1 = a[0] * b1
#define ADD(a, c0, c1) c0 = c0 + a[j] * b0, c1 = c1 + a[j] * b1
    for (k = k0; k + 8 <= n; k += 8) {
        v4 b0 = ld4(B + k), b1 = ld4(B + k + 4);
        FIRST(a0, c00, c01);
        FIRST(a1, c10, c11);
        FIRST(a2, c20, c21);
        FIRST(a3, c30, c31);
        for (j = 1; j < n; j++) {
            b0 = ld4(B + j * n + k);
            b1 = ld4(B + j * n + k + 4);
            ADD(a0, c00, c01);
            ADD(a1, c10, c11);
            ADD(a2, c20, c21);
            ADD(a3, c30, c31);
        }
        st4(C + k, c00), st4(C + k + 4, c01), st4(C + n + k, c10), st4(C + n + k + 4, c11);
        st4(C + 2 * n + k, c20), st4(C + 2 * n + k + 4, c21), st4(C + 3 * n + k, c30), st4(C + 3 * n + k + 4, c31);
    }
#undef FIRST
#undef ADD
    for (; k + 4 <= n; k += 4) {
        v4 b0 = ld4(B + k);
        v4 c0 = a0[0] * b0, c1 = a1[0] * b0, c2 = a2[0] * b0, c3 = a3[0] * b0;
        for (j = 1; j < n; j++) {
            b0 = ld4(B + j * n + k);
            c0 = c0 + a0[j] * b0;
            c1 = c1 + a1[j] * b0;
            c2 = c2 + a2[j] * b0;
            c3 = c3 + a3[j] * b0;
        }
        st4(C + k, c0);
        st4(C + n + k, c1);
        st4(C + 2 * n + k, c2);
        st4(C + 3 * n + k, c3);
    }
    for (r = 0; r < 4; r++)         /* the last columns, row by row */
        for (w = k; w < n; w++) {
            const double *a = A + r * n;
            double z = a[0] * B[w];
            for (j = 1; j < n; j++)
                z = z + a[j] * B[j * n + w];
            C[r * n + w] = z;
        }
}

/* the rows of C = A B from row 0 (upper: row i from column i on, or from the first row of its block
 * of four: entries below the diagonal may be written too), four at a time */
static void times(Py_ssize_t n, int upper, const double *restrict A, const double *restrict B, double *restrict C)
{
    Py_ssize_t i;
    for (i = 0; i + 4 <= n; i += 4)
        rows4_times(n, upper ? i : 0, A + i * n, B, C + i * n);
    for (; i < n; i++)
        row_times(n, upper ? i : 0, A + i * n, B, C + i * n);
}

static double kernel(Py_ssize_t n, const double *restrict M, const double *restrict S,
                     const double *restrict aMd,
                     const double *restrict aux, double *restrict out, double *restrict Z,
                     double *restrict Mt, double *restrict s, double rho,
                     double c4, double *lsum, double *fac)
{
    const double *id2 = aux, *d2 = aux + n;
    const double kW = aux[2 * n], kR = aux[2 * n + 1], gsum = aux[2 * n + 2];
    const double k1 = aux[2 * n + 3], k3 = aux[2 * n + 4], kf = aux[2 * n + 5];
    const double alo = aux[2 * n + 6], ahi = aux[2 * n + 7], kth = aux[2 * n + 8], k2 = aux[2 * n + 9];
    const double eta = aux[2 * n + 10];
    Py_ssize_t i, j, k;
    double Wv = 0.0, tzs = 0.0;

    if (!(rho >= 0.0))                  /* NaN (or negative): no residual bound, a set not finite */
        rho = INFINITY;
    for (i = 0; i < n; i++)
        s[i] = sqrt(fabs(S[i * n + i]));
    /* out <- T = M S; Z = T M' on and above the diagonal (M' in Mt), each entry summed in the order
     * of j */
    times(n, 0, M, S, out);
    for (j = 0; j < n; j++)
        for (k = 0; k < n; k++)
            Mt[j * n + k] = M[k * n + j];
    times(n, 1, out, Mt, Z);
    /* w d = (D |M|) s; W and the trace that chooses alpha */
    for (i = 0; i < n; i++) {
        const double *a = aMd + i * n;
        double v = 0.0;
        for (j = 0; j < n; j++)
            v = v + a[j] * s[j];
        out[i] = v;                     /* T is read no more: out's first row holds w d */
        Wv = Wv + v * id2[i];
        tzs = tzs + Z[i * n + i] * id2[i];
    }
    double Wz = Wv * kW;
    double tz = pymax(tzs + kR * Wz * Wv, 0.0) * gsum;
    double alpha = 1.0, theta = 1.0;
    if (tz > 0.0 && rho > 0.0) {
        alpha = 1.0 + pymin(pymax(rho / sqrt(tz), alo), ahi);
        theta = (1.0 + 1.0 / (alpha - 1.0)) * kth;
    }
    fac[0] = alpha;
    fac[1] = theta;
    double c2 = rho > 0.0 ? ((theta * rho) * rho * k2 + eta) * kf : 0.0;
    double c1 = alpha * Wz * k1, c3 = alpha * k3;
    /* q = c1 w d + c2 d^2 + c3 |diag Z| + c4 into s (read no more) */
    for (i = 0; i < n; i++)
        s[i] = c1 * out[i] + c2 * d2[i] + c3 * fabs(Z[i * n + i]) + c4;
    /* S' = alpha Z + diag(q), mirrored; tr its trace rounded up, ls its balanced trace rounded up */
    double tr = 0.0, ls = 0.0;
    for (i = 0; i < n; i++) {
        double *o = out + i * n;
        const double *z = Z + i * n;
        double dii = z[i] * alpha + s[i];
        o[i] = dii;
        tr = tr + dii;
        ls = ls + dii * id2[i];
        for (k = i + 1; k < n; k++)
            o[k] = z[k] * alpha;
    }
    for (i = 1; i < n; i++)
        for (k = 0; k < i; k++)
            out[i * n + k] = out[k * n + i];
    *lsum = pymax(ls, 0.0) * gsum;
    return pymax(tr, 0.0) * gsum;
}

static PyObject *step(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer bM, bS, bA, bX, bO;
    double stack_z[2 * STACK_N * STACK_N + STACK_N];
    double *Z = stack_z, *Mt = Z + STACK_N * STACK_N, *s = Mt + STACK_N * STACK_N, rho, c4, tr, ls, fac[2];
    Py_ssize_t n, nn;

    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "step(M, S, aMd, aux, out, rho, c4)");
        return NULL;
    }
    rho = PyFloat_AsDouble(args[5]);
    if (rho == -1.0 && PyErr_Occurred())    /* before the next conversion runs Python code */
        return NULL;
    c4 = PyFloat_AsDouble(args[6]);
    if (c4 == -1.0 && PyErr_Occurred())
        return NULL;
    if (PyObject_GetBuffer(args[3], &bX, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    n = (bX.len / 8 - 11) / 2;
    if (!doubles(&bX) || bX.ndim != 1 || n < 1 || bX.len != (2 * n + 11) * 8) {
        PyBuffer_Release(&bX);
        PyErr_SetString(PyExc_ValueError, "_dense_step: aux of the wrong size");
        return NULL;
    }
    nn = n * n;
    if (get(args[0], &bM, n, 2, 0) < 0)
        goto fail_x;
    if (get(args[1], &bS, n, 2, 0) < 0)
        goto fail_m;
    if (get(args[2], &bA, n, 2, 0) < 0)
        goto fail_s;
    if (get(args[4], &bO, n, 2, PyBUF_WRITABLE) < 0)
        goto fail_a;
    if (!(apart(&bO, &bM) && apart(&bO, &bS) && apart(&bO, &bA) && apart(&bO, &bX)) && aliased() < 0)
        goto fail_o;
    if (n > STACK_N) {
        Z = PyMem_Malloc((size_t)(2 * nn + n) * sizeof(double));
        if (Z == NULL) {
            PyErr_NoMemory();
            goto fail_o;
        }
        Mt = Z + nn;
        s = Mt + nn;
    }
    tr = kernel(n, bM.buf, bS.buf, bA.buf, bX.buf, bO.buf, Z, Mt, s, rho, c4, &ls, fac);
    if (n > STACK_N)
        PyMem_Free(Z);
    PyBuffer_Release(&bO);
    PyBuffer_Release(&bA);
    PyBuffer_Release(&bS);
    PyBuffer_Release(&bM);
    PyBuffer_Release(&bX);
    return Py_BuildValue("(dddd)", tr, ls, fac[0], fac[1]);
fail_o:
    PyBuffer_Release(&bO);
fail_a:
    PyBuffer_Release(&bA);
fail_s:
    PyBuffer_Release(&bS);
fail_m:
    PyBuffer_Release(&bM);
fail_x:
    PyBuffer_Release(&bX);
    return NULL;
}

/* sum_k a_k b_k over four lanes (k mod 4), the lanes added in a fixed order: the same doubles on
 * every CPU (a computed sum in any fixed order is what the callers' allowances cover) */
__attribute__((target_clones("avx2", "default")))
static double dot(Py_ssize_t n, const double *restrict a, const double *restrict b)
{
    v4 acc = {0.0, 0.0, 0.0, 0.0};
    Py_ssize_t k = 0;
    for (; k + 4 <= n; k += 4)
        acc = acc + ld4(a + k) * ld4(b + k);
    double t = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (; k < n; k++)
        t = t + a[k] * b[k];
    return t;
}

/* D = S - c Sa (c Sa rounded, then the difference), and sum D_ij^2 as dot's lanes */
__attribute__((target_clones("avx2", "default")))
static double minus_scaled(Py_ssize_t nn, const double *restrict S, const double *restrict Sa, double c,
                           double *restrict D)
{
    v4 acc = {0.0, 0.0, 0.0, 0.0}, cc = {c, c, c, c};
    Py_ssize_t k = 0;
    for (; k + 4 <= nn; k += 4) {
        v4 d = ld4(S + k) - cc * ld4(Sa + k);
        st4(D + k, d);
        acc = acc + d * d;
    }
    double t = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (; k < nn; k++) {
        double d = S[k] - c * Sa[k];
        D[k] = d;
        t = t + d * d;
    }
    return t;
}

/* between(S, Sa, va, theta_a, w, D) -> (c, ||w||, ||D||_F): the amortised read between anchors
 * (switchobs_core/bounds/read.py): w = S va, c = va'w / theta_a, and where c is finite and >= 0,
 * D = S - c Sa with its Frobenius norm (else nan); S, Sa, D n x n, va and w n doubles. */
static PyObject *between(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer bS, bA, bv, bw, bD;
    PyObject *res = NULL;
    Py_ssize_t n, i;
    double theta, c, nw, fd = NAN;

    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "between(S, Sa, va, theta_a, w, D)");
        return NULL;
    }
    theta = PyFloat_AsDouble(args[3]);
    if (theta == -1.0 && PyErr_Occurred())
        return NULL;
    if (PyObject_GetBuffer(args[2], &bv, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    n = bv.len / 8;
    if (!doubles(&bv) || bv.ndim != 1 || n < 1) {
        PyBuffer_Release(&bv);
        PyErr_SetString(PyExc_ValueError, "_dense_step: va of the wrong size");
        return NULL;
    }
    if (get(args[0], &bS, n, 2, 0) < 0)
        goto fail_v;
    if (get(args[1], &bA, n, 2, 0) < 0)
        goto fail_s;
    if (get(args[4], &bw, n, 1, PyBUF_WRITABLE) < 0)
        goto fail_a;
    if (get(args[5], &bD, n, 2, PyBUF_WRITABLE) < 0)
        goto fail_w;
    if (!(apart(&bw, &bS) && apart(&bw, &bA) && apart(&bw, &bv) && apart(&bw, &bD) && apart(&bD, &bS)
          && apart(&bD, &bA) && apart(&bD, &bv)) && aliased() < 0)
        goto fail_d;
    {
        const double *S = bS.buf, *Sa = bA.buf, *va = bv.buf;
        double *w = bw.buf, *D = bD.buf;
        for (i = 0; i < n; i++)
            w[i] = dot(n, S + i * n, va);
        c = dot(n, va, w) / theta;
        nw = sqrt(dot(n, w, w));
        if (isfinite(c) && c >= 0.0)
            fd = sqrt(minus_scaled(n * n, S, Sa, c, D));
    }
    res = Py_BuildValue("(ddd)", c, nw, fd);
fail_d:
    PyBuffer_Release(&bD);
fail_w:
    PyBuffer_Release(&bw);
fail_a:
    PyBuffer_Release(&bA);
fail_s:
    PyBuffer_Release(&bS);
fail_v:
    PyBuffer_Release(&bv);
    return res;
}

/* norm(x, s) -> ||diag(s) x|| (s None: ||x||): the square root of dot's lane sum of the squares */
__attribute__((target_clones("avx2", "default")))
static double sumsq(Py_ssize_t n, const double *restrict x, const double *restrict s)
{
    v4 acc = {0.0, 0.0, 0.0, 0.0};
    Py_ssize_t k = 0;
    if (s != NULL) {
        for (; k + 4 <= n; k += 4) {
            v4 v = ld4(x + k) * ld4(s + k);
            acc = acc + v * v;
        }
    } else {
        for (; k + 4 <= n; k += 4) {
            v4 v = ld4(x + k);
            acc = acc + v * v;
        }
    }
    double t = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (; k < n; k++) {
        double v = s != NULL ? x[k] * s[k] : x[k];
        t = t + v * v;
    }
    return t;
}

static PyObject *norm(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer bx, bs;
    double t;
    int scaled;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "norm(x, s)");
        return NULL;
    }
    if (PyObject_GetBuffer(args[0], &bx, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    if (!doubles(&bx)) {
        PyBuffer_Release(&bx);
        PyErr_SetString(PyExc_ValueError, "_dense_step: x is not doubles");
        return NULL;
    }
    scaled = args[1] != Py_None;
    if (scaled && get(args[1], &bs, bx.len / 8, 1, 0) < 0) {
        PyBuffer_Release(&bx);
        return NULL;
    }
    t = sumsq(bx.len / 8, bx.buf, scaled ? bs.buf : NULL);
    if (scaled)
        PyBuffer_Release(&bs);
    PyBuffer_Release(&bx);
    return PyFloat_FromDouble(sqrt(t));
}

/* correct(Phi, H, K, x0, y, xm, nu, xp): a Kalman sample through a fused map (KalmanMap.correct):
 * xm = Phi x0, nu = y - H xm, xp = xm + K nu, each entry a dot product in dot()'s fixed order (within
 * gamma_n |a|.|b| as any order: the allowances of the bound's residual, RoundingBound.fused_sample);
 * Phi n x n, H p x n, K n x p C-ordered, x0, xm, xp n and y, nu p doubles (outputs not aliased). */
static PyObject *correct(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer b[8];
    Py_ssize_t n, p, i, got = 0;
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError, "correct(Phi, H, K, x0, y, xm, nu, xp)");
        return NULL;
    }
    if (PyObject_GetBuffer(args[3], &b[0], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    got = 1;
    n = b[0].len / 8;
    if (!doubles(&b[0]) || n < 1 || n > 4096)
        goto bad;
    if (PyObject_GetBuffer(args[4], &b[1], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        goto fail;
    got = 2;
    p = b[1].len / 8;
    if (!doubles(&b[1]) || p < 1 || p > 4096)
        goto bad;
    {
        const Py_ssize_t lens[6] = {n * n, p * n, n * p, n, p, n};
        const int idx[6] = {0, 1, 2, 5, 6, 7};
        for (i = 0; i < 6; i++) {
            if (getlen(args[idx[i]], &b[2 + i], lens[i], i >= 3 ? PyBUF_WRITABLE : 0) < 0)
                goto fail;
            got = 3 + i;
        }
    }
    for (i = 5; i < 8; i++) {       /* the outputs xm, nu, xp apart from every other buffer */
        Py_ssize_t j;
        for (j = 0; j < 8; j++)
            if (j != i && !apart(&b[i], &b[j])) {
                aliased();
                goto fail;
            }
    }
    {
        const double *Phi = b[2].buf, *H = b[3].buf, *K = b[4].buf, *x0 = b[0].buf, *y = b[1].buf;
        double *xm = b[5].buf, *nu = b[6].buf, *xp = b[7].buf;
        for (i = 0; i < n; i++)
            xm[i] = dot(n, Phi + i * n, x0);
        for (i = 0; i < p; i++)
            nu[i] = y[i] - dot(n, H + i * n, xm);
        for (i = 0; i < n; i++)
            xp[i] = xm[i] + dot(p, K + i * p, nu);
    }
    for (i = 0; i < got; i++)
        PyBuffer_Release(&b[i]);
    Py_RETURN_NONE;
bad:
    PyErr_SetString(PyExc_ValueError, "_dense_step: x0 or y of the wrong size or type");
fail:
    for (i = 0; i < got; i++)
        PyBuffer_Release(&b[i]);
    return NULL;
}

/* absrows(D, n) -> max_i sum_j |D_ij| (D n x n C-ordered doubles; each row summed in index order, the
 * rows' maximum as Python's max: a NaN row gives NaN only where numpy's would too, see the wrapper) */
static PyObject *absrows(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer bD;
    Py_ssize_t n, i, j;
    double best = 0.0;
    int nan = 0;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "absrows(D, n)");
        return NULL;
    }
    n = PyLong_AsSsize_t(args[1]);
    if (n < 1 || n > 46340) {       /* n * n stays within a Py_ssize_t on every platform */
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "_dense_step: n < 1 or n > 46340");
        return NULL;
    }
    if (getlen(args[0], &bD, n * n, 0) < 0)
        return NULL;
    {
        const double *D = bD.buf;
        for (i = 0; i < n; i++) {
            double t = 0.0;
            for (j = 0; j < n; j++)
                t = t + fabs(D[i * n + j]);
            if (isnan(t))
                nan = 1;
            else if (t > best)
                best = t;
        }
    }
    PyBuffer_Release(&bD);
    return PyFloat_FromDouble(nan ? NAN : best);
}

/* ---- the factored step of a Kalman sample (switchobs_core.bounds.kalman_map, steps 1-3;
 * switchobs_core.numerics.rounding, steps 5-8): sandwich() and factored() ---- */

/* an index array: C-ordered 8-byte signed integers (np.intp on x86-64) of len entries */
static int getidx(PyObject *o, Py_buffer *b, Py_ssize_t len)
{
    const char *f;
    if (PyObject_GetBuffer(o, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    f = b->format;
    if (f != NULL && (f[0] == '@' || f[0] == '=' || (!PY_BIG_ENDIAN && f[0] == '<')))
        f++;
    if (b->itemsize != 8 || f == NULL || (f[0] != 'l' && f[0] != 'q') || f[1] != 0 || (len >= 0 && b->len != len * 8)) {
        PyBuffer_Release(b);
        PyErr_SetString(PyExc_ValueError, "_dense_step: an index array of the wrong size or type");
        return -1;
    }
    return 0;
}

/* whether (ip, ix) are compressed rows of `rows` rows over `cols` columns: ip[0] = 0, ip nondecreasing,
 * ip[rows] = nnz, every column index in [0, cols) (else ValueError: no read outside the arrays) */
static int csr_ok(Py_ssize_t rows, Py_ssize_t cols, const Py_ssize_t *ip, const Py_ssize_t *ix, Py_ssize_t nnz)
{
    Py_ssize_t i;
    if (ip[0] != 0 || ip[rows] != nnz)
        goto bad;
    for (i = 0; i < rows; i++)
        if (ip[i + 1] < ip[i])
            goto bad;
    for (i = 0; i < nnz; i++)
        if (ix[i] < 0 || ix[i] >= cols)
            goto bad;
    return 0;
bad:
    PyErr_SetString(PyExc_ValueError, "_dense_step: compressed rows out of range");
    return -1;
}

/* (ip, ix, dv) of args[0..2] into b[0..2]: compressed rows of `rows` rows over `cols` columns (csr_ok) with nnz
 * values; b[0..2] held on success (nnz returned), none on failure (-1) */
static Py_ssize_t getcsr(PyObject *const *args, Py_buffer *b, Py_ssize_t rows, Py_ssize_t cols)
{
    Py_ssize_t nnz;
    if (getidx(args[0], &b[0], rows + 1) < 0)
        return -1;
    if (getidx(args[1], &b[1], -1) < 0)
        goto fail_p;
    nnz = b[1].len / 8;
    if (csr_ok(rows, cols, b[0].buf, b[1].buf, nnz) < 0 || getlen(args[2], &b[2], nnz, 0) < 0)
        goto fail_i;
    return nnz;
fail_i:
    PyBuffer_Release(&b[1]);
fail_p:
    PyBuffer_Release(&b[0]);
    return -1;
}

/* o as an n x n array of doubles with any strides (a diagonal is read): n, or -1 with ValueError */
static Py_ssize_t getsq(PyObject *o, Py_buffer *b)
{
    Py_ssize_t n;
    if (PyObject_GetBuffer(o, b, PyBUF_STRIDES | PyBUF_FORMAT) < 0)
        return -1;
    n = b->ndim == 2 ? b->shape[0] : 0;
    if (!doubles(b) || n < 1 || b->shape[1] != n || b->strides[0] % 8 || b->strides[1] % 8) {
        PyBuffer_Release(b);
        PyErr_SetString(PyExc_ValueError, "_dense_step: a square array of the wrong shape or type");
        return -1;
    }
    return n;
}

/* C = A B for A in compressed rows (n x n) and B n x n C-ordered: row i of C is 0.0 plus a_ij B[j, :] added
 * over the row's nonzeros in their stored order: the doubles of scipy's csr_matvecs (switchobs_core.numerics.csr),
 * each entry on its own (four columns at a time, elementwise) */
__attribute__((target_clones("avx2", "default")))
static void csr_times(Py_ssize_t n, const Py_ssize_t *restrict ip, const Py_ssize_t *restrict ix,
                      const double *restrict dv, const double *restrict B, double *restrict C)
{
    Py_ssize_t i, jj, k;
    for (i = 0; i < n; i++) {
        double *c = C + i * n;
        for (k = 0; k < n; k++)
            c[k] = 0.0;
        for (jj = ip[i]; jj < ip[i + 1]; jj++) {
            const double a = dv[jj];
            const double *b = B + ix[jj] * n;
            v4 a4 = {a, a, a, a};
            for (k = 0; k + 4 <= n; k += 4)
                st4(c + k, ld4(c + k) + a4 * ld4(b + k));
            for (; k < n; k++)
                c[k] = c[k] + a * b[k];
        }
    }
}

/* T = X' (n x n, C-ordered both), in tiles of 8 x 8 */
static void transpose(Py_ssize_t n, const double *restrict X, double *restrict T)
{
    Py_ssize_t ib, kb, i, k;
    for (ib = 0; ib < n; ib += 8)
        for (kb = 0; kb < n; kb += 8)
            for (i = ib; i < ib + 8 && i < n; i++)
                for (k = kb; k < kb + 8 && k < n; k++)
                    T[k * n + i] = X[i * n + k];
}

/* sandwich(ip, ix, dv, S, X, Y): Y = Phi (Phi S)' (SparseTransition.sandwich_either): X = Phi S written into Y,
 * its transpose into X, then Y = Phi X; Phi in compressed rows (ip n + 1, ix and dv nnz), S, X, Y n x n
 * C-ordered doubles (X and Y written, apart from each other and from the inputs). The doubles of the two
 * csr_matvecs products and the copy of numpy's path. */
static PyObject *sandwich(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer bp, bi, bd, bS, bX, bY;
    Py_ssize_t n, nnz;
    PyObject *res = NULL;
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "sandwich(ip, ix, dv, S, X, Y)");
        return NULL;
    }
    if (getidx(args[0], &bp, -1) < 0)
        return NULL;
    n = bp.len / 8 - 1;
    if (n < 1) {
        PyErr_SetString(PyExc_ValueError, "_dense_step: ip of the wrong size");
        goto fail_p;
    }
    if (getidx(args[1], &bi, -1) < 0)
        goto fail_p;
    nnz = bi.len / 8;
    if (csr_ok(n, n, bp.buf, bi.buf, nnz) < 0)
        goto fail_i;
    if (getlen(args[2], &bd, nnz, 0) < 0)
        goto fail_i;
    if (get(args[3], &bS, n, 2, 0) < 0)
        goto fail_d;
    if (get(args[4], &bX, n, 2, PyBUF_WRITABLE) < 0)
        goto fail_s;
    if (get(args[5], &bY, n, 2, PyBUF_WRITABLE) < 0)
        goto fail_x;
    if (!(apart(&bX, &bY) && apart(&bX, &bS) && apart(&bY, &bS) && apart(&bX, &bd) && apart(&bY, &bd)
          && apart(&bX, &bp) && apart(&bY, &bp) && apart(&bX, &bi) && apart(&bY, &bi)) && aliased() < 0)
        goto fail_y;
    csr_times(n, bp.buf, bi.buf, bd.buf, bS.buf, bY.buf);
    transpose(n, bY.buf, bX.buf);
    csr_times(n, bp.buf, bi.buf, bd.buf, bX.buf, bY.buf);
    res = Py_None;
    Py_INCREF(res);
fail_y:
    PyBuffer_Release(&bY);
fail_x:
    PyBuffer_Release(&bX);
fail_s:
    PyBuffer_Release(&bS);
fail_d:
    PyBuffer_Release(&bd);
fail_i:
    PyBuffer_Release(&bi);
fail_p:
    PyBuffer_Release(&bp);
    return res;
}

/* Y <- Y - A B (Y n x n, A n x m, B m x n, C-ordered), each entry's sum over l = 0..m-1 in that order, then the
 * difference: blocks of 4 rows by 8 columns in registers, elementwise (rows4_times' pattern) */
__attribute__((target_clones("avx2", "default")))
static void minus_product(Py_ssize_t n, Py_ssize_t m, const double *restrict A, const double *restrict B,
                          double *restrict Y)
{
    Py_ssize_t i, k, l, r;
    for (i = 0; i + 4 <= n; i += 4) {
        const double *a0 = A + i * m, *a1 = a0 + m, *a2 = a1 + m, *a3 = a2 + m;
        double *y0 = Y + i * n, *y1 = y0 + n, *y2 = y1 + n, *y3 = y2 + n;
        for (k = 0; k + 8 <= n; k += 8) {
            v4 b0 = ld4(B + k), b1 = ld4(B + k + 4);
            v4 c00 = a0[0] * b0, c01 = a0[0] * b1, c10 = a1[0] * b0, c11 = a1[0] * b1;
            v4 c20 = a2[0] * b0, c21 = a2[0] * b1, c30 = a3[0] * b0, c31 = a3[0] * b1;
            for (l = 1; l < m; l++) {
                b0 = ld4(B + l * n + k);
                b1 = ld4(B + l * n + k + 4);
                c00 = c00 + a0[l] * b0, c01 = c01 + a0[l] * b1;
                c10 = c10 + a1[l] * b0, c11 = c11 + a1[l] * b1;
                c20 = c20 + a2[l] * b0, c21 = c21 + a2[l] * b1;
                c30 = c30 + a3[l] * b0, c31 = c31 + a3[l] * b1;
            }
            st4(y0 + k, ld4(y0 + k) - c00), st4(y0 + k + 4, ld4(y0 + k + 4) - c01);
            st4(y1 + k, ld4(y1 + k) - c10), st4(y1 + k + 4, ld4(y1 + k + 4) - c11);
            st4(y2 + k, ld4(y2 + k) - c20), st4(y2 + k + 4, ld4(y2 + k + 4) - c21);
            st4(y3 + k, ld4(y3 + k) - c30), st4(y3 + k + 4, ld4(y3 + k + 4) - c31);
        }
        for (r = 0; r < 4; r++)
            for (l = k; l < n; l++) {         /* the last columns, one at a time */
                const double *a = A + (i + r) * m;
                double z = a[0] * B[l];
                Py_ssize_t j;
                for (j = 1; j < m; j++)
                    z = z + a[j] * B[j * n + l];
                Y[(i + r) * n + l] = Y[(i + r) * n + l] - z;
            }
    }
    for (; i < n; i++)                          /* the last rows, one at a time */
        for (k = 0; k < n; k++) {
            const double *a = A + i * m;
            double z = a[0] * B[k];
            for (l = 1; l < m; l++)
                z = z + a[l] * B[l * n + k];
            Y[i * n + k] = Y[i * n + k] - z;
        }
}

/* numpy's max: NaN once any value is NaN */
static double npmax(double acc, double v) { return (v > acc || isnan(v)) ? v : acc; }

/* rounding.ErrorEllipsoid._plan without an added shaped set, its operations in its order (every sum in index
 * order): from the diagonal zd of Z (before its symmetrisation) and w, q into q and fac = (alpha, theta, the
 * sum of the new diagonal sd + q); aux as factored()'s, c4 = (n + 4) n eta (2 + ||M||_inf) */
static void plan_core(Py_ssize_t n, const double *zd, const double *w, const double *aux, double rho, double czp,
                      double c1f, double c4, double *q, double *fac)
{
    const double *d = aux, *id = aux + n, *id2 = aux + 2 * n, *d2 = aux + 3 * n;
    const double gsum = aux[4 * n], k4 = aux[4 * n + 1], alo = aux[4 * n + 2], ahi = aux[4 * n + 3];
    const double kth = aux[4 * n + 4], k2 = aux[4 * n + 5], eta = aux[4 * n + 6], k8 = aux[4 * n + 7];
    const double u2 = aux[4 * n + 8];
    double Wv = 0.0, tzs = 0.0, alpha = 1.0, theta = 1.0, c1, c2 = 0.0, trace = 0.0, Wz, rzf, tz;
    Py_ssize_t i;
    for (i = 0; i < n; i++)
        Wv = Wv + w[i] * id[i];
    Wz = Wv * gsum;                             /* W of step 6, rounded up */
    rzf = (czp * Wz) * k4;                      /* R_z = rzf (w d): _diag(w, cz) */
    for (i = 0; i < n; i++)
        tzs = tzs + (((zd[i] + zd[i]) * 0.5) + rzf * (w[i] * d[i])) * id2[i];
    tz = pymax(tzs, 0.0) * gsum;                /* trace_D of E(Z + R_z) */
    if (tz > 0.0 && ((double)n * (rho * rho) > 0.0 || rho > 0.0)) {
        alpha = 1.0 + pymin(pymax(rho / sqrt(tz), alo), ahi);
        theta = (1.0 + 1.0 / (alpha - 1.0)) * kth;
    }
    c1 = (alpha * c1f) * Wz;
    if (rho > 0.0)
        c2 = ((theta * rho) * rho * k2 + eta);
    for (i = 0; i < n; i++) {
        double zs = (zd[i] + zd[i]) * 0.5, sd = alpha != 1.0 ? zs * alpha : zs;
        double qi = c1 * (w[i] * d[i]);
        if (rho > 0.0)
            qi = qi + c2 * d2[i];
        qi = qi + (fabs(sd) * u2 + c4);
        qi = qi * k8;
        q[i] = qi;
        trace = trace + (sd + qi);
    }
    fac[0] = alpha;
    fac[1] = theta;
    fac[2] = trace;
}

/* The factored step's work: see factored() */
static void factored_kernel(Py_ssize_t n, Py_ssize_t p, double *restrict Y, const double *S, Py_ssize_t s0,
                            Py_ssize_t s1, const Py_ssize_t *ip, const Py_ssize_t *ix, const double *adv,
                            const double *restrict K, const Py_ssize_t *hp, const Py_ssize_t *hj,
                            const double *hv, const double *aux, const double *cf, double *restrict work,
                            double *out)
{
    const double *id2 = aux + 2 * n, gsum = aux[4 * n];
    const double rho = cf[0], wf = cf[1], czp = cf[2], c1f = cf[3], c4f = cf[4], mn = cf[5];
    const Py_ssize_t m = 2 * p;
    double *s = work, *w = s + n, *zd = w + n, *Bm = zd + n, *Am = Bm + m * n, *Cm = Am + n * m, *hy = Cm + p * p;
    Py_ssize_t i, k, r, q, jj;
    double tr = 0.0, ls = 0.0;

    /* w = (y + |K| (|H| y)) wf, y = |Phi~| s, s = sqrt(max(diag S, 0)) (step 3) */
    for (i = 0; i < n; i++)
        s[i] = sqrt(pymax(S[i * s0 + i * s1], 0.0));
    for (i = 0; i < n; i++) {
        double t = 0.0;
        for (jj = ip[i]; jj < ip[i + 1]; jj++)
            t = t + adv[jj] * s[ix[jj]];
        w[i] = t;                               /* y */
    }
    for (r = 0; r < p; r++) {
        double t = 0.0;
        for (jj = hp[r]; jj < hp[r + 1]; jj++)
            t = t + fabs(hv[jj]) * w[hj[jj]];
        hy[r] = t;
    }
    for (i = 0; i < n; i++) {
        const double *ki = K + i * p;
        double t = fabs(ki[0]) * hy[0];
        for (r = 1; r < p; r++)
            t = t + fabs(ki[r]) * hy[r];
        w[i] = (w[i] + t) * wf;
    }
    /* G = H Y into Bm's first p rows, K' into its last p; Am's rows [K_i, V_i], V = Y H' - K (G H') (step 2) */
    for (r = 0; r < p; r++) {
        double *g = Bm + r * n;
        if (hp[r] == hp[r + 1])
            for (k = 0; k < n; k++)
                g[k] = 0.0;
        for (jj = hp[r]; jj < hp[r + 1]; jj++) {
            const double h = hv[jj], *yr = Y + hj[jj] * n;
            if (jj == hp[r])
                for (k = 0; k < n; k++)
                    g[k] = h * yr[k];
            else
                for (k = 0; k < n; k++)
                    g[k] = g[k] + h * yr[k];
        }
        for (k = 0; k < n; k++)
            Bm[(p + r) * n + k] = K[k * p + r];
    }
    for (r = 0; r < p; r++)                     /* C = G H': C[r][q] = sum_c G_rc H_qc */
        for (q = 0; q < p; q++) {
            double t = 0.0;
            for (jj = hp[q]; jj < hp[q + 1]; jj++)
                t = jj == hp[q] ? hv[jj] * Bm[r * n + hj[jj]] : t + hv[jj] * Bm[r * n + hj[jj]];
            Cm[r * p + q] = t;
        }
    for (i = 0; i < n; i++) {
        const double *ki = K + i * p, *yi = Y + i * n;
        double *a = Am + i * m;
        for (r = 0; r < p; r++) {
            double yh = 0.0, kc = ki[0] * Cm[r];
            for (jj = hp[r]; jj < hp[r + 1]; jj++)
                yh = jj == hp[r] ? hv[jj] * yi[hj[jj]] : yh + hv[jj] * yi[hj[jj]];
            for (q = 1; q < p; q++)
                kc = kc + ki[q] * Cm[q * p + r];
            a[r] = ki[r];
            a[p + r] = yh - kc;
        }
    }
    /* Z = Y - [K V] [G; K'] in place (one product of inner dimension 2p), its diagonal */
    minus_product(n, m, Am, Bm, Y);
    for (i = 0; i < n; i++)
        zd[i] = Y[i * n + i];
    /* the plan (rounding.ErrorEllipsoid._plan without an added shaped set): q into s (read no more) */
    {
        double fac[3], alpha, ha;
        plan_core(n, zd, w, aux, rho, czp, c1f, c4f * (2.0 + mn), s, fac);
        alpha = fac[0];
        /* S' = (Z + Z') (alpha / 2) + diag(q) in place, exactly symmetric, in tiles of 8 x 8 */
        ha = 0.5 * alpha;
        for (i = 0; i < n; i += 8)
            for (k = i; k < n; k += 8) {
                Py_ssize_t a, b;
                for (a = i; a < i + 8 && a < n; a++)
                    for (b = (k == i ? a + 1 : k); b < k + 8 && b < n; b++) {
                        double v = (Y[a * n + b] + Y[b * n + a]) * ha;
                        Y[a * n + b] = v;
                        Y[b * n + a] = v;
                    }
            }
        for (i = 0; i < n; i++) {
            double v = (zd[i] + zd[i]) * ha + s[i];
            Y[i * n + i] = v;
            tr = tr + v;
            ls = ls + v * id2[i];
        }
        out[2] = alpha;
        out[3] = fac[1];
    }
    out[0] = pymax(tr, 0.0) * gsum;
    out[1] = pymax(ls, 0.0) * gsum;
}

/* factored(Y, S, ip, ix, adv, K, hp, hj, hv, aux, rho, wf, czp, c1f, c4f, mn) -> (tr, ls, alpha, theta):
 * a Kalman sample's step of the exact set through its factored map (KalmanMap.sandwich and
 * ErrorEllipsoid.propagate_product in one call, switchobs_core.numerics.rounding.ErrorEllipsoid.step_factored):
 * Y (n x n C-ordered, the prior's Phi~ S Phi~') is overwritten with S'; S (n x n, any strides) gives diag S;
 * (ip, ix, adv) |Phi~| and (hp, hj, hv) H in compressed rows, K n x p C-ordered; aux the ellipsoid's
 * (d, 1/d, 1/d^2, d^2, gsum, 1 + 4u, alo, ahi, kth, k2, eta, 1 + 8u, 2u); the scalars: the residual rho, w's
 * factor, cz + u (1 + cz), q's factor of W (w d), (n + 4) n eta, the map's underflow gain mn (KalmanMap's
 * factored_underflow: c4 = c4f (2 + mn)). Every sum in index
 * order (within the gamma_m of the docstrings' standard model, as any order); tr and ls the trace and the
 * balanced trace of S' rounded up by gsum. */
static PyObject *factored(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer b[10];
    Py_ssize_t n, p = 0, got = 0, i;
    double cf[6], out[4], *work;
    PyObject *res = NULL;
    if (nargs != 16) {
        PyErr_SetString(PyExc_TypeError, "factored(Y, S, ip, ix, adv, K, hp, hj, hv, aux, rho, wf, czp, c1f, c4f, "
                                         "mn)");
        return NULL;
    }
    for (i = 0; i < 6; i++) {
        cf[i] = PyFloat_AsDouble(args[10 + i]);
        if (cf[i] == -1.0 && PyErr_Occurred())
            return NULL;
    }
    if ((n = getsq(args[1], &b[1])) < 0)
        return NULL;
    if (get(args[0], &b[0], n, 2, PyBUF_WRITABLE) < 0) {
        PyBuffer_Release(&b[1]);
        return NULL;
    }
    got = 2;
    if (getcsr(args + 2, b + 2, n, n) < 0)
        goto fail;
    got = 5;
    {       /* H's rows: p from hp's length (getcsr then checks it) */
        Py_buffer bh;
        if (PyObject_GetBuffer(args[6], &bh, PyBUF_C_CONTIGUOUS) < 0)
            goto fail;
        p = bh.len / 8 - 1;
        PyBuffer_Release(&bh);
    }
    if (p < 1 || p > 4096) {
        PyErr_SetString(PyExc_ValueError, "_dense_step: hp of the wrong size");
        goto fail;
    }
    if (getcsr(args + 6, b + 5, p, n) < 0)
        goto fail;
    got = 8;
    if (getlen(args[5], &b[8], n * p, 0) < 0)
        goto fail;
    got = 9;
    if (getlen(args[9], &b[9], 4 * n + 9, 0) < 0)
        goto fail;
    got = 10;
    for (i = 1; i < 10; i++)            /* Y (written) apart from every input */
        if (!apart(&b[0], &b[i])) {
            aliased();
            goto fail;
        }
    work = PyMem_Malloc((size_t)(3 * n + 4 * p * n + p * p + p) * sizeof(double));
    if (work == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    factored_kernel(n, p, b[0].buf, b[1].buf, b[1].strides[0] / 8, b[1].strides[1] / 8, b[2].buf, b[3].buf,
                    b[4].buf, b[8].buf, b[5].buf, b[6].buf, b[7].buf, b[9].buf, cf, work, out);
    PyMem_Free(work);
    res = Py_BuildValue("(dddd)", out[0], out[1], out[2], out[3]);
fail:
    for (i = 0; i < got; i++)
        PyBuffer_Release(&b[i]);
    return res;
}

/* open_plan(Z, S, ip, ix, adv, aux, q, rho, wf, czp, c1f, c4f, mn) -> (alpha, theta, trace, tr): the plan of an
 * open-loop step's set (ErrorEllipsoid.pending_open, a prior's PendingSet): w = (|Phi~| s) wf with s =
 * sqrt(max(diag S, 0)) (ErrorEllipsoid.image_bound, the sum as scipy's csr_matvec), then plan_core on Z's
 * diagonal with c4 = c4f (2 + mn); q (n doubles) written; trace the sum of the new diagonal, tr it rounded up. */
static PyObject *open_plan(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer b[7];
    Py_ssize_t n, got = 0, i, jj;
    double cf[6], fac[3], *work;
    PyObject *res = NULL;
    if (nargs != 13) {
        PyErr_SetString(PyExc_TypeError, "open_plan(Z, S, ip, ix, adv, aux, q, rho, wf, czp, c1f, c4f, mn)");
        return NULL;
    }
    for (i = 0; i < 6; i++) {
        cf[i] = PyFloat_AsDouble(args[7 + i]);
        if (cf[i] == -1.0 && PyErr_Occurred())
            return NULL;
    }
    if ((n = getsq(args[0], &b[0])) < 0)
        return NULL;
    got = 1;
    if (getsq(args[1], &b[1]) != n) {
        if (!PyErr_Occurred()) {
            PyBuffer_Release(&b[1]);
            PyErr_SetString(PyExc_ValueError, "_dense_step: S and Z of different sizes");
        }
        goto fail;
    }
    got = 2;
    if (getcsr(args + 2, b + 2, n, n) < 0)
        goto fail;
    got = 5;
    if (getlen(args[5], &b[5], 4 * n + 9, 0) < 0)
        goto fail;
    got = 6;
    if (getlen(args[6], &b[6], n, PyBUF_WRITABLE) < 0)
        goto fail;
    got = 7;
    for (i = 0; i < 6; i++)
        if (!apart(&b[6], &b[i])) {
            aliased();
            goto fail;
        }
    work = PyMem_Malloc((size_t)(3 * n) * sizeof(double));
    if (work == NULL) {
        PyErr_NoMemory();
        goto fail;
    }
    {
        const double *Z = b[0].buf, *S = b[1].buf, *adv = b[4].buf, wf = cf[1];
        const Py_ssize_t z0 = b[0].strides[0] / 8, z1 = b[0].strides[1] / 8, s0 = b[1].strides[0] / 8,
                         s1 = b[1].strides[1] / 8, *ip = b[2].buf, *ix = b[3].buf;
        double *s = work, *w = s + n, *zd = w + n;
        for (i = 0; i < n; i++) {
            s[i] = sqrt(pymax(S[i * s0 + i * s1], 0.0));
            zd[i] = Z[i * z0 + i * z1];
        }
        for (i = 0; i < n; i++) {
            double t = 0.0;
            for (jj = ip[i]; jj < ip[i + 1]; jj++)
                t = t + adv[jj] * s[ix[jj]];
            w[i] = t * wf;
        }
        plan_core(n, zd, w, b[5].buf, cf[0], cf[2], cf[3], cf[4] * (2.0 + cf[5]), b[6].buf, fac);
    }
    PyMem_Free(work);
    res = Py_BuildValue("(dddd)", fac[0], fac[1], fac[2], pymax(fac[2], 0.0) * ((const double *)b[5].buf)[4 * n]);
fail:
    for (i = 0; i < got; i++)
        PyBuffer_Release(&b[i]);
    return res;
}

/* block(Z, cols, ha, q, B): B[a, b] = (Z[c_a, c_b] + Z[c_b, c_a]) ha, then q[c_a] added on the diagonal: a block of
 * (Z + Z') (alpha / 2) + diag(q) without the n x n passes (ErrorEllipsoid._block without a shaped set), the
 * operations of numpy's path in its order, so its doubles; Z n x n (any strides), cols m np.intp in [0, n),
 * q n doubles, B m x m C-ordered (written, apart from the inputs) */
static PyObject *block(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer bZ, bc, bq, bB;
    Py_ssize_t n, m, a, b;
    double ha;
    PyObject *res = NULL;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "block(Z, cols, ha, q, B)");
        return NULL;
    }
    ha = PyFloat_AsDouble(args[2]);
    if (ha == -1.0 && PyErr_Occurred())
        return NULL;
    if ((n = getsq(args[0], &bZ)) < 0)
        return NULL;
    if (getidx(args[1], &bc, -1) < 0)
        goto fail_z;
    m = bc.len / 8;
    if (getlen(args[3], &bq, n, 0) < 0)
        goto fail_c;
    if (getlen(args[4], &bB, m * m, PyBUF_WRITABLE) < 0)
        goto fail_q;
    if (!(apart(&bB, &bZ) && apart(&bB, &bc) && apart(&bB, &bq)) && aliased() < 0)
        goto fail_b;
    {
        const Py_ssize_t *cols = bc.buf, z0 = bZ.strides[0] / 8, z1 = bZ.strides[1] / 8;
        const double *Z = bZ.buf, *q = bq.buf;
        double *B = bB.buf;
        for (a = 0; a < m; a++)
            if (cols[a] < 0 || cols[a] >= n) {
                PyErr_SetString(PyExc_ValueError, "_dense_step: a column out of range");
                goto fail_b;
            }
        for (a = 0; a < m; a++)
            for (b = 0; b < m; b++)
                B[a * m + b] = (Z[cols[a] * z0 + cols[b] * z1] + Z[cols[b] * z0 + cols[a] * z1]) * ha;
        for (a = 0; a < m; a++)
            B[a * m + a] = B[a * m + a] + q[cols[a]];
    }
    res = Py_None;
    Py_INCREF(res);
fail_b:
    PyBuffer_Release(&bB);
fail_q:
    PyBuffer_Release(&bq);
fail_c:
    PyBuffer_Release(&bc);
fail_z:
    PyBuffer_Release(&bZ);
    return res;
}

/* kappa(K, H, d) -> (one, inf): the 1- and inf-norms of |D^-1 K| |H D| (K n x p, H p x n C-ordered, d n doubles;
 * KalmanMap.kappa's sums, each in index order, the scalings as numpy's: K_ir / d_i and H_rc d_c):
 * one = max_c sum_r (sum_i |K_ir / d_i|) |H_rc d_c|, inf = max_i sum_r |K_ir / d_i| (sum_c |H_rc d_c|) */
static PyObject *kappa(PyObject *Py_UNUSED(self), PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer bK, bH, bd;
    Py_ssize_t n, p, i, r, k;
    double one = 0.0, inf = 0.0, *cs;
    PyObject *res = NULL;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "kappa(K, H, d)");
        return NULL;
    }
    if (PyObject_GetBuffer(args[2], &bd, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    n = bd.len / 8;
    if (!doubles(&bd) || n < 1) {
        PyBuffer_Release(&bd);
        PyErr_SetString(PyExc_ValueError, "_dense_step: d of the wrong size or type");
        return NULL;
    }
    if (PyObject_GetBuffer(args[1], &bH, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        goto fail_d;
    p = bH.len / 8 / n;
    if (!doubles(&bH) || p < 1 || bH.len != p * n * 8) {
        PyErr_SetString(PyExc_ValueError, "_dense_step: H of the wrong size or type");
        goto fail_h;
    }
    if (getlen(args[0], &bK, n * p, 0) < 0)
        goto fail_h;
    cs = PyMem_Malloc((size_t)(2 * p) * sizeof(double));
    if (cs == NULL) {
        PyErr_NoMemory();
        goto fail_k;
    }
    {
        const double *K = bK.buf, *H = bH.buf, *d = bd.buf;
        double *hs = cs + p;
        for (r = 0; r < p; r++) {
            double a = fabs(K[r] / d[0]), h = fabs(H[r * n] * d[0]);
            for (i = 1; i < n; i++) {
                a = a + fabs(K[i * p + r] / d[i]);
                h = h + fabs(H[r * n + i] * d[i]);
            }
            cs[r] = a;
            hs[r] = h;
        }
        for (k = 0; k < n; k++) {
            double o = cs[0] * fabs(H[k] * d[k]), t = fabs(K[k * p] / d[k]) * hs[0];
            for (r = 1; r < p; r++) {
                o = o + cs[r] * fabs(H[r * n + k] * d[k]);
                t = t + fabs(K[k * p + r] / d[k]) * hs[r];
            }
            one = k ? npmax(one, o) : o;
            inf = k ? npmax(inf, t) : t;
        }
    }
    PyMem_Free(cs);
    res = Py_BuildValue("(dd)", one, inf);
fail_k:
    PyBuffer_Release(&bK);
fail_h:
    PyBuffer_Release(&bH);
fail_d:
    PyBuffer_Release(&bd);
    return res;
}

static PyMethodDef methods[] = {
    {"absrows", (PyCFunction)(void (*)(void))absrows, METH_FASTCALL,
     "absrows(D, n) -> the largest absolute row sum of the n x n D (each row in index order; NaN if any is)"},
    {"correct", (PyCFunction)(void (*)(void))correct, METH_FASTCALL,
     "correct(Phi, H, K, x0, y, xm, nu, xp): xm = Phi x0, nu = y - H xm, xp = xm + K nu (fixed-order sums)"},
    {"step", (PyCFunction)(void (*)(void))step, METH_FASTCALL,
     "step(M, S, aMd, aux, out, rho, c4) -> (tr, ls, alpha, theta): ErrorEllipsoid.step_dense's set into out"},
    {"norm", (PyCFunction)(void (*)(void))norm, METH_FASTCALL,
     "norm(x, s) -> ||diag(s) x|| (s None: ||x||), a sum in a fixed order"},
    {"sandwich", (PyCFunction)(void (*)(void))sandwich, METH_FASTCALL,
     "sandwich(ip, ix, dv, S, X, Y): Y = Phi (Phi S)' for Phi in compressed rows (csr_matvecs' doubles)"},
    {"factored", (PyCFunction)(void (*)(void))factored, METH_FASTCALL,
     "factored(Y, S, ip, ix, adv, K, hp, hj, hv, aux, rho, wf, czp, c1f, c4f, mn) -> (tr, ls, alpha, theta)"},
    {"kappa", (PyCFunction)(void (*)(void))kappa, METH_FASTCALL,
     "kappa(K, H, d) -> (one, inf): the 1- and inf-norms of |D^-1 K| |H D| (sums in index order)"},
    {"block", (PyCFunction)(void (*)(void))block, METH_FASTCALL,
     "block(Z, cols, ha, q, B): B = ((Z + Z') ha + diag(q))[cols, cols] (numpy's operations, its doubles)"},
    {"open_plan", (PyCFunction)(void (*)(void))open_plan, METH_FASTCALL,
     "open_plan(Z, S, ip, ix, adv, aux, q, rho, wf, czp, c1f, c4f, mn) -> (alpha, theta, trace, tr)"},
    {"between", (PyCFunction)(void (*)(void))between, METH_FASTCALL,
     "between(S, Sa, va, theta_a, w, D) -> (c, ||w||, ||D||_F): the amortised read between anchors"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_dense_step",
                                    "ErrorEllipsoid.step_dense in one call (optional)", -1, methods,
                                    NULL, NULL, NULL, NULL};

#ifndef SOURCE_SHA256
#define SOURCE_SHA256 "" /* setup.py passes the SHA-256 of this file: dense_kernel compares it with the file */
#endif

PyMODINIT_FUNC PyInit__dense_step(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && PyModule_AddStringConstant(m, "SOURCE_SHA256", SOURCE_SHA256) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
