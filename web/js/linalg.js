// Small dense linear algebra for 3x3 covariances and 4x4 column-major model matrices.
// Matrices 3x3 are arrays of rows: [[a, b, c], [d, e, f], [g, h, i]].

/** Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations.
 *  Returns {values: [l0, l1, l2] descending, vectors: [v0, v1, v2] (unit, right-handed)}. */
export function eigSym3(m) {
  const a = m.map((r) => r.slice());
  const v = [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
  for (let sweep = 0; sweep < 50; sweep++) {
    const off = a[0][1] ** 2 + a[0][2] ** 2 + a[1][2] ** 2;
    const scale = a[0][0] ** 2 + a[1][1] ** 2 + a[2][2] ** 2;
    if (off <= 1e-30 * scale || off === 0) break;
    for (const [p, q] of [[0, 1], [0, 2], [1, 2]]) {
      if (a[p][q] === 0) continue;
      const theta = (a[q][q] - a[p][p]) / (2 * a[p][q]);
      const t = Math.sign(theta || 1) / (Math.abs(theta) + Math.sqrt(theta * theta + 1));
      const c = 1 / Math.sqrt(t * t + 1);
      const s = t * c;
      for (let k = 0; k < 3; k++) { // A <- A J
        const akp = a[k][p], akq = a[k][q];
        a[k][p] = c * akp - s * akq;
        a[k][q] = s * akp + c * akq;
      }
      for (let k = 0; k < 3; k++) { // A <- J^T A
        const apk = a[p][k], aqk = a[q][k];
        a[p][k] = c * apk - s * aqk;
        a[q][k] = s * apk + c * aqk;
      }
      for (let k = 0; k < 3; k++) { // V <- V J
        const vkp = v[k][p], vkq = v[k][q];
        v[k][p] = c * vkp - s * vkq;
        v[k][q] = s * vkp + c * vkq;
      }
    }
  }
  const order = [0, 1, 2].sort((i, j) => a[j][j] - a[i][i]);
  const values = order.map((i) => a[i][i]);
  const vectors = order.map((i) => [v[0][i], v[1][i], v[2][i]]);
  const c = cross(vectors[0], vectors[1]);
  if (dot(c, vectors[2]) < 0) vectors[2] = vectors[2].map((x) => -x);
  return { values, vectors };
}

export function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
export function cross(a, b) {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}
export function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
export function add(a, b) { return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]; }
export function scale(a, s) { return [a[0] * s, a[1] * s, a[2] * s]; }
export function norm(a) { return Math.sqrt(dot(a, a)); }

/** 4x4 column-major (16 numbers) applied to a point. */
export function applyPoint(m, p) {
  return [m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12],
    m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13],
    m[2] * p[0] + m[6] * p[1] + m[10] * p[2] + m[14]];
}

/** Linear part of a 4x4 column-major matrix applied to a direction (not normalised). */
export function applyDirection(m, d) {
  return [m[0] * d[0] + m[4] * d[1] + m[8] * d[2],
    m[1] * d[0] + m[5] * d[1] + m[9] * d[2],
    m[2] * d[0] + m[6] * d[1] + m[10] * d[2]];
}

/** L C L^T for the linear part L of a column-major 4x4 and a 3x3 covariance C (rows). */
export function transformCovariance(m, c) {
  const l = [[m[0], m[4], m[8]], [m[1], m[5], m[9]], [m[2], m[6], m[10]]];
  const lc = l.map((row) => [0, 1, 2].map((j) => row[0] * c[0][j] + row[1] * c[1][j] + row[2] * c[2][j]));
  return lc.map((row) => [0, 1, 2].map((j) => row[0] * l[j][0] + row[1] * l[j][1] + row[2] * l[j][2]));
}

export const IDENTITY16 = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
