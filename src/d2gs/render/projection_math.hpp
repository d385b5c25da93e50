#pragma once
// Per-Gaussian projection math (EWA splatting, method.md §2), forward and vector-Jacobian product.
// Templated on the scalar type (float for rendering, double for the finite-difference checks) and
// marked D2GS_HD so the CUDA kernels can call it unchanged; C++17, no std:: calls.
//
// Conventions (those of the original 3DGS rasterizer "diff-gaussian-rasterization"):
//  - camera space = OpenCV axes (x right, y down, z forward), p_cam = R_world_to_cam * x + t;
//  - a Gaussian is culled when p_cam.z <= 0.2 (near plane);
//  - Sigma3 = R(q) S S^T R(q)^T with S = diag(exp(log_scale)), q = (w,x,y,z) normalised here;
//  - Sigma2 = J W Sigma3 W^T J^T + 0.3 I, W = R_world_to_cam, J the perspective Jacobian evaluated at
//    x/z, y/z clamped to the gsplat general-principal-point limits (equal to +-1.3 tan(fov/2) when
//    cx = W/2, as in the original);
//  - conic = Sigma2^-1 stored as (a, b, c) = (Q00, Q01, Q11);
//  - radius = ceil(3 sqrt(lambda_max)), lambda_max = mid + sqrt(max(0.1, mid^2 - det));
//  - mean2d is in the original's pixel frame: pixel (i, j) is evaluated at the integer point (i, j),
//    i.e. mean2d = (fx x/z + cx - 0.5, fy y/z + cy - 0.5) for d2gs's cx, cy (pixel centres at +0.5).
#include <math.h>

#include "d2gs/core/host_device.hpp"

namespace d2gs::render {

// ---- scalar helpers with float and double overloads (device-safe) ----
D2GS_HD float hd_sqrt(float x) { return sqrtf(x); }
D2GS_HD double hd_sqrt(double x) { return sqrt(x); }
D2GS_HD float hd_exp(float x) { return expf(x); }
D2GS_HD double hd_exp(double x) { return exp(x); }
D2GS_HD float hd_log(float x) { return logf(x); }
D2GS_HD double hd_log(double x) { return log(x); }
D2GS_HD float hd_ceil(float x) { return ceilf(x); }
D2GS_HD double hd_ceil(double x) { return ceil(x); }
D2GS_HD float hd_floor(float x) { return floorf(x); }
D2GS_HD double hd_floor(double x) { return floor(x); }
template <typename T> D2GS_HD T hd_min(T a, T b) { return a < b ? a : b; }
template <typename T> D2GS_HD T hd_max(T a, T b) { return a > b ? a : b; }
// c ? a : b with both sides evaluated (the VJP's form, so that a SIMD scalar type can give it lane masks).
template <typename T> D2GS_HD T hd_select(bool c, T a, T b) { return c ? a : b; }

// The type of a per-Gaussian flag in ProjectionState<T>: bool, or a lane mask where the CPU backend
// runs the VJP on a SIMD type (cpu/projection.cpp).
template <typename T>
struct StateFlag {
  using type = bool;
};

inline constexpr int kTileSize = 16;        // 16 x 16 pixel tiles
inline constexpr double kNearPlane = 0.2;   // cull when view-space z <= 0.2
inline constexpr double kCov2dBlur = 0.3;   // added to the 2D covariance diagonal
inline constexpr double kMinQuatNorm = 1e-12;

// Camera as the kernels see it (built from d2gs::Camera by make_render_camera in rasterizer.hpp).
template <typename T>
struct CameraParams {
  int width = 0, height = 0;
  T R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // world -> camera rotation, row-major
  T t[3] = {0, 0, 0};                    // world -> camera translation
  T campos[3] = {0, 0, 0};               // camera centre in world space (for SH view directions)
  T fx = 1, fy = 1, cx = 0, cy = 0;      // d2gs convention: pixel centres at integer + 0.5
  // Jacobian clamp on x/z and y/z: [-lim_x_neg, lim_x_pos] etc. (gsplat's general form).
  T lim_x_neg = 1, lim_x_pos = 1, lim_y_neg = 1, lim_y_pos = 1;
};

template <typename T>
D2GS_HD void set_jacobian_limits(CameraParams<T>& cam) {
  const T tan_fovx = T(0.5) * T(cam.width) / cam.fx;
  const T tan_fovy = T(0.5) * T(cam.height) / cam.fy;
  cam.lim_x_pos = (T(cam.width) - cam.cx) / cam.fx + T(0.3) * tan_fovx;
  cam.lim_x_neg = cam.cx / cam.fx + T(0.3) * tan_fovx;
  cam.lim_y_pos = (T(cam.height) - cam.cy) / cam.fy + T(0.3) * tan_fovy;
  cam.lim_y_neg = cam.cy / cam.fy + T(0.3) * tan_fovy;
}

// Rotation matrix (row-major) of a unit quaternion (w, x, y, z).
template <typename T>
D2GS_HD void quat_to_rotmat(const T q[4], T m[9]) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  m[0] = T(1) - T(2) * (y * y + z * z);
  m[1] = T(2) * (x * y - w * z);
  m[2] = T(2) * (x * z + w * y);
  m[3] = T(2) * (x * y + w * z);
  m[4] = T(1) - T(2) * (x * x + z * z);
  m[5] = T(2) * (y * z - w * x);
  m[6] = T(2) * (x * z - w * y);
  m[7] = T(2) * (y * z + w * x);
  m[8] = T(1) - T(2) * (x * x + y * y);
}

// d(loss)/d(q) for a unit quaternion q given d(loss)/d(rotmat) (row-major).
template <typename T>
D2GS_HD void quat_to_rotmat_vjp(const T q[4], const T d[9], T dq[4]) {
  const T w = q[0], x = q[1], y = q[2], z = q[3];
  dq[0] = T(2) * (-z * d[1] + y * d[2] + z * d[3] - x * d[5] - y * d[6] + x * d[7]);
  dq[1] = T(2) * (y * d[1] + z * d[2] + y * d[3] - T(2) * x * d[4] - w * d[5] + z * d[6] + w * d[7] -
                  T(2) * x * d[8]);
  dq[2] = T(2) * (-T(2) * y * d[0] + x * d[1] + w * d[2] + x * d[3] + z * d[5] - w * d[6] + z * d[7] -
                  T(2) * y * d[8]);
  dq[3] = T(2) * (-T(2) * z * d[0] - w * d[1] + x * d[2] + w * d[3] - T(2) * z * d[4] + y * d[5] +
                  x * d[6] + y * d[7]);
}

// q / max(|q|, 1e-12) (torch.nn.functional.normalize, as the original's rotation activation).
template <typename T>
D2GS_HD T normalize_quat(const T q[4], T qn[4]) {
  const T norm = hd_max(hd_sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), T(kMinQuatNorm));
  const T inv = T(1) / norm;
  for (int k = 0; k < 4; ++k) qn[k] = q[k] * inv;
  return norm;
}

// Sigma3 = M M^T with M = R(q) diag(exp(s)); full symmetric 3x3, row-major. Also returns M, R, qn and
// the scales s = exp(log_scale).
template <typename T>
D2GS_HD void covariance3d(const T log_scale[3], const T quat[4], T sigma[9], T M[9], T Rq[9], T qn[4],
                          T& qnorm, T s[3]) {
  qnorm = normalize_quat(quat, qn);
  quat_to_rotmat(qn, Rq);
  for (int j = 0; j < 3; ++j) s[j] = hd_exp(log_scale[j]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) M[i * 3 + j] = Rq[i * 3 + j] * s[j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      sigma[i * 3 + j] = M[i * 3 + 0] * M[j * 3 + 0] + M[i * 3 + 1] * M[j * 3 + 1] + M[i * 3 + 2] * M[j * 3 + 2];
}

// Intermediate values of one projection, kept so the VJP needs no second pass (the CPU backend keeps
// the forward's; the CUDA kernels recompute them).
template <typename T>
struct ProjectionState {
  T pc[3];          // camera-space mean
  T u, v;           // clamped x/z, y/z
  typename StateFlag<T>::type u_free, v_free;  // not clamped: the Jacobian depends on x/z, y/z
  T A[6];           // J W, 2x3 row-major
  T sigma[9], M[9], Rq[9], qn[4], qnorm;
  T s[3];           // exp(log_scale)
  T cov2[3];        // (a, b, c) of Sigma2 including the +0.3
};

// Projects one Gaussian. Returns false (culled) behind the near plane or for a singular Sigma2.
template <typename T>
D2GS_HD bool project_gaussian(const T mean[3], const T log_scale[3], const T quat[4], const CameraParams<T>& cam,
                              T mean2d[2], T conic[3], T& depth, int& radius, ProjectionState<T>& st) {
  const T* R = cam.R;
  for (int i = 0; i < 3; ++i)
    st.pc[i] = R[i * 3 + 0] * mean[0] + R[i * 3 + 1] * mean[1] + R[i * 3 + 2] * mean[2] + cam.t[i];
  const T z = st.pc[2];
  if (!(z > T(kNearPlane))) return false;
  covariance3d(log_scale, quat, st.sigma, st.M, st.Rq, st.qn, st.qnorm, st.s);
  const T inv_z = T(1) / z;
  const T u_raw = st.pc[0] * inv_z, v_raw = st.pc[1] * inv_z;
  st.u_free = u_raw >= -cam.lim_x_neg && u_raw <= cam.lim_x_pos;
  st.v_free = v_raw >= -cam.lim_y_neg && v_raw <= cam.lim_y_pos;
  st.u = hd_min(cam.lim_x_pos, hd_max(-cam.lim_x_neg, u_raw));
  st.v = hd_min(cam.lim_y_pos, hd_max(-cam.lim_y_neg, v_raw));
  // A = J W with J = [[fx/z, 0, -fx u/z], [0, fy/z, -fy v/z]].
  const T jx = cam.fx * inv_z, jy = cam.fy * inv_z;
  for (int k = 0; k < 3; ++k) {
    st.A[k] = jx * (R[k] - st.u * R[6 + k]);
    st.A[3 + k] = jy * (R[3 + k] - st.v * R[6 + k]);
  }
  // Sigma2 = A Sigma3 A^T.
  T AS[6];
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 3; ++k)
      AS[r * 3 + k] = st.A[r * 3 + 0] * st.sigma[0 * 3 + k] + st.A[r * 3 + 1] * st.sigma[1 * 3 + k] +
                      st.A[r * 3 + 2] * st.sigma[2 * 3 + k];
  const T a = AS[0] * st.A[0] + AS[1] * st.A[1] + AS[2] * st.A[2] + T(kCov2dBlur);
  const T b = AS[0] * st.A[3] + AS[1] * st.A[4] + AS[2] * st.A[5];
  const T c = AS[3] * st.A[3] + AS[4] * st.A[4] + AS[5] * st.A[5] + T(kCov2dBlur);
  st.cov2[0] = a; st.cov2[1] = b; st.cov2[2] = c;
  const T det = a * c - b * b;
  if (!(det > T(0))) return false;
  const T inv_det = T(1) / det;
  conic[0] = c * inv_det;
  conic[1] = -b * inv_det;
  conic[2] = a * inv_det;
  const T mid = T(0.5) * (a + c);
  const T lambda_max = mid + hd_sqrt(hd_max(T(0.1), mid * mid - det));
  // Capped far beyond any image (2^24 px) so that a huge (or infinite) extent converts to int defined.
  radius = int(hd_min(hd_ceil(T(3) * hd_sqrt(lambda_max)), T(16777216)));
  mean2d[0] = cam.fx * st.pc[0] * inv_z + cam.cx - T(0.5);
  mean2d[1] = cam.fy * st.pc[1] * inv_z + cam.cy - T(0.5);
  depth = z;
  return true;
}

// VJP of project_gaussian (for a Gaussian it did not cull, given the state it filled): accumulates into
// d_mean, d_log_scale, d_quat (+=) from d(loss)/d(mean2d), d(loss)/d(conic (a,b,c)) and d(loss)/d(depth).
// Exact derivative of the forward above, including the Jacobian clamp (a clamped x/z contributes no
// gradient through x/z; its 1/z factor still does).
template <typename T>
D2GS_HD void project_gaussian_vjp(const T mean[3], const T log_scale[3], const T quat[4],
                                  const CameraParams<T>& cam, const ProjectionState<T>& st,
                                  const T conic[3], const T d_mean2d[2], const T d_conic[3], T d_depth,
                                  T d_mean[3], T d_log_scale[3], T d_quat[4]) {
  (void)mean;
  (void)log_scale;
  const T* R = cam.R;
  const T z = st.pc[2], inv_z = T(1) / z;
  // conic = Sigma2^-1: dS = -Q G Q with G the matrix form of d_conic (off-diagonal halves).
  const T q00 = conic[0], q01 = conic[1], q11 = conic[2];
  const T g00 = d_conic[0], g01 = T(0.5) * d_conic[1], g11 = d_conic[2];
  const T QG00 = q00 * g00 + q01 * g01, QG01 = q00 * g01 + q01 * g11;
  const T QG10 = q01 * g00 + q11 * g01, QG11 = q01 * g01 + q11 * g11;
  const T dS00 = -(QG00 * q00 + QG01 * q01);
  const T dS01 = -(QG00 * q01 + QG01 * q11);
  const T dS11 = -(QG10 * q01 + QG11 * q11);
  const T dS[4] = {dS00, dS01, dS01, dS11};
  // Sigma2 = A Sigma3 A^T: dA = 2 dS A Sigma3, dSigma3 = A^T dS A.
  T AS[6];
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 3; ++k)
      AS[r * 3 + k] = st.A[r * 3 + 0] * st.sigma[0 * 3 + k] + st.A[r * 3 + 1] * st.sigma[1 * 3 + k] +
                      st.A[r * 3 + 2] * st.sigma[2 * 3 + k];
  T dA[6];
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 3; ++k) dA[r * 3 + k] = T(2) * (dS[r * 2 + 0] * AS[k] + dS[r * 2 + 1] * AS[3 + k]);
  T dA_S[6];  // dS A
  for (int r = 0; r < 2; ++r)
    for (int k = 0; k < 3; ++k) dA_S[r * 3 + k] = dS[r * 2 + 0] * st.A[k] + dS[r * 2 + 1] * st.A[3 + k];
  T dSigma[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dSigma[i * 3 + j] = st.A[i] * dA_S[j] + st.A[3 + i] * dA_S[3 + j];
  // A = J W: dJ = dA W^T (only the non-zero entries of J matter).
  T dJ00 = 0, dJ02 = 0, dJ11 = 0, dJ12 = 0;
  for (int k = 0; k < 3; ++k) {
    dJ00 += dA[k] * R[k];
    dJ02 += dA[k] * R[6 + k];
    dJ11 += dA[3 + k] * R[3 + k];
    dJ12 += dA[3 + k] * R[6 + k];
  }
  T dpc[3] = {0, 0, d_depth};
  // J00 = fx/z, J02 = -fx u/z, J11 = fy/z, J12 = -fy v/z.
  const T inv_z2 = inv_z * inv_z;
  dpc[2] += -cam.fx * inv_z2 * dJ00 + cam.fx * st.u * inv_z2 * dJ02 - cam.fy * inv_z2 * dJ11 +
            cam.fy * st.v * inv_z2 * dJ12;
  const T du = hd_select(st.u_free, -cam.fx * inv_z * dJ02, T(0));
  const T dv = hd_select(st.v_free, -cam.fy * inv_z * dJ12, T(0));
  // mean2d = (fx x/z + cx - .5, fy y/z + cy - .5); u = x/z, v = y/z when not clamped.
  const T gx = du + cam.fx * d_mean2d[0], gy = dv + cam.fy * d_mean2d[1];
  dpc[0] += gx * inv_z;
  dpc[1] += gy * inv_z;
  dpc[2] -= (gx * st.pc[0] + gy * st.pc[1]) * inv_z2;
  for (int k = 0; k < 3; ++k) d_mean[k] += R[0 * 3 + k] * dpc[0] + R[1 * 3 + k] * dpc[1] + R[2 * 3 + k] * dpc[2];
  // Sigma3 = M M^T (dSigma symmetric): dM = 2 dSigma M.
  T dM[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      dM[i * 3 + j] = T(2) * (dSigma[i * 3 + 0] * st.M[0 * 3 + j] + dSigma[i * 3 + 1] * st.M[1 * 3 + j] +
                              dSigma[i * 3 + 2] * st.M[2 * 3 + j]);
  // M = Rq diag(s): dRq_ij = dM_ij s_j, ds_j = sum_i dM_ij Rq_ij, d log s = s ds.
  T dRq[9];
  for (int j = 0; j < 3; ++j) {
    const T s = st.s[j];
    T ds = 0;
    for (int i = 0; i < 3; ++i) {
      dRq[i * 3 + j] = dM[i * 3 + j] * s;
      ds += dM[i * 3 + j] * st.Rq[i * 3 + j];
    }
    d_log_scale[j] += ds * s;
  }
  T dqn[4];
  quat_to_rotmat_vjp(st.qn, dRq, dqn);
  // qn = q / |q|: dq = (dqn - qn (qn . dqn)) / |q|.
  const T dot = st.qn[0] * dqn[0] + st.qn[1] * dqn[1] + st.qn[2] * dqn[2] + st.qn[3] * dqn[3];
  const T inv_norm = T(1) / st.qnorm;
  for (int k = 0; k < 4; ++k) d_quat[k] += (dqn[k] - st.qn[k] * dot) * inv_norm;
  (void)quat;
}

}  // namespace d2gs::render
