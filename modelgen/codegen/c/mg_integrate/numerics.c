/* Part of mg_integrate.c (included there, not compiled alone): the numerics every
 * method shares and that know nothing of the system: vector helpers, LU
 * factorization, and the dense output's nested polynomial form. */

#define MG_UROUND 2.220446049250313e-16

static int mg_finite(const double *v, int n)
{
    int i;
    for (i = 0; i < n; ++i)
        if (!(v[i] - v[i] == 0.0)) /* NaN or infinity */
            return 0;
    return 1;
}

static void mg_copy(double *dst, const double *src, int n)
{
    int i;
    for (i = 0; i < n; ++i)
        dst[i] = src[i];
}

static double mg_clamp(double v, double lo, double hi)
{
    return v < lo ? lo : (v > hi ? hi : v);
}

/* LU factorization with partial pivoting of the n x n row-major M, in place.
 * Returns 0, or 1 when a pivot is not finite or below 16 eps max |M_ij|
 * (singular to working precision). */
static int mg_lu(double *M, int n, double *piv)
{
    double scale = 0.0;
    int i, j, k;
    for (i = 0; i < n * n; ++i)
        scale = fabs(M[i]) > scale ? fabs(M[i]) : scale;
    for (k = 0; k < n; ++k) {
        int r = k;
        double big = fabs(M[k * n + k]);
        for (i = k + 1; i < n; ++i)
            if (fabs(M[i * n + k]) > big) {
                big = fabs(M[i * n + k]);
                r = i;
            }
        piv[k] = (double)r;
        if (!(big > 16.0 * MG_UROUND * scale) || !(big - big == 0.0))
            return 1;
        if (r != k)
            for (j = 0; j < n; ++j) {
                const double tmp = M[k * n + j];
                M[k * n + j] = M[r * n + j];
                M[r * n + j] = tmp;
            }
        for (i = k + 1; i < n; ++i) {
            const double l = M[i * n + k] / M[k * n + k];
            M[i * n + k] = l;
            if (l != 0.0)
                for (j = k + 1; j < n; ++j)
                    M[i * n + j] -= l * M[k * n + j];
        }
    }
    return 0;
}

/* Solves M y = b with the factors of mg_lu; y overwrites b. */
static void mg_lu_solve(const double *M, int n, const double *piv, double *b)
{
    int i, j;
    for (i = 0; i < n; ++i) {
        const int r = (int)piv[i];
        if (r != i) {
            const double tmp = b[i];
            b[i] = b[r];
            b[r] = tmp;
        }
    }
    for (i = 1; i < n; ++i) {
        double s = b[i];
        for (j = 0; j < i; ++j)
            s -= M[i * n + j] * b[j];
        b[i] = s;
    }
    for (i = n - 1; i >= 0; --i) {
        double s = b[i];
        for (j = i + 1; j < n; ++j)
            s -= M[i * n + j] * b[j];
        b[i] = s / M[i * n + i];
    }
}

/* Dense output x(t_old + s h) = c0 + s (c1 + (1-s) (c2 + s (c3 + (1-s) (...))))
 * from m coefficient vectors cont[k * NX ...] (Hairer's nested form). */
static void mg_dense(int nx, const double *cont, int m, double s, double *x)
{
    const double s1 = 1.0 - s;
    int i, k;
    for (i = 0; i < nx; ++i) {
        double v = cont[(m - 1) * nx + i];
        for (k = m - 1; k >= 1; --k)
            v = cont[(k - 1) * nx + i] + ((k & 1) ? s : s1) * v;
        x[i] = v;
    }
}

/* Cubic Hermite interpolant of x, xdot at both ends, in the same nested form. */
static void mg_hermite(int nx, const double *x0, const double *x1, const double *f0,
                       const double *f1, double h, double *cont)
{
    int i;
    for (i = 0; i < nx; ++i) {
        const double dx = x1[i] - x0[i], b = h * f0[i] - dx;
        cont[i] = x0[i];
        cont[nx + i] = dx;
        cont[2 * nx + i] = b;
        cont[3 * nx + i] = dx - h * f1[i] - b;
    }
}
