/* Prototype: the 20-link chain's inverse dynamics as loops over the joints with one
 * inline kernel per joint signature (root about z, joints about z, joints about y),
 * link frames (Featherstone Table 5.1), per-joint constants in a table T[j][6]:
 * r_x (joint origin along the parent's x), m, h_x = m c_x, Ixx, Iyy, Izz (inertia
 * about the joint origin; the chain's zero entries folded into the signature). */
#include "trig.h"
#define NJ 20
enum { RX, M, HX, IXX, IYY, IZZ };

/* f = I a + v x* (I v) for the folded inertia (h = (hx,0,0), I_O diagonal) */
static MG_ALWAYS_INLINE void link_force(const double *t, const double *v, const double *a, double *f)
{
    const double m = t[M], hx = t[HX], ix = t[IXX], iy = t[IYY], iz = t[IZZ];
    /* I [w; u] = [I_O w + h x u; m u - h x w], h x u = (0, -hx u2, hx u1) */
    double Iv[6], Ia[6];
    Iv[0] = ix * v[0];              Iv[1] = iy * v[1] - hx * v[5];  Iv[2] = iz * v[2] + hx * v[4];
    Iv[3] = m * v[3];               Iv[4] = m * v[4] + hx * v[2];   Iv[5] = m * v[5] - hx * v[1];
    Ia[0] = ix * a[0];              Ia[1] = iy * a[1] - hx * a[5];  Ia[2] = iz * a[2] + hx * a[4];
    Ia[3] = m * a[3];               Ia[4] = m * a[4] + hx * a[2];   Ia[5] = m * a[5] - hx * a[1];
    /* crf(v) p = [w x n + u x f; w x f] */
    f[0] = Ia[0] + v[1] * Iv[2] - v[2] * Iv[1] + v[4] * Iv[5] - v[5] * Iv[4];
    f[1] = Ia[1] + v[2] * Iv[0] - v[0] * Iv[2] + v[5] * Iv[3] - v[3] * Iv[5];
    f[2] = Ia[2] + v[0] * Iv[1] - v[1] * Iv[0] + v[3] * Iv[4] - v[4] * Iv[3];
    f[3] = Ia[3] + v[1] * Iv[5] - v[2] * Iv[4];
    f[4] = Ia[4] + v[2] * Iv[3] - v[0] * Iv[5];
    f[5] = Ia[5] + v[0] * Iv[4] - v[1] * Iv[3];
}

/* joint about z (axis 3) at (rx, 0, 0) of the parent: X m = [E w; E (u - r x w)],
 * r x w = (0, -rx w2, rx w1); E = Rz(q)^T */
static MG_ALWAYS_INLINE void forward_z(const double *t, double c, double s, double qd, double qdd,
                                       const double *vp, const double *ap, double *v, double *a, double *f)
{
    const double rx = t[RX];
    const double u1 = vp[4] + rx * vp[2], u2 = vp[5] - rx * vp[1];
    const double b1 = ap[4] + rx * ap[2], b2 = ap[5] - rx * ap[1];
    v[0] = c * vp[0] + s * vp[1]; v[1] = -s * vp[0] + c * vp[1]; v[2] = vp[2] + qd;
    v[3] = c * vp[3] + s * u1;    v[4] = -s * vp[3] + c * u1;    v[5] = u2;
    /* a = X a_p + S qdd + v x S qd: [w x ez qd; u x ez qd] = [(w1, -w0, 0) qd; (u1, -u0, 0) qd] */
    a[0] = c * ap[0] + s * ap[1] + v[1] * qd; a[1] = -s * ap[0] + c * ap[1] - v[0] * qd;
    a[2] = ap[2] + qdd;
    a[3] = c * ap[3] + s * b1 + v[4] * qd;    a[4] = -s * ap[3] + c * b1 - v[3] * qd;
    a[5] = b2;
    link_force(t, v, a, f);
}

/* joint about y: E = Ry(q)^T: E w = (c w0 - s w2, w1, s w0 + c w2); v x ey qd = [(-w2, 0, w0) qd; (-u2, 0, u0) qd] */
static MG_ALWAYS_INLINE void forward_y(const double *t, double c, double s, double qd, double qdd,
                                       const double *vp, const double *ap, double *v, double *a, double *f)
{
    const double rx = t[RX];
    const double u1 = vp[4] + rx * vp[2], u2 = vp[5] - rx * vp[1];
    const double b1 = ap[4] + rx * ap[2], b2 = ap[5] - rx * ap[1];
    v[0] = c * vp[0] - s * vp[2]; v[1] = vp[1] + qd; v[2] = s * vp[0] + c * vp[2];
    v[3] = c * vp[3] - s * u2;    v[4] = u1;         v[5] = s * vp[3] + c * u2;
    a[0] = c * ap[0] - s * ap[2] - v[2] * qd; a[1] = ap[1] + qdd; a[2] = s * ap[0] + c * ap[2] + v[0] * qd;
    a[3] = c * ap[3] - s * b2 - v[5] * qd;    a[4] = b1;          a[5] = s * ap[3] + c * b2 + v[3] * qd;
    link_force(t, v, a, f);
}

/* the root about z at the ground's origin, v_p = 0, a_p = (0,0,0, 0,0,g) */
static MG_ALWAYS_INLINE void forward_root(const double *t, double g, double c, double s, double qd, double qdd,
                                          double *v, double *a, double *f)
{
    v[0] = 0; v[1] = 0; v[2] = qd; v[3] = 0; v[4] = 0; v[5] = 0;
    a[0] = 0; a[1] = 0; a[2] = qdd; a[3] = 0; a[4] = 0; a[5] = g;
    (void)c; (void)s;
    link_force(t, v, a, f);
}

/* X^T f into the parent: [E^T n + r x E^T f; E^T f], r x y = (0, -rx y2, rx y1) */
static MG_ALWAYS_INLINE void back_z(const double *t, double c, double s, const double *f, double *fp)
{
    const double rx = t[RX];
    const double n0 = c * f[0] - s * f[1], n1 = s * f[0] + c * f[1];
    const double y0 = c * f[3] - s * f[4], y1 = s * f[3] + c * f[4], y2 = f[5];
    fp[0] += n0; fp[1] += n1 - rx * y2; fp[2] += f[2] + rx * y1;
    fp[3] += y0; fp[4] += y1; fp[5] += y2;
}

static MG_ALWAYS_INLINE void back_y(const double *t, double c, double s, const double *f, double *fp)
{
    const double rx = t[RX];
    const double n0 = c * f[0] + s * f[2], n2 = -s * f[0] + c * f[2];
    const double y0 = c * f[3] + s * f[5], y1 = f[4], y2 = -s * f[3] + c * f[5];
    fp[0] += n0; fp[1] += f[1] - rx * y2; fp[2] += n2 + rx * y1;
    fp[3] += y0; fp[4] += y1; fp[5] += y2;
}

static const int sig[NJ] = {0, 2, 1, 2, 1, 2, 1, 2, 1, 2, 1, 2, 1, 2, 1, 2, 1, 2, 1, 2};
static const int parent[NJ] = {-1, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18};

/* the table from the parameters m1..m20, l1..l20, r, g */
static void fill(const double *p, double *T)
{
    int j;
    for (j = 0; j < NJ; ++j) {
        const double m = p[j], l = p[NJ + j], r = p[2 * NJ];
        double *t = T + 6 * j;
        const double mr2 = m * (r * r);
        t[RX] = j ? p[NJ + j - 1] : 0.0;
        t[M] = m; t[HX] = 0.5 * m * l;
        t[IXX] = 0.5 * mr2;
        t[IYY] = t[IZZ] = t[HX] * l * (2.0 / 3.0) + 0.25 * mr2;
    }
}

void id_loop(const double *x, const double *qdd, const double *p, double *Q)
{
    double T[6 * NJ], F[6 * NJ], cs[2 * NJ];
    double v0[6], a0[6], v1[6], a1[6];
    int j;
    fill(p, T);
    for (j = 0; j < NJ; ++j) { cs[2 * j] = mg_cos(x[j]); cs[2 * j + 1] = mg_sin(x[j]); }
    forward_root(T, p[2 * NJ + 1], cs[0], cs[1], x[NJ], qdd[0], v0, a0, F);
    /* the chain's period of signatures (y, z) in one body: the state carried in locals */
    for (j = 1; j + 1 < NJ; j += 2) {
        forward_y(T + 6 * j, cs[2 * j], cs[2 * j + 1], x[NJ + j], qdd[j], v0, a0, v1, a1, F + 6 * j);
        forward_z(T + 6 * (j + 1), cs[2 * j + 2], cs[2 * j + 3], x[NJ + j + 1], qdd[j + 1], v1, a1, v0, a0, F + 6 * (j + 1));
    }
    forward_y(T + 6 * j, cs[2 * j], cs[2 * j + 1], x[NJ + j], qdd[j], v0, a0, v1, a1, F + 6 * j);
    {
        /* inwards, the subtree's force carried in locals: j = 19 (y), then pairs (z, y) */
        double Fc[6], i;
        (void)i;
        for (int c = 0; c < 6; ++c) Fc[c] = F[6 * (NJ - 1) + c];
        j = NJ - 1;
        Q[j] = Fc[1];
        back_y(T + 6 * j, cs[2 * j], cs[2 * j + 1], Fc, F + 6 * (j - 1));
        for (j = NJ - 2; j >= 2; j -= 2) {
            const double *fz = F + 6 * j, *fy = F + 6 * (j - 1);
            Q[j] = fz[2];
            back_z(T + 6 * j, cs[2 * j], cs[2 * j + 1], fz, F + 6 * (j - 1));
            Q[j - 1] = fy[1];
            back_y(T + 6 * (j - 1), cs[2 * j - 2], cs[2 * j - 1], fy, F + 6 * (j - 2));
        }
        Q[0] = F[2];
    }
}
