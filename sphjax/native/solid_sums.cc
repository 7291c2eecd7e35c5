// The pair sums of an elastic solid (total-Lagrangian SPH) as compiled loops, called
// from XLA (FFI handlers).
//
// The penalty force's momentum goes over the solid's reference neighbour list (symmetric:
// b in N(a) iff a in N(b)) with pair_loop.h's each_pair_once, each pair once, its term added to both particles.
// The pair geometry of the loop is the reference one: X_ab = X_a - X_b (minimum image on
// periodic axes), W(X_ab) and grad0_a W(X_ab), from the reference positions X; the
// current positions x are a field of the sums (x_ab = x_a - x_b, minimum image).
//
//   sphjax_solid_momentum     sum_b V0_b [(P L0)_a + (P L0)_b] grad0_a W(X_ab) / rho0
//                             + the penalty force f^PF_ab / (V0_a V0_b rho0)
//                             (eq. 14 per unit mass with rho0 = m0 / V0; Ganzenmüller 2015's
//                             hourglass penalty, sphjax.physics.solid.penalty), antisymmetric
//                             under a <-> b: b receives -V0_a times a's term.
#include <cmath>
#include <cstdint>
#include <vector>

#include "pair_loop.h"
#include "xla/ffi/api/ffi.h"

using namespace sphjax_native;

namespace {

// x_a - x_b with the minimum image on the box's periodic axes (size 0 elsewhere)
template <typename T, int D>
struct Box {
  T size[D], inverse[D];
  static Box of(const Setting<T>& s) {
    Box box;
    for (int i = 0; i < D; i++) {
      box.size[i] = s.size[i];
      box.inverse[i] = s.inverse[i];
    }
    return box;
  }
  T image(T d, int i) const { return d - size[i] * std::nearbyint(d * inverse[i]); }
};

template <typename T, int D>
struct OwnSolid {
  T V, x[D], PL0[D * D], F[D * D];
};

// eq. 14 per pair per unit neighbour volume, with Ganzenmüller's penalty force when
// Penalty: on a V0_b times it, on b -V0_a times it.  Fields per neighbour: V0, P L0 and,
// with the penalty, x and F.
template <typename T, int D, bool Penalty>
struct SolidMomentumTerm {
  static constexpr bool within = true, between = false;
  static constexpr int width = D, fields = 1 + D * D + (Penalty ? D + D * D : 0);
  const T *V, *x, *PL0, *F;
  Box<T, D> box;
  T inverse_rho0, stiffness;  // 1 / rho0 and alpha E / 2
  void load(int64_t b, T* into, int64_t stride) const {
    into[0] = V[b];
    for (int i = 0; i < D * D; i++) into[(1 + i) * stride] = PL0[b * D * D + i];
    if (Penalty) {
      for (int i = 0; i < D; i++) into[(1 + D * D + i) * stride] = x[b * D + i];
      for (int i = 0; i < D * D; i++) into[(1 + D * D + D + i) * stride] = F[b * D * D + i];
    }
  }
  OwnSolid<T, D> row(int64_t a) const {
    OwnSolid<T, D> o{V[a], {}, {}, {}};
    for (int i = 0; i < D * D; i++) o.PL0[i] = PL0[a * D * D + i];
    if (Penalty) {
      for (int i = 0; i < D; i++) o.x[i] = x[a * D + i];
      for (int i = 0; i < D * D; i++) o.F[i] = F[a * D * D + i];
    }
    return o;
  }
  void pair(const OwnSolid<T, D>& o, const Pair<T, D>& p, const T* from, int64_t stride,
            T* on_a, T* on_b, int64_t step) const {
    const T V_b = from[0];
    T acceleration[D];
    for (int i = 0; i < D; i++) {  // ((P L0)_a + (P L0)_b) grad0_a W / rho0
      T sum = T(0);
      for (int j = 0; j < D; j++)
        sum += (o.PL0[i * D + j] + from[(1 + i * D + j) * stride]) * p.grad[j];
      acceleration[i] = sum * inverse_rho0;
    }
    if (Penalty) {
      // f_ab = alpha E / 2 W0 / |X_ab|^2 (eps_a + eps_b) . u u,  eps = F X_ab - x_ab,
      // u = x_ab / |x_ab|; none for coincident particles (now or in the reference)
      const T* x_b = from + (1 + D * D) * stride;
      const T* F_b = from + (1 + D * D + D) * stride;
      T dx[D], r2 = T(0);
      for (int i = 0; i < D; i++) {
        dx[i] = box.image(o.x[i] - x_b[i * stride], i);
        r2 += dx[i] * dx[i];
      }
      // (eps . u) u = (eps . x_ab) x_ab / |x_ab|^2: no square root
      const bool ok = (r2 > T(0)) & (p.r2 > T(0));
      T along = T(0);  // (eps_a + eps_b) . x_ab
      for (int i = 0; i < D; i++) {
        T eps = T(-2) * dx[i];
        for (int j = 0; j < D; j++) eps += (o.F[i * D + j] + F_b[(i * D + j) * stride]) * p.dr[j];
        along += eps * dx[i];
      }
      const T magnitude =
          ok ? stiffness * inverse_rho0 * p.w * along / (ok ? p.r2 * r2 : T(1)) : T(0);
      for (int i = 0; i < D; i++) acceleration[i] += magnitude * dx[i];
    }
    for (int i = 0; i < D; i++) {
      on_a[i * step] = V_b * acceleration[i];
      on_b[i * step] = -o.V * acceleration[i];
    }
  }
};

template <typename T, int D>
void solid_momentum(ffi::ThreadPool* pool, int kernel, const Setting<T>& s, const T* X,
                    const T* x, const T* V, const T* PL0, const T* F, const int32_t* idx,
                    int64_t n, int64_t k, T rho0, T young_modulus, T alpha, bool penalty,
                    T* out) {
  const T inverse_rho0 = T(1) / rho0, stiffness = T(0.5) * alpha * young_modulus;
  if (penalty) {
    SolidMomentumTerm<T, D, true> term{V, x, PL0, F, Box<T, D>::of(s), inverse_rho0, stiffness};
    by_kernel<T, D>(pool, kernel, s, X, idx, n, k, out, term);
  } else {
    SolidMomentumTerm<T, D, false> term{V, x, PL0, F, Box<T, D>::of(s), inverse_rho0, stiffness};
    by_kernel<T, D>(pool, kernel, s, X, idx, n, k, out, term);
  }
}

// ------------------------------------------------ row by row over stored weights
//
// The same two sums over the solid's fixed reference list row by row (each pair seen
// from both sides, as XLA sums it), reading weights per slot computed once per run
// ([N, K, D]; 0 in the free slots, which index N) instead of recomputing the reference
// geometry: per slot a few scalar loads and products, no gathering into buffers.  (The
// slots as one vectorised loop read the neighbours' fields with the CPU's gather
// instructions: slower here.)  The rows are shared between threads.
//
//   deformation_by_rows   F_a = -sum_b x_ab c_ab^T,   c_ab = V0_b L0_a grad0_a W(X_ab)     (eq. 16)
//   elastic_by_rows       sum_b [(P L0)_a + (P L0)_b] e_ab / rho0
//                         = [(P L0)_a sum_b e_ab + sum_b (P L0)_b e_ab] / rho0,
//                         e_ab = V0_b grad0_a W(X_ab)                                    (eq. 14)

// GCC vectorises a row's loop over its slots with gather instructions, about twice slower
// here than the scalar loop
#define SPHJAX_SCALAR __attribute__((optimize("no-tree-loop-vectorize")))

// x_a - x_b on axis i, the minimum image when Periodic
template <typename T, int D, bool Periodic>
inline T separation(const Box<T, D>& box, T xa, T xb, int i) {
  return Periodic ? box.image(xa - xb, i) : xa - xb;
}

template <typename T, int D, bool Periodic>
void deformation_by_rows(ffi::ThreadPool* pool, const Box<T, D>& box, const T* x,
                         const T* weight, const int32_t* idx, int64_t n, int64_t k, T* F) {
  const int64_t threads = thread_count(pool, n);
  auto rows = [&](int64_t t) SPHJAX_FLATTEN SPHJAX_SCALAR {
    const int64_t lo = n * t / threads, hi = n * (t + 1) / threads;
    for (int64_t a = lo; a < hi; a++) {
      const int32_t* row = idx + a * k;
      const T* c = weight + a * k * D;
      T xa[D];
      for (int i = 0; i < D; i++) xa[i] = x[a * D + i];
      T S[D * D] = {};
      for (int64_t j = 0; j < k; j++) {
        const int64_t b = row[j] < n ? row[j] : a;  // a free slot: x_ab = 0, c = 0
        for (int i = 0; i < D; i++) {
          const T dx = separation<T, D, Periodic>(box, xa[i], x[b * D + i], i);
          for (int m = 0; m < D; m++) S[i * D + m] -= dx * c[j * D + m];
        }
      }
      for (int i = 0; i < D * D; i++) F[a * D * D + i] = S[i];
    }
  };
  in_parallel(pool, threads, rows);
}

template <typename T, int D>
void elastic_by_rows(ffi::ThreadPool* pool, const T* PL0, const T* weight, const int32_t* idx,
                     int64_t n, int64_t k, T rho0, T* out) {
  const int64_t threads = thread_count(pool, n);
  const T inverse_rho0 = T(1) / rho0;
  auto rows = [&](int64_t t) SPHJAX_FLATTEN SPHJAX_SCALAR {
    const int64_t lo = n * t / threads, hi = n * (t + 1) / threads;
    for (int64_t a = lo; a < hi; a++) {
      const int32_t* row = idx + a * k;
      const T* e = weight + a * k * D;
      // H_i's terms by m: chains of additions D times shorter
      T G[D] = {}, H[D * D] = {};
      for (int64_t j = 0; j < k; j++) {
        const int64_t b = row[j] < n ? row[j] : a;  // a free slot: e = 0
        const T* Pb = PL0 + b * D * D;
        for (int m = 0; m < D; m++) {
          G[m] += e[j * D + m];
          for (int i = 0; i < D; i++) H[i * D + m] += Pb[i * D + m] * e[j * D + m];
        }
      }
      const T* Pa = PL0 + a * D * D;
      for (int i = 0; i < D; i++) {
        T sum = T(0);
        for (int m = 0; m < D; m++) sum += H[i * D + m] + Pa[i * D + m] * G[m];
        out[a * D + i] = sum * inverse_rho0;
      }
    }
  };
  in_parallel(pool, threads, rows);
}

// ------------------------------------------------------------------ FFI handlers

ffi::Error check(const ffi::AnyBuffer& X, const ffi::Buffer<ffi::S32>& idx) {
  auto dims = X.dimensions();
  if (dims.size() != 2 || (dims[1] != 2 && dims[1] != 3))
    return ffi::Error::InvalidArgument("reference positions must be [N, 2] or [N, 3]");
  if (X.element_type() != ffi::F32 && X.element_type() != ffi::F64)
    return ffi::Error::InvalidArgument("reference positions must be float32 or float64");
  if (idx.dimensions().size() != 2 || idx.dimensions()[0] != dims[0])
    return ffi::Error::InvalidArgument("the neighbour list must be [N, K]");
  return ffi::Error::Success();
}

// body.template operator()<T, D>() for the call's element type and dimension
template <typename Body>
ffi::Error dispatch(ffi::DataType type, int64_t dim, const Body& body) {
  const bool single = type == ffi::F32;
  if (single && dim == 2) body.template operator()<float, 2>();
  if (single && dim == 3) body.template operator()<float, 3>();
  if (!single && dim == 2) body.template operator()<double, 2>();
  if (!single && dim == 3) body.template operator()<double, 3>();
  return ffi::Error::Success();
}

template <typename T>
T scalar(const ffi::AnyBuffer& buffer) {
  return *data<T>(buffer);
}

struct MomentumBody {
  ffi::ThreadPool* pool;
  const ffi::AnyBuffer &X, &x, &V, &PL0, &F, &rho0, &young_modulus, &alpha;
  const int32_t* idx;
  int64_t n, k;
  ffi::Result<ffi::AnyBuffer>& out;
  int64_t kernel;
  double h, cutoff, sigma, lx, ly, lz;
  int64_t periodic;
  bool penalty;
  template <typename T, int D>
  void operator()() const {
    const Setting<T> s = setting<T>(D, h, cutoff, sigma, lx, ly, lz, periodic);
    solid_momentum<T, D>(pool, int(kernel), s, data<T>(X), data<T>(x), data<T>(V),
                         data<T>(PL0), data<T>(F), idx, n, k, scalar<T>(rho0),
                         scalar<T>(young_modulus), scalar<T>(alpha), penalty, data<T>(out));
  }
};

ffi::Error SolidMomentum(ffi::ThreadPool pool, ffi::AnyBuffer X, ffi::AnyBuffer x,
                         ffi::AnyBuffer V, ffi::AnyBuffer PL0, ffi::AnyBuffer F,
                         ffi::Buffer<ffi::S32> idx, ffi::AnyBuffer rho0,
                         ffi::AnyBuffer young_modulus, ffi::AnyBuffer alpha,
                         ffi::Result<ffi::AnyBuffer> out, SPHJAX_SETTING_ATTRS,
                         bool penalty) {
  if (auto e = check(X, idx); e.failure()) return e;
  if (cross) return ffi::Error::InvalidArgument("a solid's sums are within the solid");
  MomentumBody body{&pool,   X,      x,     V,     PL0, F,  rho0, young_modulus, alpha,
                    idx.typed_data(), X.dimensions()[0], idx.dimensions()[1], out, kernel, h,
                    cutoff,  sigma,  lx,    ly,    lz,  periodic, penalty};
  return dispatch(X.element_type(), X.dimensions()[1], body);
}

// the stored-weight sums: x [N, D], P L0 [N, D, D], the weights per slot [N, K, D], the
// list [N, K]; a box (lx, ly, lz) with its periodic axes (bits of `periodic`)
ffi::Error check_rows(const ffi::AnyBuffer& grad, const ffi::Buffer<ffi::S32>& idx) {
  auto dims = grad.dimensions();
  if (dims.size() != 3 || (dims[2] != 2 && dims[2] != 3))
    return ffi::Error::InvalidArgument("the weights per slot must be [N, K, 2 or 3]");
  if (grad.element_type() != ffi::F32 && grad.element_type() != ffi::F64)
    return ffi::Error::InvalidArgument("the weights per slot must be float32 or float64");
  if (idx.dimensions().size() != 2 || idx.dimensions()[0] != dims[0] ||
      idx.dimensions()[1] != dims[1])
    return ffi::Error::InvalidArgument("the neighbour list must be [N, K]");
  return ffi::Error::Success();
}

struct DeformationRowsBody {
  ffi::ThreadPool* pool;
  const ffi::AnyBuffer &x, &grad;
  const int32_t* idx;
  ffi::Result<ffi::AnyBuffer>& F;
  double lx, ly, lz;
  int64_t periodic;
  template <typename T, int D>
  void operator()() const {
    const Setting<T> s = setting<T>(D, 1.0, 1.0, 1.0, lx, ly, lz, periodic);
    const Box<T, D> box = Box<T, D>::of(s);
    const int64_t n = grad.dimensions()[0], k = grad.dimensions()[1];
    auto run = [&](auto wrapped) {
      deformation_by_rows<T, D, decltype(wrapped)::value>(pool, box, data<T>(x), data<T>(grad),
                                                          idx, n, k, data<T>(F));
    };
    if (periodic) run(std::true_type{});
    else run(std::false_type{});
  }
};

ffi::Error DeformationByRows(ffi::ThreadPool pool, ffi::AnyBuffer x, ffi::AnyBuffer grad,
                             ffi::Buffer<ffi::S32> idx, ffi::Result<ffi::AnyBuffer> F, double lx,
                             double ly, double lz, int64_t periodic) {
  if (auto e = check_rows(grad, idx); e.failure()) return e;
  DeformationRowsBody body{&pool, x, grad, idx.typed_data(), F, lx, ly, lz, periodic};
  return dispatch(grad.element_type(), grad.dimensions()[2], body);
}

struct ElasticRowsBody {
  ffi::ThreadPool* pool;
  const ffi::AnyBuffer &PL0, &grad, &rho0;
  const int32_t* idx;
  ffi::Result<ffi::AnyBuffer>& out;
  template <typename T, int D>
  void operator()() const {
    elastic_by_rows<T, D>(pool, data<T>(PL0), data<T>(grad), idx,
                          grad.dimensions()[0], grad.dimensions()[1], scalar<T>(rho0),
                          data<T>(out));
  }
};

ffi::Error ElasticByRows(ffi::ThreadPool pool, ffi::AnyBuffer PL0, ffi::AnyBuffer grad,
                         ffi::Buffer<ffi::S32> idx, ffi::AnyBuffer rho0,
                         ffi::Result<ffi::AnyBuffer> out) {
  if (auto e = check_rows(grad, idx); e.failure()) return e;
  ElasticRowsBody body{&pool, PL0, grad, rho0, idx.typed_data(), out};
  return dispatch(grad.element_type(), grad.dimensions()[2], body);
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxSolidMomentum, SolidMomentum,
                              SPHJAX_BIND(5, 3).Attr<bool>("penalty"));
XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxDeformationByRows, DeformationByRows,
                              ffi::Ffi::Bind()
                                  .Ctx<ffi::ThreadPool>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::Buffer<ffi::S32>>()
                                  .Ret<ffi::AnyBuffer>()
                                  .Attr<double>("lx")
                                  .Attr<double>("ly")
                                  .Attr<double>("lz")
                                  .Attr<int64_t>("periodic"));
XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxElasticByRows, ElasticByRows,
                              ffi::Ffi::Bind()
                                  .Ctx<ffi::ThreadPool>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Arg<ffi::Buffer<ffi::S32>>()
                                  .Arg<ffi::AnyBuffer>()
                                  .Ret<ffi::AnyBuffer>());
