/* 4x4 double matrices in the OpenEXR/Imath layout: row-major, row vectors
 * (p' = p . M), translation in m[12..14]. */
#ifndef EF_MAT4_H
#define EF_MAT4_H

typedef struct ef_mat4 { double m[16]; } ef_mat4;

/* out = a . b (apply a first, then b, to a row vector). out may alias a or b. */
void ef_mat4_mul(const ef_mat4 *a, const ef_mat4 *b, ef_mat4 *out);

/* Inverts a by Gaussian elimination with partial pivoting in long double.
 * Returns 0, or -1 when a is singular or holds a non-finite value. */
int ef_mat4_invert(const ef_mat4 *a, ef_mat4 *out);

/* out = (p, w) . M, all four homogeneous components. */
void ef_mat4_apply(const ef_mat4 *M, const double p[3], double w, double out[4]);

/* 1 when every entry is finite. */
int ef_mat4_finite(const ef_mat4 *a);

#endif
