// A cell-blocked pair loop: a sum within one system over every pair closer than the
// cutoff, found through a grid of cells instead of a neighbour list.
//
// The particles are sorted into cells at least cutoff / R wide (R = 2: half the support)
// and their positions and the Term's fields copied into cell order, one array per field,
// so that the cells of one row of the grid (axis 0 fastest) hold one contiguous run of
// particles.  A particle a meets the half shell of its cell (the rest of its own cell
// and the next R cells of its row; the 2R + 1 cells about its column in each of the next
// R rows; in 3D also the (2R + 1)^2 about it in each of the next R planes) as a few such
// runs, each a unit-stride loop over vectors of L particles b: no list, no gather.  Each
// pair once: in a's own cell only the b after a, and no two cells hold each other in
// their half shells.  a's numbers are kept as L partial sums over all its runs and added
// once; b's are added into the run (a whole vector at once; the run's last part one by
// one).  Pairs outside the support have W = grad W = 0, so their terms are 0: no branch.
//
// On a periodic axis the grid wraps and a run across the box's face carries the image
// shift (subtracted from a's position); on the others the grid spans the particles'
// extent and the runs stop at its ends.
//
// Threads take stripes of the slowest axis' slices of cells: first the slices of their
// stripe but the last R, whose half shells stay inside it, then (once every thread is
// done) those last R, whose half shells reach R slices into the next stripe, slices no
// other thread's last ones reach.  So no two threads ever add to the same particle, and
// there are no output copies.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "pair_geometry.h"
#include "threads.h"

namespace sphjax_native {

// The grid: cells per axis (1 on an unused axis), where cell 0 starts, the cells'
// inverse width, the period of each periodic axis (0 on the others), and R.
struct CellGrid {
  int64_t cells[3] = {1, 1, 1};
  double origin[3] = {0, 0, 0}, inverse_width[3] = {0, 0, 0};
  double period[3] = {0, 0, 0}, inverse_period[3] = {0, 0, 0};
  int reach = 1;
  int64_t count() const { return cells[0] * cells[1] * cells[2]; }
};

// The grid for positions x [n, D] (false where none serves: a periodic axis of fewer
// than 2R + 1 cells, where a cell would meet another twice; positions not finite; more
// cells than 4 n + 4096, particles spread far apart).  The cells are 1e-4 wider than
// cutoff / R, so rounding never puts a pair inside the support more than R cells apart.
template <typename T, int D>
bool grid_for(const Setting<T>& s, const T* x, int64_t n, CellGrid* g) {
  g->reach = 2;
  const double width = double(s.cutoff) / g->reach * (1 + 1e-4);
  if (!(width > 0) || n == 0) return false;
  double total = 1;
  for (int i = 0; i < D; i++) {
    const double period = s.size[i];
    if (period > 0) {
      const double cells = std::floor(period / width);
      if (cells < 2 * g->reach + 1) return false;
      g->cells[i] = int64_t(cells);
      g->origin[i] = 0;
      g->inverse_width[i] = cells / period;
      g->period[i] = period;
      g->inverse_period[i] = 1 / period;
    } else {
      double lo = x[i], hi = x[i];
      for (int64_t a = 1; a < n; a++) {
        lo = std::min(lo, double(x[a * D + i]));
        hi = std::max(hi, double(x[a * D + i]));
      }
      if (!std::isfinite(lo) || !std::isfinite(hi)) return false;
      const double cells = std::floor((hi - lo) / width) + 1;
      if (cells > double(4 * n + 4096)) return false;
      g->cells[i] = int64_t(cells);
      g->origin[i] = lo;
      g->inverse_width[i] = 1 / width;
    }
    total *= double(g->cells[i]);
  }
  return total <= double(4 * n + 4096);
}

// A run of particles b in cell order, lo <= b < hi, and the image shift of their cells
// (own: the run starts with a's own cell, where only the b after a pair with it)
template <typename T>
struct Run {
  int64_t lo, hi;
  bool own;
  T shift[3];
};

// The cells from column c0 to c1 (at most R past either end) of the row whose first cell
// is `base`, as at most three runs (a periodic axis 0 wraps: the columns before 0 are
// the last ones, their images at -L; those past the end the first ones, at +L)
template <typename T>
int add_row(const CellGrid& g, const int64_t* start, int64_t base, int64_t c0, int64_t c1,
            bool own, const T* shift, Run<T>* runs) {
  const int64_t n0 = g.cells[0];
  const bool wraps = g.period[0] > 0;
  int count = 0;
  auto add = [&](int64_t first, int64_t last, bool is_own, T shift0) {
    Run<T> run{start[base + first], start[base + last + 1], is_own, {shift0, shift[1], shift[2]}};
    if (run.hi > run.lo) runs[count++] = run;
  };
  if (c0 < 0) {
    if (wraps) add(c0 + n0, n0 - 1, false, T(-g.period[0]));
    c0 = 0;
  }
  add(c0, std::min(c1, n0 - 1), own, T(0));
  if (c1 >= n0 && wraps) add(0, c1 - n0, false, T(g.period[0]));
  return count;
}

// the half shell of cell (c[0], c[1], c[2]) as runs; their count
template <typename T, int D>
int half_shell(const CellGrid& g, const int64_t* start, const int64_t* c, Run<T>* runs) {
  const int R = g.reach;
  int count = 0;
  for (int o2 = 0; o2 <= (D == 3 ? R : 0); o2++)
    for (int o1 = o2 == 0 ? 0 : -R; o1 <= R; o1++) {
      const int offset[3] = {0, o1, o2};
      int64_t cell[3] = {0, 0, 0};
      T shift[3] = {T(0), T(0), T(0)};
      bool outside = false;
      for (int i = 1; i < D; i++) {
        int64_t ci = c[i] + offset[i];
        if (ci < 0 || ci >= g.cells[i]) {
          outside |= !(g.period[i] > 0);
          shift[i] = T(ci < 0 ? -g.period[i] : g.period[i]);
          ci += ci < 0 ? g.cells[i] : -g.cells[i];
        }
        cell[i] = ci;
      }
      if (outside) continue;
      const bool own = o1 == 0 && o2 == 0;
      const int64_t base = (cell[2] * g.cells[1] + cell[1]) * g.cells[0];
      count += add_row(g, start, base, own ? c[0] : c[0] - R, c[0] + R, own, shift,
                       runs + count);
    }
  return count;
}

// What one call keeps between its passes: the particles in cell order (`order`: their
// indices), where each cell starts, the positions and the Term's fields in cell order
// (field f of the particle at place j at [f * stride + j], padded past n by L copies of
// the last one), and the sums in cell order.
template <typename T>
struct Sorted {
  std::vector<int32_t> order;
  std::vector<int64_t> key, start, next;  // each particle's cell; each cell's first place
  std::vector<T> x, fields, sums;
};

// 1. The grid of the positions x [n, D] (false where none serves: grid_for), the
// counting sort into its cells (axis 0 fastest) and the positions in cell order, wrapped
// into the box on periodic axes (the cell is that of the wrapped position, which the
// pairs see); the keys and the copies shared between the threads.  Of T and D only: one
// compiled copy for every Term and kernel.
template <typename T, int D>
bool sort_into_cells(ffi::ThreadPool* pool, const Setting<T>& s, const T* x, int64_t n,
                     int64_t threads, CellGrid* g, Sorted<T>* at) {
  constexpr int L = 32 / sizeof(T);
  if (!grid_for<T, D>(s, x, n, g)) return false;
  const int64_t cells = g->count(), stride = n + L;
  T period[D], inverse[D];
  for (int i = 0; i < D; i++) period[i] = T(g->period[i]), inverse[i] = T(g->inverse_period[i]);
  auto wrapped = [&](int64_t a, int i) {
    const T u = x[a * D + i];
    return u - period[i] * std::floor(u * inverse[i]);
  };
  at->key.resize(n);
  int64_t* key = at->key.data();
  const CellGrid grid = *g;
  in_parallel(pool, threads, [&, key](int64_t t) {
    for (int64_t a = n * t / threads; a < n * (t + 1) / threads; a++) {
      int64_t k = 0;
      for (int i = D - 1; i >= 0; i--) {
        const double u = (double(wrapped(a, i)) - grid.origin[i]) * grid.inverse_width[i];
        k = k * grid.cells[i] + std::clamp<int64_t>(int64_t(u), 0, grid.cells[i] - 1);
      }
      key[a] = k;
    }
  });
  at->start.assign(cells + 1, 0);
  for (int64_t a = 0; a < n; a++) at->start[key[a] + 1]++;
  for (int64_t c = 0; c < cells; c++) at->start[c + 1] += at->start[c];
  at->next.assign(at->start.begin(), at->start.end() - 1);
  at->order.resize(n);
  for (int64_t a = 0; a < n; a++) at->order[at->next[key[a]]++] = static_cast<int32_t>(a);
  at->x.resize(D * stride);
  const int32_t* order = at->order.data();
  T* xs = at->x.data();
  in_parallel(pool, threads, [&, order, xs](int64_t t) {
    for (int64_t j = stride * t / threads; j < stride * (t + 1) / threads; j++) {
      const int64_t a = order[std::min(j, n - 1)];  // (past n: copies of the last)
      for (int i = 0; i < D; i++) xs[i * stride + j] = wrapped(a, i);
    }
  });
  return true;
}

// The Term's fields in cell order and its sums zeroed (of T, D and the Term: one compiled
// copy for the four kernels)
template <typename T, int D, typename Term>
void fields_into_cells(ffi::ThreadPool* pool, int64_t n, int64_t threads, const Term& term,
                       Sorted<T>* at) {
  constexpr int W = Term::width, F = Term::fields;
  constexpr int L = 32 / sizeof(T);
  const int64_t stride = n + L;
  at->fields.resize(std::max(F, 1) * stride);
  at->sums.resize(W * stride);
  const int32_t* order = at->order.data();
  T *fs = at->fields.data(), *sums = at->sums.data();
  in_parallel(pool, threads, [&, order, fs, sums](int64_t t) {
    for (int64_t j = stride * t / threads; j < stride * (t + 1) / threads; j++) {
      term.load(order[std::min(j, n - 1)], fs + j, stride);
      for (int w = 0; w < W; w++) sums[w * stride + j] = T(0);
    }
  });
}

// The sums in cell order back into the particles' order, out [n, W]
template <typename T, int W>
void out_of_cells(const Sorted<T>& at, int64_t n, T* out) {
  constexpr int L = 32 / sizeof(T);
  const int64_t stride = n + L;
  for (int64_t j = 0; j < n; j++)
    for (int w = 0; w < W; w++) out[int64_t(at.order[j]) * W + w] = at.sums[w * stride + j];
}

// The sum of Term over every pair within the cutoff of the positions x [n, D], each pair
// once, into out [n, width]; false (nothing done) where no grid serves (grid_for).
template <typename T, int D, int Kernel, typename Term>
bool cell_blocked(ffi::ThreadPool* pool, const Setting<T>& s, const T* x, int64_t n, T* out,
                  const Term& term) {
  constexpr int W = Term::width;
  constexpr int L = 32 / sizeof(T);  // numbers per 256-bit vector
  thread_local Sorted<T> at;  // kept between calls: no new pages each step
  const int64_t threads = thread_count(pool, n);
  CellGrid g;
  if (!sort_into_cells<T, D>(pool, s, x, n, threads, &g, &at)) return false;
  fields_into_cells<T, D>(pool, n, threads, term, &at);
  const int R = g.reach;
  const int64_t cells = g.count(), stride = n + L;

  // 2. the pairs, slice by slice of the slowest axis
  const int64_t* start = at.start.data();
  const int32_t* order = at.order.data();
  const int64_t slices = g.cells[D - 1], per_slice = cells / slices;
  // (`at` is this thread's: the threads below see it through these pointers)
  const T *x_sorted = at.x.data(), *f_sorted = at.fields.data();
  T* sums_sorted = at.sums.data();
  auto over = [&, stride, x_sorted, f_sorted, sums_sorted](int64_t first_slice,
                                                           int64_t end_slice) SPHJAX_FLATTEN {
    // (the loops read locals, not the closure: GCC leaves them scalar otherwise)
    const Setting<T> geometry = s;
    const Term pairs = term;
    const T *xs = x_sorted, *fs = f_sorted;
    T* sums = sums_sorted;
    Run<T> runs[64];
    for (int64_t c = first_slice * per_slice; c < end_slice * per_slice; c++) {
      if (start[c + 1] == start[c]) continue;
      const int64_t cell[3] = {c % g.cells[0], (c / g.cells[0]) % g.cells[1],
                               c / (g.cells[0] * g.cells[1])};
      const int count = half_shell<T, D>(g, start, cell, runs);
      for (int64_t j = start[c]; j < start[c + 1]; j++) {
        const auto mine = pairs.row(order[j]);
        T partial[W * L] = {};
        for (int r = 0; r < count; r++) {
          const Run<T>& run = runs[r];
          T xa[D];
          for (int i = 0; i < D; i++) xa[i] = xs[i * stride + j] - run.shift[i];
          for (int64_t b0 = run.own ? j + 1 : run.lo; b0 < run.hi; b0 += L) {
            T on_a[W * L], on_b[W * L];
#pragma omp simd
            for (int l = 0; l < L; l++) {
              const Pair<T, D> p = pair_of<T, D, Kernel, false>(geometry, xa, xs + b0 + l, stride);
              pairs.pair(mine, p, fs + b0 + l, stride, on_a + l, on_b + l, L);
            }
            if (run.hi - b0 >= L) {
              for (int w = 0; w < W; w++) {
#pragma omp simd
                for (int l = 0; l < L; l++) {
                  partial[w * L + l] += on_a[w * L + l];
                  sums[w * stride + b0 + l] += on_b[w * L + l];
                }
              }
            } else {  // the run's last particles: the other lanes belong to no pair
              for (int l = 0; l < run.hi - b0; l++)
                for (int w = 0; w < W; w++) {
                  partial[w * L + l] += on_a[w * L + l];
                  sums[w * stride + b0 + l] += on_b[w * L + l];
                }
            }
          }
        }
        for (int w = 0; w < W; w++) {
          T total = T(0);
          for (int l = 0; l < L; l++) total += partial[w * L + l];
          sums[w * stride + j] += total;
        }
      }
    }
  };
  const int64_t stripes = std::min<int64_t>(threads, std::max<int64_t>(1, slices / (2 * R)));
  // (one stripe: its slices in order, in two calls)
  auto stripe = [&](int64_t t, bool last) {
    const int64_t lo = slices * t / stripes, hi = slices * (t + 1) / stripes;
    const int64_t middle = std::max(lo, hi - R);
    if (last) over(middle, hi);
    else over(lo, middle);
  };
  for (const bool last : {false, true})
    in_parallel(pool, stripes, [&, last](int64_t t) { stripe(t, last); });

  out_of_cells<T, W>(at, n, out);
  return true;
}

}  // namespace sphjax_native
