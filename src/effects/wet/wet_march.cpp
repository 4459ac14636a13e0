// brume — the camera's mirror march (wet_march.hpp): a batch of rays, 8 side by side in a vector
// of doubles (AVX-512), written once with Highway and compiled for every target of core/simd.hpp,
// the CPU choosing at run time (HWY_DYNAMIC_DISPATCH). Where a vector holds fewer than 8 doubles
// (AVX2: 4, SSE4 and the fallback: 2) the lanes were measured slower than render_wet's march a
// ray at a time (1.16x, 1.8x and 5x the time on KITTI 000001), so the kernel declines there and
// wet.cpp marches a ray at a time.
//
// Each lane runs one ray's march, render_wet's loop (wet.cpp, march_rays_one_by_one; docs/
// wet-ground.md, "The mirror"), one phase of an iteration a round: at the iteration's top the
// vanishing point's and the lift's tests, then (where the last ask's 8 single steps are done) the
// 32-px blocks asked for a whole step, next round the 8-px ones where those did not clear, and one
// pixel's step and its depth test where neither cleared or single steps are left. A phase reads
// the maps once (one gather: the maps lie in one array) and divides once. Four vectors of rays take
// their rounds in turn (their reads overlap). A lane whose ray ends takes the batch's next ray; a
// ray that crosses the map waits with its state while its lane takes another, and the crossings
// are bisected 8 at a time (a hit ends the ray, else it goes on from where it was).
//
// Every lane performs the scalar loop's IEEE operations in its order: w is added a step at a time
// as before, the products and sums are the same (-ffp-contract=off on this file, CMakeLists.txt:
// AVX-512's FMA never fuses them), Div is correctly rounded as divsd, a pixel's rounding is Trunc
// plus the half's test (round_inside), the depths' products with the margins are taken in float as
// before, and a block index's integer division by the block's size is the floor of the truncated
// coordinate times 1/S (a power of two: exact). Test: WetCamera.MarchSideBySideGivesTheSameBits.
//
// Below the march, render_wet's work on every pixel around it (wet_march.hpp: a row's planar depth
// and ground flags, the rays' set-up and the mirror's Fresnel weight), side by side on every
// target, each the scalar expression's IEEE operations in its order. Test:
// WetCamera.PixelKernelsGiveTheScalarBits.
#include "core/simd.hpp"  // first: the targets

#ifndef BRUME_WET_MARCH_SHARED
#define BRUME_WET_MARCH_SHARED
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "effects/wet/wet_march.hpp"

// (the march's lambdas inlined: GCC left one a call with its vectors passed through memory)
#define BRUME_WET_INLINE __attribute__((always_inline))

namespace brume::detail {

void WetMarchRays::clear() {
  for (auto* v : {&w0, &dw, &uinf, &vinf, &cu, &cv, &major, &w_lift, &hu, &hv}) v->clear();
  flags.clear(), end.clear();
}

void WetMarchRays::push(double w0_, double dw_, double uinf_, double vinf_, double cu_, double cv_, double major_,
                        double w_lift_, std::uint8_t flags_) {
  w0.push_back(w0_), dw.push_back(dw_), uinf.push_back(uinf_), vinf.push_back(vinf_), cu.push_back(cu_);
  cv.push_back(cv_), major.push_back(major_), w_lift.push_back(w_lift_), flags.push_back(flags_);
}

void WetMarchRays::resize(std::size_t n) {
  for (auto* v : {&w0, &dw, &uinf, &vinf, &cu, &cv, &major, &w_lift}) v->resize(n);
  flags.resize(n);
}

}  // namespace brume::detail
#endif

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "effects/wet/wet_march.cpp"
#include <hwy/aligned_allocator.h>
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace brume::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

bool WetMarchRaysK(const WetMarchMaps& m, WetMarchRays& r) {
  const hn::ScalableTag<double> dd;
  const hn::Rebind<float, decltype(dd)> df;
  const hn::Rebind<std::int32_t, decltype(dd)> di;
  using VD = hn::Vec<decltype(dd)>;
  using MD = hn::Mask<decltype(dd)>;
  const std::size_t N = hn::Lanes(dd);
  constexpr std::size_t kMaxLanes = HWY_MAX_BYTES / sizeof(double);
  if (N < 8) return false;
  const std::size_t n = r.size();
  r.end.assign(n, WetMarchRays::leaves), r.hu.assign(n, 0.0), r.hv.assign(n, 0.0);
  const int W = m.width, H = m.height;

  // The lanes' state, in memory between rounds (a lane taking a new ray writes it here): kGroups
  // vectors of rays, their rounds side by side (each round's reads wait on the last's: one vector
  // alone leaves the core idle).
  constexpr std::size_t kGroups = 4;  // (2 and 6 measured the same)
  const std::size_t L = kGroups * N;
  enum {
    kWc,
    kDw,
    kUinf,
    kVinf,
    kCu,
    kCv,
    kMajor,
    kWlift,
    kDzPos,
    kCanLift,
    kLifted,
    kFront,
    kFine,
    kStep,
    kBusy,
    kPhase,
    kEvent,
    kWprev,
    kU,
    kV,
    kStates
  };
  auto st = hwy::AllocateAligned<double>(kStates * L);
  double* S[kStates];
  std::fill(st.get(), st.get() + kStates * L, 0.0);  // (a lane without a ray computes on zeros)
  for (int k = 0; k < kStates; ++k) S[k] = st.get() + k * L;
  std::vector<std::size_t> ray(L, 0);
  std::size_t next = 0;
  // A crossing's ray waits for its bisection (kept with its state, so that a ray that passed behind
  // a surface goes on); the bisections run side by side once a vector's worth wait.
  struct Waiting {
    std::size_t ray;
    double st[kStates];
  };
  std::vector<Waiting> waiting, again;    // crossed; to go on
  const auto take = [&](std::size_t l) {  // lane l takes a ray that goes on, else the next ray, if any
    S[kEvent][l] = 0.0;
    if (!again.empty()) {
      const Waiting& a = again.back();
      for (int k = 0; k < kStates; ++k) S[k][l] = a.st[k];
      ray[l] = a.ray;
      again.pop_back();
      return;
    }
    S[kBusy][l] = next < n ? 1.0 : 0.0;
    if (next >= n) return;
    const std::size_t i = next++;
    ray[l] = i;
    S[kWc][l] = r.w0[i], S[kDw][l] = r.dw[i], S[kUinf][l] = r.uinf[i], S[kVinf][l] = r.vinf[i];
    S[kCu][l] = r.cu[i], S[kCv][l] = r.cv[i], S[kMajor][l] = r.major[i], S[kWlift][l] = r.w_lift[i];
    S[kDzPos][l] = (r.flags[i] & WetMarchRays::dz_positive) ? 1.0 : 0.0;
    S[kCanLift][l] = (r.flags[i] & WetMarchRays::can_lift) ? 1.0 : 0.0;
    S[kLifted][l] = (r.flags[i] & WetMarchRays::lifted) ? 1.0 : 0.0;
    S[kFront][l] = 1.0, S[kFine][l] = 0.0, S[kStep][l] = 0.0, S[kPhase][l] = 0.0;
  };
  for (std::size_t l = 0; l < L; ++l) take(l);
  // a round's events, a lane's bits
  enum { kVanish = 1, kLeave = 2, kCross = 4, kAtMax = 8, kStepped = 16 };

  const VD zero = hn::Zero(dd), one = hn::Set(dd, 1.0), half = hn::Set(dd, 0.5), mhalf = hn::Set(dd, -0.5);
  const VD Wm = hn::Set(dd, W - 0.5), Hm = hn::Set(dd, H - 0.5), Wd = hn::Set(dd, static_cast<double>(W));
  const VD z_off = hn::Set(dd, static_cast<double>(m.z_off));
  const auto fk = hn::Set(df, m.front_k);
  const VD max_steps = hn::Set(dd, static_cast<double>(m.max_steps));
  const auto inside = [&](VD u, VD v) -> MD {
    return hn::And(hn::And(hn::Gt(u, mhalf), hn::Lt(u, Wm)), hn::And(hn::Gt(v, mhalf), hn::Lt(v, Hm)));
  };
  const auto round_inside = [&](VD x) -> VD {
    const VD t = hn::Trunc(x);
    return hn::Add(t, hn::IfThenElseZero(hn::Ge(hn::Sub(x, t), half), one));
  };
  // One round of group g: each lane's ray one phase of an iteration of render_wet's loop (the
  // 32-px blocks asked; the 8-px blocks asked, where 32 did not clear; one pixel's step, where
  // those did not clear or the last ask's 8 single steps are not done): one read of the maps and
  // one division a lane. The lanes whose ray met an event (ended, or crossed the map), a bit each.
  const VD two = hn::Set(dd, 2.0);
  // A round in two halves, each group's first half before any group's second: the first computes
  // the step, issues the read of the maps and the division, the second waits on them and decides
  // (the groups' reads and divisions in flight together, not one group's after another's
  // decisions). Between them, per group: the read, the inverse, the step's end, and the masks.
  enum { kNear, kInv, kW1, kTemps };
  enum { kMDoA, kMDoB, kMDoC, kMOk, kMAskedFits, kMOther, kMVanish, kMasks };
  constexpr std::size_t kMaskBytes = 16;  // (LoadMaskBits reads up to 8 bytes; a mask of up to 64 lanes)
  auto tmp = hwy::AllocateAligned<double>(kTemps * L);
  double* T[kTemps];
  for (int k = 0; k < kTemps; ++k) T[k] = tmp.get() + k * L;
  HWY_ALIGN std::uint8_t mb[kGroups][kMasks][kMaskBytes] = {};
  const auto put = [&](std::size_t g, int k, MD m) BRUME_WET_INLINE { hn::StoreMaskBits(dd, m, mb[g][k]); };
  const auto get = [&](std::size_t g, int k) BRUME_WET_INLINE -> MD { return hn::LoadMaskBits(dd, mb[g][k]); };
  const auto round_a = [&](std::size_t g) BRUME_WET_INLINE {
    const std::size_t o = g * N;
    const VD wc = hn::Load(dd, S[kWc] + o);
    const VD dw = hn::Load(dd, S[kDw] + o), uinf = hn::Load(dd, S[kUinf] + o), vinf = hn::Load(dd, S[kVinf] + o);
    const VD cu = hn::Load(dd, S[kCu] + o), cv = hn::Load(dd, S[kCv] + o);
    VD lifted = hn::Load(dd, S[kLifted] + o);
    const VD fine = hn::Load(dd, S[kFine] + o), ph = hn::Load(dd, S[kPhase] + o);
    const MD act = hn::Gt(hn::Load(dd, S[kBusy] + o), zero);
    const MD dzpos = hn::Gt(hn::Load(dd, S[kDzPos] + o), zero);
    // the top of the loop: within half a pixel of the vanishing point; the lift
    const MD start = hn::And(act, hn::Eq(ph, zero));
    const MD vanish = hn::And(start, hn::And(dzpos, hn::Lt(hn::Mul(wc, hn::Load(dd, S[kMajor] + o)), half)));
    const MD go = hn::AndNot(vanish, start);
    const VD wlift = hn::Load(dd, S[kWlift] + o);
    const MD lift_now = hn::And(
        hn::And(go, hn::Gt(hn::Load(dd, S[kCanLift] + o), zero)),
        hn::And(hn::Eq(lifted, zero), hn::Or(hn::And(dzpos, hn::Le(wc, wlift)), hn::AndNot(dzpos, hn::Ge(wc, wlift)))));
    lifted = hn::IfThenElse(lift_now, one, lifted);
    const MD on_lift = hn::Gt(lifted, zero);
    // the phase: A asks the 32-px blocks, B the 8-px ones, C steps a pixel
    const MD doA = hn::And(go, hn::Eq(fine, zero));
    const MD doB = hn::And(act, hn::Eq(ph, one));
    const MD ask = hn::Or(doA, doB);
    const MD doC = hn::Or(hn::AndNot(doA, go), hn::And(act, hn::Eq(ph, two)));
    // the step's end: w + 32·dw, w + 8·dw, w + dw (1·dw is dw)
    const VD k = hn::IfThenElse(doA, hn::Set(dd, static_cast<double>(kWetCoarseBlock)),
                                hn::IfThenElse(doB, hn::Set(dd, static_cast<double>(kWetFineBlock)), one));
    const VD w1 = hn::Add(wc, hn::Mul(k, dw));
    const VD u1 = hn::Add(uinf, hn::Mul(w1, cu)), v1 = hn::Add(vinf, hn::Mul(w1, cv));
    const MD ok = hn::And(hn::Gt(w1, zero), inside(u1, v1));
    // An ask: the blocks the step and its margins meet, std::max(0, int(x) / S) = floor(max(int(x),
    // 0)/S) and std::min(last, int(y) / S) (y > 0), S a power of two.
    const VD u0 = hn::Add(uinf, hn::Mul(wc, cu)), v0 = hn::Add(vinf, hn::Mul(wc, cv));
    const VD inv_s = hn::IfThenElse(doA, hn::Set(dd, 1.0 / kWetCoarseBlock), hn::Set(dd, 1.0 / kWetFineBlock));
    const VD bw = hn::IfThenElse(doA, hn::Set(dd, m.bw[0]), hn::Set(dd, m.bw[1]));
    const VD bh = hn::IfThenElse(doA, hn::Set(dd, m.bh[0]), hn::Set(dd, m.bh[1]));
    const auto lo = [&](VD a) { return hn::Floor(hn::Mul(hn::Max(hn::Trunc(hn::Sub(a, one)), zero), inv_s)); };
    const auto hi = [&](VD a, VD n) {
      return hn::Min(hn::Floor(hn::Mul(hn::Trunc(hn::Add(a, two)), inv_s)), hn::Sub(n, one));
    };
    const VD bx0 = lo(hn::Min(u0, u1)), by0 = lo(hn::Min(v0, v1));
    const VD bx1 = hi(hn::Max(u0, u1), bw), by1 = hi(hn::Max(v0, v1), bh);
    const VD nx = hn::Sub(bx1, bx0), ny = hn::Sub(by1, by0);
    const MD fits = hn::And(hn::And(hn::Ge(nx, zero), hn::Le(nx, two)), hn::And(hn::Ge(ny, zero), hn::Le(ny, two)));
    const MD asked = hn::And(ask, ok);
    MD other = hn::FirstN(dd, 0);  // the lanes whose blocks the table does not hold, asked one by one
    if (HWY_UNLIKELY(!hn::AllFalse(dd, hn::AndNot(fits, asked)))) {
      // (not seen: a step of S px and its margins spans at most 3 x 3 blocks) render_wet's loop
      // over the blocks, lane by lane
      HWY_ALIGN double a[8][kMaxLanes];
      hn::Store(bx0, dd, a[0]), hn::Store(bx1, dd, a[1]), hn::Store(by0, dd, a[2]), hn::Store(by1, dd, a[3]);
      hn::Store(hn::IfThenElseZero(hn::AndNot(fits, asked), one), dd, a[4]);
      hn::Store(hn::IfThenElseZero(doA, one), dd, a[5]), hn::Store(wc, dd, a[6]), hn::Store(w1, dd, a[7]);
      HWY_ALIGN double lf[kMaxLanes];
      hn::Store(lifted, dd, lf);
      for (std::size_t l = 0; l < N; ++l) {
        if (!(a[4][l] > 0.0)) continue;
        const int lv = a[5][l] > 0.0 ? 0 : 1;
        const float* b = m.blocks[lv] + (lf[l] > 0.0 ? m.blocks_off[lv] : 0);
        float near = INFINITY;
        for (int y = static_cast<int>(a[2][l]); y <= static_cast<int>(a[3][l]); ++y)
          for (int x = static_cast<int>(a[0][l]); x <= static_cast<int>(a[1][l]); ++x)
            near = std::min(near, b[static_cast<std::size_t>(y) * m.bw[lv] + x]);
        a[4][l] = 1.0 / std::min(a[6][l], a[7][l]) <= near * m.front_k ? 1.0 : 0.0;
      }
      other = hn::Gt(hn::Load(dd, a[4]), zero);
    }
    const VD rect_at = hn::IfThenElse(doA, hn::Set(dd, static_cast<double>(m.rect_at[0])),
                                      hn::Set(dd, static_cast<double>(m.rect_at[1])));
    const VD rect_off = hn::IfThenElse(doA, hn::Set(dd, static_cast<double>(m.rect_off[0])),
                                       hn::Set(dd, static_cast<double>(m.rect_off[1])));
    const VD ridx = hn::Add(
        hn::Add(hn::Mul(hn::Set(dd, 9.0), hn::Add(hn::Mul(by0, bw), bx0)), hn::Add(hn::Mul(hn::Set(dd, 3.0), ny), nx)),
        hn::Add(rect_at, hn::IfThenElseZero(on_lift, rect_off)));
    // a step: the pixel's planar depth
    const VD zidx = hn::Add(hn::Add(hn::Mul(round_inside(v1), Wd), round_inside(u1)),
                            hn::IfThenElseZero(on_lift, z_off));
    const MD read_on = hn::And(ok, hn::Or(hn::And(ask, fits), doC));
    const auto i32 = hn::DemoteTo(di, hn::IfThenElseZero(read_on, hn::IfThenElse(ask, ridx, zidx)));
    // the depth times the margin in float, as the scalar march's product, widened
    const VD near = hn::PromoteTo(dd, hn::Mul(hn::GatherIndex(df, m.maps, i32), fk));
    const VD inv = hn::Div(one, hn::IfThenElse(doC, w1, hn::Min(wc, w1)));
    hn::Store(near, dd, T[kNear] + o), hn::Store(inv, dd, T[kInv] + o), hn::Store(w1, dd, T[kW1] + o);
    hn::Store(lifted, dd, S[kLifted] + o);
    hn::Store(u1, dd, S[kU] + o), hn::Store(v1, dd, S[kV] + o);
    put(g, kMDoA, doA), put(g, kMDoB, doB), put(g, kMDoC, doC), put(g, kMOk, ok);
    put(g, kMAskedFits, hn::And(asked, fits)), put(g, kMOther, other), put(g, kMVanish, vanish);
  };
  const auto round_b = [&](std::size_t g) BRUME_WET_INLINE -> std::uint64_t {
    const std::size_t o = g * N;
    const VD wc = hn::Load(dd, S[kWc] + o), w1 = hn::Load(dd, T[kW1] + o);
    const VD near = hn::Load(dd, T[kNear] + o), inv = hn::Load(dd, T[kInv] + o);
    VD front = hn::Load(dd, S[kFront] + o), fine = hn::Load(dd, S[kFine] + o), step = hn::Load(dd, S[kStep] + o);
    const MD doA = get(g, kMDoA), doB = get(g, kMDoB), doC = get(g, kMDoC), ok = get(g, kMOk);
    const MD other = get(g, kMOther), vanish = get(g, kMVanish), asked_fits = get(g, kMAskedFits);
    const MD clear = hn::Or(other, hn::And(asked_fits, hn::Le(inv, near)));
    const MD behind = hn::Gt(inv, near);
    const MD ca = hn::And(doA, clear), cb = hn::And(doB, clear);
    const MD leave = hn::AndNot(ok, doC);
    const MD stepped = hn::And(doC, ok);
    const MD cross = hn::And(hn::And(stepped, behind), hn::Gt(front, zero));
    fine = hn::IfThenElse(doC, hn::IfThenElse(hn::Gt(fine, zero), hn::Sub(fine, one), hn::Set(dd, kWetFineBlock - 1.0)),
                          fine);
    const MD cleared = hn::Or(ca, cb);
    front = hn::IfThenElse(stepped, hn::IfThenElseZero(hn::Not(behind), one), hn::IfThenElse(cleared, one, front));
    const MD moved = hn::Or(cleared, stepped);
    // the next phase: B after a failed A, C after a failed B, else a new iteration
    const VD ph = hn::IfThenElse(hn::AndNot(clear, doA), one, hn::IfThenElseZero(hn::AndNot(clear, doB), two));
    // the iteration's end: the step count (the scalar loop's bound: a single step that reaches it
    // ends at infinity, a block step leaves)
    const MD at_max = hn::And(moved, hn::Eq(hn::Add(step, one), max_steps));
    step = hn::IfThenElse(moved, hn::Add(step, one), step);
    hn::Store(hn::IfThenElse(moved, w1, wc), dd, S[kWc] + o);
    hn::Store(front, dd, S[kFront] + o), hn::Store(fine, dd, S[kFine] + o), hn::Store(step, dd, S[kStep] + o);
    hn::Store(ph, dd, S[kPhase] + o);
    const MD event = hn::Or(hn::Or(vanish, leave), hn::Or(cross, at_max));
    const VD ev = hn::Add(
        hn::Add(hn::IfThenElseZero(vanish, hn::Set(dd, kVanish)), hn::IfThenElseZero(leave, hn::Set(dd, kLeave))),
        hn::Add(
            hn::Add(hn::IfThenElseZero(cross, hn::Set(dd, kCross)), hn::IfThenElseZero(at_max, hn::Set(dd, kAtMax))),
            hn::IfThenElseZero(stepped, hn::Set(dd, kStepped))));
    hn::Store(ev, dd, S[kEvent] + o), hn::Store(wc, dd, S[kWprev] + o);
    std::uint8_t bits[8] = {};
    hn::StoreMaskBits(dd, event, bits);
    std::uint64_t b = 0;
    std::memcpy(&b, bits, sizeof b);
    return b;
  };
  // The crossings of waiting[0, c), N at a time, bisected to 1/64 of a step (render_wet's
  // expressions): a hit ends the ray; else it goes on (or, at the step bound, ends at infinity).
  std::size_t busy = std::min(L, n);  // lanes holding a ray
  const auto bisect = [&]() {
    for (std::size_t c0 = 0; c0 < waiting.size(); c0 += N) {
      const std::size_t c = std::min(N, waiting.size() - c0);
      HWY_ALIGN double a[9][kMaxLanes];
      for (std::size_t j = 0; j < N; ++j) {
        const double* q = waiting[c0 + (j < c ? j : 0)].st;
        a[0][j] = q[kWprev], a[1][j] = q[kWc], a[2][j] = q[kUinf], a[3][j] = q[kVinf], a[4][j] = q[kCu];
        a[5][j] = q[kCv], a[6][j] = q[kLifted], a[7][j] = q[kU], a[8][j] = q[kV];
      }
      VD lo = hn::Load(dd, a[0]), hi = hn::Load(dd, a[1]);
      const VD ui = hn::Load(dd, a[2]), vi = hn::Load(dd, a[3]), cui = hn::Load(dd, a[4]), cvi = hn::Load(dd, a[5]);
      const VD zo = hn::IfThenElseZero(hn::Gt(hn::Load(dd, a[6]), zero), z_off);
      const auto depth = [&](VD mu, VD mv, MD on, decltype(fk) k) {
        const VD idx = hn::Add(hn::Add(hn::Mul(round_inside(mv), Wd), round_inside(mu)), zo);
        const auto i32 = hn::DemoteTo(di, hn::IfThenElseZero(on, idx));
        return hn::PromoteTo(dd, hn::Mul(hn::GatherIndex(df, m.maps + m.z_at, i32), k));
      };
      for (int it = 0; it < 6; ++it) {
        const VD mid = hn::Mul(half, hn::Add(lo, hi));
        const VD mu = hn::Add(ui, hn::Mul(mid, cui)), mv = hn::Add(vi, hn::Mul(mid, cvi));
        const MD in = inside(mu, mv);
        const MD c_hi = hn::And(in, hn::Gt(hn::Div(one, mid), depth(mu, mv, in, fk)));
        hi = hn::IfThenElse(c_hi, mid, hi), lo = hn::IfThenElse(c_hi, lo, mid);
      }
      VD hu = hn::Add(ui, hn::Mul(hi, cui)), hv = hn::Add(vi, hn::Mul(hi, cvi));
      const MD in = inside(hu, hv);
      hu = hn::IfThenElse(in, hu, hn::Load(dd, a[7])), hv = hn::IfThenElse(in, hv, hn::Load(dd, a[8]));
      const MD hit = hn::Le(hn::Div(one, hi), depth(hu, hv, hn::FirstN(dd, N), hn::Set(df, m.thick_k)));
      hn::Store(hu, dd, a[0]), hn::Store(hv, dd, a[1]), hn::Store(hn::IfThenElseZero(hit, one), dd, a[2]);
      for (std::size_t j = 0; j < c; ++j) {
        Waiting& w = waiting[c0 + j];
        const std::size_t i = w.ray;
        if (a[2][j] > 0.0) {
          r.end[i] = WetMarchRays::hit, r.hu[i] = a[0][j], r.hv[i] = a[1][j];
        } else if (static_cast<int>(w.st[kEvent]) & kAtMax) {
          r.end[i] = WetMarchRays::infinity;
        } else {
          w.st[kEvent] = 0.0;
          again.push_back(w);
        }
      }
    }
    waiting.clear();
    for (std::size_t l = 0; l < L && !again.empty(); ++l)
      if (!(S[kBusy][l] > 0.0)) {
        S[kBusy][l] = 1.0;
        take(l);
        ++busy;
      }
  };
  while (busy > 0 || !waiting.empty()) {
    if (waiting.size() >= N || busy == 0) bisect();
    if (busy == 0) continue;
    std::uint64_t bits[kGroups], any = 0;
    for (std::size_t g = 0; g < kGroups; ++g) round_a(g);
    for (std::size_t g = 0; g < kGroups; ++g) any |= bits[g] = round_b(g);
    if (HWY_LIKELY(any == 0)) continue;
    for (std::size_t g = 0; g < kGroups; ++g)
      for (std::uint64_t bs = bits[g]; bs != 0; bs &= bs - 1) {
        const std::size_t l = g * N + static_cast<std::size_t>(hwy::Num0BitsBelowLS1Bit_Nonzero64(bs));
        const int e = static_cast<int>(S[kEvent][l]);
        const std::size_t i = ray[l];
        WetMarchRays::End end = WetMarchRays::leaves;
        bool over = false;
        if (e & kVanish) over = true, end = WetMarchRays::infinity;
        if (e & kLeave) over = true, end = WetMarchRays::leaves;
        if (e & kCross) {  // (kVanish and kLeave exclude it) bisected below
          Waiting w;
          w.ray = i;
          for (int k = 0; k < kStates; ++k) w.st[k] = S[k][l];
          waiting.push_back(w);
          take(l);
          busy -= S[kBusy][l] > 0.0 ? 0 : 1;
          continue;
        }
        if (!over && (e & kAtMax)) over = true, end = (e & kStepped) ? WetMarchRays::infinity : WetMarchRays::leaves;
        if (!over) continue;
        r.end[i] = end;
        take(l);
        busy -= S[kBusy][l] > 0.0 ? 0 : 1;
      }
  }
  return true;
}


// ---- render_wet's pixels around the march (wet_march.hpp): the scalar expressions they
// replaced, operation for operation (no contraction on this file; Div and Sqrt correctly rounded
// as divsd and sqrtsd; float's rounding of a double as static_cast's), so the same bits.

// std::max's and std::min's own choice ((a < b) ? b : a; (b < a) ? b : a): the scalar code's
// value whatever the zeros' signs.
template <class V>
HWY_INLINE V StdMax(V a, V b) {
  return hn::IfThenElse(hn::Lt(a, b), b, a);
}
template <class V>
HWY_INLINE V StdMin(V a, V b) {
  return hn::IfThenElse(hn::Lt(b, a), b, a);
}
// The first `count` lanes from p (the rest `pad`), and back: a row's or a batch's last vector.
template <class D, class T>
HWY_INLINE hn::Vec<D> LoadPart(D d, const T* p, std::size_t count, T pad) {
  if (count == hn::Lanes(d)) return hn::LoadU(d, p);
  HWY_ALIGN T b[HWY_MAX_BYTES / sizeof(T)];
  for (std::size_t j = 0; j < hn::Lanes(d); ++j) b[j] = j < count ? p[j] : pad;
  return hn::Load(d, b);
}
template <class D, class T>
HWY_INLINE void StorePart(D d, hn::Vec<D> v, T* p, std::size_t count) {
  if (count == hn::Lanes(d)) return hn::StoreU(v, d, p);
  HWY_ALIGN T b[HWY_MAX_BYTES / sizeof(T)];
  hn::Store(v, d, b);
  std::copy(b, b + count, p);
}

void WetDepthRowK(const WetPixelFrame& f, const double* rx, double ry, const float* range, int width, float* z,
                  float* zo, std::uint8_t* flags) {
  const hn::ScalableTag<double> dd;
  const hn::Rebind<float, decltype(dd)> df;
  using VD = hn::Vec<decltype(dd)>;
  const std::size_t N = hn::Lanes(dd), W = static_cast<std::size_t>(width);
  const VD zero = hn::Zero(dd), one = hn::Set(dd, 1.0), inf = hn::Set(dd, INFINITY);
  const VD ryv = hn::Set(dd, ry), ry2 = hn::Set(dd, ry * ry);
  const auto zero_f = hn::Zero(df), inf_f = hn::Set(df, INFINITY);
  const VD nx = hn::Set(dd, f.nx), ny = hn::Set(dd, f.ny), nz = hn::Set(dd, f.nz);
  const VD h = hn::Set(dd, f.h), tol = hn::Set(dd, f.tol);
  HWY_ALIGN double fl[HWY_MAX_BYTES / sizeof(double)];
  for (std::size_t x = 0; x < W; x += N) {
    const std::size_t c = std::min(N, W - x);
    const auto rf = LoadPart(df, range + x, c, 0.0f);
    const VD r = hn::PromoteTo(dd, rf);
    const VD rxv = LoadPart(dd, rx + x, c, 0.0);
    // |ray| for the ray (rx, ry, 1); a known range: finite and > 0. (inf chosen among floats:
    // Highway's one-lane DemoteTo gives the largest float for inf.)
    const VD len = hn::Sqrt(hn::Add(hn::Add(hn::Mul(rxv, rxv), ry2), one));
    const auto known = hn::And(hn::Gt(r, zero), hn::Lt(r, inf));
    const auto known_f = hn::And(hn::Gt(rf, zero_f), hn::Lt(rf, inf_f));
    const auto zf = hn::IfThenElse(known_f, hn::DemoteTo(df, hn::Div(r, len)), inf_f);
    StorePart(df, zf, z + x, c);
    // the unit ray's d·n (< 0: down), and the pixel's 3-D point within the tolerance of the plane
    const VD inv = hn::Div(one, len);
    const VD dn = hn::Add(hn::Add(hn::Mul(hn::Mul(rxv, inv), nx), hn::Mul(hn::Mul(ryv, inv), ny)), hn::Mul(inv, nz));
    const auto down = hn::And(known, hn::Lt(dn, zero));
    const VD zd = hn::PromoteTo(dd, zf);
    const auto plane = hn::And(down, hn::Le(hn::Abs(hn::Add(h, hn::Mul(hn::Div(zd, inv), dn))), tol));
    if (zo) {
      const auto plane_f = hn::Gt(hn::DemoteTo(df, hn::IfThenElseZero(plane, one)), zero_f);
      StorePart(df, hn::IfThenElse(plane_f, inf_f, zf), zo + x, c);
    }
    hn::Store(hn::Add(hn::IfThenElseZero(down, hn::Set(dd, kWetDown)), hn::IfThenElseZero(plane, hn::Set(dd, kWetOnPlane))),
              dd, fl);
    for (std::size_t j = 0; j < c; ++j) flags[x + j] = static_cast<std::uint8_t>(fl[j]);
  }
}

void WetSetupRaysK(const WetPixelFrame& f, const std::int32_t* xs, const std::int32_t* ys, const float* z0s,
                   std::size_t n, WetMarchRays& r, float* mirror) {
  const hn::ScalableTag<double> dd;
  const hn::Rebind<float, decltype(dd)> df;
  const hn::Rebind<std::int32_t, decltype(dd)> di;
  using VD = hn::Vec<decltype(dd)>;
  const std::size_t N = hn::Lanes(dd);
  r.resize(n);
  const VD zero = hn::Zero(dd), one = hn::Set(dd, 1.0), two = hn::Set(dd, 2.0), half = hn::Set(dd, 0.5);
  const VD fx = hn::Set(dd, f.fx), fy = hn::Set(dd, f.fy), cx = hn::Set(dd, f.cx), cy = hn::Set(dd, f.cy);
  const VD nx = hn::Set(dd, f.nx), ny = hn::Set(dd, f.ny), nz = hn::Set(dd, f.nz);
  const VD h = hn::Set(dd, f.h), tol = hn::Set(dd, f.tol), step = hn::Set(dd, f.step_px);
  const VD wf = hn::Set(dd, f.f), wn = hn::Set(dd, f.n), wnn = hn::Set(dd, f.n * f.n);
  const VD tiny = hn::Set(dd, 1e-9), far = hn::Set(dd, 1e-30);
  HWY_ALIGN double fl[HWY_MAX_BYTES / sizeof(double)];
  for (std::size_t i = 0; i < n; i += N) {
    const std::size_t c = std::min(N, n - i);
    const VD x = hn::PromoteTo(dd, LoadPart(di, xs + i, c, std::int32_t{0}));
    const VD y = hn::PromoteTo(dd, LoadPart(di, ys + i, c, std::int32_t{0}));
    // the unit ray (cv) and d·n (< 0: the ray goes down)
    const VD rx = hn::Div(hn::Sub(x, cx), fx), ry = hn::Div(hn::Sub(y, cy), fy);
    const VD inv = hn::Div(one, hn::Sqrt(hn::Add(hn::Add(hn::Mul(rx, rx), hn::Mul(ry, ry)), one)));
    const VD dx = hn::Mul(rx, inv), dy = hn::Mul(ry, inv), dz = inv;
    const VD dn = hn::Add(hn::Add(hn::Mul(dx, nx), hn::Mul(dy, ny)), hn::Mul(dz, nz));
    const VD r0 = hn::Div(hn::PromoteTo(dd, LoadPart(df, z0s + i, c, 1.0f)), inv);
    // the mirrored ray X(t) = P + t·D and its image u = uinf + w·cu, v = vinf + w·cv (w = 1/Z)
    const VD Px = hn::Mul(r0, dx), Py = hn::Mul(r0, dy), Pz = hn::Mul(r0, dz);
    const VD dn2 = hn::Mul(two, dn);
    const VD Dx = hn::Sub(dx, hn::Mul(dn2, nx)), Dy = hn::Sub(dy, hn::Mul(dn2, ny));
    VD Dz = hn::Sub(dz, hn::Mul(dn2, nz));
    Dz = hn::IfThenElse(hn::Lt(hn::Abs(Dz), tiny), hn::IfThenElse(hn::Lt(Dz, zero), hn::Neg(tiny), tiny), Dz);
    const VD bu = hn::Add(hn::Mul(fx, Dx), hn::Mul(cx, Dz)), bv = hn::Add(hn::Mul(fy, Dy), hn::Mul(cy, Dz));
    const VD cu = hn::Sub(hn::Add(hn::Mul(fx, Px), hn::Mul(cx, Pz)), hn::Div(hn::Mul(bu, Pz), Dz));
    const VD cv = hn::Sub(hn::Add(hn::Mul(fy, Py), hn::Mul(cy, Pz)), hn::Div(hn::Mul(bv, Pz), Dz));
    const VD major = StdMax(hn::Abs(cu), hn::Abs(cv));
    const auto dzpos = hn::Gt(Dz, zero);
    const VD dw = hn::Div(hn::Mul(hn::IfThenElse(dzpos, hn::Neg(one), one), step), StdMax(major, far));
    StorePart(dd, hn::Div(one, Pz), r.w0.data() + i, c);
    StorePart(dd, dw, r.dw.data() + i, c);
    StorePart(dd, hn::Div(bu, Dz), r.uinf.data() + i, c), StorePart(dd, hn::Div(bv, Dz), r.vinf.data() + i, c);
    StorePart(dd, cu, r.cu.data() + i, c), StorePart(dd, cv, r.cv.data() + i, c);
    StorePart(dd, major, r.major.data() + i, c);
    // above_ground's lift: the ray leaves the plane's tolerance at t_lift (Z = z_lift)
    VD flags = hn::IfThenElseZero(dzpos, hn::Set(dd, WetMarchRays::dz_positive));
    VD w_lift = zero;
    if (f.lift) {
      const VD t_lift = hn::Div(hn::Sub(tol, hn::Add(h, hn::Mul(r0, dn))), hn::Neg(dn));
      const VD z_lift = hn::Add(Pz, hn::Mul(StdMax(t_lift, zero), Dz));
      const auto lifted = hn::Le(t_lift, zero);
      const auto can = hn::AndNot(lifted, hn::Gt(z_lift, zero));
      flags = hn::Add(flags, hn::Add(hn::IfThenElseZero(lifted, hn::Set(dd, WetMarchRays::lifted)),
                                     hn::IfThenElseZero(can, hn::Set(dd, WetMarchRays::can_lift))));
      w_lift = hn::IfThenElseZero(can, hn::Div(one, z_lift));
    }
    StorePart(dd, w_lift, r.w_lift.data() + i, c);
    hn::Store(flags, dd, fl);
    for (std::size_t j = 0; j < c; ++j) r.flags[i + j] = static_cast<std::uint8_t>(fl[j]);
    // the mirror's weight f·R_F(θ), cos θ = −d·n (fresnel_air_to's unpolarised R)
    const VD ci = StdMin(one, StdMax(zero, hn::Neg(dn)));
    const VD s2 = StdMax(zero, hn::Sub(one, hn::Mul(ci, ci)));
    const VD ct = hn::Sqrt(StdMax(zero, hn::Sub(one, hn::Div(s2, wnn))));
    const VD ds = hn::Add(ci, hn::Mul(wn, ct)), dp = hn::Add(hn::Mul(wn, ci), ct);
    const VD rs = hn::Div(hn::Sub(ci, hn::Mul(wn, ct)), ds), rp = hn::Div(hn::Sub(hn::Mul(wn, ci), ct), dp);
    const VD R = hn::Mul(half, hn::Add(hn::Mul(rs, rs), hn::Mul(rp, rp)));
    StorePart(df, hn::DemoteTo(df, hn::Mul(wf, R)), mirror + i, c);
  }
}

}  // namespace HWY_NAMESPACE
}  // namespace brume::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace brume::detail {
HWY_EXPORT(WetMarchRaysK);

HWY_EXPORT(WetDepthRowK);
HWY_EXPORT(WetSetupRaysK);

bool wet_march_rays(const WetMarchMaps& m, WetMarchRays& r) { return HWY_DYNAMIC_DISPATCH(WetMarchRaysK)(m, r); }

void wet_depth_row(const WetPixelFrame& f, const double* rx, double ry, const float* range, int width, float* z,
                   float* zo, std::uint8_t* flags) {
  HWY_DYNAMIC_DISPATCH(WetDepthRowK)(f, rx, ry, range, width, z, zo, flags);
}

void wet_setup_rays(const WetPixelFrame& f, const std::int32_t* x, const std::int32_t* y, const float* z0,
                    std::size_t n, WetMarchRays& r, float* mirror) {
  HWY_DYNAMIC_DISPATCH(WetSetupRaysK)(f, x, y, z0, n, r, mirror);
}
}  // namespace brume::detail
#endif  // HWY_ONCE
