/* Small fixed-size vector, matrix and quaternion helpers (header-only, inlined
 * into the hot loops). Matrices are row-major 3x3; a frame matrix holds the
 * frame's unit vectors as columns, so R*v maps frame coordinates to world. */
#ifndef LSS_MATH_H
#define LSS_MATH_H

#include <math.h>

static inline void v3_set(double *a, double x, double y, double z) { a[0] = x; a[1] = y; a[2] = z; }
static inline void v3_copy(double *a, const double *b) { a[0] = b[0]; a[1] = b[1]; a[2] = b[2]; }
static inline double v3_dot(const double *a, const double *b) { return a[0]*b[0] + a[1]*b[1] + a[2]*b[2]; }
static inline double v3_norm(const double *a) { return sqrt(v3_dot(a, a)); }
static inline void v3_add(double *r, const double *a, const double *b) { r[0] = a[0]+b[0]; r[1] = a[1]+b[1]; r[2] = a[2]+b[2]; }
static inline void v3_sub(double *r, const double *a, const double *b) { r[0] = a[0]-b[0]; r[1] = a[1]-b[1]; r[2] = a[2]-b[2]; }
static inline void v3_scale(double *r, const double *a, double s) { r[0] = a[0]*s; r[1] = a[1]*s; r[2] = a[2]*s; }
static inline void v3_axpy(double *r, double s, const double *a) { r[0] += s*a[0]; r[1] += s*a[1]; r[2] += s*a[2]; }
static inline void v3_cross(double *r, const double *a, const double *b) {
    double x = a[1]*b[2] - a[2]*b[1], y = a[2]*b[0] - a[0]*b[2], z = a[0]*b[1] - a[1]*b[0];
    r[0] = x; r[1] = y; r[2] = z;
}
static inline void m3_mulv(double *r, const double *M, const double *v) {
    double x = M[0]*v[0] + M[1]*v[1] + M[2]*v[2];
    double y = M[3]*v[0] + M[4]*v[1] + M[5]*v[2];
    double z = M[6]*v[0] + M[7]*v[1] + M[8]*v[2];
    r[0] = x; r[1] = y; r[2] = z;
}
/* r = M^T v */
static inline void m3_tmulv(double *r, const double *M, const double *v) {
    double x = M[0]*v[0] + M[3]*v[1] + M[6]*v[2];
    double y = M[1]*v[0] + M[4]*v[1] + M[7]*v[2];
    double z = M[2]*v[0] + M[5]*v[1] + M[8]*v[2];
    r[0] = x; r[1] = y; r[2] = z;
}
static inline void m3_mul(double *R, const double *A, const double *B) {
    double T[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            T[3*i+j] = A[3*i]*B[j] + A[3*i+1]*B[3+j] + A[3*i+2]*B[6+j];
    for (int k = 0; k < 9; k++) R[k] = T[k];
}
/* R = A^T B */
static inline void m3_tmul(double *R, const double *A, const double *B) {
    double T[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            T[3*i+j] = A[i]*B[j] + A[3+i]*B[3+j] + A[6+i]*B[6+j];
    for (int k = 0; k < 9; k++) R[k] = T[k];
}
static inline void m3_identity(double *R) {
    for (int k = 0; k < 9; k++) R[k] = (k % 4 == 0) ? 1.0 : 0.0;
}
static inline void m3_col(double *c, const double *R, int j) { c[0] = R[j]; c[1] = R[3+j]; c[2] = R[6+j]; }

/* Rotation matrix of the unit quaternion q = (w, x, y, z); q need not be
 * exactly unit: it is normalised here so that drift never scales the body. */
static inline void quat_to_m3(double *R, const double *q) {
    double n2 = q[0]*q[0] + q[1]*q[1] + q[2]*q[2] + q[3]*q[3];
    double s = 2.0 / n2;
    double w = q[0], x = q[1], y = q[2], z = q[3];
    R[0] = 1 - s*(y*y + z*z); R[1] = s*(x*y - w*z);     R[2] = s*(x*z + w*y);
    R[3] = s*(x*y + w*z);     R[4] = 1 - s*(x*x + z*z); R[5] = s*(y*z - w*x);
    R[6] = s*(x*z - w*y);     R[7] = s*(y*z + w*x);     R[8] = 1 - s*(x*x + y*y);
}

/* Quaternion of a proper rotation matrix (Shepperd's method). */
static inline void m3_to_quat(double *q, const double *R) {
    double tr = R[0] + R[4] + R[8];
    if (tr > 0) {
        double s = sqrt(tr + 1.0) * 2;
        q[0] = 0.25 * s; q[1] = (R[7] - R[5]) / s; q[2] = (R[2] - R[6]) / s; q[3] = (R[3] - R[1]) / s;
    } else if (R[0] > R[4] && R[0] > R[8]) {
        double s = sqrt(1.0 + R[0] - R[4] - R[8]) * 2;
        q[0] = (R[7] - R[5]) / s; q[1] = 0.25 * s; q[2] = (R[1] + R[3]) / s; q[3] = (R[2] + R[6]) / s;
    } else if (R[4] > R[8]) {
        double s = sqrt(1.0 + R[4] - R[0] - R[8]) * 2;
        q[0] = (R[2] - R[6]) / s; q[1] = (R[1] + R[3]) / s; q[2] = 0.25 * s; q[3] = (R[5] + R[7]) / s;
    } else {
        double s = sqrt(1.0 + R[8] - R[0] - R[4]) * 2;
        q[0] = (R[3] - R[1]) / s; q[1] = (R[2] + R[6]) / s; q[2] = (R[5] + R[7]) / s; q[3] = 0.25 * s;
    }
}

#endif
