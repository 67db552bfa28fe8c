/* Looped prototype of <name>_derivative_terms_eval for spatial_chain_N
 * (modelgen research, not generated): per-joint-signature kernels (revolute
 * about z, revolute about y) called in a loop over the links, every quantity
 * in E as derive/rnea_partials.py, writing the same W (component c of dof k
 * at W[c*N + k]; 0 J, 6 dAdq, 12 dVdq, 18 dAdv, 24 dFda, 30 dYtJ, 33 dFdq0,
 * 39 dFdq, 45 dFdv, and above 30 dofs 51 U, 57 1/D).
 *
 * Compile with -DN=<links>.  -DPROTO_CARRY: the parent's state is passed in a
 * local carried across the iterations (a chain) instead of loaded from the
 * parent's slot of an array (a tree).  -DPROTO_INLINE: the kernels are
 * inlined into the loops (no calls).  -DPROTO_ROOT: the root joint has its
 * own signature (ground parent constant-folded). */
#include "mgtrig.h"     /* the generated file's mg_sin, mg_cos, cut out by the runner */

#ifndef N
#error "compile with -DN=<links>"
#endif
#define ARTIC (N > 30)

#ifdef PROTO_INLINE
#define KERNEL static inline __attribute__((always_inline))
#else
#define KERNEL static __attribute__((noinline))
#endif
#define H static inline __attribute__((always_inline))
#ifdef PROTO_NORESTRICT
#define RS
#else
#define RS restrict
#endif

/* per-link constants, from p at prepare time */
typedef struct {
    double ox;  /* offset of the joint in the parent's frame along x */
    double m, hx;   /* mass, first moment (hx, 0, 0) about the link origin */
    double d, s;    /* inertia about the origin: d 1 + s e_x e_x^T */
} link_const;

/* what a link passes to its child (forward) */
typedef struct {
    double R[9];    /* row-major, link -> E */
    double p[3];
    double ov[6], oa[6];
} kin_state;

/* what a link keeps for the backward pass: Y = (I, h, m), doY = (A, F), of */
typedef struct {
    double I[6];    /* 00 11 22 01 02 12 */
    double h[3];
    double m;
    double A[9];    /* row-major */
    double F[3];
    double f[6];
} dyn_state;

static link_const cst[N];
static double grav;

void proto_prepare(const double *p)
{
    const double r = p[2 * N];
    int i;
    for (i = 0; i < N; ++i) {
        const double m = p[i], l = p[N + i];
        cst[i].ox = i ? p[N + i - 1] : 0.0;
        cst[i].m = m;
        cst[i].hx = m * l / 2;
        cst[i].d = m * l * l / 3 + m * r * r / 4;
        cst[i].s = m * r * r / 2 - cst[i].d;
    }
    grav = p[2 * N + 1];
}

/* ---- spatial algebra ---- */
H void cross3(const double *a, const double *b, double *o)
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}

/* a x b (motion) */
H void crm(const double *a, const double *b, double *o)
{
    double t[3], u[3];
    cross3(a, b, o);
    cross3(a, b + 3, t);
    cross3(a + 3, b, u);
    o[3] = t[0] + u[0]; o[4] = t[1] + u[1]; o[5] = t[2] + u[2];
}

/* v x* f */
H void crf(const double *v, const double *f, double *o)
{
    double t[3], u[3];
    cross3(v, f, t);
    cross3(v + 3, f + 3, u);
    o[0] = t[0] + u[0]; o[1] = t[1] + u[1]; o[2] = t[2] + u[2];
    cross3(v, f + 3, o + 3);
}

/* Y x = (I w + h x v, m v - h x w) */
H void ytimes(const double *I, const double *h, double m, const double *x, double *o)
{
    double t[3], u[3];
    cross3(h, x + 3, t);
    cross3(h, x, u);
    o[0] = I[0] * x[0] + I[3] * x[1] + I[4] * x[2] + t[0];
    o[1] = I[3] * x[0] + I[1] * x[1] + I[5] * x[2] + t[1];
    o[2] = I[4] * x[0] + I[5] * x[1] + I[2] * x[2] + t[2];
    o[3] = m * x[3] - u[0];
    o[4] = m * x[4] - u[1];
    o[5] = m * x[5] - u[2];
}

/* doY x = (A w, 2 w x F) */
H void dytimes(const double *A, const double *F, const double *x, double *o)
{
    double t[3];
    o[0] = A[0] * x[0] + A[1] * x[1] + A[2] * x[2];
    o[1] = A[3] * x[0] + A[4] * x[1] + A[5] * x[2];
    o[2] = A[6] * x[0] + A[7] * x[1] + A[8] * x[2];
    cross3(x, F, t);
    o[3] = 2 * t[0]; o[4] = 2 * t[1]; o[5] = 2 * t[2];
}

/* ---- forward kernels ---- */
/* The body of both signatures; `ax` is a constant after inlining (2: z, 1: y),
 * so the rotation and J are folded for the axis. */
H void fwd_body(int ax, const kin_state *RS P, kin_state *RS K, dyn_state *RS D, const link_const *RS c,
                double q, double qd, double qdd, double *RS W)
{
    const double co = mg_cos(q), si = mg_sin(q);
    const double *Rp = P->R;
    double *R = K->R;
    double J[6], dV[6], t6[6], oh[6], dA[6];
    /* R = Rp Rot(axis, q) */
    if (ax == 2) {
            R[3 * 0 + 0] = co * Rp[3 * 0 + 0] + si * Rp[3 * 0 + 1];
            R[3 * 0 + 1] = co * Rp[3 * 0 + 1] - si * Rp[3 * 0 + 0];
            R[3 * 0 + 2] = Rp[3 * 0 + 2];
            R[3 * 1 + 0] = co * Rp[3 * 1 + 0] + si * Rp[3 * 1 + 1];
            R[3 * 1 + 1] = co * Rp[3 * 1 + 1] - si * Rp[3 * 1 + 0];
            R[3 * 1 + 2] = Rp[3 * 1 + 2];
            R[3 * 2 + 0] = co * Rp[3 * 2 + 0] + si * Rp[3 * 2 + 1];
            R[3 * 2 + 1] = co * Rp[3 * 2 + 1] - si * Rp[3 * 2 + 0];
            R[3 * 2 + 2] = Rp[3 * 2 + 2];
    } else {
            R[3 * 0 + 0] = co * Rp[3 * 0 + 0] - si * Rp[3 * 0 + 2];
            R[3 * 0 + 1] = Rp[3 * 0 + 1];
            R[3 * 0 + 2] = co * Rp[3 * 0 + 2] + si * Rp[3 * 0 + 0];
            R[3 * 1 + 0] = co * Rp[3 * 1 + 0] - si * Rp[3 * 1 + 2];
            R[3 * 1 + 1] = Rp[3 * 1 + 1];
            R[3 * 1 + 2] = co * Rp[3 * 1 + 2] + si * Rp[3 * 1 + 0];
            R[3 * 2 + 0] = co * Rp[3 * 2 + 0] - si * Rp[3 * 2 + 2];
            R[3 * 2 + 1] = Rp[3 * 2 + 1];
            R[3 * 2 + 2] = co * Rp[3 * 2 + 2] + si * Rp[3 * 2 + 0];
    }
        K->p[0] = P->p[0] + c->ox * Rp[3 * 0];
        K->p[1] = P->p[1] + c->ox * Rp[3 * 1];
        K->p[2] = P->p[2] + c->ox * Rp[3 * 2];
    /* J = (w, p x w), w = R's column ax (= Rp's) */
    J[0] = Rp[ax]; J[1] = Rp[3 + ax]; J[2] = Rp[6 + ax];
    cross3(K->p, J, J + 3);
    crm(P->ov, J, dV);
        K->ov[0] = P->ov[0] + J[0] * qd;
        K->oa[0] = P->oa[0] + J[0] * qdd + dV[0] * qd;
        K->ov[1] = P->ov[1] + J[1] * qd;
        K->oa[1] = P->oa[1] + J[1] * qdd + dV[1] * qd;
        K->ov[2] = P->ov[2] + J[2] * qd;
        K->oa[2] = P->oa[2] + J[2] * qdd + dV[2] * qd;
        K->ov[3] = P->ov[3] + J[3] * qd;
        K->oa[3] = P->oa[3] + J[3] * qdd + dV[3] * qd;
        K->ov[4] = P->ov[4] + J[4] * qd;
        K->oa[4] = P->oa[4] + J[4] * qdd + dV[4] * qd;
        K->ov[5] = P->ov[5] + J[5] * qd;
        K->oa[5] = P->oa[5] + J[5] * qdd + dV[5] * qd;
#ifdef PROTO_EARLY
    /* dAdq = oa_p x J + ov_p x dVdq, dAdv = 2 dVdq */
    crm(P->oa, J, dA);
    crm(P->ov, dV, t6);
        W[0 * N] = J[0];
        W[(6 + 0) * N] = dA[0] + t6[0];
        W[(12 + 0) * N] = dV[0];
        W[(18 + 0) * N] = 2 * dV[0];
        W[1 * N] = J[1];
        W[(6 + 1) * N] = dA[1] + t6[1];
        W[(12 + 1) * N] = dV[1];
        W[(18 + 1) * N] = 2 * dV[1];
        W[2 * N] = J[2];
        W[(6 + 2) * N] = dA[2] + t6[2];
        W[(12 + 2) * N] = dV[2];
        W[(18 + 2) * N] = 2 * dV[2];
        W[3 * N] = J[3];
        W[(6 + 3) * N] = dA[3] + t6[3];
        W[(12 + 3) * N] = dV[3];
        W[(18 + 3) * N] = 2 * dV[3];
        W[4 * N] = J[4];
        W[(6 + 4) * N] = dA[4] + t6[4];
        W[(12 + 4) * N] = dV[4];
        W[(18 + 4) * N] = 2 * dV[4];
        W[5 * N] = J[5];
        W[(6 + 5) * N] = dA[5] + t6[5];
        W[(12 + 5) * N] = dV[5];
        W[(18 + 5) * N] = 2 * dV[5];
#endif
    /* Y in E */
    {
        const double *p = K->p;
        const double r0[3] = {R[0], R[3], R[6]};
        double hr[3], sr[3], t[3];
            hr[0] = c->hx * r0[0];
            D->h[0] = hr[0] + c->m * p[0];
            sr[0] = c->s * r0[0];
            t[0] = p[0] * (D->h[0] + hr[0]);
            hr[1] = c->hx * r0[1];
            D->h[1] = hr[1] + c->m * p[1];
            sr[1] = c->s * r0[1];
            t[1] = p[1] * (D->h[1] + hr[1]);
            hr[2] = c->hx * r0[2];
            D->h[2] = hr[2] + c->m * p[2];
            sr[2] = c->s * r0[2];
            t[2] = p[2] * (D->h[2] + hr[2]);
        D->I[0] = (c->d + sr[0] * r0[0]) + t[1] + t[2];
        D->I[1] = (c->d + sr[1] * r0[1]) + t[0] + t[2];
        D->I[2] = (c->d + sr[2] * r0[2]) + t[0] + t[1];
        D->I[3] = sr[0] * r0[1] - p[0] * D->h[1] - hr[0] * p[1];
        D->I[4] = sr[0] * r0[2] - p[0] * D->h[2] - hr[0] * p[2];
        D->I[5] = sr[1] * r0[2] - p[1] * D->h[2] - hr[1] * p[2];
        D->m = c->m;
    }
    ytimes(D->I, D->h, D->m, K->ov, oh);
    ytimes(D->I, D->h, D->m, K->oa, D->f);
    crf(K->ov, oh, t6);
        D->f[0] += t6[0];
        D->f[1] += t6[1];
        D->f[2] += t6[2];
        D->f[3] += t6[3];
        D->f[4] += t6[4];
        D->f[5] += t6[5];
    /* doY = (A, F): A = W I - I W - (U H + H U) - (n x), F = oh's linear part */
    {
        const double *w = K->ov, *u = K->ov + 3, *h = D->h, *I = D->I, *n = oh;
        /* P_rc = (w x I[:, c])_r, I full symmetric */
        const double c0[3] = {I[0], I[3], I[4]}, c1[3] = {I[3], I[1], I[5]},
                     c2[3] = {I[4], I[5], I[2]};
        double P0[3], P1[3], P2[3];
        double s01, s02, s12;
        cross3(w, c0, P0);
        cross3(w, c1, P1);
        cross3(w, c2, P2);
        D->A[0] = 2 * (P0[0] + u[1] * h[1] + u[2] * h[2]);
        D->A[4] = 2 * (P1[1] + u[0] * h[0] + u[2] * h[2]);
        D->A[8] = 2 * (P2[2] + u[0] * h[0] + u[1] * h[1]);
        s01 = P1[0] + P0[1] - h[0] * u[1] - u[0] * h[1];
        s02 = P2[0] + P0[2] - h[0] * u[2] - u[0] * h[2];
        s12 = P2[1] + P1[2] - h[1] * u[2] - u[1] * h[2];
        D->A[1] = s01 + n[2]; D->A[3] = s01 - n[2];
        D->A[2] = s02 - n[1]; D->A[6] = s02 + n[1];
        D->A[5] = s12 + n[0]; D->A[7] = s12 - n[0];
        D->F[0] = oh[3]; D->F[1] = oh[4]; D->F[2] = oh[5];
    }
#ifndef PROTO_EARLY
    /* dAdq = oa_p x J + ov_p x dVdq, dAdv = 2 dVdq */
    crm(P->oa, J, dA);
    crm(P->ov, dV, t6);
        W[0 * N] = J[0];
        W[(6 + 0) * N] = dA[0] + t6[0];
        W[(12 + 0) * N] = dV[0];
        W[(18 + 0) * N] = 2 * dV[0];
        W[1 * N] = J[1];
        W[(6 + 1) * N] = dA[1] + t6[1];
        W[(12 + 1) * N] = dV[1];
        W[(18 + 1) * N] = 2 * dV[1];
        W[2 * N] = J[2];
        W[(6 + 2) * N] = dA[2] + t6[2];
        W[(12 + 2) * N] = dV[2];
        W[(18 + 2) * N] = 2 * dV[2];
        W[3 * N] = J[3];
        W[(6 + 3) * N] = dA[3] + t6[3];
        W[(12 + 3) * N] = dV[3];
        W[(18 + 3) * N] = 2 * dV[3];
        W[4 * N] = J[4];
        W[(6 + 4) * N] = dA[4] + t6[4];
        W[(12 + 4) * N] = dV[4];
        W[(18 + 4) * N] = 2 * dV[4];
        W[5 * N] = J[5];
        W[(6 + 5) * N] = dA[5] + t6[5];
        W[(12 + 5) * N] = dV[5];
        W[(18 + 5) * N] = 2 * dV[5];
#endif
}

KERNEL void fwd_revz(const kin_state *RS P, kin_state *RS K, dyn_state *RS D, const link_const *RS c,
                     double q, double qd, double qdd, double *RS W)
{
    fwd_body(2, P, K, D, c, q, qd, qdd, W);
}

KERNEL void fwd_revy(const kin_state *RS P, kin_state *RS K, dyn_state *RS D, const link_const *RS c,
                     double q, double qd, double qdd, double *RS W)
{
    fwd_body(1, P, K, D, c, q, qd, qdd, W);
}

#ifdef PROTO_ROOT
/* the root revolute about z with the ground as parent, folded: R = Rz, p = 0,
 * ov = qd e_z, oa = (0, 0, qdd, 0, 0, g), J = e_z, dVdq = dAdq = dAdv = 0 */
KERNEL void fwd_root_revz(kin_state *RS K, dyn_state *RS D, const link_const *RS c,
                          double q, double qd, double qdd, double g, double *RS W)
{
    const double co = mg_cos(q), si = mg_sin(q);
    double *R = K->R;
    R[0] = co; R[1] = -si; R[2] = 0.0;
    R[3] = si; R[4] = co;  R[5] = 0.0;
    R[6] = 0.0; R[7] = 0.0; R[8] = 1.0;
    K->p[0] = K->p[1] = K->p[2] = 0.0;
    K->ov[0] = K->ov[1] = 0.0; K->ov[2] = qd; K->ov[3] = K->ov[4] = K->ov[5] = 0.0;
    K->oa[0] = K->oa[1] = 0.0; K->oa[2] = qdd; K->oa[3] = K->oa[4] = 0.0; K->oa[5] = g;
    {
        /* p = 0: I = d 1 + s r0 r0^T, h = hx r0, r0 = (co, si, 0) */
        const double hx = c->hx, m = c->m, s = c->s, d = c->d;
        const double h0 = hx * co, h1 = hx * si, sr0 = s * co, sr1 = s * si;
        const double I0 = d + sr0 * co, I1 = d + sr1 * si, I3 = sr0 * si;
        double n0, n1, n2, f0, f1;
        D->I[0] = I0; D->I[1] = I1; D->I[2] = d; D->I[3] = I3; D->I[4] = 0.0; D->I[5] = 0.0;
        D->h[0] = h0; D->h[1] = h1; D->h[2] = 0.0; D->m = m;
        /* oh = Y (0,0,qd,0,0,0) = (0, 0, d qd, -h x (0,0,qd)) */
        n0 = 0.0; n1 = 0.0; n2 = d * qd;
        f0 = -h1 * qd; f1 = h0 * qd;
        /* of = Y oa + ov x* oh, oa = (0,0,qdd,0,0,g) */
        (void)n0; (void)n1;
        D->f[0] = h1 * g;
        D->f[1] = -h0 * g;
        D->f[2] = d * qdd;
        D->f[3] = -h1 * qdd - qd * f1;
        D->f[4] = h0 * qdd + qd * f0;
        D->f[5] = m * g;
        /* A with w = (0,0,qd), u = 0, h2 = 0: P_c = w x I[:, c] */
        {
            const double P00 = -qd * I3, P01 = qd * I0, P10 = -qd * I1, P11 = qd * I3;
            D->A[0] = 2 * P00;
            D->A[4] = 2 * P11;
            D->A[8] = 0.0;
            D->A[1] = (P10 + P01) + n2; D->A[3] = (P10 + P01) - n2;
            D->A[2] = -n1; D->A[6] = n1;
            D->A[5] = n0; D->A[7] = -n0;
        }
        D->F[0] = f0; D->F[1] = f1; D->F[2] = 0.0;
    }
        W[0 * N] = 0 == 2 ? 1.0 : 0.0;
        W[(6 + 0) * N] = 0.0;
        W[(12 + 0) * N] = 0.0;
        W[(18 + 0) * N] = 0.0;
        W[1 * N] = 1 == 2 ? 1.0 : 0.0;
        W[(6 + 1) * N] = 0.0;
        W[(12 + 1) * N] = 0.0;
        W[(18 + 1) * N] = 0.0;
        W[2 * N] = 2 == 2 ? 1.0 : 0.0;
        W[(6 + 2) * N] = 0.0;
        W[(12 + 2) * N] = 0.0;
        W[(18 + 2) * N] = 0.0;
        W[3 * N] = 3 == 2 ? 1.0 : 0.0;
        W[(6 + 3) * N] = 0.0;
        W[(12 + 3) * N] = 0.0;
        W[(18 + 3) * N] = 0.0;
        W[4 * N] = 4 == 2 ? 1.0 : 0.0;
        W[(6 + 4) * N] = 0.0;
        W[(12 + 4) * N] = 0.0;
        W[(18 + 4) * N] = 0.0;
        W[5 * N] = 5 == 2 ? 1.0 : 0.0;
        W[(6 + 5) * N] = 0.0;
        W[(12 + 5) * N] = 0.0;
        W[(18 + 5) * N] = 0.0;
}
#endif

/* ---- backward kernel (no signature: J is a full 6-vector in E) ---- */
typedef struct {
    dyn_state c;        /* composite of the subtree */
#if ARTIC
    double IA[21];      /* the child's IA - U U^T / D, upper triangle row by row */
#endif
} comp_state;

KERNEL void bwd(const dyn_state *RS D, comp_state *RS C, int leaf, double *RS W)
{
    dyn_state *RS Y = &C->c;
    double J[6], dV[6], dA[6], dAv[6], x[6], y[6], t[3];
    if (leaf) {
        *Y = *D;
    } else {
            Y->I[0] += D->I[0];
            Y->I[1] += D->I[1];
            Y->I[2] += D->I[2];
            Y->I[3] += D->I[3];
            Y->I[4] += D->I[4];
            Y->I[5] += D->I[5];
            Y->h[0] += D->h[0];
            Y->h[1] += D->h[1];
            Y->h[2] += D->h[2];
        Y->m += D->m;
            Y->A[0] += D->A[0];
            Y->A[1] += D->A[1];
            Y->A[2] += D->A[2];
            Y->A[3] += D->A[3];
            Y->A[4] += D->A[4];
            Y->A[5] += D->A[5];
            Y->A[6] += D->A[6];
            Y->A[7] += D->A[7];
            Y->A[8] += D->A[8];
            Y->F[0] += D->F[0];
            Y->F[1] += D->F[1];
            Y->F[2] += D->F[2];
            Y->f[0] += D->f[0];
            Y->f[1] += D->f[1];
            Y->f[2] += D->f[2];
            Y->f[3] += D->f[3];
            Y->f[4] += D->f[4];
            Y->f[5] += D->f[5];
    }
        J[0] = W[0 * N];
        dA[0] = W[(6 + 0) * N];
        dV[0] = W[(12 + 0) * N];
        dAv[0] = W[(18 + 0) * N];
        J[1] = W[1 * N];
        dA[1] = W[(6 + 1) * N];
        dV[1] = W[(12 + 1) * N];
        dAv[1] = W[(18 + 1) * N];
        J[2] = W[2 * N];
        dA[2] = W[(6 + 2) * N];
        dV[2] = W[(12 + 2) * N];
        dAv[2] = W[(18 + 2) * N];
        J[3] = W[3 * N];
        dA[3] = W[(6 + 3) * N];
        dV[3] = W[(12 + 3) * N];
        dAv[3] = W[(18 + 3) * N];
        J[4] = W[4 * N];
        dA[4] = W[(6 + 4) * N];
        dV[4] = W[(12 + 4) * N];
        dAv[4] = W[(18 + 4) * N];
        J[5] = W[5 * N];
        dA[5] = W[(6 + 5) * N];
        dV[5] = W[(12 + 5) * N];
        dAv[5] = W[(18 + 5) * N];
    /* dFda = Yc J */
    ytimes(Y->I, Y->h, Y->m, J, x);
        W[(24 + 0) * N] = x[0];
        W[(24 + 1) * N] = x[1];
        W[(24 + 2) * N] = x[2];
        W[(24 + 3) * N] = x[3];
        W[(24 + 4) * N] = x[4];
        W[(24 + 5) * N] = x[5];
    /* dYtJ = A^T Jw + 2 F x Jv */
    cross3(Y->F, J + 3, t);
    W[30 * N] = Y->A[0] * J[0] + Y->A[3] * J[1] + Y->A[6] * J[2] + 2 * t[0];
    W[31 * N] = Y->A[1] * J[0] + Y->A[4] * J[1] + Y->A[7] * J[2] + 2 * t[1];
    W[32 * N] = Y->A[2] * J[0] + Y->A[5] * J[1] + Y->A[8] * J[2] + 2 * t[2];
    /* dFdq0 = doYc dVdq + Yc dAdq, dFdq = dFdq0 + J x* fc */
    dytimes(Y->A, Y->F, dV, x);
    ytimes(Y->I, Y->h, Y->m, dA, y);
        x[0] += y[0];
        x[1] += y[1];
        x[2] += y[2];
        x[3] += y[3];
        x[4] += y[4];
        x[5] += y[5];
        W[(33 + 0) * N] = x[0];
        W[(33 + 1) * N] = x[1];
        W[(33 + 2) * N] = x[2];
        W[(33 + 3) * N] = x[3];
        W[(33 + 4) * N] = x[4];
        W[(33 + 5) * N] = x[5];
    crf(J, Y->f, y);
        W[(39 + 0) * N] = x[0] + y[0];
        W[(39 + 1) * N] = x[1] + y[1];
        W[(39 + 2) * N] = x[2] + y[2];
        W[(39 + 3) * N] = x[3] + y[3];
        W[(39 + 4) * N] = x[4] + y[4];
        W[(39 + 5) * N] = x[5] + y[5];
    /* dFdv = doYc J + Yc dAdv */
    dytimes(Y->A, Y->F, J, x);
#ifdef PROTO_TWICE
    /* dAdv = 2 dVdq for a joint of one dof: Yc dAdv = 2 Yc dVdq */
    ytimes(Y->I, Y->h, Y->m, dV, y);
        W[(45 + 0) * N] = x[0] + 2 * y[0];
        W[(45 + 1) * N] = x[1] + 2 * y[1];
        W[(45 + 2) * N] = x[2] + 2 * y[2];
        W[(45 + 3) * N] = x[3] + 2 * y[3];
        W[(45 + 4) * N] = x[4] + 2 * y[4];
        W[(45 + 5) * N] = x[5] + 2 * y[5];
    (void)dAv;
#else
    ytimes(Y->I, Y->h, Y->m, dAv, y);
        W[(45 + 0) * N] = x[0] + y[0];
        W[(45 + 1) * N] = x[1] + y[1];
        W[(45 + 2) * N] = x[2] + y[2];
        W[(45 + 3) * N] = x[3] + y[3];
        W[(45 + 4) * N] = x[4] + y[4];
        W[(45 + 5) * N] = x[5] + y[5];
#endif
#if ARTIC
    {
        /* IA = sym6(Y own) + the child's; U = IA J, D = J.U */
        double A6[6][6], U[6], Uw[6], dd, inv;
        int c2, k;
        const double *I = D->I, *h = D->h;
        A6[0][0] = I[0]; A6[0][1] = I[3]; A6[0][2] = I[4];
        A6[1][1] = I[1]; A6[1][2] = I[5]; A6[2][2] = I[2];
        /* [[I, h x], [-(h x), m 1]] */
        A6[0][3] = 0.0;   A6[0][4] = -h[2]; A6[0][5] = h[1];
        A6[1][3] = h[2];  A6[1][4] = 0.0;   A6[1][5] = -h[0];
        A6[2][3] = -h[1]; A6[2][4] = h[0];  A6[2][5] = 0.0;
        A6[3][3] = D->m; A6[3][4] = 0.0; A6[3][5] = 0.0;
        A6[4][4] = D->m; A6[4][5] = 0.0; A6[5][5] = D->m;
        if (!leaf) {
            k = 0;
                _Pragma("GCC unroll 36")
                for (c2 = 0; c2 < 6; ++c2)
                    A6[0][c2] += C->IA[k++];
                _Pragma("GCC unroll 36")
                for (c2 = 1; c2 < 6; ++c2)
                    A6[1][c2] += C->IA[k++];
                _Pragma("GCC unroll 36")
                for (c2 = 2; c2 < 6; ++c2)
                    A6[2][c2] += C->IA[k++];
                _Pragma("GCC unroll 36")
                for (c2 = 3; c2 < 6; ++c2)
                    A6[3][c2] += C->IA[k++];
                _Pragma("GCC unroll 36")
                for (c2 = 4; c2 < 6; ++c2)
                    A6[4][c2] += C->IA[k++];
                _Pragma("GCC unroll 36")
                for (c2 = 5; c2 < 6; ++c2)
                    A6[5][c2] += C->IA[k++];
        }
            _Pragma("GCC unroll 36")
            for (c2 = 0; c2 < 0; ++c2)
                A6[0][c2] = A6[c2][0];
            _Pragma("GCC unroll 36")
            for (c2 = 0; c2 < 1; ++c2)
                A6[1][c2] = A6[c2][1];
            _Pragma("GCC unroll 36")
            for (c2 = 0; c2 < 2; ++c2)
                A6[2][c2] = A6[c2][2];
            _Pragma("GCC unroll 36")
            for (c2 = 0; c2 < 3; ++c2)
                A6[3][c2] = A6[c2][3];
            _Pragma("GCC unroll 36")
            for (c2 = 0; c2 < 4; ++c2)
                A6[4][c2] = A6[c2][4];
            _Pragma("GCC unroll 36")
            for (c2 = 0; c2 < 5; ++c2)
                A6[5][c2] = A6[c2][5];
            U[0] = A6[0][0] * J[0] + A6[0][1] * J[1] + A6[0][2] * J[2]
                   + A6[0][3] * J[3] + A6[0][4] * J[4] + A6[0][5] * J[5];
            U[1] = A6[1][0] * J[0] + A6[1][1] * J[1] + A6[1][2] * J[2]
                   + A6[1][3] * J[3] + A6[1][4] * J[4] + A6[1][5] * J[5];
            U[2] = A6[2][0] * J[0] + A6[2][1] * J[1] + A6[2][2] * J[2]
                   + A6[2][3] * J[3] + A6[2][4] * J[4] + A6[2][5] * J[5];
            U[3] = A6[3][0] * J[0] + A6[3][1] * J[1] + A6[3][2] * J[2]
                   + A6[3][3] * J[3] + A6[3][4] * J[4] + A6[3][5] * J[5];
            U[4] = A6[4][0] * J[0] + A6[4][1] * J[1] + A6[4][2] * J[2]
                   + A6[4][3] * J[3] + A6[4][4] * J[4] + A6[4][5] * J[5];
            U[5] = A6[5][0] * J[0] + A6[5][1] * J[1] + A6[5][2] * J[2]
                   + A6[5][3] * J[3] + A6[5][4] * J[4] + A6[5][5] * J[5];
        dd = J[0] * U[0] + J[1] * U[1] + J[2] * U[2] + J[3] * U[3] + J[4] * U[4]
             + J[5] * U[5];
        inv = 1 / dd;
            W[(51 + 0) * N] = U[0];
            W[(51 + 1) * N] = U[1];
            W[(51 + 2) * N] = U[2];
            W[(51 + 3) * N] = U[3];
            W[(51 + 4) * N] = U[4];
            W[(51 + 5) * N] = U[5];
        W[57 * N] = inv;
            Uw[0] = inv * U[0];
            Uw[1] = inv * U[1];
            Uw[2] = inv * U[2];
            Uw[3] = inv * U[3];
            Uw[4] = inv * U[4];
            Uw[5] = inv * U[5];
        k = 0;
            _Pragma("GCC unroll 36")
            for (c2 = 0; c2 < 6; ++c2)
                C->IA[k++] = A6[0][c2] - U[0] * Uw[c2];
            _Pragma("GCC unroll 36")
            for (c2 = 1; c2 < 6; ++c2)
                C->IA[k++] = A6[1][c2] - U[1] * Uw[c2];
            _Pragma("GCC unroll 36")
            for (c2 = 2; c2 < 6; ++c2)
                C->IA[k++] = A6[2][c2] - U[2] * Uw[c2];
            _Pragma("GCC unroll 36")
            for (c2 = 3; c2 < 6; ++c2)
                C->IA[k++] = A6[3][c2] - U[3] * Uw[c2];
            _Pragma("GCC unroll 36")
            for (c2 = 4; c2 < 6; ++c2)
                C->IA[k++] = A6[4][c2] - U[4] * Uw[c2];
            _Pragma("GCC unroll 36")
            for (c2 = 5; c2 < 6; ++c2)
                C->IA[k++] = A6[5][c2] - U[5] * Uw[c2];
    }
#endif
}


void proto_eval(const double *x, const double *a, double *W)
{
    dyn_state D[N];
    comp_state C;
    int i;
#ifdef PROTO_CARRY
    kin_state K[2];
#else
    kin_state K[N];
#endif
#ifdef PROTO_ROOT
    fwd_root_revz(&K[0], &D[0], &cst[0], x[0], x[N], a[0], grav, W);
#else
    {
        static const kin_state ground0 = {{1, 0, 0, 0, 1, 0, 0, 0, 1}, {0, 0, 0},
                                          {0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, 0, 0}};
        kin_state ground = ground0;
        ground.oa[5] = grav;
        fwd_revz(&ground, &K[0], &D[0], &cst[0], x[0], x[N], a[0], W);
    }
#endif
    for (i = 1; i < N; ++i) {
#ifdef PROTO_CARRY
        const kin_state *P = &K[(i - 1) & 1];
        kin_state *S = &K[i & 1];
#else
        const kin_state *P = &K[i - 1];
        kin_state *S = &K[i];
#endif
        if (i & 1)
            fwd_revy(P, S, &D[i], &cst[i], x[i], x[N + i], a[i], W + i);
        else
            fwd_revz(P, S, &D[i], &cst[i], x[i], x[N + i], a[i], W + i);
    }
    for (i = N - 1; i >= 0; --i)
        bwd(&D[i], &C, i == N - 1, W + i);
}

