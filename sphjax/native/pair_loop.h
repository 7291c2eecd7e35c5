// The pair loops that sphjax's compiled pair sums share: within one system the
// cell-blocked loop (cell_blocked.h) or each_pair_once, which evaluates a Term over a
// symmetric neighbour list once per pair and adds its numbers to both particles; between
// two systems rows_against_columns (see pair_sums.cc for the sums).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <type_traits>
#include <vector>

#include "cell_blocked.h"
#include "pair_geometry.h"
#include "threads.h"
#include "xla/ffi/api/ffi.h"

namespace sphjax_native {

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
// pair(own, p, from, stride, on_a, on_b, step): the pair's numbers for a and for b
// (on_a[w * step], on_b[w * step] for w < width).
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
        term.pair(own, p, fb + j, k, oa + j, ob + j, k);
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
        columns.pair(own, p, fb + j, k, oa + j, ob + j, k);
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

// Whether a sum within one system takes the cell-blocked loop: yes, unless
// $SPHJAX_NATIVE_CELLS is 0 (each_pair_once over the list then, to compare the two).
inline bool cells_wanted() {
  const char* env = std::getenv("SPHJAX_NATIVE_CELLS");
  return env == nullptr || std::strcmp(env, "0") != 0;
}

// A sum over pairs with the kernel as a template argument: within one system (`columns`
// == nullptr: the cell-blocked loop where a grid serves, else each_pair_once over the
// symmetric list) or rows against columns.
template <typename T, int D, typename Term>
void sum_pairs(ffi::ThreadPool* pool, int kernel, const Setting<T>& s, const T* x_rows,
               const T* x_columns, const int32_t* idx, int64_t n_rows, int64_t n_columns,
               int64_t k, T* out, const Term& rows, const Term* columns) {
  auto with = [&](auto shape) {
    constexpr int K = decltype(shape)::value;
    if constexpr (Term::within)  // (only the loops a Term has are compiled)
      if (columns == nullptr) {
        if (cells_wanted() && cell_blocked<T, D, K>(pool, s, x_rows, n_rows, out, rows)) return;
        return each_pair_once<T, D, K>(pool, s, x_rows, idx, n_rows, k, out, rows);
      }
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
