// The Taylor-Green right-hand side of benchmarks/pair_loop_ceiling.c (each pair once, one
// thread) as an XLA FFI handler, so that a jitted JAX step can call it: what the ceiling
// becomes inside a compiled lax.scan.  Not part of sphjax; built and timed by
// benchmarks/pair_loop_ffi.py.
//
// Arguments: positions x [N, 2] and velocities v [N, 2] (float32) on the periodic unit
// square; attributes h, mass, sound_speed, reference_density, kinematic_viscosity.
// Results: the acceleration [N, 2] and the summation density [N] (quintic spline, support
// 3 h, linear equation of state p = c0^2 (rho - rho0), Morris viscosity with mu = rho nu).
#include <cmath>
#include <cstdint>
#include <vector>

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

inline float wrap(float d) { return d - std::rint(d); }  // minimum image, unit square

// quintic spline f(q) = (3-q)^5 - 6 (2-q)^5 + 15 (1-q)^5 (each term where positive)
inline float shape(float q) {
  float q3 = std::fmax(3 - q, 0.0f), q2 = std::fmax(2 - q, 0.0f), q1 = std::fmax(1 - q, 0.0f);
  float k3 = q3 * q3, k2 = q2 * q2, k1 = q1 * q1;
  return k3 * k3 * q3 - 6 * k2 * k2 * q2 + 15 * k1 * k1 * q1;
}

// its derivative f'(q)
inline float shape_derivative(float q) {
  float q3 = std::fmax(3 - q, 0.0f), q2 = std::fmax(2 - q, 0.0f), q1 = std::fmax(1 - q, 0.0f);
  return -5 * q3 * q3 * q3 * q3 + 30 * q2 * q2 * q2 * q2 - 75 * q1 * q1 * q1 * q1;
}

ffi::Error TaylorGreenRhs(ffi::Buffer<ffi::F32> x, ffi::Buffer<ffi::F32> v, float h,
                          float mass, float sound_speed, float reference_density,
                          float kinematic_viscosity, ffi::ResultBuffer<ffi::F32> acceleration,
                          ffi::ResultBuffer<ffi::F32> density) {
  const int64_t n = x.dimensions()[0];
  const float support = 3.0f * h, support2 = support * support, eta2 = 0.01f * h * h;
  const float sigma = 7.0f / (478.0f * static_cast<float>(M_PI) * h * h);
  const int nc = static_cast<int>(std::floor(1.0f / support));
  if (nc < 3) return ffi::Error::InvalidArgument("fewer than three cells of the support");
  const float cell = 1.0f / nc;
  const float* xin = x.typed_data();
  const float* vin = v.typed_data();
  // cell list: counting sort, fields copied in cell order
  std::vector<int> cid(n), start(nc * nc + 1, 0), order(n);
  for (int64_t a = 0; a < n; a++) {
    float px = xin[2 * a] - std::floor(xin[2 * a]), py = xin[2 * a + 1] - std::floor(xin[2 * a + 1]);
    int ci = std::min(static_cast<int>(px / cell), nc - 1);
    int cj = std::min(static_cast<int>(py / cell), nc - 1);
    cid[a] = ci * nc + cj;
    start[cid[a] + 1]++;
  }
  for (int c = 0; c < nc * nc; c++) start[c + 1] += start[c];
  {
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (int64_t a = 0; a < n; a++) order[fill[cid[a]]++] = static_cast<int>(a);
  }
  std::vector<float> px(n), py(n), u(n), w(n), rho(n, 0.0f), coef(n), inv(n), ax(n, 0.0f),
      ay(n, 0.0f);
  for (int64_t k = 0; k < n; k++) {
    int a = order[k];
    px[k] = xin[2 * a];
    py[k] = xin[2 * a + 1];
    u[k] = vin[2 * a];
    w[k] = vin[2 * a + 1];
  }
  auto neighbour_cell = [&](int c, int di, int dj) {
    int ci = c / nc, cj = c % nc;
    return ((ci + di + nc) % nc) * nc + (cj + dj + nc) % nc;
  };
  // the upper half of the 3 x 3 stencil: each pair of cells once
  const int stencil[5][2] = {{0, 0}, {0, 1}, {1, -1}, {1, 0}, {1, 1}};
  for (int c = 0; c < nc * nc; c++)
    for (const auto& s : stencil) {
      int d = neighbour_cell(c, s[0], s[1]);
      for (int a = start[c]; a < start[c + 1]; a++) {
        float sum = 0.0f;
        for (int b = d == c ? a + 1 : start[d]; b < start[d + 1]; b++) {
          float rx = wrap(px[a] - px[b]), ry = wrap(py[a] - py[b]), r2 = rx * rx + ry * ry;
          if (r2 >= support2) continue;
          float kernel = shape(std::sqrt(r2) / h);
          sum += kernel;
          rho[b] += kernel;
        }
        rho[a] += sum;
      }
    }
  const float c2 = sound_speed * sound_speed;
  for (int64_t a = 0; a < n; a++) {  // the self term (q = 0), the equation of state
    rho[a] = mass * sigma * (rho[a] + shape(0.0f));
    float p = c2 * (rho[a] - reference_density);
    coef[a] = p / (rho[a] * rho[a]);
    inv[a] = 1.0f / rho[a];
  }
  for (int c = 0; c < nc * nc; c++)
    for (const auto& s : stencil) {
      int d = neighbour_cell(c, s[0], s[1]);
      for (int a = start[c]; a < start[c + 1]; a++) {
        float gx = 0.0f, gy = 0.0f;
        for (int b = d == c ? a + 1 : start[d]; b < start[d + 1]; b++) {
          float rx = wrap(px[a] - px[b]), ry = wrap(py[a] - py[b]), r2 = rx * rx + ry * ry;
          if (r2 >= support2) continue;
          float r = std::sqrt(r2), dw = shape_derivative(r / h);
          float f = r > 0 ? sigma / h * dw / r : 0.0f;  // grad_a W = f (x_a - x_b)
          float pressure = -mass * (coef[a] + coef[b]);
          float viscous = mass * kinematic_viscosity * (inv[a] + inv[b]) * (r2 * f) / (r2 + eta2);
          float fx = pressure * f * rx + viscous * (u[a] - u[b]);
          float fy = pressure * f * ry + viscous * (w[a] - w[b]);
          gx += fx;
          gy += fy;
          ax[b] -= fx;  // equal masses: the pair's terms are antisymmetric
          ay[b] -= fy;
        }
        ax[a] += gx;
        ay[a] += gy;
      }
    }
  float* out = acceleration->typed_data();
  float* out_rho = density->typed_data();
  for (int64_t k = 0; k < n; k++) {
    int a = order[k];
    out[2 * a] = ax[k];
    out[2 * a + 1] = ay[k];
    out_rho[a] = rho[k];
  }
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxTaylorGreenRhs, TaylorGreenRhs,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F32>>()
                                  .Arg<ffi::Buffer<ffi::F32>>()
                                  .Attr<float>("h")
                                  .Attr<float>("mass")
                                  .Attr<float>("sound_speed")
                                  .Attr<float>("reference_density")
                                  .Attr<float>("kinematic_viscosity")
                                  .Ret<ffi::Buffer<ffi::F32>>()
                                  .Ret<ffi::Buffer<ffi::F32>>());
