// sphjax's pair sums within one fluid as compiled loops, called from XLA (FFI handlers).
//
// The pair sums of sphjax.physics.pairs.pair_sum over a symmetric neighbour list
// (b in N(a) iff a in N(b)) evaluate each pair once and add its term to both particles:
// for a term f with f(b, a) = parity f(a, b) and the weight w_b,
//
//     out_a += w_b f(a, b),    out_b += parity w_a f(a, b)          (each pair a < b once)
//
// which halves the pair arithmetic of XLA's sum, which visits every pair from both
// sides.  The threads of XLA's CPU pool take equal ranges of rows and add into their own
// copies of the output, summed at the end (no two threads write one number).
//
// Sums (one handler each, float32 or float64, 2 or 3 dimensions):
//   sphjax_kernel_sum          sum_b m_b W_ab                          (eq. 5 without the
//                                                                       self term)
//   sphjax_velocity_divergence sum_b m_b (v_a - v_b) . grad_a W_ab     (eq. 11)
//   sphjax_continuity_molteni  eq. 11 plus Molteni & Colagrossi's density diffusion
//                              (hydrostatic part removed; not symmetric: both roles)
//   sphjax_momentum            sum_b m_b [-(P_a + P_b + Pi_ab) grad_a W_ab
//                                   + nu (1/rho_a + 1/rho_b) (r_ab . grad_a W_ab)
//                                     / (r_ab^2 + 0.01 h^2) v_ab]      (eq. 10, Monaghan's
//                                                                       Pi_ab and Morris'
//                                                                       viscosity optional)
// with P = p / rho^2.  Pair geometry as sphjax.physics.pairs.Geometry: r_ab = x_a - x_b
// with the minimum image on periodic axes, pairs with |r_ab| >= cutoff left out, W and
// grad_a W = W'(r) / r r_ab of the kernel (0 at r = 0).
#include <cstdint>
#include <vector>

#include "pair_loop.h"
#include "xla/ffi/api/ffi.h"

using namespace sphjax_native;

namespace {

constexpr double kEta2 = 0.01;  // the 0.01 h^2 in the viscous denominators

// ------------------------------------------------------------------ the sums
//
// Each sum is a Term of pair_loop.h's each_pair_once.

template <typename T, int D>
struct KernelSumTerm {  // sum_b m_b W_ab
  static constexpr bool within = true, between = true;
  static constexpr int width = 1, fields = 1;
  const T* m;
  void load(int64_t b, T* into, int64_t stride) const { into[0] = m[b]; }
  T row(int64_t a) const { return m[a]; }
  void pair(T m_a, const Pair<T, D>& p, const T* from, int64_t stride, T* on_a, T* on_b,
            int64_t step) const {
    on_a[0] = from[0] * p.w;
    on_b[0] = m_a * p.w;
  }
};

template <typename T, int D>
struct Own {  // what the divergence and the diffusion read of a
  T m, rho, v[D];
};

template <typename T, int D>
struct DivergenceTerm {  // sum_b m_b (v_a - v_b) . grad_a W_ab
  static constexpr bool within = true, between = true;
  static constexpr int width = 1, fields = 1 + D;
  const T *m, *v;
  void load(int64_t b, T* into, int64_t stride) const {
    into[0] = m[b];
    for (int i = 0; i < D; i++) into[(1 + i) * stride] = v[b * D + i];
  }
  Own<T, D> row(int64_t a) const {
    Own<T, D> o{m[a], T(0), {}};
    for (int i = 0; i < D; i++) o.v[i] = v[a * D + i];
    return o;
  }
  void pair(const Own<T, D>& o, const Pair<T, D>& p, const T* from, int64_t stride, T* on_a,
            T* on_b, int64_t step) const {
    T flux = T(0);
    for (int i = 0; i < D; i++) flux += (o.v[i] - from[(1 + i) * stride]) * p.grad[i];
    on_a[0] = from[0] * flux;
    on_b[0] = o.m * flux;
  }
};

struct DiffusionParameters {
  double gravity[3], reference_density, sound_speed, delta;
};

// eq. 11 with Molteni & Colagrossi's density diffusion, the hydrostatic part of the
// density difference removed: per pair m_b v_ab . grad_a W + delta h c0 2 (rho_a - rho_b -
// rho0 g . r_ab / c0^2) (r_ab . grad_a W) / (r_ab^2 + 0.01 h^2) m_b / rho_b, and for b the
// same with a and b swapped (r_ba = -r_ab, grad_b W_ba = -grad_a W_ab)
template <typename T, int D>
struct MolteniTerm {
  static constexpr bool within = true, between = false;
  static constexpr int width = 1, fields = 2 + D;
  const T *m, *v, *rho;
  T hydrostatic[D], diffusion, eta2;
  void load(int64_t b, T* into, int64_t stride) const {
    into[0] = m[b];
    into[stride] = rho[b];
    for (int i = 0; i < D; i++) into[(2 + i) * stride] = v[b * D + i];
  }
  Own<T, D> row(int64_t a) const {
    Own<T, D> o{m[a], rho[a], {}};
    for (int i = 0; i < D; i++) o.v[i] = v[a * D + i];
    return o;
  }
  void pair(const Own<T, D>& o, const Pair<T, D>& p, const T* from, int64_t stride, T* on_a,
            T* on_b, int64_t step) const {
    const T m_b = from[0], rho_b = from[stride];
    T flux = T(0), along = T(0), drho = o.rho - rho_b;
    for (int i = 0; i < D; i++) {
      flux += (o.v[i] - from[(2 + i) * stride]) * p.grad[i];
      along += p.dr[i] * p.grad[i];
      drho -= hydrostatic[i] * p.dr[i];
    }
    const T spread = diffusion * T(2) * drho * along / (p.r2 + eta2);
    on_a[0] = m_b * flux + spread * (m_b / rho_b);
    on_b[0] = o.m * flux - spread * (o.m / o.rho);
  }
};

struct MomentumParameters {
  double sound_speed, alpha, beta, nu;
  bool artificial, morris;
};

template <typename T, int D>
struct OwnMomentum {
  T m, rho, P, inv, v[D];
};

// eq. 10 per pair: -(P_a + P_b + Pi_ab) grad_a W + Morris, times m_b for a and -m_a for b
// (antisymmetric); P = p / rho^2; the viscosities' switches are factors 0 or 1
template <typename T, int D>
struct MomentumTerm {
  static constexpr bool within = true, between = true;
  static constexpr int width = D, fields = 4 + D;
  const T *m, *v, *rho, *P, *inv;
  T h, c0, alpha, beta, nu, artificial, morris, eta2;
  void load(int64_t b, T* into, int64_t stride) const {
    into[0] = m[b];
    into[stride] = rho[b];
    into[2 * stride] = P[b];
    into[3 * stride] = inv[b];
    for (int i = 0; i < D; i++) into[(4 + i) * stride] = v[b * D + i];
  }
  OwnMomentum<T, D> row(int64_t a) const {
    OwnMomentum<T, D> o{m[a], rho[a], P[a], inv[a], {}};
    for (int i = 0; i < D; i++) o.v[i] = v[a * D + i];
    return o;
  }
  void pair(const OwnMomentum<T, D>& o, const Pair<T, D>& p, const T* from, int64_t stride,
            T* on_a, T* on_b, int64_t step) const {
    const T m_b = from[0], rho_b = from[stride], P_b = from[2 * stride], inv_b = from[3 * stride];
    T v_ab[D], vr = T(0), along = T(0);
    for (int i = 0; i < D; i++) {
      v_ab[i] = o.v[i] - from[(4 + i) * stride];
      vr += v_ab[i] * p.dr[i];
      along += p.dr[i] * p.grad[i];
    }
    const T inverse_denominator = T(1) / (p.r2 + eta2);
    const T mu = h * vr * inverse_denominator;
    const T pi = (-alpha * c0 * mu + beta * mu * mu) / (T(0.5) * (o.rho + rho_b));
    const T term = o.P + P_b + (vr < T(0) ? artificial * pi : T(0));
    const T factor = morris * nu * (o.inv + inv_b) * along * inverse_denominator;
    for (int i = 0; i < D; i++) {
      const T f = -term * p.grad[i] + factor * v_ab[i];
      on_a[i * step] = m_b * f;
      on_b[i * step] = -o.m * f;
    }
  }
};

// The particles on one side of a sum: the rows, or the columns of another system (the
// fields a sum does not read are null).
template <typename T>
struct Side {
  const T *x, *m, *v, *rho, *p;
  int64_t n;
};

// where a sum runs: XLA's threads, the kernel, the list's width, within one system
// (each pair once) or rows against the columns of another
struct Where {
  ffi::ThreadPool* pool;
  int kernel;
  int64_t k;
  bool cross;
};

template <typename T, int D, typename Term>
void over_pairs(const Where& at, const Setting<T>& s, const Side<T>& a, const Side<T>& b,
                const int32_t* idx, T* out, const Term& rows, const Term& columns) {
  sum_pairs<T, D>(at.pool, at.kernel, s, a.x, b.x, idx, a.n, b.n, at.k, out, rows,
                  at.cross ? &columns : nullptr);
}

template <typename T, int D>
void kernel_sum(const Where& at, const Setting<T>& s, const Side<T>& a, const Side<T>& b,
                const int32_t* idx, T* out) {
  over_pairs<T, D>(at, s, a, b, idx, out, KernelSumTerm<T, D>{a.m}, KernelSumTerm<T, D>{b.m});
}

template <typename T, int D>
void velocity_divergence(const Where& at, const Setting<T>& s, const Side<T>& a,
                         const Side<T>& b, const int32_t* idx, T* out) {
  over_pairs<T, D>(at, s, a, b, idx, out, DivergenceTerm<T, D>{a.m, a.v},
                   DivergenceTerm<T, D>{b.m, b.v});
}

template <typename T, int D>
void continuity_molteni(const Where& at, const Setting<T>& s, const DiffusionParameters& dp,
                        const Side<T>& a, const int32_t* idx, T* out) {
  MolteniTerm<T, D> term{a.m, a.v, a.rho, {}, T(0), T(kEta2) * s.h * s.h};
  const T c0 = T(dp.sound_speed);
  term.diffusion = T(dp.delta) * s.h * c0;
  for (int i = 0; i < D; i++) term.hydrostatic[i] = T(dp.reference_density * dp.gravity[i]) / (c0 * c0);
  over_pairs<T, D>(at, s, a, a, idx, out, term, term);
}

// the per-particle numbers the momentum term reads instead of dividing per pair
template <typename T>
struct Coefficients {
  std::vector<T> P, inverse;  // p / rho^2, 1 / rho
  explicit Coefficients(const Side<T>& side) : P(side.n), inverse(side.n) {
    for (int64_t a = 0; a < side.n; a++) {
      inverse[a] = T(1) / side.rho[a];
      P[a] = side.p[a] * (inverse[a] * inverse[a]);
    }
  }
};

template <typename T, int D>
void momentum(const Where& at, const Setting<T>& s, const MomentumParameters& mp,
              const Side<T>& a, const Side<T>& b, const int32_t* idx, T* out) {
  auto term = [&](const Side<T>& side, const Coefficients<T>& c) {
    return MomentumTerm<T, D>{side.m,
                              side.v,
                              side.rho,
                              c.P.data(),
                              c.inverse.data(),
                              s.h,
                              T(mp.sound_speed),
                              T(mp.alpha),
                              T(mp.beta),
                              T(mp.nu),
                              mp.artificial ? T(1) : T(0),
                              mp.morris ? T(1) : T(0),
                              T(kEta2) * s.h * s.h};
  };
  const Coefficients<T> of_a(a);
  if (!at.cross) return over_pairs<T, D>(at, s, a, a, idx, out, term(a, of_a), term(a, of_a));
  const Coefficients<T> of_b(b);
  over_pairs<T, D>(at, s, a, b, idx, out, term(a, of_a), term(b, of_b));
}

// Adami et al.'s extrapolation onto a boundary particle a from its fluid neighbours b, per
// pair: W_ab, p_b W_ab, rho_b W_ab r_ab and W_ab v_b (rows against columns only)
template <typename T, int D>
struct ExtrapolationTerm {
  static constexpr bool within = false, between = true;
  static constexpr int width = 2 + 2 * D, fields = 2 + D;
  const T *p, *rho, *v;
  void load(int64_t b, T* into, int64_t stride) const {
    into[0] = p[b];
    into[stride] = rho[b];
    for (int i = 0; i < D; i++) into[(2 + i) * stride] = v[b * D + i];
  }
  int row(int64_t) const { return 0; }
  void pair(int, const Pair<T, D>& q, const T* from, int64_t stride, T* on_a, T* on_b,
            int64_t step) const {
    on_a[0] = q.w;
    on_a[step] = from[0] * q.w;
    for (int i = 0; i < D; i++) {
      on_a[(2 + i) * step] = from[stride] * q.w * q.dr[i];
      on_a[(2 + D + i) * step] = q.w * from[(2 + i) * stride];
    }
    on_b[0] = T(0);
  }
};

template <typename T, int D>
void extrapolation(const Where& at, const Setting<T>& s, const Side<T>& a, const Side<T>& b,
                   const int32_t* idx, T* out) {
  const ExtrapolationTerm<T, D> columns{b.p, b.rho, b.v};
  over_pairs<T, D>(at, s, a, b, idx, out, columns, columns);
}

// ------------------------------------------------------------------ FFI handlers

template <typename T>
const T* optional(const ffi::AnyBuffer* buffer) {
  return buffer == nullptr ? nullptr : data<T>(*buffer);
}

ffi::Error check(const ffi::AnyBuffer& x, const ffi::AnyBuffer& x_columns,
                 const ffi::Buffer<ffi::S32>& idx) {
  auto xd = x.dimensions();
  if (xd.size() != 2 || (xd[1] != 2 && xd[1] != 3))
    return ffi::Error::InvalidArgument("positions must be [N, 2] or [N, 3]");
  if (x.element_type() != ffi::F32 && x.element_type() != ffi::F64)
    return ffi::Error::InvalidArgument("positions must be float32 or float64");
  auto cd = x_columns.dimensions();
  if (cd.size() != 2 || cd[1] != xd[1] || x_columns.element_type() != x.element_type())
    return ffi::Error::InvalidArgument("the columns' positions must be [M, d] as the rows'");
  if (idx.dimensions().size() != 2 || idx.dimensions()[0] != xd[0])
    return ffi::Error::InvalidArgument("the neighbour list must be [N, K]");
  return ffi::Error::Success();
}


// One call: where it runs, the pair geometry, and the fields of its two sides as buffers
// (a field a sum does not read: nullptr).
struct Call {
  ffi::ThreadPool* pool;
  int64_t kernel, k;
  double h, cutoff, sigma, lx, ly, lz;
  int64_t periodic;
  bool cross;
  int dim;
  Call(ffi::ThreadPool& pool, const ffi::AnyBuffer& x, const ffi::Buffer<ffi::S32>& idx,
       SPHJAX_SETTING_ATTRS)
      : pool(&pool), kernel(kernel), k(idx.dimensions()[1]), h(h), cutoff(cutoff),
        sigma(sigma), lx(lx), ly(ly), lz(lz), periodic(periodic), cross(cross),
        dim(static_cast<int>(x.dimensions()[1])) {}
  template <typename T>
  Setting<T> geometry() const {
    return setting<T>(dim, h, cutoff, sigma, lx, ly, lz, periodic);
  }
  Where where() const { return Where{pool, static_cast<int>(kernel), k, cross}; }
};

struct Buffers {  // x, m, v, rho, p of one side
  const ffi::AnyBuffer *x, *m, *v, *rho, *p;
  template <typename T>
  Side<T> side() const {
    return Side<T>{optional<T>(x), optional<T>(m), optional<T>(v), optional<T>(rho),
                   optional<T>(p), x->dimensions()[0]};
  }
};

// Run Sum<T, D>::run(...) for the call's element type and dimension.
template <template <typename, int> class Sum, typename... Args>
ffi::Error dispatch(const ffi::AnyBuffer& x, Args&&... args) {
  const bool single = x.element_type() == ffi::F32;
  const int64_t dim = x.dimensions()[1];
  if (single && dim == 2) Sum<float, 2>::run(args...);
  if (single && dim == 3) Sum<float, 3>::run(args...);
  if (!single && dim == 2) Sum<double, 2>::run(args...);
  if (!single && dim == 3) Sum<double, 3>::run(args...);
  return ffi::Error::Success();
}

template <typename T, int D>
struct KernelSumBody {
  static void run(const Call& c, const Buffers& a, const Buffers& b, const int32_t* idx,
                  ffi::Result<ffi::AnyBuffer>& out) {
    kernel_sum<T, D>(c.where(), c.geometry<T>(), a.side<T>(), b.side<T>(), idx, data<T>(out));
  }
};

template <typename T, int D>
struct DivergenceBody {
  static void run(const Call& c, const Buffers& a, const Buffers& b, const int32_t* idx,
                  ffi::Result<ffi::AnyBuffer>& out) {
    velocity_divergence<T, D>(c.where(), c.geometry<T>(), a.side<T>(), b.side<T>(), idx,
                              data<T>(out));
  }
};

template <typename T, int D>
struct MolteniBody {
  static void run(const Call& c, const DiffusionParameters& dp, const Buffers& a,
                  const int32_t* idx, ffi::Result<ffi::AnyBuffer>& out) {
    continuity_molteni<T, D>(c.where(), c.geometry<T>(), dp, a.side<T>(), idx, data<T>(out));
  }
};

template <typename T, int D>
struct MomentumBody {
  static void run(const Call& c, const MomentumParameters& mp, const Buffers& a,
                  const Buffers& b, const int32_t* idx, ffi::Result<ffi::AnyBuffer>& out) {
    momentum<T, D>(c.where(), c.geometry<T>(), mp, a.side<T>(), b.side<T>(), idx, data<T>(out));
  }
};

template <typename T, int D>
struct ExtrapolationBody {
  static void run(const Call& c, const Buffers& a, const Buffers& b, const int32_t* idx,
                  ffi::Result<ffi::AnyBuffer>& out) {
    extrapolation<T, D>(c.where(), c.geometry<T>(), a.side<T>(), b.side<T>(), idx,
                        data<T>(out));
  }
};

// a parameter passed as a 0-d or 1-d array of the run's dtype, as a double
double value(const ffi::AnyBuffer& x, const ffi::AnyBuffer& b, int i = 0) {
  return x.element_type() == ffi::F32 ? double(data<float>(b)[i]) : data<double>(b)[i];
}

ffi::Error KernelSum(ffi::ThreadPool pool, ffi::AnyBuffer x, ffi::AnyBuffer m,
                     ffi::AnyBuffer x_b, ffi::AnyBuffer m_b, ffi::Buffer<ffi::S32> idx,
                     ffi::Result<ffi::AnyBuffer> out, SPHJAX_SETTING_ATTRS) {
  if (auto e = check(x, x_b, idx); e.failure()) return e;
  const Call c(pool, x, idx, SPHJAX_SETTING_NAMES);
  const Buffers a{&x, &m, nullptr, nullptr, nullptr}, b{&x_b, &m_b, nullptr, nullptr, nullptr};
  return dispatch<KernelSumBody>(x, c, a, b, idx.typed_data(), out);
}

ffi::Error VelocityDivergence(ffi::ThreadPool pool, ffi::AnyBuffer x, ffi::AnyBuffer v,
                              ffi::AnyBuffer m, ffi::AnyBuffer x_b, ffi::AnyBuffer v_b,
                              ffi::AnyBuffer m_b, ffi::Buffer<ffi::S32> idx,
                              ffi::Result<ffi::AnyBuffer> out, SPHJAX_SETTING_ATTRS) {
  if (auto e = check(x, x_b, idx); e.failure()) return e;
  const Call c(pool, x, idx, SPHJAX_SETTING_NAMES);
  const Buffers a{&x, &m, &v, nullptr, nullptr}, b{&x_b, &m_b, &v_b, nullptr, nullptr};
  return dispatch<DivergenceBody>(x, c, a, b, idx.typed_data(), out);
}

ffi::Error ContinuityMolteni(ffi::ThreadPool pool, ffi::AnyBuffer x, ffi::AnyBuffer v,
                             ffi::AnyBuffer m, ffi::AnyBuffer rho, ffi::Buffer<ffi::S32> idx,
                             ffi::AnyBuffer gravity, ffi::AnyBuffer reference_density,
                             ffi::AnyBuffer sound_speed, ffi::AnyBuffer delta,
                             ffi::Result<ffi::AnyBuffer> out, SPHJAX_SETTING_ATTRS) {
  if (auto e = check(x, x, idx); e.failure()) return e;
  if (cross) return ffi::Error::InvalidArgument("the diffusion sum is within one fluid");
  const Call c(pool, x, idx, SPHJAX_SETTING_NAMES);
  DiffusionParameters dp{{0.0, 0.0, 0.0}, value(x, reference_density), value(x, sound_speed),
                         value(x, delta)};
  for (int i = 0; i < c.dim; i++) dp.gravity[i] = value(x, gravity, i);
  const Buffers a{&x, &m, &v, &rho, nullptr};
  return dispatch<MolteniBody>(x, c, dp, a, idx.typed_data(), out);
}

ffi::Error Momentum(ffi::ThreadPool pool, ffi::AnyBuffer x, ffi::AnyBuffer v, ffi::AnyBuffer m,
                    ffi::AnyBuffer rho, ffi::AnyBuffer p, ffi::AnyBuffer x_b,
                    ffi::AnyBuffer v_b, ffi::AnyBuffer m_b, ffi::AnyBuffer rho_b,
                    ffi::AnyBuffer p_b, ffi::Buffer<ffi::S32> idx, ffi::AnyBuffer sound_speed,
                    ffi::AnyBuffer alpha, ffi::AnyBuffer beta, ffi::AnyBuffer nu,
                    ffi::Result<ffi::AnyBuffer> out, SPHJAX_SETTING_ATTRS, bool artificial,
                    bool morris) {
  if (auto e = check(x, x_b, idx); e.failure()) return e;
  const Call c(pool, x, idx, SPHJAX_SETTING_NAMES);
  MomentumParameters mp{value(x, sound_speed), value(x, alpha), value(x, beta), value(x, nu),
                        artificial, morris};
  const Buffers a{&x, &m, &v, &rho, &p}, b{&x_b, &m_b, &v_b, &rho_b, &p_b};
  return dispatch<MomentumBody>(x, c, mp, a, b, idx.typed_data(), out);
}

ffi::Error Extrapolation(ffi::ThreadPool pool, ffi::AnyBuffer x, ffi::AnyBuffer x_b,
                         ffi::AnyBuffer p_b, ffi::AnyBuffer rho_b, ffi::AnyBuffer v_b,
                         ffi::Buffer<ffi::S32> idx, ffi::Result<ffi::AnyBuffer> out,
                         SPHJAX_SETTING_ATTRS) {
  if (auto e = check(x, x_b, idx); e.failure()) return e;
  if (!cross) return ffi::Error::InvalidArgument("the extrapolation is onto another system");
  const Call c(pool, x, idx, SPHJAX_SETTING_NAMES);
  const Buffers a{&x, nullptr, nullptr, nullptr, nullptr}, b{&x_b, nullptr, &v_b, &rho_b, &p_b};
  return dispatch<ExtrapolationBody>(x, c, a, b, idx.typed_data(), out);
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxKernelSum, KernelSum, SPHJAX_BIND(4, 0));
XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxVelocityDivergence, VelocityDivergence, SPHJAX_BIND(6, 0));
XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxContinuityMolteni, ContinuityMolteni, SPHJAX_BIND(4, 4));
XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxMomentum, Momentum,
                              SPHJAX_BIND(10, 4).Attr<bool>("artificial").Attr<bool>("morris"));
XLA_FFI_DEFINE_HANDLER_SYMBOL(SphjaxExtrapolation, Extrapolation, SPHJAX_BIND(5, 0));
