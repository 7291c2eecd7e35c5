// The pair geometry every compiled pair loop of sphjax shares: the kernels' shapes, what
// every pair sees (the kernel's scale, the box) and one pair's geometry.
#pragma once

#include <cmath>
#include <cstdint>

#include "xla/ffi/api/ffi.h"

namespace sphjax_native {

// A thread's rows are compiled with everything they call inlined (the pair geometry, the
// Term's arithmetic): left to its own budget GCC may call them from the vectorised loop,
// which then stays scalar (three times slower; checked with objdump's AVX count)
#define SPHJAX_FLATTEN __attribute__((flatten))

namespace ffi = xla::ffi;

template <typename T>
inline T positive(T x) {
  return x > T(0) ? x : T(0);
}

// kernel shapes f(q) and f'(q) of sphjax.core.kernels, by the ids of sphjax/native
template <typename T, int Kernel>
struct Shape;

template <typename T>
struct Shape<T, 0> {  // cubic spline
  static T value(T q) {
    T a = positive(T(2) - q), b = positive(T(1) - q);
    return T(0.25) * a * a * a - b * b * b;
  }
  static T derivative(T q) {
    T a = positive(T(2) - q), b = positive(T(1) - q);
    return T(-0.75) * a * a + T(3) * b * b;
  }
};

template <typename T>
struct Shape<T, 1> {  // quintic spline
  static T value(T q) {
    T a = positive(T(3) - q), b = positive(T(2) - q), c = positive(T(1) - q);
    T a2 = a * a, b2 = b * b, c2 = c * c;
    return a2 * a2 * a - T(6) * b2 * b2 * b + T(15) * c2 * c2 * c;
  }
  static T derivative(T q) {
    T a = positive(T(3) - q), b = positive(T(2) - q), c = positive(T(1) - q);
    T a2 = a * a, b2 = b * b, c2 = c * c;
    return T(-5) * (a2 * a2 - T(6) * b2 * b2 + T(15) * c2 * c2);
  }
};

template <typename T>
struct Shape<T, 2> {  // Wendland C2
  static T value(T q) {
    T s = positive(T(1) - T(0.5) * q), s2 = s * s;
    return s2 * s2 * (T(2) * q + T(1));
  }
  static T derivative(T q) {
    T s = positive(T(1) - T(0.5) * q);
    return T(-5) * q * s * s * s;
  }
};

template <typename T>
struct Shape<T, 3> {  // Wendland C4
  static T value(T q) {
    T s = positive(T(1) - T(0.5) * q), s2 = s * s;
    return s2 * s2 * s2 * (T(35.0 / 12.0) * q * q + T(3) * q + T(1));
  }
  static T derivative(T q) {
    T s = positive(T(1) - T(0.5) * q), s2 = s * s;
    return -T(14.0 / 3.0) * q * (T(1) + T(2.5) * q) * s2 * s2 * s;
  }
};

// what every pair sees: the kernel's scale and the box
template <typename T>
struct Setting {
  T h, inverse_h, cutoff, cutoff2, w_scale, grad_scale;  // W = w_scale f(q), W' = grad_scale f'(q)
  T size[3];        // the box's lengths on the periodic axes, 0 on the others
  T inverse[3];     // their inverses (0 on the others: no image is subtracted)
};

// one pair's geometry
template <typename T, int D>
struct Pair {
  T dr[D];    // r_a - r_b (minimum image)
  T r2;       // |r_ab|^2
  T w;        // W_ab
  T grad[D];  // grad_a W_ab
};

// The geometry of the pair of a (at xa) and b (at xb[i * stride]): the minimum image
// (unless `Image` is false: xa is already the image nearest b), and W = grad W = 0
// outside the support (grad W = 0 at r = 0), without a branch.
template <typename T, int D, int Kernel, bool Image = true>
inline Pair<T, D> pair_of(const Setting<T>& s, const T* xa, const T* xb, int64_t stride) {
  Pair<T, D> p;
  T r2 = T(0);
  for (int i = 0; i < D; i++) {
    T d = xa[i] - xb[i * stride];
    if (Image) d -= s.size[i] * std::nearbyint(d * s.inverse[i]);  // the minimum image
    p.dr[i] = d;
    r2 += d * d;
  }
  const T inside = r2 < s.cutoff2 ? T(1) : T(0);
  const T r = std::sqrt(r2);
  const T q = r * s.inverse_h;
  const T safe = r > T(0) ? r : T(1);
  p.r2 = r2;
  p.w = inside * s.w_scale * Shape<T, Kernel>::value(q);
  const T factor =
      r > T(0) ? inside * s.grad_scale * Shape<T, Kernel>::derivative(q) / safe : T(0);
  for (int i = 0; i < D; i++) p.grad[i] = factor * p.dr[i];
  return p;
}

template <typename T>
Setting<T> setting(int dim, double h, double cutoff, double sigma, double lx, double ly,
                   double lz, int64_t periodic) {
  Setting<T> s;
  s.h = T(h);
  s.inverse_h = T(1.0 / h);
  s.cutoff = T(cutoff);
  s.cutoff2 = T(cutoff * cutoff);
  s.w_scale = T(sigma / std::pow(h, dim));
  s.grad_scale = T(sigma / std::pow(h, dim + 1));
  const double size[3] = {lx, ly, lz};
  for (int i = 0; i < 3; i++) {
    const bool on = (periodic >> i) & 1;
    s.size[i] = on ? T(size[i]) : T(0);
    s.inverse[i] = on ? T(1.0 / size[i]) : T(0);
  }
  return s;
}

}  // namespace sphjax_native
