// The pair loop that sphjax's compiled pair sums share: kernel shapes, the pair
// geometry, and each_pair_once, which evaluates a Term over a symmetric neighbour list
// once per pair and adds its numbers to both particles (see pair_sums.cc for the sums).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "threads.h"
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
  T h, inverse_h, cutoff2, w_scale, grad_scale;  // W = w_scale f(q), W' = grad_scale f'(q)
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

// The geometry of the pair of a (at xa) and b (at xb[i * stride]): the minimum image,
// and W = grad W = 0 outside the support (grad W = 0 at r = 0), without a branch.
template <typename T, int D, int Kernel>
inline Pair<T, D> pair_of(const Setting<T>& s, const T* xa, const T* xb, int64_t stride) {
  Pair<T, D> p;
  T r2 = T(0);
  for (int i = 0; i < D; i++) {
    T d = xa[i] - xb[i * stride];
    d -= s.size[i] * std::nearbyint(d * s.inverse[i]);  // the minimum image
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

// The loop.  For each row a of the list, its neighbours b > a are gathered into
// contiguous buffers (positions, and the Term's F numbers per neighbour: Term::load),
// then one vectorised loop over them computes each pair's geometry and the Term's W
// numbers for a and for b (Term::pair); a's are summed, b's added to the output one by
// one after.  Pairs outside the support have W = grad W = 0, so every term is 0 there and
// the loop has no branch.  Threads take equal ranges of rows, each with its own output
// copy.
//
// A Term: `within` and `between`: whether it sums within one system (each_pair_once)
// and between two (rows_against_columns); `width` numbers per particle out, `fields` numbers per neighbour gathered by
// load(b, into, stride) (into[f * stride] for f < fields), row(a): what it reads of a,
// pair(own, p, from, stride, on_a, on_b): the pair's numbers for a and for b
// (on_a[w * stride], on_b[w * stride] for w < width).
template <typename T, int D, int Kernel, typename Term>
void each_pair_once(ffi::ThreadPool* pool, const Setting<T>& s, const T* x, const int32_t* idx,
                    int64_t n, int64_t k, T* out, const Term& term) {
  constexpr int W = Term::width, F = Term::fields;
  const int64_t threads = thread_count(pool, n);
  std::vector<std::vector<T>> copies(threads - 1, std::vector<T>(n * W, T(0)));
  std::fill(out, out + n * W, T(0));
  auto rows = [&](int64_t t) SPHJAX_FLATTEN {
    T* acc = t == 0 ? out : copies[t - 1].data();
    const int64_t lo = n * t / threads, hi = n * (t + 1) / threads;
    std::vector<int32_t> later(k);                   // the row's neighbours b > a
    std::vector<T> buffer((D + F + 2 * W) * k + 1);  // theirs: x, the Term's, for a, b
    T* xb = buffer.data();
    T* fb = xb + D * k;
    T* oa = fb + F * k;
    T* ob = oa + W * k;
    for (int64_t a = lo; a < hi; a++) {
      const int32_t* row = idx + a * k;
      int64_t count = 0;
      for (int64_t j = 0; j < k; j++) {  // without a branch: which b > a is unpredictable
        later[count] = row[j];
        count += (row[j] > a) & (row[j] < n);
      }
      for (int64_t j = 0; j < count; j++) {
        const int64_t b = later[j];
        for (int i = 0; i < D; i++) xb[i * k + j] = x[b * D + i];
        term.load(b, fb + j, k);
      }
      T xa[D];
      for (int i = 0; i < D; i++) xa[i] = x[a * D + i];
      const auto own = term.row(a);
#pragma omp simd
      for (int64_t j = 0; j < count; j++) {
        const Pair<T, D> p = pair_of<T, D, Kernel>(s, xa, xb + j, k);
        // written straight into the buffers: a Term's W numbers held in a local array
        // per pair would become strided stores, which keep GCC from vectorising the loop
        term.pair(own, p, fb + j, k, oa + j, ob + j);
      }
      for (int w = 0; w < W; w++) {
        T sum = T(0);
        for (int64_t j = 0; j < count; j++) sum += oa[w * k + j];
        acc[a * W + w] += sum;
      }
      for (int64_t j = 0; j < count; j++)
        for (int w = 0; w < W; w++) acc[later[j] * W + w] += ob[w * k + j];
    }
  };
  in_parallel(pool, threads, rows);
  for (const auto& copy : copies)
    for (int64_t i = 0; i < n * W; i++) out[i] += copy[i];
}

// Rows of one system against the columns of another: out_a = sum_{b in idx[a]} f(a, b)
// (the Term's weight included) over a list whose entries index the columns (padded with
// n_cols or more), each pair from a's side only, so threads write their own rows and
// need no copies.  `rows` reads a (Term::row), `columns` reads b (Term::load) and
// evaluates the pair (Term::pair; its numbers for b are dropped).  Its gathering repeats
// each_pair_once's on purpose: with both in one shared helper GCC left the momentum's
// pair loop scalar (no AVX instruction in it; -fopt-info-vec: "control flow in loop").
template <typename T, int D, int Kernel, typename Term>
void rows_against_columns(ffi::ThreadPool* pool, const Setting<T>& s, const T* x_rows,
                          const T* x_columns, const int32_t* idx, int64_t n_rows,
                          int64_t n_columns, int64_t k, T* out, const Term& rows,
                          const Term& columns) {
  constexpr int W = Term::width, F = Term::fields;
  const int64_t threads = thread_count(pool, n_rows);
  auto block = [&](int64_t t) SPHJAX_FLATTEN {
    const int64_t lo = n_rows * t / threads, hi = n_rows * (t + 1) / threads;
    std::vector<int32_t> present(k);
    std::vector<T> buffer((D + F + 2 * W) * k + 1);
    T* xb = buffer.data();
    T* fb = xb + D * k;
    T* oa = fb + F * k;
    T* ob = oa + W * k;  // the pairs' numbers for b: not wanted
    for (int64_t a = lo; a < hi; a++) {
      const int32_t* row = idx + a * k;
      int64_t count = 0;
      for (int64_t j = 0; j < k; j++) {
        present[count] = row[j];
        count += (row[j] >= 0) & (row[j] < n_columns);
      }
      for (int64_t j = 0; j < count; j++) {
        const int64_t b = present[j];
        for (int i = 0; i < D; i++) xb[i * k + j] = x_columns[b * D + i];
        columns.load(b, fb + j, k);
      }
      T xa[D];
      for (int i = 0; i < D; i++) xa[i] = x_rows[a * D + i];
      const auto own = rows.row(a);
#pragma omp simd
      for (int64_t j = 0; j < count; j++) {
        const Pair<T, D> p = pair_of<T, D, Kernel>(s, xa, xb + j, k);
        columns.pair(own, p, fb + j, k, oa + j, ob + j);
      }
      for (int w = 0; w < W; w++) {
        T sum = T(0);
        for (int64_t j = 0; j < count; j++) sum += oa[w * k + j];
        out[a * W + w] = sum;
      }
    }
  };
  in_parallel(pool, threads, block);
}

// A sum over pairs with the kernel as a template argument: within one system
// (`columns` == nullptr: each_pair_once over a symmetric list) or rows against columns.
template <typename T, int D, typename Term>
void sum_pairs(ffi::ThreadPool* pool, int kernel, const Setting<T>& s, const T* x_rows,
               const T* x_columns, const int32_t* idx, int64_t n_rows, int64_t n_columns,
               int64_t k, T* out, const Term& rows, const Term* columns) {
  auto with = [&](auto shape) {
    constexpr int K = decltype(shape)::value;
    if constexpr (Term::within)  // (only the loops a Term has are compiled)
      if (columns == nullptr)
        return each_pair_once<T, D, K>(pool, s, x_rows, idx, n_rows, k, out, rows);
    if constexpr (Term::between)
      if (columns != nullptr)
        return rows_against_columns<T, D, K>(pool, s, x_rows, x_columns, idx, n_rows,
                                             n_columns, k, out, rows, *columns);
  };
  switch (kernel) {
    case 0: return with(std::integral_constant<int, 0>{});
    case 1: return with(std::integral_constant<int, 1>{});
    case 2: return with(std::integral_constant<int, 2>{});
    default: return with(std::integral_constant<int, 3>{});
  }
}

// each_pair_once with the kernel as a template argument
template <typename T, int D, typename Term>
void by_kernel(ffi::ThreadPool* pool, int kernel, const Setting<T>& s, const T* x,
               const int32_t* idx, int64_t n, int64_t k, T* out, const Term& term) {
  sum_pairs<T, D>(pool, kernel, s, x, x, idx, n, n, k, out, term, static_cast<const Term*>(nullptr));
}

// a buffer's numbers as T (the handlers check its element type first)
template <typename T>
const T* data(const ffi::AnyBuffer& buffer) {
  return reinterpret_cast<const T*>(buffer.untyped_data());
}

template <typename T>
T* data(ffi::Result<ffi::AnyBuffer>& buffer) {
  return reinterpret_cast<T*>(buffer->untyped_data());
}

template <typename T>
Setting<T> setting(int dim, double h, double cutoff, double sigma, double lx, double ly,
                   double lz, int64_t periodic) {
  Setting<T> s;
  s.h = T(h);
  s.inverse_h = T(1.0 / h);
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

// The attributes every handler takes: the pair geometry (kernel, h, cutoff, the kernel's
// normalisation, the box, its periodic axes) and whether the sum is between two systems.
#define SPHJAX_SETTING_ATTRS                                                        \
  int64_t kernel, double h, double cutoff, double sigma, double lx, double ly, double lz, \
      int64_t periodic, bool cross

#define SPHJAX_BIND_SETTING(binding)                                                    \
  binding.Attr<int64_t>("kernel")                                                       \
      .Attr<double>("h")                                                                \
      .Attr<double>("cutoff")                                                           \
      .Attr<double>("sigma")                                                            \
      .Attr<double>("lx")                                                               \
      .Attr<double>("ly")                                                               \
      .Attr<double>("lz")                                                               \
      .Attr<int64_t>("periodic")                                                        \
      .Attr<bool>("cross")

#define SPHJAX_SETTING_NAMES kernel, h, cutoff, sigma, lx, ly, lz, periodic, cross

// the arguments of a handler: XLA's thread pool, n buffers, the neighbour list, m more
#define SPHJAX_ARGS_1 .Arg<ffi::AnyBuffer>()
#define SPHJAX_ARGS_2 SPHJAX_ARGS_1 SPHJAX_ARGS_1
#define SPHJAX_ARGS_3 SPHJAX_ARGS_2 SPHJAX_ARGS_1
#define SPHJAX_ARGS_4 SPHJAX_ARGS_2 SPHJAX_ARGS_2
#define SPHJAX_ARGS_5 SPHJAX_ARGS_4 SPHJAX_ARGS_1
#define SPHJAX_ARGS_6 SPHJAX_ARGS_3 SPHJAX_ARGS_3
#define SPHJAX_ARGS_10 SPHJAX_ARGS_5 SPHJAX_ARGS_5
#define SPHJAX_ARGS_0
#define SPHJAX_BIND(before, after)                                                       \
  SPHJAX_BIND_SETTING(ffi::Ffi::Bind().Ctx<ffi::ThreadPool>() SPHJAX_ARGS_##before       \
                          .Arg<ffi::Buffer<ffi::S32>>() SPHJAX_ARGS_##after              \
                          .Ret<ffi::AnyBuffer>())
