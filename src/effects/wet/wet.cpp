// brume — wet ground (issue #57): the film's optics (Fresnel, Lekner & Dorf's
// darkening, the wetted fraction), the camera's wet ground with its mirror
// image, and the LiDAR's ground returns through the same film
// (brume/wet.hpp; docs/wet-ground.md).
#include "brume/wet.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <vector>

#include "brume/error.hpp"
#include "brume/medium.hpp"
#include "core/text.hpp"
#include "effects/wet/wet_gpu.hpp"
#include "effects/wet/wet_march.hpp"

namespace brume {

// ---- the film's optics ---------------------------------------------------------------------

Fresnel fresnel_air_to(double cos_theta, double n) {
  const double ci = std::min(1.0, std::max(0.0, cos_theta));
  const double s2 = std::max(0.0, 1.0 - ci * ci);
  const double ct = std::sqrt(std::max(0.0, 1.0 - s2 / (n * n)));  // n >= 1: never total reflection
  Fresnel f;
  const double ds = ci + n * ct, dp = n * ci + ct;
  const double rs = (ci - n * ct) / ds, rp = (n * ci - ct) / dp;
  f.rs = rs * rs;
  f.rp = rp * rp;
  // The transmittances from the transmitted amplitudes (t_s = 2 cos θ/ds, t_p = 2 cos θ/dp) and
  // the flux ratio n cos θ_t/cos θ: computed apart from R, so that R + T = 1 tests both.
  f.ts = 4.0 * n * ci * ct / (ds * ds);
  f.tp = 4.0 * n * ci * ct / (dp * dp);
  return f;
}

double fresnel_reflectance(double cos_theta, double n) { return fresnel_air_to(cos_theta, n).r(); }

namespace {

// Gauss–Legendre nodes and weights on [0, 1] (Newton on P_m; Abramowitz & Stegun 25.4.29).
struct GaussLegendre {
  std::vector<double> x, w;
  explicit GaussLegendre(int m) {
    for (int i = 1; i <= m; ++i) {
      double z = std::cos(M_PI * (i - 0.25) / (m + 0.5)), dp = 0.0;
      for (int it = 0; it < 100; ++it) {
        double p0 = 1.0, p1 = z;
        for (int k = 2; k <= m; ++k) {
          const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
          p0 = p1, p1 = p2;
        }
        dp = m * (z * p1 - p0) / (z * z - 1.0);
        const double dz = p1 / dp;
        z -= dz;
        if (std::fabs(dz) < 1e-16) break;
      }
      x.push_back(0.5 * (1.0 - z));
      w.push_back(1.0 / ((1.0 - z * z) * dp * dp));  // 2/((1 − z²)P′²) halved for [0, 1]
    }
  }
};

}  // namespace

double water_diffuse_external_reflectance(double n) {
  // r_e = ∫_0^1 R_F(μ)·2μ dμ (μ = cos θ): smooth in μ for n > 1; 8 panels of 16 nodes reach 1e−15.
  static const GaussLegendre gl(16);
  constexpr int kPanels = 8;
  double s = 0.0;
  for (int p = 0; p < kPanels; ++p)
    for (std::size_t i = 0; i < gl.x.size(); ++i) {
      const double mu = (p + gl.x[i]) / kPanels;
      s += gl.w[i] / kPanels * fresnel_reflectance(mu, n) * 2.0 * mu;
    }
  return s;
}

double water_diffuse_internal_reflectance(double n) {
  return 1.0 - (1.0 - water_diffuse_external_reflectance(n)) / (n * n);
}

double film_transfer(double t_in, double t_out, double n, double albedo, double r_i) {
  return t_in * t_out / (n * n * (1.0 - albedo * r_i));
}

double wetted_fraction(double film_mm, double roughness_mm) { return std::min(1.0, film_mm / roughness_mm); }

const ParamTable<WetFilm>& wet_film_param_table() {
  static const ParamTable<WetFilm> t = [] {
    ParamTable<WetFilm> d("wet");
    d.real("film", &WetFilm::film_mm, "mm", Range::closed(0.0, 100.0),
           "thickness h of the water film on the ground (one film for the camera and the LiDAR); 0: dry, the input "
           "back bit for bit",
           "none")
        .real("ground-albedo", &WetFilm::ground_albedo, "1", Range::left_open(0.0, 1.0),
              "the dry ground's diffuse albedo a in Lekner & Dorf's darkening (default: dense asphalt, 0.12)")
        .real("roughness", &WetFilm::roughness_mm, "mm", Range::left_open(0.0, 20.0),
              "the ground's roughness depth d (mean texture depth; asphalt 0.5-1.5 mm): the wetted fraction is "
              "min(film/roughness, 1)")
        .real("water-index", &WetFilm::water_index, "1", Range::closed(1.2, 1.5),
              "refractive index n of the water relative to air (Fresnel's R_F, Lekner & Dorf's r_e and r_i)");
    return d;
  }();
  return t;
}

void validate_wet_film(const WetFilm& w) {
  wet_film_param_table().validate(w);
  if (!w.film_mm) throw Error("no film thickness given: use --film MM (the water film on the ground, in [0, 100] mm)");
}

WetOptics::WetOptics(const WetFilm& w)
    : n(w.water_index), a(w.ground_albedo), f(w.film_mm ? wetted_fraction(*w.film_mm, w.roughness_mm) : 0.0) {
  r_e = water_diffuse_external_reflectance(n);
  r_i = 1.0 - (1.0 - r_e) / (n * n);
  k = film_transfer(1.0 - r_e, 1.0 - r_e, n, a, r_i);
  k_eff = 1.0 - f * (1.0 - k);
}

double WetOptics::mirror(double cos_theta) const { return f * fresnel_reflectance(cos_theta, n); }

double WetOptics::lidar(double cos_theta) const {
  const double t = 1.0 - fresnel_reflectance(cos_theta, n);
  return 1.0 - f * (1.0 - film_transfer(t, t, n, a, r_i));
}

nlohmann::json wet_optics_record(const WetFilm& w, const WetOptics& o) {
  return {{"film_mm", w.film_mm ? nlohmann::json(*w.film_mm) : nlohmann::json(nullptr)},
          {"ground_albedo", w.ground_albedo},
          {"roughness_mm", w.roughness_mm},
          {"water_index", w.water_index},
          {"wetted_fraction", o.f},
          {"wetted_fraction_rule", "f = min(film/roughness, 1): asperity heights uniform over the roughness depth"},
          {"r_e", o.r_e},
          {"r_e_rule", "R_F (unpolarised Fresnel, air to water) averaged over a Lambertian hemisphere of incidence"},
          {"r_i", o.r_i},
          {"r_i_rule", "1 - (1 - r_e)/n^2 (Lekner & Dorf 1988)"},
          {"k_lekner_dorf", o.k},
          {"k_eff", o.k_eff},
          {"reflectance_normal", fresnel_reflectance(1.0, o.n)},
          {"model",
           "wet = K_eff dry + f R_F(theta) L_mirror on the ground; K = (1 - r_e)(1 - r_i)/(1 - a r_i); K_eff = 1 - f (1 "
           "- K); LiDAR: Q_eff(theta) = 1 - f (1 - (1 - R_F)^2/(n^2 (1 - a r_i)))"}};
}

// ---- the camera ----------------------------------------------------------------------------

const EnumNames<WetMarch>& wet_march_names() {
  static const EnumNames<WetMarch> n = {{WetMarch::blocks, "blocks"}, {WetMarch::above_ground, "above-ground"}};
  return n;
}

namespace {

// std::lround, inline: the nearest integer, halves away from zero, for |x| < 2^52 (x − trunc(x)
// is then exact). The march rounds two coordinates a step; the library call cost more than the step.
inline long round_half_away(double x) {
  const long t = static_cast<long>(x);
  const double f = x - static_cast<double>(t);
  return t + (f >= 0.5) - (f <= -0.5);
}

// round_half_away for x > −0.5 (a coordinate inside the frame): x − trunc(x) >= 0 there, so the
// half below zero is never taken; the same integer.
inline long round_inside(double x) {
  const long t = static_cast<long>(x);
  return t + (x - static_cast<double>(t) >= 0.5);
}

// The march a ray at a time (wet_march.hpp's rays and maps): the reference the lanes of
// wet_march.cpp reproduce bit for bit, and the march where a vector holds fewer than 8 doubles
// (there the lanes measured slower: docs/wet-ground.md).
void march_rays_one_by_one(const detail::WetMarchMaps& m, detail::WetMarchRays& r) {
  using Rays = detail::WetMarchRays;
  const int W = m.width, H = m.height;
  const float front_k = m.front_k, thick_k = m.thick_k;
  const std::size_t n = r.size();
  r.end.assign(n, Rays::leaves), r.hu.assign(n, 0.0), r.hv.assign(n, 0.0);
  // (-0.5 itself rounds away from zero to -1: outside, as W - 0.5 is.)
  const auto inside = [&](double u, double v) { return u > -0.5 && u < W - 0.5 && v > -0.5 && v < H - 0.5; };
  for (std::size_t i = 0; i < n; ++i) {
    const double uinf = r.uinf[i], vinf = r.vinf[i], cu = r.cu[i], cv = r.cv[i], major = r.major[i], dw = r.dw[i];
    const bool dz_positive = r.flags[i] & Rays::dz_positive, can_lift = r.flags[i] & Rays::can_lift;
    const double w_lift = r.w_lift[i];
    // the maps the march asks now: above_ground's without the plane's pixels once the ray is lifted
    bool lifted = r.flags[i] & Rays::lifted;
    const float* zm = nullptr;
    const float *rect[2] = {nullptr, nullptr}, *blocks[2] = {nullptr, nullptr};
    const auto maps = [&] {
      zm = m.maps + m.z_at + (lifted ? m.z_off : 0);
      for (int l = 0; l < 2; ++l) {
        rect[l] = m.maps + m.rect_at[l] + (lifted ? m.rect_off[l] : 0);
        blocks[l] = m.blocks[l] + (lifted ? m.blocks_off[l] : 0);
      }
    };
    maps();
    const auto zat = [&](double u, double v) {  // (u, v) inside the frame
      return zm[static_cast<std::size_t>(round_inside(v)) * W + static_cast<std::size_t>(round_inside(u))];
    };
    Rays::End end = Rays::leaves;
    double hu = 0.0, hv = 0.0;
    double wc = r.w0[i];
    bool front = true;  // the ray's last point lay in front of the depth map
    int fine_left = 0;  // single-pixel steps before the pyramid is asked again
    // Whether the step from w = wc to w1 clears the blocks of S px it meets (level l; S a
    // constant: the block indices without an integer division).
    const auto clears = [&]<int S>(int l, double w1) {
      const double u0 = uinf + wc * cu, v0 = vinf + wc * cv, u1 = uinf + w1 * cu, v1 = vinf + w1 * cv;
      if (!inside(u1, v1)) return false;
      const int bx0 = std::max(0, static_cast<int>(std::min(u0, u1) - 1.0) / S);
      const int bx1 = std::min(m.bw[l] - 1, static_cast<int>(std::max(u0, u1) + 2.0) / S);
      const int by0 = std::max(0, static_cast<int>(std::min(v0, v1) - 1.0) / S);
      const int by1 = std::min(m.bh[l] - 1, static_cast<int>(std::max(v0, v1) + 2.0) / S);
      float near = INFINITY;
      if (bx0 <= bx1 && by0 <= by1 && bx1 - bx0 <= 2 && by1 - by0 <= 2) {
        // Up to 3 x 3 blocks (a step of S px and its margins spans no more): their rectangle's
        // minimum, one read.
        near = rect[l][9 * (static_cast<std::size_t>(by0) * m.bw[l] + bx0) + 3 * (by1 - by0) + (bx1 - bx0)];
      } else {
        for (int by = by0; by <= by1; ++by)
          for (int bx = bx0; bx <= bx1; ++bx) near = std::min(near, blocks[l][static_cast<std::size_t>(by) * m.bw[l] + bx]);
      }
      return 1.0 / std::min(wc, w1) <= near * front_k;
    };
    const int max_steps = m.max_steps;
    for (int step = 0; step < max_steps; ++step) {
      if (dz_positive && wc * major < 0.5) {  // within half a pixel of its vanishing point
        end = Rays::infinity;
        break;
      }
      if (can_lift && !lifted && (dz_positive ? wc <= w_lift : wc >= w_lift)) {
        lifted = true;
        maps();
      }
      // A whole block's step where the pyramid clears it; where it does not, the next 8 steps
      // are single pixels without asking it again (asking before every pixel cost more than
      // the pixels: 2.3 M block steps and 6.6 M pixel steps on the demo at 1242x375).
      if (fine_left == 0) {
        const double wa = wc + detail::kWetCoarseBlock * dw;
        if (wa > 0.0 && clears.template operator()<detail::kWetCoarseBlock>(0, wa)) {
          wc = wa, front = true;
          continue;
        }
        const double wb = wc + detail::kWetFineBlock * dw;
        if (wb > 0.0 && clears.template operator()<detail::kWetFineBlock>(1, wb)) {
          wc = wb, front = true;
          continue;
        }
      }
      fine_left = fine_left > 0 ? fine_left - 1 : detail::kWetFineBlock - 1;
      const double wprev = wc;
      wc += dw;
      const double u = uinf + wc * cu, v = vinf + wc * cv;
      if (!(wc > 0.0) || !inside(u, v)) break;  // leaves the frame (or the ray turns behind the camera)
      const bool behind = 1.0 / wc > zat(u, v) * front_k;
      // The crossing (behind the map after a point in front of it) as one flag: a branch taken at
      // each crossing only (`behind` alone changes too often to predict).
      const unsigned cross = static_cast<unsigned>(behind) & static_cast<unsigned>(front);
      front = !behind;
      if (cross != 0u) {
        double lo = wprev, hi = wc;  // bisection to the crossing: within 1/64 of a step
        for (int b = 0; b < 6; ++b) {
          const double mid = 0.5 * (lo + hi);
          const double mu = uinf + mid * cu, mv = vinf + mid * cv;
          if (inside(mu, mv) && 1.0 / mid > zat(mu, mv) * front_k) hi = mid; else lo = mid;
        }
        hu = uinf + hi * cu, hv = vinf + hi * cv;
        if (!inside(hu, hv)) hu = u, hv = v;
        // Within the surfaces' thickness behind the pixel's depth: a hit; further behind, the
        // ray passed behind an occluder (as the camera sees it) and goes on.
        if (1.0 / hi <= zat(hu, hv) * thick_k) {
          end = Rays::hit;
          break;
        }
      }
      if (step + 1 == max_steps) end = Rays::infinity;
    }
    r.end[i] = end;
    if (end == Rays::hit) r.hu[i] = hu, r.hv[i] = hv;
  }
}

}  // namespace

void check_wet_scene(const WetScene& s) {
  const int W = s.rgb.width(), H = s.rgb.height();
  if (s.range.width() != W || s.range.height() != H)
    throw Error("the range is " + std::to_string(s.range.width()) + "x" + std::to_string(s.range.height()) +
                " but the image is " + std::to_string(W) + "x" + std::to_string(H) + "; give a range of the image's size");
  const bool masked = s.mask.width() > 0;
  if (masked && (s.mask.width() != W || s.mask.height() != H))
    throw Error("the ground mask is " + std::to_string(s.mask.width()) + "x" + std::to_string(s.mask.height()) +
                " but the image is " + std::to_string(W) + "x" + std::to_string(H) + "; give a mask of the image's size");
  if (!masked) s.camera.require_height("wet ground (the ground plane; or give a ground mask)");
}

WetMarch wet_march_that_runs(const WetScene& s) {
  return s.march == WetMarch::above_ground && std::isfinite(s.camera.position_m.y) ? WetMarch::above_ground
                                                                                  : WetMarch::blocks;
}

Image render_wet(const WetScene& s, const WetFilm& w, const Exec& exec, WetStats* stats, Image* ground_out) {
  check_wet_scene(s);
  const int W = s.rgb.width(), H = s.rgb.height();
  const bool masked = s.mask.width() > 0;
  const WetOptics o(w);
  // the output starts as the input, its rows copied with the depth's (below)
  const int nc = s.rgb.channels();
  Image out(W, H, nc);
  Image ground(W, H, 1);
  WetStats st;
  const Camera& cam = s.camera;
  const Mat3 R = cam.world_from_camera().rotation;           // world_from_cv
  const double nx = R.m[1][0], ny = R.m[1][1], nz = R.m[1][2];  // the plane's normal (world +y) in cv
  const double h = cam.position_m.y;
  const double fx = cam.k.fx, fy = cam.k.fy, cx = cam.k.cx, cy = cam.k.cy;
  const int nt = exec.threads > 0 ? exec.threads : omp_get_max_threads();
  const auto t_maps = std::chrono::steady_clock::now();
  // Min-depth pyramids over blocks of 8 and 32 px: a step whose image (the projection of a 3-D
  // segment is a 2-D segment) meets only blocks whose nearest depth lies beyond the segment's
  // farthest point (Z is linear along the ray: an endpoint) cannot cross the depth map, so the
  // march takes it whole.
  struct Pyramid {
    int bw = 0, bh = 0;
    std::vector<float> m;
    // With the march's maps (mm.rect_at): the minimum of every rectangle of 1 to 3 x 1 to 3
    // blocks, 9 to a block (its top-left one): rect[9 (by·bw + bx) + 3 (rows − 1) + (columns − 1)].
    // An ask meets at most 3 x 3 blocks, so it reads one number where it read nine (the same
    // minimum: min is exact, the depths hold no NaN).
  };
  // above_ground (WetMarch): a second depth map and pyramid without the plane's pixels, for rays
  // higher above the plane than the tolerance.
  st.march = wet_march_that_runs(s);
  const bool lift = st.march == WetMarch::above_ground;
  std::array<Pyramid, 2> pyr, pyr_off;  // the coarse blocks, then the fine ones; off the plane
  const auto blocks_of = [&](Pyramid& p, int b) {
    p.bw = (W + b - 1) / b, p.bh = (H + b - 1) / b;
    p.m.assign(static_cast<std::size_t>(p.bw) * p.bh, INFINITY);
  };
  for (int l = 0; l < 2; ++l) {
    const int b = l == 0 ? detail::kWetCoarseBlock : detail::kWetFineBlock;
    blocks_of(pyr[l], b);
    if (lift) blocks_of(pyr_off[l], b);
  }
  // The march's maps in one array (its lanes read any of them in one gather): the planar depth
  // z = range/|ray| of each pixel (inf: the sky; a point of planar depth Z on a pixel's ray is
  // behind the pixel's surface when Z > z), and above_ground the depth without the plane's pixels,
  // then each level's rectangle minima (and without the plane's).
  const std::size_t wh = static_cast<std::size_t>(W) * H;
  detail::WetMarchMaps mm;
  mm.width = W, mm.height = H;
  mm.z_at = 0, mm.z_off = lift ? wh : 0;
  std::size_t size = lift ? 2 * wh : wh;
  for (int l = 0; l < 2; ++l) {
    const std::size_t n = 9 * pyr[l].m.size();
    mm.rect_at[l] = size, mm.rect_off[l] = lift ? n : 0;
    size += lift ? 2 * n : n;
  }
  std::vector<float> maps(size);
  // Each pixel's flags (detail::kWetDown, kWetOnPlane): its ray goes down; it lies on the plane.
  std::vector<std::uint8_t> flags(wh);
  detail::WetPixelFrame pf;
  pf.fx = fx, pf.fy = fy, pf.cx = cx, pf.cy = cy, pf.nx = nx, pf.ny = ny, pf.nz = nz;
  pf.h = h, pf.tol = s.ground_tolerance_m, pf.f = o.f, pf.n = o.n, pf.step_px = kWetMarchStepPx, pf.lift = lift;
  std::vector<double> rxs(W);
  for (int x = 0; x < W; ++x) rxs[x] = (x - cx) / fx;
  // The depth, the flags and the fine blocks a band of 8 rows at a time (one parallel region: on a
  // busy host each region's barrier waits for the slowest core), a row's pixels side by side
  // (wet_depth_row); the coarse blocks as the minima of 4 x 4 fine ones (the blocks nest from the
  // origin: the same minima, min being exact).
  Pyramid& f = pyr[1];
  Pyramid& f_off = pyr_off[1];
  const bool dense = s.range.pixel_stride() == 1;
#pragma omp parallel num_threads(nt)
  {
    std::vector<float> row(dense ? 0 : W);
#pragma omp for schedule(dynamic, 1)
    for (int by = 0; by < f.bh; ++by)
      for (int y = by * detail::kWetFineBlock; y < std::min(H, (by + 1) * detail::kWetFineBlock); ++y) {
        const float* range = s.range.data() + static_cast<std::ptrdiff_t>(y) * s.range.row_stride();
        if (!dense) {
          for (int x = 0; x < W; ++x) row[x] = s.range.at(x, y);
          range = row.data();
        }
        float* z = maps.data() + static_cast<std::size_t>(y) * W;
        float* zo = lift ? z + wh : nullptr;
        detail::wet_depth_row(pf, rxs.data(), (y - cy) / fy, range, W, z, zo, flags.data() + static_cast<std::size_t>(y) * W);
        const auto block_minima = [&](const float* zr, Pyramid& p) {
          float* fm = p.m.data() + static_cast<std::size_t>(by) * p.bw;
          for (int bx = 0; bx < p.bw; ++bx) {
            float m = fm[bx];
            for (int x = bx * detail::kWetFineBlock; x < std::min(W, (bx + 1) * detail::kWetFineBlock); ++x)
              m = std::min(m, zr[x]);
            fm[bx] = m;
          }
        };
        block_minima(z, f);
        if (lift) block_minima(zo, f_off);
        const float* src = s.rgb.row(y);
        float* dst = out.row(y);
        if (s.rgb.pixel_stride() == nc) {
          std::copy(src, src + static_cast<std::size_t>(W) * nc, dst);
        } else {
          for (int x = 0; x < W; ++x)
            for (int c = 0; c < nc; ++c) dst[x * nc + c] = src[x * s.rgb.pixel_stride() + c];
        }
      }
  }
  for (int l = 0; l < (lift ? 2 : 1); ++l) {
    std::array<Pyramid, 2>& p = l == 0 ? pyr : pyr_off;
    Pyramid &c = p[0], &fi = p[1];
    constexpr int r = detail::kWetCoarseBlock / detail::kWetFineBlock;
    for (int by = 0; by < fi.bh; ++by)
      for (int bx = 0; bx < fi.bw; ++bx) {
        float& m = c.m[static_cast<std::size_t>(by / r) * c.bw + bx / r];
        m = std::min(m, fi.m[static_cast<std::size_t>(by) * fi.bw + bx]);
      }
    for (int k = 0; k < 2; ++k) {
      const Pyramid* q = &p[k];
      float* rect = maps.data() + mm.rect_at[k] + (l == 1 ? mm.rect_off[k] : 0);
      for (int by = 0; by < q->bh; ++by)
        for (int bx = 0; bx < q->bw; ++bx) {
          // rect[9 (by·bw + bx) + 3 ny + nx]: the minimum over rows by .. by + ny and columns
          // bx .. bx + nx (the blocks past the edge left out: they are never asked, the ask's
          // indices are clamped), each column's minimum carried down the rows
          float* e = rect + 9 * (static_cast<std::size_t>(by) * q->bw + bx);
          float col[3] = {INFINITY, INFINITY, INFINITY};
          for (int ny = 0; ny < 3; ++ny) {
            float v = INFINITY;
            for (int nx = 0; nx < 3; ++nx) {
              if (by + ny < q->bh && bx + nx < q->bw)
                col[nx] = std::min(col[nx], q->m[static_cast<std::size_t>(by + ny) * q->bw + bx + nx]);
              v = std::min(v, col[nx]);
              e[3 * ny + nx] = v;
            }
          }
        }
    }
  }
  std::array<std::vector<float>, 2> blocks;
  for (int l = 0; l < 2; ++l) {
    blocks[l] = pyr[l].m;
    if (lift) blocks[l].insert(blocks[l].end(), pyr_off[l].m.begin(), pyr_off[l].m.end());
    mm.blocks[l] = blocks[l].data(), mm.blocks_off[l] = lift ? pyr[l].m.size() : 0;
    mm.bw[l] = pyr[l].bw, mm.bh[l] = pyr[l].bh;
  }
  mm.maps = maps.data();
  mm.front_k = static_cast<float>(1.0 + kWetHitMargin);
  mm.thick_k = static_cast<float>(1.0 + kWetHitMargin + kWetThickness);
  mm.max_steps = 4 * (W + H);
  const auto t_march = std::chrono::steady_clock::now();
  const float kf = static_cast<float>(o.k_eff);
  std::size_t n_ground = 0, n_hits = 0, n_sky = 0, n_left = 0;
  // Bands of 4 rows: each band's ground pixels set their rays up, the march takes them (several
  // side by side), and the pixels are written from where each ended.
  constexpr int kBand = 4;
  const int bands = (H + kBand - 1) / kBand;
#pragma omp parallel num_threads(nt) reduction(+ : n_ground, n_hits, n_sky, n_left)
  {
    detail::WetMarchRays rays;
    std::vector<std::int32_t> px, py;
    std::vector<float> pz, mirror;
#pragma omp for schedule(dynamic, 1)
    for (int band = 0; band < bands; ++band) {
      // The band's ground pixels: a ray that goes down (it can meet the ground from above) whose
      // point lies within the tolerance of the plane, or in the mask.
      px.clear(), py.clear(), pz.clear();
      for (int y = band * kBand; y < std::min(H, (band + 1) * kBand); ++y) {
        const std::uint8_t* fl = flags.data() + static_cast<std::size_t>(y) * W;
        for (int x = 0; x < W; ++x) {
          if (!(fl[x] & detail::kWetDown)) continue;
          if (masked ? !(s.mask.at(x, y) > 0.5f) : !(fl[x] & detail::kWetOnPlane)) continue;
          ground.at(x, y) = 1.0f;
          px.push_back(x), py.push_back(y), pz.push_back(maps[static_cast<std::size_t>(y) * W + x]);
        }
      }
      n_ground += px.size();
      // The mirrored ray X(t) = P + t·D from each ground point (side by side: wet_setup_rays). Its
      // image is a line, and with w = 1/Z along it (Z = P_z + t·D_z) u = u∞ + w·c_u, v = v∞ + w·c_v
      // exactly (u∞, v∞ the vanishing point of D): the march steps w, one pixel of the line's major
      // axis a step (w falls towards 0, the vanishing point, when D_z > 0, rises towards the image
      // plane else). above_ground: the ray is above the plane's tolerance from w_lift on (its height
      // h0 + t·(−dn) grows along the march, t = (1/w − P_z)/D_z), after which the maps without the
      // plane's pixels serve. With each ray, the mirror's weight f·R_F(θ) (WetOptics::mirror).
      mirror.resize(px.size());
      detail::wet_setup_rays(pf, px.data(), py.data(), pz.data(), px.size(), rays, mirror.data());
      if (!detail::wet_march_rays(mm, rays)) march_rays_one_by_one(mm, rays);
      for (std::size_t i = 0; i < rays.size(); ++i) {
        const int x = px[i], y = py[i];
        std::array<float, 3> L = s.sky;
        double hu = rays.hu[i], hv = rays.hv[i];
        bool hit = rays.end[i] == detail::WetMarchRays::hit;
        if (rays.end[i] == detail::WetMarchRays::infinity) {
          // The vanishing point's pixel: the sky there (or a surface the ray would meet at infinity).
          const double uinf = rays.uinf[i], vinf = rays.vinf[i];
          if ((rays.flags[i] & detail::WetMarchRays::dz_positive) && uinf > -0.5 && uinf < W - 0.5 && vinf > -0.5 &&
              vinf < H - 0.5) {
            hu = uinf, hv = vinf, hit = true;
            ++n_sky;
          }
        } else if (hit) {
          ++n_hits;
        }
        if (hit) {
          const int iu = static_cast<int>(round_half_away(hu)), iv = static_cast<int>(round_half_away(hv));
          for (int c = 0; c < 3; ++c) L[c] = s.rgb.at(iu, iv, c);
        } else {
          ++n_left;
        }
        for (int c = 0; c < 3; ++c) out.at(x, y, c) = kf * s.rgb.at(x, y, c) + mirror[i] * L[c];
      }
    }
  }
  st.ground = n_ground, st.hits = n_hits, st.sky_pixels = n_sky, st.left_frame = n_left;
  const auto t_end = std::chrono::steady_clock::now();
  st.maps_ms = std::chrono::duration<double, std::milli>(t_march - t_maps).count();
  st.march_ms = std::chrono::duration<double, std::milli>(t_end - t_march).count();
  if (o.f == 0.0) out = s.rgb.to_image();  // a dry film: the input, bit for bit
  if (stats) *stats = st;
  if (ground_out) *ground_out = std::move(ground);
  return out;
}

// ---- the LiDAR -----------------------------------------------------------------------------

const ParamTable<WetScan>& wet_scan_param_table() {
  static const ParamTable<WetScan> t = [] {
    ParamTable<WetScan> d("scan");
    d.real("lidar-height", &WetScan::lidar_height_m, "m", Range::above(0.0),
           "height of the LiDAR above the ground plane (level sensor; KITTI's Velodyne: 1.73 m)")
        .real("scan-ground-tolerance", &WetScan::scan_tolerance_m, "m", Range::above(0.0),
              "a point within this of the plane z = -lidar-height is ground")
        .real("noise-floor", &WetScan::noise_floor, "1/m^2", Range::above(0.0),
              "noise floor F: the weakest mean return power (intensity/range^2) the sensor detects (as brume lidar "
              "rain's)")
        .count("scan-seed", &WetScan::seed, "1", Range::at_least(0.0), "seed of the detection draws (same seed, same scan)");
    return d;
  }();
  return t;
}

const ParamTable<LidarWetParams>& lidar_wet_param_table() {
  static const ParamTable<LidarWetParams> t = [] {
    ParamTable<LidarWetParams> d("wet");
    d.nest(&LidarWetParams::film, wet_film_param_table()).nest(&LidarWetParams::scan, wet_scan_param_table());
    return d;
  }();
  return t;
}

void validate_lidar_wet(const LidarWetParams& p) {
  lidar_wet_param_table().validate(p);
  validate_wet_film(p.film);
}

LidarWetStats lidar_wet(const float* in, float* out, std::size_t n, const LidarWetParams& p, std::uint8_t* labels,
                        const std::string& what) {
  validate_lidar_wet(p);
  const WetOptics o(p.film);
  const double H = p.scan.lidar_height_m, tol = p.scan.scan_tolerance_m, F = p.scan.noise_floor;
  LidarWetStats st;
  st.points = n;
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = in + 4 * i;
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(q[c]) || (c == 3 && q[c] < 0.0f))
        throw Error(what + ": point " + std::to_string(i) + " has " + (c == 3 ? "intensity " : "coordinate ") +
                    text::g(q[c]) + "; a scan's coordinates must be finite and its intensities finite and >= 0");
  }
  std::size_t k = 0;  // the next output slot (k <= i: in place is safe)
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = in + 4 * i;
    const double r = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2]);
    const bool on_ground = r > 0.0 && std::fabs(q[2] + H) <= tol;
    std::uint8_t label = on_ground ? 1 : 0;
    float intensity = q[3];
    if (on_ground && o.f > 0.0) {
      const double qe = o.lidar(-q[2] / r);
      intensity = static_cast<float>(q[3] * qe);
      if (qe < 1.0) {
        const double x = std::max<double>(q[3], F * r * r);  // the clear power on the scan's scale, >= F r²
        const double keep = std::exp(-(F * r * r / x) * (1.0 / qe - 1.0));
        const double u = hash_unit(hash_fold(hash_fold(p.scan.seed, 0x3e7ull), i));
        if (!(u < keep)) label = 2;
      }
    }
    if (label == 1) ++st.ground;
    if (labels) labels[i] = label;
    if (label == 2) {
      ++st.lost, ++st.ground;
      continue;
    }
    float* d = out + 4 * k++;
    d[0] = q[0], d[1] = q[1], d[2] = q[2], d[3] = intensity;
  }
  return st;
}

nlohmann::json lidar_wet_record(const LidarWetParams& p, const LidarWetStats& st) {
  const WetOptics o(p.film);
  nlohmann::json j = wet_optics_record(p.film, o);
  j["lidar_height_m"] = p.scan.lidar_height_m;
  j["scan_ground_tolerance_m"] = p.scan.scan_tolerance_m;
  j["noise_floor_per_m2"] = p.scan.noise_floor;
  j["seed"] = p.scan.seed;
  j["ground_rule"] = "|z + lidar_height| <= scan_ground_tolerance (sensor frame: z up); cos theta = -z/r";
  j["loss_rule"] =
      "a ground point the film weakens (Q_eff < 1) is kept with probability exp(-(F/x)(1/Q_eff - 1)), x = "
      "max(i/r^2, F) (brume/medium.hpp's detection rule)";
  j["points"] = st.points;
  j["ground"] = st.ground;
  j["lost"] = st.lost;
  j["labels"] = "0 off the ground (unchanged), 1 wet ground (kept), 2 lost";
  return j;
}

}  // namespace brume
