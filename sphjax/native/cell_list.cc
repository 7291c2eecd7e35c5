// sphjax's neighbour search in the current configuration as a compiled loop, called from
// XLA (an FFI handler): the rebuild of a dense Verlet list [N, K] (Model.pair_loop="native").
//
// The positions arrive in the search's box (sphjax.neighbors.NeighborSearch.to_box: each
// axis in [0, L); the non-periodic axes padded so that no image across them is near).
// The box is cut into a grid of cells at least as wide as the search radius
// r = cutoff + skin, so every neighbour of a particle lies in its own cell or in one of
// the 3^d cells around it (across the box's faces: the grid wraps like the box):
//
//   1. counting sort: each particle's cell c(x) = floor(x / cell size) per axis; the
//      particles counted per cell, the counts summed into each cell's first slot, and the
//      particles (in increasing index) and their positions copied into cell order, so a
//      cell's members are one contiguous range;
//   2. for each particle a (rows shared between the threads of XLA's CPU pool), the
//      members b of the 3^d cells around its own are tested, |x_a - x_b|^2 < r^2 with the
//      minimum image on every axis (the padded ones never bring an image within r), b = a
//      left out; the row keeps the first K of them, in the order jax-md's dense list has
//      them (the cells by offset, axis 0 slowest; within a cell, increasing index rotated
//      as jax-md's cell list stores it), and is padded with N.
//
// Besides the list it returns the widest row's count (more than K: the list overflowed)
// and the fullest cell's count (the capacity jax-md's cell list would have needed).  An
// axis with fewer than 3 cells is one cell (its particles are all candidates), so no cell
// is visited twice.
//
// The distance is computed as jax-md's periodic metric computes it, in the positions'
// precision (d = x_a - x_b, d -> mod(d + L/2, L) - L/2, |d|^2 summed over the axes in
// order), so the rows hold the same neighbours as jax-md's to the last bit.
#include <algorithm>
#include <condition_variable>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <vector>

#include "threads.h"
#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

using sphjax_native::in_parallel;
using sphjax_native::thread_count;

// The search: the box, its grid, the radius.
template <typename T>
struct Grid {
  T box[3], half[3];    // L and L / 2 per axis (in the positions' precision)
  T cell_size[3];       // the grid's spacing per axis
  int64_t cells[3];     // cells per axis (1 on the unused third axis)
  T radius2;            // (cutoff + skin)^2
  int64_t capacity;     // the slots per cell of jax-md's cell list (0: none)
};

// d = x_a - x_b on one axis, wrapped as jax-md's periodic displacement wraps it:
// mod(d + L/2, L) - L/2, with mod the floored remainder.  Both positions are in [0, L], so
// d + L/2 is in [-L/2, 3L/2]: the remainder is that number, less L (exact) at L or above,
// plus L below 0.
template <typename T>
inline T wrapped(T d, T box, T half) {
  const T y = d + half;
  const T r = y >= box ? y - box : (y < T(0) ? y + box : y);
  return r - half;
}

// A particle's cell on one axis: floor(x / size) (x >= 0), wrapped onto the grid.
template <typename T>
inline int64_t cell_on_axis(T x, T size, int64_t cells) {
  const int64_t c = static_cast<int32_t>(x / size);
  return ((c % cells) + cells) % cells;
}

// Where a cell's members start in jax-md's cell list of capacity C: it gives the particle
// at place p of the sorted order (cell by cell) the slot p mod C of its cell, so a cell's
// members, starting at place `begin`, sit in its slots rotated by (-begin) mod C (none if
// that is past the last of its m members, or C is 0: no cell list to follow).
inline int64_t rotation(int64_t begin, int64_t m, int64_t capacity) {
  if (capacity <= 0) return 0;
  const int64_t turn = (capacity - begin % capacity) % capacity;
  return turn < m ? turn : 0;
}

template <typename T, int D>
void rebuild(ffi::ThreadPool* pool, const Grid<T>& g, const T* x, int64_t n, int64_t k,
             int32_t* idx, int32_t* sizes) {
  // 1. counting sort of the particles into cells (axis 0 fastest)
  int64_t count = 1;
  for (int i = 0; i < D; i++) count *= g.cells[i];
  std::vector<int64_t> own(n);   // each particle's cell
  std::vector<int64_t> first(count + 1, 0);  // each cell's first slot in cell order
  for (int64_t a = 0; a < n; a++) {
    int64_t key = 0, stride = 1;
    for (int i = 0; i < D; i++) {
      key += stride * cell_on_axis(x[a * D + i], g.cell_size[i], g.cells[i]);
      stride *= g.cells[i];
    }
    own[a] = key;
    first[key + 1]++;
  }
  int64_t fullest = 0;
  for (int64_t c = 0; c < count; c++) {
    fullest = std::max(fullest, first[c + 1]);
    first[c + 1] += first[c];
  }
  std::vector<int64_t> turn(count);  // where each cell's members start (rotation)
  for (int64_t c = 0; c < count; c++)
    turn[c] = rotation(first[c], first[c + 1] - first[c], g.capacity);
  std::vector<int32_t> member(n);  // the particles in cell order
  std::vector<T> xs(D * n);        // their positions, axis by axis
  {
    std::vector<int64_t> next(first.begin(), first.end() - 1);
    for (int64_t a = 0; a < n; a++) {
      const int64_t slot = next[own[a]]++;
      member[slot] = static_cast<int32_t>(a);
      for (int i = 0; i < D; i++) xs[i * n + slot] = x[a * D + i];
    }
  }

  // the cell offsets around a cell, axis 0 slowest (jax-md's order); one offset on an
  // axis of fewer than 3 cells
  std::vector<int64_t> offsets;  // D numbers per offset
  const int64_t reach[3] = {g.cells[0] >= 3 ? 1 : 0, g.cells[1] >= 3 ? 1 : 0,
                            g.cells[2] >= 3 ? 1 : 0};
  for (int64_t o0 = -reach[0]; o0 <= reach[0]; o0++)
    for (int64_t o1 = -reach[1]; o1 <= reach[1]; o1++)
      for (int64_t o2 = -(D == 3 ? reach[2] : 0); o2 <= (D == 3 ? reach[2] : 0); o2++) {
        const int64_t o[3] = {o0, o1, o2};
        for (int i = 0; i < D; i++) offsets.push_back(o[i]);
      }
  const int64_t around = static_cast<int64_t>(offsets.size()) / D;

  // 2. the rows
  const int64_t threads = thread_count(pool, n);
  std::vector<int64_t> widest(threads, 0);
  auto rows = [&](int64_t t) {
    std::vector<int32_t> found(around * fullest + 1);  // a row's neighbours, all of them
    const int64_t lo = n * t / threads, hi = n * (t + 1) / threads;
    int64_t most = 0;
    for (int64_t a = lo; a < hi; a++) {
      int64_t cell[D];
      for (int64_t i = 0, rest = own[a]; i < D; i++) {
        cell[i] = rest % g.cells[i];
        rest /= g.cells[i];
      }
      T xa[D];
      for (int i = 0; i < D; i++) xa[i] = x[a * D + i];
      int64_t found_count = 0;
      for (int64_t s = 0; s < around; s++) {
        int64_t key = 0, stride = 1;
        for (int i = 0; i < D; i++) {  // (c + o) mod cells, o in {-1, 0, 1}
          int64_t c = cell[i] + offsets[s * D + i];
          c += c < 0 ? g.cells[i] : (c >= g.cells[i] ? -g.cells[i] : 0);
          key += stride * c;
          stride *= g.cells[i];
        }
        const int64_t begin = first[key], m = first[key + 1] - begin, start = turn[key];
        // the members in their slots' order; without a branch: which b is in is
        // unpredictable
        for (int64_t r = 0; r < m; r++) {
          const int64_t j = begin + (r + start < m ? r + start : r + start - m);
          T r2 = T(0);
          for (int i = 0; i < D; i++) {
            const T d = wrapped(xa[i] - xs[i * n + j], g.box[i], g.half[i]);
            r2 += d * d;
          }
          found[found_count] = member[j];
          found_count += (r2 < g.radius2) & (member[j] != a);
        }
      }
      most = std::max(most, found_count);
      int32_t* row = idx + a * k;
      const int64_t kept = std::min(found_count, k);
      std::copy(found.begin(), found.begin() + kept, row);
      std::fill(row + kept, row + k, static_cast<int32_t>(n));
    }
    widest[t] = most;
  };
  in_parallel(pool, threads, rows);
  sizes[0] = static_cast<int32_t>(*std::max_element(widest.begin(), widest.end()));
  sizes[1] = static_cast<int32_t>(fullest);
}

template <typename T>
Grid<T> grid(double lx, double ly, double lz, double cx, double cy, double cz, int64_t nx,
             int64_t ny, int64_t nz, double radius2, int64_t capacity) {
  Grid<T> g;
  const double box[3] = {lx, ly, lz}, size[3] = {cx, cy, cz};
  const int64_t cells[3] = {nx, ny, nz};
  for (int i = 0; i < 3; i++) {
    g.box[i] = T(box[i]);
    g.half[i] = g.box[i] * T(0.5);
    g.cell_size[i] = T(size[i]);
    g.cells[i] = std::max<int64_t>(1, cells[i]);
  }
  g.radius2 = T(radius2);
  g.capacity = capacity;
  return g;
}

ffi::Error CellListRebuild(ffi::ThreadPool pool, ffi::AnyBuffer x,
                           ffi::Result<ffi::Buffer<ffi::S32>> idx,
                           ffi::Result<ffi::Buffer<ffi::S32>> sizes, double lx, double ly,
                           double lz, double cx, double cy, double cz, int64_t nx, int64_t ny,
                           int64_t nz, double radius2, int64_t capacity) {
  auto xd = x.dimensions();
  if (xd.size() != 2 || (xd[1] != 2 && xd[1] != 3))
    return ffi::Error::InvalidArgument("positions must be [N, 2] or [N, 3]");
  if (x.element_type() != ffi::F32 && x.element_type() != ffi::F64)
    return ffi::Error::InvalidArgument("positions must be float32 or float64");
  auto id = idx->dimensions();
  if (id.size() != 2 || id[0] != xd[0])
    return ffi::Error::InvalidArgument("the neighbour list must be [N, K]");
  if (sizes->element_count() != 2)
    return ffi::Error::InvalidArgument("the sizes must be two numbers");
  const int64_t n = xd[0], k = id[1];
  int32_t* out = idx->typed_data();
  int32_t* counts = sizes->typed_data();
  const bool single = x.element_type() == ffi::F32;
  const void* data = x.untyped_data();
  if (single) {
    auto g = grid<float>(lx, ly, lz, cx, cy, cz, nx, ny, nz, radius2, capacity);
    if (xd[1] == 2) rebuild<float, 2>(&pool, g, static_cast<const float*>(data), n, k, out, counts);
    else rebuild<float, 3>(&pool, g, static_cast<const float*>(data), n, k, out, counts);
  } else {
    auto g = grid<double>(lx, ly, lz, cx, cy, cz, nx, ny, nz, radius2, capacity);
    if (xd[1] == 2) rebuild<double, 2>(&pool, g, static_cast<const double*>(data), n, k, out, counts);
    else rebuild<double, 3>(&pool, g, static_cast<const double*>(data), n, k, out, counts);
  }
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxCellListRebuild, CellListRebuild,
                              ffi::Ffi::Bind()
                                  .Ctx<ffi::ThreadPool>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Ret<ffi::Buffer<ffi::S32>>()
                                  .Ret<ffi::Buffer<ffi::S32>>()
                                  .Attr<double>("lx")
                                  .Attr<double>("ly")
                                  .Attr<double>("lz")
                                  .Attr<double>("cx")
                                  .Attr<double>("cy")
                                  .Attr<double>("cz")
                                  .Attr<int64_t>("nx")
                                  .Attr<int64_t>("ny")
                                  .Attr<int64_t>("nz")
                                  .Attr<double>("radius2")
                                  .Attr<int64_t>("capacity"));
